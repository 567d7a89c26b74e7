"""Writing a flatten run's results into Blender (main thread, Object mode): per-corner UVs, packing
with ``bpy.ops.uv.pack_islands``, the true-scale rescale after it, baking mu, and the stored report.

No math happens here: the UVs, the measures, the per-vertex conformal factor and the true-scale
factor all come from the core (``core.unwrap`` and ``core.atlas.unwrap.true_scale``); this module
only moves arrays in and out of the mesh."""
import time

import bpy
import numpy as np

from ..core.atlas.unwrap import true_scale
from . import meshio, targets
from .colormap import colormap as colormap_rgba, normalise
from .job import mesh_hash
from .wording import island_error, message

REPORT_KEY = 'conformal_flatten_report'
ATTR_NAME = 'conformal_factor'           # FLOAT point attribute; colour: ATTR_NAME + '_color'
RANGE_KEY = ATTR_NAME + '_range'         # mesh custom property [min, max] of the baked values
CONE_ATTR = 'conformal_cones'            # FLOAT point attribute: cone curvature kappa (radians), 0 elsewhere
MAX_ISLAND_REPORTS = 100                 # per-island entries kept in the stored report
NO_VALUE_RGBA = (0.5, 0.5, 0.5, 1.0)     # colour of vertices without a baked value


def job_loops(job, res) -> np.ndarray:
    """(k,3) corner (loop) indices of the flattened triangles of ``job`` (``JobResult`` ``res``)."""
    return job.md.tri_corners[res.tris]


def write_uvs(me, loops: np.ndarray, uv_tri: np.ndarray) -> str:
    """Write the corner UVs ``uv_tri`` (k,3,2) of the corners ``loops`` (k,3) into the active UV map;
    the other corners keep their float32 values bit for bit. Returns the layer's name."""
    old = meshio.read_uv(me)
    new = np.zeros((len(me.loops), 2), np.float32) if old is None else old.astype(np.float32)
    new[loops.ravel()] = uv_tri.reshape(-1, 2)
    return meshio.write_uv(me, new)


def pack_with_blender(context, objs: list, faces: list, opts) -> str | None:
    """Arrange the islands of the polygons ``faces[i]`` ((p,) bool) of mesh objects ``objs`` (Object
    mode) with ``bpy.ops.uv.pack_islands`` in Edit mode: one layout for all of ``objs``, relative
    island scale kept (one global scale). Selections are put back bitwise. Returns None, or the
    reason packing failed (the UVs are then as before the call)."""
    tool = context.scene.tool_settings
    sync = tool.use_uv_select_sync
    saved = [meshio.save_attributes(o.data) for o in objs]
    before = [meshio.read_uv(o.data) for o in objs]
    error = None
    try:
        for o, f in zip(objs, faces):
            meshio.select_faces_only(o.data, f)
        tool.use_uv_select_sync = True
        with targets.in_edit_mode(context, objs):
            ret = bpy.ops.uv.pack_islands(udim_source='CLOSEST_UDIM', rotate=opts.pack_rotate,
                                          rotate_method='ANY', scale=True, merge_overlap=False,
                                          margin_method='SCALED', margin=opts.margin, pin=False,
                                          shape_method=opts.pack_shape)
        if ret != {'FINISHED'}:
            error = f"it returned {', '.join(sorted(ret))}"
    except (RuntimeError, TypeError) as exc:
        error = str(exc).strip()
    finally:
        tool.use_uv_select_sync = sync
        for o, s in zip(objs, saved):
            meshio.restore_attributes(o.data, s)
    if error is not None:
        for o, uv in zip(objs, before):
            if o.mode == 'OBJECT' and uv is not None:
                meshio.write_uv(o.data, uv.astype(np.float32))
    return error


def rescale_true(group: list) -> None:
    """After Pack Islands (which fits the unit square), scale the UVs of ``group`` ((MeshJob,
    JobResult) pairs) back to mesh units with one factor for the whole group
    (``core.atlas.unwrap.true_scale``: UV area = 3D area over the flattened faces)."""
    data, parts = [], []
    for job, res in group:
        me = job.obj.data
        uv = meshio.read_uv(me)
        loops = job_loops(job, res)
        data.append((me, uv, loops))
        parts.append((job.md.V, job.md.F[res.tris], uv[loops]))
    for (me, uv, loops), scaled in zip(data, true_scale(parts)):
        new = uv.astype(np.float32)
        new[loops] = scaled.astype(np.float32)
        meshio.write_uv(me, new)


