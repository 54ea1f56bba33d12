// strata — the nested dissection driver (see ordering.hpp).
//
// What: a fill-reducing ordering by recursive vertex-separator bisection. A subgraph is
// split into its connected components first (each is ordered on its own; they become
// siblings under a tree node with an empty separator); a subgraph of at most
// `leaf_size` vertices is a leaf, ordered by AMD; any other subgraph is cut by
// METIS_ComputeVertexSeparator into part 0, part 1 and a separator, numbered in that
// order (the separator last), and the two parts are dissected in turn. The result is the
// permutation and the separator tree, whose nodes own contiguous ranges of pivots.
//
// Why our own driver rather than METIS_NodeND: the separator tree is what the symbolic
// phase, the level schedule and the multi-GPU split work on, and the driver is where
// strata controls leaf sizes and, later, balances the top bisections by work. METIS
// itself (multilevel node bisection: coarsening, initial separator, FM refinement) is
// used as is.
//
// Quality: METIS_NodeND compresses vertices with identical closed adjacency before it
// dissects (a 3-dof-per-node mesh has three such vertices per node), which both speeds it
// up and improves the separators of multi-dof problems; it then tries 2 separators per
// bisection where the graph compressed by more than 1.5x. This driver does the same:
// the graph is compressed once (when that removes at least 15% of the vertices, as in
// METIS), bisections work on the compressed graph with vertex weights, and leaves are
// expanded back to the original vertices before AMD (which finds indistinguishable
// vertices on its own). In addition the top three levels keep the best of 3 separators,
// since the top separators dominate the fill (see kTopLevels).
//
// Tree shape: small components (at most leaf_size vertices) are packed together into
// shared leaves rather than given one node each, so a graph with many isolated vertices
// does not get a node per vertex. A leaf exceeds leaf_size only when the subgraph cannot
// be bisected: it compresses to fewer than 3 vertices (e.g. a clique), or METIS returns
// an empty part.
//
// Groups (the overload with VertexGroups): the graph given is a quotient graph whose vertex
// v stands for the members of group v (a 2×2 pivot pair of the symmetric matching, see
// pairing.cpp). Everything above runs on that graph with vertex weights = group sizes
// (compression adds the weights of the vertices it merges, METIS balances and minimises
// weights, leaf sizes count members), and a vertex is expanded into its members, in the
// group's order, wherever a vertex is numbered. AMD in the leaves orders the quotient
// subgraph unweighted. Without groups every vertex is its own group of weight 1.
//
// Balance by work (NestedDissectionOptions::balance_levels > 0, several workers): METIS
// balances the vertex counts of the two sides of a bisection, but the multi-worker split
// of the tree wants its top subtrees balanced by factorization work, which vertex counts
// predict poorly (a side touching more of the separator, or the boundary, fills more).
// After the whole dissection, the top balance_levels levels are revisited top-down. For
// each bisection there, the work of each side is estimated exactly for the ordering just
// made — Σ colcount² over its columns, from the elimination tree and the Gilbert–Ng–Peyton
// column counts of the whole graph under the current permutation (O(nnz·α), much less
// than the dissection itself). A bisection whose sides' work differs by more than
// balance_tolerance (max side / mean − 1) is redone: METIS gets the vertices of the
// heavier side weighted by α = (w_heavy / w_light)^(1/2) · n_light / n_heavy (work of
// a nested-dissection subtree of a 3D mesh grows like n², so this equalises the model
// c·n² of both sides when the new cut lies near the old), and the subgraph is dissected
// again below it. All redone bisections of one level share one work estimate; a redo that
// is not better balanced than the best so far is undone (the previous permutation segment
// and subtree are restored), and at most balance_attempts redos are made per bisection.
// So the ordering is never less balanced than METIS's, and costs at most one extra
// dissection of the redone subgraphs per attempt. The idea of steering the bisection by
// work rather than by vertex count is the paper's "balanced graph bisection" (Jung & Bae
// 2018); the exponent comes from George 1973 (nested dissection of a k×k×k grid costs
// O(n²) flops).
//
// Threads: the two parts of a bisection (and the components of a split) share no edge, so
// once a cut has left large pieces they are dissected side by side over the calling TBB
// arena's threads, each piece in a region of its own whose tree nodes are appended in the
// order of the sequential walk. METIS draws its random numbers from the C library's
// rand(), one state per process; strata gives each thread its own state, seeded as METIS
// seeds it (metis_random.hpp), so every METIS call gets the numbers it would get alone and
// the permutation and tree are the same for any thread count. Where that does not take
// effect (strata loaded as a shared module), the driver keeps to one thread.
//
// Robustness: the recursion is an explicit stack of pending subgraphs (disjoint, so O(n)
// memory in all), so a degenerate chain of bisections cannot overflow the call stack (the
// regions dissected side by side nest at most kSideBySideLevels deep). A
// bisection that leaves a part empty is not followed: the subgraph is ordered as one
// AMD leaf instead. METIS 5.1 uses 32-bit indices; a subgraph that does not fit is
// rejected with InvalidInput.
//
// Sources: George, "Nested dissection of a regular finite element mesh", SIAM J. Numer.
// Anal. 10 (1973); Karypis & Kumar, "A fast and high quality multilevel scheme for
// partitioning irregular graphs", SIAM J. Sci. Comput. 20 (1998), and METIS 5.1's
// ometis.c/compress.c for the compression and separator-count rules; Amestoy, Davis &
// Duff, "An approximate minimum degree ordering algorithm", SIAM J. Matrix Anal. Appl. 17
// (1996) for the leaves.
#include <metis.h>
#include <tbb/parallel_for.h>
#include <tbb/parallel_sort.h>
#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <numeric>
#include <string>

