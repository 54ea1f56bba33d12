"""Plots of a multibody simulation: ``strata.plot(result)``, ``strata simulate --plot`` and
``strata plot DIR``.

Writes ``summary.png`` (energy, constraint violation, step size, Newton iterations and
factorizations, and time per step in the solver and the assembly, against time) and, when
coordinates are named, ``coordinates.png`` (one panel per coordinate). The data come from
a :class:`strata.SimulationResult` or from an output folder of ``strata simulate`` (its
``steps.csv`` and ``positions.csv``, or the ``*.partial.csv`` files of a run that stopped).

This file imports nothing from strata: the command line runs it as a script
(``python3 -c <this file> DIR [--coordinates a,b] [--title T]``), so it works with any
Python 3 that has matplotlib. Exit status of the script: 0 written, 1 bad input (message
on stderr, starting "strata: error:"), 3 matplotlib missing (the command line then tries
another interpreter).
"""

import csv
import json
import os
import sys

__all__ = ["plot"]

STEP_COLUMNS = ("step", "time", "h", "order", "newton_iterations", "factorizations", "rejected",
                "assembly_seconds", "solver_seconds", "kinetic_energy", "potential_energy",
                "total_energy", "position_violation", "velocity_violation")


class PlotInputError(ValueError):
    """The output folder or the coordinates asked for are not usable."""


def _read_csv(path):
    """(header, rows as lists of float) of a CSV file of numbers."""
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    if not rows:
        raise PlotInputError(f"{path}: empty file")
    try:
        data = [[float(v) for v in r] for r in rows[1:] if r]
    except ValueError as e:
        raise PlotInputError(f"{path}: not a table of numbers ({e})") from None
    return rows[0], data


def _history_file(folder, stem):
    """folder/stem.csv, else folder/stem.partial.csv (a run that stopped early), else None."""
    for name in (stem + ".csv", stem + ".partial.csv"):
        path = os.path.join(folder, name)
        if os.path.isfile(path):
            return path
    return None


def _units(name):
    """The unit of a coordinate by its suffix (docs/model-format.md): positions in m,
    planar angles in rad, Euler parameters dimensionless."""
    suffix = name.rsplit(".", 1)[-1]
    if suffix in ("x", "y", "z"):
        return "m"
    if suffix == "phi":
        return "rad"
    if suffix in ("e0", "e1", "e2", "e3"):
        return "1"
    return "SI"


class _Data:
    """What the plots need: per-step columns, coordinate histories, a title."""

    def __init__(self, steps, time, positions, names, title):
        self.steps = steps          # {column: list of float}, entry 0 the initial state
        self.time = time            # output times of positions, s
        self.positions = positions  # list of rows, one per output time
        self.names = names          # coordinate names, columns of positions
        self.title = title

    @classmethod
    def from_folder(cls, folder, title=None):
        steps_path = _history_file(folder, "steps")
        if steps_path is None:
            raise PlotInputError(f"{folder}: no steps.csv (nor steps.partial.csv): not an "
                                 f"output folder of strata simulate")
        header, rows = _read_csv(steps_path)
        missing = [c for c in STEP_COLUMNS if c not in header]
        if missing:
            raise PlotInputError(f"{steps_path}: missing columns {', '.join(missing)}")
        steps = {c: [r[header.index(c)] for r in rows] for c in STEP_COLUMNS}
        time, positions, names = [], [], []
        pos_path = _history_file(folder, "positions")
        if pos_path is not None:
            pheader, prows = _read_csv(pos_path)
            names = pheader[1:]
            time = [r[0] for r in prows]
            positions = [r[1:] for r in prows]
        state = ""
        try:
            with open(os.path.join(folder, "status.json")) as f:
                status = json.load(f)
            if not status.get("complete", True):
                state = f" ({status.get('state', 'partial')} at t = {status.get('t_reached')} s)"
        except (OSError, ValueError):
            pass
        if title is None:
            title = os.path.basename(os.path.normpath(os.path.abspath(folder)))
        return cls(steps, time, positions, names, title + state)

    @classmethod
    def from_result(cls, result, title=None):
        steps = {c: [float(v) for v in result.steps[c]] for c in STEP_COLUMNS}
        if title is None:
            title = str(result.model.get("name", "simulation"))
            if not result.complete:
                title += f" ({result.state} at t = {result.t_reached:g} s)"
        return cls(steps, [float(t) for t in result.time], result.positions.tolist(),
                   list(result.coordinate_names), title)


