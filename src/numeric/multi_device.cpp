// strata — the multi-worker factorization driver: subtrees on several executors (GPUs),
// then the upper parts of the tree as soon as the parts below them are done, then the
// top part (DESIGN.md §3, docs/multigpu.md).
//
// What: the analysis splits the assembly tree into disjoint subtrees (layer 0), upper
// layers 1, 2, … of disjoint parts above them, and a top part (schedule/
// tree_partition.hpp). Each worker — one host thread driving one Executor — has a queue
// of subtrees filled largest-first by the partition's LPT assignment and takes them from
// the front; with work stealing, a worker whose queue is empty takes the last (smallest)
// unstarted subtree of the queue with the most work left. A part is factored by levels
// exactly as the whole tree is on one device — its own level schedule, memory plan under
// the same budget, and contribution-block arena — and its root's contribution block is
// exported to a host buffer (or, on GPUs that reach each other, left in device memory for
// a peer copy) for the worker that factors the parent's part. When its queues are empty,
// each worker factors the upper parts the partition gave it (static owners: the exporter
// of a block knows its importer), in layer order, each one as soon as the parts it
// imports from are done (a wait on those parts, not a barrier between layers), with
// their blocks imported first. Finally, all threads joined, worker 0 imports the blocks
// of the top part's children and factors it.
//
// Why this shape: subtrees of a nested-dissection tree are independent, so the workers
// share nothing but the factor (each front's panel, rows, D and pivot statistics are
// disjoint ranges written by exactly one worker), the queues (one mutex) and the set of
// parts done (another). Largest first is Graham's LPT rule; stealing covers what the work
// estimate gets wrong (a slower device, a shared machine); stealing from the back leaves
// the victim its large items, the usual work-stealing choice (Blumofe & Leiserson, J. ACM
// 46, 1999). Upper parts are not stolen: there are few of them, and their owners were
// chosen (earliest finish in the partition's list schedule) where their inputs are ready
// first. Without the barrier a worker whose subtrees are done goes on up its side of the
// tree while another still factors a large subtree (with a barrier it idles until the
// large subtree is done: schedule/tree_partition.cpp says when that matters). Every
// front is factored by the same executor code as on one worker, so with executors of the
// same kind and thread count the factor is bitwise the one-worker factor.
//
// The top part — the root separators, the largest fronts — runs on worker 0 while every
// other worker is idle: they are handed to it as helpers (FactorContext::helpers), and the
// CUDA executor factors a large Cholesky front over all of them, its columns dealt out
// in blocks (Options::distributed_front_min_rows, distributed_front.cu), or splits a
// large front's update by column strips over them (Options::split_front_min_cb). Upper
// parts get no helpers: no worker is known to be idle while one runs.
//
// Several processes (src/distributed, docs/distributed.md): MultiWorkerConfig names the
// global workers this process runs; it factors their subtrees, then hands every transfer
// to config.exchange (which moves the blocks between processes), and only the process
// that owns the top part goes on to it. The transfers are indexed by part id (subtree i
// at i), the exchange reads those of the subtrees. Upper layers are not supported there
// (the distributed solver analyzes without them).
//
// Errors: a worker that throws records the first exception and stops the others from
// taking new subtrees or starting upper parts (a wait for a part's inputs ends too); all
// threads are joined and the first exception is rethrown (the top part does not start).
#include <algorithm>
#include <atomic>
#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <string>
#include <thread>

#include "base/alloc.hpp"
#include "base/timer.hpp"
#include "numeric/factor.hpp"
#include "strata/errors.hpp"

namespace strata::numeric {
namespace {

// The per-worker queues of subtree indices, under one mutex.
class Queues {
 public:
  // Only the subtrees of workers first .. first + workers − 1 (distributed: this process's).
  Queues(const schedule::TreePartition& p, int workers, bool stealing, int first)
      : part_(p), queue_(workers), load_(workers, 0.0), stealing_(stealing) {
    for (std::size_t i = 0; i < p.subtrees.size(); ++i) {  // decreasing work: largest first
      const int w = p.owner[i] - first;
      if (w < 0 || w >= workers) continue;
      queue_[w].push_back(static_cast<int>(i));
      load_[w] += p.subtrees[i].work;
    }
  }

