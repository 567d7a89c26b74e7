"""Intrinsic Delaunay triangulation with intrinsic mollification (docs/math.md §8).

The cotan Laplacian of a real mesh has negative weights wherever an edge is not Delaunay (the two angles
opposite it sum to more than pi). Harmonic maps built on it then lose the maximum principle and can fold.
The cure used here does not move any vertex and does not change the surface:

1. Intrinsic mollification (Sharp and Crane 2020, "A Laplacian for nonmanifold triangle meshes"). The
   mesh is described only by its edge lengths. Add one small ``eps >= 0`` to every edge length, the
   smallest one for which every triangle inequality holds with a margin ``delta * mean edge length``.
   Zero-area and needle triangles become valid, small, well-defined triangles; a good mesh gets
   ``eps = 0`` and is left exactly as it was.
2. Intrinsic edge flips (Fisher, Springborn, Schroeder and Bobenko 2007, "An algorithm for the
   construction of intrinsic Delaunay triangulations with applications to digital geometry
   processing"). An interior edge whose opposite angles sum to more than pi is replaced by the other
   diagonal of the quad formed by its two triangles. The quad is laid out flat in the plane (it is flat
   intrinsically: two triangles glued along an edge) and the new diagonal is measured there, so the
   metric is unchanged; only the triangulation of that metric changes. Repeating until no such edge is
   left gives the intrinsic Delaunay triangulation, whose interior-edge cotan weights are all
   nonnegative (an obtuse angle opposite a boundary edge stays: it cannot be flipped away). Boundary
   edges are never flipped.

The flips are done in parallel rounds, with array operations only: each round finds the non-Delaunay
edges among those that may have changed, picks a set of them in which no two share a triangle (an edge
wins when it is the worst non-Delaunay edge of both its triangles, so the worst edge overall always wins),
and flips that whole set at once. After flips two vertices may be joined by more than one edge, so the
data structure is by edge ids, never by vertex pairs:

- ``F`` (m,3): the vertices of each intrinsic triangle, counter-clockwise.
- ``FE`` (m,3): the edge opposite each corner; ``l = edge_lengths[FE]`` (m,3) are the per-face lengths.
- ``EF``, ``EC`` (E,2): the face and the corner opposite the edge on each of its two sides (-1 on the
  missing side of a boundary edge).

A flip keeps the number of triangles and the vertex set, so per-vertex quantities (``u``, UVs) live on
the original vertices. All operators here are computed from lengths only: corner angles ``theta``, areas
``A``, cotan weights, the cotan Laplacian ``L = D - W``, the angle sums (hence ``Omega``, which flips do
not change), a 2D layout of every intrinsic triangle, and per-triangle gradient / divergence in those
layouts. For the formulas see docs/math.md.

Only numpy and scipy are used, so this module has no dependency on the rest of the core.
"""
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..errors import ConformalError

_NEXT = np.array([1, 2, 0])
_PREV = np.array([2, 0, 1])


# --- length geometry (per-face lengths l (m,3), l[t,k] = length of the edge opposite corner k) ---------

def edge_lengths_3d(V, F):
    """(m,3) lengths of the 3D triangles; ``l[t,k] = |V[F[t,k+1]] - V[F[t,k+2]]|`` (units of V)."""
    V = np.asarray(V, dtype=np.float64)
    F = np.asarray(F, dtype=np.int64)
    P = V[F]                                                 # (m,3,3), one gather
    d = np.empty_like(P)
    for k in range(3):
        np.subtract(P[:, (k + 1) % 3], P[:, (k + 2) % 3], out=d[:, k])
    # np.linalg.norm(d, axis=2), the same sum in the same order, without its temporaries
    return np.sqrt(d[..., 0] * d[..., 0] + d[..., 1] * d[..., 1] + d[..., 2] * d[..., 2])


def mollify(l, delta=1e-4):
    """Intrinsic mollification of per-face edge lengths.

    ``l`` (m,3) lengths (l[t,k] opposite corner k; the same edge may appear in two faces). Returns
    ``(l + eps, eps)`` with the smallest ``eps >= 0`` such that, for every triangle and every k,
    ``l_i + l_j - l_k >= delta * mean(l)`` after adding ``eps`` to every entry. ``delta`` is relative to
    the mean of all entries of ``l`` (so it is scale free). A mesh that already has this margin gets
    ``eps = 0`` and its lengths back unchanged.
    """
    l = np.asarray(l, dtype=np.float64)
    if l.size == 0:
        return l.copy(), 0.0
    margin = delta * float(np.mean(l))
    # (l_i + eps) + (l_j + eps) - (l_k + eps) = l_i + l_j - l_k + eps
    slack = l.sum(axis=1, keepdims=True) - 2.0 * l          # (m,3): l_i + l_j - l_k for k = 0, 1, 2
    eps = max(0.0, float(np.max(margin - slack)))
    return l + eps, eps


