// strata — the split of the assembly tree into subtrees for several workers
// (see tree_partition.hpp).
//
// What: Geist & Ng's subtree-splitting heuristic ("Task scheduling for parallel sparse
// Cholesky factorization", Int. J. Parallel Programming 18, 1989), the layer of
// independent subtrees that MUMPS calls L0 (Amestoy, Duff, Koster & L'Excellent, SIAM J.
// Matrix Anal. Appl. 23, 2001): keep a set of disjoint subtrees, initially the roots',
// and split the heaviest into its children's subtrees until there are enough of them
// and their largest-processing-time-first assignment (Graham, SIAM J. Appl. Math. 17,
// 1969) onto the workers is balanced. The fronts of split subtrees' roots form the top
// part.
//
// Why score every state: Geist & Ng stop at the first balanced state; but on a
// chain-like tree (separator blocking makes chains) balance may only come after moving
// much of the work into the top part. Each state with at least workers ×
// subtrees_per_worker subtrees (or every state, when the tree never yields that many) is
// scored by the estimate of the whole split — its upper layers chosen as below, then the
// list schedule's end + the top part's work — and the best is kept (without upper layers
// the estimate is LPT makespan + top work). The states form a sequence of splits, so the
// kept one is rebuilt by replaying a prefix.
//
// Upper layers: the top part above the subtrees holds the root separators, which on 3D
// problems are a large share of the flops (42% for lap3d 80³ on 4 GPUs), and as one part
// it runs on one worker while the others idle. But it is itself a tree, with the same
// independence between its subtrees: the root's children's subtrees, and so on. So the
// same split runs again on the fronts left in the top (T'), with a subtree's work counted
// over its T' fronts, and its best state becomes layer 1 if it saves more than the
// tolerance; then again on what is left (layer 2, …). This is MUMPS's layered view of
// tree parallelism above L0 (Amestoy et al. 2001), scheduled as a static list schedule:
// each part's owner is fixed (no stealing, so that the worker exporting a block knows
// which worker will import it), and the driver starts an upper part as soon as its
// worker is free and the parts below it are done — no barrier between layers. Owners are
// chosen for that schedule: a layer's parts, largest first, each go to the worker that
// would finish it first (earliest finish time, as in list scheduling of task graphs:
// Topcuoglu, Hariri & Wu, IEEE TPDS 13, 2002). Why not a barrier per layer with LPT
// owners: when one subtree holds a large share of the flops, the separator chain above
// the other worker's small subtrees could only start after the big one, and the top
// left serial caps the speedup; with the list schedule that chain runs beside the big
// subtree (bench/history.md has the lap3d 100³ case). A layer may have a single part,
// for the same reason.
// The estimate counts no transfers: a part reads the blocks of its children in lower
// layers, one block per such child, as the top part did. Within a layer's choice, the
// work left above the candidate parts is not counted as serial: later layers split it
// again, so it is estimated by Graham's lower bound for any schedule of it, max(its
// critical path, its work / workers) — the critical path being the heaviest root-to-leaf
// chain of its fronts (Graham, SIAM J. Appl. Math. 17, 1969). Counted as serial, a deeper
// split always looked worse on 3D nested-dissection trees (splitting a part moves its
// root separator, which outweighs a grandchild subtree, into "left"). That bound can be
// optimistic, so layers are kept only as far as the estimate with the rest left serial
// drops.
//
// Then each part gets its own level schedule, memory plan (same budget) and arena
// layout, so that a worker can factor it alone: fronts are numbered in postorder, so a
// subtree is the contiguous range first_descendant(root) .. root; an upper part is the
// fronts of such a range that are still in the top.
#include "schedule/tree_partition.hpp"

#include <algorithm>
#include <queue>
#include <string>

#include "strata/errors.hpp"

