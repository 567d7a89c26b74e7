"""Exact distances on flat parts (core.geodesic.planar, ``PlanarChart`` in the solver), against
references computed here from the domain's geometry alone: straight segments, and paths that bend at
the corners of a removed rectangle."""
import numpy as np
import pytest

from core.geodesic import solver as geo
from core.geodesic.planar import PlanarPaths, plane_coordinates, planar_paths
from meshgen import compact


def flat_grid(n, size=2.0):
    """Flat grid of n x n vertices on [0, size]^2 (z = 0)."""
    x, y = np.meshgrid(np.linspace(0, size, n), np.linspace(0, size, n))
    V = np.c_[x.ravel(), y.ravel(), np.zeros(n * n)]
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    return V, np.r_[np.c_[a, b, d], np.c_[a, d, c]]


def without_box(V, F, lo, hi):
    """The triangles whose centroid lies outside the open box ``lo`` < (x, y) < ``hi``."""
    C = V[F].mean(1)[:, :2]
    inside = ((C > lo) & (C < hi)).all(1)
    return compact(V, F[~inside])


def blocked(p, q, lo, hi):
    """(k,) bool: the segments p (k,2) -> q (k,2) pass through the open box lo < x < hi (Liang-Barsky)."""
    d = q - p
    t0, t1 = np.zeros(len(p)), np.ones(len(p))
    for ax in (0, 1):
        with np.errstate(divide='ignore', invalid='ignore'):
            a = (lo[ax] - p[:, ax]) / d[:, ax]
            b = (hi[ax] - p[:, ax]) / d[:, ax]
        par = np.abs(d[:, ax]) < 1e-15
        inside = (p[:, ax] > lo[ax]) & (p[:, ax] < hi[ax])
        t0 = np.where(par, np.where(inside, t0, 2.0), np.maximum(t0, np.minimum(a, b)))
        t1 = np.where(par, np.where(inside, t1, -1.0), np.minimum(t1, np.maximum(a, b)))
    return t1 - t0 > 1e-9


def around_box(S, X, lo, hi):
    """Exact distances (k,) from the point ``S`` (2,) to the points ``X`` (k,2) in a domain with the
    rectangle lo..hi removed: straight, or bent at one corner, or at two corners joined by a side."""
    corners = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    S2 = np.broadcast_to(S, X.shape)
    best = np.where(blocked(S2, X, lo, hi), np.inf, np.hypot(*(X - S).T))
    reach = {}
    for i, c in enumerate(corners):
        if not blocked(S[None], c[None], lo, hi)[0]:
            reach[i] = np.hypot(*(c - S))
    for i in range(4):                       # around one side: from corner i to a neighbour
        for j in ((i + 1) % 4, (i - 1) % 4):
            if i in reach:
                side = reach[i] + np.hypot(*(corners[j] - corners[i]))
                reach[j] = min(reach.get(j, np.inf), side)
    for j, dj in reach.items():
        c = np.broadcast_to(corners[j], X.shape)
        best = np.minimum(best, np.where(blocked(c, X, lo, hi), np.inf, dj + np.hypot(*(X - corners[j]).T)))
    return best


def test_plane_coordinates_finds_flat_parts_only():
    V, F = flat_grid(6)
    rng = np.random.default_rng(0)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    P = plane_coordinates(V @ Q.T + [1.0, -2.0, 0.5], F)
    assert P is not None
    # lengths are kept (the plane's own coordinates)
    E = F[:, :2]
    assert np.allclose(np.hypot(*(P[E[:, 0]] - P[E[:, 1]]).T),
                       np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1))
    bent = V.copy()
    bent[:, 2] = 0.05 * bent[:, 0] ** 2
    assert plane_coordinates(bent, F) is None
    flipped = F.copy()
    flipped[0] = flipped[0, ::-1]                 # one triangle turned the other way: not one sheet
    assert plane_coordinates(V, flipped) is None


@pytest.mark.parametrize('source', [(0.3, 0.2), (1.7, 0.35), (0.1, 1.9)])
def test_distances_around_a_removed_rectangle_are_exact(source):
    V, F = flat_grid(41)
    lo, hi = np.array([0.55, 0.75]), np.array([1.45, 1.25])
    V, F = without_box(V, F, lo, hi)
    s = int(np.argmin(np.hypot(*(V[:, :2] - source).T)))
    ref = around_box(V[s, :2], V[:, :2], lo, hi)
    d, rep = geo.GeodesicSolver(V, F).distance([s])
    assert rep['planar_islands'] == 1 and rep['error_estimate'] == 0.0 and not rep['warnings']
    assert rep['clamped'] == {'below_euclid': 0, 'above_edges': 0}
    assert np.isfinite(ref).all()
    assert np.abs(d - ref).max() < 1e-12 * ref.max()
    assert (ref > np.hypot(*(V[:, :2] - V[s, :2]).T) + 1e-6).any()     # some paths do bend


