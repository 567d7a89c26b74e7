"""``core.unwrap``, the single entry for UV work: it agrees with the disk primitive ``flatten``, handles
selections in the input's numbering, reports warnings on poor results only, and does not depend on
the order of the faces. The CLI's ``--json`` carries the warnings."""
import json

import numpy as np
import pytest

from core import ConformalError, UnwrapResult, __version__, flatten, make_surface, unwrap
from core.atlas.unwrap import true_scale
from core.mesh import topology
from core.mesh.geometry import face_areas
from core.mesh.measures import signed_uv_areas, uv_measures, vertex_mu


def rigid_residual(A, B):
    """Largest distance between point sets A and B (k,2) after the best rotation and translation of B
    onto A (no reflection)."""
    A0, B0 = A - A.mean(0), B - B.mean(0)
    U, _, Wt = np.linalg.svd(B0.T @ A0)
    R = U @ Wt
    assert np.linalg.det(R) > 0                     # a reflection would be a flipped map
    return float(np.abs(B0 @ R - A0).max())


def soup_areas(W):
    """Signed areas (k,) of UV triangles W (k,3,2)."""
    k = len(W)
    return signed_uv_areas(W.reshape(-1, 2), np.arange(3 * k).reshape(k, 3))


@pytest.fixture(scope='module')
def bump():
    return make_surface('bump', 13)


def two_squares():
    """Two loose flat grids, 1 x 1 and 2 x 2 (3D areas 1 and 4), one mesh."""
    n = 5
    t = np.linspace(0, 1, n)
    X, Y = np.meshgrid(t, t)
    P = np.stack([X.ravel(), Y.ravel(), 0.1 * X.ravel() * Y.ravel()], 1)
    q = [(i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j) for i in range(n - 1)
         for j in range(n - 1)]
    F = np.array([t for a, b, c, d in q for t in ((a, b, c), (a, c, d))])
    return np.vstack([P, 2 * P + [3, 0, 0]]), np.vstack([F, F + n * n])


@pytest.mark.parametrize('boundary', ['area', 'free', 'uniform'])
def test_disk_equals_flatten(bump, boundary):
    """A disk without seams: exactly the disk primitive's map and report numbers, in both fits."""
    V, F = bump
    ref = flatten(V, F, boundary=boundary, fit='unit_square')
    res = unwrap(V, F, boundary=boundary)
    assert isinstance(res, UnwrapResult) and res.report['path'] == 'disk'
    np.testing.assert_allclose(res.uv_corner, ref.uv[F], atol=1e-12)
    assert res.report['mu_ratio'] == ref.report['mu_ratio'] and res.report['flips'] == 0
    assert res.warnings == [] and res.flattened.all() and (res.face_island == 0).all()
    np.testing.assert_allclose(res.uv[res.F_uv], res.uv_corner, atol=0)
    ref = flatten(V, F, boundary=boundary, fit='true_scale')
    res = unwrap(V, F, boundary=boundary, fit='true_scale', pack=False)
    assert rigid_residual(ref.uv[F].reshape(-1, 2), res.uv_corner.reshape(-1, 2)) < 1e-9
    assert soup_areas(res.uv_corner).sum() == pytest.approx(face_areas(V, F).sum(), rel=1e-9)


@pytest.mark.parametrize('boundary', ['area', 'uniform'])
def test_island_pipeline_agrees_with_flatten(bump, boundary):
    """A seam on a boundary edge cuts nothing but sends the disk through the island pipeline: the
    same map up to a rigid motion (true scale, unpacked)."""
    V, F = bump
    loop = topology.boundary_loops(F, len(V))[0]
    res = unwrap(V, F, seams=[[loop[0], loop[1]]], boundary=boundary, fit='true_scale', pack=False)
    assert res.report['path'] == 'islands' and res.report['islands'] == 1
    ref = flatten(V, F, boundary=boundary, fit='true_scale')
    assert rigid_residual(ref.uv[F].reshape(-1, 2), res.uv_corner.reshape(-1, 2)) < 1e-9
    assert res.report['mu_ratio'] == pytest.approx(ref.report['mu_ratio'], rel=1e-9)


