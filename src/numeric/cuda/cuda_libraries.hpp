// strata — NVIDIA cuBLAS and cuSOLVER loaded when the CUDA backend is first used, not when
// a program that links strata starts (cuda_libraries.cpp says why and how).
#pragma once

namespace strata::cuda {

/// Loads libcublas and libcusolver (the versions of the CUDA toolkit strata was built
/// with) into the process, once; later calls return at once. Every cuBLAS and cuSOLVER
/// function strata calls loads them on its first call as well, so this only moves the
/// loading earlier (the CUDA executor's set-up, the engine's background start of the
/// device). Thread-safe. Throws NotSupported naming the library and the dynamic loader's
/// message when one cannot be loaded; a later call tries again.
void load_libraries();

/// Opens the shared library `file` (e.g. "libcublas.so.13") by the dynamic loader's
/// search, then in the CUDA toolkit's library folder of the build; `what` names it in the
/// error. Returns the handle (never closed: the library stays for the process's life).
/// Throws NotSupported naming `what`, `file` and the loader's message when neither opens.
void* open_library(const char* file, const char* what);

}  // namespace strata::cuda