def _positive(values, floor):
    """values for a log axis: zeros and negatives raised to floor."""
    return [v if v > floor else floor for v in values]


def _summary(data, path):
    from matplotlib.figure import Figure  # Agg through savefig; pyplot state untouched

    s = data.steps
    t0, t = s["time"], s["time"][1:]  # entry 0: the initial state, no step
    fig = Figure(figsize=(9, 12), dpi=100)
    axes = fig.subplots(5, 1, sharex=True)
    fig.suptitle(f"strata simulate: {data.title}", fontsize=12)

    ax = axes[0]
    ax.plot(t0, s["kinetic_energy"], label="kinetic")
    ax.plot(t0, s["potential_energy"], label="potential")
    ax.plot(t0, s["total_energy"], label="total", color="black", linewidth=1.2)
    ax.set_ylabel("energy [J]")
    ax.legend(loc="best", fontsize=8)
    ax.set_title("Energy", fontsize=10, loc="left")

    ax = axes[1]
    floor = 1e-18
    ax.semilogy(t0, _positive(s["position_violation"], floor), label="position max |Φ| [m, rad]")
    ax.semilogy(t0, _positive(s["velocity_violation"], floor),
                label="velocity max |dΦ/dt| [m/s, rad/s]")
    ax.set_ylabel("max |Φ|, max |dΦ/dt|")
    ax.legend(loc="best", fontsize=8)
    ax.set_title("Constraint violation (zeros drawn at 1e-18)", fontsize=10, loc="left")

    ax = axes[2]
    h = s["h"][1:]
    ax.step(t, h, where="post", label="step size h")
    rejected = [(ti, hi) for ti, hi, r in zip(t, h, s["rejected"][1:]) if r > 0]
    if rejected:
        ax.plot([x for x, _ in rejected], [y for _, y in rejected], "rx", markersize=4,
                label="step after rejections")
    if h and max(h) > 4 * min(v for v in h if v > 0):
        ax.set_yscale("log")
    ax.set_ylabel("h [s]")
    ax.legend(loc="best", fontsize=8)
    ax.set_title("Step size", fontsize=10, loc="left")

    ax = axes[3]
    ax.step(t, s["newton_iterations"][1:], where="post", label="Newton iterations",
            linewidth=0.8)
    ax.step(t, s["factorizations"][1:], where="post", label="factorizations", linewidth=0.8)
    ax.set_ylabel("per step [count]")
    ax.set_ylim(bottom=0)
    ax.legend(loc="best", fontsize=8)
    ax.set_title("Newton iterations and factorizations per step", fontsize=10, loc="left")

    ax = axes[4]
    ax.plot(t, [1e3 * v for v in s["solver_seconds"][1:]], label="strata (solver)",
            linewidth=0.8)
    ax.plot(t, [1e3 * v for v in s["assembly_seconds"][1:]], label="assembly", linewidth=0.8)
    ax.set_ylabel("wall time per step [ms]")
    ax.set_ylim(bottom=0)
    ax.legend(loc="best", fontsize=8)
    ax.set_title("Time per step", fontsize=10, loc="left")
    ax.set_xlabel("time [s]")
    for ax in axes:
        ax.grid(True, alpha=0.3)
    fig.tight_layout()
    fig.savefig(path, metadata={"Software": None})


