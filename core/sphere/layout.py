"""Spherical UVs and the other per-vertex outputs of sphere mode (docs/sphere.md).

The UV layout of a sphere map is the equirectangular one, ``u = longitude / 2 pi + 1/2``,
``v = latitude / pi + 1/2``, with three precautions that make it a valid UV map (all UVs in [0,1], no
flipped UV triangle, split per corner along a seam):

1. Poles on vertices. The sphere is rotated so that a vertex ``a`` sits at the north pole (rotations
   leave the conformal factor unchanged); ``a`` is chosen where the sphere's triangles are small, as
   the layout shears big triangles near a pole (``pole_candidates``). For the layout only, the vertex
   ``b`` nearest the south pole is moved to the south pole by the Moebius map ``w -> w / (1 - w / w_b)``
   of the stereographic chart ``w`` (it fixes the north pole; ``b`` is nearly antipodal, so it is close
   to the identity). No polygon then contains a pole in its interior, and the longitude is continuous
   inside every polygon.
2. Poles per corner. A corner at a pole takes the mean u of its polygon's other corners: a triangle
   (pole, p, q) then keeps its orientation in UV (its UV area is ``(u_q - u_p)(2 - v_p - v_q) / 4 > 0``
   at the north pole, and the mirror at the south pole).
3. The seam. Each polygon's longitudes are unwrapped relative to its first non-pole corner and the
   polygon is shifted by whole turns so that its mean u lies in [0, 1): polygons on either side of
   longitude 180 degrees get u near 1 and near 0, so the UVs split along the mesh edges between them.
   Polygons at the seam reach slightly past 0 or 1; u is then rescaled by one global affine map into
   [0, 1] (the layout is not conformal anyway; the rescale is reported as ``u_scale``).

UV flips (triangles with nonpositive signed UV area, ``core.mesh.measures.signed_uv_areas``) are counted
and reported separately from the sphere map's folds.
"""
import numpy as np

from ..mesh.geometry import face_areas
from ..mesh.measures import signed_uv_areas, vertex_mu
from ..mesh.validate import degenerate_faces
from .map import from_sphere, to_sphere

POLE_TOL = 1e-12          # |(x, y)| below this on the unit sphere: the vertex sits at a pole
POLE_TRIES = 6            # candidate pole vertices tried for a layout without flipped UV triangles


def every_edge_twice(corner_edges: np.ndarray, n_edges: int) -> bool:
    """True if every one of ``n_edges`` edges is used by exactly two corners: ``corner_edges`` (c,) the
    edge of each polygon corner (a closed mesh without boundary or non-manifold edges)."""
    return bool((np.bincount(np.asarray(corner_edges, np.int64), minlength=n_edges) == 2).all())


def pole_rotation(S: np.ndarray, k: int) -> np.ndarray:
    """Rotation matrix (3,3) taking the unit vector ``S[k]`` (``S`` (n,3)) to the north pole (0,0,1)
    (Rodrigues' formula about ``S[k] x z``; a half turn about x if ``S[k]`` is the south pole)."""
    a = S[k] / np.linalg.norm(S[k])
    z = np.array([0.0, 0.0, 1.0])
    v = np.cross(a, z)
    s, c = float(np.linalg.norm(v)), float(a @ z)
    if s < 1e-15:
        return np.eye(3) if c > 0 else np.diag([1.0, -1.0, -1.0])
    K = np.array([[0, -v[2], v[1]], [v[2], 0, -v[0]], [-v[1], v[0], 0]]) / s
    return np.eye(3) + s * K + (1 - c) * (K @ K)


def layout_sphere(unit: np.ndarray) -> tuple:
    """Positions (n,3) for the UV layout from unit vectors ``unit`` (n,3) whose north pole is a vertex:
    the vertex with the smallest z is moved to the south pole by the chart Moebius map of the module
    docstring (the north pole stays). Returns (X (n,3), south vertex index)."""
    b = int(np.argmin(unit[:, 2]))
    w = from_sphere(unit)
    wb = w[b]
    X = unit.copy()
    if np.isfinite(wb) and abs(wb) > 0:
        with np.errstate(divide='ignore', invalid='ignore'):
            g = w / (1.0 - w / wb)
        ok = np.isfinite(g)
        ok[b] = False
        X[ok] = to_sphere(g[ok])
    X[b] = (0.0, 0.0, -1.0)
    return X, b


