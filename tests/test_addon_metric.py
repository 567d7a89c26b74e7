"""The metric-reconstruction operator against the real bpy module: a constant metric recovered from
consistent times and baked as attributes; bad CSV rows and bad files fail with the line number and
leave every mesh untouched; Edit mode is restored."""
import bpy
import numpy as np
import pytest

pytestmark = pytest.mark.bpy

N = 17          # flat grid: geodesics are straight lines, so times = c * distance are exact


def flat_object(bl, name='flat'):
    from conformal_flatten.core.surfaces import make_surface
    V, F = make_surface('flat', N)
    V = V.astype(np.float32).astype(float)
    return bl.mesh_object(name, V, F), V, F


def boundary_pairs(V, F):
    from conformal_flatten.core.mesh.topology import boundary_loops
    loop = boundary_loops(F, len(V))[0]
    S, T = np.meshgrid(loop[::12], loop[6::12], indexing='ij')
    return S.ravel(), T.ravel()


def write_csv(path, S, T, d, header=True):
    rows = ''.join(f'{a},{b},{t:.9f}\n' for a, b, t in zip(S, T, d))
    path.write_text(('source_vertex,sensor_vertex,time\n' if header else '') + rows)
    return str(path)


def point_float(me, name):
    a = me.attributes[name]
    buf = np.empty(len(a.data), np.float32)
    a.data.foreach_get('value', buf)
    return buf


def test_operator_registered(addon):
    assert hasattr(bpy.ops.mesh, 'conformal_reconstruct_metric')
    from conformal_flatten.addon import ops_metric
    from conformal_flatten.addon import sidebar
    assert any(d is ops_metric.draw_section for _, d in sidebar.sections())


@pytest.mark.parametrize('mode', ['OBJECT', 'EDIT'])
def test_bakes_constant_metric(addon, bl, tmp_path, mode):
    obj, V, F = flat_object(bl)
    S, T = boundary_pairs(V, F)
    c = 1.6
    path = write_csv(tmp_path / 'times.csv', S, T, c * np.linalg.norm(V[S] - V[T], axis=1))
    if mode == 'EDIT':
        bpy.ops.object.mode_set(mode='EDIT')
    assert bpy.ops.mesh.conformal_reconstruct_metric(filepath=path, cells=64) == {'FINISHED'}
    assert obj.mode == mode
    if mode == 'EDIT':
        bpy.ops.object.mode_set(mode='OBJECT')
    me = obj.data
    attr = me.attributes['recovered_metric']
    assert attr.domain == 'POINT' and attr.data_type == 'FLOAT'
    xi = point_float(me, 'recovered_metric')
    assert xi.shape == (len(V),)
    assert np.abs(xi / c - 1).max() < 0.01
    col = me.color_attributes['recovered_metric_color']
    assert col.domain == 'POINT' and col.data_type == 'FLOAT_COLOR'
    from conformal_flatten.addon import meshio, ops_metric
    rep = meshio.load_report(me, ops_metric.REPORT_KEY)
    assert rep['measurements'] == len(S) and rep['file'] == 'times.csv'
    assert rep['metric_range'][0] == pytest.approx(float(xi.min()), rel=1e-5)


def _fails_unchanged(bl, match, **props):
    before = bl.all_meshes_snapshot()
    with pytest.raises(RuntimeError, match=match):
        bpy.ops.mesh.conformal_reconstruct_metric(**props)
    after = bl.all_meshes_snapshot()
    assert before.keys() == after.keys()
    for name in before:
        bl.assert_same(before[name], after[name])


@pytest.mark.parametrize('bad, match', [
    ('0,99999,1.0', 'line 3.*99999'),
    ('0,5,-2.0', 'line 3.*negative'),
    ('0,5,nan', 'line 3.*finite'),
    ('0,5,fast', 'line 3.*not a number'),
])
def test_bad_csv_row_fails_unchanged(addon, bl, tmp_path, bad, match):
    obj, V, F = flat_object(bl)
    path = tmp_path / 'bad.csv'
    path.write_text(f'source_vertex,sensor_vertex,time\n0,40,2.0\n{bad}\n')
    _fails_unchanged(bl, match, filepath=str(path), cells=64)
    assert 'recovered_metric' not in obj.data.attributes


def test_missing_file_and_no_mesh_fail(addon, bl, tmp_path):
    flat_object(bl)
    _fails_unchanged(bl, 'cannot read', filepath=str(tmp_path / 'nope.csv'))
    _fails_unchanged(bl, 'no travel-time file', filepath='')
    bpy.context.view_layer.objects.active = None
    _fails_unchanged(bl, 'no active object', filepath=str(tmp_path / 'nope.csv'))
