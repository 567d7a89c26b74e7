"""Intrinsic mollification and intrinsic Delaunay flips (core/mesh/intrinsic.py, docs/math.md §8)."""
import time

import numpy as np
import pytest
import scipy.sparse as sp
from scipy.spatial import Delaunay

from core.errors import ConformalError

from core.mesh.intrinsic import (IntrinsicTriangulation, corner_angles, edge_lengths_3d, face_areas,
                                 intrinsic_delaunay, layout, mollify)


# --- meshes -----------------------------------------------------------------------------------------

def jittered_grid(N, shear=0.0, jitter=0.3, seed=0):
    """Planar (z = 0) N x N grid, points jittered (boundary points only along the boundary), each quad
    cut by a random diagonal, then sheared: many non-Delaunay edges, boundary = the convex hull."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(N + 1.0), np.arange(N + 1.0), indexing='ij')
    P = np.stack([x.ravel(), y.ravel()], 1)
    J = rng.uniform(-jitter, jitter, P.shape)
    J[(P[:, 0] == 0) | (P[:, 0] == N), 0] = 0
    J[(P[:, 1] == 0) | (P[:, 1] == N), 1] = 0
    P = P + J
    P[:, 0] += shear * P[:, 1]
    i, j = np.meshgrid(np.arange(N), np.arange(N), indexing='ij')
    i, j = i.ravel(), j.ravel()
    a, b, c, d = i * (N + 1) + j, (i + 1) * (N + 1) + j, (i + 1) * (N + 1) + j + 1, i * (N + 1) + j + 1
    diag = rng.random(len(a)) < 0.5
    F1 = np.where(diag[:, None], np.stack([a, b, c], 1), np.stack([a, b, d], 1))
    F2 = np.where(diag[:, None], np.stack([a, c, d], 1), np.stack([b, c, d], 1))
    return np.c_[P, np.zeros(len(P))], np.concatenate([F1, F2]).astype(np.int64)


def boundary_vertices(F, n):
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    u, c = np.unique(e, axis=0, return_counts=True)
    b = np.zeros(n, dtype=bool)
    b[u[c == 1].ravel()] = True
    return b


def twisted_sphere(n_lon=64, n_lat=6, seed=1):
    """Closed genus-0 UV sphere, few latitudes, many longitudes, each ring turned by a random angle:
    long thin skewed triangles with many negative cotan weights."""
    rng = np.random.default_rng(seed)
    V = [[0.0, 0.0, 1.0]]
    for r in range(1, n_lat):
        th = np.pi * r / n_lat
        ph = 2 * np.pi * (np.arange(n_lon) + rng.uniform(0, 1)) / n_lon
        V += list(np.c_[np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.full(n_lon, np.cos(th))])
    V.append([0.0, 0.0, -1.0])
    V = np.array(V)
    ring = lambda r, k: 1 + r * n_lon + (k % n_lon)  # noqa: E731
    k = np.arange(n_lon)
    F = [np.c_[np.zeros(n_lon, int), ring(0, k), ring(0, k + 1)]]
    for r in range(n_lat - 2):
        F.append(np.c_[ring(r, k), ring(r + 1, k), ring(r + 1, k + 1)])
        F.append(np.c_[ring(r, k), ring(r + 1, k + 1), ring(r, k + 1)])
    F.append(np.c_[ring(n_lat - 2, k), np.full(n_lon, len(V) - 1), ring(n_lat - 2, k + 1)])
    F = np.concatenate(F).astype(np.int64)
    # orient outwards
    P = V[F]
    out = np.einsum('md,md->m', np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), P.mean(1)) < 0
    F[out] = F[out][:, ::-1]
    return V, F


def cross2(a, b):
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def planar_delaunay(V):
    D = Delaunay(V[:, :2])
    F = D.simplices.astype(np.int64)
    P = V[F]
    cw = cross2(P[:, 1, :2] - P[:, 0, :2], P[:, 2, :2] - P[:, 0, :2]) < 0
    F[cw] = F[cw][:, ::-1]
    return F


def interior_weights(T):
    return T.edge_weights()[T.EF[:, 1] >= 0]


@pytest.fixture(scope='module')
def flat():
    V, F = jittered_grid(16, shear=2.0, jitter=0.25, seed=3)
    T0 = intrinsic_delaunay(V, F, max_rounds=0)
    T = intrinsic_delaunay(V, F)
    return V, F, T0, T


# --- mollification ----------------------------------------------------------------------------------

def test_mollify_margin_and_noop():
    l = np.array([[1.0, 1.0, 1.0], [1.0, 2.0, 1.0], [3.0, 1.0, 1.0]])   # equilateral, flat, violated
    delta = 1e-3
    lm, eps = mollify(l, delta)
    margin = delta * l.mean()
    slack = lm.sum(1, keepdims=True) - 2 * lm
    assert slack.min() == pytest.approx(margin, rel=1e-12, abs=1e-15)
    assert eps == pytest.approx(1.0 + margin)
    np.testing.assert_allclose(lm, l + eps)
    good = np.array([[1.0, 1.0, 1.0], [3.0, 4.0, 5.0]])
    lg, eg = mollify(good)
    assert eg == 0.0 and np.array_equal(lg, good)


def test_length_geometry_helpers():
    l = np.array([[5.0, 4.0, 3.0]])  # right angle at corner 0 (opposite the 5)
    assert face_areas(l)[0] == pytest.approx(6.0)
    np.testing.assert_allclose(corner_angles(l)[0], [np.pi / 2, np.arcsin(0.8), np.arcsin(0.6)])
    P = layout(l)[0]
    d = np.linalg.norm(P[[1, 2, 0]] - P[[2, 0, 1]], axis=1)
    np.testing.assert_allclose(d, l[0])
    assert cross2(P[1] - P[0], P[2] - P[0]) > 0


# --- flat meshes: intrinsic Delaunay == planar Delaunay -----------------------------------------------

def test_flat_equals_scipy_delaunay(flat):
    V, F, T0, T = flat
    assert T.report['eps'] == 0.0 and T.report['flips'] > 0 and T.report['converged']
    assert T0.report['negative_before'] > 0
    FD = planar_delaunay(V)
    assert len(FD) == len(F)
    TD = intrinsic_delaunay(V, FD, max_rounds=0)
    diff = abs(T.cotan_laplacian() - TD.cotan_laplacian()).max()
    assert diff < 1e-9
    same = {tuple(np.roll(f, -np.argmin(f))) for f in T.F}
    assert same == {tuple(np.roll(f, -np.argmin(f))) for f in FD}


def test_flipped_lengths_are_3d_distances():
    # planar mesh placed obliquely in 3D: intrinsic distances equal straight 3D distances
    V, F = jittered_grid(14, shear=3.0, jitter=0.2, seed=5)
    R = np.linalg.qr(np.random.default_rng(0).normal(size=(3, 3)))[0]
    V = V @ R.T + np.array([1.0, -2.0, 0.5])
    T = intrinsic_delaunay(V, F)
    assert T.report['flips'] > 50 and T.report['eps'] == 0.0
    ev = T.edge_vertices()
    np.testing.assert_allclose(T.edge_lengths, np.linalg.norm(V[ev[:, 0]] - V[ev[:, 1]], axis=1),
                               rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(T.l, edge_lengths_3d(V, T.F), rtol=1e-12, atol=1e-12)


def test_laplacian_properties(flat):
    V, F, T0, T = flat
    w = interior_weights(T)
    assert w.min() >= -1e-12
    assert interior_weights(T0).min() < -0.1
    for tri in (T0, T):
        L = tri.cotan_laplacian()
        assert sp.isspmatrix_csc(L) and L.shape == (len(V), len(V))
        assert abs(L - L.T).max() < 1e-12
        assert np.abs(L @ np.ones(len(V))).max() < 1e-10
        assert np.linalg.eigvalsh(L.toarray()).min() > -1e-10
    off = T.cotan_laplacian().tocoo()
    interior_pairs = off.row != off.col
    # multi-edges do not arise on a flat Delaunay mesh, so every off-diagonal entry is -w_e <= 0 except
    # obtuse angles at the boundary
    assert T.report['negative_after'] == T.report['negative_boundary_after']
    assert np.sum(off.data[interior_pairs] > 1e-12) == 2 * T.report['negative_boundary_after']


def test_linear_precision_before_and_after(flat):
    V, F, T0, T = flat
    inner = ~boundary_vertices(F, len(V))
    for tri in (T0, T):
        L = tri.cotan_laplacian()
        for c in (0, 1):
            assert np.abs((L @ V[:, c])[inner]).max() < 1e-10


def test_angle_sums_and_area_preserved(flat):
    V, F, T0, T = flat
    np.testing.assert_allclose(T.angle_sums(), T0.angle_sums(), atol=1e-12)
    inner = ~boundary_vertices(F, len(V))
    np.testing.assert_allclose(T.angle_sums()[inner], 2 * np.pi, atol=1e-12)
    A3 = 0.5 * np.linalg.norm(np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]]), axis=1)
    assert T.areas().sum() == pytest.approx(A3.sum(), rel=1e-13)
    assert T0.areas().sum() == pytest.approx(A3.sum(), rel=1e-13)


def test_gradient_divergence_rotation(flat):
    V, F, T0, T = flat
    rng = np.random.default_rng(2)
    f = rng.normal(size=len(V))
    L = T.cotan_laplacian()
    np.testing.assert_allclose(T.divergence(T.gradient(f)), L @ f, atol=1e-10)
    gx = T.gradient(V[:, 0])
    np.testing.assert_allclose(np.linalg.norm(gx, axis=1), 1.0, atol=1e-10)
    # the plane is conformal to itself: rot grad x = grad y triangle by triangle, so L y = div(rot grad x)
    np.testing.assert_allclose(T.rotated(gx), T.gradient(V[:, 1]), atol=1e-10)
    np.testing.assert_allclose(T.divergence(T.rotated(gx)), L @ V[:, 1], atol=1e-10)
    P = T.layout()
    np.testing.assert_allclose(np.linalg.norm(P[:, [1, 2, 0]] - P[:, [2, 0, 1]], axis=2), T.l, atol=1e-12)


def test_invariant_to_vertex_and_face_order(flat):
    V, F, T0, T = flat
    rng = np.random.default_rng(7)
    perm = rng.permutation(len(V))          # new vertex q is old vertex perm[q]
    inv = np.argsort(perm)                  # old vertex i is new vertex inv[i]
    F2 = inv[F][rng.permutation(len(F))]
    F2 = np.roll(F2, 1, axis=1)             # also rotate the corners
    T2 = intrinsic_delaunay(V[perm], F2)
    L1 = T.cotan_laplacian().toarray()
    L2 = T2.cotan_laplacian().toarray()[np.ix_(inv, inv)]
    assert np.abs(L1 - L2).max() < 1e-10
    assert T2.report['flips'] == T.report['flips']


# --- degenerate and curved meshes --------------------------------------------------------------------

def test_zero_area_triangle_is_mollified():
    V = np.array([[0, 0, 0], [2, 0, 0], [1, 0, 0], [1, 1, 0], [1, -1, 0]], dtype=float)
    F = np.array([[0, 2, 1], [0, 1, 3], [2, 0, 4], [1, 2, 4]])   # face 0 has three collinear vertices
    T0 = intrinsic_delaunay(V, F, max_rounds=0)
    assert T0.report['eps'] > 0
    assert np.all(T0.areas() > 0)
    T = intrinsic_delaunay(V, F)
    assert T.report['flips'] >= 1 and T.report['converged']
    L = T.cotan_laplacian().toarray()
    assert np.all(np.isfinite(L))
    assert np.abs(L - L.T).max() < 1e-12 and np.abs(L.sum(1)).max() < 1e-9
    assert interior_weights(T).min() >= -1e-12
    # without mollification the same mesh gives inf / nan
    Tr = intrinsic_delaunay(V, F, mollify_delta=0, max_rounds=0)
    assert not np.all(np.isfinite(Tr.cotan_laplacian().toarray()))


def test_twisted_sphere_becomes_delaunay():
    V, F = twisted_sphere()
    T = intrinsic_delaunay(V, F)
    r = T.report
    assert r['negative_before'] > 20 and r['flips'] > 0
    assert r['converged'] and r['negative_after'] == 0
    assert T.edge_weights().min() >= -1e-12
    Omega = 2 * np.pi - T.angle_sums()
    assert Omega.sum() == pytest.approx(4 * np.pi, abs=1e-9)           # Gauss-Bonnet, genus 0
    T0 = intrinsic_delaunay(V, F, max_rounds=0)
    np.testing.assert_allclose(T.angle_sums(), T0.angle_sums(), atol=1e-10)
    assert T.areas().sum() == pytest.approx(T0.areas().sum(), rel=1e-12)
    L = T.cotan_laplacian()
    assert np.abs(L @ np.ones(len(V))).max() < 1e-10 and abs(L - L.T).max() < 1e-12


def test_several_components_and_errors():
    V1, F1 = jittered_grid(6, shear=2.0, seed=1)
    V2, F2 = twisted_sphere(24, 4)
    V = np.concatenate([V1, V2 + 50.0])
    F = np.concatenate([F1, F2 + len(V1)])
    T = intrinsic_delaunay(V, F)
    assert T.report['converged']
    assert interior_weights(T).min() >= -1e-12
    with pytest.raises(ConformalError):
        intrinsic_delaunay(V1, np.concatenate([F1, F1[:1]]))          # an edge with 3 faces
    bad = F1.copy()
    bad[0] = bad[0, ::-1]
    with pytest.raises(ConformalError):
        intrinsic_delaunay(V1, bad)
    assert isinstance(T, IntrinsicTriangulation)


def test_speed_100k_printed():
    V, F = jittered_grid(224, shear=3.0)
    t0 = time.perf_counter()
    T = intrinsic_delaunay(V, F)
    dt = time.perf_counter() - t0
    print('\nintrinsic_delaunay: %d triangles in %.2f s, %s' % (len(F), dt, T.report))
    assert T.report['converged']


def test_guards_unflippable_edge_and_round_limit():
    # a two-triangle "pillow": edge 1-2 sees the obtuse angle at vertex 0 on both sides, but its two
    # opposite vertices are the same vertex, so it is not flipped; no endless loop, and it is reported
    V = np.array([[0, 0.2, 0], [-1, 0, 0], [1, 0, 0]], dtype=float)
    T = intrinsic_delaunay(V, [[0, 1, 2], [0, 2, 1]])
    assert T.report['flips'] == 0 and T.report['non_delaunay_after'] == 1 and not T.report['converged']
    V, F = jittered_grid(20, shear=6.0, jitter=0.2, seed=4)
    T1 = intrinsic_delaunay(V, F, max_rounds=1)
    assert T1.report['rounds'] == 1 and not T1.report['converged']
    T = intrinsic_delaunay(V, F)
    assert T.report['rounds'] > 1 and T.report['converged']
    assert intrinsic_delaunay(V, F[:0]).report['flips'] == 0


# two faces of a voxel-remeshed figure (Blender's Remesh modifier, exported to OBJ at 9 digits) after
# one round of flips: a right isosceles triangle against a sliver whose lengths nearly meet the
# triangle inequality, so that cot alpha + cot beta is -1.5e-12 for either diagonal
SLIVER_QUAD_F = np.array([[3, 2, 0], [1, 3, 0]])
SLIVER_QUAD_L = np.array([[0.015238406389101428, 0.010816024643697995, 0.010815658787351388],
                          [0.010816024643697995, 0.010815658787351388, 5.193514642509722e-07]])


def test_a_tie_within_rounding_is_not_flipped_back_and_forth():
    """The edge of a quad whose cotangent sum is zero within its rounding error is Delaunay: the
    flips stop at once. Testing against a fixed 1e-12 flipped it back and forth for all of
    ``max_rounds`` (10,000 rounds: 7.7 s of the cone path's set-up on a 22k-triangle figure, and 86 s
    of its layouts, which triangulate each cut mesh again)."""
    from core.mesh.intrinsic import cot_rounding
    T = intrinsic_delaunay(np.zeros((4, 3)), SLIVER_QUAD_F, mollify_delta=0, lengths=SLIVER_QUAD_L,
                           max_rounds=100)
    assert T.report['converged'] and T.report['rounds'] <= 1 and T.report['flips'] <= 1
    w = T.cotangents()
    inner = np.flatnonzero(T.EF[:, 1] >= 0)[0]
    s = sum(w[T.EF[inner, i], T.EC[inner, i]] for i in (0, 1))
    assert -1e-9 < s < 0 and abs(s) < cot_rounding(T.l, T.areas()).sum()
    # an edge that is non-Delaunay beyond rounding still flips: the long diagonal of a flat kite
    V = np.array([[0, -0.1, 0], [1, 0, 0], [0, 0.1, 0], [-1, 0, 0]], dtype=float)
    T = intrinsic_delaunay(V, [[1, 2, 3], [1, 3, 0]], mollify_delta=0)
    assert T.report['flips'] == 1 and T.report['converged']


def test_the_cotangent_rounding_bound_holds_on_slivers():
    """``cot_rounding`` bounds the error of the cotangents computed from float lengths: against the
    same lengths in 60-digit decimal arithmetic, on 2,000 random triangles from well shaped to slivers
    within 1e-9 of the triangle inequality."""
    from decimal import Decimal, getcontext
    from core.mesh.intrinsic import corner_cotangents, cot_rounding
    getcontext().prec = 60
    rng = np.random.default_rng(7)
    a = rng.uniform(0.5, 2.0, 2000)
    b = rng.uniform(0.5, 2.0, 2000)
    gap = 10.0 ** rng.uniform(-9, 0, 2000)                 # c from |a - b| + gap to a + b - gap
    lo, hi = np.abs(a - b) + gap, a + b - gap
    c = np.where(rng.random(2000) < 0.5, lo, hi)
    ok = (lo < hi)
    L = np.c_[a, b, c][ok]
    cot = corner_cotangents(L)
    rho = cot_rounding(L, face_areas(L))
    worst = 0.0
    for row, got, r in zip(L, cot, rho):
        x, y, z = (Decimal(float(v)) for v in row)
        q = (x + y + z) * (-x + y + z) * (x - y + z) * (x + y - z)
        four_area = q.sqrt()
        exact = [(y * y + z * z - x * x) / four_area, (z * z + x * x - y * y) / four_area,
                 (x * x + y * y - z * z) / four_area]
        err = max(abs(float(Decimal(float(g)) - e)) for g, e in zip(got, exact))
        worst = max(worst, err / r)
    assert worst < 1.0, worst
    print(f"largest error over the bound: {worst:.3g}")
