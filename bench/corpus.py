"""Issue 12: the messy corpus (``meshes.corpus_dir()``) through ``unwrap`` with the defaults, beside Blender's
CONFORMAL and ANGLE_BASED unwraps run in this process through bpy, measured with the same measures
(``core.mesh.measures.uv_measures`` per corner, via ``bench/blender_unwrap.corner_measures``).

    .venv/bin/python bench/corpus.py [--meshes teapot suzanne ...] [--no-blender]

Columns: the repairs each mesh needed, islands, flips, overlaps, worst qc_mean, worst mu_ratio and
seconds. A closed part gives the one remaining error (no_boundary / mark_seams), printed as such."""
import argparse
import os
import sys
import time


ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))

from core.atlas.islands import seams_from_corner_ids, unwrap     # noqa: E402
from core.errors import ConformalError                           # noqa: E402
from core.io.obj import read_obj                                 # noqa: E402
from core.mesh.triangulate import triangulate                    # noqa: E402
from blender_unwrap import blender_unwrap                         # noqa: E402
from meshes import corpus_dir                                     # noqa: E402

MESHES = corpus_dir()
NAMES = ['woody', 'alligator', 'suzanne', 'teapot', 'spot', 'cow', 'cheburashka', 'rocker-arm', 'beast',
         'stanford-bunny', 'ogre']


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--meshes', nargs='*', default=NAMES)
    ap.add_argument('--no-blender', action='store_true')
    args = ap.parse_args()
    if not os.path.isdir(MESHES):
        sys.exit(f"the corpus is missing: {os.path.abspath(MESHES)} does not exist (see docs/robustness.md)")
    blender = '' if args.no_blender else ' Blender conformal flips / mu_ratio / s | Blender angle-based |'
    print("| mesh | triangles | repairs | islands | flips | overlaps | qc_mean worst | mu_ratio worst | s |"
          + blender)
    print('|---' * (9 if args.no_blender else 11) + '|')
    for name in args.meshes:
        mesh = read_obj(os.path.join(MESHES, f'{name}.obj'))
        tc, tp = triangulate(mesh.corner_verts, mesh.sizes, mesh.V)
        F = mesh.corner_verts[tc]
        seams = None
        if (mesh.corner_uvs >= 0).any():
            seams = seams_from_corner_ids(F, mesh.corner_uvs[tc], len(mesh.V))
        t = time.perf_counter()
        try:
            res = unwrap(mesh.V, F, seams=seams, tri_poly=tp)
            r = res.report
            reps = ', '.join(f"{x['repair']} {x['count']}" for x in r['repairs']) or '-'
            row = (f"| {name} | {len(F)} | {reps} | {r['islands']} | {r['flips']} | {r['overlaps']} | "
                   f"{r['qc_mean_worst']:.3f} | {r['mu_ratio_worst']:.3g} | {time.perf_counter() - t:.1f} |")
        except ConformalError as exc:
            row = (f"| {name} | {len(F)} | | error {exc.code} / {exc.remedy} | | | | | "
                   f"{time.perf_counter() - t:.1f} |")
            if exc.code == 'no_boundary':
                # the open parts still unwrap: on_error='skip' (CLI --skip-bad) flattens them
                try:
                    t = time.perf_counter()
                    r = unwrap(mesh.V, F, seams=seams, tri_poly=tp, on_error='skip').report
                    reps = ', '.join(f"{x['repair']} {x['count']}" for x in r['repairs']) or '-'
                    row = (f"| {name} (skip closed) | {len(F)} | {reps} | {r['flattened']} of "
                           f"{r['islands']} ({r['failed']} closed) | {r['flips']} | {r['overlaps']} | "
                           f"{r['qc_mean_worst']:.3f} | {r['mu_ratio_worst']:.3g} | "
                           f"{time.perf_counter() - t:.1f} |")
                except ConformalError:
                    pass
        if not args.no_blender:
            from blender_unwrap import corner_measures
            closed = 'error no_boundary' in row
            for method in ('CONFORMAL', 'ANGLE_BASED'):
                try:
                    uv, sec = blender_unwrap(mesh.V, F, method, seams=seams)
                    b = corner_measures(mesh.V, F, uv)
                    note = ' (warns: failed to solve)' if closed else ''
                    row += f" {b['flips']} / {b['mu_ratio']:.3g} / {sec:.1f} s{note} |"
                except Exception as exc:          # Blender's own failure is a result too
                    row += f" failed: {type(exc).__name__} |"
        print(row)
        sys.stdout.flush()


if __name__ == '__main__':
    main()
