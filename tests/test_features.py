"""Feature curves (core/atlas/features.py) and the automatic seams along them (``cone_layout``)."""
import os

import numpy as np

import meshgen
from core import unwrap
from core.atlas.features import feature_curves

DATA = os.path.join(os.path.dirname(__file__), 'data')


def _edges(E):
    return set(map(tuple, np.sort(np.asarray(E), axis=1).tolist()))


def _rotation(seed=0):
    q, _ = np.linalg.qr(np.random.default_rng(seed).standard_normal((3, 3)))
    return q * np.sign(np.linalg.det(q))


def test_feature_curves_are_the_sharp_rims_that_hold_curvature():
    """A closed 48-sided cylinder holds all its curvature on its two rims (2 pi / 48 at each rim
    vertex): those 96 edges are its feature curves, the same after a rotation, a scaling and a
    renumbering of the vertices. A box's sharp edges hold none (its curvature sits at its eight
    corners), a coarse torus's rings are not sharp, and the cow's creases are short runs on a noisy
    surface: no feature curve."""
    V, F = meshgen.capped_cylinder(48, 12)
    rims = {(a, b) for ring in (0, 12) for a, b in
            np.sort(np.c_[ring * 48 + np.arange(48), ring * 48 + (np.arange(48) + 1) % 48], axis=1).tolist()}
    assert _edges(feature_curves(V, F)) == rims
    perm = np.random.default_rng(1).permutation(len(V))
    inv = np.argsort(perm)
    got = feature_curves(3.7 * V[perm] @ _rotation().T + [1.0, -2.0, 5.0], inv[F])
    assert _edges(perm[got]) == rims
    assert len(feature_curves(*meshgen.box(8))) == 0
    # a coarse smooth torus: its rings are 30 degrees apart (as Blender's default torus), not sharp
    assert len(feature_curves(*meshgen.torus(48, 12))) == 0
    from core.io.obj import read_obj
    from core.mesh.repair import repair_merged
    cow = read_obj(os.path.join(DATA, 'cow.obj'))
    from core.mesh.triangulate import triangulate
    tc, _ = triangulate(cow.corner_verts, cow.sizes, cow.V)
    fixed, _ = repair_merged(cow.V, cow.corner_verts[tc])
    assert len(feature_curves(fixed.V, fixed.F)) == 0


def test_a_cylinder_is_cut_along_its_rims_and_unrolled():
    """``unwrap(cones='auto')`` on a closed 48-sided cylinder: before, 6 cones, 1%/99% ratio 0.60 and
    qc_mean 1.21 (warned), in 0.9 s. Cut along its rims it unrolls: two caps and the side, no cone,
    every triangle at one scale (an isometry up to the packing's scale), no warning; the same after
    a rotation and a scaling."""
    V, F = meshgen.capped_cylinder(48, 12)
    for Vx in (V, 0.02 * V @ _rotation(3).T):
        res = unwrap(Vx, F, cones='auto')
        r = res.report
        assert r['feature_edges'] == 96 and r['islands'] == 3 and r['cones'] == 0 and r['flips'] == 0
        assert not res.warnings
        e3 = np.linalg.norm(Vx[F] - Vx[np.roll(F, 1, axis=1)], axis=2)
        uv = res.uv_corner
        e2 = np.linalg.norm(uv - np.roll(uv, 1, axis=1), axis=2)
        ratio = e2 / e3
        assert ratio.max() < ratio.min() * (1 + 1e-6), (ratio.min(), ratio.max())
        bottom = np.c_[np.arange(48), (np.arange(48) + 1) % 48]
        assert _edges(res.seams) >= _edges(bottom)


