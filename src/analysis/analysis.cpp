// strata — the analysis phase (DESIGN.md §1 step 2).
//
// Order of work:
//   1. canonical pattern of the input (lower triangle for symmetric types, full for
//      general), validated;
//   2. general: maximum product matching and scaling (Duff & Koster 2001), so that
//      B = Dr·A(:,q)·Dc has a large diagonal and static pivoting is rarely needed;
//      symmetric_indefinite (including `automatic` matrices resolved to it because a
//      diagonal entry is missing or ≤ 0, which no SPD matrix has): the symmetric scaling
//      B = D·A·D from the same matching and its 2×2 pivot pairs (Duff & Pralet 2005,
//      ordering/pairing.cpp);
//   3. the fill-reducing ordering on the graph of B + Bᵀ (nested dissection by default),
//      on the quotient graph with one vertex per pair when there are pairs, so that the
//      two members of a pair are consecutive;
//   4. the symbolic phase on the permuted pattern: etree, postorder, column counts,
//      supernodes, amalgamation, separator blocking — the assembly tree, with every pair
//      in one front (AmalgamationOptions::keep_with_next);
//   5. the level schedule and the memory plan for the device budget;
//   6. layouts computed once and reused by every (re)factorization: where every input
//      entry lands in its front (assembly map), where each contribution block lives in
//      the CB arena, and where each front's factor panel is stored;
//   7. for several workers (GPUs): the split of the tree into subtrees, upper layers
//      (Options::split_top) and a top part (schedule/tree_partition.hpp), each part with
//      its own schedule, plan and arena; the
//      nested dissection of step 3 then also balances its top bisections by work.
#include "analysis/analysis.hpp"

#include <tbb/task_arena.h>

#include <algorithm>
#include <atomic>
#include <functional>
#include <thread>

#include "analysis/patterns.hpp"
#include "base/device.hpp"
#include "base/serial_scope.hpp"
#include "base/timer.hpp"
#include "ordering/matching.hpp"
#include "ordering/pairing.hpp"
#include "sparse/canonical.hpp"
#include "strata/errors.hpp"