def _coordinates(data, names, path):
    from matplotlib.figure import Figure

    if not data.names:
        raise PlotInputError("no positions to plot (positions.csv missing)")
    unknown = [n for n in names if n not in data.names]
    if unknown:
        raise PlotInputError(f"no coordinate named {', '.join(unknown)}; the coordinates are "
                             f"BODY.x, BODY.y, BODY.z, BODY.phi (planar), BODY.e0..e3, e.g. "
                             f"{', '.join(data.names[:4])}")
    fig = Figure(figsize=(9, 2.2 * len(names) + 0.8), dpi=100)
    axes = fig.subplots(len(names), 1, sharex=True, squeeze=False)[:, 0]
    fig.suptitle(f"strata simulate: {data.title}", fontsize=12)
    for ax, name in zip(axes, names):
        j = data.names.index(name)
        ax.plot(data.time, [row[j] for row in data.positions])
        ax.set_ylabel(f"{name} [{_units(name)}]")
        ax.grid(True, alpha=0.3)
    axes[-1].set_xlabel("time [s]")
    fig.tight_layout()
    fig.savefig(path, metadata={"Software": None})


def _coordinate_list(coordinates):
    if coordinates is None:
        return []
    if isinstance(coordinates, str):
        coordinates = coordinates.split(",")
    return [c.strip() for c in coordinates if c.strip()]


def plot(result, directory=None, coordinates=None, title=None):
    """Plots a simulation: writes ``summary.png`` and, when ``coordinates`` are given,
    ``coordinates.png`` into ``directory``; returns the paths written.

    Parameters
    ----------
    result : SimulationResult, str or os.PathLike
        A result of :func:`strata.simulate`, or an output folder of ``strata simulate``
        (``steps.csv`` and ``positions.csv``, or their ``.partial.csv`` forms).
    directory : str or os.PathLike, optional
        Where to write the PNG files; default: the output folder itself, or the current
        folder for a SimulationResult.
    coordinates : str or list of str, optional
        Coordinates to plot against time, by name (``"chassis.x"``, ``"crank.phi"``; a str
        is split at commas). Units: m for x/y/z, rad for phi, 1 for Euler parameters.
    title : str, optional
        Title of the figures (default: the model's name, or the folder's).

    summary.png has five panels against time [s]: kinetic, potential and total energy [J];
    the largest position and velocity constraint violation (log scale); the step size h
    [s] (rejections marked); Newton iterations and factorizations per step; wall time per
    step in strata and in the assembly [ms]. Needs matplotlib (ImportError otherwise);
    raises ValueError for a folder that is not an output folder or an unknown coordinate.
    """
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        raise ImportError("strata.plot needs matplotlib (pip install matplotlib, or Debian's "
                          "python3-matplotlib)") from None
    if isinstance(result, (str, os.PathLike)):
        folder = os.fspath(result)
        data = _Data.from_folder(folder, title)
        out = folder if directory is None else os.fspath(directory)
    else:
        data = _Data.from_result(result, title)
        out = "." if directory is None else os.fspath(directory)
    names = _coordinate_list(coordinates)
    os.makedirs(out, exist_ok=True)
    written = [os.path.join(out, "summary.png")]
    _summary(data, written[0])
    if names:
        written.append(os.path.join(out, "coordinates.png"))
        _coordinates(data, names, written[1])
    return written


def _main(argv):
    """The command line's entry: DIR [--coordinates a,b] [--title T]."""
    import argparse

    ap = argparse.ArgumentParser(prog="strata plot")
    ap.add_argument("folder")
    ap.add_argument("--coordinates", default="")
    ap.add_argument("--title", default=None)
    args = ap.parse_args(argv)
    try:
        import matplotlib  # noqa: F401
    except ImportError:
        return 3  # silent: the command line tries the next interpreter, then says why
    try:
        for path in plot(args.folder, coordinates=args.coordinates, title=args.title):
            print(f"plot                  {path}")
    except (PlotInputError, OSError) as e:
        print(f"strata: error: {e}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(_main(sys.argv[1:]))
