"""Issue 16, the add-on at scale: ``bpy.ops.uv.conformal_flatten`` (default options: uniform boundary)
on the ``bump`` grid at about 1M and 2M triangles, headless in the bpy module, and the 2M / 1M ratio
of the operator's wall time (the issue's line: at most 2.2x).

    .venv/bin/python bench/addon_scale.py                    # 1M and 2M, interleaved, medians of 3
    .venv/bin/python bench/addon_scale.py --sizes 1000000 --repeat 1

Each run is a fresh child process (its own peak resident set size, Blender included). The mesh is
built with ``foreach_set`` before the clock starts; the time is the operator call alone, which reads
the mesh, flattens it in the core, and writes the UVs and the mu attribute. Runs are interleaved
(1M, 2M, 1M, 2M, ...) so that a change of load on a shared machine hits both sizes alike.
"""
import argparse
import json
import os
import statistics
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)


def grid_n(triangles):
    """Grid size n of the bump surface with about ``triangles`` = 2 (n-1)^2 triangles."""
    return int(round((triangles / 2) ** 0.5)) + 1


def child(n):
    """Build the bump mesh with grid size n in Blender, run the operator, print one JSON line."""
    import resource

    import bpy
    import numpy as np

    from core.surfaces import make_surface
    from tools import devpkg

    bpy.ops.wm.read_factory_settings(use_empty=True)
    pkg = devpkg.load()
    pkg.register()
    V, F = make_surface('bump', n)
    me = bpy.data.meshes.new('bump')
    me.vertices.add(len(V))
    me.vertices.foreach_set('co', V.astype(np.float32).ravel())
    me.loops.add(F.size)
    me.loops.foreach_set('vertex_index', F.astype(np.int32).ravel())
    me.polygons.add(len(F))
    me.polygons.foreach_set('loop_start', np.arange(0, F.size, 3, dtype=np.int32))
    me.update(calc_edges=True)
    me.validate()
    obj = bpy.data.objects.new('bump', me)
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    obj.select_set(True)
    del V, F
    t = time.perf_counter()
    result = bpy.ops.uv.conformal_flatten()
    wall = time.perf_counter() - t
    report = json.loads(me.get('conformal_flatten_report', '{}'))
    print(json.dumps({'n': n, 'triangles': len(me.polygons), 'result': sorted(result), 'seconds': wall,
                      'peak_mb': resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
                      'mu_ratio': report.get('mu_ratio'), 'flips': report.get('flips'),
                      'core_seconds': report.get('seconds')}))


def run(n):
    out = subprocess.run([sys.executable, os.path.abspath(__file__), '--child', str(n)], check=True,
                         capture_output=True, text=True).stdout
    return json.loads(out.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--sizes', type=int, nargs='+', default=[1_000_000, 2_000_000])
    ap.add_argument('--repeat', type=int, default=3)
    ap.add_argument('--child', type=int, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child)
        return
    runs = {s: [] for s in args.sizes}
    for _ in range(args.repeat):
        for s in args.sizes:
            r = run(grid_n(s))
            runs[s].append(r)
            print(f"  {r['triangles']:,} triangles: {r['seconds']:.1f} s, peak {r['peak_mb']:.0f} MB, "
                  f"mu_ratio {r['mu_ratio']}, flips {r['flips']}", file=sys.stderr, flush=True)
    try:
        load = f"load average {os.getloadavg()[0]:.1f} on {os.cpu_count()} cores"
    except OSError:
        load = ''
    print(f"add-on `uniform` (operator defaults), medians of {args.repeat}, {load}\n")
    print("| triangles | operator s (median) | runs s | core total s (median) | peak MB | mu_ratio | flips "
          "| vs smallest |")
    print("|---|---|---|---|---|---|---|---|")
    base = None
    for s in args.sizes:
        rs = runs[s]
        med = statistics.median(r['seconds'] for r in rs)
        base = base or med
        each = ', '.join(f"{r['seconds']:.1f}" for r in rs)
        core = [r.get('core_seconds') for r in rs]
        core = [c.get('total') if isinstance(c, dict) else c for c in core]
        core = f"{statistics.median(core):.1f}" if all(c is not None for c in core) else '-'
        print(f"| {rs[0]['triangles']:,} | {med:.1f} | {each} | {core} | "
              f"{max(r['peak_mb'] for r in rs):.0f} | {rs[0]['mu_ratio']:.4f} | {rs[0]['flips']} | "
              f"{med / base:.2f}x |")


if __name__ == '__main__':
    main()