def test_selection(bump):
    """Only the selected triangles get UVs (the others NaN, island -1); the result is the unwrap of
    the selected sub-mesh, in the input's numbering; the input arrays are not modified."""
    V, F = bump
    V0, F0 = V.copy(), F.copy()
    sel = V[F].mean(1)[:, 0] < 0.3
    res = unwrap(V, F, faces=sel, boundary='area')
    np.testing.assert_array_equal(V, V0)
    np.testing.assert_array_equal(F, F0)
    assert np.array_equal(res.flattened, sel) and np.isnan(res.uv_corner[~sel]).all()
    assert (res.face_island[~sel] == -1).all() and (res.F_uv[~sel] == -1).all()
    used = np.unique(F[sel])
    remap = np.full(len(V), -1)
    remap[used] = np.arange(len(used))
    sub = unwrap(V[used], remap[F[sel]], boundary='area')
    np.testing.assert_allclose(res.uv_corner[sel], sub.uv_corner, atol=1e-12)
    outside = np.setdiff1d(np.arange(len(V)), used)
    assert np.isnan(res.mu_vertex[outside]).all() and np.isfinite(res.mu_vertex[used]).all()
    assert res.report['selected_triangles'] == sel.sum() == res.report['flattened_triangles']
    # seams outside the selection are ignored, not an error
    far = np.nonzero(~sel)[0][0]
    res2 = unwrap(V, F, faces=sel, seams=[F[far, :2]], boundary='area')
    np.testing.assert_allclose(res2.uv_corner[sel], res.uv_corner[sel], atol=1e-12)
    with pytest.raises(ConformalError) as err:
        unwrap(V, F, faces=np.zeros(len(F), bool))
    assert err.value.code == 'empty_mesh'
    with pytest.raises(ConformalError, match='one entry per triangle'):
        unwrap(V, F, faces=sel[:-1])


def test_per_vertex_mu_and_measures(bump):
    """``mu_vertex`` is the core's one per-vertex mu of the per-triangle ``mu``; the report's measures
    are those of ``uv_corner``."""
    V, F = bump
    V2, F2 = two_squares()
    for V_, F_ in ((V, F), (V2, F2)):
        res = unwrap(V_, F_, boundary='uniform')
        np.testing.assert_allclose(res.mu_vertex, vertex_mu(F_, res.mu, face_areas(V_, F_), len(V_)))
        k = len(F_)
        meas = uv_measures(V_[F_].reshape(-1, 3), np.arange(3 * k).reshape(k, 3),
                           res.uv_corner.reshape(-1, 2))
        for key in ('flips', 'mu_ratio', 'qc_mean', 'qc_max'):
            assert res.report[key] == pytest.approx(meas[key], rel=1e-9), key


def test_warnings_on_bad_results_only():
    """A closed part skipped with on_error='skip' and a badly distorted island give warnings; the
    clean islands give none."""
    V, F = two_squares()
    res = unwrap(V, F, boundary='area')
    assert res.report['islands'] == 2 and res.warnings == []
    assert all(r['warnings'] == [] for r in res.islands)
    S, G = _closed_octahedron()
    V2 = np.vstack([V, S + [10, 0, 0]])
    F2 = np.vstack([F, G + len(V)])
    with pytest.raises(ConformalError) as err:
        unwrap(V2, F2, boundary='area')
    assert err.value.code == 'no_boundary' and err.value.remedy == 'mark_seams'
    res = unwrap(V2, F2, boundary='area', on_error='skip')
    assert res.report['failed'] == 1 and len(res.warnings) == 1 and 'skipped' in res.warnings[0]
    bad = res.face_island == res.face_island[-1]
    assert not res.flattened[bad].any() and np.isnan(res.uv_corner[bad]).all()
    failed = [r for r in res.islands if 'error' in r][0]
    assert failed['error_code'] == 'no_boundary' and failed['error_remedy'] == 'mark_seams'
    # a needle-like cone: far from conformal at this resolution -> a quality warning, not silence
    Vc, Fc = _cone(40)
    res = unwrap(Vc, Fc, boundary='free')
    assert res.report['qc_mean'] > 1.5
    assert any('far from conformal' in w for w in res.warnings)


def test_a_closed_part_with_handles_is_not_sent_to_sphere_mode():
    """A closed torus (genus 1) cannot take sphere mode: its error names the genus and offers cones or
    seams through the handles; a closed genus-0 part keeps sphere mode among its remedies."""
    from meshgen import icosphere, torus
    V, F = torus()
    with pytest.raises(ConformalError) as err:
        unwrap(V, F)
    assert err.value.code == 'no_boundary' and err.value.remedy == 'seam_handles'
    assert 'genus 1' in str(err.value) and 'or use sphere mode' not in str(err.value)
    V, F = icosphere(2)
    with pytest.raises(ConformalError) as err:
        unwrap(V, F)
    assert err.value.remedy == 'mark_seams' and 'or use sphere mode' in str(err.value)


