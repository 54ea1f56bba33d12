// strata — the tree and multi-worker drivers of the numeric phase (see driver.hpp).
#include "numeric/driver.hpp"

#include <algorithm>
#include <exception>
#include <future>
#include <mutex>
#include <string>
#include <thread>

#include "base/device.hpp"
#include "base/timer.hpp"
#include "numeric/subtree_solve.hpp"
#include "strata/errors.hpp"

namespace strata::numeric {
namespace {

// Runs f(w) for w in [0, count) where run(w), each on a thread of its own (the GPUs side
// by side); rethrows the first exception once every thread is done.
template <class Run, class F>
void on_threads(std::size_t count, Run&& run, F&& f) {
  std::exception_ptr error;
  std::mutex error_mutex;
  std::vector<std::thread> threads;
  for (std::size_t w = 0; w < count; ++w) {
    if (!run(w)) continue;
    threads.emplace_back([&, w] {
      try {
        f(w);
      } catch (...) {
        const std::lock_guard<std::mutex> lock(error_mutex);
        if (!error) error = std::current_exception();
      }
    });
  }
  for (std::thread& t : threads) t.join();
  if (error) std::rethrow_exception(error);
}

// The host solve's threads and plan, kept by a driver from one solve to the next: the
// subtree cut of the analysis (numeric/subtree_solve.hpp), made at the first solve after
// an analysis, and an arena of Options::num_threads threads (0: all).
class HostSolve {
 public:
  explicit HostSolve(const Options& o)
      : arena_(o.num_threads > 0 ? o.num_threads : tbb::task_arena::automatic),
        reproducible_(o.reproducible) {}
  // With the factor in host memory: the panels fetched from the executors that kept them
  // on their devices, then the solve by subtrees.
  void run(const Analysis& an, const std::vector<Executor*>& execs, NumericFactor& factor,
           double* x, index_t nrhs) {
    fetch_panels(an, execs, factor);
    if (plan_.analysis_id != an.id) plan_ = plan_subtree_solve(an);
    // the top's large fronts with every thread in BLAS: bitwise the same result (OpenBLAS
    // splits a product's rows over the threads), kept at one under Options::reproducible
    const int blas = reproducible_ ? 1 : arena_.max_concurrency();
    solve_by_subtrees(an, factor, plan_, x, nrhs, arena_, blas);
  }
  void release() noexcept { plan_ = SubtreeSolvePlan{}; }

