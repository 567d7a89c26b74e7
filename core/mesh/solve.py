"""Sparse symmetric positive definite solves, factored once and reused.

Two backends (docs/scale.md):

- ``cholmod``: CHOLMOD's supernodal sparse Cholesky factorisation ``K = L L^T`` with an optimised
  BLAS, through cvxopt's ``cholmod`` module, when its wheel is installed; where ``cholmod_block``
  reaches CHOLMOD, the numeric factorisation runs without the GIL and solves with many right-hand
  sides go to CHOLMOD in blocks of columns. Used from
  ``CHOLMOD_MIN`` rows: measured 1.7-2.7x faster than SuperLU from 8k to 100k triangles and 2.5-3x
  at 1M-2M (docs/scale.md), in about half of SuperLU's factor memory (one triangle instead of L and
  U).
- ``superlu``: scipy's SuperLU in symmetric mode, always available. Used below ``CHOLMOD_MIN``,
  where cvxopt is missing, for a matrix that is not numerically symmetric, and for one that CHOLMOD
  finds not positive definite (a Laplacian of a mesh with very obtuse triangles can be indefinite
  yet nonsingular). It releases the GIL, so two of its factorisations can run on two cores.

``backend(size)`` names the backend a new factorisation of a ``size`` x ``size`` matrix uses;
``Factor.backend`` the one that ran. ``CONFORMAL_SOLVER=superlu`` or ``=cholmod`` in the environment
forces one for all sizes (for comparisons).

Big meshes: a caller that knows where its unknowns lie (vertex positions) passes a fill-reducing
``order`` from ``fill_order`` (nested dissection by recursive coordinate bisection, separators last;
docs/scale.md). CHOLMOD takes it as its user ordering (and keeps it unless its own is better);
SuperLU factors the permuted matrix in that order ('NATURAL'), about half of its time with MMD at 1M
triangles. ``sub_order`` restricts one order of all vertices to a submatrix (interior vertices, all
but one vertex), so one ordering serves every matrix of a mesh.
"""
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..background import Background
from ..blas import library_paths, set_threads
from ..errors import ConformalError
from .cholmod_block import BlockSolver

try:                                     # the optional compiled Cholesky (a pinned requirement)
    from cvxopt import cholmod as _cholmod
    from cvxopt import matrix as _cvx_matrix
    from cvxopt import spmatrix as _cvx_spmatrix
except ImportError:                      # pragma: no cover - depends on the platform's wheels
    _cholmod = None


def _cvxopt_blas_threads(n=1):
    """Set the thread count of the OpenBLAS bundled in cvxopt's wheel (its own copy, used by nothing
    else here) to ``n``; returns the count it reports after, or None where the library is not found.

    CHOLMOD's supernodal kernels on 2D meshes are too small to gain from BLAS threads (factor CPU time
    equals wall time), but OpenBLAS's threads spin while they wait: on a busy machine (Blender's own
    threads, other processes) a 32-column solve measured 2.8x slower with them than without
    (docs/scale.md)."""
    return set_threads(library_paths('cvxopt'), n)


BLAS_THREADS = _cvxopt_blas_threads() if _cholmod is not None else None

WORKERS = min(2, os.cpu_count() or 1)
BACKENDS = ('cholmod', 'superlu')
SPLIT_RHS = 8           # SuperLU: split at least this many right-hand sides over WORKERS threads ...
SPLIT_MIN_ROWS = 1_000  # ... for a matrix of at least this many rows (below, a pool's 0.15 ms costs more
                        # than the solve: 0.02-0.08 ms for 32 columns at 49-225 rows; even at 961)
