"""Cones and seams for the L-inf objective (issue 13): the Pareto table and the anchors.

    .venv/bin/python bench/cones.py [--meshes spot cheburashka cow rocker-arm] [--budgets 4 8 12 16 24]
                                    [--no-anchor] [--no-xatlas] [--no-auto] [--big] [--acceptance]
                                    [--cuts [spot cow cheburashka]] [--cut-subdivisions 2] [--features]

Rows per mesh: ``cone_unwrap`` with exactly N cones (``target_ratio=None, max_cones=N``) and 'auto'
(``target_ratio=0.5``); the BFF-style greedy anchor (a cone at the vertex of largest |u| with u equal
at the cones, re-solve, repeat: L2 flavour, no moves, BFF's angles) laid out by the same cut and
layout; xatlas's charts (if the ``xatlas`` package is installed; benchmarks only). Every row is
measured per triangle with core.mesh.measures: mu_ratio (min/max), p1/p99 (area-weighted and by
count, DESIGN section 3; the placement scores the worse of the two), the vertex-level p1/p99 of
the cones' u, qc_mean, flips; 'cross' counts boundary self-crossings of the cut disk (0 with 0
flips: no overlap). 'charts' counts the pieces of the layout (an overlapping cut disk is split,
then glued back where the pieces do not overlap: ``split_overlaps``, ``merge_charts``). 'seam' is
the cut's length (chart splits included) as a fraction of the total edge length. Published
MovingCones p1/p99 (vertex level) for comparison: spot 16 cones 0.367, 41 cones 0.615; cheburashka
24 cones 0.383, 53 cones 0.604; rocker-arm 8 cones 0.420, 18 cones 0.617.

``--cuts [names]``: head-like disks cut from spot, cow and cheburashka (``meshes.HEAD_CUTS``), Loop-subdivided
``--cut-subdivisions`` times (default 2: 28k-64k triangles), at 7, 9 and 10 cones and at the
``--targets`` ratios (default 0.66 and 0.74, the xatlas goal on the issue's held-out heads): stand-ins
for the held-out scans, which are not used here.

``--acceptance``: only the MovingCones rows (spot 16 and 41 cones, cheburashka 24 and 53, rocker-arm 8
and 18), placed and laid out by ``cone_unwrap``, beside the published figure.

``--features``: machined parts (tests/data/bool_boss.obj and bool_bracket.obj, ``meshgen``'s capped
cylinders, and Blender's cylinder and cone where ``bpy`` imports) laid out by ``cone_layout`` with
and without their feature curves (docs/cones.md, "Thirtieth round"): islands, cones, feature edges,
p1/p99 per triangle, qc_mean, flips and seconds.

``--big``: the speed target, auto cones plus flattening on ~100k-triangle meshes (spot subdivided
twice; a blob), with wall and CPU time, stage times and peak memory (``--big-extra``: also
cheburashka and rocker-arm subdivided once, cow twice). Meshes are read from
``meshes.corpus_dir()`` (outside the repository); the script says so and skips a mesh that is
missing. Cow's non-manifold vertex is split by ``cone_unwrap`` itself. Timings are noisy (shared machine).
``--meshes`` also takes the voxel-remeshed and decimated meshes of ``blender_made`` (``figure-dec``,
``suzvox-dec``, ``cow-dec``, ...), built with bpy."""
import argparse
import os
import resource
import sys
import time

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

import numpy as np

from core.atlas.cones import ConeSystem, cone_unwrap, weighted_spread
from core.atlas.islands import cut_along_seams
from core.io.obj import read_obj
from core.mesh import topology
from core.mesh.measures import uv_measures
from core.mesh.validate import normalise_scale
from core.surfaces import blob, subdivide
from meshes import HEAD_CUTS, corpus_dir

MESHES = corpus_dir()
MOVING_CONES = {'spot': {16: 0.367, 41: 0.615}, 'cheburashka': {24: 0.383, 53: 0.604},
                'rocker-arm': {8: 0.420, 18: 0.617}}


def load(name):
    """(V, F) of a corpus mesh, or of a mesh made with Blender's tools (``blender_made.NAMES``)."""
    import blender_made
    if name in blender_made.NAMES:
        return blender_made.load(name)
    path = os.path.join(MESHES, f'{name}.obj')
    if not os.path.exists(path):
        print(f"!! {path} is missing: the public meshes are not in the repository (set CONFORMAL_MESHES); "
              f"skipping {name}")
        return None
    m = read_obj(path)
    F, _ = m.triangles()
    return m.V, F