def face_areas(l):
    """(m,) triangle areas from lengths ``l`` (m,3), Heron's formula in Kahan's stable ordering."""
    l = np.asarray(l, dtype=np.float64)
    l0, l1, l2 = l[:, 0], l[:, 1], l[:, 2]
    a = np.maximum(np.maximum(l0, l1), l2)                   # a >= b >= c
    c = np.minimum(np.minimum(l0, l1), l2)
    b = np.maximum(np.minimum(l0, l1), np.minimum(np.maximum(l0, l1), l2))
    q = (a + (b + c)) * (c - (a - b)) * (c + (a - b)) * (a + (b - c))
    return 0.25 * np.sqrt(np.maximum(q, 0.0))


def corner_angles(l):
    """(m,3) corner angles ``theta`` (radians) from lengths ``l`` (m,3), half-angle formula.

    ``tan(theta_k / 2) = sqrt((s - l_i)(s - l_j) / (s (s - l_k)))`` with s the half perimeter; accurate
    for needles and for angles near 0 and pi.
    """
    l = np.asarray(l, dtype=np.float64)
    s = 0.5 * l.sum(axis=1, keepdims=True)
    r = np.maximum(s - l, 0.0)                               # s - l_k, (m,3)
    num = np.sqrt(r[:, _NEXT] * r[:, _PREV])
    den = np.sqrt(s * r)
    return 2.0 * np.arctan2(num, den)


def corner_cotangents(l, A=None):
    """(m,3) cotangents of the corner angles from lengths: ``(l_i^2 + l_j^2 - l_k^2) / (4 A)``.

    Degenerate (zero-area) triangles give +-inf; mollify first to avoid them.
    """
    l = np.asarray(l, dtype=np.float64)
    if A is None:
        A = face_areas(l)
    l2 = l * l
    den = 4.0 * A
    out = np.empty_like(l2)
    with np.errstate(divide='ignore', invalid='ignore'):
        for k in range(3):                                   # column by column: no (m,3) gathers
            o = out[:, k]
            np.add(l2[:, (k + 1) % 3], l2[:, (k + 2) % 3], out=o)
            o -= l2[:, k]
            o /= den
    return out


def layout(l, A=None):
    """(m,3,2) a planar copy of each triangle: corner 0 at the origin, corner 1 on +x, corner 2 above.

    The triangle is counter-clockwise in its own frame. Units of ``l``.
    """
    l = np.asarray(l, dtype=np.float64)
    if A is None:
        A = face_areas(l)
    l0, l1, l2 = l[:, 0], l[:, 1], l[:, 2]                   # |p1 p2|, |p2 p0|, |p0 p1|
    with np.errstate(divide='ignore', invalid='ignore'):
        x = (l2 * l2 + l1 * l1 - l0 * l0) / (2.0 * l2)
        y = 2.0 * A / l2
    P = np.zeros((len(l), 3, 2))
    P[:, 1, 0] = l2
    P[:, 2, 0] = x
    P[:, 2, 1] = y
    return P


# --- the half-edge-free, edge-id based connectivity --------------------------------------------------

