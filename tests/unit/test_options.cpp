// strata tests — the options' vocabulary (strata/options.hpp, src/core/options.cpp), which
// the CLI, the C API, Python and the engine share: every value's canonical name parses
// back to the value, the aliases parse to theirs, an unknown name is refused with the
// option's name, the names accepted and the text given (and the target left unchanged);
// validate passes the defaults and names the field of every value out of range, and the
// analysis refuses such options before it reads the matrix; the generic setter
// (set_option / get_option) reads and writes every field by its name.
#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <string>
#include <vector>

#include "sparse/generators.hpp"
#include "strata/strata.hpp"

namespace strata {
namespace {

template <class E>
void expect_round_trip(const std::vector<E>& values) {
  const std::vector<std::string> names = option_names<E>();
  for (std::size_t k = 0; k < values.size(); ++k) {
    const E v = values[k];
    E back = values[(k + 1) % values.size()];
    parse(to_string(v), &back);
    EXPECT_EQ(back, v) << to_string(v);
    EXPECT_EQ(names[k], to_string(v)) << "canonical names first, in the enum's order";
  }
  for (const std::string& name : names) {  // every name listed parses
    E v{};
    EXPECT_NO_THROW(parse(name, &v)) << name;
  }
}

TEST(OptionNames, CanonicalNamesRoundTrip) {
  expect_round_trip<MatrixType>({MatrixType::automatic, MatrixType::spd,
                                 MatrixType::symmetric_indefinite, MatrixType::general});
  expect_round_trip<OrderingMethod>({OrderingMethod::nested_dissection, OrderingMethod::metis,
                                     OrderingMethod::amd, OrderingMethod::natural});
  expect_round_trip<Backend>({Backend::automatic, Backend::cpu, Backend::cuda});
  expect_round_trip<Pivoting>(
      {Pivoting::fixed, Pivoting::automatic, Pivoting::delayed, Pivoting::corrected});
  expect_round_trip<SolveCheck>({SolveCheck::always, SolveCheck::after_perturbed_pivots});
  EXPECT_STREQ(to_string(OrderingMethod::user), "user");
}

TEST(OptionNames, AliasesParseToTheirValues) {
  MatrixType t{};
  parse("lu", &t);
  EXPECT_EQ(t, MatrixType::general);
  parse("ldlt", &t);
  EXPECT_EQ(t, MatrixType::symmetric_indefinite);
  parse("automatic", &t);
  EXPECT_EQ(t, MatrixType::automatic);
  Backend b{};
  parse("gpu", &b);
  EXPECT_EQ(b, Backend::cuda);
  OrderingMethod o{};
  parse("nested_dissection", &o);
  EXPECT_EQ(o, OrderingMethod::nested_dissection);
  Pivoting p{};
  parse("auto", &p);
  EXPECT_EQ(p, Pivoting::automatic);
}

TEST(OptionNames, UnknownNamesAreRefusedWithTheChoices) {
  OrderingMethod o = OrderingMethod::amd;
  try {
    parse("rcm", &o);
    FAIL() << "rcm was accepted";
  } catch (const InvalidInput& e) {
    EXPECT_STREQ(e.what(),
                 "ordering must be 'nd', 'metis', 'amd', 'natural' or 'auto' (aliases: "
                 "nested_dissection = nd, automatic = auto), got 'rcm'");
  }
  EXPECT_EQ(o, OrderingMethod::amd);  // unchanged
  MatrixType t = MatrixType::spd;
  EXPECT_THROW(parse("", &t), InvalidInput);
  EXPECT_THROW(parse("SPD", &t), InvalidInput);   // names are case-sensitive
  EXPECT_THROW(parse("user", &o), InvalidInput);  // set by giving a permutation
  EXPECT_EQ(t, MatrixType::spd);
  SolveCheck c{};
  try {
    parse("never", &c);
    FAIL();
  } catch (const InvalidInput& e) {
    EXPECT_EQ(std::string(e.what()),
              "solve_check must be 'always' or 'after_perturbed_pivots', got 'never'");
  }
}

TEST(OptionsValidate, DefaultsPassAndEveryFieldOutOfRangeIsNamed) {
  EXPECT_NO_THROW(validate(Options{}));
  const double nan = std::numeric_limits<double>::quiet_NaN();
  const double inf = std::numeric_limits<double>::infinity();
  struct Case {
    const char* field;
    void (*set)(Options&, double);
    std::vector<double> bad, good;
  };
  const std::vector<Case> cases = {
      {"nd_leaf_size",
       [](Options& o, double v) { o.nd_leaf_size = index_t(v); },
       {0, -3},
       {1, 128}},
      {"nd_top_separators",
       [](Options& o, double v) { o.nd_top_separators = int(v); },
       {0},
       {1, 3}},
      {"nd_separators", [](Options& o, double v) { o.nd_separators = int(v); }, {-1}, {0, 1, 2}},
      {"relax_small", [](Options& o, double v) { o.relax_small = index_t(v); }, {-1}, {0, 4}},
      {"relax_zeros_1",
       [](Options& o, double v) { o.relax_zeros_1 = v; },
       {-0.1, 1.5, nan},
       {0, 1}},
      {"max_block_size",
       [](Options& o, double v) { o.max_block_size = index_t(v); },
       {-1},
       {0, 64}},
      {"num_threads", [](Options& o, double v) { o.num_threads = int(v); }, {-1}, {0, 2}},
      {"gpu_tiled_pool_share",
       [](Options& o, double v) { o.gpu_tiled_pool_share = v; },
       {1, -0.5, nan},
       {0, 0.5}},
      {"gpu_small_front_rows",
       [](Options& o, double v) { o.gpu_small_front_rows = index_t(v); },
       {0, -1, 257},
       {1, 64, 256}},
      {"gpu_small_front_threads",
       [](Options& o, double v) { o.gpu_small_front_threads = int(v); },
       {-1, 513},
       {0, 256, 512}},
      {"num_gpus", [](Options& o, double v) { o.num_gpus = int(v); }, {-1}, {0}},
      {"subtrees_per_gpu", [](Options& o, double v) { o.subtrees_per_gpu = int(v); }, {0}, {1}},
      {"distributed_front_block_size",
       [](Options& o, double v) { o.distributed_front_block_size = index_t(v); },
       {63},
       {64}},
      {"pairing_threshold",
       [](Options& o, double v) { o.pairing_threshold = v; },
       {nan, inf},
       {0, -1, 0.01}},
      {"static_pivot_epsilon",
       [](Options& o, double v) { o.static_pivot_epsilon = v; },
       {-1e-8, inf, nan},
       {0, 1e-8}},
      {"pivot_threshold",
       [](Options& o, double v) { o.pivot_threshold = v; },
       {0, 1.01, nan},
       {1, 0.01}},
      {"diagonal_pivot_threshold",
       [](Options& o, double v) { o.diagonal_pivot_threshold = v; },
       {0, -0.1, 1.01, inf, nan},
       {1, 0.1, 1e-3}},
      {"refinement_max_steps",
       [](Options& o, double v) { o.refinement_max_steps = int(v); },
       {-1},
       {0, 10}},
      {"refinement_tolerance",
       [](Options& o, double v) { o.refinement_tolerance = v; },
       {-1, inf, nan},
       {0, 1e-15}},
      {"gmres_max_iterations",
       [](Options& o, double v) { o.gmres_max_iterations = int(v); },
       {-1},
       {0}},
  };
  for (const Case& c : cases) {
    for (double v : c.good) {
      Options o;
      c.set(o, v);
      EXPECT_NO_THROW(validate(o)) << c.field << " = " << v;
    }
    for (double v : c.bad) {
      Options o;
      c.set(o, v);
      try {
        validate(o);
        ADD_FAILURE() << c.field << " = " << v << " was accepted";
      } catch (const InvalidInput& e) {
        EXPECT_NE(std::string(e.what()).find(std::string("Options::") + c.field + " must be"),
                  std::string::npos)
            << e.what();
      }
    }
  }
  Options o;
  o.pivoting = static_cast<Pivoting>(17);
  EXPECT_THROW(validate(o), InvalidInput);
}

// The analysis checks the options first: a bad one is refused whatever the matrix.
TEST(OptionsValidate, AnalysisRefusesBadOptions) {
  const SparseMatrix a = generators::laplacian_2d(3, 3);
  Options o;
  o.pivot_threshold = 2;
  Solver s(o);
  try {
    s.analyze(a);
    FAIL() << "analysis accepted pivot_threshold 2";
  } catch (const InvalidInput& e) {
    EXPECT_STREQ(e.what(), "Options::pivot_threshold must be in (0, 1] (got 2)");
  }
  Options negative;
  negative.gpu_min_flops = -1;
  try {
    Solver(negative).analyze(a);
    FAIL() << "analysis accepted gpu_min_flops -1";
  } catch (const InvalidInput& e) {
    EXPECT_STREQ(e.what(), "Options::gpu_min_flops must be at least 0 (got -1)");
  }
}

// Every field set_option knows reads back what was written, through a second Options:
// a changed value of each field (the next enum value, a number + 1, the flag flipped) is
// written as text into a default Options and compared field by field.
TEST(SetOption, EveryFieldRoundTripsThroughText) {
  const std::vector<std::string> names = option_fields();
  EXPECT_EQ(names.size(), 51u);  // Options' fields but user_permutation
  Options changed;
  for (const std::string& name : names) {
    const std::string before = get_option(changed, name);
    std::string text;
    if (before == "true" || before == "false") {
      text = before == "true" ? "false" : "true";
    } else if (name == "type") {
      text = "lu";
    } else if (name == "ordering") {
      text = "amd";
    } else if (name == "backend") {
      text = "gpu";
    } else if (name == "pivoting") {
      text = "delayed";
    } else if (name == "solve_check") {
      text = "after_perturbed_pivots";
    } else if (name == "gpu_small_front_threads") {
      text = "256";  // the default is the largest
    } else if (before.find_first_of(".e") != std::string::npos) {
      text = std::to_string(std::stod(before) / 2);
    } else {
      text = std::to_string(std::stoll(before) + 1);
    }
    set_option(changed, name, text);
    EXPECT_NE(get_option(changed, name), before) << name;
  }
  Options copy;
  for (const std::string& name : names) set_option(copy, name, get_option(changed, name));
  for (const std::string& name : names)
    EXPECT_EQ(get_option(copy, name), get_option(changed, name)) << name;
  // spot checks against the fields themselves
  EXPECT_EQ(copy.type, MatrixType::general);
  EXPECT_EQ(copy.ordering, OrderingMethod::amd);
  EXPECT_EQ(copy.backend, Backend::cuda);
  EXPECT_EQ(copy.pivoting, Pivoting::delayed);
  EXPECT_EQ(copy.max_corrected_pivots, Options{}.max_corrected_pivots + 1);
  EXPECT_EQ(copy.nd_leaf_size, Options{}.nd_leaf_size + 1);
  EXPECT_EQ(copy.nd_separators, Options{}.nd_separators + 1);
  EXPECT_EQ(copy.pivot_threshold, Options{}.pivot_threshold / 2);
  EXPECT_EQ(copy.reproducible, !Options{}.reproducible);
  EXPECT_EQ(copy.device_memory_limit, Options{}.device_memory_limit + 1);
  EXPECT_EQ(copy.host_memory_limit, Options{}.host_memory_limit + 1);
  EXPECT_EQ(copy.gpu_min_flops, Options{}.gpu_min_flops + 1);  // written as 10000000000
}

TEST(SetOption, AliasesFlagsAndFullRanges) {
  Options o;
  set_option(o, "device", "cpu");
  EXPECT_EQ(o.backend, Backend::cpu);
  for (const char* on : {"true", "on", "1"}) {
    o.split_top = false;
    set_option(o, "split_top", on);
    EXPECT_TRUE(o.split_top) << on;
  }
  for (const char* off : {"false", "off", "0"}) {
    o.split_top = true;
    set_option(o, "split_top", off);
    EXPECT_FALSE(o.split_top) << off;
  }
  set_option(o, "device_memory_limit", "18446744073709551615");
  EXPECT_EQ(o.device_memory_limit, std::numeric_limits<std::size_t>::max());
  set_option(o, "static_pivot_epsilon", "1e-300");
  EXPECT_EQ(o.static_pivot_epsilon, 1e-300);
  EXPECT_EQ(get_option(o, "static_pivot_epsilon"), "1e-300");
}

TEST(SetOption, BadNamesAndValuesAreRefusedAndLeaveTheOptions) {
  Options o;
  o.num_threads = 3;
  auto refused = [&](const char* name, const char* value, const char* says) {
    const Options before = o;
    try {
      set_option(o, name, value);
      ADD_FAILURE() << name << " = " << value << " was accepted";
    } catch (const InvalidInput& e) {
      EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
    }
    EXPECT_EQ(get_option(o, "num_threads"), get_option(before, "num_threads"));
  };
  refused("num_thread", "2", "unknown option 'num_thread'");
  refused("user_permutation", "1", "unknown option");
  refused("num_threads", "two", "option num_threads must be a whole number");
  refused("num_threads", "2.5", "option num_threads must be a whole number");
  refused("num_threads", "", "option num_threads must be a whole number");
  refused("num_threads", "99999999999999999999", "in range");
  refused("device_memory_limit", "-1", "of at least 0");
  refused("pivot_threshold", "nan", "option pivot_threshold must be a finite number");
  refused("pivot_threshold", "0.1x", "a finite number");
  refused("pivot_threshold", "1e999", "a finite number");
  refused("reproducible", "yes", "true or false");
  refused("ordering", "colamd", "ordering must be");
  EXPECT_EQ(o.num_threads, 3);
  // ranges are validate's: a parsed value out of range is set, and validate names it
  set_option(o, "pivot_threshold", "0");
  EXPECT_THROW(validate(o), InvalidInput);
}

}  // namespace
}  // namespace strata