def manifold(V, F):
    """Split non-manifold vertices (one copy per fan) for the anchors, which work on vertex ids."""
    n = len(V)
    if (topology.vertex_fans(F, n) <= 1).all():
        return V, F
    cut = cut_along_seams(F, n)
    return V[cut.vert_of], cut.F


def greedy_anchor(V, F, N):
    """BFF's greedy cones (L2 flavour): cone at the vertex of largest |u - u_cone|, u equal at the
    cones, re-solve, repeat. Returns (ids, kappa)."""
    sy = ConeSystem(normalise_scale(V)[0], F)
    if sy.needs_sum:
        va = sy.vertex_area / sy.vertex_area.sum()
        u = sy.solve(sy.total * va - sy.Omega)
    else:
        u = sy.u0.copy()
    S, kap = [], np.zeros(0)
    for _ in range(N):
        dev = np.abs(u - (u[S[0]] if S else np.median(u)))
        dev[~sy.eligible] = -1
        if S:
            dev[sy.rings(S, 1)] = -1
        S.append(int(np.argmax(dev)))
        kap = sy.dirichlet_angles(S)
        u = sy.u_of(S, kap)
    return np.array(S, np.int64), kap


def xatlas_row(V, F):
    import xatlas
    t = time.perf_counter()
    vmap, idx, uvs = xatlas.parametrize(V.astype(np.float32), F.astype(np.uint32))
    dt = time.perf_counter() - t
    idx = idx.astype(np.int64)
    uvs = uvs.astype(np.float64)
    m = uv_measures(V[vmap], idx, uvs)
    # flips per chart (xatlas may mirror a whole chart, which is not a fold)
    nchart, chart = topology.face_components(idx, len(vmap))
    W = uvs[idx]
    d1, d2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    det = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
    major = np.sign(np.bincount(chart, np.sign(det), minlength=nchart))
    m['flips'] = int((np.sign(det) != major[chart]).sum())
    # the acceptance measure: area-weighted 1%/99% of the scale sqrt(|A_uv| / A_3d), as for the cones
    Vc = V[vmap].astype(np.float64)
    a3 = 0.5 * np.linalg.norm(np.cross(Vc[idx[:, 1]] - Vc[idx[:, 0]], Vc[idx[:, 2]] - Vc[idx[:, 0]]), axis=1)
    m['mu_ratio_p1_p99_area'] = weighted_spread(np.sqrt(0.5 * np.abs(det) / np.maximum(a3, 1e-300)), a3)
    # seams: boundary edges of the chart mesh, as input edges (both copies give the same key)
    E, _ = topology.unique_edges(F)
    total = np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).sum()
    Hs = topology.halfedges(idx)
    tw = topology.twin_halfedges(idx, len(vmap))
    He = vmap[Hs[tw < 0]]
    key = np.unique(np.minimum(He[:, 0], He[:, 1]) * len(V) + np.maximum(He[:, 0], He[:, 1]))
    seam = np.linalg.norm(V[key // len(V)] - V[key % len(V)], axis=1).sum()
    return {'cones': f'{nchart} charts', 'seam_fraction': seam / total, **m, 'overlaps': '-', 'time': dt}


def fmt(name, label, r, ref=None):
    cells = [name, label, str(r['cones']), str(r.get('charts', '-')), f"{r['seam_fraction']:.4f}",
             f"{r['mu_ratio']:.3f}",
             f"{r.get('mu_ratio_p1_p99_area', float('nan')):.3f}", f"{r['mu_ratio_p1_p99']:.3f}",
             f"{r.get('estimated_p1_p99', float('nan')):.3f}",
             f"{r['qc_mean']:.3f}", str(r['flips']), str(r['overlaps']),
             f"{r['time']:.1f}", '' if ref is None else f"{ref:.3f}"]
    return '| ' + ' | '.join(cells) + ' |'


def header(first, last):
    """The header of ``fmt``'s rows: ``first`` names the mesh column, ``last`` the reference column."""
    cells = [first, 'method', 'cones', 'charts', 'seam', 'mu_ratio', 'p1/p99 (area)', 'p1/p99 (count)',
             'p1/p99 of u', 'qc_mean', 'flips', 'cross', 's', last]
    print('| ' + ' | '.join(cells) + ' |')
    print('|' + '---|' * len(cells))


def row(res, t):
    r = dict(res.report)
    r['time'] = t
    return r


def table(names, budgets, anchor, use_xatlas, auto=True, per_mesh=None):
    """Print the Pareto table; ``per_mesh`` (dict name -> budgets) overrides ``budgets``."""
    header('mesh', 'MovingCones p1/p99')
    for name in names:
        got = load(name)
        if got is None:
            continue
        V, F = got
        ref = MOVING_CONES.get(name, {})
        for N in list((per_mesh or {}).get(name, budgets)) + (['auto'] if auto else []):
            t = time.perf_counter()
            if N == 'auto':
                res = cone_unwrap(V, F, target_ratio=0.5)
            else:
                res = cone_unwrap(V, F, target_ratio=None, max_cones=N)
            print(fmt(name, 'L-inf cones' + (' (auto, target 0.5)' if N == 'auto' else ''),
                      row(res, time.perf_counter() - t), ref.get(N)), flush=True)
        if anchor:
            Vm, Fm = manifold(V, F)
            for N in budgets:
                t = time.perf_counter()
                ids, kap = greedy_anchor(Vm, Fm, N)
                res = cone_unwrap(Vm, Fm, cones=(ids, kap))
                print(fmt(name, 'greedy anchor (BFF, L2)', row(res, time.perf_counter() - t), ref.get(N)),
                      flush=True)
        if use_xatlas:
            try:
                r = xatlas_row(*manifold(V, F))
                print(fmt(name, 'xatlas charts', r), flush=True)
            except ImportError:
                print(f"| {name} | xatlas | not installed (pip install xatlas; benchmarks only) |")


CORPUS_REST = ['alligator', 'woody', 'suzanne', 'teapot', 'stanford-bunny', 'beast', 'ogre']
SURFACES = ['bump', 'bump3', 'edgebump', 'ridge', 'saddle']


def corpus_rows(names, budgets, auto=True, n=65):
    """The Pareto rows of every other mesh (disks, holes, several parts, messy input) and of the
    generated surfaces at ``n`` (disks), through ``core.unwrap(V, F, cones=N)`` (a budget per part;
    'auto': target 0.5), as a user's one call does: the core repairs and splits the input itself.
    The result's own per-triangle measures (``report``, ``mu``: zero-area triangles left out):
    mu_ratio, area-weighted p1/p99, qc_mean, flips, overlaps, and the seams' length over all edges."""
    from core import make_surface, unwrap
    from core.mesh.geometry import face_areas
    print('| mesh | triangles | cones | islands | seam | mu_ratio | p1/p99 (area) | qc_mean | flips '
          '| overlaps | s | warnings |')
    print('|---|---|---|---|---|---|---|---|---|---|---|---|')
    for name in names:
        if name in SURFACES:
            V, F = make_surface(name, n)
            label = f'{name} {n}'
        else:
            got = load(name)
            if got is None:
                continue
            V, F = got
            label = name
        for N in list(budgets) + (['auto'] if auto else []):
            t = time.perf_counter()
            try:
                res = unwrap(V, F, cones=N, target_ratio=0.5)
            except Exception as exc:                      # a row that fails is a finding: print it
                print(f"| {label} | {len(F)} | {N} | error: {exc} |", flush=True)
                continue
            dt = time.perf_counter() - t
            r = res.report
            ok = np.isfinite(res.mu)                  # flattened, zero-area triangles left out
            spread = weighted_spread(res.mu[ok], face_areas(V, F)[ok])
            print(f"| {label} | {len(F)} | {N}: {len(res.cones)} | {r['islands']} | "
                  f"{r['seam_fraction']:.4f} | {r['mu_ratio']:.3f} | {spread:.3f} | {r['qc_mean']:.3f} | "
                  f"{r['flips']} | {r['overlaps']} | {dt:.1f} | {len(res.warnings)} |", flush=True)




def cut_rows(names, budgets, subdivisions, targets):
    """Head-like disks (``meshes.HEAD_CUTS``: a plane cut of spot, cow and cheburashka, the largest piece,
    then ``subdivisions`` steps of Loop's rule, to the size of scanned heads: 28k-64k triangles at 2), as
    stand-ins for the issue's held-out scans: ``cone_unwrap`` with exactly N cones for each of
    ``budgets`` and with each of ``targets`` (target_ratio, up to 64 cones; the xatlas goal on the
    held-out heads is 0.66 and 0.74). Over 20k vertices (cheburashka's at 2) the big-mesh path runs."""
    from meshes import cut_disk, loop_subdivide
    header('mesh (triangles)', '')
    for name in names:
        got = load(name)
        if got is None:
            continue
        V, F = cut_disk(*got, *HEAD_CUTS[name])
        for _ in range(subdivisions):
            V, F = loop_subdivide(V, F)
        label = f"{name} cut x{subdivisions} ({len(F)})"
        for N in list(budgets) + [f't{x}' for x in targets]:
            t = time.perf_counter()
            if isinstance(N, str):
                res = cone_unwrap(V, F, target_ratio=float(N[1:]), max_cones=64)
            else:
                res = cone_unwrap(V, F, target_ratio=None, max_cones=N)
            print(fmt(label, f'target {N[1:]}' if isinstance(N, str) else 'L-inf cones',
                      row(res, time.perf_counter() - t)), flush=True)


def big(extra=False):
    """The speed rows: wall and CPU seconds (CPU: this process, all threads), the stage times of
    ``report['seconds']``, the peak resident memory of the process so far (it only grows from row to
    row) and the load average when the row ended (the machine is shared: compare rows run minutes
    apart, interleaved). ``extra``: also cheburashka and rocker-arm subdivided once and cow twice
    (needles, genus 1, a split non-manifold vertex), the robustness rows of the big-mesh path."""
    print('| mesh | triangles | cones | charts | p1/p99 (area) | p1/p99 (count) | mu_ratio | qc_mean | flips '
          '| cross | s (wall) | s (CPU) | s by stage | peak RSS MB | load |')
    print('|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|')
    cases = []
    for name, times in [('spot', 2)] + ([('cheburashka', 1), ('rocker-arm', 1), ('cow', 2)] if extra else []):
        got = load(name)
        if got is None:
            continue
        V, F = got
        for _ in range(times):
            V, F = subdivide(V, F)
        cases.append((f"{name} subdivided x{times}", V, F))
        if name == 'spot':
            cases.append(('blob(71)', *blob(71)))
    if not cases:
        cases.append(('blob(71)', *blob(71)))
    for name, V, F in cases:
        t, c = time.perf_counter(), time.process_time()
        res = cone_unwrap(V, F, target_ratio=0.5)
        dt, dc = time.perf_counter() - t, time.process_time() - c
        r = res.report
        peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
        stages = ', '.join(f"{k} {v:.1f}" for k, v in r['seconds'].items() if k != 'total')
        print(f"| {name} | {len(F)} | {r['cones']} | {r['charts']} | {r['mu_ratio_p1_p99_area']:.3f} | "
              f"{r['mu_ratio_p1_p99']:.3f} | {r['mu_ratio']:.3f} | "
              f"{r['qc_mean']:.3f} | {r['flips']} | {r['overlaps']} | {dt:.1f} | {dc:.1f} | {stages} | "
              f"{peak:.0f} | {os.getloadavg()[0]:.1f} |", flush=True)


def feature_cases():
    """(name, V, F, poly or None) of the machined parts of ``--features``."""
    from core.mesh.triangulate import triangulate
    sys.path.insert(0, os.path.join(ROOT, 'tests'))
    from meshgen import capped_cylinder
    cases = []
    for name in ('bool_boss', 'bool_bracket'):
        mesh = read_obj(os.path.join(ROOT, 'tests', 'data', name + '.obj'))
        tc, poly = triangulate(mesh.corner_verts, mesh.sizes, mesh.V)
        cases.append((name, mesh.V, mesh.corner_verts[tc], poly))
    cases += [('capped_cylinder 48x12', *capped_cylinder(48, 12), None),
              ('capped_cylinder 64x20', *capped_cylinder(64, 20), None)]
    try:
        import bpy
    except ImportError:
        print("(bpy is missing: Blender's primitives are left out)")
        return cases
    for name, add in (('Blender cylinder', bpy.ops.mesh.primitive_cylinder_add),
                      ('Blender cone', bpy.ops.mesh.primitive_cone_add)):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        add()
        me = bpy.context.object.data
        V = np.array([v.co[:] for v in me.vertices], np.float64)
        cv = np.array([lp.vertex_index for lp in me.loops], np.int64)
        sizes = np.array([p.loop_total for p in me.polygons], np.int64)
        tc, poly = triangulate(cv, sizes, V)
        cases.append((name, V, cv[tc], poly))
    return cases


def feature_rows():
    """``--features``: each machined part through ``cone_layout`` (after the same repair as
    ``core.unwrap``) without and with its feature curves."""
    from core.atlas.unwrap import cone_layout
    from core.mesh.repair import repair_merged
    from core.mesh.validate import degenerate_faces
    print("| part | triangles | feature curves | islands | cones | feature edges | p1/p99 | qc_mean | flips "
          "| s |")
    print('|---' * 10 + '|')
    for name, V, F, poly in feature_cases():
        fixed, _ = repair_merged(V, F)
        pf = None if poly is None else poly[fixed.face_map]
        for feat in (False, True):
            t = time.perf_counter()
            uv, _, reps, _, cones, nf = cone_layout(fixed.V, fixed.F, poly=pf, features=feat)
            t = time.perf_counter() - t
            good = ~degenerate_faces(fixed.V, fixed.F)        # the repair's collapsed triangles left out
            m = int(good.sum())
            r = uv_measures(fixed.V[fixed.F[good]].reshape(-1, 3), np.arange(3 * m).reshape(m, 3),
                            uv[good].reshape(-1, 2))
            print(f"| {name} | {m} | {'yes' if feat else 'no'} | {len(reps)} | {len(cones)} | {nf} "
                  f"| {r['mu_ratio_p1_p99']:.3f} | {r['qc_mean']:.3f} | {r['flips']} | {t:.2f} |", flush=True)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--meshes', nargs='+', default=['spot', 'cheburashka', 'cow', 'rocker-arm'])
    ap.add_argument('--budgets', nargs='+', type=int, default=[4, 8, 12, 16, 24])
    ap.add_argument('--no-anchor', action='store_true')
    ap.add_argument('--no-xatlas', action='store_true')
    ap.add_argument('--no-auto', action='store_true', help="skip the 'auto' (target 0.5) rows")
    ap.add_argument('--big', action='store_true', help='only the 100k-triangle speed rows')
    ap.add_argument('--big-extra', action='store_true',
                    help='with --big: also cheburashka, rocker-arm (subdivided once) and cow (twice)')
    ap.add_argument('--acceptance', action='store_true', help='only the MovingCones rows')
    ap.add_argument('--cuts', nargs='*', default=None,
                    help='head-like disks cut from the corpus (names from HEAD_CUTS; none given: all), '
                         'at --budgets (default here 7 9 10) and --targets')
    ap.add_argument('--cut-subdivisions', type=int, default=2, help="with --cuts: Loop's steps")
    ap.add_argument('--targets', nargs='*', type=float, default=[0.66, 0.74], help='with --cuts')
    ap.add_argument('--corpus', nargs='*', default=None,
                    help='the rows of the other corpus meshes and the generated surfaces through '
                         'core.unwrap (names; none given: all of CORPUS_REST and SURFACES)')
    ap.add_argument('--features', action='store_true',
                    help='machined parts with and without their feature curves (docs/cones.md)')
    a = ap.parse_args()
    if a.features:
        feature_rows()
    elif a.big:
        big(a.big_extra)
    elif a.cuts is not None:
        budgets = a.budgets if a.budgets != ap.get_default('budgets') else [7, 9, 10]
        cut_rows(a.cuts or list(HEAD_CUTS), budgets, a.cut_subdivisions, a.targets)
    elif a.acceptance:
        table(list(MOVING_CONES), [], False, False, False, per_mesh=MOVING_CONES)
    elif a.corpus is not None:
        corpus_rows(a.corpus or CORPUS_REST + SURFACES, a.budgets, not a.no_auto)
    else:
        table(a.meshes, a.budgets, not a.no_anchor, not a.no_xatlas, not a.no_auto)


if __name__ == '__main__':
    main()
