"""Islands: cutting along seams, hole filling and cutting, per-island flattening, packing, the
``unwrap`` CLI command. Uses boundary='area' (fast); one test runs the default 'uniform'."""
import os

import numpy as np
import pytest

from conftest import DATA
from meshgen import coverage, grid, two_holes, uv_sphere
from core.mesh import topology
from core.cli import main
from core.errors import ConformalError
from core.mesh.geometry import face_areas
from core.atlas.cut import glued_pieces
from core.atlas.islands import (boundary_crossings, cut_along_seams, fill_holes, seams_from_corner_ids,
                          shelf_pack, unwrap)
from core.mesh.measures import uv_measures
from core.io.obj import read_obj
from core.mesh.triangulate import triangulate


def uv_area(uv, F):
    W = uv[F]
    e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


@pytest.fixture(scope='module')
def sphere():
    return uv_sphere(32, 64)


@pytest.fixture(scope='module')
def sphere_unwrap(sphere):
    V, F, S = sphere
    return unwrap(V, F, S, boundary='area')


# --- cutting -------------------------------------------------------------------------------------
def test_cut_keeps_positions_and_counts(sphere):
    V, F, S = sphere
    cut = cut_along_seams(F, len(V), S)
    assert cut.n_islands == 2
    # every corner keeps its position; split vertices are the seam vertices counted once per side
    assert np.array_equal(V[cut.vert_of][cut.F], V[F])
    seam_verts = np.unique(S)
    poles = 2
    # equator vertices get one copy per hemisphere, meridian vertices one per side, the vertex where
    # both seams cross four copies, and the poles (where the slit ends) stay single
    n_lon = 64
    n_mer_inner = len(seam_verts) - n_lon - poles        # meridian vertices off the equator
    assert len(cut.vert_of) == len(V) + n_lon + 2 + n_mer_inner
    for i, faces in enumerate(cut.island_faces()):
        lo, hi = cut.vert_start[i], cut.vert_start[i + 1]
        Fi = cut.F[faces] - lo
        assert Fi.min() == 0 and Fi.max() == hi - lo - 1
        loops = topology.boundary_loops(Fi, hi - lo)
        assert len(loops) == 1 and topology.euler_characteristic(Fi) == 1


def test_gluing_undoes_only_the_cuts_beyond_the_seams(sphere):
    """``glued_pieces`` is the inverse of a cut: the sphere cut along its seams and glued back with the
    same seams is unchanged (its two hemispheres, every split vertex its own, nothing joined); glued
    with only the equator as seams, the meridian cut is undone (one copy per vertex of each
    hemisphere, flagged as joined); with none, the whole sphere is one piece again, up to shuffled
    faces."""
    V, F, S = sphere
    cut = cut_along_seams(F, len(V), S)
    piece, n_p, glued, joined = glued_pieces(F, cut.F, cut.face_island, S, len(V))
    assert n_p == 2 and not joined.any() and len(np.unique(glued)) == len(cut.vert_of)
    assert np.array_equal(np.unique(np.c_[piece, cut.face_island], axis=0)[:, 0], [0, 1])
    equator = S[:64]
    piece, n_p, glued, joined = glued_pieces(F, cut.F, cut.face_island, equator, len(V))
    assert n_p == 2 and joined.all() and len(np.unique(glued)) == len(V) + 64
    rng = np.random.default_rng(0)
    order = rng.permutation(len(F))
    Fp = np.roll(F[order], 1, axis=1)
    Fc = np.roll(cut.F[order], 1, axis=1)
    piece, n_p, glued, joined = glued_pieces(Fp, Fc, cut.face_island[order], None, len(V))
    assert n_p == 1 and joined.all() and len(np.unique(glued)) == len(V)
    assert np.array_equal(np.unique(glued[cut.F]), np.arange(len(V)))


def test_slit_seam_opens_a_closed_sphere_into_one_disk():
    V, F, S = uv_sphere(16, 32)
    meridian = S[32:]
    cut = cut_along_seams(F, len(V), meridian)
    assert cut.n_islands == 1
    assert [len(lp) for lp in topology.boundary_loops(cut.F, len(cut.vert_of))] == [2 * 16]
    res = unwrap(V, F, meridian, boundary='area')
    assert res.report['flips'] == 0 and res.report['overlaps'] == 0


def test_a_seam_that_does_not_open_a_closed_mesh_is_named_in_the_error():
    """One seam edge (or edges apart) on a closed surface opens nothing: the error says so, beside its
    remedy, rather than only that the island has no boundary."""
    V, F, S = uv_sphere(16, 32)
    meridian = S[32:]
    for seams, count in ((meridian[3:4], 1), (meridian[[2, 6, 10]], 3)):
        with pytest.raises(ConformalError, match=rf'the {count} seam edge\(s\) marked on it do not cut it'):
            unwrap(V, F, seams, boundary='area')
    with pytest.raises(ConformalError) as exc:                         # no seam: the plain message
        unwrap(V, F, boundary='area')
    assert 'seam edge(s) marked' not in str(exc.value)


def test_components_are_islands_without_seams():
    V, F = grid(5)
    V2 = np.vstack([V, V + [3.0, 0, 0]])
    F2 = np.vstack([F, F + len(V)])
    cut = cut_along_seams(F2, len(V2))
    assert cut.n_islands == 2
    assert np.array_equal(cut.vert_of, np.arange(len(V2)))      # nothing split


