// strata — the Python extension module `strata._strata` (pybind11).
//
// A thin layer over the C++ Solver: the user-facing API (scipy.sparse input, shape and
// dtype checks, docstrings) is python/strata/__init__.py. Here: arrays in, the phases
// with the GIL released, statistics out as dicts, and strata's typed exceptions mapped
// to a Python hierarchy rooted at strata.Error (a RuntimeError); InvalidInputError is
// also a ValueError and OutOfMemoryError a MemoryError. The multibody engine's entry
// point is in simulate.cpp.
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <memory>
#include <string>

#include "strata/distributed.hpp"
#include "strata/strata.h"
#include "strata/strata.hpp"
#ifdef STRATA_HAVE_MPI
#include "strata/mpi.hpp"
#endif

namespace py = pybind11;
using strata::index_t;

// simulate.cpp: strata.simulate's core and ModelError / SimulationError.
void bind_simulate(py::module_& m, PyObject* invalid_input, PyObject* error);

namespace {

PyObject* exc_error = nullptr;
PyObject* exc_invalid_input = nullptr;
PyObject* exc_not_supported = nullptr;
PyObject* exc_out_of_memory = nullptr;
PyObject* exc_device = nullptr;
PyObject* exc_not_positive_definite = nullptr;
PyObject* exc_invalid_state = nullptr;
PyObject* exc_internal = nullptr;

PyObject* make_exception(py::module_& m, const char* name, py::tuple bases, const char* doc) {
  const std::string full = std::string("strata.") + name;
  PyObject* e = PyErr_NewExceptionWithDoc(full.c_str(), doc, bases.ptr(), nullptr);
  if (e == nullptr) throw py::error_already_set();
  m.add_object(name, py::handle(e));
  return e;
}

using Int64Array = py::array_t<std::int64_t, py::array::c_style | py::array::forcecast>;
using DoubleArray = py::array_t<double, py::array::c_style | py::array::forcecast>;

// Copies compressed arrays (0-based, int64 offsets and indices) into a SparseMatrix.
strata::SparseMatrix to_matrix(index_t n_rows, index_t n_cols, const std::string& layout,
                               const std::string& storage, const Int64Array& indptr,
                               const Int64Array& indices, const py::object& data) {
  strata::SparseMatrix a;
  a.n_rows = n_rows;
  a.n_cols = n_cols;
  if (layout == "csr")
    a.layout = strata::Layout::csr;
  else if (layout == "csc")
    a.layout = strata::Layout::csc;
  else
    throw strata::InvalidInput("layout must be 'csr' or 'csc', got '" + layout + "'");
  if (storage == "full")
    a.storage = strata::Storage::full;
  else if (storage == "lower")
    a.storage = strata::Storage::lower;
  else if (storage == "upper")
    a.storage = strata::Storage::upper;
  else
    throw strata::InvalidInput("storage must be 'full', 'lower' or 'upper', got '" + storage + "'");
  if (indptr.ndim() != 1 || indices.ndim() != 1)
    throw strata::InvalidInput("indptr and indices must be 1-D arrays");
  a.offsets.assign(indptr.data(), indptr.data() + indptr.size());
  a.indices.assign(indices.data(), indices.data() + indices.size());
  if (!data.is_none()) {
    const DoubleArray values = data.cast<DoubleArray>();
    if (values.ndim() != 1) throw strata::InvalidInput("data must be a 1-D array");
    a.values.assign(values.data(), values.data() + values.size());
  }
  strata::validate(a);
  return a;
}

strata::Options make_options(const std::string& type, const std::string& ordering,
                             const std::string& device, index_t max_block_size, int num_threads,
                             int refinement_steps, double refinement_tolerance,
                             std::size_t device_memory_limit) {
  strata::Options o;
  strata::parse(type, &o.type);
  strata::parse(ordering, &o.ordering);
  strata::parse(device, &o.backend);
  o.max_block_size = max_block_size;
  o.num_threads = num_threads;
  o.refinement_max_steps = refinement_steps;
  o.refinement_tolerance = refinement_tolerance;
  o.device_memory_limit = device_memory_limit;
  strata::validate(o);  // its messages name the fields of strata::Options
  return o;
}

// inertia, log_abs_determinant and determinant_sign, withheld (None) when static
// pivoting perturbed pivots: they would be those of the nearby matrix factored, not A's
void put_inertia(py::dict& d, const strata::FactorStats& f) {
  d["inertia_valid"] = f.inertia_valid;
  if (!f.inertia_valid) {
    d["inertia"] = py::none();
    d["log_abs_determinant"] = py::none();
    d["determinant_sign"] = py::none();
    return;
  }
  d["inertia"] = py::make_tuple(f.inertia_positive, f.inertia_negative, f.inertia_zero);
  d["log_abs_determinant"] = f.log_abs_determinant;
  d["determinant_sign"] = f.determinant_sign;
}

py::dict analysis_dict(const strata::AnalysisStats& a) {
  py::dict d;
  d["n"] = a.n;
  d["nnz_a"] = a.nnz_a;
  d["nnz_l"] = a.nnz_l;
  d["nnz_l_fronts"] = a.nnz_l_fronts;
  d["factor_flops"] = a.factor_flops;
  d["n_fronts"] = a.n_fronts;
  d["largest_front_rows"] = a.largest_front_rows;
  d["largest_front_pivots"] = a.largest_front_pivots;
  d["max_block_size"] = a.max_block_size;
  d["tree_height"] = a.tree_height;
  d["fronts_per_level"] = a.fronts_per_level;
  d["peak_working_bytes"] = a.peak_working_bytes;
  d["factor_bytes"] = a.factor_bytes;
  d["memory_budget"] = a.memory_budget;
  d["n_batches"] = a.batches.size();
  d["analysis_type"] = strata::to_string(a.type);
  d["ordering"] = strata::to_string(a.ordering);
  d["pairs"] = a.pairs;
  d["odd_cycles"] = a.odd_cycles;
  d["ordering_seconds"] = a.ordering_seconds;
  d["symbolic_seconds"] = a.symbolic_seconds;
  d["plan_seconds"] = a.plan_seconds;
  d["device_setup_seconds"] = a.device_setup_seconds;
  d["analysis_seconds"] = a.total_seconds;
  return d;
}

// One Solver plus the phase flags the Python side needs.
class Core {
 public:
  explicit Core(strata::Options o) : options_(std::move(o)) {}

