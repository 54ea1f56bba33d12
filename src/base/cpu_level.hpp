// strata — the instruction-set level the host code was compiled for, checked at start-up.
//
// Why: the C++ code is compiled for an x86-64 microarchitecture level (CMake's
// STRATA_CPU_ARCH, default x86-64-v3: AVX2 and FMA), so that the compiler vectorizes the
// small dense kernels, the assemblies and the engine's dual numbers four doubles wide. On a
// CPU without those instructions such code dies of SIGILL at its first vector instruction,
// with no message. This file's object is compiled for the base x86-64 level; its start-up
// check runs before the other static initializers of the program (or of the Python
// module) and, on a CPU below the build's level, prints which instructions are missing and
// how to rebuild, and ends the process with exit status 1.
#pragma once
#include <cstddef>

namespace strata::detail {

/// Whether this CPU has the instruction set extension `name` (one of the names below;
/// false for any other name and off x86-64).
bool cpu_has_extension(const char* name) noexcept;

/// The extensions of `level` ("x86-64-v3" or "x86-64-v4"; any other level needs none)
/// for which has(name) is false, space-separated into out (size bytes, truncated;
/// "" when none). Names as GCC's __builtin_cpu_supports: avx avx2 bmi bmi2 fma popcnt for
/// v3, and avx512f avx512bw avx512cd avx512dq avx512vl for v4. The start-up check calls it
/// with this CPU's answers.
void missing_cpu_extensions(const char* level, bool (*has)(const char* name), char* out,
                            std::size_t size) noexcept;

/// Whether this CPU has every instruction set extension of the build's level (true when
/// no level is checked: native, none, or not x86-64). Cheap after the first call.
/// Solver's constructor calls it, which also links the start-up check into every program
/// that makes a Solver.
bool cpu_supports_build_level() noexcept;
/// What the host code was compiled for: CMake's STRATA_CPU_ARCH ("x86-64-v3",
/// "x86-64-v4", "native"), or "the compiler's default target" when no -march was given.
const char* build_cpu_arch() noexcept;

}  // namespace strata::detail
