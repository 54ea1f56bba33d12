// strata — solver options. Every field has a documented default; a default-constructed
// Options is what `strata solve` uses when no flag is given.
#pragma once

#include <cstddef>
#include <string>
#include <string_view>
#include <vector>

#include "strata/types.hpp"

namespace strata {

/// The factorization a matrix gets.
enum class MatrixType {
  automatic,             ///< spd if symmetric and a Cholesky attempt succeeds, else
                         ///< symmetric_indefinite if symmetric, else general. A symmetric
                         ///< matrix with a diagonal entry that is missing or ≤ 0 (values
                         ///< given at analysis) cannot be spd: it is resolved to
                         ///< symmetric_indefinite by the analysis.
  spd,                   ///< symmetric positive definite: Cholesky L Lᵀ.
  symmetric_indefinite,  ///< symmetric: L D Lᵀ with Bunch–Kaufman 1×1/2×2 pivots.
  general,               ///< unsymmetric: L U on the pattern of A + Aᵀ.
};

/// The fill-reducing ordering computed in the analysis phase.
enum class OrderingMethod {
  nested_dissection,  ///< strata's own driver: recursive METIS vertex separators, AMD in
                      ///< leaves; keeps the separator tree (default).
  metis,              ///< METIS_NodeND on the whole graph.
  amd,                ///< SuiteSparse AMD on the whole graph.
  natural,            ///< identity permutation.
  user,               ///< Options::user_permutation.
  /// AMD, kept when its factor is cheap for its size — flops / nnz(L) < 500 or
  /// nnz(L) / nnz(tril(A)) < 5, AMD's own counts — else nested_dissection (CHOLMOD's rule
  /// for its default orderings, cholmod_analyze with nmethods = 0); nested_dissection
  /// whenever the tree is split over several workers. AnalysisStats::ordering says which.
  automatic,
};

/// Where the numeric phases run.
enum class Backend {
  cpu,   ///< BLAS/LAPACK on host threads (default).
  cuda,  ///< one or more CUDA GPUs; NotSupported in a build without CUDA.
  /// cuda when a GPU is present and the build has CUDA (and the analysis's factor needs at
  /// least Options::gpu_min_flops flops, 0 by default); else cpu.
  automatic,
};

/// How pivots that the analysis's fixed order cannot take are handled (LU and LDLᵀ; see
/// Options::pivoting).
enum class Pivoting {
  fixed,      ///< static pivots only: a tiny pivot becomes ±static_pivot_epsilon·‖B‖₁.
  automatic,  ///< the fixed order first; when it needs static pivots, delayed pivoting
              ///< on the host (default).
  delayed,    ///< delayed pivoting on the host for every factorization.
  corrected,  ///< the fixed order; its static pivots made regular and corrected in the
              ///< solve (Sherman–Morrison–Woodbury), delayed pivoting on the host only
              ///< where that cannot be done (Options::pivoting).
};

/// When a solve checks the solution it returns (see Options::solve_check).
enum class SolveCheck {
  always,                  ///< the backward error of every solution, refinement, GMRES
  after_perturbed_pivots,  ///< only when the factorization perturbed pivots or corrected them
};

/// Options of every phase. Units: bytes for memory, seconds for time.
struct Options {
  // --- structure ---
  /// Factorization type (default: automatic).
  MatrixType type = MatrixType::automatic;

