"""Tests of the Python package `strata` against scipy.sparse.linalg.spsolve.

Run by ctest (test `python_api`) with PYTHONPATH=<build>/python and STRATA_MATRIX_DIR set
to the shared SuiteSparse matrices; by hand:
    PYTHONPATH=build/python STRATA_MATRIX_DIR=data/matrices /usr/bin/python3 -m pytest -q tests/python
"""

import os
import threading

import numpy as np
import pytest
import scipy.io
import scipy.sparse as sp
import scipy.sparse.linalg as spla

import strata

MATRIX_DIR = os.environ.get("STRATA_MATRIX_DIR", "")

# (name, expected factorization type) of shared matrices small enough for spsolve
SHARED = [
    ("LFAT5", "spd"),
    ("494_bus", "spd"),
    ("bcsstk09", "spd"),
    ("tumorAntiAngiogenesis_2", "symmetric_indefinite"),
    ("reorientation_1", "symmetric_indefinite"),
    ("west0067", "general"),
    ("rajat11", "general"),
    ("olm1000", "general"),
    ("nnc1374", "general"),
]

SIZES = [1, 2, 3, 5, 17, 733]


def backward_error(A, x, b):
    """max over columns of ‖b−Ax‖∞ / (‖A‖∞‖x‖∞ + ‖b‖∞)"""
    A = sp.csr_matrix(A)
    r = b - A @ x
    anorm = abs(A).sum(axis=1).max()
    if x.ndim == 1:
        return np.abs(r).max() / (anorm * np.abs(x).max() + np.abs(b).max())
    return max(
        np.abs(r[:, j]).max() / (anorm * np.abs(x[:, j]).max() + np.abs(b[:, j]).max())
        for j in range(x.shape[1])
    )


def rel_diff(x, y):
    return np.linalg.norm(x - y) / max(np.linalg.norm(y), 1e-300)


def random_matrix(n, kind, seed):
    """Random sparse n×n matrix: 'spd', 'indefinite' (symmetric, eigenvalues of both
    signs) or 'general' (unsymmetric pattern)."""
    rng = np.random.default_rng(seed)
    density = min(1.0, 4.0 / n)
    R = sp.random(n, n, density=density, random_state=rng, format="csr")
    if kind == "spd":
        S = R + R.T
        d = np.asarray(abs(S).sum(axis=1)).ravel() + 1.0
        return (S + sp.diags(d)).tocsc()
    if kind == "indefinite":
        S = R + R.T
        d = np.asarray(abs(S).sum(axis=1)).ravel() + 1.0
        signs = np.where(np.arange(n) % 3 == 1, -1.0, 1.0)
        return (S + sp.diags(d * signs)).tocsc()
    d = np.asarray(abs(R).sum(axis=1)).ravel() + 1.0
    return (R + sp.diags(d * np.where(np.arange(n) % 2 == 0, 1.0, -0.5))).tocsr()


# ---------------------------------------------------------------------------------------
# shared SuiteSparse matrices
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("name,kind", SHARED)
def test_shared_matrix_agrees_with_spsolve(name, kind):
    path = os.path.join(MATRIX_DIR, name + ".mtx.gz")
    if not MATRIX_DIR or not os.path.exists(path):
        pytest.skip(f"{path} not found (set STRATA_MATRIX_DIR)")
    A = sp.csc_matrix(scipy.io.mmread(path))
    n = A.shape[0]
    rng = np.random.default_rng(7)
    b = rng.standard_normal(n)
    solver = strata.Solver(A)
    x = solver.solve(b)
    assert x.shape == (n,) and x.dtype == np.float64
    x_ref = spla.spsolve(A, b)
    assert backward_error(A, x, b) < 1e-12
    # agreement limited by conditioning: both solutions are backward stable
    cond_bound = 1e-6 if kind == "general" else 1e-8
    assert rel_diff(x, x_ref) < cond_bound, rel_diff(x, x_ref)
    st = solver.stats
    assert st["factor"]["type"] == kind
    assert st["n"] == n and st["nnz_l"] >= n and st["factor_flops"] > 0
    assert st["solve"]["backward_error"] < 1e-12
    # two right-hand sides at once give the same columns
    B = np.column_stack([b, 2 * b])
    X = solver.solve(B)
    assert X.shape == (n, 2)
    assert rel_diff(X[:, 0], x) < 1e-10 and rel_diff(X[:, 1], 2 * x) < 1e-10


