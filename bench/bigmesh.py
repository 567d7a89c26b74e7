"""Big meshes: time and peak memory of flattening up to ~1M triangles.

    .venv/bin/python bench/bigmesh.py                 # 125k, 250k, 500k, 1M triangles
    .venv/bin/python bench/bigmesh.py --sizes 1000000 --modes flatten-area unwrap-area

Each case runs in a fresh child process, so its peak resident set size (ru_maxrss) is its own. The
mesh is the paper's ``bump`` height field on an n x n grid (2(n-1)^2 triangles). ``unwrap-area``
cuts it into 4 islands with two seams and packs them. Progress goes to stderr as the run goes.
Timings are wall-clock on a shared machine: treat them as rough."""
import argparse
import json
import os
import resource
import subprocess
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
MODES = ('flatten-area', 'unwrap-area', 'flatten-free', 'flatten-uniform')


def child(mode, n):
    sys.path.insert(0, ROOT)
    import numpy as np
    from core.surfaces import make_surface

    V, F = make_surface('bump', n)
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    last = [0.0]

    def progress(f, msg):
        if f - last[0] >= 0.05 or f >= 1.0 or f < last[0]:
            last[0] = f
            print(f"  {100 * f:5.1f}%  {msg}", file=sys.stderr, flush=True)

    t = time.perf_counter()
    if mode.startswith('flatten'):
        from core.disk.flatten import flatten
        res = flatten(V, F, boundary=mode.split('-')[1], progress=progress, max_faces=None)
        rep = res.report
        out = {'flips': rep['flips'], 'qc_mean': rep['qc_mean'], 'mu_ratio': rep['mu_ratio'],
               'seconds_parts': rep.get('seconds')}
    else:
        from core.atlas.islands import unwrap
        mid = n // 2
        row = mid * n + np.arange(n - 1)                   # the horizontal grid line y = 0
        col = np.arange(n - 1) * n + mid                   # the vertical grid line x = 0
        seams = np.concatenate([np.stack([row, row + 1], 1), np.stack([col, col + n], 1)])
        res = unwrap(V, F, seams, boundary='area', progress=progress, max_faces=None)
        rep = res.report
        out = {'flips': rep['flips'], 'qc_mean': rep['qc_mean_worst'], 'mu_ratio': rep['mu_ratio_worst'],
               'islands': rep['islands'], 'overlaps': rep['overlaps']}
    out.update(seconds=time.perf_counter() - t, triangles=len(F), vertices=len(V),
               rss_mesh_mb=base / 1024, rss_peak_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024)
    print(json.dumps(out))


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--sizes', type=int, nargs='+', default=[125_000, 250_000, 500_000, 1_000_000],
                    help='target triangle counts')
    ap.add_argument('--modes', nargs='+', choices=MODES, default=['flatten-area', 'unwrap-area'])
    ap.add_argument('--child', nargs=2, help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child[0], int(args.child[1]))
        return
    print("| mode | triangles | vertices | seconds | peak RSS MB | RSS after mesh MB | bytes/triangle "
          "| flips | qc_mean | mu_ratio |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for size in args.sizes:
        n = int(round((size / 2) ** 0.5)) + 1
        for mode in args.modes:
            print(f"running {mode} on {2 * (n - 1) ** 2:,} triangles", file=sys.stderr, flush=True)
            p = subprocess.run([sys.executable, __file__, '--child', mode, str(n)], stdout=subprocess.PIPE,
                               text=True)
            if p.returncode:
                print(f"| {mode} | {2 * (n - 1) ** 2:,} | failed (exit {p.returncode}) |||||||")
                continue
            r = json.loads(p.stdout.strip().splitlines()[-1])
            per_tri = (r['rss_peak_mb'] - r['rss_mesh_mb']) * 2 ** 20 / r['triangles']
            print(f"| {mode} | {r['triangles']:,} | {r['vertices']:,} | {r['seconds']:.1f} | "
                  f"{r['rss_peak_mb']:.0f} | {r['rss_mesh_mb']:.0f} | {per_tri:.0f} | {r['flips']} | "
                  f"{r['qc_mean']:.4f} | {r['mu_ratio']:.4f} |", flush=True)


if __name__ == '__main__':
    main()
