"""Sphere mode: conformal map of a closed genus-0 mesh to the unit sphere (docs/sphere.md, docs/math.md).

Method: one Laplace solve with the pole's singularity subtracted analytically, then a few steps of
the harmonic map flow on the sphere
---------------------------------------------------------------------------------------------------
The Laplacian ``L`` is the cotan Laplacian of the intrinsic Delaunay triangulation of the mesh, after
intrinsic mollification (Sharp and Crane 2020; ``core.mesh.intrinsic``): the same metric, the same
vertices, but every cotan weight nonnegative, so needle triangles and non-Delaunay edges no longer
break the maximum principle. The measures are still taken on the original faces.

In the stereographic chart that sends a point ``p`` of the surface to infinity, the conformal map to
the sphere is a harmonic (indeed holomorphic) function ``z`` with a simple pole at ``p``: near ``p``,
``z = a / (f - f(p)) + holomorphic``, where ``f`` is any local conformal coordinate.

1. Pick a well-shaped triangle (largest smallest angle) whose k-ring neighbourhood (k <= 6) is a disk;
   ``p`` is its centroid. Flatten that patch with the project's conformal flattening
   (``core.disk.flatten.flatten(boundary='area')``, BFF): ``f``. Set ``s = 1 / (f - f(p))`` on the
   patch.
2. Solve ``L z = b`` on the closed mesh (one vertex pinned, one factorisation for x and y): within
   k/2 rings of ``p`` the *regular part* ``z - s`` is discretely harmonic (``b_i = (L s)_i``),
   elsewhere ``z`` itself is (``b_i = 0``). The small sum of ``b`` (the discrete flux error of ``s``)
   is removed on the inner rings, so no logarithmic term appears.
3. Centre the chart at its area-weighted median, scale it so that half the area lies in each
   hemisphere, and project with the orientation-preserving inverse stereographic projection.
4. Harmonic map flow (``harmonic_flow``): projected backward-Euler steps ``(M + L) X' = M X`` with the
   lumped mass ``M`` of the current flat sphere triangles, each followed by centring and projection
   to the unit sphere. Its fixed point ``L X = M diag(k) X`` is the discrete harmonic map to the
   sphere (for genus 0: conformal), which, unlike the planar chart, does not see the stereographic
   scale: on cheburashka it halves the mean angle error of the chart map (4.75 -> 2.78 degrees, below
   conformalized mean curvature flow's 2.94). From the chart map it converges in 3-6 steps (one
   factorisation, later steps by preconditioned CG). The flow result is kept only if it folds no more
   triangles than the chart map.
5. Folded obtuse faces of the mesh (the map is linear on the intrinsic triangles, not on these) are
   undone where the map around them allows: ``core.sphere.untangle`` relaxes a few rings around them
   on the mesh's own conformal energy, keeping every face oriented.

Why this method: puncture methods (Angenent/Haker's dipole, Choi-Lam-Lui's fixed big triangle) leave
the 1/w singularity to the piecewise-linear Laplacian. Its error is first order in the edge length
and reaches the whole sphere: on a 2562-vertex icosphere a fixed-triangle puncture gave qc_mean 1.075
and min/max mu 0.49 for what should be the identity. Choi-Lam-Lui repair the polar region with a
Beltrami solve in a second chart; the widely used Python port divides by chart triangle areas there and
fails with a fixed zero-area tolerance on fine meshes. Here the Laplacian only ever sees smooth
functions: the same icosphere maps to itself with qc_mean 1.0007 and min/max mu 0.996, nothing is
computed from chart areas, and no tolerance depends on absolute size. Needle triangles can still fold
a few original faces (cheburashka: 4 of 13334 before step 5 and none after, against 42 with the 3D
cotan Laplacian); a map with folds, qc_mean above ``QC_WARN``, an unconverged Moebius optimiser or a
mu_ratio below ``MU_WARN`` (``core.disk.flatten``) carries ``report['warnings']``.

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
0.05% at the default grid. By default shortest surface paths (``core.geodesic.paths``) answer instead
whenever the mesh fits their memory budget: more accurate, and they need no resolved sphere map.

Measures: per triangle, ``mu = sqrt(area of the flat triangle of the
mapped vertices / 3D area)``, normalised so that the totals agree; ``qc`` from the 2x2 Jacobian between
the triangle's plane and the mapped triangle's plane; a flip is a mapped normal pointing inwards.
"""
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..errors import ConformalError
from ..mesh.geometry import corner_angles, face_areas
from ..mesh.intrinsic import intrinsic_delaunay
from ..mesh.measures import summarise
from .moebius import MOEBIUS_MODES, optimise
from ..mesh.solve import Factor
from ..mesh import topology
from ..mesh.validate import check_arrays, check_mesh, degenerate_faces, DEFAULT_MAX_FACES


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
    least half of the vertices outside (3 for one ring); else None. Returns (level (n,), vertex ids
    (k,), faces (f,3) renumbered)."""
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
MOLLIFY_DELTA = 1e-4      # intrinsic mollification margin, relative to the mean edge length
FLOW_DT = 1.0             # harmonic map flow step on the unit sphere (dimensionless)
FLOW_STEPS = 8            # at most this many flow steps
FLOW_TOL = 1e-4           # stop when the corner angles change by less than this (mean, radians)
QC_WARN = 1.5             # qc_mean above this gets a warning


def conformal_sphere(V: np.ndarray, F: np.ndarray, progress=None) -> tuple:
    """Conformal map of a closed genus-0 triangle mesh to the unit sphere (method in the module
    docstring). ``V`` (n,3), ``F`` (m,3); the mesh must already pass ``check_mesh(kind='sphere')``.
    Returns ``(S (n,3) unit vectors, info dict)``: ``pole_triangle``, ``pole_rings``, ``intrinsic``
    (the intrinsic Delaunay report: ``flips``, ``eps`` in units of V, ``negative_before``,
    ``negative_after``, ``converged``), ``flow_steps``, ``flow_last_angle_change`` (radians),
    ``chart_flips`` (folds of the chart map before the flow), ``untangle`` (``core.sphere.untangle``:
    the folds before and after, the patches kept and dropped)."""
    from ..disk.flatten import flatten
    report = progress or (lambda f, msg: None)
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n = len(V)
    A = face_areas(V, F)
    tri = intrinsic_delaunay(V, F, mollify_delta=MOLLIFY_DELTA)
    L = tri.cotan_laplacian()
    idt = {k: tri.report[k] for k in ('flips', 'eps', 'negative_before', 'negative_after', 'converged')}

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
        f = flatten(V[idx], Fp, boundary='area', exact=False).uv
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
    S0 = to_sphere(z)
    report(0.6, 'harmonic map flow on the sphere')
    S, steps, move = harmonic_flow(S0, F, L)
    f0, f1 = _count_flips(F, S0), _count_flips(F, S)
    if f1 > f0:                               # never trade the chart's orientation for angles
        S, steps = S0, 0
    # folded obtuse faces undone where the map around them allows (``core.sphere.untangle``)
    from .untangle import untangle
    real = ~degenerate_faces(V, F)
    S, unt = untangle(S, F, V, real, qc=lambda X, f: sphere_measures(V, F[f], X, per_face=True)[1][1])
    return S, {'pole_triangle': int(t), 'pole_rings': int(kout), 'intrinsic': idt,
               'flow_steps': int(steps), 'flow_last_angle_change': float(move), 'chart_flips': int(f0),
               'untangle': unt}


def _count_flips(F, S):
    """How many faces ``F`` (m,3) the sphere map ``S`` (n,3) folds (``untangle.orientation``)."""
    from .untangle import orientation
    return int((orientation(S, F) <= 0).sum())


def _flat_mass(X, F):
    """(n,) lumped mass: a third of the flat triangle areas of ``X`` (n,3) around each vertex."""
    P = X[F]
    a = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    return np.bincount(F.ravel(), np.repeat(a / 3.0, 3), minlength=len(X))


def _pcg(K, B, pre, X0, rtol=1e-10, maxiter=100):
    """Solve ``K X = B`` (K (n,n) SPD, B (n,r)) by conjugate gradients on all r columns at once,
    preconditioned by the ``Factor`` ``pre`` of a nearby matrix, starting from ``X0`` (n,r)."""
    X = X0.copy()
    R = B - K @ X
    Z = pre.solve(R)
    P = Z.copy()
    rz = (R * Z).sum(0)
    bnorm = np.linalg.norm(B, axis=0)
    for _ in range(maxiter):
        if (np.linalg.norm(R, axis=0) <= rtol * bnorm).all():
            break
        KP = K @ P
        alpha = rz / np.maximum((P * KP).sum(0), np.finfo(float).tiny)
        X += alpha * P
        R -= alpha * KP
        Z = pre.solve(R)
        rz_new = (R * Z).sum(0)
        P = Z + (rz_new / np.maximum(rz, np.finfo(float).tiny)) * P
        rz = rz_new
    return X


def harmonic_flow(S: np.ndarray, F: np.ndarray, L: sp.spmatrix, steps: int | None = None,
                  dt: float = FLOW_DT, tol: float = FLOW_TOL) -> tuple:
    """Polish a conformal sphere map ``S`` (n,3) unit vectors by projected backward-Euler steps of the
    harmonic map flow (docs/math.md, sphere mode): ``(M + dt L) X' = M X`` with ``L`` (n,n) the fixed
    (intrinsic Delaunay) cotan Laplacian and ``M`` the lumped mass of the current flat sphere
    triangles (unit sphere, so ``dt`` is dimensionless); then ``X'`` is centred at its area centroid and
    projected to the unit sphere. The fixed point is ``L X = M diag(k) X``: the discrete harmonic map
    to the sphere, which for genus 0 is the conformal map. Started from the chart map it converges in
    a few steps; it stops when a step changes the corner angles of the flat sphere triangles by less
    than ``tol`` radians on average (the Moebius drift that the centring causes does not count: it
    hardly changes angles). Returns (S (n,3), steps taken, last mean angle change in radians)."""
    steps = FLOW_STEPS if steps is None else steps
    X = S
    move = 0.0
    k = 0
    K0 = None
    while k < steps:
        k += 1
        m = _flat_mass(X, F)
        K = sp.diags(m) + dt * L
        if K0 is None:                        # factor once; later steps: CG preconditioned by it
            K0 = Factor(K)
            Y = K0.solve(m[:, None] * X)
        else:
            Y = _pcg(K, m[:, None] * X, K0, X)
        Pa = Y[F]
        ay = 0.5 * np.linalg.norm(np.cross(Pa[:, 1] - Pa[:, 0], Pa[:, 2] - Pa[:, 0]), axis=1)
        Y = Y - (Pa.mean(1) * ay[:, None]).sum(0) / ay.sum()
        Y = Y / np.linalg.norm(Y, axis=1)[:, None]
        move = float(np.abs(corner_angles(Y, F) - corner_angles(X, F)).mean())
        X = Y
        if move < tol:
            break
    return X, k, move


def sphere_measures(V, F, S, per_face=False):
    """docs/math.md §3 measures of a map to the sphere : dict with
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


