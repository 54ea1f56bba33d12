// strata programs (the CLI, the benchmark drivers) — what a process that dies of a signal
// leaves behind.
#pragma once

namespace strata::app {

/// Makes a fatal signal in this process (SIGSEGV, SIGBUS, SIGFPE, SIGILL, SIGABRT) print,
/// on standard error, "fatal signal N (NAME)" and the call stack as glibc's
/// backtrace_symbols_fd writes it (one frame a line, `binary(+offset)` or
/// `binary(symbol+offset)`; `addr2line -f -C -e binary offset` on the same build names the
/// function, and the source line where the build has debug information), then die of that signal as
/// it would have. The handlers run on a stack of their own, so a stack overflow is reported too.
/// Also makes standard output line-buffered, so that the rows a driver printed before the crash
/// reach a pipe (a benchmark on a lent GPU machine is read through one). Call once, at the start of
/// main. Why: a crash on a machine without a debugger, whose core files do not come back,
/// must still say where it happened.
void report_fatal_signals();

}  // namespace strata::app
