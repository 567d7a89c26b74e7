"""Islands, seams, holes, Edit-mode selections, several objects and cancellation in the add-on
(issue 7), against the real bpy module.

The checks are made on the UVs the operator wrote, read back with ``foreach_get``; islands are found
independently of the add-on (core triangulation + ``cut_along_seams`` on the seams read from the
mesh), and overlap between islands is tested exactly (separating axes) on every pair of triangles
from different islands."""
import json
import re
import types

import bpy
import bmesh  # noqa: E402  (importable once bpy is)
import numpy as np
import pytest

from meshgen import two_holes

pytestmark = pytest.mark.bpy


# --- helpers -------------------------------------------------------------------------------------
def loop_uv(me):
    """(c,2) float32 per-corner UVs of the active map (for bitwise comparisons)."""
    buf = np.empty(2 * len(me.loops), np.float32)
    me.uv_layers.active.uv.foreach_get('vector', buf)
    return buf.reshape(-1, 2)


def set_loop_uv(me, uv):
    if not me.uv_layers:
        me.uv_layers.new(name='UVMap')
    me.uv_layers.active.uv.foreach_set('vector', np.ascontiguousarray(uv, np.float32).ravel())


def report_of(me):
    return json.loads(me['conformal_flatten_report'])


def mesh_arrays(me):
    """V (n,3), corner verts (c,), sizes (p,), edges (e,2), seams (e,) bool, from the mesh itself."""
    V = np.empty(3 * len(me.vertices), np.float32)
    me.vertices.foreach_get('co', V)
    cv = np.empty(len(me.loops), np.int32)
    me.loops.foreach_get('vertex_index', cv)
    sizes = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get('loop_total', sizes)
    E = np.empty(2 * len(me.edges), np.int32)
    me.edges.foreach_get('vertices', E)
    seam = np.zeros(len(me.edges), bool)
    me.edges.foreach_get('use_seam', seam)
    return (V.reshape(-1, 3).astype(float), cv.astype(np.int64), sizes.astype(np.int64),
            E.reshape(-1, 2).astype(np.int64), seam)


def islands_of(me, faces=None):
    """Triangles of the mesh (core triangulation), their corner loops, and the island of each, cut
    along the mesh's seams (restricted to the polygons ``faces``, (p,) bool, if given). Returns
    (V, F (m,3) vertex ids, tri_loops (m,3), island (m,), tri_poly (m,))."""
    from conformal_flatten.core.atlas.islands import cut_along_seams
    from conformal_flatten.core.mesh.triangulate import triangulate
    V, cv, sizes, E, seam = mesh_arrays(me)
    tri, tri_poly = triangulate(cv, sizes, V)
    if faces is not None:
        keep = faces[tri_poly]
        tri, tri_poly = tri[keep], tri_poly[keep]
    F = cv[tri]
    S = E[seam]
    S = S[np.isin(S, F).all(1)]
    # keep only seams that are edges of these triangles
    H = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    n = len(V)
    S = S[np.isin(np.sort(S, 1) @ [n, 1], H @ [n, 1])]
    cut = cut_along_seams(F, n, S)
    return V, F, tri, cut.face_island, tri_poly


def signed_areas(W):
    """(m,) signed areas of UV triangles W (m,3,2)."""
    e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def island_measures(V, F, W):
    """core measures of one island given as a triangle soup: V[F] positions, W (m,3,2) UVs."""
    from conformal_flatten.core.mesh.measures import uv_measures
    m = len(F)
    return uv_measures(V[F].reshape(-1, 3), np.arange(3 * m).reshape(m, 3), W.reshape(-1, 2).astype(float))


def overlapping_pairs(W, island, tol=1e-9):
    """Number of pairs of triangles from *different* islands whose UV interiors intersect, by the
    separating axis theorem on all candidate pairs (bounding boxes overlap). W (m,3,2)."""
    W = W.astype(float)
    lo, hi = W.min(1), W.max(1)
    i, j = np.triu_indices(len(W), 1)
    cand = (island[i] != island[j]) & (lo[i, 0] < hi[j, 0]) & (lo[j, 0] < hi[i, 0]) & \
        (lo[i, 1] < hi[j, 1]) & (lo[j, 1] < hi[i, 1])
    i, j = i[cand], j[cand]
    if not len(i):
        return 0
    A, B = W[i], W[j]
    separated = np.zeros(len(i), bool)
    for T in (A, B):
        for k in range(3):
            d = T[:, (k + 1) % 3] - T[:, k]
            axis = np.stack([-d[:, 1], d[:, 0]], 1)
            pa = np.einsum('pvk,pk->pv', A, axis)
            pb = np.einsum('pvk,pk->pv', B, axis)
            scale = np.abs(axis).sum(1) * (np.abs(W).max() + 1)
            separated |= (pa.max(1) <= pb.min(1) + tol * scale) | (pb.max(1) <= pa.min(1) + tol * scale)
    return int((~separated).sum())


