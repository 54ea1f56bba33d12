// strata::mbd — the Newton matrix condensed by its rows of two entries before the sparse
// solve.
//
// The BDF relations of the engine's Newton matrix (docs/formulation.md §3–4) are rows of
// two entries: β a_j − v_j = ζ₁ and β v_j − q_j = ζ₂ (partitioned formulation: the
// independent coordinates; stabilized: the first for every coordinate). Each one gives
// one unknown as an affine function of another, x_c = (b_r − J(r, d) x_d) / J(r, c), so
// it can be eliminated exactly before the factorization: the rows holding x_c gain its
// coefficient times −J(r, d)/J(r, c) in column d, and row r and column c leave the
// system. For a flexible body, whose Newton matrix is two thirds BDF rows, the system
// the sparse solver sees shrinks to about a third, without the fill that the
// multifrontal LU's symmetrized pattern gives these rows (the unsymmetric elimination
// of a row of two entries adds none).
//
// CondensedSystem is that elimination as a map from a pattern: the reduced matrix R
// (the rows and columns that stay, in their order), R's values from the full matrix's,
// the reduced right-hand side, and the full solution from R's. With the eliminations
// e = (r, c, d) — pivot row r, eliminated column c, partner d — each eliminated unknown
// is x_c = S_c + w_c x_K(c), where K(c) is the column that stays at the end of c's
// chain of partners (q_j → v_j → a_j), w_c = m_c w_d (w = 1 on a column that stays),
// m_c = −J(r, d)/J(r, c), S_c = b_r / J(r, c) + m_c S_d (S = 0 on a column that stays).
// Then R(k, K) = Σ_{c : K(c) = K} w_c J(k, c) and the reduced right-hand side is
// b_k − Σ_c J(k, c) S_c (Gaussian elimination of the pivots (r, c) in dependency order;
// e.g. Duff, Erisman & Reid, Direct Methods for Sparse Matrices, 2nd ed., §7.2 on the
// elimination of rows with one off-diagonal entry).
//
// make_condensed_solver wraps any LinearSolver (strata's, the dense reference) so that
// it factors and solves R; the engine uses it for every Newton matrix.
#pragma once

#include <tbb/task_arena.h>

#include <functional>
#include <memory>
#include <vector>

#include "mbd/linear_solver.hpp"
#include "strata/sparse_matrix.hpp"

namespace strata::mbd {

/// One elimination: `row` is a pivot row whose only nonzero entries are in `column` (the
/// unknown eliminated with it) and `partner` (every other entry of the row must be an
/// explicit zero); 0-based indices of the full matrix.
struct RowElimination {
  index_t row = 0, column = 0, partner = 0;
  bool operator==(const RowElimination&) const = default;
};

/// The reduced system of a square CSC matrix (sorted rows in each column) under a list
/// of row eliminations (see the file comment). Built from the pattern; values() is then
/// called with each new set of values of that pattern.
class CondensedSystem {
 public:
  /// Maps the pattern of `a` (n × n, CSC with sorted rows) under `eliminations`. Throws
  /// InvalidInput when an elimination's indices are out of range, a row or column is
  /// named twice, the pivot or partner is not an entry of the pattern, or the partners
  /// form a cycle. `reduced` gets R's pattern (order n − eliminations, CSC, sorted rows).
  void build(const SparseMatrix& a, const std::vector<RowElimination>& eliminations,
             SparseMatrix& reduced);
  /// R's values from the full matrix's (the pattern given to build). Throws InvalidInput
  /// naming the row when a pivot is zero or not finite, and InternalError when an entry of
  /// a pivot row other than its pivot and partner is not zero.
  void values(const std::vector<double>& full_values, std::vector<double>& reduced_values);
  /// The reduced right-hand side (order of R) from b (order n), with the values of the
  /// last values() call (kept here: the full matrix may have changed since); keeps the
  /// S_c for expand(). Throws InvalidState before the first values().
  void reduce_rhs(const double* b, double* reduced_b);
  /// The full solution x (order n) from R's solution, after reduce_rhs of the same b.
  void expand(const double* reduced_x, double* x) const;

  index_t full_order() const { return n_; }
  index_t reduced_order() const { return n_ - static_cast<index_t>(elim_.size()); }
  /// The eliminations as build() was given them.
  const std::vector<RowElimination>& eliminations() const { return given_; }

 private:
  index_t n_ = 0;
  std::vector<RowElimination> given_;  // as given to build()
  std::vector<RowElimination> elim_;   // in dependency order: a partner eliminated before
  std::vector<index_t> pivot_pos_;     // per elimination: the entry (r, c)
  std::vector<index_t> partner_pos_;   // and (r, d)
  std::vector<index_t> partner_elim_;  // the elimination of d, or −1 when d stays
  std::vector<index_t> elim_of_col_;   // per column: its elimination, or −1
  std::vector<index_t> final_col_;     // per elimination: K(c), in R's numbering
  std::vector<index_t> new_row_;       // per row: its row in R, or −1 (a pivot row)
  std::vector<index_t> kept_col_;      // per column of R: its column of the full matrix
  std::vector<index_t> zero_pos_;      // the other entries of the pivot rows
  // R's entries: contrib_[contrib_ptr_[q] .. contrib_ptr_[q+1]) are the full matrix's
  // entries summed into entry q, each with the elimination whose w scales it (−1: w = 1)
  std::vector<index_t> contrib_ptr_, contrib_pos_, contrib_elim_;
  // the entries of eliminated columns in rows that stay, by row of R (rhs_ptr_): their
  // positions, eliminations and (from values()) values; R's rows in the full matrix
  std::vector<index_t> kept_row_, rhs_ptr_, rhs_pos_, rhs_elim_;
  std::vector<index_t> col_ptr_, col_pos_, col_row_;  // the same by elimination
  std::vector<double> col_val_;
  std::vector<double> rhs_val_;
  // per elimination, from the last values() (pivot, m, w) and reduce_rhs() (S): what a
  // solve needs stays here, so the full matrix may change between values() and the solves
  std::vector<double> pivot_, m_, w_, s_;
  bool have_values_ = false;
};

/// Whether the engine condenses a Newton matrix of this order by this many eliminations:
/// when they remove at least a third of its rows (a flexible body's two thirds, a lattice
/// of bushings over half; not a tracked vehicle's 8–21 %, whose condensed runs were no
/// faster on the host and slower on a GPU: bench/history.md, "The Newton matrix condensed
/// by its BDF relations").
bool worth_condensing(index_t order, std::size_t eliminations);

/// A LinearSolver that hands `inner` the system condensed by `eliminations()` (called at
/// every analysis and at every factorization of a pattern other than the one mapped, so
/// it follows the engine's formulation and partition; an empty list hands it the matrix
/// as it is). The passes over R's values and the right-hand side run on the threads of
/// `arena()` (the engine's, as its thread count says; null: one thread), or without an
/// `arena` function on the calling thread's arena. Statistics, factor entries and pivots are those
/// of `inner` on the reduced system.
std::unique_ptr<LinearSolver> make_condensed_solver(
    std::unique_ptr<LinearSolver> inner, std::function<std::vector<RowElimination>()> eliminations,
    std::function<tbb::task_arena*()> arena = {});

}  // namespace strata::mbd