def test_point_sources_and_several_sources():
    V, F = flat_grid(21)
    lo, hi = np.array([0.5, 0.5]), np.array([1.5, 1.1])
    V, F = without_box(V, F, lo, hi)
    gs = geo.GeodesicSolver(V, F)
    f = int(np.flatnonzero((V[F].mean(1)[:, 1] < 0.3))[7])
    bary = np.array([[0.2, 0.5, 0.3]])
    X = bary @ V[F[f]]
    d, rep = gs.distance(points=([f], bary))
    assert rep['planar_islands'] == 1
    assert np.abs(d - around_box(X[0, :2], V[:, :2], lo, hi)).max() < 1e-12
    s = [0, len(V) - 1]
    d2, _ = gs.distance(s)
    ref = np.minimum(around_box(V[s[0], :2], V[:, :2], lo, hi), around_box(V[s[1], :2], V[:, :2], lo, hi))
    assert np.abs(d2 - ref).max() < 1e-12


def test_a_seam_slit_is_walked_around():
    """A seam from the bottom edge to the middle of a flat square: the two sides meet at the same
    points in space, but a path must go round the slit's end."""
    n = 21
    V, F = flat_grid(n, 1.0)
    col = n // 2
    seams = np.array([[i * n + col, (i + 1) * n + col] for i in range(12)])    # x = 0.5, y 0 .. 0.6
    tip = V[12 * n + col, :2]
    s = 3 * n + 2                                                               # left of the slit
    gs = geo.GeodesicSolver(V, F, seams=seams)
    d, rep = gs.distance([s])
    assert rep['planar_islands'] == 1
    S, X = V[s, :2], V[:, :2]
    # right of the slit and below the line from the source over its end: round the end
    over = tip[1] + (X[:, 0] - tip[0]) * (tip[1] - S[1]) / (tip[0] - S[0])     # the line over the end
    shade = (X[:, 0] > 0.5 + 1e-9) & (X[:, 1] < over - 1e-9)
    ref = np.where(shade, np.hypot(*(tip - S)) + np.hypot(*(X - tip).T), np.hypot(*(X - S).T))
    assert shade.sum() > 20
    assert np.abs(d - ref).max() < 1e-12


def test_invariant_to_rigid_motion_scale_and_vertex_order():
    V, F = flat_grid(17)
    V, F = without_box(V, F, np.array([0.6, 0.3]), np.array([1.2, 1.5]))
    s = 5
    d0, _ = geo.GeodesicSolver(V, F).distance([s])
    rng = np.random.default_rng(4)
    Q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
    d1, _ = geo.GeodesicSolver(3.0 * V @ Q.T + [2.0, 1.0, -1.0], F).distance([s])
    assert np.allclose(d1, 3.0 * d0, rtol=1e-12, atol=1e-12)
    perm = rng.permutation(len(V))
    inv = np.argsort(perm)
    d2, _ = geo.GeodesicSolver(V[perm], inv[F][rng.permutation(len(F))]).distance([inv[s]])
    assert np.allclose(d2[inv], d0, rtol=1e-12, atol=1e-12)


def test_visibility_along_walls_and_through_corners():
    """Segments that run along a wall, or touch a reflex corner, are inside; one that cuts across the
    removed square is not."""
    V, F = flat_grid(5, 4.0)                     # unit cells on [0,4]^2, the square (1,1)-(3,3) removed
    V, F = without_box(V, F, np.array([1.0, 1.0]), np.array([3.0, 3.0]))
    P = plane_coordinates(V, F)
    pp = PlanarPaths(P, F)
    at = {tuple(np.round(V[i, :2]).astype(int)): i for i in range(len(V))}
    assert set(pp.R.tolist()) == {at[(1, 1)], at[(3, 1)], at[(3, 3)], at[(1, 3)]}
    seen = pp.visible_from(P[at[(0, 1)]], at[(0, 1)])
    assert seen[at[(4, 1)]]                      # along the bottom side of the square
    assert seen[at[(2, 0)]]
    assert not seen[at[(4, 2)]]                  # through the square
    seen = pp.visible_from(P[at[(0, 2)]], at[(0, 2)])
    assert seen[at[(2, 0)]]                      # touches the corner (1,1) from outside
    assert seen[at[(2, 4)]]                      # touches the corner (1,3) from outside
    assert not seen[at[(4, 2)]]
    seen = pp.visible_from(P[at[(0, 0)]], at[(0, 0)])
    assert seen[at[(1, 1)]] and not seen[at[(4, 2)]] and not seen[at[(3, 3)]]


