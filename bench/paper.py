"""Issue 8 benchmark: the paper's own experiments (Aflalo, Kimmel and Zibulevsky 2013) on its surface,
set beside our ``area`` and ``uniform`` modes.

    .venv/bin/python bench/paper.py                     # bump, n = 65, geodesic grid 512
    .venv/bin/python bench/paper.py --lp                # also the LP relaxation (minutes)
    .venv/bin/python bench/paper.py --figure docs/img/paper_mu.png

Rows (all on ``core.surfaces.make_surface('bump', n)``, n = 65 by default):

- ``midedge, uncontrolled``: Polthier's midedge map, the paper's Algorithm 1
  (``core.disk.midedge.midedge_map``).
  The cut face is face 0, which touches the corner (-2,-2); ``u = -1, +1`` at its first two vertices;
  every other vertex, boundary included, has the natural condition. Sections 4 and Figures 1-2.
- ``restricted, ramp``: the section 5 family at its starting point, ``u_B`` linear in arc length from 0
  at the corner (-2,-2) to 1 at the opposite corner and back.
- ``restricted, smoothed``: section 5.3, soft-max over soft-min with area-weighted p-norms
  (p = 8, 32, 128, 512), L-BFGS-B on non-negative increment weights (the monotonicity and [0,1]
  constraints are exact in that parametrisation, so the penalty of the paper's PBM is not needed).
- ``restricted, LP`` (only with ``--lp``): section 5.2 read as a sequential LP: all vertex values
  unknown, harmonic rows as equalities, the gradient norm bounded above by a polygon and below by its
  projection on the previous round's gradient direction (HiGHS). About a minute per round here.
- ``area`` and ``uniform``: ``core.disk.flatten.flatten`` (BFF with ``u_B = 0``; our L-inf mode).

Columns: mu_ratio (min/max per-triangle conformal factor), area_ratio (min/max per-triangle image
area / surface area), qc_mean (area-weighted mean s1/s2), flips, geodesic relative error (mean and max
over 3 sources x all vertices farther than 0.05 from the source, against the exact MMP references in
``tests/data/geodesic_ref_bump_<n>.npz``) by ``core.geodesic.solver.geodesic_distance`` on a grid of the same
size (``--grid``) for every map, and the seconds to build the map (noisy: 2 shared cores).

Midedge rows are measured on the medial triangles (``core.disk.midedge.map_measures``): each carries
exactly the map's Jacobian on its face, so qc is 1 by construction and flips are 0. The geodesic
columns use the conforming vertex version of the map (``MidedgeMap.vertex_uv``) without the cut face.
A source whose neighbourhood maps to less than one grid cell cannot be seeded: such sources are
counted as failures, not averaged.

The SDP relaxation is not run. It lifts the boundary vector ``x`` (nb = 256 values at n = 65) to a
matrix ``X = x x^T`` (an nb x nb, or with all vertex values an n x n = 4225 x 4225, PSD variable): each
``|grad_T u|^2`` becomes linear in ``X`` and the max-min ratio a linear objective over the PSD cone.
That is 32,896 (or 8.9 million) unknowns with 16,384 dense constraint matrices, one pair per
triangle; an interior-point solver forms a dense Schur complement of that many constraints (~2 GB,
hours on 2 cores), no SDP solver is in the venv (core may use numpy and scipy only), and the
relaxed ``X`` would still need a rank-one rounding, the same nonconvex step the smoothed formulation
solves directly. The smoothed formulation is the paper's practical route as well.
"""
import argparse
import importlib.util
import os
import struct
import sys
import time
import zlib

import numpy as np

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, ROOT)

from core.errors import ConformalError                                   # noqa: E402
from core.disk.flatten import flatten                                         # noqa: E402
from core.mesh.measures import conformal_factor, uv_measures                  # noqa: E402
from core.disk.midedge import (RestrictedFamily, lp_restricted, map_measures,  # noqa: E402
                          midedge_map, optimise_restricted)
from core.surfaces import make_surface                                   # noqa: E402

PAPER = {  # the paper's reported values, for the comparison table
    'uncontrolled': ('Figs 1-2', 1e-7, 1e-13),
    'initial': ('Fig 4, before', 0.003, 0.001),
    'optimised': ('Fig 4, after', 0.59, 0.34),
}


