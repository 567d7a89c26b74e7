"""``core.unwrap``: the single entry for UV work (a disk, islands cut along seams, holes, a face
selection). Front ends (the Blender add-on, ``python -m core unwrap``) call it and never look at the
topology themselves.

What it does:

1. Selection: with ``faces`` ((m,) bool) only those triangles are unwrapped; they are taken out as a
   sub-mesh (vertices renumbered, seams restricted to it) and the results are put back in the input's
   numbering. The input arrays are never modified.
2. Dispatch: a clean sub-mesh that is one disk (one piece, one boundary loop, Euler characteristic 1)
   without seams is flattened directly by the disk primitive ``core.disk.flatten.flatten`` with the
   requested fit (no packing: there is nothing to pack). Everything else (seams, several pieces,
   holes, closed parts, messy input) goes through the island pipeline
   ``core.atlas.islands.unwrap``, which repairs what it can and says what is wrong otherwise.
   With ``cones`` set, every connected part gets automatic seams instead: cone singularities placed
   for the L-inf objective and a cut through them (``core.atlas.cones.cone_unwrap``), one island per
   part, packed like the others. This is how closed meshes of any genus unwrap in one call.
3. Measures: the final layout is measured on the flattened triangles only (docs/math.md section 3):
   flips, mu ratio, qc; the per-triangle conformal factor ``mu`` and the per-vertex one
   (``core.mesh.measures.vertex_mu``, the area-weighted geometric mean) come with the result.
4. Warnings: every island with flips, boundary overlaps, qc_mean above ``QC_WARN``, a mu_ratio below
   ``MU_WARN`` (texel density varying more than 10^4-fold), an optimiser that did not converge, a
   failed certificate, or that failed and was skipped, gives one line in
   ``warnings``. A result with warnings is not a plain success.

Units: UVs are in mesh units for ``fit='true_scale'`` (UV area = 3D area), in [0,1]^2 for
``fit='unit_square'``; ``mu`` is dimensionless (total UV area normalised to the 3D area).
"""
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
import time

import numpy as np

from ..blas import one_thread
from ..errors import ConformalError
from ..disk.flatten import QC_WARN, SCALE_REMEDY, flatten, scale_variation
from ..mesh import topology
from ..mesh.geometry import face_areas
from ..mesh.repair import repair_merged, require_faces, zero_area_note
from ..mesh.measures import flip_warning, jacobians, measures_from_jacobians, signed_uv_areas, vertex_mu
from ..mesh.validate import (DEFAULT_MAX_FACES, as_arrays, check_mesh, degenerate_faces, loose_edge_count,
                             normalise_scale)
from .islands import boundary_crossings, seam_pairs, shelf_pack
from .islands import unwrap as unwrap_islands
from .cutgraph import polygon_sides
from .repeats import Repeats

MEASURE_KEYS = ('faces', 'flips', 'mu_ratio', 'mu_ratio_p1_p99', 'qc_mean', 'qc_max')


@dataclass
class UnwrapResult:
    """The result of ``unwrap`` for input triangles ``F`` (m,3) with ``n`` vertices.

    - ``uv_corner`` (m,3,2) float64: UV of every corner of every input triangle; NaN on triangles that
      were not unwrapped (outside ``faces``, or in an island skipped with ``on_error='skip'``).
    - ``flattened`` (m,) bool: triangles that got UVs.
    - ``face_island`` (m,) int64: island of each triangle (0-based, as in ``islands``); -1 outside
      ``faces``.
    - ``mu`` (m,) float64: realised conformal factor per triangle, NaN where not flattened.
    - ``mu_vertex`` (n,) float64: per-vertex conformal factor (``vertex_mu``), NaN on vertices of no
      flattened triangle.
    - ``uv`` (N,2) and ``F_uv`` (m,3) int64: the same layout with shared UV vertices (one per island
      corner, like OBJ ``vt``); ``F_uv`` is -1 outside ``faces``. ``uv[F_uv]`` equals ``uv_corner``
      where flattened.
    - ``islands``: list of per-island report dicts (``island`` 1-based, ``triangles``, measures,
      ``warnings``; failed ones carry ``error``, ``error_problem``, ``error_code``, ``error_remedy``).
    - ``report``: summary dict (measures of the whole layout, counts, ``path`` 'disk' or 'islands').
    - ``warnings``: list of str, one per problem found (empty for a clean result).
    - ``seams`` (k,2) int64: the seams the core chose (input vertex pairs; empty without ``cones``).
    - ``cones``: list of (vertex, kappa) of the cone singularities (input vertex ids, radians; the
      flattened angle at the vertex is 2*pi - kappa)."""
    uv_corner: np.ndarray
    flattened: np.ndarray
    face_island: np.ndarray
    mu: np.ndarray
    mu_vertex: np.ndarray
    uv: np.ndarray
    F_uv: np.ndarray
    islands: list = field(default_factory=list)
    report: dict = field(default_factory=dict)
    warnings: list = field(default_factory=list)
    seams: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int64))
    cones: list = field(default_factory=list)

    def seam_mask(self, E) -> np.ndarray:
        """(e,) bool: which of the edges ``E`` (e,2) (vertex pairs, e.g. all edges of the mesh) are
        among the chosen ``seams``."""
        return topology.edge_mask(E, self.seams)


