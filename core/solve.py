"""Sparse symmetric positive definite solves, factored once and reused."""
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla

from .errors import ConformalError


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
                                 "triangles or a disconnected piece") from None
        self.shape = K.shape

    def solve(self, b):
        x = self._lu.solve(np.asarray(b, dtype=np.float64))
        if not np.all(np.isfinite(x)):
            raise ConformalError("the linear solve produced NaN: the mesh is numerically degenerate "
                                 "(needle or zero-area triangles); clean it up and retry")
        return x