def test_scale_warning_names_a_remedy_that_is_left():
    """An island of the plain path with an extreme scale variation is told to take seams or cones; an
    island cut through the cones the tool chose is told what is left (tiny triangles, the target or
    the budget), not to choose cones."""
    from core.atlas.unwrap import CONE_SCALE_REMEDY, island_warnings
    from core.disk.flatten import SCALE_REMEDY
    rep = {'mu_ratio': 2.4e-5, 'flips': 0, 'qc_mean': 1.02}
    plain, = island_warnings(rep, 'the map')
    coned, = island_warnings(rep, 'the map', cones=True)
    assert 'mu_ratio 2.4e-05' in plain and plain.endswith(SCALE_REMEDY) and 'cones' in SCALE_REMEDY
    assert 'mu_ratio 2.4e-05' in coned and coned.endswith(CONE_SCALE_REMEDY)
    assert 'choose cones' not in coned and 'merge vertices by distance' in coned
    assert island_warnings(dict(rep, mu_ratio=0.2), 'the map', cones=True) == []


def _closed_octahedron():
    V = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    F = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return V, F


def _cone(k, height=30.0):
    """A fan of ``k`` thin triangles around an apex high above a unit circle: one disk whose
    triangles cannot all be mapped conformally by a piecewise-linear map."""
    t = np.linspace(0, 2 * np.pi, k, endpoint=False)
    V = np.vstack([[0, 0, height], np.c_[np.cos(t), np.sin(t), np.zeros(k)],
                   0.5 * np.c_[np.cos(t), np.sin(t), np.full(k, height)]])
    F = []
    for i in range(k):
        j = (i + 1) % k
        a, b, c, d = 1 + i, 1 + j, 1 + k + i, 1 + k + j
        F += [(a, b, d), (a, d, c), (c, d, 0)]
    return V, np.array(F)


def test_face_order_invariance():
    """Permuting the triangles permutes the result: per island the same map up to a rigid motion,
    the same measures. Face order changes where each boundary loop starts (the boundary curve's
    closure) and the rows of the optimiser's linear programs, so the islands agree to about 1e-7
    ('area') and 1e-5 ('uniform', the optimiser's stopping tolerance) of their size; the bump disk in
    'area' mode agrees to rounding."""
    V, F = two_squares()
    perm = np.random.default_rng(3).permutation(len(F))
    for boundary, tol in (('area', 2e-6), ('uniform', 5e-5)):
        a = unwrap(V, F, boundary=boundary, fit='true_scale', pack=False)
        b = unwrap(V, F[perm], boundary=boundary, fit='true_scale', pack=False)
        for key in ('flips', 'mu_ratio', 'qc_mean', 'islands'):
            assert b.report[key] == pytest.approx(a.report[key], rel=tol), key
        Wa, Wb = a.uv_corner[perm], b.uv_corner
        for i in np.unique(a.face_island):
            t = a.face_island[perm] == i
            assert len(np.unique(b.face_island[t])) == 1
            assert rigid_residual(Wa[t].reshape(-1, 2), Wb[t].reshape(-1, 2)) < tol
    # the disk path too
    Vb, Fb = make_surface('bump', 9)
    perm = np.random.default_rng(4).permutation(len(Fb))
    a = unwrap(Vb, Fb, boundary='area', fit='true_scale')
    b = unwrap(Vb, Fb[perm], boundary='area', fit='true_scale')
    assert rigid_residual(a.uv_corner[perm].reshape(-1, 2), b.uv_corner.reshape(-1, 2)) < 1e-9


def test_true_scale_helper():
    """``true_scale`` gives several layouts one factor: total UV area = total 3D area."""
    V, F = two_squares()
    res = unwrap(V, F, boundary='area')               # unit square
    half = len(F) // 2
    parts = [(V, F[:half], res.uv_corner[:half]), (V, F[half:], res.uv_corner[half:])]
    out = true_scale(parts)
    total = sum(soup_areas(W).sum() for W in out)
    assert total == pytest.approx(face_areas(V, F).sum(), rel=1e-12)
    ratio = soup_areas(out[0]).sum() / soup_areas(res.uv_corner[:half]).sum()
    assert ratio == pytest.approx(soup_areas(out[1]).sum() / soup_areas(res.uv_corner[half:]).sum())