def mark_seams(me, pred):
    """Mark as seams the edges whose end points (a, b) (each (e,3)) satisfy ``pred(a, b)``."""
    V, _, _, E, _ = mesh_arrays(me)
    s = pred(V[E[:, 0]], V[E[:, 1]])
    me.edges.foreach_set('use_seam', s)
    me.update()
    return int(s.sum())


def sphere_with_seams(segments=48, rings=24, name=None):
    """Blender's UV sphere with one seam ring (the equator) and one meridian seam (pole to pole)."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=segments, ring_count=rings)
    obj = bpy.context.object
    if name:
        obj.name = obj.data.name = name

    def pred(a, b):
        equator = (np.abs(a[:, 2]) < 1e-4) & (np.abs(b[:, 2]) < 1e-4)
        meridian = (np.abs(a[:, 1]) < 1e-6) & (np.abs(b[:, 1]) < 1e-6) & (a[:, 0] > -1e-6) & (b[:, 0] > -1e-6)
        return equator | meridian
    assert mark_seams(obj.data, pred) == segments + rings
    return obj


def check_islands_layout(me, faces=None, qc_max=1.05, unit=True):
    """Flips, conformality and overlap of the written layout, island by island. Returns the island
    measures."""
    V, F, tri, island, _ = islands_of(me, faces)
    W = loop_uv(me)[tri]
    if unit:
        assert W.min() >= -1e-6 and W.max() <= 1 + 1e-6
    out = []
    for i in np.unique(island):
        t = island == i
        meas = island_measures(V, F[t], W[t])
        assert meas['flips'] == 0, (i, meas)
        assert meas['qc_mean'] <= qc_max, (i, meas)
        assert (signed_areas(W[t]) > 0).all()          # counter-clockwise, not mirrored
        out.append(meas)
    assert overlapping_pairs(W, island) == 0
    return out


# --- islands from seams ----------------------------------------------------------------------------
def test_uv_sphere_equator_and_meridian_seams(addon, bl):
    """Acceptance: a UV sphere with one seam ring and one meridian seam, flattened as islands: every
    island 0 flips and qc_mean <= 1.05, the packed islands do not overlap, relative scale kept."""
    obj = sphere_with_seams(48, 24)
    me = obj.data
    assert bpy.ops.uv.conformal_flatten(boundary='UNIFORM') == {'FINISHED'}
    rep = report_of(me)
    assert rep['islands'] == 2 and rep['packer'] == 'pack_islands' and rep['flips'] == 0
    meas = check_islands_layout(me)
    assert len(meas) == 2
    # the two hemispheres are congruent: with one texel density they get the same UV area
    V, F, tri, island, _ = islands_of(me)
    a = [signed_areas(loop_uv(me)[tri][island == i]).sum() for i in (0, 1)]
    assert a[0] == pytest.approx(a[1], rel=1e-3)
    # each island is a disk cut open along its meridian: the seam corners got two UVs
    W = loop_uv(me)
    _, cv, _, _, _ = mesh_arrays(me)
    split = [v for v in range(len(V)) if np.ptp(W[cv == v], axis=0).max() > 1e-4]
    assert len(split) >= 48 + 24 - 2


def test_default_uv_sphere_all_modes(addon, bl):
    """Blender's default UV sphere (32 x 16) in every boundary mode: qc_mean is limited by the
    coarse triangulation (about 1.0499 here), still <= 1.05; shelf packing (fast) also has no
    overlap."""
    obj = sphere_with_seams(32, 16)
    for boundary in ('AREA', 'FREE', 'UNIFORM'):
        bpy.ops.uv.conformal_flatten(boundary=boundary, packer='SHELF')
        assert report_of(obj.data)['packer'] == 'shelf'
        check_islands_layout(obj.data)


def test_closed_mesh_cut_by_one_slit_is_one_disk(addon, bl):
    """A closed sphere with only a meridian seam (pole to pole) is one island, opened along the slit."""
    bpy.ops.mesh.primitive_uv_sphere_add(segments=32, ring_count=16)
    me = bpy.context.object.data
    mark_seams(me, lambda a, b: (np.abs(a[:, 1]) < 1e-6) & (np.abs(b[:, 1]) < 1e-6) &
               (a[:, 0] > -1e-6) & (b[:, 0] > -1e-6))
    bpy.ops.uv.conformal_flatten(boundary='AREA')
    rep = report_of(me)
    assert rep['islands'] == 1 and rep['flips'] == 0
    check_islands_layout(me, qc_max=1.2)


def test_suzanne_island_by_island(addon, bl):
    """Acceptance: Blender's monkey. Without seams it has 3 islands (two eyes, the head with an open
    eye socket): hole filling off gives a clear ERROR naming the island that is not a disk, with
    hole filling it is flattened island by island; with seams marked on the symmetry plane the head
    becomes two islands."""
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.object
    me = obj.data
    before = bl.mesh_snapshot(me)
    with pytest.raises(RuntimeError, match=r"island 3 of 3 \(856 triangles, e\.g\. polygon \d+\) has 2 "
                                           r"boundary loops.*set Holes to Automatic, Fill or Cut"):
        bpy.ops.uv.conformal_flatten(boundary='AREA', holes='ERROR')
    bl.assert_same(before, bl.mesh_snapshot(me))
    bpy.ops.uv.conformal_flatten(boundary='AREA', holes='FILL')
    rep = report_of(me)
    assert rep['islands'] == 3 and rep['holes_filled'] == 1 and rep['flips'] == 0
    # Suzanne is coarse: the eyes (56 triangles each) are far from conformal at this resolution
    check_islands_layout(me, qc_max=1.8)
    n = mark_seams(me, lambda a, b: (np.abs(a[:, 0]) < 1e-5) & (np.abs(b[:, 0]) < 1e-5))
    assert n > 0
    bpy.ops.uv.conformal_flatten(boundary='UNIFORM', pack_shape='CONCAVE', holes='FILL')
    rep = report_of(me)
    assert rep['islands'] == 4 and rep['holes_filled'] == 2 and rep['flips'] == 0
    assert [r['triangles'] for r in rep['island_reports']] == [56, 56, 428, 428]
    check_islands_layout(me, qc_max=1.5)


def test_holes_automatic_cuts_a_tube_open(addon, bl):
    """Holes default to Automatic: an island with holes is flattened both ways and the better map
    kept. Blender's cylinder without caps (a tube: two boundary loops) filled gives a map far from
    conformal (qc_mean 2.26, warned; the default before); cut open it is a rectangle, isometric."""
    bpy.ops.mesh.primitive_cylinder_add(end_fill_type='NOTHING')
    me = bpy.context.object.data
    bpy.ops.uv.conformal_flatten(holes='FILL')
    filled = report_of(me)
    assert filled['holes_filled'] == 1 and filled['qc_mean'] > 1.5 and filled['warnings']
    bpy.ops.uv.conformal_flatten()
    rep = report_of(me)
    assert rep['holes_cut'] == 1 and rep['holes_filled'] == 0 and rep['flips'] == 0
    assert rep['qc_mean'] < 1 + 1e-6 and rep['mu_ratio'] > 1 - 1e-6 and not rep['warnings']


def test_cut_holes_and_skip_bad_islands(addon, bl):
    bpy.ops.mesh.primitive_monkey_add()
    me = bpy.context.object.data
    bpy.ops.uv.conformal_flatten(boundary='AREA', holes='CUT', packer='SHELF')
    rep = report_of(me)
    assert rep['holes_cut'] == 1 and rep['holes_filled'] == 0 and rep['flips'] == 0
    # skip: the head keeps its UVs bit for bit, the eyes are flattened, a WARNING says so
    old = np.random.default_rng(1).random((len(me.loops), 2)).astype(np.float32)
    set_loop_uv(me, old)
    bpy.ops.uv.conformal_flatten(boundary='AREA', holes='ERROR', skip_bad_islands=True)
    rep = report_of(me)
    assert rep['islands'] == 3 and rep['islands_failed'] == 1
    assert 'boundary loops' in rep['island_reports'][2]['error']
    _, _, tri, island, _ = islands_of(me)
    W = loop_uv(me)
    head = np.unique(tri[island == 2])
    np.testing.assert_array_equal(W[head], old[head])
    eyes = np.unique(tri[island != 2])
    assert not np.isin(eyes, head).any() and (W[eyes] != old[eyes]).any(1).all()


def test_two_holes_filled(addon, bl):
    """Acceptance: a mesh with two holes is flattened with hole filling: 0 flips; the measures and
    the baked mu are on the real faces only; the report says what was done."""
    V, F = two_holes('bump', 33)
    obj = bl.mesh_object('holes', V.astype(np.float32).astype(float), F)
    me = obj.data
    assert bpy.ops.uv.conformal_flatten(boundary='UNIFORM', holes='FILL') == {'FINISHED'}
    rep = report_of(me)
    assert rep['holes_filled'] == 2 and rep['islands'] == 1 and rep['flips'] == 0
    assert rep['triangles'] == len(F)
    assert rep['island_reports'][0]['holes']['filled'] == 2
    from conformal_flatten.addon.report import summary_line
    assert 'filled 2 holes' in summary_line(rep)
    W = loop_uv(me)[np.arange(3 * len(F)).reshape(-1, 3)]       # triangles: corners in order
    meas = island_measures(V, F, W)
    assert meas['flips'] == 0 and meas['qc_mean'] < 1.05
    assert rep['mu_ratio'] == pytest.approx(meas['mu_ratio'], rel=1e-4)
    mu = np.empty(len(V), np.float32)
    me.attributes['conformal_factor'].data.foreach_get('value', mu)
    assert np.isfinite(mu).all()
    # filling off: an error naming the three loops, data unchanged
    before = bl.mesh_snapshot(me)
    with pytest.raises(RuntimeError, match='3 boundary loops'):
        bpy.ops.uv.conformal_flatten(boundary='AREA', holes='ERROR')
    bl.assert_same(before, bl.mesh_snapshot(me))


# --- scale between islands -------------------------------------------------------------------------
def _two_squares(bl):
    """Two loose flat squares, 1 x 1 and 2 x 2 (3D areas 1 and 4), as one mesh."""
    n = 5
    t = np.linspace(0, 1, n)
    X, Y = np.meshgrid(t, t)
    P = np.stack([X.ravel(), Y.ravel(), np.zeros(n * n)], 1)
    quads = [[i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j]
             for i in range(n - 1) for j in range(n - 1)]
    V = np.vstack([P, 2 * P + [3, 0, 0]])
    polys = quads + [[v + n * n for v in q] for q in quads]
    return bl.mesh_object('squares', V, polys)


@pytest.mark.parametrize('packer', ['BLENDER', 'SHELF'])
def test_relative_scale_kept_or_normalised(addon, bl, packer):
    obj = _two_squares(bl)
    me = obj.data
    V, F, tri, island, _ = islands_of(me)
    area3 = [0.5 * np.linalg.norm(np.cross(V[F[island == i][:, 1]] - V[F[island == i][:, 0]],
                                           V[F[island == i][:, 2]] - V[F[island == i][:, 0]]), axis=1).sum()
             for i in (0, 1)]
    assert area3 == pytest.approx([1, 4])
    bpy.ops.uv.conformal_flatten(boundary='AREA', packer=packer)
    W = loop_uv(me)[tri]
    a = [signed_areas(W[island == i]).sum() for i in (0, 1)]
    assert a[1] / a[0] == pytest.approx(4.0, rel=1e-4)          # one texel density
    assert overlapping_pairs(W, island) == 0
    bpy.ops.uv.conformal_flatten(boundary='AREA', packer=packer, keep_relative_scale=False)
    W = loop_uv(me)[tri]
    a = [signed_areas(W[island == i]).sum() for i in (0, 1)]
    assert a[1] / a[0] == pytest.approx(1.0, rel=1e-4)          # every island the same UV area
    assert report_of(me)['relative_scale'] == 'normalised'
    assert overlapping_pairs(W, island) == 0


def test_true_scale_islands(addon, bl):
    obj = _two_squares(bl)
    me = obj.data
    bpy.ops.uv.conformal_flatten(boundary='AREA', fit='TRUE_SCALE')
    V, F, tri, island, _ = islands_of(me)
    W = loop_uv(me)[tri]
    assert signed_areas(W).sum() == pytest.approx(5.0, rel=1e-4)
    assert overlapping_pairs(W, island) == 0


# --- Edit-mode selection ---------------------------------------------------------------------------
def _select_faces(obj, faces):
    """Select exactly the polygons ``faces`` ((p,) bool) in Edit mode (face select mode)."""
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.context.tool_settings.mesh_select_mode = (False, False, True)
    bm = bmesh.from_edit_mesh(obj.data)
    bm.faces.ensure_lookup_table()
    for f in bm.faces:
        f.select_set(False)
    for f in bm.faces:
        if faces[f.index]:
            f.select_set(True)
    bm.select_flush_mode()
    bmesh.update_edit_mesh(obj.data)


def _selection_attrs(me):
    from conformal_flatten.addon import meshio
    return meshio.save_attributes(me)


@pytest.mark.parametrize('packer', ['BLENDER', 'SHELF'])
def test_edit_mode_selection_leaves_other_uvs_bitwise(addon, bl, packer):
    """Acceptance: in Edit mode only the selected faces are flattened (here islands: the part of a
    seamed sphere north of z = -0.5, so both hemispheres, one of them clipped); the UVs of every
    unselected face are bitwise unchanged; the selection itself is unchanged."""
    obj = sphere_with_seams(32, 16)
    me = obj.data
    rng = np.random.default_rng(0)
    old = rng.random((len(me.loops), 2)).astype(np.float32)
    old[5] = [np.float32(1e-30), np.float32(-0.0)]      # odd values survive bit for bit
    set_loop_uv(me, old)
    centres = np.empty(3 * len(me.polygons), np.float32)
    me.polygons.foreach_get('center', centres)
    faces = centres.reshape(-1, 3)[:, 2] > -0.5
    assert 0 < faces.sum() < len(faces)
    _select_faces(obj, faces)
    bpy.ops.object.mode_set(mode='OBJECT')
    sel_before = _selection_attrs(me)
    bpy.ops.object.mode_set(mode='EDIT')
    assert bpy.ops.uv.conformal_flatten(boundary='AREA', packer=packer) == {'FINISHED'}
    assert obj.mode == 'EDIT'
    bpy.ops.object.mode_set(mode='OBJECT')
    sel_after = _selection_attrs(me)
    assert sel_before.keys() == sel_after.keys()
    for k, v in sel_before.items():
        if v is None:
            assert sel_after[k] is None, k
        else:
            assert v[0] == sel_after[k][0] and np.array_equal(v[1], sel_after[k][1]), k
    W = loop_uv(me)
    sizes = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get('loop_total', sizes)
    corner_sel = np.repeat(faces, sizes)
    assert np.array_equal(W[~corner_sel].view(np.uint32), old[~corner_sel].view(np.uint32))
    assert (W[corner_sel] != old[corner_sel]).any(1).mean() > 0.99
    rep = report_of(me)
    assert rep['selection'] == 'selected faces' and rep['flattened_polygons'] == int(faces.sum())
    assert rep['islands'] == 2 and rep['flips'] == 0
    assert rep['packer'] == {'BLENDER': 'pack_islands', 'SHELF': 'shelf'}[packer]
    check_islands_layout(me, faces=faces, qc_max=1.05)


def test_edit_mode_selection_single_disk(addon, bl):
    """A selection that is one disk without seams: flattened directly (core.disk.flatten), fitted to the
    unit square; the rest untouched; the baked mu is new on the selection's vertices only."""
    from conformal_flatten.core.surfaces import make_surface
    V, F = make_surface('bump', 17)
    obj = bl.mesh_object('bump', V.astype(np.float32).astype(float), F)
    me = obj.data
    old = np.full((len(me.loops), 2), 0.25, np.float32)
    set_loop_uv(me, old)
    faces = V[F].mean(1)[:, 0] < 0.3
    _select_faces(obj, faces)
    bpy.ops.uv.conformal_flatten(boundary='AREA')
    bpy.ops.object.mode_set(mode='OBJECT')
    W = loop_uv(me).reshape(-1, 3, 2)
    np.testing.assert_array_equal(W[~faces], old.reshape(-1, 3, 2)[~faces])
    rep = report_of(me)
    assert rep['islands'] == 1 and rep['packer'] == 'none' and rep['bound_vertex'] is None
    assert rep['triangles'] == int(faces.sum())
    assert W[faces].min() >= -1e-6 and W[faces].max() <= 1 + 1e-6
    assert (signed_areas(W[faces]) > 0).all()
    mu = np.empty(len(V), np.float32)
    me.attributes['conformal_factor'].data.foreach_get('value', mu)
    inside = np.zeros(len(V), bool)
    inside[F[faces].ravel()] = True
    assert np.isfinite(mu[inside]).all() and np.isnan(mu[~inside]).all()


