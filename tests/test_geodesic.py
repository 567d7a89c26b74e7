"""Geodesic distance by fast marching on the conformal plane (core.geodesic.solver, core.geodesic.eikonal,
CLI).

Exact references: tests/data/geodesic_ref_*.npz (pygeodesic exact MMP, bench/make_refdata.py)."""
import os
import sys
import warnings

import numpy as np
import pytest

from conftest import DATA
from meshgen import closed_end_tube, jagged_cap, scan_patch
from core.geodesic import solver as geo
from core.mesh import topology
from core.cli import main
from core.geodesic.eikonal import sweep, travel_time
from core.errors import ConformalError
from core.disk.flatten import flatten
from core.io.obj import write_obj
from core.surfaces import make_surface


def rel_errors(V, d, D, s, exclude=0.05):
    """Mean and max relative error, leaving out vertices within ``exclude`` of source vertex s."""
    far = np.linalg.norm(V - V[s], axis=1) > exclude
    r = np.abs(d[far] - D[far]) / D[far]
    return r.mean(), r.max()


def _reference(name, j):
    """Source ``j`` of ``tests/data/geodesic_ref_<name>.npz`` (exact MMP): ``(V, F, s, D, far)``, ``far``
    the vertices more than 2 % of the bounding-box diagonal from the source ``s``."""
    ref = np.load(os.path.join(DATA, f'geodesic_ref_{name}.npz'))
    V, F = ref['V'], ref['F'].astype(np.int64)
    s, D = int(ref['sources'][j]), ref['dist'][j]
    return V, F, s, D, np.linalg.norm(V - V[s], axis=1) > 0.02 * np.linalg.norm(np.ptp(V, axis=0))


@pytest.fixture(scope='module')
def flat():
    V, F = make_surface('flat', 65)
    return V, F, flatten(V, F, boundary='area').uv


@pytest.fixture(scope='module')
def bump65():
    V, F = make_surface('bump', 65)
    ref = np.load(os.path.join(DATA, 'geodesic_ref_bump_65.npz'))
    return V, F, flatten(V, F, boundary='area').uv, ref['sources'], ref['dist'].astype(np.float64)


# ------------------------------------------------------------------------------------------------
def test_flat_square_is_euclidean(flat):
    V, F, uv = flat
    for s in (0, 2112, 32, 1000):
        d, rep = geo.geodesic_distance(V, F, [s], uv=uv, grid=512)
        E = np.linalg.norm(V - V[s], axis=1)
        mean, mx = rel_errors(V, d, E, s)
        assert mx < 1e-3, (s, mean, mx)
        assert mean < 2e-4
        assert d[s] == pytest.approx(0.0, abs=1e-9)
        assert rep['solver'] == 'skfmm' and rep['grid'][1] == 512


def test_flat_square_through_the_whole_pipeline():
    """No UV given: flatten inside (uniform boundary, the default), any rotation/translation of
    the plane must still give Euclidean distances."""
    V, F = make_surface('flat', 33)
    d, rep = geo.geodesic_distance(V, F, [100], grid=512)
    E = np.linalg.norm(V - V[100], axis=1)
    _, mx = rel_errors(V, d, E, 100)
    assert mx < 1e-3
    assert rep['boundary'] == 'uniform'


@pytest.mark.parametrize('k', [0, 1, 2])
def test_bump65_against_exact_geodesics(bump65, k):
    V, F, uv, sources, D = bump65
    s = int(sources[k])
    d, rep = geo.geodesic_distance(V, F, [s], uv=uv, grid=512)
    mean, mx = rel_errors(V, d, D[k], s)
    # measured: mean 0.007-0.013 %, max 0.04-0.10 %
    assert mean < 5e-4, mean
    assert mx < 5e-3, mx


def test_seed_handling_removes_the_point_source_offset(flat):
    """A bare point seed leaves fast marching ~0.3 cells off; the exact disk with the calibrated
    rim must be far better near the source (within 0.3 units, excluding 0.05)."""
    V, F, uv = flat
    s = 1000
    E = np.linalg.norm(V - V[s], axis=1)
    ring = (E > 0.05) & (E < 0.3)
    d_good, _ = geo.geodesic_distance(V, F, [s], uv=uv, grid=256)
    d_bare, _ = geo.geodesic_distance(V, F, [s], uv=uv, grid=256, source_radius=1.0, calibrate=False)
    err_good = np.abs(d_good - E)[ring].max()
    err_bare = np.abs(d_bare - E)[ring].max()
    assert err_good < 0.3 * err_bare, (err_good, err_bare)


def test_calibrated_rim_starts_exactly():
    """Replicate scikit-fmm's start formula and check it returns the wanted distances outside."""
    h = 1.0
    x = np.arange(40.0)
    X, Y = np.meshgrid(x, x)
    D = np.hypot(X - 19.3, Y - 20.6) - 7.0
    valid = np.ones(D.shape, bool)
    phi = geo.calibrate_phi(D, valid, h)
    assert np.array_equal(np.sign(phi), np.sign(D))
    inv2 = np.zeros(D.shape)
    for axis in (0, 1):
        best = np.full(D.shape, np.inf)
        for shift in (1, -1):
            q = np.roll(phi, shift, axis=axis)
            ok = phi * q < 0
            with np.errstate(divide='ignore', invalid='ignore'):
                best = np.minimum(best, np.where(ok, h * phi / (phi - q), np.inf))
        inv2 += np.where(np.isfinite(best), 1 / best ** 2, 0)
    ring = (inv2 > 0) & (D > 0)
    start = 1 / np.sqrt(inv2[ring])
    assert np.abs(start - D[ring]).max() < 1e-9
    # without calibration the same formula is off by a good fraction of a cell
    assert ring.sum() > 20


def test_two_sources_give_the_pointwise_minimum(bump65):
    V, F, uv, sources, D = bump65
    a, b = int(sources[0]), int(sources[1])
    d2, rep = geo.geodesic_distance(V, F, [a, b], uv=uv, grid=512)
    da, _ = geo.geodesic_distance(V, F, [a], uv=uv, grid=512)
    db, _ = geo.geodesic_distance(V, F, [b], uv=uv, grid=512)
    both = np.minimum(da, db)
    assert np.abs(d2 - both).max() < 2e-3 * both.max()
    exact = np.minimum(D[0], D[1])
    far = (np.linalg.norm(V - V[a], axis=1) > 0.05) & (np.linalg.norm(V - V[b], axis=1) > 0.05)
    assert (np.abs(d2 - exact)[far] / exact[far]).mean() < 5e-4
    assert rep['sources'] == 2


def test_barycentric_point_sources(flat, bump65):
    V, F, uv = flat
    # a point in the middle of triangle 1234 of the flat square: Euclidean distances
    f, b = 1234, np.array([0.2, 0.3, 0.5])
    p = b @ V[F[f]]
    d, _ = geo.geodesic_distance(V, F, points=([f], [b]), uv=uv, grid=512)
    E = np.linalg.norm(V - p, axis=1)
    far = E > 0.05
    assert (np.abs(d - E)[far] / E[far]).max() < 1e-3
    # a barycentric point on a vertex is that vertex
    Vb, Fb, uvb, sources, D = bump65
    s = int(sources[1])
    f = int(np.nonzero((Fb == s).any(1))[0][0])
    bary = (Fb[f] == s).astype(float)
    dp, _ = geo.geodesic_distance(Vb, Fb, points=([f], [bary]), uv=uvb, grid=512)
    dv, _ = geo.geodesic_distance(Vb, Fb, [s], uv=uvb, grid=512)
    assert np.allclose(dp, dv, atol=1e-12)


def test_a_surface_point_source_takes_the_refined_seed():
    """A surface point at edgebump 65's peak, on the automatic grid: the refined seed's window searched
    the point's triangle by its row in the whole chart, not in the window (an IndexError, or another
    triangle where the row fell inside the window). Now the point at a vertex, given in each triangle
    around it, answers as that vertex does: against exact MMP 0.0055-0.0072 % mean (measured), the
    vertex 0.0066 %."""
    V, F = make_surface('edgebump', 65)
    ref = np.load(os.path.join(DATA, 'geodesic_ref_edgebump_65.npz'))
    s, D = int(ref['sources'][3]), ref['dist'][3].astype(np.float64)
    gs = geo.GeodesicSolver(V, F, method='grid')
    dv, rv = gs.distance([s])
    assert rv['refined_sources'] == 1
    for f in np.nonzero((F == s).any(1))[0][:3]:
        dp, rp = gs.distance(points=([f], [(F[f] == s).astype(float)]))
        assert rp['refined_sources'] == 1
        mean, mx = rel_errors(V, dp, D, s)
        assert mean < 1e-4 and mean < 1.3 * rel_errors(V, dv, D, s)[0], (f, mean)


def test_units_follow_the_mesh_not_the_uv_scale(bump65):
    V, F, uv, sources, D = bump65
    s = int(sources[0])
    d1, _ = geo.geodesic_distance(V, F, [s], uv=uv, grid=256)
    d3, _ = geo.geodesic_distance(V, F, [s], uv=3.0 * uv + 7.0, grid=256)
    # the same grid up to round-off: a vertex exactly on a cell boundary may fall in the next cell
    # near the source and the seed shifts by 5e-7 (1.2e-6 relative at most on this map); a unit
    # error would be a factor 3
    assert np.allclose(d1, d3, rtol=1e-5, atol=1e-12)
    d2, _ = geo.geodesic_distance(2.0 * V, F, [s], uv=uv, grid=256)
    assert np.allclose(d2, 2.0 * d1, rtol=1e-9, atol=1e-12)


def test_face_mu_mode_and_report(bump65):
    V, F, uv, sources, D = bump65
    s = int(sources[2])
    d, rep = geo.geodesic_distance(V, F, [s], uv=uv, grid=512, mu_mode='face')
    mean, mx = rel_errors(V, d, D[2], s)
    assert mean < 1e-3 and mx < 1e-2
    ny, nx = rep['grid']
    assert max(ny, nx) == 512
    assert 0.0 < rep['masked_fraction'] < 0.5
    assert set(rep['seconds']) >= {'rasterise', 'solve', 'sample', 'total'}


def test_face_metric_gives_the_3d_edge_lengths():
    """The exact per-triangle metric: every UV edge, measured with G = (G^-1)^-1 of its triangle, has
    its 3D length, for any affine distortion of the map; a similarity gives G^-1 = mu^2 I."""
    V, F = make_surface('bump', 17)
    rng = np.random.default_rng(3)
    uv = V[:, :2] @ np.array([[1.3, 0.4], [-0.2, 0.7]]) + rng.normal(0, 2e-3, (len(V), 2))
    gi = geo.face_metric_inverse(V, F, uv)
    det = gi[:, 0] * gi[:, 2] - gi[:, 1] ** 2
    G = np.stack([gi[:, 2], -gi[:, 1], gi[:, 0]], 1) / det[:, None]       # (a, b, c) of G
    for i, j in ((0, 1), (1, 2), (2, 0)):
        du = uv[F[:, j]] - uv[F[:, i]]
        L = np.sqrt(G[:, 0] * du[:, 0] ** 2 + 2 * G[:, 1] * du[:, 0] * du[:, 1] + G[:, 2] * du[:, 1] ** 2)
        assert np.allclose(L, np.linalg.norm(V[F[:, j]] - V[F[:, i]], axis=1), rtol=1e-9)
    Vf, Ff = make_surface('flat', 9)
    c, s_ = np.cos(0.3), np.sin(0.3)
    gi = geo.face_metric_inverse(Vf, Ff, 2.5 * Vf[:, :2] @ np.array([[c, s_], [-s_, c]]))
    assert np.allclose(gi, np.c_[np.full(len(Ff), 6.25), np.zeros(len(Ff)), np.full(len(Ff), 6.25)])


def test_directional_mu_of_a_linear_field():
    """For T = g . x the speed is sqrt(g^T G^-1 g) / |g| on every node of the triangle, central or
    one-sided at the edges of the used region."""
    ny, nx = 6, 7
    ii, jj = np.mgrid[0:ny, 0:nx]
    g = np.array([0.6, -0.8])
    T = g[0] * jj + g[1] * ii + 10.0
    valid = np.ones((ny, nx), bool)
    valid[0, 0] = False
    face = np.where(jj < 3, 0, 1)
    ginv = np.array([[4.0, 1.0, 2.0], [1.0, 0.0, 1.0]])
    mu = geo.directional_mu(T, valid, face, ginv)
    want = [np.sqrt(g[0] ** 2 * a + 2 * g[0] * g[1] * b + g[1] ** 2 * c) for a, b, c in ginv]
    assert np.allclose(mu[valid], np.where(face == 0, want[0], want[1])[valid])
    assert mu[0, 0] == 1.0


def test_directional_mu_over_several_nodes_does_not_see_node_scale_ripples():
    """The re-marches take their directions at most ``DIRECTION_NODES`` fine: on a finer grid the
    difference spans ``step`` nodes, which a ripple of wavelength 2 step / k does not reach. A linear
    field with a ripple of 4 nodes gets the exact directional speed with ``step`` 2 (and with 4),
    and not with 1 (whose ripple feeds the next pass: the fixed point of the passes drifted on fine
    grids, edgebump's central source 0.0133 % at 2048, 0.0146 % at 4096). Near the used region's edge
    and a triangle's edge the wider difference falls back to the one-node one."""
    ny, nx = 24, 40
    ii, jj = np.mgrid[0:ny, 0:nx]
    g = np.array([0.6, -0.8])
    T = g[0] * jj + g[1] * ii + 10.0 + 0.3 * np.cos(np.pi * jj / 2) + 0.3 * np.cos(np.pi * ii / 2)
    valid = np.ones((ny, nx), bool)
    face = np.where(jj < 20, 0, 1)
    ginv = np.array([[4.0, 1.0, 2.0], [1.0, 0.0, 1.0]])
    want = np.array([np.sqrt(g[0] ** 2 * a + 2 * g[0] * g[1] * b + g[1] ** 2 * c) for a, b, c in ginv])[face]
    inner = (ii >= 4) & (ii < ny - 4) & (np.abs(jj - 19.5) > 4) & (jj >= 4) & (jj < nx - 4)
    for step in (2, 4):
        mu = geo.directional_mu(T, valid, face, ginv, step)
        assert np.allclose(mu[inner], want[inner], rtol=1e-12), step
        assert np.isfinite(mu).all() and (mu > 0).all()
    mu1 = geo.directional_mu(T, valid, face, ginv)
    assert np.abs(mu1[inner] / want[inner] - 1).max() > 0.05
    assert geo.directional_mu(T, valid, face, ginv, 1).tolist() == mu1.tolist()


def _speed_toward(G, ginv, x, y, cx, cy):
    """Exact directional speed ``sqrt(g^T G^-1 g)`` at the points (x, y) of the field ``|p - c|_G``: its
    gradient is ``G (p - c)``; G and ginv as (a, b, c) of the symmetric 2x2 matrices."""
    dx, dy = x - cx, y - cy
    gx, gy = G[0] * dx + G[1] * dy, G[1] * dx + G[2] * dy
    n = np.hypot(gx, gy)
    gx, gy = gx / n, gy / n
    return np.sqrt(ginv[0] * gx * gx + 2 * ginv[1] * gx * gy + ginv[2] * gy * gy)


def test_point_source_fit_gives_the_directions_of_an_unfolded_source():
    """Inside a triangle of constant metric G a front from one unfolded source ``c`` is ``|x - c|_G``,
    whose ``T^2 - x^T G x`` is affine: the fit over the triangle's nodes finds the directions exactly,
    where the neighbours' differences see every ripple of the times (a node-scale ripple of 0.02 cells:
    the differences err by up to 2.5 %, the fit by 2e-6). A triangle where two fronts meet
    is not fitted (its residual is far above ``FIT_RESIDUAL`` of its times' spread), nor one of fewer
    than ``FIT_MIN_NODES`` nodes, nor unused nodes."""
    from core.geodesic.directions import FIT_MIN_NODES, point_source_mu
    ny, nx, h = 40, 60, 0.05
    ii, jj = np.mgrid[0:ny, 0:nx]
    x, y = jj * h, ii * h
    ginv = np.array([[4.0, 1.0, 2.0], [1.0, 0.2, 0.5], [2.0, -0.5, 1.0], [1.0, 0.0, 1.0]])
    G = np.array([[c, -b, a] for a, b, c in ginv]) / (ginv[:, 0] * ginv[:, 2] - ginv[:, 1] ** 2)[:, None]
    face = np.where(jj < 25, 0, np.where(jj < 45, 1, 2))
    face[:2, :2] = 3                                       # a triangle of 4 nodes
    src = {0: (-2.0, 0.7), 1: (-1.5, -0.8), 2: (0.4, 3.9), 3: (-1.0, 0.0)}
    T = np.zeros((ny, nx))
    want = np.zeros((ny, nx))
    for t, (cx, cy) in src.items():
        at = face == t
        a, b, c = G[t]
        dx, dy = x[at] - cx, y[at] - cy
        T[at] = np.sqrt(a * dx * dx + 2 * b * dx * dy + c * dy * dy)
        want[at] = _speed_toward(G[t], ginv[t], x[at], y[at], cx, cy)
    # two fronts meeting in triangle 2: the times there are the nearer of two sources
    at = face == 2
    a, b, c = G[2]
    dx, dy = x[at] - 3.0, y[at] - (-2.0)
    T[at] = np.minimum(T[at], np.sqrt(a * dx * dx + 2 * b * dx * dy + c * dy * dy))
    valid = np.ones((ny, nx), bool)
    valid[20, 10] = False
    ripple = 2e-2 * h * np.cos(np.pi * jj / 2) * np.cos(np.pi * ii / 2)
    mu, fitted = point_source_mu(T + ripple, valid, face, ginv, G, h)
    assert FIT_MIN_NODES > 4
    assert fitted[(face <= 1) & valid].all() and not fitted[face >= 2].any() and not fitted[20, 10]
    assert (mu[~fitted] == 1.0).all()
    on = fitted
    assert np.abs(mu[on] / want[on] - 1).max() < 1e-4
    clean, _ = point_source_mu(T, valid, face, ginv, G, h)
    assert np.allclose(clean[on], want[on], rtol=1e-9)
    diff = geo.directional_mu(T + ripple, valid, face, ginv)
    assert np.abs(diff[on] / want[on] - 1).max() > 1e-2
    # directional_mu takes the fit where there is one, the differences elsewhere
    both = geo.directional_mu(T + ripple, valid, face, ginv, 1, (G, h))
    assert np.array_equal(both[on], mu[on]) and np.array_equal(both[~on], diff[~on])