def pack_groups(context, jobs: list, results: list, opts) -> dict:
    """Arrange the islands of every result the core packed (several islands), per mesh or in one
    shared layout. Returns {mesh pointer: (packer name, note or None)}."""
    packer = {}
    pairs = [(j, r) for j, r in zip(jobs, results)
             if r is not None and (r.report['packed'] or opts.shared_layout)]
    if opts.shared_layout and len(pairs) > 1 and opts.packer == 'SHELF':
        pairs = []      # each mesh keeps its own shelf layout
    groups = [pairs] if opts.shared_layout else [[p] for p in pairs]
    for group in groups:
        if not group:
            continue
        how, note = 'shelf', None
        if opts.packer == 'BLENDER':
            objs, faces = [], []
            for j, r in group:
                f = np.zeros(len(j.md.sizes), bool)
                f[j.md.tri_poly[r.tris]] = True
                objs.append(j.obj)
                faces.append(f)
            note = pack_with_blender(context, objs, faces, opts)
            how = 'pack_islands' if note is None else 'shelf'
            if note is not None:
                note = f"Pack Islands failed ({note}); the core's shelf packing is kept"
        if opts.fit == 'TRUE_SCALE' and how == 'pack_islands':
            rescale_true(group)
        for j, _ in group:
            packer[j.obj.data.as_pointer()] = (how, note)
    return packer


def bake(me, mu_vertex: np.ndarray, colormap_name: str) -> tuple:
    """Bake per-vertex mu (n,) (NaN where no face was flattened: such vertices keep a previous baked
    value, or get NaN and a grey colour). Returns (min, max) of the finite values."""
    vals = np.asarray(mu_vertex, float)
    missing = ~np.isfinite(vals)
    if missing.any():
        prev = meshio.read_point_float(me, ATTR_NAME)
        if prev is not None:
            vals = np.where(missing, prev, vals)
            missing = ~np.isfinite(vals)
    if not missing.any():
        return meshio.bake_scalar(me, ATTR_NAME, vals, colormap_name=colormap_name, log=True)
    lo, hi = float(np.nanmin(vals)), float(np.nanmax(vals))
    rgba = colormap_rgba(normalise(vals, lo, hi, log=True), colormap_name)
    rgba[missing] = NO_VALUE_RGBA
    meshio.write_point_float(me, ATTR_NAME, vals)
    meshio.write_point_color(me, ATTR_NAME + '_color', rgba)
    me[RANGE_KEY] = [lo, hi]
    return lo, hi


def mark_seams(job, res) -> int:
    """With automatic seams: make the core's seams (``res.result.seams``, vertex pairs) the mesh's UV
    seams on the flattened faces, so the user sees and can edit them (seams='KEEP' then respects the
    edits). Seams of edges outside the flattened faces are left as they were. Returns the count."""
    me = job.obj.data
    E = job.edges
    inside = np.isfinite(res.result.mu_vertex[E]).all(axis=1)     # both ends on flattened faces
    seams = meshio.read_seams(me)
    seams[inside] = False
    seams |= res.result.seam_mask(E)
    me.edges.foreach_set('use_seam', seams)
    me.update()
    return int(len(res.result.seams))


def write_cones(me, cones: list) -> None:
    """The cone vertices as the FLOAT point attribute ``CONE_ATTR``: kappa (radians) at each cone,
    0 elsewhere."""
    vals = np.zeros(len(me.vertices))
    for v, k in cones:
        vals[v] = k
    meshio.write_point_float(me, CONE_ATTR, vals)


def island_summary(r: dict) -> dict:
    """The per-island entry of the stored report; a failed island's ``error`` in Blender wording."""
    keep = ('island', 'triangles', 'vertices', 'loops', 'holes', 'flips', 'mu_ratio', 'qc_mean',
            'qc_max', 'overlaps', 'bound_vertex', 'warnings')
    out = {k: r[k] for k in keep if k in r}
    if 'error' in r:
        out['error'] = island_error(r)
        out['error_code'] = r.get('error_code')
    return out


