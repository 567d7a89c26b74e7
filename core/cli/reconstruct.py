"""``python -m core reconstruct MESH.obj TIMES.csv OUT.txt [--json]``.

TIMES.csv: one measurement per row, ``source_vertex,sensor_vertex,time`` (0-based vertex indices in
the OBJ's vertex order, time in mesh length units times the metric), optional header line. OUT.txt:
one recovered metric value per vertex, in the OBJ's vertex order."""
import json

import numpy as np

from ..errors import ConformalError
from ..disk.flatten import BOUNDARY_MODES
from ..metric import (DEFAULT_CELLS, DEFAULT_CONTROL, DEFAULT_CURVATURE, DEFAULT_NOISE, DEFAULT_SMOOTHNESS,
                     read_times, reconstruct)
from ..io.obj import read_obj, write_values


def add_arguments(p):
    p.add_argument('mesh', help='input OBJ (a disk-topology mesh; n-gons are triangulated)')
    p.add_argument('times', help="CSV rows 'source_vertex,sensor_vertex,time' (0-based vertices)")
    p.add_argument('output', help='output text file: one metric value per vertex')
    p.add_argument('--boundary', choices=BOUNDARY_MODES, default='uniform',
                   help='flattening mode (default uniform)')
    p.add_argument('--cells', type=int, default=DEFAULT_CELLS,
                   help=f'grid cells along the longer UV side (default {DEFAULT_CELLS})')
    p.add_argument('--control', type=int, default=DEFAULT_CONTROL,
                   help=f'B-spline control values along the longer side (default {DEFAULT_CONTROL})')
    p.add_argument('--noise', type=float, default=DEFAULT_NOISE,
                   help='expected relative error of the times; raise it for noisy measurements '
                        f'(default {DEFAULT_NOISE:g})')
    p.add_argument('--smoothness', type=float, default=DEFAULT_SMOOTHNESS,
                   help=f'weight of the Dirichlet smoothness term (default {DEFAULT_SMOOTHNESS:g})')
    p.add_argument('--curvature', type=float, default=DEFAULT_CURVATURE,
                   help=f'weight of the thin-plate smoothness term (default {DEFAULT_CURVATURE:g})')
    p.add_argument('--max-iter', type=int, default=60, help='maximum iterations (default 60)')
    p.add_argument('--json', action='store_true', help='print the report as JSON')


def run(args):
    if args.max_iter < 1:
        raise ConformalError(f"--max-iter must be at least 1, got {args.max_iter}")
    mesh = read_obj(args.mesh)
    F, _ = mesh.triangles()
    src, sns, times = read_times(args.times, len(mesh.V))
    res = reconstruct(mesh.V, F, src, sns, times, boundary=args.boundary, cells=args.cells,
                      control=args.control, noise=args.noise, smoothness=args.smoothness,
                      curvature=args.curvature, max_iter=args.max_iter)
    write_values(args.output, res.xi)
    r = res.report
    if args.json:
        print(json.dumps(r))
    else:
        print(f"{r['measurements']} measurements ({r['sources']} sources, {r['sensors']} sensors): "
              f"rms relative misfit {r['rms_relative_misfit']:.2e} (best constant "
              f"{r['constant_fit']:.4g}: {r['rms_relative_misfit_constant']:.2e}), metric "
              f"{np.min(res.xi):.4g} .. {np.max(res.xi):.4g}, {r['iterations']} iterations, "
              f"{r['seconds']['total']:.1f} s")
    return 0