def test_fitted_directions_lift_the_re_marches_undershoot_on_a_given_grid(monkeypatch):
    """The re-marches' fixed point sat below the exact distances, and further below the finer the grid
    (the gradient differences' noise: the eikonal solution takes the cheapest of the noisy speeds);
    with the directions fitted per triangle to an unfolded source it does not. A deep noisy cap's far
    (rim) source at a given 1024, against exact MMP, measured: mean 0.0349 -> 0.0286 %, signed -0.0268
    -> -0.0114 %; at 2048 0.0341 -> 0.0226 % and 4096 0.0426 -> 0.0192 % (docs/geodesic.md, "Forty-first
    session"). Here the fit is switched off by hand for the comparison, with the plain seed this was
    measured with (``FINE_GIVEN_ALL`` off: the refined seed, now taken by every source on a given grid,
    brings both to about 0.018 % here at 1024)."""
    monkeypatch.setattr(geo, 'FINE_GIVEN_ALL', False)
    V, F, s, D, far = _reference('deepcap', 0)
    gs = geo.GeodesicSolver(V, F, grid=1024)
    err = {}
    for fit in (True, False):
        if not fit:
            monkeypatch.setattr(geo, 'point_source_mu',
                                lambda T, *a: (np.ones(T.shape), np.zeros(T.shape, bool)))
        d, rep = gs.distance([s])
        assert rep['marches'] == 1 + geo.METRIC_PASSES
        r = (d[far] - D[far]) / D[far]
        err[fit] = (float(np.abs(r).mean()), float(r.mean()))
    assert err[True][0] < 0.9 * err[False][0] and err[True][0] < 3.1e-4, err
    assert -1.5e-4 < err[True][1] and err[False][1] < -2.2e-4, err


def test_exact_metric_removes_the_mesh_floor():
    """edgebump 65 against exact MMP: the smooth per-vertex mu ('vertex') stalls at a floor set by the
    mesh (measured centre source 0.040 % at grid 512, 0.033 % at 1024; 0.030 % at 1024 with the refined
    seed every source takes on a given grid), the exact per-triangle metric (the default) keeps falling
    with the grid (0.024 %, 0.0098 % with the plain seed; 0.0083 %, 0.0051 % refined) and its largest
    error shrinks."""
    V, F = make_surface('edgebump', 65)
    ref = np.load(os.path.join(DATA, 'geodesic_ref_edgebump_65.npz'))
    k = 1
    s, D = int(ref['sources'][k]), ref['dist'][k].astype(np.float64)
    uv = flatten(V, F, boundary='area').uv
    err = {}
    for mode, g in (('vertex', 1024), ('metric', 512), ('metric', 1024)):
        d, rep = geo.geodesic_distance(V, F, [s], uv=uv, grid=g, mu_mode=mode)
        err[mode, g] = rel_errors(V, d, D, s)
        assert rep['metric_passes'] == (geo.METRIC_PASSES if mode == 'metric' else 0)
    assert err['metric', 1024][0] < 0.7 * err['metric', 512][0], err
    assert err['metric', 1024][0] < 0.5 * err['vertex', 1024][0], err
    assert err['metric', 1024][1] < 0.8 * err['vertex', 1024][1], err
    assert err['metric', 1024][0] < 2e-4 and err['metric', 1024][1] < 1e-2, err


def test_the_automatic_grid_takes_as_few_re_marches_as_its_target_allows(bump65):
    """bump 65's map is nearly conformal per triangle (metric excess 0.0024): with an automatic grid
    the isotropic march alone meets the 0.1 % target (measured 0.0075-0.010 % mean over the bench's
    source sets, against 0.0024-0.0064 % with two re-marches, at a third of the time), and the estimate
    carries the term the re-marches would have removed. edgebump (excess 0.0235) keeps both: without
    them its centre source is 0.15 % mean, 4.5 % max. A given grid always takes both."""
    V, F, uv, sources, D = bump65
    auto = geo.GeodesicSolver(V, F, uv=uv)
    ch = auto.charts[0]
    assert ch.metric_passes == 0 and ch.excess < 0.003
    for k in range(3):
        s = int(sources[k])
        d, rep = auto.distance([s])
        mean, mx = rel_errors(V, d, D[k], s)
        assert rep['metric_passes'] == 0 and rep['marches'] == 1
        assert mean < 3e-4 and mx < 5e-3, (mean, mx)
        assert rep['error_estimate'] >= geo.PASS_ERROR[0] * ch.excess > mean
    forced = geo.GeodesicSolver(V, F, uv=uv, grid=ch.size)
    assert forced.distance([int(sources[0])])[1]['metric_passes'] == geo.METRIC_PASSES
    assert geo.metric_passes_for(0.0235, geo.ERROR_TARGET) == geo.METRIC_PASSES
    assert geo.metric_passes_for(0.016, geo.ERROR_TARGET) == 1
    assert geo.metric_error(0.0235, 0) > geo.metric_error(0.0235, 1) > geo.metric_error(0.0235, 2)


def test_a_source_on_a_jagged_boundary_seeds_no_node_it_cannot_see():
    """A cap cut along its triangles has a zigzag boundary. From a source on it, grid nodes behind the
    notches are hidden from the seed's straight segments; with the seed's level at its full radius
    they started at that level, too late, and so did what the front reached through them (measured
    0.19 % mean, 10.1 % max against the surface paths). The level now stays below every hidden node,
    at least 10 cells (0.039 %, 0.91 %)."""
    V, F = jagged_cap(5, 0.02)
    src = int(np.argmin(V[:, 2]))                     # on the cut
    loops = topology.boundary_loops(F, len(V))
    assert src in np.concatenate([np.asarray(lp) for lp in loops])
    ref, _ = geo.GeodesicSolver(V, F, method='paths', steiner_points=15).distance([src])
    d, rep = geo.GeodesicSolver(V, F, method='grid').distance([src])
    far = np.linalg.norm(V - V[src], axis=1) > 0.02 * np.linalg.norm(np.ptp(V, axis=0))
    err = np.abs(d - ref)[far] / ref[far]
    assert err.mean() < 1e-3 and err.max() < 0.02, (err.mean(), err.max())


def test_a_source_that_needs_the_refined_seed_keeps_it_beside_plain_sources():
    """Sources whose mu differ by less than 2x march together. One of them in a patch of small
    triangles takes the refined seed alone; with another source of the set on a plain seed it lost it
    (the whole group took plain seeds): on a face-like scan the multi-source set had 0.42 % mean and
    11.5 % max error where each source alone had 0.04 % and 0.5 %. Now the set's distance is the
    smallest of its sources' own distances (here 0.084 % mean, 1.2 % max apart before). On a grid
    asked for: by default a scan of needles takes the surface paths."""
    V, F = scan_patch()
    solver = geo.GeodesicSolver(V, F, method='grid')
    a = int(np.argmin(((V[:, :2] - 0.35) ** 2).sum(1)))         # in the dense patch
    b = int(np.argmin(((V[:, :2] - [-0.2, -0.5]) ** 2).sum(1)))
    da, ra = solver.distance([a])
    db, rb = solver.distance([b])
    d, rep = solver.distance([a, b])
    assert (ra['refined_sources'], rb['refined_sources'], rep['refined_sources']) == (1, 0, 1)
    both = np.minimum(da, db)
    far = np.minimum(np.linalg.norm(V - V[a], axis=1), np.linalg.norm(V - V[b], axis=1)) > \
        0.02 * np.linalg.norm(np.ptp(V, axis=0))
    apart = np.abs(d - both)[far] / both[far]
    assert apart.mean() < 1e-4 and apart.max() < 0.01, (apart.mean(), apart.max())
    ref, _ = geo.GeodesicSolver(V, F, method='paths', steiner_points=15).distance([a, b])
    err = np.abs(d - ref)[far] / ref[far]
    assert err.mean() < 1e-3 and err.max() < 0.02, (err.mean(), err.max())


def test_a_spot_the_grid_resolves_poorly_takes_the_mesh_paths_around_it():
    """On a scan-like face (``core.surfaces.scan_like``) the eye dimple holds the mesh's largest angle
    defect, and the grid there is coarser than the triangles (cell / edge up to 1.2). From a source
    0.12 away the march came late at two vertices of that spot: +4.35 % against exact MMP. Its
    vertices now take the shortest paths through Steiner points over two rings of triangles, from the
    grid around them (0.65 % max against MMP). Here against surface paths at k = 15, on a grid asked
    for (by default this scan takes the surface paths)."""
    from core.surfaces import scan_like
    V, F = scan_like('facescan')
    solver = geo.GeodesicSolver(V, F, method='grid')
    d, _ = solver.distance([1491])
    spots = solver.charts[0].spots
    assert spots.active and 491 in set(spots.inner.tolist())
    ref, _ = geo.GeodesicSolver(V, F, method='paths', steiner_points=15).distance([1491])
    far = np.linalg.norm(V - V[1491], axis=1) > 0.02 * np.linalg.norm(np.ptp(V, axis=0))
    err = np.abs(d - ref)[far] / ref[far]
    assert err.mean() < 1e-3 and err.max() < 0.01, (err.mean(), err.max())
    assert abs(d[491] - ref[491]) < 0.005 * ref[491]


def test_refined_seeds_march_one_by_one_and_slivers_take_the_mesh_paths():
    """On a scan-like deep cap (``core.surfaces.scan_like('deepcap')``), three or more of five sources
    take the refined seed. Marched as one group they came out up to 6.6 % long near one of them (against 1.2 %
    for the smallest of the five single-source runs); each now marches alone. And a sliver (cell /
    edge 2.3, anisotropy 4.7) left its three vertices to on-mesh fast marching, +15 % late from a
    source 0.13 away; the spot window around it now gives them the mesh's own paths (0.3 %)."""
    from core.surfaces import scan_like
    V, F = scan_like('deepcap')
    solver = geo.GeodesicSolver(V, F, method='grid')      # by default: the surface paths
    src = [1227, 1694, 2524, 1805, 238]
    singles = [solver.distance([s]) for s in src]
    refined = sum(r['refined_sources'] for _, r in singles)
    assert refined >= 3                     # 3 at FINE_ANISO 1.15, 4 at 1.1
    d, rep = solver.distance(src)
    both = np.minimum.reduce([x for x, _ in singles])
    diag = np.linalg.norm(np.ptp(V, axis=0))
    far = np.min(np.linalg.norm(V[:, None] - V[src][None], axis=2), axis=1) > 0.02 * diag
    apart = np.abs(d - both)[far] / both[far]
    assert rep['refined_sources'] == refined and apart.max() < 0.01, apart.max()
    d, _ = solver.distance([1246])
    ref, _ = geo.GeodesicSolver(V, F, method='paths', steiner_points=15).distance([1246])
    sliver = [2539, 1306, 3905]
    assert np.all(np.abs(d[sliver] - ref[sliver]) < 0.01 * ref[sliver]), d[sliver] / ref[sliver]


def _spot_head_cut(tmp_path):
    """spot's head cut (bench/meshes.py HEAD_CUTS['spot']: the faces above z = 0.546, their largest part;
    919 vertices, 1760 triangles, a disk) from the corpus copy in tests/data."""
    import lzma
    from core.io.obj import read_obj
    path = tmp_path / 'spot.obj'
    with lzma.open(os.path.join(os.path.dirname(__file__), 'data', 'corpus', 'spot.obj.xz')) as src:
        path.write_bytes(src.read())
    m = read_obj(str(path))
    V, F = m.V, m.triangles()[0]
    keep = F[V[F].mean(1)[:, 2] > 0.546]
    _, lab = topology.face_components(keep, len(V))
    keep = keep[lab == np.bincount(lab).argmax()]
    used = np.unique(keep)
    new = np.full(len(V), -1)
    new[used] = np.arange(len(used))
    return V[used], new[keep]


def test_a_pocket_no_march_reaches_takes_no_other_source_s_seed(tmp_path, monkeypatch):
    """On spot's head cut at grid 1024 a few nodes by the boundary lie in a pocket that no march
    reaches. Alone, each source leaves its vertices to be filled from their neighbours. In a set, a
    refined source's seed (its own march, whose level covers the pocket) gave them its times instead,
    whatever the other sources: +40 % at a boundary vertex. Now the set's distances are the smallest of
    its sources' own (one source refined, one plain: ``FINE_GIVEN_ALL`` off, as on an automatic grid)."""
    V, F = _spot_head_cut(tmp_path)
    monkeypatch.setattr(geo, 'FINE_GIVEN_ALL', False)
    solver = geo.GeodesicSolver(V, F, grid=1024, refine=False)     # on the head cut's own triangles
    (d3, r3), (d118, r118) = solver.distance([3]), solver.distance([118])
    assert (r3['refined_sources'], r118['refined_sources']) == (1, 0)
    d, _ = solver.distance([3, 118])
    both = np.minimum(d3, d118)
    far = np.minimum(np.linalg.norm(V - V[3], axis=1), np.linalg.norm(V - V[118], axis=1)) > \
        0.02 * np.linalg.norm(np.ptp(V, axis=0))
    apart = np.abs(d - both)[far] / both[far]
    assert apart.max() < 0.01, apart.max()


def test_a_given_grid_refines_every_source_s_seed(tmp_path, monkeypatch):
    """On a grid the user gives, a source whose cells are fine enough for the plain seed takes the
    refined one too: the plain seed's deficit is an offset that does not fall with the grid. spot's head
    cut from its boundary vertex farthest from the middle, against exact MMP: 0.0231 -> 0.0122 % mean
    at a given 512, 0.0098 -> 0.0074 % at 1024 (measured; a voxel figure's far source 0.031 / 0.042 ->
    0.015 / 0.020 % at 2048 / 4096, docs/geodesic.md, "Forty-second session"). The test takes 512,
    against surface paths at 31 points per edge (0.005 % from exact MMP on this mesh)."""
    V, F = _spot_head_cut(tmp_path)
    bnd = np.unique(np.concatenate(topology.boundary_loops(F, len(V))))
    mid = np.argmin(np.linalg.norm(V - V.mean(0), axis=1))
    s = int(bnd[np.argmax(np.linalg.norm(V[bnd] - V[mid], axis=1))])
    D = geo.GeodesicSolver(V, F, method='paths', steiner_points=31).distance([s])[0]    # 0.005 % from MMP
    far = np.linalg.norm(V - V[s], axis=1) > 0.02 * np.linalg.norm(np.ptp(V, axis=0))
    gs = geo.GeodesicSolver(V, F, grid=512)
    err = {}
    for every in (False, True):
        monkeypatch.setattr(geo, 'FINE_GIVEN_ALL', every)
        d, rep = gs.distance([s])
        assert rep['refined_sources'] == int(every)
        err[every] = float(np.mean(np.abs(d[far] - D[far]) / D[far]))
    assert err[True] < 0.7 * err[False] and err[True] < 1.5e-4, err


def test_a_forced_grid_on_a_map_far_from_conformal_marches_on_finer_triangles(tmp_path, capsys):
    """spot's head cut at a forced grid: its map is far from conformal on its triangles (metric_excess
    0.13), a metric the re-marches do not follow, so the error stayed at about 0.1 % whatever the grid
    (0.11 / 0.08 / 0.09 / 0.11 % mean at 512-4096 from its far source, against exact MMP). The solver
    now marches on the same surface subdivided twice at its edge midpoints (excess 0.03), and the error
    falls with the grid (0.069 / 0.029 / 0.014 / 0.009 %). Against surface paths at 31 points per
    edge (0.005 % from exact MMP on this mesh), from its boundary vertex farthest from the middle:
    0.031 % at 512 and 0.014 % at 1024 (0.088 % and 0.075 % on its own triangles); since every source
    on a given grid takes the refined seed, 0.013 % and 0.009 % (0.036 % at 1024 on its own
    triangles); the distances come back per input vertex. A surface point is answered in the child
    triangle that holds it."""
    V, F = _spot_head_cut(tmp_path)
    ref = geo.GeodesicSolver(V, F, method='paths', steiner_points=31)
    bnd = np.unique(np.concatenate(topology.boundary_loops(F, len(V))))
    mid = np.argmin(np.linalg.norm(V - V.mean(0), axis=1))
    src = int(bnd[np.argmax(np.linalg.norm(V[bnd] - V[mid], axis=1))])
    D, _ = ref.distance([src])
    far = D > 0.05 * np.linalg.norm(np.ptp(V, axis=0))

    def err(solver):
        d, rep = solver.distance([src])
        assert d.shape == (len(V),) and np.isfinite(d).all()
        return float(np.mean(np.abs(d[far] - D[far]) / D[far])), rep
    e512, rep = err(geo.GeodesicSolver(V, F, grid=512))
    assert rep['refined'] == {'levels': 2, 'triangles': 16 * len(F)} and rep['marches'] == 3
    e1024, _ = err(geo.GeodesicSolver(V, F, grid=1024))
    coarse, rep = err(geo.GeodesicSolver(V, F, grid=1024, refine=False))
    assert 'refined' not in rep
    assert e1024 < 0.8 * e512 and e1024 < 0.5 * coarse and e1024 < 2e-4, (e512, e1024, coarse)
    # a surface point: the same distances as from the vertex it sits on (its corner, barycentric 1)
    f = int(np.flatnonzero((F == src).any(1))[0])
    b = (F[f] == src).astype(float)
    solver = geo.GeodesicSolver(V, F, grid=512)
    d_pt, _ = solver.distance(points=(np.array([f]), b[None]))
    d_v, _ = solver.distance([src])
    assert np.allclose(d_pt, d_v, rtol=2e-3)
    obj = tmp_path / 'head.obj'
    write_obj(str(obj), V, F)
    rc = main(['geodesic', str(obj), '--source', str(src), '--grid', '512', '--out', str(tmp_path / 'd.csv')])
    assert rc == 0 and 'grid 512x' in (out := capsys.readouterr().out) and 'subdivided 2 times' in out, out


