// strata — CUDA kernels of the triangular solves with a device-resident factor.
//
// Multifrontal solves (Liu 1992, §6) by subtrees and by the levels of the factorization's
// schedule (DESIGN.md §2). Forward: first one launch solves the plan's subtrees, one thread
// block each, the fronts of a subtree one after another in postorder (each front gathers
// its block W — pivot rows' right-hand sides plus the children's update vectors,
// SolvePlan::inv_* —, sweeps it with tiles of 32 pivot columns and warp-level triangles,
// solve_device.cuh, and scatters pivots to x, the rest to its update vector). Then per
// level, deepest first, the fronts outside the subtrees: one launch solves the block-path
// fronts of at most kChunkRows rows the same way, one block each; the taller block-path
// fronts and the library-path fronts are gathered (a block per kChunkRows rows), swept by a
// block each or run through cuBLAS (cuda_solve.cu), and scattered. A taller block-path
// front's block solves only its triangle: the products with L21 (forward) and L21ᵀ or U12
// (backward) are done by its scatter and gather blocks, a chunk of rows each, the backward
// ones as partial products the sweep then sums in chunk order. Backward, in the reverse
// order: levels from the root, then the subtrees with their fronts in reverse postorder;
// gather W = x at the front's rows, sweep, scatter the pivots. Fronts solved side by side
// write disjoint entries and every sum has a fixed order, so the solve is deterministic.
// The planner (solve_plan.hpp) decides which fronts take which path.
#pragma once

#include <cuda_runtime.h>

#include <cstdint>

#include "numeric/cuda/solve_plan.hpp"
#include "numeric/cuda/trsv_tiles.cuh"