BLOCK_BYTES = 16 << 20  # SuperLU: right-hand sides are solved in column blocks of at most this size
CHOLMOD_MIN = 1_000     # rows from which CHOLMOD is used (below, its fixed cost of ~0.5 ms dominates)
CHOLMOD_BLOCK = 4       # cvxopt's solve: this many right-hand sides per call (the GIL is free between)
CHOLMOD_BLOCK_BYTES = 64 << 20  # cholmod_block: right-hand sides per CHOLMOD call, at most this size
PARALLEL_MAX = 400_000  # total rows up to which factor_all runs SuperLU factorisations at once (memory)
PARALLEL_MIN = 4_000    # total rows from which that pays (below, the threads cost more than they save)
ND_MIN = 60_000         # rows from which fill_order computes a nested dissection order
ND_LEAF = 16            # nested dissection stops splitting parts of at most this many rows
_SYM_TOL = 1e-12        # relative asymmetry above which a matrix goes to SuperLU


def backend(size=None):
    """Name of the backend a new ``Factor`` of a ``size`` x ``size`` matrix uses: 'cholmod' or
    'superlu'. Without ``size``: 'cholmod' if cvxopt is installed (and not forced off)."""
    forced = os.environ.get('CONFORMAL_SOLVER', '').strip().lower()
    if _cholmod is None or forced == 'superlu':
        return 'superlu'
    if forced == 'cholmod' or size is None or size >= CHOLMOD_MIN:
        return 'cholmod'
    return 'superlu'


def factor_all(*matrices, orders=None, defer_last=False, meanwhile=None):
    """``Factor`` of each matrix (with ``orders``: one fill-reducing order or None per matrix).
    SuperLU releases the GIL, and so does CHOLMOD's numeric factorisation where ``cholmod_block``
    reaches it (cvxopt's own ``numeric`` holds it: then CHOLMOD's factorisations run in turn). Such
    factorisations run on two threads from ``PARALLEL_MIN`` up to ``PARALLEL_MAX`` rows in all
    (SuperLU, measured at 2.2k rows: no gain; 8.4k: 15 ms against 21 ms; above the maximum, two
    factorisations' work space at once would lift the peak memory of a 1M-triangle disk from 1.8 GB
    to 2.1 GB; docs/scale.md).

    ``defer_last``: above ``PARALLEL_MAX``, on a machine with two or more cores, the factorisations
    run in turn and the last one on its own thread, coming back as a ``FactorJob`` (``result()``
    gives its Factor), so the caller's work with the others (solves, numpy; both release the GIL)
    overlaps it (CHOLMOD at 1M triangles: 6.1 -> 5.7 s in the add-on, docs/scale.md "Twentieth
    round").

    ``meanwhile``: optional callable (no arguments, result discarded) run on the calling thread while
    factorisations run on threads (after the last one is started), else after them: work the caller
    needs anyway (8k triangles: the 2-3 ms of a disk's triangle frames, docs/scale.md)."""
    orders = list(orders) if orders is not None else [None] * len(matrices)
    if len(orders) != len(matrices):
        raise ConformalError(f"{len(orders)} orders for {len(matrices)} matrices")
    methods = [backend(K.shape[0]) for K in matrices]
    rows = sum(K.shape[0] for K in matrices)
    free = all(m == 'superlu' or BlockSolver.load() is not None for m in methods)
    in_turn = WORKERS < 2 or len(matrices) < 2 or not free
    meanwhile = meanwhile or (lambda: None)
    if in_turn or not PARALLEL_MIN <= rows <= PARALLEL_MAX:
        if defer_last and not in_turn and rows > PARALLEL_MAX:
            done = [Factor(K, order=o) for K, o in zip(matrices[:-1], orders[:-1])]
            job = FactorJob(matrices[-1], order=orders[-1])
            meanwhile()
            return done + [job]
        done = [Factor(K, order=o) for K, o in zip(matrices, orders)]
        meanwhile()
        return done
    with ThreadPoolExecutor(min(WORKERS, len(matrices))) as ex:
        jobs = [ex.submit(Factor, K, order=o) for K, o in zip(matrices, orders)]
        meanwhile()
        return [j.result() for j in jobs]


class FactorJob(Background):
    """``Factor(K, order=order)`` computed on its own thread (SuperLU releases the GIL, so the caller
    goes on meanwhile). ``result()`` waits and returns the ``Factor``, or raises its error."""

    def __init__(self, K, order=None):
        super().__init__(Factor, K, order=order)