def sphere_warnings(report: dict) -> list:
    """The warnings (list of str) a sphere map's ``report`` deserves: folded triangles, poor
    conformality (qc_mean above ``QC_WARN``), a Moebius optimiser that did not converge, and a
    conformal factor whose ratio is below ``MU_WARN``: at the most uniform Moebius choice, long
    protrusions such as limbs shrink to specks on the sphere; at another, the choice may be why."""
    from ..disk.flatten import scale_variation
    out = []
    if report.get('flips'):
        out.append(f"{report['flips']} of {report['faces']} triangles are folded on the sphere (their "
                   "image faces inwards); the mesh has needle or overlapping triangles there")
    if report.get('qc_mean', 1.0) > QC_WARN:
        out.append(f"the map is far from conformal: qc_mean {report['qc_mean']:.3g} > {QC_WARN}")
    if report.get('moebius_converged') is False:
        out.append("the Moebius optimiser did not converge: the uniform choice may not be optimal")
    scale = scale_variation(report.get('mu_ratio', 1.0))
    if scale and report.get('moebius', 'uniform') != 'uniform':
        out.append(f"{scale}: choose the Moebius transformation for the most uniform scale "
                   "(moebius='uniform', CLI --moebius uniform)")
    elif scale:
        out.append(f"{scale}: the sphere shrinks long protrusions to specks; for a texture, unwrap with "
                   "seams through cones (cones='auto', CLI --cones auto) instead")
    return out


