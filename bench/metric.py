"""Benchmarks of the metric reconstruction (core.metric, paper section 8). Prints markdown tables.

    .venv/bin/python bench/metric.py            # every table (several minutes on a busy machine)
    .venv/bin/python bench/metric.py forward    # one table: forward | sweep | noise | weights | flatten

- forward: the forward model alone, constant metric on the paper's surface (bump, 65 x 65): travel
  times by fast marching on the conformal plane against exact polyhedral geodesic distances (MMP,
  tests/data/geodesic_ref_bump_65.npz), per grid size.
- sweep: the section 8.2 experiment for several true metrics and 6, 12, 24 sources and sensors:
  area-weighted mean relative error of the recovery and of the best constant metric.
- noise: the demo metric with Gaussian noise added to the synthetic times.
- weights: sensitivity to the thin-plate weight (curvature) and the control grid.
- flatten: the same experiment on bump3 (strong curvature) with the free (LSCM), area and uniform
  flattenings.
Timings are wall-clock seconds on a shared 2-core machine: noisy."""
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from core import metric  # noqa: E402
from core.cli.reconstruct_demo import TRUE_METRIC_TEXT, demo, true_metric  # noqa: E402
from core.disk.flatten import flatten  # noqa: E402
from core.surfaces import make_surface  # noqa: E402

METRICS = {
    'demo': (true_metric, TRUE_METRIC_TEXT),
    'ramp': (lambda P: np.exp(0.2 * P[:, 0]), 'exp(0.2 x)'),
    'blob': (lambda P: 1 + 0.6 * np.exp(-((P[:, 0] - 0.6) ** 2 + (P[:, 1] + 0.4) ** 2)),
             '1 + 0.6 exp(-((x - 0.6)^2 + (y + 0.4)^2))'),
    'wave': (lambda P: np.exp(0.3 * np.sin(0.9 * P[:, 0] + 0.3) * np.cos(0.7 * P[:, 1])),
             'exp(0.3 sin(0.9 x + 0.3) cos(0.7 y))'),
    # a narrow feature: beyond what 36 boundary-to-boundary times can resolve
    'spot': (lambda P: 1 + 0.5 * np.exp(-((P[:, 0] - 0.3) ** 2 + (P[:, 1] - 0.2) ** 2) / 0.25),
             '1 + 0.5 exp(-((x - 0.3)^2 + (y - 0.2)^2) / 0.25)'),
}
DATA = {}


def table(header, rows):
    print('| ' + ' | '.join(header) + ' |')
    print('|' + '---|' * len(header))
    for r in rows:
        print('| ' + ' | '.join(str(x) for x in r) + ' |')
    print(flush=True)


def forward():
    print('### Forward model: constant metric on bump 65 x 65 vs exact geodesics (MMP), vertices '
          'farther than 0.2 from the source\n')
    V, F = make_surface('bump', 65)
    ref = np.load(os.path.join(ROOT, 'tests', 'data', 'geodesic_ref_bump_65.npz'))
    flat = flatten(V, F, boundary='uniform', fit='true_scale', bound=False)
    rows = []
    for cells in (64, 96, 192, 384):
        grid = metric.make_grid(flat.uv, F, metric.vertex_mu(V, F, flat.uv), cells)
        w = 1.0 / grid.mu
        idx, wts = grid.bilinear(flat.uv)
        errs = []
        t0 = time.perf_counter()
        for k, s in enumerate(ref['sources']):
            T, _ = metric.march(grid, w, flat.uv[s])
            t = metric.sample(T, idx, wts)
            d = ref['dist'][k].astype(np.float64)
            far = np.linalg.norm(V - V[s], axis=1) > 0.2      # 5% of the side
            errs.append((t[far] - d[far]) / d[far])
        e = np.concatenate(errs)
        rows.append([cells, f'{np.mean(e):+.4f}', f'{np.mean(np.abs(e)):.4f}',
                     f'{np.abs(e).max():.4f}',
                     f'{(time.perf_counter() - t0) / len(ref["sources"]):.3f}'])
    table(['grid cells', 'mean signed rel. error', 'mean abs rel. error', 'max abs rel. error',
           's per source'], rows)