def test_on_a_given_grid_under_resolved_triangles_take_extrapolated_surface_paths():
    """A test tube closed at the top (its map shrinks the closed end by about e^-8) at forced grids of
    256 and 512 on its own triangles: the grid cannot resolve the top (cells up to several edges
    there). Those vertices took on-mesh fast marching (first order: 0.093 / 0.067 % mean on the
    rim-sourced free vertices, 1.36 % max at 512); on a given grid every spot up to
    SPOT_MAX_FACES_GIVEN triangles now takes the window's surface paths, extrapolated from 15 and 7
    points per edge (0.041 / 0.041 %, max 0.20 / 0.17 %). Reference: surface paths at 31 points."""
    V, F = closed_end_tube()
    D, _ = geo.GeodesicSolver(V, F, method='paths', steiner_points=31).distance([0])
    far = D > 0.05 * np.linalg.norm(np.ptp(V, axis=0))
    for grid in (256, 512):
        solver = geo.GeodesicSolver(V, F, grid=grid, refine=False)
        d, rep = solver.distance([0])
        ch = solver.charts[0]
        assert ch.given and rep['on_mesh'] > 200 and ch.spots.coarse is not None, rep['on_mesh']
        free = np.zeros(len(V), bool)
        free[solver.vert_of[ch.verts[ch.free]]] = True
        e = np.abs(d - D) / D
        assert e[free & far].mean() < 6e-4 and e[far].max() < 5e-3, (grid, e[free & far].mean(), e[far].max())


def test_where_the_metric_jumps_a_finer_given_grid_keeps_a_coarser_grid_s_spots():
    """The finger (``meshgen.finger``) from a vertex far from it, on grids the user gives, against exact
    MMP. On its flank log mu jumps by up to 0.2 from a triangle to the next, and the march across those
    jumps is first order in the nodes an edge. A spot was a triangle under four nodes an edge at every
    size, so a finer grid handed the flank's triangles from the windows' paths to its own worst band:
    0.0037 / 0.0029 / 0.0036 % mean at 1024 / 2048 / 4096, and 1.43 % max at 2048. Where the metric
    jumps (``mu_jump`` above ``SPOT_JUMP``) the spots are now those of a 512 grid at every finer size
    (``spot_cell_given``): 0.0035 / 0.0019 / 0.0012 %, and 0.097 % max at 2048. Where it does not (a
    flat mesh) nothing changes."""
    V, F, s, D, far = _reference('finger', 0)
    ch = geo.GeodesicSolver(V, F, grid=512).charts[0]
    jump = geo.mu_jump(ch.F, len(ch.V), ch.mu_face)
    assert jump.max() > 10 * geo.SPOT_JUMP and (jump <= geo.SPOT_JUMP).mean() > 0.5
    assert not geo.mu_jump(ch.F, len(ch.V), np.full(len(ch.F), 3.0)).any()
    e = {}
    for g in (1024, 2048):
        d, _ = geo.GeodesicSolver(V, F, grid=g).distance([s])
        e[g] = np.abs(d[far] - D[far]) / D[far]
    assert e[2048].mean() < 0.7 * e[1024].mean() and e[2048].max() < 2e-3, \
        (e[1024].mean(), e[2048].mean(), e[2048].max())


def test_a_spot_window_never_exceeds_a_refined_seed_s_bound(monkeypatch):
    """The lifted hemisphere's central, far and curvature vertices together (``bench/geodesic_real.py``'s
    multi set) at a given 1024, against exact MMP. With one source a refined seed holds the vertices
    near it; with three, where another source is nearer in 3D, its paths only bound them from above
    (the solver's ``claim``). A spot window laid over such vertices replaced that bound with its own,
    longer paths: three vertices 0.8 / 1.2 / 2.2 % high. ``SpotWindow.repair`` now never exceeds it:
    0.49 % at most, 0.0252 % mean."""
    V, F, _, _, _ = _reference('lifted_hemisphere', 0)
    ref = np.load(os.path.join(DATA, 'geodesic_ref_lifted_hemisphere_multi.npz'))
    src, D = [int(s) for s in ref['sources']], ref['dist']
    diag = np.linalg.norm(np.ptp(V, axis=0))
    far = np.min(np.linalg.norm(V[:, None] - V[src][None], axis=2), 1) > 0.02 * diag

    def error():
        d, _ = geo.GeodesicSolver(V, F, grid=1024).distance(src)
        return np.abs(d[far] - D[far]) / D[far]
    e = error()
    assert e.max() < 6e-3 and e.mean() < 2.7e-4, (e.max(), e.mean())
    repair = geo.SpotWindow.repair
    monkeypatch.setattr(geo.SpotWindow, 'repair', lambda self, *a: repair(self, *a[:6]))
    assert error().max() > 0.015


def test_a_deep_spot_s_window_starts_its_paths_where_the_grid_resolves_the_surface(monkeypatch):
    """A narrow bump, a finger (``meshgen.finger``), that its map shrinks 1000-fold, on grids the user
    gives: the grid cannot resolve the finger's top (deep spots, cells above a mean edge), and its nodes
    next to those came out low. A window reached two rings round every spot, so its paths started from
    those nodes. Now it reaches SPOT_RINGS_DEEP = 8 round a deep spot. From a vertex far from the finger
    the mean error was 0.0099 / 0.0073 % at 512 / 1024 and is 0.0060 / 0.0037 %; without the
    subdivision that a given grid makes here it rose with the grid, 0.0139 / 0.0219 / 0.0229 % at 512 /
    1024 / 2048, and now falls, 0.0065 / 0.0057 / 0.0047 %. From the centre, on the finger's flank, the
    window also holds the source's refined seed, and its vertices now seed the window's paths too: at
    1024, 0.0154 % mean and 1.12 % max before, 0.0102 % and 0.63 % now. Reference: exact MMP."""
    def error(j, grid):
        V, F, s, D, far = _reference('finger', j)
        d, _ = geo.GeodesicSolver(V, F, grid=grid).distance([s])
        return np.abs(d[far] - D[far]) / D[far]
    e512, e1024 = error(0, 512).mean(), error(0, 1024).mean()
    assert e1024 < 0.8 * e512 and e1024 < 5e-5, (e512, e1024)
    # the rings alone, with the spots of the grid's own size (before ``spot_cell_given`` kept the
    # spots of a 512 grid where the metric jumps, which lifts the two-ring window too: 0.0044 % here)
    with monkeypatch.context() as m:
        m.setattr(geo, 'spot_cell_given', lambda size: geo.SPOT_CELL_GIVEN)
        deep = error(0, 1024).mean()
        m.setattr(geo, 'SPOT_RINGS_DEEP', geo.SPOT_RINGS)
        assert error(0, 1024).mean() > 1.6 * deep, deep
    e = error(1, 1024)
    assert e.mean() < 1.2e-4 and e.max() < 8e-3, (e.mean(), e.max())


def test_finer_triangles_follow_the_seams_and_spare_parts_answered_by_paths():
    """Spot cut along its UV seams (13 islands, every one marched at a forced grid) is subdivided once:
    each seam edge is split in two with the mesh, the islands stay the same, and the distances (per
    input vertex, a seam vertex the nearest of its copies) agree with surface paths at 31 points per
    edge within 0.05 % on average. Suzanne by its seams is not subdivided: its head is answered by
    surface paths, which would only get fewer points per edge on the finer mesh; its eyes' maps are far
    from conformal all the same. Its distances are those of ``refine=False``, to the bit."""
    d = np.load(os.path.join(DATA, 'sphere_spot.npz'))
    V, F = d['V'].astype(np.float64), d['F'].astype(np.int64)
    seams = np.load(os.path.join(DATA, 'corpus_spot_seams.npz'))['seams'].astype(np.int64)
    gs = geo.GeodesicSolver(V, F, seams=seams, grid=512)
    assert gs.report['refined'] == {'levels': 1, 'triangles': 4 * len(F)}
    assert len(gs.fine.solver.charts) == len(gs.charts) == 13
    ref = geo.GeodesicSolver(V, F, seams=seams, method='paths', steiner_points=31)
    for s in (0, 1953):
        dist, rep = gs.distance([s])
        D, _ = ref.distance([s])
        assert np.array_equal(np.isfinite(dist), np.isfinite(D)) and rep['refined']['levels'] == 1
        far = np.isfinite(D) & (D > 0.05 * np.linalg.norm(np.ptp(V, axis=0)))
        assert np.mean(np.abs(dist[far] - D[far]) / D[far]) < 5e-4
    from core.atlas.islands import seams_from_corner_ids
    from core.io.obj import read_obj
    from core.mesh.triangulate import triangulate
    m = read_obj(os.path.join(DATA, 'suzanne.obj'))
    tc, _ = triangulate(m.corner_verts, m.sizes, m.V)
    F = m.corner_verts[tc]
    seams = seams_from_corner_ids(F, m.corner_uvs[tc], len(m.V))
    gs = geo.GeodesicSolver(m.V, F, seams=seams, grid=512)
    assert 'refined' not in gs.report and max(getattr(c, 'excess', 0.0) for c in gs.charts) > 0.2
    d1, rep = gs.distance([43])
    d0, _ = geo.GeodesicSolver(m.V, F, seams=seams, grid=512, refine=False).distance([43])
    assert 'refined' not in rep and np.array_equal(d1, d0, equal_nan=True)


def test_a_part_the_own_flattening_folds_is_answered_by_surface_paths(bump65, monkeypatch):
    """A cap cut from cheburashka came out of the flattening with one flipped triangle, and the solver
    refused the mesh ("geodesic distances need a fold-free map"). The paths need no map: such an
    island is now answered by them. Here a flattening that flips one triangle stands in for it. A
    given map that folds is still an error, and so is a grid asked for on the folded map."""
    import core.disk.flatten as disk_flatten
    V, F, uv, sources, D = bump65
    real = disk_flatten.flatten

    def folding(*args, **kwargs):
        res = real(*args, **kwargs)
        a, b, _ = F[100]
        res.uv[[a, b]] = res.uv[[b, a]]                      # triangle 100 (and its neighbours) flip
        return res
    monkeypatch.setattr(disk_flatten, 'flatten', folding)
    solver = geo.GeodesicSolver(V, F)
    assert solver.report['folded_parts'] == 1
    assert isinstance(solver.charts[0], geo.PathsChart)
    s = int(sources[0])
    d, rep = solver.distance([s])
    mean, mx = rel_errors(V, d, D[0], s)
    assert rep['paths_islands'] == 1 and mean < 1e-3 and mx < 0.02, (mean, mx)
    with pytest.raises(ConformalError, match='flipped'):
        geo.GeodesicSolver(V, F, grid=512)
    bad = uv.copy()
    a, b, _ = F[100]
    bad[[a, b]] = bad[[b, a]]
    with pytest.raises(ConformalError, match='flipped'):
        geo.GeodesicSolver(V, F, uv=bad)


def test_a_disk_pinched_at_a_vertex_is_measured_through_the_pinch():
    """A strip bent round a ring whose two ends touch at one vertex (a non-manifold vertex: a cut cow
    head had one) used to be refused ("split or rip them apart"). The surface paths take the surface
    as it is: from next to the shared vertex on one end, the other end is reached through it, not
    round the ring."""
    ns, nt, R = 64, 5, 2.0
    s_, t_ = np.meshgrid(np.linspace(0, 1, ns), np.linspace(0, 1, nt), indexing='ij')
    r = R + t_ * (1 + s_)                                  # the ends meet only at t = 0
    V = np.stack([r * np.cos(2 * np.pi * s_), r * np.sin(2 * np.pi * s_), 0.5 * t_ * s_], -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(ns - 1), np.arange(nt - 1), indexing='ij')
    a = (i * nt + j).ravel()
    F = np.concatenate([np.stack([a, a + nt, a + nt + 1], 1), np.stack([a, a + nt + 1, a + 1], 1)])
    pin, twin = 0, (ns - 1) * nt                           # (s, t) = (0, 0) and (1, 0): one point
    assert np.allclose(V[pin], V[twin])
    F[F == twin] = pin
    keep = np.setdiff1d(np.arange(len(V)), [twin])
    new = np.full(len(V), -1)
    new[keep] = np.arange(len(keep))
    V, F = V[keep], new[F]
    solver = geo.GeodesicSolver(V, F)
    assert solver.report['pinched_parts'] == 1
    src = 1                                                # (s, t) = (0, 1/4), next to the pin
    d, rep = solver.distance([src])
    near_end = new[(ns - 2) * nt + 1]                      # (s, t) = (1 - 1/63, 1/4), past the pin
    through = np.linalg.norm(V[src] - V[pin]) + np.linalg.norm(V[near_end] - V[pin])
    assert d[near_end] <= 1.01 * through and d[near_end] < 0.1 * 2 * np.pi * R      # round the ring: 12.6
    E = np.linalg.norm(V - V[src], axis=1)
    assert (d >= E * (1 - 1e-9)).all() and np.isfinite(d).all()


def test_refined_seed_at_a_strongly_curved_coarse_source():
    """edgebump 65 from its peak (the vertex of largest angle defect, where the map is anisotropic per
    triangle and the grid has about one node per edge): the grid alone carries a deficit made near the
    source everywhere (measured 0.33 % mean, values below the 3D distance); the refined seed (Steiner
    shortest paths in a window) removes it (0.045 % mean, 0.65 % max, none below the 3D distance)."""
    V, F = make_surface('edgebump', 65)
    ref = np.load(os.path.join(DATA, 'geodesic_ref_edgebump_65.npz'))
    s, D = int(ref['sources'][3]), ref['dist'][3].astype(np.float64)
    E = np.linalg.norm(V - V[s], axis=1)
    gs = geo.GeodesicSolver(V, F, grid=576)
    d, rep = gs.distance([s], clamp=False)
    assert rep['refined_sources'] == 1
    mean, mx = rel_errors(V, d, D, s)
    assert mean < 1e-3 and mx < 1e-2, (mean, mx)
    assert (d >= E - 1e-9).all()
    old = geo.FINE_NODES, geo.FINE_ANISO, geo.FINE_GIVEN_ALL
    try:
        geo.FINE_NODES, geo.FINE_ANISO, geo.FINE_GIVEN_ALL = 0.0, np.inf, False
        d0, rep0 = gs.distance([s], clamp=False)
    finally:
        geo.FINE_NODES, geo.FINE_ANISO, geo.FINE_GIVEN_ALL = old
    assert rep0['refined_sources'] == 0
    assert rel_errors(V, d0, D, s)[0] > 3 * mean


def test_refined_seed_error_falls_with_the_grid_at_edgebumps_peak():
    """The refined window reaches 16 mean 3D edges of the source (the same surface at every grid), so at
    edgebump 65's peak (triggered by coarse cells at 256 and by the metric's anisotropy, 1.151, above)
    the mean error against exact MMP falls as the grid grows. With the former window of 48 cells it
    rose (0.027 % at 512, 0.056 % at 1024: the window covered less surface at the finer grid). Measured
    0.0078 %, 0.0057 %, 0.0043 % at 256, 512, 768 (max 0.21 %, 0.084 %, 0.084 %)."""
    V, F = make_surface('edgebump', 65)
    ref = np.load(os.path.join(DATA, 'geodesic_ref_edgebump_65.npz'))
    s, D = int(ref['sources'][3]), ref['dist'][3].astype(np.float64)
    errs = []
    for g in (256, 512, 768):
        d, rep = geo.GeodesicSolver(V, F, grid=g).distance([s])
        assert rep['refined_sources'] == 1, g
        errs.append(rel_errors(V, d, D, s))
    means = [e[0] for e in errs]
    assert means[0] < 1.5e-4, errs
    assert all(b < a for a, b in zip(means, means[1:])), errs
    assert max(e[1] for e in errs) < 3e-3, errs


def test_the_seed_does_not_flip_to_a_worse_one_on_a_finer_grid(monkeypatch):
    """bump3 65 from its centre (the interior vertex of largest angle defect): at grid 512 the cells there
    are coarse (2.9 nodes per edge) and the seed is refined; at 1024 (5.8) the plain seed took over and
    the error rose (0.0106 % to 0.0154 %: a plain seed on the finer grid is worse than the refined one on
    the coarser). The choice is now read at the coarser of the grid and a ``SEED_NODES`` one, so it stays
    refined and the error falls (measured 0.0106 %, 0.0073 %, and 0.0060 % at 2048)."""
    V, F = make_surface('bump3', 65)
    ref = np.load(os.path.join(DATA, 'geodesic_ref_bump3_65.npz'))
    s, D = int(ref['sources'][0]), ref['dist'][0].astype(np.float64)
    errs = []
    for g in (512, 1024):
        d, rep = geo.GeodesicSolver(V, F, grid=g).distance([s])
        assert rep['refined_sources'] == 1, g
        errs.append(rel_errors(V, d, D, s))
    assert errs[1][0] < 0.8 * errs[0][0] and errs[0][0] < 1.5e-4, errs
    monkeypatch.setattr(geo, 'SEED_NODES', 10 ** 9)             # the choice read at the grid itself
    monkeypatch.setattr(geo, 'FINE_GIVEN_ALL', False)  # a given grid otherwise refines every source
    d, rep = geo.GeodesicSolver(V, F, grid=1024).distance([s])
    assert rep['refined_sources'] == 0
    assert rel_errors(V, d, D, s)[0] > errs[0][0], errs


