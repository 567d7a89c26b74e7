"""Island workflows: the acceptance cases of issue 7 as a table.

    .venv/bin/python bench/islands_table.py [--modes area free uniform]

Cases: a UV sphere cut by the equator and one meridian (2 islands); the same sphere cut by the
meridian only (one disk with a slit); Suzanne (3 pieces, the head has two eye holes) with holes
filled and cut; a bump with two holes, filled and cut; a torus cut by one ring seam (a tube: two
boundary loops of equal length). Worst island values; 'overlaps' counts crossing boundary segments
(0 flips and 0 crossings: each island is one-to-one). Timings are noisy (shared machine)."""
import argparse
import os
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)
sys.path.insert(0, os.path.join(ROOT, 'tests'))

import numpy as np  # noqa: E402

from core.errors import ConformalError  # noqa: E402
from core.atlas.islands import unwrap  # noqa: E402
from core.io.obj import read_obj  # noqa: E402
from meshgen import torus, two_holes, uv_sphere  # noqa: E402


def cases():
    V, F, S = uv_sphere(32, 64)
    yield 'UV sphere 32x64, equator + meridian', V, F, S, 'fill'
    yield 'UV sphere 32x64, meridian only', V, F, S[64:], 'fill'
    m = read_obj(os.path.join(ROOT, 'tests', 'data', 'suzanne.obj'))
    Fs, _ = m.triangles()
    for holes in ('error', 'fill', 'cut'):
        yield f'Suzanne, holes={holes}', m.V, Fs, None, holes
    for name in ('bump', 'bump3', 'saddle'):
        Vh, Fh = two_holes(name, 33)
        for holes in ('fill', 'cut'):
            yield f'{name} 33x33 with two holes, holes={holes}', Vh, Fh, None, holes
    Vt, Ft = torus(48, 16)
    ring = np.stack([np.arange(16), np.roll(np.arange(16), -1)], 1)
    for holes in ('fill', 'cut'):
        yield f'torus 48x16 cut by one ring seam (a tube), holes={holes}', Vt, Ft, ring, holes


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument('--modes', nargs='+', default=['area', 'free', 'uniform'])
    args = ap.parse_args()
    print('| case | mode | islands | holes filled/cut | flips | overlaps | worst qc_mean | worst mu_ratio '
          '| s |')
    print('|---|---|---|---|---|---|---|---|---|')
    for name, V, F, S, holes in cases():
        for mode in args.modes:
            t = time.perf_counter()
            try:
                r = unwrap(V, F, S, boundary=mode, holes=holes, on_error='skip').report
            except ConformalError as exc:
                print(f'| {name} | {mode} | error: {exc} ||||||| ')
                continue
            dt = time.perf_counter() - t
            isl = f"{r['flattened']}/{r['islands']}" + (f" ({r['failed']} skipped)" if r['failed'] else '')
            print(f"| {name} | {mode} | {isl} | {r['holes_filled']}/{r['holes_cut']} | {r['flips']} | "
                  f"{r['overlaps']} | {r['qc_mean_worst']:.4f} | {r['mu_ratio_worst']:.4g} | {dt:.2f} |",
                  flush=True)


if __name__ == '__main__':
    main()