namespace strata::cuda {

/// Chunks of the gather/scatter launches: chunk c is rows [chunk_row[c], +kChunkRows) of
/// front chunk_front[c] (device arrays of SolvePlan).
struct SolveChunks {
  const std::int64_t* front;
  const std::int64_t* row;
};

/// Forward gather of chunks [begin, begin+count). x: n×nrhs (column-major); u:
/// u_total×nrhs; scratch: Σ rows × nrhs (front f's block at row_offsets[f]·nrhs).
void launch_gather_forward(const SolveTree& t, SolveChunks c, std::int64_t begin,
                           std::int64_t count, const double* x, const double* u, double* scratch,
                           std::int64_t nrhs, cudaStream_t s);

/// Forward scatter of chunks [begin, begin+count): pivots to x (LU: at the column
/// positions), the other rows to the fronts' update vectors in u (a tall front's less its
/// L21 rows times the solved pivots).
void launch_scatter_forward(const SolveTree& t, SolveChunks c, std::int64_t begin,
                            std::int64_t count, double* x, double* u, const double* scratch,
                            std::int64_t nrhs, bool lu, cudaStream_t s);

/// Forward sweep of the gathered fronts fronts[begin..begin+count) (device array), one block
/// each: a tall front's triangle only (its scatter does L21). `unit`: L11 has a unit
/// diagonal (LDLᵀ, LU).
void launch_sweep_forward(const SolveTree& t, const std::int64_t* fronts, std::int64_t begin,
                          std::int64_t count, double* scratch, std::int64_t nrhs, bool unit,
                          cudaStream_t s);

/// Backward sweep of the gathered fronts fronts[begin..begin+count), one block each (a tall
/// front: its chunks' partial products summed, then its triangle).
void launch_sweep_backward(const SolveTree& t, const std::int64_t* fronts, std::int64_t begin,
                           std::int64_t count, double* scratch, std::int64_t nrhs, bool lu,
                           bool unit, cudaStream_t s);

/// Forward solve (gather, sweep, scatter) by `count` blocks: block q solves the fronts
/// first[begin+q] .. last[begin+q] (device arrays) in that order. `unit`: L11 has a unit
/// diagonal (LDLᵀ, LU); `lu`: pivots go to x at their column positions.
void launch_fronts_forward(const SolveTree& t, const std::int64_t* first, const std::int64_t* last,
                           std::int64_t begin, std::int64_t count, double* x, double* u,
                           double* scratch, std::int64_t nrhs, bool unit, bool lu, cudaStream_t s);

/// Backward solve by `count` blocks: block q solves the fronts last[begin+q] down to
/// first[begin+q].
void launch_fronts_backward(const SolveTree& t, const std::int64_t* first, const std::int64_t* last,
                            std::int64_t begin, std::int64_t count, double* x, double* scratch,
                            std::int64_t nrhs, bool lu, bool unit, cudaStream_t s);

/// The chain's forward solve in one launch of c.items blocks: each block takes the next
/// item from the ticket, waits (on the device) until its children have signalled, solves
/// the item's fronts in order as launch_fronts_forward's blocks do, and signals the parent
/// (release and acquire at device scope: the parent reads what its children wrote). The
/// same arithmetic in the same order as the subtrees' and levels' launches: the same bits.
void launch_chain_forward(const SolveTree& t, const SolveChain& c, double* x, double* u,
                          double* scratch, std::int64_t nrhs, bool unit, bool lu, cudaStream_t s);

/// The chain's backward solve: the items in the reverse order, each waiting until its
/// parent's backward step has ended, its fronts from last to first.
void launch_chain_backward(const SolveTree& t, const SolveChain& c, double* x, double* scratch,
                           std::int64_t nrhs, bool lu, bool unit, cudaStream_t s);

/// x ← D⁻¹ x for LDLᵀ (1×1 and 2×2 blocks by pivot position).
void launch_solve_diagonal(const SolveTree& t, const double* d_diag, const double* d_off,
                           const int* pivot_size, double* x, std::int64_t nrhs, cudaStream_t s);

/// Backward gather of chunks [begin, begin+count): W = x at the fronts' rows, and a tall
/// front's chunk's partial product (solve_device::backward_partials) into t.part.
void launch_gather_backward(const SolveTree& t, SolveChunks c, std::int64_t begin,
                            std::int64_t count, const double* x, double* scratch, std::int64_t nrhs,
                            bool lu, cudaStream_t s);

/// Backward scatter of chunks [begin, begin+count): the fronts' pivots to x.
void launch_scatter_backward(const SolveTree& t, SolveChunks c, std::int64_t begin,
                             std::int64_t count, double* x, const double* scratch,
                             std::int64_t nrhs, bool lu, cudaStream_t s);

/// y ← y + alpha·A·x for A rows × cols, column-major with leading dimension lda (device
/// pointers; x of cols entries, y of rows, not overlapping): a block per 4, 8, 16 or 32 rows
/// (as many as leave a block per SM of the current device), each row's columns split over
/// the block's threads and summed in a fixed order (deterministic for a given device).
/// For the products of a library-path front (L21·x forward, U12·x backward), which are
/// too small for a library GEMV to spread over the device. Nothing for rows or cols ≤ 0.
void launch_gemv_n(std::int64_t rows, std::int64_t cols, double alpha, const double* a,
                   std::int64_t lda, const double* x, double* y, cudaStream_t s);

/// The inverses of op(A)'s diagonal tiles for `count` jobs (trsv_tiles.cuh: TrsvTileJob,
/// device array), op(A) of `form` with a unit diagonal when `unit`, A's entries at
/// panels + job.panel, the inverses at inverses + job.out. Nothing for count ≤ 0.
void launch_trsv_inverses(const trsv_tiles::TrsvTileJob* jobs, std::int64_t count,
                          const double* panels, double* inverses, trsv_tiles::TrsvForm form,
                          bool unit, cudaStream_t s);

/// x ← op(A)⁻¹ x for the n × n triangle of A (column-major, leading dimension lda, device
/// pointers) by tiles of trsv_tiles::kTrsvTile unknowns (trsv_tiles.cuh), `inv` the tiles'
/// inverses from launch_trsv_inverses and `sync` ⌈n/kTrsvTile⌉ flags, a ticket and a
/// counter, zero before and after. Nothing for n ≤ 0.
void launch_trsv_tiles(trsv_tiles::TrsvForm form, std::int64_t n, const double* a, std::int64_t lda,
                       double* x, const double* inv, trsv_tiles::TrsvSync sync, cudaStream_t s);

/// The checks of a solve from GPU arrays, made as the entries pass through
/// launch_permute_in (the right-hand sides) or launch_permute_out (the solutions), both in
/// device memory: *bad ← max(*bad, ~e) for every entry e (its index in the column-major
/// array in the original numbering) that is not finite, and *max_bits ← max(*max_bits,
/// the bits of every finite magnitude; the bits of a non-negative double order as its
/// value). The caller zeroes both first: *bad is then the complement of the least such
/// index, 0 when every entry is finite. The result does not depend on timing. Null `bad`:
/// no check.
struct EntryCheck {
  unsigned long long* bad = nullptr;
  unsigned long long* max_bits = nullptr;
};

/// The right-hand sides into the factor's numbering and scaling, for n unknowns and nrhs
/// columns (column-major): to[k + r·n] = scaled(from[index[k] + r·n], scale[k],
/// rescale[index[k]]) (rescale null: 1), scaled(v, d, e) = v·(d·e) when d·e is a normal
/// number, else v·d·e — the host's arithmetic (core/solve_phase.cpp), so the same bits.
/// `check`: from's entries checked (EntryCheck).
void launch_permute_in(const double* from, const std::int64_t* index, const double* scale,
                       const double* rescale, double* to, std::int64_t n, std::int64_t nrhs,
                       cudaStream_t s, EntryCheck check = {});

/// The solutions back: to[index[k] + r·n] = scaled(from[k + r·n], scale[k], rescale[index[k]]).
/// Nothing when `unless` (device memory) is given and is not zero (the right-hand sides'
/// EntryCheck found an entry that is not finite). `check`: to's entries checked.
void launch_permute_out(const double* from, const std::int64_t* index, const double* scale,
                        const double* rescale, double* to, std::int64_t n, std::int64_t nrhs,
                        cudaStream_t s, const unsigned long long* unless = nullptr,
                        EntryCheck check = {});

}  // namespace strata::cuda
