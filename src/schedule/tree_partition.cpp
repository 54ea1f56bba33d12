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
// Why score every state: Geist & Ng stop at the first balanced state, which is what we do
// when the tree allows it; but on a chain-like tree (separator blocking makes chains)
// balance may only come after moving much of the work into the top part, which one worker
// factors after all subtrees. Each state s gets the estimate T(s) = LPT makespan + top
// work, and the best state with at least workers × subtrees_per_worker subtrees (or the
// best of all when the tree never yields that many) is kept. The states form a sequence
// of splits, so the kept one is rebuilt by replaying a prefix.
//
// Upper layers: the top part above the subtrees holds the root separators, which on 3D
// problems are a large share of the flops (42% for lap3d 80³ on 4 GPUs), and as one part
// it runs on one worker while the others idle. But it is itself a tree, with the same
// independence between its subtrees: the root's children's subtrees, and so on. So the
// same split runs again on the fronts left in the top (T'), with a subtree's work counted
// over its T' fronts, and its best state — if it has at least 2 parts and saves more than
// the tolerance — becomes layer 1; then again on what is left (layer 2, …). This is
// MUMPS's layered view of tree parallelism above L0 (Amestoy et al. 2001) in its simplest
// static form: the parts of one layer are independent, each layer waits for the layers
// below it (a barrier), and each part's owner is fixed by LPT within its layer (no
// stealing), so that the worker exporting a block knows which worker will import it. The
// estimate "makespan + work left" counts no transfers: a layer's parts read the blocks of
// their children in lower layers, one block per such child, as the top part did.
// Within a layer's choice, the work left above the candidate parts is not counted as
// serial: later layers split it again, so it is estimated by Graham's lower bound for any
// schedule of it, max(its critical path, its work / workers) — the critical path being the
// heaviest root-to-leaf chain of its fronts (Graham, SIAM J. Appl. Math. 17, 1969). Counted
// as serial, a deeper split always looked worse on 3D nested-dissection trees (splitting
// a part moves its root separator, which outweighs a grandchild subtree, into "left"), and
// lap3d 80³ on 4 workers got one layer of 2 parts with two workers idle.
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

