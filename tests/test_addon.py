"""The Blender add-on against the real bpy module: registration, the flatten operator's UVs and baked
attributes against the core, modes, modifiers, and failures that must leave every data array as it was.

Note: ``ed.undo`` cannot run in background mode (its poll fails, checked below), so undo itself is not
exercised here; the operator's {'REGISTER', 'UNDO'} flags are, and so is the property undo relies on
for failures: nothing is written unless the whole computation succeeded."""
import bpy
import json
import os

import numpy as np
import pytest

pytestmark = pytest.mark.bpy

N = 25          # bump grid size: 1152 triangles, fast enough to run every mode


def core_of(pkg):
    from conformal_flatten.core.disk.flatten import flatten
    from conformal_flatten.core.surfaces import make_surface
    from conformal_flatten.core.mesh.triangulate import triangulate
    return flatten, make_surface, triangulate


def bump_object(bl, n=N, name='bump'):
    from conformal_flatten.core.surfaces import make_surface
    V, F = make_surface('bump', n)
    V = V.astype(np.float32).astype(float)     # what Blender stores
    return bl.mesh_object(name, V, F), V, F


def loop_uv(me):
    buf = np.empty(len(me.loops) * 2, np.float32)
    me.uv_layers.active.uv.foreach_get('vector', buf)
    return buf.reshape(-1, 2).astype(float)


def corner_verts(me):
    buf = np.empty(len(me.loops), np.int32)
    me.attributes['.corner_vert'].data.foreach_get('value', buf)
    return buf.astype(np.int64)


def sizes_of(me):
    buf = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get('loop_total', buf)
    return buf.astype(np.int64)


def point_attr(me, name, field, width):
    a = me.attributes[name]
    buf = np.empty(len(a.data) * width, np.float32)
    a.data.foreach_get(field, buf)
    return buf.reshape(-1, width) if width > 1 else buf


def quad_ngon_mesh():
    """A 5x5-vertex grid of quads whose central 2x2 block of quads is one octagon (centre vertex
    removed, then unused vertices dropped), lifted into a bump. Polygons counter-clockwise."""
    n = 5
    t = np.linspace(-1, 1, n)
    X, Y = np.meshgrid(t, t)
    V = np.stack([X.ravel(), Y.ravel(), 0.4 * np.exp(-(X**2 + Y**2)).ravel()], 1)
    idx = lambda i, j: i * n + j
    polys = []
    for i in range(n - 1):
        for j in range(n - 1):
            if 1 <= i <= 2 and 1 <= j <= 2:
                continue
            polys.append([idx(i, j), idx(i, j + 1), idx(i + 1, j + 1), idx(i + 1, j)])
    ring = [idx(1, 1), idx(1, 2), idx(1, 3), idx(2, 3), idx(3, 3), idx(3, 2), idx(3, 1), idx(2, 1)]
    polys.append(ring)
    centre = idx(2, 2)
    keep = np.ones(len(V), bool)
    keep[centre] = False
    remap = np.cumsum(keep) - 1
    return V[keep].astype(np.float32).astype(float), [[int(remap[v]) for v in p] for p in polys]


# --- registration --------------------------------------------------------------------------------
def test_register_unregister_twice(blank_blender):
    pkg = blank_blender
    from conformal_flatten.addon import ops_flatten
    for _ in range(2):
        pkg.register()
        assert hasattr(bpy.types, 'UV_OT_conformal_flatten')
        assert hasattr(bpy.types, 'VIEW3D_PT_conformal_flatten')
        assert hasattr(bpy.types, 'IMAGE_PT_conformal_flatten')
        assert hasattr(bpy.types.Scene, 'conformal_flatten')
        assert ops_flatten.menu_unwrap in bpy.types.IMAGE_MT_uvs_unwrap._dyn_ui_initialize()
        pkg.unregister()
        assert not hasattr(bpy.types, 'UV_OT_conformal_flatten')
        assert not hasattr(bpy.types, 'VIEW3D_PT_conformal_flatten')
        assert not hasattr(bpy.types.Scene, 'conformal_flatten')
        assert ops_flatten.menu_unwrap not in bpy.types.IMAGE_MT_uvs_unwrap._dyn_ui_initialize()


