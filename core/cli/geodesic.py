"""``python -m core geodesic IN.obj --source I [--source J ...] [--grid N] [--boundary MODE] --out DIST.txt``.

Writes one geodesic distance per vertex (input vertex order, mesh units, ``%.9g``) to the nearest of
the source vertices (0-based indices into the OBJ's ``v`` lines). The file is written only when the
whole computation succeeded."""
import json

import numpy as np

from ..disk.flatten import BOUNDARY_MODES
from ..geodesic.solver import SOLVERS, geodesic_distance
from ..io.obj import read_obj, write_values


def add_arguments(p):
    p.add_argument('input', help='input OBJ (a disk-topology mesh; n-gons are triangulated)')
    p.add_argument('--source', type=int, action='append', required=True, metavar='I',
                   help='source vertex, 0-based (repeat for several; the result is the distance to the nearest)')
    p.add_argument('--out', required=True, help='output text file: one distance per vertex')
    p.add_argument('--grid', type=int, default=None,
                   help='fast-marching grid nodes along the longer UV side (default: follows the mesh resolution)')
    p.add_argument('--boundary', choices=BOUNDARY_MODES, default='uniform',
                   help='boundary mode of the conformal map (default: uniform)')
    p.add_argument('--solver', choices=SOLVERS, default='auto',
                   help='auto (scikit-fmm if installed), skfmm, or sweep (pure numpy)')
    p.add_argument('--json', action='store_true', help='print the report as JSON')


def run(args):
    mesh = read_obj(args.input)
    F, _ = mesh.triangles()
    dist, report = geodesic_distance(mesh.V, F, sources=np.asarray(args.source, np.int64),
                                     boundary=args.boundary, grid=args.grid, solver=args.solver)
    write_values(args.out, dist)
    if args.json:
        print(json.dumps(report))
    else:
        ny, nx = report['grid']
        print(f"geodesic: {len(dist)} vertices, max {np.nanmax(dist):.6g}, grid {nx}x{ny}, "
              f"solver {report['solver']}, {report['seconds']['total']:.2f} s")
    return 0