def test_boundary_seams_change_nothing_and_bad_seams_raise():
    V, F = grid(4)
    loop = topology.boundary_loops(F, len(V))[0]
    cut = cut_along_seams(F, len(V), np.stack([loop, np.roll(loop, -1)], 1))
    assert cut.n_islands == 1 and len(cut.vert_of) == len(V)
    with pytest.raises(ConformalError, match='not edges of the mesh'):
        cut_along_seams(F, len(V), [[0, 15]])
    assert cut_along_seams(F, len(V), [[0, 15]], strict=False).n_islands == 1      # ignored
    with pytest.raises(ConformalError, match='do not exist'):
        cut_along_seams(F, len(V), [[0, 99]])
    with pytest.raises(ConformalError, match='to itself'):
        cut_along_seams(F, len(V), [[3, 3]])
    with pytest.raises(ConformalError, match=r'\(k,2\)'):
        cut_along_seams(F, len(V), [0, 1, 2])


def test_seams_from_corner_ids_recovers_the_seams():
    V, F, S = uv_sphere(8, 16)
    cut = cut_along_seams(F, len(V), S)
    got = seams_from_corner_ids(F, cut.F, len(V))
    want = np.unique(np.sort(S, 1), axis=0)
    assert np.array_equal(got, want)


# --- the sphere acceptance ----------------------------------------------------------------------
def test_uv_sphere_islands_acceptance(sphere, sphere_unwrap):
    V, F, S = sphere
    res = sphere_unwrap
    assert res.report['islands'] == 2 and res.report['failed'] == 0
    for isl in res.islands:
        assert isl['flips'] == 0
        assert isl['qc_mean'] <= 1.05
        assert isl['overlaps'] == 0
    # independent re-measure of each island from the written per-corner UVs
    for i in range(2):
        Fi = res.F[res.face_island == i]
        meas = uv_measures(V[res.vert_of], Fi, res.uv)
        assert meas['flips'] == 0 and meas['qc_mean'] <= 1.05
    # packed into the unit square, without overlap: rasterised coverage is at most 1 everywhere
    assert res.uv.min() >= 0 and res.uv.max() <= 1
    cov = coverage(res.uv, res.F, res=400)
    assert cov.max() == 1 and len(cov) > 0.5 * 400 * 400 * 0.5
    # island bounding boxes are disjoint
    boxes = [(res.uv[res.F[res.face_island == i]].reshape(-1, 2).min(0),
              res.uv[res.F[res.face_island == i]].reshape(-1, 2).max(0)) for i in range(2)]
    (a0, a1), (b0, b1) = boxes
    assert (a1 < b0).any() or (b1 < a0).any()


def test_uv_sphere_uniform_default_mode():
    V, F, S = uv_sphere(16, 32)
    res = unwrap(V, F, S)           # default boundary='uniform'
    assert res.report['boundary'] == 'uniform'
    assert res.report['flips'] == 0 and res.report['overlaps'] == 0
    assert res.report['qc_mean_worst'] <= 1.06       # coarse sphere: qc is discretisation error


def test_true_relative_scale_and_normalise():
    V, F = grid(9)
    small = V * 0.25 + [3.0, 0, 0]
    V2, F2 = np.vstack([V, small]), np.vstack([F, F + len(V)])
    res = unwrap(V2, F2, boundary='area', fit='true_scale')
    ratio = [uv_area(res.uv, res.F[res.face_island == i]).sum()
             / face_areas(V2, F2[res.face_island == i]).sum() for i in range(2)]
    assert ratio == pytest.approx([1, 1], rel=1e-9)
    res = unwrap(V2, F2, boundary='area', fit='true_scale', island_scale='normalise')
    a = [uv_area(res.uv, res.F[res.face_island == i]).sum() for i in range(2)]
    assert a[0] == pytest.approx(a[1], rel=1e-9)
    # unit_square fit scales the layout uniformly: relative scale is kept
    res = unwrap(V2, F2, boundary='area')
    a = [uv_area(res.uv, res.F[res.face_island == i]).sum() for i in range(2)]
    assert a[0] / a[1] == pytest.approx(16, rel=1e-9)


def test_shelf_pack_has_no_overlap():
    rng = np.random.default_rng(1)
    sizes = rng.uniform(0.05, 1.0, (60, 2))
    off, (w, h) = shelf_pack(sizes, 0.01)
    lo, hi = off, off + sizes
    assert lo.min() >= 0.01 - 1e-12 and hi[:, 0].max() <= w and hi[:, 1].max() <= h
    g = 0.01 - 1e-12
    sep = (hi[:, None, 0] + g <= lo[None, :, 0]) | (hi[None, :, 0] + g <= lo[:, None, 0]) \
        | (hi[:, None, 1] + g <= lo[None, :, 1]) | (hi[None, :, 1] + g <= lo[:, None, 1])
    np.fill_diagonal(sep, True)
    assert sep.all()
    assert (sizes.prod(1).sum() / (w * h)) > 0.5        # not absurdly wasteful


def test_boundary_crossings_detects_a_folded_boundary():
    t = np.linspace(0, 2 * np.pi, 40, endpoint=False)
    circle = np.c_[np.cos(t), np.sin(t)]
    loop = np.arange(40)
    assert boundary_crossings(circle, [loop]) == 0
    # sampled off its crossing: a boundary that only meets itself at a point touches there (a cut
    # that the layout closes up on), and this curve's samples at t = 0 and pi were both that point
    figure8 = np.c_[np.sin(t + 0.05), np.sin(2 * (t + 0.05))]
    assert boundary_crossings(figure8, [loop]) >= 1