def test_shared_kkt_inertia_and_lower_storage():
    path = os.path.join(MATRIX_DIR, "tumorAntiAngiogenesis_2.mtx.gz")
    if not MATRIX_DIR or not os.path.exists(path):
        pytest.skip("shared matrices not found")
    A = sp.csc_matrix(scipy.io.mmread(path))
    full = strata.Solver(A)
    lower = strata.Solver(sp.tril(A, format="csc"), storage="lower")
    upper = strata.Solver(sp.triu(A, format="csr"), storage="upper")
    b = np.ones(A.shape[0])
    x = full.solve(b)
    for s in (lower, upper):
        assert s.stats["factor"]["inertia"] == full.stats["factor"]["inertia"]
        assert rel_diff(s.solve(b), x) < 1e-8
    pos, neg, zero = full.stats["factor"]["inertia"]
    assert pos + neg + zero == A.shape[0] and neg > 0


# ---------------------------------------------------------------------------------------
# random matrices
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("n", SIZES)
@pytest.mark.parametrize("kind", ["spd", "indefinite", "general"])
def test_random_agrees_with_spsolve(n, kind):
    A = random_matrix(n, kind, seed=n)
    rng = np.random.default_rng(n + 1)
    b = rng.standard_normal(n)
    solver = strata.Solver(A)
    x = solver.solve(b)
    x_ref = spla.spsolve(sp.csc_matrix(A), b)
    assert x.shape == b.shape
    assert rel_diff(x, np.atleast_1d(x_ref)) < 1e-10
    assert backward_error(A, x, b) < 1e-13
    expected = {"spd": "spd", "indefinite": "symmetric_indefinite", "general": "general"}[kind]
    if n == 1:
        expected = "spd"  # a positive 1×1 matrix is symmetric positive definite
    assert solver.stats["factor"]["type"] == expected
    # several right-hand sides, Fortran- and C-ordered
    B = rng.standard_normal((n, 3))
    for Bo in (B, np.asfortranarray(B)):
        X = solver.solve(Bo)
        assert X.shape == (n, 3)
        X_ref = spla.spsolve(sp.csc_matrix(A), B).reshape(n, 3)
        assert rel_diff(X, X_ref) < 1e-10


@pytest.mark.parametrize("fmt", ["csr", "csc", "coo", "lil", "dok", "bsr"])
def test_every_scipy_format(fmt):
    A = random_matrix(17, "general", seed=3)
    b = np.arange(17, dtype=float)
    x = strata.Solver(A.asformat(fmt)).solve(b)
    assert rel_diff(x, spla.spsolve(sp.csc_matrix(A), b)) < 1e-10


def test_sparse_array_and_integer_dtypes():
    A = sp.csr_matrix(np.array([[4, 1, 0], [1, 3, 0], [0, 0, 2]], dtype=np.int32))
    if hasattr(sp, "csr_array"):
        A2 = sp.csr_array(A)
        assert rel_diff(strata.Solver(A2).solve([1, 2, 3]), strata.Solver(A).solve([1, 2, 3])) < 1e-15
    x = strata.Solver(A).solve(np.array([1, 2, 3], dtype=np.int64))
    assert x.dtype == np.float64
    assert rel_diff(A @ x, np.array([1.0, 2.0, 3.0])) < 1e-14
    A32 = A.astype(np.float32)
    assert rel_diff(strata.Solver(A32).solve([1.0, 2.0, 3.0]), x) < 1e-12


