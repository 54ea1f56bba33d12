// strata — the numeric phase's drivers: how a Solver's factorization and its solves with
// the factor run over the analysis, as cuDSS's and SPRAL SSIDS's numeric-phase objects.
//
// The Solver (src/core) does what every driver shares — the values checked and scaled,
// Cholesky tried before LDLᵀ, the delayed pivoting of a general matrix on the host, the
// statistics, the refinement — and leaves the numeric work to one NumericDriver:
//   - the tree driver: one executor (CPU, or CUDA on device 0) factors the whole tree
//     (numeric::factorize, multifrontal.cpp) and solves with it, on the device when the
//     factor stayed there;
//   - the multi-worker driver: one executor per worker (GPUs, or CPU executors for tests
//     and benchmarks) over the analysis's split tree (numeric::factorize_multi,
//     multi_device.cpp); the solve runs part by part on the GPUs that hold the parts'
//     panels (cuda/part_solve.cu), or on the host with the panels fetched there when some
//     part's panels are not on a GPU (LDLᵀ, tiled fronts, a memory limit, CPU workers);
//   - the distributed driver (src/distributed): the factorization and the solves are
//     collective over MPI ranks.
// The analysis is made for the driver's workers() (Analysis::partition).
#pragma once

#include <memory>
#include <vector>

#include "numeric/factor.hpp"