def test_a_boolean_boss_is_cut_along_its_rims_and_laid_out_flat():
    """A block with a cylindrical boss as Blender's exact Boolean leaves it (tests/data/bool_boss.obj:
    n-gons around the boss). Before, its rims' curvature went to 34 cones: 1%/99% ratio 0.28, qc_mean
    1.74 (warned), 2.8 s. Cut along the two rims (96 feature edges) every face is laid out flat:
    ratio and qc_mean 1.000, no flip, no polygon split, no warning."""
    from core.atlas.unwrap import split_polygons
    from core.io.obj import read_obj
    from core.mesh.triangulate import triangulate
    mesh = read_obj(os.path.join(DATA, 'bool_boss.obj'))
    tc, poly = triangulate(mesh.corner_verts, mesh.sizes, mesh.V)
    F = mesh.corner_verts[tc]
    res = unwrap(mesh.V, F, tri_poly=poly, cones='auto')
    r = res.report
    assert r['feature_edges'] == 96 and r['flips'] == 0 and r['overlaps'] == 0
    assert r['mu_ratio_p1_p99'] > 0.999 and r['qc_mean'] < 1.001
    assert res.report['split_polygons'] == 0 == split_polygons(F, poly, res.uv_corner)
    assert not res.warnings
    # the boss and the block's top face selected: that face, an n-gon plate with a hole once the
    # foot is cut, closes up on its cut, which used to count as an overlap and split a polygon
    top = np.all(mesh.V[F][:, :, 2] > 0.5 - 1e-6, axis=1)
    res = unwrap(mesh.V, F, tri_poly=poly, cones='auto', faces=top)
    r = res.report
    assert r['feature_edges'] == 96 and r['flips'] == 0 and r['overlaps'] == 0 and not res.warnings
    assert r['mu_ratio_p1_p99'] > 0.999 and r['qc_mean'] < 1.001 and r['split_polygons'] == 0
    assert np.isnan(res.uv_corner[~top]).all()


def test_copies_of_a_part_cut_along_its_feature_curves_are_laid_out_once():
    """Three copies of the Boolean boss (an Array modifier's; the last mirrored): the first is cut
    along its rims and laid out, the others take its islands, seams and cones (``repeat_of``), the
    mirror image reflected: every triangle at one scale, none flipped."""
    from core.io.obj import read_obj
    from core.mesh.triangulate import triangulate
    mesh = read_obj(os.path.join(DATA, 'bool_boss.obj'))
    tc, poly = triangulate(mesh.corner_verts, mesh.sizes, mesh.V)
    F0, n = mesh.corner_verts[tc], len(mesh.V)
    V = np.concatenate([mesh.V, mesh.V + [5.0, 0.0, 0.0], mesh.V * [-1, 1, 1] + [10.0, 0.0, 0.0]])
    F = np.concatenate([F0, F0 + n, F0[:, ::-1] + 2 * n])
    res = unwrap(V, F, tri_poly=np.r_[poly, poly + 1000, poly + 2000], cones='auto')
    r = res.report
    assert r['islands'] == 9 and r['feature_edges'] == 3 * 96 and r['flips'] == 0 and not res.warnings
    assert sum('repeat_of' in i for i in res.islands) == 6
    assert np.nanmax(res.mu) < np.nanmin(res.mu) * (1 + 1e-6)


def test_a_part_whose_pieces_have_no_layout_is_laid_out_whole(monkeypatch):
    """If a piece cut off along the feature curves has no layout (``ConformalError``), the part is laid
    out whole, as without feature curves, instead of failing."""
    import core.atlas.unwrap as unwrap_module
    from core.errors import ConformalError
    real = unwrap_module.cone_layout

    def pieces_fail(*args, **kw):
        if kw.get('features') is False:
            raise ConformalError("no layout of the cut disk could be built", 'solve_failed')
        return real(*args, **kw)

    monkeypatch.setattr(unwrap_module, 'cone_layout', pieces_fail)
    V, F = meshgen.capped_cylinder(16, 4)
    res = unwrap(V, F, cones='auto')
    r = res.report
    assert r['feature_edges'] == 0 and r['islands'] == 1 and r['cones'] > 0 and r['flips'] == 0
    assert np.isfinite(res.uv_corner).all()
