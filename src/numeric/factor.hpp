// strata — the numeric factor and the executor interface every backend implements.
//
// One algorithm, several executors (DESIGN.md §4): the driver in numeric/multifrontal.cpp
// walks the memory plan batch by batch and hands each batch to an Executor, which
// assembles, factors and stores its fronts. The CPU executor runs the fronts of a batch
// on host threads with BLAS/LAPACK; the CUDA executor (numeric/cuda) runs them as
// batched launches. Both fill the same NumericFactor, so the solve and every test can
// compare them entry by entry.
//
// An executor always factors a *part* of the tree with the part's own level schedule,
// batches and contribution-block arena: the whole tree (one executor), or one subtree or
// an upper part or the top part of a schedule::TreePartition (several executors, one per
// worker, driven by numeric/multi_device.cpp). Contribution blocks cross from one part
// to the part of the root's parent through export_cb / import_cb.
#pragma once

#include <cmath>
#include <exception>
#include <functional>
#include <memory>
#include <vector>

#include "analysis/analysis.hpp"
#include "base/device.hpp"
#include "numeric/pivot_stats.hpp"
#include "numeric/static_pivot.hpp"
#include "strata/errors.hpp"
#include "strata/options.hpp"
#include "strata/stats.hpp"

namespace strata::numeric {

/// A part of a factor held by the executor that computed it: the panels of the tree's
/// part `part` (PartView::id: -1 the whole tree, else a part of an.partition) in the
/// memory of worker `worker`'s executor (the index of that executor in the list the
/// factorization ran with: 0 for a whole-tree factorization).
/// A factorization's rescaling (core/rescale.hpp) as Executor::solve_original takes it:
/// row and col, n each in the original numbering, or null for none; `id` names their
/// values (a new id whenever they change, 0 for none), so an executor may keep the copy
/// it made for an earlier solve of the same factorization.
struct RescaleView {
  const double* row = nullptr;
  const double* col = nullptr;
  std::uint64_t id = 0;
};

/// What a solve whose right-hand sides b and solutions x lie in GPU memory found there
/// (Executor::solve_gpu_arrays; the host does not read them): the first entry of b
/// (column-major index) that is not finite, −1 for none (x is then left as it was); the same
/// for x; and the largest magnitudes of b and x (the solve's condition estimate).
struct GpuArrayCheck {
  std::int64_t b_not_finite = -1, x_not_finite = -1;
  double b_max = 0, x_max = 0;
};

/// A matrix's values for Executor::residual: `host` (the canonical entry order of the
/// analysis's pattern) named by `id`, a number that changes whenever they do; host null
/// for the values the executor's last factorization kept on its device.
struct MatrixValues {
  const double* host = nullptr;
  std::uint64_t id = 0;
};

struct HeldPanels {
  int part = -1;
  int worker = 0;
};

/// The factor of one matrix, in the tree numbering of its Analysis.
///   panels:     front f's first k columns (n_rows×k column-major: L11 or L11\U11 packed,
///               then L21) at factor_layout.panel_offset[f]; for LU the k×(n_rows−k) U12
///               follows. LDLᵀ: L11 is unit lower with zeros in the (j+1, j) places of
///               2×2 pivots; D is kept apart in d_diag / d_off.
///   rows:       row indices of each front with its local pivot permutation applied to
///               the first k (same offsets as AssemblyTree::rows).
///   d_diag, d_off: LDLᵀ only, by pivot position: D(j,j) and, for the first column of a
///               2×2 pivot, D(j+1,j) (pivot_size[j] == 2 there, 0 on the second column).
///   held:       the parts of the factor whose panels stayed in the memory of the executor
///               that computed them (a GPU's, Executor::keeps_panels): their place in
///               `panels` is not written — `panels` may be empty — until fetch_panels
///               copies them there. Empty: every panel is in `panels`.
struct NumericFactor {
  MatrixType type = MatrixType::automatic;
  std::vector<double> panels;
  std::vector<HeldPanels> held;
  std::vector<index_t> rows;
  std::vector<double> d_diag;
  std::vector<double> d_off;
  std::vector<int> pivot_size;
  std::vector<PivotStats> front_stats;  ///< per front, merged in front order
  /// LU, by pivot position (tree numbering, n entries): where static pivoting replaced the
  /// pivot, 1 when the new pivot is positive and 2 when it is negative, else 0 — written by the
  /// executors for the fronts whose front_stats count perturbed pivots only (the other fronts'
  /// entries are left as they were). The pivot of position first_pivot[f] + j is in row
  /// rows[row_offsets[f] + j].
  std::vector<unsigned char> static_pivot_at;
  bool valid = false;
};

/// Records in factor.static_pivot_at which of a front's k pivots static pivoting replaced
/// (is_static_pivot; pivot i at diag[i·stride], the front's first pivot position is
/// `first`). For a front whose PivotStats count perturbed pivots.
inline void mark_static_pivots(const double* diag, index_t stride, index_t k, index_t first,
                               double static_pivot, NumericFactor& factor) {
  for (index_t i = 0; i < k; ++i)
    factor.static_pivot_at[first + i] =
        is_static_pivot(diag[i * stride], static_pivot) ? (diag[i * stride] < 0 ? 2 : 1) : 0;
}

/// The part of the tree an executor is factoring: its level schedule, the batches of its
/// memory plan (positions index schedule->fronts) and its arena layout.
struct PartView {
  /// -1: the whole tree; else the part's id in an.partition (schedule::TreePartition):
  /// 0..P-1 subtree, P the top part, P+1+k upper part k
  int id = -1;
  const symbolic::LevelSchedule* schedule = nullptr;
  const std::vector<BatchInfo>* batches = nullptr;
  const CbLayout* cb_layout = nullptr;

