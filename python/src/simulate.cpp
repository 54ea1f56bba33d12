// strata — the multibody engine in the extension module: strata._strata._simulate.
//
// The model comes as a file path (read by load_model, as `strata simulate FILE` does), as
// JSON text (a Python dict serialized by python/strata/_simulate.py; parse_model, the
// same reader, so the messages name the problem the same way), or as a generator spec
// ("tracked:10", as --generate). The run settings are the CLI's (RunSettings,
// simulation_options), so defaults and model overrides match `strata simulate`. The
// model is built and integrated with the GIL released; the time histories come back as
// NumPy arrays (copied once from the in-memory SimulationHistory) in a dict that the
// Python layer wraps. A run that stops early returns complete=False, state "failed" and
// its message: the Python layer raises SimulationError carrying the partial result (and
// with output_dir, the files stay NAME.partial.csv with status.json marked partial, as
// the command line leaves them).
#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <nlohmann/json.hpp>
#include <string>

#include "mbd/generators.hpp"
#include "mbd/model_io.hpp"
#include "mbd/simulation.hpp"

namespace py = pybind11;

namespace {

PyObject* exc_model = nullptr;
PyObject* exc_simulation = nullptr;

// rows × cols float64 array, copied from a row-major buffer.
py::array_t<double> matrix(const std::vector<double>& v, std::size_t rows, std::size_t cols) {
  py::array_t<double> a({static_cast<py::ssize_t>(rows), static_cast<py::ssize_t>(cols)});
  if (!v.empty()) std::copy(v.begin(), v.end(), a.mutable_data());
  return a;
}

py::array_t<double> vector(const std::vector<double>& v) {
  py::array_t<double> a(static_cast<py::ssize_t>(v.size()));
  if (!v.empty()) std::copy(v.begin(), v.end(), a.mutable_data());
  return a;
}

template <class T, class F>
py::array_t<T> column(const std::vector<strata::mbd::StepRecord>& steps, F get) {
  py::array_t<T> a(static_cast<py::ssize_t>(steps.size()));
  T* p = a.mutable_data();
  for (std::size_t i = 0; i < steps.size(); ++i) p[i] = static_cast<T>(get(steps[i]));
  return a;
}

py::dict steps_dict(const std::vector<strata::mbd::StepRecord>& s) {
  using R = strata::mbd::StepRecord;
  py::dict d;
  d["step"] = column<std::int64_t>(s, [](const R& r) { return r.step; });
  d["time"] = column<double>(s, [](const R& r) { return r.t; });
  d["h"] = column<double>(s, [](const R& r) { return r.h; });
  d["order"] = column<std::int64_t>(s, [](const R& r) { return r.order; });
  d["newton_iterations"] = column<std::int64_t>(s, [](const R& r) { return r.newton_iterations; });
  d["factorizations"] = column<std::int64_t>(s, [](const R& r) { return r.factorizations; });
  d["rejected"] = column<std::int64_t>(s, [](const R& r) { return r.rejected; });
  d["assembly_seconds"] = column<double>(s, [](const R& r) { return r.assembly_seconds; });
  d["solver_seconds"] = column<double>(s, [](const R& r) { return r.solver_seconds; });
  d["kinetic_energy"] = column<double>(s, [](const R& r) { return r.kinetic_energy; });
  d["potential_energy"] = column<double>(s, [](const R& r) { return r.potential_energy; });
  d["total_energy"] =
      column<double>(s, [](const R& r) { return r.kinetic_energy + r.potential_energy; });
  d["position_violation"] = column<double>(s, [](const R& r) { return r.position_violation; });
  d["velocity_violation"] = column<double>(s, [](const R& r) { return r.velocity_violation; });
  return d;
}

py::dict stats_dict(const strata::mbd::SimulationResult& r) {
  const strata::mbd::IntegratorStats& s = r.stats;
  py::dict d;
  d["steps"] = s.steps;
  d["rejected"] = s.rejected;
  d["error_rejections"] = s.error_rejections;
  d["newton_iterations"] = s.newton_iterations;
  d["factorizations"] = s.factorizations;
  d["analyses"] = s.analyses;
  d["reanalyses"] = s.reanalyses;
  d["repartitions"] = s.repartitions;
  d["contact_updates"] = s.contact_updates;
  d["kept_order_analyses"] = s.kept_order_analyses;
  d["contact_analyses"] = s.contact_analyses;
  d["solves"] = s.solves;
  d["perturbed_pivots"] = s.perturbed_pivots;
  d["jacobian_size"] = s.jacobian_size;
  d["jacobian_nnz"] = s.jacobian_nnz;
  d["factor_nnz"] = s.factor_nnz;
  d["linear_solver"] = s.solver;
  d["wall_seconds"] = r.wall_seconds;
  d["solver_seconds"] = s.solver_seconds;
  d["factor_seconds"] = s.factor_seconds;
  d["solve_seconds"] = s.solve_seconds;
  d["condensation_seconds"] = s.condensation_seconds;
  d["analysis_seconds"] = s.analysis_seconds;
  d["assembly_seconds"] = s.assembly_seconds;
  d["partition_seconds"] = s.partition_seconds;
  d["initial_conditions_seconds"] = s.initial_conditions_seconds;
  d["output_seconds"] = r.output_seconds;
  d["energy_initial"] = r.energy_initial;
  d["energy_final"] = r.energy_final;
  d["max_position_violation"] = r.max_position_violation;
  d["max_velocity_violation"] = r.max_velocity_violation;
  return d;
}

// kind: "path", "json" or "generate"; source: the path, the JSON text or the spec.
py::dict run(const std::string& kind, const std::string& source, const std::string& name,
             const py::dict& settings) {
  using namespace strata::mbd;
  RunSettings rs;
  auto num = [&](const char* k, double& v) {
    if (settings.contains(k)) v = settings[k].cast<double>();
  };
  auto integer = [&](const char* k, auto& v) {
    if (settings.contains(k)) v = settings[k].cast<std::int64_t>();
  };
  auto flag = [&](const char* k, bool& v) {
    if (settings.contains(k)) v = settings[k].cast<bool>();
  };
  auto text = [&](const char* k, std::string& v) {
    if (settings.contains(k)) v = settings[k].cast<std::string>();
  };
  num("t_end", rs.t_end);
  num("step", rs.step);
  integer("order", rs.order);
  std::string device = "auto";
  text("device", device);
  strata::parse(device, &rs.solver.backend);
  integer("threads", rs.solver.num_threads);
  if (settings.contains("solver_options"))
    for (const auto& [name, value] : settings["solver_options"].cast<py::dict>())
      strata::set_option(rs.solver, name.cast<std::string>(), value.cast<std::string>());
  flag("full_newton", rs.full_newton);
  integer("anderson_depth", rs.anderson_depth);
  num("newton_tol", rs.newton_tol);
  flag("variable_step", rs.variable_step);
  num("rtol", rs.rtol);
  num("atol", rs.atol);
  num("max_step", rs.max_step);
  flag("dense_reference", rs.dense_reference);
  flag("condensation", rs.condensation);
  text("output_dir", rs.output_dir);
  num("output_interval", rs.output_interval);
  flag("vtk", rs.vtk);
  text("dump_dir", rs.dump_dir);
  integer("dump_step", rs.dump_step);

  Model model;
  SimulationResult r;
  SimulationHistory h;
  SimulationOptions o;
  {
    py::gil_scoped_release release;
    if (kind == "path")
      model = load_model(source);
    else if (kind == "json")
      model = parse_model(source, name);
    else if (kind == "generate")
      model = build_model(generate(source), source);
    else
      throw strata::InvalidInput("unknown model kind '" + kind + "'");
    o = simulation_options(model, rs);
    o.history = &h;
    r = simulate(model, o);
  }
  const std::size_t rows = h.time.size();
  py::dict d;
  d["complete"] = r.complete;
  d["state"] = r.state;  // "complete" or "failed" (no interrupt flag is passed here)
  d["message"] = r.message;
  d["t_reached"] = r.t_reached;
  d["model"] = py::dict(py::arg("name") = model.name, py::arg("planar") = model.planar,
                        py::arg("n") = model.n, py::arg("m") = model.n_constraints(),
                        py::arg("bodies") = model.bodies.size() - 1,
                        py::arg("forces") = model.forces.size());
  d["settings"] = py::dict(
      py::arg("t_end") = o.integrator.t_end, py::arg("step") = o.integrator.step,
      py::arg("order") = o.integrator.order, py::arg("variable_step") = o.integrator.variable_step,
      py::arg("modified_newton") = o.integrator.modified_newton,
      py::arg("anderson_depth") = o.integrator.anderson_depth,
      py::arg("newton_rtol") = o.integrator.newton_rtol,
      py::arg("newton_atol") = o.integrator.newton_atol,
      py::arg("output_interval") = o.output_interval, py::arg("device") = device);
  d["time"] = vector(h.time);
  d["positions"] = matrix(h.positions, rows, static_cast<std::size_t>(model.n));
  d["velocities"] = matrix(h.velocities, rows, static_cast<std::size_t>(model.n));
  d["accelerations"] = matrix(h.accelerations, rows, static_cast<std::size_t>(model.n));
  d["reactions"] = matrix(h.reactions, rows, h.reaction_names.size());
  d["coordinate_names"] = h.coordinate_names;
  d["reaction_names"] = h.reaction_names;
  d["steps"] = steps_dict(h.steps);
  d["stats"] = stats_dict(r);
  d["summary"] = summary(model, r);
  return d;
}

}  // namespace