# --- holes --------------------------------------------------------------------------------------
def test_two_holes_filled_acceptance():
    V, F = two_holes('bump', 33)
    res = unwrap(V, F, boundary='area', holes='fill', fit='true_scale')
    isl = res.islands[0]
    assert isl['loops'] == 3 and isl['holes']['filled'] == 2
    assert isl['flips'] == 0 and isl['overlaps'] == 0 and isl['qc_mean'] < 1.02
    # mu is measured on the real faces only: the report equals the measures of the real triangles
    assert isl['faces'] == len(F)
    meas = uv_measures(V[res.vert_of], res.F, res.uv)
    for key in ('flips', 'mu_ratio', 'qc_mean', 'qc_max'):
        assert isl[key] == pytest.approx(meas[key], rel=1e-9)
    # UV area equals 3D area on the real faces (the fill is not counted)
    assert uv_area(res.uv, res.F).sum() == pytest.approx(face_areas(V, F).sum(), rel=1e-9)
    assert res.uv.shape[0] == len(V)           # no fill vertex comes back


def test_flat_holes_filled_exactly():
    V, F = two_holes('flat', 17)
    res = unwrap(V, F, boundary='area', holes='fill')
    assert res.islands[0]['mu_ratio'] > 0.999 and res.islands[0]['qc_mean'] < 1.0001


def test_fill_holes_makes_a_disk():
    V, F = two_holes('saddle', 17)
    loops = topology.boundary_loops(F, len(V))
    V2, F2, info = fill_holes(V, F, loops)
    assert len(info) == 2 and np.array_equal(F2[:len(F)], F) and np.array_equal(V2[:len(V)], V)
    assert len(topology.boundary_loops(F2, len(V2))) == 1
    assert topology.euler_characteristic(F2) == 1
    assert face_areas(V2, F2[len(F):]).min() > 1e-6


def test_holes_cut_and_error_modes():
    V, F = two_holes('bump', 33)
    res = unwrap(V, F, boundary='area', holes='cut')
    isl = res.islands[0]
    assert isl['holes'] == {'mode': 'cut', 'cut': 2, 'cut_edges': isl['holes']['cut_edges']}
    assert isl['loops'] == 1 and isl['loops_before_cut'] == 3 and isl['flips'] == 0
    assert len(res.vert_of) > len(V)                # the cut paths split vertices
    with pytest.raises(ConformalError, match=r'3 boundary loops.*fill the holes'):
        unwrap(V, F, boundary='area', holes='error')


def test_hole_cut_paths_are_those_of_the_mesh_cut_so_far():
    """The holes' paths come from searches on the uncut mesh, with the merged holes and the earlier paths
    as sources. A hole nearer another hole than the rim takes its path to that hole once it is merged;
    the paths are those of searches on the mesh cut hole by hole (the definition), and cutting along
    them leaves one boundary loop."""
    from scipy.sparse.csgraph import dijkstra
    import scipy.sparse as sp
    from meshgen import compact
    from core import make_surface
    from core.atlas.islands import hole_cut_paths
    V, F = make_surface('bump', 41)
    centres = [(-0.5, 0.0), (-0.05, 0.05), (0.4, -0.1), (0.1, 0.55)]
    inside = np.zeros(len(V), bool)
    for cx, cy in centres:
        inside |= np.hypot(V[:, 0] - cx, V[:, 1] - cy) < 0.13
    V, F = compact(V, F[~inside[F].any(1)])
    n = len(V)
    loops = topology.boundary_loops(F, n)
    assert len(loops) == 5
    paths = hole_cut_paths(V, F, n, loops)
    want, Fc, vmap = [], F, np.arange(n)               # hole by hole on the mesh cut so far
    for _ in range(len(loops) - 1):
        nc = int(Fc.max()) + 1
        cur = topology.boundary_loops(Fc, nc)
        E, _ = topology.unique_edges(Fc)
        G = sp.coo_matrix((np.linalg.norm(V[vmap[E[:, 0]]] - V[vmap[E[:, 1]]], axis=1), (E[:, 0], E[:, 1])),
                          shape=(nc, nc)).tocsr()
        dist, pred, _ = dijkstra(G, directed=False, indices=cur[0], min_only=True, return_predecessors=True)
        holes = np.concatenate(cur[1:])
        path = [int(holes[np.argmin(dist[holes])])]
        while pred[path[-1]] >= 0:
            path.append(int(pred[path[-1]]))
        pairs = np.stack([path[::-1][:-1], path[::-1][1:]], 1)
        want.append(vmap[pairs])
        cut = cut_along_seams(Fc, nc, pairs)
        Fc, vmap = cut.F, vmap[cut.vert_of]
    assert len(paths) == len(want) == 4
    for got, ref in zip(paths, want):
        np.testing.assert_array_equal(got, ref)
    rim = set(loops[0].tolist())
    assert any(int(p[0, 0]) not in rim for p in paths)     # some path starts at a merged hole or path
    cut = cut_along_seams(F, n, np.concatenate(paths))
    assert cut.n_islands == 1 and len(topology.boundary_loops(cut.F, len(cut.vert_of))) == 1