namespace strata {
namespace {

// Lower triangle (diagonal included) of a symmetric matrix given in any storage, as
// canonical CSC. For `full` storage the upper entries are ignored.
// True when a is already canonical lower CSC (sorted, no duplicates, no upper entry),
// as the Matrix Market reader and the generators produce: then no pass is needed.
bool is_canonical_lower(const SparseMatrix& a) {
  if (a.layout != Layout::csc || a.storage != Storage::lower) return false;
  for (index_t j = 0; j < a.n_cols; ++j) {
    index_t prev = j - 1;
    for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p) {
      if (a.indices[p] <= prev) return false;
      prev = a.indices[p];
    }
  }
  return true;
}

// `validated`: the caller has checked a (validate); otherwise it is checked here.
SparseMatrix lower_triangle(const SparseMatrix& a, bool validated) {
  if (is_canonical_lower(a)) {
    if (!validated) validate(a);
    return a;
  }
  SparseMatrix full = expand_symmetric(a);
  SparseMatrix low;
  low.n_rows = low.n_cols = full.n_cols;
  low.storage = Storage::lower;
  low.offsets.assign(full.n_cols + 1, 0);
  const bool vals = !full.values.empty();
  for (index_t j = 0; j < full.n_cols; ++j) {
    for (index_t p = full.offsets[j]; p < full.offsets[j + 1]; ++p)
      if (full.indices[p] >= j) {
        low.indices.push_back(full.indices[p]);
        if (vals) low.values.push_back(full.values[p]);
      }
    low.offsets[j + 1] = static_cast<index_t>(low.indices.size());
  }
  return low;
}

// True when the lower-triangular canonical matrix `low` has a diagonal entry that is
// structurally missing or (values given) ≤ 0: such a symmetric matrix is not SPD.
bool has_nonpositive_diagonal(const SparseMatrix& low) {
  const bool vals = !low.values.empty();
  for (index_t j = 0; j < low.n_cols; ++j) {
    const index_t p = low.offsets[j];
    if (p == low.offsets[j + 1] || low.indices[p] != j) return true;  // sorted: diagonal first
    if (vals && !(low.values[p] > 0.0)) return true;
  }
  return false;
}

// Panels are laid out in schedule order, so that the panels of one batch are contiguous
// and a GPU executor moves a batch's factor in one copy.
FactorLayout plan_factor_layout(const symbolic::AssemblyTree& t, const symbolic::LevelSchedule& s,
                                bool lu) {
  FactorLayout out;
  out.panel_offset.assign(t.n_fronts() + 1, 0);
  std::size_t at = 0;
  for (index_t f : s.fronts) {
    out.panel_offset[f] = at;
    at += panel_size(t, f, lu);
  }
  out.panel_offset[t.n_fronts()] = at;
  out.total = at;
  return out;
}

// A matrix with an empty row or column is structurally singular: say which one.
// (Empty lines are the common case; the matching finds the others for general and
// symmetric indefinite matrices.)
void check_no_empty_line(const SparseMatrix& c, bool symmetric) {
  std::vector<char> row_seen(c.n_rows, 0);
  for (index_t j = 0; j < c.n_cols; ++j)
    for (index_t p = c.offsets[j]; p < c.offsets[j + 1]; ++p) {
      row_seen[c.indices[p]] = 1;
      if (symmetric) row_seen[j] = 1;  // lower storage: column j is row j mirrored
    }
  for (index_t i = 0; i < c.n_rows; ++i)
    if (!row_seen[i])
      throw InvalidInput("the matrix is structurally singular: row " + std::to_string(i) +
                         " (0-based) has no entry");
  if (!symmetric)
    for (index_t j = 0; j < c.n_cols; ++j)
      if (c.offsets[j] == c.offsets[j + 1])
        throw InvalidInput("the matrix is structurally singular: column " + std::to_string(j) +
                           " (0-based) has no entry");
}

// The multi-GPU split's hook: the factor flops (Σ colcount² over its columns) of each
// separator-tree node's subtree. Column counts are in the ordering's numbering, the one
// the tree's ranges use. Left at 0 when the tree does not cover 0..n-1 (no ND).
void fill_separator_work(ordering::SeparatorTree& tree, const std::vector<index_t>& colcount) {
  if (tree.empty() || tree.nodes.back().end != static_cast<index_t>(colcount.size())) return;
  std::vector<double> prefix(colcount.size() + 1, 0.0);
  for (std::size_t j = 0; j < colcount.size(); ++j)
    prefix[j + 1] = prefix[j] + static_cast<double>(colcount[j]) * colcount[j];
  for (auto& node : tree.nodes) node.work = prefix[node.end] - prefix[node.subtree_begin];
}

void finish_analysis(Analysis& an, const SparseMatrix& c, const ordering::Graph& graph,
                     index_t diagonal_entries, ordering::OrderingResult ord, const Options& opts,
                     int workers);

int cpu_threads(const Options& opts) {
  return opts.num_threads > 0 ? opts.num_threads
                              : std::max(1, static_cast<int>(std::thread::hardware_concurrency()));
}

// AnalysisStats::cpu_factorization_bytes: the factor's panels and row indices, the
// contribution-block stack of the depth-first plan, and the dense front workspaces of the
// fronts factored in one (all but the Cholesky fronts that pass a block on): the calling
// thread's, grown to the largest such front, and with several threads one per thread,
// grown to the largest such front of the small subtrees.
std::size_t cpu_factorization_bytes(const Analysis& an) {
  const auto& t = an.tree;
  const auto& plan = an.stack_plan;
  const bool cholesky = an.type == MatrixType::spd || an.type == MatrixType::automatic;
  std::size_t any = 0, in_subtrees = 0;
  for (index_t f = 0; f < t.n_fronts(); ++f) {
    if (cholesky && (t.cb_size(f) == 0 || t.parent[f] >= 0)) continue;
    const auto m = static_cast<std::size_t>(t.n_rows(f));
    any = std::max(any, m * m);
    if (plan.subtree_of[f] >= 0) in_subtrees = std::max(in_subtrees, m * m);
  }
  std::size_t doubles = an.factor_layout.total + plan.arena_size() + any;
  if (plan.threads > 1) doubles += static_cast<std::size_t>(plan.threads) * in_subtrees;
  // the factor's row indices and LDLᵀ's D and pivot sizes (not its per-front pivot
  // figures: a few dozen bytes per front)
  std::size_t other = an.tree.rows.size() * sizeof(index_t);
  if (an.type != MatrixType::spd && an.symmetric)
    other += static_cast<std::size_t>(an.n) * (2 * sizeof(double) + sizeof(int));
  return doubles * sizeof(double) + other;
}

template <class T>
std::size_t vector_bytes(const std::vector<T>& v) {
  return v.capacity() * sizeof(T);
}

// AnalysisStats::analysis_bytes: the arrays of the Analysis (the parts split for several
// workers counted by their schedules and layouts).
std::size_t analysis_bytes(const Analysis& an) {
  std::size_t b = vector_bytes(an.pattern_offsets) + vector_bytes(an.pattern_indices) +
                  vector_bytes(an.matching_perm) + vector_bytes(an.row_scaling) +
                  vector_bytes(an.col_scaling) + vector_bytes(an.pivot_groups.ptr) +
                  vector_bytes(an.pivot_groups.members) + vector_bytes(an.perm) +
                  vector_bytes(an.iperm) + vector_bytes(an.kept_order);
  for (const auto& node : an.separator_tree.nodes) b += sizeof(node) + vector_bytes(node.children);
  const auto& t = an.tree;
  b += vector_bytes(t.first_pivot) + vector_bytes(t.row_offsets) + vector_bytes(t.rows) +
       vector_bytes(t.parent) + vector_bytes(t.child_offsets) + vector_bytes(t.children) +
       vector_bytes(t.front_of_column);
  b += vector_bytes(an.child_rows.offsets) + vector_bytes(an.child_rows.rel);
  auto schedule_bytes = [](const symbolic::LevelSchedule& s) {
    return vector_bytes(s.level_offsets) + vector_bytes(s.fronts) + vector_bytes(s.level_of);
  };
  b += schedule_bytes(an.schedule) + vector_bytes(an.plan.batches);
  b += vector_bytes(an.assembly.entry_offsets) + vector_bytes(an.assembly.entry_src) +
       vector_bytes(an.assembly.entry_dst);
  b += vector_bytes(an.cb_layout.cb_offset) + vector_bytes(an.factor_layout.panel_offset);
  const auto& sp = an.stack_plan;
  b += vector_bytes(sp.subtree_first) + vector_bytes(sp.subtree_root) +
       vector_bytes(sp.subtree_of) + vector_bytes(sp.step_front) + vector_bytes(sp.group_offsets) +
       vector_bytes(sp.group) + vector_bytes(sp.cb_offset) + vector_bytes(sp.build_offset);
  auto part_bytes = [&](const schedule::FactorPart& p) {
    return vector_bytes(p.fronts) + schedule_bytes(p.schedule) + vector_bytes(p.plan.batches) +
           vector_bytes(p.cb_layout.cb_offset) + vector_bytes(p.imports);
  };
  for (const auto& p : an.partition.subtrees) b += part_bytes(p);
  for (const auto& p : an.partition.upper) b += part_bytes(p);
  b += part_bytes(an.partition.top) + vector_bytes(an.partition.part_of) +
       vector_bytes(an.partition.part_id) + vector_bytes(an.partition.owner);
  return b;
}

// Analysis::id: unique over the process, whichever function made the analysis.
std::uint64_t next_analysis_id() {
  static std::atomic<std::uint64_t> next{1};
  return next++;
}

}  // namespace