def test_edit_mode_nothing_selected_flattens_everything(addon, bl):
    obj = sphere_with_seams(32, 16)
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_all(action='DESELECT')
    bpy.ops.uv.conformal_flatten(boundary='AREA', packer='SHELF')
    bpy.ops.object.mode_set(mode='OBJECT')
    rep = report_of(obj.data)
    assert rep['selection'] == 'all (no face selected)' and rep['islands'] == 2
    assert rep['triangles'] == len(islands_of(obj.data)[1])


# --- several objects ---------------------------------------------------------------------------------
def test_several_objects_and_linked_duplicate(addon, bl):
    """Acceptance: two objects and a linked duplicate of one of them, flattened in one call; the
    shared mesh once."""
    from conformal_flatten.addon import job, targets
    from conformal_flatten.core.surfaces import make_surface
    sphere = sphere_with_seams(32, 16, name='Ball')
    dup = sphere.copy()                       # linked duplicate: shares sphere.data
    dup.location.x += 3
    bpy.context.scene.collection.objects.link(dup)
    V, F = make_surface('bump', 13)
    grid = bl.mesh_object('Grid', V, F)       # active and selected alone
    sphere.select_set(True)
    dup.select_set(True)
    found = targets.target_objects(bpy.context)
    assert [o.name for o, _ in found] == ['Grid', 'Ball']
    assert found[1][1] == ['Ball', dup.name]
    calls = []
    real = job.compute_job

    def counting(j, *a, **k):
        calls.append(j.obj.data.name)
        return real(j, *a, **k)
    job.compute_job = counting
    try:
        assert bpy.ops.uv.conformal_flatten(boundary='AREA') == {'FINISHED'}
    finally:
        job.compute_job = real
    assert sorted(calls) == ['Ball', 'Grid']                  # the shared mesh once
    assert report_of(sphere.data)['objects'] == ['Ball', dup.name]
    assert report_of(sphere.data)['packer'] == 'pack_islands'     # with another object active
    assert report_of(grid.data)['islands'] == 1
    check_islands_layout(sphere.data)
    assert {o.name for o in bpy.context.selected_objects} == {'Grid', 'Ball', dup.name}
    assert bpy.context.view_layer.objects.active == grid