 private:
  tbb::task_arena arena_;
  bool reproducible_;
  SubtreeSolvePlan plan_;
};

// The solve over a split factor whose every part stayed with the executor that factored
// it (Executor::solve_held_parts; cuda/part_solve.cu): the layers of an.partition — the
// subtrees, the upper layers, the top part — forward from the bottom, then backward from
// the top, a layer's executors side by side on threads of their own, the parts' exports
// handed up through a host array of update vectors. False, x as it was, when some part's
// panels are on the host, its executor cannot solve it where it is, or a GPU has no room
// for the solve's workspaces.
bool solve_where_held(const Analysis& an, const std::vector<Executor*>& execs,
                      const NumericFactor& factor, double* x, index_t nrhs, std::vector<double>& u,
                      std::vector<double>& b) {
  const schedule::TreePartition& tp = an.partition;
  if (tp.part_of.size() != static_cast<std::size_t>(an.tree.n_fronts()) || factor.held.empty())
    return false;
  std::vector<int> worker(static_cast<std::size_t>(tp.n_parts()), -1);
  for (const HeldPanels& h : factor.held) {
    if (h.part < 0 || h.part >= tp.n_parts() || h.worker < 0 ||
        h.worker >= static_cast<int>(execs.size()) || worker[h.part] >= 0)
      return false;
    worker[h.part] = h.worker;
  }
  for (int id = 0; id < tp.n_parts(); ++id)  // every part with fronts is held
    if (worker[id] < 0 && !tp.part(id).fronts.empty()) return false;
  const std::vector<std::vector<int>> layers = tp.layers();
  // per layer, each executor's parts
  std::vector<std::vector<std::vector<int>>> lists(layers.size());
  for (std::size_t l = 0; l < layers.size(); ++l) {
    lists[l].resize(execs.size());
    for (const int id : layers[l])
      if (worker[id] >= 0) lists[l][worker[id]].push_back(id);
    for (std::size_t w = 0; w < execs.size(); ++w)
      if (!lists[l][w].empty() && !execs[w]->can_solve_held_parts(an, factor, lists[l][w]))
        return false;
  }
  // the whole tree's update-vector arena (the parts read and write only their imports
  // and exports): kept by the driver, so that a solve neither allocates nor zero-fills it
  const std::size_t u_size = static_cast<std::size_t>(an.child_rows.offsets.back()) * nrhs;
  if (u.size() < u_size) u.resize(u_size);
  auto run_layer = [&](std::size_t l, bool forward) {
    on_threads(
        execs.size(), [&](std::size_t w) { return !lists[l][w].empty(); },
        [&](std::size_t w) {
          execs[w]->solve_held_parts(an, factor, lists[l][w], forward, x, u.data(), nrhs);
        });
  };
  // the right-hand sides kept (in the driver's buffer, as u): a GPU without room for the
  // solve's workspaces (outside the factorization's device budget) leaves the solve to
  // the host
  b.assign(x, x + static_cast<std::size_t>(an.n) * nrhs);
  try {
    for (std::size_t l = 0; l < layers.size(); ++l) run_layer(l, true);
    for (std::size_t l = layers.size(); l-- > 0;) run_layer(l, false);
  } catch (const OutOfMemory&) {
    std::copy(b.begin(), b.end(), x);
    return false;
  }
  return true;
}

class TreeDriver final : public NumericDriver {
 public:
  explicit TreeDriver(const Options& o) : options_(o), gpu_(uses_cuda(o.backend)), host_solve_(o) {}
  int workers() const override { return 1; }
  bool in_one_process() const override { return true; }
  bool uploads_values() const override { return gpu_; }
  void prepare(const Analysis& an) override {
    if (!gpu_) return;
    executor().prepare(an, 1);
    creation_seconds_ = 0;  // part of the analysis's device set-up, not a factorization's
  }
  void begin_setup() override {
    if (!gpu_ || executor_ || pending_.valid()) return;
    pending_ = std::async(std::launch::async, [o = options_] { return make_cuda_executor(o); });
  }
  bool scale_values_on_device(const Analysis& an, const double* values, const StageValues& stage,
                              int max_sweeps, bool copy_input, DeviceValueNorms& out) override {
    return gpu_ &&
           executor().scale_values_on_device(an, values, stage, max_sweeps, copy_input, out);
  }
  bool download_scaled_values(const Analysis& an, double* host) override {
    return gpu_ && executor().download_scaled_values(an, host);
  }
  bool keep_device_input(const Analysis& an) override {
    return gpu_ && executor_ && executor_->keep_device_input(an);
  }
  bool download_device_input(const Analysis& an, double* host) override {
    return gpu_ && executor_ && executor_->download_device_input(an, host);
  }
  void factorize(const Analysis& an, const std::vector<double>& scaled_values,
                 bool values_on_device, MatrixType type, const PivotPolicy& pivots,
                 NumericFactor& factor) override {
    numeric::factorize(an, scaled_values, type, pivots, executor(), factor, cb_arena_,
                       values_on_device);
  }
  bool solve(const Analysis& an, NumericFactor& factor, double* x, index_t nrhs) override {
    Executor& e = executor();
    if (e.solve(an, factor, x, nrhs)) return true;
    host_solve_.run(an, {&e}, factor, x, nrhs);
    return false;
  }
  bool solve_original(const Analysis& an, NumericFactor& factor, const double* b, double* x,
                      index_t nrhs, const RescaleView& rescale, double* stage) override {
    return executor_ && executor_->solve_original(an, factor, b, x, nrhs, rescale, stage);
  }
  bool solve_gpu_arrays(const Analysis& an, NumericFactor& factor, const double* b, double* x,
                        index_t nrhs, const RescaleView& rescale, GpuArrayCheck* check) override {
    return executor_ && executor_->solve_gpu_arrays(an, factor, b, x, nrhs, rescale, check);
  }
  void last_gpu_array_check(GpuArrayCheck& check) override {
    if (!executor_) throw InternalError("last_gpu_array_check: no executor ran the solve");
    executor_->last_gpu_array_check(check);
  }
  double* refinement_workspace(std::size_t count) override {
    return executor_ ? executor_->refinement_workspace(count) : nullptr;
  }
  bool residual(const Analysis& an, const MatrixValues& a, const double* b, const double* x,
                double* r, index_t nrhs, double* maxima) override {
    return executor_ && executor_->residual(an, a, b, x, r, nrhs, maxima);
  }
  void refinement_step(double* x, const double* d, double* kept, index_t n, bool undo) override {
    if (!executor_) throw InternalError("refinement_step: no executor holds the vectors");
    executor_->refinement_step(x, d, kept, n, undo);
  }
  Backend backend() const override {
    return executor_ ? executor_->backend() : gpu_ ? Backend::cuda : Backend::cpu;
  }
  void report(FactorStats& fs) const override {
    if (!executor_) return;
    executor_->report(fs);
    if (fs.backend == Backend::cuda) fs.device_phases.setup += creation_seconds_;
    creation_seconds_ = 0;
  }
  void release_workspaces() noexcept override {
    cb_arena_.clear();
    host_solve_.release();
  }
  void release() noexcept override {
    std::vector<double>().swap(cb_arena_);
    host_solve_.release();
    drop_executors();
  }
  void drop_executors() noexcept override {
    if (pending_.valid()) {
      try {
        pending_.get();  // made or failed: dropped either way
      } catch (...) {
      }
    }
    executor_.reset();
  }