def test_operator_flags(addon):
    assert bpy.types.UV_OT_conformal_flatten.bl_options == {'REGISTER', 'UNDO'}
    assert bpy.ops.uv.conformal_flatten.bl_options == {'REGISTER', 'UNDO'}
    props = bpy.ops.uv.conformal_flatten.get_rna_type().properties
    assert {i.identifier for i in props['boundary'].enum_items} == {'UNIFORM', 'AREA', 'FREE'}
    assert {i.identifier for i in props['fit'].enum_items} == {'UNIT_SQUARE', 'TRUE_SCALE'}
    assert props['bake'].default is True


def test_undo_not_runnable_headless(addon):
    # Documented limitation (docs/blender.md): undo needs a GUI session, so it is not tested here.
    assert bpy.app.background
    assert not bpy.ops.ed.undo.poll()


# --- results against the core --------------------------------------------------------------------
@pytest.mark.parametrize('boundary', ['AREA', 'FREE', 'UNIFORM'])
def test_bump_uvs_match_core(addon, bl, boundary):
    flatten, _, _ = core_of(addon)
    obj, V, F = bump_object(bl)
    assert not obj.data.uv_layers                 # "UVMap" must be created
    assert bpy.ops.uv.conformal_flatten(boundary=boundary, fit='UNIT_SQUARE') == {'FINISHED'}
    me = obj.data
    assert me.uv_layers.active.name == 'UVMap'
    ref = flatten(V, F, boundary=boundary.lower(), fit='unit_square')
    np.testing.assert_allclose(loop_uv(me), ref.uv[corner_verts(me)], atol=2e-6)
    rep = addon.addon.meshio.load_report(me, 'conformal_flatten_report')
    assert rep['flips'] == 0 == ref.report['flips']
    assert rep['mu_ratio'] == pytest.approx(ref.report['mu_ratio'], rel=1e-12)
    uv = loop_uv(me)
    assert uv.min() >= -1e-6 and uv.max() <= 1 + 1e-6


def test_true_scale_area(addon, bl):
    from conformal_flatten.core.mesh.geometry import face_areas
    obj, V, F = bump_object(bl)
    bpy.ops.uv.conformal_flatten(boundary='AREA', fit='TRUE_SCALE', bake=False)
    me = obj.data
    W = loop_uv(me)
    cv = corner_verts(me)
    UVv = np.zeros((len(V), 2))
    UVv[cv] = W
    e1, e2 = UVv[F[:, 1]] - UVv[F[:, 0]], UVv[F[:, 2]] - UVv[F[:, 0]]
    a_uv = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    assert (a_uv > 0).all()
    assert a_uv.sum() == pytest.approx(face_areas(V, F).sum(), rel=1e-5)
    assert 'conformal_factor' not in me.attributes        # bake=False writes no attributes


def test_quads_and_ngon(addon, bl):
    flatten, _, triangulate = core_of(addon)
    V, polys = quad_ngon_mesh()
    obj = bl.mesh_object('qn', V, polys)
    me = obj.data
    n_poly, sizes_before = len(me.polygons), sizes_of(me)
    assert sorted(set(sizes_before.tolist())) == [4, 8]
    bpy.ops.uv.conformal_flatten(boundary='AREA', fit='UNIT_SQUARE')
    assert len(me.polygons) == n_poly                          # the n-gon keeps its face
    np.testing.assert_array_equal(sizes_of(me), sizes_before)
    cv = corner_verts(me)
    tri, _ = triangulate(cv, sizes_before, V)
    ref = flatten(V, cv[tri], boundary='area', fit='unit_square')
    W = loop_uv(me)
    np.testing.assert_allclose(W, ref.uv[cv], atol=2e-6)
    # every polygon, the octagon included, is counter-clockwise (positive signed area) in UV
    start = np.r_[0, np.cumsum(sizes_before)[:-1]]
    for s, k in zip(start, sizes_before):
        P = W[s:s + k]
        area = 0.5 * np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1])
        assert area > 0
    # one UV per vertex: corners of the same vertex share their UV (no seams on a disk)
    for v in range(len(V)):
        assert np.ptp(W[cv == v], axis=0).max() < 1e-7