namespace strata::schedule {
namespace {

// Sum of `work` and the LPT makespan of the subtrees in `set` (sorted by decreasing work).
struct Score {
  double subtree_work = 0;
  double makespan = 0;
};

Score score(const std::vector<index_t>& set, const std::vector<double>& w, int workers) {
  std::vector<double> items;
  items.reserve(set.size());
  Score s;
  for (const index_t r : set) {
    items.push_back(w[r]);
    s.subtree_work += w[r];
  }
  std::sort(items.begin(), items.end(), std::greater<>());
  lpt_assign(items, workers, &s.makespan);
  return s;
}

FactorPart make_part(const symbolic::AssemblyTree& t, index_t root, std::vector<index_t> fronts,
                     const PartitionOptions& o) {
  FactorPart p;
  p.root = root;
  p.fronts = std::move(fronts);
  for (const index_t f : p.fronts) p.work += symbolic::front_flops(t, f);
  p.schedule = symbolic::level_schedule(t, p.fronts);
  p.plan = plan_memory(t, p.schedule, o.budget, o.unsymmetric);
  p.cb_layout = plan_cb_layout(t, p.schedule);
  p.imports = imported_children(t, p.schedule);
  return p;
}

// The splitting sequence shared by layer 0 and the upper layers: states k = 0, 1, … of a
// set of disjoint subtrees, from `roots`; state k + 1 replaces state k's heaviest subtree
// (by w; ties: the larger front number, a fixed rule) by its children's subtrees, the
// children being the members that children(h, kids) appends. stop(set, left) sees each
// state (set: its subtrees; left: Σ front_flops of the fronts split so far, which leave
// the subtrees; path: the heaviest chain of split fronts from a root down, by
// front_flops) and ends the sequence by returning true; it also ends at `cap` subtrees or
// when the heaviest subtree is a single member front. Returns the fronts split, in order.
template <class Children, class Stop>
std::vector<index_t> split_sequence(const symbolic::AssemblyTree& t, const std::vector<double>& w,
                                    const std::vector<index_t>& roots, std::size_t cap,
                                    Children&& children, Stop&& stop) {
  const auto heavier = [&](index_t a, index_t b) { return w[a] < w[b] || (w[a] == w[b] && a < b); };
  std::priority_queue<index_t, std::vector<index_t>, decltype(heavier)> heap(heavier);
  for (const index_t r : roots) heap.push(r);
  std::vector<index_t> sequence, set, kids;
  // chain[f]: the split fronts' work from a root down to f (a split front's parent is
  // split or outside the members, so it is known when f is split)
  std::vector<double> chain(t.n_fronts(), 0.0);
  double left = 0, path = 0;
  for (;;) {
    set.clear();
    for (auto copy = heap; !copy.empty(); copy.pop()) set.push_back(copy.top());
    if (stop(set, left, path) || heap.empty() || heap.size() >= cap) break;
    const index_t h = heap.top();
    kids.clear();
    children(h, kids);
    if (kids.empty()) break;
    heap.pop();
    const double x = symbolic::front_flops(t, h);
    left += x;
    chain[h] = x + (t.parent[h] >= 0 ? chain[t.parent[h]] : 0.0);
    path = std::max(path, chain[h]);
    for (const index_t c : kids) heap.push(c);
    sequence.push_back(h);
  }
  return sequence;
}

// The subtree roots of the state after the first `k` splits of `sequence`: the members
// not split whose parent is split or absent, by decreasing w (ties: increasing front).
template <class Member>
std::vector<index_t> state_roots(const symbolic::AssemblyTree& t, const std::vector<double>& w,
                                 const std::vector<index_t>& sequence, std::size_t k,
                                 Member&& member) {
  const index_t nf = t.n_fronts();
  std::vector<char> split(nf, 0);
  for (std::size_t i = 0; i < k; ++i) split[sequence[i]] = 1;
  std::vector<index_t> roots;
  for (index_t f = 0; f < nf; ++f) {
    const index_t p = t.parent[f];
    if (member(f) && !split[f] && (p < 0 || split[p])) roots.push_back(f);
  }
  std::sort(roots.begin(), roots.end(),
            [&](index_t a, index_t b) { return w[a] > w[b] || (w[a] == w[b] && a < b); });
  return roots;
}

// Where the parts placed so far stand in the list schedule the driver runs
// (multi_device.cpp): each worker factors its subtrees in queue order, then its upper
// parts in layer order, each starting when the worker is free and the parts it imports
// from are done. finish is indexed by part id (the top part's slot unused).
struct ScheduleState {
  std::vector<double> finish;  ///< per part id: when it is done
  std::vector<double> free;    ///< per worker: when its last part is done
  double end() const {
    double e = 0;
    for (double x : free) e = std::max(e, x);
    return e;
  }
};

// The worker that finishes a part of this work, ready at `ready`, first (earliest finish
// time, ties: the lowest index), and that finish.
std::pair<int, double> earliest_finish(const std::vector<double>& free, double ready, double work) {
  int best = 0;
  double best_t = 0;
  for (int w = 0; w < static_cast<int>(free.size()); ++w) {
    const double t = std::max(free[w], ready) + work;
    if (w == 0 || t < best_t) {
      best = w;
      best_t = t;
    }
  }
  return {best, best_t};
}

// One upper layer chosen from the fronts with in_top set (a set closed under parents).
struct Layer {
  std::vector<index_t> roots;  ///< its parts' roots, decreasing work (ties: increasing root)
  std::vector<int> owners;     ///< the worker of each (earliest finish, in that order)
  std::vector<double> finish;  ///< when each is done in the list schedule
};

// The best state of the split of the top tree T' (in_top) under the list schedule `s`:
// each candidate part goes, largest first, to the worker that finishes it first, given
// when that worker is free and when the parts below it are done; a state's estimate is
// the end of that schedule + Graham's bound on what is left above. Empty roots when no
// state with at least one split beats "the top part after everything" by more than
// tolerance × the top's work.
Layer choose_layer(const symbolic::AssemblyTree& t, const std::vector<char>& in_top,
                   const std::vector<index_t>& part_id, const ScheduleState& s,
                   const PartitionOptions& o) {
  const index_t nf = t.n_fronts();
  std::vector<double> w(nf, 0.0);      // work over T' fronts of each T' subtree
  std::vector<double> ready(nf, 0.0);  // when every part a T' subtree imports from is done
  double top_work = 0;
  for (index_t f = 0; f < nf; ++f) {
    if (!in_top[f]) continue;
    const double x = symbolic::front_flops(t, f);
    w[f] += x;
    top_work += x;
    for (index_t q = t.child_offsets[f]; q < t.child_offsets[f + 1]; ++q) {
      const index_t c = t.children[q];
      if (!in_top[c]) ready[f] = std::max(ready[f], s.finish[part_id[c]]);
    }
    if (t.parent[f] >= 0) {  // the parent of a top front is in the top
      w[t.parent[f]] += w[f];
      ready[t.parent[f]] = std::max(ready[t.parent[f]], ready[f]);
    }
  }
  if (top_work <= 0) return {};
  std::vector<index_t> t_roots;
  for (index_t f = 0; f < nf; ++f)
    if (in_top[f] && t.parent[f] < 0) t_roots.push_back(f);
  const auto order = [&](index_t a, index_t b) { return w[a] > w[b] || (w[a] == w[b] && a < b); };
  const double before = s.end();
  std::size_t k = 0, best_k = 0;
  double best_time = 0;
  std::vector<index_t> sorted;
  const std::vector<index_t> sequence = split_sequence(
      t, w, t_roots, 64 * static_cast<std::size_t>(o.workers),
      [&](index_t h, std::vector<index_t>& kids) {
        for (index_t q = t.child_offsets[h]; q < t.child_offsets[h + 1]; ++q)
          if (in_top[t.children[q]]) kids.push_back(t.children[q]);
      },
      [&](const std::vector<index_t>& set, double left, double path) {
        // state 0 is the whole top as parts: nothing would be left for the top part
        if (k++ == 0) return false;
        sorted = set;
        std::sort(sorted.begin(), sorted.end(), order);
        std::vector<double> free = s.free;
        double end = before;
        for (const index_t r : sorted) {
          const auto [wk, fin] = earliest_finish(free, ready[r], w[r]);
          free[wk] = fin;
          end = std::max(end, fin);
        }
        // what later layers can make of the fronts left above: Graham's bound
        const double time = end + std::max(path, left / o.workers);
        if (best_k == 0 || time < best_time) {
          best_k = k - 1;
          best_time = time;
        }
        return false;
      });
  if (best_k == 0 || best_time >= before + (1 - o.tolerance) * top_work) return {};
  Layer out;
  out.roots = state_roots(t, w, sequence, best_k, [&](index_t f) { return in_top[f] != 0; });
  std::vector<double> free = s.free;
  for (const index_t r : out.roots) {
    const auto [wk, fin] = earliest_finish(free, ready[r], w[r]);
    free[wk] = fin;
    out.owners.push_back(wk);
    out.finish.push_back(fin);
  }
  return out;
}

// The upper layers above one layer-0 state (subtree roots `roots`, decreasing work, on
// workers `owner`), chosen layer by layer by choose_layer, and the list-schedule estimate
// (its end + the top part's work). Layers are kept only as far as they lower that
// estimate (choose_layer judges a layer by a bound on what is left above it, which later
// layers may not reach), so the estimate is never above the one without upper layers.
struct UpperPlan {
  std::vector<Layer> layers;
  std::vector<index_t> upper_of;  ///< per front: index of its upper part over all layers, or -1
  double estimate = 0;
};

UpperPlan plan_upper(const symbolic::AssemblyTree& t, const std::vector<index_t>& roots,
                     const std::vector<int>& owner, const std::vector<double>& w,
                     const std::vector<index_t>& first, const PartitionOptions& o) {
  const index_t nf = t.n_fronts();
  const auto n_sub = static_cast<index_t>(roots.size());
  UpperPlan out;
  ScheduleState sched;
  sched.free.assign(o.workers, 0.0);
  sched.finish.assign(n_sub + 1, 0.0);
  std::vector<index_t> part_id(nf, n_sub);
  std::vector<char> in_top(nf, 1);
  for (index_t i = 0; i < n_sub; ++i) {
    const index_t r = roots[i];
    sched.finish[i] = sched.free[owner[i]] += w[r];
    for (index_t f = first[r]; f <= r; ++f) {
      part_id[f] = i;
      in_top[f] = 0;
    }
  }
  double top_work = 0;
  for (index_t f = 0; f < nf; ++f)
    if (in_top[f]) top_work += symbolic::front_flops(t, f);
  out.estimate = sched.end() + top_work;
  out.upper_of.assign(nf, -1);
  std::size_t keep = 0;
  index_t n_upper = 0;
  for (int layer = 1; o.upper_layers && layer <= kMaxUpperLayers; ++layer) {
    Layer chosen = choose_layer(t, in_top, part_id, sched, o);
    if (chosen.roots.empty()) break;
    // a front of the top below a root of this layer is in that root's part (the split
    // fronts are ancestors of the roots): parents first, downwards
    std::vector<index_t> in_part(nf, -1);
    for (std::size_t i = 0; i < chosen.roots.size(); ++i)
      in_part[chosen.roots[i]] = static_cast<index_t>(i);
    for (index_t f = nf - 1; f >= 0; --f)
      if (in_top[f] && in_part[f] < 0 && t.parent[f] >= 0 && in_part[t.parent[f]] >= 0)
        in_part[f] = in_part[t.parent[f]];
    for (index_t f = 0; f < nf; ++f)
      if (in_part[f] >= 0) {
        out.upper_of[f] = n_upper + in_part[f];
        part_id[f] = n_sub + 1 + n_upper + in_part[f];
        in_top[f] = 0;
        top_work -= symbolic::front_flops(t, f);
      }
    for (std::size_t i = 0; i < chosen.roots.size(); ++i) {
      sched.finish.push_back(chosen.finish[i]);
      sched.free[chosen.owners[i]] = chosen.finish[i];
    }
    n_upper += static_cast<index_t>(chosen.roots.size());
    out.layers.push_back(std::move(chosen));
    const double estimate = sched.end() + std::max(top_work, 0.0);
    if (estimate < out.estimate) {
      out.estimate = estimate;
      keep = out.layers.size();
    }
  }
  index_t kept_parts = 0;
  for (std::size_t l = 0; l < keep; ++l)
    kept_parts += static_cast<index_t>(out.layers[l].roots.size());
  out.layers.resize(keep);
  for (index_t& u : out.upper_of)
    if (u >= kept_parts) u = -1;
  return out;
}

}  // namespace

const FactorPart& TreePartition::part(int id) const {
  const int s = top_id();
  if (id < 0 || id >= n_parts())
    throw InvalidInput("TreePartition::part: id " + std::to_string(id) + " out of range [0, " +
                       std::to_string(n_parts()) + ")");
  if (id < s) return subtrees[id];
  if (id == s) return top;
  return upper[id - s - 1];
}

int TreePartition::worker_of(int id) const {
  const int s = top_id();
  if (id < 0 || id >= n_parts())
    throw InvalidInput("TreePartition::worker_of: id " + std::to_string(id) + " out of range");
  if (id < s) return owner[id];
  if (id == s) return 0;
  return upper_owner[id - s - 1];
}

std::vector<std::vector<int>> TreePartition::layers() const {
  std::vector<std::vector<int>> l(1);
  for (int id = 0; id < top_id(); ++id) l[0].push_back(id);
  for (int k = 1; k <= n_upper_layers(); ++k) {
    l.emplace_back();
    for (index_t q = upper_layer_offsets[k - 1]; q < upper_layer_offsets[k]; ++q)
      l.back().push_back(top_id() + 1 + static_cast<int>(q));
  }
  l.push_back({top_id()});
  return l;
}

std::vector<int> lpt_assign(const std::vector<double>& work, int workers, double* makespan) {
  std::vector<int> owner(work.size(), 0);
  std::vector<double> load(std::max(workers, 1), 0.0);
  for (std::size_t i = 0; i < work.size(); ++i) {
    const auto k = std::min_element(load.begin(), load.end()) - load.begin();
    owner[i] = static_cast<int>(k);
    load[k] += work[i];
  }
  if (makespan) *makespan = *std::max_element(load.begin(), load.end());
  return owner;
}

TreePartition partition_tree(const symbolic::AssemblyTree& t, const PartitionOptions& o) {
  if (o.workers < 1 || o.subtrees_per_worker < 1)
    throw InvalidInput("partition_tree: workers (" + std::to_string(o.workers) +
                       ") and subtrees_per_worker (" + std::to_string(o.subtrees_per_worker) +
                       ") must be at least 1");
  const index_t nf = t.n_fronts();
  TreePartition out;
  out.workers = o.workers;
  // subtree work and first descendant (postorder: children before parents)
  std::vector<double> w(nf, 0.0);
  std::vector<index_t> first(nf);
  for (index_t f = 0; f < nf; ++f) {
    w[f] += symbolic::front_flops(t, f);
    first[f] = f;
  }
  for (index_t f = 0; f < nf; ++f)
    if (t.parent[f] >= 0) {
      w[t.parent[f]] += w[f];
      first[t.parent[f]] = std::min(first[t.parent[f]], first[f]);
    }
  for (index_t f = 0; f < nf; ++f)
    if (t.parent[f] < 0) out.total_work += w[f];

  // the splitting sequence from the roots' subtrees; each state with enough subtrees (or
  // every state, when the tree never yields enough) is judged with its upper layers, and
  // the best is found again by replaying a prefix
  std::vector<index_t> tree_roots;
  for (index_t f = 0; f < nf; ++f)
    if (t.parent[f] < 0) tree_roots.push_back(f);
  const auto target = static_cast<std::size_t>(o.workers) * o.subtrees_per_worker;
  std::size_t n_states = 0;
  bool any_enough = false;
  const std::vector<index_t> sequence = split_sequence(
      t, w, tree_roots, 64 * target,  // the cap bounds the search on degenerate trees
      [&](index_t h, std::vector<index_t>& kids) {
        for (index_t q = t.child_offsets[h]; q < t.child_offsets[h + 1]; ++q)
          kids.push_back(t.children[q]);
      },
      [&](const std::vector<index_t>& set, double, double) {
        const Score sc = score(set, w, o.workers);
        const bool enough = set.size() >= target;
        any_enough = any_enough || enough;
        ++n_states;
        return enough && sc.makespan <= (1 + o.tolerance) * (sc.subtree_work / o.workers);
      });
  const auto all = [](index_t) { return true; };
  // every candidate's estimate and number of parts; then the fewest parts among those
  // within fewer_parts_slack of the best estimate (ties: the better estimate, the earlier
  // state), rebuilt
  struct Candidate {
    std::size_t k;
    double estimate;
    std::size_t parts;
  };
  std::vector<Candidate> candidates;
  // the LPT owners of state roots r, and their upper layers
  const auto plan_state = [&](const std::vector<index_t>& r, std::vector<int>& own) {
    std::vector<double> items;
    for (const index_t x : r) items.push_back(w[x]);
    own = lpt_assign(items, o.workers);
    return plan_upper(t, r, own, w, first, o);
  };
  double best_estimate = 0;
  for (std::size_t k = 0; k < n_states; ++k) {
    const std::vector<index_t> r = state_roots(t, w, sequence, k, all);
    if (any_enough && r.size() < target) continue;
    std::vector<int> own;
    const UpperPlan p = plan_state(r, own);
    std::size_t parts = r.size();
    for (const Layer& l : p.layers) parts += l.roots.size();
    candidates.push_back({k, p.estimate, parts});
    if (candidates.size() == 1 || p.estimate < best_estimate) best_estimate = p.estimate;
  }
  const Candidate* pick = nullptr;
  for (const Candidate& c : candidates)
    if (c.estimate <= best_estimate * (1 + o.fewer_parts_slack) &&
        (!pick || c.parts < pick->parts || (c.parts == pick->parts && c.estimate < pick->estimate)))
      pick = &c;
  const std::size_t best_k = pick ? pick->k : 0;
  const std::vector<index_t> roots = state_roots(t, w, sequence, best_k, all);
  std::vector<int> owner;
  const UpperPlan plan = plan_state(roots, owner);
  out.splits = static_cast<index_t>(best_k);
  out.owner = owner;
  out.part_of.assign(nf, -1);
  double makespan = 0, sum = 0;
  {
    std::vector<double> load(o.workers, 0.0);
    for (std::size_t i = 0; i < roots.size(); ++i) {
      const index_t r = roots[i];
      std::vector<index_t> fronts;
      for (index_t f = first[r]; f <= r; ++f) {
        fronts.push_back(f);
        out.part_of[f] = static_cast<index_t>(i);
      }
      out.subtrees.push_back(make_part(t, r, std::move(fronts), o));
      load[owner[i]] += w[r];
      sum += w[r];
    }
    makespan = *std::max_element(load.begin(), load.end());
  }
  out.balance = sum > 0 ? makespan / (sum / o.workers) : 1.0;

  // the upper layers of the kept state, and the top part: the rest
  const auto n_sub = static_cast<index_t>(out.subtrees.size());
  out.part_id.assign(nf, n_sub);
  for (index_t f = 0; f < nf; ++f)
    if (out.part_of[f] >= 0) out.part_id[f] = out.part_of[f];
  std::vector<std::vector<index_t>> upper_fronts;
  for (const Layer& layer : plan.layers)
    for (std::size_t i = 0; i < layer.roots.size(); ++i) upper_fronts.emplace_back();
  std::vector<index_t> top;
  for (index_t f = 0; f < nf; ++f) {
    const index_t u = plan.upper_of[f];
    if (u >= 0) {
      upper_fronts[u].push_back(f);
      out.part_id[f] = n_sub + 1 + u;
    } else if (out.part_of[f] < 0) {
      top.push_back(f);
    }
  }
  std::size_t u = 0;
  for (const Layer& layer : plan.layers) {
    for (std::size_t i = 0; i < layer.roots.size(); ++i, ++u) {
      out.upper.push_back(make_part(t, layer.roots[i], std::move(upper_fronts[u]), o));
      out.upper_owner.push_back(layer.owners[i]);
    }
    out.upper_layer_offsets.push_back(static_cast<index_t>(out.upper.size()));
  }
  out.top = make_part(t, -1, std::move(top), o);
  out.estimated_time = plan.estimate;
  return out;
}

}  // namespace strata::schedule
