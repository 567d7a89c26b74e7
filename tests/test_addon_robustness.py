"""Bad input in the add-on (issue 7): every case the core rejects reaches the user as an ERROR report
(a RuntimeError in scripts) naming the problem, and every data array of every mesh is bitwise
unchanged, in Object and Edit mode. Complements tests/test_addon.py (closed mesh, two boundary
loops, non-mesh object, no active object)."""
import bpy
import numpy as np
import pytest

from test_addon import _fails_unchanged

pytestmark = pytest.mark.bpy


def _grid(n=5):
    t = np.linspace(-1, 1, n)
    X, Y = np.meshgrid(t, t)
    V = np.stack([X.ravel(), Y.ravel(), 0.3 * np.exp(-(X ** 2 + Y ** 2)).ravel()], 1)
    polys = [[i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j]
             for i in range(n - 1) for j in range(n - 1)]
    return V, polys


def _non_manifold_edge():
    V, polys = _grid()
    # a third face on the interior edge (6, 7) (shared by two quads of the grid)
    return np.vstack([V, [[0.0, -0.5, 1.0]]]), polys + [[6, 7, 25]]


def _non_manifold_vertex():
    V, polys = _grid()
    # a triangle touching the grid only at its corner vertex 0 (a bow tie)
    return np.vstack([V, [[-1.5, -2.5, 0], [-2.5, -1.5, 0]]]), polys + [[0, 25, 26]]


def _zero_area():
    V, polys = _grid()
    V = V.copy()
    V[6] = V[7]                               # two corners of several quads coincide
    return V, polys


def _duplicate_face():
    V, polys = _grid()
    return V, polys + [list(polys[5])]


def _loose_vertex():
    V, polys = _grid()
    return np.vstack([V, [[3.0, 3, 3]]]), polys


# issue 12: the core repairs these internally (core.mesh.repair, intrinsic mollification) and lists
# the repairs; the mesh's own data stays bitwise unchanged
REPAIRED = {
    'duplicate_face': _duplicate_face,
    'loose_vertex': _loose_vertex,
    'non_manifold_edge': _non_manifold_edge,
    'non_manifold_vertex': _non_manifold_vertex,
    'zero_area': _zero_area,
}


@pytest.mark.parametrize('name', sorted(REPAIRED))
def test_repaired_mesh_flattens_geometry_unchanged(addon, bl, name):
    V, polys = REPAIRED[name]()
    obj = bl.mesh_object(name, V, polys)
    before = np.empty(3 * len(obj.data.vertices), np.float32)
    obj.data.attributes['position'].data.foreach_get('vector', before)
    n_polys = len(obj.data.polygons)
    bpy.ops.uv.conformal_flatten(boundary='AREA')
    after = np.empty_like(before)
    obj.data.attributes['position'].data.foreach_get('vector', after)
    assert np.array_equal(before, after) and len(obj.data.polygons) == n_polys
    buf = np.empty(2 * len(obj.data.loops), np.float32)
    obj.data.uv_layers.active.uv.foreach_get('vector', buf)
    assert np.isfinite(buf).all()


@pytest.mark.parametrize('mode', ['OBJECT', 'EDIT'])
@pytest.mark.parametrize('value', [np.nan, np.inf, -np.finfo(np.float32).max])
def test_non_finite_coordinates_fail_unchanged(addon, bl, value, mode):
    """NaN, inf, and -FLT_MAX (what Blender stores when "-inf" is typed into a number field; issue 12:
    it was reported as "zero-area faces") are all named as non-finite coordinates."""
    V, polys = _grid()
    obj = bl.mesh_object('nan', V, polys)
    pos = np.empty(3 * len(V), np.float32)
    obj.data.attributes['position'].data.foreach_get('vector', pos)
    pos[3 * 7 + 1] = value
    obj.data.attributes['position'].data.foreach_set('vector', pos)
    _fails_unchanged(bl, 'NaN or infinite', mode)


