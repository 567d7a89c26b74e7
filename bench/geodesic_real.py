"""Geodesic distances on real meshes and generated surfaces: our fast marching on the conformal plane
(``core.geodesic.solver.GeodesicSolver``) against exact polyhedral distances (MMP, pygeodesic), beside
the heat method (potpourri3d, or the three sparse solves in ``heat_method`` when it is missing).

    .venv/bin/python bench/geodesic_real.py                  # table + one PNG per mesh in out/
    .venv/bin/python bench/geodesic_real.py --quick          # fewer meshes and grids
    .venv/bin/python bench/geodesic_real.py --calibrate      # rows for the error-model fit (JSON)
    .venv/bin/python bench/geodesic_real.py --meshes woody bump

Meshes: the generated surfaces of ``core.surfaces`` and every mesh of ``meshes.corpus_dir()`` (outside the
repository; the script says so and skips them if that folder is missing) that the tool handles as
disks or disk islands: closed meshes are cut along their OBJ ``vt`` seams when they have some (spot),
and skipped otherwise (use sphere mode for those). Distances are then on the cut surface, and the
exact reference is MMP on the same cut surface (its split vertices), restricted to the source's part.

Errors: relative to the exact distance, mean and max over the vertices of the source's part farther
than ``EXCLUDE`` times the part's bounding-box diagonal from the source; a vertex split by a seam counts
once, with the smallest distance over its copies (for every method and for MMP alike). Three sources
per mesh, chosen at random (seed 0) among the vertices of the largest part. Times are wall-clock
seconds on a shared 2-core machine (noisy): set-up (flattening, rasterising) and one query separately,
heat likewise (factorisation, one solve). Mesh fast marching is not measured: no installable
package provides it.
"""
import argparse
import json
import os
import sys
import time

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from core.errors import ConformalError  # noqa: E402
from core.geodesic.solver import GeodesicSolver  # noqa: E402
from core.surfaces import blob, make_surface  # noqa: E402
from meshes import corpus_dir  # noqa: E402

MESH_DIR = corpus_dir()
OUT = os.path.join(ROOT, 'out', 'geodesic_real')
EXCLUDE = 0.02
REAL = ['woody', 'alligator', 'suzanne', 'teapot', 'spot', 'stanford-bunny', 'cow', 'ogre']
SURF = ['bump', 'bump3', 'edgebump', 'ridge', 'saddle', 'waves', 'cliff', 'blob']
HEADER = ('| mesh | verts | tris | method | grid | mean err % | max err % | set-up s | query s | '
          'estimate % | warnings (3 queries) |\n|---|---|---|---|---|---|---|---|---|---|---|')


def print_row(r):
    est = '-' if r[9] is None else f"{100 * r[9]:.3g}"
    print(f"| {r[0]} | {r[1]} | {r[2]} | {r[3]} | {r[4]} | {100 * r[5]:.4f} | {100 * r[6]:.3f} | "
          f"{r[7]:.2f} | {r[8]:.2f} | {est} | {'-' if r[10] is None else r[10]} |", flush=True)


# --------------------------------------------------------------------------------------------------
def load(name):
    """(V, F, seams or None) of a generated surface or a mesh file; None when missing."""
    if name == 'blob':
        V, F = blob()
        return V, F, None
    if name in SURF:
        V, F = make_surface(name, 65)
        return V, F, None
    path = os.path.join(MESH_DIR, name + '.obj')
    if not os.path.exists(path):
        return None
    from core.atlas.islands import seams_from_corner_ids
    from core.io.obj import read_obj
    from core.mesh.triangulate import triangulate
    mesh = read_obj(path)
    tri, _ = triangulate(mesh.corner_verts, mesh.sizes, mesh.V)
    F = mesh.corner_verts[tri]
    seams = None
    if (mesh.corner_uvs >= 0).any():
        seams = seams_from_corner_ids(F, mesh.corner_uvs[tri], len(mesh.V))
        seams = seams if len(seams) else None
    return mesh.V, F, seams


def exact(Vs, Fs, sources):
    """(k, N) exact polyhedral distances (MMP) on the split mesh from split vertices ``sources``."""
    from pygeodesic import geodesic
    alg = geodesic.PyGeodesicAlgorithmExact(np.ascontiguousarray(Vs, np.float64),
                                            np.ascontiguousarray(Fs, np.int32))
    out = []
    for s in sources:
        d, _ = alg.geodesicDistances(np.array([s], np.int32), None)
        out.append(np.asarray(d, np.float64))
    return np.array(out)


