"""Sparse symmetric positive definite solves, factored once and reused.

Two backends (docs/scale.md):

- ``cholmod``: a sparse Cholesky factorisation ``K = L L^T`` by CHOLMOD (nested dissection ordering)
  through the small ``cholespy`` binding, when its wheel is installed. Used for matrices of at
  least ``CHOLMOD_MIN`` rows (about 600k triangles): it scales as a 2D nested dissection should
  (measured 2.6x the factor time from 1M to 2M triangles, SuperLU 5.3x) in a third of SuperLU's
  factor memory.
- ``superlu``: scipy's SuperLU in symmetric mode, always available. Used below ``CHOLMOD_MIN``
  (measured faster there, and it releases the GIL, so two factorisations run on two cores), where
  cholespy is missing, for a matrix that is not numerically symmetric, and for one that CHOLMOD
  finds not positive definite (a Laplacian of a mesh with very obtuse triangles can be indefinite
  yet nonsingular).

``backend(size)`` names the backend a new factorisation of a ``size`` x ``size`` matrix uses;
``Factor.backend`` the one that ran. ``CONFORMAL_SOLVER=superlu`` or ``=cholmod`` in the environment
forces one for all sizes (for comparisons).
"""
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import ConformalError

try:                                     # the optional compiled Cholesky (a pinned requirement)
    import cholespy as _cholespy
except ImportError:                      # pragma: no cover - depends on the platform's wheels
    _cholespy = None

WORKERS = min(2, os.cpu_count() or 1)
BACKENDS = ('cholmod', 'superlu')
SPLIT_RHS = 8           # SuperLU: split at least this many right-hand sides over WORKERS threads
CHOLMOD_MIN = 300_000   # rows from which CHOLMOD is used (a disk of ~600k triangles; docs/scale.md)
_SYM_TOL = 1e-12        # relative asymmetry above which a matrix goes to SuperLU


def backend(size=None):
    """Name of the backend a new ``Factor`` of a ``size`` x ``size`` matrix uses: 'cholmod' or
    'superlu'. Without ``size``: 'cholmod' if cholespy is installed (and not forced off)."""
    forced = os.environ.get('CONFORMAL_SOLVER', '').strip().lower()
    if _cholespy is None or forced == 'superlu':
        return 'superlu'
    if forced == 'cholmod' or size is None or size >= CHOLMOD_MIN:
        return 'cholmod'
    return 'superlu'


def factor_all(*matrices):
    """``Factor`` of each matrix. SuperLU releases the GIL, so its factorisations run on two
    threads; CHOLMOD's binding holds it (two threads measured no faster), so they run in turn."""
    if WORKERS < 2 or len(matrices) < 2 or any(backend(K.shape[0]) == 'cholmod' for K in matrices):
        return [Factor(K) for K in matrices]
    with ThreadPoolExecutor(min(WORKERS, len(matrices))) as ex:
        return list(ex.map(Factor, matrices))


def _is_symmetric(K):
    """True if the CSC matrix ``K`` equals its transpose to ``_SYM_TOL`` relative (max norm)."""
    if K.nnz == 0:
        return True
    D = (K - K.T).tocsc()
    return D.nnz == 0 or np.abs(D.data).max() <= _SYM_TOL * np.abs(K.data).max()


class _QuietStderr:
    """Send the C-level stderr (file descriptor 2) to a temporary file for the duration and replay
    it afterwards, unless ``drop`` is set: CHOLMOD prints its own warning when it meets a matrix
    that is not positive definite, which we handle (SuperLU retry) and report ourselves."""

    def __init__(self):
        self.drop = False

    def __enter__(self):
        import tempfile
        try:
            self._saved = os.dup(2)
            self._tmp = tempfile.TemporaryFile()
            os.dup2(self._tmp.fileno(), 2)
        except (OSError, ValueError):          # no usable fd 2 (e.g. some embedded interpreters)
            self._saved = None
        return self

    def __exit__(self, *exc):
        if self._saved is None:
            return False
        os.dup2(self._saved, 2)
        os.close(self._saved)
        try:
            if not self.drop:
                self._tmp.seek(0)
                text = self._tmp.read()
                if text:
                    os.write(2, text)
        finally:
            self._tmp.close()
        return False


class Factor:
    """Factorisation of a sparse symmetric positive definite matrix ``K`` (k,k), computed once.

    ``solve(b)`` takes (k,) or (k,r) right-hand sides and returns float64 of the same shape.
    ``backend`` is the backend that ran ('cholmod' or 'superlu'); ``method`` (optional) forces one,
    otherwise ``backend(k)`` chooses.
    Raises ``ConformalError`` ('degenerate') if ``K`` is singular."""

    def __init__(self, K, method=None):
        K = sp.csc_matrix(K, dtype=np.float64)
        self.shape = K.shape
        method = method or backend(K.shape[0])
        if method not in BACKENDS:
            raise ConformalError(f"unknown solver backend {method!r}: use one of {', '.join(BACKENDS)}")
        if method == 'cholmod' and _cholespy is None:
            method = 'superlu'
        self._chol = self._lu = None
        if method == 'cholmod' and K.shape[0] > 0 and _is_symmetric(K):
            self._chol = self._cholmod(K)
        if self._chol is None:
            self._lu = self._superlu(K)
        self.backend = 'cholmod' if self._chol is not None else 'superlu'

    @staticmethod
    def _cholmod(K):
        """CHOLMOD factor of the lower triangle of ``K``, or None if it is not positive definite."""
        K = K.copy()
        K.sum_duplicates()
        K.sort_indices()
        n = K.shape[0]
        with _QuietStderr() as quiet:
            try:
                return _cholespy.CholeskySolverD(n, K.indptr.astype(np.int32), K.indices.astype(np.int32),
                                                 np.ascontiguousarray(K.data), _cholespy.MatrixType.CSC)
            except ValueError:                 # "Matrix is not positive definite!"
                quiet.drop = True
                return None

    @staticmethod
    def _superlu(K):
        try:
            return spla.splu(K, permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                             options=dict(SymmetricMode=True))
        except RuntimeError as exc:
            raise ConformalError(f"the Laplacian is singular ({exc}): the mesh has degenerate "
                                 "triangles or a disconnected piece", 'degenerate') from None

    def _solve_cholmod(self, b):
        b = np.ascontiguousarray(b)
        x = np.empty_like(b)
        self._chol.solve(b, x)
        return x

    def solve(self, b):
        """``K^-1 b`` for ``b`` (k,) or (k,r); float64 of the same shape."""
        b = np.asarray(b, dtype=np.float64)
        if b.shape[0] != self.shape[0]:
            raise ConformalError(f"right-hand side has {b.shape[0]} rows, the matrix {self.shape[0]}")
        if b.size == 0:
            return np.zeros(b.shape)
        if self._chol is not None:
            x = self._solve_cholmod(b)
        elif b.ndim == 2 and b.shape[1] >= SPLIT_RHS and WORKERS > 1:
            # SuperLU releases the GIL: split many right-hand sides over the cores
            parts = np.array_split(np.arange(b.shape[1]), WORKERS)
            with ThreadPoolExecutor(WORKERS) as ex:
                cols = list(ex.map(lambda p: self._lu.solve(np.ascontiguousarray(b[:, p])), parts))
            x = np.concatenate(cols, axis=1)
        else:
            x = self._lu.solve(b)
        if not np.all(np.isfinite(x)):
            raise ConformalError("the linear solve produced NaN: the mesh is numerically degenerate "
                                 "(needle or zero-area triangles)", 'degenerate', 'clean_mesh')
        return x
