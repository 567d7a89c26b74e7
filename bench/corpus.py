"""Issue 12: the messy corpus (../shared/meshes) through ``unwrap`` with the defaults, beside Blender's
CONFORMAL and ANGLE_BASED unwraps run in this process through bpy, measured with the same measures
(``core.mesh.measures.uv_measures`` per corner, via ``bench/blender_unwrap.corner_measures``).

    .venv/bin/python bench/corpus.py [--meshes teapot suzanne ...] [--no-blender]

Columns: the repairs each mesh needed, islands, flips, overlaps, worst qc_mean, worst mu_ratio and
seconds. A closed part gives the one remaining error (no_boundary / mark_seams), printed as such."""
import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from core.atlas.islands import seams_from_corner_ids, unwrap     # noqa: E402
from core.errors import ConformalError                           # noqa: E402
from core.io.obj import read_obj                                 # noqa: E402
from core.mesh.triangulate import triangulate                    # noqa: E402

MESHES = os.path.join(ROOT, '..', 'shared', 'meshes')
NAMES = ['woody', 'alligator', 'suzanne', 'teapot', 'spot', 'cow', 'cheburashka', 'rocker-arm', 'beast',
         'stanford-bunny', 'ogre']


def blender_unwrap_seams(V, F, method, seams):
    """Blender's unwrap (per-corner UVs (m,3,2), seconds) of the triangles ``F`` with ``seams`` (k,2)
    marked as seam edges (the same input our ``unwrap`` gets)."""
    import bpy
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
        ev = np.sort(ev.reshape(-1, 2), axis=1).astype(np.int64)
        n = len(V)
        S = np.sort(np.asarray(seams, np.int64), axis=1)
        me.edges.foreach_set('use_seam', np.isin(ev[:, 0] * n + ev[:, 1], S[:, 0] * n + S[:, 1]))
    me.uv_layers.new(name='UVMap')
    ob = bpy.data.objects.new('bench', me)
    bpy.context.scene.collection.objects.link(ob)
    bpy.context.view_layer.objects.active = ob
    ob.select_set(True)
    bpy.ops.object.mode_set(mode='EDIT')
    bpy.ops.mesh.select_all(action='SELECT')
    t = time.perf_counter()
    bpy.ops.uv.unwrap(method=method, margin=0.0)
    seconds = time.perf_counter() - t
    bpy.ops.object.mode_set(mode='OBJECT')
    uv = np.empty(F.size * 2, np.float32)
    me.uv_layers.active.uv.foreach_get('vector', uv)
    bpy.data.objects.remove(ob)
    bpy.data.meshes.remove(me)
    return uv.reshape(-1, 3, 2).astype(np.float64), seconds


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--meshes', nargs='*', default=NAMES)
    ap.add_argument('--no-blender', action='store_true')
    args = ap.parse_args()
    if not os.path.isdir(MESHES):
        sys.exit(f"the corpus is missing: {os.path.abspath(MESHES)} does not exist (see docs/robustness.md)")
    blender = '' if args.no_blender else ' Blender conformal flips / mu_ratio / s | Blender angle-based |'
    print("| mesh | triangles | repairs | islands | flips | overlaps | qc_mean worst | mu_ratio worst | s |"
          + blender)
    print('|---' * (9 if args.no_blender else 11) + '|')
    for name in args.meshes:
        mesh = read_obj(os.path.join(MESHES, f'{name}.obj'))
        tc, tp = triangulate(mesh.corner_verts, mesh.sizes, mesh.V)
        F = mesh.corner_verts[tc]
        seams = None
        if (mesh.corner_uvs >= 0).any():
            seams = seams_from_corner_ids(F, mesh.corner_uvs[tc], len(mesh.V))
        t = time.perf_counter()
        try:
            res = unwrap(mesh.V, F, seams=seams, tri_poly=tp)
            r = res.report
            reps = ', '.join(f"{x['repair']} {x['count']}" for x in r['repairs']) or '-'
            row = (f"| {name} | {len(F)} | {reps} | {r['islands']} | {r['flips']} | {r['overlaps']} | "
                   f"{r['qc_mean_worst']:.3f} | {r['mu_ratio_worst']:.3g} | {time.perf_counter() - t:.1f} |")
        except ConformalError as exc:
            row = (f"| {name} | {len(F)} | | error {exc.code} / {exc.remedy} | | | | | "
                   f"{time.perf_counter() - t:.1f} |")
            if exc.code == 'no_boundary':
                # the open parts still unwrap: on_error='skip' (CLI --skip-bad) flattens them
                try:
                    t = time.perf_counter()
                    r = unwrap(mesh.V, F, seams=seams, tri_poly=tp, on_error='skip').report
                    reps = ', '.join(f"{x['repair']} {x['count']}" for x in r['repairs']) or '-'
                    row = (f"| {name} (skip closed) | {len(F)} | {reps} | {r['flattened']} of "
                           f"{r['islands']} ({r['failed']} closed) | {r['flips']} | {r['overlaps']} | "
                           f"{r['qc_mean_worst']:.3f} | {r['mu_ratio_worst']:.3g} | "
                           f"{time.perf_counter() - t:.1f} |")
                except ConformalError:
                    pass
        if not args.no_blender:
            from blender_unwrap import corner_measures
            closed = 'error no_boundary' in row
            for method in ('CONFORMAL', 'ANGLE_BASED'):
                try:
                    uv, sec = blender_unwrap_seams(mesh.V, F, method, seams)
                    b = corner_measures(mesh.V, F, uv)
                    note = ' (warns: failed to solve)' if closed else ''
                    row += f" {b['flips']} / {b['mu_ratio']:.3g} / {sec:.1f} s{note} |"
                except Exception as exc:          # Blender's own failure is a result too
                    row += f" failed: {type(exc).__name__} |"
        print(row)
        sys.stdout.flush()


if __name__ == '__main__':
    main()