def test_steiner_distances_bound_the_geodesic_from_above():
    """Shortest paths through Steiner points are paths on the surface: never below the exact geodesic
    distance, and closer to it with more points per edge (bump 65 against exact MMP)."""
    V, F = make_surface('bump', 65)
    ref = np.load(os.path.join(DATA, 'geodesic_ref_bump_65.npz'))
    s, D = int(ref['sources'][1]), ref['dist'][1].astype(np.float64)
    errs = []
    for k in (0, 2, 6):
        dv = geo.steiner_distances(V, F, src=s, k=k)[0]
        assert (dv >= D * (1 - 1e-6) - 1e-6).all()
        errs.append(rel_errors(V, dv, D, s)[0])
    assert errs[0] > 2 * errs[1] > 2 * errs[2], errs
    assert errs[2] < 5e-3, errs


@pytest.mark.parametrize('direction', [(1.0, 0.0), (0.6, 0.8), (-0.28, 0.96)])
def test_mesh_relax_is_exact_for_a_plane_front(direction):
    """On-mesh fast marching (MeshRelax) on equilateral triangles (acute: every direction has an
    upwind triangle) reproduces a plane front T = n . x exactly from its values on the boundary, with
    every interior vertex relaxed from inf."""
    k = 15
    j, i = np.mgrid[0:k, 0:k]
    V = np.c_[(i + 0.5 * j).ravel(), (np.sqrt(3) / 2 * j).ravel(), np.zeros(k * k)]
    q = (j * k + i)[:-1, :-1].ravel()
    F = np.concatenate([np.c_[q, q + 1, q + k], np.c_[q + 1, q + k + 1, q + k]])
    exact = V[:, :2] @ np.array(direction)
    edge = (i == 0) | (j == 0) | (i == k - 1) | (j == k - 1)
    free = ~edge.ravel()
    T = np.where(free, np.inf, exact)
    rounds = geo.MeshRelax(V, F, np.flatnonzero(free[F].any(1))).relax(T, free)
    assert rounds > 1
    assert np.abs(T - exact).max() < 1e-9


def test_under_resolved_triangles_go_on_mesh():
    """bump 129 on a 64-node grid: the cell is over twice the edge near the bump's top, those
    vertices take on-mesh fast marching; a source inside such a region cannot be marched from, so its
    island is answered by surface paths (accurate), and the report says so."""
    V, F = make_surface('bump', 129)
    ref = np.load(os.path.join(DATA, 'geodesic_ref_bump_129.npz'))
    gs = geo.GeodesicSolver(V, F, uv=flatten(V, F, boundary='area').uv, grid=64)
    d, rep = gs.distance([int(ref['sources'][0])])
    assert rep['on_mesh'] > 0
    assert not any('does not resolve' in w for w in rep['warnings'])
    mean, _ = rel_errors(V, d, ref['dist'][0].astype(np.float64), int(ref['sources'][0]))
    assert mean < 1e-2
    d, rep = gs.distance([int(ref['sources'][1])])
    assert rep['on_mesh'] == 0 and rep['paths_fallback'] == 1 and rep['marches'] == 0
    assert any('does not resolve' in w for w in rep['warnings'])
    mean, _ = rel_errors(V, d, ref['dist'][1].astype(np.float64), int(ref['sources'][1]))
    assert mean < 1e-3


def test_default_grid_follows_mesh_resolution():
    sizes = []
    for n in (17, 65, 129):
        V, F = make_surface('bump', n)
        sizes.append(geo.default_grid(V, F, V[:, :2]))
    assert sizes[0] <= sizes[1] <= sizes[2]
    assert sizes[0] == 256 and sizes[2] > sizes[1]


# ------------------------------------------------------------------------------------------------
# fallback solver
def test_fallback_sweep_within_twice_the_skfmm_error(bump65):
    V, F, uv, sources, D = bump65
    for k in (0, 1):
        s = int(sources[k])
        d_fmm, r1 = geo.geodesic_distance(V, F, [s], uv=uv, grid=256, solver='skfmm')
        d_sw, r2 = geo.geodesic_distance(V, F, [s], uv=uv, grid=256, solver='sweep')
        assert (r1['solver'], r2['solver']) == ('skfmm', 'sweep')
        m1, x1 = rel_errors(V, d_fmm, D[k], s)
        m2, x2 = rel_errors(V, d_sw, D[k], s)
        assert m2 <= 2.0 * m1 and x2 <= 2.0 * x1, (m1, m2, x1, x2)


def test_auto_falls_back_when_skfmm_is_missing(monkeypatch, flat):
    V, F, uv = flat
    monkeypatch.setitem(sys.modules, 'skfmm', None)          # makes `import skfmm` fail
    d, rep = geo.geodesic_distance(V, F, [2112], uv=uv, grid=128)
    assert rep['solver'] == 'sweep'
    E = np.linalg.norm(V - V[2112], axis=1)
    _, mx = rel_errors(V, d, E, 2112)
    assert mx < 5e-3
    with pytest.raises(ConformalError, match='scikit-fmm is not installed'):
        geo.geodesic_distance(V, F, [2112], uv=uv, grid=128, solver='skfmm')


def test_sweep_goes_around_an_obstacle():
    """A wall with a gap: the travel time behind the wall is the path through the gap's end."""
    n, h = 101, 0.01
    x = np.arange(n) * h
    X, Y = np.meshgrid(x, x)
    mask = (np.abs(X - 0.5) < 0.006) & (Y < 0.7)          # wall x = 0.5 from y = 0 to 0.7
    src = np.array([0.2, 0.2])
    R = np.hypot(X - src[0], Y - src[1])
    T0 = np.where(R <= 0.08, R, np.inf)
    T = sweep(T0, np.ones_like(R), h, mask=mask)
    corner = np.array([0.5, 0.7])                            # the wall's free end
    behind = np.array([0.8, 0.2])                            # node (row 20, col 80)
    expect = np.linalg.norm(corner - src) + np.linalg.norm(behind - corner)
    assert abs(T[20, 80] - expect) < 0.01 * expect
    assert T[20, 80] > 1.5 * np.linalg.norm(behind - src)    # far more than the straight line
    assert np.isinf(T[mask]).all()
    # in front of the wall it is the straight line
    assert abs(T[30, 30] - np.hypot(0.3 - 0.2, 0.3 - 0.2)) < 1e-3


def test_sweep_variable_speed_matches_skfmm():
    import skfmm
    n, h = 81, 1.0 / 80
    x = np.arange(n) * h
    X, Y = np.meshgrid(x, x)
    speed = 1.0 + 0.5 * np.sin(3 * X) * np.cos(2 * Y)
    phi = np.hypot(X - 0.5, Y - 0.5) - 0.1
    T_ref = np.asarray(skfmm.travel_time(phi, speed, dx=h, order=2))
    T = travel_time(phi, speed, h)
    out = phi > 0
    assert np.abs(T - T_ref)[out].max() < 0.02 * T_ref.max()


# ------------------------------------------------------------------------------------------------
# bad input
def test_bad_input_raises_conformal_error(flat):
    V, F, uv = flat
    with pytest.raises(ConformalError, match='out of range'):
        geo.geodesic_distance(V, F, [len(V)], uv=uv)
    with pytest.raises(ConformalError, match='no source'):
        geo.geodesic_distance(V, F, [], uv=uv)
    with pytest.raises(ConformalError, match='barycentric'):
        geo.geodesic_distance(V, F, points=([0], [[0.5, 0.6, 0.1]]), uv=uv)
    with pytest.raises(ConformalError, match='grid size'):
        geo.geodesic_distance(V, F, [0], uv=uv, grid=10)
    bad = uv.copy()
    bad[F[5]] = bad[F[5][[0, 2, 1]]]                          # fold one triangle
    with pytest.raises(ConformalError, match='flipped'):
        geo.geodesic_distance(V, F, [0], uv=bad)
    with pytest.raises(ConformalError, match='solver'):
        geo.geodesic_distance(V, F, [0], uv=uv, solver='dijkstra')


# ------------------------------------------------------------------------------------------------
# CLI
def test_cli_writes_one_distance_per_vertex(tmp_path, capsys):
    V, F = make_surface('bump', 33)
    obj = tmp_path / 'b.obj'
    write_obj(str(obj), V, F)
    out = tmp_path / 'd.txt'
    rc = main(['geodesic', str(obj), '--source', '0', '--source', '544', '--boundary', 'area',
               '--grid', '512', '--out', str(out)])
    assert rc == 0
    d = np.loadtxt(out)
    assert d.shape == (len(V),)
    assert d[0] == pytest.approx(0, abs=1e-9) and d[544] == pytest.approx(0, abs=1e-9)
    ref, _ = geo.geodesic_distance(V, F, [0, 544], boundary='area', grid=512)
    assert np.allclose(d, ref, rtol=1e-7, atol=1e-8)
    bad = tmp_path / 'e.txt'
    rc = main(['geodesic', str(obj), '--source', '99999', '--out', str(bad)])
    assert rc == 2
    err = capsys.readouterr().err
    assert err.startswith('error:') and 'out of range' in err and 'Traceback' not in err
    assert not bad.exists()
    # a closed mesh: surface paths, named in the summary line
    from core.surfaces import icosphere
    Vs, Fs = icosphere(4)
    write_obj(str(obj), Vs, Fs)
    rc = main(['geodesic', str(obj), '--source', '3', '--out', str(out)])
    assert rc == 0 and 'surface paths on 1 of 1 islands' in capsys.readouterr().out
    assert np.allclose(np.loadtxt(out), geo.geodesic_distance(Vs, Fs, [3])[0], rtol=1e-7)
    # fixed Steiner points: named in the summary, the library's answer; a bad count is refused
    rc = main(['geodesic', str(obj), '--source', '3', '--steiner-points', '5', '--out', str(out)])
    assert rc == 0 and '(5 points per edge)' in capsys.readouterr().out
    assert np.allclose(np.loadtxt(out), geo.geodesic_distance(Vs, Fs, [3], steiner_points=5)[0], rtol=1e-7)
    rc = main(['geodesic', str(obj), '--source', '3', '--steiner-points', '4', '--out', str(bad)])
    assert rc == 2 and 'steiner_points' in capsys.readouterr().err and not bad.exists()


def test_loose_vertex_gets_nan_and_does_not_shift_the_grid(flat):
    V, F, uv = flat
    V2 = np.vstack([V, [[50.0, 50.0, 0.0]]])
    uv2 = np.vstack([uv, [[1e3, -1e3]]])
    d, rep = geo.geodesic_distance(V2, F, [2112], uv=uv2, grid=512)
    assert np.isnan(d[-1])
    d0, rep0 = geo.geodesic_distance(V, F, [2112], uv=uv, grid=512)
    assert rep['grid'] == rep0['grid']
    np.testing.assert_allclose(d[:-1], d0, rtol=1e-12, atol=1e-12)


# ------------------------------------------------------------------------------------------------
# GeodesicSolver: the per-mesh work is done once
def test_solver_answers_a_second_source_without_reflattening(monkeypatch):
    import core.disk.flatten as flatten_module
    calls = {'flatten': 0, 'rasterise': 0}
    real_flatten, real_rasterise = flatten_module.flatten, geo.Grid.rasterise

    def counting_flatten(*a, **k):
        calls['flatten'] += 1
        return real_flatten(*a, **k)

    def counting_rasterise(self, *a, **k):
        calls['rasterise'] += 1
        return real_rasterise(self, *a, **k)

    monkeypatch.setattr(flatten_module, 'flatten', counting_flatten)
    monkeypatch.setattr(geo.Grid, 'rasterise', counting_rasterise)
    V, F = make_surface('bump', 33)
    gs = geo.GeodesicSolver(V, F, boundary='area', grid=256)
    assert calls == {'flatten': 1, 'rasterise': 1}
    d0, r0 = gs.distance([0])
    d1, r1 = gs.distance([544])
    d2, _ = gs.distance(points=([100], [[0.2, 0.3, 0.5]]))
    assert calls == {'flatten': 1, 'rasterise': 1}
    assert d0[0] == pytest.approx(0, abs=1e-12) and d1[544] == pytest.approx(0, abs=1e-12)
    assert int(np.argmin(d1)) == 544 and d1[0] == pytest.approx(d0[544], rel=2e-3)   # symmetry
    assert np.isfinite(d2).all() and 'flatten' in r0['seconds']
    # the one-shot wrapper gives the same numbers (and flattens once more)
    ref, _ = geo.geodesic_distance(V, F, [544], boundary='area', grid=256)
    np.testing.assert_allclose(d1, ref, rtol=1e-12, atol=1e-12)
    assert calls == {'flatten': 2, 'rasterise': 2}


# ------------------------------------------------------------------------------------------------
# exact bounds, error against grid size, error estimate and warnings (issue #14)
def test_clamps_between_euclidean_and_edge_paths(monkeypatch):
    """Coarse grids overshoot the edge paths (and, without the refined seed, undershoot the 3D
    distance); the clamps must remove both, and the unclamped run must show that there was something
    to remove. (The spot windows, which mend most of that on so coarse a grid, are off here.)"""
    from scipy.sparse.csgraph import dijkstra
    monkeypatch.setattr(geo, 'SPOT_CELL', np.inf)
    monkeypatch.setattr(geo, 'SPOT_CELL_GIVEN', np.inf)
    monkeypatch.setattr(geo, 'SPOT_ANISO', np.inf)
    import scipy.sparse as sp
    V, F = make_surface('edgebump', 33)
    gs = geo.GeodesicSolver(V, F, boundary='area', grid=64)
    # the edge graph built here, independently of the solver's: each edge once, at its 3D length
    # (the solver's once summed an interior edge's two sides, so its bound was twice the edge path)
    pairs = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)
    w = np.linalg.norm(V[pairs[:, 0]] - V[pairs[:, 1]], axis=1)
    graph = sp.coo_matrix((w, (pairs[:, 0], pairs[:, 1])), shape=(len(V), len(V))).tocsr()
    below = above = clamped = 0
    for s in (0, 500, 1088):
        E = np.linalg.norm(V - V[s], axis=1)
        D = dijkstra(graph, directed=False, indices=s)       # edge paths
        np.testing.assert_allclose(gs._upper_bound(np.array([s]), np.zeros(0, int), np.zeros((0, 3))), D,
                                   rtol=1e-12)
        raw, rep = gs.distance([s], clamp=False)
        assert rep['refined_sources'] == 1                    # 64 nodes: coarse at every source
        below += int((raw < E - 1e-12).sum())
        above += int((raw > D * (1 + 1e-3)).sum())
        d, rep = gs.distance([s])
        assert (d >= E - 1e-12).all()
        assert (d <= D * (1 + 1e-3)).all()
        clamped += rep['clamped']['above_edges']
    assert above > 0 and clamped >= above
    # without the refined seed the same grid undershoots the 3D distance by far
    old = geo.FINE_NODES, geo.FINE_GIVEN_ALL
    try:
        geo.FINE_NODES, geo.FINE_GIVEN_ALL = 0.0, False
        raw, rep = gs.distance([500], clamp=False)
    finally:
        geo.FINE_NODES, geo.FINE_GIVEN_ALL = old
    assert rep['refined_sources'] == 0
    assert int((raw < np.linalg.norm(V - V[500], axis=1) - 1e-12).sum()) > 20


def corridor(h=0.05):
    """A flat 8 x 1 strip with a notch [3.9, 4.1] x [0.4, 1] cut in from the top: (V, F) with the unused
    vertices inside the notch dropped. Exact distances are shortest paths around the notch corners."""
    nx, ny = int(round(8 / h)) + 1, int(round(1 / h)) + 1
    X, Y = np.meshgrid(np.arange(nx) * h, np.arange(ny) * h)
    V = np.c_[X.ravel(), Y.ravel(), np.zeros(nx * ny)]
    idx = np.arange(nx * ny).reshape(ny, nx)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    cx = X[:-1, :-1].ravel() + h / 2
    cy = Y[:-1, :-1].ravel() + h / 2
    keep = ~((cx > 3.9) & (cx < 4.1) & (cy > 0.4))
    F = np.r_[np.c_[a, b, c][keep], np.c_[a, c, d][keep]]
    used, F = np.unique(F, return_inverse=True)
    return V[used], F.reshape(-1, 3)


def corridor_exact(P, s):
    """Shortest paths in the corridor from point s (2,) to points P (k,2), around the notch corners."""
    c1, c2 = np.array([3.9, 0.4]), np.array([4.1, 0.4])

    def visible(a, b):                                        # segment a-b misses the notch interior
        t = np.linspace(0, 1, 801)[:, None, None]
        q = a[None] + t * (b - a)[None]
        inside = (q[..., 0] > 3.9 + 1e-9) & (q[..., 0] < 4.1 - 1e-9) & (q[..., 1] > 0.4 + 1e-9)
        return ~inside.any(0)

    def leg(a, B):                                            # straight legs a -> B (k,2), inf if blocked
        return np.where(visible(np.broadcast_to(a, B.shape), B), np.linalg.norm(B - a, axis=1), np.inf)

    # shortest paths through the corners (the visibility graph s, c1, c2, x)
    s1, s2 = leg(s, c1[None])[0], leg(s, c2[None])[0]
    c12 = np.linalg.norm(c2 - c1)
    to1, to2 = min(s1, s2 + c12), min(s2, s1 + c12)
    return np.minimum(leg(s, P), np.minimum(to1 + leg(c1, P), to2 + leg(c2, P)))


@pytest.fixture(scope='module')
def notch():
    V, F = corridor()
    s = int(np.argmin(np.linalg.norm(V[:, :2] - [1.0, 0.8], axis=1)))
    return V, F, s, corridor_exact(V[:, :2], V[s, :2])


def test_error_falls_with_grid_size_and_the_estimate_is_honest(notch):
    V, F, s, D = notch
    far = np.linalg.norm(V - V[s], axis=1) > 0.05
    means = []
    for g in (512, 1024, 2048, 4096):
        d, rep = geo.geodesic_distance(V, F, [s], uv=V[:, :2], grid=g)
        mean = (np.abs(d - D)[far] / D[far]).mean()
        means.append(mean)
        # the estimate is an honest (conservative) figure for this first-order case
        est = rep['error_estimate']
        assert est / 20 <= mean <= est, (g, mean, est)
    assert means[0] > means[1] > means[2] > means[3], means
    assert means[3] < 0.3 * means[1]
    assert means[2] < 1e-3                                    # the 0.1 % target is reached by 2048


