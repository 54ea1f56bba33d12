// strata::mbd — the residual H(x) and Jacobian H_x of one implicit BDF step.
//
// Unknowns x = [a; v; q; λ] (n, n, n, m). Residual (docs/formulation.md):
//   F  = Σ g(q, v, a, t) + Φ_qᵀλ                    n   equations of motion
//   Φ̈  = Φ_q a + (Φ_q v)_q v + 2Φ_qt v + Φ_tt         m   acceleration constraints
//   Φ̇  = Φ_q v + Φ_t                                m   velocity constraints
//   Φ  = Φ(q, t)                                    m   position constraints
//   U₁ᵀ(β a − v − ζ₁)                               n−m BDF relation v ↔ a, independent coords
//   U₂ᵀ(β v − q − ζ₂)                               n−m BDF relation q ↔ v, independent coords
// with β = h/b₀ the BDF coefficient and ζ₁, ζ₂ the BDF history terms. U₁ = U₂ select the
// independent coordinates of a coordinate partitioning (partition.hpp). H_x is a square
// sparse matrix of order 3n + m; its pattern is built once per partition and every
// evaluation only rewrites the values (element blocks are scattered through
// precomputed positions).
#pragma once

#include <vector>

#include "mbd/model.hpp"
#include "mbd/partition.hpp"
#include "strata/sparse_matrix.hpp"

namespace strata::mbd {

/// Builds a canonical CSC matrix from (row, col) pairs and finds entry positions.
class PatternBuilder {
 public:
  explicit PatternBuilder(index_t n_rows, index_t n_cols) : rows_(n_rows), cols_(n_cols) {}
  void add(index_t r, index_t c) {
    keys_.push_back(static_cast<unsigned long long>(c) * rows_ + r);
  }
  /// Sorts, removes duplicates, and returns the pattern (values zero).
  SparseMatrix finish();
  /// Position of (r, c) in the finished matrix's values.
  index_t find(index_t r, index_t c) const;

 private:
  index_t rows_, cols_;
  std::vector<unsigned long long> keys_;
  SparseMatrix a_;
};

/// The BDF relation of the current step: β = h/b₀ and the history terms ζ₁, ζ₂ (n each).
struct BdfTerms {
  double beta = 1;
  const double* zeta1 = nullptr;
  const double* zeta2 = nullptr;
};

class NewtonSystem {
 public:
  explicit NewtonSystem(const Model& model);
  index_t n() const { return n_; }
  index_t m() const { return m_; }
  index_t size() const { return 3 * n_ + m_; }
  /// Threads for the assembly (OpenMP); default 1.
  void set_threads(int threads) { threads_ = threads > 0 ? threads : 1; }

  /// Uses the partition's independent coordinates for U₁ = U₂ and rebuilds the pattern.
  void set_partition(const Partition& p);
  /// Rebuilds the pattern (after a change of the partition or the candidate set).
  void rebuild_pattern();
  const std::vector<index_t>& independent() const { return independent_; }

  /// H(x) into h (size()), and the Jacobian values when `jacobian`. With
  /// skip_intermittent, contact elements are left out (values for the solver's analysis).
  void evaluate(const double* x, double t, const BdfTerms& bdf, bool jacobian, double* h,
                bool skip_intermittent = false);

  /// Contact pairs with a margin enter the matrix only while closer than their margin.
  /// Recomputes the set at q; rebuilds the pattern and returns true when it changed.
  bool update_candidates(const double* q);
  /// 0: the candidate set is fine at q; 1: a pair outside it came within half its margin
  /// (update soon); 2: a pair outside it penetrates (the state is invalid).
  int check_candidates(const double* q) const;
  /// Per force element: 1 while it is part of the Newton matrix (the candidate set).
  const std::vector<char>& candidates() const { return candidate_; }
  /// Restores a candidate set saved from candidates() (checkpoint restart); the pattern is
  /// rebuilt by the next set_partition.
  void set_candidates(const std::vector<char>& c);
  /// Number of force elements in the Newton matrix now.
  index_t active_forces() const;
  /// The Jacobian H_x (pattern fixed between set_partition calls).
  const SparseMatrix& matrix() const { return jac_; }

  /// Rows of Φ_q at (q, t) (m rows, n columns), for partitioning and initial conditions.
  SparseRows constraint_jacobian(const double* q, double t) const;
  /// Φ, Φ̇, Φ̈ at (q, v, a, t) without Jacobians (each m).
  void constraint_values(const double* q, const double* v, const double* a, double t, double* phi,
                         double* phid, double* phidd) const;
  /// Σ g(q, v, a, t) (n), and optionally the mass matrix ∂g/∂a as triplets.
  void force_values(const double* q, const double* v, const double* a, double t, double* g) const;
  /// ∂g/∂a entries (row, col, value), for the initial acceleration analysis.
  void mass_triplets(const double* q, const double* v, double t, std::vector<index_t>& rows,
                     std::vector<index_t>& cols, std::vector<double>& vals) const;
  /// Kinetic and potential energy at (q, v, t).
  void energy(const double* q, const double* v, double t, double* kinetic, double* potential) const;
  /// "joints[3] 'J4' equation 2" for constraint row r.
  std::string row_name(index_t r) const;
  /// First row of each constraint element.
  const std::vector<index_t>& constraint_rows() const { return row0_; }
  const Model& model() const { return model_; }

 private:
  void gather(const std::vector<index_t>& dofs, const double* src, std::vector<double>& dst) const;
  const Model& model_;
  index_t n_ = 0, m_ = 0;
  std::vector<index_t> row0_;  // first constraint row of each constraint element
  std::vector<index_t> independent_;
  std::vector<char> candidate_;  // per force: part of the Newton matrix
  SparseMatrix jac_;
  // value positions of element blocks
  struct ForcePos {
    std::vector<index_t> q, v, a;
  };
  struct ConstraintPos {
    std::vector<index_t> hq, fl, aa, av, aq, vv, vq, pq;
  };
  std::vector<ForcePos> fpos_;
  std::vector<ConstraintPos> cpos_;
  std::vector<index_t> upos_;  // 4 per independent coordinate
  int threads_ = 1;
};

/// A CSC matrix from triplets (duplicates summed).
SparseMatrix from_triplets(index_t n_rows, index_t n_cols, const std::vector<index_t>& rows,
                           const std::vector<index_t>& cols, const std::vector<double>& vals);

}  // namespace strata::mbd