def pole_candidates(S: np.ndarray, F: np.ndarray, k: int = POLE_TRIES) -> list:
    """Up to ``k`` candidate north-pole vertices for the UV layout of the sphere map ``S`` (n,3) with
    faces ``F`` (m,3), best first: the equirectangular layout shears triangles near the poles, and big
    ones there can turn over, so the poles go where the sphere's triangles are small. Score of a vertex
    ``a``: the flat sphere area around ``a`` plus that around the vertex nearest ``-S[a]`` (the south
    pole of the layout); the 64 vertices with the smallest area around them are scored."""
    P = S[F]
    a = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    va = np.bincount(F.ravel(), np.repeat(a, 3), minlength=len(S))
    va = np.where(np.bincount(F.ravel(), minlength=len(S)) > 0, va, np.inf)     # loose vertices: never
    cand = np.argsort(va, kind='stable')[:64]
    south = np.argmin(S @ S[cand].T, axis=0)
    score = va[cand] + va[south]
    return [int(x) for x in cand[np.argsort(score, kind='stable')[:k]]]


def spherical_uv(X: np.ndarray, corner_verts: np.ndarray, sizes: np.ndarray,
                 tri_corners: np.ndarray | None = None, counted: np.ndarray | None = None) -> tuple:
    """Per-corner UVs (c,2) of the unit-sphere positions ``X`` (n,3) (poles on vertices, see
    ``layout_sphere``) for polygons given by ``corner_verts`` (c,) and ``sizes`` (p,) (corners listed
    polygon by polygon), following the module docstring. ``tri_corners`` (t,3) optional: triangles of
    the polygons as corner indices, for the flip count (default: every polygon is a triangle);
    ``counted`` (t,) bool optional: the triangles the flip count looks at (a zero-area triangle has no
    orientation to lose).

    Returns ``(uv (c,2) in [0,1], info)``; ``info`` has ``uv_flips`` (triangles with nonpositive signed
    UV area), ``pole_polygons`` (polygons whose corners wind around a pole: 0 when the poles are
    vertices), ``u_scale`` (the global factor that brought u into [0,1]), ``pole_corners``."""
    corner_verts = np.asarray(corner_verts, np.int64)
    sizes = np.asarray(sizes, np.int64)
    x, y, z = X[:, 0], X[:, 1], X[:, 2]
    lon = np.arctan2(y, x)
    lat = np.arctan2(z, np.hypot(x, y))
    at_pole = np.hypot(x, y) < POLE_TOL
    u = lon[corner_verts] / (2 * np.pi) + 0.5
    v = np.clip(lat[corner_verts] / np.pi + 0.5, 0.0, 1.0)
    p = len(sizes)
    nc = len(corner_verts)
    poly = np.repeat(np.arange(p), sizes)
    start = np.r_[0, np.cumsum(sizes)[:-1]]
    pole_c = at_pole[corner_verts]
    # winding of each polygon around the pole axis: sum of wrapped longitude steps (pole corners skipped)
    nxt = np.arange(nc) + 1
    nxt[np.cumsum(sizes) - 1] = start
    d = u[nxt] - u
    d = np.where(pole_c | pole_c[nxt], 0.0, d - np.round(d))
    wind = np.bincount(poly, d, minlength=p)
    encl = np.abs(wind) > 0.5
    # every corner within half a turn of the polygon's first non-pole corner
    ref_c = np.where(pole_c, np.inf, np.arange(nc))
    first = np.minimum.reduceat(ref_c, start)
    has = np.isfinite(first)
    ref = np.where(has, u[np.where(has, first, 0).astype(np.int64)], 0.5)
    u = u - np.round(u - ref[poly])
    # a polygon that still winds around a pole (only if a pole is not a vertex): unwrap continuously
    for q in np.nonzero(encl)[0].tolist():
        s, k = start[q], sizes[q]
        uu = u[s] + np.r_[0.0, np.cumsum(d[s:s + k - 1])]
        u[s:s + k] = uu - np.floor(uu.mean())
    # whole turns: each polygon's mean u in [0, 1)
    cnt = np.bincount(poly, ~pole_c, minlength=p)
    mean = np.bincount(poly, np.where(pole_c, 0.0, u), minlength=p) / np.maximum(cnt, 1)
    u = u - np.floor(mean)[poly]
    mean = mean - np.floor(mean)
    # corners on a pole: the mean u of the polygon's other corners
    u = np.where(pole_c, mean[poly], u)
    lo, hi = float(u.min()), float(u.max())
    scale = 1.0
    if lo < 0.0 or hi > 1.0:
        lo, hi = min(lo, 0.0), max(hi, 1.0)
        scale = 1.0 / (hi - lo)
        u = (u - lo) * scale
    uv = np.stack([np.clip(u, 0.0, 1.0), v], 1)
    if tri_corners is None:
        tri_corners = np.arange(nc).reshape(-1, 3)
    flipped = signed_uv_areas(uv, np.asarray(tri_corners, np.int64)) <= 0
    flips = int((flipped if counted is None else flipped & counted).sum())
    return uv, {'uv_flips': flips, 'pole_polygons': int(encl.sum()), 'u_scale': float(scale),
                'pole_corners': int(pole_c.sum())}


