// strata — the CUDA executor's class (internal to src/numeric/cuda; nothing CUDA is in a
// public header). The implementation is split by concern:
//   cuda_executor.cu  life cycle: set-up, parts, contribution-block export and import,
//                     the end of a factorization, statistics;
//   device_plan.cu    the device memory plan and the per-analysis uploads;
//   factor_chunk.cu   in-core batches chunk by chunk, and the host bookkeeping of a chunk;
//   lu_fronts.cu      LU's large fronts (strips, library calls, pivoted redo);
//   device_query.cu   GPUs visible, host memory pinning, the executor's factory;
//   tiled_front.cu    fronts larger than the device budget, factored slab by slab;
//   tiled_llt.cu      a Cholesky front larger than the budget, streamed through in pieces;
//   tiled_host.cpp    their assembly on the host's threads;
//   cuda_solve.cu     triangular solves on the device with a resident factor;
//   split_update.cu   a large front's update split over idle GPUs (several GPUs);
//   distributed_front.cu  a large Cholesky front's columns over a team of GPUs.
#pragma once

#include <cstdint>
#include <functional>
#include <future>
#include <map>
#include <memory>
#include <vector>

#include "numeric/cuda/cuda_check.hpp"
#include "numeric/cuda/device_buffer.hpp"
#include "numeric/cuda/kernels.cuh"
#include "numeric/cuda/kernels_ldlt.cuh"
#include "numeric/cuda/solve_plan.hpp"
#include "numeric/factor.hpp"

