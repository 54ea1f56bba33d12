// strata — statistics reported by each phase. Numerical outcomes (perturbed pivots,
// inertia, refinement) are reported here rather than thrown.
#pragma once

#include <cstddef>
#include <limits>
#include <string>
#include <vector>

#include "strata/options.hpp"
#include "strata/types.hpp"

namespace strata {

/// One batch of the memory plan: fronts schedule[begin..end) of one level processed
/// together. `bytes` is its working set (fronts, contribution blocks read and written).
/// `tiled` marks a batch of a single front that alone exceeds the budget and must be
/// factored tile by tile.
struct BatchInfo {
  index_t level = 0;
  index_t begin = 0;
  index_t end = 0;
  std::size_t bytes = 0;
  bool tiled = false;
};

/// Results of the analysis phase (pattern only).
struct AnalysisStats {
  index_t n = 0;
  index_t nnz_a = 0;         ///< entries of the full (both triangles) matrix A
  index_t nnz_l = 0;         ///< exact nnz(L), diagonal included (no amalgamation)
  index_t nnz_l_fronts = 0;  ///< entries of L as stored in fronts (with amalgamation zeros)
  double factor_flops = 0;   ///< flops of a Cholesky of the fronts (LU: about 2×)
  index_t n_fronts = 0;
  index_t largest_front_rows = 0;    ///< rows of the largest front
  index_t largest_front_pivots = 0;  ///< most pivots in one front
  index_t max_block_size = 0;  ///< separator block size used (Options::max_block_size resolved)
  index_t tree_height = 0;     ///< levels in the assembly tree
  std::vector<index_t> fronts_per_level;  ///< level 0 is processed first (deepest)
  std::size_t peak_working_bytes = 0;     ///< in-core multifrontal working memory peak
  std::size_t factor_bytes = 0;           ///< bytes of the factor as stored in fronts
  /// Bytes a factorization on the CPU backend holds at its peak besides its input: the
  /// factor (panels, row indices, LDLᵀ's D), the contribution-block stack of its
  /// depth-first traversal (Options::num_threads threads), and the dense front workspaces
  /// of the fronts that need one (LDLᵀ and LU fronts; Cholesky fronts are formed in the
  /// factor and on the stack): one per thread, each sized by the largest front it factors.
  std::size_t cpu_factorization_bytes = 0;
  /// Bytes of the analysis's own arrays (the order, the assembly tree, the maps that assemble
  /// the fronts, the schedules and layouts), which every factorization reads; with the input
  /// and cpu_factorization_bytes, what a CPU factorization's process holds at its peak.
  std::size_t analysis_bytes = 0;
  std::size_t memory_budget = 0;            ///< budget the plan was made for (0: unlimited)
  std::vector<BatchInfo> batches;           ///< the memory plan
  MatrixType type = MatrixType::automatic;  ///< type the analysis was made for
  /// symmetric_indefinite: pivot groups of the symmetric matching kept together in one
  /// front (Duff & Pralet 2005): pairs, and short odd cycles of the matching kept whole
  /// (when even their best singleton has a small diagonal).
  index_t pairs = 0;
  index_t odd_cycles = 0;
  OrderingMethod ordering = OrderingMethod::nested_dissection;
  /// Solver::analyze_keeping_order: the matching, scaling and fill-reducing order of the
  /// analysis before were kept for a pattern that contains its own (ordering_seconds is
  /// then the time to form the permuted pattern).
  bool order_kept = false;
  /// Solver::analyze_keeping_matching: the matching and scaling of the analysis before
  /// were kept and a new fill-reducing order computed (matching_seconds is then 0).
  bool matching_kept = false;
  /// Solver::analyze_in_pivot_order: the matching and order are those in which the last
  /// factorization with delayed pivots took its pivots (the pattern and the ordering
  /// method reported are the analysis's before; ordering_seconds is the time to form the
  /// new order).
  bool order_from_pivots = false;
  /// Where the factorizations of this analysis run: Options::backend, with
  /// Backend::automatic resolved (cuda or cpu, by the GPUs present and
  /// Options::gpu_min_flops).
  Backend backend = Backend::cpu;
  /// Several workers (GPUs): the split of the tree (docs/multigpu.md). workers is 1 and
  /// the rest 0 when the analysis was made for one.
  index_t workers = 1;
  index_t subtrees = 0;           ///< disjoint subtrees the workers share
  double subtree_balance = 0;     ///< LPT makespan / mean load over the subtrees (≥ 1)
  double top_flops_fraction = 0;  ///< share of factor_flops in the top part (one worker)
  /// The top split again (Options::split_top): upper layers above the subtrees, their
  /// parts (each factored by one worker, the parts of a layer side by side), and the
  /// share of factor_flops in them. top_flops_fraction is then what is left above them.
  index_t upper_layers = 0;
  index_t upper_parts = 0;
  double upper_flops_fraction = 0;
  /// factor_flops / the split's estimated time (schedule::TreePartition::estimated_time:
  /// the list schedule of the parts by flops, transfers not counted): the speedup the
  /// split allows at best, ≤ workers. 0 for one worker.
  double estimated_speedup = 0;
  /// Nested dissection balanced by work (Options::balance_by_work): top bisections redone
  /// with weighted vertices, and the time spent estimating and redoing them (included in
  /// ordering_seconds).
  index_t nd_rebisections = 0;
  double nd_balance_seconds = 0;
  /// The matching and scaling (maximum product matching of a general matrix, symmetric
  /// matching of a symmetric indefinite one), included in ordering_seconds.
  double matching_seconds = 0;
  double ordering_seconds = 0;
  double symbolic_seconds = 0;
  double plan_seconds = 0;
  /// CUDA backend: the device set-up done at analysis (analysis arrays uploaded, device
  /// memory planned and allocated, streams and library handles created), which the first
  /// factorization then skips; 0 for the CPU backend. Included in total_seconds.
  double device_setup_seconds = 0;
  /// CUDA backend: why that set-up failed (the error's message), empty when it did not;
  /// the first factorization sets the device up again and throws if it fails there too.
  std::string device_setup_error;
  double total_seconds = 0;
};

/// One part of the tree split (AnalysisStats::subtrees, the upper parts, the top part)
/// as a worker of a multi-worker factorization ran it (DeviceStats::parts): a timeline
/// of the factorization, to see which worker waited for what.
struct PartRun {
  enum class Kind { subtree, upper, top };
  Kind kind = Kind::subtree;
  /// The part's index among its kind: subtree i (0-based, largest work first, as in the
  /// analysis), upper part i (layer by layer), or 0 for the top part.
  index_t index = 0;
  bool stolen = false;  ///< a subtree taken from another worker's queue
  /// Host-clock seconds from the start of the factorization: when the worker began the
  /// part (after waiting for the parts it imports from; its imports included), and when
  /// it was done (its last batch finished on the device, its root's block exported).
  double start_seconds = 0;
  double end_seconds = 0;
  double flops = 0;  ///< Σ front flops of the part (Cholesky count)
};

/// One worker (a GPU, or a host executor) of a multi-worker factorization.
struct DeviceStats {
  int worker = 0;
  std::string device;                 ///< "cuda:0", "cuda:1", ... or "cpu"
  double busy_seconds = 0;            ///< factoring subtrees, upper parts, the top, transfers
  double idle_seconds = 0;            ///< the factorization's wall time minus busy
  index_t subtrees_run = 0;           ///< subtrees this worker factored
  index_t subtrees_stolen = 0;        ///< of those, taken from another worker's queue
  index_t upper_parts_run = 0;        ///< parts of the upper layers it factored (not subtrees)
  std::size_t bytes_transferred = 0;  ///< contribution blocks exported and imported
  double flops = 0;                   ///< Σ front flops (Cholesky count) it factored
  /// Fronts of its parts whose update it split over idle GPUs (Options::split_front_min_cb).
  index_t fronts_split = 0;
  /// Fronts of its parts factored over it and the idle GPUs, columns distributed
  /// (Options::distributed_front_min_rows).
  index_t fronts_distributed = 0;
  /// Column strips of other GPUs' fronts it updated (not counted in busy_seconds; their
  /// bytes, in and out, are in bytes_transferred).
  index_t strips_helped = 0;
  std::vector<PartRun> parts;  ///< the parts it factored, in the order it ran them
};

/// Results of the last factorize/refactorize.
struct FactorStats {
  MatrixType type = MatrixType::automatic;  ///< the factorization actually computed
  Backend backend = Backend::cpu;           ///< where it ran: cpu or cuda (never automatic)
  double seconds = 0;
  /// Of `seconds`, the work on the input before the numeric factorization: the pattern
  /// compared with the analyzed one (not for refactorize(values)), the values checked
  /// (finite, norms), copied and scaled, on the host or, with values_scaled_on_device,
  /// staged, copied to the GPU and checked and scaled there (page-locked values are not
  /// staged: Solver::refactorize).
  double input_seconds = 0;
  /// The values were checked, measured and scaled on the GPU (the CUDA backend, one GPU,
  /// values in the analyzed pattern), not on the host.
  bool values_scaled_on_device = false;
  double gflops = 0;             ///< AnalysisStats::factor_flops (×2 for LU) / seconds
  index_t perturbed_pivots = 0;  ///< tiny pivots replaced by ±ε‖A‖ (static pivoting)
  /// Delayed pivoting (Options::pivoting) computed this factor: the analysis's fixed order
  /// needed static pivots (Pivoting::automatic), or Pivoting::delayed asked for it.
  bool delayed_pivoting = false;
  /// With delayed_pivoting: pivots passed from a front to its parent (Σ over fronts; one
  /// pivot delayed twice counts twice), the fronts that passed any, and the static pivots
  /// the fixed order had needed (0 when it was not tried).
  index_t delayed_pivots = 0;
  index_t fronts_delaying = 0;
  index_t fixed_order_perturbed_pivots = 0;
  /// Pivoting::corrected: the static pivots of the fixed order made regular in this factor
  /// and corrected by each solve's low-rank update (0: none, or delayed pivoting ran).
  index_t corrected_pivots = 0;
  /// Pivoting::corrected: the normwise backward error of the correction's probe, the
  /// corrected solve of A·x = A·x̂ after at most one refinement step, which kept the
  /// correction when at most max(Options::refinement_tolerance, (m+1)·u); NaN where no
  /// probe ran (no static pivot, too many, or the k×k matrix refused).
  double correction_backward_error = std::numeric_limits<double>::quiet_NaN();
  /// Equilibration sweeps applied on top of the analysis's scaling because the values had
  /// moved far from those it was computed for (core/rescale.hpp); 0 when none was needed.
  int rescaling_sweeps = 0;
  index_t two_by_two_pivots = 0;  ///< LDLᵀ: number of 2×2 pivot blocks
  index_t inertia_positive = 0;   ///< LDLᵀ/LLᵀ: eigenvalue signs of D (after perturbation)
  index_t inertia_negative = 0;
  index_t inertia_zero = 0;
  double log_abs_determinant = 0;  ///< log|det A| (spd, LDLᵀ and LU)
  int determinant_sign = 0;        ///< sign of det A: -1, 0 or 1
  /// True when the inertia and the determinant above are A's. False when static pivoting
  /// perturbed pivots (perturbed_pivots > 0): they are then those of the nearby matrix
  /// that was factored, not A's (a positive semidefinite A can show negative eigenvalues,
  /// a singular one a finite log-determinant), and the outputs withhold or mark them.
  bool inertia_valid = true;
  double matrix_norm = 0;  ///< ‖A‖₁ used for static pivoting (after scaling)
  // --- GPU backend (zero on the CPU, and for a factorization that delayed its pivots
  // straight away on the host (Pivoting::delayed); with several GPUs: bytes, batches and
  // tiled fronts summed over them, device_seconds and device_budget the largest) ---
  double device_seconds = 0;        ///< time of the factorization's work on the GPU (events)
  std::size_t bytes_to_device = 0;  ///< host→device bytes moved by the factorization
  std::size_t bytes_to_host = 0;    ///< device→host bytes (factor panels, spilled blocks)
  index_t device_batches = 0;       ///< launch groups run (memory-plan batches, split
                                    ///< further when the device pool is smaller)
  /// Of device_batches, those assembled, factored and stored by one launch, each front
  /// straight in shared memory (Options::gpu_fused_small_batches).
  index_t device_fused_batches = 0;
  index_t tiled_fronts = 0;  ///< fronts over the device budget, factored by slabs
  /// Of tiled_fronts, those assembled on the host beside the previous one's device work
  /// (Options::gpu_tiled_prefetch).
  index_t tiled_fronts_prefetched = 0;
  /// LU: large fronts (over Options::gpu_small_front_rows rows); of those the ones factored
  /// again with interchanges (cuSOLVER GETRF for Options::diagonal_pivot_threshold = 1,
  /// strata's panel kernel below it) because their elimination without interchanges
  /// was rejected (rows to interchange, or a pivot needing static pivoting), and the ones
  /// eliminated by strata's batched kernels (Options::gpu_lu_strip_pivots > 0) rather than by GETRF
  /// without pivoting. Fronts of one 64-column step interchange rows inside the batched
  /// kernels and are not counted as factored again. See src/numeric/cuda/lu_fronts.cu.
  index_t lu_large_fronts = 0;
  index_t lu_large_fronts_pivoted = 0;
  index_t lu_large_fronts_batched = 0;
  std::size_t device_budget = 0;      ///< bytes the numeric working memory was held to
  std::size_t device_pool_bytes = 0;  ///< of device_budget, the pool fronts are factored in
  /// Bytes the numeric working memory holds on the device: the pool, the device part of
  /// the contribution-block arena, and the staging of a chunk's panels on their way to the
  /// host (or the whole factor when it stays). Within device_budget, except where a
  /// device_memory_limit is below the pool and its staging together.
  std::size_t device_working_bytes = 0;
  /// Bytes of page-locked host memory the GPU plan holds: the two chunk buffers the factor
  /// panels come back through (when the factor does not stay on the device), spilled
  /// contribution blocks, and the host copy of the largest front factored by slabs. The
  /// plan keeps these, the host factor and the value arrays within
  /// Options::host_memory_limit (by default the host memory available at analysis).
  std::size_t host_pinned_bytes = 0;
  bool contribution_blocks_on_host = false;  ///< some blocks spilled to pinned host memory
  bool factor_resident = false;              ///< the factor stayed on the device: solve runs there
  /// Where the GPU time went (seconds, from CUDA events around each in-core launch group;
  /// summed over groups and, with several GPUs, over the GPUs). `host` is the wall time
  /// after each group's GPU work: copying its panels to the host factor (unless the
  /// factor stays on the device only) and per-front bookkeeping.
  struct DevicePhases {
    double assembly = 0;      ///< zeroing fronts, scattering A, extend-add of children
    double small_fronts = 0;  ///< the one-block-per-front kernel of small fronts
    double large_fronts = 0;  ///< library calls (POTRF/GETRF/TRSM/SYRK/GEMM) and panels
    double store = 0;         ///< contribution blocks stored, panels packed
    double tiled_fronts = 0;  ///< fronts over the budget, slab by slab (wall time)
    /// Parts of tiled_fronts (wall time): the front assembled into pinned host memory by
    /// the host's threads (tiled_assembly), its pieces moved through the device and
    /// updated (tiled_slabs), the panels (and, for LU, the contribution block) copied out
    /// and the per-front bookkeeping (tiled_store).
    double tiled_assembly = 0;
    double tiled_slabs = 0;
    /// Of tiled_slabs, for Cholesky fronts (tiled_llt.cu): the pivot columns, left-looking
    /// by slabs (tiled_pivot_columns), and the contribution block's update by tiles
    /// (tiled_cb_update). Wall time; 0 for LU, whose slabs do both at once.
    double tiled_pivot_columns = 0;
    double tiled_cb_update = 0;
    double tiled_store = 0;
    double host = 0;  ///< see above
    /// Wall time preparing the device, not in the groups above: the analysis arrays
    /// uploaded, the device memory planned and allocated, the library handles and streams
    /// created, the solve's row arrays uploaded. A refactorization with the same analysis
    /// reuses all of it (near zero); the first factorization pays it.
    double setup = 0;
  } device_phases;
  /// Per worker, when several factored the tree (Options::num_gpus > 1); empty when one
  /// executor factored the whole tree.
  std::vector<DeviceStats> devices;
};

/// Results of the last solve.
struct SolveStats {
  double seconds = 0;
  /// Seconds of the first application of the factor alone (permutation and scaling, the
  /// forward and backward triangular solves, and on the GPU the transfers of b and x):
  /// what a solver without refinement reports as its solve phase. A checked solve on the
  /// GPU that holds the factor waits for that application together with its first
  /// residual: there the first residual is included.
  double first_solve_seconds = 0;
  int refinement_steps = 0;
  int gmres_iterations = 0;  ///< total over right-hand sides (0 when refinement sufficed)
  /// max over right-hand sides of ‖b−Ax‖∞/(‖A‖∞‖x‖∞+‖b‖∞); NaN when the solve did not
  /// compute it (Options::solve_check)
  double backward_error = 0;
  /// The rounding floor of the backward error, (m+1)·u for m the most entries in a row of
  /// A and u the unit roundoff: the residual computed in working precision is uncertain by
  /// about this much (Higham, Accuracy and Stability of Numerical Algorithms, §12.1).
  double backward_error_floor = 0;
  /// max over right-hand sides of ‖A‖∞‖x‖∞/‖b‖∞ (b ≠ 0): a lower bound on κ∞(A) that
  /// every solution gives (b and x in GPU memory: ‖A‖∞ max‖x‖∞ / max‖b‖∞ over the columns,
  /// no larger). Near 1/u (1e16) or above, A is singular to working precision
  /// (x then holds an arbitrary null-space component), whether or not pivots were perturbed.
  double condition_lower_bound = 0;
  /// The backward error reached Options::refinement_tolerance, or the rounding floor when
  /// that is larger (no method can verify less; GMRES is then not run). False when the
  /// backward error was not computed (Options::solve_check).
  bool refinement_converged = false;
  /// When the factorization perturbed pivots (A numerically singular): max over
  /// right-hand sides of ‖b − A x‖∞ / ‖b‖∞, at least b's distance from A's range (no x
  /// does better); 0 when no pivot was perturbed (not computed).
  double relative_residual = 0;
  /// The factorization perturbed pivots (A is numerically singular), the solve converged
  /// and relative_residual ≤ √u: b is in A's range to working precision and x is one of
  /// A's solutions (not the only one). False with perturbed pivots and a larger
  /// relative_residual: b is not in the range, and x solves only the perturbed matrix.
  bool singular_consistent = false;
  /// The triangular solves ran on the GPU (a resident factor) or GPUs (a multi-GPU factor,
  /// each part on the GPU that holds its panels).
  bool on_device = false;
  /// Host threads the triangular solves ran on: a factor with delayed pivots is solved by
  /// disjoint subtrees, one group per thread, then the top of the tree (1: sequential).
  int host_threads = 1;
};

/// All statistics of a Solver.
struct Stats {
  AnalysisStats analysis;
  FactorStats factor;
  SolveStats solve;
};

}  // namespace strata