# --- Suzanne ------------------------------------------------------------------------------------
@pytest.fixture(scope='module')
def suzanne():
    mesh = read_obj(os.path.join(DATA, 'suzanne.obj'))
    tri, tri_poly = triangulate(mesh.corner_verts, mesh.sizes, mesh.V)
    return mesh.V, mesh.corner_verts[tri], tri_poly


def test_suzanne_triangulates_cleanly(suzanne):
    V, F, _ = suzanne
    E, count = topology.unique_edges(F)
    assert count.max() == 2 and len(topology.duplicate_rows(F)) == 0


def test_suzanne_island_by_island(suzanne):
    V, F, tri_poly = suzanne
    with pytest.raises(ConformalError, match=r'island 3 of 3 .*polygon .*2 boundary loops'):
        unwrap(V, F, boundary='area', holes='error', tri_poly=tri_poly)
    res = unwrap(V, F, boundary='area', holes='error', tri_poly=tri_poly, on_error='skip')
    assert res.report['flattened'] == 2 and res.report['failed'] == 1
    assert not res.ok[res.face_island == 2].any() and res.ok[res.face_island != 2].all()
    res = unwrap(V, F, boundary='area', holes='fill', tri_poly=tri_poly)
    assert res.report['flattened'] >= 3
    # the head's few triangles that fold at the doublet and cone vertices of Suzanne's brows in every
    # mode are detached as islands of their own: no flip, no overlap, and the repair is reported
    assert res.report['flips'] == 0 and res.report['overlaps'] == 0
    assert any(r['repair'] == 'islands_split_for_overlap' for r in res.report['repairs'])
    assert all(np.isfinite(r['mu_ratio']) and r['mu_ratio'] > 0 for r in res.islands)


def test_suzanne_defaults_no_flips(suzanne):
    """Issue 12: Suzanne with the defaults (uniform, holes='auto') flattens with no flip and no overlap."""
    V, F, tri_poly = suzanne
    res = unwrap(V, F, tri_poly=tri_poly)
    r = res.report
    assert r['flips'] == 0 and r['overlaps'] == 0 and r['mu_ratio_worst'] > 0.01
    assert r['qc_mean_worst'] < 1.5 and not r['warnings']
    # every input corner has a UV of a split vertex of its own vertex
    assert (res.vert_of[res.F] == F).all() and res.ok.all()


# --- progress and the CLI ------------------------------------------------------------------------
def test_progress_is_monotone():
    V, F, S = uv_sphere(8, 16)
    seen = []
    unwrap(V, F, S, boundary='area', progress=lambda f, msg: seen.append(f))
    assert seen == sorted(seen) and seen[-1] == 1.0 and len(seen) > 4


def _write_obj_mesh(path, V, polys):
    with open(path, 'w') as fh:
        fh.write(''.join(f"v {x!r} {y!r} {z!r}\n" for x, y, z in V.tolist()))
        fh.write(''.join('f ' + ' '.join(str(i + 1) for i in p) + '\n' for p in polys))


def test_cli_unwrap_sphere_with_seams(tmp_path, capsys):
    V, F, S = uv_sphere(16, 32)
    src, out, seams = tmp_path / 'sphere.obj', tmp_path / 'out.obj', tmp_path / 'seams.txt'
    _write_obj_mesh(src, V, F)
    seams.write_text('# equator and meridian\n' + ''.join(f"{a + 1} {b + 1}\n" for a, b in S.tolist()))
    assert main(['unwrap', str(src), str(out), '--seams', str(seams), '--boundary', 'area']) == 0
    assert '2 island(s)' in capsys.readouterr().out
    back = read_obj(str(out))
    assert np.allclose(back.V, V)
    assert np.array_equal(back.corner_verts, F.ravel())
    lines = out.read_text().splitlines()
    vt = np.array([[float(x) for x in ln.split()[1:]] for ln in lines if ln.startswith('vt ')])
    ref = unwrap(V, F, S, boundary='area')
    assert len(vt) == len(ref.vert_of)
    corner_uv = vt[back.corner_uvs].reshape(-1, 3, 2)
    assert np.allclose(corner_uv, ref.corner_uv, atol=1e-8)
    # the written UVs are a valid map: no flips, no overlap
    assert coverage(vt, back.corner_uvs.reshape(-1, 3), res=200).max() == 1


def test_cli_unwrap_keeps_quads_and_reads_uv_seams(tmp_path, capsys):
    out = tmp_path / 'suz.obj'
    assert main(['unwrap', os.path.join(DATA, 'suzanne.obj'), str(out), '--boundary', 'area', '--json']) == 0
    import json
    rep = json.loads(capsys.readouterr().out)
    # 3 pieces; the head's few triangles that fold in every mode become islands of their own
    k = rep['summary']['islands']
    assert k >= 3 and len(rep['islands']) == k and rep['summary']['flips'] == 0
    src, back = read_obj(os.path.join(DATA, 'suzanne.obj')), read_obj(str(out))
    assert np.array_equal(back.sizes, src.sizes) and np.array_equal(back.corner_verts, src.corner_verts)
    # round trip: the written vt seams are exactly the island boundaries, so unwrapping the output
    # with --seams-from-uv finds the same islands
    out2 = tmp_path / 'suz2.obj'
    assert main(['unwrap', str(out), str(out2), '--boundary', 'area', '--seams-from-uv', '--json']) == 0
    assert json.loads(capsys.readouterr().out)['summary']['islands'] == k


