// strata — CUDA kernels of the level-batched multifrontal factorization.
//
// A batch's fronts live in one device pool: the front at batch position p starts at
// pool + pos_offset[p] and is n_rows×n_rows, column-major (leading dimension n_rows).
// Every kernel here is launched once per batch with one thread block per front — the
// fronts of a level are independent, so one launch covers them all (DESIGN.md §2).
#pragma once

#include <cuda_runtime.h>

#include <cstddef>
#include <cstdint>
#include <vector>

namespace strata::cuda {

/// Device copies of the analysis arrays the kernels read (all int64 unless noted).
struct DeviceTree {
  const std::int64_t* fronts;         ///< schedule.fronts (position -> front)
  const std::int64_t* pos_offset;     ///< position -> offset of its front in the pool
  const std::int64_t* n_rows;         ///< per front
  const std::int64_t* n_pivots;       ///< per front
  const std::int64_t* parent;         ///< per front
  const std::int64_t* entry_offsets;  ///< assembly map
  const std::int64_t* entry_src;
  const std::int64_t* entry_dst;
  const std::int64_t* child_offsets;
  const std::int64_t* children;
  double* const* cb_ptr;            ///< per front: where its contribution block lives
                                    ///< (device memory, or mapped pinned host memory when
                                    ///< the device budget is short; null: no block)
  const std::int64_t* rel_offsets;  ///< per child: its CB rows' positions in the parent
  const std::int64_t* rel;
  /// Per front, for the small-front LU kernels: bit q set when panel q (pivot columns
  /// [8q, 8q + 8)) interchanged rows in the front's last factorization, so that the next
  /// one searches that panel's pivots straight away instead of trying its diagonal first
  /// (zero: every panel tries its diagonal first). Either way the same factor results.
  std::uint32_t* lu_interchanges;
};

/// Zeroes the batch's fronts, scatters the original entries and extend-adds the
/// children's contribution blocks (lower triangle only when `symmetric`). `pool` may be
/// mapped pinned host memory (a front factored tile by tile).
/// `max_rows`: the most rows of a front in the launch (sizes the grid of column slices).
void launch_assemble(const DeviceTree& t, std::int64_t begin, std::int64_t count,
                     std::int64_t max_rows, const double* values, double* pool, bool symmetric,
                     cudaStream_t s);

/// Copies each front's contribution block F[k:m, k:m] to t.cb_ptr[f] (fronts with a
/// parent only).
void launch_store_cb(const DeviceTree& t, std::int64_t begin, std::int64_t count,
                     std::int64_t max_rows, const double* pool, bool symmetric, cudaStream_t s);

/// Packs each front's factor panel (its first k columns, m×k, contiguous in the front)
/// and, for LU, its U12 block (k×(m−k), leading dimension k) into `staging` at
/// staging_offset[position − begin], so the batch comes back in one copy.
void launch_pack_panels(const DeviceTree& t, std::int64_t begin, std::int64_t count,
                        std::int64_t max_rows, const double* pool,
                        const std::int64_t* staging_offset, double* staging, bool lu,
                        cudaStream_t s);

/// Partial factorization of small fronts, one block each, in place in the pool.
/// `positions` lists batch positions (device array of `count`); max_rows is the most rows
/// of a listed front (it sizes the blocks). Per listed front i: info[i] = local index of a
/// failed Cholesky pivot or -1; perturbed[i] = static pivots; perm (LU) receives the local
/// row permutation at perm + first_pivot offsets given by perm_offset[i]. LU pivots by
/// the CPU's rule (numeric/cpu/dense_front.hpp, factor_front_lu) with u = `threshold`.
/// Blocks have a thread per row of the largest front (rounded up to a power of two); a
/// launch of few fronts gets wider ones, up to `max_threads` (Options::
/// gpu_small_front_threads; 0: never wider), the same results bit for bit. A launch whose
/// fronts fit the device's shared memory per block (max_rows ≤ lu_shared_max_rows() for
/// LU, llt_fused_max_rows() for Cholesky, whose lower triangle is copied there packed)
/// factors a copy of each front there.
void launch_factor_small(const DeviceTree& t, const std::int64_t* positions, std::int64_t count,
                         std::int64_t max_rows, double* pool, bool lu, double static_pivot,
                         double threshold, std::int64_t* info, std::int64_t* perturbed,
                         std::int64_t* perm, const std::int64_t* perm_offset, int max_threads,
                         cudaStream_t s);

/// A launch group of small LU (lu) or Cholesky fronts, all of them, by one launch, each
/// front by one block in shared memory (max_rows ≤ lu_shared_max_rows() for LU,
/// llt_fused_max_rows() for Cholesky): the front assembled there as launch_assemble
/// assembles it (zeroed, the original entries of `values`, each child's contribution block
/// in child order: the same bits), factored as launch_factor_small factors it, its panel
/// (m×k, leading dimension m) and for LU U12 (k×(m−k), leading dimension k) written to
/// panels + panel_offset[i], its contribution block (Cholesky: the lower triangle, as
/// launch_store_cb) to t.cb_ptr[f] (fronts with a parent) and its k pivots' diagonal
/// entries to diag + diag_offset[i]; the pool is not touched. `positions` lists the
/// group's batch positions (device array of `count`); info, perturbed, perm and
/// perm_offset as launch_factor_small's, per listed front (Cholesky: info only, perturbed
/// set to 0). Blocks as launch_factor_small's for max_threads.
void launch_small_fused(const DeviceTree& t, bool lu, const std::int64_t* positions,
                        std::int64_t count, std::int64_t max_rows, const double* values,
                        double static_pivot, double threshold, std::int64_t* info,
                        std::int64_t* perturbed, std::int64_t* perm,
                        const std::int64_t* perm_offset, const std::int64_t* panel_offset,
                        double* panels, const std::int64_t* diag_offset, double* diag,
                        int max_threads, cudaStream_t s);

/// The most rows of a front the shared-memory LU kernels (launch_factor_small's for LU,
/// launch_small_fused's) take on the current device (0 when none fits).
std::int64_t lu_shared_max_rows();

/// The most rows of a front launch_small_fused takes for Cholesky on the current device
/// (its front's lower triangle, packed, shares the room with llt_front_blocked's panel
/// buffer; 0 when none fits).
std::int64_t llt_fused_max_rows();

/// The shared-memory LU kernels' own (static) shared memory per block on the current
/// device, bytes.
std::size_t lu_shared_static_bytes();

/// The threads per block launch_factor_small and launch_small_fused give `count` fronts
/// of at most max_rows rows on the current device (a power of two from 32 to 512), for
/// fronts copied into shared_bytes of dynamic shared memory per block (0: none).
unsigned small_front_threads(std::int64_t count, std::int64_t max_rows, int max_threads,
                             std::size_t shared_bytes = 0);

/// Doubles of workspace launch_llt_panel needs for `count` fronts (64×64 each).
std::size_t llt_panel_work_size(std::int64_t count);

/// The pivot block and the panel of large LLᵀ fronts (any k; the executor sends those with
/// k ≤ Options::gpu_panel_kernel_max_pivots), all fronts of
/// the list together, three launches per 64 pivot columns (kernels_panel.cu): for item i,
/// batch position items[2i] (its m×m front in the pool, leading dimension m) gets L11
/// (lower triangle of its k×k block) and L21 = A21·L11⁻ᵀ in place, and info[items[2i + 1]]
/// = 0, or j + 1 for the first non-positive pivot j (cuSOLVER's convention; the front is
/// then left partly factored, to be reported as failed). `rows[i]`, `pivots[i]`: m and k of
/// item i (host copies), sorted by pivots, largest first. `work`: llt_panel_work_size(count)
/// doubles. The contribution-block update is the caller's. Throws CudaError if a launch
/// fails.
void launch_llt_panel(const DeviceTree& t, const std::int64_t* items,
                      const std::vector<std::int64_t>& rows,
                      const std::vector<std::int64_t>& pivots, double* pool, double* work,
                      int* info, cudaStream_t s);

/// A large LU front, or the part of one from its pivot b0 on, for launch_lu_panel_batched:
/// F (device) points at entry (b0, b0) of the front, whose leading dimension is ld; the
/// part has m rows and columns, its first k are the pivots to eliminate now (a strip), and
/// its first kc ≥ k rows are fully summed (the rows whose multipliers the check covers).
/// perm (device, k entries) non-null: a whole front with k = kc ≤ 64 (one step) whose rows
/// the kernels interchange by restricted threshold partial pivoting, recording its local row
/// permutation there (perm[i] = the local row now in position i).
struct LuPanelItem {
  double* F;
  std::int64_t ld, m, k, kc;
  std::int64_t* perm;
};

/// Doubles of workspace launch_lu_panel_batched needs for `count` fronts (two pairs of
/// 64×64 inverses each: a step's and the next's).
std::size_t lu_panel_work_size(std::int64_t count);

/// A side stream and two events (no timing) for launch_lu_panel_batched's look-ahead: the
/// next step's pivot block on `stream` while the current step's panels and update go on.
struct LuLookahead {
  cudaStream_t stream = nullptr;
  cudaEvent_t ready = nullptr, done = nullptr;
};

/// The pivot block, L panel and U panel of large LU fronts without row interchanges, all
/// fronts of the list together, three launches per 64 pivot columns on stream s
/// (kernels_lu_panel.cu): item i (items: device array, sorted by k, largest first; `rows`,
/// `pivots`: host copies of its m and k) gets L11 (unit lower, implicit diagonal) and U11
/// in its k × k block, L21 = A21·U11⁻¹ below it (all m rows) and U12 = L11⁻¹·A12 right of it
/// (all m columns); A22 is left for the caller's update A22 −= L21·U12. bad[i] (device,
/// zeroed by the caller) is set to 1, and the item left partly factored, when restricted
/// threshold partial pivoting with u = `threshold` (factor_front_lu's rule) would
/// interchange rows (a multiplier |L(r, j)| > 1/u in a fully summed row r < kc) or a pivot
/// is not finite or below `static_pivot` in magnitude; an item whose
/// bad[i] is already set is left alone. An item with a perm (see LuPanelItem) is factored
/// with the interchanges instead — P·A11 = L11·U11, U12 = L11⁻¹·P·A12, rows k.. not moved,
/// as the CPU's factor_front_lu — and is bad only for a pivot that needs static pivoting. `work`:
/// lu_panel_work_size(count) doubles. With `ahead`, each step's first panel tiles and
/// trailing diagonal tile go first and the next step's pivot block then runs on
/// ahead->stream beside the rest of the step (a look-ahead of one step, Kurzak & Dongarra,
/// "Implementing linear algebra routines on multi-core processors with pipelining and a
/// look ahead", 2006); every entry takes the same operations in the same order, so the
/// factor is the same bit for bit, and s waits for the side stream before each next step's
/// panels and at the end. Throws DeviceError if a launch fails.
void launch_lu_panel_batched(const LuPanelItem* items, const std::vector<std::int64_t>& rows,
                             const std::vector<std::int64_t>& pivots, double* work, int* bad,
                             double static_pivot, double threshold, cudaStream_t s,
                             const LuLookahead* ahead = nullptr);

/// Fronts whose contribution block has at most this many rows and columns get their update
/// from launch_lu_cb_update_batched in enqueue_lu_strips; larger ones one cuBLAS GEMM each.
constexpr std::int64_t kLuBatchedCbMaxRows = 512;

/// The contribution blocks of large LU fronts once their pivots are eliminated, A22 −=
/// L21·U12, all fronts of the list in one launch on stream s (kernels_lu_panel.cu): items
/// (device) with F at the front's entry (0, 0), leading dimension ld, m rows and columns and
/// k pivots (kc and perm unused); one block per 64×64 tile of A22 (grid-stride over the
/// tiles), the products on the FP64 tensor cores over the whole inner dimension k.
/// max_tiles: the most A22 tiles of any item, ⌈(m − k)/64⌉². Nothing for count ≤ 0. Throws
/// DeviceError if the launch fails.
void launch_lu_cb_update_batched(const LuPanelItem* items, std::int64_t count,
                                 std::int64_t max_tiles, cudaStream_t s);

/// One LU panel of a large front: columns p0..p0+w-1 of the m×m front F (fully summed
/// rows 0..k-1), with row interchanges among rows p0..k-1 (threshold partial pivoting with
/// u = `threshold`, factor_front_lu's rule) applied to whole rows, static pivoting, and the
/// update restricted to the panel's columns. One block.
void launch_lu_panel(double* f, std::int64_t m, std::int64_t k, std::int64_t p0, std::int64_t w,
                     double static_pivot, double threshold, std::int64_t* perm,
                     std::int64_t* perturbed, cudaStream_t s);

/// The most columns (at most 64) a panel of `rows` fully summed rows may have for
/// launch_lu_tall_panel on the current device; 0 when not even one column fits.
std::int64_t lu_tall_panel_columns(std::int64_t rows);

/// One LU panel of a large front by one block in shared memory: columns p0..p0+w-1
/// (w ≤ 64) of the m×m front F (leading dimension m), only its fully summed rows
/// p0..k-1 — the pivots and multipliers by threshold partial pivoting (u = `threshold`,
/// factor_front_lu's rule) and static pivoting as launch_lu_panel, the update within the
/// panel, the interchanges applied to whole rows and to perm (k entries), static pivots
/// added to *perturbed. Rows k..m-1 of the panel are left for the caller (their
/// multipliers: a TRSM with the panel's U block). Returns false, launching nothing, when the
/// panel's (k − p0) × w entries do not fit the device's shared memory. Throws
/// InternalError for a panel outside the front.
bool launch_lu_tall_panel(double* f, std::int64_t m, std::int64_t k, std::int64_t p0,
                          std::int64_t w, double static_pivot, double threshold, std::int64_t* perm,
                          std::int64_t* perturbed, cudaStream_t s);

/// LU of a column slab S (r×w, leading dimension r) that alone is on the device: the
/// columns p0..p0+w of a front factored tile by tile, rows p0..m. Pivot candidates for
/// slab column j are slab rows [j, kk) (kk = k − p0: the fully summed rows), chosen with
/// threshold u = `threshold` as launch_lu_panel; row swaps
/// move the slab's w columns only and are recorded in perm (slab rows 0..kk, initialized
/// by the caller) for the caller to apply to the front's other columns.
void launch_lu_slab(double* s_, std::int64_t r, std::int64_t w, std::int64_t kk,
                    double static_pivot, double threshold, std::int64_t* perm,
                    std::int64_t* perturbed, cudaStream_t s);

/// Large-front LU glue (kernels_lu.cu). After cuSOLVER GETRF of the k×k block A11 (column-
/// major, leading dimension ld): *bad = 1 when *getrf_info ≠ 0 or a pivot |A11(j,j)| is
/// below static_pivot or not finite (the front then goes to the panel-kernel path), else 0.
void launch_lu_check(const double* a, std::int64_t ld, std::int64_t k, double static_pivot,
                     const int* getrf_info, int* bad, cudaStream_t s);

/// After cuSOLVER GETRF without pivoting of the k×k block A11 (leading dimension ld):
/// *bad = 1 when *getrf_info ≠ 0, a pivot |U(j,j)| is below static_pivot or not finite,
/// or a multiplier |L(i,j)| (i > j) is above 1/threshold or not finite — that is, unless
/// threshold partial pivoting among these k rows (factor_front_lu's rule) would have
/// interchanged no row — else 0; ipiv[j] = j + 1 (no interchange, 1-based as GETRF's).
void launch_lu_unpivoted_check(const double* a, std::int64_t ld, std::int64_t k,
                               double static_pivot, double threshold, const int* getrf_info,
                               int* ipiv, int* bad, cudaStream_t s);

/// The row permutation of GETRF's interchanges: perm[i] = the local row (0-based) that
/// ended in position i, for ipiv (1-based, LAPACK) of length k. One thread.
void launch_ipiv_to_perm(const int* ipiv, std::int64_t k, std::int64_t* perm, cudaStream_t s);

/// perm[0..k) = 0, 1, …, k−1: the permutation of a front whose pivots needed no
/// interchange (what launch_ipiv_to_perm makes of an identity ipiv, without its serial loop).
void launch_identity_perm(std::int64_t k, std::int64_t* perm, cudaStream_t s);

/// Segment copies on the device: for i < count, dst[seg[3i] + j] = src[seg[3i + 2] + j] for
/// j < seg[3i + 1] (seg, src, dst: device arrays; one block per segment).
void launch_scatter_segments(const std::int64_t* seg, std::int64_t count, const std::int64_t* src,
                             std::int64_t* dst, cudaStream_t s);

/// The same for `count` fronts at once: perm[offset[i] + j] = j for j < offset[i + 1] −
/// offset[i] (offset: device array of count + 1).
void launch_identity_perms(const std::int64_t* offset, std::int64_t count, std::int64_t* perm,
                           cudaStream_t s);

/// Applies the interchanges ipiv[0..k) (1-based, in order) to the rows of the ncols
/// columns of a (leading dimension ld), as LAPACK's DLASWP with increment 1.
void launch_laswp(double* a, std::int64_t ld, std::int64_t ncols, const int* ipiv, std::int64_t k,
                  cudaStream_t s);

/// For fronts at positions begin..begin+count of t: diag[diag_offset[i] + j] = the j-th
/// diagonal entry (j < k) of the front's packed panel at panels + panel_offset[i].
void launch_gather_diagonals(const DeviceTree& t, std::int64_t begin, std::int64_t count,
                             const std::int64_t* panel_offset, const double* panels,
                             const std::int64_t* diag_offset, double* diag, cudaStream_t s);

/// Up to six device arrays packed back to back into one of int64 words
/// (launch_pack_results): segment q is src[q][0, end[q] − end[q−1]) (end[−1] = 0), of
/// std::int64_t (kind 0), int (kind 1, widened) or double (kind 2, its bits). Unused
/// segments are empty (end[q] = end[q−1]).
struct ResultSegments {
  const void* src[6] = {};
  std::int64_t end[6] = {};
  int kind[6] = {};
};

/// out[0, seg.end[5]) ← the segments of `seg` back to back, so that a chunk's results
/// (pivot checks, permutations, diagonals) come back in one copy.
void launch_pack_results(const ResultSegments& seg, std::int64_t* out, cudaStream_t s);

}  // namespace strata::cuda
