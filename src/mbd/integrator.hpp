// strata::mbd — implicit BDF integration of the index-3 equations of motion with
// coordinate partitioning (docs/formulation.md).
//
// Per step: BDF coefficients of order k on the actual (possibly non-uniform) time
// points (Brenan, Campbell & Petzold, "Numerical Solution of Initial-Value Problems in
// DAEs", 1996, §3.2: fixed-leading-coefficient-free, variable-coefficient form); a
// predictor by polynomial extrapolation; Newton's method on H(x) = 0 (newton_system.hpp)
// whose every iteration is a sparse solve by strata (analysis once per pattern, then
// refactorizations; modified Newton keeps the factor while it converges fast). Before
// the first step, consistent initial conditions: position analysis (Φ = 0 with the
// independent coordinates held), velocity analysis, acceleration analysis (Haug 1989,
// §6.5 and §11.5). A step whose Newton iteration fails is retried with half the step;
// below the minimum step the integration stops with a SimulationError.
#pragma once

#include <deque>
#include <memory>
#include <string>
#include <vector>

#include "mbd/linear_solver.hpp"
#include "mbd/model.hpp"
#include "mbd/newton_system.hpp"
#include "strata/errors.hpp"
#include "strata/options.hpp"

namespace strata::mbd {

/// The integration cannot continue (Newton failure at the minimum step, inconsistent
/// initial conditions). what() says why, at which time.
class SimulationError : public Error {
 public:
  using Error::Error;
};

struct IntegratorOptions {
  double t_end = 1.0;           ///< s
  double step = 1e-3;           ///< nominal step h (s)
  int order = 2;                ///< BDF order k, 1..5
  bool modified_newton = true;  ///< keep the factor while Newton converges fast
  int max_newton_iterations = 25;
  double newton_rtol = 1e-6;             ///< relative tolerance of the Newton update
  double newton_atol = 1e-8;             ///< absolute tolerance (q, v; a: times b0/h)
  double partition_threshold = 0.25;     ///< relative pivot threshold of the partitioning
  double repartition_quality = 0.05;     ///< repartition when the partition's quality drops
  int partition_check_interval = 10;     ///< steps between partition quality checks
  int startup_levels = -1;               ///< startup: first step h/2^levels (−1: automatic)
  double min_step = 0;                   ///< smallest step before giving up (0: step·1e-6)
  Backend backend = Backend::automatic;  ///< strata backend
  std::size_t device_memory_limit = 0;   ///< GPU budget in bytes (0: the whole device)
  int threads = 0;  ///< CPU threads for strata and the assembly (0: automatic — all, but one
                    ///< for strata below 20000 unknowns)
  bool dense_solver = false;  ///< LAPACK instead of strata (tests only)
  index_t dump_step = -1;     ///< write the Newton Jacobian of this step (1-based)
  std::string dump_dir;       ///< ... into this folder (Matrix Market)
  bool verbose = false;
  /// Variable step size and order with local error control: the local error of q and v
  /// is estimated from the difference between the converged solution and the predictor
  /// (Milne's device) and kept below rtol/atol; the order (1..`order`) is chosen from
  /// divided-difference error estimates of the neighbouring orders.
  bool variable_step = false;
  double rtol = 1e-4, atol = 1e-6;  ///< local error tolerances of variable steps
  double max_step = 0;  ///< largest variable step (0: (t_end − 0)/10)       ///< print every Newton
                        ///< iteration to stderr
};

/// What happened in one accepted step.
struct StepInfo {
  index_t step = 0;
  double t = 0, h = 0;
  int order = 0;
  int newton_iterations = 0;
  int factorizations = 0;
  int rejected = 0;             ///< attempts with a smaller step before this one succeeded
  double assembly_seconds = 0;  ///< residual and Jacobian evaluation
  double solver_seconds = 0;    ///< strata analysis + factorization + solves
  bool repartitioned = false;
  double error_estimate = 0;  ///< weighted local error estimate (variable step; ≤ 1)
};

struct IntegratorStats {
  index_t steps = 0, rejected = 0, newton_iterations = 0, factorizations = 0, analyses = 0,
          repartitions = 0, solves = 0;
  index_t reanalyses = 0;        ///< analyses redone because pivots had to be perturbed
  index_t contact_updates = 0;   ///< changes of the set of contact pairs in the matrix
  index_t error_rejections = 0;  ///< variable step: steps rejected by the local error test
  index_t perturbed_pivots = 0;  ///< static pivots over all factorizations
  double factor_seconds = 0, solve_seconds = 0;  ///< parts of solver_seconds
  double assembly_seconds = 0, solver_seconds = 0, analysis_seconds = 0, partition_seconds = 0,
         initial_conditions_seconds = 0;
  index_t jacobian_size = 0, jacobian_nnz = 0, factor_nnz = 0;
  std::string solver;
};

class Integrator {
 public:
  /// The model must outlive the integrator.
  Integrator(const Model& model, IntegratorOptions options);
  /// Consistent initial conditions at t = 0. Throws SimulationError, RedundantConstraints.
  void initialize();
  /// Advances one step. Throws SimulationError when even the minimum step fails.
  StepInfo advance();
  bool done() const;

  double t() const { return t_; }
  const std::vector<double>& q() const { return q_; }
  const std::vector<double>& v() const { return v_; }
  const std::vector<double>& a() const { return a_; }
  const std::vector<double>& lambda() const { return lambda_; }
  /// max |Φ| and max |Φ̇| at the current state.
  void constraint_violation(double* position, double* velocity) const;
  const IntegratorStats& stats() const { return stats_; }
  NewtonSystem& system() { return sys_; }
  const IntegratorOptions& options() const { return opts_; }

 private:
  struct Point {
    double t;
    std::vector<double> q, v, a;
  };
  std::unique_ptr<LinearSolver> new_solver() const;
  void repartition(double t, const double* q);
  bool try_step(double h, StepInfo& info);
  void analyze(const BdfTerms& bdf, double t);
  void factorize(StepInfo& info, const BdfTerms& bdf, double t);
  void choose_order(double h, int p, double tn, const double* xq, const double* xv, double est);

  const Model& model_;
  IntegratorOptions opts_;
  NewtonSystem sys_;
  std::unique_ptr<LinearSolver> solver_;
  Partition partition_;
  bool pattern_changed_ = true, factor_valid_ = false, fresh_analysis_ = false, retry_ = false;
  double lte_reject_h_ = 0;  // > 0: the step was rejected by the error test; retry with this
  double next_h_ = 0;        // step proposed by the error control
  int order_ = 1;            // current BDF order (variable-step mode selects it)
  int steps_at_order_ = 0;
  double factor_beta_ = 0;
  bool slow_last_step_ = false;
  double t_ = 0, h_ = 0;
  std::vector<double> q_, v_, a_, lambda_;
  std::deque<Point> history_;
  IntegratorStats stats_;
  std::vector<double> x_, res_, dx_, rhs_, zeta1_, zeta2_, qpred_, vpred_;
  index_t step_ = 0;
};

/// BDF coefficients α_0..α_p with ẏ(t₀) ≈ Σ α_j y(t_j), from the derivative of the
/// interpolating polynomial through the points times[0..p] (times[0] the new time).
std::vector<double> bdf_coefficients(const std::vector<double>& times);

}  // namespace strata::mbd