SparseMatrix canonical_values(const Analysis& an, const SparseMatrix& a) {
  if (a.n_rows != an.n || a.n_cols != an.n)
    throw InvalidInput("matrix is " + std::to_string(a.n_rows) + "x" + std::to_string(a.n_cols) +
                       ", the analysis was for " + std::to_string(an.n) + "x" +
                       std::to_string(an.n));
  SparseMatrix c = an.symmetric ? lower_triangle(a, false) : canonicalize(a);
  if (c.offsets != an.pattern_offsets || c.indices != an.pattern_indices)
    throw InvalidInput("the matrix pattern differs from the analyzed pattern; call analyze again");
  if (c.values.empty() && c.nnz() > 0) throw InvalidInput("the matrix has no values");
  return c;
}

int resolve_workers(const Options& opts) {
  if (opts.num_gpus < 0)
    throw InvalidInput("Options::num_gpus must be at least 0 (got " +
                       std::to_string(opts.num_gpus) + ")");
  if (!numeric::uses_cuda(opts.backend)) return 1;
  const int visible = numeric::cuda_device_count();
  // No GPU at all: the CUDA executor says so (NotSupported) when the factorization asks
  // for it; the analysis itself does not need one.
  if (visible == 0) return 1;
  if (opts.num_gpus > visible)
    throw InvalidInput("Options::num_gpus asks for " + std::to_string(opts.num_gpus) + " GPUs, " +
                       std::to_string(visible) + " are visible");
  return std::max(1, opts.num_gpus == 0 ? visible : opts.num_gpus);
}

index_t resolve_max_block_size(const Options& opts, MatrixType type) {
  if (opts.max_block_size > 0) return opts.max_block_size;
  // Options::max_block_size documents the choice (bench/history.md, "Option defaults")
  return numeric::uses_cuda(opts.backend) && type == MatrixType::spd ? 4096 : 1024;
}