def _select(V, F, faces, seams):
    """The sub-mesh of the triangles ``faces`` ((m,) bool or None). Returns (sel (k,) triangle ids,
    used (n_s,) input vertex ids, V_s, F_s, seams_s)."""
    m, n = len(F), len(V)
    S = seam_pairs(seams, n)
    if faces is None:
        return np.arange(m), np.arange(n), V, F, S
    faces = np.asarray(faces)
    if faces.shape != (m,) or faces.dtype != bool:
        raise ConformalError(f"faces must be a boolean array with one entry per triangle ({m}), got "
                             f"dtype {faces.dtype} and shape {faces.shape}")
    sel = np.nonzero(faces)[0]
    if len(sel) == 0:
        raise ConformalError("no face is selected: select the faces to unwrap", 'empty_mesh')
    used = np.unique(F[sel])
    remap = np.full(n, -1, np.int64)
    remap[used] = np.arange(len(used))
    S = remap[S]
    S = S[(S >= 0).all(1)] if len(S) else S
    return sel, used, V[used], remap[F[sel]], S


def _plain_disk(V, F, seams, max_faces):
    """(True, boundary loops) if the mesh is clean, one piece and one disk without seams; else
    (False, None): the island pipeline then handles it (repairs, holes, or a precise error)."""
    if len(seams):
        return False, None
    try:
        info = check_mesh(V, F, kind='surface', max_faces=max_faces, allow_parts=True)
    except ConformalError:
        return False, None
    if len(info.loops) != 1 or info.euler != 1 or info.parts != 1:
        return False, None
    return True, info.loops


def _measure(V, F, uv_corner):
    """docs/math.md §3 measures of the triangles ``F`` (k,3) under the corner UVs ``uv_corner``
    (k,3,2), as a triangle soup (split vertices need no bookkeeping). Zero-area triangles (kept for
    the solve by the mollification) have no Jacobian: they are left out and get NaN mu. Returns
    (report dict, mu (k,))."""
    k = len(F)
    Vn = normalise_scale(V)[0]                          # measures are scale invariant; no overflow
    good = ~degenerate_faces(Vn, F)
    g = int(good.sum())
    P = Vn[F[good]].reshape(-1, 3)
    meas, mu_g = measures_from_jacobians(*jacobians(P, np.arange(3 * g).reshape(g, 3),
                                                    uv_corner[good].reshape(-1, 2)))
    mu = np.full(k, np.nan)
    mu[good] = mu_g
    return meas, mu


# what to do about an extreme scale variation on an island whose cones the tool chose already
CONE_SCALE_REMEDY = ("merge vertices by distance where tiny triangles sit, or raise the target ratio or "
                     "the cone budget")


def island_warnings(rep: dict, desc: str, cones: bool = False) -> list:
    """Quality warnings of one island report (not its failure): flips, overlaps, qc_mean above
    ``QC_WARN``, a ``mu_ratio`` below ``MU_WARN``, an optimiser that did not converge, a failed
    certificate. ``cones``: the island was cut through cones the tool chose (``CONE_SCALE_REMEDY``
    names what is left to do about its scale, not ``SCALE_REMEDY``)."""
    out = []
    if rep.get('flips'):
        out.append(flip_warning(rep, desc))
    if rep.get('overlaps'):
        out.append(f"{desc} overlaps itself ({rep['overlaps']} boundary crossing(s))")
    if rep.get('qc_mean') is not None and rep['qc_mean'] > QC_WARN:
        out.append(f"{desc} is far from conformal (qc_mean {rep['qc_mean']:.3g} > {QC_WARN}): mesh too "
                   "coarse or too distorted for a good conformal map")
    mu = rep.get('mu_ratio')
    if mu is not None and scale_variation(mu):
        out.append(f"{desc} has {scale_variation(mu)}; {CONE_SCALE_REMEDY if cones else SCALE_REMEDY}")
    if rep.get('converged') is False:
        out.append(f"{desc}: the optimiser did not converge; the map is the best one found")
    if rep.get('bound_note'):
        out.append(f"{desc}: no certified bound ({rep['bound_note']})")
    return out


def _disk(V, F, loops, boundary, fit, max_faces, progress, options):
    """The disk path: ``flatten`` with the requested fit. Returns (uv (n,2), mu (m,), island report)."""
    res = flatten(V, F, boundary=boundary, fit=fit, max_faces=max_faces, progress=progress,
                  checked_loop=loops[0], **options)      # _plain_disk has checked V, F
    if not np.isfinite(res.uv).all():
        raise ConformalError("the flattening produced non-finite UVs: the mesh is numerically too "
                             "degenerate", 'degenerate', 'clean_mesh')
    r = res.report
    rep = {'island': 1, 'triangles': int(len(F)), 'vertices': int(len(V)), 'loops': 1,
           **{k: r[k] for k in MEASURE_KEYS if k in r},
           'overlaps': boundary_crossings(res.uv, loops), 'area_3d': float(face_areas(V, F).sum())}
    for k in ('bound_vertex', 'vertex_ratio', 'bound_note', 'converged', 'iterations', 'flips_folded',
              'layout'):
        if k in r:
            rep[k] = r[k]
    rep['seconds'] = r.get('seconds', {}).get('total')
    return res.uv, res.mu, rep


