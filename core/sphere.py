"""Sphere mode: conformal map of a closed genus-0 mesh to the unit sphere (DESIGN.md section 5).

Method: one cotan Laplace solve with the pole's singularity subtracted analytically
---------------------------------------------------------------------------------
In the stereographic chart that sends a point ``p`` of the surface to infinity, the conformal map to
the sphere is a harmonic (indeed holomorphic) function ``z`` with a simple pole at ``p``: near ``p``,
``z = a / (f - f(p)) + holomorphic``, where ``f`` is any local conformal coordinate.

1. Pick a well-shaped triangle (largest smallest angle) whose k-ring neighbourhood (k <= 6) is a disk;
   ``p`` is its centroid. Flatten that patch with the project's conformal flattening
   (``core.flatten.flatten(boundary='area')``, BFF): ``f``. Set ``s = 1 / (f - f(p))`` on the patch.
2. Solve ``L z = b`` on the closed mesh (``L`` the 3D cotan Laplacian, one vertex pinned, one
   factorisation for x and y): within k/2 rings of ``p`` the *regular part* ``z - s`` is discretely
   harmonic (``b_i = (L s)_i``), elsewhere ``z`` itself is (``b_i = 0``). The small sum of ``b``
   (the discrete flux error of ``s``) is removed on the inner rings, so no logarithmic term appears.
3. Centre the chart at its area-weighted median, scale it so that half the area lies in each
   hemisphere, and project with the orientation-preserving inverse stereographic projection.

Why this method: puncture methods (Angenent/Haker's dipole, Choi-Lam-Lui's fixed big triangle) leave
the 1/w singularity to the piecewise-linear Laplacian. Its error is first order in the edge length
and reaches the whole sphere: on a 2562-vertex icosphere a fixed-triangle puncture gave qc_mean 1.075
and min/max mu 0.49 for what should be the identity. Choi-Lam-Lui repair the polar region with a
Beltrami solve in a second chart; the widely used Python port divides by chart triangle areas there and
fails with a fixed zero-area tolerance on fine meshes. Here the Laplacian only ever sees smooth
functions: the same icosphere maps to itself with qc_mean 1.0007 and min/max mu 0.996, nothing is
computed from chart areas, and no tolerance depends on absolute size. Needle triangles make some cotan
weights negative, which can fold a few faces (cheburashka: about 0.3%); they are reported.

The per-triangle measures have a floor for *any* piecewise-linear map whose scale varies: a triangle's
qc is at least the ratio of its edges' scale factors, so qc_mean - 1 is of the order of
``h |grad log mu|`` (h the edge length). Coarse meshes with protrusions (spot at 2930 vertices) cannot
reach qc_mean 1.05; subdividing them halves qc_mean - 1 per level (bench/sphere.py shows it).

Then ``core.moebius`` chooses the Moebius transformation (``none``, ``center``, ``area``, ``uniform``).

Geodesic distances (``sphere_geodesic``): fast marching on two stereographic charts of the sphere,
each a regular grid (``core.geodesic.Grid`` rasterisation, ``calibrate_phi`` seeding, scikit-fmm or
the numpy sweep of ``core.eikonal``), with the surface metric ``ds = |dw| / speed``. The charts overlap
in a band; time is marched in buckets no longer than the shortest crossing of that band, so every
optimal path segment within a bucket lies in one chart, and the charts exchange their times through
the overlap after each bucket. On an icosphere the mean relative error against great circles is about
0.05% at the default grid.

Measures (as ``tools/measure.py sphere``): per triangle, ``mu = sqrt(area of the flat triangle of the
mapped vertices / 3D area)``, normalised so that the totals agree; ``qc`` from the 2x2 Jacobian between
the triangle's plane and the mapped triangle's plane; a flip is a mapped normal pointing inwards.
"""
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .errors import ConformalError
from .geometry import corner_angles, face_areas
from .laplacian import cotan_laplacian
from .measures import summarise
from .moebius import MOEBIUS_MODES, optimise
from .solve import Factor
from . import topology
from .validate import check_mesh, DEFAULT_MAX_FACES


