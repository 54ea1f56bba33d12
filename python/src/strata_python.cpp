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

#include <cstdint>
#include <memory>
#include <span>
#include <string>

#include "blas_kernels.hpp"
#include "core/stats_json.hpp"
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

// A JSON value as the Python object json.loads would give (dict, list, str, int, float,
// bool, None): how the statistics document (core/stats_json.hpp) reaches Python.
py::object to_python(const nlohmann::json& j) {
  switch (j.type()) {
    case nlohmann::json::value_t::null:
      return py::none();
    case nlohmann::json::value_t::boolean:
      return py::bool_(j.get<bool>());
    case nlohmann::json::value_t::number_integer:
      return py::int_(j.get<std::int64_t>());
    case nlohmann::json::value_t::number_unsigned:
      return py::int_(j.get<std::uint64_t>());
    case nlohmann::json::value_t::number_float:
      return py::float_(j.get<double>());
    case nlohmann::json::value_t::string:
      return py::str(j.get_ref<const std::string&>());
    case nlohmann::json::value_t::array: {
      py::list l;
      for (const auto& e : j) l.append(to_python(e));
      return l;
    }
    case nlohmann::json::value_t::object: {
      py::dict d;
      for (const auto& [k, v] : j.items()) d[py::str(k)] = to_python(v);
      return d;
    }
    default:
      throw strata::InternalError("statistics: a JSON value of an unexpected type");
  }
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

  // Solver::refactorize(values): the values alone, in the analyzed matrix's entry order
  void refactorize_values(const DoubleArray& values) {
    if (!analyzed_) throw strata::InvalidState("refactorize called before analyze");
    if (values.ndim() != 1)
      throw strata::InvalidInput("refactorize_values: the values must be a 1-D array");
    const std::span<const double> v(values.data(), static_cast<std::size_t>(values.size()));
    numeric_phase([&] { solver_->refactorize(v); });
  }

  void factorize(const strata::SparseMatrix& a, bool refactor) {
    if (!analyzed_) {
      if (refactor) throw strata::InvalidState("refactorize called before analyze");
      analyze(a);
    }
    numeric_phase([&] {
      if (refactor)
        solver_->refactorize(a);
      else
        solver_->factorize(a);
    });
  }

  // A factorization without the GIL: rejected input keeps the previous factor, any other
  // failure leaves none.
  template <class F>
  void numeric_phase(F&& f) {
    try {
      py::gil_scoped_release release;
      f();
    } catch (const strata::InvalidInput&) {
      throw;
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

  py::object stats() const {
    if (!analyzed_) return py::dict();
    nlohmann::json j = strata::stats_document(solver_->stats(), factorized_, solved_);
    j["analyzed"] = true;
    j["factorized"] = factorized_;
    j["solved"] = solved_;
    return to_python(j);
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
  py::object stats() const {
    nlohmann::json j = strata::stats_document(solver_.stats(), factorized_, solved_);
    j["factorized"] = factorized_;
    j["solved"] = solved_;
    j["distributed"] = solver_.distributed_stats();
    return to_python(j);
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
      .def("refactorize_values", &Core::refactorize_values, py::arg("values"))
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
  m.def(
      "blas_kernels",
      [] {
        py::dict d;
        d["library"] = strata::app::blas_description();
        d["fitting"] = strata::app::openblas_core_for_cpu();
        return d;
      },
      "The BLAS in use (\"OpenBLAS 0.3.21, SkylakeX kernels\") and the OpenBLAS core type "
      "this CPU supports best (\"SkylakeX\", \"Haswell\" or \"\").");
  bind_simulate(m, exc_invalid_input, exc_error);
  m.attr("__version__") = strata_version();  // the project version (CMakeLists.txt)
}