def test_several_objects_shared_layout_and_bad_one(addon, bl):
    """shared_layout packs both meshes into one UV square without overlap; a bad object among the
    selected ones stops the whole call with its name and writes nothing."""
    a = sphere_with_seams(32, 16, name='A')
    b = sphere_with_seams(32, 16, name='B')
    b.location.x = 3
    a.select_set(True)
    bpy.ops.uv.conformal_flatten(boundary='AREA', shared_layout=True)
    assert report_of(a.data)['packer'] == report_of(b.data)['packer'] == 'pack_islands'
    Wa, Wb = loop_uv(a.data), loop_uv(b.data)
    _, _, ta, ia, _ = islands_of(a.data)
    _, _, tb, ib, _ = islands_of(b.data)
    W = np.concatenate([Wa[ta], Wb[tb]])
    assert overlapping_pairs(W, np.concatenate([ia, ib + 10])) == 0
    # scale kept across the two meshes: congruent spheres get the same total UV area
    assert signed_areas(Wa[ta]).sum() == pytest.approx(signed_areas(Wb[tb]).sum(), rel=1e-3)
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, location=(6, 0, 0))   # closed
    c = bpy.context.object
    a.select_set(True)
    b.select_set(True)
    before = bl.all_meshes_snapshot()
    with pytest.raises(RuntimeError, match=r"object 'Sphere': island 1 of 1 .* is closed"):
        bpy.ops.uv.conformal_flatten(boundary='AREA')
    after = bl.all_meshes_snapshot()
    for name in before:
        bl.assert_same(before[name], after[name])
    assert c.mode == 'OBJECT'


