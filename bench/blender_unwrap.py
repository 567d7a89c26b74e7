"""Blender's own unwraps run through the bpy module, as baselines in the same process.

``blender_unwrap(V, F, method)`` builds a temporary mesh object, runs ``bpy.ops.uv.unwrap`` on all of
it and returns per-corner UVs (m,3,2) and the seconds the operator took."""
import time

import numpy as np


def blender_unwrap(V, F, method='CONFORMAL', seams=None, **kwargs):
    """Per-corner UVs (m,3,2) and seconds of ``bpy.ops.uv.unwrap(method)`` on the triangles ``F``;
    ``seams`` (k,2) vertex pairs are marked as seam edges first (the same input our ``unwrap`` gets)."""
    import bpy
    from core.mesh.topology import edge_mask
    bpy.ops.wm.read_factory_settings(use_empty=True)
    me = bpy.data.meshes.new('bench')
    me.vertices.add(len(V))
    me.vertices.foreach_set('co', np.asarray(V, np.float32).ravel())
    me.loops.add(F.size)
    me.loops.foreach_set('vertex_index', np.asarray(F, np.int32).ravel())
    me.polygons.add(len(F))
    me.polygons.foreach_set('loop_start', np.arange(0, F.size, 3, dtype=np.int32))
    me.update(calc_edges=True)
    if seams is not None and len(seams):
        ev = np.empty(2 * len(me.edges), np.int32)
        me.edges.foreach_get('vertices', ev)
        me.edges.foreach_set('use_seam', edge_mask(ev.reshape(-1, 2), seams))
    me.uv_layers.new(name='UVMap')
    ob = bpy.data.objects.new('bench', me)
    bpy.context.scene.collection.objects.link(ob)
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_all(action='SELECT')
    t = time.perf_counter()
    bpy.ops.uv.unwrap(method=method, margin=0.0, **kwargs)
    seconds = time.perf_counter() - t
    bpy.ops.object.mode_set(mode='OBJECT')
    uv = np.empty(F.size * 2, np.float32)
    me.uv_layers.active.uv.foreach_get('vector', uv)
    bpy.data.objects.remove(ob)
    bpy.data.meshes.remove(me)
    return uv.reshape(-1, 3, 2).astype(np.float64), seconds


def corner_measures(V, F, uv_corners):
    """docs/math.md §3 measures of a per-corner UV map (m,3,2)."""
    from core.mesh.measures import uv_measures
    m = len(F)
    return uv_measures(V[F].reshape(-1, 3), np.arange(3 * m).reshape(m, 3), uv_corners.reshape(-1, 2))