  /// The whole tree: an.schedule, an.plan.batches, an.cb_layout.
  static PartView whole(const Analysis& an);
  /// A part of an.partition with id `id` (TreePartition::part(id)).
  static PartView of(const schedule::FactorPart& p, int id);
};

class Executor;

/// What a value pass on a device (Executor::scale_values_on_device) found: the figures a
/// factorization needs before it starts, of the values as given (A) and as scaled by the
/// analysis's matching scaling (B = Dr·A(:,Q)·Dc); the host's pass (core/value_pass.hpp)
/// computes the same.
struct DeviceValueNorms {
  bool finite = true;         ///< every value is finite
  bool sums_finite = true;    ///< every row and column magnitude sum of A is finite
  double norm_inf = 0;        ///< ‖A‖∞ (max row sum of |a|, symmetric storage expanded)
  double scaled_norm1 = 0;    ///< ‖B‖₁ (max column sum of |b|)
  bool equilibrated = false;  ///< every row and column maximum of |b| is 0 or in [½, 2]
  /// Equilibration sweeps the pass made on B (core/rescale.hpp, as rescale_values makes
  /// them; 0: none asked or none needed), and their factors (powers of two, n each,
  /// original numbering) when it made any: B, ‖B‖₁ and `equilibrated` are then of
  /// diag(row_rescaling)·B·diag(col_rescaling).
  int rescaling_sweeps = 0;
  std::vector<double> row_rescaling, col_rescaling;
  /// The pass was asked to copy the values as given (copy_input) and had the device
  /// memory for it: Executor::keep_device_input can keep them.
  bool input_copied = false;
};

/// Called by a StageValues for each piece of the staging buffer it has filled: entries
/// [begin, end) are in place. Pieces are disjoint and may be reported from several of
/// the caller's threads at once.
using StagedPiece = std::function<void(std::size_t begin, std::size_t end)>;

/// Fills entries [begin, end) of a value pass's staging buffer (Executor::
/// scale_values_on_device), reporting each filled piece to `done` as soon as it is in
/// place (on the caller's threads), and returns when all of them are.
using StageValues =
    std::function<void(std::size_t begin, std::size_t end, const StagedPiece& done)>;

/// How a factorization chooses and repairs its pivots: the numeric side of
/// Options::static_pivot_epsilon and Options::diagonal_pivot_threshold.
struct PivotPolicy {
  /// Static pivoting's threshold, absolute: a pivot below |static_pivot| in magnitude is
  /// replaced (numeric/static_pivot.hpp: by ±static_pivot when it is positive, shifted by
  /// ±kCorrectedPivotShift when it is negative, LU only: Pivoting::corrected) and counted
  /// in PivotStats; 0: none.
  double static_pivot = 0;
  /// LU in the analysis's fixed order, threshold partial pivoting among the fully summed
  /// rows (Duff, Erisman & Reid, "Direct Methods for Sparse Matrices", 2nd ed., §5.4):
  /// column j keeps its diagonal pivot when |a_jj| ≥ u·max_{j≤i<k} |a_ij|, else takes the
  /// largest of those entries (the first on ties), so |L| ≤ 1/u in the fully summed rows.
  /// u in (0, 1]; 1 is partial pivoting restricted to the fully summed rows.
  double threshold = 1;
  PivotPolicy() = default;
  /// A static pivot with u = 1 unless given (implicit: a bare static pivot is this policy).
  PivotPolicy(double sp, double u = 1) : static_pivot(sp), threshold(u) {}  // NOLINT
};

/// Everything an executor needs to factor a batch.
struct FactorContext {
  const Analysis* analysis = nullptr;
  const double* values = nullptr;  ///< scaled values of the canonical input (entry order)
  /// The executor's device already holds the scaled values (its scale_values_on_device
  /// ran for this factorization): `values` is not read.
  bool values_on_device = false;
  /// The same scaled values (an.pattern_indices.size() of them, canonical entry order) in
  /// the memory of GPU `device_values_device`, or null: a GPU executor copies them from
  /// there, device to device, instead of uploading `values`, which then needs to hold only
  /// what the executors that read values on the host read (Executor::reads_host_values);
  /// the executor whose own buffer they are copies nothing. Distributed ranks receive
  /// their share of the values there (src/distributed); with several GPUs in one process
  /// they are the value pass's result on the first GPU (Executor::device_scaled_values).
  const double* device_values = nullptr;
  int device_values_device = -1;
  MatrixType type = MatrixType::spd;
  double static_pivot = 0;              ///< absolute threshold / replacement for tiny pivots
  double diagonal_pivot_threshold = 1;  ///< LU's u (PivotPolicy::threshold)
  NumericFactor* factor = nullptr;
  std::vector<double>* cb_arena = nullptr;  ///< host arena of the part (host executors)
  const PartView* part = nullptr;           ///< set from begin_part to end_part
  /// Several workers: an executor may keep the panels of the parts it factors in its own
  /// memory (Executor::keeps_panels; fetch_panels brings them to the host). A whole-tree
  /// factorization leaves that choice to the executor.
  bool keep_part_panels = false;
  /// Several workers: executors that have no part of their own while this part runs (the
  /// top part: every other worker, all of whose parts are done; subtrees and upper parts
  /// get none, since no worker is known to be idle then). The part's executor may use them for its
  /// large fronts (the CUDA executor: the update split by column strips,
  /// Options::split_front_min_cb) and must be done with them when end_part returns.
  std::vector<Executor*> helpers;
};

/// How the host buffers of contribution blocks in transit are allocated: new[] by
/// default; a GPU executor lends page-locked memory, which its copies to and from the
/// device move at the bus's full rate (Executor::transfer_memory). `allocate` may return
/// nullptr (no page-locked memory to spare): new[] is used then.
struct TransferMemory {
  double* (*allocate)(std::size_t doubles) = nullptr;
  void (*release)(double* p) = nullptr;
};

/// Frees a transfer buffer as it was allocated (TransferMemory::release, else delete[]).
struct TransferBufferDelete {
  void (*release)(double* p) = nullptr;
  void operator()(double* p) const {
    if (release)
      release(p);
    else
      delete[] p;
  }
};
using TransferBuffer = std::unique_ptr<double[], TransferBufferDelete>;

/// A contribution block on its way from the part that produced it (a subtree or an upper
/// part) to the part of its parent (an upper part or the top part).
/// The driver provides host_buffer() (size doubles); an exporter either fills it, or — a device
/// executor whose importer can read its memory directly (peer access) — leaves the block
/// in its own memory, valid until its end(), and sets `device` and `device_ordinal`.
struct CbTransfer {
  index_t front = -1;              ///< the part root whose block this is
  std::size_t size = 0;            ///< doubles: cb_size(front)², column-major (0: no block)
  double* host = nullptr;          ///< the host buffer of `size` doubles, once host_buffer()
  bool on_host = false;            ///< the exporter filled `host`
  const double* device = nullptr;  ///< or: the block in the exporter's device memory
  int device_ordinal = -1;         ///< CUDA device holding `device`
  /// With `device`: an event of the device runtime (CUDA: a cudaEvent_t of the exporter's
  /// device) that completes once `device` holds the block, for a copy still in flight when
  /// export_cb returned; null: it holds it then.
  void* device_ready = nullptr;
  int target_device = -1;  ///< CUDA device of the importer (-1: a host executor)
  TransferMemory memory;   ///< how host_buffer() allocates
  TransferBuffer host_storage;