def test_warnings_when_the_grid_is_too_coarse(notch, tmp_path, capsys, monkeypatch):
    V, F, s, D = notch
    d, rep = geo.geodesic_distance(V, F, [s], uv=V[:, :2], grid=128)
    assert rep['error_estimate'] > geo.ERROR_TARGET
    assert rep['warnings'] and 'above the target' in rep['warnings'][0]
    # the automatic grid is chosen for the target: no warning, and the estimate meets it (the grid
    # asked for: 'auto' answers this flat mesh exactly in its plane, test_planar.py)
    gs = geo.GeodesicSolver(V, F, uv=V[:, :2], method='grid')
    d, rep = gs.distance([s])
    assert rep['error_estimate'] <= geo.ERROR_TARGET and not rep['warnings']
    assert max(rep['grid']) > 128
    # a target the capped grid cannot reach: warned, with the cap named (a lower cap keeps this fast)
    monkeypatch.setattr(geo, 'GRID_AUTO_MAX', 320)
    d, rep = geo.geodesic_distance(V, F, [s], uv=V[:, :2], error_target=1e-5, method='grid')
    assert max(rep['grid']) == 320 and 'capped at 320' in rep['warnings'][0]
    # the CLI prints the warnings in its JSON report
    obj = tmp_path / 'c.obj'
    write_obj(str(obj), V, F)
    rc = main(['geodesic', str(obj), '--source', str(s), '--grid', '128', '--boundary', 'free',
               '--out', str(tmp_path / 'd.txt'), '--json'])
    assert rc == 0
    import json
    rep = json.loads(capsys.readouterr().out)
    assert rep['warnings'] and rep['error_estimate'] > geo.ERROR_TARGET


# ------------------------------------------------------------------------------------------------
# several parts and seams
def test_two_parts_are_islands_with_infinite_distance_between():
    V1, F1 = make_surface('bump', 17)
    V2 = V1 + [10.0, 0.0, 0.0]
    V = np.vstack([V1, V2])
    F = np.vstack([F1, F1 + len(V1)])
    s = 100
    d, rep = geo.geodesic_distance(V, F, [s], boundary='area', grid=256)
    assert rep['islands'] == 2 and rep['islands_reached'] == 1
    assert np.isinf(d[len(V1):]).all() and np.isfinite(d[:len(V1)]).all()
    assert any('no source' in w for w in rep['warnings'])
    alone, _ = geo.geodesic_distance(V1, F1, [s], boundary='area', grid=256)
    np.testing.assert_allclose(d[:len(V1)], alone, rtol=2e-3)
    # a source on each part: both finite, each part its own distances
    d2, rep2 = geo.geodesic_distance(V, F, [s, len(V1) + 200], boundary='area', grid=256)
    assert np.isfinite(d2).all() and rep2['islands_reached'] == 2
    assert d2[len(V1) + 200] == pytest.approx(0, abs=1e-12)


def test_seams_cut_the_surface():
    """A seam across the flat square splits it into two islands: no distance crosses it."""
    n = 17
    V, F = make_surface('flat', n)
    grid_id = np.arange(n * n).reshape(n, n)
    col = grid_id[:, 8]                                       # the middle column of vertices
    full = np.c_[col[:-1], col[1:]]
    s = int(grid_id[8, 2])
    d, rep = geo.geodesic_distance(V, F, [s], seams=full, grid=256)
    assert rep['islands'] == 2
    side = V[:, 0] < V[col[0], 0] - 1e-9
    assert np.isfinite(d[side]).all() and np.isinf(d[~side & ~np.isin(np.arange(n * n), col)]).all()
    # the vertices on the seam have a copy on the source's side: finite, Euclidean there
    E = np.linalg.norm(V - V[s], axis=1)
    np.testing.assert_allclose(d[col], E[col], rtol=2e-3)
    # the cut surface's own distances: vertices on the seam are on the boundary of the source's side
    assert rep['clamped']['above_edges'] >= 0 and rep['islands_reached'] == 1


def test_surface_paths_keep_their_graphs_between_queries():
    """A part answered by surface paths builds its Steiner graphs at the first query and keeps them: a
    later query runs on the same graphs (no rebuild) and gives what a fresh search gives, whatever
    came before it (vertex sources, a surface point: the virtual source's links are rewritten)."""
    from core.geodesic import paths
    from core.surfaces import icosphere
    V, F = icosphere(6)
    gs = geo.GeodesicSolver(V, F)
    ch = gs.charts[0]
    assert ch.paths_k and ch.paths_cache == {}
    d0, _ = gs.distance([0])
    (k, pair), = ch.paths_cache['graphs'].items()
    fresh = paths.surface_paths(V, F, [7], k)[0]
    d1, _ = gs.distance([7])
    assert ch.paths_cache['graphs'] == {k: pair}
    # (to round-off: where a path runs along edges the edge-path bound clamps it by an ulp)
    np.testing.assert_allclose(d1[np.isfinite(fresh)], np.maximum(
        fresh, np.linalg.norm(V - V[7], axis=1))[np.isfinite(fresh)], rtol=1e-14, atol=0)
    # a point in triangle 5, then a vertex again: each as a fresh search
    bary = np.array([[0.2, 0.3, 0.5]])
    X = bary @ V[F[5]]
    fp = paths.surface_paths(V, F, None, k, X=X, faces=[5])[0]
    dp, _ = gs.distance(points=(np.array([5]), bary))
    assert ch.paths_cache['graphs'] == {k: pair}
    np.testing.assert_allclose(dp, np.maximum(fp, np.linalg.norm(V - X, axis=1)), rtol=0, atol=1e-12)
    d2, _ = gs.distance([0])
    np.testing.assert_array_equal(d2, d0)


def _ngon_cone(k=32, depth=2.0):
    """Blender's cone: a regular k-gon base of radius 1 cut into a fan from its first vertex (needle
    triangles), and k slanted triangles to an apex at height ``depth``. Returns V (k+1,3), F (2k-2,3)."""
    t = 2 * np.pi * np.arange(k) / k
    V = np.r_[np.c_[np.sin(t), np.cos(t), np.zeros(k)], [[0.0, 0.0, depth]]]
    i = np.arange(k)
    side = np.c_[i, np.full(k, k), (i + 1) % k]
    fan = np.c_[np.zeros(k - 2, int), np.arange(2, k), np.arange(1, k - 1)]
    return V, np.r_[side, fan].astype(np.int64)


def test_flat_convex_patches_are_crossed_straight():
    """An n-gon cut into a fan of needles is one flat convex patch: the paths cross it by straight
    links between the points on its boundary, so the distances between its rim vertices are their
    chords, exactly (before: 0.50 % mean and 3 % max against exact MMP, falling as 1/k). Every link of
    the graph is its segment's length (no link added twice), and Richardson's coarse graph crosses the
    same patches as the fine one, so it is never shorter (with the budget choosing for each graph, the
    coarse one had taken more patches and the extrapolation removed nothing)."""
    from core.geodesic import paths
    from core.geodesic.paths import SurfacePaths, mesh_edges, planar_patches
    V, F = _ngon_cone()
    ue, inv = mesh_edges(F)
    patches = planar_patches(V, F, ue, inv)
    assert len(patches) == 1 and len(patches[0][0]) == 32            # the base, bounded by its rim
    for src in (0, 5):
        d, est, k = paths.surface_paths(V, F, [src], 9)
        rim = np.arange(32) != src
        chord = np.linalg.norm(V[:32] - V[src], axis=1)
        assert np.allclose(d[:32][rim], chord[rim], rtol=1e-12)
        assert abs(d[32] - np.sqrt(5.0)) < 1e-12                      # the apex, along its edge
    sp = SurfacePaths(V, F, 9)
    for g in (sp.fine, sp.coarse):
        G = g.G.tocoo()
        real = (G.row < g.N) & (G.col < g.N)
        r, c = np.argsort(g.rank)[G.row[real]], np.argsort(g.rank)[G.col[real]]
        assert np.allclose(G.data[real], np.linalg.norm(g.P[r] - g.P[c], axis=1), rtol=1e-12)
    assert [p[0].tolist() for p in sp.coarse.patches] == [p[0].tolist() for p in sp.fine.patches]


def test_steiner_graphs_keep_every_link_at_its_own_length():
    """The link matrix is built without scipy's search for repeated entries, which summed a pair linked
    twice into one link of their total length. A graded graph with flat patches (a Boolean part) links
    every pair of points once, both ways alike, by its segment's 3D length. An intrinsic triangulation
    (a noisy scan-like patch) can put one vertex opposite an edge in both triangles of that edge: the
    vertex and the edge's points are then joined through either triangle, by two different segments,
    and both are kept (the sum of the two was one link before)."""
    from core.geodesic import paths
    from core.io.obj import read_obj
    from core.mesh.triangulate import triangulate
    mesh = read_obj(os.path.join(DATA, 'bool_boss.obj'))
    tri, _ = triangulate(mesh.corner_verts, mesh.sizes, mesh.V)
    V, F = mesh.V, mesh.corner_verts[tri]
    sp = paths.SurfacePaths(V, F, 9, graded=True)
    assert sp.fine.patches and sp.fine.own is None                 # patches and graded points are used
    Vs, Fs = scan_patch(1500, 3)
    Vs = Vs + np.c_[np.zeros((len(Vs), 2)), 0.04 * np.random.default_rng(0).normal(size=len(Vs))]
    Fi, L, root, edges = paths.path_triangulation(Vs, Fs, {})
    for g in (sp.fine, sp.coarse, paths.SteinerGraph(Vs, Fi, 5, edges=edges, lengths=L)):
        G = g.G.tocoo()
        real = (G.row < g.N) & (G.col < g.N)
        row, col, w = G.row[real].astype(np.int64), G.col[real].astype(np.int64), G.data[real]
        key, yek = row * g.N + col, col * g.N + row
        order, back = np.lexsort((w, key)), np.lexsort((w, yek))
        assert np.array_equal(key[order], yek[back]) and np.array_equal(w[order], w[back])   # both ways
        pairs, count = np.unique(key, return_counts=True)
        if not g.intrinsic:
            assert count.max() == 1
            pos = np.argsort(g.rank)
            assert np.allclose(w, np.linalg.norm(g.P[pos[row]] - g.P[pos[col]], axis=1), rtol=1e-12)
            continue
        twice = np.isin(key, pairs[count == 2])
        assert count.max() == 2 and twice.sum() > 100
        # two segments of their own (different lengths), each within a triangle: not their sum
        both = w[twice][np.argsort(key[twice], kind='stable')].reshape(-1, 2)
        assert (both[:, 0] != both[:, 1]).all() and both.max() <= L.max()


def test_richardsons_pair_crosses_the_same_patches(monkeypatch):
    """With a patch budget that takes only some of a mesh's flat patches (a cylinder's 64 flat strips
    of 40 triangles each and its two fan caps), the coarse graph takes exactly the fine graph's, and
    its paths are never shorter than the fine ones at the vertices."""
    import core.geodesic.paths as paths
    from core.geodesic.paths import SurfacePaths
    ring, rows = 64, 20
    t = np.linspace(0, 2 * np.pi, ring, endpoint=False)
    V = np.concatenate([np.c_[np.cos(t), np.sin(t), np.full(ring, z)] for z in np.linspace(0, 2, rows + 1)])
    a = (np.arange(rows)[:, None] * ring + np.arange(ring)[None]).ravel()
    b = (np.arange(rows)[:, None] * ring + (np.arange(ring)[None] + 1) % ring).ravel()
    F = np.r_[np.c_[a, b, b + ring], np.c_[a, b + ring, a + ring]]
    bot, top = len(V), len(V) + 1
    V = np.r_[V, [[0, 0, 0], [0, 0, 2]]]
    i = np.arange(ring)
    caps = [np.c_[np.full(ring, bot), (i + 1) % ring, i],
            np.c_[np.full(ring, top), rows * ring + i, rows * ring + (i + 1) % ring]]
    F = np.r_[F, caps[0], caps[1]].astype(np.int64)
    monkeypatch.setattr(paths, 'PATCH_LINKS', 600_000)
    sp = SurfacePaths(V, F, 9)
    assert 0 < len(sp.fine.patches) < 66
    assert [p[0].tolist() for p in sp.coarse.patches] == [p[0].tolist() for p in sp.fine.patches]
    fine = sp.fine.search(np.array([0]))[:len(V)]
    coarse = sp.coarse.search(np.array([0]))[:len(V)]
    assert (coarse >= fine - 1e-12).all()


def test_surface_paths_estimate_is_not_below_the_error_on_a_scan_like_mesh():
    """On a scan-like disk (random points, Delaunay-triangulated and lifted: tests/meshgen.scan_patch)
    Richardson's extrapolation gains only 1.9-2.1x over the plain Steiner paths at k = 9 (3-5x on
    regular meshes). The estimate must not promise more than it gives: against exact MMP
    (geodesic_ref_scan_patch.npz), for three sources, the estimate is at least the measured mean error
    and at most 3x it (with the earlier gain of 2.5 it was 0.77-0.86x of it), and with the 0.1 %
    target the paths meet it (they search the mesh's intrinsic Delaunay triangulation, its triangles
    being thin: ``path_triangulation``)."""
    from core.geodesic import paths
    ref = np.load(os.path.join(DATA, 'geodesic_ref_scan_patch.npz'))
    V, F = ref['V'], ref['F'].astype(np.int64)
    diag = np.linalg.norm(np.ptp(V, axis=0))
    cache = {}
    for s, D in zip(ref['sources'], ref['dist']):
        far = np.linalg.norm(V - V[s], axis=1) > 0.02 * diag
        d, est, k = paths.surface_paths(V, F, [int(s)], 9, cache=cache)
        e = np.abs(d[far] - D[far]) / D[far]
        assert k == 9 and e.mean() <= est <= 3 * e.mean(), (s, est, e.mean())
        d, est, k = paths.surface_paths(V, F, [int(s)], 9, target=1e-3, cache=cache)
        e = np.abs(d[far] - D[far]) / D[far]
        assert k >= 9 and est <= 1e-3 and e.mean() < 1e-3 and e.max() < 0.02, (s, k, est, e.mean(), e.max())
    assert cache['triangulation'] is not None


def test_a_coarse_cad_part_takes_enough_points_per_edge():
    """A bevelled cube (tests/meshgen.bevel_box: each face's middle one flat quad of two triangles,
    588 triangles) is coarse: a path crosses a few edges, and the Steiner paths' excess falls about as
    k^-1.25, not k^-1.85, so the extrapolation and its estimate fall short (at k = 9, 0.12 % mean
    under an estimate of 0.08 %, and no refinement). The points per edge start from a spacing of
    ``PATH_SPACING`` of the median distance (``coarse_k``): against exact MMP
    (geodesic_ref_bevel_box.npz), the mean error is under the 0.1 % target with a margin, the max
    under 2 %."""
    from core.geodesic import paths
    from core.geodesic.solver import geodesic_distance
    ref = np.load(os.path.join(DATA, 'geodesic_ref_bevel_box.npz'))
    V, F = ref['V'], ref['F'].astype(np.int64)
    diag = np.linalg.norm(np.ptp(V, axis=0))
    for s, D in zip(ref['sources'], ref['dist']):
        far = np.linalg.norm(V - V[s], axis=1) > 0.02 * diag
        d, rep = geodesic_distance(V, F, sources=[int(s)])
        e = np.abs(d[far] - D[far]) / D[far]
        assert e.mean() < 0.7e-3 and e.max() < 0.02, (s, e.mean(), e.max())
        k_min = paths.coarse_k(V, F, None, d[far], {})
        assert rep['steiner_points'] > 9 and k_min > 9
    # a fine mesh is not affected: its paths cross many edges
    V2, F2 = make_surface('bump', 33)
    d2, _ = geodesic_distance(V2, F2, sources=[0], method='paths')
    assert paths.coarse_k(V2, F2, None, d2[d2 > 0], {}) <= 5


def test_surface_paths_search_the_intrinsic_delaunay_triangulation_of_slivers():
    """A CAD-like closed part whose triangles are those of a convex hull of random points (slivers over
    most of the area, tests/meshgen.cylinder_hull): the Steiner graphs on its own triangles came out
    87 % off on the mean at k = 9 (the graded points cannot reach corners of 0.001 degrees), with an
    estimate of 2 %. The paths search its intrinsic Delaunay triangulation (edge flips, the same
    surface). On the cylinder's side the exact distance is the unrolled helix's, sqrt((r dtheta)^2 +
    dz^2) (MMP agrees to 0.005 %): mean error under 0.1 %, max under 2 %, the estimate at least
    the mean error; the mesh's own triangles, forced, are several percent off."""
    from core.geodesic import paths
    from meshgen import cylinder_hull
    V, F = cylinder_hull(3000)
    z, th = V[:, 2], np.arctan2(V[:, 1], V[:, 0])
    s = int(np.argmin(np.abs(z) + np.abs(th)))          # a side vertex at z = 0, theta = 0
    exact = np.hypot(0.5 * np.abs((th - th[s] + np.pi) % (2 * np.pi) - np.pi), z - z[s])
    side = (np.abs(z) < 0.6) & (exact > 0.05)
    cache = {}
    d, est, k = paths.surface_paths(V, F, [s], 9, target=1e-3, cache=cache)
    assert cache['triangulation'] is not None
    e = np.abs(d[side] - exact[side]) / exact[side]
    assert e.mean() < 1e-3 and e.max() < 0.02 and est >= e.mean(), (e.mean(), e.max(), est)
    d0, _, _ = paths.surface_paths(V, F, [s], 9, cache={'triangulation': None})
    assert (np.abs(d0[side] - exact[side]) / exact[side]).mean() > 0.01
    # triangles wound the wrong way (a CAD export's zero-area ones are): the same intrinsic paths
    Fw = F.copy()
    Fw[::50] = Fw[::50, ::-1]
    cache = {}
    dw, _, _ = paths.surface_paths(V, Fw, [s], 9, target=1e-3, cache=cache)
    assert cache['triangulation'] is not None and np.allclose(dw, d, rtol=1e-12)


