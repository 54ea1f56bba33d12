"""Tests of the plots: strata.plot(result), `strata simulate --plot`, `strata plot DIR`.

The PNG files are read back by matplotlib's own reader (matplotlib.image.imread) and must
have the size the figure asks for and be drawn on (not blank); the data behind the plots
come from the run's steps.csv, so a run whose steps.csv is missing or has a wrong column
must be refused with a message. Run by ctest (`python_api`) with STRATA_CLI set.
"""

import os
import shutil
import subprocess

import numpy as np
import pytest

import strata

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))

mpl_image = pytest.importorskip("matplotlib.image", reason="strata.plot needs matplotlib")


def cli_path():
    path = os.environ.get("STRATA_CLI") or os.path.join(REPO, "build", "strata")
    if not os.access(path, os.X_OK):
        pytest.skip(f"the strata command is not built ({path}); set STRATA_CLI")
    return path


def check_png(path, width, height):
    """A PNG of width × height pixels with some drawing on it (not one colour)."""
    assert os.path.getsize(path) > 10_000, path
    img = mpl_image.imread(path)
    assert img.shape[:2] == (height, width), (path, img.shape)
    assert np.unique(img.reshape(-1, img.shape[2]), axis=0).shape[0] > 50, path


def test_plot_result(tmp_path):
    r = strata.simulate(generate="andrews", t_end=0.002, step=1e-4)
    written = strata.plot(r, tmp_path, coordinates=["K1.phi", "K2.x"])
    assert written == [str(tmp_path / "summary.png"), str(tmp_path / "coordinates.png")]
    check_png(written[0], 900, 1200)        # figsize 9 × 12 in at 100 dpi
    check_png(written[1], 900, 2 * 220 + 80)  # 2.2 in per coordinate + 0.8 in
    with pytest.raises(ValueError, match="no coordinate named nope.x"):
        strata.plot(r, tmp_path, coordinates="nope.x")


def test_cli_simulate_plot_and_plot_dir(tmp_path):
    out = tmp_path / "run"
    proc = subprocess.run([cli_path(), "simulate", "--generate", "chain:3", "--t-end", "0.01",
                           "--output", str(out), "--quiet", "--plot-coordinates",
                           "link1.x,link1.z"], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    check_png(out / "summary.png", 900, 1200)
    check_png(out / "coordinates.png", 900, 2 * 220 + 80)
    # strata plot DIR redraws from the folder alone
    os.remove(out / "summary.png")
    proc = subprocess.run([cli_path(), "plot", str(out)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    check_png(out / "summary.png", 900, 1200)
    # an unknown coordinate: exit 1 and a message naming it
    proc = subprocess.run([cli_path(), "plot", str(out), "--coordinates", "link9.q"],
                          capture_output=True, text=True)
    assert proc.returncode == 1
    assert "strata: error: no coordinate named link9.q" in proc.stderr


def test_cli_plot_refuses_other_folders(tmp_path):
    # no steps.csv at all
    proc = subprocess.run([cli_path(), "plot", str(tmp_path)], capture_output=True, text=True)
    assert proc.returncode == 1
    assert "no steps.csv" in proc.stderr
    # a steps.csv without the energy columns
    (tmp_path / "steps.csv").write_text("step,time,h\n0,0,0\n1,0.001,0.001\n")
    proc = subprocess.run([cli_path(), "plot", str(tmp_path)], capture_output=True, text=True)
    assert proc.returncode == 1
    assert "missing columns" in proc.stderr and "kinetic_energy" in proc.stderr
    # a folder that does not exist is a usage error (non-zero, CLI11's message)
    proc = subprocess.run([cli_path(), "plot", str(tmp_path / "nowhere")], capture_output=True,
                          text=True)
    assert proc.returncode != 0 and "nowhere" in proc.stderr


def test_cli_plot_without_matplotlib(tmp_path):
    """An interpreter without matplotlib: a clear error, exit 1."""
    out = tmp_path / "run"
    subprocess.run([cli_path(), "simulate", "--generate", "chain:2", "--t-end", "0.002",
                    "--output", str(out), "--quiet"], check=True, capture_output=True)
    fake = tmp_path / "python3"  # a "Python" that cannot import matplotlib
    fake.write_text("#!/bin/sh\nexit 3\n")
    fake.chmod(0o755)
    proc = subprocess.run([cli_path(), "plot", str(out)], capture_output=True, text=True,
                          env={**os.environ, "STRATA_PYTHON": str(fake)})
    assert proc.returncode == 1
    assert "plotting needs Python 3 with matplotlib" in proc.stderr
    assert not (out / "summary.png").exists()


def test_plot_partial_run(tmp_path):
    """A run that stopped early is plotted from its *.partial.csv files, marked so."""
    out = tmp_path / "run"
    subprocess.run([cli_path(), "simulate", "--generate", "chain:2", "--t-end", "0.003",
                    "--output", str(out), "--quiet"], check=True, capture_output=True)
    for stem in ("steps", "positions"):
        shutil.move(out / f"{stem}.csv", out / f"{stem}.partial.csv")
    status = (out / "status.json").read_text().replace('"complete": true', '"complete": false')
    (out / "status.json").write_text(status.replace('"state": "complete"', '"state": "failed"'))
    written = strata.plot(str(out), coordinates="link1.x")
    assert written == [str(out / "summary.png"), str(out / "coordinates.png")]
    check_png(written[0], 900, 1200)