  /// The host buffer (`size` doubles, uninitialized), allocated on first use: a block
  /// that goes device to device never needs one — allocating (and zeroing) every subtree
  /// root's block up front cost more than the multi-GPU factorization itself.
  double* host_buffer() {
    if (!host) {
      double* p = memory.allocate ? memory.allocate(size) : nullptr;
      host_storage = p ? TransferBuffer(p, TransferBufferDelete{memory.release})
                       : TransferBuffer(new double[size]);
      host = host_storage.get();
    }
    return host;
  }
};

/// Statistics of one executor over a multi-worker factorization.
using DeviceStats = strata::DeviceStats;

/// A backend that factors batches of fronts. Implementations: CpuExecutor, CudaExecutor.
class Executor {
 public:
  virtual ~Executor() = default;
  /// A name for reports ("cpu", "cuda", a test's own).
  virtual const char* name() const = 0;
  /// The backend it is (FactorStats::backend): Backend::cuda for a device executor.
  virtual Backend backend() const { return Backend::cpu; }
  /// The CUDA device this executor runs on; -1 for a host executor.
  virtual int device() const { return -1; }
  /// Whether the driver must size FactorContext::cb_arena (host memory) for this executor.
  /// A device executor keeps its contribution blocks in its own memory: sizing (and
  /// zero-filling) a host arena of several GB for it cost seconds of the first
  /// factorization and was never read.
  virtual bool uses_host_arena() const { return true; }
  /// How the host buffers of the contribution blocks this executor exports or imports
  /// through host memory are allocated (see TransferMemory); the default: new[].
  virtual TransferMemory transfer_memory() const { return {}; }
  /// Optional set-up for the analysis `an` ahead of its first factorization, for a
  /// factorization by `workers` executors (1: the whole tree on this one): what a device
  /// executor would otherwise do at the start of the first factorization (upload the
  /// analysis arrays, plan and allocate its memory, create streams and library handles).
  /// Solver::analyze calls it, as cuDSS's analysis phase prepares the device. Throws what
  /// that set-up throws (OutOfMemory, DeviceError); the default does nothing.
  virtual void prepare(const Analysis& an, int workers) {}
  /// The value pass of a factorization on the executor's device: `values` (the analysis's
  /// canonical entry order; host memory, page-locked for a fast copy, or device memory)
  /// copied there, checked,
  /// scaled by the analysis's matching scaling, equilibrated again by at most
  /// `max_sweeps` sweeps when B is not within a factor 2 of equilibrium (0: not; see
  /// DeviceValueNorms) and measured there (`out`), and kept for
  /// the factorizations that follow with FactorContext::values_on_device, until the next
  /// call or analysis. When `stage` is set it fills `values` and each piece goes up as
  /// soon as stage reports it in place, so that the caller's filling of the buffer
  /// overlaps the copies. `copy_input`: the values as given are also copied, on the
  /// device, before they are scaled, where keep_device_input can keep them
  /// (out.input_copied: there was room). Returns false, having called nothing and changed
  /// nothing, where the executor has no such pass: host executors, or a plan whose fronts
  /// read the values on the host (fronts factored tile by tile). Throws DeviceError, as
  /// factorize.
  virtual bool scale_values_on_device(const Analysis& an, const double* values,
                                      const StageValues& stage, int max_sweeps, bool copy_input,
                                      DeviceValueNorms& out) {
    return false;
  }
  /// Makes the values the last scale_values_on_device copied as given (copy_input) the
  /// executor's kept input for `an`, in place of those kept before: a factorization
  /// accepted them. False, having done nothing, where there is no such copy for `an`.
  virtual bool keep_device_input(const Analysis& an) { return false; }
  /// The kept input (keep_device_input) copied into `host` (an.pattern_indices.size()
  /// values). False, having done nothing, where the executor keeps none for `an` (another
  /// analysis since, or its device memory released). Throws DeviceError.
  virtual bool download_device_input(const Analysis& an, double* host) { return false; }
  /// The scaled values the last scale_values_on_device left on the device (B in the
  /// analysis's canonical entry order, an.pattern_indices.size() of them) copied into
  /// `host`, for a host algorithm that needs them (the delayed LU). False, having done
  /// nothing, where the executor holds none for `an`. Throws DeviceError.
  virtual bool download_scaled_values(const Analysis& an, double* host) { return false; }
  /// Sets up the value pass (scale_values_on_device) for `an` on an executor prepared for
  /// several workers, whose prepare leaves it out: with several GPUs in one process one of
  /// them scales the values and the others copy its result (device_scaled_values). Call
  /// after prepare. Returns whether the pass is ready; false, having changed nothing, where
  /// the executor has no such pass or its device has no room for its arrays. Throws
  /// DeviceError.
  virtual bool prepare_shared_value_pass(const Analysis& an) { return false; }
  /// The scaled values the last scale_values_on_device left on this executor's device
  /// for `an` (device memory, an.pattern_indices.size() doubles), once the pass's work on
  /// them is done (it waits for that); null where the executor holds none for `an`. They
  /// stay until its next value pass or analysis. Throws DeviceError.
  virtual const double* device_scaled_values(const Analysis& an) { return nullptr; }
  /// Whether this executor's factorizations of the analysis it was last prepared for
  /// read FactorContext::values on the host even when FactorContext::device_values is
  /// given: host executors, and a GPU whose plan factors some front tile by tile (their
  /// assembly runs on the host) or that has no plan yet.
  virtual bool reads_host_values() const { return true; }
  /// Called once per factorization, before this executor's first part (ctx.part unset).
  virtual void begin(const FactorContext& ctx) {}
  /// Called before the batches of the part ctx.part.
  virtual void begin_part(const FactorContext& ctx) {}
  /// Assembles (original entries + extend-add of children's contribution blocks),
  /// factors and stores the fronts ctx.part->schedule->fronts[batch.begin .. batch.end).
  /// Throws NotPositiveDefinite (original column) for a failed Cholesky pivot.
  virtual void factor_batch(const FactorContext& ctx, const BatchInfo& batch) = 0;
  /// After begin_part of a whole-tree factorization (ctx.part->id == -1): factors the
  /// whole tree in an order of the executor's own and returns true, or returns false to be
  /// handed the memory plan's batches (factor_batch). The CPU executor runs the tree
  /// depth-first with its contribution blocks on a stack (schedule/stack_plan.hpp), sizing
  /// ctx.cb_arena itself. Throws as factor_batch.
  virtual bool factor_tree(const FactorContext& ctx) { return false; }
  /// Called after the last batch of the part ctx.part.
  virtual void end_part(const FactorContext& ctx) {}
  /// After the part's last batch and before end_part: hands out the contribution block of
  /// the part's root t.front (see CbTransfer). Returns the bytes moved.
  virtual std::size_t export_cb(const FactorContext& ctx, CbTransfer& t) = 0;
  /// After begin_part of the part that consumes it, before its first batch: places the
  /// block of child t.front (outside the part) in the part's arena. Returns the bytes moved.
  virtual std::size_t import_cb(const FactorContext& ctx, const CbTransfer& t) = 0;
  /// Called once per factorization, after this executor's last part.
  virtual void end(const FactorContext& ctx) {}
  /// Solves with `fac` where this executor keeps it (the CUDA executor, when the factor
  /// stayed resident on the device): x as solve_in_place. Returns false when it cannot
  /// (the caller then runs solve_in_place on the host); the default cannot.
  virtual bool solve(const Analysis& an, const NumericFactor& fac, double* x, index_t nrhs) {
    return false;
  }
  /// solve for right-hand sides in the analysis's original numbering: x = A⁻¹ b for b and
  /// x host arrays of n × nrhs (column-major; they may not alias), the analysis's
  /// permutation and matching scaling and the factorization's rescaling (`rescale`)
  /// applied where the factor is, around the triangular solves; b and x move through `stage`
  /// (page-locked host memory of n × nrhs doubles) unless they are page-locked themselves. Returns
  /// false, having done nothing, where solve would return false (the caller then permutes and
  /// scales on the host and calls solve); the default does.
  virtual bool solve_original(const Analysis& an, const NumericFactor& fac, const double* b,
                              double* x, index_t nrhs, const RescaleView& rescale, double* stage) {
    return false;
  }
  /// solve_original for b and x in the GPU memory of this executor's device (cudaMalloc;
  /// n × nrhs column-major, not aliasing), with nothing through the host: b is checked on
  /// the device and x written only when every entry of b is finite, x checked after
  /// (`check`). Work on the legacy default stream that writes b is complete before b is
  /// read. With `check` null the solve is only enqueued: the host does not wait for it, and
  /// its check stays on the device until last_gpu_array_check reads it (a checked solve
  /// waits once, for its residual, instead of twice). Returns false, having done nothing,
  /// where solve_original would, or when b or x is not in this device's memory; the
  /// default does.
  virtual bool solve_gpu_arrays(const Analysis& an, const NumericFactor& fac, const double* b,
                                double* x, index_t nrhs, const RescaleView& rescale,
                                GpuArrayCheck* check) {
    return false;
  }
  /// Waits for the last solve_gpu_arrays and writes what it found to `check`. Throws
  /// InternalError where no such solve ran on this executor; the default does.
  virtual void last_gpu_array_check(GpuArrayCheck& check) {
    throw InternalError("last_gpu_array_check: this executor ran no solve of GPU arrays");
  }
  /// Device vectors for a checked solve with a factor resident on this executor's GPU
  /// (core/solve_phase.cpp): `count` doubles of its memory, kept until the next call, the
  /// next analysis or release. Null where it has none (no GPU, or no room for them).
  virtual double* refinement_workspace(std::size_t count) { return nullptr; }
  /// The residuals of a checked solve on this executor's GPU: r = b − A·x for nrhs columns
  /// (b, x, r: n × nrhs column-major in that GPU's memory, original numbering; r may not
  /// alias the others) with A the values `a` in the canonical entry order of an's pattern
  /// (a.host: host memory, copied to the device once per a.id; null: the values the last
  /// factorization kept on the device, keep_device_input), and per column c
  /// maxima[3c .. 3c+2] = ‖r_c‖∞, ‖x_c‖∞, ‖b_c‖∞ (host; a NaN's magnitude compares above
  /// +inf). Returns false, having done nothing, where it cannot (no device row map of the
  /// pattern, no room for A's values, no values kept). Throws DeviceError.
  virtual bool residual(const Analysis& an, const MatrixValues& a, const double* b, const double* x,
                        double* r, index_t nrhs, double* maxima) {
    return false;
  }
  /// A refinement step of column vectors of length n in this executor's GPU memory, in
  /// order with residual and solve_gpu_arrays: kept = x, then x += d; or, with `undo`,
  /// x = kept. Throws DeviceError.
  virtual void refinement_step(double* x, const double* d, double* kept, index_t n, bool undo) {
    throw InternalError("refinement_step: this executor holds no vectors on a GPU");
  }
  /// After begin_part: true when the panels of the part ctx.part will stay in the
  /// executor's memory only (a resident GPU factor of the whole tree; a part's panels kept
  /// on its GPU when FactorContext::keep_part_panels asks for it). The driver then records
  /// the part in NumericFactor::held and does not write its place in factor.panels. The
  /// default: the panels go to factor.panels.
  virtual bool keeps_panels(const FactorContext& ctx) const { return false; }
  /// Copies the panels of part `part` (HeldPanels::part) that this executor kept into
  /// their place in fac.panels, which the caller has sized to the whole factor. Throws
  /// InvalidState when it holds no such part for `an` (a later factorization or analysis
  /// replaced it).
  virtual void download_panels(const Analysis& an, int part, NumericFactor& fac) {
    throw InvalidState("download_panels: this executor holds no factor panels");
  }
  /// Whether solve_held_parts can run over `parts` (ids of an.partition, TreePartition::
  /// part) of `fac`: this executor holds their panels from its last factorization of
  /// this analysis, and can solve with them there. The default cannot.
  virtual bool can_solve_held_parts(const Analysis& an, const NumericFactor& fac,
                                    const std::vector<int>& parts) const {
    return false;
  }
  /// One sweep of the triangular solve over parts of `fac` that this executor holds,
  /// where they are (SPRAL SSIDS's numeric subtrees; cuda/part_solve.cu): `parts` of one
  /// layer of an.partition (independent of each other), `forward` the forward sweep (L)
  /// else the backward one (Lᵀ or U). x: host, n × nrhs column-major, tree numbering —
  /// forward reads the right-hand sides at the parts' pivot rows and writes the forward
  /// results there; backward reads those and the solution at the pivot rows of the fronts
  /// above the parts, and writes the solution at the parts' pivot rows. u: host, the update
  /// vectors of the whole tree (an.child_rows.offsets[f] is front f's, the arena's length
  /// offsets.back() per right-hand side, column-major) — forward reads those of the parts'
  /// children in other parts and writes those of the parts' fronts whose parent is in
  /// another part. Other entries of x and u are neither read nor written. Throws
  /// InternalError when can_solve_held_parts is false, DeviceError on a device failure.
  virtual void solve_held_parts(const Analysis& an, const NumericFactor& fac,
                                const std::vector<int>& parts, bool forward, double* x, double* u,
                                index_t nrhs) {
    throw InternalError("solve_held_parts: this executor holds no factor panels");
  }
  /// Adds backend figures of the last factorization (bytes moved, device time) to `fs`.
  virtual void report(FactorStats& fs) const {}
  /// Adds this executor's per-worker figures of the last factorization that the driver
  /// cannot see (fronts it split over helpers, strips it computed for others, their
  /// bytes) to `d`.
  virtual void report_worker(DeviceStats& d) const {}
};

/// The CPU executor; `threads` host threads (0: all hardware threads). `reproducible`:
/// large fronts too run single-threaded BLAS (see Options::reproducible).
std::unique_ptr<Executor> make_cpu_executor(int threads, bool reproducible = false);

/// The CUDA executor on CUDA device `device` (0-based ordinal); throws NotSupported in a
/// build without CUDA or when that device is not visible.
std::unique_ptr<Executor> make_cuda_executor(const Options& opts, int device = 0);

/// Host memory page-locked for transfers to the GPUs while the handle lives (CUDA:
/// cudaHostRegister with cudaHostRegisterPortable, undone by cudaHostUnregister). The
/// memory must outlive the handle and must not be reallocated under it.
class PinnedHostRange {
 public:
  PinnedHostRange(const void* p, std::size_t bytes) : p_(p), bytes_(bytes) {}
  virtual ~PinnedHostRange() = default;
  PinnedHostRange(const PinnedHostRange&) = delete;
  PinnedHostRange& operator=(const PinnedHostRange&) = delete;
  const void* data() const { return p_; }
  std::size_t bytes() const { return bytes_; }

