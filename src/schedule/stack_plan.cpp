// strata — the depth-first plan of the CPU factorization (see stack_plan.hpp).
//
// Sources: Liu, "On the storage requirement in the out-of-core multifrontal method for
// sparse factorization", ACM TOMS 12 (1986) — the postorder traversal with the update
// matrices on a stack; Geist & Ng, "Task scheduling for parallel sparse Cholesky
// factorization", IJPP 18 (1989) — independent subtrees mapped to threads; the same two
// ideas organize MUMPS's and SPRAL SSIDS's CPU factorizations; L'Excellent & Sid-Lakhdar,
// "A study of shared-memory parallelism in a multifrontal solver", Parallel Computing 40
// (2014) — the layer of subtrees below which each runs on one thread (MUMPS's "L0").
//
// 1. Subtrees. work(f) is the flops of f's subtree (symbolic::front_flops summed). A front
//    is in a small subtree when its whole subtree consists of fronts under
//    kLargeFrontFlops and its work is at most total / (4 · threads) (with one thread, no
//    limit). The small subtrees are the maximal such subtrees; in the tree's postorder
//    numbering each is a range of fronts ending at its root. Every other front belongs
//    to the top. With kLayerThreads threads or more, the subtrees are instead the layer
//    that minimizes an estimated time (subtree_layer below: the MUMPS "L0 layer" idea),
//    large fronts included: they then run one BLAS thread each, all at once in one first
//    step, where a large front alone on many BLAS threads uses them poorly.
// 2. Steps. The top fronts are processed by the calling thread in increasing (post)order.
//    Either each top front is preceded by a step that runs its small-subtree children
//    concurrently ("per front": their roots' blocks are pushed on the stack right before
//    the parent needs them), or all small subtrees run concurrently in one first step
//    ("subtrees first": their roots' blocks get slots of their own below the stack). The
//    second gives the most parallelism, the first the least memory; the plan takes the
//    second when its main stack is within 10 % of the first's, which holds where the
//    subtree roots' blocks are small (the multibody matrices) and fails on 3D meshes.
// 3. The stack. A front's children's blocks are the topmost blocks on the stack when it
//    runs (postorder). Its own block is formed above them (build_offset: the Cholesky path
//    forms it there, with no dense front workspace), and once the children are assembled
//    and the front factored it is moved down to where the lowest child's block began
//    (cb_offset). The peak of top + block over the traversal is the stack's size. A
//    small subtree's fronts but its root use the same scheme in the region of the thread
//    that runs the subtree; the root writes its block straight to the main stack (or its
//    slot).
#include "schedule/stack_plan.hpp"

#include <algorithm>
#include <functional>
#include <limits>
#include <queue>
#include <string>

#include "strata/errors.hpp"