def test_attributes_domain_type_range(addon, bl):
    from conformal_flatten.addon.colormap import colormap
    from conformal_flatten.core.mesh.geometry import face_areas
    obj, V, F = bump_object(bl)
    bpy.ops.uv.conformal_flatten(boundary='AREA')
    me = obj.data
    a = me.attributes['conformal_factor']
    assert (a.domain, a.data_type) == ('POINT', 'FLOAT')
    c = me.attributes['conformal_factor_color']
    assert (c.domain, c.data_type) == ('POINT', 'FLOAT_COLOR')
    assert me.color_attributes.active_color_name == 'conformal_factor_color'
    mu = point_attr(me, 'conformal_factor', 'value', 1)
    lo, hi = me['conformal_factor_range']
    assert mu.min() == pytest.approx(lo, rel=1e-6) and mu.max() == pytest.approx(hi, rel=1e-6)
    assert 0.5 < lo < 1 < hi < 2                       # mu is normalised: total UV area = 3D area
    rep = addon.addon.meshio.load_report(me, 'conformal_flatten_report')
    assert rep['conformal_factor_range'] == pytest.approx([lo, hi])
    # independent check: vertex mu = area-weighted geometric mean over the vertex star of the
    # triangle mu = sqrt((UV area / 3D area) / (total ratio)) (docs/math.md: the one per-vertex mu)
    cv = corner_verts(me)
    UVv = np.zeros((len(V), 2))
    UVv[cv] = loop_uv(me)
    e1, e2 = UVv[F[:, 1]] - UVv[F[:, 0]], UVv[F[:, 2]] - UVv[F[:, 0]]
    a_uv = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    a_3d = face_areas(V, F)
    log_mu = 0.5 * np.log(a_uv / a_3d / (a_uv.sum() / a_3d.sum()))
    star_log = np.bincount(F.ravel(), np.repeat(a_3d * log_mu, 3), minlength=len(V))
    star_3d = np.bincount(F.ravel(), np.repeat(a_3d, 3), minlength=len(V))
    expect = np.exp(star_log / star_3d)
    np.testing.assert_allclose(mu, expect, rtol=1e-4)
    # colours: in [0,1], the extremes get the ends of the colour map
    col = point_attr(me, 'conformal_factor_color', 'color', 4)
    assert col.min() >= 0 and col.max() <= 1
    np.testing.assert_allclose(col[np.argmin(mu)], colormap([0.0])[0], atol=1e-5)
    np.testing.assert_allclose(col[np.argmax(mu)], colormap([1.0])[0], atol=1e-5)


def test_colormap_preference(addon, bl):
    from conformal_flatten.addon.prefs import get_prefs
    prefs = get_prefs(bpy.context)
    assert prefs.grid_size == 0 and prefs.colormap == 'PERCEPTUAL'
    prefs.colormap = 'GRAY'
    obj, _, _ = bump_object(bl)
    bpy.ops.uv.conformal_flatten(boundary='AREA')
    col = point_attr(obj.data, 'conformal_factor_color', 'color', 4)
    np.testing.assert_allclose(col[:, 0], col[:, 1], atol=1e-4)
    np.testing.assert_allclose(col[:, 1], col[:, 2], atol=1e-4)
    assert col[:, 0].max() > 0.9 and col[:, 0].min() < 0.05


