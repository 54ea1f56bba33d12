"""strata tests — strata.Solver(A, comm=...) across MPI ranks from Python (mpi4py).

Run by ctest as ``mpiexec -n 2 python3 tests/mpi/test_python_mpi.py``. Rank 0 builds random
SPD, symmetric indefinite and unsymmetric matrices (n = 1, 5 and 600) and right-hand sides;
the distributed solution is compared with the one-process strata.Solver and with scipy's
SuperLU (an independent reference). Also: several right-hand sides, refactorization, and
a bad right-hand side on rank 0 raising InvalidInputError on every rank. Exits non-zero on
any rank's failure.
"""
import sys

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from mpi4py import MPI

import strata

comm = MPI.COMM_WORLD
rank = comm.Get_rank()
rng = np.random.default_rng()


def random_matrix(n, kind):
    a = sp.random(n, n, density=min(1.0, 4.0 / n), random_state=rng, format="csr")
    if kind == "general":
        return (a + sp.diags(rng.uniform(1, 2, n) * 4)).tocsr()
    s = a + a.T
    if kind == "spd":
        return (s + sp.diags(np.abs(s).sum(axis=1).A1 + 1)).tocsr()
    d = rng.uniform(1, 2, n) * rng.choice([-1, 1], n) * (np.abs(s).sum(axis=1).A1 + 1)
    return (s + sp.diags(d)).tocsr()


failures = []


def check(cond, what):
    if not cond:
        failures.append(what)


for kind, typ in (("spd", "spd"), ("indefinite", "symmetric_indefinite"),
                  ("general", "general")):
    for n in (1, 5, 600):
        a = random_matrix(n, kind) if rank == 0 else None
        b = rng.uniform(-1, 1, (n, 2)) if rank == 0 else None
        s = strata.Solver(a, type=typ, num_threads=1, comm=comm)
        check(s.n == n, f"{kind} {n}: n on rank {rank}")
        x = s.solve(b)
        x1 = s.solve(b[:, 0] if rank == 0 else None)
        if rank != 0:
            check(x is None and x1 is None, f"{kind} {n}: rank {rank} got a solution")
        else:
            ref = strata.Solver(a, type=typ, num_threads=1).solve(b)
            lu = spla.splu(a.tocsc()).solve(b)
            check(np.allclose(x, ref, rtol=1e-9, atol=1e-12), f"{kind} {n}: vs one process")
            check(np.allclose(x, lu, rtol=1e-7, atol=1e-10), f"{kind} {n}: vs SuperLU")
            check(np.allclose(x1, x[:, 0], rtol=1e-12, atol=1e-14), f"{kind} {n}: one rhs")
            st = s.stats
            ds = st["distributed"]
            check(ds["ranks"] == comm.Get_size() and len(ds["per_rank"]) == comm.Get_size()
                  or comm.Get_size() == 1, f"{kind} {n}: per-rank statistics")
            check(st["solve"]["backward_error"] < 1e-14, f"{kind} {n}: backward error")
        # refactorization: 2A gives x/2
        s.refactorize(2 * a if rank == 0 else None)
        x2 = s.solve(b)
        if rank == 0:
            check(np.allclose(x2, x / 2, rtol=1e-9, atol=1e-12), f"{kind} {n}: refactorize")
        # a bad right-hand side raises on every rank
        try:
            s.solve(np.zeros(n + 1) if rank == 0 else None)
            check(False, f"{kind} {n}: no error for a wrong shape on rank {rank}")
        except strata.InvalidInputError:
            pass

if failures:
    print(f"rank {rank}: FAILED: " + "; ".join(failures), flush=True)
worst = comm.allreduce(len(failures), op=MPI.MAX)
if rank == 0:
    print("python mpi: " + ("ok" if worst == 0 else "failures"), flush=True)
sys.exit(1 if worst else 0)
