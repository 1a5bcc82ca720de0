// Progress of a long command (frames registered, generated or evaluated) on a
// stream: a bar redrawn in place on a terminal, whole lines now and then in a
// log file or pipe, so that a log reads line by line without carriage returns.
#pragma once

#include <chrono>
#include <cstdio>
#include <string>

namespace arreg {

struct ProgressOptions {
  // true: one line redrawn with '\r' at every update (a terminal); false: whole
  // lines, only as often as the two limits below allow.
  bool terminal = false;
  double line_every_fraction = 0.1;  // lines: one each time this fraction more is done, in (0, 1]
  double line_every_s = 10.0;        // lines: ... or once this many seconds passed since the last
  int bar_width = 30;                // terminal: characters of the bar, >= 1
  void Check() const;                // throws arreg::Error naming the bad field
};

// The options for `stream`: terminal mode when it is a terminal (isatty), else
// lines every 10 % or 10 s.
ProgressOptions ProgressOptionsFor(std::FILE* stream);

// Reports `done` of `total` units after a label that names them ("arreg eval:
// run frame" prints "arreg eval: run frame 3/90 (3 %)" in lines mode, "arreg
// eval: run frame 3/90 [#  ...  ]" on a terminal). Each call to Update may
// print; Finish ends the terminal line. Not thread-safe.
class ProgressReporter {
 public:
  ProgressReporter(std::string label, std::FILE* stream, const ProgressOptions& options);
  ~ProgressReporter() { Finish(); }
  ProgressReporter(const ProgressReporter&) = delete;
  ProgressReporter& operator=(const ProgressReporter&) = delete;

  // `detail` follows the counts (e.g. "12.3 fps"); `total` <= 0 means unknown
  // (no bar; lines by time only). The elapsed time is the reporter's own clock.
  void Update(int done, int total, const std::string& detail = "");
  // The same with the time since construction given (for tests and replays).
  void UpdateAt(int done, int total, const std::string& detail, double elapsed_s);
  // Ends a terminal line left open by Update (once); lines mode prints nothing.
  void Finish();

  int lines_printed() const { return lines_printed_; }  // newline-ended lines written so far

 private:
  std::string label_;
  std::FILE* stream_;
  ProgressOptions options_;
  std::chrono::steady_clock::time_point start_;
  bool line_open_ = false;      // terminal: a redrawn line awaits its newline
  int last_line_done_ = -1;     // lines: `done` of the last line printed
  double last_line_s_ = 0.0;    // lines: when the last line was printed
  double next_fraction_ = 0.0;  // lines: the fraction at which the next line is due
  int lines_printed_ = 0;
};

}  // namespace arreg