  /// The next subtree for worker w, or -1 when none is left (or after stop()).
  int take(int w, bool& stolen) {
    std::lock_guard<std::mutex> lock(mutex_);
    stolen = false;
    if (stopped_) return -1;
    if (!queue_[w].empty()) return pop(w, true);
    if (!stealing_) return -1;
    int victim = -1;
    for (int v = 0; v < static_cast<int>(queue_.size()); ++v)
      if (v != w && !queue_[v].empty() && (victim < 0 || load_[v] > load_[victim])) victim = v;
    if (victim < 0) return -1;
    stolen = true;
    return pop(victim, false);
  }

  void stop() {
    std::lock_guard<std::mutex> lock(mutex_);
    stopped_ = true;
  }

 private:
  int pop(int v, bool front) {
    const int i = front ? queue_[v].front() : queue_[v].back();
    if (front)
      queue_[v].pop_front();
    else
      queue_[v].pop_back();
    load_[v] -= part_.subtrees[i].work;
    return i;
  }

  const schedule::TreePartition& part_;
  std::vector<std::deque<int>> queue_;
  std::vector<double> load_;
  bool stealing_;
  bool stopped_ = false;
  std::mutex mutex_;
};

// Factors the batches of one part with `ex` (ctx.part already set, begin_part done).
void run_batches(Executor& ex, const FactorContext& ctx) {
  for (const BatchInfo& b : *ctx.part->batches) ex.factor_batch(ctx, b);
}

// Which parts are done (their blocks exported), which an upper part waits for, and the
// first error of any worker, which stops the others.
class PartProgress {
 public:
  PartProgress(int n_parts, Queues& queues) : done_(n_parts, 0), queues_(queues) {}

  // Records the exception in flight (the first one is kept) and wakes every waiter.
  void record_error() {
    {
      std::lock_guard<std::mutex> lock(done_mutex_);
      failed_ = true;
    }
    done_cv_.notify_all();
    queues_.stop();
    std::lock_guard<std::mutex> lock(error_mutex_);
    if (!error_) error_ = std::current_exception();
  }
  void mark_done(int id) {
    {
      std::lock_guard<std::mutex> lock(done_mutex_);
      done_[id] = 1;
    }
    done_cv_.notify_all();
  }
  // Waits until every part that `fp` imports from is done; false after a failure.
  bool wait_for_imports(const schedule::TreePartition& part, const schedule::FactorPart& fp) {
    std::unique_lock<std::mutex> lock(done_mutex_);
    done_cv_.wait(lock, [&] {
      if (failed_) return true;
      for (const index_t c : fp.imports)
        if (!done_[part.part_id[c]]) return false;
      return true;
    });
    return !failed_;
  }
  void fail() {
    std::lock_guard<std::mutex> lock(done_mutex_);
    failed_ = true;
  }
  std::exception_ptr error() const { return error_; }

 private:
  std::mutex done_mutex_, error_mutex_;
  std::condition_variable done_cv_;
  std::vector<char> done_;
  bool failed_ = false;
  std::exception_ptr error_;
  Queues& queues_;
};

// Host buffers of earlier factorizations lent to the transfers (BlockBuffers), given back
// on every way out, with the ones allocated this time.
class KeptBuffers {
 public:
  KeptBuffers(std::vector<CbTransfer>& transfer, BlockBuffers* keep)
      : transfer_(transfer), keep_(keep), capacity_(transfer.size(), 0) {
    if (!keep_) return;
    const std::size_t n = transfer_.size();
    keep_->buffer.resize(n);
    keep_->size.resize(n, 0);
    for (std::size_t id = 0; id < n; ++id) {
      CbTransfer& x = transfer_[id];
      if (x.size == 0 || !keep_->buffer[id] || keep_->size[id] < x.size) continue;
      capacity_[id] = keep_->size[id];
      x.host_storage = std::move(keep_->buffer[id]);
      x.host = x.host_storage.get();  // stale contents: on_host says when it is filled
    }
  }
  ~KeptBuffers() {
    if (!keep_) return;
    for (std::size_t id = 0; id < transfer_.size(); ++id)
      if (transfer_[id].host_storage) {
        keep_->buffer[id] = std::move(transfer_[id].host_storage);
        keep_->size[id] = std::max(capacity_[id], transfer_[id].size);
      }
  }
  KeptBuffers(const KeptBuffers&) = delete;
  KeptBuffers& operator=(const KeptBuffers&) = delete;

