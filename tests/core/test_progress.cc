// ProgressReporter: in lines mode (a log file) whole lines at every tenth of
// the work or after the time limit, never a carriage return; in terminal mode
// one line redrawn in place and ended once.
#include "core/progress.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <string>
#include <vector>

#include "core/error.h"

namespace arreg {
namespace {

// A temporary file the reporter writes into, read back whole.
class Sink {
 public:
  Sink() : f_(std::tmpfile()) { EXPECT_NE(f_, nullptr) << "no temporary file"; }
  ~Sink() {
    if (f_) std::fclose(f_);
  }
  Sink(const Sink&) = delete;
  Sink& operator=(const Sink&) = delete;
  std::FILE* get() const { return f_; }
  std::string Text() const {
    std::fflush(f_);
    std::rewind(f_);
    std::string text;
    char buffer[256];
    size_t n = 0;
    while ((n = std::fread(buffer, 1, sizeof buffer, f_)) > 0) text.append(buffer, n);
    return text;
  }

 private:
  std::FILE* f_;
};

std::vector<std::string> Lines(const std::string& text) {
  std::vector<std::string> lines;
  size_t begin = 0;
  for (size_t end; (end = text.find('\n', begin)) != std::string::npos; begin = end + 1)
    lines.push_back(text.substr(begin, end - begin));
  EXPECT_EQ(begin, text.size()) << "the last line is not ended";
  return lines;
}

TEST(Progress, LinesModePrintsEveryTenthAndTheEndWithoutCarriageReturns) {
  Sink sink;
  {
    ProgressReporter p("arreg test: frame", sink.get(), ProgressOptions{});  // lines, 10 %, 10 s
    for (int done = 1; done <= 120; ++done) p.UpdateAt(done, 120, "x", 0.01 * done);
    EXPECT_EQ(p.lines_printed(), 10);
  }
  const std::string text = sink.Text();
  EXPECT_EQ(text.find('\r'), std::string::npos);
  const std::vector<std::string> lines = Lines(text);
  ASSERT_EQ(lines.size(), 10u);
  EXPECT_EQ(lines[0], "arreg test: frame 12/120 (10 %)  x");
  EXPECT_EQ(lines[4], "arreg test: frame 60/120 (50 %)  x");
  EXPECT_EQ(lines[9], "arreg test: frame 120/120 (100 %)  x");
}

TEST(Progress, LinesModePrintsAfterTheTimeLimitAndOnceForAJumpOverSeveralTenths) {
  Sink sink;
  ProgressOptions o;
  o.line_every_s = 5.0;
  ProgressReporter p("slow", sink.get(), o);
  p.UpdateAt(1, 1000, "", 1.0);     // 0.1 %, 1 s: nothing due
  p.UpdateAt(2, 1000, "", 5.5);     // 5.5 s since the start: a line
  p.UpdateAt(3, 1000, "", 9.0);     // 3.5 s since that line: nothing
  p.UpdateAt(4, 1000, "", 10.6);    // 5.1 s: a line
  p.UpdateAt(350, 1000, "", 10.7);  // over 10, 20 and 30 %: one line
  p.UpdateAt(399, 1000, "", 10.8);  // the next is due at 40 %
  p.UpdateAt(400, 1000, "", 10.9);
  p.UpdateAt(400, 1000, "", 20.0);  // the same count again: nothing new to say
  const std::vector<std::string> lines = Lines(sink.Text());
  ASSERT_EQ(lines.size(), 4u);
  EXPECT_EQ(lines[0], "slow 2/1000 (0 %)");
  EXPECT_EQ(lines[1], "slow 4/1000 (0 %)");
  EXPECT_EQ(lines[2], "slow 350/1000 (35 %)");
  EXPECT_EQ(lines[3], "slow 400/1000 (40 %)");
}

TEST(Progress, UnknownTotalPrintsByTimeOnly) {
  Sink sink;
  ProgressReporter p("open", sink.get(), ProgressOptions{});
  for (int done = 1; done <= 30; ++done) p.UpdateAt(done, 0, "", done);  // one per second
  const std::vector<std::string> lines = Lines(sink.Text());
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_EQ(lines[0], "open 10");
  EXPECT_EQ(lines[2], "open 30");
}

TEST(Progress, TerminalModeRedrawsOneLineAndEndsItOnce) {
  Sink sink;
  ProgressOptions o;
  o.terminal = true;
  o.bar_width = 4;
  {
    ProgressReporter p("bar", sink.get(), o);
    for (int done = 1; done <= 4; ++done) p.UpdateAt(done, 4, "", done);
    p.Finish();  // already ended at 4/4: no second newline
  }
  const std::string text = sink.Text();
  EXPECT_EQ(text, "\rbar 1/4 [#   ]   \rbar 2/4 [##  ]   \rbar 3/4 [### ]   \rbar 4/4 [####]   \n");
}

TEST(Progress, AnInterruptedTerminalLineIsEndedByTheDestructor) {
  Sink sink;
  ProgressOptions o;
  o.terminal = true;
  { ProgressReporter("bar", sink.get(), o).UpdateAt(1, 3, "", 0.0); }
  const std::string text = sink.Text();
  ASSERT_FALSE(text.empty());
  EXPECT_EQ(text.back(), '\n');
  EXPECT_EQ(std::count(text.begin(), text.end(), '\n'), 1);
}

TEST(Progress, BadOptionsNameTheField) {
  ProgressOptions o;
  o.line_every_fraction = 0.0;
  EXPECT_THROW(o.Check(), Error);
  o = ProgressOptions{};
  o.line_every_s = -1.0;
  EXPECT_THROW(o.Check(), Error);
  o = ProgressOptions{};
  o.bar_width = 0;
  try {
    ProgressReporter p("x", stderr, o);
    FAIL() << "no error";
  } catch (const Error& e) {
    EXPECT_NE(std::string(e.what()).find("bar_width"), std::string::npos);
  }
}

}  // namespace
}  // namespace arreg
