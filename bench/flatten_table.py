"""Issue 2 benchmark: the README's results table on the n = 65 test surfaces.

Rows: our ``free``, ``area`` and ``uniform`` modes, and Blender's own 'CONFORMAL' and 'ANGLE_BASED'
unwraps run through bpy in this process. Columns: mu_ratio, p1/p99, qc_mean, qc_max, flips, seconds,
and for ``uniform`` the certified vertex-level bound.

    .venv/bin/python bench/flatten_table.py [--n 65] [--surfaces bump ridge ...] [--no-blender]
"""
import argparse
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.abspath(__file__))))
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from core import flatten, make_surface          # noqa: E402
from blender_unwrap import blender_unwrap, corner_measures   # noqa: E402

SURFACES = ['bump', 'bump3', 'edgebump', 'ridge', 'saddle']


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--n', type=int, default=65)
    ap.add_argument('--surfaces', nargs='*', default=SURFACES)
    ap.add_argument('--no-blender', action='store_true')
    args = ap.parse_args()
    head = f"{'surface':9} {'method':18} {'mu_ratio':>8} {'p1/p99':>7} {'qc_mean':>8} {'qc_max':>7} " \
           f"{'flips':>5} {'seconds':>8} {'bound':>7}"
    print(head)
    print('-' * len(head))
    for name in args.surfaces:
        V, F = make_surface(name, args.n)
        rows = []
        for mode in ('free', 'area', 'uniform'):
            r = flatten(V, F, boundary=mode).report
            rows.append((mode, r, r['seconds']['total'], r.get('bound_vertex')))
        if not args.no_blender:
            for method in ('CONFORMAL', 'ANGLE_BASED'):
                uv, sec = blender_unwrap(V, F, method)
                rows.append(('blender ' + method.lower(), corner_measures(V, F, uv), sec, None))
        for label, r, sec, bound in rows:
            b = f"{bound:7.4f}" if bound is not None else ' ' * 7
            print(f"{name:9} {label:18} {r['mu_ratio']:8.4f} {r['mu_ratio_p1_p99']:7.4f} "
                  f"{r['qc_mean']:8.4f} {r['qc_max']:7.3f} {r['flips']:5d} {sec:8.3f} {b}")
        sys.stdout.flush()


if __name__ == '__main__':
    main()
