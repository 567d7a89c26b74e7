"""Islands in the add-on (issue 7), headless in the bpy module. Prints two markdown tables: the
acceptance cases (seamed UV spheres, Suzanne, two holes) through the operator with default options,
then the cost of each packer on seamed meshes: mesh, triangles, islands, packer, flatten s (core),
write+pack s, total s, flips, worst island qc_mean.

    .venv/bin/python bench/addon_islands.py [--quick | --acceptance]

Wall-clock on whatever machine runs it (noisy on a shared machine)."""
import argparse
import json
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)


def mark_seams(me, pred):
    V = np.empty(3 * len(me.vertices), np.float32)
    me.vertices.foreach_get('co', V)
    V = V.reshape(-1, 3)
    E = np.empty(2 * len(me.edges), np.int32)
    me.edges.foreach_get('vertices', E)
    E = E.reshape(-1, 2)
    s = pred(V[E[:, 0]], V[E[:, 1]])
    me.edges.foreach_set('use_seam', s)
    me.update()
    return int(s.sum())


def sphere(bpy, seg, ring):
    bpy.ops.mesh.primitive_uv_sphere_add(segments=seg, ring_count=ring)
    obj = bpy.context.object

    def pred(a, b):
        eq = (np.abs(a[:, 2]) < 1e-4) & (np.abs(b[:, 2]) < 1e-4)
        mer = (np.abs(a[:, 1]) < 1e-6) & (np.abs(b[:, 1]) < 1e-6) & (a[:, 0] > -1e-6) & (b[:, 0] > -1e-6)
        return eq | mer
    mark_seams(obj.data, pred)
    return obj, f"UV sphere {seg}x{ring}, equator + meridian seams"


def grid_islands(bpy, n, k):
    """An n x n quad grid bent into a bump, cut by seams into k x k islands."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=n, y_subdivisions=n, size=2)
    obj = bpy.context.object
    bpy.ops.object.mode_set(mode='OBJECT')
    me = obj.data
    V = np.empty(3 * len(me.vertices), np.float32)
    me.vertices.foreach_get('co', V)
    V = V.reshape(-1, 3)
    V[:, 2] = np.exp(-0.2 * (2 * V[:, 0]) ** 2 - 0.5 * (2 * V[:, 1]) ** 2)
    me.vertices.foreach_set('co', V.ravel())
    cuts = np.linspace(-1, 1, k + 1)[1:-1]
    h = 2.0 / n

    def on_cut(c):
        if not len(cuts):
            return np.zeros(len(c), bool)
        return np.abs(c[:, None] - cuts[None, :]).min(1) < 0.25 * h

    def pred(a, b):
        return (on_cut(a[:, 0]) & on_cut(b[:, 0])) | (on_cut(a[:, 1]) & on_cut(b[:, 1]))
    mark_seams(me, pred)
    return obj, f"bump grid {n}x{n} quads, {k}x{k} islands by seams"


def monkey(bpy, seams):
    bpy.ops.mesh.primitive_monkey_add()
    obj = bpy.context.object
    if seams:
        mark_seams(obj.data, lambda a, b: (np.abs(a[:, 0]) < 1e-5) & (np.abs(b[:, 0]) < 1e-5))
    return obj, "Suzanne (monkey)" + (", seams on the symmetry plane" if seams else ", no seams")


def two_holes(bpy):
    from core.surfaces import make_surface
    V, F = make_surface('bump', 33)
    inside = ((np.abs(V[:, 0] + 0.9) < 0.4) & (np.abs(V[:, 1]) < 0.4)) | \
             (np.hypot(V[:, 0] - 0.9, V[:, 1] - 0.3) < 0.5)
    F = F[~inside[F].any(1)]
    used = np.unique(F)
    remap = np.full(len(V), -1)
    remap[used] = np.arange(len(used))
    me = bpy.data.meshes.new('holes')
    me.from_pydata(V[used].tolist(), [], remap[F].tolist())
    obj = bpy.data.objects.new('holes', me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    return obj, "bump 33x33 with two holes"


def acceptance(bpy, pkg):
    """The issue's acceptance cases through the operator (uniform boundary, default options)."""
    print("| case | triangles | islands | holes filled | flips | qc_mean per island | mu_ratio (all "
          "islands) | total s |")
    print("|---|---|---|---|---|---|---|---|")
    cases = [lambda: sphere(bpy, 32, 16), lambda: sphere(bpy, 48, 24), lambda: monkey(bpy, False),
             lambda: monkey(bpy, True), lambda: two_holes(bpy)]
    for make in cases:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        pkg.register()
        obj, label = make()
        t = time.perf_counter()
        bpy.ops.uv.conformal_flatten(boundary='UNIFORM')
        total = time.perf_counter() - t
        r = json.loads(obj.data['conformal_flatten_report'])
        qc = ', '.join(f"{i['qc_mean']:.4f}" for i in r['island_reports'])
        print(f"| {label} | {r['triangles']:,} | {r['islands']} | {r['holes_filled']} | {r['flips']} | "
              f"{qc} | {r['mu_ratio']:.3g} | {total:.2f} |", flush=True)
        pkg.unregister()
    print()


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument('--quick', action='store_true', help='small meshes only')
    ap.add_argument('--acceptance', action='store_true', help='only the acceptance table')
    args = ap.parse_args()
    import bpy
    from tools import devpkg
    pkg = devpkg.load()
    acceptance(bpy, pkg)
    if args.acceptance:
        return
    cases = [lambda: sphere(bpy, 64, 32), lambda: grid_islands(bpy, 64, 4)]
    if not args.quick:
        cases += [lambda: sphere(bpy, 256, 128), lambda: grid_islands(bpy, 200, 8)]
    runs = [('SHELF', None), ('BLENDER', 'AABB'), ('BLENDER', 'CONVEX'), ('BLENDER', 'CONCAVE')]
    print("| mesh | triangles | islands | boundary | packer | flatten s | write + pack s | total s | "
          "flips | worst qc_mean |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for make in cases:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        pkg.register()
        obj, label = make()
        for boundary in ('AREA', 'UNIFORM'):
            for packer, shape in runs:
                kw = {'packer': packer}
                if shape:
                    kw['pack_shape'] = shape
                t = time.perf_counter()
                bpy.ops.uv.conformal_flatten(boundary=boundary, **kw)
                total = time.perf_counter() - t
                r = json.loads(obj.data['conformal_flatten_report'])
                worst = max(i['qc_mean'] for i in r['island_reports'])
                name = 'shelf (core)' if packer == 'SHELF' else f"Pack Islands {shape.lower()}"
                print(f"| {label} | {r['triangles']:,} | {r['islands']} | {boundary.lower()} | {name} | "
                      f"{r['seconds']['flatten']:.2f} | {r['seconds']['write']:.2f} | {total:.2f} | "
                      f"{r['flips']} | {worst:.4f} |", flush=True)
        pkg.unregister()


if __name__ == '__main__':
    main()