// Called from PYBIND11_MODULE in strata_python.cpp, after its exception translator (a
// translator registered later is tried first: ModelError and SimulationError are
// matched here before the generic InvalidInput / Error there).
void bind_simulate(py::module_& m, PyObject* invalid_input, PyObject* error) {
  exc_model = PyErr_NewExceptionWithDoc(
      "strata.ModelError",
      "A model file or dict is wrong: the message names the JSON path of the value.",
      py::make_tuple(py::handle(invalid_input)).ptr(), nullptr);
  if (exc_model == nullptr) throw py::error_already_set();
  m.add_object("ModelError", py::handle(exc_model));
  exc_simulation = PyErr_NewExceptionWithDoc(
      "strata.SimulationError",
      "The integration cannot go on (Newton failure at the minimum step, inconsistent "
      "initial conditions). A run that stopped after its first step carries what it "
      "computed up to then in the attribute `result` (a SimulationResult).",
      py::make_tuple(py::handle(error)).ptr(), nullptr);
  if (exc_simulation == nullptr) throw py::error_already_set();
  m.add_object("SimulationError", py::handle(exc_simulation));

  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const strata::mbd::ModelError& e) {
      PyErr_SetString(exc_model, e.what());
    } catch (const strata::mbd::SimulationError& e) {
      PyErr_SetString(exc_simulation, e.what());
    }
  });

  m.def("_simulate", &run, py::arg("kind"), py::arg("source"), py::arg("name"), py::arg("settings"),
        "Runs a multibody simulation (internal; see strata.simulate).");
  m.def(
      "_generate_model", [](const std::string& spec) { return strata::mbd::generate(spec).dump(); },
      py::arg("spec"), "The generated model `spec` as JSON text (internal).");
}
