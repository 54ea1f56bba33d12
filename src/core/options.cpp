// strata — the options' vocabulary: one table of names per enum and one range check per
// field (strata/options.hpp), used by the analysis, the command line, the C API, the
// Python module and the multibody engine, so that each accepts the same names and gives
// the same message for the same mistake.
#include "strata/options.hpp"

#include <cmath>
#include <cstdio>
#include <string>
#include <type_traits>
#include <utility>

#include "strata/errors.hpp"

namespace strata {
namespace {

// One value and its names: the canonical one first, then the aliases.
template <class E>
struct Named {
  E value;
  std::vector<const char*> names;
};

template <class E>
struct Vocabulary;

template <>
struct Vocabulary<MatrixType> {
  static constexpr const char* option = "type";
  static const std::vector<Named<MatrixType>>& values() {
    static const std::vector<Named<MatrixType>> v = {
        {MatrixType::automatic, {"auto", "automatic"}},
        {MatrixType::spd, {"spd"}},
        {MatrixType::symmetric_indefinite, {"symmetric_indefinite", "ldlt", "sym"}},
        {MatrixType::general, {"general", "lu"}}};
    return v;
  }
};

template <>
struct Vocabulary<OrderingMethod> {
  static constexpr const char* option = "ordering";
  static const std::vector<Named<OrderingMethod>>& values() {
    static const std::vector<Named<OrderingMethod>> v = {
        {OrderingMethod::nested_dissection, {"nd", "nested_dissection"}},
        {OrderingMethod::metis, {"metis"}},
        {OrderingMethod::amd, {"amd"}},
        {OrderingMethod::natural, {"natural"}}};
    return v;
  }
};

template <>
struct Vocabulary<Backend> {
  static constexpr const char* option = "device";
  static const std::vector<Named<Backend>>& values() {
    static const std::vector<Named<Backend>> v = {{Backend::automatic, {"auto", "automatic"}},
                                                  {Backend::cpu, {"cpu"}},
                                                  {Backend::cuda, {"cuda", "gpu"}}};
    return v;
  }
};

template <>
struct Vocabulary<Pivoting> {
  static constexpr const char* option = "pivoting";
  static const std::vector<Named<Pivoting>>& values() {
    static const std::vector<Named<Pivoting>> v = {{Pivoting::fixed, {"fixed"}},
                                                   {Pivoting::automatic, {"automatic", "auto"}},
                                                   {Pivoting::delayed, {"delayed"}}};
    return v;
  }
};

template <>
struct Vocabulary<SolveCheck> {
  static constexpr const char* option = "solve_check";
  static const std::vector<Named<SolveCheck>>& values() {
    static const std::vector<Named<SolveCheck>> v = {
        {SolveCheck::always, {"always"}},
        {SolveCheck::after_perturbed_pivots, {"after_perturbed_pivots"}}};
    return v;
  }
};

template <class E>
const char* name_of(E value) {
  for (const auto& n : Vocabulary<E>::values())
    if (n.value == value) return n.names.front();
  return "unknown";
}

template <class E>
void parse_into(std::string_view text, E* out) {
  std::string accepted;
  const auto& values = Vocabulary<E>::values();
  for (std::size_t i = 0; i < values.size(); ++i) {
    for (std::string_view name : values[i].names)
      if (name == text) {
        *out = values[i].value;
        return;
      }
    accepted += (i == 0                   ? "'"
                 : i + 1 == values.size() ? " or '"
                                          : ", '") +
                std::string(values[i].names.front()) + "'";
  }
  std::string aliases;
  for (const auto& v : values)
    for (std::size_t k = 1; k < v.names.size(); ++k)
      aliases += (aliases.empty() ? "" : ", ") + std::string(v.names[k]) + " = " +
                 std::string(v.names.front());
  throw InvalidInput(std::string(Vocabulary<E>::option) + " must be " + accepted +
                     (aliases.empty() ? "" : " (aliases: " + aliases + ")") + ", got '" +
                     std::string(text) + "'");
}

// "Options::NAME must be WHAT (got VALUE)"
template <class T>
[[noreturn]] void out_of_range(const char* name, const char* what, T value) {
  std::string got;
  if constexpr (std::is_floating_point_v<T>) {
    char buf[32];
    std::snprintf(buf, sizeof buf, "%g", static_cast<double>(value));
    got = buf;
  } else {
    got = std::to_string(value);
  }
  throw InvalidInput(std::string("Options::") + name + " must be " + what + " (got " + got + ")");
}

template <class T>
void at_least(const char* name, T value, T least) {
  if (value < least) out_of_range(name, ("at least " + std::to_string(least)).c_str(), value);
}

void fraction(const char* name, double value, bool zero_ok, bool one_ok) {
  const bool ok = (zero_ok ? value >= 0 : value > 0) && (one_ok ? value <= 1 : value < 1);
  if (!ok) {
    const std::string what =
        std::string("in ") + (zero_ok ? "[" : "(") + "0, 1" + (one_ok ? "]" : ")");
    out_of_range(name, what.c_str(), value);
  }
}

template <class E>
void known(const char* name, E value) {
  for (const auto& n : Vocabulary<E>::values())
    if (n.value == value) return;
  out_of_range(name, "one of the enum's values", static_cast<int>(value));
}

}  // namespace

const char* to_string(MatrixType value) { return name_of(value); }
const char* to_string(OrderingMethod value) {
  return value == OrderingMethod::user ? "user" : name_of(value);
}
const char* to_string(Backend value) { return name_of(value); }
const char* to_string(Pivoting value) { return name_of(value); }
const char* to_string(SolveCheck value) { return name_of(value); }

void parse(std::string_view text, MatrixType* out) { parse_into(text, out); }
void parse(std::string_view text, OrderingMethod* out) { parse_into(text, out); }
void parse(std::string_view text, Backend* out) { parse_into(text, out); }
void parse(std::string_view text, Pivoting* out) { parse_into(text, out); }
void parse(std::string_view text, SolveCheck* out) { parse_into(text, out); }

template <class E>
std::vector<std::string> option_names() {
  std::vector<std::string> names;
  for (const auto& v : Vocabulary<E>::values()) names.emplace_back(v.names.front());
  for (const auto& v : Vocabulary<E>::values())
    for (std::size_t k = 1; k < v.names.size(); ++k) names.emplace_back(v.names[k]);
  return names;
}
template std::vector<std::string> option_names<MatrixType>();
template std::vector<std::string> option_names<OrderingMethod>();
template std::vector<std::string> option_names<Backend>();
template std::vector<std::string> option_names<Pivoting>();
template std::vector<std::string> option_names<SolveCheck>();

void validate(const Options& o) {
  known("type", o.type);
  if (o.ordering != OrderingMethod::user) known("ordering", o.ordering);
  known("backend", o.backend);
  known("pivoting", o.pivoting);
  known("solve_check", o.solve_check);
  at_least<index_t>("nd_leaf_size", o.nd_leaf_size, 1);
  at_least("nd_top_separators", o.nd_top_separators, 1);
  at_least<index_t>("relax_small", o.relax_small, 0);
  at_least<index_t>("relax_size_1", o.relax_size_1, 0);
  at_least<index_t>("relax_size_2", o.relax_size_2, 0);
  fraction("relax_zeros_1", o.relax_zeros_1, true, true);
  fraction("relax_zeros_2", o.relax_zeros_2, true, true);
  fraction("relax_zeros_3", o.relax_zeros_3, true, true);
  at_least<index_t>("max_block_size", o.max_block_size, 0);
  at_least("num_threads", o.num_threads, 0);
  at_least<index_t>("gpu_panel_kernel_max_pivots", o.gpu_panel_kernel_max_pivots, 0);
  at_least<index_t>("gpu_lu_strip_pivots", o.gpu_lu_strip_pivots, 0);
  fraction("gpu_tiled_pool_share", o.gpu_tiled_pool_share, true, false);
  at_least<index_t>("gpu_tiled_stream_columns", o.gpu_tiled_stream_columns, 0);
  at_least<index_t>("gpu_potrf_block_size", o.gpu_potrf_block_size, 0);
  at_least("num_gpus", o.num_gpus, 0);
  at_least("subtrees_per_gpu", o.subtrees_per_gpu, 1);
  at_least<index_t>("split_front_min_cb", o.split_front_min_cb, 0);
  at_least<index_t>("distributed_front_min_rows", o.distributed_front_min_rows, 0);
  at_least<index_t>("distributed_front_block_size", o.distributed_front_block_size, 64);
  if (!std::isfinite(o.pairing_threshold))
    out_of_range("pairing_threshold", "finite", o.pairing_threshold);
  if (!(o.static_pivot_epsilon >= 0 && std::isfinite(o.static_pivot_epsilon)))
    out_of_range("static_pivot_epsilon", "finite and at least 0", o.static_pivot_epsilon);
  fraction("pivot_threshold", o.pivot_threshold, false, true);
  at_least("refinement_max_steps", o.refinement_max_steps, 0);
  if (!(o.refinement_tolerance >= 0 && std::isfinite(o.refinement_tolerance)))
    out_of_range("refinement_tolerance", "finite and at least 0", o.refinement_tolerance);
  at_least("gmres_max_iterations", o.gmres_max_iterations, 0);
}

}  // namespace strata