 private:
  const void* p_;
  std::size_t bytes_;
};

/// Page-locks [p, p + bytes) (see PinnedHostRange). Returns nullptr in a build without
/// CUDA, without a visible GPU, for an empty range, or when the driver refuses (the
/// transfers then go from pageable memory, slower; nothing is reported).
std::unique_ptr<PinnedHostRange> pin_host_memory(void* p, std::size_t bytes);

/// Whether the host range [p, p + bytes) is page-locked for the GPUs (cudaMallocHost,
/// cudaHostAlloc, cudaHostRegister: cudaPointerGetAttributes reports host memory at its
/// first and its last byte), so that a copy to a device can read it directly. False in a
/// build without CUDA, without a visible GPU and for an empty range.
bool page_locked(const void* p, std::size_t bytes);

/// The CUDA device whose memory holds `p` (cudaMalloc: cudaPointerGetAttributes reports
/// device memory), or -1 for host memory (managed memory included: the host reads it), in
/// a build without CUDA and without a visible GPU.
int device_memory_of(const void* p);

/// host[0, n) = device[0, n), a copy from device memory (device_memory_of ≥ 0) that
/// returns when it is complete. Throws DeviceError; NotSupported in a build without CUDA.
void copy_from_device(double* host, const double* device, std::size_t n);

/// device[0, n) = host[0, n), the other way; the same errors.
void copy_to_device(double* device, const double* host, std::size_t n);

/// Sizes `factor` for the analysis and type (a no-op when it already is: refactorization
/// reuses the storage) and marks it invalid; the panels only when `host_panels`.
void prepare_factor(const Analysis& an, MatrixType type, NumericFactor& factor,
                    bool host_panels = true);

/// Adds one executor's device figures (FactorStats' GPU fields, phases included) to those
/// of a multi-worker factorization: bytes, launch groups, tiled fronts and phase times
/// summed; device_seconds and device_budget the largest; spilled blocks if any spilled.
void merge_device_figures(FactorStats& into, const FactorStats& one);

/// Makes fac.panels hold every panel: sizes it and has each held part's executor
/// (execs[HeldPanels::worker], the executors the factorization ran with, in that order)
/// copy its panels there, then clears fac.held; a no-op when nothing is held. Throws
/// InternalError when a held part names a worker outside execs, and what download_panels
/// throws.
void fetch_panels(const Analysis& an, const std::vector<Executor*>& execs, NumericFactor& fac);
/// The same for a whole-tree factorization by `exec`.
void fetch_panels(const Analysis& an, Executor& exec, NumericFactor& fac);

/// LDLᵀ bookkeeping of front f once its partial factorization is in the factor (shared by
/// the executors, so that a CPU and a GPU factor have one layout): moves D out of the
/// front's panel (its diagonal to d_diag, the (j+1, j) entries of 2×2 pivots to d_off,
/// leaving L11 unit lower with zeros there), sets pivot_size by global pivot position
/// (first_pivot[f] + i: 1, or 2 then 0 for a 2×2 pivot) and the permuted pivot rows.
/// local_perm[0..k) and local_pivot_size[0..k) are as factor_front_ldlt returns them.
void store_ldlt_front(const Analysis& an, index_t f, const index_t* local_perm,
                      const int* local_pivot_size, NumericFactor& factor);

/// Runs the numeric factorization of the scaled canonical values with `exec` on the whole
/// tree; values_on_device: those its scale_values_on_device left on its device instead
/// (scaled_values is not read). Fills `factor`; throws as Executor::factor_batch.
void factorize(const Analysis& an, const std::vector<double>& scaled_values, MatrixType type,
               const PivotPolicy& pivots, Executor& exec, NumericFactor& factor,
               std::vector<double>& cb_arena, bool values_on_device = false);

/// Options of the multi-worker driver that are not user options.
/// Host buffers of the contribution blocks that cross between parts through host memory,
/// indexed by part id, kept by the caller from one factorization to the next: allocating
/// them afresh each time made every copy into them fault its pages in again (both sides of
/// an MPI exchange: 612 MB per refactorization of lap3d 80³ on 2 ranks).
struct BlockBuffers {
  std::vector<TransferBuffer> buffer;
  std::vector<std::size_t> size;  ///< doubles in buffer[id]
};

struct MultiWorkerConfig {
  bool work_stealing = true;  ///< an idle worker takes an unstarted subtree of another
  /// Optional: called by worker w (0-based) after it takes subtree part i and before it
  /// factors it, on that worker's thread (tracing; the tests make one worker slow with it
  /// to show stealing). Must not throw.
  std::function<void(int w, int part)> before_subtree;
  /// Distributed factorization (src/distributed): the partition was made for more workers
  /// than this process runs; its executors are the global workers first_worker ..
  /// first_worker + execs.size() − 1, and it factors only the subtrees they own (stealing
  /// among them). Once those are done — or one of them failed (`failed`) — `exchange` is
  /// called with the transfers indexed by part id — those of the subtrees first, at their
  /// index; upper layers are refused with an exchange — (and the first error of this process's
  /// workers, or null): the blocks this process exported are in
  /// their host buffers (or, with remote_blocks_on_device, in the exporter's device
  /// memory); a process that factors the top fills the others' before returning. It runs
  /// on every process whatever happened, so it can agree on failure (and throw).
  int first_worker = 0;
  std::function<void(std::vector<CbTransfer>& transfers, std::exception_ptr failed)> exchange;
  /// Whether this process factors the top part (false: it stops after `exchange`).
  bool factor_top = true;
  /// With factor_top false: ask exporters to leave the blocks in device memory (NCCL).
  bool remote_blocks_on_device = false;
  /// Executors may keep their parts' panels in device memory (FactorContext::
  /// keep_part_panels); those parts are listed in NumericFactor::held and the caller
  /// fetches them (fetch_panels with every executor) before a host solve.
  bool keep_panels_on_devices = false;
  /// Optional: where the transfers' host buffers are kept between factorizations.
  BlockBuffers* block_buffers = nullptr;
  /// Optional: the scaled values also in device memory (FactorContext::device_values).
  const double* device_values = nullptr;
  int device_values_device = -1;
};

/// Runs the numeric factorization on several executors (one per worker, one host thread
/// each) over an.partition, which must have been made for execs.size() workers: the
/// subtrees from per-worker queues filled largest-first (an.partition.owner), stealing
/// when config.work_stealing; then each executor its upper parts (an.partition.upper_owner)
/// in layer order, each as soon as the parts it reads from are done (no barrier between
/// layers), their children's blocks handed in; then the top part on execs[0], all threads
/// joined, with its children's contribution
/// blocks handed in. `arenas` (one per worker) are sized here and reused
/// across calls. Fills `factor` (the same entries as factorize) and, when given,
/// `devices` (one per worker). The first exception of any worker is rethrown after all
/// workers have stopped.
void factorize_multi(const Analysis& an, const std::vector<double>& scaled_values, MatrixType type,
                     const PivotPolicy& pivots, const std::vector<Executor*>& execs,
                     NumericFactor& factor, std::vector<std::vector<double>>& arenas,
                     const MultiWorkerConfig& config, std::vector<DeviceStats>* devices);

/// Solves with the factor in place: x (tree numbering, n×nrhs column-major, leading
/// dimension n) holds the right-hand sides on entry and the solutions on return.
void solve_in_place(const Analysis& an, const NumericFactor& factor, double* x, index_t nrhs);

/// The pieces of solve_in_place for one front f (x as there; w a workspace): the forward
/// step (reads and writes x at f's rows), the diagonal step (LDLᵀ; a no-op otherwise; f's
/// pivot rows) and the backward step (reads f's rows, writes its pivot rows).
/// solve_in_place = forward over f = 0, 1, …, diagonal over every f, backward over
/// f = n_fronts − 1, …, 0. The caller sets the BLAS threads (solve_in_place uses one).
void forward_front(const Analysis& an, const NumericFactor& factor, index_t f, double* x,
                   index_t nrhs, std::vector<double>& w);
/// forward_front with some of f's update rows redirected: a row i ≥ k of f whose
/// slots[i] is ≥ 0 is read from and written to delta[slots[i] + r·ld_delta] (right-hand
/// side r) instead of x (slots: per row of f, as AssemblyTree::rows_of(f); the subtree
/// solve's updates of rows outside a subtree, numeric/subtree_solve.hpp).
void forward_front(const Analysis& an, const NumericFactor& factor, index_t f, double* x,
                   index_t nrhs, std::vector<double>& w, const index_t* slots, double* delta,
                   index_t ld_delta);
void diagonal_front(const Analysis& an, const NumericFactor& factor, index_t f, double* x,
                    index_t nrhs);
void backward_front(const Analysis& an, const NumericFactor& factor, index_t f, double* x,
                    index_t nrhs, std::vector<double>& w);

}  // namespace strata::numeric