@pytest.mark.parametrize('packer', ['BLENDER', 'SHELF'])
def test_multi_object_edit_mode(addon, bl, packer):
    """Two objects in Edit mode, each with its own face selection: both flattened, both stay in Edit
    mode."""
    a = sphere_with_seams(32, 16, name='A')
    b = sphere_with_seams(32, 16, name='B')
    b.location.x = 3
    a.select_set(True)
    bpy.context.view_layer.objects.active = a
    bpy.ops.object.mode_set(mode='EDIT')
    assert a.mode == b.mode == 'EDIT'
    bpy.ops.mesh.select_all(action='SELECT')
    bpy.ops.uv.conformal_flatten(boundary='AREA', packer=packer)
    assert a.mode == b.mode == 'EDIT'
    assert bpy.context.view_layer.objects.active == a
    bpy.ops.object.mode_set(mode='OBJECT')
    for o in (a, b):
        assert report_of(o.data)['islands'] == 2
        assert report_of(o.data)['packer'] == {'BLENDER': 'pack_islands', 'SHELF': 'shelf'}[packer]
        check_islands_layout(o.data)


# --- packing fallback -------------------------------------------------------------------------------
def test_pack_islands_failure_falls_back_to_shelf(addon, bl, monkeypatch):
    from conformal_flatten.addon import report, targets
    obj = sphere_with_seams(32, 16)
    me = obj.data
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.object.mode_set(mode='OBJECT')
    sel_before = _selection_attrs(me)
    def broken(context, objs):
        raise RuntimeError("Error: simulated poll failure")
    monkeypatch.setattr(targets, 'in_edit_mode', broken)
    assert bpy.ops.uv.conformal_flatten(boundary='AREA') == {'FINISHED'}
    rep = report_of(me)
    assert rep['packer'] == 'shelf' and 'simulated poll failure' in rep['pack_note']
    assert any('shelf' in w for w in report.warnings_of([rep]))
    check_islands_layout(me)
    sel_after = _selection_attrs(me)
    for k, v in sel_before.items():
        assert (v is None) == (sel_after[k] is None), k
        if v is not None:
            assert np.array_equal(v[1], sel_after[k][1]), k