def test_existing_attribute_of_other_type_is_replaced(addon, bl):
    obj, _, _ = bump_object(bl)
    me = obj.data
    me.attributes.new('conformal_factor', 'INT', 'CORNER')
    me.uv_layers.new(name='Mine')
    me.uv_layers.new(name='Other')
    me.uv_layers.active = me.uv_layers['Mine']
    other_before = np.empty(len(me.loops) * 2, np.float32)
    me.uv_layers['Other'].uv.foreach_get('vector', other_before)
    bpy.ops.uv.conformal_flatten(boundary='AREA')
    a = me.attributes['conformal_factor']
    assert (a.domain, a.data_type) == ('POINT', 'FLOAT')
    assert [u.name for u in me.uv_layers] == ['Mine', 'Other']   # writes into the active map
    other = np.empty(len(me.loops) * 2, np.float32)
    me.uv_layers['Other'].uv.foreach_get('vector', other)
    np.testing.assert_array_equal(other, other_before)           # the other map is untouched
    assert np.ptp(loop_uv(me)) > 0.5


def test_edit_mode_keeps_mode_and_selection(addon, bl):
    import bmesh
    obj, V, F = bump_object(bl)
    me = obj.data
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.context.tool_settings.mesh_select_mode = (True, False, False)
    bm = bmesh.from_edit_mesh(me)
    for v in bm.verts:
        v.select_set(v.index % 7 == 0)
    bm.select_flush_mode()
    bmesh.update_edit_mesh(me)
    # an edit made in Edit mode and not yet written to the mesh must be seen by the operator
    bm.verts.ensure_lookup_table()
    bm.verts[len(V) // 2].co.z += 0.25
    bmesh.update_edit_mesh(me)
    assert bpy.ops.uv.conformal_flatten(boundary='AREA') == {'FINISHED'}
    assert obj.mode == 'EDIT'
    bpy.ops.object.mode_set(mode='OBJECT')
    sel = np.zeros(len(me.vertices), bool)
    me.attributes['.select_vert'].data.foreach_get('value', sel)
    np.testing.assert_array_equal(sel, np.arange(len(V)) % 7 == 0)
    assert tuple(bpy.context.tool_settings.mesh_select_mode) == (True, False, False)
    flatten, _, _ = core_of(addon)
    V2 = V.copy()
    V2[len(V) // 2, 2] += 0.25
    ref = flatten(V2, F, boundary='area', fit='unit_square')
    np.testing.assert_allclose(loop_uv(me), ref.uv[corner_verts(me)], atol=2e-6)


def test_modifiers_ignored(addon, bl):
    obj, V, F = bump_object(bl)
    obj.modifiers.new('sub', 'SUBSURF').levels = 1
    obj.modifiers.new('disp', 'DISPLACE').strength = 0.3
    bpy.ops.uv.conformal_flatten(boundary='AREA')
    me = obj.data
    assert len(me.vertices) == len(V)
    flatten, _, _ = core_of(addon)
    ref = flatten(V, F, boundary='area', fit='unit_square')
    np.testing.assert_allclose(loop_uv(me), ref.uv[corner_verts(me)], atol=2e-6)
    assert len(obj.modifiers) == 2


# --- failures leave everything unchanged ---------------------------------------------------------
def _annulus():
    """A 9x9 grid with the central 3x3 block of quads removed: two boundary loops."""
    n = 9
    t = np.linspace(-1, 1, n)
    X, Y = np.meshgrid(t, t)
    V = np.stack([X.ravel(), Y.ravel(), 0.2 * (X**2 - Y**2).ravel()], 1)
    polys = [[i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j]
             for i in range(n - 1) for j in range(n - 1) if not (3 <= i <= 5 and 3 <= j <= 5)]
    used = np.zeros(len(V), bool)
    used[np.concatenate(polys)] = True                   # drop the vertices inside the hole
    remap = np.cumsum(used) - 1
    return V[used], [[int(remap[v]) for v in p] for p in polys]


def _fails_unchanged(bl, match, mode='OBJECT', **op_kw):
    """The operator (with ``op_kw``) raises RuntimeError (its ERROR report) matching ``match``, keeps
    the mode, and every mesh's data arrays are bitwise what they were."""
    obj = bpy.context.view_layer.objects.active
    if mode == 'EDIT':       # a round trip first, so that 'before' is what Edit mode writes back
        bpy.ops.object.mode_set(mode='EDIT')
        bpy.ops.object.mode_set(mode='OBJECT')
    before = bl.all_meshes_snapshot()
    if mode == 'EDIT':
        bpy.ops.object.mode_set(mode='EDIT')
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.uv.conformal_flatten(boundary='AREA', **op_kw)
    if obj is not None:
        assert obj.mode == mode
    if mode == 'EDIT':
        bpy.ops.object.mode_set(mode='OBJECT')
    after = bl.all_meshes_snapshot()
    assert before.keys() == after.keys()
    for name in before:
        bl.assert_same(before[name], after[name])


@pytest.mark.parametrize('mode', ['OBJECT', 'EDIT'])
def test_closed_mesh_fails_unchanged(addon, bl, mode):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=16, ring_count=8)
    bpy.context.object.data.uv_layers.active.uv.foreach_set('vector', np.full(
        2 * len(bpy.context.object.data.loops), 0.25, np.float32))
    _fails_unchanged(bl, 'closed', mode)


def test_two_boundary_loops_fail_unchanged(addon, bl):
    V, polys = _annulus()
    obj = bl.mesh_object('annulus', V, polys)
    obj.data.uv_layers.new(name='UVMap')
    obj.data.attributes.new('conformal_factor', 'FLOAT', 'POINT').data.foreach_set(
        'value', np.linspace(0, 1, len(V), dtype=np.float32))
    obj.data['conformal_factor_range'] = [0.0, 1.0]
    # holes are handled by default (issue 7); with Holes set to Refuse, two loops are an error
    _fails_unchanged(bl, '2 boundary loops', holes='ERROR')


def test_non_mesh_object_fails_unchanged(addon, bl):
    bump_object(bl)                    # a mesh in the scene that must stay untouched
    bpy.ops.curve.primitive_bezier_curve_add()
    curve = bpy.context.object
    pts = [tuple(p.co) for p in curve.data.splines[0].bezier_points]
    _fails_unchanged(bl, 'not a mesh')
    assert [tuple(p.co) for p in curve.data.splines[0].bezier_points] == pts


def test_no_active_object_fails(addon, bl):
    bump_object(bl)
    bpy.context.view_layer.objects.active = None
    _fails_unchanged(bl, 'no active object')


def test_report_and_summary(addon, bl):
    from conformal_flatten.addon import apply, report, ui
    obj, _, _ = bump_object(bl)
    bpy.ops.uv.conformal_flatten(boundary='UNIFORM')
    rep = addon.addon.meshio.load_report(obj.data, apply.REPORT_KEY)
    for key in ('mu_ratio', 'bound_vertex', 'flips', 'qc_mean', 'seconds', 'mesh_hash'):
        assert rep[key] is not None, key
    assert rep['bound_vertex'] >= rep['mu_ratio'] * 0.98
    line = report.summary_line(rep)
    assert 'mu ratio' in line and 'certified bound' in line and 'flips' in line
    assert ui.geodesic_solver_label()


@pytest.mark.parametrize('mode', ['SCULPT', 'VERTEX_PAINT'])
def test_other_modes_are_restored(addon, bl, mode):
    obj, V, F = bump_object(bl)
    bpy.ops.object.mode_set(mode=mode)
    assert bpy.ops.uv.conformal_flatten(boundary='AREA') == {'FINISHED'}
    assert obj.mode == mode
    bpy.ops.object.mode_set(mode='OBJECT')
    assert 'conformal_factor' in obj.data.attributes


class FakeLayout:
    """Records what a panel draws (UILayout cannot be created outside a UI)."""

    def __init__(self, log):
        self.log = log
        self.use_property_split = False

    def _sub(self, *a, **k):
        return FakeLayout(self.log)
    column = row = box = _sub

    def label(self, text='', icon='NONE'):
        self.log.append(('label', text))

    def prop(self, data, name, **k):
        assert hasattr(data, name), name
        self.log.append(('prop', name))

    def separator(self):
        pass

    def operator(self, idname, **k):
        self.log.append(('operator', idname))
        return type('OperatorProperties', (), {})()


def test_panel_draws_report_and_sections(addon, bl):
    from conformal_flatten.addon import sidebar, ui
    from conformal_flatten.addon.prefs import ConformalFlattenPreferences, get_prefs
    obj, _, _ = bump_object(bl)
    panel = ui.VIEW3D_PT_conformal_flatten
    log = []
    fake = type('P', (), {'layout': FakeLayout(log)})()
    panel.draw(fake, bpy.context)
    assert ('operator', 'uv.conformal_flatten') in log
    assert ('label', "No flatten report for the active mesh") in log
    bpy.ops.uv.conformal_flatten(boundary='AREA')
    calls = []

    def extra(layout, context):
        calls.append(context)
    sidebar.add_section("Extra", extra)
    log.clear()
    panel.draw(fake, bpy.context)
    labels = [t for kind, t in log if kind == 'label']
    assert "Mu ratio" in labels and "Flips" in labels and "Certified bound" in labels
    assert any(t.startswith("Geodesic solver: ") for t in labels)
    assert calls and "Extra" in labels
    sidebar.remove_section(extra)
    assert all(d is not extra for _, d in sidebar.sections())
    prefs = get_prefs(bpy.context)
    assert isinstance(prefs, ConformalFlattenPreferences)       # enabled: the real preferences
    log.clear()
    fake_prefs = type('P', (), {'layout': FakeLayout(log), 'grid_size': 0, 'colormap': 'GRAY',
                                'max_faces': 1000})()
    ConformalFlattenPreferences.draw(fake_prefs, bpy.context)
    assert ('prop', 'grid_size') in log and ('prop', 'colormap') in log and ('prop', 'max_faces') in log


# --- structure (issue 11): one way through the code -------------------------------------------------
ADDON_DIR = os.path.join(os.path.dirname(os.path.dirname(os.path.abspath(__file__))), 'addon')


def _relative_imports(path, package):
    """Modules imported by ``path`` with relative imports anywhere in it (module level or inside
    functions), resolved to dotted names under the repository root."""
    import ast
    tree = ast.parse(open(path).read())
    parts = package.split('.')
    out = set()
    root = os.path.dirname(ADDON_DIR)
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom) and node.level:
            base = parts[:len(parts) - (node.level - 1)]
            mod = base + (node.module.split('.') if node.module else [])
            for alias in node.names:
                sub = mod + [alias.name]
                if os.path.exists(os.path.join(root, *sub) + '.py') or \
                        os.path.isdir(os.path.join(root, *sub)):
                    out.add('.'.join(sub))
                else:
                    out.add('.'.join(mod))
    return out