#include "base/parallel_ranges.hpp"
#include "base/serial_scope.hpp"
#include "ordering/metis_random.hpp"
#include "ordering/ordering.hpp"
#include "strata/errors.hpp"
#include "symbolic/symbolic.hpp"

namespace strata::ordering {
namespace {

// METIS compresses when the compressed graph has fewer than this fraction of the vertices.
constexpr double kCompressionFraction = 0.85;
// The top separators dominate the fill (the root separator of a 3D grid alone becomes a
// dense n^(2/3) block), so the first kTopLevels levels of bisection may keep the best of
// NestedDissectionOptions::top_separators METIS separators. Measured (nnz(L) ND/NodeND,
// CPU time) with 3: 7-point 60^3 0.995 -> 0.93; 7-point 100^3 0.989 -> 0.949 for
// 11 s -> 14 s. Deeper levels use METIS_NodeND's rule (below).
constexpr int kTopLevels = 3;
// METIS ufactor (imbalance allowed, in 1/1000) of the bisections redone to balance work.
constexpr idx_t kBalanceUfactor = 20;

// The graph with indistinguishable vertices (equal closed neighbourhoods) merged. Compressed
// vertex c stands for the original vertices members[mptr[c] .. mptr[c+1]-1] and has weight
// mptr[c+1]-mptr[c]. When compression does not pay, `active` is false and the compressed
// graph is the original one (xadj/adjncy are then left empty and the caller uses g's).
struct Compressed {
  bool active = false;
  index_t n = 0;
  std::vector<index_t> xadj, adjncy;
  std::vector<index_t> mptr, members;
};

// Compression as in METIS's CompressGraph: vertices are sorted by the sum of their closed
// neighbourhood, and within a run of equal sums a vertex joins the group of an earlier
// one when it has the same degree and the same closed neighbourhood. Isolated vertices
// are never merged (their closed neighbourhoods differ). Groups are numbered in the order
// of their first members in the sorted list.
//
// Over the threads (graphs whose adjacency lists are sorted, as graph_of and
// detail::symmetric_graph make them): the sums, the sort (the keys are distinct: the
// vertex breaks ties), the comparison of closed neighbourhoods within each run (runs are
// independent; two sorted lists are compared by merging, without a mark array) and the
// compressed adjacency lists run in ranges; the numbering of groups is one sequential
// pass. The result is that of the sequential marking, which an unsorted graph still gets.

// Whether u and v (u ≠ v, equal degrees) have the same closed neighbourhood, their
// adjacency lists being sorted: the merged sequences adj(u) ∪ {u} and adj(v) ∪ {v}.
bool same_closed_neighbourhood(const Graph& g, index_t u, index_t v) {
  // one vertex's closed neighbourhood in increasing order: its list with itself merged in
  struct Closed {
    const Graph& g;
    index_t self, p, end;
    bool self_done = false;
    bool empty() const { return p == end && self_done; }
    index_t next() {
      if (!self_done && (p == end || self < g.adjncy[p])) {
        self_done = true;
        return self;
      }
      return g.adjncy[p++];
    }
  };
  Closed a{g, u, g.xadj[u], g.xadj[u + 1]}, b{g, v, g.xadj[v], g.xadj[v + 1]};
  while (!a.empty() && !b.empty())
    if (a.next() != b.next()) return false;
  return a.empty() && b.empty();
}

bool adjacency_sorted(const Graph& g) {
  std::atomic<bool> sorted{true};
  detail::parallel_ranges(g.n, 1024, [&](index_t v0, index_t v1) {
    for (index_t v = v0; v < v1 && sorted.load(std::memory_order_relaxed); ++v)
      for (index_t p = g.xadj[v] + 1; p < g.xadj[v + 1]; ++p)
        if (g.adjncy[p] <= g.adjncy[p - 1]) sorted = false;
  });
  return sorted;
}

Compressed compress(const Graph& g) {
  const index_t n = g.n;
  Compressed c;
  if (n < 2) return c;
  std::vector<std::pair<std::uint64_t, index_t>> keys(n);
  detail::parallel_ranges(n, 1024, [&](index_t v0, index_t v1) {
    for (index_t v = v0; v < v1; ++v) {
      std::uint64_t s = static_cast<std::uint64_t>(v);
      for (index_t p = g.xadj[v]; p < g.xadj[v + 1]; ++p)
        s += static_cast<std::uint64_t>(g.adjncy[p]);
      keys[v] = {s, v};
    }
  });
  if (detail::serial_passes())
    std::sort(keys.begin(), keys.end());
  else
    tbb::parallel_sort(keys.begin(), keys.end());
  // rep[v]: the first vertex of v's group in the sorted order
  std::vector<index_t> rep(n, -1);
  if (adjacency_sorted(g)) {
    std::vector<index_t> run_start{0};  // runs of equal sums in the sorted order
    for (index_t a = 1; a < n; ++a)
      if (keys[a].first != keys[a - 1].first) run_start.push_back(a);
    run_start.push_back(n);
    const auto runs = static_cast<index_t>(run_start.size()) - 1;
    detail::parallel_ranges(runs, 256, [&](index_t r0, index_t r1) {
      for (index_t r = r0; r < r1; ++r)
        for (index_t a = run_start[r]; a < run_start[r + 1]; ++a) {
          const index_t u = keys[a].second;
          if (rep[u] >= 0) continue;
          rep[u] = u;
          const index_t du = g.xadj[u + 1] - g.xadj[u];
          if (du == 0) continue;
          for (index_t b = a + 1; b < run_start[r + 1]; ++b) {
            const index_t v = keys[b].second;
            if (rep[v] < 0 && g.xadj[v + 1] - g.xadj[v] == du && same_closed_neighbourhood(g, u, v))
              rep[v] = u;
          }
        }
    });
  } else {  // the sequential marking of closed neighbourhoods
    std::vector<index_t> mark(n, -1);
    for (index_t a = 0; a < n; ++a) {
      const index_t u = keys[a].second;
      if (rep[u] >= 0) continue;
      rep[u] = u;
      const index_t du = g.xadj[u + 1] - g.xadj[u];
      if (du == 0) continue;
      mark[u] = u;
      for (index_t p = g.xadj[u]; p < g.xadj[u + 1]; ++p) mark[g.adjncy[p]] = u;
      for (index_t b = a + 1; b < n && keys[b].first == keys[a].first; ++b) {
        const index_t v = keys[b].second;
        if (rep[v] >= 0 || g.xadj[v + 1] - g.xadj[v] != du || mark[v] != u) continue;
        bool same = true;
        for (index_t p = g.xadj[v]; p < g.xadj[v + 1] && same; ++p) same = mark[g.adjncy[p]] == u;
        if (same) rep[v] = u;
      }
    }
  }
  std::vector<index_t> group(n, -1), first;  // first: the representative of each group
  first.reserve(n);
  for (index_t a = 0; a < n; ++a) {
    const index_t u = keys[a].second;
    if (rep[u] == u) {
      group[u] = static_cast<index_t>(first.size());
      first.push_back(u);
    }
  }
  const auto cn = static_cast<index_t>(first.size());
  if (static_cast<double>(cn) >= kCompressionFraction * static_cast<double>(n)) return c;
  for (index_t v = 0; v < n; ++v) group[v] = group[rep[v]];

  c.active = true;
  c.n = cn;
  c.mptr.assign(cn + 1, 0);
  for (index_t v = 0; v < n; ++v) ++c.mptr[group[v] + 1];
  for (index_t k = 0; k < cn; ++k) c.mptr[k + 1] += c.mptr[k];
  c.members.resize(n);
  {
    std::vector<index_t> next(c.mptr.begin(), c.mptr.end() - 1);
    for (index_t v = 0; v < n; ++v) c.members[next[group[v]]++] = v;
  }
  // Adjacency of a compressed vertex: the groups of its representative's neighbours (all
  // members of a neighbouring group are neighbours too), sorted, without repeats or the
  // vertex itself; in fixed ranges of compressed vertices, each into its own list, joined
  // in order.
  const index_t ranges =
      detail::serial_passes() || cn < 4096 ? 1 : std::min<index_t>(cn / 4096, 256);
  std::vector<std::vector<index_t>> part(ranges);
  c.xadj.assign(cn + 1, 0);
  auto range_of = [&](index_t r) { return static_cast<index_t>(std::int64_t{cn} * r / ranges); };
  auto build = [&](index_t r) {
    std::vector<index_t>& out = part[r];
    for (index_t k = range_of(r); k < range_of(r + 1); ++k) {
      const index_t u = first[k];
      const std::size_t at = out.size();
      for (index_t p = g.xadj[u]; p < g.xadj[u + 1]; ++p) {
        const index_t h = group[g.adjncy[p]];
        if (h != k) out.push_back(h);
      }
      std::sort(out.begin() + static_cast<std::ptrdiff_t>(at), out.end());
      out.erase(std::unique(out.begin() + static_cast<std::ptrdiff_t>(at), out.end()), out.end());
      c.xadj[k + 1] = static_cast<index_t>(out.size() - at);
    }
  };
  if (ranges == 1)
    build(0);
  else
    tbb::parallel_for(index_t{0}, ranges, build);
  for (index_t k = 0; k < cn; ++k) c.xadj[k + 1] += c.xadj[k];
  c.adjncy.resize(c.xadj[cn]);
  detail::parallel_ranges(ranges, 1, [&](index_t r0, index_t r1) {
    for (index_t r = r0; r < r1; ++r)
      std::copy(part[r].begin(), part[r].end(), c.adjncy.begin() + c.xadj[range_of(r)]);
  });
  return c;
}

// Pieces dissected side by side (Driver::drain): at most this many levels of regions
// inside regions, and only when the pieces of a cut weigh this many vertices together.
constexpr int kSideBySideLevels = 24;
constexpr index_t kSideBySideWeight = 1024;
// Task::parent of a region's first subgraph: the node of the enclosing region that the
// region's Region::outer_parent names.
constexpr index_t kOuter = -2;

// A pending subgraph: compressed vertices `verts`, total weight (original vertices)
// `weight`, to be numbered from pivot `lo`, hanging under tree node `parent` (-1: root).
struct Task {
  std::vector<index_t> verts;
  index_t weight = 0;
  index_t lo = 0;
  index_t parent = -1;
  int depth = 0;  ///< number of bisections above
};

// The nodes made and the subgraphs pending in one sequential part of the dissection: the
// whole graph's (Driver::top_), or a piece's dissected side by side with others. Node ids
// and Task::parent are indices into `nodes`; kOuter stands for outer_parent, a node of the
// enclosing region.
struct Region {
  std::vector<SeparatorTree::Node> nodes;
  std::vector<Task> stack;
  index_t outer_parent = -1;
};

class Driver {
 public:
  Driver(const Graph& g, const NestedDissectionOptions& opts, const VertexGroups* groups)
      : g_(g), opts_(opts), groups_(groups) {}