@pytest.mark.parametrize("ordering", ["nd", "metis", "amd", "natural", "auto"])
@pytest.mark.parametrize("type_", ["auto", "general"])
def test_options(ordering, type_):
    A = random_matrix(733, "spd", seed=11)
    b = np.ones(733)
    s = strata.Solver(A, type=type_, ordering=ordering, device="cpu", max_block_size=16,
                      num_threads=1, refinement_steps=2)
    assert backward_error(A, s.solve(b), b) < 1e-13
    # "auto" reports the method it chose (AMD or nested dissection)
    assert s.stats["ordering"] == ordering if ordering != "auto" else s.stats["ordering"] in (
        "amd", "nd")
    assert s.stats["factor"]["backend"] == "cpu" and s.stats["backend"] == "cpu"
    # device "auto": the analysis reports where its factorizations run
    auto = strata.Solver(A, type=type_, ordering=ordering, num_threads=1)
    assert auto.stats["backend"] == auto.stats["factor"]["backend"] in ("cpu", "cuda")
    perm = s.permutation
    assert perm.dtype == np.int64 and sorted(perm.tolist()) == list(range(733))


def test_solve_function_and_repr():
    A = random_matrix(5, "general", seed=5)
    b = np.ones(5)
    x = strata.solve(A, b, ordering="amd")
    assert rel_diff(x, spla.spsolve(sp.csc_matrix(A), b)) < 1e-12
    assert "strata.Solver" in repr(strata.Solver(A))


# ---------------------------------------------------------------------------------------
# refactorization and analysis
# ---------------------------------------------------------------------------------------


@pytest.mark.parametrize("kind", ["spd", "indefinite", "general"])
def test_refactorize(kind):
    A = random_matrix(733, kind, seed=21)
    b = np.linspace(-1, 1, 733)
    s = strata.Solver(A)
    x1 = s.solve(b)
    A2 = A.copy()
    A2.data = A2.data * 1.5 + (0.25 if kind == "spd" else 0.0) * (A2.data != 0)
    A2 = A2 + 0.5 * sp.diags(A.diagonal())  # same pattern: the diagonal is stored
    A2 = A2.asformat(A.format)
    assert A2.nnz == A.nnz
    assert s.refactorize(A2) is s
    x2 = s.solve(b)
    assert rel_diff(x2, spla.spsolve(sp.csc_matrix(A2), b)) < 1e-9
    assert not np.allclose(x1, x2)
    # back to the first values: the same solution as the first factorization
    s.refactorize(A)
    assert rel_diff(s.solve(b), x1) < 1e-12


@pytest.mark.parametrize("kind", ["spd", "indefinite", "general"])
@pytest.mark.parametrize("fmt", ["csr", "csc"])
def test_refactorize_values_equals_refactorize(kind, fmt):
    A = random_matrix(733, kind, seed=23).asformat(fmt)
    A2 = A.copy()
    A2.data = A2.data * 1.25
    b = np.linspace(-1, 1, 733)
    by_matrix, by_values = strata.Solver(A), strata.Solver(A)
    by_matrix.refactorize(A2)
    assert by_values.refactorize_values(A2.data) is by_values
    x = by_values.solve(b)
    assert np.array_equal(x, by_matrix.solve(b))
    assert rel_diff(x, spla.spsolve(sp.csc_matrix(A2), b)) < 1e-9
    with pytest.raises(ValueError, match="values"):
        by_values.refactorize_values(A2.data[:-1])
    bad = A2.data.copy()
    bad[3] = np.nan
    with pytest.raises(ValueError, match="finite"):
        by_values.refactorize_values(bad)
    assert np.array_equal(by_values.solve(b), x)  # the previous factor is kept


