"""``python -m core geodesic IN.obj --source I [--source J ...] [--grid N] [--boundary MODE] --out DIST.txt``.

Writes one geodesic distance per vertex (input vertex order, mesh units, ``%.9g``) to the nearest of
the source vertices (0-based indices into the OBJ's ``v`` lines); ``inf`` on parts without a source,
``nan`` for vertices in no face. Warnings (estimated error above the target, parts not reached) are printed
as ``warning:`` lines after the summary (stdout; stderr is kept for the one error line), or go into the
JSON report's ``warnings``. The file is written only when the
whole computation succeeded."""
import json

import numpy as np

from ..disk.flatten import BOUNDARY_MODES
from ..geodesic.solver import ERROR_TARGET, SOLVERS, geodesic_distance
from ..io.obj import read_obj, write_values


def add_arguments(p):
    p.add_argument('input', help='input OBJ (disk-topology parts; n-gons are triangulated)')
    p.add_argument('--source', type=int, action='append', required=True, metavar='I',
                   help='source vertex, 0-based (repeat for several; the result is the distance to the '
                        'nearest)')
    p.add_argument('--out', required=True, help='output text file: one distance per vertex')
    p.add_argument('--grid', type=int, default=None,
                   help='fast-marching grid nodes along the longer UV side of each part (default: from '
                        'the error target and the local resolution)')
    p.add_argument('--boundary', choices=BOUNDARY_MODES, default='uniform',
                   help='boundary mode of the conformal map (default: uniform)')
    p.add_argument('--solver', choices=SOLVERS, default='auto',
                   help='auto (scikit-fmm if installed), skfmm, or sweep (pure numpy)')
    p.add_argument('--error-target', type=float, default=ERROR_TARGET, metavar='E',
                   help='target for the estimated mean relative error, sets the automatic grid and the '
                        f'surface paths\' points (default {ERROR_TARGET:g}; 0.005-0.01 answer 2-20x '
                        'faster by surface paths); a result above it prints a warning')
    p.add_argument('--steiner-points', type=int, default=None, metavar='K',
                   help='points per edge (odd, 3..31) on the parts answered by surface paths, without '
                        'refining toward the error target: fewer answer faster and less accurately '
                        '(default: chosen per part for the target)')
    p.add_argument('--json', action='store_true', help='print the report as JSON (warnings in "warnings")')


def run(args):
    mesh = read_obj(args.input)
    F, _ = mesh.triangles()
    dist, report = geodesic_distance(mesh.V, F, sources=np.asarray(args.source, np.int64),
                                     boundary=args.boundary, grid=args.grid, solver=args.solver,
                                     error_target=args.error_target, steiner_points=args.steiner_points)
    write_values(args.out, dist)
    if args.json:
        print(json.dumps(report))
    else:
        ny, nx = report['grid']
        fin = dist[np.isfinite(dist)]
        fine = report.get('refined')
        on = f" on the mesh subdivided {fine['levels']} times ({fine['triangles']} triangles)" if fine else ""
        how = f"grid {nx}x{ny}{on}, solver {report['solver']}" if nx else ""
        if report['paths_islands']:
            paths = (f"surface paths on {report['paths_islands']} of {report['islands_reached']} islands "
                     f"({report['steiner_points']} points per edge)")
            how = f"{how}, {paths}" if how else paths
        if report['planar_islands']:
            flat = (f"exact in the plane on {report['planar_islands']} of {report['islands_reached']} "
                    "islands (flat)")
            how = f"{how}, {flat}" if how else flat
        est, sec = 100 * report['error_estimate'], report['seconds']['total']
        print(f"geodesic: {len(dist)} vertices, max {fin.max():.6g}, {how}, "
              f"estimated mean error {est:.2g}%, {sec:.2f} s")
        for w in report['warnings']:
            print(f"warning: {w}")
    return 0