  void analyze(const strata::SparseMatrix& a) {
    analyzed_ = factorized_ = solved_ = false;
    auto s = std::make_unique<strata::Solver>(options_);
    {
      py::gil_scoped_release release;
      s->analyze(a);
    }
    solver_ = std::move(s);
    analyzed_ = true;
  }

  void factorize(const strata::SparseMatrix& a, bool refactor) {
    if (!analyzed_) {
      if (refactor) throw strata::InvalidState("refactorize called before analyze");
      analyze(a);
    }
    try {
      py::gil_scoped_release release;
      if (refactor)
        solver_->refactorize(a);
      else
        solver_->factorize(a);
    } catch (const strata::InvalidInput&) {
      throw;  // rejected input: the previous factor is kept
    } catch (...) {
      factorized_ = solved_ = false;
      throw;
    }
    factorized_ = true;
    solved_ = false;
  }

  // b: n×k, column-major (Fortran order), float64. Returns x of the same shape.
  py::array_t<double> solve(
      const py::array_t<double, py::array::f_style | py::array::forcecast>& b) {
    if (!factorized_) throw strata::InvalidState("solve called before factorize");
    const index_t n = solver_->size();
    if (b.ndim() != 2 || b.shape(0) != n)
      throw strata::InvalidInput("right-hand side must have shape (" + std::to_string(n) + ", k)");
    const index_t k = b.shape(1);
    py::array_t<double, py::array::f_style> x(
        {static_cast<py::ssize_t>(n), static_cast<py::ssize_t>(k)});
    if (n > 0 && k > 0) {
      const double* bp = b.data();
      double* xp = x.mutable_data();
      py::gil_scoped_release release;
      solver_->solve(bp, xp, k);
    }
    solved_ = true;
    return x;
  }