def _repaired(V, F):
    """The mesh to map: ``(F2, fixed, root)``. A mesh that needs at most some faces turned keeps its
    vertices: ``F2`` is ``F`` (m,3) with those faces turned (``turned_faces``) and ``fixed`` None, so
    that a clean mesh keeps its map to the bit. Otherwise ``fixed`` is ``repair_merged``'s copy
    (vertices at one point joined by an edge of zero length merged into ``root`` (n,), None if none
    was; loose vertices, repeated-vertex and duplicate faces left out; non-manifold vertices and edges
    split) and ``F2`` its faces."""
    from ..mesh.repair import repair_merged, turned_faces
    R, root = repair_merged(V, F)
    if root is None and {r['repair'] for r in R.repairs} <= {'faces_reoriented'}:
        return turned_faces(F, R), None, None
    return R.F, R, root


def _wedge_of(fixed, root, n):
    """(n,) a wedge of the repaired mesh ``fixed`` for every input vertex: its first wedge, or its
    ``root``'s for a merged vertex; -1 for a loose vertex (in no face)."""
    first = np.full(n, -1, np.int64)
    first[fixed.vert_map[::-1]] = np.arange(len(fixed.vert_map))[::-1]   # the first wedge wins
    return first if root is None else first[root]


def _to_input(fixed, root, S, mu, V_in, m_in):
    """The map of the repaired mesh ``fixed`` (``Repaired``) in the input's numbering: ``S`` (n_in,3),
    each input vertex at its first wedge's point (a merged one at its ``root``'s), a loose vertex (in
    no face) at the point of the nearest vertex in 3D; ``mu`` (m_in,) per input face, a dropped
    duplicate face taking its twin's, NaN for a face left out with a repeated vertex or zero area."""
    n_in = len(V_in)
    w = _wedge_of(fixed, root, n_in)
    S_in = np.where((w >= 0)[:, None], S[np.maximum(w, 0)], np.nan)
    loose = np.flatnonzero(w < 0)
    if len(loose):
        from scipy.spatial import cKDTree
        used = np.flatnonzero(w >= 0)
        near = cKDTree(V_in[used]).query(V_in[loose])[1]
        S_in[loose] = S_in[used[near]]
    mu_in = np.full(m_in, np.nan)
    mu_in[fixed.face_map] = mu
    twin = fixed.twin_of_dropped
    dup = twin >= 0
    mu_in[fixed.dropped[dup]] = mu_in[twin[dup]]
    return S_in, mu_in


