// strata programs (the CLI, the benchmark drivers) — which OpenBLAS kernels the process
// runs, and a fix for the case where OpenBLAS picks the wrong ones.
//
// OpenBLAS built with DYNAMIC_ARCH (Debian's and Ubuntu's packages) chooses its kernels
// once, when the library is loaded, from the CPU's family and model. Releases before 0.3.25
// fall back to the Prescott kernels (SSE3, 2004) on Intel CPUs whose model they do not
// know, however many vector units the CPU has (OpenBLAS issue #4267, fixed by pull request
// #4268 in 0.3.25): Debian 12's 0.3.21 does so on current Xeons, where its dense
// factorization kernels then run at a quarter of their speed. The environment variable
// OPENBLAS_CORETYPE overrides the choice, but only when it is set before the library
// loads, that is before the program starts.
#pragma once

#include <string>

namespace strata::app {

/// The BLAS this process uses, e.g. "OpenBLAS 0.3.21, SkylakeX kernels": the library's
/// version from openblas_get_config() and the kernels from openblas_get_corename().
std::string blas_description();

/// The OpenBLAS core type this CPU supports best among those every OpenBLAS with
/// DYNAMIC_ARCH on x86-64 has: "SkylakeX" when the CPU has AVX-512 F, CD, BW, DQ and VL,
/// else "Haswell" when it has AVX2 and FMA, else "" (older x86-64 CPUs and other
/// architectures, where nothing is changed).
std::string openblas_core_for_cpu();

/// Makes the process run OpenBLAS's kernels for its CPU: when the loaded OpenBLAS chose
/// its Prescott kernels, OPENBLAS_CORETYPE is not set, and the CPU supports better ones
/// (openblas_core_for_cpu), sets OPENBLAS_CORETYPE to them and executes the program again
/// (/proc/self/exe, the same arguments and environment otherwise; the process id stays).
/// Returns when nothing needed to change, or when the execution failed (the process then
/// goes on with the kernels it has). A user who sets OPENBLAS_CORETYPE, to any value, keeps
/// it. Call at the very start of main, before threads, MPI or files are opened: the
/// process image is replaced. `argv` is main's (terminated by a null pointer).
void use_fitting_blas_kernels(char** argv);

}  // namespace strata::app