def test_refactorize_rejects_other_pattern_and_keeps_factor():
    A = random_matrix(17, "general", seed=2)
    s = strata.Solver(A)
    b = np.ones(17)
    x = s.solve(b)
    B = (A + sp.csr_matrix(([1.0], ([0], [16])), shape=(17, 17))).tocsr()
    if B.nnz != A.nnz:
        with pytest.raises(ValueError, match="pattern"):
            s.refactorize(B)
    with pytest.raises(ValueError, match="shape"):
        s.refactorize(random_matrix(5, "general", seed=2))
    bad = A.copy()
    bad.data[0] = np.nan
    with pytest.raises(ValueError, match="finite"):
        s.refactorize(bad)
    assert rel_diff(s.solve(b), x) == 0.0


def test_analyze_returns_statistics():
    A = random_matrix(733, "spd", seed=4)
    st = strata.analyze(A)
    for key in ("n", "nnz_a", "nnz_l", "factor_flops", "fronts", "tree_height",
                "fronts_per_level", "peak_working_bytes", "seconds"):
        assert key in st, key
    assert st["n"] == 733 and st["nnz_l"] >= 733
    assert sum(st["fronts_per_level"]) == st["fronts"]
    assert st["seconds"]["total"] >= st["seconds"]["ordering"] >= 0
    assert "factor" not in st and "solve" not in st
    assert strata.analyze(A, ordering="natural")["nnz_l"] >= st["nnz_l"] * 0.5
    s = strata.Solver(A)
    assert s.stats["nnz_l"] == st["nnz_l"]