@dataclass
class SphereResult:
    """``S`` (n,3) float64 unit-sphere positions per vertex; ``mu`` (m,) per-triangle conformal factor
    (normalised, dimensionless); ``report`` dict: measures, Moebius info, timings (seconds)."""
    S: np.ndarray
    mu: np.ndarray
    report: dict = field(default_factory=dict)


# --- small helpers ----------------------------------------------------------------------------------
def _frames(P):
    """Triangles P (m,3,3) -> their corners in the triangle's own plane as complex numbers (m,3)
    (corner 0 at 0, corner 1 on the positive real axis) and the areas (m,)."""
    e1, e2 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    nrm = np.cross(e1, e2)
    dbl = np.linalg.norm(nrm, axis=1)
    l1 = np.linalg.norm(e1, axis=1)
    x = (e1 * e2).sum(1) / np.maximum(l1, np.finfo(float).tiny)
    y = dbl / np.maximum(l1, np.finfo(float).tiny)
    Z = np.zeros((len(P), 3), complex)
    Z[:, 1] = l1
    Z[:, 2] = x + 1j * y
    return Z, 0.5 * dbl


def _weighted_median(x, w):
    order = np.argsort(x)
    cw = np.cumsum(w[order])
    return x[order][np.searchsorted(cw, 0.5 * cw[-1])]


def _ring_levels(F, n, seed, k):
    """(n,) int: ring distance (0..k) of each vertex from the vertices ``seed``, -1 beyond k rings."""
    i = np.r_[F.ravel(), F[:, [1, 2, 0]].ravel()]
    j = np.r_[F[:, [1, 2, 0]].ravel(), F.ravel()]
    adj = sp.csr_matrix((np.ones(len(i)), (i, j)), shape=(n, n))
    level = np.full(n, -1)
    level[seed] = 0
    mask = level == 0
    for r in range(1, k + 1):
        new = (adj @ mask.astype(float) > 0) & ~mask
        if not new.any():
            break
        level[new] = r
        mask |= new
    return level


