// strata::mbd — the residual H(x) and Jacobian H_x of one implicit BDF step.
//
// Two formulations (docs/formulation.md §4 and §5). Partitioned: unknowns
// x = [a; v; q; λ] (n, n, n, m) and the residual
//   F  = Σ g(q, v, a, t) + Φ_qᵀλ                    n   equations of motion
//   Φ̈  = Φ_q a + (Φ_q v)_q v + 2Φ_qt v + Φ_tt         m   acceleration constraints
//   Φ̇  = Φ_q v + Φ_t                                m   velocity constraints
//   Φ  = Φ(q, t)                                    m   position constraints
//   U₁ᵀ(β a − v − ζ₁)                               n−m BDF relation v ↔ a, independent coords
//   U₂ᵀ(β v − q − ζ₂)                               n−m BDF relation q ↔ v, independent coords
// with β = h/b₀ the BDF coefficient and ζ₁, ζ₂ the BDF history terms. U₁ = U₂ select the
// independent coordinates of a coordinate partitioning (partition.hpp); H_x has order
// 3n + m. Stabilized (used where no partition is well conditioned: singular
// configurations): the stabilized index-2 formulation of Gear, Gupta & Leimkuhler (1985),
// x = [a; v; q; λ; ν] (3n + 2m), BDF on every coordinate, the velocity constraints
// determining λ and the position constraints the multiplier ν that projects the BDF
// relation of q back onto them, with a small regularisation of the constraint rows:
//   F as above;  Φ̇ − ε_v(λ − λ*);  Φ − ε_p ν                 (m each)
//   β a − v − ζ₁;  β v − q − ζ₂ + β Φ_qᵀν                    (n each)
// with ε_p = ε β |∇Φ_r|², ε_v = ε β |∇Φ_r|²/m̄ per row (m̄ the mean mass of the row's
// coordinates, ε BdfTerms::regularization: the sizes of the Schur complements these
// rows see) and λ* the multipliers of the previous step. No acceleration constraint is
// imposed: near a singular configuration Φ̈ = 0 amplifies velocity errors by the inverse
// of the vanishing singular value of Φ_q.
// Constraint equations may be switched off (redundant equations removed for the run): m
// counts the active ones. The pattern is built once per formulation, partition and
// active set; every evaluation only rewrites the values (element blocks are scattered
// through precomputed positions).
//
// The evaluation is deterministic on any number of threads. Elements are evaluated in
// parallel, each writing its contributions to entries that other elements share (the
// equations of motion's residual and their rows of H_x) to its own slots; a second
// parallel pass sums each shared entry's slots in element order (forces, then
// constraints), so H(x) and H_x are bitwise the same for 1 or 64 threads and a restarted
// run repeats the first one. Entries only one element writes (its constraint rows and
// multiplier columns) are written directly.
#pragma once

#include <tbb/task_arena.h>

#include <cstdint>
#include <memory>
#include <vector>

#include "mbd/condensed_solver.hpp"
#include "mbd/model.hpp"
#include "mbd/partition.hpp"
#include "mbd/pattern_builder.hpp"
#include "strata/sparse_matrix.hpp"

namespace strata::mbd {

/// The BDF relation of the current step: β = h/b₀ and the history terms ζ₁, ζ₂ (n each);
/// for the stabilized formulation also the regularisation ε (dimensionless, see the file
/// comment) and λ* (m, the previous step's multipliers; null: zero).
struct BdfTerms {
  double beta = 1;
  const double* zeta1 = nullptr;
  const double* zeta2 = nullptr;
  double regularization = 0;
  const double* lambda_prev = nullptr;
};

/// How the BDF step is made square (see the file comment).
enum class Formulation { partitioned, stabilized };

class NewtonSystem {
 public:
  explicit NewtonSystem(const Model& model);
  index_t n() const { return n_; }
  /// Active constraint equations.
  index_t m() const { return m_; }
  /// All constraint equations of the model (active or not).
  index_t model_m() const { return static_cast<index_t>(active_.size()); }
  /// 3n + m (partitioned) or 3n + 2m (stabilized).
  index_t size() const { return 3 * n_ + (formulation_ == Formulation::stabilized ? 2 : 1) * m_; }
  Formulation formulation() const { return formulation_; }
  /// Switches the formulation and rebuilds the pattern.
  void set_formulation(Formulation f);
  /// Per model constraint row (model_m()): 1 active, 0 removed (a redundant equation).
  /// Rebuilds the pattern; the partition must then be set again (m changed).
  void set_active_rows(const std::vector<char>& active);
  const std::vector<char>& active_rows() const { return active_; }
  /// Model row of active row r, and the active index of model row k (−1: removed).
  index_t model_row(index_t r) const { return model_row_[r]; }
  index_t active_index(index_t k) const { return active_index_[k]; }
  /// Threads for the assembly (oneTBB); default 1.
  void set_threads(int threads);
  /// The assembly's threads (null: the calling thread alone), for work of the same run
  /// outside the Newton matrix (the initial conditions' matrices).
  tbb::task_arena* arena() const { return arena_.get(); }