def test_a_forced_grid_keeps_the_grid_and_a_given_map_is_still_checked():
    V, F = flat_grid(17)
    uv = V[:, :2].copy()
    assert geo.GeodesicSolver(V, F, uv=uv).distance([0])[1]['planar_islands'] == 1
    uv[F[3]] = uv[F[3][[0, 2, 1]]]
    with pytest.raises(geo.ConformalError, match='flipped'):
        geo.GeodesicSolver(V, F, uv=uv)
    assert geo.GeodesicSolver(V, F, grid=256).distance([0])[1]['planar_islands'] == 0
    assert geo.GeodesicSolver(V, F, method='grid').distance([0])[1]['planar_islands'] == 0
    assert geo.GeodesicSolver(V, F, steiner_points=5).distance([0])[1]['planar_islands'] == 0


def test_planar_paths_declines_two_fans_at_a_vertex_and_too_many_pairs():
    """Two squares that touch at one corner (that vertex's interior is two wedges), and a budget of
    (vertex, corner) pairs: no ``PlanarPaths``, so the solver keeps the grid."""
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0], [2, 1, 0], [2, 2, 0], [1, 2, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3], [2, 4, 5], [2, 5, 6]])
    assert planar_paths(plane_coordinates(V, F), F) is None
    W, G = flat_grid(9)
    W, G = without_box(W, G, np.array([0.5, 0.5]), np.array([1.5, 1.5]))
    P = plane_coordinates(W, G)
    assert len(planar_paths(P, G).R) == 4
    assert planar_paths(P, G, budget=4 * len(W) - 1) is None


def cells_mesh(cells, triangles=()):
    """Triangles of axis-aligned cells ``(x0, x1, y0, y1)`` (two each) and of extra ``triangles`` (three
    (x, y) corners each, counter-clockwise), vertices merged by position."""
    pts, F = {}, []
    for x0, x1, y0, y1 in cells:
        q = [pts.setdefault(p, len(pts)) for p in ((x0, y0), (x1, y0), (x1, y1), (x0, y1))]
        F += [[q[0], q[1], q[2]], [q[0], q[2], q[3]]]
    for tri in triangles:
        F.append([pts.setdefault(tuple(p), len(pts)) for p in tri])
    V = np.array([[x, y, 0.0] for x, y in pts], float)
    return V, np.array(F)


def test_a_long_wall_near_the_source_blocks_what_lies_behind_it():
    """A U whose arms are split by a slot, each inner wall one edge 4 long: the source 0.02 from the
    middle of the left one, a vertex 0.27 away behind both walls, nearer than any end of them."""
    xs = [0, 0.95, 1.0, 1.2, 1.25, 2.2]
    cells = [(a, b, 0.0, 1.0) for a, b in zip(xs[:-1], xs[1:])]                    # the bottom
    cells += [(0.0, 0.95, 1.0, 5.0), (0.95, 1.0, 1.0, 5.0)]                        # the left arm
    cells += [(1.25, 2.2, 1.0, 3.0), (1.25, 2.2, 3.0, 5.0)]                        # the right arm
    strip = [((1.2, 1.0), (1.25, 1.0), (1.25, 3.0)), ((1.2, 1.0), (1.25, 3.0), (1.2, 5.0)),
             ((1.25, 3.0), (1.25, 5.0), (1.2, 5.0))]                               # its wall: one edge
    V, F = cells_mesh(cells, strip)
    gs = geo.GeodesicSolver(V, F)
    for f in np.flatnonzero(np.all(np.isin(V[F][:, :, 0], [0.95, 1.0]), axis=1)):
        W = V[F[f], :2]
        bary = np.linalg.solve(np.r_[W.T, np.ones((1, 3))], [0.98, 3.0, 1.0])
        if (bary >= 0).all():
            break
    X = bary @ W
    d, rep = gs.distance(points=([f], bary[None]))
    assert rep['planar_islands'] == 1
    t = int(np.argmin(np.hypot(V[:, 0] - 1.25, V[:, 1] - 3.0)))
    behind = np.hypot(*(X - [1.0, 1.0])) + 0.2 + np.hypot(0.05, 2.0)  # round the slot's bottom corners
    assert abs(d[t] - behind) < 1e-12 and np.hypot(*(V[t, :2] - X)) < 0.3