  // --- analysis ---
  /// Fill-reducing ordering (default: nested_dissection).
  OrderingMethod ordering = OrderingMethod::nested_dissection;
  /// Permutation for OrderingMethod::user: user_permutation[k] is the original index of
  /// the k-th pivot (0-based, "new to old", as CHOLMOD's Perm). Must be a permutation of
  /// 0..n-1 or analyze throws InvalidInput.
  std::vector<index_t> user_permutation;
  /// Nested dissection stops bisecting a subgraph of at most this many vertices and
  /// orders it with AMD (default 128).
  index_t nd_leaf_size = 128;
  /// Separators METIS computes (the best kept) at each of the top three bisection levels
  /// of nested dissection. More costs analysis time for less fill: 3 gives about 5% less
  /// nnz(L) on 3D grids for about 30% more ordering time (default 1).
  int nd_top_separators = 1;
  /// Separators METIS computes (the best kept) at each bisection below the top three
  /// levels; 0 (default): METIS_NodeND's rule, 2 where merging vertices of identical
  /// adjacency leaves fewer than 2/3 of them (multi-dof meshes), else 1. More costs
  /// ordering time for less fill.
  int nd_separators = 0;
  /// Relaxed amalgamation: a child front is merged into its parent when the merged front
  /// has at most `relax_small` pivots, or when the share of explicit zeros it adds stays
  /// below relax_zeros_{1,2,3} for fronts of at most relax_size_{1,2} pivots / larger.
  /// Defaults follow CHOLMOD's (nrelax = 4, 16, 48; zrelax = 0.8, 0.1, 0.05).
  index_t relax_small = 4;
  index_t relax_size_1 = 16;
  index_t relax_size_2 = 48;
  double relax_zeros_1 = 0.8;
  double relax_zeros_2 = 0.1;
  double relax_zeros_3 = 0.05;
  /// Separator blocking: a front with more pivot columns than this is split into a chain
  /// of fronts of at most this many pivots (the paper's maximum block size). 0 (default)
  /// picks it by backend and type (AnalysisStats::max_block_size says which was used):
  /// 4096 for Cholesky (type spd) on the CUDA backend, whose large fronts' pivot blocks
  /// are factored by recursion (gpu_recursive_panel), 1024 otherwise (bench/REPORT.md,
  /// "Option defaults", has the measurements). At least 0.
  index_t max_block_size = 0;
  /// Device memory budget for the memory plan, in bytes; 0 means "the whole device"
  /// (for the CPU backend: no limit). Default 0.
  std::size_t device_memory_limit = 0;
  /// Host memory the CUDA backend's plan may count on, in bytes: the host factor (when
  /// the factor does not stay on the device), the page-locked buffers beside it
  /// (FactorStats::host_pinned_bytes) and the factorization's value arrays (about three
  /// of nnz(A)), with a reserve of an eighth for the rest of the process, are kept
  /// within it, the factor panels' buffers made smaller to fit; else the analysis's
  /// device set-up fails (AnalysisStats::device_setup_error) and the first factorization
  /// throws OutOfMemory naming the bytes. 0 means what the operating system reports
  /// available when the plan is made (MemAvailable, and the room under a cgroup memory
  /// limit). Default 0.
  std::size_t host_memory_limit = 0;

  // --- numeric factorization ---
  /// Where factorize/solve run (default: cpu).
  Backend backend = Backend::cpu;
  /// Backend::automatic with a GPU present: an analysis whose factor needs fewer flops
  /// than this (AnalysisStats::factor_flops) is factored and solved on the host, the
  /// CPU backend, and AnalysisStats::backend says so; a larger one on the GPU(s). A GPU
  /// run pays fixed costs (its context, the device set-up, launches and a wait per level
  /// of the tree) that a small factorization may not win back; where the crossover lies
  /// depends on the host's CPU (the multibody Newton matrices: bench/history.md), so
  /// the default keeps every analysis on the GPU. An analysis made for several GPUs is
  /// made again for the host's one worker; one made for one GPU is kept, with its
  /// separator blocking. The distributed solver (several MPI ranks) does not use it:
  /// there automatic means the ranks' GPUs. Default 0; at least 0.
  double gpu_min_flops = 0;
  /// Host threads for the CPU backend and for the analysis's linear passes (whose result
  /// does not depend on it); 0 means all hardware threads (default 0). The CPU
  /// factorization's memory depends on it: with 4 threads or more independent subtrees run
  /// at once, each with a contribution-block stack of its own
  /// (AnalysisStats::cpu_factorization_bytes reports the bytes for this count).
  int num_threads = 0;
  /// CPU backend: bitwise the same factor and solution for every num_threads. Fronts are
  /// always factored one per thread in a schedule-independent way; what differs between
  /// thread counts is only multithreaded OpenBLAS on the large fronts (more than 2e7
  /// flops), which rounds differently for different thread counts. With this set, those
  /// fronts run single-threaded BLAS too, giving up their parallelism, and a factor with
  /// delayed pivots (whose solve splits its subtrees by the thread count) is solved on one
  /// thread. Without it, results
  /// for a fixed num_threads are still bitwise repeatable run to run, and results for
  /// different thread counts differ at the level of the unit roundoff. Default off.
  /// (docs/reliability.md, "Determinism".)
  bool reproducible = false;