  index_t size() const { return analyzed_ ? solver_->size() : 0; }

  py::dict stats() const {
    if (!analyzed_) return py::dict();
    const strata::Stats& st = solver_->stats();
    py::dict d = analysis_dict(st.analysis);
    d["analyzed"] = true;
    d["factorized"] = factorized_;
    d["solved"] = solved_;
    if (factorized_) {
      const strata::FactorStats& f = st.factor;
      d["type"] = strata::to_string(f.type);
      d["backend"] = strata::to_string(f.backend);
      d["factor_seconds"] = f.seconds;
      d["factor_gflops"] = f.gflops;
      d["factor_input_seconds"] = f.input_seconds;
      d["perturbed_pivots"] = f.perturbed_pivots;
      d["delayed_pivoting"] = f.delayed_pivoting;
      d["delayed_pivots"] = f.delayed_pivots;
      d["fronts_delaying"] = f.fronts_delaying;
      d["fixed_order_perturbed_pivots"] = f.fixed_order_perturbed_pivots;
      d["rescaling_sweeps"] = f.rescaling_sweeps;
      d["two_by_two_pivots"] = f.two_by_two_pivots;
      put_inertia(d, f);
      d["matrix_norm"] = f.matrix_norm;
    }
    if (solved_) {
      const strata::SolveStats& s = st.solve;
      d["solve_seconds"] = s.seconds;
      d["refinement_steps"] = s.refinement_steps;
      d["gmres_iterations"] = s.gmres_iterations;
      d["backward_error"] = s.backward_error;
      d["refinement_converged"] = s.refinement_converged;
      d["backward_error_floor"] = s.backward_error_floor;
      d["condition_lower_bound"] = s.condition_lower_bound;
      d["relative_residual"] = s.relative_residual;
      d["singular_consistent"] = s.singular_consistent;
    }
    return d;
  }

  py::array_t<std::int64_t> permutation() const {
    if (!analyzed_) throw strata::InvalidState("permutation asked before analyze");
    const auto& p = solver_->permutation();
    py::array_t<std::int64_t> out(static_cast<py::ssize_t>(p.size()));
    std::copy(p.begin(), p.end(), out.mutable_data());
    return out;
  }

 private:
  strata::Options options_;
  std::unique_ptr<strata::Solver> solver_;
  bool analyzed_ = false;
  bool factorized_ = false;
  bool solved_ = false;
};

#ifdef STRATA_HAVE_MPI
// One DistributedSolver over an mpi4py communicator (given by its Fortran handle,
// comm.py2f(), so that no mpi4py header is needed). Every method is collective; the
// matrix and b matter on rank 0 only.
class DistCore {
 public:
  DistCore(long long comm_f, strata::Options o)
      : solver_(strata::mpi_communicator(MPI_Comm_f2c(static_cast<MPI_Fint>(comm_f))),
                std::move(o)) {}