namespace strata::numeric {

/// The numeric phases of one Solver (see the file header). A driver keeps its executors
/// and their memory from one factorization to the next (refactorization allocates
/// nothing); it is not thread-safe.
class NumericDriver {
 public:
  virtual ~NumericDriver() = default;
  /// Workers the analysis is split for (Analysis::partition.workers); 1: the whole tree.
  virtual int workers() const = 0;
  /// Whether the whole tree is factored in this process (one executor, or several workers
  /// that share its memory), so that a host algorithm on the analysis and the scaled
  /// values may take over, as delayed pivoting does; false for the distributed driver.
  virtual bool in_one_process() const = 0;
  /// Whether the executors copy the scaled values from host memory to a GPU at every
  /// factorization (the Solver page-locks them then).
  virtual bool uploads_values() const = 0;
  /// The device set-up that depends on the analysis alone (Executor::prepare: uploads,
  /// the device memory plan, streams and library handles), done at analysis as cuDSS's
  /// analysis phase does; nothing for host executors. Throws as factorize.
  virtual void prepare(const Analysis& an) {}
  /// Starts, on a thread of its own, the part of that set-up that does not need the
  /// analysis (the CUDA context, streams and library handles of a new CUDA executor), so
  /// that it overlaps the host's analysis; prepare (or any later call that needs the
  /// executor) waits for it and rethrows its error. Nothing for host executors, or when
  /// the executors exist.
  virtual void begin_setup() {}
  /// The value pass of the next factorizations on the GPU (Executor::scale_values_on_device
  /// of the tree driver's CUDA executor, or of the multi-worker driver's first GPU, whose
  /// scaled values the other GPUs copy): `values` (host, canonical entry order, filled
  /// piece by piece by `stage`) checked, scaled, equilibrated again by at most
  /// `max_sweeps` sweeps where needed, and measured on the device, `out` its findings;
  /// with `copy_input` also copied there as given.
  /// False, having done nothing, for every other driver and where the executor has no
  /// such pass.
  virtual bool scale_values_on_device(const Analysis& an, const double* values,
                                      const StageValues& stage, int max_sweeps, bool copy_input,
                                      DeviceValueNorms& out) {
    return false;
  }
  /// The values the last scale_values_on_device scaled, copied back into `host`
  /// (Executor::download_scaled_values); false for drivers without that pass.
  virtual bool download_scaled_values(const Analysis& an, double* host) { return false; }
  /// Executor::keep_device_input and download_device_input of that executor; false for
  /// drivers without that pass.
  virtual bool keep_device_input(const Analysis& an) { return false; }
  virtual bool download_device_input(const Analysis& an, double* host) { return false; }
  /// Factors the scaled values (the analysis's canonical entry order) as `type` with
  /// the pivot policy `pivots` (static pivots, LU's threshold) into `factor`; values_on_device:
  /// those the last scale_values_on_device left on the GPU instead (scaled_values is not read).
  /// Throws NotPositiveDefinite, OutOfMemory (with the bytes), DeviceError, as the executors do;
  /// InternalError for values_on_device on a driver without that pass.
  virtual void factorize(const Analysis& an, const std::vector<double>& scaled_values,
                         bool values_on_device, MatrixType type, const PivotPolicy& pivots,
                         NumericFactor& factor) = 0;
  /// x ← F⁻¹ x with the factor of the last factorize: x in tree numbering, n × nrhs
  /// column-major. Panels kept on devices are fetched to `factor` first when the solve
  /// runs on the host. Returns whether it ran on GPUs (the tree driver: the resident
  /// factor's device solve; the multi-worker driver: every part on the GPU holding it).
  virtual bool solve(const Analysis& an, NumericFactor& factor, double* x, index_t nrhs) = 0;
  /// Executor::solve_original of the tree driver's executor (b and x in the original
  /// numbering, permuted and scaled where the factor is); false, having done nothing, for
  /// every other driver and where that executor's solve would not run (the caller then
  /// permutes and scales on the host and calls solve).
  virtual bool solve_original(const Analysis& an, NumericFactor& factor, const double* b, double* x,
                              index_t nrhs, const RescaleView& rescale, double* stage) {
    return false;
  }
  /// Executor::solve_gpu_arrays and last_gpu_array_check of the tree driver's executor (b
  /// and x in that GPU's memory); false, having done nothing, and InternalError for every
  /// other driver, and false where that executor's returns false.
  virtual bool solve_gpu_arrays(const Analysis& an, NumericFactor& factor, const double* b,
                                double* x, index_t nrhs, const RescaleView& rescale,
                                GpuArrayCheck* check) {
    return false;
  }
  virtual void last_gpu_array_check(GpuArrayCheck& check) {
    throw InternalError("last_gpu_array_check: this driver ran no solve of GPU arrays");
  }
  /// Executor::refinement_workspace, residual and refinement_step of the tree driver's
  /// executor; null, false and InternalError for every other driver.
  virtual double* refinement_workspace(std::size_t count) { return nullptr; }
  virtual bool residual(const Analysis& an, const MatrixValues& a, const double* b, const double* x,
                        double* r, index_t nrhs, double* maxima) {
    return false;
  }
  virtual void refinement_step(double* x, const double* d, double* kept, index_t n, bool undo) {
    throw InternalError("refinement_step: this driver holds no vectors on a GPU");
  }
  /// Where the last factorization ran (FactorStats::backend; never automatic).
  virtual Backend backend() const = 0;
  /// Adds the last factorization's own figures to `fs`: the device figures (summed over
  /// the workers), FactorStats::devices, the executors' creation time in setup.
  virtual void report(FactorStats& fs) const = 0;
  /// Frees the workspaces kept between factorizations (contribution-block arenas, block
  /// buffers); the executors stay. For a new analysis.
  virtual void release_workspaces() noexcept {}
  /// Frees everything it holds, executors included (device memory): after an allocation
  /// failure, so that the caller can free memory and try again.
  virtual void release() noexcept {}
  /// Gives up the executors after a failed device set-up (prepare): the next
  /// factorization makes them again and meets the failure with its context.
  virtual void drop_executors() noexcept {}
};

/// One executor on the whole tree, made on first use: the CUDA executor on device 0 when
/// options.backend resolves to CUDA (base/device.hpp uses_cuda), else the CPU executor
/// with options.num_threads and options.reproducible.
std::unique_ptr<NumericDriver> make_tree_driver(const Options& options);

/// One executor per worker over the split tree (factorize_multi with `config`; the
/// driver keeps the block buffers between factorizations): GPUs 0 .. workers − 1 with
/// `options` when cpu_threads is 0, else `workers` CPU executors of cpu_threads threads
/// each (tests and benchmarks run the multi-GPU path so). Throws InvalidInput for
/// workers < 1 or cpu_threads < 0.
std::unique_ptr<NumericDriver> make_multi_worker_driver(const Options& options, int workers,
                                                        int cpu_threads, MultiWorkerConfig config);

}  // namespace strata::numeric
