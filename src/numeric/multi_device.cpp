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
// tree while another still factors a large subtree: lap3d 100³ on 2 workers had one
// subtree of 44% of the flops on one worker while the other, after 31% in small subtrees,
// idled until it was done (the estimate for that split was 1.46×, as measured). Every
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
#include <chrono>
#include <condition_variable>
#include <deque>
#include <exception>
#include <mutex>
#include <string>
#include <thread>

#include "core/alloc.hpp"
#include "core/timer.hpp"
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

}  // namespace

void factorize_multi(const Analysis& an, const std::vector<double>& scaled_values, MatrixType type,
                     double static_pivot, const std::vector<Executor*>& execs,
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
  auto mine = [&](int i) { return part.owner[i] >= first && part.owner[i] < first + workers; };
  Timer wall;
  // the host panels are sized only when some part's panels go there (keeps_part_panels):
  // with every part kept on its GPU, zero-filling the whole factor's host copy (7.1 GB
  // for lap3d 100³) was work no one read
  prepare_factor(an, type, factor, false);
  std::once_flag panels_sized;
  auto size_host_panels = [&] {
    std::call_once(panels_sized, [&] {
      sized_resize(factor.panels, an.factor_layout.total, "factorize: factor panels");
    });
  };
  arenas.resize(workers);
  const auto& t = an.tree;
  const int n_sub = static_cast<int>(part.subtrees.size());
  const int n_parts = part.n_parts();

  // the contribution block of each part's root, indexed by part id (the top part's root
  // has no parent: no block); host buffers allocated when used
  std::vector<CbTransfer> transfer(n_parts);
  for (int id = 0; id < n_parts; ++id) {
    if (id == n_sub) continue;
    const index_t r = part.part(id).root;
    CbTransfer& x = transfer[id];
    x.front = r;
    if (config.exchange) {
      // distributed: the importer is worker 0's device here; a process that does not
      // factor the top sends its blocks on through host memory (MPI), unless they are to
      // stay on the device
      x.target_device =
          config.factor_top || config.remote_blocks_on_device ? execs[0]->device() : -1;
    } else if (t.parent[r] >= 0) {  // the worker that factors the parent's part
      x.target_device =
          execs[part.worker_of(static_cast<int>(part.part_id[t.parent[r]]))]->device();
    }
    if (t.parent[r] < 0 || t.cb_size(r) == 0) continue;           // nothing to hand over
    if (id < n_sub && !config.factor_top && !mine(id)) continue;  // neither made nor used here
    x.size = static_cast<std::size_t>(t.cb_size(r)) * static_cast<std::size_t>(t.cb_size(r));
  }

  // host buffers of earlier factorizations handed to the transfers, and given back on
  // every way out (with the ones allocated this time)
  struct KeptBuffers {
    std::vector<CbTransfer>& transfer;
    BlockBuffers* keep;
    std::vector<std::size_t> capacity;
    ~KeptBuffers() {
      if (!keep) return;
      for (std::size_t id = 0; id < transfer.size(); ++id)
        if (transfer[id].host_storage) {
          keep->buffer[id] = std::move(transfer[id].host_storage);
          keep->size[id] = std::max(capacity[id], transfer[id].size);
        }
    }
  } kept{transfer, config.block_buffers, std::vector<std::size_t>(n_parts, 0)};
  if (BlockBuffers* keep = config.block_buffers) {
    keep->buffer.resize(n_parts);
    keep->size.resize(n_parts, 0);
    for (int id = 0; id < n_parts; ++id) {
      CbTransfer& x = transfer[id];
      if (x.size == 0 || !keep->buffer[id] || keep->size[id] < x.size) continue;
      kept.capacity[id] = keep->size[id];
      x.host_storage = std::move(keep->buffer[id]);
      x.host = x.host_storage.get();  // stale contents: on_host says when it is filled
    }
  }

  FactorContext base;
  base.analysis = &an;
  base.values = scaled_values.data();
  base.type = type;
  base.static_pivot = static_pivot;
  base.factor = &factor;
  base.keep_part_panels = config.keep_panels_on_devices;

  std::vector<DeviceStats> st(workers);
  for (int w = 0; w < workers; ++w) {
    st[w].worker = first + w;
    const int d = execs[w]->device();
    st[w].device = d >= 0 ? std::string(execs[w]->name()) + ":" + std::to_string(d)
                          : std::string(execs[w]->name());
  }
  Queues queues(part, workers, config.work_stealing, first);
  std::mutex error_mutex;
  std::exception_ptr error;
  std::atomic<bool> failed{false};
  // parts done (their blocks exported): what an upper part waits for
  std::mutex done_mutex;
  std::condition_variable done_cv;
  std::vector<char> done(n_parts, 0);
  auto record_error = [&] {
    {
      std::lock_guard<std::mutex> lock(done_mutex);
      failed = true;
    }
    done_cv.notify_all();
    queues.stop();
    std::lock_guard<std::mutex> lock(error_mutex);
    if (!error) error = std::current_exception();
  };
  auto mark_done = [&](int id) {
    {
      std::lock_guard<std::mutex> lock(done_mutex);
      done[id] = 1;
    }
    done_cv.notify_all();
  };
  // waits until every part that part `id` imports from is done; false after a failure
  auto wait_for_imports = [&](int id) {
    const schedule::FactorPart& fp = part.part(id);
    std::unique_lock<std::mutex> lock(done_mutex);
    done_cv.wait(lock, [&] {
      if (failed) return true;
      for (const index_t c : fp.imports)
        if (!done[part.part_id[c]]) return false;
      return true;
    });
    return !failed;
  };

  // One part on worker w (its executor begun): begin_part, the blocks of its children in
  // other parts imported, its batches, its root's block exported, end_part.
  auto factor_one = [&](int w, int id, bool export_here, std::vector<Executor*> helpers = {}) {
    PartRun run;
    run.kind = id < n_sub ? PartRun::Kind::subtree
                          : (id == n_sub ? PartRun::Kind::top : PartRun::Kind::upper);
    run.index = id < n_sub ? id : (id == n_sub ? 0 : id - n_sub - 1);
    run.start_seconds = wall.seconds();
    Executor& ex = *execs[w];
    const schedule::FactorPart& fp = part.part(id);
    const PartView view = PartView::of(fp, id);
    FactorContext ctx = base;
    ctx.cb_arena = &arenas[w];
    ctx.helpers = std::move(helpers);
    if (ex.uses_host_arena() && arenas[w].size() < fp.cb_layout.arena_size)
      arenas[w].resize(fp.cb_layout.arena_size);
    ctx.part = &view;
    ex.begin_part(ctx);
    if (!ex.keeps_part_panels(ctx)) size_host_panels();
    for (const index_t c : fp.imports)
      st[w].bytes_transferred += ex.import_cb(ctx, transfer[part.part_id[c]]);
    run_batches(ex, ctx);
    if (export_here && transfer[id].size)
      st[w].bytes_transferred += ex.export_cb(ctx, transfer[id]);
    ex.end_part(ctx);
    st[w].flops += fp.work;
    run.end_seconds = wall.seconds();
    run.flops = fp.work;
    st[w].parts.push_back(run);
  };

  // layer 0: the subtrees from the queues
  auto worker = [&](int w) {
    try {
      Executor& ex = *execs[w];
      FactorContext ctx = base;
      ctx.cb_arena = &arenas[w];
      Timer busy;
      ex.begin(ctx);
      st[w].busy_seconds += busy.seconds();
      for (;;) {
        bool stolen = false;
        const int i = queues.take(w, stolen);
        if (i < 0) break;
        busy.reset();
        if (w < static_cast<int>(config.injected_delay.size()) && config.injected_delay[w] > 0)
          std::this_thread::sleep_for(std::chrono::duration<double>(config.injected_delay[w]));
        if (config.remote_blocks_on_device && !config.factor_top)
          transfer[i].target_device = ex.device();
        factor_one(w, i, true);
        st[w].busy_seconds += busy.seconds();
        ++st[w].subtrees_run;
        st[w].subtrees_stolen += stolen ? 1 : 0;
        st[w].parts.back().stolen = stolen;
        mark_done(i);
      }
      // then this worker's upper parts, in layer order (decreasing work within a layer),
      // each as soon as the parts below it are done: no barrier between layers
      for (std::size_t k = 0; k < part.upper.size(); ++k) {
        if (part.upper_owner[k] != first + w) continue;
        const int id = n_sub + 1 + static_cast<int>(k);
        if (!wait_for_imports(id)) break;
        busy.reset();
        factor_one(w, id, true);
        st[w].busy_seconds += busy.seconds();
        ++st[w].upper_parts_run;
        mark_done(id);
      }
    } catch (...) {
      record_error();
    }
  };

  // runs f(w) for every worker, one thread each (worker 0 on the calling thread), and
  // joins them
  auto all_workers = [&](const auto& f) {
    std::vector<std::thread> threads;
    try {
      for (int w = 1; w < workers; ++w) threads.emplace_back(f, w);
    } catch (...) {  // could not start a thread: stop and join the started ones
      failed = true;
      queues.stop();
      for (auto& th : threads) th.join();
      throw;
    }
    f(0);
    for (auto& th : threads) th.join();
  };

  all_workers(worker);
  if (config.exchange) config.exchange(transfer, error);
  if (error) std::rethrow_exception(error);

  // the top part on worker 0, with the blocks of its children in other parts handed in;
  // every other worker of this process is idle then: its helpers
  if (config.factor_top) {
    Timer busy;
    factor_one(0, n_sub, false, std::vector<Executor*>(execs.begin() + 1, execs.end()));
    st[0].busy_seconds += busy.seconds();
  }
  for (int w = 0; w < workers; ++w) {
    FactorContext ctx = base;
    ctx.cb_arena = &arenas[w];
    Timer busy;
    execs[w]->end(ctx);
    st[w].busy_seconds += busy.seconds();
    execs[w]->report_worker(st[w]);
  }
  const double total = wall.seconds();
  for (auto& d : st) d.idle_seconds = std::max(0.0, total - d.busy_seconds);
  factor.panels_on_host = true;
  for (Executor* e : execs)
    if (e->holds_part_panels()) factor.panels_on_host = false;
  factor.valid = true;
  if (devices) *devices = std::move(st);
}

}  // namespace strata::numeric
