// strata::mbd — implicit BDF integration of the index-3 equations of motion with
// coordinate partitioning, or the stabilized formulation where no partition is well
// conditioned (docs/formulation.md).
//
// Per step: BDF coefficients of order k on the actual (possibly non-uniform) time
// points (Brenan, Campbell & Petzold, "Numerical Solution of Initial-Value Problems in
// DAEs", 1996, §3.2: fixed-leading-coefficient-free, variable-coefficient form); a
// predictor by polynomial extrapolation; Newton's method on H(x) = 0 (newton_system.hpp)
// whose every iteration is a sparse solve by strata (analysis once per pattern, then
// refactorizations; modified Newton keeps the factor while it converges fast). Before
// the first step, consistent initial conditions: position analysis (Φ = 0 with the
// independent coordinates held), velocity analysis, acceleration analysis (Haug 1989,
// §6.5 and §11.5). Redundant constraint equations are found by a rank-revealing QR of
// Φ_qᵀ (SuiteSparseQR) and switched off for the run. A step is accepted only when Newton
// converged and the constraints hold to tolerance at the position and velocity level; a
// step whose Newton iteration fails is retried with half the step; below the minimum step
// the integration stops with a SimulationError. The energy of conservative models is
// monitored (a warning for fixed steps, a rejected step for variable steps).
#pragma once

#include <deque>
#include <functional>
#include <limits>
#include <memory>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "mbd/anderson.hpp"
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

/// Which formulation makes the BDF step square (docs/formulation.md §4–§5). automatic:
/// partitioned while the coordinate partition is well conditioned, stabilized from the
/// first step where it is not (a singular configuration, or a partition that would have to
/// change) to the end of the run.
enum class FormulationChoice { automatic, partitioned, stabilized };

struct IntegratorOptions {
  double t_end = 1.0;           ///< s
  double step = 1e-3;           ///< nominal step h (s)
  int order = 2;                ///< BDF order k, 1..5
  bool modified_newton = true;  ///< keep the factor while Newton converges fast
  /// Anderson acceleration of the iterations that reuse a factor: the number of past
  /// updates combined (anderson.hpp; 0: plain modified Newton).
  int anderson_depth = 3;
  int max_newton_iterations = 25;
  double newton_rtol = 1e-6;          ///< relative tolerance of the Newton update
  double newton_atol = 1e-8;          ///< absolute tolerance (q, v; a: times b0/h)
  double partition_threshold = 0.25;  ///< relative pivot threshold of the partitioning
  double repartition_quality = 0.05;  ///< repartition when the partition's quality drops
  int partition_check_interval = 10;  ///< steps between partition quality checks
  int startup_levels = -1;            ///< startup: first step h/2^levels (−1: automatic)
  double min_step = 0;                ///< smallest step before giving up (0: step·1e-6)
  /// strata's options for the Newton matrices (make_strata_solver): every field settable
  /// (set_option); num_threads also sets the assembly's threads (0: one for a small model,
  /// else all).
  Options solver = engine_solver_options();
  bool dense_solver = false;  ///< LAPACK instead of strata (tests only)
  /// Eliminate the BDF relations' rows from the Newton matrix before the sparse solve
  /// where they are a third of its rows or more (condensed_solver.hpp, worth_condensing;
  /// docs/formulation.md §5); false: the solver factors the full matrix.
  bool condensation = true;
  /// A fresh analysis of the Newton matrix at every step attempt, with the current
  /// values (tests: the reference for the loop that reuses one analysis per pattern).
  bool analyze_every_step = false;
  /// When contact pairs new to the pattern make the kept order's factor more than a
  /// quarter larger than the last analysis's: false (default) analyzes afresh at the next
  /// Newton iteration, with a new matching from the values then; true drops the pairs that
  /// left and orders the pattern anew keeping the analysis's matching and scaling
  /// (Solver::analyze_keeping_matching; afresh where the pattern lost a matched entry),
  /// which costs less per analysis but leaves the later factorizations the older matching
  /// (more delayed pivots where the values have drifted from those it was made for).
  bool reorder_keeping_matching = false;
  index_t dump_step = -1;  ///< write the Newton Jacobian of this step (1-based)
  std::string dump_dir;    ///< ... into this folder (Matrix Market): jacobian_stepK.mtx and
                           ///< rhs_stepK.mtx, and, when the engine condenses it by the BDF
                           ///< relations (condensed_solver.hpp), the system the sparse
                           ///< solver factors: jacobian_condensed_stepK.mtx,
                           ///< rhs_condensed_stepK.mtx
  bool verbose = false;
  /// Variable step size and order with local error control: the local error of q and v
  /// is estimated from the difference between the converged solution and the predictor
  /// (Milne's device) and kept below rtol/atol; the order (1..`order`) is chosen from
  /// divided-difference error estimates of the neighbouring orders.
  bool variable_step = false;
  double rtol = 1e-4, atol = 1e-6;  ///< local error tolerances of variable steps
  double max_step = 0;              ///< largest variable step (0: (t_end − 0)/10)
  FormulationChoice formulation = FormulationChoice::automatic;
  /// ε of the stabilized formulation's regularisation (newton_system.hpp): constraint
  /// directions whose singular value is below about √ε of the typical one are enforced
  /// softly within a step (singular configurations).
  double regularization = 1e-8;
  /// Conservative models: largest energy drift, relative to the largest kinetic energy
  /// seen (0: not monitored). Fixed step: a warning at the end; variable step: a step whose
  /// energy change exceeds energy_tolerance · E_ref · h / t_end is redone with a smaller one.
  double energy_tolerance = 1e-3;
  /// A constraint equation is redundant when its column of Φ_qᵀ is, relative to the largest
  /// column norm, within this of the span of the earlier ones (rank-revealing QR).
  double redundancy_tolerance = 1e-9;
  /// Tests only: called with the converged q and v (n each) of every step attempt, before
  /// the acceptance checks (a test perturbs them to check that no step off the constraints
  /// is accepted). Not saved in checkpoints.
  std::function<void(double* q, double* v)> perturb_converged;
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
  bool stabilized = false;    ///< taken with the stabilized formulation
};