namespace strata::schedule {
namespace {

using symbolic::AssemblyTree;

// Places front f's block above its children's (the topmost `stacked` blocks below `top`)
// and returns the new top; `peak` grows to cover the block while it is formed.
std::size_t push_front(const AssemblyTree& t, index_t f, std::size_t top, std::size_t& peak,
                       StackPlan& p, bool (*stacked)(const StackPlan&, index_t)) {
  std::size_t lowest = top, sum = 0;
  for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
    const index_t c = t.children[q];
    const std::size_t b = p.block_doubles(t, c);
    if (b == 0 || !stacked(p, c)) continue;
    lowest = std::min(lowest, p.cb_offset[c]);
    sum += b;
  }
  if (lowest + sum != top)
    throw InternalError("stack plan: the blocks of front " + std::to_string(f) +
                        "'s children are not the top of the stack");
  const std::size_t b = p.block_doubles(t, f);
  p.build_offset[f] = top;
  peak = std::max(peak, top + b);
  p.cb_offset[f] = lowest;
  return lowest + b;
}

// The main stack of the top fronts and the subtree roots (step 3 of the file header).
void layout_main(const AssemblyTree& t, StackPlan& p) {
  std::size_t top = 0;
  auto slot = [&](index_t s) {
    const index_t r = p.subtree_root[s];
    const std::size_t b = p.block_doubles(t, r);
    p.cb_offset[r] = p.build_offset[r] = top;
    top += b;
  };
  if (p.subtrees_first)
    for (const index_t s : p.group) slot(s);
  std::size_t peak = top;
  auto stacked = [](const StackPlan& pl, index_t c) {
    return pl.subtree_of[c] < 0 || !pl.subtrees_first;
  };
  for (std::size_t i = 0; i < p.step_front.size(); ++i) {
    if (!p.subtrees_first)
      for (index_t q = p.group_offsets[i]; q < p.group_offsets[i + 1]; ++q) slot(p.group[q]);
    peak = std::max(peak, top);
    const index_t f = p.step_front[i];
    if (f >= 0) top = push_front(t, f, top, peak, p, stacked);
  }
  p.main_size = peak;
}

// The fronts of each small subtree but its root, in its thread's region.
void layout_regions(const AssemblyTree& t, StackPlan& p) {
  p.region_size = 0;
  auto stacked = [](const StackPlan&, index_t) { return true; };
  for (std::size_t s = 0; s < p.subtree_root.size(); ++s) {
    std::size_t top = 0, peak = 0;
    for (index_t f = p.subtree_first[s]; f < p.subtree_root[s]; ++f)
      top = push_front(t, f, top, peak, p, stacked);
    p.region_size = std::max(p.region_size, peak);
  }
}

void make_steps(const AssemblyTree& t, const std::vector<double>& work, StackPlan& p) {
  const index_t n = t.n_fronts();
  auto by_work = [&](std::vector<index_t>& g) {
    std::stable_sort(g.begin(), g.end(), [&](index_t a, index_t b) {
      return work[p.subtree_root[a]] > work[p.subtree_root[b]];
    });
  };
  p.step_front.clear();
  p.group.clear();
  p.group_offsets.assign(1, 0);
  auto close_step = [&](index_t front) {
    p.step_front.push_back(front);
    p.group_offsets.push_back(static_cast<index_t>(p.group.size()));
  };
  std::vector<index_t> g;
  if (p.subtrees_first) {
    for (index_t s = 0; s < static_cast<index_t>(p.subtree_root.size()); ++s) g.push_back(s);
    by_work(g);
    p.group = g;
    close_step(-1);
    for (index_t f = 0; f < n; ++f)
      if (p.subtree_of[f] < 0) close_step(f);
    return;
  }
  for (index_t f = 0; f < n; ++f) {
    if (p.subtree_of[f] >= 0) continue;
    g.clear();
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
      const index_t c = t.children[q];
      if (p.subtree_of[c] >= 0) g.push_back(p.subtree_of[c]);
    }
    by_work(g);
    p.group.insert(p.group.end(), g.begin(), g.end());
    close_step(f);
  }
  g.clear();
  for (index_t s = 0; s < static_cast<index_t>(p.subtree_root.size()); ++s)
    if (t.parent[p.subtree_root[s]] < 0) g.push_back(s);
  if (!g.empty()) {
    by_work(g);
    p.group.insert(p.group.end(), g.begin(), g.end());
    close_step(-1);
  }
}

// Step 1 with many threads: the layer of independent subtrees. From the roots down, the
// subtree of most work is replaced by its children (its root joins the top) as long as
// that may lower the estimated time: the layer's flops over the threads, largest first onto
// the least loaded (one BLAS thread each), plus the top's: its large fronts' flops at
// kTopEfficiency of the threads' rate, its small ones' at one thread's (they run alone on
// the calling thread). Returns, per front, whether it lies in a layer subtree.
std::vector<char> subtree_layer(const AssemblyTree& t, const std::vector<double>& work,
                                int threads) {
  const index_t n = t.n_fronts();
  std::vector<index_t> cut, best;
  for (index_t f = 0; f < n; ++f)
    if (t.parent[f] < 0) cut.push_back(f);
  auto makespan = [&](std::vector<double> w) {
    std::sort(w.begin(), w.end(), std::greater<>());
    std::priority_queue<double, std::vector<double>, std::greater<>> load;
    for (int i = 0; i < threads; ++i) load.push(0.0);
    for (const double x : w) {
      const double l = load.top();
      load.pop();
      load.push(l + x);
    }
    double m = 0;
    while (!load.empty()) {
      m = load.top();
      load.pop();
    }
    return m;
  };
  // the top's time in one thread's flops: a large front on all threads at kTopEfficiency,
  // a small one on the calling thread alone
  double top = 0, best_time = std::numeric_limits<double>::infinity();
  const std::size_t max_cut = static_cast<std::size_t>(16) * static_cast<std::size_t>(threads);
  // the top's time only grows: once it alone reaches the best estimate, stop (on a
  // chain-like tree the cut stays small and would otherwise be walked to its end)
  while (!cut.empty() && cut.size() <= max_cut && top < best_time) {
    std::vector<double> w;
    for (const index_t r : cut) w.push_back(work[r]);
    const double time = makespan(w) + top;
    if (time < best_time) {
      best_time = time;
      best = cut;
    }
    const auto largest = std::max_element(cut.begin(), cut.end(),
                                          [&](index_t a, index_t b) { return work[a] < work[b]; });
    const index_t r = *largest;
    cut.erase(largest);
    const double flops = symbolic::front_flops(t, r);
    top += flops > kLargeFrontFlops ? flops / (kTopEfficiency * threads) : flops;
    for (index_t q = t.child_offsets[r]; q < t.child_offsets[r + 1]; ++q)
      cut.push_back(t.children[q]);
  }
  std::vector<char> in(n, 0);
  for (const index_t r : best) in[r] = 1;
  for (index_t f = n - 1; f >= 0; --f)
    if (t.parent[f] >= 0 && in[t.parent[f]]) in[f] = 1;
  return in;
}

}  // namespace