# --- cancellation (function level: modal timers never fire in background mode) ------------------------
def _run_for_active(pkg, **opts):
    from conformal_flatten.addon import ops_flatten
    return ops_flatten.FlattenRun(bpy.context, ops_flatten.FlattenOptions(**opts))


def test_cancel_between_islands_writes_nothing(addon, bl):
    from conformal_flatten.addon.ops_flatten import Cancelled
    obj = sphere_with_seams(32, 16)
    before = bl.all_meshes_snapshot()
    run = _run_for_active(addon, boundary='AREA')
    run.read(bpy.context)
    seen = []

    def progress(f, msg):
        seen.append(msg)
        if msg.startswith('island 2/'):
            run.cancel()
    with pytest.raises(Cancelled):
        run.compute(progress)
    assert any(m.startswith('island 1/') for m in seen)
    assert run.results is None
    with pytest.raises(Cancelled):
        run.apply(bpy.context)
    after = bl.all_meshes_snapshot()
    for name in before:
        bl.assert_same(before[name], after[name])
    assert obj.mode == 'OBJECT'


def test_worker_thread_result_equals_synchronous(addon, bl):
    obj = sphere_with_seams(32, 16)
    bpy.ops.uv.conformal_flatten(boundary='AREA', packer='SHELF')
    sync = loop_uv(obj.data).copy()
    set_loop_uv(obj.data, np.zeros_like(sync))
    run = _run_for_active(addon, boundary='AREA', packer='SHELF')
    run.read(bpy.context)
    run.start()
    run.thread.join(60)
    assert run.done and run.error is None and run.fraction == pytest.approx(1.0)
    run.apply(bpy.context)
    np.testing.assert_array_equal(loop_uv(obj.data), sync)


