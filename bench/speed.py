"""Issue 2 speed benchmark: a 100k-triangle disk (bump at n = 225) in ``area`` and ``uniform`` mode,
against Blender's ``bpy.ops.uv.unwrap(method='CONFORMAL')`` on the same mesh in the same process,
with the core's peak memory (measured in a child process), then scaling up to about 1M triangles.

    .venv/bin/python bench/speed.py [--sizes 225 400 708] [--surface bump] [--no-blender]
"""
import argparse
import json
import os
import subprocess
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

CHILD = r'''
import json, resource, sys, time
def peak_mb():
    # VmHWM starts afresh at exec; ru_maxrss would include the forked parent (bpy) before exec
    try:
        for line in open('/proc/self/status'):
            if line.startswith('VmHWM:'):
                return int(line.split()[1]) / 1024
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
sys.path.insert(0, {root!r})
from core import flatten, make_surface
V, F = make_surface({surface!r}, {n})
t = time.perf_counter()
r = flatten(V, F, boundary={mode!r}, bound=False).report
sec = time.perf_counter() - t
print(json.dumps(dict(seconds=sec, parts=r['seconds'], mu_ratio=r['mu_ratio'], qc_mean=r['qc_mean'],
                      flips=r['flips'], faces=r['faces'],
                      peak_mb=peak_mb())))
'''


def run_core(surface, n, mode):
    code = CHILD.format(root=ROOT, surface=surface, n=n, mode=mode)
    out = subprocess.run([sys.executable, '-c', code], capture_output=True, text=True, check=True)
    return json.loads(out.stdout.strip().splitlines()[-1])


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--surface', default='bump')
    ap.add_argument('--sizes', type=int, nargs='*', default=[225, 400, 708])
    ap.add_argument('--no-blender', action='store_true')
    ap.add_argument('--blender-max-n', type=int, default=225,
                    help='run Blender\'s unwrap only up to this grid size (it is slow)')
    args = ap.parse_args()
    print(f"{'n':>5} {'faces':>9} {'mode':8} {'seconds':>8} {'peak MB':>8} {'mu_ratio':>8} "
          f"{'qc_mean':>8} {'flips':>5} {'vs Blender CONFORMAL':>21}")
    for n in args.sizes:
        base = None
        if not args.no_blender and n <= args.blender_max_n:
            from core import make_surface
            from blender_unwrap import blender_unwrap
            V, F = make_surface(args.surface, n)
            _, base = blender_unwrap(V, F, 'CONFORMAL')
            print(f"{n:5d} {len(F):9d} {'blender':8} {base:8.2f}")
        for mode in ('area', 'uniform'):
            r = run_core(args.surface, n, mode)
            ratio = f"{base / r['seconds']:20.1f}x" if base else ''
            print(f"{n:5d} {r['faces']:9d} {mode:8} {r['seconds']:8.2f} {r['peak_mb']:8.0f} "
                  f"{r['mu_ratio']:8.4f} {r['qc_mean']:8.4f} {r['flips']:5d} {ratio}")
            print('      parts: ' + ', '.join(f"{k} {v:.2f}" for k, v in r['parts'].items()))
            sys.stdout.flush()


if __name__ == '__main__':
    main()