def _projection_if_better(V, F, real, S, info):
    """``S`` (n,3), the conformal map, unless it is far from conformal (qc_mean above ``QC_WARN`` on
    the ``real`` (m,) triangles) and the central projection of ``V`` (n,3) from its area-weighted
    centroid folds no triangle and is more conformal: then that projection, with ``info['start']``
    saying so. A mesh of a few triangles (a tetrahedron: the pole chart is one triangle) came out
    with qc_mean 4e14, where the projection of a convex shape is the natural map."""
    qc = sphere_measures(V, F[real], S)['qc_mean']
    if qc <= QC_WARN:
        return S
    A = face_areas(V, F)
    c = (V[F].mean(1) * A[:, None]).sum(0) / max(A.sum(), np.finfo(float).tiny)
    P = V - c
    r = np.linalg.norm(P, axis=1)
    if not (r > 1e-9 * r.max()).all():
        return S
    P = P / r[:, None]
    if _count_flips(F, P) == len(F):
        P[:, 2] = -P[:, 2]                # a mesh wound inside out: its mirror image keeps the winding
    m = sphere_measures(V, F[real], P)
    if _count_flips(F, P) == 0 and m['flips'] == 0 and m['qc_mean'] < qc:
        info['start'] = f"central projection (the conformal map's qc_mean was {qc:.3g})"
        return P
    return S


