#include "core/progress.h"

#include <unistd.h>

#include <algorithm>
#include <cmath>
#include <utility>

#include "core/error.h"

namespace arreg {

void ProgressOptions::Check() const {
  ARREG_CHECK_INPUT(line_every_fraction > 0.0 && line_every_fraction <= 1.0, "",
                    "line_every_fraction", "must be in (0, 1], got ", line_every_fraction);
  ARREG_CHECK_INPUT(line_every_s > 0.0, "", "line_every_s", "must be > 0, got ", line_every_s);
  ARREG_CHECK_INPUT(bar_width >= 1, "", "bar_width", "must be >= 1, got ", bar_width);
}

ProgressOptions ProgressOptionsFor(std::FILE* stream) {
  ProgressOptions o;
  o.terminal = stream != nullptr && isatty(fileno(stream)) == 1;
  return o;
}

ProgressReporter::ProgressReporter(std::string label, std::FILE* stream,
                                   const ProgressOptions& options)
    : label_(std::move(label)),
      stream_(stream),
      options_(options),
      start_(std::chrono::steady_clock::now()) {
  options_.Check();
  next_fraction_ = options_.line_every_fraction;
}

void ProgressReporter::Update(int done, int total, const std::string& detail) {
  const double elapsed_s =
      std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count();
  UpdateAt(done, total, detail, elapsed_s);
}

void ProgressReporter::UpdateAt(int done, int total, const std::string& detail, double elapsed_s) {
  const std::string tail = detail.empty() ? "" : "  " + detail;
  if (options_.terminal) {
    std::string bar;
    if (total > 0) {
      const int width = options_.bar_width;
      const int filled =
          std::clamp(static_cast<int>(static_cast<long long>(width) * done / total), 0, width);
      bar = " [" + std::string(filled, '#') + std::string(width - filled, ' ') + "]";
    }
    // Trailing spaces wipe what a longer previous line left.
    std::fprintf(stream_, "\r%s %d/%d%s%s   ", label_.c_str(), done, total, bar.c_str(),
                 tail.c_str());
    line_open_ = true;
    if (total > 0 && done >= total) Finish();
    std::fflush(stream_);
    return;
  }
  if (done == last_line_done_) return;
  const bool complete = total > 0 && done >= total;
  const double fraction = total > 0 ? static_cast<double>(done) / total : 0.0;
  const bool fraction_due = total > 0 && fraction + 1e-9 >= next_fraction_;
  const bool time_due = elapsed_s - last_line_s_ >= options_.line_every_s;
  if (!complete && !fraction_due && !time_due) return;
  if (total > 0)
    std::fprintf(stream_, "%s %d/%d (%.0f %%)%s\n", label_.c_str(), done, total, 100.0 * fraction,
                 tail.c_str());
  else
    std::fprintf(stream_, "%s %d%s\n", label_.c_str(), done, tail.c_str());
  std::fflush(stream_);
  ++lines_printed_;
  last_line_done_ = done;
  last_line_s_ = elapsed_s;
  // The next line is due at the next multiple of the step above this fraction,
  // so a jump over several steps prints one line, not one per step.
  const double step = options_.line_every_fraction;
  next_fraction_ = (std::floor(fraction / step + 1e-9) + 1.0) * step;
}

void ProgressReporter::Finish() {
  if (!line_open_) return;
  std::fprintf(stream_, "\n");
  std::fflush(stream_);
  line_open_ = false;
  ++lines_printed_;
}

}  // namespace arreg