 private:
  std::vector<CbTransfer>& transfer_;
  BlockBuffers* keep_;
  std::vector<std::size_t> capacity_;
};

// One multi-worker factorization (factorize_multi): the shared state of the workers'
// threads and the stages that use it.
class MultiRun {
 public:
  MultiRun(const Analysis& an, const std::vector<double>& scaled_values, MatrixType type,
           const PivotPolicy& pivots, const std::vector<Executor*>& execs, NumericFactor& factor,
           std::vector<std::vector<double>>& arenas, const MultiWorkerConfig& config)
      : an_(an),
        part_(an.partition),
        execs_(execs),
        factor_(factor),
        arenas_(arenas),
        config_(config),
        workers_(static_cast<int>(execs.size())),
        first_(config.first_worker),
        n_sub_(static_cast<int>(an.partition.subtrees.size())),
        transfer_(plan_transfers()),
        kept_(transfer_, config.block_buffers),
        st_(workers_),
        queues_(part_, workers_, config.work_stealing, first_),
        progress_(part_.n_parts(), queues_) {
    base_.analysis = &an;
    base_.values = scaled_values.data();
    base_.device_values = config.device_values;
    base_.device_values_device = config.device_values_device;
    base_.type = type;
    base_.static_pivot = pivots.static_pivot;
    base_.diagonal_pivot_threshold = pivots.threshold;
    base_.factor = &factor;
    base_.keep_part_panels = config.keep_panels_on_devices;
    arenas_.resize(workers_);
    for (int w = 0; w < workers_; ++w) {
      st_[w].worker = first_ + w;
      const int d = execs_[w]->device();
      st_[w].device = d >= 0 ? std::string(execs_[w]->name()) + ":" + std::to_string(d)
                             : std::string(execs_[w]->name());
    }
  }

  // The subtrees and upper parts on every worker, the exchange (distributed), the top
  // part on worker 0, then every executor's end. Rethrows the first worker's error.
  void run(std::vector<DeviceStats>* devices) {
    all_workers([this](int w) { worker(w); });
    if (config_.exchange) config_.exchange(transfer_, progress_.error());
    if (progress_.error()) std::rethrow_exception(progress_.error());
    // the top part on worker 0, with the blocks of its children in other parts handed in;
    // every other worker of this process is idle then: its helpers
    if (config_.factor_top) {
      Timer busy;
      factor_one(0, n_sub_, false, std::vector<Executor*>(execs_.begin() + 1, execs_.end()));
      st_[0].busy_seconds += busy.seconds();
    }
    for (int w = 0; w < workers_; ++w) {
      FactorContext ctx = base_;
      ctx.cb_arena = &arenas_[w];
      Timer busy;
      execs_[w]->end(ctx);
      st_[w].busy_seconds += busy.seconds();
      execs_[w]->report_worker(st_[w]);
    }
    const double total = wall_.seconds();
    for (auto& d : st_) d.idle_seconds = std::max(0.0, total - d.busy_seconds);
    factor_.valid = true;
    if (devices) *devices = std::move(st_);
  }

 private:
  bool mine(int i) const { return part_.owner[i] >= first_ && part_.owner[i] < first_ + workers_; }

