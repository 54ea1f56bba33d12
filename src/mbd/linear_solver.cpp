// strata::mbd — adapters from the LinearSolver interface to strata::Solver and LAPACK.
#include "mbd/linear_solver.hpp"

#include <vector>

#include "base/device.hpp"
#include "strata/errors.hpp"
#include "strata/solver.hpp"

extern "C" {
void dgetrf_(const int* m, const int* n, double* a, const int* lda, int* ipiv, int* info);
void dgetrs_(const char* trans, const int* n, const int* nrhs, const double* a, const int* lda,
             const int* ipiv, double* b, const int* ldb, int* info);
}

namespace strata::mbd {
namespace {

class StrataLinearSolver : public LinearSolver {
 public:
  StrataLinearSolver(const Options& o, MatrixType type)
      : solver_(options(o, type)),
        adaptive_(type == MatrixType::general && o.pivoting == Pivoting::automatic &&
                  solver_on_gpu(o.backend)) {}
  static Options options(Options o, MatrixType type) {
    if (o.type != MatrixType::automatic && o.type != type)
      throw InvalidInput(std::string(type == MatrixType::general
                                         ? "the Newton matrix is unsymmetric: the solver's type "
                                           "must be general, got "
                                         : "this solver is for symmetric matrices: its type must "
                                           "be symmetric_indefinite, got ") +
                         to_string(o.type));
    validate(o);
    o.type = type;
    if (type != MatrixType::general) return o;
    // The Newton matrix's values drift from those the analysis matched and scaled (step
    // size, contacts, rotations): on the host every factorization delays the pivots the
    // analysis's order cannot take (numeric/delayed.hpp). A GPU factors in that order
    // (Pivoting::automatic); the first factorization that needs static pivots delays them
    // on the host, and so do the later factorizations of the same analysis, directly
    // (delaying_: their values keep drifting the same way), as does an analysis that
    // Backend::automatic put on the host. So no pivot is perturbed and no new analysis is
    // needed for them. Pivoting::corrected (the static pivots corrected in the GPU's
    // solves) is the run's choice only: its checked and refined solves cost more than the
    // delayed factorization saves on the engine's matrices (bench/history.md).
    if (o.pivoting == Pivoting::automatic && !solver_on_gpu(o.backend))
      o.pivoting = Pivoting::delayed;
    return o;
  }
  void analyze(const SparseMatrix& a) override { analyze_from(a, MatchingStart{}); }
  void analyze_from(const SparseMatrix& a, const MatchingStart& start) override {
    solver_.analyze(a, start);
    // Backend::automatic may have put a small factor on the host: delayed pivots from the
    // first factorization there, as with Backend::cpu (options())
    set_delaying(solver_.stats().analysis.backend == Backend::cpu);
    fresh_ = true;
  }
  MatchingStart matching_start() const override { return solver_.matching_start(); }
  void analyze_keeping_order(const SparseMatrix& a) override {
    solver_.analyze_keeping_order(a);  // the matching and scaling stay: so does delaying
    fresh_ = true;
  }
  index_t factor_entries_keeping_order(const SparseMatrix& a) const override {
    return solver_.factor_entries_keeping_order(a);
  }
  void analyze_keeping_matching(const SparseMatrix& a) override {
    solver_.analyze_keeping_matching(a);  // as analyze_keeping_order: delaying stays
    fresh_ = true;
  }
  void factorize(const SparseMatrix& a) override {
    if (fresh_)
      solver_.factorize(a);
    else
      solver_.refactorize(a);
    factorized();
  }
  void factorize_analyzed_pattern(const SparseMatrix& a) override {
    if (fresh_)
      solver_.factorize(a);
    else  // the values alone: the pattern is not compared with the analysis's
      solver_.refactorize(std::span<const double>(a.values));
    factorized();
  }
  bool delaying() const override { return delaying_; }
  void set_delaying(bool on) override {
    if (!adaptive_) return;
    delaying_ = on;
    solver_.set_pivoting(on ? Pivoting::delayed : Pivoting::automatic);
  }
  void solve(const double* b, double* x) override { solver_.solve(b, x, 1); }
  index_t factor_entries() const override {
    const auto& s = solver_.stats().analysis;
    return s.nnz_l;
  }
  index_t perturbed_pivots() const override { return solver_.stats().factor.perturbed_pivots; }
  double backward_error() const override { return solver_.stats().solve.backward_error; }
  void factorized() {
    fresh_ = false;
    // static pivots in the analysis's order: it no longer fits these values, and the next
    // factorizations would try the GPU for nothing
    const FactorStats& f = solver_.stats().factor;
    if (adaptive_ && f.delayed_pivoting && f.fixed_order_perturbed_pivots > 0) set_delaying(true);
  }
  std::string describe() const override {
    const FactorStats& f = solver_.stats().factor;
    if (f.type == MatrixType::symmetric_indefinite)
      return std::string("strata LDLT (matching + scaling) on ") + to_string(f.backend);
    return "strata LU (matching + scaling" +
           std::string(f.delayed_pivoting ? ", delayed pivots" : "") + ") on " +
           to_string(f.backend);
  }
  const Stats* stats() const override { return &solver_.stats(); }

