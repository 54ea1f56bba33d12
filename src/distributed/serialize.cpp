// strata — Analysis to bytes and back (see serialize.hpp). A plain field-by-field writer:
// trivially copyable values as their bytes, vectors as a length and their elements.
#include "distributed/serialize.hpp"

#include <cstdint>
#include <cstring>
#include <string>
#include <type_traits>

#include "strata/errors.hpp"

namespace strata::distributed {
namespace {

class Writer {
 public:
  template <class T>
  void value(const T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    const char* p = reinterpret_cast<const char*>(&v);
    out.insert(out.end(), p, p + sizeof(T));
  }
  template <class T>
  void vec(const std::vector<T>& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    value<std::uint64_t>(v.size());
    const char* p = reinterpret_cast<const char*>(v.data());
    out.insert(out.end(), p, p + sizeof(T) * v.size());
  }
  std::vector<char> out;
};

class Reader {
 public:
  explicit Reader(const std::vector<char>& b) : b_(b) {}
  template <class T>
  void value(T& v) {
    static_assert(std::is_trivially_copyable_v<T>);
    need(sizeof(T));
    std::memcpy(&v, b_.data() + at_, sizeof(T));
    at_ += sizeof(T);
  }
  template <class T>
  void vec(std::vector<T>& v) {
    std::uint64_t n = 0;
    value(n);
    if (n > (b_.size() - at_) / sizeof(T)) fail();
    v.resize(n);
    if (n > 0) std::memcpy(v.data(), b_.data() + at_, sizeof(T) * n);  // data() may be null
    at_ += sizeof(T) * n;
  }
  void finish() const {
    if (at_ != b_.size()) fail();
  }