 private:
  Executor& executor() {
    if (!executor_) {
      // a new CUDA executor (device context, streams, library handles), or the one
      // begin_setup started: the time spent waiting for it
      const Timer t;
      if (pending_.valid())
        executor_ = pending_.get();
      else
        executor_ = gpu_ ? make_cuda_executor(options_)
                         : make_cpu_executor(options_.num_threads, options_.reproducible);
      creation_seconds_ += t.seconds();
    }
    return *executor_;
  }

  Options options_;
  bool gpu_;
  std::unique_ptr<Executor> executor_;
  std::future<std::unique_ptr<Executor>> pending_;  // begin_setup's executor, until taken
  std::vector<double> cb_arena_;
  HostSolve host_solve_;
  mutable double creation_seconds_ = 0;  // reported once, with the next factorization
};

class MultiWorkerDriver final : public NumericDriver {
 public:
  MultiWorkerDriver(const Options& o, int workers, int cpu_threads, MultiWorkerConfig config)
      : options_(o),
        workers_(workers),
        cpu_threads_(cpu_threads),
        config_(std::move(config)),
        host_solve_(o) {}
  int workers() const override { return workers_; }
  bool in_one_process() const override { return true; }
  bool uploads_values() const override { return cpu_threads_ == 0; }
  void prepare(const Analysis& an) override {
    if (cpu_threads_ > 0) return;
    // the GPUs side by side: each one's set-up is mostly host work of its own (plans,
    // uploads from pageable memory)
    const std::vector<Executor*> execs = executors();
    on_threads(
        execs.size(), [](std::size_t) { return true; },
        [&](std::size_t w) { execs[w]->prepare(an, workers_); });
    // the part solve's host array of update vectors for one right-hand side, zero-filled
    // here rather than in the first solve
    if (options_.gpu_solve_parts &&
        an.partition.part_of.size() == static_cast<std::size_t>(an.tree.n_fronts()))
      part_solve_u_.resize(static_cast<std::size_t>(an.child_rows.offsets.back()));
    // the value pass on the first GPU (one worker's prepare sets it up itself); the others
    // copy its scaled values at each factorization
    if (execs.size() > 1) execs[0]->prepare_shared_value_pass(an);
    creation_seconds_ = 0;  // part of the analysis's device set-up
  }
  // The value pass on the first GPU, as the tree driver's: refused where another GPU reads
  // values on the host (fronts factored tile by tile), which needs the host's pass.
  bool scale_values_on_device(const Analysis& an, const double* values, const StageValues& stage,
                              int max_sweeps, bool copy_input, DeviceValueNorms& out) override {
    if (cpu_threads_ > 0) return false;
    const std::vector<Executor*> execs = executors();
    for (std::size_t w = 1; w < execs.size(); ++w)
      if (execs[w]->reads_host_values()) return false;
    return execs[0]->scale_values_on_device(an, values, stage, max_sweeps, copy_input, out);
  }
  bool download_scaled_values(const Analysis& an, double* host) override {
    return cpu_threads_ == 0 && executors()[0]->download_scaled_values(an, host);
  }
  bool keep_device_input(const Analysis& an) override {
    return cpu_threads_ == 0 && !executors_.empty() && executors_[0]->keep_device_input(an);
  }
  bool download_device_input(const Analysis& an, double* host) override {
    return cpu_threads_ == 0 && !executors_.empty() &&
           executors_[0]->download_device_input(an, host);
  }
  void factorize(const Analysis& an, const std::vector<double>& scaled_values,
                 bool values_on_device, MatrixType type, const PivotPolicy& pivots,
                 NumericFactor& factor) override {
    const std::vector<Executor*> execs = executors();
    devices_.clear();
    if (execs.size() == 1 && an.partition.part_id.empty()) {
      // an analysis for one worker is not split into parts: the whole tree on that worker
      arenas_.resize(1);
      numeric::factorize(an, scaled_values, type, pivots, *execs[0], factor, arenas_[0],
                         values_on_device);
      return;
    }
    MultiWorkerConfig config = config_;
    config.block_buffers = &blocks_;
    if (values_on_device) {  // scale_values_on_device's result on the first GPU
      config.device_values = execs[0]->device_scaled_values(an);
      if (!config.device_values)
        throw InternalError("values on the device from no value pass of this analysis");
      config.device_values_device = execs[0]->device();
    }
    factorize_multi(an, scaled_values, type, pivots, execs, factor, arenas_, config, &devices_);
  }
  bool solve(const Analysis& an, NumericFactor& factor, double* x, index_t nrhs) override {
    const std::vector<Executor*> execs = executors();
    if (options_.gpu_solve_parts &&
        solve_where_held(an, execs, factor, x, nrhs, part_solve_u_, part_solve_b_))
      return true;
    host_solve_.run(an, execs, factor, x, nrhs);
    return false;
  }
  Backend backend() const override {
    return !executors_.empty() ? executors_[0]->backend()
           : cpu_threads_ > 0  ? Backend::cpu
                               : Backend::cuda;
  }
  void report(FactorStats& fs) const override {
    fs.devices = devices_;
    for (const auto& e : executors_) {  // device figures summed over the workers
      FactorStats one;
      e->report(one);
      merge_device_figures(fs, one);
    }
    if (fs.backend == Backend::cuda) fs.device_phases.setup += creation_seconds_;
    creation_seconds_ = 0;
  }
  void release_workspaces() noexcept override {
    arenas_.clear();
    blocks_ = BlockBuffers{};
    std::vector<double>().swap(part_solve_u_);
    std::vector<double>().swap(part_solve_b_);
    host_solve_.release();
  }
  void release() noexcept override { release_workspaces(); }
  void drop_executors() noexcept override { executors_.clear(); }