def test_modal_escape_and_timer(addon, bl):
    """The modal handler's logic, driven with stand-in events: Esc cancels the worker (nothing is
    written, even if the worker finishes later); a timer tick after the worker is done applies."""
    from conformal_flatten.addon.ops_flatten import UV_OT_conformal_flatten
    obj = sphere_with_seams(32, 16)
    before = bl.all_meshes_snapshot()
    reports = []
    timer = object()

    def fake_operator(run):
        return types.SimpleNamespace(_run=run, _timer=None,
                                     report=lambda kind, msg: reports.append((kind, msg)),
                                     _cleanup=lambda ctx: None, _done=lambda r: {'FINISHED'})
    run = _run_for_active(addon, boundary='AREA')
    run.read(bpy.context)
    run.start()
    op = fake_operator(run)
    esc = types.SimpleNamespace(type='ESC', value='PRESS')
    assert UV_OT_conformal_flatten.modal(op, bpy.context, esc) == {'CANCELLED'}
    run.thread.join(60)
    assert reports[-1][0] == {'WARNING'} and 'nothing was written' in reports[-1][1]
    after = bl.all_meshes_snapshot()
    for name in before:
        bl.assert_same(before[name], after[name])
    run = _run_for_active(addon, boundary='AREA')
    run.read(bpy.context)
    run.start()
    run.thread.join(60)
    op = fake_operator(run)
    op._timer = timer
    other = types.SimpleNamespace(type='MOUSEMOVE', value='NOTHING')
    assert UV_OT_conformal_flatten.modal(op, bpy.context, other) == {'RUNNING_MODAL'}
    tick = types.SimpleNamespace(type='TIMER', value='NOTHING', timer=timer)
    assert UV_OT_conformal_flatten.modal(op, bpy.context, tick) == {'FINISHED'}
    assert report_of(obj.data)['islands'] == 2


def test_invoke_in_background_runs_execute(addon, bl):
    obj = sphere_with_seams(32, 16)
    assert bpy.ops.uv.conformal_flatten('INVOKE_DEFAULT', boundary='AREA', packer='SHELF') == {'FINISHED'}
    assert report_of(obj.data)['islands'] == 2


def test_operator_properties(addon):
    props = bpy.ops.uv.conformal_flatten.get_rna_type().properties
    assert props['holes'].default == 'AUTO' and props['keep_relative_scale'].default is True
    assert {i.identifier for i in props['holes'].enum_items} == {'AUTO', 'FILL', 'CUT', 'ERROR'}
    assert props['skip_bad_islands'].default is False
    assert props['packer'].default == 'BLENDER'
    assert {i.identifier for i in props['pack_shape'].enum_items} == {'CONCAVE', 'CONVEX', 'AABB'}
    assert props['pack_shape'].default == 'AABB'          # as Blender's Unwrap packs