 private:
  void need(std::size_t k) const {
    if (b_.size() - at_ < k) fail();
  }
  [[noreturn]] void fail() const {
    throw InternalError("the broadcast analysis is malformed (" + std::to_string(b_.size()) +
                        " bytes, read up to " + std::to_string(at_) + ")");
  }
  const std::vector<char>& b_;
  std::size_t at_ = 0;
};

// One function per struct, used for both directions: `io` is a Writer or a Reader, and
// `x` const or not accordingly.
template <class IO, class Tree>
void tree_io(IO& io, Tree& t) {
  io.value(t.n);
  io.vec(t.first_pivot);
  io.vec(t.row_offsets);
  io.vec(t.rows);
  io.vec(t.parent);
  io.vec(t.child_offsets);
  io.vec(t.children);
  io.vec(t.front_of_column);
}

template <class IO, class S>
void schedule_io(IO& io, S& s) {
  io.vec(s.level_offsets);
  io.vec(s.fronts);
  io.vec(s.level_of);
}

template <class IO, class P>
void plan_io(IO& io, P& p) {
  io.value(p.budget);
  io.vec(p.batches);
  io.value(p.peak_in_core_bytes);
  io.value(p.factor_bytes);
}

template <class IO, class L>
void cb_layout_io(IO& io, L& l) {
  io.vec(l.cb_offset);
  io.value(l.arena_size);
}

template <class IO, class P>
void part_io(IO& io, P& p) {
  io.value(p.root);
  io.value(p.work);
  io.vec(p.fronts);
  schedule_io(io, p.schedule);
  plan_io(io, p.plan);
  cb_layout_io(io, p.cb_layout);
  io.vec(p.imports);
}

template <class IO, class S>
void stats_io(IO& io, S& s) {
  io.value(s.n);
  io.value(s.nnz_a);
  io.value(s.nnz_l);
  io.value(s.nnz_l_fronts);
  io.value(s.factor_flops);
  io.value(s.n_fronts);
  io.value(s.largest_front_rows);
  io.value(s.largest_front_pivots);
  io.value(s.tree_height);
  io.vec(s.fronts_per_level);
  io.value(s.peak_working_bytes);
  io.value(s.factor_bytes);
  io.value(s.cpu_factorization_bytes);
  io.value(s.analysis_bytes);
  io.value(s.memory_budget);
  io.vec(s.batches);
  io.value(s.type);
  io.value(s.backend);
  io.value(s.pairs);
  io.value(s.odd_cycles);
  io.value(s.ordering);
  io.value(s.workers);
  io.value(s.subtrees);
  io.value(s.subtree_balance);
  io.value(s.top_flops_fraction);
  io.value(s.upper_layers);
  io.value(s.upper_parts);
  io.value(s.upper_flops_fraction);
  io.value(s.estimated_speedup);
  io.value(s.nd_rebisections);
  io.value(s.nd_balance_seconds);
  io.value(s.matching_seconds);
  io.value(s.ordering_seconds);
  io.value(s.symbolic_seconds);
  io.value(s.plan_seconds);
  io.value(s.device_setup_seconds);
  io.value(s.total_seconds);
}

void write(Writer& w, const Analysis& an) {
  w.value(an.id);
  w.value(an.n);
  w.value(an.type);
  w.value(an.symmetric);
  w.vec(an.pattern_offsets);
  w.vec(an.pattern_indices);
  w.value(an.input_storage);
  w.vec(an.matching_perm);
  w.vec(an.row_scaling);
  w.vec(an.col_scaling);
  w.vec(an.pivot_groups.ptr);
  w.vec(an.pivot_groups.members);
  w.value(an.structurally_singular);
  w.vec(an.perm);
  w.vec(an.iperm);
  w.value<std::uint64_t>(an.separator_tree.nodes.size());
  for (const auto& node : an.separator_tree.nodes) {
    w.value(node.begin);
    w.value(node.end);
    w.value(node.parent);
    w.vec(node.children);
    w.value(node.subtree_begin);
    w.value(node.work);
  }
  tree_io(w, an.tree);
  schedule_io(w, an.schedule);
  plan_io(w, an.plan);
  w.vec(an.assembly.entry_offsets);
  w.vec(an.assembly.entry_src);
  w.vec(an.assembly.entry_dst);
  cb_layout_io(w, an.cb_layout);
  w.vec(an.factor_layout.panel_offset);
  w.value(an.factor_layout.total);
  const auto& p = an.partition;
  w.value(p.workers);
  w.value<std::uint64_t>(p.subtrees.size());
  for (const auto& s : p.subtrees) part_io(w, s);
  part_io(w, p.top);
  // upper layers travel whole, though the distributed factorization does not use them
  // (the distributed solver analyzes without them; make_layout refuses them)
  w.value<std::uint64_t>(p.upper.size());
  for (const auto& u : p.upper) part_io(w, u);
  w.vec(p.upper_layer_offsets);
  w.vec(p.upper_owner);
  w.vec(p.part_id);
  w.vec(p.part_of);
  w.vec(p.owner);
  w.value(p.total_work);
  w.value(p.balance);
  w.value(p.splits);
  w.value(p.estimated_time);
  stats_io(w, an.stats);
}

void read(Reader& r, Analysis& an) {
  r.value(an.id);
  r.value(an.n);
  r.value(an.type);
  r.value(an.symmetric);
  r.vec(an.pattern_offsets);
  r.vec(an.pattern_indices);
  r.value(an.input_storage);
  r.vec(an.matching_perm);
  r.vec(an.row_scaling);
  r.vec(an.col_scaling);
  r.vec(an.pivot_groups.ptr);
  r.vec(an.pivot_groups.members);
  r.value(an.structurally_singular);
  r.vec(an.perm);
  r.vec(an.iperm);
  std::uint64_t nodes = 0;
  r.value(nodes);
  an.separator_tree.nodes.clear();
  for (std::uint64_t i = 0; i < nodes; ++i) {
    auto& node = an.separator_tree.nodes.emplace_back();
    r.value(node.begin);
    r.value(node.end);
    r.value(node.parent);
    r.vec(node.children);
    r.value(node.subtree_begin);
    r.value(node.work);
  }
  tree_io(r, an.tree);
  an.child_rows = symbolic::child_row_map(an.tree);  // derived: not sent
  an.stack_plan = {};  // not sent: the executor plans for its own thread count
  schedule_io(r, an.schedule);
  plan_io(r, an.plan);
  r.vec(an.assembly.entry_offsets);
  r.vec(an.assembly.entry_src);
  r.vec(an.assembly.entry_dst);
  cb_layout_io(r, an.cb_layout);
  r.vec(an.factor_layout.panel_offset);
  r.value(an.factor_layout.total);
  auto& p = an.partition;
  r.value(p.workers);
  std::uint64_t subs = 0;
  r.value(subs);
  p.subtrees.clear();
  for (std::uint64_t i = 0; i < subs; ++i) part_io(r, p.subtrees.emplace_back());
  part_io(r, p.top);
  std::uint64_t uppers = 0;
  r.value(uppers);
  p.upper.clear();
  for (std::uint64_t i = 0; i < uppers; ++i) part_io(r, p.upper.emplace_back());
  r.vec(p.upper_layer_offsets);
  r.vec(p.upper_owner);
  r.vec(p.part_id);
  r.vec(p.part_of);
  r.vec(p.owner);
  r.value(p.total_work);
  r.value(p.balance);
  r.value(p.splits);
  r.value(p.estimated_time);
  stats_io(r, an.stats);
}

}  // namespace

std::vector<char> serialize(const Analysis& an) {
  Writer w;
  write(w, an);
  return std::move(w.out);
}

Analysis deserialize(const std::vector<char>& bytes) {
  Reader r(bytes);
  Analysis an;
  read(r, an);
  r.finish();
  return an;
}

}  // namespace strata::distributed