def test_threads_release_gil():
    mats = [random_matrix(733, "general", seed=30 + i) for i in range(4)]
    b = np.ones(733)
    results = [None] * 4

    def work(i):
        s = strata.Solver(mats[i], num_threads=1)
        results[i] = s.solve(b)

    threads = [threading.Thread(target=work, args=(i,)) for i in range(4)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    for i in range(4):
        assert backward_error(mats[i], results[i], b) < 1e-13


# ---------------------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------------------


def test_error_hierarchy():
    assert issubclass(strata.InvalidInputError, strata.Error)
    assert issubclass(strata.InvalidInputError, ValueError)
    assert issubclass(strata.Error, RuntimeError)
    for e in (strata.NotSupportedError, strata.NotPositiveDefiniteError,
              strata.InvalidStateError, strata.DeviceError, strata.OutOfMemoryError):
        assert issubclass(e, strata.Error)


def test_non_square():
    with pytest.raises(ValueError, match="square"):
        strata.Solver(sp.random(3, 4, density=0.5, format="csr"))
    with pytest.raises(ValueError, match="square"):
        strata.analyze(sp.random(4, 3, density=0.5, format="csc"))


def test_nan_and_inf_values():
    A = random_matrix(5, "general", seed=1).tocsr()
    for bad in (np.nan, np.inf):
        B = A.copy()
        B.data[3] = bad
        with pytest.raises(strata.InvalidInputError, match="not finite"):
            strata.Solver(B)


def test_wrong_types():
    with pytest.raises(TypeError, match="scipy.sparse"):
        strata.Solver(np.eye(3))
    with pytest.raises(TypeError, match="scipy.sparse"):
        strata.Solver([[1.0, 0.0], [0.0, 1.0]])
    with pytest.raises(TypeError, match="dtype"):
        strata.Solver(sp.eye(3, dtype=complex, format="csr"))
    s = strata.Solver(sp.eye(3, format="csr"))
    with pytest.raises(TypeError, match="dtype"):
        s.solve(np.ones(3, dtype=complex))
    with pytest.raises(TypeError, match="dtype"):
        s.solve(np.array(["a", "b", "c"]))


def test_wrong_rhs_shapes_and_values():
    s = strata.Solver(random_matrix(5, "spd", seed=9))
    with pytest.raises(ValueError, match="shape"):
        s.solve(np.ones(4))
    with pytest.raises(ValueError, match="shape"):
        s.solve(np.ones((6, 2)))
    with pytest.raises(ValueError, match="1-D or 2-D"):
        s.solve(np.ones((5, 2, 2)))
    with pytest.raises(ValueError, match="1-D or 2-D"):
        s.solve(np.float64(1.0))
    b = np.ones(5)
    b[2] = np.nan
    with pytest.raises(ValueError, match="not finite"):
        s.solve(b)
    assert s.solve(np.ones((5, 0))).shape == (5, 0)


def test_bad_options():
    A = sp.eye(3, format="csr")
    for kwargs in ({"type": "cholesky"}, {"ordering": "rcm"}, {"device": "tpu"},
                   {"storage": "diagonal"}, {"max_block_size": -1}, {"num_threads": -1},
                   {"refinement_steps": -1}):
        with pytest.raises(ValueError):
            strata.Solver(A, **kwargs)
    # the names come from the vocabulary every interface shares (strata::parse): the same
    # message as the CLI's, and the same aliases
    with pytest.raises(strata.InvalidInputError,
                       match="ordering must be 'nd', 'metis', 'amd', 'natural' or 'auto'.*got 'rcm'"):
        strata.Solver(A, ordering="rcm")
    with pytest.raises(strata.InvalidInputError, match="must be a string"):
        strata.Solver(A, type=3)
    assert strata.Solver(A, type="lu").stats["factor"]["type"] == "general"


def test_not_positive_definite():
    A = random_matrix(17, "indefinite", seed=17)
    with pytest.raises(strata.NotPositiveDefiniteError, match="positive definite"):
        strata.Solver(A, type="spd")
    # declared symmetric_indefinite it works
    b = np.ones(17)
    x = strata.Solver(A, type="symmetric_indefinite").solve(b)
    assert backward_error(A, x, b) < 1e-13


def test_lower_storage_rejects_upper_entries():
    A = random_matrix(5, "spd", seed=3)
    with pytest.raises(ValueError, match="triangle"):
        strata.Solver(A, storage="lower")


def test_cuda_device_is_supported_or_a_clear_error():
    A = random_matrix(17, "spd", seed=8)
    try:
        s = strata.Solver(A, device="cuda")
    except (strata.NotSupportedError, strata.DeviceError) as e:
        assert str(e)
        return
    assert s.stats["factor"]["backend"] == "cuda"
    b = np.ones(17)
    assert backward_error(A, s.solve(b), b) < 1e-13


def _cpu_flags():
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                if line.startswith("flags"):
                    return set(line.split(":", 1)[1].split())
    except OSError:
        pass
    return set()


def test_blas_kernels_and_the_prescott_fallback_warning():
    # the CPU's best OpenBLAS core type from the kernel's flag list (the module asks the
    # compiler's CPU checks), and the warning exactly when OpenBLAS fell back to Prescott
    import platform
    import subprocess
    import sys

    if platform.machine() != "x86_64":
        pytest.skip("OpenBLAS's x86-64 core types only")
    flags = _cpu_flags()
    if not flags:
        pytest.skip("no /proc/cpuinfo flags on this system")
    if {"avx512f", "avx512cd", "avx512bw", "avx512dq", "avx512vl"} <= flags:
        fitting = "SkylakeX"
    elif {"avx2", "fma"} <= flags:
        fitting = "Haswell"
    else:
        fitting = ""
    assert strata.blas_kernels()["fitting"] == fitting
    code = "import strata; print(strata.blas_kernels()['library'])"
    env = dict(os.environ, OPENBLAS_CORETYPE="Prescott")
    run = [sys.executable, "-W", "always", "-c", code]
    r = subprocess.run(run, env=env, capture_output=True, text=True, check=True)
    assert r.stdout.strip().endswith("Prescott kernels"), r.stdout
    assert "OPENBLAS_CORETYPE=" not in r.stderr  # the user's own choice is not warned about
    del env["OPENBLAS_CORETYPE"]
    r = subprocess.run(run, env=env, capture_output=True, text=True, check=True)
    fell_back = r.stdout.strip().endswith("Prescott kernels")
    assert ("OPENBLAS_CORETYPE=" + fitting in r.stderr) == (fell_back and fitting != ""), r.stderr