  // The contribution block of each part's root, indexed by part id (the top part's root
  // has no parent: no block), with the device that imports it; host buffers come later.
  std::vector<CbTransfer> plan_transfers() const {
    const auto& t = an_.tree;
    const int n_parts = part_.n_parts();
    std::vector<CbTransfer> transfer(n_parts);
    for (int id = 0; id < n_parts; ++id) {
      if (id == n_sub_) continue;
      const index_t r = part_.part(id).root;
      CbTransfer& x = transfer[id];
      x.front = r;
      x.memory = execs_[0]->transfer_memory();  // every worker of a process is of one kind
      if (config_.exchange) {
        // distributed: the importer is worker 0's device here; a process that does not
        // factor the top sends its blocks on through host memory (MPI), unless they are
        // to stay on the device
        x.target_device =
            config_.factor_top || config_.remote_blocks_on_device ? execs_[0]->device() : -1;
      } else if (t.parent[r] >= 0) {  // the worker that factors the parent's part
        x.target_device =
            execs_[part_.worker_of(static_cast<int>(part_.part_id[t.parent[r]]))]->device();
      }
      if (t.parent[r] < 0 || t.cb_size(r) == 0) continue;             // nothing to hand over
      if (id < n_sub_ && !config_.factor_top && !mine(id)) continue;  // neither made nor used
      x.size = static_cast<std::size_t>(t.cb_size(r)) * static_cast<std::size_t>(t.cb_size(r));
    }
    return transfer;
  }

  // The host panels are sized only when some part's panels go there (keeps_panels):
  // with every part kept on its GPU, zero-filling the whole factor's host copy was work
  // no one read.
  void size_host_panels() {
    std::call_once(panels_sized_, [&] {
      sized_resize(factor_.panels, an_.factor_layout.total, "factorize: factor panels");
    });
  }

  // Part `id`'s panels stay with worker w's executor (NumericFactor::held, in part order).
  void hold_panels(int id, int w) {
    const std::lock_guard<std::mutex> lock(held_mutex_);
    auto& held = factor_.held;
    const auto at =
        std::find_if(held.begin(), held.end(), [id](const HeldPanels& h) { return h.part > id; });
    held.insert(at, HeldPanels{id, w});
  }

  // One part on worker w (its executor begun): begin_part, the blocks of its children in
  // other parts imported, its batches, its root's block exported, end_part.
  void factor_one(int w, int id, bool export_here, std::vector<Executor*> helpers = {}) {
    PartRun run;
    run.kind = id < n_sub_ ? PartRun::Kind::subtree
                           : (id == n_sub_ ? PartRun::Kind::top : PartRun::Kind::upper);
    run.index = id < n_sub_ ? id : (id == n_sub_ ? 0 : id - n_sub_ - 1);
    run.start_seconds = wall_.seconds();
    Executor& ex = *execs_[w];
    const schedule::FactorPart& fp = part_.part(id);
    const PartView view = PartView::of(fp, id);
    FactorContext ctx = base_;
    ctx.cb_arena = &arenas_[w];
    ctx.helpers = std::move(helpers);
    if (ex.uses_host_arena() && arenas_[w].size() < fp.cb_layout.arena_size)
      arenas_[w].resize(fp.cb_layout.arena_size);
    ctx.part = &view;
    ex.begin_part(ctx);
    if (ex.keeps_panels(ctx))
      hold_panels(id, w);
    else
      size_host_panels();
    for (const index_t c : fp.imports)
      st_[w].bytes_transferred += ex.import_cb(ctx, transfer_[part_.part_id[c]]);
    run_batches(ex, ctx);
    if (export_here && transfer_[id].size)
      st_[w].bytes_transferred += ex.export_cb(ctx, transfer_[id]);
    ex.end_part(ctx);
    st_[w].flops += fp.work;
    run.end_seconds = wall_.seconds();
    run.flops = fp.work;
    st_[w].parts.push_back(run);
  }

