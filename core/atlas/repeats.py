"""Islands that repeat: flatten each shape once.

Meshes are full of copies: the quarters of a teapot's body and lid, a car's wheels, the rungs of an
array, the left and right halves a mirror modifier makes. Two islands that are the same triangle mesh up
to a rotation and a translation (vertices within ``REPEAT_TOL`` of the island's radius, the same
oriented triangles, the same polygons) have the same edge lengths, so the same conformal map: every step
of ``_solve_island`` depends on the geometry only through quantities a rigid motion keeps. The copy
takes the first island's pieces (its local vertex ids and triangles renumbered, the same UVs in mesh
units, a copy of its reports) instead of solving again. A mirror image whose triangles turn the other
way (as a mirror modifier leaves them, normals outward) has the same edge lengths with the opposite
orientation: its conformal map is the original's reflected, with the same measures.

A copy numbered like its original (an array modifier's) is recognised by the fit of one rigid motion,
vertex by vertex, whatever its symmetry. Otherwise the copy's vertices may be numbered in any order.
The correspondence comes from the geometry: both
islands are put in the frame of their principal axes (the four choices of the axes' signs, then their
four reflections), each vertex of the copy is matched to the nearest vertex of the original (position
and the mean of its triangles' centroids, so that vertices at one point are told apart), and the match
is accepted only if it is one-to-one, within the tolerance, and carries every oriented triangle and
polygon onto one of the original's. Shapes whose principal axes are not determined (two equal moments)
are solved on their own: nothing is reused that is not checked.

``REPEAT_TOL`` is relative to the island's radius about its centroid. Blender stores positions in single
precision (relative spacing 6e-8), so a copy rotated by a modifier differs from its original by about
1e-7: the tolerance accepts that, and no difference a map could show.
"""
import copy
from functools import cached_property

import numpy as np
from scipy.spatial import cKDTree

REPEAT_TOL = 1e-6
# the axes' signs tried: the rotations of the principal frame first, then its reflections
SIGNS = ((1, 1, 1), (-1, -1, 1), (-1, 1, -1), (1, -1, -1), (-1, 1, 1), (1, -1, 1), (1, 1, -1), (-1, -1, -1))
CORNERS = {False: np.array([0, 1, 2]), True: np.array([0, 2, 1])}    # a reflection reverses the winding


def principal_frame(V: np.ndarray):
    """(centred points (n,3) in the frame of their principal axes, radius about the centroid,
    the moments (3,) in ascending order) of the points ``V`` (n,3)."""
    a = V - V.mean(0)
    w, R = np.linalg.eigh(a.T @ a)
    if np.linalg.det(R) < 0:
        R[:, 0] = -R[:, 0]
    return a @ R, float(np.sqrt((a * a).sum(1).max())), w


def side_lengths(V, F):
    """The lengths (3m,) of the sides of the triangles ``F`` (m,3) on ``V`` (n,3), sorted."""
    return np.sort(np.linalg.norm(V[F] - V[F[:, [1, 2, 0]]], axis=2).ravel())


def _fan_centroids(P, F):
    """Mean (n,3) of the centroids of the triangles ``F`` (m,3) at each vertex of ``P`` (n,3)."""
    C = np.zeros_like(P)
    k = np.zeros(len(P))
    cen = P[F].mean(1)
    for c in range(3):
        np.add.at(C, F[:, c], cen)
        np.add.at(k, F[:, c], 1.0)
    return C / np.maximum(k, 1.0)[:, None]


def _canonical_rows(F):
    """Each row of ``F`` (m,3) turned cyclically so that its smallest entry comes first, and the
    turn (m,) applied: row ``k`` of the result is ``F[k, (c + turn[k]) % 3]`` for c = 0, 1, 2."""
    turn = F.argmin(1)
    idx = (np.arange(3)[None, :] + turn[:, None]) % 3
    return np.take_along_axis(F, idx, 1), turn


class Shape:
    """An island kept for matching: positions ``V`` (n,3), triangles ``F`` (m,3), polygons ``poly``
    (m,) or None, and what ``match_shape`` compares against, each computed once, when a candidate
    first needs it: the principal frame, the sorted side lengths, a KD-tree of (position, fan
    centroid) in that frame, and the triangles' canonical rows in sorted order."""

    def __init__(self, V, F, poly=None):
        self.V, self.F = np.array(V, float), np.array(F, np.int64)
        self.poly = None if poly is None else np.array(poly)

    @cached_property
    def frame(self):
        return principal_frame(self.V)

    @cached_property
    def sides(self):
        return side_lengths(self.V, self.F)

    @cached_property
    def tree(self):
        P = self.frame[0]
        return cKDTree(np.hstack([P, _fan_centroids(P, self.F)]))

    @cached_property
    def canonical(self):
        """(rows (m,3) in sorted order, turn (m,), order (m,)): ``_canonical_rows`` of ``F``, sorted."""
        rows, turn = _canonical_rows(self.F)
        order = np.lexsort(rows.T[::-1])
        return rows[order], turn, order


def _moved_in_order(V0, V, tol):
    """True if the points ``V`` (n,3) are ``V0`` (n,3) moved by one rotation and translation, point by
    point, within ``tol`` (the rotation from the best fit of the centred points, proper only)."""
    A, B = V0 - V0.mean(0), V - V.mean(0)
    U, _, Wt = np.linalg.svd(B.T @ A)
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Wt)) or 1.0])
    return bool(np.abs(B @ (U @ D @ Wt) - A).max() <= tol)


def match(V0, F0, poly0, V, F, poly, tol=REPEAT_TOL):
    """``match_shape`` of the island ``V``, ``F``, ``poly`` onto the island ``V0`` (n,3), ``F0`` (m,3),
    ``poly0`` (m,) or None."""
    return match_shape(Shape(V0, F0, poly0), V, F, poly, tol)