def heat_setup(Vs, Fs):
    """A heat-method solver on the split mesh: potpourri3d if it imports, else our own."""
    try:
        import potpourri3d as pp3d
        solver = pp3d.MeshHeatMethodDistanceSolver(np.asarray(Vs, np.float64), np.asarray(Fs, np.int64))
        return 'potpourri3d', solver.compute_distance
    except ImportError:
        return 'own heat', heat_method(Vs, Fs)


def heat_method(V, F):
    """The heat method (Crane et al. 2013) with scipy: factor once, then per source one heat solve,
    a divergence, one Poisson solve. Returns ``distance(source) -> (n,)``."""
    import scipy.sparse as sp
    import scipy.sparse.linalg as sla
    from core.mesh.geometry import face_areas
    from core.mesh.laplacian import cotan_laplacian
    n = len(V)
    L = cotan_laplacian(V, F)
    A = face_areas(V, F)
    M = sp.diags(np.bincount(F.ravel(), np.repeat(A / 3, 3), minlength=n))
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    h = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).mean()
    heat = sla.factorized((M + h * h * L).tocsc())
    poisson = sla.factorized((L + 1e-10 * M).tocsc())
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    Nn = N / np.linalg.norm(N, axis=1)[:, None]

    def distance(s):
        u0 = np.zeros(n)
        u0[s] = 1.0
        u = heat(M @ u0)
        g = np.zeros((len(F), 3))
        for k in range(3):
            e = V[F[:, (k + 2) % 3]] - V[F[:, (k + 1) % 3]]
            g += u[F[:, k], None] * np.cross(Nn, e)
        g /= (2 * A)[:, None]
        X = -g / np.maximum(np.linalg.norm(g, axis=1), 1e-300)[:, None]
        div = np.zeros(n)
        for k in range(3):
            i, j, o = F[:, k], F[:, (k + 1) % 3], F[:, (k + 2) % 3]
            e1, e2 = V[j] - V[i], V[o] - V[i]
            c1 = cot(V[o] - V[j], V[i] - V[j])    # angle at j, opposite e2? (see below)
            c2 = cot(V[i] - V[o], V[j] - V[o])
            div += np.bincount(i, 0.5 * (c2 * (e1 * X).sum(1) + c1 * (e2 * X).sum(1)), minlength=n)
        phi = poisson(-div)
        return phi - phi[s]
    return distance


def cot(a, b):
    return (a * b).sum(1) / np.maximum(np.linalg.norm(np.cross(a, b), axis=1), 1e-300)


def rel_err(d, D, keep):
    r = np.abs(d[keep] - D[keep]) / D[keep]
    return float(r.mean()), float(r.max())


