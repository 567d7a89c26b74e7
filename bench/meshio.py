"""Mesh I/O cost against flatten time on a ~100k-triangle mesh (issue 3 acceptance: I/O < 10%).

    .venv/bin/python bench/meshio.py [--n 225] [--repeat 5] [--uniform]

Reads (positions, corner vertices, polygon starts, triangulation) and writes (per-corner UVs, the
FLOAT point attribute, the colour attribute through the colour map) with the add-on's ``meshio``
helpers, next to the per-element paths they replace, and the flatten time of the core on the same mesh.
Timings are best-of-``repeat`` wall-clock seconds on a shared machine: noisy."""
import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
from tools.blender_user import private_user_resources  # noqa: E402

private_user_resources('cf-bench-user-')

import numpy as np  # noqa: E402


def best(fn, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t)
    return min(times), out


def main(argv=None):
    ap = argparse.ArgumentParser()
    ap.add_argument('--n', type=int, default=225, help="bump grid size (225: 100,352 triangles)")
    ap.add_argument('--repeat', type=int, default=5)
    ap.add_argument('--uniform', action='store_true', help="also time the uniform mode (slow)")
    ap.add_argument('--quads', action='store_true', help="build the mesh from quads, not triangles")
    args = ap.parse_args(argv)

    import bpy
    from tools import devpkg
    pkg = devpkg.load()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    pkg.register()
    from conformal_flatten.addon import meshio
    from conformal_flatten.core import unwrap
    from conformal_flatten.core.mesh.measures import vertex_mu

    def compute_flatten(md, boundary, fit):
        """core.unwrap of the whole mesh -> (result, per-corner UVs (c,2), per-vertex mu (n,))."""
        res = unwrap(md.V, md.F, boundary=boundary.lower(), fit=fit.lower())
        loop_uv = np.zeros((len(md.corner_verts), 2))
        loop_uv[md.tri_corners.ravel()] = res.uv_corner.reshape(-1, 2)
        return res, loop_uv, res.mu_vertex
    from conformal_flatten.core.surfaces import make_surface

    n = args.n
    V, F = make_surface('bump', n)
    if args.quads:
        i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing='ij')
        a = (i * n + j).ravel()
        polys = np.stack([a, a + 1, a + n + 1, a + n], 1)
    else:
        polys = F
    me = bpy.data.meshes.new('bench')
    me.vertices.add(len(V))
    me.loops.add(polys.size)
    me.polygons.add(len(polys))
    me.attributes['position'].data.foreach_set('vector', V.astype(np.float32).ravel())
    me.attributes['.corner_vert'].data.foreach_set('value', polys.astype(np.int32).ravel())
    me.polygons.foreach_set('loop_start', np.arange(0, polys.size, polys.shape[1], dtype=np.int32))
    me.update(calc_edges=True)
    obj = bpy.data.objects.new('bench', me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    rep = args.repeat

    rows = []
    t_read, md = best(lambda: meshio.read_mesh(obj, triangles=False), rep)
    rows.append(('read: positions + corner verts + loop starts', t_read))
    from conformal_flatten.core.mesh.triangulate import triangulate
    t_tri, _ = best(lambda: triangulate(md.corner_verts, md.sizes, md.V), rep)
    rows.append(('triangulate (core, numpy)', t_tri))
    md = meshio.read_mesh(obj)
    ntri = len(md.tri_corners)
    result, loop_uv, mu_v = compute_flatten(md, 'AREA', 'UNIT_SQUARE')
    t_uv, _ = best(lambda: meshio.write_uv(me, loop_uv), rep)
    rows.append(('write per-corner UVs', t_uv))
    t_bake, _ = best(lambda: meshio.bake_scalar(me, 'conformal_factor', mu_v), rep)
    rows.append(('bake: FLOAT attribute + colour map + FLOAT_COLOR attribute', t_bake))
    t_v2f, _ = best(lambda: vertex_mu(md.F, result.mu, np.ones(ntri), len(md.V)), rep)
    rows.append(('per-triangle mu -> per-vertex', t_v2f))
    io_total = t_read + t_tri + t_uv + t_bake + t_v2f

    # the per-element paths the fast ones replace
    slow = []
    buf = np.empty(len(me.vertices) * 3, np.float32)
    slow.append(('vertices.foreach_get("co")', best(lambda: me.vertices.foreach_get('co', buf), rep)[0]))
    ibuf = np.empty(len(me.loops), np.int32)
    slow.append(('loops.foreach_get("vertex_index")',
                 best(lambda: me.loops.foreach_get('vertex_index', ibuf), rep)[0]))
    uvbuf = loop_uv.astype(np.float32).ravel()
    slow.append(('uv_layer.data.foreach_set("uv")',
                 best(lambda: me.uv_layers.active.data.foreach_set('uv', uvbuf), rep)[0]))
    tl = np.empty(ntri * 3, np.int32)

    def loop_tris():
        me.calc_loop_triangles()
        me.loop_triangles.foreach_get('loops', tl)
    slow.append(('calc_loop_triangles + loop_triangles.foreach_get', best(loop_tris, rep)[0]))

    flat = {}
    for mode in ['AREA', 'FREE'] + (['UNIFORM'] if args.uniform else []):
        flat[mode], _ = best(lambda mode=mode: compute_flatten(md, mode, 'UNIT_SQUARE'),
                             1 if mode == 'UNIFORM' else 2)

    def edit_round_trip():
        with meshio.object_mode(obj):
            pass
    bpy.ops.object.mode_set(mode='EDIT')
    t_mode, _ = best(edit_round_trip, rep)
    bpy.ops.object.mode_set(mode='OBJECT')

    print(f"\nbump n={n}: {len(V):,} vertices, {len(polys):,} polygons, {ntri:,} triangles "
          f"(best of {rep}; shared 2-core machine, noisy)\n")
    print("| step | ms |\n|---|---|")
    for name, t in rows:
        print(f"| {name} | {1e3 * t:.1f} |")
    print(f"| **I/O total** | **{1e3 * io_total:.1f}** |")
    print(f"| Edit-mode round trip (leave and re-enter Edit mode) | {1e3 * t_mode:.1f} |")
    print("\n| per-element path (not used) | ms |\n|---|---|")
    for name, t in slow:
        print(f"| {name} | {1e3 * t:.1f} |")
    print("\n| flatten mode | flatten s | I/O share of flatten |\n|---|---|---|")
    for mode, t in flat.items():
        print(f"| {mode.lower()} | {t:.2f} | {100 * io_total / t:.1f}% |")
    pkg.unregister()
    return 0


if __name__ == '__main__':
    sys.exit(main())
