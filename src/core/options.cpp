// strata — the options' vocabulary: one table of names per enum and one range check per
// field (strata/options.hpp), used by the analysis, the command line, the C API, the
// Python module and the multibody engine, so that each accepts the same names and gives
// the same message for the same mistake.
#include "strata/options.hpp"

#include <cerrno>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <functional>
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
        {OrderingMethod::natural, {"natural"}},
        {OrderingMethod::automatic, {"auto", "automatic"}}};
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
                                                   {Pivoting::delayed, {"delayed"}},
                                                   {Pivoting::corrected, {"corrected"}}};
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
  at_least("nd_separators", o.nd_separators, 0);
  at_least<index_t>("relax_small", o.relax_small, 0);
  at_least<index_t>("relax_size_1", o.relax_size_1, 0);
  at_least<index_t>("relax_size_2", o.relax_size_2, 0);
  fraction("relax_zeros_1", o.relax_zeros_1, true, true);
  fraction("relax_zeros_2", o.relax_zeros_2, true, true);
  fraction("relax_zeros_3", o.relax_zeros_3, true, true);
  at_least<index_t>("max_block_size", o.max_block_size, 0);
  at_least("num_threads", o.num_threads, 0);
  if (!(o.gpu_min_flops >= 0))  // NaN too; +inf keeps every automatic analysis on the host
    out_of_range("gpu_min_flops", "at least 0", o.gpu_min_flops);
  if (o.gpu_small_front_rows < 1 || o.gpu_small_front_rows > 256)
    out_of_range("gpu_small_front_rows", "in [1, 256]", o.gpu_small_front_rows);
  if (o.gpu_small_front_threads < 0 || o.gpu_small_front_threads > 512)
    out_of_range("gpu_small_front_threads", "in [0, 512]", o.gpu_small_front_threads);
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
  at_least<index_t>("max_corrected_pivots", o.max_corrected_pivots, 0);
  fraction("pivot_threshold", o.pivot_threshold, false, true);
  fraction("diagonal_pivot_threshold", o.diagonal_pivot_threshold, false, true);
  at_least("refinement_max_steps", o.refinement_max_steps, 0);
  if (!(o.refinement_tolerance >= 0 && std::isfinite(o.refinement_tolerance)))
    out_of_range("refinement_tolerance", "finite and at least 0", o.refinement_tolerance);
  at_least("gmres_max_iterations", o.gmres_max_iterations, 0);
}

namespace {

// One settable field: its name and how to read and write it as text.
struct Field {
  const char* name;
  std::function<void(Options&, std::string_view)> set;
  std::function<std::string(const Options&)> get;
};

[[noreturn]] void not_a(const char* name, const char* what, std::string_view text) {
  throw InvalidInput(std::string("option ") + name + " must be " + what + ", got '" +
                     std::string(text) + "'");
}

template <class T>
Field integer_field(const char* name, T Options::*member) {
  return {name,
          [name, member](Options& o, std::string_view text) {
            T v{};
            const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), v);
            if (ec != std::errc() || end != text.data() + text.size() || text.empty())
              not_a(name,
                    std::is_signed_v<T> ? "a whole number in range"
                                        : "a whole number of at least 0, in range",
                    text);
            o.*member = v;
          },
          [member](const Options& o) { return std::to_string(o.*member); }};
}

Field number_field(const char* name, double Options::*member) {
  return {name,
          [name, member](Options& o, std::string_view text) {
            const std::string t(text);
            char* end = nullptr;
            errno = 0;
            const double v = std::strtod(t.c_str(), &end);
            if (t.empty() || end != t.c_str() + t.size() || errno == ERANGE || !std::isfinite(v))
              not_a(name, "a finite number", text);
            o.*member = v;
          },
          [member](const Options& o) {
            char buf[32];
            std::snprintf(buf, sizeof buf, "%.17g", o.*member);
            return std::string(buf);
          }};
}

Field flag_field(const char* name, bool Options::*member) {
  return {name,
          [name, member](Options& o, std::string_view text) {
            if (text == "true" || text == "on" || text == "1")
              o.*member = true;
            else if (text == "false" || text == "off" || text == "0")
              o.*member = false;
            else
              not_a(name, "true or false (on/off, 1/0)", text);
          },
          [member](const Options& o) { return std::string(o.*member ? "true" : "false"); }};
}

template <class E>
Field enum_field(const char* name, E Options::*member) {
  return {name, [member](Options& o, std::string_view text) { parse(text, &(o.*member)); },
          [member](const Options& o) { return std::string(to_string(o.*member)); }};
}