// `canonical_full`: null, or what the caller's validation of `a` found
// (detail::is_canonical_full), so that `a` is not checked again here.
static Analysis analyze_matrix_impl(const SparseMatrix& a, const Options& opts, int workers,
                                    const bool* canonical_full,
                                    const ordering::Matching* start = nullptr) {
  Timer total;
  if (workers < 1)
    throw InvalidInput("analyze_matrix: workers must be at least 1 (got " +
                       std::to_string(workers) + ")");
  validate(opts);
  if (a.n_rows != a.n_cols)
    throw InvalidInput("matrix must be square, got " + std::to_string(a.n_rows) + "x" +
                       std::to_string(a.n_cols));
  Analysis an;
  an.id = next_analysis_id();
  an.n = a.n_rows;
  an.input_storage = a.storage;
  an.type = opts.type;
  if (an.type == MatrixType::automatic) {
    const bool sym = a.storage != Storage::full || (a.has_values() && is_numerically_symmetric(a));
    an.type = sym ? MatrixType::automatic : MatrixType::general;
  }
  an.symmetric = an.type != MatrixType::general;
  // the canonical input: a general matrix that is canonical already is read as it is
  const bool as_is =
      !an.symmetric && (canonical_full ? *canonical_full : detail::is_canonical_full(a));
  SparseMatrix converted;
  if (!as_is)
    converted = an.symmetric ? lower_triangle(a, canonical_full != nullptr) : expand_symmetric(a);
  const SparseMatrix& c = as_is ? a : converted;
  an.pattern_offsets = c.offsets;
  an.pattern_indices = c.indices;
  if (an.type == MatrixType::automatic && has_nonpositive_diagonal(c))
    an.type = MatrixType::symmetric_indefinite;
  check_no_empty_line(c, an.symmetric);

  Timer step;
  index_t unmatched_row = -1;
  if (!an.symmetric && opts.matching_and_scaling && an.n > 0 && !c.values.empty()) {
    ordering::Matching m = ordering::maximum_product_matching_canonical(c, start);
    an.matching_perm = std::move(m.column_permutation);
    an.row_scaling = std::move(m.row_scaling);
    an.col_scaling = std::move(m.column_scaling);
    an.structurally_singular = m.structurally_singular;
    unmatched_row = m.first_unmatched_row;
  }
  if (an.type == MatrixType::symmetric_indefinite && opts.matching_and_scaling && an.n > 0 &&
      !c.values.empty()) {
    ordering::SymmetricPairing sp = ordering::symmetric_matching_pairing(c, opts.pairing_threshold);
    an.row_scaling = sp.scaling;
    an.col_scaling = std::move(sp.scaling);
    an.structurally_singular = sp.structurally_singular;
    unmatched_row = sp.first_unmatched_row;
    an.pivot_groups = std::move(sp.groups);
  }
  an.stats.matching_seconds = step.seconds();
  if (an.structurally_singular)
    throw InvalidInput(
        "the matrix is structurally singular: no permutation puts nonzero "
        "entries on the whole diagonal (maximum matching, Duff & Koster 2001); row " +
        std::to_string(unmatched_row) +
        " (0-based) is left unmatched (explicit zeros do not count as entries)");
  const bool grouped = an.pivot_groups.n_groups() > 0;
  index_t diagonal_entries = 0;
  const ordering::Graph graph =
      detail::symmetric_graph(c, an.symmetric, an.matching_perm, &diagonal_entries);
  ordering::OrderingResult ord =
      grouped ? ordering::compute_grouped_ordering(
                    graph, ordering::complete_groups(an.n, an.pivot_groups), opts, workers)
              : ordering::compute_ordering(graph, opts, workers);
  an.stats.nd_rebisections = ord.rebisections;
  an.stats.nd_balance_seconds = ord.balance_seconds;
  an.stats.ordering_seconds = step.seconds();
  finish_analysis(an, c, graph, diagonal_entries, std::move(ord), opts, workers);
  an.stats.total_seconds = total.seconds();
  return an;
}