def test_selection_workflow_with_all_seams():
    """A selection (a sub-mesh) unwrapped with every seam of the whole mesh: seams outside the
    selection are ignored with strict_seams=False."""
    V, F, S = uv_sphere(16, 32)
    north = V[F].mean(1)[:, 2] > 0.3                    # a cap around the north pole
    used = np.unique(F[north])
    remap = np.full(len(V), -1)
    remap[used] = np.arange(len(used))
    Fs = remap[F[north]]
    Ss = remap[S[(remap[S] >= 0).all(1)]]
    with pytest.raises(ConformalError, match='not edges'):
        unwrap(V[used], Fs, np.r_[Ss, [[0, len(used) - 1]]], boundary='area')
    res = unwrap(V[used], Fs, np.r_[Ss, [[0, len(used) - 1]]], boundary='area', strict_seams=False)
    assert res.report['islands'] == 1 and res.report['flips'] == 0 and res.report['overlaps'] == 0


# --- issue 12: the automatic hole choice and overlap repair ---------------------------------------
def _cylinder(nu=32, nv=12, h=2.0):
    """An open tube (both ends open): ``V`` (nu*nv,3), ``F`` (2*nu*(nv-1),3)."""
    t = np.linspace(0, 2 * np.pi, nu, endpoint=False)
    z = np.linspace(0, h, nv)
    V = np.stack([np.tile(np.cos(t), nv), np.tile(np.sin(t), nv), np.repeat(z, nu)], 1)
    j, i = np.meshgrid(np.arange(nv - 1), np.arange(nu), indexing='ij')
    a = (j * nu + i).ravel()
    b = (j * nu + (i + 1) % nu).ravel()
    return V, np.concatenate([np.stack([a, b, b + nu], 1), np.stack([a, b + nu, a + nu], 1)])


def test_tube_is_cut_not_filled_by_auto():
    V, F = _cylinder()
    auto = unwrap(V, F)                                     # holes='auto' is the default
    fill = unwrap(V, F, holes='fill')
    assert auto.islands[0]['holes']['mode'] == 'cut'
    assert auto.report['mu_ratio_worst'] >= 0.05
    assert auto.report['mu_ratio_worst'] > fill.report['mu_ratio_worst']
    assert auto.report['flips'] == 0 and auto.report['overlaps'] == 0 and not auto.report['warnings']
    # both candidates are measured and reported
    assert set(auto.islands[0]['holes']['auto']) == {'fill/uniform', 'cut/uniform'}


def test_many_holes_cut_without_overlap():
    """A bumpy sheet with 10 holes, cut open: no overlap is ever returned silently."""
    from core import make_surface
    V, F = make_surface('bump', 33)
    C = V[F].mean(1)
    rng = np.random.default_rng(3)
    centres = rng.uniform(0.15, 0.85, (10, 2))
    drop = np.zeros(len(F), bool)
    lo, hi = V[:, :2].min(0), V[:, :2].max(0)
    P = (C[:, :2] - lo) / (hi - lo)
    for c in centres:
        drop |= np.linalg.norm(P - c, axis=1) < 0.03
    F = F[~drop]
    for holes in ('cut', 'auto'):
        res = unwrap(V, F, holes=holes, boundary='area')
        r = res.report
        assert r['flips'] == 0 and r['overlaps'] == 0 and not r['warnings']
        # the mode actually used is reported; when 'cut' overlapped, 'fill' was tried and kept
        isl = res.islands[0]['holes']
        assert isl['mode'] in ('fill', 'cut')
        if isl['mode'] == 'fill' and holes == 'cut':
            assert isl['auto']['cut/area']['overlaps'] > 0


def test_extreme_scale_is_warned():
    """A long tube forced to be filled (not cut) has texel density varying by orders of magnitude: the
    result comes back with a warning, never as plain success."""
    V, F = _cylinder(nu=16, nv=41, h=12.0)
    res = unwrap(V, F, holes='fill', boundary='area')
    r = res.report
    assert r['mu_ratio_worst'] < 1e-4
    assert any('extreme scale variation' in w for w in r['warnings'])
    assert any('extreme scale variation' in w for w in res.islands[0]['warnings'])
    cut = unwrap(V, F, boundary='area')                      # auto: cut, uniform density
    assert cut.report['mu_ratio_worst'] > 0.5 and not cut.report['warnings']
    # core.unwrap (the add-on's and the CLI's entry) says so too: it used to drop this warning
    from core import unwrap as core_unwrap
    top = core_unwrap(V, F, holes='fill', boundary='area')
    assert top.report['mu_ratio_worst'] < 1e-4
    assert sum('extreme scale variation' in w for w in top.warnings) == 1
    assert not core_unwrap(V, F, boundary='area').warnings


def _two_bumps():
    """Two bump disks (n = 17) side by side: two islands, so ``unwrap`` takes the island path."""
    from core import make_surface
    V, F = make_surface('bump', 17)
    return np.vstack([V, V + [5.0, 0, 0]]), np.vstack([F, F + len(V)]), V, F


