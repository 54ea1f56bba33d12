"""strata.simulate: the multibody engine (implicit BDF + Newton, every Newton step solved
by strata) from Python, with the time histories as NumPy arrays.

The model is read by the engine's own JSON reader, the one ``strata simulate`` uses: a
file path is read as the command line reads it, a dict is serialized to JSON and given
to the same reader, so the same mistake gives the same message (with ``<dict>`` in place
of the file name). The schema is docs/model-format.md. The run settings mirror the
command line's flags and defaults.
"""

import json as _json
import os as _os

import numpy as _np

from . import _strata
from ._strata import InvalidInputError, ModelError, SimulationError

__all__ = ["simulate", "generate_model", "SimulationResult"]

# set on the instances raised for a run that stopped after its first step
SimulationError.result = None



class SimulationResult:
    """The result of :func:`strata.simulate`: time histories as NumPy arrays.

    With k output rows (the initial state, then every step, or every
    ``output_interval`` seconds, and the last step), n coordinates and r reaction
    columns:

    Attributes
    ----------
    time : ndarray of float64, shape (k,)
        Output times in s, from 0.
    positions : ndarray of float64, shape (k, n)
        Coordinates q: per planar body ``x, y`` (m) and ``phi`` (rad); per spatial body
        the centre of mass ``x, y, z`` (m) and the Euler parameters ``e0..e3``
        (dimensionless); per flexible-body node ``x, y, z`` (m). Column names in
        ``coordinate_names`` (``"link3.e2"``); the columns of positions.csv.
    velocities : ndarray of float64, shape (k, n)
        dq/dt (m/s, rad/s, 1/s for Euler parameters).
    accelerations : ndarray of float64, shape (k, n)
        d²q/dt² (m/s², rad/s², 1/s²).
    reactions : ndarray of float64, shape (k, r)
        Joint reaction forces (N, global frame, on body j — on body i when j does not
        move), then the Lagrange multipliers of every constraint equation; names in
        ``reaction_names`` (``"j1.Fx"``, ``"j1.lambda0"``). The columns of reactions.csv.
    coordinate_names, reaction_names : list of str
    steps : dict of ndarray, each of shape (s + 1,)
        Per accepted step (entry 0 is the initial state), the columns of steps.csv:
        ``step`` (int64), ``time`` (s), ``h`` (step size, s), ``order`` (BDF order, int64),
        ``newton_iterations``, ``factorizations``, ``rejected`` (int64: attempts with a
        smaller step before it), ``assembly_seconds``, ``solver_seconds`` (wall time in
        the residual/Jacobian assembly and in strata), ``kinetic_energy``,
        ``potential_energy``, ``total_energy`` (J), ``position_violation`` (max |Φ|),
        ``velocity_violation`` (max |dΦ/dt|).
    stats : dict
        Totals of the run: steps, rejected, error_rejections, newton_iterations,
        factorizations, analyses (full ones), reanalyses, repartitions, contact_updates
        (changes of the contact pairs in the matrix), kept_order_analyses (those that grew
        the pattern and kept the order: not counted in analyses), contact_analyses
        (full analyses where the kept order's factor would grow by more than 25%), solves,
        perturbed_pivots, jacobian_size and jacobian_nnz (the Newton matrix),
        factor_nnz (nnz(L)), linear_solver (str), and times in s: wall_seconds,
        solver_seconds (= analysis + factorization + solves), factor_seconds,
        solve_seconds, condensation_seconds (the host's share of factor_seconds and
        solve_seconds spent on the system condensed by the BDF relations),
        analysis_seconds, assembly_seconds, partition_seconds,
        initial_conditions_seconds, output_seconds; energy_initial, energy_final (J),
        max_position_violation, max_velocity_violation.
    model : dict
        name, planar (bool), n (coordinates), m (constraint equations), bodies, forces.
    settings : dict
        The settings actually used (after the model's defaults): t_end, step, order,
        variable_step, modified_newton, anderson_depth, newton_rtol, newton_atol,
        output_interval, device.
    complete : bool
        True when the run reached t_end (always True for a returned result; a run that
        stops early raises SimulationError, whose ``result`` has complete=False).
    state : str
        "complete", or "failed" for the partial result of a run that stopped early (the
        ``state`` of status.json).
    message : str
        Why the run stopped early ("" when complete).
    t_reached : float
        The last time reached, s.
    summary : str
        The summary ``strata simulate`` prints.
    """

    def __init__(self, d):
        self.time = d["time"]
        self.positions = d["positions"]
        self.velocities = d["velocities"]
        self.accelerations = d["accelerations"]
        self.reactions = d["reactions"]
        self.coordinate_names = list(d["coordinate_names"])
        self.reaction_names = list(d["reaction_names"])
        self.steps = dict(d["steps"])
        self.stats = dict(d["stats"])
        self.model = dict(d["model"])
        self.settings = dict(d["settings"])
        self.complete = bool(d["complete"])
        self.state = str(d["state"])
        self.message = str(d["message"])
        self.t_reached = float(d["t_reached"])
        self.summary = str(d["summary"])

    def coordinate(self, name):
        """The history of one coordinate by name (``"crank.phi"``): positions[:, i]."""
        try:
            return self.positions[:, self.coordinate_names.index(name)]
        except ValueError:
            raise KeyError(f"no coordinate named {name!r} (e.g. "
                           f"{self.coordinate_names[:3]})") from None

    def __repr__(self):
        return (f"<strata.SimulationResult {self.model['name']!r}: {len(self.time)} rows x "
                f"{self.positions.shape[1]} coordinates, t = 0..{self.t_reached:g} s, "
                f"{self.stats['steps']} steps, "
                f"{'complete' if self.complete else 'PARTIAL'}>")