def finish(job, res, uv_name: str, packer: str, pack_note: str | None, colormap: str, opts,
           seconds: dict) -> dict:
    """Bake and store the report of one mesh (``job``, ``res``). ``seconds``: dict of timings.
    Every measure comes from the core's result. Returns the report dict."""
    me = job.obj.data
    md = job.md
    core = res.report
    rng = bake(me, res.result.mu_vertex, colormap) if opts.bake else None
    auto = opts.core_cones is not None
    if auto:
        mark_seams(job, res)
        if opts.bake:
            write_cones(me, res.result.cones)
    isl = res.islands
    polys = np.zeros(len(md.sizes), bool)
    polys[md.tri_poly[res.tris]] = True
    report = {
        'object': job.users[0], 'objects': job.users, 'mesh': me.name,
        'boundary': opts.boundary, 'fit': opts.fit, 'uv_map': uv_name,
        'vertices': md.n_vertices, 'polygons': int(len(md.sizes)),
        'triangles': int(len(res.tris)), 'selection': job.selection,
        'flattened_polygons': int(polys.sum()),
        'islands': core['islands'], 'islands_failed': core['failed'],
        'seams': core['seams'], 'holes': opts.core_holes, 'seam_mode': opts.seams,
        'repairs': core.get('repairs', []),
        'cones': len(res.result.cones) if auto else None,
        'seam_fraction': core.get('seam_fraction') if auto else None,
        'feature_edges': core.get('feature_edges') if auto else None,
        'holes_filled': core['holes_filled'], 'holes_cut': core['holes_cut'],
        'relative_scale': 'true' if (opts.keep_relative_scale or core['islands'] == 1) else 'normalised',
        'packer': packer, 'pack_note': pack_note,
        'mu_ratio': core['mu_ratio'], 'mu_ratio_p1_p99': core['mu_ratio_p1_p99'],
        'bound_vertex': core.get('bound_vertex'), 'vertex_ratio': core.get('vertex_ratio'),
        'qc_mean': core['qc_mean'], 'qc_max': core['qc_max'], 'flips': core['flips'],
        'overlaps': core['overlaps'], 'mu_triangle_range': core['mu_range'],
        'baked': bool(opts.bake), 'conformal_factor_range': list(rng) if rng else None,
        'seconds': {**seconds, 'flatten': round(res.seconds, 4)},
        'core_seconds': core.get('seconds'), 'mesh_hash': mesh_hash(md),
        # the core's warnings: every island's, and the mesh's own (split polygons, mirrored triangles,
        # a triangle soup); an island skipped is listed from its report instead
        'warnings': [w for w in res.result.warnings if not w.startswith('skipped ')],
        'island_reports': [island_summary(r) for r in isl[:MAX_ISLAND_REPORTS]],
    }
    meshio.store_report(me, REPORT_KEY, report)
    return report


def skipped_entry(skipped) -> dict:
    """The stored form of an object skipped with ``skip_bad_islands`` (``job.Skipped``)."""
    exc = skipped.error
    return {'object': skipped.name, 'error': message(exc), 'error_code': exc.code}


def apply_all(context, jobs: list, results: list, skipped: list, opts, t0: float, t_read: float) -> list:
    """Write every result (Object mode). ``results[i]`` is None for a skipped job. Returns the
    per-mesh reports (the first one lists the skipped objects)."""
    t = time.perf_counter()
    uv_names = [None if r is None else write_uvs(j.obj.data, job_loops(j, r), r.uv_tri)
                for j, r in zip(jobs, results)]
    packer = pack_groups(context, jobs, results, opts)
    t_write = time.perf_counter() - t
    reports = []
    colormap = opts.colormap
    for job, res, uv_name in zip(jobs, results, uv_names):
        if res is None:
            continue
        how, note = packer.get(job.obj.data.as_pointer(), ('shelf' if res.report['packed'] else 'none', None))
        seconds = {'read': round(t_read, 4), 'write': round(t_write, 4),
                   'total': round(time.perf_counter() - t0, 4)}
        reports.append(finish(job, res, uv_name, how, note, colormap, opts, seconds))
    if skipped and reports:
        reports[0]['skipped_objects'] = [skipped_entry(s) for s in skipped]
        meshio.store_report(jobs[[r is not None for r in results].index(True)].obj.data, REPORT_KEY,
                            reports[0])
    return reports
