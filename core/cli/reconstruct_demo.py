"""``python -m core reconstruct-demo [--sources 6 --sensors 6] [--sweep] [--json]``.

The experiment of the paper's section 8.2: a known smooth metric on the paper's surface (``bump``),
sources and sensors around the boundary, synthetic travel times computed on a finer mesh, a separate
flattening and a finer grid than the recovery uses (no inverse crime), then the recovery and the
paper's error measure, the area-weighted mean of ``|xi_true - xi_rec| / xi_true`` over the surface.
The best constant metric fitted to the same times is reported as the baseline."""
import json
import time

import numpy as np

from ..errors import ConformalError
from ..disk.flatten import BOUNDARY_MODES, flatten
from ..metric import (DEFAULT_CELLS, DEFAULT_CONTROL, DEFAULT_CURVATURE, DEFAULT_NOISE, DEFAULT_SMOOTHNESS,
                     reconstruct, simulate_times, vertex_areas)
from ..surfaces import make_surface
from ..mesh.topology import boundary_loops

TRUE_METRIC_TEXT = 'xi = exp(0.2 x - 0.1 y + 0.3 exp(-((x + 0.5)^2 + (y - 0.4)^2) / 1.2))'
PAPER_ERROR = 0.06


def true_metric(P):
    """The demo's metric (k,) at surface points ``P`` (k,3): a ramp with a broad bump, in log."""
    x, y = P[:, 0], P[:, 1]
    return np.exp(0.2 * x - 0.1 * y + 0.3 * np.exp(-((x + 0.5) ** 2 + (y - 0.4) ** 2) / 1.2))


def boundary_points(V, loop, k, offset):
    """``k`` vertices of the boundary ``loop`` evenly spaced by arc length, the first at the fraction
    ``offset / k`` of the loop's length from ``loop[0]``."""
    P = V[loop]
    seg = np.linalg.norm(np.roll(P, -1, axis=0) - P, axis=1)
    s = np.r_[0.0, np.cumsum(seg)[:-1]]
    L = seg.sum()
    target = (np.arange(k) + offset) / k * L
    gap = np.abs((s[None, :] - target[:, None] + L / 2) % L - L / 2)
    return loop[np.argmin(gap, axis=1)]


def error(xi_true, xi, weights):
    """Area-weighted mean of ``|xi_true - xi| / xi_true``."""
    return float((np.abs(xi_true - xi) / xi_true * weights).sum() / weights.sum())


def demo(sources=6, sensors=6, n=65, fine=129, cells=DEFAULT_CELLS, fine_cells=4 * DEFAULT_CELLS,
         boundary='uniform', control=DEFAULT_CONTROL, smoothness=DEFAULT_SMOOTHNESS,
         curvature=DEFAULT_CURVATURE, add_noise=0.0, noise=None, seed=0, data=None,
         surface='bump', metric=None, metric_text=None):
    """Run the experiment once; returns a dict of results (errors are dimensionless, seconds wall
    time). ``surface``: a ``core.surfaces`` name; ``metric``: callable (k,3) points -> (k,) positive
    metric (default ``true_metric``), described by ``metric_text``. ``add_noise``: relative Gaussian
    noise added to the synthetic times (seeded by ``seed``);
    ``noise``: the noise level the recovery assumes (default: the larger of ``DEFAULT_NOISE`` and
    ``add_noise``). ``data`` caches the meshes and flattenings between runs."""
    if sources < 1 or sensors < 1:
        raise ConformalError("need at least one source and one sensor")
    if fine < n:
        raise ConformalError(f"the synthetic mesh ({fine}) must be at least as fine as the recovery "
                             f"mesh ({n})")
    t0 = time.perf_counter()
    data = {} if data is None else data
    metric = metric or true_metric
    key = (surface, n, fine, boundary)
    if key not in data:
        V, F = make_surface(surface, n)
        Vf, Ff = make_surface(surface, fine)
        data[key] = (V, F, flatten(V, F, boundary=boundary, fit='true_scale', bound=False),
                     Vf, Ff, flatten(Vf, Ff, boundary=boundary, fit='true_scale', bound=False))
    V, F, flat, Vf, Ff, flat_f = data[key]
    loop = boundary_loops(F, len(V))[0]
    src = boundary_points(V, loop, sources, 0.0)
    sns = boundary_points(V, loop, sensors, 0.5)
    S, T = (a.ravel() for a in np.meshgrid(src, sns, indexing='ij'))
    # the same surface points on the fine mesh
    near = lambda idx: np.argmin(((Vf[None, :, :] - V[idx][:, None, :]) ** 2).sum(2), axis=1)
    src_f, sns_f = near(src), near(sns)
    Sf, Tf = (a.ravel() for a in np.meshgrid(src_f, sns_f, indexing='ij'))
    t1 = time.perf_counter()
    times = simulate_times(Vf, Ff, metric(Vf), Sf, Tf, cells=fine_cells, flat=flat_f)
    if add_noise > 0:
        times = times * (1 + add_noise * np.random.default_rng(seed).standard_normal(len(times)))
        times = np.maximum(times, 0.0)
    if noise is None:
        noise = max(DEFAULT_NOISE, add_noise)
    t2 = time.perf_counter()
    res = reconstruct(V, F, S, T, times, cells=cells, control=control, noise=noise,
                      smoothness=smoothness, curvature=curvature, flat=flat)
    t3 = time.perf_counter()
    xt = metric(V)
    wa = vertex_areas(V, F)
    err = error(xt, res.xi, wa)
    const = res.report['constant_fit']
    err_c = error(xt, np.full(len(V), const), wa)
    r = res.report
    return {
        'surface': surface, 'true_metric': metric_text or TRUE_METRIC_TEXT, 'boundary': boundary,
        'sources': int(sources), 'sensors': int(sensors), 'measurements': int(len(times)),
        'mean_relative_error': err,
        'max_relative_error': float(np.max(np.abs(xt - res.xi) / xt)),
        'constant_metric': const, 'constant_relative_error': err_c,
        'baseline_over_recovery': err_c / err if err > 0 else float('inf'),
        'paper_error': PAPER_ERROR,
        'true_metric_range': [float(xt.min()), float(xt.max())],
        'rms_relative_misfit': r['rms_relative_misfit'],
        'iterations': r['iterations'], 'forward_solves': r['forward_solves'],
        'added_noise': add_noise, 'noise_level': noise,
        'recovery_mesh': [len(V), len(F)], 'synthetic_mesh': [len(Vf), len(Ff)],
        'recovery_grid': r['grid'], 'synthetic_grid_cells': int(fine_cells), 'control': r['control'],
        'smoothness': smoothness, 'curvature': curvature,
        'seconds': round(time.perf_counter() - t0, 2),
        'seconds_parts': {'setup': round(t1 - t0, 2), 'synthetic': round(t2 - t1, 2),
                          'recovery': round(t3 - t2, 2)},
    }