  /// CUDA backend: fronts of at most this many rows are factored each by one thread block of
  /// one launch per batch (all such fronts of the batch together; their elimination is
  /// serial within the block); larger fronts by the batched panel kernels and library
  /// calls below, which spread one front over many blocks. In [1, 256]; default 256.
  index_t gpu_small_front_rows = 256;
  /// CUDA backend: the most threads of a small-front block. A block has a thread per row
  /// of the largest front of its launch (a power of two); a launch of few fronts, which
  /// leaves most of the GPU idle, or of fronts copied into shared memory so large that few
  /// of them fit an SM at once, gets blocks up to this wide so that each front's trailing
  /// updates are spread over more threads (src/numeric/cuda/kernels.cu). The same
  /// results bit for bit. 0: a thread per row always. In [0, 512]; default 512.
  int gpu_small_front_threads = 512;
  /// CUDA backend, LU and Cholesky with the factor kept on the device: a launch group (a
  /// level of the schedule, or the part of one that fits the device pool) whose fronts all
  /// fit shared memory (up to about 168 rows for LU and 230 for Cholesky, whose fronts are
  /// held as their packed lower triangle, on an H100 or H200) and
  /// gpu_small_front_rows is assembled,
  /// factored, and its contribution blocks and panels stored by one launch, each front
  /// assembled straight into shared memory, instead of four launches through the device
  /// pool (src/numeric/cuda/kernels.cu). The same results bit for bit. Default on.
  bool gpu_fused_small_batches = true;
  /// CUDA backend, Cholesky: fronts over gpu_small_front_rows rows with at most this many
  /// pivots get their
  /// pivot block and panel from strata's batched kernels (all such fronts of a batch
  /// together, 64 pivot columns per step); fronts with more pivots, from cuSOLVER POTRF and
  /// cuBLAS TRSM one front at a time. 0 sends every front to the library. Default 256; at
  /// least 0.
  index_t gpu_panel_kernel_max_pivots = 256;
  /// CUDA backend, LU: fronts over gpu_small_front_rows rows are eliminated without row
  /// interchanges by
  /// the blocked right-looking LU in strips of this many pivot columns, each strip's pivot
  /// block and panels from strata's batched kernels for all fronts of a batch together (64
  /// pivot columns per step, src/numeric/cuda/kernels_lu_panel.cu), the rest by cuBLAS
  /// GEMMs (src/numeric/cuda/lu_fronts.cu); a front is kept where restricted partial
  /// pivoting would have interchanged no row and no pivot needs static pivoting, and is
  /// otherwise assembled again and factored by cuSOLVER GETRF with pivoting. 0: every
  /// front to cuSOLVER GETRF without pivoting first and two cuBLAS TRSMs, one front at a
  /// time. Default 256; at least 0.
  index_t gpu_lu_strip_pivots = 256;
  /// CUDA backend under a device_memory_limit, when some front is over the budget and is
  /// factored through the device in pieces (a "tiled" front): the device pool, where
  /// fronts are factored, is made at least this share of the limit, in [0, 1). The pieces
  /// of a tiled front grow with the pool — the traffic of its factorization falls about
  /// as 1 / pool — while the rest of the limit holds contribution blocks, which spill to
  /// pinned host memory when it is short. 0: the pool is the largest batch of fronts that
  /// fit (the plan's own size). Outside [0, 1): InvalidInput.
  double gpu_tiled_pool_share = 0.0;
  /// CUDA backend, a Cholesky front over the device budget (src/numeric/cuda/tiled_llt.cu):
  /// the earlier pivot columns streamed against a slab, and another tile row's rows of L21
  /// streamed against a tile, come in pieces of at most this many columns, so that the
  /// slab and the tiles that stay on the device can be wider — fewer passes over the
  /// front's columns, at the price of narrower products. 0: pieces as wide as the slab (a
  /// third of the pool each) and whole rows of L21. Default 256; at least 0.
  index_t gpu_tiled_stream_columns = 256;
  /// CUDA backend, Cholesky fronts over the device budget: the host assembles the next
  /// such front of the same level on a thread of its own while the device factors the
  /// current one and the fronts between them (src/numeric/cuda/tiled_llt.cu). Costs a
  /// second pinned buffer the size of the largest such front's panel. Default on.
  bool gpu_tiled_prefetch = true;
  /// CUDA backend, Cholesky: a front with more pivots than gpu_panel_kernel_max_pivots
  /// and than this gets its pivot block and panel in column blocks of this width (POTRF
  /// of each diagonal block, TRSM of the rows below it, SYRK and GEMM of the remaining
  /// pivot columns, src/numeric/cuda/llt_blocked.cu) instead of one POTRF and one TRSM of
  /// all k pivots. 0: one POTRF and one TRSM. Default 0; at least 0.
  index_t gpu_potrf_block_size = 0;
  /// CUDA backend, Cholesky: a front with more pivots than gpu_panel_kernel_max_pivots
  /// (and every slab of a front factored tile by tile) gets its pivot block and panel by
  /// recursion on the pivot columns (src/numeric/cuda/llt_recursive.cu: 64-column base
  /// cases of strata's own, everything else cuBLAS SYRK and GEMM; Gustavson & Jonsson,
  /// IBM J. Res. Dev. 44(6), 2000) instead of cuSOLVER POTRF and cuBLAS TRSM (or the
  /// column blocks of gpu_potrf_block_size, which it takes precedence over). Default on.
  bool gpu_recursive_panel = true;
  /// CUDA backend: the device solve's sweeps (its gather, small-front, library and scatter
  /// launches over every level) are recorded once as a CUDA graph per analysis and number
  /// of right-hand sides and replayed with one launch per solve
  /// (src/numeric/cuda/cuda_solve.cu); false launches them one by one at every solve.
  /// The same bits either way. Default on.
  bool gpu_solve_graph = true;
  /// CUDA backend: the device solve's subtrees and the bottom levels of small fronts
  /// above them run as one launch per sweep whose thread blocks wait on the device for
  /// the fronts they read (a front starts when its children, or forward its parent, are
  /// done; src/numeric/cuda/solve_plan.hpp: plan_chain); false: one launch for the
  /// subtrees and one per level. The plan differs (the planner prices the chain), so the
  /// results agree to rounding, not bit for bit; each is the same on every run. Default on.
  bool gpu_solve_chain = true;
  /// CUDA backend: a checked solve (solve_check) with the factor resident on the GPU
  /// computes its residuals b − A·x and backward errors there and refines there
  /// (src/numeric/cuda/residual.cu); only GMRES, where refinement stalls, runs on the host.
  /// A's values are read from a copy on the device: with solve_check always, a
  /// factorization's value pass on the GPU keeps one (8 bytes per entry of A); otherwise the first
  /// checked solve after a factorization copies them there. false: the residuals on the
  /// host, each refinement step's solve on the device. Default on.
  bool gpu_refinement = true;
  /// CUDA backend on several GPUs (num_gpus > 1): a solve runs part by part on the GPUs
  /// that hold the parts' panels, only the parts' rows of x and their contribution to the
  /// part above crossing the bus (src/numeric/cuda/part_solve.cu); false copies every
  /// panel to host memory at the first solve after a factorization and solves there. The
  /// same solution to rounding either way. Default on.
  bool gpu_solve_parts = true;