def fill_order(points, K, min_size=None, leaf=ND_LEAF):
    """Nested dissection order (k,) int64 of the symmetric sparse matrix ``K`` (k,k) whose row i
    belongs to the point ``points[i]`` (k,d), for factoring ``K[order][:, order]``; None below
    ``min_size`` rows (default ``ND_MIN``; the solver's own ordering is as good there).

    Each part (at first all rows) is split at the median of its longest bounding-box axis; the rows of
    the second half with a neighbour (a nonzero of K) in the first half form the separator, which
    takes the part's last positions; both halves are split again until at most ``leaf`` rows are
    left, which keep their sorted order. All parts of one level are split at once (vectorised), so
    the cost is O(k log k) numpy work over about log2(k / leaf) levels."""
    k = K.shape[0]
    if k < (ND_MIN if min_size is None else min_size):
        return None
    X = np.asarray(points, np.float64).reshape(k, -1)
    cols = [np.ascontiguousarray(X[:, d]) for d in range(X.shape[1])]
    flat = np.ascontiguousarray(X).ravel()
    C = sp.triu(sp.coo_matrix(K), 1).tocoo()
    idx = np.int32 if 2 * k < 2 ** 31 - 1 else np.int64
    ei, ej = C.row.astype(idx), C.col.astype(idx)
    del C
    pos = np.empty(k, np.int64)              # output position of each row
    work = np.arange(k)                      # rows of the open parts, grouped by part
    part = np.zeros(k, np.int64)             # part of each entry of work (non-decreasing)
    lo_pos, size = np.zeros(1, np.int64), np.array([k])     # output range of each open part
    code = np.full(k, -1, idx)               # 2 * part + (second half) of the rows being split, else -1
    sep = np.zeros(k, bool)
    while len(work):
        first = np.zeros(len(size), np.int64)
        np.cumsum(size[:-1], out=first[1:])
        rank = np.arange(len(work)) - first[part]
        small = (size <= leaf)[part]
        if small.any():                      # leaves: keep the current order in their range
            pos[work[small]] = lo_pos[part[small]] + rank[small]
        big = size > leaf
        if not big.any():
            break
        renum = np.cumsum(big) - 1
        work, part = work[~small], renum[part[~small]]
        lo_pos, size = lo_pos[big], size[big]
        first = np.zeros(len(size), np.int64)
        np.cumsum(size[:-1], out=first[1:])
        Pw = [c[work] for c in cols]
        lo = np.stack([np.minimum.reduceat(c, first) for c in Pw], 1)
        ext = np.stack([np.maximum.reduceat(c, first) for c in Pw], 1) - lo
        axis = np.argmax(ext, axis=1)
        a = axis[part]
        span = ext[np.arange(len(size)), axis] * (1 + 1e-9) + 1e-300
        d = len(cols)
        key = part + (flat[work * d + a] - lo.ravel()[part * d + a]) / span[part]      # in [part, part+1)
        o = np.argsort(key, kind='stable')
        work = work[o]
        rank = np.arange(len(work)) - first[part]
        side = rank >= (size // 2)[part]     # the second half of each part
        code[work] = 2 * part + side
        # edges inside a part: those between its halves put their second-half end in the separator;
        # edges between parts or touching a separator never matter again
        ci, cj = code[ei], code[ej]
        cut = ((ci >> 1) == (cj >> 1)) & (ci != cj) & (ci >= 0)
        sep[np.where(ci[cut] & 1, ei[cut], ej[cut])] = True
        is_sep = sep[work]
        n_sep = np.bincount(part, is_sep, minlength=len(size)).astype(np.int64)
        n_first = np.bincount(part, ~side, minlength=len(size)).astype(np.int64)
        if is_sep.any():                     # separators: the last positions of their part's range
            sp_part = part[is_sep]
            start = np.searchsorted(sp_part, np.arange(len(size)))
            pos[work[is_sep]] = (lo_pos + size - n_sep)[sp_part] + np.arange(len(sp_part)) - start[sp_part]
        alive = (ci == cj) & (ci >= 0) & ~sep[ei] & ~sep[ej]
        ei, ej = ei[alive], ej[alive]
        keep = ~is_sep
        work, part = work[keep], 2 * part[keep] + side[keep]      # still grouped: first half first
        lo_pos = np.stack([lo_pos, lo_pos + n_first], 1).ravel()
        size = np.stack([n_first, size - n_first - n_sep], 1).ravel()
        nonempty = size > 0
        part = (np.cumsum(nonempty) - 1)[part]
        lo_pos, size = lo_pos[nonempty], size[nonempty]
        code[:] = -1
    order = np.empty(k, np.int64)
    order[pos] = np.arange(k)
    return order


def sub_order(order, rows):
    """The order (r,) of the submatrix ``K[rows][:, rows]`` that ``order`` (k,) of ``K`` induces
    (``rows`` increasing indices or a (k,) bool mask); None if ``order`` is None."""
    if order is None:
        return None
    rows = np.flatnonzero(rows) if np.asarray(rows).dtype == bool else np.asarray(rows, np.int64)
    at = np.full(len(order), -1, np.int64)
    at[rows] = np.arange(len(rows))
    sub = at[order]
    return sub[sub >= 0]


def _is_symmetric(K):
    """True if the CSC matrix ``K`` equals its transpose to ``_SYM_TOL`` relative (max norm)."""
    if K.nnz == 0:
        return True
    D = (K - K.T).tocsc()
    return D.nnz == 0 or np.abs(D.data).max() <= _SYM_TOL * np.abs(K.data).max()


class Factor:
    """Factorisation of a sparse symmetric positive definite matrix ``K`` (k,k), computed once.

    ``solve(b)`` takes (k,) or (k,r) right-hand sides and returns float64 of the same shape.
    ``backend`` is the backend that ran ('cholmod' or 'superlu'); ``method`` (optional) forces one,
    otherwise ``backend(k)`` chooses, or SuperLU when ``order`` is given. ``order`` (k,) optional:
    a fill-reducing permutation of the rows (``fill_order``) in which SuperLU factors ``K``
    (CHOLMOD orders by itself); ``ordering`` says which ordering ran ('given', 'mmd' or 'cholmod').
    Raises ``ConformalError`` ('degenerate') if ``K`` is singular."""

    def __init__(self, K, method=None, order=None):
        K = sp.csc_matrix(K, dtype=np.float64)
        self.shape = K.shape
        self._order = None
        if order is not None:
            order = np.asarray(order, np.int64)
            if order.shape != (K.shape[0],):
                raise ConformalError(f"the order has {order.size} entries, the matrix {K.shape[0]} rows")
        method = method or backend(K.shape[0])
        if method not in BACKENDS:
            raise ConformalError(f"unknown solver backend {method!r}: use one of {', '.join(BACKENDS)}")
        if method == 'cholmod' and _cholmod is None:
            method = 'superlu'
        self._chol = self._lu = None
        if method == 'cholmod' and K.shape[0] > 0 and _is_symmetric(K):
            self._chol = self._cholmod(K, order)
        if self._chol is None:
            if order is not None:
                self._order = order
                K = K[order][:, order].tocsc()
            self._lu = self._superlu(K, 'NATURAL' if order is not None else 'MMD_AT_PLUS_A')
        self.backend = 'cholmod' if self._chol is not None else 'superlu'
        self.ordering = ('given' if order is not None else 'cholmod') if self._chol is not None else \
            ('given' if order is not None else 'mmd')

    @staticmethod
    def _cholmod(K, order=None):
        """CHOLMOD's factor of ``K`` (its lower triangle, in ``order`` if given), or None if ``K`` is
        not positive definite or the binding refuses the arrays (then SuperLU factors it). cvxopt
        analyses the pattern; the numeric factorisation goes through ``cholmod_block`` where it
        loads (the GIL free meanwhile), else through cvxopt's ``numeric``."""
        C = sp.tril(K, format='csc')
        C.sum_duplicates()
        C.sort_indices()
        n = K.shape[0]
        block = BlockSolver.load()
        try:
            cols = np.repeat(np.arange(n, dtype=np.int64), np.diff(C.indptr))
            A = _cvx_spmatrix(_cvx_matrix(np.ascontiguousarray(C.data, np.float64)), _cvx_matrix(
                C.indices.astype(np.int64)), _cvx_matrix(cols), (n, n))
            del cols
            p = None if order is None else _cvx_matrix(np.asarray(order, np.int64))
            fac = _cholmod.symbolic(A) if p is None else _cholmod.symbolic(A, p=p)
            if block is not None:
                del A
                block.factorize(fac, C.indptr, C.indices, C.data)
            else:
                _cholmod.numeric(A, fac)       # CHOLMOD prints nothing here: it raises
            return fac
        except (ArithmeticError, ValueError, TypeError):    # not positive definite, or the arrays
            return None

    @staticmethod
    def _superlu(K, permc_spec):
        try:
            return spla.splu(K, permc_spec=permc_spec, diag_pivot_thresh=0.0,
                             options=dict(SymmetricMode=True))
        except RuntimeError as exc:
            raise ConformalError(f"the Laplacian is singular ({exc}): the mesh has degenerate "
                                 "triangles or a disconnected piece", 'degenerate') from None

    def _solve_cholmod(self, b):
        """CHOLMOD's solve of (k,) or (k,r) ``b``; (k,r) comes back Fortran-ordered.

        Where ``cholmod_block`` loads, columns go to CHOLMOD in blocks of at most
        ``CHOLMOD_BLOCK_BYTES`` (one pass over the factor per block, the GIL free during each). Else
        through cvxopt, whose solve takes one column per pass and holds the GIL for the whole call:
        blocks of ``CHOLMOD_BLOCK`` columns, so other threads (numpy work beside a long multi-column
        solve, Blender's interface) get the GIL between them."""
        block = BlockSolver.load()
        if b.ndim == 1:
            if block is not None:
                return block.solve(self._chol, b[:, None])[:, 0]
            B = _cvx_matrix(np.ascontiguousarray(b))
            _cholmod.solve(self._chol, B)
            return np.asarray(B)[:, 0]
        x = np.empty(b.shape, order='F')
        if block is not None:
            w = max(1, CHOLMOD_BLOCK_BYTES // (8 * b.shape[0]))
            for c0 in range(0, b.shape[1], w):
                block.solve(self._chol, b[:, c0:c0 + w], out=x[:, c0:c0 + w])
            return x
        for c0 in range(0, b.shape[1], CHOLMOD_BLOCK):
            B = _cvx_matrix(np.asfortranarray(b[:, c0:c0 + CHOLMOD_BLOCK]))
            _cholmod.solve(self._chol, B)
            x[:, c0:c0 + CHOLMOD_BLOCK] = np.asarray(B)
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
        else:
            rows = slice(None) if self._order is None else self._order
            x = np.empty(b.shape)
            if b.ndim == 1:
                x[rows] = self._lu.solve(b[rows])
            else:
                # columns in blocks of at most BLOCK_BYTES, each permuted, solved and put in its place
                # on its own (the peak memory of many right-hand sides stays near the output's); SuperLU
                # releases the GIL, so with SPLIT_RHS or more columns of SPLIT_MIN_ROWS or more rows
                # the blocks go to two threads
                r = b.shape[1]
                w = max(1, min(r, BLOCK_BYTES // (8 * max(1, b.shape[0]))))
                split = r >= SPLIT_RHS and b.shape[0] >= SPLIT_MIN_ROWS and WORKERS > 1
                if split:
                    w = min(w, -(-r // WORKERS))

                def block(c0):
                    x[rows, c0:c0 + w] = self._lu.solve(b[rows, c0:c0 + w])
                if split:
                    with ThreadPoolExecutor(WORKERS) as ex:
                        list(ex.map(block, range(0, r, w)))
                else:
                    for c0 in range(0, r, w):
                        block(c0)
        if not np.all(np.isfinite(x)):
            raise ConformalError("the linear solve produced NaN: the mesh is numerically degenerate "
                                 "(needle or zero-area triangles)", 'degenerate', 'clean_mesh')
        return x