  /// Uses the partition's independent coordinates for U₁ = U₂ and rebuilds the pattern;
  /// returns false (and keeps the pattern) when they are those of the current pattern.
  bool set_partition(const Partition& p);
  /// Rebuilds the pattern (after a change of the partition or the candidate set).
  void rebuild_pattern();
  const std::vector<index_t>& independent() const { return independent_; }
  /// The BDF relations as eliminations of matrix() (condensed_solver.hpp), in the order
  /// they are made: partitioned, each independent coordinate's q_j by its relation
  /// β v_j − q_j, then its v_j by β a_j − v_j; stabilized, every v_j by β a_j − v_j (the
  /// relation of q also holds β Φ_qᵀν). Follows the formulation, partition and active set.
  std::vector<RowElimination> bdf_eliminations() const;

  /// H(x) into h (size()), and the Jacobian values when `jacobian`. With
  /// skip_intermittent, contact elements are left out (values for the solver's analysis).
  void evaluate(const double* x, double t, const BdfTerms& bdf, bool jacobian, double* h,
                bool skip_intermittent = false);

  /// Contact pairs with a margin enter the matrix only while closer than their margin.
  /// Recomputes the set at q. A pair that leaves keeps its entries in the pattern (values
  /// zero), so the pattern only grows until prune_pattern(): returns 0 when the set did
  /// not change, 1 when it changed within the pattern, 2 when a pair new to the pattern
  /// entered (the pattern was rebuilt, containing the one before).
  int update_candidates(const double* q);
  /// Drops from the pattern the pairs no longer in the candidate set; rebuilds the
  /// pattern and returns true when there were any.
  bool prune_pattern();
  /// 0: the candidate set is fine at q; 1: a pair outside it came within half its margin
  /// (update soon); 2: a pair outside it penetrates (the state is invalid).
  int check_candidates(const double* q) const;
  /// Per force element: 1 while it is part of the Newton matrix (the candidate set).
  const std::vector<char>& candidates() const { return candidate_; }
  /// Restores a candidate set saved from candidates() (checkpoint restart); the pattern is
  /// rebuilt by the next set_partition.
  void set_candidates(const std::vector<char>& c);
  /// Per force element: 1 while its entries are in the pattern (the candidates, and the
  /// pairs that left since the last prune_pattern()).
  const std::vector<char>& pattern_forces() const { return in_pattern_; }
  /// Restores a set saved from pattern_forces() (checkpoint restart); the pattern is
  /// rebuilt by the next set_partition or rebuild_pattern. It must contain the candidates
  /// before the next evaluate.
  void set_pattern_forces(const std::vector<char>& p);
  /// Number of force elements in the Newton matrix now.
  index_t active_forces() const;
  /// The Jacobian H_x (pattern fixed between set_partition calls).
  const SparseMatrix& matrix() const { return jac_; }
  /// Changes whenever matrix()'s pattern is rebuilt or dropped (never repeats in a run).
  std::uint64_t pattern_id() const { return pattern_id_; }