 private:
  Solver solver_;
  bool adaptive_ = false;  // the engine's choice of pivoting, delaying_ on the host (options())
  bool delaying_ = false;
  bool fresh_ = true;
};

class DenseLinearSolver : public LinearSolver {
 public:
  void analyze(const SparseMatrix& a) override { n_ = static_cast<int>(a.n_rows); }
  void factorize(const SparseMatrix& a) override {
    n_ = static_cast<int>(a.n_rows);
    lu_.assign(static_cast<std::size_t>(n_) * n_, 0.0);
    for (index_t j = 0; j < a.n_cols; ++j)
      for (index_t p = a.offsets[j]; p < a.offsets[j + 1]; ++p)
        lu_[a.indices[p] + j * n_] += a.values[p];
    piv_.resize(n_);
    int info = 0;
    dgetrf_(&n_, &n_, lu_.data(), &n_, piv_.data(), &info);
    singular_ = info > 0 ? 1 : 0;
    if (info < 0) throw Error("dgetrf: invalid argument");
  }
  void solve(const double* b, double* x) override {
    std::copy(b, b + n_, x);
    const int one = 1;
    int info = 0;
    dgetrs_("N", &n_, &one, lu_.data(), &n_, piv_.data(), x, &n_, &info);
  }
  index_t factor_entries() const override { return static_cast<index_t>(n_) * n_; }
  index_t factor_entries_keeping_order(const SparseMatrix& a) const override {
    return a.n_rows * a.n_rows;
  }
  index_t perturbed_pivots() const override { return singular_; }
  double backward_error() const override { return 0; }
  std::string describe() const override { return "dense LAPACK LU"; }

 private:
  int n_ = 0;
  std::vector<double> lu_;
  std::vector<int> piv_;
  index_t singular_ = 0;
};

}  // namespace

bool solver_on_gpu(Backend backend) { return numeric::uses_cuda(backend); }

Options engine_solver_options() {
  Options o;
  o.type = MatrixType::general;
  o.backend = Backend::automatic;
  o.num_gpus = 1;
  o.solve_check = SolveCheck::after_perturbed_pivots;
  // One METIS separator per bisection: the engine analyzes again at every contact change
  // and at set-up, and on its Newton matrices the second separator of METIS_NodeND's rule
  // costs about a quarter of the ordering for a fill within a few tenths of a percent.
  o.nd_separators = 1;
  return o;
}

std::unique_ptr<LinearSolver> make_strata_solver(const Options& o) {
  return std::make_unique<StrataLinearSolver>(o, MatrixType::general);
}
std::unique_ptr<LinearSolver> make_strata_symmetric_solver(const Options& o) {
  return std::make_unique<StrataLinearSolver>(o, MatrixType::symmetric_indefinite);
}
std::unique_ptr<LinearSolver> make_dense_solver() { return std::make_unique<DenseLinearSolver>(); }

}  // namespace strata::mbd