def test_no_import_cycle_in_addon_or_core():
    """The static graph of relative imports (also those inside functions) of addon/ and core/ has no
    cycle, and no operator imports ui.py (ui imports the operators)."""
    root = os.path.dirname(ADDON_DIR)
    graph = {}
    for top in ('addon', 'core'):
        for dirpath, _, files in os.walk(os.path.join(root, top)):
            for f in files:
                if f.endswith('.py'):
                    rel = os.path.relpath(os.path.join(dirpath, f), root)[:-3].replace(os.sep, '.')
                    name = rel[:-len('.__init__')] if rel.endswith('.__init__') else rel
                    package = name if f == '__init__.py' else name.rsplit('.', 1)[0]
                    graph[name] = _relative_imports(os.path.join(dirpath, f), package)
    state = {}

    def visit(node, stack):
        state[node] = 1
        for nxt in sorted(graph.get(node, ())):
            if state.get(nxt) == 1:
                raise AssertionError(f"import cycle: {' -> '.join(stack + [node, nxt])}")
            if nxt in graph and not state.get(nxt):
                visit(nxt, stack + [node])
        state[node] = 2
    for node in sorted(graph):
        if not state.get(node):
            visit(node, [])
    assert 'addon.ops_flatten' in graph['addon.ui']
    importers_of_ui = [m for m, deps in graph.items() if 'addon.ui' in deps]
    assert importers_of_ui == [], importers_of_ui