def sphere_map(V: np.ndarray, F: np.ndarray, moebius: str = 'uniform', max_faces: int = DEFAULT_MAX_FACES,
               progress=None, **options) -> SphereResult:
    """Map a closed genus-0 triangle mesh conformally to the unit sphere and choose the Moebius
    transformation. ``V`` (n,3) float, ``F`` (m,3) int counter-clockwise; ``moebius`` one of
    ``MOEBIUS_MODES``; ``progress(fraction, message)`` optional. Extra ``options`` go to
    ``core.sphere.moebius.optimise``. Returns ``SphereResult``; its report has the measures (``flips``
    are folds of the sphere map), the Moebius info (``baselines``, ``moebius_converged``, ...), the
    map's info (``conformal_sphere``) and ``warnings`` (list of str, ``sphere_warnings``: empty only
    for a clean result). Messy input is repaired on a copy and the repairs listed in ``report['repairs']``
    (``_repaired``); ``S`` and ``mu`` are in the input's numbering. Raises ``ConformalError`` on input
    with no answer (an open mesh, higher genus, several parts)."""
    if moebius not in MOEBIUS_MODES:
        raise ConformalError(f"unknown Moebius mode {moebius!r}: use one of {', '.join(MOEBIUS_MODES)}")
    report_progress = progress or (lambda f, msg: None)
    t0 = time.perf_counter()
    V_in, F_in = check_arrays(V, F, max_faces=max_faces)
    # messy input is repaired on a copy (``core.mesh.repair``): faces wound the wrong way are turned,
    # loose vertices, repeated-vertex and duplicate faces left out, non-manifold vertices and edges
    # split; zero-area triangles are kept (the mollified metric handles them) and left out of the
    # measures and of the Moebius objective
    F, fixed, root = _repaired(V_in, F_in)
    V = V_in if fixed is None else fixed.V
    turned = int((F != F_in).any(1).sum()) if fixed is None else 0
    check_mesh(V, F, kind='sphere', max_faces=max_faces, allow_degenerate=True)
    real = ~degenerate_faces(V, F)
    timings = {'check': time.perf_counter() - t0}
    t = time.perf_counter()
    S, info = conformal_sphere(V, F, progress=lambda f, m: report_progress(0.5 * f, m))
    S = _projection_if_better(V, F, real, S, info)
    timings['map'] = time.perf_counter() - t
    t = time.perf_counter()
    A = face_areas(V, F)
    S, minfo = optimise(S, F[real], A[real], mode=moebius,
                        progress=lambda f, m: report_progress(0.5 + 0.45 * f, m), **options)
    timings['moebius'] = time.perf_counter() - t
    report_progress(0.95, 'measuring')
    meas, (mu_r, qc, flipped) = sphere_measures(V, F[real], S, per_face=True)
    report = {'moebius': moebius, 'vertices': len(V_in), 'faces': len(F_in)}
    report.update(meas)
    faces_r = np.flatnonzero(real)                       # the measured triangles of F
    mu = np.full(len(F), np.nan)
    mu[faces_r] = mu_r
    if fixed is None:
        report['flipped_faces'] = faces_r[flipped].tolist()
    else:
        report['flipped_faces'] = np.unique(fixed.face_map[faces_r[flipped]]).tolist()
        S, mu = _to_input(fixed, root, S, mu, V_in, len(F_in))
    if flipped.any() and not flipped.all():
        report['mu_ratio_oriented'] = float(mu_r[~flipped].min() / mu_r[~flipped].max())
    report['moebius_point'] = [round(x, 9) for x in minfo['c']]
    for k in ('baselines', 'converged', 'evaluations', 'guarded_faces'):
        if k in minfo:
            report['moebius_' + k if k != 'baselines' else k] = minfo[k]
    report.update({k: v for k, v in info.items()})
    repairs = [] if fixed is None else list(fixed.repairs)
    if turned:
        repairs.append({'repair': 'faces_reoriented', 'count': turned,
                        'note': 'faces turned to agree with their neighbours'})
    if not real.all():
        from ..mesh.repair import zero_area_note
        repairs.append(zero_area_note(int((~real).sum())))
    if repairs:
        report['repairs'] = repairs
    report['warnings'] = sphere_warnings(report)
    timings['total'] = time.perf_counter() - t0
    report['seconds'] = {k: round(v, 4) for k, v in timings.items()}
    return SphereResult(S=S, mu=mu, report=report)