def test_a_kept_retry_gets_the_certified_bound_once(monkeypatch):
    """Retries (here: the area map after a uniform map made to report an overlap) make no bound of
    their own; the kept retry's bound is made afterwards and equals the map's own certificate."""
    import core.atlas.islands as isl
    from core import flatten
    V2, F2, V, F = _two_bumps()
    calls = []
    real = isl._flatten_island

    def fake(Vi, Fi, loops, holes, boundary, desc, progress, options):
        calls.append((boundary, bool(options.get('bound'))))
        uv, rep = real(Vi, Fi, loops, holes, boundary, desc, progress, options)
        if boundary == 'uniform':
            rep['overlaps'] = 1
        return uv, rep
    monkeypatch.setattr(isl, '_flatten_island', fake)
    r = isl.unwrap(V2, F2, boundary='uniform', bound=True)
    # (the second bump is a copy of the first, numbered alike: it takes the first one's pieces)
    assert calls == [('uniform', True), ('area', False)]
    assert r.islands[1]['repeat_of'] and 'repeat_of' not in r.islands[0]
    want = flatten(V, F, boundary='uniform', bound=True).report['bound_vertex']
    assert 0.8 < want < 1
    for rep in r.islands:
        assert rep['boundary_used'] == 'area'
        assert rep['bound_vertex'] == pytest.approx(want, rel=1e-9)


def test_no_area_retry_when_the_uniform_map_already_is_the_area_map(monkeypatch):
    """A uniform attempt whose optimiser fell back to the area map (it folds) is not followed by the
    same area map again."""
    import core.atlas.islands as isl
    V2, F2, _, _ = _two_bumps()
    calls = []
    real = isl._flatten_island

    def fake(Vi, Fi, loops, holes, boundary, desc, progress, options):
        calls.append(boundary)
        uv, rep = real(Vi, Fi, loops, holes, boundary, desc, progress, options)
        rep['flips'], rep['fallback'] = 1, 'area'
        return uv, rep
    monkeypatch.setattr(isl, '_flatten_island', fake)
    r = isl.unwrap(V2, F2, boundary='uniform', bound=True)
    assert calls.count('area') == 0
    assert all(rep['bound_vertex'] is not None for rep in r.islands)


def test_an_overlapping_island_is_split_into_few_charts():
    """A helical ramp of 1.5 turns: its conformal map is uniform (ratio 0.998) but overlaps itself.
    ``unwrap`` splits that map into charts along shortest paths and keeps their coordinates: two
    charts with no flip or overlap (the halving repair made 4 islands here, 976 on a 34k-triangle
    ramp), the scale as uniform as before. Alone (the disk path) or beside another part."""
    from core import unwrap as core_unwrap
    r_, t = np.linspace(1.0, 2.0, 10), np.linspace(0.0, 3 * np.pi, 150)
    R, T = np.meshgrid(r_, t, indexing='ij')
    V = np.stack([R * np.cos(T), R * np.sin(T), 0.3 * T], -1).reshape(-1, 3)
    idx = np.arange(len(V)).reshape(10, 150)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[:-1, 1:].ravel(), idx[1:, 1:].ravel(), idx[1:, :-1].ravel()
    F = np.r_[np.stack([a, b, c], 1), np.stack([a, c, d], 1)]
    for Vx, Fx, want in ((V, F, 2), (np.vstack([V, V + [10.0, 0, 0]]), np.vstack([F, F + len(V)]), 4)):
        r = core_unwrap(Vx, Fx)
        assert len(r.islands) == want
        assert r.report['flips'] == 0 and r.report['overlaps'] == 0 and not r.report['warnings']
        assert r.report['mu_ratio'] > 0.99


def test_coincident_vertices_are_merged_for_unwrap():
    """Vertices at one point joined by an edge of zero length (marching cubes leaves thousands) are
    merged before unwrapping, as the other repairs, on the core's copy: seamed islands and cones give
    the clean mesh's maps, every face is flattened (a collapsed zero-area triangle takes its
    neighbour's corner UVs), ``vert_of[F]`` is the input, and the repair is listed. Unmerged, their
    fake curvature drew the cones (a marching-cubes part: 48 cones and a 1 %/99 % ratio of 0.08 in
    48 s, against 10, 0.56 and 7 s merged)."""
    from meshgen import with_coincident_vertices
    from core import unwrap
    from core.atlas.islands import unwrap as unwrap_islands
    from core.surfaces import blob
    V, F = grid(17)
    V = np.c_[V[:, :2], 0.3 * np.sin(3 * V[:, 0]) * np.cos(2 * V[:, 1])]
    seams = np.array([[8 * 17 + j, 8 * 17 + j + 1] for j in range(16)])      # one row of edges
    clean = unwrap_islands(V, F, seams=seams, boundary='area')
    V2, F2, twin = with_coincident_vertices(V, F, 30, seed=3)
    res = unwrap_islands(V2, F2, seams=seams, boundary='area')
    assert {r['repair']: r['count'] for r in res.report['repairs']} == {'coincident_vertices_merged': 30}
    assert np.array_equal(res.vert_of[res.F], F2) and res.ok.all()
    uvc, uvc0 = res.uv[res.F], clean.uv[clean.F]
    np.testing.assert_allclose(uvc[:len(F)], uvc0, atol=1e-9)      # the same map, corner by corner
    copies = res.F[:len(F)][F2[:len(F)] >= len(V)]
    assert len(copies) and (res.vert_of[copies] >= len(V)).all()
    assert res.report['mu_ratio_worst'] == pytest.approx(clean.report['mu_ratio_worst'], rel=1e-9)
    Vb, Fb = blob(6)
    c0 = unwrap(Vb, Fb, cones='auto')
    Vc, Fc, _ = with_coincident_vertices(Vb, Fb, 60, seed=4)
    c1 = unwrap(Vc, Fc, cones='auto')
    assert c1.report['cones'] == c0.report['cones'] and c1.flattened.all() and c1.report['flips'] == 0
    assert c1.report['mu_ratio_p1_p99'] == pytest.approx(c0.report['mu_ratio_p1_p99'], rel=1e-6)
    assert 'coincident_vertices_merged' in {r['repair'] for r in c1.report['repairs']}



