"""The files `strata simulate` and `strata solve` write, read by readers we did not write.

- The ParaView series (`--vtk`): series.pvd parsed with the standard library's XML parser,
  every frame read by meshio (an independent VTK reader); its points, cells and
  orientations are checked against the model file (`--write-model`) and positions.csv.
- The Matrix Market files (`--dump-matrix`, `strata solve --out`): read by
  scipy.io.mmread; the Newton matrix has the size and nnz the run reports, and the
  solution strata writes solves it by scipy's own residual (normwise backward error; the
  matrix is far too ill-conditioned, κ∞ ~ 1e22, for a forward comparison with another
  solver to mean anything).

Run by ctest (`python_api`) with STRATA_CLI set to the built binary.
"""

import csv
import json
import os
import re
import subprocess
import xml.etree.ElementTree as ET

import meshio  # Debian's python3-meshio (scripts/setup.sh); a missing reader is a failure
import numpy as np
import pytest
import scipy.io
import scipy.sparse as sp

REPO = os.path.dirname(os.path.dirname(os.path.dirname(os.path.abspath(__file__))))


def cli_path():
    path = os.environ.get("STRATA_CLI") or os.path.join(REPO, "build", "strata")
    if not os.access(path, os.X_OK):
        pytest.skip(f"the strata command is not built ({path}); set STRATA_CLI")
    return path


def simulate(tmp_path, spec, *args):
    out, model = tmp_path / "out", tmp_path / "model.json"
    proc = subprocess.run([cli_path(), "simulate", "--generate", spec, "--output", str(out),
                           "--write-model", str(model), "--quiet", *args],
                          capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    with open(model) as f:
        return out, json.load(f), proc.stdout


def read_positions(out):
    with open(out / "positions.csv", newline="") as f:
        rows = list(csv.reader(f))
    return rows[0], np.array([[float(v) for v in r] for r in rows[1:]])


def expected_geometry(model):
    """From the model file alone: the moving bodies in order (rigid bodies, then the nodes
    of each flexible body), the lines (pairs of moving bodies joined by a joint, and each
    flexible node attached to a rigid body) and the hexahedra."""
    rigid = [b["name"] for b in model.get("bodies", [])]
    points = list(rigid)
    hexes, lines = [], set()
    for fb in model.get("flexible_bodies", []):
        base = len(points)
        points += [f"{fb['name']}.n{k}" for k in range(len(fb["nodes"]))]
        hexes += [[base + k for k in e] for e in fb["elements"]]
        for att in fb.get("attachments", []):
            for k in att["nodes"]:
                lines.add(tuple(sorted((points.index(att["body"]), base + k))))
    for j in model.get("joints", []):
        if j.get("body_i") in rigid and j.get("body_j") in rigid:
            lines.add(tuple(sorted((rigid.index(j["body_i"]), rigid.index(j["body_j"])))))
    return points, rigid, lines, hexes


@pytest.mark.parametrize("spec,t_end", [("flexible:2x2x1", "0.02"), ("andrews", "0.002"),
                                        ("chain:4", "0.02")])
def test_vtk_series_read_by_meshio(tmp_path, spec, t_end):
    out, model, _ = simulate(tmp_path, spec, "--t-end", t_end, "--vtk",
                             "--output-interval", "0.001")
    planar = model["type"] == "planar"
    points, rigid, lines, hexes = expected_geometry(model)
    header, pos = read_positions(out)
    col = {name: i for i, name in enumerate(header)}

    pvd = ET.parse(out / "vtk" / "series.pvd").getroot()
    assert pvd.get("type") == "Collection"
    frames = [(float(d.get("timestep")), d.get("file")) for d in pvd.iter("DataSet")]
    assert len(frames) == pos.shape[0] >= 3
    for (t, name), row in zip(frames, pos):
        assert t == pytest.approx(row[col["time"]], abs=1e-9)
        mesh = meshio.read(out / "vtk" / name)

        # points: the coordinates of positions.csv at this time (9 significant digits)
        want = np.array([[row[col[f"{p}.x"]], row[col[f"{p}.y"]],
                          0.0 if planar else row[col[f"{p}.z"]]] for p in points])
        np.testing.assert_allclose(mesh.points, want, rtol=1e-8, atol=1e-12)

        # cells: a vertex per rigid body, the lines, the hexahedra
        cells = {c.type: c.data for c in mesh.cells}
        assert set(cells) <= {"vertex", "line", "hexahedron"}
        assert sorted(cells["vertex"].ravel().tolist()) == list(range(len(rigid)))
        got_lines = [tuple(sorted(map(int, c))) for c in cells.get("line", [])]
        assert len(got_lines) == len(set(got_lines)) and set(got_lines) == lines
        got_hexes = cells.get("hexahedron", np.zeros((0, 8), int)).tolist()
        assert got_hexes == hexes

        # orientation: Euler parameters of spatial bodies, (cos φ/2, 0, 0, sin φ/2) of
        # planar ones, the identity for flexible nodes
        q = mesh.point_data["orientation"]
        for i, p in enumerate(points):
            if p not in rigid:
                want_q = [1, 0, 0, 0]
            elif planar:
                phi = row[col[f"{p}.phi"]]
                want_q = [np.cos(phi / 2), 0, 0, np.sin(phi / 2)]
            else:
                want_q = [row[col[f"{p}.e{k}"]] for k in range(4)]
            np.testing.assert_allclose(q[i], want_q, rtol=1e-8, atol=1e-9)


def test_matrix_market_read_by_scipy(tmp_path):
    out, _, stdout = simulate(tmp_path, "flexible:2x2x1", "--t-end", "0.003",
                              "--dump-matrix", str(tmp_path / "mm"), "--dump-step", "2")
    m = re.search(r"^Newton matrix\s+(\d+) x (\d+), nnz (\d+)", stdout, re.M)
    assert m, stdout
    n, nnz = int(m.group(1)), int(m.group(3))
    J = sp.csr_matrix(scipy.io.mmread(tmp_path / "mm" / "jacobian_step2.mtx"))
    r = np.asarray(scipy.io.mmread(tmp_path / "mm" / "rhs_step2.mtx")).reshape(-1)
    assert J.shape == (n, n) and r.shape == (n,)
    J.sum_duplicates()
    assert J.nnz == nnz
    assert np.isfinite(J.data).all() and np.abs(r).max() > 0

    # strata solve writes x; scipy reads it and checks it against its own solve
    x_path = tmp_path / "x.mtx"
    proc = subprocess.run([cli_path(), "solve", str(tmp_path / "mm" / "jacobian_step2.mtx"),
                           "--rhs", str(tmp_path / "mm" / "rhs_step2.mtx"), "--out",
                           str(x_path)], capture_output=True, text=True)
    assert proc.returncode == 0, proc.stderr
    x = np.asarray(scipy.io.mmread(x_path)).reshape(-1)
    assert x.shape == (n,)
    berr = np.abs(J @ x - r).max() / (abs(J).sum(axis=1).max() * np.abs(x).max()
                                       + np.abs(r).max())
    assert berr < 1e-13