def _build_edges(F, n):
    """Edge ids from faces: returns FE (m,3), EF (E,2), EC (E,2). Raises on non-manifold/misoriented.

    One stable sort of the 3m undirected half-edge keys gives the edge ids (in increasing key order),
    the counts and both sides of every edge."""
    m = len(F)
    u = F[:, _NEXT].ravel()                                  # halfedge 3t+k goes u -> v, opposite corner k
    v = F[:, _PREV].ravel()
    key = np.minimum(u, v) * np.int64(n) + np.maximum(u, v)
    order = np.argsort(key, kind='stable')
    skey = key[order]
    first = np.ones(3 * m, dtype=bool)
    first[1:] = skey[1:] != skey[:-1]
    sid = np.cumsum(first) - 1                               # edge id of each sorted half-edge
    E = int(sid[-1]) + 1 if len(sid) else 0
    cnt = np.diff(np.flatnonzero(np.r_[first, True]))
    if np.any(cnt > 2):
        raise ConformalError(f'{int(np.sum(cnt > 2))} non-manifold edges have more than two faces',
                             'bad_topology')
    if np.any(u == v):
        raise ConformalError('a face uses the same vertex twice', 'degenerate')
    inv = np.empty(3 * m, dtype=np.int64)
    inv[order] = sid
    FE = inv.reshape(m, 3)
    EF = np.full((E, 2), -1, dtype=np.int64)
    EC = np.full((E, 2), -1, dtype=np.int64)
    h0 = order[first]
    h1 = order[~first]
    EF[sid[first], 0], EC[sid[first], 0] = h0 // 3, h0 % 3
    e1 = sid[~first]
    EF[e1, 1], EC[e1, 1] = h1 // 3, h1 % 3
    # consistent orientation: the two halfedges of an interior edge run in opposite directions
    g0 = h0[e1]
    if np.any(u[h1] != v[g0]):
        raise ConformalError('faces are not consistently oriented', 'bad_topology')
    return FE, EF, EC


def _cot_pair(l_edge, l_a1, l_a2, l_b1, l_b2):
    """cot alpha + cot beta for edges with opposite triangles (l_edge, l_a1, l_a2), (l_edge, l_b1, l_b2)."""
    def cot(lo, l1, l2):
        A = face_areas(np.stack([lo, l1, l2], axis=1))
        with np.errstate(divide='ignore', invalid='ignore'):
            return (l1 * l1 + l2 * l2 - lo * lo) / (4.0 * A)
    return cot(l_edge, l_a1, l_a2) + cot(l_edge, l_b1, l_b2)


