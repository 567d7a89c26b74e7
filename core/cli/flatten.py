"""``python -m core flatten IN.obj OUT.obj [--boundary free|area|uniform] [--json]``."""
import json
import sys

import numpy as np

from ..disk.flatten import BOUNDARY_MODES, FIT_MODES, flatten
from ..io.obj import read_obj, write_obj


def add_arguments(p):
    p.add_argument('input', help='input OBJ (a disk-topology mesh; n-gons are triangulated)')
    p.add_argument('output', help='output OBJ with one vt per vertex')
    p.add_argument('--boundary', choices=BOUNDARY_MODES, default='uniform',
                   help='boundary mode (default: uniform)')
    p.add_argument('--fit', choices=FIT_MODES, default='true_scale',
                   help='UV scale: true_scale (UV area = 3D area) or unit_square')
    p.add_argument('--json', action='store_true', help='print the report as JSON')


def run(args):
    mesh = read_obj(args.input)
    F, _ = mesh.triangles()
    res = flatten(mesh.V, F, boundary=args.boundary, fit=args.fit)
    uv = res.uv
    if np.isnan(uv).any():           # loose vertices (in no face): a vt no face uses, written as 0 0
        uv = np.where(np.isnan(uv), 0.0, uv)
    # faces go back as the input's polygons: UVs are per vertex
    # ... and the vertices as their own text (the same numbers; formatting 1M floats again costs ~1 s)
    write_obj(args.output, mesh.V, mesh.polygons() if (mesh.sizes != 3).any() else F, uv,
              v_text=mesh.v_text)
    if args.json:
        print(json.dumps(res.report))
    else:
        r = res.report
        print(f"{args.boundary}: mu_ratio {r['mu_ratio']:.4f}, qc_mean {r['qc_mean']:.4f}, "
              f"flips {r['flips']}, {r['seconds']['total']:.2f} s")
    for r in res.report.get('repairs', []):
        print(f"repaired: {r['repair']} ({r['count']}): {r['note']}", file=sys.stderr)
    for w in res.report.get('warnings', []):
        print(f"warning: {w}", file=sys.stderr)
    return 0