  // --- several GPUs (docs/multigpu.md) ---
  /// GPUs the CUDA backend factors on; 0 means every visible GPU (default 0). With more
  /// than one, the assembly tree is split into subtrees that the GPUs factor concurrently,
  /// then the top of the tree is factored on the first GPU. Asking for more GPUs than are
  /// visible is an InvalidInput error at analyze (with no GPU at all, the factorization
  /// raises NotSupported instead). Ignored by the CPU backend.
  int num_gpus = 0;
  /// Subtrees per GPU in that split, at least (the paper's "additional sub-trees"): more
  /// gives the largest-first assignment and work stealing finer pieces to balance with,
  /// at the cost of a larger top part and of smaller parts, which batch worse on a GPU
  /// (each part is factored by levels on its own); the split still makes more subtrees
  /// wherever that lowers its estimate. Default 1; at least 1.
  int subtrees_per_gpu = 1;
  /// With several GPUs and nested dissection: balance the top ⌈log₂(GPUs × subtrees)⌉
  /// bisections by estimated factorization work instead of vertex count (the paper's
  /// "balanced graph bisection"); it costs ordering time (docs/multigpu.md). Default off.
  bool balance_by_work = false;
  /// With several GPUs: a GPU whose queue of subtrees is empty takes an unstarted subtree
  /// from the most loaded queue (default on).
  bool work_stealing = true;
  /// With several GPUs: split the top part above the subtrees again into "upper layers"
  /// of independent subtrees, each part factored by the GPU that the analysis's list
  /// schedule finishes it on first, as soon as the parts below it are done, instead of
  /// factoring the whole top part on one GPU (default on; docs/multigpu.md).
  /// The distributed solver (several MPI ranks) does not use upper layers.
  bool split_top = true;
  /// With several GPUs: a front of the top part, factored by GPU 0 while the other GPUs
  /// have nothing left to do (upper parts run while other GPUs may still work, so they
  /// are not split), whose contribution block has at
  /// least this many rows has its update — the SYRK (LLᵀ) or GEMM (LU) where a large
  /// front's flops are — split by column strips over its GPU and those idle GPUs; the
  /// pivot block and panel stay on its GPU, and each strip travels to its GPU and back
  /// (peer copies). 0 turns this off. LDLᵀ fronts, fronts of at most
  /// gpu_panel_kernel_max_pivots pivots and fronts factored tile by tile are not split.
  /// Default 0 (off); at least 0.
  index_t split_front_min_cb = 0;
  /// With several GPUs: a Cholesky front of the top part with at least this many rows is
  /// factored whole — pivot block, panel and update — by GPU 0 and the idle GPUs
  /// together, its columns dealt out in blocks of distributed_front_block_size (1-D
  /// block-cyclic, right-looking with one step of lookahead;
  /// src/numeric/cuda/distributed_front.cu); it takes precedence over split_front_min_cb
  /// for the fronts it covers. Not distributed: LU and LDLᵀ fronts, fronts of at most
  /// gpu_panel_kernel_max_pivots pivots, fronts factored tile by tile, and every front
  /// under a device_memory_limit (the panel slots, 2 × rows × block doubles per GPU, would
  /// be memory beside the budget). 0 turns this off. Default 1024; at least 0.
  index_t distributed_front_min_rows = 1024;
  /// Columns per block of a distributed front (distributed_front_min_rows): smaller
  /// blocks make each step's serial pivot block cheaper but add steps and shrink the
  /// blocks' DGEMMs. Default 512; at least 64.
  index_t distributed_front_block_size = 512;
  /// For `general`: permute large entries onto the diagonal by a maximum weighted
  /// matching and scale rows and columns (MC64-style, Duff & Koster 2001). For
  /// `symmetric_indefinite`: the symmetric scaling D·A·D from the same matching and the
  /// 2×2 pivot pairs it suggests, kept together by the ordering and in one front (Duff &
  /// Pralet 2005). Computed from the values given at analysis and reused by every
  /// refactorization. Default on.
  bool matching_and_scaling = true;
  /// For `symmetric_indefinite` with matching_and_scaling: a pair (i, j) of the matching
  /// is kept as a 2×2 pivot candidate only when one of its scaled diagonal entries has
  /// magnitude below this (structurally zero counts as 0); ≤ 0 keeps no pair (scaling
  /// only). Default 0.01.
  double pairing_threshold = 0.01;
  /// Static pivoting: a pivot with |d| < static_pivot_epsilon · ‖A‖₁ (after scaling) is
  /// replaced by ±static_pivot_epsilon · ‖A‖₁ and counted in FactorStats (default 1e-8 ≈ √ε, as in
  /// SuperLU_DIST and MUMPS).
  double static_pivot_epsilon = 1e-8;
  /// Delayed pivoting (LU and LDLᵀ: MatrixType::general and symmetric_indefinite;
  /// numeric/delayed.hpp): fronts refuse pivots below pivot_threshold times their column's
  /// largest entry (LDLᵀ: 1×1 or 2×2 pivots by MA57's test) and pass them to their parent
  /// (MUMPS, MA57), so static pivots remain only where the matrix is numerically
  /// singular. automatic (default) factors in the analysis's fixed order first and runs
  /// the delayed factorization only when that needed static pivots; delayed always runs
  /// it (a Newton loop whose values keep drifting from the analysis's); fixed never does.
  /// Each choice depends on the values alone, never on earlier factorizations, so a run
  /// restarted from a checkpoint repeats the uninterrupted one bit for bit. Delayed
  /// pivoting runs on the host, after the fixed-order factorization of one executor or of
  /// several workers (GPUs) alike; the distributed solver keeps the fixed order.
  ///
  /// corrected (LU only; symmetric indefinite matrices as automatic): every factorization in
  /// the analysis's fixed order, where the factor lives (a GPU's too). Where that order
  /// needs static pivots, the entries of B at those k pivots get +1 (B's entries are at
  /// most about 1) and B is factored again, so the factor is of A + E with E of rank k and
  /// known exactly; each solve then corrects x = (A + E)⁻¹b to A⁻¹b by the
  /// Sherman–Morrison–Woodbury formula (Golub & Van Loan, "Matrix Computations", 4th ed.,
  /// §2.1.4): k solves and a k×k LU at the factorization, one k-column product per solve.
  /// Delayed pivoting on the host instead when more than max_corrected_pivots are needed,
  /// the k×k matrix is singular to working precision (A numerically singular), or
  /// the corrected solve of a fixed probe b = A·x̂ misses the backward error that a checked
  /// solve must reach (max(refinement_tolerance, (m+1)·u), m the most entries in a row) within
  /// one step of refinement.
  /// Corrected solves are always checked and refined. The choice depends on the values
  /// alone, as automatic's does.
  Pivoting pivoting = Pivoting::automatic;
  /// Pivoting::corrected: the most static pivots corrected by the solve's low-rank update
  /// (each costs one more solve at the factorization). Default 64.
  index_t max_corrected_pivots = 64;
  /// The relative threshold u of delayed pivoting, in (0, 1]: a pivot is taken when it is
  /// at least u times the largest entry of its column (|L| ≤ 1/u). Default 0.01.
  double pivot_threshold = 0.01;
  /// LU in the analysis's fixed order (every factorization unless delayed pivoting runs):
  /// the relative threshold u, in (0, 1], of its threshold partial pivoting with a
  /// preference for the diagonal (UMFPACK's diagonal pivot tolerance; Duff, Erisman & Reid,
  /// "Direct Methods for Sparse Matrices", 2nd ed., §5.4): column j of a front keeps its
  /// diagonal pivot when |a_jj| ≥ u·max |a_ij| over the front's fully summed rows i ≥ j,
  /// and otherwise takes the largest of those entries, the first on ties; so |L| ≤ 1/u
  /// there. 1: partial pivoting restricted to the fully summed rows. After the matching has
  /// put large entries on the diagonal, u < 1 leaves most fronts without interchanges, which
  /// the CUDA backend exploits (a large front is eliminated without interchanges first and
  /// kept when no multiplier exceeds 1/u). Default 0.1.
  double diagonal_pivot_threshold = 0.1;