  void analyze(const strata::SparseMatrix& a) {
    factorized_ = solved_ = false;
    py::gil_scoped_release release;
    solver_.analyze(a);
  }
  void factorize(const strata::SparseMatrix& a, bool refactor) {
    {
      py::gil_scoped_release release;
      if (refactor)
        solver_.refactorize(a);
      else
        solver_.factorize(a);
    }
    factorized_ = true;
    solved_ = false;
  }
  // b: the right-hand sides flattened column-major (rank 0; empty elsewhere). Returns x
  // flattened the same way on rank 0, None on the others.
  py::object solve(const DoubleArray& b) {
    std::vector<double> bv(b.data(), b.data() + b.size()), x;
    {
      py::gil_scoped_release release;
      x = solver_.solve(bv);
    }
    solved_ = true;
    if (solver_.communicator().rank() != 0) return py::none();
    py::array_t<double> out(static_cast<py::ssize_t>(x.size()));
    std::copy(x.begin(), x.end(), out.mutable_data());
    return out;
  }
  index_t size() const { return solver_.size(); }
  int rank() const { return solver_.communicator().rank(); }
  py::dict stats() const {
    const strata::Stats& st = solver_.stats();
    py::dict d = analysis_dict(st.analysis);
    d["factorized"] = factorized_;
    d["solved"] = solved_;
    if (factorized_) {
      const strata::FactorStats& f = st.factor;
      d["type"] = strata::to_string(f.type);
      d["backend"] = strata::to_string(f.backend);
      d["factor_seconds"] = f.seconds;
      d["perturbed_pivots"] = f.perturbed_pivots;
      put_inertia(d, f);
    }
    if (solved_) {
      d["solve_seconds"] = st.solve.seconds;
      d["refinement_steps"] = st.solve.refinement_steps;
      d["backward_error"] = st.solve.backward_error;
    }
    const strata::DistributedStats& ds = solver_.distributed_stats();
    d["ranks"] = ds.ranks;
    d["workers_per_rank"] = ds.workers_per_rank;
    py::list per_rank;
    for (const strata::RankStats& r : ds.per_rank) {
      py::dict e;
      e["rank"] = r.rank;
      e["subtrees"] = r.subtrees;
      e["factor_flops"] = r.factor_flops;
      e["factor_seconds"] = r.factor_seconds;
      e["factor_bytes_sent"] = r.factor_bytes_sent;
      e["factor_bytes_received"] = r.factor_bytes_received;
      e["values_bytes"] = r.values_bytes;
      e["factor_bytes_held"] = r.factor_bytes_held;
      e["solve_seconds"] = r.solve_seconds;
      e["solve_bytes_sent"] = r.solve_bytes_sent;
      e["solve_bytes_received"] = r.solve_bytes_received;
      per_rank.append(e);
    }
    d["per_rank"] = per_rank;
    return d;
  }

 private:
  strata::DistributedSolver solver_;
  bool factorized_ = false;
  bool solved_ = false;
};
#endif

}  // namespace