  /// Rows of Φ_q at (q, t) (m rows, n columns), for partitioning and initial conditions.
  SparseRows constraint_jacobian(const double* q, double t) const;
  /// Φ_q at (q, t) into `rows` with the elements' whole pattern: every coordinate of each
  /// active row, exact zeros kept, so that the pattern depends on the active rows alone
  /// (a PartitionMonitor built on it stays valid while they do). The elements are
  /// evaluated on the assembly's threads; `rows` keeps its storage between calls.
  void constraint_jacobian_full(const double* q, double t, SparseRows& rows) const;
  /// Φ, Φ̇, Φ̈ at (q, v, a, t) without Jacobians (each m, active rows).
  void constraint_values(const double* q, const double* v, const double* a, double t, double* phi,
                         double* phid, double* phidd) const;
  /// Φ, Φ̇ of every model row, active or not (each model_m()); v may be null (zero).
  void model_constraint_values(const double* q, const double* v, double t, double* phi,
                               double* phid) const;
  /// Rows of Φ_q of every model row (model_m() rows), for the redundancy analysis.
  SparseRows model_constraint_jacobian(const double* q, double t) const;
  /// Σ g(q, v, a, t) (n), and optionally the mass matrix ∂g/∂a as triplets.
  void force_values(const double* q, const double* v, const double* a, double t, double* g) const;
  /// ∂g/∂a entries (row, col, value) within each element's Force::mass_structure, appended,
  /// for the initial acceleration analysis.
  void mass_triplets(const double* q, const double* v, double t, std::vector<index_t>& rows,
                     std::vector<index_t>& cols, std::vector<double>& vals) const;
  /// Kinetic and potential energy at (q, v, t).
  void energy(const double* q, const double* v, double t, double* kinetic, double* potential) const;
  /// "joints[3] 'J4' equation 2" for active constraint row r.
  std::string row_name(index_t r) const { return model_row_name(model_row_[r]); }
  /// The same for model row k.
  std::string model_row_name(index_t k) const;
  /// First row of each constraint element.
  const std::vector<index_t>& constraint_rows() const { return row0_; }
  const Model& model() const { return model_; }

 private:
  void gather(const std::vector<index_t>& dofs, const double* src, std::vector<double>& dst) const;
  void add_bdf_rows(const double* a, const double* v, const double* q, const BdfTerms& bdf,
                    bool jacobian, double* hu);
  const Model& model_;
  index_t n_ = 0, m_ = 0;
  Formulation formulation_ = Formulation::partitioned;
  std::vector<index_t> row0_;  // first model row of each constraint element
  std::vector<char> active_;   // per model row
  std::vector<index_t> model_row_, active_index_;
  std::vector<double> mass_scale_;  // per constraint element: mean mass of its coordinates
  std::vector<index_t> independent_;
  // per coordinate: the first coordinate of its flexible-body node (a node's coordinates
  // are consecutive), −1 for the coordinates of other bodies (rebuild_pattern)
  std::vector<index_t> node_first_;
  std::vector<char> candidate_;   // per force: evaluated into the Newton matrix
  std::vector<char> in_pattern_;  // per force: entries in the pattern (⊇ candidate_)
  bool pattern_current_ = false;  // jac_ is the pattern of the state above
  void compute_mass_scale();
  SparseMatrix jac_;
  // value positions of element blocks
  struct ForcePos {
    std::vector<index_t> q, v, a;
  };
  // positions of the active rows only, in the order (row, dof) / (dof, row)
  struct ConstraintPos {
    std::vector<index_t> hq, fl, aa, av, aq, vv, vq, pq, nu, nuq, reg;
  };
  std::vector<ForcePos> fpos_;
  std::vector<ConstraintPos> cpos_;
  void write_constraint_jacobian(const ConstraintPos& cp, std::size_t nz,
                                 const std::vector<index_t>& act, const ConstraintEval& ce,
                                 const std::vector<double>& eps_a, const std::vector<double>& eps_p,
                                 double beta, double* J) const;
  // The shared entries' summation (see the file comment): each target (an index of H or
  // of H_x's values) and its slots, in element order (CSR: slot[first[t] .. first[t+1])).
  using SlotSums = TargetGroups;
  // first residual / Jacobian slot of each force element (nf + 1) and constraint element
  // (nc + 1; constraints' slots follow the forces')
  std::vector<std::size_t> force_rslot_, constraint_rslot_, force_jslot_, constraint_jslot_;
  FillLater<double> rslots_, jslots_;
  SlotSums rsums_, jsums_;
  void build_slot_sums();
  void add_slot_sums(const SlotSums& sums, const double* slots, double* out) const;
  std::vector<index_t> upos_;  // 4 per BDF coordinate (independent, or all when stabilized)
  int threads_ = 1;
  std::uint64_t pattern_id_ = 0;
  // the assembly's threads, kept: one arena for every evaluation
  std::unique_ptr<tbb::task_arena> arena_;
  // f(begin, end) over element ranges of [0, n), on the assembly's threads
  template <class F>
  void for_element_ranges(std::size_t n, F&& f) const;
  // f() on the assembly's threads (their arena), or inside a SerialScope without one
  template <class F>
  void in_arena(F&& f) const;
  // Each constraint element's Φ, Φ̇, Φ̈ at (q, v, a, t) without Jacobians (v, a null: zero),
  // on the assembly's threads; put(e, eval) writes element e's rows (its own only).
  template <class Put>
  void each_constraint_value(const double* q, const double* v, const double* a, double t,
                             Put&& put) const;
};

}  // namespace strata::mbd