# --------------------------------------------------------------------------------------------------
def run_mesh(name, grids, rows, calib, plot):
    got = load(name)
    if got is None:
        print(f"# {name}: not found in {MESH_DIR} (the public meshes are not in a user's clone); skipped",
              flush=True)
        return
    V, F, seams = got
    t = time.perf_counter()
    try:
        gs = GeodesicSolver(V, F, seams=seams)
    except ConformalError as exc:
        print(f"# {name}: not handled ({exc}); skipped", flush=True)
        return
    t_setup = time.perf_counter() - t
    Vs, Fs = gs.Vs, gs.Fs
    ch = max(gs.charts, key=lambda c: len(c.verts))
    part = ch.verts                                              # split vertices of the largest island
    rng = np.random.default_rng(0)
    src_split = rng.choice(part, 3, replace=False)
    src = gs.vert_of[src_split]
    t = time.perf_counter()
    D = exact(Vs, Fs, src_split)
    t_exact = (time.perf_counter() - t) / len(src)
    diag = float(np.linalg.norm(np.ptp(Vs[part], axis=0)))
    heat_name, heat = heat_setup(Vs, Fs)
    results = {}

    n = len(V)
    vert_of = gs.vert_of
    in_part = np.zeros(n, bool)
    in_part[vert_of[part]] = True

    def per_vertex(x):
        """Per input vertex: the smallest value over its split copies (a seam vertex is the nearest
        of its copies, as the solver reports it)."""
        out = np.full(n, np.inf)
        np.minimum.at(out, vert_of, x)
        return out

    D_in = [per_vertex(D[k]) for k in range(len(src))]

    def evaluate(label, dist_split_list, seconds):
        errs = []
        for k, s in enumerate(src_split):
            keep = in_part & (np.linalg.norm(V - Vs[s], axis=1) > EXCLUDE * diag)
            keep &= np.isfinite(D_in[k]) & (D_in[k] > 0) & (D_in[k] < 1e30)
            errs.append(rel_err(per_vertex(dist_split_list[k]), D_in[k], keep))
        e = np.array(errs)
        results[label] = (float(e[:, 0].mean()), float(e[:, 1].max()), seconds)
        return results[label]

    def ours(solver):
        out, tq, est, warn, med = [], 0.0, [], 0, []
        for s in src:
            t = time.perf_counter()
            d, rep = solver.distance([int(s)])
            tq += time.perf_counter() - t
            out.append(d[solver.vert_of])
            est.append(rep['error_estimate'])
            warn += len(rep['warnings'])
            fin = d[np.isfinite(d) & (d > 0)]
            med.append(float(np.median(fin)))
        return out, tq / len(src), {'error_estimate': float(np.mean(est)), 'warnings': warn,
                                    'median': float(np.mean(med))}

    d_list, tq, rep = ours(gs)
    g_def = max(c.size for c in gs.charts)
    m, x, _ = evaluate(f'ours default (grid {g_def})', d_list, t_setup + tq)
    rows.append((name, len(V), len(F), 'ours default', g_def, m, x, t_setup, tq, rep['error_estimate'],
                 rep['warnings']))
    calib.append({'mesh': name, 'grid': g_def, 'cell': ch.cell, 'spread': ch.spread, 'reflex': ch.reflex,
                  'median': rep['median'],
                  'mean': m, 'max': x, 'estimate': rep['error_estimate']})
    for g in grids:
        if g == g_def:
            continue
        t = time.perf_counter()
        gg = GeodesicSolver(V, F, seams=seams, grid=g)
        ts = time.perf_counter() - t
        d_list, tq, rep = ours(gg)
        c2 = max(gg.charts, key=lambda c: len(c.verts))
        m, x, _ = evaluate(f'ours grid {g}', d_list, ts + tq)
        rows.append((name, len(V), len(F), 'ours', g, m, x, ts, tq, rep['error_estimate'],
                     rep['warnings']))
        calib.append({'mesh': name, 'grid': g, 'cell': c2.cell, 'spread': c2.spread, 'reflex': c2.reflex,
                      'median': rep['median'],
                      'mean': m, 'max': x, 'estimate': rep['error_estimate']})
    t = time.perf_counter()
    heat_name, heat = heat_setup(Vs, Fs)
    th_setup = time.perf_counter() - t
    hl, th = [], 0.0
    for s in src_split:
        t = time.perf_counter()
        hl.append(np.asarray(heat(int(s)), np.float64))
        th += time.perf_counter() - t
    m, x, _ = evaluate(heat_name, hl, th_setup + th / len(src))
    rows.append((name, len(V), len(F), heat_name, '-', m, x, th_setup, th / len(src), None, None))
    rows.append((name, len(V), len(F), 'exact MMP', '-', 0.0, 0.0, 0.0, t_exact, None, None))
    print(f"# {name}: done ({len(V)} vertices, {len(gs.charts)} islands)", flush=True)
    if plot:
        plot_mesh(name, results)


def plot_mesh(name, results):
    try:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
    except ImportError:
        print("# matplotlib is not installed: no plots")
        return
    os.makedirs(OUT, exist_ok=True)
    fig, ax = plt.subplots(figsize=(5, 3.6))
    for label, (m, _x, s) in results.items():
        ax.loglog([s], [100 * m], 'o', label=label)
    ax.set_xlabel('seconds (set-up + one query)')
    ax.set_ylabel('mean relative error, %')
    ax.set_title(name)
    ax.grid(True, which='both', alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(os.path.join(OUT, f'{name}.png'), dpi=110)
    plt.close(fig)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--quick', action='store_true')
    ap.add_argument('--calibrate', action='store_true', help='print the calibration rows as JSON')
    ap.add_argument('--meshes', nargs='*')
    ap.add_argument('--grids', nargs='*', type=int)
    ap.add_argument('--no-plot', action='store_true')
    a = ap.parse_args()
    if not os.path.isdir(MESH_DIR):
        print(f"# {MESH_DIR} is missing: only the generated surfaces are measured")
    names = a.meshes or (['bump', 'edgebump', 'blob', 'woody', 'suzanne', 'spot'] if a.quick
                         else SURF + REAL[:-1])
    grids = a.grids or ([512, 1024] if a.quick else [512, 1024, 2048, 4096])
    rows, calib = [], []
    print(HEADER, flush=True)
    for name in names:
        n0 = len(rows)
        run_mesh(name, grids, rows, calib, not a.no_plot)
        for r in rows[n0:]:
            print_row(r)
    if a.calibrate:
        print(json.dumps(calib))


if __name__ == '__main__':
    main()
