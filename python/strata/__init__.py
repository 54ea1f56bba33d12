"""strata: a multifrontal sparse direct solver (Cholesky, LDLᵀ, LU) on a CPU or a GPU.

Solves A x = b for a square sparse matrix A given as any ``scipy.sparse`` matrix or
array. The four phases of a direct solve are those of the C++ library:

    >>> import numpy as np, scipy.sparse as sp, strata
    >>> A = sp.random(100, 100, density=0.05, format="csr") + 10 * sp.eye(100)
    >>> solver = strata.Solver(A)            # analysis + numeric factorization
    >>> x = solver.solve(np.ones(100))       # triangular solves + iterative refinement
    >>> solver.refactorize(2 * A)            # same pattern, new values: reuses the analysis
    >>> solver.stats["nnz_l"], solver.stats["solve"]["backward_error"]

``strata.analyze(A)`` returns the statistics of the analysis alone (nnz(L), factor flops,
fronts, tree height, memory) without factoring.

``strata.simulate(model)`` runs the multibody engine (the command ``strata simulate``) on a
model file or dict and returns the time histories as NumPy arrays:

    >>> r = strata.simulate("models/pendulum_chain.json", t_end=0.1)
    >>> r.time.shape, r.positions.shape       # (k,), (k, n)
    >>> r.steps["newton_iterations"], r.stats["factorizations"]
    >>> strata.plot(r, "plots", coordinates=["link1.x"])  # summary.png, coordinates.png

Errors raise subclasses of :class:`strata.Error` (a ``RuntimeError``) carrying the
solver's message: :class:`InvalidInputError` (also a ``ValueError``) for a non-square
matrix, NaN/Inf values, wrong shapes or a changed pattern; :class:`NotPositiveDefiniteError`
when ``type="spd"`` meets a non-positive pivot; :class:`InvalidStateError`,
:class:`NotSupportedError`, :class:`DeviceError`, :class:`OutOfMemoryError` (also a
``MemoryError``), :class:`InternalError` (a bug in strata: please report it), and from simulate :class:`ModelError` (an InvalidInputError) and
:class:`SimulationError`. Inputs of a dtype that is not real (complex, object, strings) raise
``TypeError``.

The GIL is released during analysis, factorization and solve, so several solvers can
run in parallel Python threads (one solver must not be used by two threads at once).
"""

import numpy as _np
import scipy.sparse as _sp

from ._strata import (  # noqa: F401  (re-exported)
    DeviceError,
    Error,
    InternalError,
    InvalidInputError,
    InvalidStateError,
    ModelError,
    NotPositiveDefiniteError,
    NotSupportedError,
    OutOfMemoryError,
    SimulationError,
    __version__,
    blas_kernels,
    cuda_in_build,
)
from . import _strata


def _check_blas_kernels():
    # OpenBLAS before 0.3.25 runs its Prescott (SSE3) kernels on Intel CPUs it does not know
    # (OpenBLAS issue #4267); OPENBLAS_CORETYPE fixes that, but only when set before the
    # library loads, i.e. before Python starts. The command-line programs set it themselves.
    import os
    import warnings

    blas = blas_kernels()
    if (
        blas["library"].endswith("Prescott kernels")
        and blas["fitting"]
        and "OPENBLAS_CORETYPE" not in os.environ
    ):
        warnings.warn(
            f"strata: {blas['library']} on a CPU that runs OpenBLAS's {blas['fitting']} "
            f"kernels, which factor several times faster: start Python with "
            f"OPENBLAS_CORETYPE={blas['fitting']} in the environment",
            RuntimeWarning,
            stacklevel=3,
        )


_check_blas_kernels()
from ._simulate import SimulationResult, generate_model, simulate  # noqa: F401
from ._plot import plot  # noqa: F401

__all__ = [
    "Solver",
    "analyze",
    "solve",
    "simulate",
    "generate_model",
    "SimulationResult",
    "plot",
    "cuda_in_build",
    "blas_kernels",
    "mpi_in_build",
    "Error",
    "InternalError",
    "InvalidInputError",
    "InvalidStateError",
    "NotPositiveDefiniteError",
    "NotSupportedError",
    "DeviceError",
    "OutOfMemoryError",
    "ModelError",
    "SimulationError",
]