def test_a_dropped_face_on_a_seam_stays_in_one_island():
    """A face naming a seam vertex twice is dropped; its corners take split vertices of one island
    (the one holding copies of most of its corners), so its UVs are a segment of one edge's length
    inside that island. They were each vertex's lowest copy: a segment from one island to the other,
    3.5 times a triangle's size across the layout."""
    V, F = grid(9)
    V = np.c_[V[:, :2], 0.2 * np.sin(2 * V[:, 0])]
    row = np.arange(81).reshape(9, 9)[4]
    seams = np.c_[row[:-1], row[1:]]                       # two islands
    F2 = np.vstack([F, [[40, 40, 49]]])                    # 40 on the seam, 49 above it
    res = unwrap(V, F2, seams=seams, boundary='area')
    ids = res.F[len(F)]
    owner = np.zeros(len(res.vert_of), np.int64)
    owner[res.F[:len(F)].ravel()] = np.repeat(res.face_island[:len(F)], 3)
    assert len(set(owner[ids].tolist())) == 1 and res.face_island[len(F)] == owner[ids[0]]
    seg = np.ptp(res.uv[ids], axis=0).max()
    edge = np.linalg.norm(res.uv[res.F[:len(F), 0]] - res.uv[res.F[:len(F), 1]], axis=1).max()
    assert seg <= edge * (1 + 1e-9)


def test_a_repeated_vertex_face_alone_merges_nothing():
    """A face naming one vertex twice has an edge of zero length from that vertex to itself; it is
    dropped as degenerate, and no 'coincident_vertices_merged' repair with a count of 0 is listed
    beside it (the merge found no two vertices to join)."""
    from core.mesh.repair import repair_merged
    V, F = grid(9)
    F2 = np.vstack([F, [[40, 40, 41]]])
    R, root = repair_merged(V, F2)
    assert root is None
    assert {r['repair']: r['count'] for r in R.repairs} == {'degenerate_faces_dropped': 1}
    res = unwrap(V, F2, boundary='area')
    assert {r['repair'] for r in res.report['repairs']} == {'degenerate_faces_dropped'}


def test_a_triangle_soup_is_laid_out_triangle_by_triangle(monkeypatch):
    """A triangle soup (every triangle its own vertices, as an STL file stores it) is as many islands
    as triangles. Each one-triangle island is laid out as it is, with the report the disk pipeline
    gives it, and without a search for repeats: a 2048-triangle soup took 53 s, each island matched
    against all before it. With automatic seams, each part of one triangle likewise (27 s there)."""
    import core.atlas.islands as islands
    from core.atlas.islands import _flat_island, _solve_island
    from core.atlas.unfold import unfold_flat_disk
    from core.surfaces import make_surface
    V, F = make_surface('bump', 17)
    rng = np.random.default_rng(3)
    F = F[rng.permutation(len(F))]
    Vs, Fs = V[F.ravel()] * 2.5 + [1.0, -2.0, 0.5], np.arange(3 * len(F)).reshape(-1, 3)
    monkeypatch.setattr(islands.Repeats, 'find', lambda *a: pytest.fail("a one-triangle island searched"))
    res = unwrap(Vs, Fs, boundary='uniform', bound=True)
    assert res.report['islands'] == len(Fs) and res.report['flips'] == 0 and res.ok.all()
    e3 = np.linalg.norm(Vs[Fs] - Vs[np.roll(Fs, -1, axis=1)], axis=2)
    W = res.uv[res.F]
    euv = np.linalg.norm(W - np.roll(W, -1, axis=1), axis=2)
    ratio = euv / e3                                     # one scale for the whole layout
    assert np.allclose(ratio, ratio.mean(), rtol=1e-9)
    assert all(r['bound_vertex'] == 1.0 and r['qc_mean'] == 1.0 for r in res.islands)
    # the same report and the same shape as the disk pipeline's, on a triangle and on a bent strip
    strip = (np.array([[0, 0, 0], [1, 0, 0], [0, 1, .2], [1, 1, .3], [0, 2, .5], [1, 2.2, .4], [.1, 3, .9],
                       [1, 3, 1.]]),
             np.array([[0, 1, 3], [0, 3, 2], [2, 3, 5], [2, 5, 4], [4, 5, 7], [4, 7, 6]]))
    one = (np.array([[0.0, 0.0, 0.0], [1.0, 0.2, 0.0], [0.3, 0.8, 0.4]]), np.array([[0, 1, 2]]))
    for P, T in (one, strip):
        uv_fast = unfold_flat_disk(P, T)
        fast = _flat_island(len(T), 'uniform', {'bound': True})
        (_, _, _, uv, rep), = _solve_island(P, T, 'auto', 'uniform', 'x', None, {'bound': True})
        assert set(fast) == set(rep)
        for k in ('flips', 'mu_ratio', 'mu_ratio_p1_p99', 'qc_mean', 'qc_max', 'bound_vertex', 'overlaps',
                  'loops', 'faces'):
            assert fast[k] == pytest.approx(rep[k], abs=1e-9), k
        dist = lambda W: np.linalg.norm(W[:, None] - W[None], axis=2)          # noqa: E731
        assert np.allclose(dist(uv_fast), dist(uv), atol=1e-9)
    # with automatic seams too: each part with no interior vertex as cone_unwrap lays it out
    import core.atlas.cones as cones
    from core.atlas.cones import cone_unwrap, flat_part
    P, T = strip
    full, quick = cone_unwrap(P, T), flat_part(P, T, unfold_flat_disk(P, T))
    d3 = lambda W: np.linalg.norm(W[:, :, None] - W[:, None], axis=3)           # noqa: E731
    assert np.abs(d3(full.uv) - d3(quick.uv)).max() < 1e-9 and set(full.report) == set(quick.report)
    for k, v in full.report.items():
        if k not in ('seconds', 'angle_candidates', 'layouts', 'placement'):
            assert quick.report[k] == (pytest.approx(v, abs=1e-9) if isinstance(v, float) else v), k
    monkeypatch.setattr(cones, 'cone_unwrap', lambda *a, **k: pytest.fail("a one-triangle part placed cones"))
    from core import unwrap as unwrap_any
    res = unwrap_any(Vs, Fs, cones='auto')
    assert res.report['islands'] == len(Fs) and res.report['flips'] == 0 and res.report['cones'] == 0


