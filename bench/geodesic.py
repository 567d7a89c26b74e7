"""Geodesic distance by fast marching on the conformal plane: accuracy against exact polyhedral
geodesics (MMP) and speed. Prints markdown tables.

    .venv/bin/python bench/geodesic.py                 # all tables
    .venv/bin/python bench/geodesic.py --quick         # acceptance table only

Tables:
1. Acceptance: bump n=129, grid 1024, sources 0 (corner), 8320 (centre), 64 (edge midpoint) and
   0+8320 together; scikit-fmm path and the numpy sweep fallback.
2. The paper's point: the same grid (256 and 1024) on the `free` (LSCM) map and on the `area` and
   `uniform` maps, for bump (n=129) and edgebump (n=65 and 129). A uniform conformal factor spreads the
   grid's resolution evenly over the surface.
3. Error and time against grid size (256 .. 2048).

Errors are relative to the exact distance, over vertices farther than 0.05 from the source (mean and
max). Exact references: tests/data/geodesic_ref_bump_129.npz, and pygeodesic (a dev dependency) on
the fly for edgebump. Timings are wall-clock seconds on a shared machine: treat them as noisy."""
import argparse
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, 'bench'))

from core.disk.flatten import flatten  # noqa: E402
from core.geodesic.solver import geodesic_distance  # noqa: E402
from core.surfaces import make_surface  # noqa: E402

EXCLUDE = 0.05


def errors(V, d, D, sources):
    """(mean, max) relative error over vertices farther than EXCLUDE from every source."""
    far = np.ones(len(V), bool)
    for s in sources:
        far &= np.linalg.norm(V - V[s], axis=1) > EXCLUDE
    r = np.abs(d[far] - D[far]) / D[far]
    return r.mean(), r.max()


def references(name, n, sources):
    """(k, n*n) exact distances: stored file if it has them, else pygeodesic."""
    path = os.path.join(ROOT, 'tests', 'data', f'geodesic_ref_{name}_{n}.npz')
    if os.path.exists(path):
        ref = np.load(path)
        if all(s in ref['sources'] for s in sources):
            idx = [int(np.flatnonzero(ref['sources'] == s)[0]) for s in sources]
            return ref['dist'][idx].astype(np.float64)
    from make_refdata import exact_distances
    V, F = make_surface(name, n)
    return exact_distances(V, F, sources)


def timed(fn, *a, **kw):
    t = time.perf_counter()
    out = fn(*a, **kw)
    return out, time.perf_counter() - t


def pct(x):
    return f"{100 * x:.4f}%"


def table_acceptance(uv_cache, solvers=('skfmm', 'sweep')):
    V, F = make_surface('bump', 129)
    uv, mu_ratio, t_flat = uv_cache('bump', 129, 'uniform')
    D = references('bump', 129, (0, 8320, 64))
    print(f"\n### bump n=129, grid 1024, `uniform` map (mu_ratio {mu_ratio:.3f}, flatten {t_flat:.1f} s)\n")
    print("| sources | solver | mean error | max error | solve + sampling (s) |")
    print("|---|---|---|---|---|")
    cases = [((0,), D[0]), ((8320,), D[1]), ((64,), D[2]), ((0, 8320), np.minimum(D[0], D[1]))]
    for solver in solvers:
        for src, ref in cases:
            (d, rep), t = timed(geodesic_distance, V, F, list(src), uv=uv, grid=1024, solver=solver)
            m, x = errors(V, d, ref, src)
            print(f"| {'+'.join(map(str, src))} | {rep['solver']} | {pct(m)} | {pct(x)} | {t:.2f} |")


def table_modes(uv_cache, grids=(256, 1024)):
    print("\n### Same grid, different conformal maps (scikit-fmm; mean of the three sources' mean "
          "errors, worst max error)\n")
    print("| surface | n | map | mu_ratio | grid | mean error | max error |")
    print("|---|---|---|---|---|---|---|")
    for name, n in (('bump', 129), ('edgebump', 65), ('edgebump', 129)):
        V, F = make_surface(name, n)
        c = n // 2
        srcs = (0, c * n + c, c)
        D = references(name, n, srcs)
        for mode in ('free', 'area', 'uniform'):
            uv, mu_ratio, _ = uv_cache(name, n, mode)
            for g in grids:
                ms, xs = [], []
                for s, ref in zip(srcs, D):
                    d, rep = geodesic_distance(V, F, [s], uv=uv, grid=g)
                    m, x = errors(V, d, ref, (s,))
                    ms.append(m)
                    xs.append(x)
                print(f"| {name} | {n} | {mode} | {mu_ratio:.3f} | {g} | {pct(np.mean(ms))} | "
                      f"{pct(max(xs))} |")


def table_grid(uv_cache, grids=(256, 512, 1024, 2048)):
    V, F = make_surface('bump', 129)
    uv, _, _ = uv_cache('bump', 129, 'uniform')
    D = references('bump', 129, (0, 8320))
    print("\n### Error and time against grid size (bump n=129, `uniform` map, scikit-fmm)\n")
    print("| grid | cell (mesh units) | source 0 mean / max | source 8320 mean / max | "
          "seconds (rasterise, solve, sample) |")
    print("|---|---|---|---|---|")
    for g in grids:
        row = []
        for s, ref in zip((0, 8320), D):
            (d, rep), t = timed(geodesic_distance, V, F, [s], uv=uv, grid=g)
            m, x = errors(V, d, ref, (s,))
            row.append(f"{pct(m)} / {pct(x)}")
        sec = rep['seconds']
        print(f"| {g} | {rep['cell']:.4f} | {row[0]} | {row[1]} | {t:.2f} ({sec['rasterise']:.2f}, "
              f"{sec['solve']:.2f}, {sec['sample']:.2f}) |")


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--quick', action='store_true', help='only the acceptance table (scikit-fmm)')
    args = ap.parse_args(argv)
    cache = {}

    def uv_cache(name, n, mode):
        key = (name, n, mode)
        if key not in cache:
            V, F = make_surface(name, n)
            res, t = timed(flatten, V, F, boundary=mode)
            cache[key] = (res.uv, res.report['mu_ratio'], t)
        return cache[key]

    if args.quick:
        table_acceptance(uv_cache, solvers=('skfmm',))
        return 0
    table_acceptance(uv_cache)
    table_modes(uv_cache)
    table_grid(uv_cache)
    return 0


if __name__ == '__main__':
    sys.exit(main())