def test_non_finite_coordinates_named():
    """An infinite coordinate is reported as such (not as zero-area faces), also inside a selection
    and with seams."""
    V, F = make_surface('bump', 7)
    V = V.copy()
    V[5, 1] = np.inf
    for kw in ({}, {'faces': np.isin(F, 5).any(1) | (np.arange(len(F)) < 10)}, {'seams': [F[0, :2]]}):
        with pytest.raises(ConformalError) as err:
            unwrap(V, F, **kw)
        assert err.value.code == 'bad_coordinates' and 'infinite' in err.value.problem


def test_version_and_cli_json_warnings(tmp_path, capsys):
    from core.cli import main
    from core.io.obj import write_obj
    with open(_manifest()) as f:
        assert f'version = "{__version__}"' in f.read()
    Vc, Fc = _cone(40)
    src, out = tmp_path / 'cone.obj', tmp_path / 'out.obj'
    write_obj(str(src), Vc, Fc)
    assert main(['unwrap', str(src), str(out), '--boundary', 'free', '--json']) == 0
    printed = json.loads(capsys.readouterr().out.strip().splitlines()[-1])
    assert any('far from conformal' in w for w in printed['warnings'])
    assert printed['summary']['warnings'] == len(printed['warnings'])


def _manifest():
    import os
    return os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'blender_manifest.toml')


def test_unwrap_with_cones_opens_a_closed_mesh():
    """cones='auto' unwraps a closed genus-0 mesh in one call: automatic seams, cones that satisfy
    Gauss-Bonnet, per-corner UVs everywhere, zero flips, and the seams reported as input edges."""
    from core.surfaces import blob
    from core.mesh import topology
    V, F = blob(6, bumps=((0, 0, 1, 0.8), (1, 0, 0, 0.5)), width=0.2)
    res = unwrap(V, F, cones='auto')
    assert res.report['path'] == 'cones'
    assert np.isfinite(res.uv_corner).all() and res.flattened.all()
    assert res.report['flips'] == 0 and res.report['overlaps'] == 0
    kappa = np.array([k for _, k in res.cones])
    assert len(kappa) >= 3 and kappa.sum() == pytest.approx(4 * np.pi, abs=1e-6)   # chi = 2
    E, _ = topology.unique_edges(F)
    keys = set(map(tuple, E.tolist()))
    assert len(res.seams) and all(tuple(sorted(e)) in keys for e in res.seams.tolist())
    assert res.uv_corner.min() >= -1e-12 and res.uv_corner.max() <= 1 + 1e-12
    # a seam edge's two sides get different UVs, an inner edge's the same
    assert res.uv.shape[0] > len(V)
    with pytest.raises(ConformalError):
        unwrap(V, F, cones='many')


def test_a_flip_that_the_mesh_itself_folds_is_named():
    """Bump at n = 65 with every vertex moved by 0.2 mean edges at random: 9-20 triangles are folded
    over in the mesh itself (their normal opposes all their neighbours'; ``folded_faces``). The
    conformal map sees only lengths, so it flips at most one triangle here, folded or not (seeds
    0-11: flips on seeds 2, 4, 5, 8; on 2 and 5 a folded one). When a flip is such a crumpled spot,
    the warning says so and what to do; the clean bump has no folded triangle."""
    from core.mesh.geometry import folded_faces
    V0, F = make_surface('bump', 65)
    assert not folded_faces(V0, F).any()
    e = np.linalg.norm(V0[F[:, 0]] - V0[F[:, 1]], axis=1).mean()
    named = 0
    for seed in range(8):
        V = V0 + 0.2 * e * np.random.default_rng(seed).standard_normal(V0.shape)
        assert folded_faces(V, F).any()
        res = unwrap(V, F)
        k = res.report.get('flips_folded', 0) if 'flips_folded' in res.report else \
            sum(r.get('flips_folded', 0) for r in res.islands)
        assert k <= res.report['flips']
        said = any('folded over in the mesh itself' in w for w in res.warnings)
        assert said == (k > 0), (seed, k, res.warnings)
        named += k > 0
    assert named >= 1