namespace {

// Steps 4–7 of the file comment for an analysis whose matching, scaling and ordering are
// made: `c` the canonical input, `graph` the graph of B + Bᵀ that `ord` orders and
// `diagonal_entries` B's diagonal entries (detail::symmetric_graph).
void finish_analysis(Analysis& an, const SparseMatrix& c, const ordering::Graph& graph,
                     index_t diagonal_entries, ordering::OrderingResult ord, const Options& opts,
                     int workers) {
  const bool grouped = an.pivot_groups.n_groups() > 0;
  Timer step;
  symbolic::AmalgamationOptions ao;
  ao.relax_small = opts.relax_small;
  ao.relax_size_1 = opts.relax_size_1;
  ao.relax_size_2 = opts.relax_size_2;
  ao.relax_zeros_1 = opts.relax_zeros_1;
  ao.relax_zeros_2 = opts.relax_zeros_2;
  ao.relax_zeros_3 = opts.relax_zeros_3;
  ao.max_block_size = resolve_max_block_size(opts, an.type);
  if (grouped) {
    // Consecutive members of a group that the ordering placed side by side (all of them,
    // except under the natural and user orderings, which keep only what they happen to
    // place so) become pivots of one front; they are coupled by an entry, as
    // keep_with_next requires.
    const auto& gr = an.pivot_groups;
    std::vector<index_t> group_of(an.n, -1), pos(an.n, -1);
    for (index_t g = 0; g < gr.n_groups(); ++g)
      for (index_t p = gr.ptr[g]; p < gr.ptr[g + 1]; ++p) {
        group_of[gr.members[p]] = g;
        pos[gr.members[p]] = p;
      }
    ao.keep_with_next.assign(an.n, 0);
    std::vector<index_t> links(gr.n_groups(), 0);
    for (index_t k = 0; k + 1 < an.n; ++k) {
      const index_t u = ord.perm[k], v = ord.perm[k + 1];
      if (group_of[u] < 0 || group_of[u] != group_of[v] || pos[v] != pos[u] + 1) continue;
      ao.keep_with_next[k] = 1;
      ++links[group_of[u]];
    }
    for (index_t g = 0; g < gr.n_groups(); ++g)
      if (links[g] == gr.size(g) - 1) ++(gr.size(g) == 2 ? an.stats.pairs : an.stats.odd_cycles);
  }
  // B + Bᵀ by construction (detail::symmetric_graph), read through the ordering
  symbolic::SymbolicFactorization sym =
      symbolic::analyze_permuted_graph(graph.n, graph.xadj, graph.adjncy.data(), ord.perm, ao);
  // the tree is in the postordered numbering: pivot k is permuted column post[k]
  an.perm.resize(an.n);
  for (index_t k = 0; k < an.n; ++k) an.perm[k] = ord.perm[sym.post[k]];
  an.iperm = ordering::invert_permutation(an.perm);
  an.separator_tree = std::move(ord.tree);
  fill_separator_work(an.separator_tree, sym.colcount);
  an.tree = std::move(sym.tree);
  an.child_rows = symbolic::child_row_map(an.tree);
  an.schedule = symbolic::level_schedule(an.tree);
  an.stats.symbolic_seconds = step.seconds();

  step.reset();
  const bool lu = !an.symmetric;
  an.plan = schedule::plan_memory(an.tree, an.schedule, opts.device_memory_limit, lu);
  an.assembly = detail::build_assembly_map(c, an);
  an.cb_layout = schedule::plan_cb_layout(an.tree, an.schedule);
  an.stack_plan = schedule::plan_stack(
      an.tree, cpu_threads(opts), an.type == MatrixType::spd || an.type == MatrixType::automatic);
  an.factor_layout = plan_factor_layout(an.tree, an.schedule, lu);
  if (workers > 1) {
    schedule::PartitionOptions po;
    po.workers = workers;
    po.subtrees_per_worker = opts.subtrees_per_gpu;
    po.budget = opts.device_memory_limit;
    po.unsymmetric = lu;
    po.upper_layers = opts.split_top;
    an.partition = schedule::partition_tree(an.tree, po);
  }
  an.stats.plan_seconds = step.seconds();

  // statistics
  AnalysisStats& st = an.stats;
  st.n = an.n;
  st.nnz_a = graph.n_edges_directed() + diagonal_entries;
  st.nnz_l = sym.nnz_l;
  st.type = an.type;
  st.max_block_size = resolve_max_block_size(opts, an.type);
  st.ordering = ord.method;
  st.n_fronts = an.tree.n_fronts();
  for (index_t f = 0; f < an.tree.n_fronts(); ++f) {
    const index_t m = an.tree.n_rows(f), k = an.tree.n_pivots(f);
    st.nnz_l_fronts += k * m - k * (k - 1) / 2;
    st.factor_flops += symbolic::front_flops(an.tree, f);
    st.largest_front_rows = std::max(st.largest_front_rows, m);
    st.largest_front_pivots = std::max(st.largest_front_pivots, k);
  }
  st.tree_height = an.schedule.n_levels();
  for (index_t l = 0; l < an.schedule.n_levels(); ++l)
    st.fronts_per_level.push_back(an.schedule.level_offsets[l + 1] - an.schedule.level_offsets[l]);
  st.peak_working_bytes = an.plan.peak_in_core_bytes;
  st.factor_bytes = an.plan.factor_bytes;
  st.cpu_factorization_bytes = cpu_factorization_bytes(an);
  st.memory_budget = an.plan.budget;
  st.batches = an.plan.batches;
  st.workers = workers;
  if (workers > 1) {
    const auto& p = an.partition;
    st.subtrees = static_cast<index_t>(p.subtrees.size());
    st.subtree_balance = p.balance;
    st.top_flops_fraction = p.total_work > 0 ? p.top.work / p.total_work : 0.0;
    st.upper_layers = p.n_upper_layers();
    st.upper_parts = static_cast<index_t>(p.upper.size());
    double upper = 0;
    for (const auto& u : p.upper) upper += u.work;
    st.upper_flops_fraction = p.total_work > 0 ? upper / p.total_work : 0.0;
    st.estimated_speedup = p.estimated_time > 0 ? p.total_work / p.estimated_time : 0.0;
  }
  st.analysis_bytes = analysis_bytes(an);
}

}  // namespace