  OrderingResult run() {
    OrderingResult r;
    const index_t n = g_.n;
    if (n == 0) return r;
    const index_t total = groups_ ? groups_->ptr.back() : n;  // pivots to number
    perm_.assign(total, -1);

    cg_ = compress(g_);
    if (cg_.active) {
      cn_ = cg_.n;
      cx_ = cg_.xadj.data();
      ca_ = cg_.adjncy.data();
    } else {
      cn_ = n;
      cx_ = g_.xadj.data();
      ca_ = g_.adjncy.data();
    }
    cweight_.resize(cn_);
    for (index_t c = 0; c < cn_; ++c) {
      if (!cg_.active) {
        cweight_[c] = group_size(c);
        continue;
      }
      cweight_[c] = 0;
      for (index_t p = cg_.mptr[c]; p < cg_.mptr[c + 1]; ++p)
        cweight_[c] += group_size(cg_.members[p]);
    }
    // METIS_NodeND's rule unless the options name a count: 2 separators per bisection when
    // compression was effective.
    nseps_ = (cg_.active && static_cast<double>(n) > 1.5 * static_cast<double>(cn_)) ? 2 : 1;
    if (opts_.separators > 0) nseps_ = opts_.separators;
    top_separators_ = std::max(1, opts_.top_separators);
    cloc_.assign(cn_, -1);
    oloc_.assign(n, -1);

    vfirst_.assign(n, -1);
    Task root;
    root.verts.resize(cn_);
    std::iota(root.verts.begin(), root.verts.end(), index_t{0});
    root.weight = total;
    root_ = dissect(top_, root);
    if (opts_.balance_levels > 0 && !info_.empty()) {
      const auto t0 = std::chrono::steady_clock::now();
      balance_by_work();
      r.balance_seconds =
          std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
      r.rebisections = rebisections_;
    }
    r.side_by_side = side_by_side_pieces_.load();
    r.perm = std::move(perm_);
    r.tree = postorder_tree();
    return r;
  }