PYBIND11_MODULE(_strata, m) {
  m.doc() = "strata: multifrontal sparse direct solver (extension module; use `import strata`)";

  exc_error = make_exception(m, "Error", py::make_tuple(py::handle(PyExc_RuntimeError)),
                             "Base of every error strata raises.");
  py::handle base(exc_error);
  exc_invalid_input = make_exception(
      m, "InvalidInputError", py::make_tuple(base, py::handle(PyExc_ValueError)),
      "Malformed input: non-square matrix, index out of range, NaN/Inf, wrong shape, "
      "changed pattern.");
  exc_not_supported = make_exception(m, "NotSupportedError", py::make_tuple(base),
                                     "A valid request this build or backend cannot do.");
  exc_out_of_memory =
      make_exception(m, "OutOfMemoryError", py::make_tuple(base, py::handle(PyExc_MemoryError)),
                     "An allocation failed.");
  exc_device = make_exception(m, "DeviceError", py::make_tuple(base),
                              "A CUDA, cuBLAS or cuSOLVER call failed.");
  exc_not_positive_definite =
      make_exception(m, "NotPositiveDefiniteError", py::make_tuple(base),
                     "type='spd' was requested and Cholesky met a pivot that is not positive.");
  exc_invalid_state = make_exception(m, "InvalidStateError", py::make_tuple(base),
                                     "Phases called in the wrong order.");
  exc_internal = make_exception(m, "InternalError", py::make_tuple(base),
                                "A broken internal invariant: a bug in strata (please report).");

  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const strata::InvalidInput& e) {
      PyErr_SetString(exc_invalid_input, e.what());
    } catch (const strata::NotSupported& e) {
      PyErr_SetString(exc_not_supported, e.what());
    } catch (const strata::OutOfMemory& e) {
      PyErr_SetString(exc_out_of_memory, e.what());
    } catch (const strata::DeviceError& e) {
      PyErr_SetString(exc_device, e.what());
    } catch (const strata::NotPositiveDefinite& e) {
      PyErr_SetString(exc_not_positive_definite, e.what());
    } catch (const strata::InvalidState& e) {
      PyErr_SetString(exc_invalid_state, e.what());
    } catch (const strata::InternalError& e) {
      PyErr_SetString(exc_internal, e.what());
    } catch (const strata::Error& e) {
      PyErr_SetString(exc_error, e.what());
    }
  });

  py::class_<strata::SparseMatrix>(m, "_Matrix", "A validated copy of a sparse matrix (internal).")
      .def(py::init(&to_matrix), py::arg("n_rows"), py::arg("n_cols"), py::arg("layout"),
           py::arg("storage"), py::arg("indptr"), py::arg("indices"), py::arg("data"))
      .def_property_readonly("nnz", &strata::SparseMatrix::nnz);

  py::class_<Core>(m, "_Core", "One strata::Solver (internal; see strata.Solver).")
      .def(py::init([](const std::string& type, const std::string& ordering,
                       const std::string& device, index_t max_block_size, int num_threads,
                       int refinement_steps, double refinement_tolerance,
                       std::size_t device_memory_limit) {
             return Core(make_options(type, ordering, device, max_block_size, num_threads,
                                      refinement_steps, refinement_tolerance, device_memory_limit));
           }),
           py::arg("type"), py::arg("ordering"), py::arg("device"), py::arg("max_block_size"),
           py::arg("num_threads"), py::arg("refinement_steps"), py::arg("refinement_tolerance"),
           py::arg("device_memory_limit"))
      .def("analyze", &Core::analyze, py::arg("a"))
      .def("factorize", [](Core& c, const strata::SparseMatrix& a) { c.factorize(a, false); })
      .def("refactorize", [](Core& c, const strata::SparseMatrix& a) { c.factorize(a, true); })
      .def("solve", &Core::solve, py::arg("b"))
      .def_property_readonly("n", &Core::size)
      .def("stats", &Core::stats)
      .def("permutation", &Core::permutation);

#ifdef STRATA_HAVE_MPI
  py::class_<DistCore>(m, "_DistCore", "One strata::DistributedSolver (internal).")
      .def(py::init([](long long comm_f, const std::string& type, const std::string& ordering,
                       const std::string& device, index_t max_block_size, int num_threads,
                       int refinement_steps, double refinement_tolerance,
                       std::size_t device_memory_limit) {
             return std::make_unique<DistCore>(
                 comm_f, make_options(type, ordering, device, max_block_size, num_threads,
                                      refinement_steps, refinement_tolerance, device_memory_limit));
           }),
           py::arg("comm_f"), py::arg("type"), py::arg("ordering"), py::arg("device"),
           py::arg("max_block_size"), py::arg("num_threads"), py::arg("refinement_steps"),
           py::arg("refinement_tolerance"), py::arg("device_memory_limit"))
      .def("analyze", &DistCore::analyze, py::arg("a"))
      .def("factorize", [](DistCore& c, const strata::SparseMatrix& a) { c.factorize(a, false); })
      .def("refactorize", [](DistCore& c, const strata::SparseMatrix& a) { c.factorize(a, true); })
      .def("solve", &DistCore::solve, py::arg("b"))
      .def_property_readonly("n", &DistCore::size)
      .def_property_readonly("rank", &DistCore::rank)
      .def("stats", &DistCore::stats);
#endif
  m.def(
      "mpi_in_build", [] { return strata::Communicator::mpi_available(); },
      "True when this build has MPI support (strata.Solver accepts comm=).");
  m.def(
      "cuda_in_build",
      [] {
#ifdef STRATA_HAVE_CUDA
        return true;
#else
        return false;
#endif
      },
      "True when this build has the CUDA backend.");
  bind_simulate(m, exc_invalid_input, exc_error);
  m.attr("__version__") = strata_version();  // the project version (CMakeLists.txt)
}
