"""Exact geodesic distances on a flat part of a mesh: shortest paths in a plane domain.

On a part whose triangles all lie in one plane, a shortest path is a polyline that bends only at
reflex corners of the boundary (interior angle above pi). The distance from the sources to a vertex
``x`` is therefore the smaller of ``|x - s|``, over the sources ``s`` that ``x`` sees, and
``D(r) + |x - r|``, over the reflex corners ``r`` that ``x`` sees, where ``D`` is the distance of the
corners: Dijkstra on the graph of the corners that see each other, started from the corners the
sources see. Exact up to round-off (docs/geodesic.md, "Flat parts").

Visibility is decided exactly on the triangulated domain (holes and seams are boundary too): the open
segment ``p q`` may properly cross no boundary edge, and at every boundary vertex it touches (its ends
included) it must keep to that vertex's interior wedge. That covers grazing contacts and walls that run
along the segment. From one point, the candidates are culled by angle: the targets are sorted by
their direction from the point, and each boundary edge is tested only against the targets inside the
angle it subtends (``PlanarPaths.visible_from``).

Lengths are in the units of the 2D coordinates ``P`` (the mesh's own, for a flat mesh)."""
import numpy as np

from ..mesh.geometry import corner_angles
from ..mesh.topology import halfedges, twin_halfedges

PLANE_TOL = 1e-9     # flat: every vertex within this times the bounding-box diagonal of one plane
GRAZE_TOL = 1e-10    # lengths below this times the part's extent count as zero in the visibility tests
ANGLE_TOL = 1e-9     # radians of slack in the angular culling and the wedge tests
PLANAR_BUDGET = 20_000_000   # at most this many (vertex, reflex corner) pairs: beyond, the grid answers


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def plane_coordinates(V, F):
    """2D coordinates (k,2) of a flat part ``V`` (k,3) (every vertex in a triangle of ``F`` (m,3)) in
    its own plane, turned so that every triangle is counter-clockwise; None if the part is not flat (a
    vertex further than ``PLANE_TOL`` times the bounding-box diagonal from the best plane) or its
    triangles do not all turn the same way in that plane (folded)."""
    V = np.asarray(V, np.float64)
    diag = float(np.linalg.norm(np.ptp(V, axis=0))) if len(V) else 0.0
    if len(F) == 0 or diag == 0.0:
        return None
    X = V - V.mean(0)
    _, U = np.linalg.eigh(X.T @ X)                  # the plane's normal: the least-spread direction
    if float(np.abs(X @ U[:, 0]).max()) > PLANE_TOL * diag:
        return None
    P = X @ U[:, 1:]
    e1, e2 = P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]]
    area = _cross(e1[:, 0], e1[:, 1], e2[:, 0], e2[:, 1])
    if (area > 0).all():
        return P
    if (area < 0).all():
        return P * np.array([1.0, -1.0])
    return None


def _ranges(sorted_angle, lo, width, pad):
    """Index ranges into ``sorted_angle`` (t,) ascending in [-pi, pi] covering the arcs
    ``[lo - pad, lo + width + pad]`` (q,) (which may wrap past +-pi). Returns (starts, counts, owner)
    of up to three ranges per arc."""
    n = len(sorted_angle)
    a, b = lo - pad, lo + width + pad
    s1 = np.searchsorted(sorted_angle, a, 'left')
    e1 = np.searchsorted(sorted_angle, np.minimum(b, np.pi), 'right')
    e2 = np.where(b > np.pi, np.searchsorted(sorted_angle, b - 2 * np.pi, 'right'), 0)
    under = a < -np.pi
    s3 = np.where(under, np.searchsorted(sorted_angle, a + 2 * np.pi, 'left'), n)
    starts = np.r_[s1, np.zeros_like(s1), s3]
    counts = np.maximum(np.r_[e1 - s1, e2, np.where(under, n - s3, 0)], 0)
    owner = np.tile(np.arange(len(lo)), 3)
    return starts, counts, owner


def _expand(starts, counts, owner):
    """The (owner, index) pairs (two (p,) arrays) of the ranges ``starts``/``counts``."""
    total = int(counts.sum())
    if total == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    rep = np.repeat(np.arange(len(counts)), counts)
    off = np.arange(total) - np.repeat(np.cumsum(counts) - counts, counts)
    return owner[rep], starts[rep] + off


def planar_paths(P, F, budget=PLANAR_BUDGET):
    """``PlanarPaths`` for the flat part ``P`` (k,2) (``plane_coordinates``), ``F`` (m,3), or None where
    it does not apply: a vertex where two boundary fans meet (its interior is not one wedge), or more
    than ``budget`` (vertex, reflex corner) pairs to keep."""
    pp = PlanarPaths(P, F)
    if pp.E is None or len(pp.P) * len(pp.R) > budget:
        return None
    return pp