namespace strata::cuda {

struct EventPair;  // tiled_llt.cu
struct TeamGpu;    // distributed_front.cu

// the most rows of a front factored by one thread block (Options::gpu_small_front_rows at
// most): the kernels' block size
inline constexpr std::int64_t kSmallFront = 256;
inline constexpr std::int64_t kMinSlab = 16;  // narrowest slab worth a library call
// Streams for the large fronts of one chunk. The fronts of a level below the top few are
// many and medium-sized (hundreds to a few thousand rows): one after another on one
// stream, each library call leaves most of the GPU idle. Eight lanes fill it without
// many handles (each cuBLAS handle holds its own workspace).
inline constexpr std::size_t kLanes = 8;

/// Where the executor put things on the device for the current analysis (see
/// CudaExecutor::plan_device_memory).
struct DevicePlan {
  std::size_t budget = 0;        ///< bytes the numeric working memory may use
  std::size_t pool = 0;          ///< doubles: fronts of one in-core chunk
  std::size_t arena_device = 0;  ///< doubles of the CB arena kept on the device
  bool arena_on_host = false;    ///< some contribution blocks live in pinned host memory
  bool factor_resident = false;  ///< the whole factor stays on the device (GPU solve)
  std::int64_t slab = 0;         ///< slab width for fronts factored tile by tile
  /// doubles: the panels of the largest chunk, staged on the device on their way to the
  /// host factor (when the factor does not stay there); part of the budget
  std::size_t staging = 1;
  /// doubles: where the host arena of spilled contribution blocks starts in the arena
  /// layout (blocks at or after it that do not fit arena_device live there)
  std::size_t host_arena_base = 0;
  std::size_t host_pinned = 0;  ///< bytes of page-locked host memory the plan holds
};

/// How one chunk's fronts are split and where their pivots, diagonals and panels go, the
/// same at every factorization of a plan: the small fronts (one thread block each) and the
/// large ones as chunk positions, the pivot permutations' offsets (small fronts first, then
/// the large ones), each front's first diagonal slot and the panels' size. The device copies of
/// `small`, `perm_off`, each position's panel offset and `diag_off` sit in PartDevice::layout at
/// `device_at`; `key` is what they depend on besides the plan (CudaExecutor::chunk_layout).
struct ChunkLayout {
  std::vector<std::int64_t> small, big, perm_off, big_perm_at, diag_off;
  std::int64_t perm_total = 0;
  std::size_t panels_total = 0;
  std::size_t device_at = 0;
  int key = -1;  ///< −1: not made yet
};

/// What the executor keeps on the device for one part of the tree (the whole tree, or a
/// subtree / the top part of a multi-GPU split): the part's schedule, where each of its
/// fronts sits in the pool, how its batches are cut into chunks, where each contribution
/// block it reads or writes lives, and the kernels' view of all that.
struct PartDevice {
  DeviceBuffer<std::int64_t> fronts, pos_offset;
  DeviceBuffer<double*> cb_ptr;
  std::vector<std::int64_t> pos_offset_host;  ///< offset in the pool (current chunk)
  std::vector<char> tiled;                    ///< per position: factored tile by tile
  std::vector<index_t> chunk_end;             ///< per position starting a chunk: its end
  std::vector<index_t> fronts_host;           ///< the part's schedule order
  /// Per position: where the front's panel sits in the part's own panel buffer (a part
  /// of a multi-GPU split whose panels stay on this device), and that buffer's size.
  std::vector<std::int64_t> panel_off_host;
  std::size_t panel_total = 0;
  std::vector<double*> cb_ptr_host;  ///< per front: where its block lives
  DeviceTree tree{};
  /// Per position starting a chunk: the chunk's layout (CudaExecutor::chunk_layout), made
  /// by the chunk's first factorization and reused by the plan's later ones.
  std::vector<ChunkLayout> layouts;
  /// Every chunk's device index arrays, the chunk starting at position q at 6q
  /// (ChunkLayout::device_at): uploaded once, not at each factorization.
  DeviceBuffer<std::int64_t> layout;
};

/// A stream with its own library handles and workspaces, on which the large fronts of a
/// chunk run side by side (a front's calls all go to one lane; lanes are joined before
/// the chunk's stores). Lane 0 is the executor's main stream.
struct Lane {
  cudaStream_t stream = nullptr;
  cublasHandle_t blas = nullptr;
  cusolverDnHandle_t solver = nullptr;
  cudaEvent_t done = nullptr;
  bool owned = false;  ///< created for this lane (lane 0 borrows the executor's)
  DeviceBuffer<double> potrf_work, getrf_work;
  DeviceBuffer<int> block_info;    ///< llt_pivot_block_and_panel: one status per column block
  DeviceBuffer<double> diag_work;  ///< llt_pivot_block_and_panel_recursive: L_jj slots
  double load = 0;                 ///< flops given to it in the current chunk
};

/// Copies rows [r0, r0+rows) of columns [c0, c0+cols) of the column-major host matrix h
/// (leading dimension ldh; pinned for the copy to be asynchronous) to the device matrix d
/// (leading dimension rows), or back, enqueued on s (tiled_front.cu).
void copy_host_block(cudaStream_t s, double* d, const double* h, std::int64_t ldh, std::int64_t r0,
                     std::int64_t c0, std::int64_t rows, std::int64_t cols, bool to_device);

/// Grows `work` to cuSOLVER's workspace for a POTRF of order k, leading dimension ld.
void grow_potrf_work(cusolverDnHandle_t h, DeviceBuffer<double>& work, double* a, int k, int ld);

/// Cholesky pivot block and panel of front F (m × m, column-major, lower triangle, on the
/// device) with k pivots, enqueued on `ln`: F₁₁ ← L₁₁ = chol(F₁₁), F₂₁ ← F₂₁ L₁₁⁻ᵀ; the
/// contribution block is left alone. nb > 0 and nb < k: in column blocks of nb
/// (llt_blocked.cu); else one cuSOLVER POTRF and one cuBLAS TRSM. `info` (device) gets
/// what POTRF of order k reports: 0, or i > 0 when the leading minor of order i is not
/// positive definite. Uses ln.potrf_work and ln.block_info (grown if short).
void llt_pivot_block_and_panel(Lane& ln, double* F, int m, int k, int nb, int* info);

/// The same pivot block and panel by recursion on the pivot columns (llt_recursive.cu:
/// 64-column base cases of our own, the rest cuBLAS GEMMs), enqueued on `ln`; F is
/// m × m with leading dimension m, k ≥ 0 pivots; `info` as above. The strict upper
/// triangle of the k × k pivot block is left zero (it is scratch meanwhile). Uses
/// ln.diag_work (llt_recursive_work_size(k) doubles, grown if short).
void llt_pivot_block_and_panel_recursive(Lane& ln, double* F, std::int64_t m, std::int64_t k,
                                         int* info);

/// The same for a panel P of `rows` rows and k ≤ rows columns with leading dimension
/// ld ≥ rows (its first k rows the pivot block): a column block of a front distributed
/// over GPUs (distributed_front.cu).
void llt_pivot_block_and_panel_recursive(Lane& ln, double* P, std::int64_t ld, std::int64_t rows,
                                         std::int64_t k, int* info);

/// Doubles of workspace llt_pivot_block_and_panel_recursive needs for k pivots.
std::size_t llt_recursive_work_size(std::int64_t k);

/// The contribution-block update of a Cholesky front, C −= L·Lᵀ on the lower triangle of
/// the n × n block C (leading dimension ldc) from the n × k block L (leading dimension
/// ld), enqueued on `blas`'s stream: cuBLAS DSYRK, or one DGEMM of the whole square
/// where llt_update_by_gemm(n, k) (llt_update.cu says why; the GEMM also writes C's
/// strict upper triangle). Nothing for n or k ≤ 0.
void llt_update(cublasHandle_t blas, std::int64_t n, std::int64_t k, const double* L,
                std::int64_t ld, double* C, std::int64_t ldc);

/// Whether llt_update takes the DGEMM for this shape (measured rule, llt_update.cu).
bool llt_update_by_gemm(std::int64_t n, std::int64_t k);

/// The contribution-block update of front i of enqueue_lu_strips, enqueued on the lane given.
using LuFinalUpdate = std::function<void(std::size_t i, Lane&)>;

/// The elimination without row interchanges of large LU fronts by strips of nb pivot
/// columns (lu_fronts.cu): `fronts` (F, leading dimension ld = m, m, k, kc = k, perm; sorted
/// by k, largest first) get L11\U11, L21 and U12 in place — those of one step and one strip
/// (k ≤ 64, k ≤ nb) with restricted threshold partial pivoting (u = pivots.threshold),
/// their permutations in their perm — the
/// strips' pivot blocks and panels by launch_lu_panel_batched on lanes[0] for all fronts with
/// pivots left in the strip, the rest of each strip's update of the pivot rows and columns by two
/// cuBLAS GEMMs per front on the other lanes (lanes[0] waits for them before the next strip), and
/// after a front's last strip the update of its contribution block (A22 −= L21·U12) on a lane
/// (lane_of[i] says which): for the fronts ending in a strip whose block has at most
/// kLuBatchedCbMaxRows rows and that `may_batch(i)` allows, one launch_lu_cb_update_batched
/// for all of them (their items in `cb_items`, grown as needed), for the others
/// `final_update(i, lane)`, which must do that update. bad[i] (device) as
/// launch_lu_panel_batched's, zeroed here. `items` and `work` are grown as needed (Σ ⌈k/nb⌉
/// items; count fronts' inverses); `strip_done` is recorded on lanes[0] after each strip's
/// kernels, last after the last one's; `ahead` (may be null) the strips' look-ahead stream
/// and events (launch_lu_panel_batched). Everything is enqueued; nothing waits on the host.
/// Throws InvalidInput for nb < 1.
void enqueue_lu_strips(const std::vector<LuPanelItem>& fronts, std::int64_t nb,
                       const std::vector<Lane*>& lanes, DeviceBuffer<LuPanelItem>& items,
                       DeviceBuffer<LuPanelItem>& cb_items, DeviceBuffer<double>& work, int* bad,
                       const numeric::PivotPolicy& pivots, cudaEvent_t strip_done,
                       const LuLookahead* ahead, const std::function<bool(std::size_t)>& may_batch,
                       const LuFinalUpdate& final_update, std::vector<Lane*>& lane_of);

class CudaExecutor final : public numeric::Executor {
 public:
  /// `device`: CUDA device ordinal this executor runs on.
  explicit CudaExecutor(const Options& o, int device = 0);
  ~CudaExecutor() override;
  const char* name() const override { return "cuda"; }
  Backend backend() const override { return Backend::cuda; }
  int device() const override { return device_; }
  bool uses_host_arena() const override { return false; }
  numeric::TransferMemory transfer_memory() const override;
  void prepare(const Analysis& an, int workers) override;
  bool scale_values_on_device(const Analysis& an, const double* values,
                              const numeric::StageValues& stage, int max_sweeps, bool copy_input,
                              numeric::DeviceValueNorms& out) override;    // value_pass.cu
  bool download_scaled_values(const Analysis& an, double* host) override;  // value_pass.cu
  bool keep_device_input(const Analysis& an) override;                     // value_pass.cu
  bool download_device_input(const Analysis& an, double* host) override;   // value_pass.cu
  bool prepare_shared_value_pass(const Analysis& an) override;             // value_pass.cu
  const double* device_scaled_values(const Analysis& an) override;         // value_pass.cu
  bool reads_host_values() const override;
  void begin(const numeric::FactorContext& ctx) override;
  void begin_part(const numeric::FactorContext& ctx) override;
  void factor_batch(const numeric::FactorContext& ctx, const BatchInfo& b) override;
  std::size_t export_cb(const numeric::FactorContext& ctx, numeric::CbTransfer& t) override;
  std::size_t import_cb(const numeric::FactorContext& ctx, const numeric::CbTransfer& t) override;
  void end(const numeric::FactorContext& ctx) override;
  bool solve(const Analysis& an, const numeric::NumericFactor& fac, double* x,
             index_t nrhs) override;
  bool solve_original(const Analysis& an, const numeric::NumericFactor& fac, const double* b,
                      double* x, index_t nrhs, const numeric::RescaleView& rescale,
                      double* stage) override;  // cuda_solve.cu
  bool solve_gpu_arrays(const Analysis& an, const numeric::NumericFactor& fac, const double* b,
                        double* x, index_t nrhs, const numeric::RescaleView& rescale,
                        numeric::GpuArrayCheck* check) override;      // cuda_solve.cu
  void last_gpu_array_check(numeric::GpuArrayCheck& check) override;  // cuda_solve.cu
  double* refinement_workspace(std::size_t count) override;           // residual.cu
  bool residual(const Analysis& an, const numeric::MatrixValues& a, const double* b,
                const double* x, double* r, index_t nrhs,
                double* maxima) override;  // residual.cu
  void refinement_step(double* x, const double* d, double* kept, index_t n,
                       bool undo) override;  // residual.cu
  bool keeps_panels(const numeric::FactorContext& ctx) const override {
    return ctx.part->id == -1 ? device_only_ : part_device_only_;
  }
  void download_panels(const Analysis& an, int part, numeric::NumericFactor& fac) override;
  bool can_solve_held_parts(const Analysis& an, const numeric::NumericFactor& fac,
                            const std::vector<int>& parts) const override;  // part_solve.cu
  void solve_held_parts(const Analysis& an, const numeric::NumericFactor& fac,
                        const std::vector<int>& parts, bool forward, double* x, double* u,
                        index_t nrhs) override;  // part_solve.cu
  void end_part(const numeric::FactorContext& ctx) override;
  void report(FactorStats& fs) const override;
  void report_worker(DeviceStats& d) const override;