 private:
  std::vector<Executor*> executors() {
    if (static_cast<int>(executors_.size()) != workers_) {
      const Timer t;
      executors_.clear();
      for (int d = 0; d < workers_; ++d)
        executors_.push_back(cpu_threads_ > 0 ? make_cpu_executor(cpu_threads_)
                                              : make_cuda_executor(options_, d));
      creation_seconds_ += t.seconds();
    }
    std::vector<Executor*> execs;
    for (auto& e : executors_) execs.push_back(e.get());
    return execs;
  }

  Options options_;
  int workers_, cpu_threads_;
  MultiWorkerConfig config_;
  std::vector<std::unique_ptr<Executor>> executors_;
  std::vector<std::vector<double>> arenas_;
  BlockBuffers blocks_;
  std::vector<DeviceStats> devices_;
  std::vector<double> part_solve_u_;  // solve_where_held's update vectors
  std::vector<double> part_solve_b_;  // and its copy of the right-hand sides
  HostSolve host_solve_;
  mutable double creation_seconds_ = 0;
};

}  // namespace

std::unique_ptr<NumericDriver> make_tree_driver(const Options& options) {
  return std::make_unique<TreeDriver>(options);
}

std::unique_ptr<NumericDriver> make_multi_worker_driver(const Options& options, int workers,
                                                        int cpu_threads, MultiWorkerConfig config) {
  if (workers < 1 || cpu_threads < 0)
    throw InvalidInput("multi-worker driver: workers must be at least 1 (got " +
                       std::to_string(workers) + ") and threads at least 0 (got " +
                       std::to_string(cpu_threads) + ")");
  return std::make_unique<MultiWorkerDriver>(options, workers, cpu_threads, std::move(config));
}

}  // namespace strata::numeric
