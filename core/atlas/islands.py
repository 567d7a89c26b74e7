"""UV islands: cut a mesh along seams, make every island a disk, flatten each one, pack them.

Pipeline of ``unwrap``:

1. Check the arrays (``check_arrays``) and repair a copy of the mesh (``core.mesh.repair``): loose,
   degenerate and duplicate elements left out, non-manifold vertices split, faces re-oriented.
2. ``cut_along_seams``: triangles joined across a non-seam interior edge belong to the same island;
   the corners around each vertex are grouped into wedges separated by seam edges, and every wedge
   becomes its own vertex. So islands never share vertices, and a seam that ends inside an island
   (a slit, such as a meridian from the equator to a pole) opens the island along it.
3. Holes: an island with several boundary loops keeps its longest loop as the outer boundary. The
   others are either filled virtually (``holes='fill'``: a cap of rings and a fan around a new centre
   vertex, flattened with the island and removed afterwards) or cut open (``holes='cut'``: a
   shortest edge path from the outer boundary to the hole becomes an extra seam).
4. Each island is flattened by ``core.flatten.flatten`` with the chosen boundary mode, and measured
   on its real faces only.
5. Scale: by default every island keeps UV area = 3D area, so one texel density holds on all of
   them (``island_scale='true'``); ``'normalise'`` gives every island the same UV area instead.
6. ``shelf_pack`` places the islands' bounding boxes in rows without overlap.

Indices: ``F`` (m,3) are the input triangles; "split vertices" are the vertices after cutting, with
``vert_of`` (N,) giving the input vertex of each. UVs are per split vertex, i.e. per corner.
"""
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra

from ..errors import ConformalError
from ..mesh.geometry import face_areas
from ..mesh.measures import (SQUASHED_QC, determinants, flip_warning, jacobians, signed_uv_areas,
                             singular_values, uv_measures)
from ..mesh import topology
from ..mesh.repair import repair, repair_merged, require_faces, zero_area_note
from ..disk.flatten import QC_WARN, SCALE_REMEDY, scale_variation
from .charts import split_overlaps
from .cutgraph import avoiding, inner_pairs
from .repeats import Repeats
from .unfold import FLAT_TREE_MAX, unfold_flat_disk
from .cut import (Cut, _seam_halfedges, boundary_crossings, cut_along_seams, seam_edge_counts,  # noqa: F401
                  seam_pairs, shelf_pack)
from ..mesh.validate import (DEFAULT_MAX_FACES, check_arrays, degenerate_faces, loose_edge_count,
                             normalise_scale)

HOLE_MODES = ('auto', 'fill', 'cut', 'error')
ISLAND_SCALES = ('true', 'normalise')
FITS = ('unit_square', 'true_scale')
ON_ERROR = ('raise', 'skip')


# ----------------------------------------------------------------------------------------------
# cutting (``cut_along_seams`` and the layout checks live in ``core.atlas.cut``)
# ----------------------------------------------------------------------------------------------