@pytest.mark.parametrize('mode', ['OBJECT', 'EDIT'])
def test_mesh_without_faces_fails_unchanged(addon, bl, mode):
    me = bpy.data.meshes.new('wire')
    me.from_pydata([(0, 0, 0), (1, 0, 0), (1, 1, 0)], [(0, 1), (1, 2)], [])
    obj = bpy.data.objects.new('wire', me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    _fails_unchanged(bl, 'no faces', mode)


def test_empty_mesh_fails_unchanged(addon, bl):
    me = bpy.data.meshes.new('empty')
    obj = bpy.data.objects.new('empty', me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    _fails_unchanged(bl, 'no faces')


def test_genuine_needle_still_works(addon, bl):
    V, polys = _grid()
    V = np.vstack([V, 0.5 * (V[6] + V[7]) + [0, 1e-4, 0]])     # almost on the edge (6, 7)
    # the two quads on the edge become pentagons through the new vertex: the triangulation has
    # needle triangles of aspect ratio about 1e4 there
    polys = [p for p in polys if p not in ([6, 7, 12, 11], [1, 2, 7, 6])] + [[6, 25, 7, 12, 11],
                                                                           [1, 2, 7, 25, 6]]
    obj = bl.mesh_object('needle', V, polys)
    bpy.ops.uv.conformal_flatten(boundary='AREA')
    buf = np.empty(2 * len(obj.data.loops), np.float32)
    obj.data.uv_layers.active.uv.foreach_get('vector', buf)
    assert np.isfinite(buf).all()


@pytest.mark.parametrize('mode', ['OBJECT', 'EDIT'])
def test_mesh_over_size_limit_fails_unchanged(addon, bl, mode):
    """The preferences' size limit refuses a mesh before any work, with the counts in the message."""
    V, polys = _grid(9)                      # 64 quads = 128 triangles
    bl.mesh_object('big', V, polys)
    prefs = bpy.context.preferences.addons['conformal_flatten'].preferences
    prefs.max_faces = 100
    try:
        _fails_unchanged(bl, r'128 triangles, over the limit of 100', mode)
    finally:
        prefs.max_faces = 5_000_000
    bpy.ops.uv.conformal_flatten(boundary='AREA')       # within the limit again: it works


@pytest.mark.parametrize('mode', ['OBJECT', 'EDIT'])
def test_infinite_coordinate_with_seams_named(addon, bl, mode):
    """Issue 12: an infinite coordinate is reported as such, also when seams send the mesh through
    the island pipeline (not as "zero-area faces")."""
    V, polys = _grid()
    obj = bl.mesh_object('inf', V, polys)
    me = obj.data
    seam = np.zeros(len(me.edges), bool)
    seam[0] = True
    me.edges.foreach_set('use_seam', seam)
    pos = np.empty(3 * len(V), np.float32)
    me.attributes['position'].data.foreach_get('vector', pos)
    pos[3 * 12] = np.finfo(np.float32).max          # "inf" typed into Blender's UI
    me.attributes['position'].data.foreach_set('vector', pos)
    _fails_unchanged(bl, r'NaN or infinite coordinates \(vertices 12\): fix or delete', mode)


def test_the_meshs_own_warnings_reach_blender(addon, bl):
    """A grid with a block of faces wound the other way (their normals flipped): the core flattens it
    in one orientation and warns that those triangles' UVs read mirrored against their own normals.
    That warning is the mesh's, not an island's; the report kept only the islands' warnings, so
    Blender said nothing."""
    import bmesh
    import json
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=8, y_subdivisions=8)
    me = bpy.context.object.data
    bm = bmesh.new()
    bm.from_mesh(me)
    bmesh.ops.reverse_faces(bm, faces=[f for f in bm.faces if f.calc_center_median().x > 0.3])
    bm.to_mesh(me)
    bm.free()
    assert bpy.ops.uv.conformal_flatten() == {'FINISHED'}
    report = json.loads(me['conformal_flatten_report'])
    assert any('wound against their neighbours' in w for w in report['warnings'])