const std::vector<Field>& fields() {
  using O = Options;
  static const std::vector<Field> f = {
      enum_field("type", &O::type),
      {"ordering", [](Options& o, std::string_view text) { parse(text, &o.ordering); },
       [](const Options& o) { return std::string(to_string(o.ordering)); }},
      integer_field("nd_leaf_size", &O::nd_leaf_size),
      integer_field("nd_top_separators", &O::nd_top_separators),
      integer_field("nd_separators", &O::nd_separators),
      integer_field("relax_small", &O::relax_small),
      integer_field("relax_size_1", &O::relax_size_1),
      integer_field("relax_size_2", &O::relax_size_2),
      number_field("relax_zeros_1", &O::relax_zeros_1),
      number_field("relax_zeros_2", &O::relax_zeros_2),
      number_field("relax_zeros_3", &O::relax_zeros_3),
      integer_field("max_block_size", &O::max_block_size),
      integer_field("device_memory_limit", &O::device_memory_limit),
      integer_field("host_memory_limit", &O::host_memory_limit),
      enum_field("backend", &O::backend),
      number_field("gpu_min_flops", &O::gpu_min_flops),
      integer_field("num_threads", &O::num_threads),
      flag_field("reproducible", &O::reproducible),
      integer_field("gpu_small_front_rows", &O::gpu_small_front_rows),
      integer_field("gpu_small_front_threads", &O::gpu_small_front_threads),
      flag_field("gpu_fused_small_batches", &O::gpu_fused_small_batches),
      integer_field("gpu_panel_kernel_max_pivots", &O::gpu_panel_kernel_max_pivots),
      integer_field("gpu_lu_strip_pivots", &O::gpu_lu_strip_pivots),
      number_field("gpu_tiled_pool_share", &O::gpu_tiled_pool_share),
      integer_field("gpu_tiled_stream_columns", &O::gpu_tiled_stream_columns),
      flag_field("gpu_tiled_prefetch", &O::gpu_tiled_prefetch),
      integer_field("gpu_potrf_block_size", &O::gpu_potrf_block_size),
      flag_field("gpu_recursive_panel", &O::gpu_recursive_panel),
      flag_field("gpu_solve_graph", &O::gpu_solve_graph),
      flag_field("gpu_refinement", &O::gpu_refinement),
      flag_field("gpu_solve_chain", &O::gpu_solve_chain),
      flag_field("gpu_solve_parts", &O::gpu_solve_parts),
      integer_field("num_gpus", &O::num_gpus),
      integer_field("subtrees_per_gpu", &O::subtrees_per_gpu),
      flag_field("balance_by_work", &O::balance_by_work),
      flag_field("work_stealing", &O::work_stealing),
      flag_field("split_top", &O::split_top),
      integer_field("split_front_min_cb", &O::split_front_min_cb),
      integer_field("distributed_front_min_rows", &O::distributed_front_min_rows),
      integer_field("distributed_front_block_size", &O::distributed_front_block_size),
      flag_field("matching_and_scaling", &O::matching_and_scaling),
      number_field("pairing_threshold", &O::pairing_threshold),
      number_field("static_pivot_epsilon", &O::static_pivot_epsilon),
      enum_field("pivoting", &O::pivoting),
      integer_field("max_corrected_pivots", &O::max_corrected_pivots),
      number_field("pivot_threshold", &O::pivot_threshold),
      number_field("diagonal_pivot_threshold", &O::diagonal_pivot_threshold),
      enum_field("solve_check", &O::solve_check),
      integer_field("refinement_max_steps", &O::refinement_max_steps),
      number_field("refinement_tolerance", &O::refinement_tolerance),
      integer_field("gmres_max_iterations", &O::gmres_max_iterations)};
  return f;
}

const Field& field(std::string_view name) {
  if (name == "device") name = "backend";
  for (const Field& f : fields())
    if (name == f.name) return f;
  throw InvalidInput("unknown option '" + std::string(name) +
                     "' (the names are Options' fields, e.g. ordering, pivot_threshold, "
                     "num_threads; user_permutation has no text form)");
}

}  // namespace

void set_option(Options& options, std::string_view name, std::string_view value) {
  Options changed = options;  // options unchanged when the value does not parse
  field(name).set(changed, value);
  options = std::move(changed);
}

std::string get_option(const Options& options, std::string_view name) {
  return field(name).get(options);
}

std::vector<std::string> option_fields() {
  std::vector<std::string> names;
  for (const Field& f : fields()) names.emplace_back(f.name);
  return names;
}

}  // namespace strata