@dataclass
class IntrinsicTriangulation:
    """An intrinsic triangulation of a fixed vertex set (n vertices), described by edge lengths.

    Fields: ``n`` vertex count; ``F`` (m,3) int64 intrinsic faces (CCW); ``FE`` (m,3) edge id opposite
    each corner; ``EF``/``EC`` (E,2) face and opposite corner on each side of an edge (-1: boundary side);
    ``edge_lengths`` (E,) float64 (units of V); ``report`` dict (see ``intrinsic_delaunay``).

    The areas and the gradient basis (used again by every ``gradient`` / ``divergence``) are computed
    once, on first use, and kept (read-only): do not modify ``F``, ``FE`` or ``edge_lengths`` in place
    afterwards (build a new triangulation instead). Lengths and cotangents are not kept (memory: 48 MB
    at 1M triangles, alive during the factorisations).
    """
    n: int
    F: np.ndarray
    FE: np.ndarray
    EF: np.ndarray
    EC: np.ndarray
    edge_lengths: np.ndarray
    report: dict = field(default_factory=dict)
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def _get(self, name):
        """The cached per-face array ``name`` ('A' or 'grad'), computed on first use."""
        c = self._cache
        if name not in c:
            if name == 'A':
                c['A'] = face_areas(self.l)
            else:
                c['grad'] = self._compute_grad_basis()
            c[name].setflags(write=False)
        return c[name]

    # -- per-face geometry --
    @property
    def l(self):
        """(m,3) per-face lengths, ``l[t,k]`` opposite corner k."""
        return self.edge_lengths[self.FE]

    def areas(self):
        """(m,) intrinsic triangle areas ``A`` (units of V squared; read-only)."""
        return self._get('A')

    def angles(self):
        """(m,3) corner angles ``theta`` in radians."""
        return corner_angles(self.l)

    def cotangents(self):
        """(m,3) cotangent of each corner angle."""
        return corner_cotangents(self.l, self.areas())

    def edge_weights(self):
        """(E,) cotan weights ``w_e = (cot alpha + cot beta) / 2`` (one term on a boundary edge)."""
        return _edge_weights(self.cotangents(), self.EF, self.EC)

    def edge_vertices(self):
        """(E,2) the two end vertices of each edge (several edges may join the same pair)."""
        t, k = self.EF[:, 0], self.EC[:, 0]
        return np.stack([self.F[t, _NEXT[k]], self.F[t, _PREV[k]]], axis=1)

    def cotan_laplacian(self):
        """(n,n) scipy.sparse CSC cotan Laplacian ``L = D - W`` of the intrinsic triangulation.

        Symmetric positive semidefinite, ``L @ 1 = 0``; off-diagonal entries ``-W_ij <= 0`` once the
        triangulation is Delaunay. Multiple edges between a vertex pair add up.
        """
        n = self.n
        m = len(self.F)
        # the 12m entries (-w at (i,j) and (j,i), w at (i,i) and (j,j)) in this order, with the index
        # type scipy would convert them to (int32 when it fits), written once into their arrays
        idx = np.int32 if max(n, 12 * m) < 2 ** 31 - 1 else np.int64
        h = 3 * m
        w = (0.5 * self.cotangents()).ravel()
        vals = np.empty(4 * h)
        np.negative(w, out=vals[:h])
        vals[h:2 * h] = vals[:h]
        vals[2 * h:3 * h] = w
        vals[3 * h:] = w
        i = self.F[:, _NEXT].astype(idx).ravel()
        j = self.F[:, _PREV].astype(idx).ravel()
        rows = np.concatenate([i, j, i, j])
        cols = np.concatenate([j, i, i, j])
        return sp.csc_matrix((vals, (rows, cols)), shape=(n, n))

    def angle_sums(self):
        """(n,) sum of corner angles at each vertex (radians); invariant under flips.

        ``Omega = 2*pi - angle_sums`` at interior vertices, ``k = pi - angle_sums`` on the boundary.
        """
        return np.bincount(self.F.ravel(), self.angles().ravel(), minlength=self.n)

    def layout(self):
        """(m,3,2) per-triangle planar layouts (corner 0 at origin, corner 1 on +x, CCW)."""
        return layout(self.l)

    def _grad_basis(self):
        """(m,3,2) gradient of each corner's hat function in its triangle's frame; and A (m,)."""
        return self._get('grad'), self.areas()

    def _compute_grad_basis(self):
        P = layout(self.l, self.areas())
        A = self.areas()
        e = P[:, _PREV] - P[:, _NEXT]                         # edge opposite corner k, CCW direction
        Je = np.stack([-e[..., 1], e[..., 0]], axis=-1)       # rotated 90 deg CCW: points to corner k
        with np.errstate(divide='ignore', invalid='ignore'):
            return Je / (2.0 * A[:, None, None])

    def gradient(self, f):
        """(m,2) gradient of the piecewise-linear per-vertex function ``f`` (n,) in each face's frame."""
        G, _ = self._grad_basis()
        f = np.asarray(f, dtype=np.float64)
        return np.einsum('mk,mkd->md', f[self.F], G)

    def divergence(self, X):
        """(n,) weak divergence of a per-face vector field ``X`` (m,2) given in each face's frame.

        ``b_i = sum_T A_T grad(phi_i) . X_T``, so that ``L @ f == divergence(gradient(f))``.
        """
        G, A = self._grad_basis()
        X = np.asarray(X, dtype=np.float64)
        b = A[:, None] * np.einsum('mkd,md->mk', G, X)
        return np.bincount(self.F.ravel(), b.ravel(), minlength=self.n)

    @staticmethod
    def rotated(X):
        """(m,2) the per-face field ``X`` (m,2) turned 90 degrees counter-clockwise in its frame."""
        X = np.asarray(X, dtype=np.float64)
        return np.stack([-X[:, 1], X[:, 0]], axis=1)

    def non_delaunay(self, tol=1e-12):
        """(E,) bool: interior edges with ``cot alpha + cot beta`` below ``-tol`` by more than its
        rounding error (opposite angles sum > pi; ``cot_rounding``)."""
        return _non_delaunay(self.cotangents(), self.EF, self.EC, tol, cot_rounding(self.l, self.areas()))


def _edge_weights(c, EF, EC):
    """(E,) half cotan weight sums of per-face cotangents ``c`` (m,3) over the sides ``EF``/``EC``."""
    w = np.zeros(len(EF))
    for side in (0, 1):
        ok = EF[:, side] >= 0
        w[ok] += 0.5 * c[EF[ok, side], EC[ok, side]]
    return w


# a cotangent computed from lengths carries a rounding error of about machine epsilon times the sum of
# the squared lengths over four times the area (the numerator cancels on a sliver); this many of those
ROUNDING_ULPS = 64.0