  // --- solve ---
  /// When the solve computes the backward error of its solution (one product with A per
  /// right-hand side) and refines it. always (default): every solve.
  /// after_perturbed_pivots: only after a factorization that perturbed pivots or corrected
  /// them (Pivoting::corrected: the low-rank correction is not backward stable); otherwise
  /// x is the factor's solution as it is (no product with A, no refinement) and
  /// SolveStats::backward_error is NaN (not computed). For callers that check their
  /// solutions themselves: a Newton iteration recomputes its residual at the next iterate
  /// anyway (as MUMPS without ICNTL(10)/ICNTL(11), and cuDSS, which do not refine or
  /// check unless asked).
  SolveCheck solve_check = SolveCheck::always;
  /// Most iterative refinement steps after the first solve (default 10; 0 disables).
  int refinement_max_steps = 10;
  /// Refinement stops once the backward error ‖b−Ax‖∞ / (‖A‖∞‖x‖∞ + ‖b‖∞) is at or below
  /// this value, or stops decreasing by at least half per step (default 1e-15).
  double refinement_tolerance = 1e-15;
  /// When refinement stalls above the tolerance (typically after perturbed pivots), GMRES
  /// right-preconditioned by the factorization continues for at most this many iterations
  /// (restarted every 50; default 200; 0 disables).
  int gmres_max_iterations = 200;
};

// --- one vocabulary for every interface (CLI, C API, Python, model runs) ---

/// The canonical name of a value (a static string): MatrixType "auto", "spd",
/// "symmetric_indefinite", "general"; OrderingMethod "nd", "metis", "amd", "natural", "auto",
/// "user"; Backend "auto", "cpu", "cuda"; Pivoting "fixed", "automatic", "delayed"; SolveCheck
/// "always", "after_perturbed_pivots".
const char* to_string(MatrixType value);
const char* to_string(OrderingMethod value);
const char* to_string(Backend value);
const char* to_string(Pivoting value);
const char* to_string(SolveCheck value);

/// Parses a value's name into *out: the canonical names of to_string and the aliases
/// "automatic" (MatrixType, Backend), "ldlt" and "sym" (symmetric_indefinite), "lu"
/// (general), "nested_dissection" (nd), "gpu" (cuda), "auto" (Pivoting::automatic).
/// OrderingMethod::user is set by giving Options::user_permutation, not by name. Throws
/// InvalidInput naming the option ("type", "ordering", "device", "pivoting",
/// "solve_check"), the names accepted and the text given; *out is then unchanged.
void parse(std::string_view text, MatrixType* out);
void parse(std::string_view text, OrderingMethod* out);
void parse(std::string_view text, Backend* out);
void parse(std::string_view text, Pivoting* out);
void parse(std::string_view text, SolveCheck* out);

/// The names parse accepts for E (canonical names first, then the aliases), e.g. for a
/// command line's list of choices. E is one of the enums above.
template <class E>
std::vector<std::string> option_names();

/// Sets the field of `options` called `name` — its name in Options ("ordering",
/// "pivot_threshold", "num_gpus", ...; "device" is an alias of "backend") — from text: an
/// enum's name as parse takes it, a whole number, a number, or for a flag "true"/"false"
/// ("on"/"off", "1"/"0"). user_permutation has no text form. Throws InvalidInput naming
/// the option for an unknown name or a value that does not parse (options unchanged);
/// ranges are validate's. The generic setter behind `strata simulate --solver-option`,
/// strata.simulate(solver_options=...) and the C API's strata_set_option.
void set_option(Options& options, std::string_view name, std::string_view value);

/// The text of the field called `name` (as set_option reads it: enums by their canonical
/// names, numbers in full precision, flags "true"/"false"). Throws InvalidInput for an
/// unknown name.
std::string get_option(const Options& options, std::string_view name);

/// The names set_option knows, in the order of Options' fields.
std::vector<std::string> option_fields();

/// Checks every field against its documented range and throws InvalidInput naming the
/// first field out of range ("Options::pivot_threshold must be in (0, 1] (got 0)"); the
/// analysis calls it. Values that need the matrix (user_permutation, num_gpus against the
/// GPUs visible) are checked at analysis.
void validate(const Options& options);

}  // namespace strata
