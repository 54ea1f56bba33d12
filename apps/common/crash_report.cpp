// strata programs — the fatal-signal report (crash_report.hpp).
//
// Only async-signal-safe calls in the handler (write, backtrace_symbols_fd, signal,
// raise), except backtrace(), whose first call may allocate while libgcc's unwinder
// loads: report_fatal_signals() calls it once beforehand so that the handler's call does
// not (glibc's manual, "Backtraces").
#include "crash_report.hpp"

#include <execinfo.h>
#include <unistd.h>

#include <csignal>
#include <cstdio>
#include <cstring>

namespace strata::app {
namespace {

// the signals reported, with what the report calls them
constexpr struct {
  int sig;
  const char* name;
} kSignals[] = {{SIGSEGV, "SIGSEGV"},
                {SIGBUS, "SIGBUS"},
                {SIGFPE, "SIGFPE"},
                {SIGILL, "SIGILL"},
                {SIGABRT, "SIGABRT"}};
alignas(16) char alt_stack[1 << 16];

void put(const char* s) {
  std::size_t n = std::strlen(s);
  while (n > 0) {
    const ssize_t w = ::write(STDERR_FILENO, s, n);
    if (w <= 0) return;
    s += w;
    n -= static_cast<std::size_t>(w);
  }
}

void on_fatal(int sig) {
  char num[12];  // the number, written without the (not async-signal-safe) printf family
  char* p = num + sizeof(num) - 1;
  *p = '\0';
  for (int v = sig; v > 0 && p > num; v /= 10) *--p = static_cast<char>('0' + v % 10);
  const char* name = "?";
  for (const auto& s : kSignals)
    if (s.sig == sig) name = s.name;
  put("\nfatal signal ");
  put(p);
  put(" (");
  put(name);
  put("); backtrace (addr2line -f -C -e <binary> <offset> with the same build):\n");
  void* frames[64];
  const int n = backtrace(frames, 64);
  backtrace_symbols_fd(frames, n, STDERR_FILENO);
  std::signal(sig, SIG_DFL);  // then die of it as without this handler
  std::raise(sig);
}

}  // namespace

void report_fatal_signals() {
  std::setvbuf(stdout, nullptr, _IOLBF, 0);
  void* warm[2];
  (void)backtrace(warm, 2);
  stack_t ss{};
  ss.ss_sp = alt_stack;
  ss.ss_size = sizeof(alt_stack);
  (void)sigaltstack(&ss, nullptr);
  struct sigaction sa {};
  sa.sa_handler = on_fatal;
  sigemptyset(&sa.sa_mask);
  sa.sa_flags = SA_ONSTACK | SA_RESETHAND;
  for (const auto& s : kSignals) (void)sigaction(s.sig, &sa, nullptr);
}

}  // namespace strata::app
