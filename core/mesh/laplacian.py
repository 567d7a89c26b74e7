"""Cotan Laplacian and per-triangle gradients (docs/math.md, discrete setting).

``L = D - W`` with ``W_ij = (cot a_ij + cot b_ij) / 2``: symmetric positive semidefinite, ``L @ 1 = 0``.
It equals the P1 finite-element stiffness matrix, ``L_ij = sum_T A_T grad(phi_i) . grad(phi_j)``.
"""
import numpy as np
import scipy.sparse as sp

from .geometry import cross, norm3


def corner_cotangents(V, F):
    """(m,3) cotangent of each corner angle; cot[t,k] belongs to the edge opposite corner k."""
    P = V[F]
    a = P[:, [1, 2, 0]] - P
    b = P[:, [2, 0, 1]] - P
    cr = norm3(cross(a, b))
    dot = np.einsum('mkd,mkd->mk', a, b)
    return dot / np.maximum(cr, np.finfo(float).tiny)


def cotan_laplacian(V, F, n=None):
    """Cotan Laplacian ``L`` (n,n) as scipy.sparse CSC, float64."""
    n = len(V) if n is None else n
    cot = 0.5 * corner_cotangents(V, F)
    idx = np.int32 if max(n, 6 * len(F)) < 2 ** 31 - 1 else np.int64   # scipy's own index type
    i = F[:, [1, 2, 0]].astype(idx).ravel()
    j = F[:, [2, 0, 1]].astype(idx).ravel()
    w = cot.ravel()
    W = sp.coo_matrix((np.r_[w, w], (np.r_[i, j], np.r_[j, i])), shape=(n, n)).tocsc()
    d = np.asarray(W.sum(axis=1)).ravel()
    return (sp.diags(d) - W).tocsc()


def face_gradients(V, F):
    """Gradients of the hat functions, (m,3,3): G[t,k] = grad phi_{F[t,k]} on triangle t (a 3-vector
    in the triangle's plane, units 1/length), and the unit normals N (m,3) and areas A (m,)."""
    P = V[F]
    n = cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    dbl = norm3(n)
    N = n / np.maximum(dbl, np.finfo(float).tiny)[:, None]
    E = np.empty_like(P)                           # edge opposite corner k, counter-clockwise
    for k in range(3):
        np.subtract(P[:, (k + 2) % 3], P[:, (k + 1) % 3], out=E[:, k])
    G = cross(N[:, None, :], E)
    G /= np.maximum(dbl, np.finfo(float).tiny)[:, None, None]
    return G, N, 0.5 * dbl


def gradient(G, F, f):
    """Per-triangle gradient (m,3) of a per-vertex scalar ``f`` (n,), from ``face_gradients``."""
    return np.einsum('mk,mkd->md', f[F], G)


def divergence(G, F, A, X, n):
    """Weak divergence (n,) of a per-triangle vector field ``X`` (m,3): ``b_i = sum_T A_T grad phi_i . X_T``.
    With this sign, ``L f = divergence(gradient(f))``."""
    return np.bincount(F.ravel(), (A[:, None] * np.einsum('mkd,md->mk', G, X)).ravel(), minlength=n)
