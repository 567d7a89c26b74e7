"""``python -m core unwrap IN.obj OUT.obj [--seams SEAMS.txt | --seams-from-uv] [--holes fill|cut|error]
[--boundary uniform|area|free] [--json]``: cut a mesh into islands along seams, flatten every island
conformally, pack the islands and write an OBJ with one ``vt`` per island corner (``f v/vt``). It calls
``core.unwrap`` (a mesh that is one disk without seams is flattened directly); ``--json`` prints the
summary, the islands and the ``warnings`` (also printed on stderr as ``warning: ...`` lines).

SEAMS.txt holds one seam edge per line, two vertex numbers as in the OBJ's ``f`` lines (1-based);
blank lines and text after ``#`` are ignored. Without seams, every connected piece is one island."""
import json
import sys

import numpy as np

from ..errors import ConformalError
from ..disk.flatten import BOUNDARY_MODES
from ..atlas.islands import FITS, HOLE_MODES, ISLAND_SCALES, seams_from_corner_ids
from ..atlas.unwrap import unwrap
from ..io.obj import text_lines, read_obj, write_obj, write_text
from ..mesh.triangulate import triangulate
from ..mesh.validate import DEFAULT_MAX_FACES


def add_arguments(p):
    p.add_argument('input', help='input OBJ (n-gons are triangulated for the computation and kept)')
    p.add_argument('output', help="output OBJ: the input's vertices and polygons, one vt per island corner")
    g = p.add_mutually_exclusive_group()
    g.add_argument('--seams', metavar='SEAMS.txt',
                   help='seam edges: one pair of 1-based OBJ vertex numbers per line')
    g.add_argument('--seams-from-uv', action='store_true',
                   help="use the input's own UV seams (edges where the vt indices differ across the edge)")
    p.add_argument('--boundary', choices=BOUNDARY_MODES, default='uniform',
                   help='boundary mode of every island (default: uniform)')
    p.add_argument('--holes', choices=HOLE_MODES, default='auto',
                   help='islands with holes: auto (default: fill or cut, whichever maps better), fill them '
                        'virtually, cut them open to the outer boundary, or stop with an error')
    p.add_argument('--island-scale', choices=ISLAND_SCALES, default='true',
                   help='true: one texel density on all islands (default); normalise: equal UV area each')
    p.add_argument('--fit', choices=FITS, default='unit_square',
                   help='unit_square: the packed layout scaled into [0,1]^2 (default); true_scale: mesh '
                        'units')
    p.add_argument('--no-pack', action='store_true', help='leave every island centred where it was flattened')
    p.add_argument('--margin', type=float, default=0.01, help='gap between packed islands, a fraction of '
                   'the layout size (default 0.01)')
    p.add_argument('--max-faces', type=int, default=DEFAULT_MAX_FACES,
                   help=f'size limit in triangles (default {DEFAULT_MAX_FACES:,})')
    p.add_argument('--ignore-loose', action='store_true', help='accept loose vertices and edges')
    p.add_argument('--skip-bad', action='store_true',
                   help='flatten the islands that can be flattened; the others get UV 0 and a warning')
    p.add_argument('--cones', metavar='auto|N', type=auto_or_count, default=None,
                   help='automatic seams through cone singularities (any mesh, closed ones too): "auto" '
                        'for the fewest cones reaching --target-ratio, or a cone budget N per part; '
                        'input seams are then ignored')
    p.add_argument('--target-ratio', type=float, default=0.5,
                   help='with --cones auto: the 1%%/99%% ratio of the conformal factor to reach '
                        '(default 0.5)')
    p.add_argument('--max-cones', type=int, default=48, help='with --cones auto: at most this many cones per '
                   'part (default 48)')
    p.add_argument('--seams-out', metavar='SEAMS.txt', default=None,
                   help='write the seams the tool chose (with --cones), one 1-based vertex pair per line '
                        '(default: OUTPUT with .seams.txt appended)')
    p.add_argument('--json', action='store_true', help='print the report (summary and islands) as JSON')


def auto_or_count(text):
    """'auto' or a non-negative integer."""
    if text == 'auto':
        return text
    try:
        k = int(text)
    except ValueError:
        raise ConformalError(f"--cones takes 'auto' or a number of cones, got {text!r}") from None
    if k < 0:
        raise ConformalError(f"--cones must not be negative, got {k}")
    return k


def read_seams(path, n):
    """(k,2) int64 0-based vertex pairs from a seams file (1-based numbers, ``#`` comments)."""
    pairs = []
    for lineno, line in text_lines(path):
        p = line.split('#', 1)[0].split()
        if not p:
            continue
        try:
            if len(p) != 2:
                raise ValueError("need two vertex numbers")
            a, b = int(p[0]), int(p[1])
        except ValueError as exc:
            raise ConformalError(f"{path} line {lineno}: cannot parse {line.strip()[:60]!r} ({exc}): "
                                 "write one seam per line as two 1-based vertex numbers") from None
        if not (1 <= a <= n and 1 <= b <= n):
            raise ConformalError(f"{path} line {lineno}: vertex numbers must lie in 1..{n} "
                                 f"(1-based, as in the OBJ), got {a} {b}")
        pairs.append((a - 1, b - 1))
    return np.array(pairs, np.int64).reshape(-1, 2)


