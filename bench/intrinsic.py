"""Speed of the intrinsic Delaunay triangulation (core/mesh/intrinsic.py).

Usage: python bench/intrinsic.py [mesh.obj ...]

Without arguments: jittered, sheared grids of about 10k, 100k and 1M triangles with random diagonals
(each size in its own process, so the peak resident memory is per size), then the meshes in
/work/shared/meshes if present. Prints time, flips, rounds, mollification eps and negative cotan weights
before / after (boundary edges included; an obtuse angle opposite a boundary edge cannot be flipped).
"""
import glob
import os
import resource
import subprocess
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)


def jittered_grid(N, shear=0.0, jitter=0.3, seed=0):
    """(V, F): an N x N grid of the unit spacing, points jittered, each quad cut by a random diagonal."""
    rng = np.random.default_rng(seed)
    x, y = np.meshgrid(np.arange(N + 1.0), np.arange(N + 1.0), indexing='ij')
    P = np.stack([x.ravel(), y.ravel()], 1)
    J = rng.uniform(-jitter, jitter, P.shape)
    J[(P[:, 0] == 0) | (P[:, 0] == N), 0] = 0
    J[(P[:, 1] == 0) | (P[:, 1] == N), 1] = 0
    P = P + J
    P[:, 0] += shear * P[:, 1]
    i, j = np.meshgrid(np.arange(N), np.arange(N), indexing='ij')
    i, j = i.ravel(), j.ravel()
    a, b, c, d = i * (N + 1) + j, (i + 1) * (N + 1) + j, (i + 1) * (N + 1) + j + 1, i * (N + 1) + j + 1
    diag = rng.random(len(a)) < 0.5
    F1 = np.where(diag[:, None], np.stack([a, b, c], 1), np.stack([a, b, d], 1))
    F2 = np.where(diag[:, None], np.stack([a, c, d], 1), np.stack([b, c, d], 1))
    return np.c_[P, np.zeros(len(P))], np.concatenate([F1, F2]).astype(np.int64)


def read_obj(path):
    """(V, F) from an OBJ file: v and f lines only; n-gons fan-triangulated; v/vt/vn indices allowed."""
    V, F = [], []
    with open(path) as fh:
        for line in fh:
            if line.startswith('v '):
                V.append([float(x) for x in line.split()[1:4]])
            elif line.startswith('f '):
                idx = [int(tok.split('/')[0]) for tok in line.split()[1:]]
                idx = [i - 1 if i > 0 else len(V) + i for i in idx]
                F.extend([idx[0], idx[q], idx[q + 1]] for q in range(1, len(idx) - 1))
    return np.array(V, dtype=np.float64), np.array(F, dtype=np.int64)


def run_one(spec):
    from core.mesh.intrinsic import intrinsic_delaunay
    if spec.endswith('.obj'):
        V, F = read_obj(spec)
        name = os.path.basename(spec)
    else:
        N, shear = spec.split(':')
        V, F = jittered_grid(int(N), shear=float(shear))
        name = 'grid N=%s shear=%s' % (N, shear)
    t0 = time.perf_counter()
    try:
        T = intrinsic_delaunay(V, F)
    except ValueError as exc:                    # non-manifold input: the caller must split it first
        print('%-28s m=%8d  skipped: %s' % (name, len(F), exc), flush=True)
        return
    dt = time.perf_counter() - t0
    r = T.report
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print('%-28s m=%8d  %7.3f s  flips=%7d rounds=%3d eps=%.2e neg %6d -> %4d (boundary %d) '
          'non-Delaunay left %d  peak %.0f MB'
          % (name, len(F), dt, r['flips'], r['rounds'], r['eps'], r['negative_before'],
             r['negative_after'], r['negative_boundary_after'], r['non_delaunay_after'], peak), flush=True)


if __name__ == '__main__':
    if len(sys.argv) > 1 and sys.argv[1] == '--one':
        run_one(sys.argv[2])
        sys.exit(0)
    specs = sys.argv[1:] or (['71:0', '224:0', '707:0', '71:3.0', '224:3.0', '707:3.0']
                             + sorted(glob.glob('/work/shared/meshes/*.obj')))
    for spec in specs:
        subprocess.run([sys.executable, os.path.abspath(__file__), '--one', spec], check=False)