# --------------------------------------------------------------------------------------------------
def geodesic_errors(V, F, uv, ref, grid):
    """Relative errors of fast marching on the map ``uv`` (n,2) over triangles ``F``, against ``ref``
    (npz with ``sources`` and ``dist``). Returns (mean, max, failed sources)."""
    from core.geodesic.solver import geodesic_distance
    errs, failed = [], 0
    for s, d in zip(ref['sources'], ref['dist']):
        try:
            D, _ = geodesic_distance(V, F, sources=[int(s)], uv=uv, grid=grid)
        except ConformalError:
            failed += 1
            continue
        ok = d > 0.05
        errs.append(np.abs(D[ok] - d[ok]) / d[ok])
    if not errs:
        return np.nan, np.nan, failed
    e = np.concatenate(errs)
    return float(e.mean()), float(e.max()), failed


def uv_area_ratio(V, F, uv):
    mu = conformal_factor(V, F, uv)
    return float((mu.min() / mu.max()) ** 2)


# --------------------------------------------------------------------------------------------------
def write_png(path, rgb):
    """Write an (h, w, 3) uint8 image as an 8-bit RGB PNG (zlib, no filter)."""
    h, w, _ = rgb.shape
    raw = b''.join(b'\x00' + rgb[i].tobytes() for i in range(h))

    def chunk(tag, data):
        return (struct.pack('>I', len(data)) + tag + data
                + struct.pack('>I', zlib.crc32(tag + data) & 0xffffffff))
    png = (b'\x89PNG\r\n\x1a\n' + chunk(b'IHDR', struct.pack('>IIBBBBB', w, h, 8, 2, 0, 0, 0))
           + chunk(b'IDAT', zlib.compress(raw, 9)) + chunk(b'IEND', b''))
    with open(path, 'wb') as f:
        f.write(png)


def _colormap():
    """addon/colormap.py is pure numpy; load it by path so that bpy is not imported."""
    spec = importlib.util.spec_from_file_location('cf_colormap', os.path.join(ROOT, 'addon', 'colormap.py'))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def rasterise(P, F, shape):
    """Triangle index (h, w) int64 covering each pixel centre, -1 where none. ``P`` (n,2) vertex
    positions in pixel units (x = column, y = row), ``F`` (m,3). All (triangle, pixel of its bounding
    box) pairs are tested at once with edge functions."""
    h, w = shape
    W = P[F]
    lo = np.floor(W.min(axis=1) - 0.5).astype(np.int64)
    hi = np.ceil(W.max(axis=1) - 0.5).astype(np.int64)
    lo = np.clip(lo, 0, [w - 1, h - 1])
    hi = np.clip(hi, 0, [w - 1, h - 1])
    cw, ch = hi[:, 0] - lo[:, 0] + 1, hi[:, 1] - lo[:, 1] + 1
    cnt = cw * ch
    t = np.repeat(np.arange(len(F)), cnt)
    k = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    jj = lo[t, 0] + k % cw[t]
    ii = lo[t, 1] + k // cw[t]
    x, y = jj + 0.5, ii + 0.5
    inside = np.ones(len(t), bool)
    area = ((W[:, 1, 0] - W[:, 0, 0]) * (W[:, 2, 1] - W[:, 0, 1])
            - (W[:, 1, 1] - W[:, 0, 1]) * (W[:, 2, 0] - W[:, 0, 0]))
    sgn = np.sign(area)[t]
    for a, b in ((0, 1), (1, 2), (2, 0)):
        pa, pb = W[t, a], W[t, b]
        e = (pb[:, 0] - pa[:, 0]) * (y - pa[:, 1]) - (pb[:, 1] - pa[:, 1]) * (x - pa[:, 0])
        inside &= e * sgn >= -1e-12
    face = np.full((h, w), -1, np.int64)
    face[ii[inside], jj[inside]] = t[inside]
    return face


def render_panel(uv, F, face_value, lo, hi, size, cmap):
    """(size, size, 3) uint8: the triangles ``F`` at ``uv`` (n,2) filled with the colour of
    ``face_value`` (log scale between ``lo`` and ``hi``) on white, the domain fitted and centred, v up."""
    used = np.unique(F)
    a, b = uv[used].min(0), uv[used].max(0)
    s = (size - 4) / (b - a).max()
    P = (uv - (a + b) / 2) * s + size / 2
    P[:, 1] = size - P[:, 1]
    face = rasterise(P, F, (size, size))
    col = cmap.to_srgb8(cmap.colormap(cmap.normalise(face_value, lo, hi, log=True)))[:, :3]
    out = np.full((size, size, 3), 255, np.uint8)
    out[face >= 0] = col[face[face >= 0]]
    return out