def add_arguments(p):
    p.add_argument('--sources', type=int, default=6, help='sources around the boundary (default 6)')
    p.add_argument('--sensors', type=int, default=6, help='sensors around the boundary (default 6)')
    p.add_argument('--sweep', action='store_true',
                   help='also run with 12 and 24 sources and sensors and print a table')
    p.add_argument('--n', type=int, default=65, help='recovery mesh: n x n grid (default 65)')
    p.add_argument('--fine', type=int, default=129,
                   help='synthetic-data mesh: fine x fine grid (default 129)')
    p.add_argument('--cells', type=int, default=DEFAULT_CELLS,
                   help=f'recovery grid cells along the longer side (default {DEFAULT_CELLS})')
    p.add_argument('--fine-cells', type=int, default=4 * DEFAULT_CELLS,
                   help=f'synthetic-data grid cells (default {4 * DEFAULT_CELLS})')
    p.add_argument('--boundary', choices=BOUNDARY_MODES, default='uniform',
                   help='flattening mode (default uniform)')
    p.add_argument('--smoothness', type=float, default=DEFAULT_SMOOTHNESS,
                   help=f'weight of the Dirichlet smoothness term (default {DEFAULT_SMOOTHNESS:g})')
    p.add_argument('--curvature', type=float, default=DEFAULT_CURVATURE,
                   help=f'weight of the thin-plate smoothness term (default {DEFAULT_CURVATURE:g})')
    p.add_argument('--control', type=int, default=DEFAULT_CONTROL,
                   help=f'B-spline control values along the longer side (default {DEFAULT_CONTROL})')
    p.add_argument('--add-noise', type=float, default=0.0,
                   help='relative Gaussian noise added to the synthetic times (default 0)')
    p.add_argument('--noise', type=float, default=None,
                   help='relative error of the times the recovery assumes (default: the larger of '
                        f'{DEFAULT_NOISE:g} and --add-noise)')
    p.add_argument('--json', action='store_true', help='print the result as JSON on the last line')


def _line(r):
    return (f"{r['sources']:3d} sources x {r['sensors']:3d} sensors: mean relative error "
            f"{r['mean_relative_error']:.4f} (best constant {r['constant_relative_error']:.4f}, "
            f"{r['baseline_over_recovery']:.1f}x worse), {r['iterations']} iterations, "
            f"{r['seconds']:.1f} s")


def run(args):
    if args.cells < 8 or args.fine_cells < args.cells:
        raise ConformalError("need --cells >= 8 and --fine-cells >= --cells (no inverse crime)")
    if not args.add_noise >= 0:
        raise ConformalError(f"--add-noise must be non-negative, got {args.add_noise}")
    opts = dict(n=args.n, fine=args.fine, cells=args.cells, fine_cells=args.fine_cells,
                boundary=args.boundary, control=args.control, smoothness=args.smoothness,
                curvature=args.curvature, add_noise=args.add_noise, noise=args.noise)
    data = {}
    main = demo(args.sources, args.sensors, data=data, **opts)
    print(f"surface bump, {TRUE_METRIC_TEXT} (range {main['true_metric_range'][0]:.3f} .. "
          f"{main['true_metric_range'][1]:.3f})")
    print(f"synthetic times: {main['synthetic_mesh'][0]} vertices, {args.fine_cells}-cell grid; "
          f"recovery: {main['recovery_mesh'][0]} vertices, grid {main['recovery_grid']}, control "
          f"{main['control']}")
    print(_line(main))
    sweep = []
    if args.sweep:
        for k in (12, 24):
            r = demo(k, k, data=data, **opts)
            sweep.append({key: r[key] for key in ('sources', 'sensors', 'mean_relative_error',
                                                  'constant_relative_error', 'iterations',
                                                  'seconds')})
            print(_line(r))
        main['sweep'] = sweep
    print(f"paper (section 8.2, 6 x 6): {PAPER_ERROR}")
    if args.json:
        print(json.dumps(main))
    return 0