  // Worker w: the subtrees from the queues, then its upper parts in layer order
  // (decreasing work within a layer), each as soon as the parts below it are done: no
  // barrier between layers.
  void worker(int w) {
    try {
      Executor& ex = *execs_[w];
      FactorContext ctx = base_;
      ctx.cb_arena = &arenas_[w];
      Timer busy;
      ex.begin(ctx);
      st_[w].busy_seconds += busy.seconds();
      for (;;) {
        bool stolen = false;
        const int i = queues_.take(w, stolen);
        if (i < 0) break;
        busy.reset();
        if (config_.before_subtree) config_.before_subtree(w, i);
        if (config_.remote_blocks_on_device && !config_.factor_top)
          transfer_[i].target_device = ex.device();
        factor_one(w, i, true);
        st_[w].busy_seconds += busy.seconds();
        ++st_[w].subtrees_run;
        st_[w].subtrees_stolen += stolen ? 1 : 0;
        st_[w].parts.back().stolen = stolen;
        progress_.mark_done(i);
      }
      for (std::size_t k = 0; k < part_.upper.size(); ++k) {
        if (part_.upper_owner[k] != first_ + w) continue;
        const int id = n_sub_ + 1 + static_cast<int>(k);
        if (!progress_.wait_for_imports(part_, part_.part(id))) break;
        busy.reset();
        factor_one(w, id, true);
        st_[w].busy_seconds += busy.seconds();
        ++st_[w].upper_parts_run;
        progress_.mark_done(id);
      }
    } catch (...) {
      progress_.record_error();
    }
  }

  // Runs f(w) for every worker, one thread each (worker 0 on the calling thread), and
  // joins them.
  template <class F>
  void all_workers(const F& f) {
    std::vector<std::thread> threads;
    try {
      for (int w = 1; w < workers_; ++w) threads.emplace_back(f, w);
    } catch (...) {  // could not start a thread: stop and join the started ones
      progress_.fail();
      queues_.stop();
      for (auto& th : threads) th.join();
      throw;
    }
    f(0);
    for (auto& th : threads) th.join();
  }

  const Analysis& an_;
  const schedule::TreePartition& part_;
  const std::vector<Executor*>& execs_;
  NumericFactor& factor_;
  std::vector<std::vector<double>>& arenas_;
  const MultiWorkerConfig& config_;
  const int workers_, first_, n_sub_;
  Timer wall_;
  std::once_flag panels_sized_;
  std::mutex held_mutex_;  // NumericFactor::held, written by the workers
  std::vector<CbTransfer> transfer_;
  KeptBuffers kept_;
  std::vector<DeviceStats> st_;
  Queues queues_;
  PartProgress progress_;
  FactorContext base_;
};

}  // namespace

void factorize_multi(const Analysis& an, const std::vector<double>& scaled_values, MatrixType type,
                     const PivotPolicy& pivots, const std::vector<Executor*>& execs,
                     NumericFactor& factor, std::vector<std::vector<double>>& arenas,
                     const MultiWorkerConfig& config, std::vector<DeviceStats>* devices) {
  const schedule::TreePartition& part = an.partition;
  const int workers = static_cast<int>(execs.size());
  const int first = config.first_worker;  // > 0, or fewer executors: distributed
  if (workers < 1 || first < 0 || part.workers < first + workers ||
      (!config.exchange && part.workers != workers))
    throw InternalError("the analysis was split for " + std::to_string(part.workers) +
                        " workers, the factorization was given " + std::to_string(workers) +
                        " executors from worker " + std::to_string(first));
  if (config.exchange && !part.upper.empty())
    throw InternalError(
        "upper layers (Options::split_top) are not supported across "
        "processes");
  if (part.part_id.size() != static_cast<std::size_t>(an.tree.n_fronts()))
    throw InternalError("the analysis was not split into parts");
  prepare_factor(an, type, factor, false);
  MultiRun(an, scaled_values, type, pivots, execs, factor, arenas, config).run(devices);
}

}  // namespace strata::numeric
