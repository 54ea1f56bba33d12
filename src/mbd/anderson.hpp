// strata::mbd — Anderson acceleration of a fixed-point iteration (Anderson mixing).
//
// What. Modified Newton keeps one factorization of the Jacobian J₀ over several
// iterations: x_{k+1} = g(x_k) = x_k − J₀⁻¹ H(x_k), a fixed-point iteration that converges
// linearly, at the rate of ‖I − J₀⁻¹ H_x‖ (0.2–0.25 per iteration on the engine's tracked
// vehicle, whose first updates are 10⁴ tolerance units). Anderson acceleration of depth m
// combines the last m+1 iterates instead of taking g(x_k) alone:
//
//   f_k = g(x_k) − x_k (the Newton update),  ΔF = [f_{k−m+1} − f_{k−m}, …, f_k − f_{k−1}],
//   ΔG likewise with g,  γ = argmin ‖W (f_k − ΔF γ)‖₂,  x_{k+1} = g(x_k) − ΔG γ,
//
// with W the diagonal weights of the iteration's error norm. On a linear map it is
// equivalent to GMRES on (I − M) x = b (Walker & Ni 2011, Theorem 2.2): the error
// components that the stale Jacobian leaves (a few stiff contact modes) are removed by the
// least-squares fit instead of being contracted by 0.2 per iteration.
//
// Sources. D. G. Anderson, "Iterative procedures for nonlinear integral equations", J. ACM
// 12(4):547–560, 1965; H. F. Walker and P. Ni, "Anderson acceleration for fixed-point
// iterations", SIAM J. Numer. Anal. 49(4):1715–1735, 2011 (Algorithm AA, the
// "difference" form used here). The least-squares problem (m ≤ 5 columns) is solved by
// modified Gram–Schmidt on the weighted differences; a column that adds less than 1e-8
// of its norm to the span of the newer ones is dropped (with the oldest ones), which keeps
// γ bounded when the iterates stall.
#pragma once

#include <deque>
#include <vector>

#include "strata/types.hpp"

namespace strata::mbd {

class AndersonMixing {
 public:
  /// depth m: the number of past differences combined (0: plain fixed-point iteration).
  explicit AndersonMixing(int depth = 0) : depth_(depth) {}
  int depth() const { return depth_; }
  /// Forgets the history: the map g changed (a new Jacobian was factored).
  void reset();
  /// One step: x (size n) is x_k on entry and x_{k+1} on return; f (size n) is the
  /// update f_k = g(x_k) − x_k; w (size n, ≥ 0) weights the least-squares norm (a zero
  /// weight leaves a component out of the fit, not out of the update). Returns the number
  /// of differences used (0: x_{k+1} = x_k + f_k).
  int step(double* x, const double* f, const double* w, index_t n);

 private:
  int depth_;
  std::vector<double> x_prev_, f_prev_;
  bool have_prev_ = false;
  std::deque<std::vector<double>> df_, dg_;  // newest last
  std::vector<std::vector<double>> spare_;   // storage of forgotten differences, reused
  std::vector<double> q_, r_, gamma_;
};

}  // namespace strata::mbd