 private:
  // Pivots that vertex v of g_ stands for (its group's size, 1 without groups).
  index_t group_size(index_t v) const { return groups_ ? groups_->size(v) : 1; }

  // Pivots that compressed vertex c stands for.
  index_t weight(index_t c) const { return cweight_[c]; }

  // Numbers the members of vertex v of g_ from pivot k on; returns the next pivot.
  index_t number(index_t v, index_t k) {
    vfirst_[v] = k;
    if (!groups_) {
      perm_[k] = v;
      return k + 1;
    }
    for (index_t p = groups_->ptr[v]; p < groups_->ptr[v + 1]; ++p)
      perm_[k++] = groups_->members[p];
    return k;
  }

  // Appends the original vertices of compressed vertex c to out.
  void expand(index_t c, std::vector<index_t>& out) const {
    if (!cg_.active) {
      out.push_back(c);
      return;
    }
    for (index_t p = cg_.mptr[c]; p < cg_.mptr[c + 1]; ++p) out.push_back(cg_.members[p]);
  }

  index_t add_node(Region& r, index_t parent, index_t begin, index_t end) {
    SeparatorTree::Node node;
    node.begin = begin;
    node.end = end;
    node.parent = parent;
    r.nodes.push_back(std::move(node));
    const index_t id = static_cast<index_t>(r.nodes.size()) - 1;
    if (parent >= 0) r.nodes[parent].children.push_back(id);
    return id;
  }

  // Dissects the region's pending subgraphs, in the order of a depth-first walk (the first
  // child's subtree before the second's). When a subgraph just cut leaves two or more large
  // pieces and METIS's random numbers are per thread (metis_random.hpp), the pieces are
  // dissected side by side, each in a region of its own, and the regions' nodes appended
  // in the order the sequential walk would have made them: the tree and the permutation
  // are the same for any thread count. Side by side the subgraphs share cloc_, oloc_, perm_
  // and vfirst_ without a race: pending subgraphs are disjoint and no edge joins two of
  // them (separators or components lie between), so each reads and writes entries of its
  // own vertices only, and -1 for any neighbour outside it.
  void drain(Region& r, int levels) {
    while (!r.stack.empty()) {
      Task t = std::move(r.stack.back());
      r.stack.pop_back();
      step(r, t, levels);
    }
  }

  // Dissects subgraph t and everything below it in region r (whose stack is empty);
  // returns t's node.
  index_t dissect(Region& r, Task& t, const std::vector<idx_t>* multiplier = nullptr) {
    const auto id = static_cast<index_t>(r.nodes.size());  // t's node is made first
    step(r, t, kSideBySideLevels, multiplier);
    drain(r, kSideBySideLevels);
    return id;
  }