def _check_names(**names):
    """The option names must be strings; which strings is decided by the extension (the
    vocabulary every interface shares: strata::parse), which raises InvalidInputError."""
    for name, value in names.items():
        if not isinstance(value, str):
            raise InvalidInputError(f"{name} must be a string, got {value!r}")
_STORAGES = ("full", "lower", "upper")


def _check_real_dtype(dtype, what):
    if dtype.kind not in "biuf":
        raise TypeError(
            f"{what} must have a real numeric dtype (bool, integer or float; converted to "
            f"float64), got {dtype}"
        )


def _to_matrix(A, storage="full", what="A"):
    """A validated strata copy of the scipy.sparse matrix A (float64 values, int64
    indices; CSR is kept, every other format goes through CSC)."""
    if not _sp.issparse(A):
        raise TypeError(
            f"{what} must be a scipy.sparse matrix or array (e.g. scipy.sparse.csr_matrix), "
            f"got {type(A).__name__}"
        )
    if storage not in _STORAGES:
        raise InvalidInputError(f"storage must be one of {_STORAGES}, got {storage!r}")
    if len(A.shape) != 2:
        raise InvalidInputError(f"{what} must be 2-D, got shape {A.shape}")
    n_rows, n_cols = A.shape
    if n_rows != n_cols:
        raise InvalidInputError(f"{what} must be square, got shape {n_rows}x{n_cols}")
    _check_real_dtype(A.dtype, what)
    if A.format == "csr":
        layout = "csr"
    else:
        layout = "csc"
        if A.format != "csc":
            A = A.tocsc()
    indptr = _np.asarray(A.indptr, dtype=_np.int64)
    indices = _np.asarray(A.indices, dtype=_np.int64)
    data = _np.asarray(A.data, dtype=_np.float64)
    return _strata._Matrix(n_rows, n_cols, layout, storage, indptr, indices, data)


def _make_core(type, ordering, device, max_block_size, num_threads, refinement_steps,
               refinement_tolerance, device_memory_limit):
    _check_names(type=type, ordering=ordering, device=device)
    return _strata._Core(type, ordering, device, int(max_block_size), int(num_threads),
                         int(refinement_steps), float(refinement_tolerance),
                         int(device_memory_limit))


def _make_dist_core(comm, type, ordering, device, max_block_size, num_threads,
                    refinement_steps, refinement_tolerance, device_memory_limit):
    if not _strata.mpi_in_build():
        raise NotSupportedError("comm= needs a strata build with MPI (CMake option STRATA_MPI)")
    if not hasattr(comm, "py2f"):
        raise TypeError(f"comm must be an mpi4py communicator, got {_type_name(comm)}")
    _check_names(type=type, ordering=ordering, device=device)
    return _strata._DistCore(comm.py2f(), type, ordering, device, int(max_block_size),
                             int(num_threads), int(refinement_steps),
                             float(refinement_tolerance), int(device_memory_limit))


def _type_name(x):
    return x.__class__.__name__


def _empty_matrix():
    z = _np.zeros(1, dtype=_np.int64)
    return _strata._Matrix(0, 0, "csc", "full", z, _np.zeros(0, dtype=_np.int64),
                           _np.zeros(0))


def mpi_in_build():
    """True when this strata build can solve across MPI ranks (Solver(..., comm=))."""
    return _strata.mpi_in_build()