 private:
  void upload_analysis(const Analysis& an);
  /// The value pass's arrays for `an` (value_pass.cu): made and uploaded at prepare for a
  /// whole-tree analysis; without room for them the host's pass serves.
  void prepare_value_pass(const Analysis& an);
  void plan_parts(const Analysis& an, bool whole);
  void plan_device_memory(const Analysis& an, const std::vector<numeric::PartView>& views);
  void upload_part(const Analysis& an, const numeric::PartView& v);
  /// Grows the per-chunk buffers (device and pinned) to what the largest chunk of `views`
  /// needs, so that no factorization allocates (device_plan.cu says why).
  void presize_chunk_buffers(const Analysis& an, const std::vector<numeric::PartView>& views);
  /// The factor stays on the device only for a whole-tree factorization.
  bool keep_resident() const { return plan_.factor_resident && whole_; }
  /// A plan's sweep arrays on the device (SolvePlan less its extend-add map, which
  /// dsolve_ holds once per analysis) and where its fronts' panels sit: the whole tree's in
  /// panels_ at the factor layout's offsets, or a held part's in its part_panels_ buffer.
  /// For a part (part_solve.cu) also the rows and update vectors it exchanges with the
  /// other parts (part_exchange).
  struct SweepPlanDevice {
    SolvePlan plan;
    std::vector<std::int64_t> panel_offset_host;
    DeviceBuffer<std::int64_t> panel_offset, chunk_front, chunk_row, small_fronts, tall_fronts,
        subtree_first, subtree_last, part_offset;
    /// The chain's arrays (SolvePlan::chain_*) and synchronization words (SolveChain)
    DeviceBuffer<std::int64_t> chain_first, chain_last, chain_wait, chain_parent;
    mutable DeviceBuffer<unsigned long long> chain_sync;  // written by every solve
    PartExchange exchange;
    /// The library-path fronts' tiled triangular solves for one right-hand side
    /// (trsv_tiles.cuh; prepare_trsv_tiles): per front of the tree where its tiles'
    /// inverses start (−1: none, cuBLAS's TRSV) and its flags; the jobs that make the
    /// inverses, on the host until the first solve that uses them puts them and the
    /// buffers below on the device (trsv_flags flags; trsv_jobs_count once there); the
    /// forward and backward triangles' inverses (make_trsv_inverses, once per
    /// factorization: trsv_made is the factorization_count_ and trsv_type the type they
    /// were made for, 0 for none) and the flags (written by every solve, zero between
    /// launches).
    std::vector<std::int64_t> trsv_inverse_at, trsv_sync_at;
    std::vector<std::int64_t> trsv_jobs_host;  // 5 per job (trsv_tiles::TrsvTileJob)
    std::int64_t trsv_flags = 0;
    std::int64_t trsv_jobs_count = 0;
    DeviceBuffer<std::int64_t> trsv_jobs;
    DeviceBuffer<double> trsv_forward, trsv_backward;
    mutable DeviceBuffer<int> trsv_sync;
    std::uint64_t trsv_made = 0;
    MatrixType trsv_type = MatrixType::automatic;
  };
  /// The extend-add map of the device solve (plan_inverse_extend_add) on the device, once
  /// per analysis (cuda_solve.cu).
  void prepare_solve_inverse(const Analysis& an);
  void prepare_solve_plan(const Analysis& an);  // cuda_solve.cu
  /// solve_original's permutations and scale factors for `an`, once per analysis.
  void prepare_solve_io(const Analysis& an);  // cuda_solve.cu
  /// The factorization's rescaling to the device unless it is there already (cuda_solve.cu).
  void upload_rescale(const Analysis& an, const numeric::RescaleView& rescale);
  /// Whether `fac` is the factor resident here for `an` (solve, solve_original can run).
  bool solves_resident(const Analysis& an, const numeric::NumericFactor& fac) const;
  /// The solve's workspaces sized for nrhs and its sweeps enqueued on the stream over
  /// dsolve_.x (the recorded graph, or the launches one by one).
  void enqueue_resident_solve(const Analysis& an, const numeric::NumericFactor& fac,
                              index_t nrhs);  // cuda_solve.cu
  /// Uploads a plan's sweep arrays and panel offsets into sp (cuda_solve.cu).
  void upload_sweep_plan(SweepPlanDevice& sp);
  /// sp's tiled triangular solves (SweepPlanDevice::trsv_*) for the fronts of sp's plan
  /// that go through the library: where each front's tiles go, and their jobs on the host
  /// (cuda_solve.cu).
  void prepare_trsv_tiles(const Analysis& an, SweepPlanDevice& sp);
  /// The jobs and the tiles' buffers on the device, at the first solve that uses them:
  /// they are the solve's and can be done without, so the analysis's device set-up, whose
  /// allocations a factorization needs, does not make them; none where the device lacks
  /// the memory (those fronts keep cuBLAS's TRSV) (cuda_solve.cu).
  void allocate_trsv_tiles(SweepPlanDevice& sp);
  /// Enqueues on stream_ the inverses of sp's tiles for the factor of `type` at `panels`
  /// unless they were made for this factorization already (cuda_solve.cu).
  void make_trsv_inverses(SweepPlanDevice& sp, const double* panels, MatrixType type);
  /// Whether sp's tiled triangular solves can run for this factorization (their inverses
  /// made for it and `type`).
  bool trsv_current(const SweepPlanDevice& sp, MatrixType type) const {
    return sp.trsv_jobs_count > 0 && sp.trsv_made == factorization_count_ && sp.trsv_type == type;
  }
  /// The part solve's plan of part `id` of an.partition, made on first use per analysis
  /// (part_solve.cu).
  SweepPlanDevice& part_sweep_plan(const Analysis& an, int id);
  /// The subtree limit every part's plan takes (that of the whole tree's plan), once per
  /// analysis (part_solve.cu).
  void prepare_part_limit(const Analysis& an);
  /// What a solve of held parts (solve_held_parts) needs whatever parts this GPU holds,
  /// made at the analysis as for a whole-tree factor: the extend-add map, the row arrays
  /// of the analysis' order and the whole tree's workspaces for one right-hand side.
  /// Without room for them nothing is kept and the first solve tries again (part_solve.cu).
  void prepare_part_solve(const Analysis& an);
  /// The device solve's sweeps of one plan (everything between the upload of the
  /// right-hand sides into dsolve_.x and the download of the solutions): the forward
  /// sweep, the backward sweep or both, with the diagonal solve of an LDLᵀ factor between
  /// them when both; `panels` is where sp's panel offsets point. Enqueued on stream_
  /// (cuda_solve.cu). With `forward_subtrees` false the forward sweep leaves out its first
  /// launch, the plan's subtrees (or its chain), which the caller then enqueues before it
  /// (enqueue_forward_subtrees).
  void enqueue_solve_sweeps(const Analysis& an, const numeric::NumericFactor& fac,
                            const SweepPlanDevice& sp, const double* panels, index_t nrhs,
                            bool forward, bool backward, bool forward_subtrees = true);
  /// The forward sweep's first launch alone: every subtree of sp's plan, one block each,
  /// or where the plan has a chain (SolvePlan::chain_levels) the chain's forward launch,
  /// which also takes the bottom levels that enqueue_solve_sweeps then leaves out.
  void enqueue_forward_subtrees(const Analysis& an, const numeric::NumericFactor& fac,
                                const SweepPlanDevice& sp, const double* panels, index_t nrhs);
  /// The device solve's view of the tree, the factor's row arrays and sp's panels.
  SolveTree solve_tree(const Analysis& an, const SweepPlanDevice& sp, const double* panels);
  /// sp's chain on the device (SolvePlan::chain_levels > 0).
  static SolveChain solve_chain(const SweepPlanDevice& sp);
  /// What a recorded solve graph read: the analysis, the right-hand sides' count, the
  /// factor's type and every device buffer the sweeps use (cuda_solve.cu).
  std::vector<std::uintptr_t> solve_graph_key(const Analysis& an, const numeric::NumericFactor& fac,
                                              index_t nrhs) const;
  void drop_solve_graph() noexcept;
  /// Uploads the device solve's row arrays for a factor of `type` whose row indices are
  /// `factor_rows` (laid out as an.tree.rows; index base 0): the rows, each pivot's
  /// position in its front and the row each pivot position holds, and for LDLᵀ D and the
  /// pivot sizes of `fac`. Records the analysis and type they hold.
  /// For LU, after a first upload for the analysis, only the fronts whose pivot rows moved
  /// since the last one are sent (host copies in dsolve_.rows_host and beside it; the
  /// fronts marked in dsolve_.rows_moved by finish_front, the comparison made while the GPU
  /// factors the next chunk rather than after the last).
  void upload_solve_rows(const Analysis& an, const index_t* factor_rows, MatrixType type,
                         const numeric::NumericFactor* fac);
  /// An in-core chunk whose work was launched and whose host part has not run yet (see
  /// factor_chunk): what the host part needs, the pinned buffers its results come back
  /// to, and its events (before assembly, after assembly, after the small fronts, after
  /// the large fronts, after stores and packs, after the copies to the host).
  struct ChunkRecord {
    index_t begin = 0, end = 0;
    bool lu = false, ldlt = false, dev_only = false;
    index_t max_rows = 0;  ///< the chunk's largest front
    bool fused = false;    ///< factored by factor_chunk_fused
    std::vector<std::int64_t> small, big, perm_off, big_perm_at, diag_off;
    std::int64_t perm_total = 0;   ///< pivots of the chunk (small fronts' then large ones')
    std::size_t panels_total = 0;  ///< doubles of the chunk's panels (chunk_layout)
    /// The layout's device arrays: small fronts' positions, their perm offsets, each
    /// position's panel offset and first diagonal slot.
    const std::int64_t *small_pos = nullptr, *perm_offset = nullptr, *stage_offset = nullptr,
                       *diag_offset = nullptr;
    PinnedBuffer<std::int64_t> info, perturbed, perm;
    PinnedBuffer<int> pinfo, psize;
    PinnedBuffer<double> diag;
    /// A fused chunk's results in one copy: info, perturbed, perm, diag back to back; or
    /// another device-only chunk's (chunk_pack_results: packed_words of them, POTRF's
    /// infos and LDLᵀ's pivot sizes among them, widened to words).
    PinnedBuffer<std::int64_t> packed;
    std::size_t packed_words = 0;
    /// Where the host part reads the results (the buffers above, or in `packed`).
    const std::int64_t *info_at = nullptr, *perturbed_at = nullptr, *perm_at = nullptr;
    const std::int64_t *pinfo_at = nullptr, *psize_at = nullptr;  ///< packed_words > 0
    const double* diag_at = nullptr;
    /// The chunk's panels on their way to the host factor (LLᵀ and LU whose panels do not
    /// stay on the device): copied there on copy_stream_ while the next chunk computes,
    /// then into the factor by the host part.
    PinnedBuffer<double> panels;
    bool panels_async = false;
    /// 0–5: assembly, small fronts, large fronts, store, results copied (timed);
    /// 6: panels packed; 7: panels copied to `panels`
    cudaEvent_t ev[8] = {};
  };
  /// Launches the chunk [begin, end) of the current part, then runs the previous chunk's
  /// host part while the GPU works on this one (LDLᵀ whose panels come back: this
  /// chunk's host part too, at once).
  void factor_chunk(const numeric::FactorContext& ctx, index_t begin, index_t end);
  /// factor_chunk's stages (factor_chunk.cu), in order, each enqueued on stream_ (and the
  /// lanes): the small fronts, the large fronts (with the panel kernels' share), the
  /// panels packed and copied back, the host part's results fetched into `rec`.
  void chunk_small_fronts(const numeric::FactorContext& ctx, ChunkRecord& rec, cudaStream_t s);
  /// The chunk's layout (ChunkLayout) into `rec`: the part's cached one when its key
  /// matches, else made and its device arrays uploaded (the chunk's first factorization).
  void chunk_layout(const numeric::FactorContext& ctx, ChunkRecord& rec);
  /// Where the chunk's panels are packed (the device factor, the part's own buffer or the
  /// staging area, as the layout's panel offsets assume).
  double* chunk_panel_target(const numeric::FactorContext& ctx);
  /// The whole chunk by one launch when every front is a small LU or Cholesky front that fits
  /// shared memory and the panels stay on the device (Options::gpu_fused_small_batches).
  void factor_chunk_fused(const numeric::FactorContext& ctx, ChunkRecord& rec);
  /// A device-only chunk's results packed for one copy (factor_chunk.cu); false when not.
  bool chunk_pack_results(ChunkRecord& rec);
  /// The record's half of packed_results_.
  std::int64_t* packed_half(const ChunkRecord& rec);
  std::vector<char> chunk_panel_kernels(const numeric::FactorContext& ctx, const ChunkRecord& rec);
  /// `after`: the event its lanes wait for (the small fronts' end, or the assembly's when
  /// the small fronts run beside them).
  void chunk_large_fronts(const numeric::FactorContext& ctx, const ChunkRecord& rec,
                          cudaEvent_t after);
  void chunk_pack_panels(const numeric::FactorContext& ctx, ChunkRecord& rec);
  void chunk_fetch_results(ChunkRecord& rec);
  /// Runs the pending chunk's host part, if any (before anything that needs the host
  /// factor complete: a tiled front, the end of a part or of the factorization).
  void flush_chunk(const numeric::FactorContext& ctx);
  void finish_chunk(const numeric::FactorContext& ctx, ChunkRecord& c);
  /// A front over the budget, factored through the device in pieces: LLᵀ by
  /// factor_tiled_llt (tiled_llt.cu), LU slab by slab right-looking (tiled_front.cu).
  void factor_tiled(const numeric::FactorContext& ctx, index_t pos);
  void factor_tiled_llt(const numeric::FactorContext& ctx, index_t pos);
  /// factor_tiled_llt's two steps (tiled_llt.cu): the pivot columns by slabs, then the
  /// contribution block's update by tiles.
  struct TiledLltFront;
  void tiled_llt_pivot_columns(const numeric::FactorContext& ctx, const TiledLltFront& fr,
                               EventPair& computed);
  void tiled_llt_cb_update(const TiledLltFront& fr, EventPair& computed);
  /// Columns per slab of a tiled front (m rows, k pivots): a slab and two column blocks
  /// of the trailing matrix fit the pool (3·m·w doubles), at least 1, at most k.
  std::int64_t slab_width(std::int64_t m, std::int64_t k) const;
  /// A tiled Cholesky front's slab (columns factored together) and the pieces of earlier
  /// columns streamed against it (Options::gpu_tiled_stream_columns): a slab and two
  /// pieces of m rows fit the pool; both slab_width when the option is 0.
  struct TiledWidths {
    std::int64_t slab = 1, stream = 1;
  };
  TiledWidths tiled_llt_widths(std::int64_t m, std::int64_t k) const;
  /// Whether p points into the pinned host arena (a contribution block spilled to the host)
  /// rather than device memory.
  bool in_host_arena(const double* p) const {
    return p >= host_arena_.data() && p < host_arena_.data() + host_arena_.size();
  }
  /// Front f (m × m) assembled on the host's threads into H: zeroed, the original
  /// entries, then each child's block in child order (a block on the device copied to
  /// host_staging_ first) — the device kernel's additions in its order, so H is bitwise
  /// the front the kernel would make. LLᵀ and LDLᵀ add lower triangles only.
  void assemble_on_host(const numeric::FactorContext& ctx, index_t f, double* H, bool symmetric);
  /// The same for a Cholesky front, split: its k pivot columns into P (m × k, leading
  /// dimension m) and, when C is not null, its contribution block's lower triangle into C
  /// (mc × mc, leading dimension mc; the strict upper triangle is not written).
  void assemble_llt_split(const numeric::FactorContext& ctx, index_t f, double* P, double* C);
  /// The same from the children's blocks already on the host (in child order, null for an
  /// empty one); touches no stream, so it may run beside the device's work.
  void assemble_llt_split_from(const Analysis& an, const double* values, index_t f, double* P,
                               double* C, const std::vector<const double*>& block);
  /// Starts, on a thread of its own, the host assembly into tiled_.front_next of the next
  /// tiled Cholesky front of the level of the front `f` at position `pos` (the current
  /// part's schedule), when Options::gpu_tiled_prefetch is on (its children's blocks on
  /// the device are copied to tiled_.staging_next first; tiled_llt.cu).
  void start_tiled_prefetch(const numeric::FactorContext& ctx, index_t f, index_t pos);
  /// Waits for a pending prefetch and forgets it; true when it assembled the front at
  /// position `pos` of part `part` (into tiled_.front_next).
  bool take_tiled_prefetch(int part, index_t pos);
  /// The same when nothing will use it (a new part, a failed factorization).
  void drop_tiled_prefetch() { (void)take_tiled_prefetch(-3, -1); }
  /// Front f's children's contribution blocks on the host, in child order (null for an
  /// empty one): in the host arena, or copied from the device into host_staging_.
  std::vector<const double*> children_blocks_on_host(const numeric::FactorContext& ctx, index_t f);
  /// A large LU front of the current chunk: its lane, the front in the pool (m×m, k
  /// pivots), its position, where its local row permutation and perturbed-pivot count go.
  struct LuFront {
    Lane* lane;
    double* F;
    int m, k;
    index_t pos;  ///< its position in the part's schedule (to assemble it again)
    std::int64_t* perm;
    std::int64_t* perturbed;
  };
  /// LU of the chunk's large fronts (lu_fronts.cu): eliminated without interchanges by
  /// strips of lu_strip_pivots_ pivots (the batched kernels, kernels_lu_panel.cu) or,
  /// when that is 0, by GETRF without pivoting + TRSMs, each kept when no interchange was
  /// due; the contribution-block GEMM (split over the team for a large front,
  /// split_update; `assembled`: recorded after the chunk's assembly); a front whose check
  /// failed assembled again and factored by lu_fronts_redo. The fronts' lanes are updated
  /// to the ones their last work went to.
  void lu_large_fronts(std::vector<LuFront>& fronts, const numeric::PivotPolicy& pivots,
                       cudaEvent_t assembled);
  /// The two ways of lu_large_fronts; each returns the indices of the fronts to factor
  /// again.
  std::vector<std::size_t> lu_fronts_by_strips(std::vector<LuFront>& fronts,
                                               const numeric::PivotPolicy& pivots,
                                               cudaEvent_t assembled);
  std::vector<std::size_t> lu_fronts_by_library(std::vector<LuFront>& fronts,
                                                const numeric::PivotPolicy& pivots,
                                                cudaEvent_t assembled);
  /// Fronts `redo` of `fronts` assembled again and factored with partial pivoting (GETRF;
  /// threshold 1 only), or by the blocked panel-kernel path when a pivot needs static
  /// pivoting or the threshold is below 1 (GETRF's rule is not the CPU's then).
  void lu_fronts_redo(std::vector<LuFront>& fronts, const std::vector<std::size_t>& redo,
                      const numeric::PivotPolicy& pivots, cudaEvent_t assembled);
  /// A front whose k × k block GETRF factored (with the interchanges `ipiv`, 1-based, or
  /// none when null), on its lane: the interchanges applied to A12, L21 and U12 by cuBLAS
  /// TRSMs, and the contribution block's update (GEMM, or split_update over the team).
  void lu_panels_and_update(const LuFront& fr, const int* ipiv, cudaEvent_t assembled);
  /// Identity local permutations and no perturbed pivot for `fronts`, on stream s.
  void lu_unpivoted_results(const std::vector<LuFront>& fronts, cudaStream_t s);
  /// Grows the lane's GETRF workspace for the front's k × k block.
  void grow_getrf_work(Lane& lane, const LuFront& fr);
  /// Waits for every lane, then copies lu_.bad[0, n) to lu_.bad_host.
  void fetch_lu_checks(std::size_t n);
  /// The lanes, created on first use (kLanes of them).
  std::vector<std::unique_ptr<Lane>>& lanes();
  /// Host bookkeeping of factored front f: `diag` holds its k pivots' diagonal entries.
  void finish_front(const numeric::FactorContext& ctx, index_t f, std::int64_t bad,
                    std::int64_t npert, const std::int64_t* lperm, const double* diag);
  void copy_panels_back(const numeric::FactorContext& ctx, index_t begin, index_t end);
  /// Copies the panels of chunk positions [begin, end), packed in chunk order at `staged`
  /// (pinned host memory), into the host factor, on the host's threads.
  void store_staged_panels(const numeric::FactorContext& ctx, index_t begin, index_t end,
                           const double* staged);
  // --- a large front's update split over helper GPUs (split_update.cu) ---
  /// In begin_part: the helpers of ctx this executor can use (CUDA executors on other
  /// GPUs that reach this one's memory and whose memory it reaches; peer access enabled),
  /// each helper's lane made to wait for the work its own stream still has in flight.
  void set_team(const numeric::FactorContext& ctx);
  /// In end_part (and before any later use of a helper): waits for the helpers' lanes.
  void release_team();
  /// Whether a front of m rows and k pivots gets its update split over the team.
  bool split_front(int m, int k) const {
    return !team_.members.empty() && split_min_cb_ > 0 && m - k >= split_min_cb_;
  }
  /// Front F (m × m in the pool, k pivots), its pivot block and panel enqueued on `lane`:
  /// the update C −= L₂₁L₂₁ᵀ (LLᵀ, lower triangle) or C −= L₂₁U₁₂ (LU) of its
  /// contribution block C, split into column strips of about equal flops, the first
  /// done here on `lane`, each other one by a helper (strip of C and the rows of the
  /// panel it needs copied to the helper's pool, GEMM there, strip copied back). A
  /// helper's copy of its strip of C waits only for `assembled`. The chunk's stores must
  /// wait for the helpers (join_team).
  void split_update(Lane& lane, double* F, int m, int k, bool lu, cudaEvent_t assembled);
  /// Makes stream_ wait for the helpers used since the last call (the chunk's join).
  void join_team();
  /// Whether an LLᵀ front of m rows is factored over the team (distributed_llt). Not
  /// under a device budget: the panel slots are memory beside the plan.
  bool distribute_front(int m) const {
    return !team_.members.empty() && dist_min_rows_ > 0 && m >= dist_min_rows_ && limit_ == 0;
  }
  /// Front F (m × m in the pool, k pivots, assembled: all its work so far on `lane`)
  /// factored whole — pivot block, panel and contribution-block update — over this GPU
  /// and the team, its columns in blocks of dist_block_ dealt out cyclically
  /// (distributed_front.cu); F ends as the one-GPU code leaves it, `info` (device) as
  /// POTRF of order k reports. Everything is enqueued (lane.stream waits for the
  /// helpers' last copies). False, with nothing enqueued, when a helper's pool cannot
  /// hold its blocks, a GPU has no room for the panel slots, or the front has a single
  /// column block. A front of NB blocks is spread over min(NB, team size) GPUs.
  bool distributed_llt(Lane& lane, double* F, int m, int k, int* info);
  /// distributed_llt's layout of F's column blocks (bounds c, P pivot blocks) over this
  /// GPU and the first G − 1 helpers of the team (distributed_front.cu); false when the
  /// front cannot be distributed.
  bool team_layout(Lane& lane, double* F, std::int64_t m, const std::vector<std::int64_t>& c, int P,
                   int G, std::vector<TeamGpu>& gpu);
  /// The lane this executor lends to others (a lane of its own, idle while it helps).
  Lane& help_lane();
  void count_h2d(std::size_t bytes) { bytes_h2d_ += bytes; }
  template <class T>
  void upload(DeviceBuffer<T>& d, const std::vector<T>& h) {
    d.upload(h.data(), h.size(), stream_);
    bytes_h2d_ += h.size() * sizeof(T);
  }

