"""Feature curves: sharp edges along which a mesh holds its curvature (a hole's rim, a boss's foot, a
dimple's edge), for the automatic seams of ``core.atlas.unwrap.cone_layout``.

Where a plane meets a cylinder or a sphere, the Gaussian curvature is not spread over an area: it sits
on the vertices of the sharp rim, each with an angle defect of about ``2 pi / (rim vertices)``, all
of one sign. Cones cannot absorb a curve of curvature (the placement would need a cone at every rim
vertex), so a conformal map of such a part varies by several times; a seam along the rim makes its
vertices boundary vertices, whose free scale takes the curvature at no cost (docs/cones.md,
"Thirtieth round").

A *feature curve* is a run of sharp edges (dihedral angle above ``FEATURE_ANGLE``) between junctions
of the sharp-edge graph whose inner vertices (two sharp edges each, not on the boundary) number at
least ``FEATURE_VERTICES``, hold angle defects of one sign (``|sum| >= FEATURE_SIGN * sum |.|``) and
together at least ``FEATURE_KAPPA`` radians, on a part whose curvature is not noisy (``FEATURE_NOISE``).
The sharp creases of a coarse organic mesh are short runs (at most 11 such vertices on the corpus's
scans and characters) on noisy parts, and a box's edges hold no curvature; neither is a feature curve.
"""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..mesh import topology
from ..mesh.geometry import angle_defect, unit_face_normals

FEATURE_ANGLE = np.radians(40.0)   # a sharp edge: its faces' normals differ by more
FEATURE_VERTICES = 12              # inner vertices of a feature curve, at least
FEATURE_KAPPA = 0.5 * np.pi        # the curvature its inner vertices hold together (radians), at least
FEATURE_SIGN = 0.9                 # |sum of their defects| / sum of |defects|, at least
# a part has feature curves only if its total absolute curvature is at most this many times the least
# its topology allows (|2 pi chi|, at least 4 pi): a machined part's curvature sits at its corners, on
# its rims and on patches of one sign (1.7-3.5x on Boolean parts, as left or remeshed), a scanned or
# sculpted surface's has both signs everywhere (cheburashka 18x, ogre 250x, the other corpus meshes
# likewise), and its creases are not seams an artist would want
FEATURE_NOISE = 8.0


def feature_curves(V, F, poly=None):
    """The edges (k,2) int64 of the feature curves of the manifold, consistently oriented triangles
    ``F`` (m,3) on vertices ``V`` (n,3) (vertex pairs, each edge once; (0,2) if none). ``poly`` (m,)
    optional: the polygon of each triangle; an edge inside a polygon is never sharp."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n, m = len(V), len(F)
    none = np.zeros((0, 2), np.int64)
    if m == 0:
        return none
    N, ok = unit_face_normals(V, F)
    tw = topology.twin_halfedges(F, n)
    h = np.flatnonzero((tw >= 0) & (np.arange(3 * m) < tw))           # each interior edge once
    f1, f2 = h // 3, tw[h] // 3
    sharp = ok[f1] & ok[f2] & ((N[f1] * N[f2]).sum(1) < np.cos(FEATURE_ANGLE))
    if poly is not None:
        poly = np.asarray(poly)
        sharp &= poly[f1] != poly[f2]
    if not sharp.any():
        return none
    h = h[sharp]
    E = np.c_[F.ravel()[h], F[h // 3, (h % 3 + 1) % 3]]
    on_boundary = np.zeros(n, bool)
    on_boundary[F.ravel()[tw < 0]] = True
    defect = angle_defect(V, F, on_boundary)
    inner = (np.bincount(E.ravel(), minlength=n) == 2) & ~on_boundary
    # the runs between junctions: components of the sharp edges joining two inner vertices
    Ei = E[inner[E[:, 0]] & inner[E[:, 1]]]
    _, run = connected_components(sp.coo_matrix((np.ones(len(Ei)), (Ei[:, 0], Ei[:, 1])), shape=(n, n)),
                                  directed=False)
    iv = np.flatnonzero(inner)
    r = run[iv]
    count = np.bincount(r, minlength=n)
    total = np.bincount(r, defect[iv], minlength=n)
    size = np.bincount(r, np.abs(defect[iv]), minlength=n)
    good = (count >= FEATURE_VERTICES) & (size >= FEATURE_KAPPA) & (np.abs(total) >= FEATURE_SIGN * size)
    on = np.zeros(n, bool)
    on[iv[good[r]]] = True
    if not on.any():
        return none
    # parts whose curvature is noisy have none
    n_parts, part = topology.face_components(F, n, tw)
    pv = np.empty(n, np.int64)
    pv[F.ravel()] = np.repeat(part, 3)
    interior = np.zeros(n, bool)
    interior[F.ravel()] = True
    interior &= ~on_boundary
    total = np.bincount(pv[interior], defect[interior], minlength=n_parts)
    absolute = np.bincount(pv[interior], np.abs(defect[interior]), minlength=n_parts)
    calm = absolute <= FEATURE_NOISE * np.maximum(np.abs(total), 4.0 * np.pi)
    on &= calm[pv]
    return E[on[E[:, 0]] | on[E[:, 1]]]