def _patch(F, n, tri, kout):
    """The faces within ``kout`` rings of triangle ``tri`` (3,) if they form a disk that leaves at
    least half of the vertices outside (3 for one ring); else None. Returns (level (n,), vertex ids (k,), faces (f,3)
    renumbered)."""
    level = _ring_levels(F, n, tri, kout)
    inside = level >= 0
    if inside.sum() > (n // 2 if kout > 1 else n - 3):
        return None
    fmask = inside[F].all(1)
    idx = np.nonzero(inside)[0]
    remap = -np.ones(n, np.int64)
    remap[idx] = np.arange(len(idx))
    Fp = remap[F[fmask]]
    used = np.zeros(len(idx), bool)
    used[Fp.ravel()] = True
    if not used.all() or topology.euler_characteristic(Fp) != 1 or \
            len(topology.boundary_loops(Fp, len(idx))) != 1:
        return None
    return level, idx, Fp


def to_sphere(w):
    """Orientation-preserving inverse stereographic projection of ``w`` (k,) complex: 0 -> north pole
    (0,0,1), infinity -> south pole. Returns (k,3) unit vectors."""
    r2 = (w * np.conj(w)).real
    d = 1.0 + r2
    return np.stack([2.0 * w.real / d, 2.0 * w.imag / d, (1.0 - r2) / d], axis=1)


def from_sphere(S):
    """Inverse of ``to_sphere``: ``w = (x + i y) / (1 + z)`` (k,) complex (infinite at the south pole)."""
    with np.errstate(divide='ignore', invalid='ignore'):
        return (S[:, 0] + 1j * S[:, 1]) / (1.0 + S[:, 2])


# --- the map ----------------------------------------------------------------------------------------
RINGS = (6, 5, 4, 3, 2, 1)


def conformal_sphere(V, F, progress=None):
    """Conformal map of a closed genus-0 triangle mesh to the unit sphere (method in the module
    docstring). ``V`` (n,3), ``F`` (m,3); the mesh must already pass ``check_mesh(kind='sphere')``.
    Returns ``(S (n,3) unit vectors, info dict)``."""
    from .flatten import flatten
    report = progress or (lambda f, msg: None)
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n = len(V)
    A = face_areas(V, F)
    L = cotan_laplacian(V, F)

    # the pole: a well-shaped triangle whose neighbourhood is a disk
    order = np.argsort(-corner_angles(V, F).min(1))
    found = None
    for kout in RINGS:
        for t in order[:8].tolist():
            pat = _patch(F, n, F[t], kout)
            if pat is not None:
                found = (t, kout, pat)
                break
        if found:
            break
    if found is None:
        t, kout = int(order[0]), 1
        level = _ring_levels(F, n, F[t], 1)
        pat = (level, np.nonzero(level >= 0)[0], None)
    else:
        t, kout, pat = found
    level, idx, Fp = pat
    kin = kout // 2

    # local conformal coordinate around the pole and the singular part s = 1 / (f - f(pole))
    report(0.05, 'local chart at the pole')
    if Fp is not None:
        f = flatten(V[idx], Fp, boundary='area').uv
        f = f[:, 0] + 1j * f[:, 1]
    else:                                    # tiny mesh: the tangent plane of the pole triangle
        P = V[F[t]]
        e1 = P[1] - P[0]
        e1 /= np.linalg.norm(e1)
        nrm = np.cross(P[1] - P[0], P[2] - P[0])
        e2 = np.cross(nrm / np.linalg.norm(nrm), e1)
        f = (V[idx] - P[0]) @ e1 + 1j * ((V[idx] - P[0]) @ e2)
    s = np.zeros(n, complex)
    pos = np.searchsorted(idx, F[t])
    s[idx] = 1.0 / (f - f[pos].mean())

    # L z = b: z - s discretely harmonic near the pole, z harmonic elsewhere
    near = (level >= 0) & (level <= kin)
    b = np.zeros(n, complex)
    b[near] = (L @ s)[near]
    M = np.bincount(F.ravel(), np.repeat(A / 3.0, 3), minlength=n)
    b[near] -= b.sum() * M[near] / M[near].sum()
    pin = int(np.argmax(np.linalg.norm(V - V[F[t]].mean(0), axis=1)))
    keep = np.arange(n) != pin
    report(0.2, 'solving the Laplace equation')
    sol = Factor(L[keep][:, keep]).solve(np.stack([b.real[keep], b.imag[keep]], 1))
    z = np.zeros(n, complex)
    z[keep] = sol[:, 0] + 1j * sol[:, 1]

    # centre, half the area in each hemisphere, project
    cz = z[F].mean(1)
    z = z - (_weighted_median(cz.real, A) + 1j * _weighted_median(cz.imag, A))
    z = z / _weighted_median(np.abs(z[F].mean(1)), A)
    return to_sphere(z), {'pole_triangle': int(t), 'pole_rings': int(kout)}


def sphere_measures(V, F, S, per_face=False):
    """DESIGN.md section 3 measures of a map to the sphere (as ``tools/measure.py sphere``): dict with
    faces, flips, mu_ratio, mu_ratio_p1_p99, qc_mean, qc_max. ``S`` (n,3) is normalised first. With
    ``per_face``, also returns ``(mu (m,), qc (m,), flipped (m,) bool)``."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    S = np.asarray(S, np.float64)
    S = S / np.linalg.norm(S, axis=1)[:, None]
    Z3, A3 = _frames(V[F])
    T = S[F]
    Zs, _ = _frames(T)
    nrm = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    orient = (nrm * T.mean(1)).sum(1)
    # Jacobian J = dQ dP^-1 from the 3D triangle's plane to the sphere triangle's plane; both frames
    # put corner 1 on the x axis, so dP = [[x1, x2], [0, y2]] is upper triangular
    x1, x2, y2 = Z3[:, 1].real, Z3[:, 2].real, np.maximum(Z3[:, 2].imag, np.finfo(float).tiny)
    X1, X2, Y2 = Zs[:, 1].real, Zs[:, 2].real, Zs[:, 2].imag
    x1 = np.maximum(x1, np.finfo(float).tiny)
    a = X1 / x1
    b = (X2 - a * x2) / y2
    d = Y2 / y2                               # J = [[a, b], [0, d]]
    det = np.abs(a * d)
    fro = a * a + b * b + d * d
    disc = np.sqrt(np.maximum(fro * fro - 4.0 * det * det, 0.0))
    s1 = np.sqrt(0.5 * (fro + disc))
    s2 = np.sqrt(np.maximum(0.5 * (fro - disc), 0.0))
    s2 = np.maximum(s2, det / np.maximum(s1, np.finfo(float).tiny))   # accurate small singular value
    c = np.sqrt((det * A3).sum() / A3.sum())
    mu = np.sqrt(det) / c
    qc = s1 / np.maximum(s2, np.finfo(float).tiny)
    out = summarise(mu, qc, A3, orient)
    if per_face:
        return out, (mu, qc, orient <= 0)
    return out


def sphere_map(V, F, moebius='uniform', max_faces=DEFAULT_MAX_FACES, progress=None, **options):
    """Map a closed genus-0 triangle mesh conformally to the unit sphere and choose the Moebius
    transformation. ``V`` (n,3) float, ``F`` (m,3) int counter-clockwise; ``moebius`` one of
    ``MOEBIUS_MODES``; ``progress(fraction, message)`` optional. Extra ``options`` go to
    ``core.moebius.optimise``. Returns ``SphereResult``; raises ``ConformalError`` on bad input
    (open mesh, higher genus, degenerate faces...)."""
    if moebius not in MOEBIUS_MODES:
        raise ConformalError(f"unknown Moebius mode {moebius!r}: use one of {', '.join(MOEBIUS_MODES)}")
    report_progress = progress or (lambda f, msg: None)
    t0 = time.perf_counter()
    check_mesh(V, F, kind='sphere', max_faces=max_faces)
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    timings = {'check': time.perf_counter() - t0}
    t = time.perf_counter()
    S, info = conformal_sphere(V, F, progress=lambda f, m: report_progress(0.5 * f, m))
    timings['map'] = time.perf_counter() - t
    t = time.perf_counter()
    A = face_areas(V, F)
    S, minfo = optimise(S, F, A, mode=moebius,
                        progress=lambda f, m: report_progress(0.5 + 0.45 * f, m), **options)
    timings['moebius'] = time.perf_counter() - t
    report_progress(0.95, 'measuring')
    meas, (mu, qc, flipped) = sphere_measures(V, F, S, per_face=True)
    report = {'moebius': moebius, 'vertices': len(V), 'faces': len(F)}
    report.update(meas)
    report['flipped_faces'] = np.nonzero(flipped)[0].tolist()
    if flipped.any() and not flipped.all():
        report['mu_ratio_oriented'] = float(mu[~flipped].min() / mu[~flipped].max())
    report['moebius_point'] = [round(x, 9) for x in minfo['c']]
    if 'baselines' in minfo:
        report['baselines'] = minfo['baselines']
    report.update({k: v for k, v in info.items()})
    timings['total'] = time.perf_counter() - t0
    report['seconds'] = {k: round(v, 4) for k, v in timings.items()}
    return SphereResult(S=S, mu=mu, report=report)


# --- test shapes --------------------------------------------------------------------------------------
def icosphere(freq=8):
    """Geodesic sphere: each icosahedron face split into ``freq**2`` triangles, projected to the unit
    sphere. Returns ``V`` (10 freq^2 + 2, 3) and ``F`` (20 freq^2, 3), counter-clockwise seen from
    outside."""
    k = int(freq)
    if k < 1:
        raise ConformalError("icosphere frequency must be at least 1")
    g = (1 + 5 ** 0.5) / 2
    P = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g],
                  [0, -1, -g], [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]], float)
    T = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                  [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    ii, jj = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing='ij')
    keep = ii + jj <= k
    ii, jj = ii[keep], jj[keep]
    idx = -np.ones((k + 1, k + 1), np.int64)
    idx[ii, jj] = np.arange(len(ii))
    a, b = np.meshgrid(np.arange(k), np.arange(k), indexing='ij')
    up = a + b <= k - 1
    dn = a + b <= k - 2
    loc = np.r_[np.stack([idx[a[up], b[up]], idx[a[up] + 1, b[up]], idx[a[up], b[up] + 1]], 1),
                np.stack([idx[a[dn] + 1, b[dn]], idx[a[dn] + 1, b[dn] + 1], idx[a[dn], b[dn] + 1]], 1)]
    w = np.stack([k - ii - jj, ii, jj], 1) / k
    pts = np.einsum('pk,fkd->fpd', w, P[T]).reshape(-1, 3)
    faces = (loc[None] + (np.arange(len(T)) * len(ii))[:, None, None]).reshape(-1, 3)
    pts /= np.linalg.norm(pts, axis=1)[:, None]
    _, first, inv = np.unique(np.round(pts, 9), axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    V = pts[first[order]]
    F = rank[inv.ravel()][faces]
    nrm = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    out = (nrm * V[F].mean(1)).sum(1) < 0
    F[out] = F[out][:, ::-1]
    return V, F


def blob(freq=24, bumps=((0, 0, 1, 1.2), (1, 0, 0, 0.8), (0, -1, 0, 1.0), (-0.6, 0.6, -0.5, 0.9)),
         width=0.12):
    """Star-shaped sphere with protrusions: the icosphere scaled radially by ``1 + sum h_k exp(-(1 -
    d_k . x) / width)`` for bumps ``(dx, dy, dz, h)``. Returns ``V``, ``F`` like ``icosphere``."""
    V, F = icosphere(freq)
    r = np.ones(len(V))
    for dx, dy, dz, h in bumps:
        d = np.array([dx, dy, dz], float)
        d /= np.linalg.norm(d)
        r += h * np.exp(-(1.0 - V @ d) / width)
    return V * r[:, None], F


def subdivide(V, F):
    """Split every triangle into 4 at its edge midpoints (flat: the surface does not move). Returns
    ``V2`` (n + e, 3) and ``F2`` (4m, 3); the first n vertices are the input's."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n = len(V)
    E = np.sort(np.stack([F, F[:, [1, 2, 0]]], 2).reshape(-1, 2), 1)
    key, inv = np.unique(E[:, 0] * n + E[:, 1], return_inverse=True)
    mid = n + inv.reshape(-1, 3)             # midpoint of edge (k, k+1) of each face
    V2 = np.vstack([V, 0.5 * (V[key // n] + V[key % n])])
    a, b, c = F.T
    ab, bc, ca = mid.T
    F2 = np.vstack([np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1), np.stack([ca, bc, c], 1),
                    np.stack([ab, bc, ca], 1)])
    return V2, F2


# --- geodesic distances through the sphere ----------------------------------------------------------
# Two stereographic charts, each a regular grid: N (w = (x + i y) / (1 + z), the north pole at 0) and
# S (w' = (x - i y) / (1 - z) = 1 / w, the south pole at 0), each over the disk |w| <= R, so that they
# overlap in the band of latitudes -beta..beta (R = tan((90 + beta) / 2 degrees)). A surface length
# element is ds = |dw| / speed with speed = mu_S (1 + |w|^2) / 2, mu_S the sphere length per surface
# length. Fast marching runs in buckets of time: a path that crosses the whole overlap band needs at
# least W = (R - 1/R) / (largest speed in the band), so within a bucket [tau, tau + W] every optimal
# path segment lies in one chart; both charts march from the contour T = tau, the results are
# exchanged through the overlap (bilinear sampling), and the nodes up to tau + W are final.
GEO_OVERLAP_DEG = 25.0


class _Chart:
    """One stereographic chart as a ``core.geodesic.Grid`` over [-R, R]^2 with the speed field."""

    def __init__(self, which, S, F, logmu_v, R, nodes):
        from .geodesic import Grid
        self.which = which
        self.R = R
        w = self.coords_of(S)
        keep = (np.abs(w[F]) <= 2.0 * R).all(1)
        box = np.array([[-R, -R], [R, R]])
        self.G = G = Grid(box, nodes, pad=1)
        uv = np.stack([w.real, w.imag], 1)
        G.rasterise(uv, F[keep])
        ny, nx = G.shape
        jj, ii = np.meshgrid(np.arange(nx), np.arange(ny))
        self.w = (G.origin[0] + jj * G.h) + 1j * (G.origin[1] + ii * G.h)
        self.valid = G.inside & (np.abs(self.w) <= R)
        lm = G.interpolate(uv, F[keep], logmu_v)
        lm = np.where(self.valid, lm, 0.0)
        self.speed = np.where(self.valid, np.exp(lm) * 0.5 * (1.0 + np.abs(self.w) ** 2), 1.0)
        self.h = G.h

    def coords_of(self, X):
        """Chart coordinates (k,) complex of unit vectors X (k,3)."""
        if self.which == 'N':
            with np.errstate(divide='ignore', invalid='ignore'):
                return (X[:, 0] + 1j * X[:, 1]) / (1.0 + X[:, 2])
        with np.errstate(divide='ignore', invalid='ignore'):
            return (X[:, 0] - 1j * X[:, 1]) / (1.0 - X[:, 2])

    def node_coords(self, w):
        """Continuous node coordinates (k,2) (column, row) of chart points w (k,) complex."""
        return self.G.coords(np.stack([w.real, w.imag], 1))

    def sample(self, T, w):
        from .geodesic import bilinear
        return bilinear(np.where(self.valid, T, np.nan), self.node_coords(w), self.valid)


def _seed(chart, ws, radius):
    """Exact local times (ny, nx) (inf elsewhere) around the sources at chart points ``ws`` (k,),
    within ``radius`` + 3 cells: chart distance times the Simpson mean of 1/speed, and the time
    ``tau`` up to which the seed disks are complete."""
    from .geodesic import bilinear
    G = chart.G
    ny, nx = G.shape
    P = chart.node_coords(ws)
    w = int(np.ceil(radius)) + 3
    off = np.arange(-w, w + 1)
    oi, oj = np.meshgrid(off, off, indexing='ij')
    ci = np.rint(P[:, 1]).astype(np.int64)[:, None] + oi.ravel()[None]
    cj = np.rint(P[:, 0]).astype(np.int64)[:, None] + oj.ravel()[None]
    src = np.repeat(np.arange(len(P)), oi.size)
    ci, cj = ci.ravel(), cj.ravel()
    ok = (ci >= 0) & (ci < ny) & (cj >= 0) & (cj < nx)
    ci, cj, src = ci[ok], cj[ok], src[ok]
    ok = chart.valid[ci, cj]
    ci, cj, src = ci[ok], cj[ok], src[ok]
    if not len(ci):
        return np.full(G.shape, np.inf), np.inf
    Q = np.stack([cj, ci], 1).astype(np.float64)
    inv = 1.0 / chart.speed
    f = (bilinear(inv, P[src], chart.valid) + 4.0 * bilinear(inv, 0.5 * (P[src] + Q), chart.valid)
         + bilinear(inv, Q, chart.valid)) / 6.0
    T = np.full(G.shape, np.inf)
    np.minimum.at(T, (ci, cj), np.linalg.norm(Q - P[src], axis=1) * G.h * f)
    tau = radius * G.h / float(chart.speed[ci, cj].max())
    return T, tau


def _march(phi, chart, solver, T0=None, narrow=0.0):
    """Travel time (ny, nx) from the zero contour of ``phi`` in ``chart`` (inf where not reached).
    With scikit-fmm the march stops ``narrow`` beyond the contour (0: no limit); otherwise
    ``core.geodesic.march`` runs (the numpy sweep holds ``T0``'s finite nodes fixed and returns full
    times). Returns (T, solver used)."""
    from .geodesic import march
    mask = ~chart.valid
    if solver in ('auto', 'skfmm'):
        try:
            import skfmm
        except ImportError:
            skfmm = None
        if skfmm is not None:
            T = skfmm.travel_time(np.ma.MaskedArray(phi, mask), np.where(mask, 1.0, chart.speed),
                                  dx=chart.h, order=2, narrow=narrow)
            T = np.ma.filled(np.ma.MaskedArray(T), np.inf).astype(np.float64)
            T[mask] = np.inf
            return T, 'skfmm'
    if T0 is None:
        T0 = np.where(phi < 0, 0.0, np.inf)
    return march(T0, phi < 0, phi, chart.speed, mask, chart.h, solver)


def default_sphere_grid(n_vertices):
    """Nodes per side of each chart's grid: about 4 per sqrt(vertex), rounded up to a multiple of 64,
    clipped to 256..768."""
    return int(np.clip(64 * np.ceil(4.0 * np.sqrt(n_vertices) / 64), 256, 768))


def sphere_geodesic(V, F, sources, S=None, moebius='uniform', grid=None, solver='auto',
                    overlap=GEO_OVERLAP_DEG, source_radius=8.0, progress=None):
    """Geodesic distances on a closed genus-0 mesh by fast marching through its conformal sphere.

    V (n,3), F (m,3); ``sources`` vertex indices (k,) (the result is the distance to the nearest).
    ``S`` (n,3): a sphere map to reuse (from ``sphere_map``); None computes one with ``moebius``.
    ``grid``: nodes per side of each chart (None: ``default_sphere_grid``). ``solver``: as
    ``core.geodesic.march`` ('auto', 'skfmm', 'sweep'). ``overlap``: half-width of the band the two
    charts share, in degrees of latitude. ``source_radius``: exact seed disk radius, in cells.
    Returns ``(dist (n,) float64 in mesh units, report dict)``."""
    from .geodesic import calibrate_phi, vertex_mu
    say = progress or (lambda f, msg: None)
    t0 = time.perf_counter()
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n = len(V)
    src = np.atleast_1d(np.asarray(sources))
    if src.size == 0:
        raise ConformalError("no source given: pass at least one source vertex")
    if not np.issubdtype(src.dtype, np.integer) or src.min() < 0 or src.max() >= n:
        raise ConformalError(f"source vertices must be indices in 0..{n - 1}")
    if not 5.0 <= overlap <= 60.0:
        raise ConformalError("overlap must be between 5 and 60 degrees")
    report = {}
    if S is None:
        say(0.0, 'mapping to the sphere')
        res = sphere_map(V, F, moebius=moebius)
        S = res.S
        report['sphere'] = {k: res.report[k] for k in ('moebius', 'mu_ratio', 'qc_mean', 'flips')}
    S = np.asarray(S, np.float64)
    S = S / np.linalg.norm(S, axis=1)[:, None]
    if S.shape != V.shape:
        raise ConformalError(f"S must have shape {V.shape}, got {S.shape}")
    if grid is None:
        grid = default_sphere_grid(n)
    # sphere length per surface length, per triangle (unnormalised) and per vertex
    P = S[F]
    a_s = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    mu_f = np.sqrt(np.maximum(a_s, np.finfo(float).tiny) / face_areas(V, F))
    logmu_v = np.log(vertex_mu(V, F, mu_f))
    R = float(np.tan(np.radians(45.0 + 0.5 * overlap)))
    say(0.2, 'rasterising the charts')
    charts = [_Chart('N', S, F, logmu_v, R, grid), _Chart('S', S, F, logmu_v, R, grid)]
    other = [charts[1], charts[0]]
    # node positions of each chart in the other chart's coordinates (the band only)
    for c, o in zip(charts, other):
        wo = np.where(c.valid, 1.0 / np.where(c.w == 0, 1.0, c.w), np.inf)
        c.band = c.valid & (np.abs(wo) <= R * (1.0 - 2.0 * o.h / R))
        c.band_w = wo[c.band]
    # bucket width W: the shortest time to cross the overlap band. Measured by one march in chart N
    # from the disk |w| <= 1/R to the circle |w| = R (the band is the same set in chart S, and a
    # crossing reversed is a crossing), less two cells for the interpolation between the charts.
    cN = charts[0]
    phi = np.where(cN.valid, (np.abs(cN.w) - 1.0 / R), 1.0)
    Tb = _march(phi, cN, solver)[0]
    rim = cN.valid & (np.abs(cN.w) >= R - 1.5 * cN.h)
    vmax = max(float(c.speed[c.valid].max()) for c in charts)
    W = float(np.min(Tb[rim])) - 2.0 * max(c.h for c in charts) / vmax
    if not W > 0:
        raise ConformalError("the overlap band of the two charts is too thin for this grid: "
                             "increase the grid size or the overlap")
    # seeds: each source in every chart its seed window reaches (the window is clipped to the
    # chart), so that both charts know the first contour wherever it lies in their domain
    xs = S[src]
    T, tau = [], np.inf
    for c in charts:
        ws = c.coords_of(xs)
        with np.errstate(invalid='ignore'):
            inside = np.abs(ws) <= R + (source_radius + 4) * c.h
        if inside.any():
            Tc, tc = _seed(c, ws[inside], source_radius)
            tau = min(tau, tc)
        else:
            Tc = np.full(c.G.shape, np.inf)
        T.append(Tc)
    # nodes of the seed windows beyond tau keep their exact local times: they place the contour
    say(0.3, 'marching')
    t = time.perf_counter()
    used = None
    buckets = 0
    while True:
        buckets += 1
        new = []
        for c, Tc in zip(charts, T):
            known = np.isfinite(Tc) & (Tc <= tau) & c.valid
            if not known.any():
                new.append(np.full(c.G.shape, np.inf))
                continue
            far = 4.0 * c.h
            phi = np.where(np.isfinite(Tc), (Tc - tau) * c.speed, far)
            phi = np.where(c.valid, np.minimum(phi, far), far)
            phi = calibrate_phi(phi, c.valid, c.h)
            if not (phi[c.valid] < 0).any() or not (phi[c.valid] > 0).any():
                new.append(Tc.copy())
                continue
            Tm, used = _march(phi, c, solver, T0=np.where(known, Tc, np.inf))
            Tn = np.where(known, Tc, np.fmin(Tc, (Tm + tau) if used == 'skfmm' else Tm))
            Tn[~c.valid] = np.inf
            new.append(Tn)
        # exchange through the overlap
        for k, (c, o) in enumerate(zip(charts, other)):
            Ti = o.sample(new[1 - k], c.band_w)
            Tb = new[k][c.band]
            new[k][c.band] = np.fmin(Tb, np.where(np.isfinite(Ti), Ti, np.inf))
        T = new
        tau = tau + W
        left = sum(int((c.valid & ~(T[k] <= tau)).sum()) for k, c in enumerate(charts))
        if left == 0 or buckets > 10000:
            break
        # the next contour must exist: jump over empty buckets
        lo = min(float(np.min(np.where(c.valid & (T[k] > tau - W), T[k], np.inf))) for k, c in enumerate(charts))
        if not np.isfinite(lo):
            raise ConformalError("the fast marching front stopped before covering the sphere: "
                                 "increase the grid size")
    seconds_march = time.perf_counter() - t
    # sample at the vertices from the chart where each is more interior
    say(0.9, 'sampling')
    dist = np.empty(n)
    north = S[:, 2] >= 0
    for c, sel in zip(charts, (north, ~north)):
        dist[sel] = c.sample(T[charts.index(c)], c.coords_of(S[sel]))
    # the sources themselves and their neighbourhoods: exact local times (chart N or S)
    for c, sel in zip(charts, (north, ~north)):
        near = sel.copy()
        if not near.any():
            continue
        ws = c.coords_of(xs)
        here = np.abs(ws) <= R
        if not here.any():
            continue
        ws, s_here = ws[here], src[here]
        wv = c.coords_of(S[near])
        from scipy.spatial import cKDTree
        d, j = cKDTree(np.stack([ws.real, ws.imag], 1)).query(np.stack([wv.real, wv.imag], 1))
        close = d <= source_radius * c.h
        if close.any():
            idx = np.nonzero(near)[0][close]
            sp_v = np.exp(logmu_v[idx]) * 0.5 * (1 + np.abs(wv[close]) ** 2)
            sp_s = np.exp(logmu_v[s_here[j[close]]]) * 0.5 * (1 + np.abs(ws[j[close]]) ** 2)
            local = d[close] * 0.5 * (1.0 / sp_v + 1.0 / sp_s)
            dist[idx] = np.fmin(dist[idx], local)
    dist[src] = 0.0
    if not np.isfinite(dist).all():
        bad = int((~np.isfinite(dist)).sum())
        raise ConformalError(f"{bad} vertices were not reached by the front: increase the grid size")
    report.update({'grid': list(charts[0].G.shape), 'cell': [c.h for c in charts], 'charts': 2,
                   'overlap_deg': overlap, 'buckets': buckets, 'bucket_width': W, 'solver': used,
                   'sources': int(src.size),
                   'seconds': {'march': round(seconds_march, 4),
                               'total': round(time.perf_counter() - t0, 4)}})
    return dist, report