struct IntegratorStats {
  index_t steps = 0, rejected = 0, newton_iterations = 0, factorizations = 0, analyses = 0,
          repartitions = 0, solves = 0;
  index_t reanalyses = 0;       ///< analyses redone because pivots had to be perturbed
  index_t contact_updates = 0;  ///< changes of the set of contact pairs in the matrix
  /// Analyses that kept the ordering of the analysis before (Solver::analyze_keeping_order)
  /// because a contact pair new to the pattern entered: not counted in `analyses`.
  index_t kept_order_analyses = 0;
  /// Analyses (counted in `analyses`) made because the kept order's factor would have grown
  /// past 1.25 times the entries of the last analysis's.
  index_t contact_analyses = 0;
  /// Of those, the analyses that kept the matching and scaling of the analysis before and
  /// ordered the pattern anew (Solver::analyze_keeping_matching).
  index_t matching_kept_analyses = 0;
  index_t error_rejections = 0;  ///< variable step: steps rejected by the local error test
  index_t perturbed_pivots = 0;  ///< static pivots over all factorizations
  /// Factorizations with delayed pivoting (strata's Options::pivoting) and the pivots they
  /// passed from fronts to their parents (FactorStats::delayed_pivots, summed).
  index_t delayed_factorizations = 0, delayed_pivots = 0;
  /// Factorizations whose static pivots were corrected in the solve (Pivoting::corrected,
  /// when the run asks for it) and those pivots (FactorStats::corrected_pivots, summed).
  index_t corrected_factorizations = 0, corrected_pivots = 0;
  index_t residual_rejections = 0;  ///< steps redone: constraints violated after convergence
  index_t energy_rejections = 0;    ///< variable step: steps redone for their energy change
  index_t stabilized_steps = 0;     ///< steps taken with the stabilized formulation
  double stabilized_since = -1;     ///< time the stabilized formulation began (−1: never)
  index_t redundancy_checks = 0;    ///< rank-revealing factorizations of Φ_qᵀ
  index_t restarts = 0;     ///< variable step: BDF history restarted after a jump of the solution
  double energy_drift = 0;  ///< conservative models: max |E − E(0)| so far (J)
  double energy_scale = 0;  ///< largest kinetic energy so far (J), the drift's reference
  double factor_seconds = 0, solve_seconds = 0;  ///< parts of solver_seconds
  /// The solves whose triangular solves ran on a GPU (SolveStats::on_device) and their
  /// seconds (part of solve_seconds); the others ran on the host (a host factor, or one
  /// with delayed pivots).
  index_t device_solves = 0;
  double device_solve_seconds = 0;
  /// Host seconds of the condensation by the BDF relations (condensed_solver.hpp): the
  /// reduced matrix's values at each factorization, the reduced right-hand side and the
  /// expanded solution at each solve (part of factor_seconds and solve_seconds; 0 when
  /// the matrix is not condensed).
  double condensation_seconds = 0;
  /// strata's own split of its factorizations (FactorStats, summed): value input (checks,
  /// norms, scaling, the copy to a GPU) and the GPU's time; the factorizations whose values
  /// were scaled on the GPU (FactorStats::values_scaled_on_device) and those whose values
  /// were equilibrated again, far from the analysis's (rescaling_sweeps > 0; on the GPU
  /// too when their values were scaled there).
  double factor_input_seconds = 0, factor_device_seconds = 0;
  index_t values_on_device_factorizations = 0, rescaled_factorizations = 0;
  /// partition_seconds: coordinate partitionings and the partition and redundancy checks,
  /// those of initialize() included (they are also part of initial_conditions_seconds,
  /// which times all of initialize()).
  double assembly_seconds = 0, solver_seconds = 0, analysis_seconds = 0, partition_seconds = 0,
         initial_conditions_seconds = 0;
  index_t jacobian_size = 0, jacobian_nnz = 0, factor_nnz = 0;
  std::string solver;
};