// a's pattern for an analysis that keeps previous's matching (and, with keep_order, its
// order): the canonical input (lower triangle or full), after checking that a is square of
// previous's size and holds what is kept. Every analyzed entry when the order or 2×2 pivot
// groups are kept (the matching's entries, and a pair's coupling, are then entries of the
// new pattern, and B's diagonal keeps them); otherwise no empty line and every matched
// entry A(j, q[j]) of a general matrix.
static SparseMatrix kept_input(const SparseMatrix& a, const Analysis& previous, const char* what,
                               bool keep_order) {
  if (a.n_rows != a.n_cols || a.n_rows != previous.n)
    throw InvalidInput(std::string(what) + ": the matrix is " + std::to_string(a.n_rows) + "x" +
                       std::to_string(a.n_cols) + ", the analysis whose " +
                       (keep_order ? "order" : "matching") + " it keeps was for " +
                       std::to_string(previous.n) + "x" + std::to_string(previous.n));
  SparseMatrix c = previous.symmetric ? lower_triangle(a, false) : expand_symmetric(a);
  const index_t n = previous.n;
  if (keep_order || previous.pivot_groups.n_groups() > 0) {
    for (index_t j = 0; j < n; ++j) {
      index_t p = c.offsets[j];
      for (index_t q = previous.pattern_offsets[j]; q < previous.pattern_offsets[j + 1]; ++q) {
        const index_t i = previous.pattern_indices[q];
        while (p < c.offsets[j + 1] && c.indices[p] < i) ++p;
        if (p == c.offsets[j + 1] || c.indices[p] != i)
          throw InvalidInput(std::string(what) + ": entry (" + std::to_string(i) + ", " +
                             std::to_string(j) +
                             ") of the analyzed pattern is missing from the new one; the " +
                             (keep_order ? "order" : "matching and its 2x2 pivots") +
                             " can only be kept for a pattern that contains the analyzed one");
      }
    }
  } else {
    check_no_empty_line(c, previous.symmetric);
    const std::vector<index_t>& q = previous.matching_perm;
    for (index_t j = 0; j < n && !q.empty(); ++j) {
      const auto first = c.indices.begin() + c.offsets[q[j]];
      const auto last = c.indices.begin() + c.offsets[q[j] + 1];
      if (!std::binary_search(first, last, j))
        throw InvalidInput(std::string(what) + ": the matched entry (" + std::to_string(j) + ", " +
                           std::to_string(q[j]) +
                           ") is not in the new pattern; the matching can only be kept for a "
                           "pattern that has every matched entry");
    }
  }
  return c;
}

// The order analyze_with_order keeps: that of the analysis that computed one (postordered:
// as good a fill-reducing order as the one it came from).
static const std::vector<index_t>& kept_order_of(const Analysis& previous) {
  return previous.kept_order.empty() ? previous.perm : previous.kept_order;
}