def test_surface_paths_merge_coincident_vertices_before_flipping():
    """A mesher that leaves the same point twice, joined by an edge of zero length and two zero-area
    triangles (marching cubes does, thousands of times): the intrinsic flips around such an edge
    gave a marching-cubes part 0.3-1.4 % mean errors under estimates of 0.1 %. The coincident
    vertices are merged first (``coincident_roots``): on the sliver cylinder with 535 doubled vertices
    the paths stay within the target against the unrolled helix (without the merge 0.17 % mean, and
    refinement stopped at k = 5), and each copy gets its twin's distance."""
    from core.geodesic import paths
    from meshgen import cylinder_hull, with_coincident_vertices
    V0, F0 = cylinder_hull(3000)
    V, F, twin = with_coincident_vertices(V0, F0, 2000)
    assert len(twin) > 500
    from core.mesh.repair import coincident_roots
    root = coincident_roots(V, F)
    assert np.array_equal(root[len(V0):], twin) and np.array_equal(root[:len(V0)], np.arange(len(V0)))
    z, th = V[:, 2], np.arctan2(V[:, 1], V[:, 0])
    s = int(np.argmin(np.abs(z) + np.abs(th)))
    exact = np.hypot(0.5 * np.abs((th - th[s] + np.pi) % (2 * np.pi) - np.pi), z - z[s])
    side = (np.abs(z) < 0.6) & (exact > 0.05)
    cache = {}
    d, est, k = paths.surface_paths(V, F, [s], 9, target=1e-3, cache=cache)
    assert cache['triangulation'] is not None and cache['triangulation'][2] is not None
    e = np.abs(d[side] - exact[side]) / exact[side]
    assert e.mean() < 1e-3 and e.max() < 0.02 and est >= e.mean(), (e.mean(), e.max(), est, k)
    assert np.array_equal(d[len(V0):], d[twin])
    # a source on a copy is its twin
    d2, _, _ = paths.surface_paths(V, F, [len(V0)], 9, cache=cache)
    d1, _, _ = paths.surface_paths(V, F, [int(twin[0])], 9, cache=cache)
    assert np.array_equal(d1, d2)


def test_surface_paths_refine_without_starving_their_needles(monkeypatch):
    """Refining toward the target builds a graph with more points per edge within the same link budget.
    On a scan whose rim stands vertical (needles) a larger ``k`` can leave the needles fewer graded
    points than the first graph gave them, and the answer gets worse (a 10k-triangle one against exact
    MMP: max 1.1 % at k = 11 fully graded, 4.2 % at k = 13 and 15 short of their points). So the
    graphs start at the largest k whose full grading fits (``graded_k``), a fully graded graph is
    refined only as far as that still holds, and a refined answer is kept only if its estimate is not
    above the first one's. The mesh's own triangles, as point sources search them (vertex sources
    search its intrinsic Delaunay triangulation, whose needles are fewer)."""
    from core.geodesic import paths
    from meshgen import steep_rim
    V, F = steep_rim(2000)
    monkeypatch.setattr(paths, 'PATH_BUDGET', 6_000_000)
    monkeypatch.setattr(paths, 'path_triangulation', lambda V, F, cache=None: None)
    cache = {}
    d9, est9, _ = paths.surface_paths(V, F, [0], 9, cache=cache)
    d, est, k = paths.surface_paths(V, F, [0], 9, target=1e-3, cache=cache)
    assert est9 > 1e-3 and k > 9 and est < est9, (est9, k, est)
    assert all(g.short == (0.0, 0) for g in cache['graphs'].values()), \
        {kk: g.short for kk, g in cache['graphs'].items()}
    assert path_links_fit(paths, F, k, cache['graphs'][9].grade_need)
    # a budget that leaves the needles short at k = 9: the graphs are built at the largest k whose
    # full grading fits; asked for k = 9 as given, a refinement never returns a higher estimate
    monkeypatch.setattr(paths, 'PATH_BUDGET', 3_000_000)
    cache = {}
    d, est, k = paths.surface_paths(V, F, [0], 9, cache=cache)
    assert k == paths.graded_k(V, F, 9) < 9 and cache['graphs'][k].short == (0.0, 0), k
    assert path_links_fit(paths, F, k, cache['graphs'][k].grade_need)
    cache = {}
    _, est9, _ = paths.surface_paths(V, F, [0], 9, cache=cache, fit_grading=False)
    assert cache['graphs'][9].short[1] > 0
    _, est, k = paths.surface_paths(V, F, [0], 9, target=1e-3, cache=cache, fit_grading=False)
    assert est <= est9 and cache['short'] == cache['graphs'][k].short