def seams_from_corner_ids(F, corner_ids, n=None):
    """Seams implied by per-corner ids such as OBJ ``vt`` indices: an interior edge is a seam when the
    two triangles beside it give either of its ends different ids. ``F`` (m,3), ``corner_ids`` (m,3)
    int (negative = no id; such corners never make a seam). Returns (k,2) int64 vertex pairs."""
    F = np.asarray(F, np.int64)
    C = np.asarray(corner_ids, np.int64).reshape(F.shape)
    n = int(F.max()) + 1 if n is None else n
    tw = topology.twin_halfedges(F, n)
    h = np.nonzero(tw >= 0)[0]
    c_start, c_end = C.ravel()[h], C.ravel()[(h // 3) * 3 + (h % 3 + 1) % 3]
    t = tw[h]
    o_start, o_end = C.ravel()[t], C.ravel()[(t // 3) * 3 + (t % 3 + 1) % 3]
    # the twin runs the other way: its end is our start
    differ = ((c_start != o_end) & (c_start >= 0) & (o_end >= 0)) | \
             ((c_end != o_start) & (c_end >= 0) & (o_start >= 0))
    E = np.sort(topology.halfedges(F)[h[differ]], axis=1)
    return np.unique(E, axis=0) if len(E) else np.zeros((0, 2), np.int64)


# ----------------------------------------------------------------------------------------------
# holes
# ----------------------------------------------------------------------------------------------
def fill_holes(V, F, loops, rings=None):
    """Close every boundary loop but the first (the outer one) with a temporary cap.

    ``V`` (n,3), ``F`` (m,3), ``loops``: list of (k,) vertex loops with the surface on their left,
    longest first. Each hole gets ``rings`` (default: about k/12, 1 to 6) shrinking copies of its
    loop and a fan around a new centre vertex (the loop's centroid). The cap is flat (in the loop's
    best-fit plane direction) when that gives a valid triangulation of the projected hole, which is
    exact for a planar hole that is star-shaped from its centroid; otherwise it is lifted into a low
    dome so that no cap triangle is degenerate. Returns ``(V2 (n2,3), F2 (m2,3), info)``: the first n
    vertices and m triangles are the input's; ``info`` is a list of dicts (loop length, added vertices
    and faces) per filled hole."""
    Vs, Fs, info = [V], [F], []
    nv = len(V)
    for loop in loops[1:]:
        k = len(loop)
        P = V[loop]
        seg = np.linalg.norm(np.roll(P, -1, 0) - P, axis=1)
        w = 0.5 * (seg + np.roll(seg, 1))
        c = (P * w[:, None]).sum(0) / max(w.sum(), np.finfo(float).tiny)
        radius = float(np.linalg.norm(P - c, axis=1).mean())
        R = int(np.clip(np.ceil(k / 12), 1, 6)) if rings is None else max(1, int(rings))
        s = 1.0 - np.arange(1, R) / R                      # ring j = 1..R-1 (ring 0 is the loop)
        # flat cap if the hole, projected on its plane, is star-shaped from the centroid
        Wt = np.linalg.svd(P - c, full_matrices=False)[2]
        nrm = Wt[-1]
        Q = (P - c) @ Wt[:2].T
        turn = Q[:, 0] * np.roll(Q[:, 1], -1) - Q[:, 1] * np.roll(Q[:, 0], -1)
        star = (np.sign(turn) == np.sign(turn.sum())).all() and \
            np.abs(turn).min() > 1e-3 * np.abs(turn).max()
        lift = 0.0 if star else 0.3 * radius
        ring_pos = c + s[:, None, None] * (P - c) + (lift * (1 - s ** 2))[:, None, None] * nrm
        centre = c + lift * nrm
        ids = [loop] + [nv + j * k + np.arange(k) for j in range(R - 1)]
        cid = nv + (R - 1) * k
        tris = []
        for j in range(R - 1):
            a, b = ids[j], ids[j + 1]
            a1, b1 = np.roll(a, -1), np.roll(b, -1)
            tris += [np.stack([a1, a, b], 1), np.stack([a1, b, b1], 1)]
        last = ids[-1]
        tris.append(np.stack([np.roll(last, -1), last, np.full(k, cid)], 1))
        Vs += [ring_pos.reshape(-1, 3), centre[None]]
        Fs += tris
        added = (R - 1) * k + 1
        info.append({'loop_vertices': int(k), 'fill_vertices': int(added),
                     'fill_faces': int(sum(len(t) for t in tris))})
        nv += added
    return np.concatenate(Vs), np.concatenate(Fs).astype(np.int64), info


def hole_cut_paths(V, F, n, loops, inner=None):
    """Edge paths that cut every hole open to the outer boundary, for ``holes='cut'``.

    Hole by hole, the shortest path (3D edge lengths, Dijkstra from the outer boundary) to the
    nearest vertex of another loop is cut, which merges that hole into the outer boundary. An edge of
    ``inner`` (k,2 vertex pairs: polygons' diagonals) costs the total length on top (a cut through a
    polygon gives its corners two UVs). ``loops``: the boundary loops of ``F``, longest (the outer)
    first (``topology.boundary_loops``). Returns a list of (k,2) int64 vertex pairs (one per hole).

    The searches run on the uncut mesh: once a hole is merged, its loop and its path join the sources
    (distance 0). A shortest path from the sources never passes through a source, so it never
    crosses an earlier cut, and its length is the one it has on the mesh cut so far."""
    paths = []
    if len(loops) <= 1:
        return paths
    E, _ = topology.unique_edges(F)
    wgt = avoiding(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1), E, inner, n)
    G = sp.coo_matrix((wgt, (E[:, 0], E[:, 1])), shape=(n, n)).tocsr()
    source = np.zeros(n, bool)
    source[loops[0]] = True
    left = list(loops[1:])
    while left:
        dist, pred, _ = dijkstra(G, directed=False, indices=np.flatnonzero(source), min_only=True,
                                 return_predecessors=True)
        holes = np.concatenate(left)
        t = int(holes[np.argmin(dist[holes])])
        if not np.isfinite(dist[t]):
            break
        path = [t]
        while pred[path[-1]] >= 0:
            path.append(int(pred[path[-1]]))
        path = np.array(path[::-1], np.int64)
        paths.append(np.stack([path[:-1], path[1:]], 1))
        source[path] = True
        hit = [bool((lp == t).any()) for lp in left]          # the hole(s) the path reached
        for lp in (lp for lp, h in zip(left, hit) if h):
            source[lp] = True
        left = [lp for lp, h in zip(left, hit) if not h]
    return paths


# ----------------------------------------------------------------------------------------------
# unwrap
# ----------------------------------------------------------------------------------------------
@dataclass
class IslandsResult:
    """``uv`` (N,2) per split vertex; ``F`` (m,3) split vertex of each corner of the input triangles;
    ``vert_of`` (N,) input vertex of each split vertex; ``face_island`` (m,) island of each triangle;
    ``ok`` (m,) False on triangles of islands skipped after an error (their UVs are 0);
    ``islands`` list of per-island report dicts; ``report`` dict summary."""
    uv: np.ndarray
    F: np.ndarray
    vert_of: np.ndarray
    face_island: np.ndarray
    ok: np.ndarray
    islands: list = field(default_factory=list)
    report: dict = field(default_factory=dict)

    @property
    def corner_uv(self):
        """(m,3,2) UV of every corner of every input triangle."""
        return self.uv[self.F]


def _describe(i, n_isl, faces, tri_poly):
    what = f"polygon {int(tri_poly[faces[0]])}" if tri_poly is not None else f"triangle {int(faces[0])}"
    return f"island {i + 1} of {n_isl} ({len(faces)} triangles, e.g. {what})"


def _filled(V, F, loops):
    """The island ``V`` (n,3), ``F`` (m,3) with every hole of ``loops`` but the outer one capped
    (``fill_holes``): (Vf, Ff, real (mf,) bool: the island's own triangles, or None without holes,
    info of the caps)."""
    if len(loops) <= 1:
        return V, F, None, []
    Vf, Ff, info = fill_holes(V, F, loops)
    real = np.zeros(len(Ff), bool)
    real[:len(F)] = True             # fill triangles come after the island's own (fill_holes)
    return Vf, Ff, real, info


def _flatten_island(V, F, loops, holes, boundary, desc, progress, options):
    """Flatten one island (local ``V`` (n,3), ``F`` (m,3), its boundary ``loops``) with holes filled
    virtually (``holes`` 'fill') or, if it has one loop, as it is. Returns (uv (n,2) in mesh units with
    UV area = 3D area, report dict with the measures, ``overlaps`` and ``warnings``)."""
    from ..disk.flatten import flatten
    n = len(V)
    rep = {'loops': len(loops)}
    chi = topology.euler_characteristic(F)
    genus = topology.genus(chi, len(loops))
    if not loops:
        # sphere mode is a remedy only for a closed part of genus 0
        raise ConformalError(f"{desc} is closed (it has no boundary)" +
                             (f" and has genus {genus}" if genus > 0 else ""), 'no_boundary',
                             'seam_handles' if genus > 0 else 'mark_seams')
    if genus > 0:
        raise ConformalError(f"{desc} has genus {genus} (Euler characteristic {chi} with {len(loops)} "
                             f"boundary loop(s))", 'genus', 'cut_handles')
    if len(loops) > 1 and holes == 'error':
        raise ConformalError(f"{desc} has {len(loops)} boundary loops (an outer boundary and "
                             f"{len(loops) - 1} hole(s))", 'holes', 'fill_holes')
    Vf, Ff, real, info = _filled(V, F, loops)
    if info:
        rep['holes'] = {'mode': 'fill', 'filled': len(info),
                        'fill_vertices': sum(h['fill_vertices'] for h in info),
                        'fill_faces': sum(h['fill_faces'] for h in info),
                        'hole_loop_vertices': [h['loop_vertices'] for h in info]}
    # the certified bound (a linear program) costs far more than the map on real islands: only on
    # request (bound=True in the options)
    res = flatten(Vf, Ff, boundary=boundary, fit='true_scale', max_faces=None, progress=progress,
                  real_faces=real, **{'bound': False, **options})
    uv = res.uv[:n]
    a_uv = signed_uv_areas(uv, F).sum()
    if not a_uv > 0:
        raise ConformalError(f"{desc}: the flattened island has no positive UV area; the mesh is "
                             "numerically degenerate", 'degenerate', 'clean_mesh')
    uv = (uv - uv.mean(0)) * np.sqrt(face_areas(V, F).sum() / a_uv)
    ok = ~degenerate_faces(V, F)
    rep.update(uv_measures(V, F[ok], uv, squash_limit=SQUASHED_QC))
    if not ok.all():
        rep['degenerate_faces'] = int((~ok).sum())
        rep['flips'] += int((signed_uv_areas(uv, F[~ok]) < 0).sum())
    rep['overlaps'] = boundary_crossings(uv, loops)
    rep.update({k: res.report[k] for k in ('bound_vertex', 'vertex_ratio', 'operators', 'fallback', 'layout')
                if k in res.report})
    rep['warnings'] = [w for w in res.report.get('warnings', [])
                       if 'flipped' not in w and 'qc_mean' not in w and 'scale variation' not in w]
    rep['seconds'] = res.report.get('seconds', {}).get('total')
    return uv, rep


def _island_warnings(rep):
    """The honest-report warnings of one island's measured report (flips, qc_mean, overlaps)."""
    w = list(rep.get('warnings', []))
    if rep.get('flips', 0):
        w.append(flip_warning(rep))
    if not rep.get('qc_mean', 1.0) <= QC_WARN:
        w.append(f"poor conformality: qc_mean {rep['qc_mean']:.3f} is above {QC_WARN}")
    if rep.get('overlaps', 0):
        w.append(f"the island overlaps itself ({rep['overlaps']} boundary crossings)")
    if not (np.isfinite(rep.get('mu_ratio', np.nan)) and rep.get('mu_ratio', 0) > 0):
        w.append("the conformal factor is not finite and positive")
    elif scale_variation(rep['mu_ratio']):
        w.append(f"{scale_variation(rep['mu_ratio'])}; {SCALE_REMEDY}")
    return list(dict.fromkeys(w))


def _squashed(rep):
    """True if the map of the report ``rep`` squashes a triangle nearly flat (s1/s2 above
    ``SQUASHED_QC``): a defect like a flip (the triangle's texture is a smear). The count
    ``squashed`` (``squashed_faces``: needles and caps of the mesh itself left out) where the report
    has it, else ``qc_max``."""
    if 'squashed' in rep:
        return rep['squashed'] > 0
    return not rep.get('qc_max', np.inf) <= SQUASHED_QC


def _score(rep):
    """Sort key of a candidate map (lower is better): no flips, no overlaps and no squashed triangle
    first, then qc_mean within the warning budget, then the larger mu_ratio."""
    mu = rep.get('mu_ratio', 0.0)
    mu = mu if np.isfinite(mu) else 0.0
    return (rep.get('flips', 1) + rep.get('overlaps', 1) > 0 or _squashed(rep),
            not rep.get('qc_mean', np.inf) <= QC_WARN, -mu)


DETACH_QC = 10.0                 # triangles this sheared in an island's best map are detached
AUTO_TRY_BOTH_FACES = 150_000    # holes='auto' flattens both ways up to this size, else decides by geometry


def _hole_geometry_prefers_cut(V, F, loops):
    """Geometric rule for holes='auto' on big islands: cut when the holes are large for the island
    (a tube's open end, not a small cap): total hole perimeter squared above the island's area."""
    A = float(face_areas(V, F).sum())
    per = sum(float(np.linalg.norm(V[np.roll(lp, -1)] - V[lp], axis=1).sum()) for lp in loops[1:])
    return per * per > A


def _cut_island(V, F, loops, inner=None):
    """Cut every hole of the island (``V`` (n,3), ``F`` (m,3)) open to the outer boundary, off the
    polygons' diagonals ``inner`` (k,2) where it can. Returns (Fc (m,3) ids of the cut vertices, vert_of
    (N,) local vertex of each cut vertex, loops, info)."""
    n = len(V)
    paths = hole_cut_paths(V, F, n, loops, inner)
    pairs = np.concatenate(paths) if paths else np.zeros((0, 2), np.int64)
    c = cut_along_seams(F, n, pairs)
    if c.n_islands != 1:                    # a cut path cannot disconnect a connected island
        raise ConformalError("cutting the holes split the island", 'bad_topology')
    info = {'mode': 'cut', 'cut': len(paths), 'cut_edges': int(len(pairs))}
    return c.F, c.vert_of, topology.boundary_loops(c.F, len(c.vert_of)), info


def _flat_island(n_faces, boundary, options):
    """The report ``_flatten_island`` would give an island of ``n_faces`` triangles that
    ``unfold.unfold_flat_disk`` laid out: the measures of an isometry (the conformal map of every
    boundary mode; ``uv_measures`` gives them to round-off, at a millisecond an island), and a
    certified bound of 1 (no interior vertex). Hair cards and triangle soups are thousands of such
    islands."""
    rep = {'loops': 1, 'faces': int(n_faces), 'flips': 0, 'mu_ratio': 1.0, 'mu_ratio_p1_p99': 1.0,
           'qc_mean': 1.0, 'qc_max': 1.0, 'squashed': 0, 'overlaps': 0, 'vertex_ratio': 1.0,
           'operators': {'mode': 'auto', 'intrinsic': False}, 'seconds': 0.0, 'boundary_used': boundary}
    if options.get('bound'):
        rep['bound_vertex'] = 1.0
    rep['warnings'] = _island_warnings(rep)
    return rep


def _solve_island(V, F, holes, boundary, desc, progress, options, depth=0, poly=None):
    """Flatten one connected island (local ``V`` (n,3), ``F`` (m,3)), choosing how to treat its holes
    and repairing overlaps. Returns a list of pieces ``(faces (k,) rows of F, Fp (k,3) piece vertex ids,
    pv (N,) local vertex of each piece vertex, uv (N,2), report)``: one piece, or several when an
    overlapping island had to be split. ``poly`` (m,) optional polygon of each triangle: a polygon is
    never split between pieces (an OBJ polygon has one UV per corner)."""
    n = len(V)
    poly = np.arange(len(F)) if poly is None else np.asarray(poly)
    loops = topology.boundary_loops(F, n)
    everything = np.arange(len(F))
    ident = np.arange(n)
    cands = []
    modes = []
    if len(loops) <= 1 or holes in ('fill', 'error'):
        modes = ['fill']
    elif holes == 'cut':
        modes = ['cut']
    elif len(F) <= AUTO_TRY_BOTH_FACES:
        modes = ['fill', 'cut']
    else:
        modes = ['cut' if _hole_geometry_prefers_cut(V, F, loops) else 'fill']
    first_error = None
    inputs = {}                      # id(report) -> the (V, F, loops) that candidate flattened

    def attempt(mode, bnd, retry=False):
        """Flatten in hole ``mode`` with boundary ``bnd``. A ``retry`` makes no certified bound (a
        linear program): it is made once, for the map kept, if that is a retry's."""
        nonlocal first_error
        opts = {**options, 'bound': False} if retry else options
        try:
            if mode == 'fill':
                uv, rep = _flatten_island(V, F, loops, 'fill' if holes == 'cut' else holes, bnd, desc,
                                          progress, opts)
                cand = (everything, F, ident, uv, rep)
                inputs[id(rep)] = (V, F, loops)
            else:
                Fc, vo, lc, info = _cut_island(V, F, loops, inner_pairs(F, n, poly))
                uv, rep = _flatten_island(V[vo], Fc, lc, holes, bnd, desc, progress, opts)
                rep['holes'] = info
                rep['loops_before_cut'] = len(loops)
                cand = (everything, Fc, vo, uv, rep)
                inputs[id(rep)] = (V[vo], Fc, lc)
            rep['boundary_used'] = bnd
            cands.append(cand)
        except ConformalError as exc:
            if exc.code in ('no_boundary', 'genus', 'holes', 'invalid_input', 'too_large'):
                raise
            first_error = first_error or exc

    def clean():
        return any(c[4]['flips'] + c[4]['overlaps'] == 0 and not _squashed(c[4]) for c in cands)

    for mode in modes:
        attempt(mode, boundary)
    if not clean() and len(modes) == 1 and len(loops) > 1 and holes != 'error':
        # the requested hole mode overlaps or folds: try the other one too and keep the better
        attempt('fill' if modes[0] == 'cut' else 'cut', boundary, retry=True)
    if not clean() and boundary == 'uniform':
        # the optimiser watches flips, not overlaps: the area map (u_B = 0) may be one-to-one. Not in
        # a hole mode whose uniform map already is the area map (the optimiser fell back to it
        # because it folds): the same map again
        for mode in dict.fromkeys(c[4].get('holes', {}).get('mode', 'fill') for c in cands
                                  if c[4].get('fallback') != 'area') or ([] if cands else ['fill']):
            attempt(mode, 'area', retry=True)
    if not cands:
        raise first_error
    cands.sort(key=lambda c: _score(c[4]))
    best = cands[0]
    rep = best[4]
    if options.get('bound') and 'bound_vertex' not in rep:
        # the kept map is a retry's: its certificate now (the same system, so the same value)
        from ..disk.flatten import certified_bound
        Vb, Fb, lb = inputs[id(rep)]
        Vf, Ff, real, _ = _filled(Vb, Fb, lb)
        rep['bound_vertex'], _ = certified_bound(Vf, Ff, rep['operators']['mode'], real)
    if best[4]['boundary_used'] != boundary:
        rep['fallback_boundary'] = (f"the {boundary} map overlapped or folded in every hole mode; the "
                                    f"{rep['boundary_used']} map is used")
    if len(cands) > 1 and 'holes' in rep:
        rep['holes']['auto'] = {f"{c[4].get('holes', {}).get('mode', 'none')}/{c[4]['boundary_used']}":
                                {k: c[4][k] for k in ('mu_ratio', 'qc_mean', 'flips', 'overlaps')}
                                for c in cands}
    if (rep['flips'] + rep['overlaps'] == 0 and not _squashed(rep)) or len(F) < 4:
        rep['warnings'] = _island_warnings(rep)
        return [best]
    if rep['overlaps'] and not rep['flips']:
        # a map that overlaps itself without folding (a ramp of more than a turn): its own charts,
        # split along shortest interior paths and glued back where they do not overlap, keep the map
        pieces = _chart_pieces(V, best, poly)
        if pieces is not None:
            note = (f"the map overlapped itself ({rep['overlaps']} boundary crossing(s)): split into "
                    f"{len(pieces)} charts along shortest paths")
            for p in pieces:
                p[4]['split_from_overlap'] = note
                p[4]['warnings'] = _island_warnings(p[4])
            return pieces
    if (rep['flips'] or rep['overlaps'] or not rep['qc_mean'] <= QC_WARN) and depth < 4:
        # triangles that fold or collapse in every mode (a fold of the surface itself), and the
        # triangles on boundary edges that cross (e.g. at a pinch where two holes touch): detach them
        # as islands of their own (laid out isometrically) and flatten the rest again
        J, _ = jacobians(V[best[2]], best[1], best[3])
        sv = singular_values(J)
        folded = (determinants(J) <= 0) | (sv[:, 0] > DETACH_QC * np.maximum(sv[:, 1], np.finfo(float).tiny))
        folded &= ~degenerate_faces(V[best[2]], best[1])
        if rep['overlaps']:
            loops_b = topology.boundary_loops(best[1], len(best[2]))
            _, seg = boundary_crossings(best[3], loops_b, return_segments=True)
            H = topology.halfedges(best[1])
            hk = H[:, 0] * len(best[2]) + H[:, 1]
            folded[np.isin(hk, seg[:, 0] * len(best[2]) + seg[:, 1]).reshape(-1, 3).any(1)] = True
        folded = np.isin(poly, poly[folded])                   # whole polygons
        if folded.any() and folded.sum() <= 0.05 * len(F) + 4:
            try:
                pieces = _detach(V, F, np.nonzero(folded)[0], holes, boundary, desc, progress, options, depth,
                                 poly)
            except ConformalError:
                pieces = []
            bad_after = sum(p[4]['flips'] + p[4]['overlaps'] for p in pieces)
            if pieces and (bad_after < rep['flips'] + rep['overlaps'] or
                           (bad_after == 0 and max(_score(p[4]) for p in pieces) < _score(rep))):
                note = (f"{int(folded.sum())} folded or overlapping triangle(s) detached as islands of "
                        "their own")
                for p in pieces:
                    p[4].setdefault('split_from_overlap', note)
                return pieces
    if depth >= 3 or len(F) < 8:
        rep['warnings'] = _island_warnings(rep)
        return [best]
    # overlap (or folds) in every mode: split the island in two across its longest 3D axis and
    # flatten the halves; report the repair
    C = V[F].mean(axis=1)
    axis = np.linalg.svd(C - C.mean(0), full_matrices=False)[2][0]
    side = (C - C.mean(0)) @ axis > np.median((C - C.mean(0)) @ axis)
    _, first, inv = np.unique(poly, return_index=True, return_inverse=True)
    side = side[first][inv.ravel()]                          # whole polygons on one side
    pieces = []
    try:
        for half in (np.nonzero(~side)[0], np.nonzero(side)[0]):
            Fh = F[half]
            ncomp, lab = topology.face_components(Fh, n)
            for k in range(ncomp):
                pieces += _solve_part(V, F, half[lab == k], holes, boundary, desc, progress, options, depth,
                                      poly)
    except ConformalError:
        pieces = []
    if pieces and all(p[4]['flips'] + p[4]['overlaps'] <= rep['flips'] + rep['overlaps'] for p in pieces):
        note = (f"split into {len(pieces)} islands to remove {rep['overlaps']} overlap(s) and "
                f"{rep['flips']} flip(s)")
        for p in pieces:
            p[4]['split_from_overlap'] = note
        return pieces
    rep['warnings'] = _island_warnings(rep)
    return [best]


def _chart_pieces(V, cand, poly):
    """The candidate map ``cand`` (faces, Fc, vert_of, uv, report; ``_solve_island``) of the island
    with local positions ``V`` split into charts that do not overlap (``core.atlas.cones.
    split_overlaps``: cuts along shortest interior paths between the arcs that cross, then glued back
    where the union does not overlap), each keeping its coordinates (the same conformal map), or None
    if crossings remain, a chart folds, or a polygon of ``poly`` (m,) would be split between charts.
    Returns a list of pieces as ``_solve_island``."""
    faces, Fc, vo, uv, _ = cand
    none = np.zeros((0, 2), np.int64)
    cut = cut_along_seams(Fc, len(vo), none)
    uvc = np.zeros((len(cut.vert_of), 2))
    uvc[cut.F.ravel()] = uv[Fc.ravel()]
    cut, uvc, _, left, _ = split_overlaps(V[vo], Fc, cut, uvc, none)
    if left or cut.n_islands < 2:
        return None
    pp = poly[faces]
    if (np.bincount(np.unique(np.c_[pp, cut.face_island], axis=0)[:, 0]) > 1).any():
        return None
    pieces = []
    for i in range(cut.n_islands):
        fi = np.flatnonzero(cut.face_island == i)
        used, Fp = np.unique(cut.F[fi], return_inverse=True)
        Fp = Fp.reshape(-1, 3)
        uvp = uvc[used] - uvc[used].mean(0)
        pv = vo[cut.vert_of[used]]
        ok = ~degenerate_faces(V[pv], Fp)
        r = {'loops': 1, **uv_measures(V[pv], Fp[ok], uvp),
             'overlaps': boundary_crossings(uvp, topology.boundary_loops(Fp, len(pv))), 'warnings': []}
        r['flips'] += int((signed_uv_areas(uvp, Fp[~ok]) < 0).sum())
        if r['flips'] or r['overlaps']:
            return None
        pieces.append((faces[fi], Fp, pv, uvp, r))
    return pieces


def _single_triangle(V, tri):
    """A piece for one triangle (3,) of ``V``: laid out isometrically (its own plane), with its report."""
    P = V[tri]
    e1, e2 = P[1] - P[0], P[2] - P[0]
    x = e1 / max(np.linalg.norm(e1), np.finfo(float).tiny)
    nrm = np.cross(e1, e2)
    y = np.cross(nrm / max(np.linalg.norm(nrm), np.finfo(float).tiny), x)
    uv = np.array([[0.0, 0.0], [e1 @ x, 0.0], [e2 @ x, e2 @ y]])
    rep = {'loops': 1, **uv_measures(P, np.array([[0, 1, 2]]), uv), 'overlaps': 0, 'warnings': []}
    return np.array([[0, 1, 2]]), uv, rep


def _solve_part(V, F, sel, holes, boundary, desc, progress, options, depth, poly):
    """Pieces of the sub-island ``F[sel]`` (repaired first: removing triangles can pinch vertices)."""
    used, Fl = np.unique(F[sel], return_inverse=True)
    R = repair(V[used], Fl.reshape(-1, 3))
    out = []
    ncomp, lab = topology.face_components(R.F, len(R.V))
    for k in range(ncomp):
        sub = np.nonzero(lab == k)[0]
        u2, F2 = np.unique(R.F[sub], return_inverse=True)
        for faces, Fp, pv, uv, r in _solve_island(R.V[u2], F2.reshape(-1, 3), holes, boundary, desc,
                                                  progress, options, depth + 1, poly[sel][R.face_map[sub]]):
            out.append((sel[R.face_map[sub[faces]]], Fp, used[R.vert_map[u2[pv]]], uv, r))
    return out


def _detach(V, F, bad, holes, boundary, desc, progress, options, depth, poly):
    """Pieces of the island ``F`` (m,3) with the polygons of the triangles ``bad`` (k,) each made an
    island of its own and the rest (its edge-connected parts) flattened again with ``_solve_island``."""
    pieces = []
    rest = np.setdiff1d(np.arange(len(F)), bad)
    ncomp, lab = topology.face_components(F[rest], len(V))
    for k in range(ncomp):
        pieces += _solve_part(V, F, rest[lab == k], holes, boundary, desc, progress, options, depth, poly)
    for p in np.unique(poly[bad]).tolist():
        faces = bad[poly[bad] == p]
        if len(faces) == 1:
            Fp, uv, r = _single_triangle(V, F[faces[0]])
            pieces.append((faces, Fp, F[faces[0]].copy(), uv, r))
        else:
            pieces += _solve_part(V, F, faces, holes, boundary, desc, progress, options, 4, poly)
    return pieces


def _merged_corners(F, Fout, rows, uv, vert_of, vert_island):
    """Give the corners of the kept input triangles ``rows`` (``F`` (m,3) input vertices, ``Fout`` (m,3)
    split vertices) that sit at a vertex merged into another (``repair_merged``) split vertices of
    their own, at their root's UV in the same island, so that ``vert_of[Fout] == F``. Returns the
    extended ``uv`` (N',2), ``vert_of`` (N',) and ``vert_island`` (N',); ``Fout`` is updated in place."""
    C = Fout[rows]
    want = F[rows]
    off = vert_of[C] != want
    if not off.any():
        return uv, vert_of, vert_island
    pairs, inv = np.unique(np.stack([C[off], want[off]], 1), axis=0, return_inverse=True)
    C[off] = len(vert_of) + inv.ravel()
    Fout[rows] = C
    return _split_copies(pairs, uv, vert_of, vert_island)


def _split_copies(pairs, uv, vert_of, vert_island):
    """``uv`` (N,2), ``vert_of`` (N,) and ``vert_island`` (N,) extended by one new split vertex per row
    of ``pairs`` (k,2) (numbered ``N + row``): the split vertex ``pairs[:, 0]`` whose UV and island it
    takes (zeros without any split vertex yet), and the input vertex ``pairs[:, 1]`` it stands for."""
    src = pairs[:, 0]
    return (np.vstack([uv, uv[src] if len(uv) else np.zeros((len(pairs), 2))]), np.r_[vert_of, pairs[:, 1]],
            np.r_[vert_island, vert_island[src] if len(vert_island) else np.zeros(len(pairs), np.int64)])


def _lowest_split_vertex(res_vert_of, n_in):
    """(n_in,) the lowest split vertex of every input vertex (-1 if it has none). The corners of a
    dropped face with a repeated vertex take these; a dropped duplicate takes its kept twin's."""
    first = np.full(n_in, -1, np.int64)
    ids = np.arange(len(res_vert_of))[::-1]
    first[res_vert_of[ids]] = ids                      # lowest split vertex of every input vertex
    return first


def _one_island_ids(D, vert_of, vert_island, first):
    """(k,3) split vertices for the corners of dropped faces ``D`` (k,3) (input vertex ids): each
    corner's copy in one island where the vertex has a copy there, else its lowest copy (``first``
    (n,), ``_lowest_split_vertex``). The island is the one, among those of the corners' lowest copies,
    that holds copies of the most corners. So a dropped face on a seam stays a point or a segment
    inside one island, instead of a segment from one island to another across the layout."""
    ids = first[D]
    if not len(D) or not (ids >= 0).any():
        return ids
    n_isl = int(vert_island.max()) + 1
    key = vert_of * n_isl + vert_island
    order = np.argsort(key, kind='stable')
    skey = key[order]
    best, best_found = ids, np.full(len(D), -1)
    for c in range(3):
        ok = ids[:, c] >= 0
        q = D * n_isl + vert_island[np.maximum(ids[:, c], 0)][:, None]
        pos = np.minimum(np.searchsorted(skey, q), len(skey) - 1)
        found = (skey[pos] == q) & ok[:, None]
        nf = found.sum(1)
        better = nf > best_found
        best = np.where(better[:, None], np.where(found, order[pos], ids), best)
        best_found = np.where(better, nf, best_found)
    return best


def unwrap(V, F, seams=None, boundary='uniform', holes='auto', island_scale='true', pack=True,
           margin=0.01, fit='unit_square', max_faces=DEFAULT_MAX_FACES, allow_loose=True, edges=None,
           on_error='raise', tri_poly=None, strict_seams=True, progress=None, **options) -> 'IslandsResult':
    """Cut a triangle mesh into islands along ``seams`` and flatten every island conformally.

    V: (n,3) float positions. F: (m,3) int triangles, counter-clockwise. seams: (k,2) int vertex pairs
    (edges marked as seams) or None; connected pieces are islands even without seams.
    boundary: 'uniform', 'area' or 'free' (``core.disk.flatten``). holes: 'auto' (default: per island,
    fill the holes or cut them open to the outer boundary, whichever gives the better realised map),
    'fill' (virtual fill), 'cut' or 'error'. island_scale: 'true' (UV area = 3D area on every island:
    one texel density) or 'normalise' (every island gets the same UV area).
    pack: shelf-pack the islands without overlap, ``margin`` a fraction of the layout size.
    fit: 'unit_square' (scale the whole layout uniformly into [0,1]^2) or 'true_scale' (mesh units).
    max_faces: size limit (None: none). allow_loose: kept for compatibility; loose vertices and loose
    ``edges`` are always ignored and listed in ``report['repairs']``.
    Messy input is repaired internally (``core.mesh.repair``): degenerate and duplicate faces dropped,
    non-manifold vertices split, islands split along non-manifold edges, faces re-oriented per part;
    the input arrays are never modified. An island whose map overlaps itself is split and re-flattened.
    on_error: 'raise' stops at the first island that cannot be flattened; 'skip' leaves its UVs at 0,
    marks it in ``ok`` and reports the error.
    tri_poly: optional (m,) polygon of each triangle, used to name polygons in messages.
    strict_seams: a seam that is not an edge of ``F`` is an error; False ignores it (useful when ``F``
    is a selection of a bigger mesh and ``seams`` are all of its seams).
    progress: optional callable ``progress(fraction, message)``. Extra ``options`` go to ``flatten``.
    Returns ``IslandsResult``: every island report and the summary carry ``warnings`` (list of str) when
    a result has flips, overlaps or qc_mean above 1.5. Raises ``ConformalError`` for bad input."""
    for name, value, allowed in (('holes', holes, HOLE_MODES), ('island_scale', island_scale, ISLAND_SCALES),
                                 ('fit', fit, FITS), ('on_error', on_error, ON_ERROR)):
        if value not in allowed:
            raise ConformalError(f"unknown {name} {value!r}: use one of {', '.join(allowed)}")
    if not (np.isfinite(margin) and 0 <= margin < 0.5):
        raise ConformalError(f"margin must be a fraction in [0, 0.5), got {margin}")
    report_progress = progress or (lambda f, msg: None)
    t0 = time.perf_counter()
    V, F = check_arrays(V, F, max_faces=max_faces)
    n, m = len(V), len(F)
    if tri_poly is not None:
        tri_poly = np.asarray(tri_poly, np.int64)
        if tri_poly.shape != (m,):
            raise ConformalError(f"tri_poly must have one polygon index per triangle ({m}), got shape "
                                 f"{tri_poly.shape}")
    seams = seam_pairs(seams, n)
    if strict_seams:
        _seam_halfedges(F, n, seams, True)             # a seam that is no edge of F is an error
    # work in O(1) units whatever the mesh's (no under- or overflow); UVs are scaled back at the end
    V, unit = normalise_scale(V)
    R, root = repair_merged(V, F)
    repairs = list(R.repairs)
    if edges is not None:
        loose_e = loose_edge_count(edges, F)
        if loose_e:
            repairs.append({'repair': 'loose_edges_ignored', 'count': loose_e, 'note': 'edges in no face'})
    require_faces(R)
    zero = degenerate_faces(R.V, R.F)
    if zero.any():
        repairs.append(zero_area_note(int(zero.sum())))
    # seams on the repaired vertices: every repaired edge whose input vertices form a seam
    n2 = len(R.V)
    if len(seams):
        H2 = topology.halfedges(R.F)
        a, b = R.vert_map[H2[:, 0]], R.vert_map[H2[:, 1]]
        hk = np.minimum(a, b) * n + np.maximum(a, b)
        sr = seams if root is None else root[seams]      # a seam at a merged vertex: at its root
        sk = np.minimum(sr[:, 0], sr[:, 1]) * n + np.maximum(sr[:, 0], sr[:, 1])
        seams2 = np.unique(np.sort(H2[np.isin(hk, sk)], axis=1), axis=0)
    else:
        seams2 = np.zeros((0, 2), np.int64)
    report_progress(0.02, 'cutting along seams')
    cut = cut_along_seams(R.F, n2, seams2, strict=False)
    island_faces = cut.island_faces()
    n_cut = cut.n_islands
    seam_count = seam_edge_counts(R.F, seams2, n2, n_cut, cut.face_island)
    weights = np.cumsum([0] + [len(f) for f in island_faces]) / max(1, len(R.F))
    tri_of = R.face_map                                  # input face of each repaired face
    pieces = []                                          # (faces of R.F, Fp, vert_of (input), uv, rep)
    repeats = Repeats()                                  # islands of the same shape are solved once
    vert_start = cut.vert_start
    for i, faces in enumerate(island_faces):
        lo, hi = vert_start[i], vert_start[i + 1]
        Fi = cut.F[faces] - lo
        Vi = R.V[cut.vert_of[lo:hi]]
        desc = _describe(i, n_cut, tri_of[faces], tri_poly)
        base, span = 0.05 + 0.85 * weights[i], 0.85 * (weights[i + 1] - weights[i])

        def sub(f, msg, base=base, span=span, i=i):
            report_progress(base + span * f, f"island {i + 1}/{n_cut}: {msg}")

        poly_i = None if tri_poly is None else tri_poly[tri_of[faces]]
        try:
            flat = None if len(Fi) > FLAT_TREE_MAX or zero[faces].any() else unfold_flat_disk(Vi, Fi)
            if flat is not None:
                # no interior vertex (a card, a soup's triangle): unfolded as it is, no repeat search
                rep_i = _flat_island(len(Fi), boundary, options)
                got = [(np.arange(len(Fi)), Fi, np.arange(len(Vi)), flat, rep_i)]
            elif (same := repeats.find(Vi, Fi, poly_i)) is None:
                got = _solve_island(Vi, Fi, holes, boundary, desc, sub, options, poly=poly_i)
                repeats.add(Vi, Fi, poly_i, desc, got)
            else:
                got = same[1]
                for r in (g[4] for g in got):
                    r['repeat_of'], r['seconds'] = same[0], 0.0
            for fl, Fp, pv, ui, r in got:
                pieces.append((faces[fl], Fp, R.vert_map[cut.vert_of[lo + pv]], ui, r, desc))
        except ConformalError as exc:
            if exc.code == 'no_boundary' and seam_count[i]:
                # seams were marked on it, but none opens it (single edges, or edges apart)
                exc = ConformalError(f"{exc.problem}: the {seam_count[i]} seam edge(s) marked on it do not "
                                     "cut it open (a seam opens a closed surface only along a path of two "
                                     "edges or more)", exc.code, exc.remedy)
            if not exc.problem.startswith('island '):
                exc = exc.with_context(desc)
            if on_error == 'raise' or n_cut == 1:
                raise exc from None
            rep = {'error': str(exc), 'error_code': exc.code, 'error_remedy': exc.remedy,
                   'error_problem': exc.problem}
            used, Fl = np.unique(Fi, return_inverse=True)
            pieces.append((faces, Fl.reshape(-1, 3), R.vert_map[cut.vert_of[lo + used]],
                           np.zeros((len(used), 2)), rep, desc))
    n_isl = len(pieces)
    areas_in = face_areas(V, F)
    uv_parts, vo_parts, reports, boxes = [], [], [], []
    Fout = np.zeros((m, 3), np.int64)
    face_island = np.zeros(m, np.int64)
    ok = np.ones(m, bool)
    start = 0
    for i, (faces, Fp, vo, ui, rep, _desc) in enumerate(pieces):
        rep = {'island': i + 1, 'triangles': len(faces), 'vertices': int(len(vo)), **rep}
        rows = tri_of[faces]
        Fg = Fp + start
        flipped = R.flipped[faces]
        Fg = np.where(flipped[:, None], Fg[:, [0, 2, 1]], Fg)        # back to the input's corner order
        Fout[rows] = Fg
        face_island[rows] = i
        rep['area_3d'] = float(areas_in[rows].sum())
        if 'error' in rep:
            ok[rows] = False
        else:
            if island_scale == 'normalise':
                ui = ui * np.sqrt(areas_in.sum() / n_isl / max(rep['area_3d'], 1e-300))
            lo_uv, hi_uv = ui.min(0), ui.max(0)
            if hi_uv[1] - lo_uv[1] > hi_uv[0] - lo_uv[0]:      # lie wide: rotate by 90 degrees
                ui = np.stack([ui[:, 1], -ui[:, 0]], 1)
            ui = ui - ui.min(0)
        uv_parts.append(ui)
        vo_parts.append(vo)
        reports.append(rep)
        boxes.append(ui.max(0) if 'error' not in rep else np.zeros(2))
        start += len(vo)
    uv = np.concatenate(uv_parts)
    vert_of = np.concatenate(vo_parts)
    vert_island = np.repeat(np.arange(n_isl), [len(v) for v in vo_parts])
    if root is not None:
        uv, vert_of, vert_island = _merged_corners(F, Fout, tri_of, uv, vert_of, vert_island)
    # the dropped input faces share the split vertices of their kept twins, or of their vertices
    if len(R.dropped):
        first = _lowest_split_vertex(vert_of, n)
        D = F[R.dropped]
        ids = _one_island_ids(D, vert_of, vert_island, first)
        tw = R.twin_of_dropped
        has = tw >= 0
        if has.any():
            T = Fout[tw[has]]                                       # split ids of the twin's corners
            Tv = F[tw[has]]
            match = D[has][:, :, None] == Tv[:, None, :]            # (k,3,3)
            ids[has] = np.take_along_axis(T, match.argmax(axis=2), axis=1)
        bad = (ids < 0).any(axis=1)
        if bad.any():
            # a vertex in dropped faces only (collapsed onto a merged point): a split vertex of its own,
            # at the UV of another corner of the face (a point or a segment in UV), not flattened
            miss = ids < 0
            ref = np.where(miss.all(axis=1), 0, np.argmin(miss, axis=1))
            src = ids[np.arange(len(ids)), ref]
            r, c = np.nonzero(miss)
            pairs, inv = np.unique(np.stack([np.maximum(src[r], 0), D[r, c]], 1), axis=0,
                                   return_inverse=True)
            ids[r, c] = len(vert_of) + inv.ravel()
            uv, vert_of, vert_island = _split_copies(pairs, uv, vert_of, vert_island)
        Fout[R.dropped] = ids
        face_island[R.dropped] = vert_island[ids[:, 0]]
        ok[R.dropped] = ~bad
    failed = [i for i, r in enumerate(reports) if 'error' in r]
    if len(failed) == n_isl:
        first_r = reports[0]
        raise ConformalError(f"no island could be flattened; the first error: {first_r['error_problem']}",
                             first_r['error_code'], first_r['error_remedy'])
    report_progress(0.92, 'packing islands')
    boxes = np.array(boxes)
    good = np.array(['error' not in r for r in reports])
    size = np.sqrt((boxes[good, 0] * boxes[good, 1]).sum())
    layout = (float(boxes[:, 0].max()), float(boxes[:, 1].max()))
    if pack:
        gap = margin * size / max(1e-12, 1 - 2 * margin)
        off, layout = shelf_pack(boxes[good], gap)
        shift = np.zeros((n_isl, 2))
        shift[np.nonzero(good)[0]] = off
        uv += shift[vert_island]
    if fit == 'unit_square':
        uv /= max(layout) if max(layout) > 0 else 1.0
    else:
        uv *= unit
    for r in reports:
        r['area_3d'] *= unit * unit
    uv[~good[vert_island]] = 0.0
    rep_ok = [r for r in reports if 'error' not in r]
    split_notes = sorted({r['split_from_overlap'] for r in rep_ok if 'split_from_overlap' in r})
    if split_notes:
        repairs.append({'repair': 'islands_split_for_overlap', 'count': len(split_notes),
                        'note': '; '.join(split_notes)})
    fallbacks = [r for r in rep_ok if 'fallback_boundary' in r]
    if fallbacks:
        repairs.append({'repair': 'boundary_fallback', 'count': len(fallbacks),
                        'note': f"islands whose {boundary} map overlapped or folded use the area map"})
    warnings = []
    for r in reports:
        for w in r.get('warnings', []):
            warnings.append(f"island {r['island']}: {w}")
        if 'error' in r:
            warnings.append(f"skipped: {r['error']}")
    summary = {
        'islands': n_isl, 'flattened': len(rep_ok), 'failed': len(failed), 'boundary': boundary,
        'holes': holes, 'island_scale': island_scale, 'packed': bool(pack), 'fit': fit,
        'triangles': m, 'vertices': n, 'split_vertices': int(len(vert_of)),
        'seams': int(len(seams)),
        'holes_filled': int(sum(r.get('holes', {}).get('filled', 0) for r in rep_ok
                                if r.get('holes', {}).get('mode') == 'fill')),
        'holes_cut': int(sum(r.get('holes', {}).get('cut', 0) for r in rep_ok)),
        'repeated_islands': int(sum('repeat_of' in r for r in rep_ok)),
        'flips': int(sum(r['flips'] for r in rep_ok)),
        'overlaps': int(sum(r['overlaps'] for r in rep_ok)),
        'qc_mean_worst': float(max(r['qc_mean'] for r in rep_ok)),
        'mu_ratio_worst': float(min(r['mu_ratio'] for r in rep_ok)),
        'pack_efficiency': float((boxes[good, 0] * boxes[good, 1]).sum() / max(1e-300, layout[0] * layout[1]))
        if pack else None,
        'repairs': repairs,
        'warnings': warnings,
        'seconds': round(time.perf_counter() - t0, 4),
    }
    report_progress(1.0, 'done')
    return IslandsResult(uv=uv, F=Fout, vert_of=vert_of, face_island=face_island, ok=ok,
                        islands=reports, report=summary)