// analyze_with_order (kept order) and analyze_with_matching (a new order): previous's
// matching, scaling and pivot groups on a's pattern.
static Analysis analyze_keeping_impl(const SparseMatrix& a, const Analysis& previous,
                                     const Options& opts, int workers, bool keep_order) {
  Timer total;
  const char* what = keep_order ? "analyze_with_order" : "analyze_with_matching";
  if (workers < 1)
    throw InvalidInput(std::string(what) + ": workers must be at least 1 (got " +
                       std::to_string(workers) + ")");
  SparseMatrix c = kept_input(a, previous, what, keep_order);
  Analysis an;
  an.id = next_analysis_id();
  an.n = previous.n;
  an.input_storage = a.storage;
  an.type = previous.type;
  an.symmetric = previous.symmetric;
  const bool grouped = previous.pivot_groups.n_groups() > 0;
  an.pattern_offsets = c.offsets;
  an.pattern_indices = c.indices;
  an.matching_perm = previous.matching_perm;
  an.row_scaling = previous.row_scaling;
  an.col_scaling = previous.col_scaling;
  an.pivot_groups = previous.pivot_groups;
  Timer step;
  index_t diagonal_entries = 0;
  const ordering::Graph graph =
      detail::symmetric_graph(c, an.symmetric, an.matching_perm, &diagonal_entries);
  ordering::OrderingResult ord;
  if (keep_order) {
    ord.perm = kept_order_of(previous);
    an.kept_order = ord.perm;
    ord.method = previous.stats.ordering;
  } else {
    ord = grouped ? ordering::compute_grouped_ordering(
                        graph, ordering::complete_groups(an.n, an.pivot_groups), opts, workers)
                  : ordering::compute_ordering(graph, opts, workers);
    an.stats.nd_rebisections = ord.rebisections;
    an.stats.nd_balance_seconds = ord.balance_seconds;
  }
  const OrderingMethod method = ord.method;
  an.stats.ordering_seconds = step.seconds();
  an.stats.order_kept = keep_order;
  an.stats.matching_kept = !keep_order;
  finish_analysis(an, c, graph, diagonal_entries, std::move(ord), opts, workers);
  an.stats.ordering = method;
  an.stats.total_seconds = total.seconds();
  return an;
}

// A factorization with delayed pivots found a pivot sequence for the values it saw; this
// analysis makes that sequence the fixed order. With q the matching and π = perm, the
// factor was L·U = B(π∘σr, π∘σc): the k-th pivot is entry (π[σr[k]], π[σc[k]]) of B,
// i.e. row π[σr[k]] and column q[π[σc[k]]] of A. The new matching q' maps B' column
// π[σr[k]] to that A column, q'[π[σr[k]]] = q[π[σc[k]]], so that B'(π', π') with
// π'[k] = π[σr[k]] is B(π∘σr, π∘σc): the pivots are on B''s diagonal, in sequence.
static Analysis analyze_with_pivot_sequence_impl(const Analysis& previous,
                                                 const std::vector<index_t>& row_sequence,
                                                 const std::vector<index_t>& col_sequence,
                                                 const std::vector<double>& row_rescaling,
                                                 const std::vector<double>& col_rescaling,
                                                 const Options& opts, int workers) {
  Timer total;
  if (workers < 1)
    throw InvalidInput("analyze_with_pivot_sequence: workers must be at least 1 (got " +
                       std::to_string(workers) + ")");
  const index_t n = previous.n;
  if (previous.symmetric || previous.type != MatrixType::general)
    throw InternalError("analyze_with_pivot_sequence: the analysis is not of a general matrix");
  auto check_permutation = [n](const std::vector<index_t>& p, const char* what) {
    if (static_cast<index_t>(p.size()) != n)
      throw InternalError(std::string("analyze_with_pivot_sequence: the ") + what +
                          " sequence has " + std::to_string(p.size()) + " entries, not " +
                          std::to_string(n));
    std::vector<char> seen(n, 0);
    for (index_t v : p) {
      if (v < 0 || v >= n || seen[v])
        throw InternalError(std::string("analyze_with_pivot_sequence: the ") + what +
                            " sequence is not a permutation (" + std::to_string(v) + ")");
      seen[v] = 1;
    }
  };
  check_permutation(row_sequence, "row");
  check_permutation(col_sequence, "column");
  const bool scaled = !previous.row_scaling.empty();
  if ((!row_rescaling.empty() || !col_rescaling.empty()) &&
      (!scaled || static_cast<index_t>(row_rescaling.size()) != n ||
       static_cast<index_t>(col_rescaling.size()) != n))
    throw InternalError("analyze_with_pivot_sequence: rescaling of the wrong size or unscaled");

  Analysis an;
  an.id = next_analysis_id();
  an.n = n;
  an.input_storage = previous.input_storage;
  an.type = previous.type;
  an.symmetric = false;
  an.pattern_offsets = previous.pattern_offsets;
  an.pattern_indices = previous.pattern_indices;
  an.row_scaling = previous.row_scaling;
  an.col_scaling = previous.col_scaling;
  for (std::size_t i = 0; i < row_rescaling.size(); ++i) an.row_scaling[i] *= row_rescaling[i];
  for (std::size_t j = 0; j < col_rescaling.size(); ++j) an.col_scaling[j] *= col_rescaling[j];
  Timer step;
  const std::vector<index_t>& pi = previous.perm;
  const std::vector<index_t>& q = previous.matching_perm;
  an.matching_perm.resize(n);
  ordering::OrderingResult ord;
  ord.perm.resize(n);
  ord.method = previous.stats.ordering;
  for (index_t k = 0; k < n; ++k) {
    const index_t row = pi[row_sequence[k]], col = pi[col_sequence[k]];
    an.matching_perm[row] = q.empty() ? col : q[col];
    ord.perm[k] = row;
  }
  SparseMatrix c;
  c.n_rows = c.n_cols = n;
  c.storage = Storage::full;
  c.offsets = an.pattern_offsets;
  c.indices = an.pattern_indices;
  index_t diagonal_entries = 0;
  const ordering::Graph graph =
      detail::symmetric_graph(c, false, an.matching_perm, &diagonal_entries);
  an.stats.ordering_seconds = step.seconds();
  finish_analysis(an, c, graph, diagonal_entries, std::move(ord), opts, workers);
  an.stats.ordering = previous.stats.ordering;
  an.stats.order_from_pivots = true;
  an.stats.total_seconds = total.seconds();
  return an;
}