def _check_polygon_edges(mesh, seams, path):
    """Seams must be edges of the input polygons (not diagonals made by the triangulation)."""
    if len(seams) == 0:
        return
    n = len(mesh.V)
    nxt = np.arange(len(mesh.corner_verts)) + 1
    ends = np.cumsum(mesh.sizes)
    nxt[ends - 1] = ends - mesh.sizes
    a, b = mesh.corner_verts, mesh.corner_verts[nxt]
    edges = np.minimum(a, b) * n + np.maximum(a, b)
    keys = seams.min(1) * n + seams.max(1)
    bad = ~np.isin(keys, edges)
    if bad.any():
        ex = ', '.join(f"{x + 1}-{y + 1}" for x, y in seams[bad][:3].tolist())
        raise ConformalError(f"{path}: {int(bad.sum())} seam(s) are not edges of the mesh's polygons, e.g. "
                             f"{ex} (1-based): list edges that bound a face")


def run(args):
    mesh = read_obj(args.input)
    tri_corners, tri_poly = triangulate(mesh.corner_verts, mesh.sizes, mesh.V)
    F = mesh.corner_verts[tri_corners]
    n = len(mesh.V)
    if args.seams:
        seams = read_seams(args.seams, n)
        _check_polygon_edges(mesh, seams, args.seams)
    elif args.seams_from_uv:
        if (mesh.corner_uvs < 0).all():
            raise ConformalError(f"{args.input} has no vt indices on its faces, so it has no UV seams: "
                                 "give --seams SEAMS.txt, or leave out --seams-from-uv")
        seams = seams_from_corner_ids(F, mesh.corner_uvs[tri_corners], n)
    else:
        seams = None
    res = unwrap(mesh.V, F, seams=seams, boundary=args.boundary, holes=args.holes,
                 island_scale=args.island_scale, pack=not args.no_pack, margin=args.margin, fit=args.fit,
                 max_faces=args.max_faces, allow_loose=args.ignore_loose,
                 on_error='skip' if args.skip_bad else 'raise', tri_poly=tri_poly,
                 edges=mesh.lines if len(mesh.lines) else None, cones=args.cones,
                 target_ratio=args.target_ratio, max_cones=args.max_cones)
    # per-corner vt: every polygon corner takes the split vertex of its triangles' corner
    corner_vt = np.full(len(mesh.corner_verts), -1, np.int64)
    corner_vt[tri_corners.ravel()] = res.F_uv.ravel()
    polys = mesh.polygons()
    uv_polys = np.split(corner_vt, np.cumsum(mesh.sizes)[:-1])
    if (mesh.sizes == 3).all():
        polys, uv_polys = np.asarray(mesh.corner_verts).reshape(-1, 3), corner_vt.reshape(-1, 3)
    write_obj(args.output, mesh.V, polys, UV=res.uv, UV_faces=uv_polys)
    r = res.report
    if args.cones is not None:
        seams_out = args.seams_out or args.output + '.seams.txt'
        write_text(seams_out, '# seam edges chosen with the cones: 1-based OBJ vertex pairs\n'
                   + ''.join(f"{a} {b}\n" for a, b in (res.seams + 1).tolist()))
        r['seams_file'] = seams_out
    if args.json:
        print(json.dumps({'summary': r, 'islands': res.islands, 'warnings': res.warnings,
                          'cones': [{'vertex': v, 'kappa': k, 'angle': 2 * np.pi - k}
                                    for v, k in res.cones]}))
    else:
        print(f"{r['islands']} island(s), {r['flattened']} flattened ({args.boundary}), holes filled "
              f"{r['holes_filled']}, cut {r['holes_cut']}: flips {r['flips']}, overlaps {r['overlaps']}, "
              f"qc_mean {r['qc_mean']:.4f} (worst island {r['qc_mean_worst']:.4f}), mu_ratio "
              f"{r['mu_ratio']:.4f} (worst island {r['mu_ratio_worst']:.4f}), {r['seconds']:.2f} s")
        if args.cones is not None:
            print(f"{r['cones']} cone(s), {r['seam_edges']} seam edges ({100 * r['seam_fraction']:.1f}% "
                  f"of the edge length, {r['feature_edges']} on feature curves): {r['seams_file']}")
    for rp in r.get('repairs', []):
        print(f"repaired: {rp['repair']} ({rp['count']}): {rp['note']}", file=sys.stderr)
    for w in res.warnings:
        print(f"warning: {w}", file=sys.stderr)
    return 0