// One upper layer chosen from the fronts with in_top set (a set closed under parents):
// the roots of its parts (decreasing work, ties: increasing root), empty when no state
// is worth a layer. *makespan receives the layer's LPT makespan.
std::vector<index_t> choose_layer(const symbolic::AssemblyTree& t, const std::vector<char>& in_top,
                                  const PartitionOptions& o, double* makespan) {
  const index_t nf = t.n_fronts();
  std::vector<double> w(nf, 0.0);  // work over T' fronts of each T' subtree
  double top_work = 0;
  for (index_t f = 0; f < nf; ++f) {
    if (!in_top[f]) continue;
    const double x = symbolic::front_flops(t, f);
    w[f] += x;
    top_work += x;
    if (t.parent[f] >= 0) w[t.parent[f]] += w[f];  // the parent of a top front is in the top
  }
  if (top_work <= 0) return {};
  std::vector<index_t> t_roots;
  for (index_t f = 0; f < nf; ++f)
    if (in_top[f] && t.parent[f] < 0) t_roots.push_back(f);
  std::size_t k = 0, best_k = 0, best_count = 0;
  double best_time = 0, best_above = 0;
  const std::vector<index_t> sequence = split_sequence(
      t, w, t_roots, 64 * static_cast<std::size_t>(o.workers),
      [&](index_t h, std::vector<index_t>& kids) {
        for (index_t q = t.child_offsets[h]; q < t.child_offsets[h + 1]; ++q)
          if (in_top[t.children[q]]) kids.push_back(t.children[q]);
      },
      [&](const std::vector<index_t>& set, double left, double path) {
        // what later layers can make of the fronts left above: Graham's bound
        const double above = std::max(path, left / o.workers);
        const double time = score(set, w, o.workers).makespan + above;
        if (k == 0 || time < best_time) {
          best_k = k;
          best_time = time;
          best_above = above;
          best_count = set.size();
        }
        ++k;
        return false;
      });
  if (best_count < 2 || best_time >= (1 - o.tolerance) * top_work) return {};
  const std::vector<index_t> roots =
      state_roots(t, w, sequence, best_k, [&](index_t f) { return in_top[f] != 0; });
  *makespan = best_time - best_above;
  return roots;
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

  // the splitting sequence from the roots' subtrees; the kept state is the best with
  // enough subtrees (or the best of all), found again by replaying a prefix
  std::vector<index_t> tree_roots;
  for (index_t f = 0; f < nf; ++f)
    if (t.parent[f] < 0) tree_roots.push_back(f);
  const auto target = static_cast<std::size_t>(o.workers) * o.subtrees_per_worker;
  std::size_t k = 0, best_k = 0;
  bool best_enough = false;
  double best_time = 0;
  const std::vector<index_t> sequence = split_sequence(
      t, w, tree_roots, 64 * target,  // the cap bounds the search on degenerate trees
      [&](index_t h, std::vector<index_t>& kids) {
        for (index_t q = t.child_offsets[h]; q < t.child_offsets[h + 1]; ++q)
          kids.push_back(t.children[q]);
      },
      [&](const std::vector<index_t>& set, double left, double) {
        const Score sc = score(set, w, o.workers);
        const double time = sc.makespan + left;
        const bool enough = set.size() >= target;
        if (k == 0 || (enough && !best_enough) || (enough == best_enough && time < best_time)) {
          best_k = k;
          best_time = time;
          best_enough = enough;
        }
        ++k;
        return enough && sc.makespan <= (1 + o.tolerance) * (sc.subtree_work / o.workers);
      });
  const std::vector<index_t> roots =
      state_roots(t, w, sequence, best_k, [](index_t) { return true; });
  out.splits = static_cast<index_t>(best_k);
  out.part_of.assign(nf, -1);
  std::vector<double> items;
  for (std::size_t i = 0; i < roots.size(); ++i) {
    const index_t r = roots[i];
    std::vector<index_t> fronts;
    for (index_t f = first[r]; f <= r; ++f) {
      fronts.push_back(f);
      out.part_of[f] = static_cast<index_t>(i);
    }
    out.subtrees.push_back(make_part(t, r, std::move(fronts), o));
    items.push_back(w[r]);
  }
  double makespan = 0, sum = 0;
  out.owner = lpt_assign(items, o.workers, &makespan);
  for (double x : items) sum += x;
  out.balance = sum > 0 ? makespan / (sum / o.workers) : 1.0;
  out.estimated_time = makespan;

  // upper layers: the top split again while that pays
  const index_t n_sub = static_cast<index_t>(out.subtrees.size());
  out.part_id.assign(nf, n_sub);
  for (index_t f = 0; f < nf; ++f)
    if (out.part_of[f] >= 0) out.part_id[f] = out.part_of[f];
  std::vector<char> in_top(nf, 0);
  for (index_t f = 0; f < nf; ++f) in_top[f] = out.part_of[f] < 0;
  for (int layer = 1; o.upper_layers && layer <= kMaxUpperLayers; ++layer) {
    double layer_makespan = 0;
    const std::vector<index_t> uroots = choose_layer(t, in_top, o, &layer_makespan);
    if (uroots.empty()) break;
    const index_t base = n_sub + 1 + static_cast<index_t>(out.upper.size());
    // a front of the top below a root of this layer is in that root's part (the split
    // fronts are ancestors of the roots): parents first, downwards
    std::vector<index_t> in_part(nf, -1);
    for (std::size_t i = 0; i < uroots.size(); ++i) in_part[uroots[i]] = static_cast<index_t>(i);
    for (index_t f = nf - 1; f >= 0; --f)
      if (in_top[f] && in_part[f] < 0 && t.parent[f] >= 0 && in_part[t.parent[f]] >= 0)
        in_part[f] = in_part[t.parent[f]];
    std::vector<std::vector<index_t>> fronts(uroots.size());
    for (index_t f = 0; f < nf; ++f)
      if (in_part[f] >= 0) {
        fronts[in_part[f]].push_back(f);
        out.part_id[f] = base + in_part[f];
        in_top[f] = 0;
      }
    std::vector<double> work;
    for (std::size_t i = 0; i < uroots.size(); ++i) {
      out.upper.push_back(make_part(t, uroots[i], std::move(fronts[i]), o));
      work.push_back(out.upper.back().work);
    }
    const std::vector<int> own = lpt_assign(work, o.workers);
    out.upper_owner.insert(out.upper_owner.end(), own.begin(), own.end());
    out.upper_layer_offsets.push_back(static_cast<index_t>(out.upper.size()));
    out.estimated_time += layer_makespan;
  }
  std::vector<index_t> top;
  for (index_t f = 0; f < nf; ++f)
    if (in_top[f]) top.push_back(f);
  out.top = make_part(t, -1, std::move(top), o);
  out.estimated_time += out.top.work;
  return out;
}

}  // namespace strata::schedule