// The analysis's parallel passes (analysis/patterns.cpp) run on Options::num_threads
// threads, as the factorization does — except for a matrix of fewer than
// kParallelAnalysisEntries entries, whose passes take microseconds: there they run on the
// calling thread without entering TBB (base/serial_scope.hpp; the same result, the passes
// do not depend on the thread count).
namespace {
constexpr std::size_t kParallelAnalysisEntries = std::size_t{1} << 16;

template <class Impl>
Analysis run_analysis(const Options& opts, std::size_t entries, Impl impl) {
  if (entries < kParallelAnalysisEntries) {
    const detail::SerialScope serial(true);
    return impl();
  }
  tbb::task_arena arena(cpu_threads(opts));
  return arena.execute(impl);
}
}  // namespace

Analysis analyze_matrix(const SparseMatrix& a, const Options& opts, int workers) {
  return run_analysis(opts, a.indices.size(),
                      [&] { return analyze_matrix_impl(a, opts, workers, nullptr); });
}

Analysis analyze_validated(const SparseMatrix& a, bool canonical_full, const Options& opts,
                           int workers) {
  return analyze_validated(a, canonical_full, opts, workers, nullptr);
}

Analysis analyze_validated(const SparseMatrix& a, bool canonical_full, const Options& opts,
                           int workers, const ordering::Matching* start) {
  return run_analysis(opts, a.indices.size(), [&] {
    return analyze_matrix_impl(a, opts, workers, &canonical_full, start);
  });
}

Analysis analyze_with_order(const SparseMatrix& a, const Analysis& previous, const Options& opts,
                            int workers) {
  return run_analysis(opts, a.indices.size(),
                      [&] { return analyze_keeping_impl(a, previous, opts, workers, true); });
}

index_t factor_entries_with_order(const SparseMatrix& a, const Analysis& previous) {
  const SparseMatrix c = kept_input(a, previous, "factor_entries_with_order", true);
  const ordering::Graph graph =
      detail::symmetric_graph(c, previous.symmetric, previous.matching_perm);
  const SparseMatrix permuted = symbolic::permute_symmetric_pattern(
      graph.n, graph.xadj, graph.adjncy.data(), kept_order_of(previous));
  const std::vector<index_t> parent = symbolic::elimination_tree(permuted);
  const std::vector<index_t> counts =
      symbolic::column_counts(permuted, parent, symbolic::postorder(parent));
  index_t entries = 0;
  for (index_t cnt : counts) entries += cnt;
  return entries;
}

Analysis analyze_with_matching(const SparseMatrix& a, const Analysis& previous, const Options& opts,
                               int workers) {
  return run_analysis(opts, a.indices.size(),
                      [&] { return analyze_keeping_impl(a, previous, opts, workers, false); });
}

Analysis analyze_with_pivot_sequence(const Analysis& previous,
                                     const std::vector<index_t>& row_sequence,
                                     const std::vector<index_t>& col_sequence,
                                     const std::vector<double>& row_rescaling,
                                     const std::vector<double>& col_rescaling, const Options& opts,
                                     int workers) {
  return run_analysis(opts, previous.pattern_indices.size(), [&] {
    return analyze_with_pivot_sequence_impl(previous, row_sequence, col_sequence, row_rescaling,
                                            col_rescaling, opts, workers);
  });
}

}  // namespace strata