def path_links_fit(paths, F, k, need):
    """Whether the graphs at ``k`` and ``(k - 1) / 2`` with the full grading (``need``) fit the budget."""
    from core.mesh.topology import unique_edges
    ne = len(unique_edges(F)[0])
    base = paths.path_links(len(F), ne, k) + paths.path_links(len(F), ne, (k - 1) // 2)
    return base * (1 + need) <= 0.9 * min(paths.PATH_BUDGET, paths.GRADE_BUDGET)


def test_a_lifted_hemisphere_s_rim_sources_take_graded_refined_seeds():
    """A hemisphere lifted from random points in the plane (tests/meshgen.steep_rim(2000, 1, 0.5, 1)):
    its rim stands vertical, so the triangles there are needles and the map is mildly anisotropic
    (1.13-1.19). Against exact MMP (geodesic_ref_lifted_hemisphere.npz), three rim sources at the
    grid (``method='grid'``; by default such a mesh takes the surface paths, next test): mean below
    0.1 % and max below 2 %, each taking the refined seed. Before, the refined seed's Steiner paths
    were not graded on the needles (0.21 % and 0.15 % mean, 3.4 % and 2.5 % max, a constant offset
    from the source), and a source whose triangles' anisotropy was 1.13-1.15 took the plain seed
    (0.19 % short everywhere)."""
    ref = np.load(os.path.join(DATA, 'geodesic_ref_lifted_hemisphere.npz'))
    V, F = ref['V'], ref['F'].astype(np.int64)
    gs = geo.GeodesicSolver(V, F, method='grid')
    diag = np.linalg.norm(np.ptp(V, axis=0))
    for s, D in zip(ref['sources'], ref['dist']):
        d, rep = gs.distance([int(s)])
        far = np.linalg.norm(V - V[s], axis=1) > 0.02 * diag
        e = np.abs(d[far] - D[far]) / D[far]
        assert rep['refined_sources'] == 1 and e.mean() < 1e-3 and e.max() < 0.02, (s, e.mean(), e.max())



def test_on_a_given_grid_refined_seeds_take_enough_points_for_the_error_to_fall():
    """The lifted hemisphere's three rim sources on grids the user gives (512, then 1024), one at a time
    and together: each takes the refined seed, whose Steiner paths are a floor under the grid's error.
    At ``STEINER`` (15) points per edge they held the mean at 0.055 / 0.043 / 0.033 % at 512 (max 1.09
    %), and one source rose at 1024 (0.043 -> 0.044 %); at ``FINE_STEINER_GIVEN`` (31) 0.018 / 0.019 /
    0.017 %, and every source falls at 1024. Together (exact: the nearest of the three), a window's
    values where another source is nearer in 3D were dropped for the march's: 0.018 -> 0.021 % from 512
    to 1024; bounding the march's from above there, 0.016 -> 0.014 %."""
    ref = np.load(os.path.join(DATA, 'geodesic_ref_lifted_hemisphere.npz'))
    V, F = ref['V'], ref['F'].astype(np.int64)
    diag = np.linalg.norm(np.ptp(V, axis=0))
    sources = [int(s) for s in ref['sources']]
    sets = [([s], D) for s, D in zip(sources, ref['dist'])] + [(sources, ref['dist'].min(0))]
    means = {}
    for grid in (512, 1024):
        gs = geo.GeodesicSolver(V, F, grid=grid)
        for j, (src, D) in enumerate(sets):
            d, rep = gs.distance(src)
            far = np.min(np.linalg.norm(V[:, None] - V[src][None], axis=2), 1) > 0.02 * diag
            e = np.abs(d[far] - D[far]) / D[far]
            assert rep['refined_sources'] == len(src) and e.max() < 0.01, (grid, src, e.max())
            means[grid, j] = e.mean()
    for j in range(len(sets)):
        assert means[512, j] < 2.5e-4 and means[1024, j] < means[512, j], means


def test_a_finer_given_grid_takes_more_steiner_points_over_the_same_window(monkeypatch):
    """On a grid the user gives, the refined seed's Steiner paths (a floor under the grid's error, carried
    outward as an offset) take more points per edge as the grid grows past ``FINE_GIVEN_NODES``, over
    the same window (16 mean edges, at most 3000 triangles). At 31 points a lifted hemisphere's
    curvature source stayed at 0.027 % from 1024 to 4096; with more points 0.014 / 0.0097 % at 2048 /
    4096 (docs/geodesic.md, "Forty-second session"). Automatic grids keep ``STEINER``. The rule's
    effect is checked at 1024 with ``FINE_GIVEN_NODES`` lowered: edgebump's peak with 63 points (as at
    4096) 0.0024 -> 0.0021 % mean (0.0114 % in the former rule's window, whose reach fell as
    ``k^-1/2``: the grid then took over inside the bump, and the peak rose 0.0033 -> 0.0099 % from a
    given 2048 to 4096); the lifted hemisphere's three rim sources with 45 points 0.0159 / 0.0167 /
    0.0146 -> 0.0104 / 0.0105 / 0.0098 % (the test takes the second; 0.0131 / 0.0139 / 0.0131 % in
    the former rule's window)."""
    assert geo.fine_seed_paths(4096, False) == (geo.STEINER, geo.FINE_EDGES, geo.FINE_MAX_FACES)
    base = geo.fine_seed_paths(geo.FINE_GIVEN_NODES, True)
    assert base == (geo.FINE_STEINER_GIVEN, geo.FINE_EDGES, geo.FINE_MAX_FACES)
    assert geo.fine_seed_paths(512, True) == base
    last = base[0]
    for size in (1100, 1536, 2048, 3000, 4096):
        k, edges, faces = geo.fine_seed_paths(size, True)
        assert k % 2 == 1 and k > last and k >= geo.FINE_STEINER_GIVEN * np.sqrt(size / geo.FINE_GIVEN_NODES)
        assert (edges, faces) == base[1:]
        last = k
    V, F = make_surface('edgebump', 65)
    ref = np.load(os.path.join(DATA, 'geodesic_ref_edgebump_65.npz'))
    s, D = int(ref['sources'][3]), ref['dist'][3].astype(np.float64)
    gs = geo.GeodesicSolver(V, F, grid=1024)
    err, plain = {}, geo.FINE_GIVEN_NODES
    for nodes in (plain, 256):
        monkeypatch.setattr(geo, 'FINE_GIVEN_NODES', nodes)
        d, rep = gs.distance([s])
        assert rep['refined_sources'] == 1
        err[nodes] = rel_errors(V, d, D, s)[0]
    assert err[256] < err[plain] and err[256] < 3e-5, err
    V, F, s, D, far = _reference('lifted_hemisphere', 1)
    gs = geo.GeodesicSolver(V, F, grid=1024)
    err = {}
    for nodes in (plain, 512):
        monkeypatch.setattr(geo, 'FINE_GIVEN_NODES', nodes)
        d, rep = gs.distance([s])
        assert rep['refined_sources'] == 1
        err[nodes] = float(np.mean(np.abs(d[far] - D[far]) / D[far]))
    assert err[512] < 0.75 * err[plain] and err[512] < 1.2e-4, err


def test_a_mesh_of_needles_takes_intrinsic_surface_paths_by_default():
    """The same lifted hemisphere at default settings: its needles make the surface paths search the
    intrinsic Delaunay triangulation, and 'auto' answers it by those paths rather than the grid, whose
    re-marches undershoot at the rim beside the needles (a larger one of this kind: 2.2 % max at the
    automatic grid, 3.6 % at 1536; the paths 0.62 %). Against exact MMP: mean below 0.1 %, max below
    1 %, and an estimate at least the mean error."""
    ref = np.load(os.path.join(DATA, 'geodesic_ref_lifted_hemisphere.npz'))
    V, F = ref['V'], ref['F'].astype(np.int64)
    gs = geo.GeodesicSolver(V, F)
    diag = np.linalg.norm(np.ptp(V, axis=0))
    for s, D in zip(ref['sources'], ref['dist']):
        d, rep = gs.distance([int(s)])
        far = np.linalg.norm(V - V[s], axis=1) > 0.02 * diag
        e = np.abs(d[far] - D[far]) / D[far]
        assert rep['paths_islands'] == 1 and gs.charts[0].paths_cache['triangulation'] is not None
        assert e.mean() < 1e-3 and e.max() < 0.01 and rep['error_estimate'] >= e.mean(), \
            (s, e.mean(), e.max(), rep['error_estimate'])
        # no grid is named: the chart's own grid was never marched (the report said 'grid 64x..')
        assert gs.charts[0].size and rep['grid'] == [0, 0] and rep['cell'] is None


def test_steiner_points_trade_accuracy_for_speed_with_an_honest_estimate():
    """``steiner_points`` fixes the points per edge on islands answered by surface paths (no refinement
    toward the target): on the closed cow (tests/data), 3 points err several times more than the
    default, and the estimate says so: at k = 3 the extrapolation gains nothing, so the estimate is
    the plain excess (measured 1.05x the error against paths at k = 15; dividing by the gain of the
    finer graphs said 0.42x). Values that are not an odd 3..31 are refused."""
    from core.io.obj import read_obj
    from core.mesh.triangulate import triangulate
    mesh = read_obj(os.path.join(DATA, 'cow.obj'))
    V, F = mesh.V, mesh.corner_verts[triangulate(mesh.corner_verts, mesh.sizes, mesh.V)[0]]
    ref, rep = geo.GeodesicSolver(V, F, steiner_points=15).distance([0])
    assert rep['paths_islands'] == 1 and rep['steiner_points'] == 15
    far = np.isfinite(ref) & (ref > 0.1 * np.nanmax(ref[np.isfinite(ref)]))
    out = {}
    for k in (3, None):
        d, rep = geo.GeodesicSolver(V, F, steiner_points=k).distance([0])
        err = float(np.mean(np.abs(d[far] - ref[far]) / ref[far]))
        out[k] = (err, rep['error_estimate'], rep['steiner_points'])
    assert out[3][2] == 3 and out[None][2] >= 9
    assert out[3][0] > 3 * out[None][0], out
    assert 0.6 < out[3][1] / out[3][0] < 1.7, out
    for bad in (4, 1, 33, 'many'):
        with pytest.raises(ConformalError, match='steiner_points'):
            geo.GeodesicSolver(V, F, steiner_points=bad)


def test_a_closed_part_is_answered_by_surface_paths():
    """A closed part has no flat chart: without seams it is answered by surface paths on the closed
    surface (here beside an open part, answered by the grid), close to the great circles (the
    polyhedron's own distances are slightly shorter); method='grid' keeps the error that asks for
    seams or sphere mode."""
    from core.surfaces import icosphere
    V, F = icosphere(8)
    Vb, Fb = make_surface('bump', 33)
    W, G = np.vstack([V, Vb + [5.0, 0.0, 0.0]]), np.vstack([F, Fb + len(V)])
    gs = geo.GeodesicSolver(W, G)
    assert gs.report['closed_parts'] == 1 and len(gs.charts) == 2
    d, rep = gs.distance([0, len(V) + 500])
    U = V / np.linalg.norm(V, axis=1)[:, None]
    gc = np.arccos(np.clip(U @ U[0], -1, 1)) * np.linalg.norm(V[0])
    m = gc > 0.1
    e = (d[:len(V)][m] - gc[m]) / gc[m]
    assert rep['paths_islands'] == 1 and rep['islands_reached'] == 2
    assert -0.01 < e.min() and e.max() < 1e-9 and np.abs(e).mean() < 0.005, (e.min(), e.max())
    db, _ = geo.GeodesicSolver(Vb, Fb).distance([500])
    # the open part: unchanged, to round-off (alone, its coordinates are not shifted by 5 and scaled
    # with the sphere's: under numpy 2.4 one value differs by 1.06e-12 relative on this machine)
    np.testing.assert_allclose(d[len(V):], db, rtol=1e-10)
    with pytest.raises(ConformalError) as exc:
        geo.geodesic_distance(V, F, [0], grid=256, method='grid')
    assert exc.value.code == 'no_boundary' and 'sphere' in str(exc.value)


def slit_disk(nr=30, nphi=160, wedge=0.08):
    """A unit disk minus a thin wedge (angle ``wedge``) with its tip at the centre: a slit that tapers
    to nothing, narrower than a grid cell near its tip, where the triangles of both sides share the
    centre vertex. Polar rings, (n,3) and (m,3)."""
    r = np.linspace(0, 1, nr + 1)[1:]
    phi = np.linspace(wedge / 2, 2 * np.pi - wedge / 2, nphi + 1)
    R, P = np.meshgrid(r, phi, indexing='ij')
    V = np.r_[[[0.0, 0.0, 0.0]], np.c_[(R * np.cos(P)).ravel(), (R * np.sin(P)).ravel(), np.zeros(R.size)]]
    idx = 1 + np.arange(R.size).reshape(R.shape)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel()
    F = np.concatenate([np.c_[np.zeros(nphi, int), idx[0, :-1], idx[0, 1:]], np.c_[a, c, d], np.c_[a, d, b]])
    return V, F


def test_the_front_does_not_cross_a_tapering_slit():
    """Across the slit the exact distance runs round its tip (the centre): the straight segment where
    the angle between source and target within the domain is below pi, else through the centre. With
    the gap guard from the boundary (``boundary_bridges``) no vertex is below it (the guard from shared
    triangle corners let the front jump the slit near its tip: 5.7 % below, 0.46 % mean at 1024)."""
    V, F = slit_disk()
    ang = np.mod(np.arctan2(V[:, 1], V[:, 0]), 2 * np.pi)
    rad = np.linalg.norm(V[:, :2], axis=1)
    s = int(np.argmin(np.linalg.norm(V[:, :2] - 0.6 * np.array([np.cos(0.25), np.sin(0.25)]), axis=1)))
    D = np.where(np.abs(ang - ang[s]) < np.pi, np.linalg.norm(V[:, :2] - V[s, :2], axis=1), rad + rad[s])
    far = np.linalg.norm(V - V[s], axis=1) > 0.05
    d, rep = geo.geodesic_distance(V, F, [s], uv=V[:, :2], grid=1024)
    r = (d - D)[far] / D[far]
    assert r.min() > -1e-3, r.min()                    # measured 0.000 %
    assert np.abs(r).mean() < 1.5e-3 and np.abs(r).max() < 1e-2, (np.abs(r).mean(), np.abs(r).max())
    assert not rep['filled_from_edges']


# --- surface paths on small, coarse islands (paths_choice) ------------------------------------------
def test_coarse_island_is_answered_by_surface_paths():
    """Suzanne's face cut along its seams (853 triangles): its automatic grid would be large (its map
    shrinks parts of the face by orders of magnitude) and miss the target (0.8-1.9 % mean with a 2240
    grid), so 'auto' answers it by surface paths: against exact MMP (geodesic_ref_suzanne_island.npz)
    mean within the 0.1 % target (0.02-0.06 % from the 13 points a query starts from; 0.05 % when it
    started from the 31 the chart affords) and max below 1 % for three sources and the three
    together, 0 vertices outside the exact bounds, an error estimate within 4x of the measured mean;
    a point source at a vertex equals that vertex; any vertex and face order gives the same
    distances. Fine meshes keep the grid (bump at n = 65), and so does an explicit grid."""
    ref = np.load(os.path.join(DATA, 'geodesic_ref_suzanne_island.npz'))
    V, F = ref['V'], ref['F'].astype(np.int64)
    src, D = ref['sources'].astype(np.int64), ref['dist']
    gs = geo.GeodesicSolver(V, F)
    assert [ch.paths_k for ch in gs.charts] == [31], [ch.paths_k for ch in gs.charts]
    diag = np.linalg.norm(np.ptp(V, axis=0))
    for ss, Dk in zip([[s] for s in src] + [list(src)], list(D) + [D.min(0)]):
        d, rep = gs.distance(ss)
        far = np.min(np.linalg.norm(V[:, None] - V[ss][None], axis=2), axis=1) > 0.02 * diag
        e = np.abs(d[far] - Dk[far]) / Dk[far]
        assert e.mean() < geo.ERROR_TARGET and e.max() < 0.01, (ss, e.mean(), e.max())
        # the chart could afford 31 points; a query starts from the 13 the default target needs (start_k)
        assert rep['paths_islands'] == 1 and rep['steiner_points'] == 13 and rep['marches'] == 0
        assert rep['warnings'] == [] and e.mean() / 4 < rep['error_estimate'] < 4 * e.mean()
        assert (d >= np.linalg.norm(V - V[ss][:, None], axis=2).min(0) - 1e-12).all()
    # a surface point at vertex src[1]: barycentric 1 at its corner of one of its triangles
    f, c = (int(x[0]) for x in np.nonzero(F == src[1]))
    dp, _ = gs.distance(points=(np.array([f]), np.eye(3)[[c]]))
    dv, _ = gs.distance([int(src[1])])
    assert np.allclose(dp, dv, rtol=1e-12, atol=1e-12)
    # vertex and face order
    rng = np.random.default_rng(5)
    perm = rng.permutation(len(V))
    inv = np.argsort(perm)
    Fp = inv[F][rng.permutation(len(F))]
    d2, _ = geo.GeodesicSolver(V[perm], Fp).distance([int(inv[src[0]])])
    d0, _ = gs.distance([int(src[0])])
    assert np.allclose(d2[inv], d0, rtol=1e-9, atol=1e-12)
    # fine meshes and explicit grids stay on the grid
    Vb, Fb = make_surface('bump', 65)
    assert geo.GeodesicSolver(Vb, Fb).charts[0].paths_k is None
    assert geo.GeodesicSolver(V, F, grid=256).charts[0].paths_k is None
    with pytest.raises(ConformalError, match='method'):
        geo.GeodesicSolver(V, F, method='heat')


def test_paths_replace_a_capped_grid_only_when_clearly_better(monkeypatch):
    """A chart whose automatic grid is held at the cap short of the target goes to the paths at the
    largest k the budget allows when their expected error is under half the grid's estimate (ogre's
    largest island: 0.97 % estimated, 12-51 % measured -> 0.04-0.07 %), and stays on the grid when
    not (the bunny: 0.15-0.23 % estimated against ~0.2 % expected of the paths at k = 5)."""
    from types import SimpleNamespace
    from core.geodesic import paths
    V, F = make_surface('bump', 65)
    monkeypatch.setattr(geo, 'PATH_BUDGET', 2_000_000)              # no k = 9 for 8192 triangles
    monkeypatch.setattr(paths, 'PATH_BUDGET', 2_000_000)
    ch = SimpleNamespace(F=F, nodes=512.0 ** 2, limit='cap', grid_estimate=0.01, excess=0.0,
                         target=geo.ERROR_TARGET, planned_passes=geo.METRIC_PASSES)
    k = geo.path_points(len(F), len(np.unique(np.sort(np.r_[F[:, :2], F[:, 1:], F[:, ::2]], 1), axis=0)))
    assert k is not None and k < 9
    assert geo.paths_choice(ch, 'auto', None, 'metric') == k
    ch.grid_estimate = 0.002
    assert geo.paths_choice(ch, 'auto', None, 'metric') is None
    ch.limit, ch.grid_estimate = None, 0.01
    assert geo.paths_choice(ch, 'auto', None, 'metric') is None
    # a map far from conformal per triangle goes to the paths too, unless a grid is asked for
    ch.excess = 0.6 * geo.ERROR_TARGET / geo.ERR_ANISO
    assert geo.paths_choice(ch, 'auto', None, 'metric') == k
    assert geo.paths_choice(ch, 'auto', 512, 'metric') is None


def test_a_map_far_from_conformal_goes_to_the_paths_with_an_honest_estimate(bump65):
    """A given ``uv`` far from conformal on its triangles (bump's area map stretched 1.2x along u and
    shrunk along v: metric anisotropy 1.44 everywhere) is a metric the grid's directional-speed
    re-marches follow only in part: 0.091 / 0.092 % mean at grids 512 / 1024 (0.126 / 0.183 %, growing
    with the grid, before the directions were fitted per triangle) where the conformal map gives
    0.005 %. With a forced grid the metric term puts the estimate above the target with a warning
    that names the map; the automatic choice answers the chart by surface paths (which do not use the
    map), within the target. The conformal map itself stays on the grid."""
    V, F, uv, src, D = bump65
    s, Dk = int(src[1]), D[1]
    suv = uv * np.array([1.2, 1 / 1.2])
    d, rep = geo.geodesic_distance(V, F, [s], uv=suv, grid=512)
    mean, _ = rel_errors(V, d, Dk, s)
    assert mean > 0.5 * geo.ERROR_TARGET and rep['error_estimate'] > max(geo.ERROR_TARGET, mean)
    assert rep['warnings'] and 'far from conformal' in rep['warnings'][0]
    gs = geo.GeodesicSolver(V, F, uv=suv)
    assert gs.charts[0].excess == pytest.approx(1.2 ** 2 - 1, rel=1e-3)
    assert gs.charts[0].paths_k == 9
    d, rep = gs.distance([s])
    mean, mx = rel_errors(V, d, Dk, s)
    assert mean < geo.ERROR_TARGET and mx < 0.02 and not rep['warnings'], (mean, mx, rep['warnings'])
    assert rep['paths_islands'] == 1 and mean / 4 < rep['error_estimate'] < 4 * mean
    gs = geo.GeodesicSolver(V, F, uv=uv)
    assert gs.charts[0].paths_k is None and gs.charts[0].excess < 0.01


def test_surface_paths_grade_the_points_on_fans_of_thin_triangles():
    """A CAD cylinder's caps are fans of 7.5-degree triangles: shortest graph paths across a cap went
    through its centre (the points on the spokes were about three times the fan's width apart), 0.56 %
    mean and 1.94 % max on the bottom rim from a rim vertex, where the exact distance is the chord.
    The spokes now carry twice the points (``edge_grading``): every other edge keeps ``k``, and on a
    mesh without narrow corners (bump) every edge does; the grading stays within the extra links it is
    given."""
    from core.geodesic import paths
    from meshgen import capped_cylinder
    V, F = capped_cylinder()
    ue, inv = paths.mesh_edges(F)
    g = paths.edge_grading(V, F, ue, inv)
    centre = np.isin(ue, [len(V) - 2, len(V) - 1]).any(1)
    assert (g[centre] == 2).all() and (g[~centre] == 1).all()
    d, rep = geo.GeodesicSolver(V, F).distance([0])
    assert rep['paths_islands'] == 1
    rim = np.arange(1, 48)
    chord = np.linalg.norm(V[rim] - V[0], axis=1)                # exact: the cap is flat and convex
    e = (d[rim] - chord) / chord
    assert e.mean() < 2.5e-3 and np.abs(e).max() < 0.012, (e.mean(), np.abs(e).max())
    assert d[len(V) - 2] == pytest.approx(1.0, rel=1e-9)
    Vb, Fb = make_surface('bump', 33)
    assert (paths.edge_grading(Vb, Fb, *paths.mesh_edges(Fb)) == 1).all()
    # the cylinder's spokes add 0.128 to the links (five extra pairs per fan triangle over three per
    # triangle): with less allowed, no edge is graded
    mm = g[inv]
    extra = (mm[:, 0] * mm[:, 1] + mm[:, 1] * mm[:, 2] + mm[:, 0] * mm[:, 2] - 3).sum() / (3 * len(F))
    assert extra == pytest.approx(96 * 5 / (3 * len(F))) and extra <= paths.GRADE_EXTRA
    assert (paths.edge_grading(V, F, ue, inv, extra_max=0.1) == 1).all()


def test_surface_paths_on_sliver_triangles_bound_the_worst_vertex():
    """A thin closed box (2 x 1 x 0.3; its sides' triangles are 1:7 slivers) answered by surface paths
    from a corner: on the bottom face the exact distance is the shorter of the two unfoldings of the
    corner's side faces. k = 9 met the mean target with one vertex 2.4 % off; the worst-excess rule
    (``PATH_WORST``) refines it."""
    from meshgen import box
    V, F = box(10)
    s = int(np.argmax(V.sum(1)))                                     # the corner (2, 1, 0.3)
    assert np.allclose(V[s], [2.0, 1.0, 0.3])
    d, rep = geo.GeodesicSolver(V, F).distance(sources=[s])
    assert rep['paths_islands'] == 1
    bottom = np.flatnonzero(np.abs(V[:, 2]) < 1e-12)
    X = V[bottom, :2]
    exact = np.minimum(np.linalg.norm(X - [2.3, 1.0], axis=1), np.linalg.norm(X - [2.0, 1.3], axis=1))
    err = np.abs(d[bottom] - exact) / exact
    assert err.mean() < 1e-3 and err.max() < 0.01


def test_holes_are_not_walls():
    """An island with holes is flattened with its holes filled virtually, never cut open (``unwrap``'s
    'auto' cuts bump's two holes to the outer boundary for a better map): a cut would be a wall, with
    distances behind it above the edge paths of the uncut mesh. Every vertex lies between the 3D
    distance and the uncut mesh's edge-path distance (+0.1 %)."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import dijkstra
    from meshgen import two_holes
    V, F = two_holes('bump', 17)
    E = np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]
    w = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1)
    G = sp.coo_matrix((np.r_[w, w], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])),
                      shape=(len(V), len(V))).tocsr()
    S = geo.GeodesicSolver(V, F)
    for s in (0, len(V) // 2, len(V) - 1):
        d, rep = S.distance(sources=[s])
        upper = dijkstra(G, indices=s)
        euclid = np.linalg.norm(V - V[s], axis=1)
        assert np.all(d <= upper * (1 + 1e-3) + 1e-12)
        assert np.all(d >= euclid * (1 - 1e-9))




def _ramp(nr, nt, turns=1.5, rise=0.3):
    """A helical ramp: the annulus 1 <= r <= 2 swept over ``turns`` turns, rising ``rise`` per radian
    (``nr`` x ``nt`` vertices). Its flat map winds past a full turn and overlaps itself."""
    r, t = np.linspace(1.0, 2.0, nr), np.linspace(0.0, 2 * np.pi * turns, nt)
    R, T = np.meshgrid(r, t, indexing='ij')
    V = np.stack([R * np.cos(T), R * np.sin(T), rise * T], -1).reshape(-1, 3)
    idx = np.arange(len(V)).reshape(nr, nt)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    return V, np.r_[np.stack([a, b, c], 1), np.stack([a, c, d], 1)], idx


def test_an_overlapping_chart_is_answered_by_surface_paths():
    """A helical ramp of 1.5 turns is a disk whose flat map overlaps itself: a grid over it let the
    front jump between the layers (10-39 % mean, down to -72 %, on a 34k-triangle ramp). The part is
    answered by surface paths on the mesh instead; they agree with finer extrapolated paths."""
    from core.geodesic.paths import steiner_distances
    V, F, idx = _ramp(10, 150)
    S = geo.GeodesicSolver(V, F)
    assert S.report['cut_parts'] == 1
    s = int(idx[4, 0])
    d, rep = S.distance(sources=[s])
    assert rep['paths_islands'] == 1 and not rep['warnings']
    ref, _, _, _ = steiner_distances(V, F, src=s, k=21, extrapolate=True)
    far = ref > 0.1
    err = np.abs(d[far] - ref[far]) / ref[far]
    assert err.mean() < 1e-3 and err.max() < 0.01
    # the layer above the source is reached along the ramp (about 2 pi r), not through the gap
    assert d[idx[4, 100]] > 5.0
    # method='grid' keeps the chart and says it folds
    _, rep_g = geo.GeodesicSolver(V, F, method='grid').distance(sources=[s])
    assert any('overlaps itself' in w for w in rep_g['warnings'])


def test_a_seamed_surface_whose_map_overlaps_is_answered_on_the_cut_surface():
    """Seams and an overlapping map together: the helical ramp with a slit (a seam across half its
    width) still winds past a full turn, so the flattening splits it into more islands than the
    seams make. Those islands were walls (the far side of the split unreached: 740 infinite
    distances). The piece is glued back along every edge that is not a seam and answered by surface
    paths on the cut surface: finite everywhere, the slit crossed only around its end, and within
    0.1 % of finer paths on the cut mesh."""
    from core.atlas.cut import cut_along_seams
    from core.geodesic.paths import steiner_distances
    V, F, idx = _ramp(10, 150)
    slit = idx[:5, 75]
    seams = np.c_[slit[:-1], slit[1:]]
    S = geo.GeodesicSolver(V, F, seams=seams)
    assert S.report['cut_parts'] == 1 and len(S.charts) == 1
    s = int(idx[4, 0])
    d, rep = S.distance(sources=[s])
    assert np.isfinite(d).all() and rep['paths_islands'] == 1 and not rep['warnings']
    c = cut_along_seams(F, len(V), seams)
    ref_c, _, _, _ = steiner_distances(V[c.vert_of], c.F, src=int(np.flatnonzero(c.vert_of == s)[0]),
                                       k=21, extrapolate=True)
    ref = np.full(len(V), np.inf)
    np.minimum.at(ref, c.vert_of, ref_c)
    far = ref > 0.1
    err = np.abs(d[far] - ref[far]) / ref[far]
    assert err.mean() < 1e-3 and err.max() < 0.01
    # across the slit near its closed end: around it, much longer than the straight step across
    a, b = idx[0, 74], idx[0, 76]
    assert abs(d[b] - d[a]) > 0.5 * np.linalg.norm(V[a] - V[b]) + 0.5
    # a slit in a map that does not overlap keeps its grid chart (a bump's grid, a slit across its middle)
    from core import make_surface
    V2, F2 = make_surface('bump', 17)
    slit2 = np.arange(len(V2)).reshape(17, 17)[8, 4:13]
    S2 = geo.GeodesicSolver(V2, F2, seams=np.c_[slit2[:-1], slit2[1:]])
    assert S2.report['cut_parts'] == 0 and isinstance(S2.charts[0], geo.Chart)


def test_seams_on_one_part_leave_a_closed_part_to_the_surface_paths():
    """A closed part that no seam touches is answered by surface paths on the closed surface, seams or
    not: a mesh of a sphere (no seam) and a bump with a seam used to stop with the flattening's
    'island 1 of 2 is closed' (its remedy about cones). Distances on the sphere follow its great
    circles; between the parts they are infinite."""
    from core import make_surface
    from core.surfaces import icosphere
    V1, F1 = icosphere(8)
    V2, F2 = make_surface('bump', 17)
    V = np.vstack([V1 + [5.0, 0, 0], V2])
    F = np.vstack([F1, F2 + len(V1)])
    row = np.arange(289).reshape(17, 17)[8, 3:12] + len(V1)
    S = geo.GeodesicSolver(V, F, seams=np.c_[row[:-1], row[1:]])
    assert S.report['closed_parts'] == 1
    assert sorted(type(c).__name__ for c in S.charts) == ['Chart', 'PathsChart']
    d, rep = S.distance(sources=[5])
    ang = np.arccos(np.clip(V1 @ V1[5], -1, 1))
    far = ang > 0.2
    ratio = d[:len(V1)][far] / ang[far]               # the inscribed polyhedron: 0.4 % short at most
    assert 0.99 < ratio.min() and ratio.max() < 1.0
    assert np.isinf(d[len(V1):]).all()


def test_reversed_faces_do_not_matter():
    """A scan with a few faces wound the wrong way (ten reversed at random) gives the distances of the
    clean mesh: the solver turns them as the repair does (it used to stop with 'flipped triangles').
    A point source in a reversed face, with its barycentric coordinates in that face's own corner
    order, is the same surface point."""
    from core import make_surface
    V, F = make_surface('bump', 33)
    G = F.copy()
    k = np.random.default_rng(1).choice(len(F), 10, replace=False)
    G[k] = G[k][:, ::-1]
    f = int(k[0])
    b = np.array([0.2, 0.3, 0.5])
    d_clean, _ = geo.GeodesicSolver(V, F).distance(sources=[5], points=(np.array([f]), b[None]))
    d_rev, rep = geo.GeodesicSolver(V, G).distance(sources=[5], points=(np.array([f]), b[None, ::-1]))
    assert not rep['warnings']
    assert np.allclose(d_rev, d_clean, rtol=1e-9, atol=1e-12)


def test_a_source_the_grid_cannot_seed_is_answered_by_surface_paths():
    """The cow's head (tests/meshgen.cow_head, ~2k triangles; its map shrinks the horns and the ears
    by orders of magnitude) at a forced grid of 512: at vertex 561 (a horn tip) the cells are so coarse
    that no grid node lies inside the source's exact seed, and at vertex 864 (the middle of the head)
    the refined seed's window holds every node of the chart. Both used to raise (a ConformalError and
    scikit-fmm's ValueError). Now the first island is answered by surface paths, the same distances as
    method='paths', with a warning, and the second needs no march: its seed is the answer, within
    0.5 % of the paths on average."""
    from meshgen import cow_head
    V, F = cow_head()
    gs = geo.GeodesicSolver(V, F, grid=512, refine=False)           # the head's own triangles
    paths = geo.GeodesicSolver(V, F, method='paths')
    d, rep = gs.distance([561])
    dp, _ = paths.distance([561])
    assert rep['paths_fallback'] == 1 and rep['marches'] == 0, rep
    assert any('does not resolve' in w for w in rep['warnings']), rep['warnings']
    assert np.array_equal(d, dp)
    d, rep = gs.distance([864])
    dp, _ = paths.distance([864])
    assert rep['paths_fallback'] == 0 and rep['refined_sources'] == 1 and rep['marches'] == 0, rep
    far = dp > 0.05 * np.linalg.norm(np.ptp(V, axis=0))
    assert np.isfinite(d).all() and np.mean(np.abs(d[far] - dp[far]) / dp[far]) < 5e-3


def test_thin_triangles_left_short_of_their_points_are_warned_about(monkeypatch):
    """A closed 2 x 1 x 0.05 box (12 x 12 cells a face: 1:40 slivers on its sides) answered by surface
    paths: with the budget's room its slivers get their graded points and no warning; with a budget
    that leaves only ``GRADE_EXTRA`` they cannot (all at one angle, the grading is all or nothing),
    the paths' estimate no longer holds there (the 19200-triangle box: 0.25-0.37 % mean, 24 % max,
    against an estimate of 0.07 %), and the report says so, in sphere mode too."""
    from core.geodesic import paths
    from core.sphere.geodesic import sphere_geodesic
    from meshgen import box
    V, F = box(12, (2.0, 1.0, 0.05))
    d, rep = geo.GeodesicSolver(V, F).distance([0])
    assert rep['paths_islands'] == 1 and not any('thin triangles' in w for w in rep['warnings'])
    monkeypatch.setattr(paths, 'PATH_BUDGET', 600_000)
    d, rep = geo.GeodesicSolver(V, F).distance([0])
    thin = [w for w in rep['warnings'] if 'thin triangles' in w]
    assert len(thin) == 1 and 'remesh' in thin[0], rep['warnings']
    d, rep = sphere_geodesic(V, F, [0])
    assert any('thin triangles' in w for w in rep['warnings']), rep['warnings']



def test_paths_held_by_the_memory_budget_do_not_advise_a_finer_mesh(monkeypatch):
    """Closed icospheres answered by surface paths under a link budget of 300k and a 0.02 % target: the
    budget holds the 1280-triangle sphere at 7 Steiner points per edge and its 4x subdivision at 3
    (measured against exact MMP: 0.047 % and 0.23 % mean), so the warning names the points and the
    triangles and advises fewer triangles or a looser target, not the subdivision it used to advise;
    with the points given (``steiner_points``) it says they were asked for, and where the budget had
    room for more points it blames no budget."""
    from core.geodesic import paths
    from meshgen import icosphere
    monkeypatch.setattr(paths, 'PATH_BUDGET', 300_000)
    got = {}
    for level in (3, 4):
        V, F = icosphere(level)
        d, rep = geo.GeodesicSolver(V, F, error_target=2e-4).distance(0)
        got[level] = rep
        [w] = rep['warnings']
        k = rep['steiner_points']
        assert f"at {k} Steiner points per edge, the most the memory budget allows on {len(F):,} " \
               "triangles" in w and 'fewer triangles' in w and 'subdivide' not in w, w
    assert got[4]['steiner_points'] < got[3]['steiner_points']
    assert got[4]['error_estimate'] > 2 * got[3]['error_estimate']
    V, F = icosphere(3)
    d, rep = geo.GeodesicSolver(V, F, error_target=2e-4, steiner_points=5).distance(0)
    [w] = rep['warnings']
    assert 'at 5 Steiner points per edge, as asked' in w and 'budget' not in w, w
    # with the budget's room, a target beyond what the most points reach: no budget is blamed
    monkeypatch.undo()
    d, rep = geo.GeodesicSolver(V, F, error_target=1e-5).distance(0)
    [w] = rep['warnings']
    assert 'budget' not in w and 'raise the error target' in w and 'fewer triangles' not in w, w

def test_intrinsic_paths_keep_two_edges_between_the_same_vertices_apart():
    """Flips to the intrinsic Delaunay triangulation can join two vertices by two different edges (on a
    noisy scan-like patch: 59 such pairs in 3k triangles). Taken as one edge (by their vertex pair)
    their Steiner points were shared, a shortcut between two places of the surface, and the plain
    Steiner paths (upper bounds of the geodesic distance) fell up to 6 % below the extrinsic mesh's paths
    at k = 25 (themselves within a fraction of a percent of the geodesic); kept apart, at most 0.3 %."""
    from core.geodesic import paths
    V, F = scan_patch(1500, 3)
    V = V + np.c_[np.zeros((len(V), 2)), 0.04 * np.random.default_rng(0).normal(size=len(V))]
    Fi, L, root, edges = paths.path_triangulation(V, F, {})
    pairs = np.unique(np.sort(np.concatenate([Fi[:, [0, 1]], Fi[:, [1, 2]], Fi[:, [2, 0]]]), 1), axis=0)
    assert len(edges[0]) > len(pairs) + 20                    # there are doubled pairs to keep apart
    fine = paths.SteinerGraph(V, F, 25)
    graph = paths.SteinerGraph(V, Fi, 9, edges=edges, lengths=L)
    for s in (0, 400, 1200):
        ref = fine.search(np.array([s]))[:len(V)]
        d = graph.search(np.array([s]))[:len(V)]
        far = ref > 0
        assert (d[far] / ref[far]).min() > 0.99, s


def test_a_bent_strip_is_measured_as_its_flat_unfolding():
    """An island with no interior vertex (a hair card, a strip) is intrinsically flat: folded along
    its rungs it keeps its distances. The solver answers it in its unfolding, exactly (it went
    through a chart of its own: 8 ms an island, 1000 cards in 7.9 s). An L-shaped strip one quad
    wide, bent at two rungs, against the same strip flat (answered in its plane)."""
    cells = [(i, 0) for i in range(6)] + [(5, j) for j in range(1, 6)]          # an L of 11 unit quads
    idx = {}

    def vid(x, y):
        return idx.setdefault((x, y), len(idx))
    Q = [(vid(x, y), vid(x + 1, y), vid(x + 1, y + 1), vid(x, y + 1)) for x, y in cells]
    V = np.array([[x, y, 0.0] for (x, y) in idx], float)
    F = np.array([t for a, b, c, d in Q for t in ((a, b, c), (a, c, d))])

    def fold(P, axis_point, axis_dir, side, angle):
        k = np.asarray(axis_dir, float) / np.linalg.norm(axis_dir)
        X = P[side] - axis_point
        c, s = np.cos(angle), np.sin(angle)
        P = P.copy()
        P[side] = axis_point + X * c + np.cross(k, X) * s + np.outer(X @ k, k) * (1 - c)
        return P
    Vb = fold(V, np.array([3.0, 0, 0]), [0, 1, 0], V[:, 0] > 3 + 1e-9, 1.0)      # at the rung x = 3
    Vb = fold(Vb, Vb[vid(5, 3)], Vb[vid(6, 3)] - Vb[vid(5, 3)], V[:, 1] > 3 + 1e-9, -0.7)   # and y = 3
    assert abs(np.ptp(Vb[:, 2])) > 0.5                                            # really bent
    src = vid(0, 1)
    flat, _ = geo.geodesic_distance(V, F, sources=[src])
    bent, rep = geo.geodesic_distance(Vb, F, sources=[src])
    assert rep['planar_islands'] == 1
    np.testing.assert_allclose(bent, flat, rtol=1e-9, atol=1e-12)
    # round the reflex corner (5, 1) of the L: the exact distance bends there
    far = vid(5, 6)
    assert flat[far] == pytest.approx(np.hypot(5, 0) + 5.0, rel=1e-12)


def test_a_march_that_cannot_start_falls_back_to_surface_paths():
    """An island of near-degenerate triangles (three vertices within 1e-9 of each other, found by
    fuzzing) gave scikit-fmm no seed rim: its ValueError ('no zero contour') escaped the solver. The
    march that could not start was answered by surface paths, with a warning. Since the metric of
    such triangles is finite (``test_collinear_corners_get_a_finite_metric``) the automatic choice
    sends the island to surface paths at once: the same distances, without the grid's warning."""
    V = np.array([[-7.7720042914370668e-01, 2.6687345024835568e-01, -2.1281758924154354e-01],
                  [-2.4442981881712935e+00, -4.5485312025100172e-01, -1.7667718398053194e+00],
                  [-2.4442981877990260e+00, -4.5485311939001799e-01, -1.7667718394458671e+00],
                  [-2.4442981870308875e+00, -4.5485311905791243e-01, -1.7667718419611029e+00],
                  [-2.4448021905018256e+00, -4.5563195542332624e-01, -1.7692954914109231e+00],
                  [2.1983321006024386e-09, -5.5312999835435946e-10, -1.8321410456544528e-10],
                  [2.1983321006024386e-09, -5.5312999835435946e-10, -1.8321410456544528e-10],
                  [3.3428796198671435e-09, -1.7983656496588198e-09, 1.7184044461327565e-09],
                  [4.2849983202474337e-09, -8.2334653650376310e-10, 5.5498238495626909e-10],
                  [2.8914268663899800e-01, 9.9644164062048979e-01, -1.5734762519637444e-01]])
    F = np.array([[0, 1, 2], [2, 1, 3], [2, 3, 4], [5, 6, 7], [7, 6, 8], [7, 8, 9]])
    with warnings.catch_warnings():
        warnings.simplefilter('error', RuntimeWarning)
        d, rep = geo.geodesic_distance(V, F, sources=[0])
    assert rep['paths_islands'] == 1 and rep['marches'] == 0
    assert not any('grid' in w for w in rep['warnings'])
    E = np.linalg.norm(V[:5] - V[0], axis=1)
    assert np.isfinite(d[:5]).all() and (d[:5] >= E - 1e-12).all() and (d[:5] <= 1.01 * E + 1e-12).all()