def test_addon_files_small_and_free_of_math_and_topology():
    """Every add-on file is under 450 lines; the add-on's own files import no topology or measure code
    from the core and call no numpy math (areas, means, roots, logs, Jacobians): all of that is in
    ``core.unwrap``. Exception: colour mapping (colormap.py)."""
    import ast
    forbidden_np = {'sqrt', 'cross', 'bincount', 'log', 'exp', 'einsum', 'mean', 'linalg', 'arccos',
                    'arctan2', 'hypot', 'dot'}
    forbidden_core = ('topology', 'geometry', 'measures', 'face_areas', 'jacobians', 'islands',
                      'disk.flatten')
    for f in sorted(os.listdir(ADDON_DIR)):
        if not f.endswith('.py'):
            continue
        path = os.path.join(ADDON_DIR, f)
        text = open(path).read()
        assert text.count('\n') < 450, f
        if f == 'colormap.py':
            continue
        assert '_single_disk' not in text and '_addon_wording' not in text, f
        tree = ast.parse(text)
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and node.level:
                assert not any(k in node.module for k in forbidden_core), (f, node.module)
            if isinstance(node, ast.FunctionDef):
                for sub in ast.walk(node):
                    if isinstance(sub, ast.Attribute) and isinstance(sub.value, ast.Name) and \
                            sub.value.id == 'np':
                        assert sub.attr not in forbidden_np, (f, node.name, sub.attr)