def _plain(x):
    """json.dumps `default`: NumPy arrays and scalars as lists and numbers."""
    if isinstance(x, _np.ndarray):
        return x.tolist()
    if isinstance(x, _np.generic):
        return x.item()
    raise TypeError(f"{type(x).__name__} is not a JSON value")


def generate_model(spec):
    """A generated model as a dict in the model-file schema, as
    ``strata simulate --generate SPEC --write-model FILE`` writes it: "andrews",
    "tracked:N", "lattice:N", "flexible:NX[xNYxNZ]", "chain:N", "chain2d:N". Edit it and
    pass it to :func:`simulate`. Raises InvalidInputError for an unknown spec."""
    return _json.loads(_strata._generate_model(str(spec)))


def simulate(model=None, *, generate=None, t_end=None, step=None, order=None, device="auto",
             threads=0, full_newton=False, anderson_depth=None, newton_tol=None,
             variable_step=False, rtol=1e-4,
             atol=1e-6, max_step=None, output_interval=None, output_dir=None, vtk=False,
             dump_matrix=None, dump_step=1, dense_reference=False, condensation=True,
             solver_options=None):
    """Runs a multibody simulation and returns its time histories as NumPy arrays.

    Parameters
    ----------
    model : str, os.PathLike or dict
        A model file (JSON, docs/model-format.md), or the model itself as a dict in that
        schema (values may be NumPy arrays or scalars). Give either model or generate.
    generate : str, optional
        A generated model instead: "andrews", "tracked:N", "lattice:N",
        "flexible:NX[xNYxNZ]", "chain:N", "chain2d:N" (as ``--generate``).
    t_end, step : float, optional
        End time and (first) step size in s; default: the model's ``simulation`` values
        (1 s and 1e-3 s when absent).
    order : int, optional
        BDF order 1..5 (the largest one with variable_step); default: the model's (2).
    device : {"auto", "cpu", "gpu"}
        Where strata factorizes the Newton matrices ("auto": a GPU when the build and the
        machine have one).
    threads : int
        Host threads for strata and the assembly (0: automatic).
    full_newton : bool
        Refactorize at every Newton iteration (default: modified Newton).
    anderson_depth : int, optional
        Modified Newton: Anderson acceleration over this many past updates while a factor
        is reused, 0..10 (default 3; 0: off).
    newton_tol : float, optional
        Relative Newton tolerance (default: the model's, else 1e-6).
    variable_step : bool
        Variable step size and order with local error control (rtol, atol; max_step in s,
        default t_end/10); ``step`` is the first step.
    output_interval : float, optional
        Seconds between rows of the histories (default, or 0: the model's
        ``output_interval``, which is 0 — every step — when absent). The histories take
        8·k·(3n + r) bytes: use it for long runs of large models.
    output_dir : str, optional
        Also write the CSV files of ``strata simulate --output`` (positions, velocities,
        accelerations, reactions, steps .csv, status.json) there; vtk=True adds the
        ParaView series. As with the command line, the histories are named
        ``NAME.partial.csv`` while the run goes on and stay so when it stops early
        (status.json then has ``"partial": true`` and ``"state": "failed"``); only a
        complete run renames them ``NAME.csv``. Histories of an earlier run in the folder
        are removed first.
    dump_matrix : str, optional
        Write the Newton matrix and right-hand side of step ``dump_step`` to this folder
        (Matrix Market).
    dense_reference : bool
        Solve with dense LAPACK LU instead of strata (diagnosis of small models).
    condensation : bool
        Eliminate the Newton matrix's BDF relations before the sparse solve where they are
        a third of its rows or more (default; docs/formulation.md §5); False factors the
        full matrix (``--no-condensation``).
    solver_options : dict, optional
        Any strata option for the Newton matrices by its name, as the command line's
        ``--solver-option NAME=VALUE``: the names of ``strata::Options``' fields
        (``{"ordering": "amd", "pivot_threshold": 0.1, "pivoting": "delayed"}``); values
        are given as their text (booleans as true/false). A bad name or value raises
        InvalidInputError naming the option.

    Returns
    -------
    SimulationResult
        ``time`` (k,), ``positions``/``velocities``/``accelerations`` (k, n),
        ``reactions`` (k, r), all float64 in SI units; ``steps`` (per-step statistics),
        ``stats`` (Newton and solver totals), ``summary``. See :class:`SimulationResult`.

    Raises
    ------
    ModelError (an InvalidInputError, a ValueError)
        The model is wrong: invalid JSON, a missing or unknown key, a bad value. The
        message names the file (or ``<dict>``) and the JSON path, as the command line's.
    InvalidInputError
        A bad setting (negative time, order outside 1..5, unknown device) or an unknown
        generator spec; redundant constraints.
    SimulationError (a strata.Error)
        The integration cannot go on (Newton fails at the minimum step, inconsistent
        initial conditions). When it stopped after some steps, ``err.result`` holds the
        partial SimulationResult (complete=False, state "failed"); with output_dir, the
        same rows are in the ``NAME.partial.csv`` files there.
    TypeError
        model is neither a path nor a dict, or the dict holds a value JSON cannot hold.
    NotSupportedError
        device="gpu" in a build or on a machine without one.

    The GIL is released while the model is built and integrated.
    """
    if (model is None) == (generate is None):
        raise InvalidInputError("give either a model (a path or a dict) or generate=SPEC, "
                                "not both" if model is not None else
                                "give a model (a path or a dict) or generate=SPEC")
    if generate is not None:
        kind, source, name = "generate", str(generate), str(generate)
    elif isinstance(model, dict):
        try:
            source = _json.dumps(model, default=_plain, allow_nan=False)
        except ValueError as e:  # NaN or Inf
            raise ModelError(f"<dict>: {e}") from None
        except TypeError as e:
            raise TypeError(f"model dict: {e}") from None
        kind, name = "json", "<dict>"
    elif isinstance(model, (str, _os.PathLike)):
        kind = "path"
        source = name = _os.fspath(model)
    else:
        raise TypeError(f"model must be a path (str or os.PathLike) or a dict, got "
                        f"{type(model).__name__}")
    if not isinstance(device, str):  # which names: the extension's shared vocabulary
        raise InvalidInputError(f"device must be a string, got {device!r}")
    settings = {
        "t_end": float(t_end or 0), "step": float(step or 0), "order": int(order or 0),
        "device": device, "threads": int(threads), "full_newton": bool(full_newton),
        "anderson_depth": -1 if anderson_depth is None else int(anderson_depth),
        "newton_tol": float(newton_tol or 0), "variable_step": bool(variable_step),
        "rtol": float(rtol), "atol": float(atol), "max_step": float(max_step or 0),
        "output_interval": float(output_interval or 0), "vtk": bool(vtk),
        "dump_step": int(dump_step), "dense_reference": bool(dense_reference),
        "condensation": bool(condensation),
    }
    for key, value in (("t_end", t_end), ("step", step), ("order", order)):
        if value is not None and not value > 0:
            raise InvalidInputError(f"{key} must be positive, got {value!r}")
    if solver_options is not None:
        if not isinstance(solver_options, dict):
            raise TypeError(f"solver_options must be a dict, got {type(solver_options).__name__}")
        settings["solver_options"] = {
            str(k): ("true" if v else "false") if isinstance(v, bool) else str(v)
            for k, v in solver_options.items()}
    if output_dir is not None:
        settings["output_dir"] = _os.fspath(output_dir)
    if dump_matrix is not None:
        settings["dump_dir"] = _os.fspath(dump_matrix)
    result = SimulationResult(_strata._simulate(kind, source, name, settings))
    if not result.complete:
        err = SimulationError(f"the simulation stopped at t = {result.t_reached:.9g} s: "
                              f"{result.message}")
        err.result = result
        raise err
    return result