  // Cuts t (process) and dissects the pieces side by side when that pays (see drain).
  void step(Region& r, Task& t, int levels, const std::vector<idx_t>* multiplier = nullptr) {
    const std::size_t mark = r.stack.size();
    process(r, t, multiplier);
    const std::size_t pieces = r.stack.size() - mark;
    if (levels <= 0 || pieces < 2 || !side_by_side()) return;
    index_t weight = 0;
    bool balanced_below = true;  // balance by work keeps its levels in the top region
    for (std::size_t i = mark; i < r.stack.size(); ++i) {
      weight += r.stack[i].weight;
      balanced_below = balanced_below && r.stack[i].depth >= opts_.balance_levels;
    }
    if (weight < kSideBySideWeight || !balanced_below) return;
    std::vector<Region> sub(pieces);
    for (std::size_t i = 0; i < pieces; ++i) {  // the top of the stack is processed first
      Task& piece = r.stack[r.stack.size() - 1 - i];
      sub[i].outer_parent = piece.parent;
      piece.parent = kOuter;
      sub[i].stack.push_back(std::move(piece));
    }
    r.stack.resize(mark);
    side_by_side_pieces_ += static_cast<index_t>(pieces);
    tbb::parallel_for(std::size_t{0}, pieces, [&](std::size_t i) { drain(sub[i], levels - 1); });
    for (Region& s : sub) append(r, s);
  }

  // Appends the nodes of region s (made side by side) to r, linking those whose parent is
  // kOuter to s.outer_parent.
  static void append(Region& r, Region& s) {
    const auto offset = static_cast<index_t>(r.nodes.size());
    for (SeparatorTree::Node& node : s.nodes) {
      const index_t id = static_cast<index_t>(&node - s.nodes.data()) + offset;
      for (index_t& c : node.children) c += offset;
      if (node.parent == kOuter) {
        node.parent = s.outer_parent;
        if (node.parent >= 0) r.nodes[node.parent].children.push_back(id);
      } else if (node.parent >= 0) {
        node.parent += offset;
      }
      r.nodes.push_back(std::move(node));
    }
  }

  // Whether pieces may be dissected side by side: several threads in the calling arena
  // and METIS's random numbers per thread (known after the first bisection).
  bool side_by_side() const {
    return per_thread_random_ && !detail::serial_passes() &&
           tbb::this_task_arena::max_concurrency() > 1;
  }

  // Orders the task's subgraph (pushing its parts on the stack); returns its tree node.
  index_t process(Region& r, Task& t, const std::vector<idx_t>* multiplier = nullptr) {
    if (t.weight <= opts_.leaf_size || t.verts.size() < 3) return leaf(r, t);
    const index_t m = static_cast<index_t>(t.verts.size());
    for (index_t i = 0; i < m; ++i) cloc_[t.verts[i]] = i;

    // Connected components by breadth-first search inside the subgraph.
    std::vector<index_t> order, cstart{0};  // vertices by component, component starts
    order.reserve(m);
    {
      std::vector<char> seen(m, 0);
      for (index_t s = 0; s < m; ++s) {
        if (seen[s]) continue;
        seen[s] = 1;
        std::size_t head = order.size();
        order.push_back(t.verts[s]);
        while (head < order.size()) {
          const index_t v = order[head++];
          for (index_t p = cx_[v]; p < cx_[v + 1]; ++p) {
            const index_t w = cloc_[ca_[p]];
            if (w >= 0 && !seen[w]) {
              seen[w] = 1;
              order.push_back(t.verts[w]);
            }
          }
        }
        cstart.push_back(static_cast<index_t>(order.size()));
      }
    }
    const index_t ncomp = static_cast<index_t>(cstart.size()) - 1;
    if (ncomp > 1) {
      for (const index_t v : t.verts) cloc_[v] = -1;
      return split_components(r, t, order, cstart);
    }
    return bisect(r, t, multiplier);  // resets cloc_
  }

  // Orders the subgraph with AMD on its original vertices.
  index_t leaf(Region& r, Task& t) {
    std::vector<index_t> orig;  // vertices of g_
    orig.reserve(t.weight);
    for (const index_t c : t.verts) expand(c, orig);
    std::sort(orig.begin(), orig.end());  // keeps the local adjacency sorted
    const index_t m = static_cast<index_t>(orig.size());
    for (index_t i = 0; i < m; ++i) oloc_[orig[i]] = i;
    Graph s;
    s.n = m;
    s.xadj.assign(m + 1, 0);
    for (index_t i = 0; i < m; ++i) {
      const index_t v = orig[i];
      for (index_t p = g_.xadj[v]; p < g_.xadj[v + 1]; ++p) {
        const index_t w = oloc_[g_.adjncy[p]];
        if (w >= 0) s.adjncy.push_back(w);
      }
      s.xadj[i + 1] = static_cast<index_t>(s.adjncy.size());
    }
    for (const index_t v : orig) oloc_[v] = -1;
    const std::vector<index_t> p = (m <= 2) ? std::vector<index_t>{} : amd_ordering(s);
    index_t next = t.lo;
    for (index_t k = 0; k < m; ++k) next = number(orig[p.empty() ? k : p[k]], next);
    return add_node(r, t.parent, t.lo, t.lo + t.weight);
  }

  // Several components: a node with an empty separator whose children are the large
  // components and the small ones packed together into leaves of at most leaf_size.
  index_t split_components(Region& r, Task& t, const std::vector<index_t>& order,
                           const std::vector<index_t>& cstart) {
    const index_t id = add_node(r, t.parent, t.lo + t.weight, t.lo + t.weight);
    std::vector<Task> children;
    Task pack;
    auto flush = [&]() {
      if (!pack.verts.empty()) children.push_back(std::move(pack));
      pack = Task{};
    };
    const index_t ncomp = static_cast<index_t>(cstart.size()) - 1;
    for (index_t k = 0; k < ncomp; ++k) {
      index_t w = 0;
      for (index_t p = cstart[k]; p < cstart[k + 1]; ++p) w += weight(order[p]);
      if (w > opts_.leaf_size) {
        Task c;
        c.verts.assign(order.begin() + cstart[k], order.begin() + cstart[k + 1]);
        c.weight = w;
        children.push_back(std::move(c));
        continue;
      }
      if (pack.weight + w > opts_.leaf_size) flush();
      pack.verts.insert(pack.verts.end(), order.begin() + cstart[k], order.begin() + cstart[k + 1]);
      pack.weight += w;
    }
    flush();
    index_t lo = t.lo;
    for (auto& c : children) {
      c.depth = t.depth;
      c.lo = lo;
      c.parent = id;
      lo += c.weight;
    }
    // Push in reverse so that the first child is processed (and listed) first.
    for (auto it = children.rbegin(); it != children.rend(); ++it)
      r.stack.push_back(std::move(*it));
    return id;
  }