def figure(path, V, F, maps, size=240):
    """Conformal factor maps side by side. ``maps``: list of (uv (n,2), faces (k,3), mu (k,)), one
    column each. Row 1: each map's image in the plane, coloured by log mu on its own range. Row 2:
    log mu painted on the surface's (x, y) square, own range. Row 3: the same with one shared range
    for all columns. A thin colour bar (low = dark blue, high = yellow) under each row."""
    cmap = _colormap()
    gap, bar = 8, 8
    W = len(maps) * size + (len(maps) + 1) * gap
    H = 3 * (size + bar + 2 * gap) + gap
    img = np.full((H, W, 3), 255, np.uint8)
    glo = min(float(mu.min()) for _, _, mu in maps)
    ghi = max(float(mu.max()) for _, _, mu in maps)
    cb = cmap.to_srgb8(cmap.colormap(np.linspace(0, 1, size)))[:, :3]
    for k, (uv, Fk, mu) in enumerate(maps):
        x0 = gap + k * (size + gap)
        panels = (render_panel(uv, Fk, mu, mu.min(), mu.max(), size, cmap),
                  render_panel(V[:, :2], Fk, mu, mu.min(), mu.max(), size, cmap),
                  render_panel(V[:, :2], Fk, mu, glo, ghi, size, cmap))
        for r, panel in enumerate(panels):
            y0 = gap + r * (size + bar + 2 * gap)
            img[y0:y0 + size, x0:x0 + size] = panel
            img[y0 + size + gap:y0 + size + gap + bar, x0:x0 + size] = cb[None]
    write_png(path, img)
    return glo, ghi