  int device_ = 0;
  cudaStream_t stream_ = nullptr;
  cublasHandle_t blas_ = nullptr;
  cusolverDnHandle_t solver_ = nullptr;
  std::size_t limit_ = 0;
  std::size_t host_limit_ = 0;  ///< Options::host_memory_limit (0: what the host has)
  std::int64_t small_front_rows_ = kSmallFront;  ///< Options::gpu_small_front_rows
  int small_front_threads_ = 0;                  ///< Options::gpu_small_front_threads
  bool fused_small_batches_ = true;              ///< Options::gpu_fused_small_batches
  std::int64_t panel_max_pivots_ = 0;            ///< Options::gpu_panel_kernel_max_pivots
  std::int64_t lu_strip_pivots_ = 0;             ///< Options::gpu_lu_strip_pivots
  std::int64_t split_min_cb_ = 0;                ///< Options::split_front_min_cb
  std::int64_t dist_min_rows_ = 0;               ///< Options::distributed_front_min_rows
  std::int64_t dist_block_ = 512;                ///< Options::distributed_front_block_size
  int potrf_block_ = 0;                          ///< Options::gpu_potrf_block_size
  bool recursive_panel_ = true;                  ///< Options::gpu_recursive_panel
  bool solve_graph_ = true;                      ///< Options::gpu_solve_graph
  bool solve_chain_ = true;                      ///< Options::gpu_solve_chain
  bool solve_parts_ = true;                      ///< Options::gpu_solve_parts
  std::uint64_t analysis_id_ = 0;
  std::uint64_t factorization_count_ = 0;  ///< factorizations begun here (begin)
  DevicePlan plan_;
  // analysis arrays (fronts_: the whole tree's schedule, for the device solve)
  DeviceBuffer<std::int64_t> fronts_, n_rows_, n_pivots_, parent_, entry_offsets_, entry_src_,
      entry_dst_, child_offsets_, children_, rel_offsets_, rel_;
  DeviceBuffer<std::uint32_t> lu_interchanges_;  ///< DeviceTree::lu_interchanges
  std::map<int, PartDevice> parts_;  ///< by PartView::id: -1 whole tree, 0..P subtrees, top
  PartDevice* cur_ = nullptr;        ///< the part being factored
  bool whole_ = true;                ///< the last factorization was of the whole tree
  /// The panels of this factorization stay on the device only (resident factor, LLᵀ or
  /// LU, no front factored tile by tile): no copy to the host factor unless asked.
  bool device_only_ = false;
  /// A part of a multi-GPU split whose panels stay on this device (FactorContext::
  /// keep_part_panels, no budget set, not LDLᵀ, nothing tiled): packed into
  /// part_panels_[its id] instead of going to the host factor.
  bool part_device_only_ = false;
  std::map<int, DeviceBuffer<double>> part_panels_;
  std::vector<int> held_parts_;  ///< parts of this factorization kept so (the rest are freed)
  int planned_ = 0;              ///< parts_ planned for: 0 nothing, 1 whole, 2 split
  /// Blocks of subtree roots exported for a peer copy (or the same device): the arena they
  /// came from is reused by the next subtree. Kept from one factorization to the next (the
  /// same sizes), so that no GPU begins a factorization with a synchronizing cudaFree;
  /// dropped with the analysis.
  std::map<index_t, DeviceBuffer<double>> outbox_;
  /// Blocks pushed to the GPU that imports them as soon as they are exported (export_cb,
  /// push_block), while that GPU is still busy: per part root, the buffer on that GPU and
  /// the event on this one that completes with the copy. Kept from one factorization to
  /// the next (the same sizes); dropped with the analysis.
  struct Landing {
    int device = -1;
    DeviceBuffer<double> buffer;
    cudaEvent_t ready = nullptr;
  };
  std::map<index_t, Landing> landing_;
  cudaStream_t push_stream_ = nullptr;  ///< the pushes' copies
  /// A chunk's small-front kernel when the chunk also has large fronts (factor_chunk):
  /// the two kinds, independent fronts of one level, run side by side.
  cudaStream_t small_stream_ = nullptr;
  bool push_block(numeric::CbTransfer& t);
  void drop_landings() noexcept;
  /// The value pass on the device (value_pass.cu): the canonical pattern by columns
  /// (col_ptr, col_row) and by rows (row_ptr; per entry of a row its position and
  /// column), the matching scaling, the per-row and per-column figures (6n), an
  /// equilibration's factors (4n: the sweeps' products and the last sweep's), the flag of a
  /// value that is not finite and the five numbers for the host; `analysis`: the
  /// Analysis::id they were made for (0: none).
  struct ValuePass {
    DeviceBuffer<std::int64_t> row_ptr, col_ptr;
    DeviceBuffer<int> row_pos, row_col, col_row, bad;
    DeviceBuffer<double> row_scaling, col_scaling, sums, rescale;
    PinnedBuffer<double> out;
    std::uint64_t analysis = 0;
  } value_pass_;
  // the values as given of the last value pass that copied them (input_next_) and of the
  // last factorization that kept them (input_, for analysis input_analysis_):
  // keep_device_input, download_device_input
  DeviceBuffer<double> input_, input_next_;
  std::uint64_t input_analysis_ = 0;
  // a checked solve's refinement on the device (residual.cu): the caller's vectors
  // (refinement_workspace), A's values from the host (values, for analysis
  // values_analysis and MatrixValues::id values_id), the residual's maxima per column
  struct Refinement {
    DeviceBuffer<double> work, values;
    std::uint64_t values_analysis = 0, values_id = 0;
    DeviceBuffer<unsigned long long> maxima;
    PinnedBuffer<unsigned long long> maxima_host;
  } refine_;
  // numeric working memory
  DeviceBuffer<double> values_, arena_, pool_, potrf_work_, panels_;
  PinnedBuffer<double> host_arena_, host_staging_;
  DeviceBuffer<int> potrf_info_;
  DeviceBuffer<std::int64_t> panel_items_;  // launch_llt_panel's (position, slot)
  DeviceBuffer<double> panel_work_;         // launch_llt_panel's diagonal-block inverses
  DeviceBuffer<std::int64_t> info_, perturbed_, perm_;
  DeviceBuffer<std::int64_t> packed_results_;  // a fused chunk's results (ChunkRecord::packed)
  std::vector<std::int64_t> iota_;
  DeviceBuffer<int> pivot_size_;         // LDLᵀ: local pivot sizes, laid out as perm_
  DeviceBuffer<std::int64_t> psize_at_;  // LDLᵀ: per chunk position, its offset in pivot_size_
  // the diagonals of device-only panels
  DeviceBuffer<double> diag_;
  /// The chunk's large LU fronts (lu_fronts.cu): workspaces, the strips' items and event,
  /// the pivot checks copied on their own stream, and the counts FactorStats reports
  /// (lu_large_fronts, lu_large_fronts_pivoted, lu_large_fronts_batched).
  struct LuLargeFronts {
    DeviceBuffer<double> work;
    DeviceBuffer<LuPanelItem> items;
    DeviceBuffer<LuPanelItem> cb_items;      ///< their contribution blocks' batched updates
    DeviceBuffer<std::int64_t> perm_offset;  ///< lu_unpivoted_results: the fronts' perm offsets
    cudaEvent_t strip_done = nullptr;        ///< enqueue_lu_strips' strip_done
    LuLookahead ahead;                       ///< the strips' look-ahead stream and events
    cudaStream_t check_stream = nullptr;     ///< copies the LU checks beside the lanes' work
    DeviceBuffer<int> ipiv, info, bad;
    PinnedBuffer<int> bad_host;
    index_t fronts = 0, fronts_pivoted = 0, fronts_batched = 0;
  } lu_;
  std::vector<std::unique_ptr<Lane>> lanes_;  ///< large fronts of a chunk, side by side
  LdltLarge ldlt_large_;
  /// The device solve's state (cuda_solve.cu): the factor it holds resident and the
  /// analysis and type its row arrays were uploaded for (end()), the solve plan and its
  /// device copy, the row, pivot and offset arrays, and the solve's workspaces.
  struct DeviceSolveState {
    const numeric::NumericFactor* resident_for = nullptr;
    std::uint64_t resident_analysis = 0;
    std::uint64_t rows_analysis = 0;
    MatrixType rows_type = MatrixType::automatic;
    DeviceBuffer<std::int64_t> rows, row_offsets, first_pivot, level_offsets, pivot_pos, pivot_row,
        u_offset;
    DeviceBuffer<int> pivot_size;
    /// What rows, pivot_pos and pivot_row hold (upload_solve_rows' incremental LU uploads
    /// compare against it)
    std::vector<std::int64_t> rows_host, pivot_pos_host, pivot_row_host;
    /// LU, per front: its pivot rows in the factor differ from rows_host's (set by
    /// finish_front as each chunk's host part runs, cleared by upload_solve_rows)
    std::vector<char> rows_moved;
    DeviceBuffer<std::int64_t> moved_rows, moved_segments;  ///< their moved rows, packed
    DeviceBuffer<double> d_diag, d_off, x, u, scratch, part;
    /// solve_original: the right-hand sides and solutions in the original numbering, the
    /// factorization's rescaling (RescaleView::id rescale_id, 0: none copied), and per
    /// analysis (io_analysis) the permutations and scale factors between the two
    /// numberings (prepare_solve_io)
    DeviceBuffer<double> b, row_rescale, col_rescale, in_scale, out_scale;
    DeviceBuffer<std::int64_t> in_index, out_index;
    /// solve_gpu_arrays: b's first non-finite entry, x's (complemented), b's and x's
    /// largest magnitude (EntryCheck), and their copy on the host (complete once the
    /// stream is; checks_pending: a solve of GPU arrays wrote it)
    DeviceBuffer<unsigned long long> checks;
    PinnedBuffer<unsigned long long> checks_host;
    bool checks_pending = false;
    std::uint64_t io_analysis = 0, rescale_id = 0;
    std::vector<std::int64_t> u_offset_host;  ///< per front + 1: its update vector in u
    std::uint64_t inverse_analysis = 0;       ///< what inv_offsets and inv_src are for
    DeviceBuffer<std::int64_t> inv_offsets, inv_src;
    SweepPlanDevice whole;                 ///< the whole tree's plan, per analysis
    std::uint64_t parts_analysis = 0;      ///< what `parts` was planned for
    double parts_limit = -1.0;             ///< the whole tree's subtree limit, which the parts take
    std::map<int, SweepPlanDevice> parts;  ///< held parts' plans, by part id
    bool part_rows_current = false;        ///< the row arrays hold the last factorization's
    /// The sweeps of a solve recorded as a CUDA graph (Options::gpu_solve_graph) and
    /// replayed, one launch per solve, while graph_key (solve_graph_key) is unchanged;
    /// all but the forward sweep's first launch (the subtrees', or the chain's), which each
    /// solve enqueues just before it.
    cudaGraphExec_t graph = nullptr;
    std::vector<std::uintptr_t> graph_key;
  } dsolve_;
  // statistics of the last factorization
  std::size_t bytes_h2d_ = 0, bytes_d2h_ = 0;
  index_t chunks_ = 0, fused_chunks_ = 0;
  double device_seconds_ = 0;
  cudaEvent_t start_ = nullptr, stop_ = nullptr;
  cudaEvent_t panels_done_ = nullptr;  // the chunk's launch_llt_panel: the lanes wait for it
  /// The panels' copies to the host (ChunkRecord::panels), beside the compute, and the
  /// last one issued: the next pack into the device staging area waits for it.
  cudaStream_t copy_stream_ = nullptr;
  cudaEvent_t panels_copied_ = nullptr;
  bool copy_issued_ = false;
  /// Two chunk records used in turn: one launched, the previous one finishing on the host.
  ChunkRecord chunk_[2];
  int slot_ = 0;
  ChunkRecord* pending_ = nullptr;
  FactorStats::DevicePhases phases_;  ///< summed over the chunks of the factorization
  /// Several GPUs' help with one large front (split_update.cu, distributed_front.cu).
  struct GpuTeam {
    /// As the front's owner: the helpers of the current part and those the current chunk
    /// used; as a helper, the events its help lane records.
    std::vector<CudaExecutor*> members, used;
    cudaEvent_t split_ready = nullptr;  ///< on the owner's lane: pivot block and panel done
    cudaEvent_t help_ready = nullptr, help_done = nullptr;
    bool helped = false;  ///< its help lane has work of another executor in flight
    index_t fronts_split = 0, strips_helped = 0;
    /// Distributed fronts: on every GPU the two slots panels of other GPUs arrive in, the
    /// per-block statuses (the owner's gathers every GPU's), the per-step events and the
    /// stream panels arrive on; as the owner, events ordering one distributed front after
    /// the previous one.
    DeviceBuffer<double> dist_panels;
    DeviceBuffer<int> dist_status;
    std::vector<cudaEvent_t> dist_events;
    cudaEvent_t dist_ready = nullptr, dist_done = nullptr;
    cudaStream_t dist_copy = nullptr;
    bool dist_done_recorded = false;
    index_t fronts_distributed = 0;
    std::size_t help_bytes = 0;
  } team_;
  /// Fronts over the budget, factored through the device in pieces (tiled_front.cu,
  /// tiled_llt.cu): their options, the pinned host front they are assembled in, the next
  /// tiled Cholesky front's host assembly (start_tiled_prefetch: its buffer, its
  /// children's blocks from the device, the part and position it is for) and the counts
  /// FactorStats reports (tiled_fronts, tiled_fronts_prefetched). Last member: its
  /// prefetch is destroyed (joined) before the rest of the executor.
  struct TiledFronts {
    double pool_share = 0;         ///< Options::gpu_tiled_pool_share
    std::int64_t stream_cols = 0;  ///< Options::gpu_tiled_stream_columns
    bool prefetch_on = false;      ///< Options::gpu_tiled_prefetch
    PinnedBuffer<double> front, front_next, staging_next;
    index_t count = 0, prefetched = 0;
    struct Prefetch {
      std::future<void> done;
      int part = -2;
      index_t pos = -1;
    } prefetch;  ///< last: joined before the buffers it writes are freed
  } tiled_;
};

}  // namespace strata::cuda