class Integrator {
 public:
  /// The model must outlive the integrator.
  Integrator(const Model& model, IntegratorOptions options);
  /// Consistent initial conditions at t = 0: redundant constraint equations switched off
  /// (a consistent redundant set), then position, velocity and acceleration analyses.
  /// Throws SimulationError, RedundantConstraints (an inconsistent set: no motion satisfies
  /// it; the message names the equations).
  void initialize();
  /// Advances one step. Throws SimulationError when even the minimum step fails.
  StepInfo advance();
  /// Everything the integrator needs to continue exactly as if it had not stopped, between
  /// two steps (checkpoint/restart): time, step size, order and step-size controller state,
  /// q, v, a, λ, the BDF history, the coordinate partition, the contact candidate set, the
  /// Newton flags, the statistics, and the values of the Jacobians the solver's analysis
  /// (matching, scaling) and its current factor were computed from — modified Newton may
  /// reuse that factor in the next step, so a restart rebuilds it bitwise. Doubles are kept
  /// as doubles (nlohmann::json stores them exactly in CBOR).
  nlohmann::json save_state() const;
  /// Instead of initialize(): restores a save_state() of an integrator of the same model
  /// and options. Throws InvalidInput when the state does not fit the model.
  void restore_state(const nlohmann::json& state);
  bool done() const;

  double t() const { return t_; }
  const std::vector<double>& q() const { return q_; }
  const std::vector<double>& v() const { return v_; }
  const std::vector<double>& a() const { return a_; }
  /// Multipliers of the active constraint equations (system().m()).
  const std::vector<double>& lambda() const { return lambda_; }
  /// Multipliers of every model constraint row (model_m(); 0 for removed equations).
  std::vector<double> model_lambda() const;
  /// max |Φ| and max |Φ̇| at the current state (every model row, removed ones included).
  void constraint_violation(double* position, double* velocity) const;
  /// Dense output: the state at a time t of the last step, [t − h, t], from the BDF
  /// interpolation polynomial through the last k+1 points (k the step's order), each of
  /// q, v, a (n) interpolated on its own values; λ (model_m()) linearly between the last
  /// two steps. Any argument may be null.
  void interpolate(double t, double* q, double* v, double* a, double* lambda) const;
  /// Names of the redundant constraint equations switched off ("joints[5] 'P5' equation 4").
  std::vector<std::string> removed_equations() const;
  /// Conditions the user should know about (energy drift beyond energy_tolerance, ...).
  std::vector<std::string> warnings() const;
  /// Whether the model is conservative (energy monitored).
  bool conservative() const { return conservative_; }
  Formulation formulation() const { return sys_.formulation(); }
  const IntegratorStats& stats() const { return stats_; }
  NewtonSystem& system() { return sys_; }
  const IntegratorOptions& options() const { return opts_; }

 private:
  struct Point {
    double t;
    std::vector<double> q, v, a;
  };
  std::unique_ptr<LinearSolver> new_solver() const;
  std::vector<RowElimination> condensation() const;
  void repartition(double t, const double* q);
  void use_stabilized(const char* why);
  void find_redundant(const double* q, double t, bool initial);
  void check_removed(const double* q, const double* v, double t, bool initial);
  void partition_check(StepInfo& info);
  double current_partition_quality();
  const SparseRows& constraint_jacobian_at(const double* q, double t);
  void initial_positions();
  void report_initial_change(const std::vector<double>& given, const std::vector<double>& now,
                             const char* what, const char* unit);
  std::vector<double> solve_partitioned(const SparseRows& rows, const std::vector<double>& b,
                                        const char* what) const;
  Options set_up_options(index_t rows) const;
  void report_set_up_solve(const char* what, const char* method, const SparseMatrix& k,
                           const LinearSolver& s, double analysis, double factorization,
                           double solve) const;
  std::vector<double> solve_once(const SparseMatrix& k, const std::vector<double>& b,
                                 const char* what) const;
  std::vector<double> solve_symmetric_once(const SparseMatrix& k, const std::vector<double>& b,
                                           const char* what) const;
  bool try_step(double h, StepInfo& info);
  void predict(double h, BdfTerms& bdf);
  int newton(double h, StepInfo& info, const BdfTerms& bdf);
  bool constraints_hold(const double* q, const double* v, double t);
  void newton_tolerances(double* atol, double* rtol) const;
  bool energy_ok(double h, int p, const double* q, const double* v, double t);
  // The Newton matrix and the residual evaluated at x_ (sys_.matrix(), res_), then analyzed.
  void analyze(const BdfTerms& bdf, double t);
  void contacts_changed(int change, StepInfo* info);
  void factorize(StepInfo& info, const BdfTerms& bdf, double t);
  /// kept = the Newton matrix's values (for a checkpoint), copied over the assembly's
  /// threads: 1–2 GB for models of 10⁶ coordinates.
  void keep_values(std::vector<double>& kept) const;
  void choose_order(double h, int p, double tn, const double* xq, const double* xv, double est);