def test_auto_seams_unfold_the_default_cube_into_a_net(addon, bl):
    """The default cube with seams='AUTO' (an error before: its triangulation's first two cones
    covered it): its eight corners are the cones and the UVs are a net, every face a square of the
    same size, with no warning."""
    bpy.ops.mesh.primitive_cube_add()
    me = bpy.context.object.data
    assert bpy.ops.uv.conformal_flatten(seams='AUTO', cones=0) == {'FINISHED'}
    report = json.loads(me['conformal_flatten_report'])
    assert report['cones'] == 8 and report['flips'] == 0 and not report.get('warnings')
    uv = np.zeros(2 * len(me.loops), np.float32)
    me.uv_layers.active.uv.foreach_get('vector', uv)
    uv = uv.reshape(-1, 2).astype(np.float64)
    sides = np.array([np.linalg.norm(uv[p.loop_start + (k + 1) % 4] - uv[p.loop_start + k])
                      for p in me.polygons for k in range(4)])
    assert sides.max() < sides.min() * (1 + 1e-4)
    assert uv.min() >= -1e-6 and uv.max() <= 1 + 1e-6


def test_auto_seams_unroll_the_default_cylinder(addon, bl):
    """Blender's default cylinder (32 sides, n-gon caps) with seams='AUTO': its curvature sits on its
    two rims, which cones could not hold (8 cones, 1%/99% ratio 0.44, qc_mean 1.31, two warnings).
    Now the rims are its seams: two caps and the side unrolled, no cone, every loop triangle at one
    scale, no warning."""
    bpy.ops.mesh.primitive_cylinder_add()
    me = bpy.context.object.data
    assert bpy.ops.uv.conformal_flatten(seams='AUTO', cones=0) == {'FINISHED'}
    report = json.loads(me['conformal_flatten_report'])
    assert report['feature_edges'] == 64 and report['cones'] == 0 and report['flips'] == 0
    assert not report.get('warnings')
    assert sum(e.use_seam for e in me.edges) >= 64
    uv = np.zeros(2 * len(me.loops), np.float32)
    me.uv_layers.active.uv.foreach_get('vector', uv)
    uv = uv.reshape(-1, 2).astype(np.float64)
    co = np.array([v.co[:] for v in me.vertices], np.float64)
    me.calc_loop_triangles()
    lt = np.array([t.loops[:] for t in me.loop_triangles])
    vt = np.array([t.vertices[:] for t in me.loop_triangles])
    ratio = (np.linalg.norm(uv[lt] - uv[np.roll(lt, 1, axis=1)], axis=2)
             / np.linalg.norm(co[vt] - co[np.roll(vt, 1, axis=1)], axis=2))
    assert ratio.max() < ratio.min() * (1 + 1e-4), (ratio.min(), ratio.max())


