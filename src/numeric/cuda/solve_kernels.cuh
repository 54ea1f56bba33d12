// strata — CUDA kernels of the triangular solves with a device-resident factor.
//
// Level-parallel multifrontal solves (Liu 1992, §6; the level schedule of the
// factorization, DESIGN.md §2): one launch per level, one thread block per front.
// Forward: a front gathers its pivot rows' right-hand side and its children's update
// vectors (extend-add, children one after another, so no two writes collide and the
// result does not depend on scheduling), solves with L11, and leaves its own update
// vector u_f = x_R − L21·y for its parent. Backward, root level first: a front reads the
// solution at its non-pivot rows (ancestors, already solved) and solves for its pivots;
// fronts write disjoint entries. Both are deterministic.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

namespace strata::cuda {

/// Device copies of what the solve reads (int64 unless noted; tree numbering, 0-based).
struct SolveTree {
  const std::int64_t* fronts;         ///< schedule.fronts
  const std::int64_t* n_rows;         ///< per front
  const std::int64_t* n_pivots;       ///< per front
  const std::int64_t* row_offsets;    ///< per front, into rows and the scratch
  const std::int64_t* first_pivot;    ///< per front
  const std::int64_t* rows;           ///< NumericFactor::rows (pivot rows as factored)
  const std::int64_t* child_offsets;  ///< per front
  const std::int64_t* children;
  const std::int64_t* rel_offsets;  ///< per child: its CB rows' positions in the parent
  const std::int64_t* rel;
  const std::int64_t* pivot_pos;     ///< per unknown: its place among its front's pivots
  const std::int64_t* pivot_row;     ///< per pivot position: the unknown it eliminated
  const std::int64_t* u_offset;      ///< per front: its update vector in the u arena
  const std::int64_t* panel_offset;  ///< per front: its panel in `panels`
  const double* panels;              ///< the factor (NumericFactor::panels layout)
  std::int64_t n;                    ///< unknowns
  std::int64_t u_total;              ///< doubles of the u arena per right-hand side
};

/// Forward substitution for the fronts at schedule positions [begin, begin+count).
/// x: n×nrhs (column-major); u: u_total×nrhs; scratch: one double per front row.
/// `unit`: L11 has a unit diagonal (LDLᵀ, LU).
void launch_solve_forward(const SolveTree& t, std::int64_t begin, std::int64_t count, double* x,
                          double* u, double* scratch, std::int64_t nrhs, bool lu, bool unit,
                          cudaStream_t s);

/// x ← D⁻¹ x for LDLᵀ (1×1 and 2×2 blocks by pivot position).
void launch_solve_diagonal(const SolveTree& t, const double* d_diag, const double* d_off,
                           const int* pivot_size, double* x, std::int64_t nrhs, cudaStream_t s);

/// Backward substitution for the fronts at schedule positions [begin, begin+count).
void launch_solve_backward(const SolveTree& t, std::int64_t begin, std::int64_t count, double* x,
                           double* scratch, std::int64_t nrhs, bool lu, bool unit, cudaStream_t s);

}  // namespace strata::cuda