  const Model& model_;
  IntegratorOptions opts_;
  NewtonSystem sys_;
  AndersonMixing anderson_;
  std::vector<double> weights_;  // of the Newton update's error norm
  std::unique_ptr<LinearSolver> solver_;
  Partition partition_;
  // the partition check's Φ_q (whole element pattern) and its elimination structure
  SparseRows monitor_rows_;
  PartitionMonitor monitor_;
  // the point monitor_rows_ was evaluated at (constraint_jacobian_at)
  double jacobian_t_ = std::numeric_limits<double>::quiet_NaN();
  std::vector<double> jacobian_q_;
  std::vector<char> jacobian_active_;
  bool pattern_changed_ = true, factor_valid_ = false, fresh_analysis_ = false, retry_ = false;
  double lte_reject_h_ = 0;  // > 0: the step was rejected by the error test; retry with this
  double next_h_ = 0;        // step proposed by the error control
  int order_ = 1;            // current BDF order (variable-step mode selects it)
  int steps_at_order_ = 0;
  double factor_beta_ = 0;
  bool slow_last_step_ = false;
  // check_candidates at the converged iterate of the last try_step, which becomes q_ when
  // the step is accepted (-1: not known, e.g. the iterate was changed after the check)
  int converged_candidates_ = -1;
  double t_ = 0, h_ = 0;
  std::vector<double> q_, v_, a_, lambda_, lambda_prev_;
  std::deque<Point> history_;
  int last_order_ = 1;          // order of the last accepted step (dense output)
  bool ramp_repeat_ = false;    // fixed step, orders 1–2: the second step repeats the first
  bool energy_reject_ = false;  // the last rejection was for the energy change
  bool accept_jump_ = false;    // take the step despite the error test, then restart
  double reject_measure_ = 0;   // error estimate (or energy change / budget) of a rejection
  bool conservative_ = false;
  std::vector<std::string> initial_warnings_;  // changes made by the initial analyses
  double energy0_ = 0, energy_last_ = 0;
  IntegratorStats stats_;
  std::vector<double> x_, res_, dx_, rhs_, zeta1_, zeta2_, qpred_, vpred_, lambda_step_;
  index_t step_ = 0;
  // Jacobian values the solver's analysis and its current factor come from (restart)
  std::vector<double> analysis_values_, factor_values_;
  // where the last analysis's matching started: the analysis before it (restart)
  MatchingStart analysis_start_;
  // the force elements in the pattern at the last analysis (restart), and its factor's size
  std::vector<char> analysis_forces_;
  index_t analysis_factor_entries_ = 0;
  // the force elements in the pattern of the last analysis with a new order and the
  // matching of analysis_forces_'s kept (contacts_changed; restart), empty when none since
  std::vector<char> reorder_forces_;
  // NewtonSystem::pattern_id() of the pattern the solver last analyzed (0: none yet)
  std::uint64_t analyzed_pattern_ = 0;
};

/// BDF coefficients α_0..α_p with ẏ(t₀) ≈ Σ α_j y(t_j), from the derivative of the
/// interpolating polynomial through the points times[0..p] (times[0] the new time).
std::vector<double> bdf_coefficients(const std::vector<double>& times);

/// The nodes of a BDF step to tn for bdf_coefficients, relative to tn: tn and the past
/// times `past` (newest first), each gap between consecutive ones that is within the
/// rounding of the times themselves (8u of their magnitudes) of the step `h` [s] taken as
/// h exactly. Equal steps then give bit for bit the same coefficients at every step,
/// where the differences of times accumulated in floating point would move them by about
/// u·t/h.
std::vector<double> bdf_nodes(double tn, const std::vector<double>& past, double h);

}  // namespace strata::mbd
