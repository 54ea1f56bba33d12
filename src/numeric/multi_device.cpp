// strata — the multi-worker factorization driver: subtrees on several executors (GPUs),
// then the top of the tree (DESIGN.md §3, docs/multigpu.md).
//
// What: the analysis splits the assembly tree into disjoint subtrees and a top part
// (schedule/tree_partition.hpp). Each worker — one host thread driving one Executor — has
// a queue of subtrees filled largest-first by the partition's LPT assignment and takes
// them from the front; with work stealing, a worker whose queue is empty takes the last
// (smallest) unstarted subtree of the queue with the most work left. A subtree is
// factored by levels exactly as the whole tree is on one device — its own level
// schedule, memory plan under the same budget, and contribution-block arena — and its
// root's contribution block is exported to a host buffer (or, on GPUs that reach each
// other, left in device memory for a peer copy). When every subtree is done, worker 0
// imports those blocks into the top part's arena and factors the top part.
//
// Why this shape: subtrees of a nested-dissection tree are independent, so the workers
// share nothing but the factor (each front's panel, rows, D and pivot statistics are
// disjoint ranges written by exactly one worker) and the queues (one mutex). Largest
// first is Graham's LPT rule; stealing covers what the work estimate gets wrong (a slower
// device, a shared machine); stealing from the back leaves the victim its large items,
// the usual work-stealing choice (Blumofe & Leiserson, J. ACM 46, 1999). Every front is
// factored by the same executor code as on one worker, so with executors of the same kind
// and thread count the factor is bitwise the one-worker factor.
//
// Not yet: the top part runs on worker 0 alone; splitting its large fronts across the
// devices by tiles (the paper's treatment of the top separators) is a later step.
//
// Several processes (src/distributed, docs/distributed.md): MultiWorkerConfig names the
// global workers this process runs; it factors their subtrees, then hands every transfer
// to config.exchange (which moves the blocks between processes), and only the process
// that owns the top part goes on to it.
//
// Errors: a worker that throws records the first exception and stops the others from
// taking new subtrees; all threads are joined and the first exception is rethrown.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <deque>
#include <exception>
#include <mutex>
#include <string>
#include <thread>

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
    throw InvalidInput("internal: the analysis was split for " + std::to_string(part.workers) +
                       " workers, the factorization was given " + std::to_string(workers) +
                       " executors from worker " + std::to_string(first));
  auto mine = [&](int i) { return part.owner[i] >= first && part.owner[i] < first + workers; };
  Timer wall;
  prepare_factor(an, type, factor);
  arenas.resize(workers);
  const auto& t = an.tree;
  const int n_sub = static_cast<int>(part.subtrees.size());

  // the subtree roots' contribution blocks (host buffers allocated when used)
  std::vector<CbTransfer> transfer(n_sub);
  for (int i = 0; i < n_sub; ++i) {
    const index_t r = part.subtrees[i].root;
    CbTransfer& x = transfer[i];
    x.front = r;
    // the importer: worker 0's device here; a process that does not factor the top sends
    // its blocks on through host memory (MPI), unless they are to stay on the device
    x.target_device = config.factor_top || config.remote_blocks_on_device ? execs[0]->device() : -1;
    if (t.parent[r] < 0 || t.cb_size(r) == 0) continue;  // nothing to hand over
    if (!config.factor_top && !mine(i)) continue;        // neither made nor used here
    x.size = static_cast<std::size_t>(t.cb_size(r)) * static_cast<std::size_t>(t.cb_size(r));
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
        const schedule::FactorPart& sub = part.subtrees[i];
        const PartView view = PartView::of(sub, i);
        if (ex.uses_host_arena() && arenas[w].size() < sub.cb_layout.arena_size)
          arenas[w].resize(sub.cb_layout.arena_size);
        ctx.part = &view;
        ex.begin_part(ctx);
        run_batches(ex, ctx);
        if (config.remote_blocks_on_device && !config.factor_top)
          transfer[i].target_device = ex.device();
        if (transfer[i].size) st[w].bytes_transferred += ex.export_cb(ctx, transfer[i]);
        ex.end_part(ctx);
        ctx.part = nullptr;
        st[w].busy_seconds += busy.seconds();
        st[w].flops += sub.work;
        ++st[w].subtrees_run;
        st[w].subtrees_stolen += stolen ? 1 : 0;
      }
    } catch (...) {
      queues.stop();
      std::lock_guard<std::mutex> lock(error_mutex);
      if (!error) error = std::current_exception();
    }
  };

  {
    std::vector<std::thread> threads;
    try {
      for (int w = 1; w < workers; ++w) threads.emplace_back(worker, w);
    } catch (...) {  // could not start a thread: stop and join the started ones
      queues.stop();
      for (auto& th : threads) th.join();
      throw;
    }
    worker(0);  // worker 0 on the calling thread, which then factors the top part
    for (auto& th : threads) th.join();
  }
  if (config.exchange) config.exchange(transfer, error);
  if (error) std::rethrow_exception(error);

  // the top part on worker 0, with the subtree roots' blocks handed in
  if (config.factor_top) {
    Executor& ex = *execs[0];
    Timer busy;
    const int top_id = n_sub;
    const PartView view = PartView::of(part.top, top_id);
    FactorContext ctx = base;
    ctx.cb_arena = &arenas[0];
    if (ex.uses_host_arena() && arenas[0].size() < part.top.cb_layout.arena_size)
      arenas[0].resize(part.top.cb_layout.arena_size);
    ctx.part = &view;
    ex.begin_part(ctx);
    for (const index_t c : part.top.imports)
      st[0].bytes_transferred += ex.import_cb(ctx, transfer[part.part_of[c]]);
    run_batches(ex, ctx);
    ex.end_part(ctx);
    st[0].busy_seconds += busy.seconds();
    st[0].flops += part.top.work;
  }
  for (int w = 0; w < workers; ++w) {
    FactorContext ctx = base;
    ctx.cb_arena = &arenas[w];
    Timer busy;
    execs[w]->end(ctx);
    st[w].busy_seconds += busy.seconds();
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