def cot_rounding(l, A):
    """(m,) the rounding error bound of each face's cotangents from its lengths ``l`` (m,3) and areas
    ``A`` (m,): ``ROUNDING_ULPS eps sum(l^2) / (4 A)`` (about 1e-13 on a well-shaped triangle, up to
    1e-9 on a sliver whose lengths nearly meet the triangle inequality). 0 on a zero-area face: its
    cotangents are infinite, and their sign decides."""
    with np.errstate(divide='ignore', invalid='ignore'):
        rho = ROUNDING_ULPS * np.finfo(np.float64).eps * (l * l).sum(axis=1) / (4.0 * A)
    return np.where(A > 0, rho, 0.0)


def _non_delaunay(c, EF, EC, tol, rho):
    """(E,) bool: interior edges whose cotangents ``c`` (m,3) sum below ``-tol`` by more than the two
    faces' rounding errors ``rho`` (m,) (``cot_rounding``)."""
    inner = EF[:, 1] >= 0
    s = np.zeros(len(EF))
    f0, f1 = EF[inner, 0], EF[inner, 1]
    s[inner] = (c[f0, EC[inner, 0]] + c[f1, EC[inner, 1]]) + (rho[f0] + rho[f1])
    return inner & (s < -tol)


def intrinsic_delaunay(V, F, mollify_delta=1e-4, max_rounds=10000, tol=1e-12, lengths=None):
    """Intrinsic Delaunay triangulation of the mesh ``V`` (n,3), ``F`` (m,3) by edge flips on lengths.

    ``F`` must be manifold and consistently oriented (boundaries and several components are fine).
    ``lengths`` optional (m,3) per-face lengths to use instead of the 3D ones (they must agree on the
    two faces of an edge; the last face wins). Lengths are first mollified with ``mollify_delta``
    (0 disables), then non-Delaunay interior edges (``cot alpha + cot beta < -tol``) are flipped in
    parallel rounds until none is left or ``max_rounds`` is reached (``max_rounds=0``: no flips, the
    mollified input mesh). The test allows for the sum's rounding error (``cot_rounding``): on a sliver
    whose cotangents are only known to 1e-12, an edge that is Delaunay within that error is kept, where
    flipping it would give a diagonal that tests the same way and flips back, round after round. An
    edge is not flipped when its two opposite vertices are the same vertex or when both sides are the
    same face.

    Returns an ``IntrinsicTriangulation``; its ``report`` has ``flips``, ``rounds``, ``eps`` (the
    mollification, units of V), ``negative_before`` / ``negative_after`` (edges with cotan weight
    ``< -tol``, counted on the mollified lengths before and after flipping, boundary edges included),
    ``negative_boundary_after`` (those on the boundary: an obtuse angle opposite a boundary edge cannot be
    flipped away), ``non_delaunay_after`` (interior edges left non-Delaunay: skipped or out of rounds)
    and ``converged`` (no interior edge left non-Delaunay).
    """
    V = np.asarray(V, dtype=np.float64)
    F = np.array(F, dtype=np.int64, copy=True).reshape(-1, 3)
    n = len(V)
    FE, EF, EC = _build_edges(F, n)
    E = len(EF)
    if lengths is None:
        lf = edge_lengths_3d(V, F)
    else:
        lf = np.asarray(lengths, dtype=np.float64).reshape(-1, 3)
    el = np.zeros(E)
    el[FE.ravel()] = lf.ravel()
    eps = 0.0
    if mollify_delta and mollify_delta > 0:
        _, eps = mollify(el[FE], mollify_delta)
        el = el + eps

    T = IntrinsicTriangulation(n, F, FE, EF, EC, el)
    # the geometry of the input triangulation, once: the counts before, the first round's test, and
    # (when nothing flips) the counts after and the cached operators
    l0 = el[FE]
    A0 = face_areas(l0)
    c0 = corner_cotangents(l0, A0)
    rho = cot_rounding(l0, A0)                                # (m,), kept up to date as faces change
    neg_before = int(np.sum(_edge_weights(c0, EF, EC) < -tol))

    interior = EF[:, 1] >= 0
    dirty = np.flatnonzero(interior)
    flips = 0
    rounds = 0
    while len(dirty) and rounds < max_rounds:
        e = dirty
        t, k = EF[e, 0], EC[e, 0]
        s, j = EF[e, 1], EC[e, 1]
        k1, k2, j1, j2 = _NEXT[k], _PREV[k], _NEXT[j], _PREV[j]
        l_e = el[e]
        l_ca, l_ab = el[FE[t, k1]], el[FE[t, k2]]             # face t = (a, b, c), a opposite e
        l_bd, l_dc = el[FE[s, j1]], el[FE[s, j2]]             # face s = (d, c, b), d opposite e
        if rounds == 0:
            w = c0[t, k] + c0[s, j]                           # the same numbers _cot_pair gives
        else:
            w = _cot_pair(l_e, l_ca, l_ab, l_bd, l_dc)
        a, d = F[t, k], F[s, j]
        bad = (w + (rho[t] + rho[s]) < -tol) & (t != s) & (a != d)
        e, t, k, s, j = e[bad], t[bad], k[bad], s[bad], j[bad]
        if len(e) == 0:
            break
        k1, k2, j1, j2 = _NEXT[k], _PREV[k], _NEXT[j], _PREV[j]
        l_e, l_ca, l_ab, l_bd, l_dc = l_e[bad], l_ca[bad], l_ab[bad], l_bd[bad], l_dc[bad]
        w = w[bad]

        # independent set: an edge wins if it is the most negative candidate of both its faces
        rank = np.empty(len(e), dtype=np.int64)
        rank[np.argsort(w, kind='stable')] = np.arange(len(e))[::-1]   # most negative w: highest rank
        pe = np.full(E, -1, dtype=np.int64)
        pe[e] = rank
        best = pe[FE].max(axis=1)                                        # (m,)
        win = (best[t] == rank) & (best[s] == rank)
        e, t, k, s, j = e[win], t[win], k[win], s[win], j[win]
        k1, k2, j1, j2 = k1[win], k2[win], j1[win], j2[win]
        l_e, l_ca, l_ab, l_bd, l_dc = l_e[win], l_ca[win], l_ab[win], l_bd[win], l_dc[win]
        losers = np.setdiff1d(dirty[bad], e, assume_unique=True)

        # new diagonal a-d: lay the quad out with b at the origin and c on +x; a above, d below
        At = face_areas(np.stack([l_e, l_ca, l_ab], axis=1))
        As = face_areas(np.stack([l_e, l_bd, l_dc], axis=1))
        xa = (l_ab * l_ab - l_ca * l_ca + l_e * l_e) / (2.0 * l_e)
        xd = (l_bd * l_bd - l_dc * l_dc + l_e * l_e) / (2.0 * l_e)
        ya = 2.0 * At / l_e
        yd = -2.0 * As / l_e
        l_new = np.hypot(xa - xd, ya - yd)

        a, d = F[t, k], F[s, j]
        e_ca, e_bd = FE[t, k1], FE[s, j1]
        # which side of e_bd is (s, j1), which side of e_ca is (t, k1) -- read before any write
        side_bd = np.where((EF[e_bd, 0] == s) & (EC[e_bd, 0] == j1), 0, 1)
        side_ca = np.where((EF[e_ca, 0] == t) & (EC[e_ca, 0] == k1), 0, 1)
        # faces: t = (a, b, c) -> (a, b, d); s = (d, c, b) -> (d, c, a)
        F[t, k2] = d
        F[s, j2] = a
        FE[t, k] = e_bd
        FE[t, k1] = e
        FE[s, j] = e_ca
        FE[s, j1] = e
        EF[e_bd, side_bd], EC[e_bd, side_bd] = t, k
        EF[e_ca, side_ca], EC[e_ca, side_ca] = s, j
        EF[e, 0], EC[e, 0] = t, k1
        EF[e, 1], EC[e, 1] = s, j1
        el[e] = l_new
        for g in (t, s):
            lg = el[FE[g]]
            rho[g] = cot_rounding(lg, face_areas(lg))

        flips += len(e)
        rounds += 1
        touched = np.concatenate([FE[t].ravel(), FE[s].ravel(), losers])
        touched = np.unique(touched)
        dirty = touched[interior[touched]]

    if flips:                                                 # the flipped triangulation's geometry, once
        l0 = el[FE]
        A0 = face_areas(l0)
        c0 = corner_cotangents(l0, A0)
    A0.setflags(write=False)
    T._cache['A'] = A0
    w_after = _edge_weights(c0, EF, EC)
    T.report = dict(
        flips=int(flips), rounds=int(rounds), eps=float(eps),
        negative_before=neg_before,
        negative_after=int(np.sum(w_after < -tol)),
        negative_boundary_after=int(np.sum((w_after < -tol) & ~interior)),
        non_delaunay_after=int(np.sum(_non_delaunay(c0, EF, EC, tol, rho))),
    )
    T.report['converged'] = T.report['non_delaunay_after'] == 0
    return T