# --------------------------------------------------------------------------------------------------
def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument('--n', type=int, default=65, help='grid size of the bump (default 65)')
    ap.add_argument('--grid', type=int, default=512, help='fast-marching grid, nodes on the long side')
    ap.add_argument('--lp', action='store_true', help='also run the LP relaxation (slow)')
    ap.add_argument('--lp-rounds', type=int, default=3)
    ap.add_argument('--figure', metavar='PNG', help='write the conformal-factor figure here')
    ap.add_argument('--no-starts', action='store_true', help='skip the start-vertex sensitivity table')
    args = ap.parse_args()
    t_all = time.perf_counter()
    n = args.n
    V, F = make_surface('bump', n)
    ref_path = os.path.join(ROOT, 'tests', 'data', f'geodesic_ref_bump_{n}.npz')
    ref = np.load(ref_path) if os.path.exists(ref_path) else None
    have_geo = importlib.util.find_spec('core.geodesic.solver') is not None
    print(f"bump, n = {n} ({len(V)} vertices, {len(F)} triangles); geodesic grid {args.grid}"
          + ("" if ref is not None else f"; no reference {os.path.basename(ref_path)}: no geodesic columns")
          + ("" if have_geo else "; core.geodesic.solver missing: no geodesic columns"))
    if not have_geo:
        ref = None
    rows, figmaps, conforming = [], {}, {}

    def midedge_row(label, mm, seconds):
        m = map_measures(V, F, mm)
        Fk = F[mm.keep]
        uv = mm.vertex_uv(V, F)
        geo = geodesic_errors(V, Fk, uv, ref, args.grid) if ref is not None else (np.nan,) * 2 + (0,)
        rows.append((label, m['mu_ratio'], m['area_ratio'], m['qc_mean'], m['flips'], geo, seconds))
        conforming[label] = uv_measures(V, Fk, uv)
        return uv, Fk

    t = time.perf_counter()
    mm0 = midedge_map(V, F, cut_face=0)
    sec = time.perf_counter() - t
    uv0, F0 = midedge_row('midedge, uncontrolled', mm0, sec)
    figmaps['uncontrolled'] = (uv0, F0, mm0.mu[mm0.keep])
    cr = {'uncontrolled': mm0.report['cr_residual']}

    fam = RestrictedFamily(V, F)
    t = time.perf_counter()
    mm1 = fam.map(fam.boundary_values(fam.ramp()))
    midedge_row('restricted, ramp', mm1, time.perf_counter() - t)
    t = time.perf_counter()
    mm2, rep2 = optimise_restricted(V, F, family=fam)
    sec = time.perf_counter() - t
    uv2, F2 = midedge_row('restricted, smoothed', mm2, sec)
    figmaps['smoothed'] = (uv2, F2, mm2.mu)
    cr['smoothed'] = mm2.report['cr_residual']
    if args.lp:
        t = time.perf_counter()
        mm3, rep3 = lp_restricted(V, F, family=fam, rounds=args.lp_rounds)
        midedge_row('restricted, LP', mm3, time.perf_counter() - t)

    for mode in ('area', 'uniform'):
        try:
            r = flatten(V, F, boundary=mode, bound=False)
        except ConformalError as exc:
            print(f"  {mode}: failed: {exc}")
            continue
        rp = r.report
        geo = geodesic_errors(V, F, r.uv, ref, args.grid) if ref is not None else (np.nan,) * 2 + (0,)
        rows.append((mode, rp['mu_ratio'], uv_area_ratio(V, F, r.uv), rp['qc_mean'], rp['flips'], geo,
                     rp['seconds']['total']))
        if mode == 'uniform':
            figmaps['uniform'] = (r.uv, F, r.mu)

    head = (f"{'map':22} {'mu_ratio':>9} {'area_ratio':>10} {'qc_mean':>8} {'flips':>5} "
            f"{'geo_mean':>9} {'geo_max':>8} {'seconds':>8}")
    print()
    print(head)
    print('-' * len(head))
    for label, mr, ar, qc, fl, (gm, gx, gf), sec in rows:
        geo = f"{gm:9.4f} {gx:8.4f}" if np.isfinite(gm) else f"{'n/a':>9} {'n/a':>8}"
        note = f"  ({gf} of {len(ref['sources'])} sources fail: seed below one grid cell)" if gf else ''
        print(f"{label:22} {mr:9.3g} {ar:10.3g} {qc:8.4f} {fl:5d} {geo} {sec:8.2f}{note}")
    print("\nconforming vertex versions of the midedge maps (used for the geodesic columns):")
    for label, m in conforming.items():
        print(f"  {label:22} mu_ratio {m['mu_ratio']:9.3g}  qc_mean {m['qc_mean']:.4f}  "
              f"qc_max {m['qc_max']:.3g}  flips {m['flips']}")
    print(f"\ndiscrete Cauchy-Riemann residual (max relative): uncontrolled {cr['uncontrolled']:.1e}, "
          f"smoothed {cr['smoothed']:.1e}")
    print(f"smoothed solver: {rep2['iterations']} L-BFGS-B iterations, {rep2['evaluations']} evaluations, "
          f"p = {rep2['p_schedule']}")
    if args.lp:
        print("LP rounds: " + ', '.join(f"t={h['t']:.3f} ratio={h['ratio']:.3f}" if 'ratio' in h
                                        else str(h) for h in rep3['rounds']))

    print(f"\n{'paper vs ours':22} {'paper mu':>9} {'ours mu':>9} {'paper area':>10} {'ours area':>10}")
    by = {r[0]: r for r in rows}
    for key, label in (('uncontrolled', 'midedge, uncontrolled'), ('initial', 'restricted, ramp'),
                       ('optimised', 'restricted, smoothed')):
        fig, pm, pa = PAPER[key]
        r = by[label]
        print(f"{fig:22} {pm:9.3g} {r[1]:9.3g} {pa:10.3g} {r[2]:10.3g}")

    if not args.no_starts:
        print(f"\nsensitivity, mu_ratio: {'variant':44} {'initial':>8} {'optimised':>9} {'seconds':>8}")
        t = time.perf_counter()
        mmc = midedge_map(V, F, cut_face=int(np.argmin(np.linalg.norm(V[F].mean(1)[:, :2], axis=1))))
        ratio = map_measures(V, F, mmc)['mu_ratio']
        print(f"{'':23}{'uncontrolled, cut face at the centre':44} {ratio:8.3g} "
              f"{'':>9} {time.perf_counter() - t:8.2f}")
        k = n // 2
        for name, start in (('left edge middle (-2,0)', k * n), ('bottom edge middle (0,-2)', k)):
            t = time.perf_counter()
            _, rp = optimise_restricted(V, F, start=start)
            print(f"{'':23}{'restricted, start ' + name:44} {rp['ratio_initial']:8.3g} {rp['ratio']:9.3g} "
                  f"{time.perf_counter() - t:8.2f}")

    if args.figure:
        keys = [k for k in ('uncontrolled', 'smoothed', 'uniform') if k in figmaps]
        lo, hi = figure(args.figure, V, F, [figmaps[k] for k in keys])
        kb = os.path.getsize(args.figure) // 1024
        print(f"\nfigure {args.figure} ({kb} KB): panels {', '.join(keys)}; "
              f"per-panel mu ranges " + ', '.join(f"{figmaps[k][2].min():.3g}..{figmaps[k][2].max():.3g}"
                                                  for k in keys)
              + f"; shared range {lo:.3g}..{hi:.3g}")
    print(f"\ntotal {time.perf_counter() - t_all:.1f} s")


if __name__ == '__main__':
    main()