def test_auto_seams_keep_to_polygon_edges(addon, bl):
    """A cube with a Bevel modifier applied (quads, n-gon-free rounded edges) and seams='AUTO': the
    automatic cuts keep off the quads' diagonals, so every polygon's corners hold the map (a seam
    through a quad gave two of its corners two UVs; Blender keeps one per loop, and such quads came
    out folded). Every loop triangle is laid out the same way round, none squashed, no warning."""
    from conformal_flatten.core.mesh.measures import jacobians, signed_uv_areas, singular_values
    bpy.ops.mesh.primitive_cube_add()
    obj = bpy.context.object
    mod = obj.modifiers.new('bevel', 'BEVEL')
    mod.width, mod.segments = 0.2, 3
    bpy.ops.object.modifier_apply(modifier=mod.name)
    me = obj.data
    assert bpy.ops.uv.conformal_flatten(seams='AUTO', cones=0) == {'FINISHED'}
    report = json.loads(me['conformal_flatten_report'])
    assert report['flips'] == 0 and not report.get('warnings')
    uv = np.zeros(2 * len(me.loops), np.float32)
    me.uv_layers.active.uv.foreach_get('vector', uv)
    uv = uv.reshape(-1, 2).astype(np.float64)
    me.calc_loop_triangles()
    lt = np.array([t.loops[:] for t in me.loop_triangles])
    vt = np.array([t.vertices[:] for t in me.loop_triangles])
    co = np.array([v.co[:] for v in me.vertices], np.float64)
    a = signed_uv_areas(uv, lt)
    assert (a > 0).all() or (a < 0).all()
    J, _ = jacobians(co[vt].reshape(-1, 3), np.arange(lt.size).reshape(-1, 3), uv[lt.ravel()])
    sv = singular_values(J)
    assert (sv[:, 0] / sv[:, 1]).max() < 2.0


def test_auto_seams_unwrap_a_closed_mesh(addon, bl):
    """seams='AUTO' unwraps a closed mesh in one click: the chosen seams are marked on the mesh, the
    cones baked, every corner gets a UV in [0,1] with no flipped triangle; re-running with
    seams='KEEP' uses the marked seams (the user's to edit) and still succeeds."""
    from conformal_flatten.core.mesh.measures import signed_uv_areas
    bpy.ops.mesh.primitive_uv_sphere_add(segments=24, ring_count=12)
    obj = bpy.context.object
    me = obj.data
    with pytest.raises(RuntimeError, match='closed'):
        bpy.ops.uv.conformal_flatten(seams='KEEP')
    assert bpy.ops.uv.conformal_flatten(seams='AUTO', cones=0, target_ratio=0.5) == {'FINISHED'}
    seams = np.zeros(len(me.edges), bool)
    me.edges.foreach_get('use_seam', seams)
    assert seams.any()
    report = json.loads(me['conformal_flatten_report'])
    assert report['cones'] >= 3 and report['flips'] == 0 and report['seam_mode'] == 'AUTO'
    kappa = np.zeros(len(me.vertices), np.float32)
    me.attributes['conformal_cones'].data.foreach_get('value', kappa)
    assert np.count_nonzero(kappa) == report['cones']
    assert abs(kappa.sum() - 4 * np.pi) < 1e-3                 # Gauss-Bonnet, chi = 2
    uv = np.zeros(2 * len(me.loops), np.float32)
    me.uv_layers.active.uv.foreach_get('vector', uv)
    uv = uv.reshape(-1, 2)
    assert uv.min() >= -1e-6 and uv.max() <= 1 + 1e-6
    tris = np.array([[p.loop_start, p.loop_start + k, p.loop_start + k + 1] for p in me.polygons
                     for k in range(1, p.loop_total - 1)])
    a = signed_uv_areas(uv.astype(np.float64), tris)
    assert (a > 0).all() or (a < 0).all()
    # the marked seams now cut the sphere open: 'KEEP' works on them
    assert bpy.ops.uv.conformal_flatten(seams='KEEP') == {'FINISHED'}
