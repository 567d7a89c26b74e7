"""Sparse symmetric positive definite solves, factored once and reused."""
import os
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from ..errors import ConformalError


WORKERS = min(2, os.cpu_count() or 1)


def factor_all(*matrices):
    """``Factor`` of each matrix, computed concurrently (SuperLU releases the GIL)."""
    if WORKERS < 2 or len(matrices) < 2:
        return [Factor(K) for K in matrices]
    with ThreadPoolExecutor(min(WORKERS, len(matrices))) as ex:
        return list(ex.map(Factor, matrices))


class Factor:
    """LU factorisation of a sparse SPD matrix ``K`` (k,k), in symmetric mode with a fill-reducing
    ordering of K + K^T. ``solve(b)`` takes (k,) or (k,r) right-hand sides."""

    def __init__(self, K):
        K = sp.csc_matrix(K)
        try:
            self._lu = spla.splu(K, permc_spec='MMD_AT_PLUS_A', diag_pivot_thresh=0.0,
                                 options=dict(SymmetricMode=True))
        except RuntimeError as exc:
            raise ConformalError(f"the Laplacian is singular ({exc}): the mesh has degenerate "
                                 "triangles or a disconnected piece", 'degenerate') from None
        self.shape = K.shape

    def solve(self, b):
        b = np.asarray(b, dtype=np.float64)
        if b.ndim == 2 and b.shape[1] >= 8 and WORKERS > 1:
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
