"""``python -m core sphere IN.obj OUT.obj [--moebius none|center|area|uniform] [--json]``.

OUT.obj has the input's faces (its polygons, as read) and the unit-sphere positions as vertices."""
import json

import numpy as np

from ..sphere.moebius import MOEBIUS_MODES
from ..io.obj import read_obj, write_obj
from ..sphere.map import sphere_map


def add_arguments(p):
    p.add_argument('input', help='input OBJ: a closed genus-0 mesh (n-gons are triangulated)')
    p.add_argument('output', help='output OBJ: the same faces, vertices on the unit sphere')
    p.add_argument('--moebius', choices=MOEBIUS_MODES, default='uniform',
                   help='Moebius normalisation: none (as mapped), center (area centroid), area '
                        '(mean |log area ratio|), uniform (max min/max mu; default)')
    p.add_argument('--json', action='store_true', help='print the report as JSON')


def run(args):
    mesh = read_obj(args.input)
    F, _ = mesh.triangles()
    res = sphere_map(mesh.V, F, moebius=args.moebius)
    starts = np.r_[0, np.cumsum(mesh.sizes)[:-1]]
    polys = [mesh.corner_verts[s:s + k] for s, k in zip(starts.tolist(), mesh.sizes.tolist())]
    write_obj(args.output, res.S, polys if (mesh.sizes != 3).any() else F)
    r = res.report
    if args.json:
        print(json.dumps(r))
    else:
        line = (f"{args.moebius}: mu_ratio {r['mu_ratio']:.4g} (p1/p99 {r['mu_ratio_p1_p99']:.4g}), "
                f"qc_mean {r['qc_mean']:.4f}, flips {r['flips']}")
        if 'baselines' in r:
            line += ', baselines ' + ', '.join(f"{k} {v:.4g}" for k, v in r['baselines'].items())
        print(line + f", {r['seconds']['total']:.2f} s")
        if r['flips']:
            print(f"flipped faces: {r['flipped_faces'][:50]}{' ...' if r['flips'] > 50 else ''}")
        for w in r['warnings']:
            print(f"WARNING: {w}")
    return 0
