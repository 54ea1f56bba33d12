// strata::mbd tests — a generated model with its integrator initialized; two integrators
// of the same model stepped side by side.
#pragma once

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>

#include "mbd/generators.hpp"
#include "mbd/integrator.hpp"
#include "mbd/model.hpp"

namespace strata::mbd::test {

/// A generated model (`spec` as --generate takes it) and its integrator, initialized (the
/// consistent initial state, the Newton system's pattern), with t_end = 0.01 s.
struct InitializedModel {
  explicit InitializedModel(const std::string& spec)
      : model(build_model(generate(spec), spec)), in(model, options()) {
    in.initialize();
  }
  static IntegratorOptions options() {
    IntegratorOptions o;
    o.t_end = 0.01;
    return o;
  }
  Model model;
  Integrator in;
};

/// Initializes a and b, then advances both a step at a time to their end: each step must
/// end at the same time in both, and every position coordinate stay within `tolerance`
/// (m, rad: absolute) of the other's. Failures are gtest failures naming the step; returns
/// the number of steps and sets *largest to the largest difference seen.
inline int step_side_by_side(Integrator& a, Integrator& b, double tolerance, double* largest) {
  a.initialize();
  b.initialize();
  int steps = 0;
  *largest = 0;
  while (!a.done() && !b.done()) {
    a.advance();
    b.advance();
    ++steps;
    if (a.t() != b.t()) {
      ADD_FAILURE() << "step " << steps << " ended at t = " << a.t() << " and " << b.t();
      return steps;
    }
    for (std::size_t i = 0; i < a.q().size(); ++i)
      *largest = std::max(*largest, std::abs(a.q()[i] - b.q()[i]));
    if (!(*largest <= tolerance)) {
      ADD_FAILURE() << "step " << steps << " t = " << a.t() << ": positions differ by " << *largest;
      return steps;
    }
  }
  EXPECT_TRUE(a.done() && b.done());
  return steps;
}

/// "%.3e" of x, for RecordProperty.
inline std::string scientific(double x) {
  char text[32];
  std::snprintf(text, sizeof text, "%.3e", x);
  return text;
}

}  // namespace strata::mbd::test