def sweep():
    print('### Section 8.2: mean relative error of the recovered metric (bump, boundary sources '
          'and sensors)\n')
    rows = []
    for name, (fn, text) in METRICS.items():
        for k in (6, 12, 24):
            r = demo(k, k, data=DATA, metric=fn, metric_text=text)
            rows.append([name, f'{k} x {k}', f"{r['mean_relative_error']:.4f}",
                         f"{r['max_relative_error']:.3f}", f"{r['constant_relative_error']:.4f}",
                         f"{r['constant_relative_error'] / r['mean_relative_error']:.1f}",
                         r['iterations'], f"{r['seconds_parts']['recovery']:.1f}"])
    table(['true metric', 'sources x sensors', 'mean rel. error', 'max rel. error',
           'best constant: mean rel. error', 'constant / recovery', 'iterations', 'recovery s'],
          rows)
    print('Metrics: ' + '; '.join(f'{k}: `{t}`' for k, (_, t) in METRICS.items()) + '\n')


def noise():
    print('### Noise: relative Gaussian noise on the synthetic times (demo metric; the recovery '
          'assumes the added level)\n')
    rows = []
    for k in (6, 24):
        for nz in (0.0, 0.005, 0.01, 0.02):
            errs = [demo(k, k, data=DATA, add_noise=nz, seed=s)['mean_relative_error']
                    for s in ((0, 1, 2) if nz > 0 else (0,))]
            rows.append([f'{k} x {k}', nz, f'{np.mean(errs):.4f}', f'{np.max(errs):.4f}'])
    table(['sources x sensors', 'added noise', 'mean rel. error (mean of 3 seeds)', 'worst seed'],
          rows)


def weights():
    print('### Regularisation: thin-plate weight and control grid (demo metric)\n')
    rows = []
    for curvature in (1, 3, 10, 30, 100):
        r6 = demo(6, 6, data=DATA, curvature=curvature)
        r24 = demo(24, 24, data=DATA, curvature=curvature)
        rows.append([f'curvature {curvature}', f"{r6['mean_relative_error']:.4f}",
                     f"{r24['mean_relative_error']:.4f}"])
    for control in (6, 12):
        r6 = demo(6, 6, data=DATA, control=control)
        r24 = demo(24, 24, data=DATA, control=control)
        rows.append([f'control {control}', f"{r6['mean_relative_error']:.4f}",
                     f"{r24['mean_relative_error']:.4f}"])
    table(['setting (defaults: curvature 10, control 8)', '6 x 6', '24 x 24'], rows)


def flatten_modes():
    print('### Flattening mode on bump3 (demo metric, 6 x 6 and 24 x 24)\n')
    rows = []
    for mode in ('free', 'area', 'uniform'):
        V, F = make_surface('bump3', 65)
        res = flatten(V, F, boundary=mode, fit='true_scale', bound=False)
        r6 = demo(6, 6, data=DATA, surface='bump3', boundary=mode)
        r24 = demo(24, 24, data=DATA, surface='bump3', boundary=mode)
        rows.append([mode, f"{res.report['mu_ratio']:.3f}", f"{r6['mean_relative_error']:.4f}",
                     f"{r24['mean_relative_error']:.4f}", f"{r6['constant_relative_error']:.4f}"])
    table(['boundary', 'mu_ratio', '6 x 6', '24 x 24', 'best constant'], rows)


TABLES = {'forward': forward, 'sweep': sweep, 'noise': noise, 'weights': weights,
          'flatten': flatten_modes}


def main(argv):
    names = argv or list(TABLES)
    for name in names:
        if name not in TABLES:
            raise SystemExit(f"unknown table {name!r}: choose from {', '.join(TABLES)}")
        TABLES[name]()


if __name__ == '__main__':
    main(sys.argv[1:])