@one_thread()
def unwrap(V, F, *, seams=None, faces=None, tri_poly=None, boundary: str = 'uniform', holes: str = 'auto',
           fit: str = 'unit_square', island_scale: str = 'true', pack: bool = True, margin: float = 0.01,
           on_error: str = 'raise', max_faces: int | None = DEFAULT_MAX_FACES, edges=None,
           allow_loose: bool = True, progress: Callable[[float, str], None] | None = None,
           cones: int | str | None = None, target_ratio: float = 0.5, max_cones: int = 48,
           **options) -> UnwrapResult:
    """Unwrap the triangle mesh ``V`` (n,3) float, ``F`` (m,3) int (counter-clockwise) to UVs.

    seams: (k,2) int vertex pairs cut open, or None. faces: optional (m,) bool, only these triangles
    are unwrapped (the others get NaN UVs; seams outside them are ignored). tri_poly: optional (m,)
    polygon of each triangle, to name polygons in messages. boundary: 'uniform', 'area' or 'free'.
    holes: 'auto' (fill a cap, cut a tube: both are tried and the better map is kept), 'fill', 'cut'
    or 'error'. fit: 'unit_square' or 'true_scale' (mesh units, UV area = 3D
    area). island_scale: 'true' (one texel density) or 'normalise' (equal UV area per island). pack:
    shelf-pack several islands without overlap, ``margin`` a fraction of the layout size (one island
    is never packed). on_error: 'raise' or 'skip' (islands that cannot be flattened are left out,
    with a warning; if none can be flattened it raises). max_faces: size limit in triangles (None:
    none). edges: optional (e,2) all edges of the mesh, refused if some lie in no face (whole-mesh
    runs only). allow_loose: accept vertices in no face. progress: ``progress(fraction, message)``,
    called between steps and islands; an exception it raises (e.g. a cancellation) propagates.
    cones: None (the seams given are the only cuts), 'auto' (automatic seams through cone
    singularities: the fewest cones per part reaching ``target_ratio`` for the 1%/99% ratio of the
    conformal factor, at most ``max_cones``), or an int cone budget per part; ``seams`` are then
    ignored, and ``boundary``, ``holes`` and ``island_scale`` do not apply (each part keeps its
    boundary lengths). Extra ``options`` go to ``flatten`` (e.g. ``bound``, optimiser settings).

    Returns ``UnwrapResult``. Raises ``ConformalError`` when no answer exists (the message names the
    problem; ``exc.remedy`` says what to do)."""
    t0 = time.perf_counter()
    V, F = as_arrays(V, F)
    m = len(F)
    if tri_poly is not None:
        tri_poly = np.asarray(tri_poly, np.int64)
        if tri_poly.shape != (m,):
            raise ConformalError(f"tri_poly must have one polygon index per triangle ({m}), got shape "
                                 f"{tri_poly.shape}")
    sel, used, Vs, Fs, Ss = _select(V, F, faces, seams)
    whole = len(sel) == m
    bad = ~np.isfinite(Vs).all(1)
    if bad.any():            # first: coordinates that are not numbers make every other test meaningless
        ex = ', '.join(str(int(v)) for v in used[np.nonzero(bad)[0][:5]])
        raise ConformalError(f"mesh has {int(bad.sum())} vertex(es) with NaN or infinite coordinates "
                             f"(vertices {ex})", 'bad_coordinates', 'fix_coordinates')
    auto_seams, cone_list = np.zeros((0, 2), np.int64), []
    if cones is not None:
        if not (cones == 'auto' or (isinstance(cones, (int, np.integer)) and cones >= 0)):
            raise ConformalError(f"cones must be 'auto', a cone budget (an integer >= 0) or None, got "
                                 f"{cones!r}")
        if cones == 0:
            cones = 'auto'
    disk, loops = (False, None) if cones is not None else _plain_disk(Vs, Fs, Ss, max_faces)
    if disk and edges is not None and whole and loose_edge_count(edges, F):
        disk = False                     # the island pipeline lists the loose edges it ignores
    flat = _disk(Vs, Fs, loops, boundary, fit, max_faces, progress, options) if disk else None
    if flat is not None and flat[2]['overlaps'] and not flat[2]['flips']:
        disk = False          # the map overlaps itself: the island pipeline splits it into charts
    if cones is not None:
        fixed, root = repair_merged(Vs, Fs)     # messy input: the same internal repairs as islands
        require_faces(fixed)
        zero = degenerate_faces(fixed.V, fixed.F)
        if zero.any():                          # kept: cone_unwrap mollifies them, as islands do
            fixed.repairs.append(zero_area_note(int(zero.sum())))
        poly_s = None if tri_poly is None else tri_poly[sel]
        uv_r, isl_r, islands, seams_r, cone_r, n_feature = cone_layout(
            fixed.V, fixed.F, cones=cones, target_ratio=target_ratio, max_cones=max_cones, fit=fit,
            pack=pack, margin=margin, progress=progress,
            poly=None if poly_s is None else poly_s[fixed.face_map])
        uv_corner_s = np.full((len(Fs), 3, 2), np.nan)
        uv_corner_s[fixed.face_map] = np.where(fixed.flipped[:, None, None], uv_r[:, [0, 2, 1]], uv_r)
        rest, kept = fixed.dropped, fixed.face_map
        while len(rest):               # a dropped triangle next to a filled one is filled in the next round
            _fill_dropped(Fs if root is None else root[Fs], uv_corner_s, kept, rest, poly=poly_s)
            done = np.isfinite(uv_corner_s[rest]).all(axis=(1, 2))
            if not done.any():
                break
            kept, rest = np.r_[kept, rest[done]], rest[~done]
        isl = np.full(len(Fs), -1, np.int64)
        isl[fixed.face_map] = isl_r
        seams_s = np.unique(np.sort(fixed.vert_map[seams_r], axis=1), axis=0) if len(seams_r) else seams_r
        cone_s = [(int(fixed.vert_map[v]), k) for v, k in cone_r]
        ok = np.isfinite(uv_corner_s).all(axis=(1, 2))
        uv_s, F_uv_s = _shared_uv(Fs, uv_corner_s)
        meas, mu_ok = _measure(Vs, Fs[ok], uv_corner_s[ok])
        mu_s = np.full(len(Fs), np.nan)
        mu_s[ok] = mu_ok
        auto_seams = used[seams_s] if len(seams_s) else auto_seams
        cone_list = [(int(used[v]), k) for v, k in cone_s]
        summary = {'islands': len(islands), 'flattened': len(islands), 'failed': 0, 'holes_filled': 0,
                   'holes_cut': 0, 'packed': bool(pack and len(islands) > 1), 'pack_efficiency': None,
                   'bound_vertex': None, 'vertex_ratio': None, 'cones': len(cone_list),
                   'seam_edges': int(len(auto_seams)), 'feature_edges': int(n_feature),
                   'seam_length': float(sum(r['seam_length'] for r in islands)),
                   'seam_fraction': _seam_fraction(V, F, auto_seams), 'repairs': fixed.repairs,
                   **{k: meas[k] for k in MEASURE_KEYS}}
    elif disk:
        uv_s, mu_s, rep = flat
        uv_corner_s = uv_s[Fs]
        F_uv_s, ok, isl = Fs, np.ones(len(Fs), bool), np.zeros(len(Fs), np.int64)
        islands = [rep]
        summary = {'islands': 1, 'flattened': 1, 'failed': 0, 'holes_filled': 0, 'holes_cut': 0,
                   'packed': False, 'pack_efficiency': None, 'seconds': rep['seconds'],
                   **{k: rep[k] for k in MEASURE_KEYS}}
        for k in ('bound_vertex', 'vertex_ratio'):
            summary[k] = rep.get(k)
    else:
        res = unwrap_islands(Vs, Fs, seams=Ss, boundary=boundary, holes=holes, island_scale=island_scale,
                             pack=pack, margin=margin, fit=fit, max_faces=max_faces, allow_loose=allow_loose,
                             edges=edges if whole else None, on_error=on_error,
                             tri_poly=None if tri_poly is None else tri_poly[sel], strict_seams=whole,
                             progress=progress, **options)
        ok = np.asarray(res.ok, bool)
        uv_corner_s = res.uv[res.F]
        if not np.isfinite(uv_corner_s[ok]).all():
            raise ConformalError("the flattening produced non-finite UVs: the mesh is numerically too "
                                 "degenerate", 'degenerate', 'clean_mesh')
        F_uv_s, uv_s, isl, islands = res.F, res.uv, res.face_island, res.islands
        meas, mu_ok = _measure(Vs, Fs[ok], uv_corner_s[ok])
        mu_s = np.full(len(Fs), np.nan)
        mu_s[ok] = mu_ok
        summary = {k: v for k, v in res.report.items() if k not in ('triangles', 'vertices')}
        summary.update({k: meas[k] for k in MEASURE_KEYS})
        one = [r for r in islands if 'error' not in r]
        summary['bound_vertex'] = one[0].get('bound_vertex') if len(islands) == 1 and one else None
        summary['vertex_ratio'] = one[0].get('vertex_ratio') if len(islands) == 1 and one else None
    # back to the input's numbering
    uv_corner = np.full((m, 3, 2), np.nan)
    uv_corner[sel[ok]] = uv_corner_s[ok]
    flattened = np.zeros(m, bool)
    flattened[sel[ok]] = True
    face_island = np.full(m, -1, np.int64)
    face_island[sel] = isl
    mu = np.full(m, np.nan)
    mu[sel] = mu_s
    F_uv = np.full((m, 3), -1, np.int64)
    F_uv[sel] = F_uv_s
    A = face_areas(Vs, Fs)
    mu_vertex = np.full(len(V), np.nan)
    mu_vertex[used] = vertex_mu(Fs, mu_s, A, len(Vs))
    # warnings, in the core's wording
    warnings = []
    n_isl = len(islands)
    for r in islands:
        desc = "the map" if n_isl == 1 else f"island {r['island']} of {n_isl}"
        if 'error' in r:
            warnings.append(f"skipped {r['error']}")
            continue
        # the cone path's own warnings, named by island when there are several ("the map: the map is
        # not conformal enough" said nothing twice)
        own = [w if n_isl == 1 else f"{desc}: {w}" for w in r.get('warnings', [])
               if cones is not None and 'scale variation' not in w]
        r['warnings'] = island_warnings(r, desc, cones is not None) + own
        warnings += r['warnings']
    mirrored = summary.get('flips', 0) - sum(r.get('flips', 0) for r in islands if 'error' not in r)
    if mirrored > 0:
        # the islands are clean in the repaired orientation: these triangles are wound against their
        # neighbours in the input, so their UVs read mirrored against their own normals
        warnings.append(f"{mirrored} triangle(s) are wound against their neighbours (their normals point "
                        "the other way): their UVs are mirrored; recalculate normals")
    dup = topology.split_duplicates(Vs, Fs) if len(islands) > 1 else 0
    # (a single disk has no cut at all: nothing to split)
    split = 0 if tri_poly is None or disk else split_polygons(F, tri_poly, uv_corner)
    if split:
        warnings.append(f"{split} polygon(s) are cut by a seam through their inside: a polygon holds one UV "
                        "per corner, so theirs are wrong; triangulate them (Face > Triangulate Faces) or "
                        "mark seams along polygon edges")
    if dup > SOUP_FRACTION * len(np.unique(Fs)):       # parts that touch (a teapot's lid) are not a soup
        warnings.append(f"{dup} vertices sit on a vertex of another part (the surface is split there "
                        "without a seam, as in a triangle soup): merge vertices by distance (Mesh > Clean "
                        "Up > Merge by Distance) to unwrap them as one surface")
    path = 'cones' if cones is not None else 'disk' if disk else 'islands'
    summary.update({'path': path, 'boundary': boundary, 'fit': fit,
                    'holes': holes, 'island_scale': island_scale, 'triangles': int(m),
                    'vertices': int(len(V)), 'selected_triangles': int(len(sel)),
                    'flattened_triangles': int(flattened.sum()), 'seams': int(len(Ss)),
                    'overlaps': int(sum(r.get('overlaps', 0) for r in islands if 'error' not in r)),
                    'split_polygons': int(split),
                    'qc_mean_worst': float(max(r['qc_mean'] for r in islands if 'error' not in r)),
                    'mu_ratio_worst': float(min(r['mu_ratio'] for r in islands if 'error' not in r)),
                    'seconds': round(time.perf_counter() - t0, 4),
                    'mu_range': [float(np.nanmin(mu_s)), float(np.nanmax(mu_s))],
                    'warnings': len(warnings)})
    return UnwrapResult(uv_corner=uv_corner, flattened=flattened, face_island=face_island, mu=mu,
                        mu_vertex=mu_vertex, uv=uv_s, F_uv=F_uv, islands=islands, report=summary,
                        warnings=warnings, seams=auto_seams, cones=cone_list)