StackPlan plan_stack(const AssemblyTree& t, int threads, bool lower_panels) {
  if (threads < 1) throw InternalError("plan_stack: threads < 1");
  const index_t n = t.n_fronts();
  StackPlan p;
  p.threads = threads;
  p.lower_panels = lower_panels;
  p.regions = threads > 1 ? threads + 1 : 1;

  // 1. subtree work, sizes and the small subtrees
  std::vector<double> work(n, 0.0);
  std::vector<index_t> size(n, 1);
  std::vector<char> all_small(n, 1);
  double total = 0;
  for (index_t f = 0; f < n; ++f) {
    const double w = symbolic::front_flops(t, f);
    work[f] += w;
    if (w > kLargeFrontFlops) all_small[f] = 0;
    const index_t q = t.parent[f];
    if (q < 0) {
      total += work[f];
      continue;
    }
    if (q <= f) throw InternalError("plan_stack: the tree's numbering is not a postorder");
    work[q] += work[f];
    size[q] += size[f];
    if (!all_small[f]) all_small[q] = 0;
  }
  const double share =
      threads > 1 ? total / (4.0 * threads) : std::numeric_limits<double>::infinity();
  const std::vector<char> layer =
      threads >= kLayerThreads ? subtree_layer(t, work, threads) : std::vector<char>();
  auto small = [&](index_t f) {
    return layer.empty() ? all_small[f] && work[f] <= share : layer[f] != 0;
  };
  p.subtree_of.assign(n, -1);
  for (index_t f = n - 1; f >= 0; --f) {
    if (!small(f)) continue;
    const index_t q = t.parent[f];
    if (q >= 0 && small(q)) {
      p.subtree_of[f] = p.subtree_of[q];
    } else {
      p.subtree_of[f] = static_cast<index_t>(p.subtree_root.size());
      p.subtree_root.push_back(f);
      p.subtree_first.push_back(f - size[f] + 1);
    }
  }
  // ids in increasing root order (the roots were found decreasing)
  const auto ns = static_cast<index_t>(p.subtree_root.size());
  std::reverse(p.subtree_root.begin(), p.subtree_root.end());
  std::reverse(p.subtree_first.begin(), p.subtree_first.end());
  for (index_t f = 0; f < n; ++f)
    if (p.subtree_of[f] >= 0) p.subtree_of[f] = ns - 1 - p.subtree_of[f];
  for (index_t s = 0; s < ns; ++s)
    for (index_t f = p.subtree_first[s]; f <= p.subtree_root[s]; ++f)
      if (f < 0 || p.subtree_of[f] != s)
        throw InternalError("plan_stack: small subtree " + std::to_string(s) +
                            " is not a range of the postorder");

  // 2.–3. steps and stack, in both arrangements; the lighter one
  p.cb_offset.assign(n, 0);
  p.build_offset.assign(n, 0);
  layout_regions(t, p);
  p.subtrees_first = false;
  make_steps(t, work, p);
  layout_main(t, p);
  if (!layer.empty() && ns > 1) {  // the layer's subtrees run together
    p.subtrees_first = true;
    make_steps(t, work, p);
    layout_main(t, p);
  } else if (threads > 1 && ns > 1) {
    StackPlan q = p;
    q.subtrees_first = true;
    make_steps(t, work, q);
    layout_main(t, q);
    if (q.main_size <= p.main_size + p.main_size / 10) p = std::move(q);
  }
  return p;
}

}  // namespace strata::schedule
