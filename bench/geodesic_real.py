"""Geodesic distances on real meshes and generated surfaces: our fast marching on the conformal plane
(``core.geodesic.solver.GeodesicSolver``) against exact polyhedral distances (MMP, pygeodesic), beside
the heat method (potpourri3d, or the three sparse solves in ``heat_method`` when it is missing).

    .venv/bin/python bench/geodesic_real.py                  # table + one PNG per mesh in out/
    .venv/bin/python bench/geodesic_real.py --quick          # fewer meshes and grids
    .venv/bin/python bench/geodesic_real.py --calibrate      # rows for the error-model fit (JSON)
    .venv/bin/python bench/geodesic_real.py --meshes woody bump
    .venv/bin/python bench/geodesic_real.py --meshes alligator --grids --no-plot --where 8   # worst vertices

Meshes: the generated surfaces of ``core.surfaces`` and every mesh of ``meshes.corpus_dir()`` (outside the
repository; the script says so and skips them if that folder is missing) that the tool handles as
disks or disk islands: closed meshes are cut along their OBJ ``vt`` seams when they have some (spot),
and skipped otherwise (use sphere mode for those). Distances are then on the cut surface, and the
exact reference is MMP on the same cut surface (its split vertices), restricted to the source's part.
Head-like disks (stand-ins for the held-out scans): ``--meshes cow-cut spot-cut2 cheburashka-cut1``
(``meshes.HEAD_CUTS``, then the given number of Loop subdivisions); other plane cuts of the public
meshes by name (``meshes.PART_CUTS``: ``spot-rear cow-rear cheburashka-half rocker-half ogre-head``).
Scan-like meshes of our own (random points with a denser patch, Delaunay-triangulated and lifted,
with noise): ``--meshes facescan faceholes deepcap`` (``meshes.scan_like``). Closed CAD-like parts of
slivers, in sphere mode: ``--meshes --sphere cylinderhull boxhull`` (``meshes.HULLS``). Meshes made
with Blender's own tools through bpy (``blender_made``: voxel-remeshed and decimated): ``--meshes
figure-upper part-top suzvox-front figure-dec-upper suzvox-dec-front cow-dec-rear bunny-dec`` and, in
sphere mode, ``--meshes --sphere figure part``.

Errors: relative to the exact distance, mean and max over the vertices of the source's part farther
than ``EXCLUDE`` times the part's bounding-box diagonal from the source; a vertex split by a seam counts
once, with the smallest distance over its copies (for every method and for MMP alike). Four source
sets per mesh in its largest part (``source_sets``: central, far, highest curvature, all three). Times
are wall-clock seconds on a shared 2-core machine (noisy): set-up (flattening, rasterising) and one
query separately, heat and mesh fast marching (potpourri3d, when installed) likewise. The measured
tables are in docs/geodesic.md ("Real meshes").
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
SKIP_DEFAULT = False   # --skip-default: the first of --grids instead of the automatic grid
WHERE = 0              # --where K: print our K worst vertices per source set and what they lie in
KS = []                # --ks: Steiner points per edge of the surface-path rows ('ours paths', k = K)
TARGETS = []           # --targets: error targets of the 'ours target' rows (the solver's own choice for each)
REAL = ['woody', 'alligator', 'suzanne', 'teapot', 'spot', 'stanford-bunny', 'cow', 'ogre']
SURF = ['bump', 'bump3', 'edgebump', 'ridge', 'saddle', 'waves', 'cliff', 'blob']
HEADER = ('| mesh | method | grid | mean % central | far | curvature | multi | max % | below Euclid / above '
          'edges +0.1% | set-up s | query s | estimate % | warnings |\n'
          '|---|---|---|---|---|---|---|---|---|---|---|---|---|')


def print_row(r):
    p = r['per_set']
    est = f"{100 * r['estimate']:.3g}" if 'estimate' in r else '-'
    print(f"| {r['mesh']} | {r['method']} | {r['grid']} | " + ' | '.join(f"{100 * p[k][0]:.4f}" for k in SETS)
          + f" | {100 * r['max']:.3f} | {r['below_euclid']} / {r['above_edges']} | {r['setup']:.2f} | "
          f"{r['query']:.3f} | {est} | {r.get('warnings', '-')} |", flush=True)


def summary(rows):
    """Per mesh: our default (and each ``--targets`` row) against heat and mesh FMM (the smallest ratio
    over the source sets), and our repeated query against the heat method's one-shot time (set-up +
    one solve)."""
    print('\n| mesh | ours | ours mean (worst set) % | ours max % | heat / ours (min over sets) | '
          'FMM / ours (min over sets) | ours query s | heat one-shot s | query / heat one-shot |\n'
          '|---|---|---|---|---|---|---|---|---|')
    for mesh in dict.fromkeys(r['mesh'] for r in rows):
        rs = [r for r in rows if r['mesh'] == mesh]
        h = next((r for r in rs if r['method'].startswith('heat')), None)
        f = next((r for r in rs if r['method'].startswith('mesh FMM')), None)
        for o in rs:
            if h is not None and (o['method'] in ('ours default', 'ours target') or (
                    o['method'].startswith('ours sphere mode') and 'default' in o['method'])):
                _summary_row(mesh, o, h, f)


def _summary_row(mesh, o, h, f):
    """One row of ``summary``: ours ``o`` against heat ``h`` and mesh FMM ``f`` (or None)."""
    def ratio(x):
        if x is None:
            return '-'
        return f"{min(x['per_set'][k][0] / max(o['per_set'][k][0], 1e-12) for k in SETS):.1f}x"
    one = h['setup'] + h['query']
    which = 'default' if o['method'] != 'ours target' else f"target {o['grid']}"
    print(f"| {mesh} | {which} | {100 * o['worst_mean']:.4f} | {100 * o['max']:.3f} | {ratio(h)} "
          f"| {ratio(f)} | {o['query']:.3f} | {one:.3f} | {o['query'] / max(one, 1e-9):.1f}x |", flush=True)


# --------------------------------------------------------------------------------------------------
def load(name):
    """(V, F, seams or None) of a generated surface or a mesh file; None when missing."""
    if name == 'blob':
        V, F = blob()
        return V, F, None
    if name in SURF:
        V, F = make_surface(name, 65)
        return V, F, None
    from meshes import HULLS, SCANS, scan_like
    if name in SCANS:                       # scan-like meshes of our own (bench/meshes.py)
        V, F = scan_like(name)
        return V, F, None
    if name in HULLS:                       # closed CAD-like parts of slivers (sphere mode)
        from core.surfaces import hull_part
        V, F = hull_part(name[:-4])
        return V, F, None
    import blender_made
    if name in blender_made.NAMES:          # voxel-remeshed and decimated meshes made with bpy
        got = blender_made.load(name)
        return None if got is None else (*got, None)
    from meshes import PART_CUTS
    plane_cuts = {**PART_CUTS, **blender_made.CUTS}   # plane cuts: 'spot-rear', ..., 'figure-upper', ...
    if name in plane_cuts:
        from meshes import cut_disk
        base, direction, height = plane_cuts[name]
        got = load(base)
        return None if got is None else (*cut_disk(got[0], got[1], direction, height), None)
    if '-cut' in name:                      # head-like disks of bench/cones.py: 'cow-cut', 'spot-cut2', ...
        from meshes import HEAD_CUTS, cut_disk, loop_subdivide
        base, steps = name.split('-cut')
        got = load(base)
        if got is None:
            return None
        V, F = cut_disk(got[0], got[1], *HEAD_CUTS[base])
        for _ in range(int(steps or 0)):
            V, F = loop_subdivide(V, F)
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
SETS = ('central', 'far', 'curvature', 'multi')


def source_sets(V, F, part, graph, boundary):
    """The four source sets on the split mesh ``V``, ``F`` within the split vertices ``part``:
    'central' (the middle of an approximate edge-graph diameter: the vertex minimising the larger of its
    distances to the diameter's two ends), 'far' (the boundary vertex farthest from the central one, or
    the diameter's far end on a closed part), 'curvature' (the interior vertex of largest absolute
    angle defect), 'multi' (those three together). Returns {name: (k,) split vertex indices}."""
    from scipy.sparse.csgraph import dijkstra
    from core.mesh.geometry import corner_angles
    d0 = dijkstra(graph, indices=int(part[0]))
    a = int(part[np.argmax(np.where(np.isfinite(d0[part]), d0[part], -1))])
    da = dijkstra(graph, indices=a)
    b = int(part[np.argmax(np.where(np.isfinite(da[part]), da[part], -1))])
    db = dijkstra(graph, indices=b)
    c = int(part[np.argmin(np.maximum(da[part], db[part]))])
    dc = dijkstra(graph, indices=c)
    bpart = part[boundary[part]]
    far = int(bpart[np.argmax(dc[bpart])]) if len(bpart) else b
    ang = corner_angles(V, F)
    defect = 2 * np.pi - np.bincount(F.ravel(), ang.ravel(), minlength=len(V))
    inner = part[~boundary[part]]
    curv = int(inner[np.argmax(np.abs(defect[inner]))]) if len(inner) else int(part[1])
    return {'central': np.array([c]), 'far': np.array([far]), 'curvature': np.array([curv]),
            'multi': np.unique([c, far, curv])}


def exact_multi(Vs, Fs, sets):
    """{name: (N,) exact polyhedral distance (MMP, pygeodesic) to the nearest source of the set},
    through pinches too (``through_pinches``)."""
    from pygeodesic import geodesic
    alg = geodesic.PyGeodesicAlgorithmExact(np.ascontiguousarray(Vs, np.float64),
                                            np.ascontiguousarray(Fs, np.int32))
    out, t = {}, time.perf_counter()
    pinch = {}
    for k, src in sets.items():
        d, _ = alg.geodesicDistances(np.asarray(src, np.int32), None)
        out[k] = through_pinches(alg, Fs, len(Vs), np.asarray(d, np.float64), pinch)
    return out, (time.perf_counter() - t) / len(sets)


def through_pinches(alg, Fs, N, d, cache):
    """MMP's distances ``d`` (N,) from a source set, continued through the vertices where separate fans
    of triangles touch (``vertex_fans`` > 1). MMP's windows do not pass such a pinch (on a plane cut of
    the cow it left values up to twice the edge-graph distance, an upper bound), but a path on the
    surface does: every shortest path is a chain of MMP paths from the sources or from a pinch, so
    ``min(d, min_p dp_p + D_p)``, with ``D_p`` (N,) MMP from pinch ``p`` and ``dp`` the exact distance
    to the pinches (a Bellman-Ford closure over the few pinches). ``cache``: the ``D_p`` of this mesh."""
    if 'P' not in cache:
        from core.mesh.topology import vertex_fans
        cache['P'] = P = np.flatnonzero(vertex_fans(np.asarray(Fs, np.int64), N) > 1)
        cache['D'] = np.array([alg.geodesicDistances(np.array([p], np.int32), None)[0] for p in P],
                              np.float64).reshape(len(P), N)
    P, Dp = cache['P'], cache['D']
    if not len(P):
        return d
    Dp = np.where(Dp < 1e30, Dp, np.inf)
    dp = np.where(d[P] < 1e30, d[P], np.inf)
    for _ in range(len(P)):
        dp = np.minimum(dp, (dp[:, None] + Dp[:, P]).min(0))
    return np.minimum(d, (dp[:, None] + Dp).min(0))


def fmm_setup(Vs, Fs):
    """Fast marching on the mesh (potpourri3d 1.4's ``MeshFastMarchingDistanceSolver``, geometry-central's
    FMM with the obtuse-triangle unfolding): ``distance(sources) -> (N,)``, or None if missing."""
    try:
        import potpourri3d as pp3d
        solver = pp3d.MeshFastMarchingDistanceSolver(np.asarray(Vs, np.float64), np.asarray(Fs, np.int64))
    except (ImportError, AttributeError):
        return None
    return lambda src: np.asarray(solver.compute_distance([[(int(s), [])] for s in src]), np.float64).ravel()


def heat_multi(Vs, Fs, repeat=5):
    """The heat method on the split mesh: ``(name, setup seconds, distance(sources) -> (N,))``. The
    set-up time is the median of ``repeat`` set-ups (a single one varies 2-3x from run to run on this
    machine), timed after the import (the first mesh of a run paid potpourri3d's import before)."""
    try:
        import potpourri3d as pp3d
    except ImportError:
        pp3d = None
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        if pp3d is not None:
            solver = pp3d.MeshHeatMethodDistanceSolver(np.asarray(Vs, np.float64), np.asarray(Fs, np.int64))
        else:
            one = heat_method(Vs, Fs)
        times.append(time.perf_counter() - t)
    if pp3d is not None:
        fn = lambda src: np.asarray(solver.compute_distance_multisource([int(s) for s in src]), np.float64)  # noqa: E731
        name = 'heat (potpourri3d)'
    else:
        fn = lambda src: np.min([one(int(s)) for s in src], axis=0)  # noqa: E731
        name = 'heat (own)'
    return name, float(np.median(times)), fn


def anchor_runs(V, F, sets, post=lambda d: d):
    """The two on-mesh anchors on every source set: [(name, {set: distances}, setup s, mean query s)]
    for potpourri3d's heat method and, where potpourri3d has it, its mesh fast marching. ``post`` maps
    each distance array (e.g. to the vertices compared)."""
    out = []
    hname, th_setup, heat = heat_multi(V, F)
    t = time.perf_counter()
    fmm = fmm_setup(V, F)
    tf_setup = time.perf_counter() - t
    for name, setup, fn in ((hname, th_setup, heat), ('mesh FMM (potpourri3d)', tf_setup, fmm)):
        if fn is None:
            continue
        d, tq = {}, []
        try:
            for k in SETS:
                t = time.perf_counter()
                d[k] = post(fn(sets[k]))
                tq.append(time.perf_counter() - t)
        except RuntimeError as exc:                 # e.g. geometry-central on a non-manifold mesh
            print(f"# {name} failed: {exc}", flush=True)
            continue
        out.append((name, d, setup, float(np.mean(tq))))
    return out


def table_row(mesh, V, F, method, grid, per, setup, query, viol, extra=None):
    """One result row: ``per`` {set: (mean, max) relative error}, ``viol`` [below Euclid, above edges]."""
    row = {'mesh': mesh, 'verts': len(V), 'tris': len(F), 'method': method, 'grid': grid,
           'per_set': per, 'mean': float(np.mean([v[0] for v in per.values()])),
           'worst_mean': max(v[0] for v in per.values()), 'max': max(v[1] for v in per.values()),
           'setup': setup, 'query': query, 'below_euclid': viol[0], 'above_edges': viol[1]}
    row.update(extra or {})
    return row


def bounds_violations(d, Vs, src, upper, keep):
    """Vertices (count) below the 3D distance to the nearest source, and above the edge-graph
    distance ``upper`` by more than 0.1 %, among ``keep``."""
    E = np.min(np.linalg.norm(Vs[:, None, :] - Vs[src][None], axis=2), axis=1)
    below = keep & (d < E * (1 - 1e-9) - 1e-12)
    above = keep & (d > upper * 1.001)
    return int(below.sum()), int(above.sum())


def where_worst(name, grid, solver, sets, D, keep, dists, bnd, k):
    """Print the ``k`` vertices of largest relative error of our solver per source set, and what sets them
    apart: signed error, exact distance, 3D distance to the nearest source over the part's diagonal,
    boundary vertex, on-mesh (``MeshRelax``) vertex, largest surface cell over edge of its triangles
    (above ``UNRESOLVED`` = on-mesh), largest metric anisotropy ``sqrt(l_max / l_min)`` of its
    triangles, and the split vertex index. ``dists`` {set: (N,) on the split mesh}."""
    from core.geodesic.solver import mean_edges
    Vs = solver.Vs
    info = np.full((len(Vs), 3), np.nan)                  # on-mesh, cell/edge, anisotropy per split vertex
    for ch in solver.charts:
        if getattr(ch, 'grid', None) is None:          # no grid: surface paths, or exact on a flat part
            continue
        ratio = (ch.grid.h / ch.mu_face) / mean_edges(ch.V, ch.F)
        an = np.ones(len(ch.F))
        if ch.ginv is not None:
            a, b, c = ch.ginv.T
            half, dev = (a + c) / 2, np.sqrt(((a - c) / 2) ** 2 + b * b)
            an = np.sqrt((half + dev) / np.maximum(half - dev, 1e-300 * half))
        r = np.zeros(len(ch.V))
        q = np.ones(len(ch.V))
        np.maximum.at(r, ch.F.ravel(), np.repeat(ratio, 3))
        np.maximum.at(q, ch.F.ravel(), np.repeat(an, 3))
        free = ch.free if ch.free is not None else np.zeros(len(ch.V), bool)
        info[ch.verts] = np.c_[free, r, q]
    part = max(solver.charts, key=lambda c: len(c.verts)).verts
    diag = float(np.linalg.norm(np.ptp(Vs[part], axis=0)))
    for s_ in SETS:
        kk = np.flatnonzero(keep[s_])
        r = (dists[s_][kk] - D[s_][kk]) / D[s_][kk]
        E = np.min(np.linalg.norm(Vs[kk, None, :] - Vs[sets[s_]][None], axis=2), axis=1)
        print(f"# {name} grid {grid} {s_}: worst vertices (signed error %, exact, 3D distance / diagonal, "
              "boundary, on-mesh, cell/edge, anisotropy)", flush=True)
        for i in np.argsort(-np.abs(r))[:k]:
            v = kk[i]
            print(f"#   v{v}: {100 * r[i]:+.3f} % exact {D[s_][v]:.4g} near {E[i] / diag:.3f} "
                  f"boundary {bool(bnd[v])} on-mesh {bool(info[v, 0])} cell/edge {info[v, 1]:.2f} "
                  f"anisotropy {info[v, 2]:.3f}", flush=True)


def run_mesh(name, grids, rows, calib, plot, sphere=False):
    """Every source set on one mesh: our solver at its default grid and at ``grids``, the heat method,
    mesh fast marching, all against MMP. Appends rows (dicts) to ``rows``."""
    got = load(name)
    if got is None:
        print(f"# {name}: not found in {MESH_DIR} (the public meshes are not in a user's clone); skipped",
              flush=True)
        return
    V, F, seams = got
    if sphere:
        return run_sphere(name, V, F, rows, plot)
    t = time.perf_counter()
    try:
        gs = GeodesicSolver(V, F, seams=seams, grid=grids[0] if SKIP_DEFAULT and grids else None)
    except ConformalError as exc:
        print(f"# {name}: not handled ({exc}); skipped", flush=True)
        return
    t_setup = time.perf_counter() - t
    Vs, Fs = gs.Vs, gs.Fs
    ch = max(gs.charts, key=lambda c: len(c.verts))
    part = ch.verts                                              # split vertices of the largest island
    from core.mesh.topology import boundary_loops
    bnd = np.zeros(len(Vs), bool)
    for L in boundary_loops(Fs, len(Vs)):
        bnd[np.asarray(L)] = True
    sets = source_sets(Vs, Fs, part, gs.graph, bnd)
    # a source vertex on a seam is a source on every side of it (the solver takes all its copies)
    sets = {k: np.flatnonzero(np.isin(gs.vert_of, gs.vert_of[v])) for k, v in sets.items()}
    D, t_exact = exact_multi(Vs, Fs, sets)
    from scipy.sparse.csgraph import dijkstra
    upper = {k: dijkstra(gs.graph, indices=src, min_only=True) for k, src in sets.items()}
    diag = float(np.linalg.norm(np.ptp(Vs[part], axis=0)))
    in_part = np.zeros(len(Vs), bool)
    in_part[part] = True
    keep = {}
    for k, src in sets.items():
        near = np.min(np.linalg.norm(Vs[:, None, :] - Vs[src][None], axis=2), axis=1) <= EXCLUDE * diag
        keep[k] = in_part & ~near & np.isfinite(D[k]) & (D[k] > 0) & (D[k] < 1e30)
    results = {}

    def evaluate(label, method, grid, dists, setup, query, extra=None):
        """``dists`` {set: (N,) on the split mesh}: relative errors per set, bound violations."""
        per, viol = {}, [0, 0]
        for k in SETS:
            d, kk = dists[k], keep[k]
            r = np.abs(d[kk] - D[k][kk]) / D[k][kk]
            per[k] = (float(r.mean()), float(r.max()))
            b, a = bounds_violations(d, Vs, sets[k], upper[k], kk)
            viol[0] += b
            viol[1] += a
        row = table_row(name, V, F, method, grid, per, setup, query, viol, extra)
        rows.append(row)
        results[label] = row
        return row

    def ours(solver):
        out, tq, est, warn = {}, [], [], 0
        for k in SETS:
            t = time.perf_counter()
            d, rep = solver.distance(np.unique(solver.vert_of[sets[k]]))
            tq.append(time.perf_counter() - t)
            # per split vertex: the solver gives one value per input vertex (the nearest copy); read the
            # copy's own value back from the input vertex so that MMP on the cut surface compares
            out[k] = d[solver.vert_of]
            est.append(rep['error_estimate'])
            warn += len(rep['warnings'])
        # a repeated query: the median of the sets after the first (the first one builds what the solver
        # keeps for later queries, such as the surface paths' graphs: reported as 'first')
        return out, float(np.median(tq[1:] if len(tq) > 1 else tq)), \
            {'estimate': float(np.mean(est)), 'warnings': warn, 'first': tq[0]}

    # our per-input-vertex value is the minimum over its split copies; compare on the split mesh with MMP
    # likewise reduced (a seam vertex is the nearest of its copies, for every method and MMP alike)
    vert_of = gs.vert_of

    def reduce(x):
        out = np.full(len(V), np.inf)
        np.minimum.at(out, vert_of, x)
        return out[vert_of]

    D = {k: reduce(v) for k, v in D.items()}
    upper = {k: reduce(v) for k, v in upper.items()}
    g_def = max(c.size for c in gs.charts) or \
        ('exact' if all(type(c).__name__ == 'PlanarChart' for c in gs.charts) else 0)   # flat: no grid
    d, tq, rep = ours(gs)
    label = 'ours' if SKIP_DEFAULT else 'ours default'
    evaluate(f'ours default ({g_def})', label, g_def, d, t_setup, tq, rep)
    if WHERE:
        where_worst(name, g_def, gs, sets, D, keep, d, bnd, WHERE)
    calib.append({'mesh': name, 'grid': g_def, 'cell': getattr(ch, 'cell', None),
                  'reflex': getattr(ch, 'reflex', None),
                  'mean': results[f'ours default ({g_def})']['mean'], 'estimate': rep['estimate']})
    for g in grids:
        if g == g_def:
            continue
        t = time.perf_counter()
        gg = GeodesicSolver(V, F, seams=seams, grid=g)
        ts = time.perf_counter() - t
        d, tq, rep = ours(gg)
        evaluate(f'ours {g}', 'ours', g, d, ts, tq, rep)
        if WHERE:
            where_worst(name, g, gg, sets, D, keep, d, bnd, WHERE)
    for kk in KS:
        t = time.perf_counter()
        gg = GeodesicSolver(V, F, seams=seams, method='paths', steiner_points=kk)
        ts = time.perf_counter() - t
        d, tq, rep = ours(gg)
        evaluate(f'ours paths {kk}', 'ours paths', f'k={kk}', d, ts, tq, rep)
    for e in TARGETS:
        t = time.perf_counter()
        gg = GeodesicSolver(V, F, seams=seams, error_target=e)
        ts = time.perf_counter() - t
        d, tq, rep = ours(gg)
        evaluate(f'ours target {e:g}', 'ours target', f'{100 * e:g}%', d, ts, tq, rep)
    for aname, d, setup, tq in anchor_runs(Vs, Fs, sets, reduce):
        evaluate(aname, aname, '-', d, setup, tq)
    rows.append({'mesh': name, 'verts': len(V), 'tris': len(F), 'method': 'exact MMP', 'grid': '-',
                 'per_set': {k: (0.0, 0.0) for k in SETS}, 'mean': 0.0, 'worst_mean': 0.0, 'max': 0.0,
                 'setup': 0.0, 'query': t_exact, 'below_euclid': 0, 'above_edges': 0})
    print(f"# {name}: done ({len(V)} vertices, {len(gs.charts)} islands)", flush=True)
    if plot:
        plot_mesh(name, results)


def run_sphere(name, V, F, rows, plot):
    """Sphere mode (``core.sphere.geodesic.sphere_geodesic``) on a closed genus-0 mesh, against MMP on
    the closed mesh, beside the heat method and mesh FMM; the same four source sets."""
    from core.sphere.geodesic import sphere_geodesic
    from core.mesh.geometry import edge_graph
    from core.sphere.map import sphere_map
    from scipy.sparse.csgraph import dijkstra
    t = time.perf_counter()
    try:
        S = sphere_map(V, F).S
    except ConformalError as exc:
        print(f"# {name}: sphere mode not handled ({exc}); skipped", flush=True)
        return
    t_setup = time.perf_counter() - t
    graph = edge_graph(V, F)                    # each edge once, at its length
    part = np.unique(F)
    sets = source_sets(V, F, part, graph, np.zeros(len(V), bool))
    D, t_exact = exact_multi(V, F, sets)
    diag = float(np.linalg.norm(np.ptp(V[part], axis=0)))
    results = {}

    def evaluate(label, dists, setup, query, extra=None):
        per, viol = {}, [0, 0]
        for k in SETS:
            src = sets[k]
            near = np.min(np.linalg.norm(V[:, None, :] - V[src][None], axis=2), axis=1) <= EXCLUDE * diag
            kk = ~near & np.isfinite(D[k]) & (D[k] > 0)
            kk[np.setdiff1d(np.arange(len(V)), part)] = False
            r = np.abs(dists[k][kk] - D[k][kk]) / D[k][kk]
            per[k] = (float(r.mean()), float(r.max()))
            up = dijkstra(graph, indices=src, min_only=True)
            b, a = bounds_violations(dists[k], V, src, up, kk)
            viol[0] += b
            viol[1] += a
        row = table_row(name + ' (sphere)', V, F, label, '-', per, setup, query, viol, extra)
        rows.append(row)
        results[label] = row

    for method in ('auto', 'charts'):
        out, tq, est, warn = {}, [], [], 0
        cache = {}          # kept between the sets, as a caller asking again would keep it
        for k in SETS:
            t = time.perf_counter()
            try:
                d, rep = sphere_geodesic(V, F, sets[k], S=S, method=method, cache=cache)
            except ConformalError as exc:
                print(f"# {name}: sphere mode ({method}) failed on the {k} source set ({exc})", flush=True)
                break
            tq.append(time.perf_counter() - t)
            out[k] = d
            if rep.get('error_estimate') is not None:
                est.append(rep['error_estimate'])
            warn += len(rep['warnings'])
        else:
            extra = {'warnings': warn}
            if est:
                extra['estimate'] = float(np.mean(est))
            # the first set builds what the cache keeps (set-up); a repeated query is the median of
            # the other sets, as for the planar solver
            evaluate(f"ours sphere mode ({rep['method']}{', default' if method == 'auto' else ''})", out,
                     t_setup + tq[0] - float(np.median(tq[1:])), float(np.median(tq[1:])), extra)
    for aname, d, setup, tq in anchor_runs(V, F, sets):
        evaluate(aname, d, setup, tq)
    print(f"# {name} (sphere mode): done; exact MMP {t_exact:.2f} s per set", flush=True)
    if plot:
        plot_mesh(name + '_sphere', results)


def plot_mesh(name, results):
    """Mean error (mean over the source sets) against time: ours at its grids (repeated query, and one
    shot with the set-up), heat and mesh FMM one shot."""
    try:
        import matplotlib
        matplotlib.use('Agg')
        import matplotlib.pyplot as plt
    except ImportError:
        print("# matplotlib is not installed: no plots")
        return
    os.makedirs(OUT, exist_ok=True)
    fig, ax = plt.subplots(figsize=(5.2, 3.8))
    ours = sorted((r for r in results.values() if r['method'] in ('ours', 'ours default')),
                  key=lambda r: r['grid'] if isinstance(r['grid'], int) else 0)
    paths = sorted((r for r in results.values() if r['method'] == 'ours paths'), key=lambda r: r['query'])
    # the error targets' curve runs through the default (its target: 0.1 %)
    targets = []
    if any(r['method'] == 'ours target' for r in results.values()):
        targets = sorted((dict(r, grid='0.1%') if r['method'] == 'ours default' else r
                          for r in results.values() if r['method'] in ('ours target', 'ours default')),
                         key=lambda r: r['query'])
        ours = [r for r in ours if r['method'] != 'ours default']       # drawn once, on that curve
    for rs, what, mark in ((ours, 'ours', 'o'), (paths, 'ours, surface paths', 'D'),
                           (targets, 'ours, error targets', 's')):
        if not rs:
            continue
        ax.loglog([r['query'] for r in rs], [100 * r['mean'] for r in rs], mark + '-',
                  label=f'{what}, repeated query')
        ax.loglog([r['setup'] + r.get('first', r['query']) for r in rs], [100 * r['mean'] for r in rs],
                  mark + '--', mfc='none', label=f'{what}, one shot')
        for r in rs:
            ax.annotate(str(r['grid']), (r['query'], 100 * r['mean']), fontsize=6)
    for r in results.values():
        if not r['method'].startswith('ours'):
            ax.loglog([r['setup'] + r['query']], [100 * r['mean']], '^', label=r['method'] + ', one shot')
    ax.set_xlabel('seconds')
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
    ap.add_argument('--sphere', nargs='*', default=None,
                    help='closed genus-0 meshes to measure in sphere mode (default: spot cheburashka)')
    ap.add_argument('--grids', nargs='*', type=int)
    ap.add_argument('--ks', nargs='*', type=int, default=[],
                    help='also ours answered by surface paths with this many Steiner points per edge '
                         '(method paths, steiner_points K: the accuracy-against-time curve of the paths)')
    ap.add_argument('--targets', nargs='*', type=float, default=[],
                    help='also ours at these error targets (mean relative, e.g. 0.005: the solver chooses '
                         'its grid or Steiner points for each; the accuracy-against-time curve of the '
                         'default method)')
    ap.add_argument('--no-plot', action='store_true')
    ap.add_argument('--skip-default', action='store_true',
                    help='do not run the automatic grid (the first of --grids takes its place)')
    ap.add_argument('--where', type=int, default=0, metavar='K',
                    help='print our K worst vertices per source set and what they lie in (boundary, '
                         'on-mesh, cell/edge, anisotropy)')
    a = ap.parse_args()
    global SKIP_DEFAULT, WHERE, KS, TARGETS
    SKIP_DEFAULT = a.skip_default
    KS = a.ks
    TARGETS = a.targets
    WHERE = a.where
    if not os.path.isdir(MESH_DIR):
        print(f"# {MESH_DIR} is missing: only the generated surfaces are measured")
    names = a.meshes if a.meshes is not None else (['bump', 'edgebump', 'woody', 'spot'] if a.quick
                                                   else SURF + REAL[:-1])
    sphere = a.sphere if a.sphere is not None else ([] if a.quick or a.meshes else ['spot', 'cheburashka'])
    grids = a.grids if a.grids is not None else ([512, 1024] if a.quick else [512, 1024, 2048, 4096])
    rows, calib = [], []
    print(HEADER, flush=True)
    for name in names:
        n0 = len(rows)
        run_mesh(name, grids, rows, calib, not a.no_plot)
        for r in rows[n0:]:
            print_row(r)
    for name in sphere:
        n0 = len(rows)
        run_mesh(name, [], rows, calib, not a.no_plot, sphere=True)
        for r in rows[n0:]:
            print_row(r)
    summary(rows)
    if a.calibrate:
        print(json.dumps(calib))


if __name__ == '__main__':
    main()