# ``unwrap`` warns of a triangle soup when more than this fraction of the vertices sit on a vertex of
# another part: a soup has all of them; the corpus teapot, whose lid and spout touch its body, 18 %;
# suzanne 1 %, ogre under 0.1 %
SOUP_FRACTION = 0.5


def _fill_dropped(F, uv_corner, kept, dropped, poly=None):
    """Corner UVs (in place in ``uv_corner`` (m,3,2)) for the ``dropped`` (k,) triangles of ``F`` (m,3)
    (the repair left them out: a repeated vertex, a duplicate, or collapsed by merging coincident
    vertices, ``F`` then holding the merged ids): from a ``kept`` triangle that shares an edge with
    one, in one island, so that a zero-area triangle stays a point or a segment of its neighbour in
    UV. With ``poly`` (m,) (the polygon of each triangle) a neighbour in the same polygon is taken
    first, so that a seam along the edge does not give the polygon's corner two UVs. A dropped
    triangle with no such neighbour keeps NaN (not flattened)."""
    n = int(F.max()) + 1
    Fk = F[kept]
    e_a = np.concatenate([Fk[:, [0]], Fk[:, [1]], Fk[:, [2]]], 1)
    e_b = np.concatenate([Fk[:, [1]], Fk[:, [2]], Fk[:, [0]]], 1)
    key = (np.minimum(e_a, e_b) * n + np.maximum(e_a, e_b)).ravel()        # (3k,) edge of each side
    side_face = np.repeat(np.arange(len(kept)), 3)
    side_pos = np.tile(np.arange(3), len(kept))
    order = np.argsort(key, kind='stable')
    key_s = key[order]
    D = F[dropped]
    for j in range(3):                                   # the first side with a kept neighbour wins
        a, b = D[:, j], D[:, (j + 1) % 3]
        todo = ~np.isfinite(uv_corner[dropped]).all(axis=(1, 2)) & (a != b)
        if not todo.any():
            break
        q = np.minimum(a, b) * n + np.maximum(a, b)
        at = np.minimum(np.searchsorted(key_s, q), len(key_s) - 1)
        hit = todo & (key_s[at] == q)
        if not hit.any():
            continue
        if poly is not None:               # the edge's other kept side, if it is in the same polygon
            nx = np.minimum(at + 1, len(key_s) - 1)
            alt = hit & (key_s[nx] == q) & (poly[kept[side_face[order[nx]]]] == poly[dropped]) \
                & (poly[kept[side_face[order[at]]]] != poly[dropped])
            at = np.where(alt, nx, at)
        f = kept[side_face[order[at[hit]]]]
        p = side_pos[order[at[hit]]]
        rows = dropped[hit]
        new = np.full((len(rows), 3, 2), np.nan)
        for r in range(3):                    # each corner of the neighbour gives its vertex's UV
            vert = F[f, (p + r) % 3]
            uv_r = uv_corner[f, (p + r) % 3]
            for c in range(3):
                same = D[hit, c] == vert
                new[same, c] = uv_r[same]
        uv_corner[rows] = new
    # a triangle whose three corners merged into one vertex: that vertex's point in UV
    D = F[dropped]
    one = (D[:, 0] == D[:, 1]) & (D[:, 1] == D[:, 2]) & ~np.isfinite(uv_corner[dropped]).all(axis=(1, 2))
    if one.any():
        at = np.full(n, -1, np.int64)
        at[Fk.ravel()[::-1]] = np.arange(Fk.size)[::-1]           # a kept corner of each vertex
        c = at[D[one, 0]]
        has = c >= 0
        uv_corner[dropped[one][has]] = uv_corner[kept[c[has] // 3], c[has] % 3][:, None, :]
    return uv_corner


def _shared_uv(F, uv_corner):
    """Shared UV vertices of corner UVs: corners of one vertex with identical UVs (one wedge of an
    island) share a UV vertex, like OBJ ``vt``. ``F`` (m,3), ``uv_corner`` (m,3,2). Returns (uv (N,2),
    F_uv (m,3)); corners with NaN UVs get -1."""
    m = len(F)
    ok = np.isfinite(uv_corner).all(axis=2).ravel()
    W = np.ascontiguousarray(uv_corner.reshape(-1, 2))
    key = np.column_stack([F.ravel().astype(np.float64).view(np.int64),
                           W[:, 0].view(np.int64), W[:, 1].view(np.int64)])
    idx = np.nonzero(ok)[0]
    _, first, inv = np.unique(key[idx], axis=0, return_index=True, return_inverse=True)
    F_uv = np.full(3 * m, -1, np.int64)
    F_uv[idx] = inv.ravel()
    return W[idx[first]], F_uv.reshape(m, 3)


def _seam_fraction(V, F, seams):
    """Total length of the ``seams`` (k,2) over the total edge length of ``F``."""
    if not len(seams):
        return 0.0
    E, _ = topology.unique_edges(F)
    total = float(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1).sum())
    return float(np.linalg.norm(V[seams[:, 0]] - V[seams[:, 1]], axis=1).sum()) / total


def true_scale(parts: Sequence[tuple]) -> list:
    """Scale UV layouts to mesh units with one common factor: after the scaling the total UV area of
    all ``parts`` equals their total 3D area (one texel density across them).

    ``parts``: sequence of (V (n,3), F (k,3), uv_corner (k,3,2)) with the 3D triangles and their
    corner UVs (e.g. after an external packer fitted them into the unit square). Returns the list of
    scaled ``uv_corner`` arrays (float64), unchanged if the UV area is not positive."""
    a3 = sum(float(face_areas(np.asarray(V, np.float64), np.asarray(F, np.int64)).sum()) for V, F, _ in parts)
    auv = 0.0
    for _, _, W in parts:
        W = np.asarray(W, np.float64)
        k = len(W)
        auv += float(np.abs(signed_uv_areas(W.reshape(-1, 2), np.arange(3 * k).reshape(k, 3))).sum())
    out = [np.asarray(W, np.float64) for _, _, W in parts]
    if not auv > 0:
        return out
    s = np.sqrt(a3 / auv)
    return [W * s for W in out]


def _cone_part(V, F, cones, target_ratio, max_cones, progress, inner=None):
    """One connected part through ``cone_unwrap``: the automatic budget (``cones`` 'auto') keeps the
    best defect-free layout among ``max_cones`` and smaller budgets, since a layout that folds or
    overlaps is worth less than one with fewer cones. A budget whose cones give no layout at all (a
    coarse part: 'solve_failed') is lowered until one does (halved above 8, then one at a time), with
    a warning; the first error is raised if none does. ``inner``: ``cone_unwrap``'s. Returns
    ``ConeResult``."""
    from .cones import cone_unwrap, realised_spread
    auto = cones == 'auto'
    budget = int(max_cones) if auto else int(cones)
    best, failed = None, None
    while True:
        try:
            res = cone_unwrap(V, F, cones=None, target_ratio=target_ratio if auto else None, max_cones=budget,
                              progress=progress, inner=inner)
        except ConformalError as exc:
            if exc.code != 'solve_failed' or budget <= 1:
                if best is not None:
                    return best[1]
                raise (failed[1] if failed else exc) from None
            failed = failed or (budget, exc)
            budget = budget - 1 if budget <= 8 else budget // 2
            continue
        r = res.report
        if failed:
            r['warnings'].append(f"no layout could be built with a budget of {failed[0]} cones "
                                 f"({failed[1].problem}): {r['cones']} cones were placed")
        if not auto:
            return res
        defects = r['flips'] + r['overlaps'] + r.get('degenerate', 0) + r.get('seams_inside_polygons', 0)
        key = (defects == 0, -defects, realised_spread(r))
        if best is None or key > best[0]:
            best = (key, res)
        if defects == 0 or budget <= 4:
            return best[1]
        budget = max(4, min(budget // 2, r['cones'] - 1))


def split_polygons(F, tri_poly, uv_corner):
    """How many polygons (``tri_poly`` (m,) the polygon of each triangle of ``F`` (m,3)) give one of
    their vertices two different UVs in ``uv_corner`` (m,3,2) (NaN: a triangle not flattened, left
    out): a seam through the polygon's inside, which a polygon's corners cannot hold. A quad's two
    triangles, next to each other as ``triangulate`` gives them, are compared directly; larger
    polygons by a sort of their corners. A mesh of triangles has nothing to compare."""
    tri_poly = np.asarray(tri_poly, np.int64)
    if len(tri_poly) > 1 and (np.diff(tri_poly) < 0).any():
        order = np.argsort(tri_poly, kind='stable')
        F, tri_poly, uv_corner = F[order], tri_poly[order], uv_corner[order]
    ok = np.isfinite(uv_corner).all(axis=(1, 2))
    count = np.bincount(tri_poly, minlength=int(tri_poly.max(initial=0)) + 1)[tri_poly]
    # two triangles: the pair's corners at the same vertex must have the same UV
    i = np.flatnonzero((count[:-1] == 2) & (tri_poly[:-1] == tri_poly[1:]) & ok[:-1] & ok[1:])
    same = F[i][:, :, None] == F[i + 1][:, None, :]                                     # (k,3,3)
    differ = (uv_corner[i][:, :, None, :] != uv_corner[i + 1][:, None, :, :]).any(-1)
    polys = [tri_poly[i[(same & differ).any(axis=(1, 2))]]]
    big = ok & (count > 2)
    if big.any():
        n = int(F.max()) + 1
        key = np.repeat(tri_poly[big], 3) * n + F[big].ravel()
        order = np.argsort(key, kind='stable')
        key, W = key[order], uv_corner[big].reshape(-1, 2)[order]
        differ = (key[1:] == key[:-1]) & (W[1:] != W[:-1]).any(1)
        polys.append(key[1:][differ] // n)
    return int(len(np.unique(np.concatenate(polys))))


def _keep_part(repeats, V, F, poly, out, desc):
    """Keep the layout ``out`` (as ``_feature_part`` returns it) of the part ``V`` (n,3), ``F`` (m,3)
    with polygons ``poly`` (m,) or None in ``repeats`` (``Repeats``) as one piece whose vertices are the
    triangles' corners, with its islands, cones and seams in the piece's report."""
    m = len(F)
    uv, isl, reps, seams, cones, nf = out
    extra = {'isl': isl, 'reports': reps, 'seams': seams, 'nf': nf, 'corner_vertex': F.ravel(),
             'cones': np.array([c for c, _ in cones], np.int64), 'kappa': np.array([k for _, k in cones])}
    repeats.add(V, F, poly, desc, [(np.arange(m), np.arange(3 * m).reshape(m, 3), F.ravel(),
                                    uv.reshape(-1, 2), extra)])


def _repeated_part(repeats, V, F, poly):
    """The layout (as ``_feature_part`` returns it) of an earlier part of which the part ``V`` (n,3),
    ``F`` (m,3), ``poly`` (m,) or None is a copy (up to a rotation and a translation, or a reflection:
    ``Repeats.find``), carried onto this part's vertices and corners, or None. A copy has the same edge
    lengths, so the same cones, seams and layout (a mirror image's reflected); its reports say which
    part it repeats."""
    same = repeats.find(V, F, poly)
    if same is None:
        return None
    desc, [(mine, Fc, new_vertex, uv, extra)] = same
    uv_corner = np.empty((len(F), 3, 2))
    uv_corner[mine] = uv[Fc]
    isl = np.empty(len(F), np.int64)
    isl[mine] = extra['isl']
    vertex = np.empty(len(V), np.int64)              # this part's vertex of each vertex of the original
    vertex[extra['corner_vertex']] = new_vertex
    seams = np.sort(vertex[extra['seams']], axis=1) if len(extra['seams']) else extra['seams']
    reps = extra['reports']
    for rep in reps:
        rep['repeat_of'], rep['seconds'] = desc, {'total': 0.0}
    return (uv_corner, isl, reps, seams, list(zip(vertex[extra['cones']].tolist(), extra['kappa'].tolist())),
            extra['nf'])


def cone_layout(V, F, *, cones='auto', target_ratio: float = 0.5, max_cones: int = 48,
                fit: str = 'unit_square', pack: bool = True, margin: float = 0.01,
                progress: Callable[[float, str], None] | None = None, poly=None, features: bool = True):
    """Automatic seams from cone singularities, part by part (docs/math.md §9), and with ``features``
    (``cones='auto'`` only) along a part's feature curves (``_feature_part``).

    ``V`` (n,3), ``F`` (m,3): a manifold mesh (one or several connected parts, closed or open, any
    genus). cones: 'auto' (the fewest cones reaching ``target_ratio`` for the 1%/99% scale ratio, at
    most ``max_cones``) or a cone budget per part (int). ``poly`` (m,) optional: the polygon of each
    triangle; the cuts keep off the polygons' diagonals where they can (a seam through a polygon
    would give one of its corners two UVs). Returns (uv_corner (m,3,2), face_island (m,), islands
    (list of report dicts), seams (k,2), cones (list of (vertex, kappa)), feature_edges: how many of
    the seams are feature curves). A part cut along its feature curves can give several islands."""
    from .cones import flat_part
    from .features import feature_curves
    from .unfold import FLAT_TREE_MAX, unfold_flat_disk
    report_progress = progress or (lambda f, msg: None)
    n, m = len(V), len(F)
    n_parts, part = topology.face_components(F, n)
    uv_corner = np.full((m, 3, 2), np.nan)
    face_island = np.zeros(m, np.int64)
    islands, seams, cone_list, boxes = [], [], [], []
    n_feature = 0
    repeats = Repeats()                     # parts of one shape (an array modifier's copies) placed once
    inner = None if poly is None else polygon_sides(F, n, np.asarray(poly))
    a_total = float(face_areas(V, F).sum())
    done = 0.0
    for p in range(n_parts):
        tris = np.nonzero(part == p)[0]
        used, Fp = np.unique(F[tris], return_inverse=True)
        Fp = Fp.reshape(-1, 3)
        Vp, poly_p = V[used], None if poly is None else poly[tris]
        share = len(tris) / m
        sub = (lambda f, msg, b=done, w=share: report_progress(0.05 + 0.85 * (b + w * f), msg))

        def plain(tris=tris, Vp=Vp, Fp=Fp, sub=sub, p=p):
            """The part's ``ConeResult`` without feature curves."""
            try:
                return _cone_part(Vp, Fp, cones, target_ratio, max_cones, sub,
                                  None if inner is None else inner[tris])
            except ConformalError as exc:
                if n_parts == 1 or exc.problem.startswith('part '):
                    raise
                raise exc.with_context(f"part {p + 1} of {n_parts} ({len(tris)} triangles)") from None

        flat = None if len(Fp) > FLAT_TREE_MAX or degenerate_faces(Vp, Fp).any() else \
            unfold_flat_disk(Vp, Fp)
        if flat is not None:                  # no interior vertex (a card, a soup's triangle): no cone
            out = _one_island(flat_part(Vp, Fp, flat, target_ratio))
        elif (out := _repeated_part(repeats, Vp, Fp, poly_p)) is None:
            curves = feature_curves(Vp, Fp, poly_p) if features and cones == 'auto' else ()
            out = _feature_part(Vp, Fp, curves, plain, dict(target_ratio=target_ratio, max_cones=max_cones,
                                                            margin=margin, progress=sub, poly=poly_p)) \
                if len(curves) else _one_island(plain())
            if n_parts > 1:
                _keep_part(repeats, Vp, Fp, poly_p, out, f"part {p + 1}")
        uv_p, isl_p, reps, seams_p, cones_p, nf = out
        done += share
        area = face_areas(Vp, Fp)
        for j, r in enumerate(reps):
            r.update({'island': len(islands) + j + 1, 'triangles': int((isl_p == j).sum()),
                      'area_3d': float(area[isl_p == j].sum())})
        face_island[tris] = len(islands) + isl_p
        islands += reps
        n_feature += nf
        uv_corner[tris] = uv_p
        if len(seams_p):
            seams.append(used[seams_p])
        cone_list += [(int(used[c]), float(k)) for c, k in cones_p]
        W = uv_p.reshape(-1, 2)
        lo = W.min(0)
        uv_corner[tris] -= lo
        boxes.append(W.max(0) - lo)
    boxes = np.array(boxes)
    if pack and n_parts > 1:
        size = np.sqrt((boxes[:, 0] * boxes[:, 1]).sum())
        off, layout = shelf_pack(boxes, margin * size / max(1e-12, 1 - 2 * margin))
        for p in range(n_parts):
            uv_corner[part == p] += off[p]
    else:
        layout = (float(boxes[:, 0].max()), float(boxes[:, 1].max()))
    if fit == 'unit_square':
        uv_corner /= max(layout) if max(layout) > 0 else 1.0
    seams = np.concatenate(seams) if seams else np.zeros((0, 2), np.int64)
    for r in islands:
        r['area_fraction'] = r['area_3d'] / a_total if a_total > 0 else 0.0
    return uv_corner, face_island, islands, seams, cone_list, n_feature


def _feature_part(V, F, curves, plain, kw):
    """One connected part ``V`` (n,3), ``F`` (m,3) cut along its feature ``curves`` (k,2) and laid out
    by ``cone_layout`` (``cones='auto'``, its pieces packed at one scale): each side of a curve is a
    boundary, where the curvature its vertices hold costs nothing. That layout is kept if it is clean
    (no flip, overlap or squashed triangle), conformal (every island's qc_mean at most
    ``cones.QC_WARN``) and on target (every island and the whole part at ``target_ratio`` or more).
    Otherwise ``plain()`` (the part's ``ConeResult`` without the cut) runs too, and the better of the
    two is kept: fewer defects, then conformal, then the higher p1/p99 (the worse of every island's
    and the whole part's); and only ``plain()`` if a piece has no layout. ``kw``: ``cone_layout``'s
    target_ratio, max_cones, margin, progress and poly. Returns (uv (m,3,2), island (m,) of each
    triangle, island reports, seams (s,2), cones (list of (vertex, kappa)), feature edges among the
    seams)."""
    from .cones import QC_WARN, realised_spread
    from .cut import cut_along_seams
    cut = cut_along_seams(F, len(V), curves)
    try:
        uv, isl, reps, seams, cone_list, _ = cone_layout(V[cut.vert_of], cut.F, cones='auto',
                                                         fit='true_scale', pack=True, features=False, **kw)
    except ConformalError:              # a piece with no layout: the part as a whole may still have one
        return _one_island(plain())
    seams = np.r_[np.sort(curves, axis=1), np.sort(cut.vert_of[seams], axis=1) if len(seams) else seams]
    got = (uv, isl, reps, np.unique(seams, axis=0), [(int(cut.vert_of[v]), k) for v, k in cone_list],
           len(curves))

    def key(layout):
        reps = layout[2]
        defects = sum(r['flips'] + r['overlaps'] + r.get('degenerate', 0) + r.get('seams_inside_polygons', 0)
                      for r in reps)
        spread = min(min(realised_spread(r) for r in reps), _measure(V, F, layout[0])[0]['mu_ratio_p1_p99'])
        return defects == 0, -defects, max(r['qc_mean'] for r in reps) <= QC_WARN, spread

    k = key(got)
    if k[0] and k[2] and k[3] >= kw['target_ratio']:
        return got
    other = _one_island(plain())
    return got if k >= key(other) else other


def _one_island(res):
    """A part's ``ConeResult`` ``res`` as ``_feature_part`` returns its layouts: one island, no feature
    curve."""
    return (res.uv, np.zeros(len(res.uv), np.int64), [dict(res.report)], res.seams,
            list(zip(res.cones, res.kappa)), 0)