  // One METIS vertex separator on a connected subgraph (cloc_ holds its local numbers).
  // `multiplier` (balance by work): per local vertex, a factor on its METIS weight.
  index_t bisect(Region& r, Task& t, const std::vector<idx_t>* multiplier = nullptr) {
    const index_t m = static_cast<index_t>(t.verts.size());
    constexpr index_t idx_max = std::numeric_limits<idx_t>::max();
    std::vector<idx_t> xadj(m + 1), vwgt(m), where(m);
    std::vector<idx_t> adjncy;
    xadj[0] = 0;
    for (index_t i = 0; i < m; ++i) {
      const index_t v = t.verts[i];
      for (index_t p = cx_[v]; p < cx_[v + 1]; ++p) {
        const index_t w = cloc_[ca_[p]];
        if (w >= 0) adjncy.push_back(static_cast<idx_t>(w));
      }
      if (static_cast<index_t>(adjncy.size()) > idx_max || t.weight > idx_max || m > idx_max) {
        for (const index_t u : t.verts) cloc_[u] = -1;
        throw InvalidInput("nested_dissection: a subgraph of " + std::to_string(m) +
                           " vertices exceeds METIS's " + std::to_string(IDXTYPEWIDTH) +
                           "-bit index type");
      }
      xadj[i + 1] = static_cast<idx_t>(adjncy.size());
      vwgt[i] = static_cast<idx_t>(weight(v)) * (multiplier ? (*multiplier)[i] : 1);
    }
    for (const index_t u : t.verts) cloc_[u] = -1;

    idx_t options[METIS_NOPTIONS];
    METIS_SetDefaultOptions(options);
    options[METIS_OPTION_NUMBERING] = 0;
    options[METIS_OPTION_SEED] = opts_.seed;
    options[METIS_OPTION_NSEPS] = t.depth < kTopLevels ? std::max(nseps_, top_separators_) : nseps_;
    // A redo to balance work must meet its weighted balance closely: METIS's node
    // bisection otherwise allows 20% imbalance (ufactor 200), inside which the weights
    // do not move the cut at all.
    if (multiplier) options[METIS_OPTION_UFACTOR] = kBalanceUfactor;
    idx_t nv = static_cast<idx_t>(m), sepsize = 0;
    int status = METIS_OK;
    {
      const MetisRandomScope random;
      status = METIS_ComputeVertexSeparator(&nv, xadj.data(), adjncy.data(), vwgt.data(), options,
                                            &sepsize, where.data());
      if (&r == &top_) per_thread_random_ = random.seeded();  // top_ runs alone
    }
    if (status == METIS_ERROR_MEMORY) throw OutOfMemory(0, "METIS_ComputeVertexSeparator");
    if (status != METIS_OK)
      throw InvalidInput("METIS_ComputeVertexSeparator failed (status " + std::to_string(status) +
                         ")");

    Task part[2];
    index_t wsep = 0;
    std::vector<index_t> sep;
    for (index_t i = 0; i < m; ++i) {
      const index_t v = t.verts[i];
      if (where[i] == 0 || where[i] == 1) {
        part[where[i]].verts.push_back(v);
        part[where[i]].weight += weight(v);
      } else {
        sep.push_back(v);
        wsep += weight(v);
      }
    }
    if (part[0].weight == 0 || part[1].weight == 0) return leaf(r, t);  // degenerate: AMD leaf
    const index_t id = add_node(r, t.parent, t.lo + t.weight - wsep, t.lo + t.weight);
    if (t.depth <
        opts_.balance_levels) {  // only in top_ (see drain)  // may be redone to balance work
      Bisection& b = info_[id];
      b.verts = t.verts;
      b.where.assign(where.begin(), where.end());
      b.lo = t.lo;
      b.weight = t.weight;
      b.w0 = part[0].weight;
      b.w1 = part[1].weight;
      b.depth = t.depth;
    }
    index_t k = t.lo + t.weight - wsep;
    std::vector<index_t> orig;
    for (const index_t v : sep) {
      orig.clear();
      expand(v, orig);
      for (const index_t u : orig) k = number(u, k);
    }
    part[0].lo = t.lo;
    part[1].lo = t.lo + part[0].weight;
    part[0].parent = part[1].parent = id;
    part[0].depth = part[1].depth = t.depth + 1;
    r.stack.push_back(std::move(part[1]));
    r.stack.push_back(std::move(part[0]));
    return id;
  }

  // --- balance by work (see the file header) ---

  // A top bisection as made: its subgraph (compressed vertices), METIS's sides, its pivot
  // range [lo, lo + weight) and the weights of its two parts.
  struct Bisection {
    std::vector<index_t> verts;
    std::vector<idx_t> where;
    index_t lo = 0, weight = 0, w0 = 0, w1 = 0;
    int depth = 0;
  };