class Solver:
    """A factorization of a square sparse matrix A, for solving A x = b.

    ``Solver(A)`` runs the analysis (fill-reducing ordering, assembly tree, level
    schedule, memory plan) and the numeric factorization; ``solve`` then costs two
    triangular solves plus iterative refinement per right-hand side, and
    ``refactorize`` factors new values with the same pattern reusing the analysis.

    Parameters
    ----------
    A : scipy.sparse matrix or array, shape (n, n)
        The matrix; any format (CSR is used as is, others are converted to CSC), any
        real dtype (converted to float64). Explicitly stored zeros are part of the
        pattern. Duplicate entries are summed.
    type : {"auto", "spd", "symmetric_indefinite", "general"}
        Factorization: Cholesky LLᵀ, LDLᵀ with 1×1/2×2 pivots, or LU on the pattern of
        A+Aᵀ. "auto" (default) uses LLᵀ for a symmetric matrix when it succeeds, else
        LDLᵀ; LU for an unsymmetric one.
    ordering : {"nd", "metis", "amd", "natural", "auto"}
        Fill-reducing ordering (default "nd": strata's nested dissection; "auto": AMD when
        its factor is cheap, else nested dissection, as CHOLMOD chooses).
    device : {"auto", "cpu", "cuda"}
        Where the factorization runs. "auto" (default) uses a GPU when the build and the
        machine have one, else the host (for LLᵀ, LDLᵀ and LU alike; the option
        gpu_min_flops keeps factors of fewer flops on the host; stats["backend"] says
        where); "cuda" raises NotSupportedError in a build without CUDA or on a
        machine without a GPU.
    storage : {"full", "lower", "upper"}
        Which part of A is given: "lower"/"upper" mean A holds one triangle of a
        symmetric matrix (diagonal included) and the other is implied. Default "full".
    max_block_size : int
        Most pivot columns per front; larger separators are split (default 0: 4096
        for Cholesky on the GPU, 1024 otherwise; stats["max_block_size"] says which).
    num_threads : int
        CPU threads; 0 (default) means all hardware threads.
    refinement_steps : int
        Most iterative refinement steps per solve (default 10; 0 disables).
    refinement_tolerance : float
        Refinement stops at this backward error (default 1e-15).
    device_memory_limit : int
        GPU memory budget in bytes for the memory plan (default 0: the whole device).
    comm : mpi4py.MPI.Comm, optional
        Solve across the processes of this MPI communicator (``mpirun -n R python ...``;
        docs/distributed.md). Every rank constructs the Solver and calls every method; A
        and b are read on rank 0 only (pass None elsewhere), ``solve`` returns x on rank 0
        and None on the others. Needs a build with MPI (``strata.mpi_in_build()``) and
        mpi4py built for the same MPI (Debian's python3-mpi4py).

    Raises
    ------
    TypeError
        A is not a scipy.sparse matrix, or its dtype is not real.
    InvalidInputError (a ValueError)
        A is not square, has NaN/Inf values, or an option is invalid.
    NotPositiveDefiniteError
        type="spd" and A is not positive definite.
    NotSupportedError, DeviceError, OutOfMemoryError
    """

    def __init__(self, A, type="auto", ordering="nd", device="auto", storage="full",
                 max_block_size=0, num_threads=0, refinement_steps=10,
                 refinement_tolerance=1e-15, device_memory_limit=0, comm=None):
        self._storage = storage
        self._comm = comm
        if comm is not None:
            self._core = _make_dist_core(comm, type, ordering, device, max_block_size,
                                         num_threads, refinement_steps, refinement_tolerance,
                                         device_memory_limit)
            m = _to_matrix(A, storage) if comm.Get_rank() == 0 else _empty_matrix()
            self._core.analyze(m)
            self._core.factorize(m)
            self._shape = (self._core.n, self._core.n)
            return
        self._core = _make_core(type, ordering, device, max_block_size, num_threads,
                                refinement_steps, refinement_tolerance, device_memory_limit)
        m = _to_matrix(A, storage)
        self._shape = tuple(A.shape)
        self._core.analyze(m)
        self._core.factorize(m)

    @property
    def shape(self):
        """(n, n): the shape of the factored matrix."""
        return self._shape

    @property
    def n(self):
        """n: the order of the factored matrix."""
        return self._shape[0]

    def solve(self, b):
        """Solves A x = b.

        Parameters
        ----------
        b : array_like, shape (n,) or (n, k)
            One right-hand side, or k right-hand sides as columns; any real dtype
            (converted to float64). Must be finite.

        Returns
        -------
        x : numpy.ndarray of float64, the shape of b

        Raises
        ------
        TypeError for a non-real dtype; InvalidInputError (a ValueError) for a wrong
        shape or NaN/Inf entries; InvalidStateError when the last factorization failed.
        """
        if self._comm is not None:
            return self._solve_distributed(b)
        if _sp.issparse(b):
            b = b.toarray()
        b = _np.asarray(b)
        _check_real_dtype(b.dtype, "b")
        n = self._shape[0]
        if b.ndim == 1:
            if b.shape[0] != n:
                raise InvalidInputError(
                    f"b has shape {b.shape}, expected ({n},) or ({n}, k) for a {n}x{n} matrix"
                )
            return self._core.solve(b.reshape(n, 1)).reshape(n)
        if b.ndim == 2:
            if b.shape[0] != n:
                raise InvalidInputError(
                    f"b has shape {b.shape}, expected ({n},) or ({n}, k) for a {n}x{n} matrix"
                )
            return _np.ascontiguousarray(self._core.solve(b))
        raise InvalidInputError(f"b must be 1-D or 2-D, got {b.ndim}-D shape {b.shape}")

    def _solve_distributed(self, b):
        # Collective: rank 0 passes b flattened column-major; a b of the wrong shape goes
        # on as an empty array, so that the error is raised on every rank (a Python-side
        # exception on rank 0 alone would leave the others waiting).
        if self._comm.Get_rank() != 0:
            self._core.solve(_np.zeros(0))
            return None
        if _sp.issparse(b):
            b = b.toarray()
        b = _np.asarray(b)
        n = self._shape[0]
        ok = (_np.issubdtype(b.dtype, _np.number) and not _np.iscomplexobj(b)
              and b.ndim in (1, 2) and b.shape[0] == n and b.size > 0)
        flat = (_np.asarray(b, dtype=_np.float64).reshape(-1, order="F") if ok
                else _np.zeros(0))
        x = self._core.solve(flat)
        return x.reshape(b.shape, order="F") if b.ndim == 2 else x

    def refactorize(self, A):
        """Factors new values with the analyzed pattern (same shape, same stored
        entries, in the same `storage`), reusing the analysis and the workspace.

        Raises InvalidInputError (a ValueError) for a different shape or pattern or
        NaN/Inf values; the previous factorization is then kept. Returns self."""
        if _sp.issparse(A) and tuple(A.shape) != self._shape:
            raise InvalidInputError(
                f"refactorize: A has shape {A.shape}, the solver was built for {self._shape}"
            )
        if self._comm is not None and self._comm.Get_rank() != 0:
            self._core.refactorize(_empty_matrix())
            return self
        self._core.refactorize(_to_matrix(A, self._storage))
        return self

    def refactorize_values(self, values):
        """Factors new values given alone, as cuDSS's ``cudssMatrixSetValues``: in the
        order of the stored entries of the matrix this solver analyzed (``A.data`` of a
        CSR or CSC matrix; of another format, of ``A.tocsc()``). The pattern is neither
        passed nor compared again. Raises InvalidInputError (a ValueError) for a wrong
        number of values or NaN/Inf values, the previous factorization then kept;
        NotSupportedError with ``comm=``. Returns self."""
        if self._comm is not None:
            raise NotSupportedError(
                "refactorize_values: not with comm= (the distributed solver takes the matrix: "
                "use refactorize)"
            )
        data = _np.asarray(values)
        if data.ndim != 1 or not _np.issubdtype(data.dtype, _np.number) or _np.iscomplexobj(data):
            raise InvalidInputError(
                f"refactorize_values: values must be a 1-D real array, got shape {data.shape} "
                f"of {data.dtype}"
            )
        self._core.refactorize_values(_np.ascontiguousarray(data, dtype=_np.float64))
        return self

    @property
    def stats(self):
        """Statistics of the last analysis, factorization and solve, as a dict: the
        document ``strata solve --json`` prints and the C API's strata_get_stats_json
        writes (one vocabulary, docs/python.md), with the flags analyzed, factorized and
        solved.

        Analysis, at the top level: n, nnz_a (entries of A, both triangles), nnz_l (exact
        nnz(L), diagonal included), nnz_l_fronts, factor_flops (flops of a Cholesky of the
        fronts; LU about twice), fronts, largest_front_rows, largest_front_pivots,
        max_block_size, tree_height, fronts_per_level (list, deepest level first),
        peak_working_bytes, factor_bytes, memory_budget, batches (the memory plan), type
        (the type analyzed for), backend (where its factorizations run: "cpu" or "cuda",
        device "auto" resolved), ordering, pairs, odd_cycles, the multi-worker split
        (workers, subtrees, ...) and seconds (a dict: ordering, nd_balance, symbolic,
        plan, device_setup, total).
        "factor" (after a factorization), a dict: type ("spd", "symmetric_indefinite",
        "general"), backend ("cpu" or "cuda"), seconds, input_seconds, gflops,
        perturbed_pivots (static pivoting), delayed_pivoting, delayed_pivots,
        corrected_pivots (Pivoting corrected's low-rank update),
        correction_backward_error (its probe's; None where no probe ran),
        two_by_two_pivots, inertia (positive, negative, zero), log_abs_determinant,
        determinant_sign (these three None when inertia_valid is False: static pivoting
        perturbed pivots, and they would describe the nearby matrix factored, not A),
        matrix_norm, and the GPU figures (device_seconds, bytes_to_device, device_phases,
        devices, ...).
        "solve" (after a solve), a dict: seconds, refinement_steps, gmres_iterations,
        backward_error (max over columns of ‖b−Ax‖∞/(‖A‖∞‖x‖∞+‖b‖∞)),
        backward_error_floor ((m+1)·u, m the most entries in a row), converged (the
        tolerance, or the floor when larger, was reached), relative_residual (with
        perturbed pivots: ‖b−Ax‖∞/‖b‖∞, at least b's distance from A's range),
        singular_consistent (pivots perturbed, the solve converged and relative_residual
        ≤ √u: x is one of A's solutions), on_device.
        With comm=: "distributed", a dict: ranks, workers_per_rank, per_rank (a list).
        """
        return self._core.stats()

    @property
    def permutation(self):
        """The fill-reducing permutation (new to old): int64 array of length n whose
        k-th entry is the original index of the k-th pivot."""
        if self._comm is not None:
            raise NotSupportedError("permutation: not available with comm= (it is kept on "
                                    "rank 0's analysis; use a Solver without comm)")
        return self._core.permutation()

    def __repr__(self):
        st = self._core.stats()
        factor = st.get("factor", {})
        return (f"<strata.Solver n={self._shape[0]} type={factor.get('type', '?')} "
                f"nnz_l={st.get('nnz_l', '?')} backend={factor.get('backend', '?')}>")


def analyze(A, type="auto", ordering="nd", storage="full", max_block_size=0,
            device_memory_limit=0):
    """Runs the analysis phase of A only and returns its statistics as a dict.

    A : scipy.sparse matrix or array, shape (n, n), real dtype (values, when present,
    are used for scaling and type detection). Returns the analysis keys of
    :attr:`Solver.stats`: n, nnz_a, nnz_l, nnz_l_fronts, factor_flops (flops),
    fronts, largest_front_rows, largest_front_pivots, tree_height, fronts_per_level,
    peak_working_bytes and factor_bytes (bytes), memory_budget, batches, type,
    ordering, pairs, odd_cycles, and seconds (a dict of phase times). Raises as
    :class:`Solver` does.
    """
    core = _make_core(type, ordering, "cpu", max_block_size, 0, 0, 0.0, device_memory_limit)
    core.analyze(_to_matrix(A, storage))
    st = core.stats()
    for key in ("analyzed", "factorized", "solved"):
        st.pop(key, None)
    return st


def solve(A, b, **options):
    """x = A⁻¹ b in one call: ``Solver(A, **options).solve(b)``. b has shape (n,) or
    (n, k); x has the shape of b."""
    return Solver(A, **options).solve(b)