def match_shape(shape, V, F, poly, tol=REPEAT_TOL, this=None):
    """Correspondence of the island ``V`` (n,3), ``F`` (m,3), ``poly`` (m,) or None onto the ``Shape``
    ``shape``: (vertex (n,) vertex of the original of each vertex, face (m,) triangle of the original
    of each triangle, shift (m,), mirror (bool)): corner ``c`` of a triangle is the original's corner
    ``(CORNERS[mirror][c] + shift) % 3``. None when they are not the same mesh up to a rotation and a
    translation, or a reflection with the triangles turned the other way. ``this``: the island's own
    ``Shape`` if the caller has it (its frame and side lengths are then computed once for all the
    shapes it is matched against)."""
    if shape.V.shape != V.shape or shape.F.shape != F.shape or (shape.poly is None) != (poly is None):
        return None
    this = Shape(V, F, poly) if this is None else this
    _, r0, w0 = shape.frame
    P, r, w = this.frame
    if not r0 > 0 or abs(r - r0) > tol * r0 or np.abs(w - w0).max() > 4 * tol * r0 * r0 * len(V):
        return None
    # the same mesh moved has the same side lengths: a cheap test before the matching (spot's two
    # halves have the same vertices, triangulated differently)
    if np.abs(shape.sides - this.sides).max() > 2 * tol * r0:
        return None
    if np.array_equal(shape.F, F) and (poly is None or np.array_equal(shape.poly, poly)) and \
            _moved_in_order(shape.V, V, tol * r0):
        # numbered alike (an array modifier's copies): vertex i is vertex i, whatever the symmetry
        return np.arange(len(V)), np.arange(len(F)), np.zeros(len(F), np.int64), False
    if np.diff(w0).min() <= 1e-6 * max(w0[-1], 1e-300):
        return None                                   # axes not determined: no frame to match in
    # each vertex is told apart by its position and the centroid of its triangles' centroids: vertices
    # at one point (a pole, a pinch) belong to different triangles
    C = _fan_centroids(P, F)
    rows0, turn0, order0 = shape.canonical
    for signs in SIGNS:
        s = np.array(signs, float)
        mirror = s.prod() < 0
        dist, vertex = shape.tree.query(np.hstack([P * s, C * s]))
        if dist.max() > tol * r0 or len(np.unique(vertex)) != len(vertex):
            continue
        rows, turn = _canonical_rows(vertex[F[:, CORNERS[mirror]]])
        o = np.lexsort(rows.T[::-1])
        if not np.array_equal(rows0, rows[o]):
            continue
        face = np.empty(len(F), np.int64)
        face[o] = order0
        if poly is not None:
            pairs = np.unique(np.stack([poly, shape.poly[face]], 1), axis=0)
            if len(np.unique(pairs[:, 0])) != len(pairs) or len(np.unique(pairs[:, 1])) != len(pairs):
                continue
        return vertex, face, (turn0[face] - turn) % 3, bool(mirror)
    return None


class Repeats:
    """The islands solved so far. ``find`` before solving an island, ``add`` after."""

    def __init__(self, tol: float = REPEAT_TOL):
        self.tol = tol
        self._seen = {}                       # (n, m) -> [(Shape, desc, pieces)]
        self._radii = {}                      # (n, m) -> [radius of each of those shapes]

    def find(self, V, F, poly=None):
        """(desc of the island it repeats, that island's pieces renumbered for this one) for the island
        ``V`` (n,3), ``F`` (m,3), ``poly`` (m,) or None, or None if no island solved so far has its
        shape. A piece is ``(faces (k,) rows of F, Fp (k,3) piece vertex ids, pv (N,) local vertex of
        each piece vertex, uv (N,2), report)``, as ``_solve_island`` returns them."""
        key = (len(V), len(F))
        if key not in self._seen:
            return None
        this = Shape(V, F, poly)
        r = this.frame[1]
        # only the shapes of about this radius are matched: a triangle soup of k distinct triangles
        # matched each against all before it (bump at 2048: 53 s)
        radii = np.array(self._radii[key])
        for i in np.flatnonzero(np.abs(radii - r) <= self.tol * radii).tolist():
            shape, desc, pieces = self._seen[key][i]
            got = match_shape(shape, V, F, poly, self.tol, this)
            if got is None:
                continue
            vertex, face, shift, mirror = got
            local_of = np.empty(len(V), np.int64)
            local_of[vertex] = np.arange(len(V))            # this island's vertex of each original one
            face_of = np.empty(len(F), np.int64)
            face_of[face] = np.arange(len(F))
            out = []
            for fl, Fp, pv, uv, rep in pieces:
                mine = face_of[fl]
                # corner c of this island's triangle is corner (CORNERS[mirror][c] + shift) % 3 of the
                # original's; a mirror image's conformal map is the original's reflected
                idx = (CORNERS[mirror][None, :] + shift[mine][:, None]) % 3
                out.append((mine, np.take_along_axis(Fp, idx, 1), local_of[pv],
                            uv * np.array([-1.0, 1.0]) if mirror else uv.copy(), copy.deepcopy(rep)))
            return desc, out
        return None

    def add(self, V, F, poly, desc, pieces):
        """Keep the solved ``pieces`` of the island ``desc`` with positions ``V`` (n,3), ``F`` (m,3)
        and ``poly`` (m,) or None."""
        shape = Shape(V, F, poly)
        self._seen.setdefault((len(V), len(F)), []).append((shape, desc, copy.deepcopy(pieces)))
        self._radii.setdefault((len(V), len(F)), []).append(shape.frame[1])