  // Estimated flops per pivot position for the current permutation: Σ colcount² of the
  // graph's columns in vertex order (a vertex standing for a group of s pivots counts s
  // times its column), placed at its first pivot.
  std::vector<double> pivot_work() const {
    const index_t n = g_.n;
    std::vector<index_t> order;  // vertices of g_ by first pivot
    order.reserve(n);
    {
      std::vector<index_t> at(perm_.size(), -1);
      for (index_t v = 0; v < n; ++v) at[vfirst_[v]] = v;
      for (const index_t v : at)
        if (v >= 0) order.push_back(v);
    }
    const SparseMatrix pp =
        symbolic::permute_symmetric_pattern(n, g_.xadj, g_.adjncy.data(), order);
    const std::vector<index_t> parent = symbolic::elimination_tree(pp);
    const std::vector<index_t> post = symbolic::postorder(parent);
    const std::vector<index_t> cc = symbolic::column_counts(pp, parent, post);
    std::vector<double> w(perm_.size() + 1, 0.0);
    for (index_t k = 0; k < n; ++k) {
      const double c = static_cast<double>(cc[k]);
      w[vfirst_[order[k]]] = static_cast<double>(group_size(order[k])) * c * c;
    }
    return w;
  }

  // Max side / mean side − 1 for bisection node id under the prefix sums `prefix` of
  // pivot_work; +inf for a node that is no longer a bisection.
  double imbalance(index_t id, const std::vector<double>& prefix, double* wa = nullptr,
                   double* wb = nullptr) const {
    const auto it = info_.find(id);
    if (it == info_.end()) return std::numeric_limits<double>::infinity();
    const Bisection& b = it->second;
    const double a = prefix[b.lo + b.w0] - prefix[b.lo];
    const double c = prefix[b.lo + b.w0 + b.w1] - prefix[b.lo + b.w0];
    if (wa) *wa = a;
    if (wb) *wb = c;
    return a + c > 0 ? std::abs(a - c) / (a + c) : 0.0;
  }

  // Makes node `now` take the place of node `old` in the tree.
  void replace_node(index_t old, index_t now) {
    const index_t p = nodes_[old].parent;
    nodes_[now].parent = p;
    if (p < 0) {
      root_ = now;
      return;
    }
    for (index_t& c : nodes_[p].children)
      if (c == old) c = now;
  }

  // The bisection nodes at `depth` reachable from the root.
  std::vector<index_t> bisections_at(int depth) const {
    std::vector<index_t> out, st{root_};
    while (!st.empty()) {
      const index_t v = st.back();
      st.pop_back();
      const auto it = info_.find(v);
      if (it != info_.end() && it->second.depth == depth) {
        out.push_back(v);
        continue;
      }
      for (const index_t c : nodes_[v].children) st.push_back(c);
    }
    std::sort(out.begin(), out.end());
    return out;
  }

  // Redoes bisection `id` with the heavier side's vertices weighted; returns the new node.
  index_t rebisect(index_t id, double wa, double wb) {
    const Bisection b = info_.at(id);  // copy: info_ may rehash below
    const int heavy = wa >= wb ? 0 : 1;
    const double wh = std::max(wa, wb), wl = std::max(std::min(wa, wb), 1.0);
    const double nh = heavy == 0 ? b.w0 : b.w1, nl = heavy == 0 ? b.w1 : b.w0;
    const double alpha = std::clamp(std::sqrt(wh / wl) * nl / nh, 1.0, 4.0);
    // integer METIS weights: light vertices `base`, heavy ones base·α, within idx_t
    constexpr double idx_max = static_cast<double>(std::numeric_limits<idx_t>::max());
    const double base = std::clamp(std::floor(idx_max / (5.0 * b.weight + 1)), 1.0, 64.0);
    std::vector<idx_t> mult(b.verts.size());
    for (std::size_t i = 0; i < b.verts.size(); ++i)
      mult[i] = static_cast<idx_t>(b.where[i] == heavy ? std::lround(base * alpha) : base);
    Task t;
    t.verts = b.verts;
    t.weight = b.weight;
    t.lo = b.lo;
    t.parent = -1;  // linked in place of `id` below
    t.depth = b.depth;
    const index_t now = dissect(top_, t, &mult);
    replace_node(id, now);
    ++rebisections_;
    return now;
  }

  // Pivots and first pivots of the subgraph of bisection `id`, to undo a redo.
  struct Saved {
    std::vector<index_t> perm;
    std::vector<std::pair<index_t, index_t>> vfirst;
  };
  Saved save(index_t id) const {
    const Bisection& b = info_.at(id);
    Saved s;
    s.perm.assign(perm_.begin() + b.lo, perm_.begin() + b.lo + b.weight);
    std::vector<index_t> orig;
    for (const index_t c : b.verts) expand(c, orig);
    for (const index_t v : orig) s.vfirst.emplace_back(v, vfirst_[v]);
    return s;
  }
  void restore(index_t id, const Saved& s) {
    const Bisection& b = info_.at(id);
    std::copy(s.perm.begin(), s.perm.end(), perm_.begin() + b.lo);
    for (const auto& [v, k] : s.vfirst) vfirst_[v] = k;
  }

