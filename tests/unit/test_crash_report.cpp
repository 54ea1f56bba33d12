// The programs' fatal-signal report (apps/common/crash_report.hpp): a process that
// dies of SIGSEGV or SIGABRT after report_fatal_signals() says which signal and prints
// frames that name its binary, and still dies of that signal.
#include <gtest/gtest.h>

#include <csignal>
#include <cstdlib>

#include "crash_report.hpp"

namespace {

[[gnu::noinline]] void die_of(int sig) {
  strata::app::report_fatal_signals();
  std::raise(sig);
}

TEST(CrashReportDeathTest, SegmentationFaultNamesTheSignalAndTheFrames) {
  EXPECT_EXIT(die_of(SIGSEGV), testing::KilledBySignal(SIGSEGV),
              "fatal signal 11 \\(SIGSEGV\\); backtrace.*\n.*test_crash_report");
}

TEST(CrashReportDeathTest, AbortNamesTheSignal) {
  EXPECT_EXIT(die_of(SIGABRT), testing::KilledBySignal(SIGABRT),
              "fatal signal 6 \\(SIGABRT\\); backtrace");
}

TEST(CrashReportDeathTest, StackOverflowIsReportedFromItsOwnStack) {
  // unbounded recursion: the handler must run on the alternate stack
  struct Deep {
    [[gnu::noinline]] static int down(int d) {
      volatile char pad[4096];  // volatile: the frames stay, the recursion is not folded
      pad[0] = static_cast<char>(d);
      return down(d + 1) + pad[0];
    }
  };
  EXPECT_EXIT(
      {
        strata::app::report_fatal_signals();
        (void)Deep::down(0);
      },
      testing::KilledBySignal(SIGSEGV), "fatal signal 11 \\(SIGSEGV\\)");
}

}  // namespace
