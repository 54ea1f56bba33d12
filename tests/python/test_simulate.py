"""Tests of strata.simulate (the multibody engine from Python) against the command line.

The reference is the `strata simulate` binary run on the same model: its CSV files
(written with 17 significant digits) must hold the histories strata.simulate returns.
Run by ctest (test `python_api`) with STRATA_CLI set to the built binary; by hand:
    PYTHONPATH=build/python STRATA_CLI=build/strata /usr/bin/python3 -m pytest -q \
        tests/python/test_simulate.py
Every run is short (under a second each on two cores).
"""

import copy
import csv
import json
import math
import os
import subprocess

import numpy as np
import pytest

import strata

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
MODELS = os.path.join(REPO, "models")


def cli_path():
    path = os.environ.get("STRATA_CLI") or os.path.join(REPO, "build", "strata")
    if not os.access(path, os.X_OK):
        pytest.skip(f"the strata command is not built ({path}); set STRATA_CLI")
    return path


def read_csv(path):
    with open(path, newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array([[float(v) for v in r] for r in rows[1:]])


def run_cli(tmp_path, *args):
    out = tmp_path / "cli"
    proc = subprocess.run([cli_path(), "simulate", *args, "--output", str(out), "--quiet"],
                          capture_output=True, text=True)
    return proc, out


def slider_crank_beyond_reach():
    """A slider–crank whose slider is driven past the reach of crank + rod (2.5 m): the
    constraints have no solution after t = 0.5 s (as in test_mbd_model_errors.cpp)."""
    th = math.acos((4 + 1 - 2.25) / 4)
    return {
        "type": "planar",
        "bodies": [
            {"name": "crank", "mass": 1, "inertia": 0.1, "position": [0, 0], "angle": th},
            {"name": "slider", "mass": 1, "inertia": 0.1, "position": [2.0, 0]},
        ],
        "joints": [
            {"name": "pivot", "type": "revolute", "body_i": "ground", "body_j": "crank",
             "point": [0, 0]},
            {"name": "guide", "type": "translational", "body_i": "ground", "body_j": "slider",
             "point": [2.0, 0], "axis": [1, 0]},
            {"name": "rod", "type": "distance", "body_i": "crank", "body_j": "slider",
             "point_i": [1, 0], "point_j": [0, 0], "length": 1.5},
            {"name": "push", "type": "translation_driver", "body_i": "ground",
             "body_j": "slider", "point": [2.0, 0], "axis": [1, 0],
             "motion": {"polynomial": [0, 1]}},
        ],
    }


# ---------------------------------------------------------------------------------------
# the same histories as the command line
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("model, t_end, extra", [
    ("pendulum_chain.json", 0.05, {}),                       # spatial: Euler parameters
    ("andrews_squeezer.json", 0.002, {"output_interval": 5e-4}),  # planar, a driven torque
])
def test_histories_equal_the_cli_output(tmp_path, model, t_end, extra):
    path = os.path.join(MODELS, model)
    args = [path, "--t-end", str(t_end), "--threads", "1"]
    if "output_interval" in extra:
        args += ["--output-interval", str(extra["output_interval"])]
    proc, out = run_cli(tmp_path, *args)
    assert proc.returncode == 0, proc.stderr
    r = strata.simulate(path, t_end=t_end, threads=1, **extra)

    for name, hist in (("positions", r.positions), ("velocities", r.velocities),
                       ("accelerations", r.accelerations)):
        header, data = read_csv(out / f"{name}.csv")
        assert header == ["time"] + r.coordinate_names
        assert hist.dtype == np.float64 and hist.shape == (len(r.time), r.model["n"])
        assert data.shape == (len(r.time), 1 + r.model["n"])
        np.testing.assert_allclose(r.time, data[:, 0], rtol=1e-14, atol=0)
        np.testing.assert_allclose(hist, data[:, 1:], rtol=1e-9, atol=1e-12)
    header, data = read_csv(out / "reactions.csv")
    assert header == ["time"] + r.reaction_names
    np.testing.assert_allclose(r.reactions, data[:, 1:], rtol=1e-7, atol=1e-9)

    header, data = read_csv(out / "steps.csv")
    assert list(r.steps) == header
    assert data.shape[0] == len(r.steps["step"]) == r.stats["steps"] + 1
    for k, col in enumerate(header):
        if col.endswith("_seconds"):
            continue  # wall times differ between runs
        np.testing.assert_allclose(r.steps[col], data[:, k], rtol=1e-6, atol=1e-12,
                                   err_msg=col)
    # every step is an output row when output_interval is not set
    if "output_interval" not in extra:
        np.testing.assert_array_equal(r.time, r.steps["time"])
    else:
        assert len(r.time) < len(r.steps["time"])
    assert r.time[-1] == pytest.approx(t_end, rel=1e-12)
    assert r.stats["newton_iterations"] == r.steps["newton_iterations"].sum()
    assert r.stats["factorizations"] == r.steps["factorizations"].sum()
    assert r.stats["jacobian_size"] > 0 and r.stats["factor_nnz"] > 0
    # the summary is the CLI's (up to wall times)
    assert r.summary.splitlines()[0] in proc.stdout


def test_histories_are_consistent_with_physics():
    """Independent of the CLI: the chain of spatial links keeps |p| = 1 for the Euler
    parameters, and the velocities are the time derivative of the positions."""
    r = strata.simulate(os.path.join(MODELS, "pendulum_chain.json"), t_end=0.04)
    names = r.coordinate_names
    for body in {n.split(".")[0] for n in names}:
        e = r.positions[:, [names.index(f"{body}.e{k}") for k in range(4)]]
        np.testing.assert_allclose(np.linalg.norm(e, axis=1), 1.0, atol=1e-8)
    # central differences of q against v at the interior points (step 1e-3, BDF2)
    dq = (r.positions[2:] - r.positions[:-2]) / (r.time[2:] - r.time[:-2])[:, None]
    scale = np.abs(r.velocities).max()
    assert np.abs(dq - r.velocities[1:-1]).max() < 1e-2 * scale


# ---------------------------------------------------------------------------------------
# dict input
# ---------------------------------------------------------------------------------------


def test_dict_input_equals_file_input():
    path = os.path.join(MODELS, "pendulum_chain.json")
    with open(path) as f:
        doc = json.load(f)
    from_file = strata.simulate(path, t_end=0.02, threads=1)
    from_dict = strata.simulate(doc, t_end=0.02, threads=1)
    # NumPy values in the dict are accepted
    doc_np = copy.deepcopy(doc)
    for b in doc_np["bodies"]:
        b["position"] = np.array(b["position"])
        b["mass"] = np.float64(b["mass"])
    from_np = strata.simulate(doc_np, t_end=0.02, threads=1)
    for r in (from_dict, from_np):
        assert r.coordinate_names == from_file.coordinate_names
        assert r.model == from_file.model
        for a in ("time", "positions", "velocities", "accelerations", "reactions"):
            np.testing.assert_array_equal(getattr(r, a), getattr(from_file, a), err_msg=a)


def test_generated_model_as_dict_and_by_name(tmp_path):
    doc = strata.generate_model("chain:3")
    assert isinstance(doc, dict) and len(doc["bodies"]) == 3
    a = strata.simulate(doc, t_end=0.01, threads=1)
    b = strata.simulate(generate="chain:3", t_end=0.01, threads=1)
    np.testing.assert_array_equal(a.positions, b.positions)
    # the CLI's --write-model writes the same document
    proc = subprocess.run([cli_path(), "simulate", "--generate", "chain:3", "--t-end", "0.001",
                           "--write-model", str(tmp_path / "m.json"), "--output", str(tmp_path / "o"),
                           "--quiet"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    with open(tmp_path / "m.json") as f:
        assert json.load(f) == doc


def test_model_settings_and_overrides():
    r = strata.simulate(generate="chain2d:2", t_end=0.01, step=2e-3, order=1)
    assert r.settings["t_end"] == 0.01 and r.settings["step"] == 2e-3
    assert r.settings["order"] == 1
    assert r.time[-1] == pytest.approx(0.01, rel=1e-12) and r.stats["steps"] >= 5
    assert r.steps["h"].max() <= 2e-3 * (1 + 1e-12)
    assert set(r.steps["order"][1:]) == {1}
    doc = strata.generate_model("chain2d:2")
    doc["simulation"] = {"t_end": 0.004, "step": 1e-3, "output_interval": 2e-3}
    r = strata.simulate(doc)
    assert r.settings["t_end"] == 0.004 and r.settings["output_interval"] == 2e-3
    # a row at t = 0, at the first step at or past each multiple of 2 ms, and at the end
    t = r.steps["time"]
    expected = [0.0] + [t[np.argmax(t >= k * 2e-3 - 1e-12)] for k in (1, 2)]
    np.testing.assert_array_equal(r.time, expected)
    assert r.positions.shape == (3, r.model["n"])


def test_output_dir_writes_the_cli_files(tmp_path):
    out = tmp_path / "run"
    r = strata.simulate(generate="chain2d:2", t_end=0.005, output_dir=out)
    header, data = read_csv(out / "positions.csv")
    np.testing.assert_allclose(data[:, 1:], r.positions, rtol=1e-15, atol=0)
    assert r.state == "complete"
    assert not list(out.glob("*.partial.csv"))
    with open(out / "status.json") as f:
        status = json.load(f)
    assert status["complete"] is True and status["state"] == "complete"


# ---------------------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------------------


def test_error_classes():
    assert issubclass(strata.ModelError, strata.InvalidInputError)
    assert issubclass(strata.ModelError, ValueError)
    assert issubclass(strata.SimulationError, strata.Error)


def test_missing_field_names_the_path_like_the_cli(tmp_path):
    with open(os.path.join(MODELS, "andrews_squeezer.json")) as f:
        doc = json.load(f)
    del doc["bodies"][2]["mass"]
    with pytest.raises(strata.ModelError) as dict_err:
        strata.simulate(doc)
    msg = str(dict_err.value)
    assert msg == '<dict>: bodies[2]: missing required key "mass"'
    path = tmp_path / "bad.json"
    path.write_text(json.dumps(doc))
    with pytest.raises(strata.ModelError) as file_err:
        strata.simulate(str(path))
    assert str(file_err.value) == msg.replace("<dict>", "bad.json")
    proc = subprocess.run([cli_path(), "simulate", str(path), "--quiet"], capture_output=True,
                          text=True)
    assert proc.returncode == 1
    assert f"strata: error: {file_err.value}" in proc.stderr


def test_bad_values_and_unknown_keys():
    doc = strata.generate_model("chain2d:2")
    bad = copy.deepcopy(doc)
    bad["bodies"][0]["mass"] = "heavy"
    with pytest.raises(strata.ModelError, match=r"^<dict>: bodies\[0\]\.mass: expected a number"):
        strata.simulate(bad)
    bad = copy.deepcopy(doc)
    bad["bodies"][1]["mas"] = 1
    with pytest.raises(strata.ModelError, match=r"bodies\[1\]\.mas: unknown key"):
        strata.simulate(bad)
    bad = copy.deepcopy(doc)
    bad["joints"][0]["body_j"] = "wheel7"
    with pytest.raises(strata.ModelError, match="unknown body 'wheel7'"):
        strata.simulate(bad)
    bad = copy.deepcopy(doc)
    bad["bodies"][0]["position"][0] = float("nan")
    with pytest.raises(strata.ModelError, match="<dict>: .*Out of range float"):
        strata.simulate(bad)
    bad = copy.deepcopy(doc)
    bad["bodies"][0]["mass"] = object()
    with pytest.raises(TypeError, match="model dict"):
        strata.simulate(bad)


def test_bad_json_file_gives_line_and_column(tmp_path):
    path = tmp_path / "broken.json"
    path.write_text('{\n  "type": "planar",\n  "bodies": [\n    {"name": "a",, }\n')
    with pytest.raises(strata.ModelError, match=r"broken\.json:4:\d+: invalid JSON"):
        strata.simulate(str(path))
    with pytest.raises(strata.ModelError, match="cannot open"):
        strata.simulate(str(tmp_path / "missing.json"))


def test_bad_settings():
    with pytest.raises(strata.InvalidInputError, match="order must be 1..5"):
        strata.simulate(generate="chain2d:1", order=7)
    with pytest.raises(strata.InvalidInputError, match="t_end must be positive"):
        strata.simulate(generate="chain2d:1", t_end=-1)
    with pytest.raises(strata.InvalidInputError, match="device"):
        strata.simulate(generate="chain2d:1", device="tpu")
    with pytest.raises(strata.InvalidInputError, match="rtol"):
        strata.simulate(generate="chain2d:1", rtol=0)
    with pytest.raises(strata.InvalidInputError, match="not both"):
        strata.simulate(os.path.join(MODELS, "pendulum_chain.json"), generate="chain:2")
    with pytest.raises(strata.InvalidInputError, match="give a model"):
        strata.simulate()
    with pytest.raises(strata.InvalidInputError, match="unknown"):
        strata.simulate(generate="submarine:3")
    with pytest.raises(TypeError, match="path .* or a dict"):
        strata.simulate(42)


def test_solver_options_reach_the_solver():
    """solver_options sets any strata option of the Newton matrices by name (the command
    line's --solver-option): another ordering gives another factor, the same motion."""
    a = strata.simulate(generate="lattice:2", t_end=0.004, threads=1,
                        solver_options={"ordering": "natural", "reproducible": True})
    b = strata.simulate(generate="lattice:2", t_end=0.004, threads=1)
    assert a.stats["factor_nnz"] != b.stats["factor_nnz"]
    np.testing.assert_allclose(a.positions, b.positions, rtol=1e-8, atol=1e-10)
    with pytest.raises(strata.InvalidInputError, match="unknown option 'ordring'"):
        strata.simulate(generate="chain2d:1", solver_options={"ordring": "amd"})
    with pytest.raises(strata.InvalidInputError, match="reproducible must be true or false"):
        strata.simulate(generate="chain2d:1", solver_options={"reproducible": "maybe"})
    with pytest.raises(strata.InvalidInputError, match="pivot_threshold must be in"):
        strata.simulate(generate="chain2d:1", solver_options={"pivot_threshold": 0})
    with pytest.raises(TypeError, match="solver_options must be a dict"):
        strata.simulate(generate="chain2d:1", solver_options=["ordering=amd"])


def test_condensation_off_factors_the_full_matrix():
    """condensation=False (the command line's --no-condensation): the full Newton matrix
    goes to the solver (a larger one), the motion is the same, and no host time is spent
    condensing."""
    a = strata.simulate(generate="flexible:4x2x2", t_end=0.004, threads=1)
    b = strata.simulate(generate="flexible:4x2x2", t_end=0.004, threads=1, condensation=False)
    assert "condensed" in a.summary and "condensed" not in b.summary
    assert a.stats["condensation_seconds"] > 0 and b.stats["condensation_seconds"] == 0
    np.testing.assert_allclose(a.positions, b.positions, rtol=1e-8, atol=1e-10)


def test_failure_raises_with_the_partial_result():
    with pytest.raises(strata.SimulationError, match=r"stopped at t = 0\.[345]\d* s: .*did not "
                       r"converge") as err:
        strata.simulate(slider_crank_beyond_reach(), t_end=1.0, step=1e-2)
    r = err.value.result
    assert isinstance(r, strata.SimulationResult) and not r.complete
    assert 0.3 < r.t_reached < 0.51
    assert r.time[-1] == pytest.approx(r.t_reached)
    assert len(r.time) > 20 and r.positions.shape == (len(r.time), 6)
    # the slider follows its driver x = 2 + t up to the failure
    np.testing.assert_allclose(r.coordinate("slider.x"), 2 + r.time, atol=1e-6)
    with pytest.raises(KeyError, match="no coordinate"):
        r.coordinate("slider.z")


def test_failure_leaves_partial_files_like_the_cli(tmp_path):
    """A run that stops early with output_dir: NAME.partial.csv and a partial status.json,
    no NAME.csv, and the partial files hold the rows of err.result."""
    out = tmp_path / "run"
    out.mkdir()
    (out / "positions.csv").write_text("stale\n")  # an earlier run's: removed
    with pytest.raises(strata.SimulationError) as err:
        strata.simulate(slider_crank_beyond_reach(), t_end=1.0, step=1e-2, output_dir=out)
    r = err.value.result
    assert r.state == "failed" and not r.complete
    for name in ("positions", "velocities", "accelerations", "reactions", "steps"):
        assert (out / f"{name}.partial.csv").is_file()
        assert not (out / f"{name}.csv").exists()
    with open(out / "status.json") as f:
        status = json.load(f)
    assert status["state"] == "failed" and status["partial"] is True
    assert status["complete"] is False
    assert status["t_reached"] == pytest.approx(r.t_reached, rel=1e-15)
    header, data = read_csv(out / "positions.partial.csv")
    np.testing.assert_allclose(data[:, 1:], r.positions, rtol=1e-15, atol=0)
    np.testing.assert_allclose(data[:, 0], r.time, rtol=1e-15, atol=0)


def test_gpu_device_is_supported_or_a_clear_error():
    try:
        r = strata.simulate(generate="chain2d:2", t_end=0.002, device="gpu")
    except strata.NotSupportedError as e:
        assert "CUDA" in str(e) or "GPU" in str(e) or "cuda" in str(e)
    else:
        assert r.complete


def test_parallel_threads_give_the_sequential_results():
    """The GIL is released during the run: two simulations in threads at once give the
    same histories as one after the other."""
    import threading

    ref = [strata.simulate(generate=g, t_end=0.01, threads=1) for g in ("chain2d:3", "chain:2")]
    out = [None, None]

    def work(i, g):
        out[i] = strata.simulate(generate=g, t_end=0.01, threads=1)

    threads = [threading.Thread(target=work, args=(i, g))
               for i, g in enumerate(("chain2d:3", "chain:2"))]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for a, b in zip(out, ref):
        np.testing.assert_array_equal(a.positions, b.positions)
        np.testing.assert_array_equal(a.reactions, b.reactions)