def test_redo_panel_draws_every_option(addon):
    """``draw`` of the redo panel (UILayout cannot be created headless: a stand-in records the calls)."""
    from conformal_flatten.addon.ops_flatten import UV_OT_conformal_flatten
    drawn = []

    class Layout:
        use_property_split = False
        active = True

        def column(self, **k):
            return Layout()
        row = column

        def prop(self, data, name, **k):
            drawn.append(name)
    props = bpy.ops.uv.conformal_flatten.get_rna_type().properties
    names = [p.identifier for p in props if p.identifier != 'rna_type']
    fake = types.SimpleNamespace(layout=Layout(), **{n: props[n].default for n in names})
    UV_OT_conformal_flatten.draw(fake, bpy.context)
    assert sorted(drawn) == sorted(names)


def test_loose_edge_ignored_and_listed(addon, bl):
    """A loose edge (in no face) is ignored: the faces are flattened, the mesh's geometry is unchanged,
    and the report lists the repair; an Edit-mode face selection ignores it too."""
    from conformal_flatten.core.surfaces import make_surface
    V, F = make_surface('bump', 9)
    me = bpy.data.meshes.new('loose')
    n = len(V)
    me.from_pydata(np.vstack([V, [[3, 3, 0], [4, 3, 0]]]).tolist(), [(n, n + 1), (0, 10)], F.tolist())
    obj = bpy.data.objects.new('loose', me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    co = np.zeros(3 * len(me.vertices))
    me.vertices.foreach_get('co', co)
    n_edges = len(me.edges)
    assert bpy.ops.uv.conformal_flatten(boundary='AREA') == {'FINISHED'}
    rep = report_of(me)
    assert rep['flips'] == 0 and any('loose' in r['repair'] for r in rep['repairs'])
    co2 = np.zeros(3 * len(me.vertices))
    me.vertices.foreach_get('co', co2)
    assert (co == co2).all() and len(me.edges) == n_edges          # the user's mesh is untouched
    _select_faces(obj, np.ones(len(F), bool) & (V[F].mean(1)[:, 0] < 0))
    assert bpy.ops.uv.conformal_flatten(boundary='AREA') == {'FINISHED'}
    bpy.ops.object.mode_set(mode='OBJECT')
    assert report_of(me)['selection'] == 'selected faces'


def test_sidebar_islands_section(addon, bl):
    from conformal_flatten.addon import sidebar, ui
    assert any(d is ui.draw_islands_section for _, d in sidebar.sections())
    labels = []

    class Layout:
        def column(self, **k):
            return self
        row = column

        def label(self, text='', **k):
            labels.append(text)
    bpy.ops.mesh.primitive_monkey_add()
    ui.draw_islands_section(Layout(), bpy.context)
    assert labels == ["Seams split the mesh into islands"]
    bpy.ops.uv.conformal_flatten(boundary='AREA', packer='SHELF', holes='FILL')
    labels.clear()
    ui.draw_islands_section(Layout(), bpy.context)
    assert labels == ["Islands", "3", "Holes", "1 filled", "Faces", "all", "Packing", "shelf",
                      "Objects", "1"]


def test_skip_bad_islands_skips_a_closed_object(addon, bl, capfd):
    """Issue 12: with Skip Bad Islands a closed object among the selected ones is skipped with a
    WARNING (its data untouched); the other objects are flattened."""
    a = sphere_with_seams(32, 16, name='A')
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8, location=(6, 0, 0))   # closed
    c = bpy.context.object
    a.select_set(True)
    before = bl.mesh_snapshot(c.data)
    capfd.readouterr()
    assert bpy.ops.uv.conformal_flatten(boundary='AREA', skip_bad_islands=True) == {'FINISHED'}
    out = capfd.readouterr().out
    assert re.search(r"Warning: skipped object 'Sphere': island 1 of 1 .* is closed.*Mark Seam", out), out
    bl.assert_same(before, bl.mesh_snapshot(c.data))
    rep = report_of(a.data)
    assert rep['islands'] == 2 and rep['flips'] == 0
    assert rep['skipped_objects'][0]['object'] == 'Sphere'
    assert rep['skipped_objects'][0]['error_code'] == 'no_boundary'
    check_islands_layout(a.data)
    # alone, the closed object is still an error (nothing can be flattened)
    for o in bpy.context.view_layer.objects:
        o.select_set(o is c)
    bpy.context.view_layer.objects.active = c
    with pytest.raises(RuntimeError, match='is closed'):
        bpy.ops.uv.conformal_flatten(boundary='AREA', skip_bad_islands=True)