class PlanarPaths:
    """Shortest paths in the plane domain of a flat part: ``P`` (k,2) counter-clockwise coordinates
    (``plane_coordinates``), ``F`` (m,3) its triangles. Which vertices see which corner (and so the
    corners' visibility graph) is built by the first query (``O(k log k)`` per corner with the angular
    culling) and kept; ``distances`` answers a query. Use ``planar_paths``, which checks that it
    applies (``E`` is None where a vertex has two boundary fans)."""

    def __init__(self, P, F):
        self.P = P = np.asarray(P, np.float64)
        self.n = n = len(P)
        self.seen = self.graph = None
        self.E = E = halfedges(F)[twin_halfedges(F, n) < 0]  # boundary half-edges, the domain on the left
        self.R = np.zeros(0, np.int64)
        if len(np.unique(E[:, 0])) != len(E):               # a vertex where two boundary fans meet
            self.E = None
            return
        self.bv = bv = np.unique(E[:, 0])
        self.is_boundary = np.zeros(n, bool)
        self.is_boundary[bv] = True
        succ, pred = np.full(n, -1), np.full(n, -1)
        succ[E[:, 0]], pred[E[:, 1]] = E[:, 1], E[:, 0]
        self.tol = GRAZE_TOL * float(np.ptp(P, axis=0).max())
        # the interior wedge of a boundary vertex runs counter-clockwise from its outgoing edge to its
        # incoming edge reversed
        a, b = P[succ[bv]] - P[bv], P[pred[bv]] - P[bv]
        self.wa, self.wb = np.zeros((n, 2)), np.zeros((n, 2))
        self.wa[bv] = a / np.hypot(a[:, 0], a[:, 1])[:, None]
        self.wb[bv] = b / np.hypot(b[:, 0], b[:, 1])[:, None]
        # the interior angle as the sum of the triangles' corners (2 pi at the end of a slit, where the
        # two edges coincide)
        angle = np.bincount(F.ravel(), corner_angles(np.c_[P, np.zeros(n)], F).ravel(), minlength=n)[bv]
        self.reflex = np.zeros(n, bool)
        self.reflex[bv] = angle > np.pi
        self.R = bv[angle > np.pi + ANGLE_TOL]               # the corners a shortest path can bend at

    def _in_wedge(self, v, d):
        """(p,) bool: the directions ``d`` (p,2) leave the boundary vertices ``v`` (p,) into their closed
        interior wedge."""
        a, b = self.wa[v], self.wb[v]
        dn = d / np.maximum(np.hypot(d[:, 0], d[:, 1]), 1e-300)[:, None]
        ca, cb = _cross(a[:, 0], a[:, 1], dn[:, 0], dn[:, 1]), _cross(dn[:, 0], dn[:, 1], b[:, 0], b[:, 1])
        convex_in = (ca >= -ANGLE_TOL) & (cb >= -ANGLE_TOL)
        reflex_in = ~((ca < -ANGLE_TOL) & (cb < -ANGLE_TOL))   # outside: strictly within the outer wedge
        return np.where(self.reflex[v], reflex_in, convex_in)

    def visible_from(self, o, ov=-1):
        """(k,) bool: the vertices the point ``o`` (2,) sees along a straight segment inside the closed
        domain; ``ov`` the vertex at ``o`` (-1 for a point inside a triangle). Vertices at ``o`` itself
        are not seen (their distance is 0)."""
        P, tol = self.P, self.tol
        d = P - o
        r = np.hypot(d[:, 0], d[:, 1])
        ang = np.arctan2(d[:, 1], d[:, 0])
        order = np.argsort(ang)
        sa = ang[order]
        ok = r > tol
        if ov >= 0 and self.is_boundary[ov]:
            k = np.flatnonzero(ok)
            ok[k] = self._in_wedge(np.full(len(k), ov), d[k])
        k = np.flatnonzero(ok & self.is_boundary)
        ok[k] &= self._in_wedge(k, -d[k])
        # boundary edges that do not touch o: each against the targets within the angle it subtends
        A, B = P[self.E[:, 0]] - o, P[self.E[:, 1]] - o
        e = B - A
        s = np.clip(-(A * e).sum(1) / np.maximum((e * e).sum(1), 1e-300), 0.0, 1.0)
        near = np.hypot(A[:, 0] + s * e[:, 0], A[:, 1] + s * e[:, 1])     # o to the edge's nearest point
        far = near > tol
        A, B, near = A[far], B[far], near[far]
        ta, tb = np.arctan2(A[:, 1], A[:, 0]), np.arctan2(B[:, 1], B[:, 0])
        turn = np.mod(tb - ta + np.pi, 2 * np.pi) - np.pi
        e_i, s_i = _expand(*_ranges(sa, np.where(turn > 0, ta, tb), np.abs(turn), ANGLE_TOL + tol / near))
        t_i = order[s_i]
        keep = ok[t_i] & (r[t_i] > near[e_i] - tol)
        e_i, t_i = e_i[keep], t_i[keep]
        if len(e_i):
            dd, L, a, b = d[t_i], r[t_i], A[e_i], B[e_i]
            o1 = _cross(dd[:, 0], dd[:, 1], a[:, 0], a[:, 1]) / L
            o2 = _cross(dd[:, 0], dd[:, 1], b[:, 0], b[:, 1]) / L
            e = b - a
            le = np.hypot(e[:, 0], e[:, 1])
            o3 = _cross(e[:, 0], e[:, 1], -a[:, 0], -a[:, 1]) / le
            o4 = _cross(e[:, 0], e[:, 1], dd[:, 0] - a[:, 0], dd[:, 1] - a[:, 1]) / le
            hit = (((o1 > tol) & (o2 < -tol)) | ((o1 < -tol) & (o2 > tol))) & \
                  (((o3 > tol) & (o4 < -tol)) | ((o3 < -tol) & (o4 > tol)))
            ok[t_i[hit]] = False
        # boundary vertices on the open segments: the segment must pass on their inner side
        bv = self.bv[r[self.bv] > tol]
        rv = r[bv]
        b_i, s_i = _expand(*_ranges(sa, ang[bv], np.zeros(len(bv)), ANGLE_TOL + 2 * tol / rv))
        t_i = order[s_i]
        keep = ok[t_i] & (r[t_i] > rv[b_i] + tol)
        b_i, t_i = b_i[keep], t_i[keep]
        if len(b_i):
            dd = d[t_i]
            c = _cross(dd[:, 0], dd[:, 1], d[bv[b_i], 0], d[bv[b_i], 1]) / r[t_i]
            on = np.abs(c) <= tol
            v, t_i = bv[b_i[on]], t_i[on]
            inside = self._in_wedge(v, d[t_i]) & self._in_wedge(v, -d[t_i])
            ok[t_i[~inside]] = False
        return ok

    def _corners(self):
        """Which vertices see which corner, with the lengths: ``self.seen`` (vertex (q,), corner
        index (q,), length (q,)), and the corner graph ``self.graph`` ((k,k) CSR) from its rows."""
        from scipy.sparse import csr_matrix
        P, R, k = self.P, self.R, len(self.R)
        vi, ci = [], []
        for j, c in enumerate(R):
            vis = np.flatnonzero(self.visible_from(P[c], int(c)))
            vi.append(vis)
            ci.append(np.full(len(vis), j))
        vi = np.concatenate(vi) if k else np.zeros(0, np.int64)
        ci = np.concatenate(ci) if k else np.zeros(0, np.int64)
        length = np.hypot(*(P[vi] - P[R[ci]]).T) if k else np.zeros(0)
        self.seen = (vi, ci, length)
        pos = np.full(self.n, -1)
        pos[R] = np.arange(k)
        m = pos[vi] >= 0
        self.graph = csr_matrix((length[m], (pos[vi[m]], ci[m])), shape=(k, k))

    def distances(self, points, vertices=None):
        """Distances (k,) of every vertex to the nearest of the source ``points`` (s,2), ``vertices``
        (s,) the vertex at each point (-1 for a point inside a triangle; default all -1). Vertices
        that no path reaches (another component) are inf."""
        from scipy.sparse import coo_matrix
        from scipy.sparse.csgraph import dijkstra
        if self.seen is None:
            self._corners()
        points = np.atleast_2d(np.asarray(points, np.float64))
        vertices = np.full(len(points), -1) if vertices is None else np.asarray(vertices)
        P, R, k = self.P, self.R, len(self.R)
        d = np.full(self.n, np.inf)
        for o, ov in zip(points, vertices):
            r = np.hypot(*(P - o).T)
            seen = self.visible_from(o, int(ov)) | (r <= self.tol)
            d = np.minimum(d, np.where(seen, r, np.inf))
        if k:
            # the corners from a virtual node (index k) joined to the corners the sources see
            start = d[R]
            f = np.flatnonzero(np.isfinite(start))
            G = self.graph.tocoo()
            G = coo_matrix((np.r_[G.data, start[f]], (np.r_[G.row, np.full(len(f), k)], np.r_[G.col, f])),
                           shape=(k + 1, k + 1)).tocsr()
            D = dijkstra(G, directed=False, indices=k)[:k]
            vi, ci, length = self.seen
            np.minimum.at(d, vi, D[ci] + length)
        return d