def sphere_layout(V: np.ndarray, F: np.ndarray, S: np.ndarray, mu: np.ndarray, corner_verts: np.ndarray,
                  sizes: np.ndarray, tri_corners: np.ndarray | None = None) -> dict:
    """Everything a front end writes for a sphere map ``S`` (n,3) of the mesh ``V`` (n,3), ``F`` (m,3)
    (triangles) with per-triangle conformal factor ``mu`` (m,), for polygons ``corner_verts`` (c,),
    ``sizes`` (p,) triangulated by ``tri_corners`` (m,3) corner indices (default: the polygons are the
    triangles ``F``).

    Returns a dict: ``unit`` (n,3) unit-sphere positions rotated so that the vertex ``north`` sits at
    the north pole (same conformal factor; the first of ``pole_candidates`` whose layout flips no UV
    triangle, else the one that flips fewest), ``north`` and ``south`` (the layout's pole vertices),
    ``key`` (n,3) the sphere with the mesh's surface area (radius ``sqrt(A / 4 pi)``, units of V)
    centred at the mesh's area centroid ``centre`` (3,), ``radius``, ``loop_uv`` (c,2) spherical UVs
    (``spherical_uv``), ``mu_vertex`` (n,) (``core.mesh.measures.vertex_mu``), and the layout's
    ``uv_flips``, ``pole_polygons``, ``u_scale``. Raises ``ConformalError`` if any output is not
    finite."""
    from ..errors import ConformalError
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    S = np.asarray(S, np.float64)
    S = S / np.linalg.norm(S, axis=1)[:, None]
    best = None
    counted = ~degenerate_faces(V, F)                  # zero-area triangles have no side to flip to
    for north in pole_candidates(S, F):
        unit = S @ pole_rotation(S, north).T
        unit[north] = (0.0, 0.0, 1.0)
        X, south = layout_sphere(unit)
        loop_uv, info = spherical_uv(X, corner_verts, sizes, tri_corners, counted)
        if best is None or info['uv_flips'] < best[3]['uv_flips']:
            best = (north, south, unit, info, loop_uv)
        if info['uv_flips'] == 0:
            break
    north, south, unit, info, loop_uv = best
    A = face_areas(V, F)
    centre = (V[F].mean(1) * A[:, None]).sum(0) / A.sum()
    radius = float(np.sqrt(A.sum() / (4 * np.pi)))
    out = dict(unit=unit, north=north, south=south, key=centre + radius * unit, loop_uv=loop_uv,
               mu_vertex=vertex_mu(F, mu, A, len(V)), centre=centre, radius=radius, **info)
    for k in ('unit', 'key', 'loop_uv'):
        if not np.isfinite(out[k]).all():
            raise ConformalError("the sphere map produced non-finite positions: the mesh is too degenerate",
                                 'degenerate', 'clean_mesh')
    return out