def test_islands_with_no_interior_vertex_are_unfolded_and_checked():
    """Hair cards (quads and strips bent out of their plane) are unfolded isometrically; a strip that
    would unfold onto itself is not taken (None: the full pipeline splits it), nor is an island with
    an interior vertex."""
    from core.atlas.unfold import unfold_flat_disk
    from core.surfaces import make_surface
    rng = np.random.default_rng(5)
    Vs, Fs = [], []
    for i in range(300):                  # quads of random shape, bent along their diagonal
        P = np.array([[0, 0, 0], [rng.uniform(.05, .2), 0, 0], [.2, rng.uniform(.5, 2), rng.uniform(0, .3)],
                      [0, 1, 0]]) @ np.linalg.qr(rng.normal(size=(3, 3)))[0] + rng.uniform(-5, 5, 3)
        Vs.append(P)
        Fs.append(np.array([[0, 1, 2], [0, 2, 3]]) + 4 * i)
    V, F = np.concatenate(Vs), np.concatenate(Fs)
    res = unwrap(V, F)
    assert res.report['islands'] == 300 and res.report['flips'] == 0
    e3 = np.linalg.norm(V[F] - V[np.roll(F, -1, axis=1)], axis=2)
    W = res.uv[res.F]
    ratio = np.linalg.norm(W - np.roll(W, -1, axis=1), axis=2) / e3
    assert np.allclose(ratio, ratio.mean(), rtol=1e-9)
    # a fan strip turning 1.75 turns round a point: its unfolding overlaps itself
    t = np.linspace(0, 3.5 * np.pi, 36)
    ring = np.c_[np.cos(t), np.sin(t), 0.05 * t]
    Vc = np.r_[ring, 0.5 * ring + [0, 0, 0.3]]
    Fc = np.array([f for i in range(35) for f in ([i, i + 1, 36 + i + 1], [i, 36 + i + 1, 36 + i])])
    assert len(Fc) <= 72 and unfold_flat_disk(Vc, Fc, max_faces=100) is None
    V, F = make_surface('bump', 5)                       # interior vertices
    assert unfold_flat_disk(V, F) is None
    # a side of zero length (coincident vertices) or a collinear triangle: not unfolded
    P = np.array([[0.0, 0, 0], [1, 0, 0], [1, 0, 0], [0, 1, 0]])
    assert unfold_flat_disk(P, np.array([[0, 1, 3], [1, 2, 3]])) is None
    assert unfold_flat_disk(np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0]]), np.array([[0, 1, 2]])) is None


def test_holes_are_cut_open_along_polygon_edges():
    """A quad grid (bump, n = 17) with two square holes, cut open to its outer boundary: the shortest
    paths ran along the quads' diagonals, which split two quads (two of their corners got two UVs,
    which a polygon cannot hold). With the polygons given the cuts keep to polygon edges: no polygon
    is split and no warning; without them the same cut is taken as before."""
    from core import make_surface
    from core import unwrap as core_unwrap
    from core.atlas.unwrap import split_polygons
    n = 17
    V, F = make_surface('bump', n)
    poly = np.arange(len(F)) % ((n - 1) ** 2)                        # triangles t and t + 256: one quad
    qi, qj = poly // (n - 1), poly % (n - 1)
    hole = ((qi >= 4) & (qi < 7) & (qj >= 4) & (qj < 7)) | ((qi >= 10) & (qi < 12) & (qj >= 9) & (qj < 13))
    F, poly = F[~hole], poly[~hole]
    plain = core_unwrap(V, F, holes='cut')
    assert split_polygons(F, poly, plain.uv_corner) == 2
    res = core_unwrap(V, F, holes='cut', tri_poly=poly)
    assert res.report['holes_cut'] == 2 and res.report['split_polygons'] == 0 and not res.warnings
    assert res.report['flips'] == 0 and res.report['mu_ratio'] > 0.9
