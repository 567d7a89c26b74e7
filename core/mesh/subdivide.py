"""Midpoint subdivision of a triangle mesh: the same polyhedral surface on smaller triangles.

Each triangle is split into four at its edge midpoints. The surface does not move (the new vertices lie
on the old edges, the new triangles in the old ones' planes), so geodesic distances are unchanged,
while a piecewise-linear map computed on the finer triangles follows the surface's conformal structure
more closely (``core.geodesic.solver``, "Finer triangles for a forced grid")."""
import numpy as np

from ..errors import ConformalError


def _edge_keys(F, n):
    """Sorted unique keys ``min * n + max`` (e,) of the edges of ``F`` (m,3), and the key index (m,3) of
    side (k, k+1) of each triangle."""
    E = np.sort(np.stack([F, F[:, [1, 2, 0]]], 2).reshape(-1, 2), 1)
    key, inv = np.unique(E[:, 0] * n + E[:, 1], return_inverse=True)
    return key, inv.reshape(-1, 3)


def subdivide(V, F):
    """Split every triangle of ``F`` (m,3) into 4 at its edge midpoints (flat: the surface does not move).
    Returns ``V2`` (n + e, 3) and ``F2`` (4m, 3); the first n vertices are the input's (``V`` (n,3),
    vertices in no triangle included), the midpoint of the i-th edge in key order (``_edge_keys``) is
    vertex n + i, and triangle f's children are ``f``, ``m + f``, ``2m + f`` (at its corners 0, 1, 2) and
    ``3m + f`` (the middle one), wound as f is."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n = len(V)
    key, side = _edge_keys(F, n)
    mid = n + side                           # midpoint of side (k, k+1) of each face
    V2 = np.vstack([V, 0.5 * (V[key // n] + V[key % n])])
    a, b, c = F.T
    ab, bc, ca = mid.T
    F2 = np.vstack([np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1), np.stack([ca, bc, c], 1),
                    np.stack([ab, bc, ca], 1)])
    return V2, F2


def subdivide_pairs(F, n, pairs):
    """The vertex pairs (2k,2) of ``subdivide(V, F)`` along the edges ``pairs`` (k,2) of ``F`` (m,3) (on
    ``n`` vertices), each split at its midpoint into two, in the order (a, mid), (mid, b). Raises
    ConformalError if a pair is no edge of ``F``."""
    F = np.asarray(F, np.int64)
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    key, _ = _edge_keys(F, n)
    want = np.minimum(pairs[:, 0], pairs[:, 1]) * n + np.maximum(pairs[:, 0], pairs[:, 1])
    at = np.minimum(np.searchsorted(key, want), max(len(key) - 1, 0))
    inside = (pairs >= 0).all() and (pairs < n).all()
    if len(want) and not (inside and len(key) and (key[at] == want).all()):
        raise ConformalError("a seam's vertex pair is no edge of the mesh: a seam must join two vertices "
                             "of one face")
    mid = n + at
    return np.stack([np.c_[pairs[:, 0], mid], np.c_[mid, pairs[:, 1]]], 1).reshape(-1, 2)


def subdivide_points(m, faces, bary):
    """The triangles (p,) and barycentric coordinates (p,3) in ``subdivide``'s output of the surface
    points given by their triangles ``faces`` (p,) of a mesh of ``m`` triangles and barycentric
    coordinates ``bary`` (p,3) there: the child at the corner whose coordinate is at least 1/2, else the
    middle one."""
    faces = np.asarray(faces, np.int64)
    l0, l1, l2 = np.asarray(bary, np.float64).T
    corner = np.where(l0 >= 0.5, 0, np.where(l1 >= 0.5, 1, np.where(l2 >= 0.5, 2, 3)))
    out = np.stack([1 - 2 * l2, 1 - 2 * l0, 1 - 2 * l1], 1)             # the middle child
    out = np.where((corner == 0)[:, None], np.stack([2 * l0 - 1, 2 * l1, 2 * l2], 1), out)
    out = np.where((corner == 1)[:, None], np.stack([2 * l0, 2 * l1 - 1, 2 * l2], 1), out)
    out = np.where((corner == 2)[:, None], np.stack([2 * l0, 2 * l1, 2 * l2 - 1], 1), out)
    return corner * m + faces, np.clip(out, 0.0, 1.0)