  void balance_by_work() {
    const double tol = opts_.balance_tolerance;
    auto prefix_of = [&]() {
      std::vector<double> w = pivot_work();
      std::vector<double> prefix(w.size() + 1, 0.0);
      for (std::size_t k = 0; k < w.size(); ++k) prefix[k + 1] = prefix[k] + w[k];
      return prefix;
    };
    for (int d = 0; d < opts_.balance_levels; ++d) {
      std::vector<index_t> best = bisections_at(d);
      if (best.empty()) continue;
      std::vector<double> prefix = prefix_of();
      std::vector<double> best_imb(best.size());
      for (std::size_t i = 0; i < best.size(); ++i) best_imb[i] = imbalance(best[i], prefix);
      for (int attempt = 0; attempt < opts_.balance_attempts; ++attempt) {
        std::vector<std::size_t> redo;
        for (std::size_t i = 0; i < best.size(); ++i)
          if (best_imb[i] > tol) redo.push_back(i);
        if (redo.empty()) break;
        std::vector<index_t> now(best.size(), -1);
        std::vector<Saved> saved(best.size());
        for (const std::size_t i : redo) {
          double wa = 0, wb = 0;
          imbalance(best[i], prefix, &wa, &wb);
          saved[i] = save(best[i]);
          now[i] = rebisect(best[i], wa, wb);
        }
        prefix = prefix_of();
        bool undone = false;
        for (const std::size_t i : redo) {
          const double imb = imbalance(now[i], prefix);
          if (imb < best_imb[i]) {
            best[i] = now[i];
            best_imb[i] = imb;
          } else {  // worse: put the previous subtree and permutation back
            replace_node(now[i], best[i]);
            restore(best[i], saved[i]);
            undone = true;
          }
        }
        if (undone) prefix = prefix_of();
      }
    }
  }

  // Renumbers the nodes (created in preorder) in postorder, children in pivot order.
  SeparatorTree postorder_tree() {
    SeparatorTree tree;
    const index_t nn = static_cast<index_t>(nodes_.size());
    if (nn == 0) return tree;
    std::vector<index_t> newid(nn, -1), post;
    post.reserve(nn);
    std::vector<std::pair<index_t, std::size_t>> st;
    for (const index_t r : {root_}) {  // nodes replaced by balance_by_work are unreachable
      st.push_back({r, 0});
      while (!st.empty()) {
        auto& [v, next] = st.back();
        if (next < nodes_[v].children.size()) {
          const index_t c = nodes_[v].children[next++];
          st.push_back({c, 0});
        } else {
          newid[v] = static_cast<index_t>(post.size());
          post.push_back(v);
          st.pop_back();
        }
      }
    }
    const auto live = static_cast<index_t>(post.size());
    tree.nodes.resize(live);
    for (index_t k = 0; k < live; ++k) {
      SeparatorTree::Node& out = tree.nodes[k];
      const SeparatorTree::Node& in = nodes_[post[k]];
      out.begin = in.begin;
      out.end = in.end;
      out.parent = in.parent >= 0 ? newid[in.parent] : -1;
      out.children.reserve(in.children.size());
      for (const index_t c : in.children) out.children.push_back(newid[c]);
      out.subtree_begin =
          out.children.empty() ? out.begin : tree.nodes[out.children[0]].subtree_begin;
      out.work = 0;
    }
    return tree;
  }

  const Graph& g_;
  const NestedDissectionOptions& opts_;
  const VertexGroups* groups_;  // null: every vertex is its own group
  Compressed cg_;
  std::vector<index_t> cweight_;  // pivots per compressed vertex
  index_t cn_ = 0;
  const index_t* cx_ = nullptr;
  const index_t* ca_ = nullptr;
  int nseps_ = 1;
  int top_separators_ = 1;
  std::vector<index_t> cloc_, oloc_, perm_;
  std::vector<index_t> vfirst_;  // first pivot of each vertex of g_
  Region top_;                   // the tree's nodes (the region of the whole graph)
  std::vector<SeparatorTree::Node>& nodes_ = top_.nodes;
  bool per_thread_random_ = false;  // METIS's random numbers are per thread
  std::atomic<index_t> side_by_side_pieces_{0};
  index_t root_ = -1;
  std::map<index_t, Bisection> info_;  // top bisections, by node (balance by work)
  index_t rebisections_ = 0;
};

}  // namespace

namespace {

void check_nd_input(const Graph& g, const NestedDissectionOptions& opts) {
  if (opts.leaf_size < 1)
    throw InvalidInput("nested_dissection: leaf_size must be at least 1 (got " +
                       std::to_string(opts.leaf_size) + ")");
  if (g.n < 0 || static_cast<index_t>(g.xadj.size()) != g.n + 1)
    throw InvalidInput("nested_dissection: malformed graph (xadj has " +
                       std::to_string(g.xadj.size()) + " entries for " + std::to_string(g.n) +
                       " vertices)");
}

}  // namespace

OrderingResult nested_dissection(const Graph& g, const NestedDissectionOptions& opts) {
  check_nd_input(g, opts);
  Driver d(g, opts, nullptr);
  return d.run();
}

OrderingResult nested_dissection(const Graph& q, const NestedDissectionOptions& opts,
                                 const VertexGroups& groups) {
  check_nd_input(q, opts);
  if (groups.n_groups() != q.n)
    throw InvalidInput("nested_dissection: " + std::to_string(groups.n_groups()) +
                       " groups for a graph of " + std::to_string(q.n) + " vertices");
  for (index_t v = 0; v < q.n; ++v)
    if (groups.size(v) < 1) throw InvalidInput("nested_dissection: an empty vertex group");
  Driver d(q, opts, &groups);
  return d.run();
}

}  // namespace strata::ordering