def test_collinear_corners_get_a_finite_metric():
    """A Boolean leaves triangles whose corners are in a line (tests/data/bool_bracket.obj).
    ``face_metric_inverse`` divided by ``g11 g22 - g12^2``, which is 0 or negative there after
    rounding: inf and NaN in the metric and RuntimeWarnings on the console. Now the determinant is
    ``|e1 x e2|^2`` with a floor, and the bracket's distances are within the target of exact MMP's
    (tested against pygeodesic: 0.003-0.013 % mean) with no warning of any kind."""
    from core.geodesic.solver import face_metric_inverse
    from core.io.obj import read_obj
    from core.mesh.triangulate import triangulate
    V = np.array([[0, 0, 0], [1, 0, 0], [0.5, 0, 0], [0.3, 1e-17, 0]], float)
    F = np.array([[0, 1, 2], [0, 1, 3]])
    with warnings.catch_warnings():
        warnings.simplefilter('error')
        g = face_metric_inverse(V, F, np.array([[0, 0], [1, 0], [0.5, 0.1], [0.3, 0.2]]))
        assert np.isfinite(g).all() and (g[:, 0] + g[:, 2] > 0).all()
        mesh = read_obj(os.path.join(os.path.dirname(__file__), 'data', 'bool_bracket.obj'))
        tc, _ = triangulate(mesh.corner_verts, mesh.sizes, mesh.V)
        Fb = mesh.corner_verts[tc]
        d, rep = geo.GeodesicSolver(mesh.V, Fb).distance([15])
    assert np.isfinite(d).all() and not rep['warnings']
    from core.mesh.geometry import edge_graph
    from scipy.sparse.csgraph import dijkstra
    upper = dijkstra(edge_graph(mesh.V, Fb), indices=15)
    assert np.all(d >= np.linalg.norm(mesh.V - mesh.V[15], axis=1) * (1 - 1e-12))
    assert np.all(d <= upper * (1 + 1e-3))


def test_default_weighs_the_paths_at_the_points_a_query_starts_from():
    """At the default target 'auto' weighs the surface paths against the grid at the points a query
    starts from (``start_k``: 13 and Richardson's 6), at ``PATH_COST_LOOSE`` links a node update of
    the march: a chart whose k = 9 pair is over ``PATH_COST`` links a node update but whose 13-point
    pair is within the looser ratio takes the paths at 13 (cheburashka's head cut: 17x heat's one shot
    on its 1216 grid, 6.1x by the paths); one whose 13-point pair is not keeps the grid."""
    from types import SimpleNamespace
    V, F = make_surface('bump', 33)                     # 2048 triangles: 13-point pair 1.44M links

    def chart(nodes):
        return SimpleNamespace(V=V, F=np.asarray(F), target=geo.ERROR_TARGET, nodes=nodes, planned_passes=1,
                               excess=0.0, limit=None, grid_estimate=None, paths_cache={})
    assert geo.paths_choice(chart(150_000.0), 'auto', None, 'metric') == 13    # 1.8M allowed
    assert geo.paths_choice(chart(100_000.0), 'auto', None, 'metric') is None  # 1.2M allowed: the grid
    assert geo.paths_choice(chart(200_000.0), 'auto', None, 'metric') == 9     # k = 9 within PATH_COST
    assert geo.paths_choice(chart(150_000.0), 'grid', None, 'metric') is None


def test_a_looser_error_target_takes_fewer_steiner_points(bump65):
    """``error_target`` trades accuracy for time downward too: the surface paths start from the fewest
    points whose expected error meets it (``target_k``: 9 at the default 0.1 %, 5 at 0.5 %, 3 at 1 %;
    the guards on the worst vertex and on coarse meshes loosen with it). Against exact MMP, a
    scan-like disk answered by paths (geodesic_ref_scan_patch.npz) stays within each target and its
    estimate, with no warning, and the default starts from more points (``start_k``: 13). A smooth
    surface the grid answers at the default (bump, geodesic_ref_bump_65.npz) is answered at 1 % by the
    paths, which are then about as fast (``PATH_COST_LOOSE``), within the target."""
    from core.geodesic.paths import start_k, target_k
    assert [target_k(t) for t in (1e-4, 1e-3, 1.3e-3, 1.5e-3, 3e-3, 5e-3, 7e-3, 1e-2, 0.05)] == \
        [9, 9, 9, 7, 5, 5, 3, 3, 3]
    # a query starts from these at looser targets, and at the default and tighter ones from the points
    # whose expected error is within 0.4 of the target (up to the 31 a chart may take)
    assert [start_k(t) for t in (1e-5, 1e-4, 5e-4, 1e-3, 1.3e-3, 1.5e-3, 5e-3, 1e-2)] == \
        [31, 31, 19, 13, 11, 7, 5, 3]
    ref = np.load(os.path.join(DATA, 'geodesic_ref_scan_patch.npz'))
    V, F = ref['V'], ref['F'].astype(np.int64)
    diag = np.linalg.norm(np.ptp(V, axis=0))
    for target, k in ((geo.ERROR_TARGET, None), (5e-3, 5), (1e-2, 3)):
        gs = geo.GeodesicSolver(V, F, error_target=target)
        for s, D in zip(ref['sources'], ref['dist']):
            d, rep = gs.distance([int(s)])
            e = np.abs(d - D)[D > 0.02 * diag] / D[D > 0.02 * diag]
            assert rep['paths_islands'] == 1 and not rep['warnings'], (target, rep['warnings'])
            assert rep['steiner_points'] == (13 if k is None else k)
            assert e.mean() <= target and rep['error_estimate'] <= target, (target, s, e.mean())
            assert e.max() < 0.05
    V, F, _, sources, dist = bump65
    for target, paths in ((geo.ERROR_TARGET, 0), (1e-2, 1)):
        gs = geo.GeodesicSolver(V, F, boundary='area', error_target=target)
        for s, D in zip(sources[:2], dist[:2]):
            d, rep = gs.distance([int(s)])
            mean, mx = rel_errors(V, d, D, s)
            assert rep['paths_islands'] == paths and not rep['warnings'], (target, rep['warnings'])
            assert mean <= (target / 10 if not paths else target) and mx < 0.05, (target, s, mean, mx)
            assert rep['steiner_points'] == (3 if paths else None)
