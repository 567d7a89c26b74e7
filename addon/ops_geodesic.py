"""``bpy.ops.mesh.conformal_geodesic_distance``: geodesic distance from source vertices, by fast
marching on the conformal plane (``core.geodesic``), baked as point attributes.

Sources (``source='AUTO'``): in Edit mode the selected vertices, else the active vertex; with none
(and in Object mode) the vertex nearest the 3D cursor. ``'SELECTED'`` uses the mesh's vertex
selection in any mode, ``'CURSOR'`` the vertex nearest the cursor.

Output on the base mesh (modifiers are ignored): the FLOAT point attribute ``geodesic_distance`` (mesh
units, object space), the colour attribute ``geodesic_distance_color`` (colour map of the preferences,
optionally with iso-line bands), the mesh custom property ``geodesic_distance_range`` and a JSON report
``conformal_geodesic_report``.

Reuse: the add-on keeps the ``core.geodesic.solver.GeodesicSolver`` of the last few runs in memory
(flattening, grids and rasterised conformal factor), keyed on a hash of the positions and polygons and
on the options (boundary mode, grid, seams); the next run on an unchanged mesh with the same options
only marches, and the same sources asked again (a redo that changes only the bands or the colour map)
are answered from the kept result (``distances_reused`` in the report). Otherwise a whole-mesh,
single-island result of the flatten operator (``uv.conformal_flatten``) on the unchanged mesh is used as
the map.

Several parts are one island each (distances are infinite between them: such vertices get 0 in the
attribute and the no-value grey). With ``use_seams`` the surface is cut along the edges marked as
seams and distances are measured on the cut surface. A closed part without seams is measured on the
closed surface by surface paths (``core.geodesic.paths``).

Every report carries ``error_estimate`` (mean relative error, from the grid's resolution on the
surface) and ``warnings``; the operator reports a WARNING when that list is not empty. Everything is
computed before anything is written: on bad input the operator reports the core's message as an ERROR
and the mesh is untouched."""
import time

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty

from ..core.errors import ConformalError
from ..core.geodesic.solver import ERROR_TARGET, GeodesicSolver, nearest_vertex
from . import meshio
from .colormap import colormap
from .geodesic_cache import clear_solvers, cached_solver, keep_solver, solver_distance, solver_key
from .apply import REPORT_KEY as FLATTEN_REPORT_KEY
from .job import mesh_hash
from .ops_flatten import BOUNDARY_ITEMS
from .prefs import get_prefs

REPORT_KEY = 'conformal_geodesic_report'
ATTR_NAME = 'geodesic_distance'
COLOR_NAME = ATTR_NAME + '_color'
RANGE_KEY = ATTR_NAME + '_range'
UV_CACHE = '.conformal_geodesic_uv'          # map cache of earlier versions: removed when found
CACHE_KEY = 'conformal_geodesic_cache'       # its JSON description: removed when found
NO_VALUE_RGBA = (0.5, 0.5, 0.5, 1.0)

SOURCE_ITEMS = [
    ('AUTO', "Automatic", "Edit mode: the selected vertices, else the active vertex; otherwise the "
                          "vertex nearest the 3D cursor"),
    ('SELECTED', "Selected Vertices", "The mesh's selected vertices (in any mode)"),
    ('CURSOR', "3D Cursor", "The vertex nearest the 3D cursor"),
]


# ----------------------------------------------------------------------------------------------
# sources
# ----------------------------------------------------------------------------------------------
def active_vertex(obj):
    """Index of the active vertex of ``obj`` in Edit mode (bmesh select history), or None."""
    if obj.mode != 'EDIT':
        return None
    import bmesh
    bm = bmesh.from_edit_mesh(obj.data)
    act = bm.select_history.active
    if isinstance(act, bmesh.types.BMVert):
        return int(act.index)
    return None


def nearest_to_cursor(context, obj, V, used):
    """Index of the vertex (among ``used``, (n,) bool) nearest the 3D cursor, in object space."""
    loc = obj.matrix_world.inverted() @ context.scene.cursor.location
    return nearest_vertex(V, loc[:], used)


def pick_sources(context, obj, md, how, was_edit, active):
    """Source vertex indices (k,) and a description, following ``how`` ('AUTO', 'SELECTED',
    'CURSOR'). Raises ``ConformalError`` when 'SELECTED' finds no selected vertex."""
    used = np.zeros(md.n_vertices, bool)
    used[md.F.ravel()] = True
    if how in ('AUTO', 'SELECTED'):
        sel = meshio.read_selection(obj.data, 'POINT') & used
        if (how == 'SELECTED' or was_edit) and sel.any():
            return np.flatnonzero(sel), f"{int(sel.sum())} selected vert{'ex' if sel.sum() == 1 else 'ices'}"
        if how == 'SELECTED':
            raise ConformalError("no vertex of a face is selected: select source vertices in Edit "
                                 "mode, or use the 3D cursor as the source")
        if active is not None and used[active]:
            return np.array([active]), "the active vertex"
    k = nearest_to_cursor(context, obj, md.V, used)
    return np.array([k]), f"vertex {k} (nearest the 3D cursor)"


# ----------------------------------------------------------------------------------------------
# the solver: reuse or compute
# ----------------------------------------------------------------------------------------------
def flatten_operator_uv(me, md, boundary, digest):
    """The per-vertex conformal map (n,2) of the flatten operator (``uv.conformal_flatten``) when it
    applies to ``md`` unchanged, as one island, with the same ``boundary`` mode; else None."""
    rep = meshio.load_report(me, FLATTEN_REPORT_KEY)
    if (rep and rep.get('mesh_hash') == digest and rep.get('boundary') == boundary
            and rep.get('islands') == 1 and rep.get('triangles') == len(md.tri_corners)
            and rep.get('uv_map')):
        loop_uv = meshio.read_uv(me, rep['uv_map'])
        if loop_uv is not None:
            uv = np.zeros((md.n_vertices, 2))
            uv[md.corner_verts] = loop_uv
            ext = float(np.ptp(loop_uv, axis=0).max()) if len(loop_uv) else 0.0
            # one chart: every corner of a vertex has the vertex's UV (no seams, not re-edited)
            if ext > 0 and np.abs(uv[md.corner_verts] - loop_uv).max() <= 1e-5 * ext:
                return uv
    return None


def get_solver(me, md, boundary, grid, use_seams, digest, progress=None, error_target=ERROR_TARGET):
    """A ``GeodesicSolver`` for the mesh ``md`` and where it came from: 'geodesic cache' (kept from
    an earlier run on the unchanged mesh with the same options), 'flatten operator' (built on the
    flatten operator's map) or 'computed'. ``error_target``: the solver's (mean relative error).
    Raises ``ConformalError``."""
    seams = None
    if use_seams:
        cut = meshio.read_seams(me)
        seams = meshio.read_edges(me)[cut] if cut.any() else None
    key = solver_key(digest, boundary, grid, use_seams, seams, error_target)
    gs = cached_solver(key)
    if gs is not None:
        return gs, 'geodesic cache'
    uv = flatten_operator_uv(me, md, boundary, digest) if seams is None else None
    origin = 'computed'
    if uv is not None:
        try:
            gs = GeodesicSolver(md.V, md.F, uv=uv, grid=grid, progress=progress,
                                error_target=error_target)
            origin = 'flatten operator'
        except ConformalError:                  # a stored map that folds is not reused
            gs = None
    if gs is None:
        gs = GeodesicSolver(md.V, md.F, boundary=boundary.lower(), grid=grid, seams=seams,
                            progress=progress, error_target=error_target)
    keep_solver(key, gs)
    return gs, origin


# ----------------------------------------------------------------------------------------------
# colours
# ----------------------------------------------------------------------------------------------
def distance_colors(dist, bands=10, colormap_name='PERCEPTUAL'):
    """Linear RGBA (n,4) for distances (n,): the colour map over [0, max]; with ``bands`` > 0 every
    other of ``bands`` equal distance intervals is darkened, so the band edges read as iso-lines.
    NaN (vertices in no face) is grey."""
    dist = np.asarray(dist, float)
    ok = np.isfinite(dist)
    hi = float(dist[ok].max()) if ok.any() else 0.0
    t = np.where(ok, dist, 0.0) / hi if hi > 0 else np.zeros(len(dist))
    rgba = colormap(np.clip(t, 0.0, 1.0), colormap_name)
    if bands and bands > 0:
        odd = (np.floor(t * bands).astype(np.int64) % 2) == 1
        rgba[odd, :3] *= 0.55
    rgba[~ok] = NO_VALUE_RGBA
    return rgba


# ----------------------------------------------------------------------------------------------
# the whole job
# ----------------------------------------------------------------------------------------------
def geodesic_object(context, obj=None, source='AUTO', grid=0, boundary='UNIFORM', bands=10,
                    colormap_name=None, use_seams=False, progress=None, error_target=ERROR_TARGET):
    """Compute and bake geodesic distances on mesh object ``obj`` (default: the active object); see the module
    docstring. ``grid`` 0: the add-on preference, else automatic (from the error target). ``use_seams``: cut
    the surface along the edges marked as seams (distances on the cut surface). ``error_target``: the
    estimated mean relative error to aim for (default 0.1 %; a looser one answers faster: fewer Steiner
    points, fewer re-marches). Returns the report dict (also stored as JSON in ``obj.data[REPORT_KEY]``); its
    ``warnings`` list is non-empty when the result misses the accuracy target or islands were not reached.
    Raises ``ConformalError`` with nothing written. Usable from scripts without the operator."""
    t0 = time.perf_counter()
    obj = meshio.mesh_object(context, obj)
    prefs = get_prefs(context)
    grid = int(grid) or int(getattr(prefs, 'grid_size', 0)) or None
    colormap_name = colormap_name or getattr(prefs, 'colormap', 'PERCEPTUAL')
    say = progress or (lambda f, msg: None)
    was_edit = obj.mode == 'EDIT'
    active = active_vertex(obj) if was_edit else None
    with meshio.object_mode(obj):
        me = obj.data
        md = meshio.read_mesh(me)
        sources, described = pick_sources(context, obj, md, source, was_edit, active)
        digest = mesh_hash(md)
        t = time.perf_counter()
        gs, origin = get_solver(me, md, boundary, grid, use_seams, digest,
                                progress=lambda f, m: say(0.5 * f, m), error_target=error_target)
        t_setup = time.perf_counter() - t
        lo_p = 0.5 if origin != 'geodesic cache' else 0.05
        t = time.perf_counter()
        dist, rep, reused = solver_distance(gs, sources,
                                            progress=lambda f, m: say(lo_p + (0.95 - lo_p) * f, m))
        t_query = time.perf_counter() - t
        # --- everything computed: write
        ok = np.isfinite(dist)
        meshio.write_point_float(me, ATTR_NAME, np.where(ok, dist, 0.0))
        meshio.write_point_color(me, COLOR_NAME, distance_colors(dist, bands, colormap_name))
        lo, hi = (float(dist[ok].min()), float(dist[ok].max())) if ok.any() else (0.0, 0.0)
        me[RANGE_KEY] = [lo, hi]
        for stale in (UV_CACHE,):                 # the map cache of earlier versions
            attr = me.attributes.get(stale)
            if attr is not None:
                me.attributes.remove(attr)
        if CACHE_KEY in me:
            del me[CACHE_KEY]
        me.update()
        ny, nx = rep['grid']
        report = {
            'object': obj.name, 'mesh': me.name, 'vertices': md.n_vertices,
            'triangles': int(len(md.tri_corners)), 'sources': [int(s) for s in sources[:100]],
            'source_count': int(len(sources)), 'source_description': described,
            'boundary': boundary, 'flattening': origin, 'grid': [nx, ny],
            'cell': rep['cell'], 'masked_fraction': rep['masked_fraction'], 'solver': rep['solver'],
            'paths_islands': rep['paths_islands'], 'steiner_points': rep['steiner_points'],
            'planar_islands': rep['planar_islands'], 'refined': rep.get('refined'),
            'distance_range': [lo, hi], 'bands': int(bands), 'mesh_hash': digest,
            'islands': rep['islands'], 'islands_reached': rep['islands_reached'],
            'unreached_vertices': int((~ok & md_used(md)).sum()), 'use_seams': bool(use_seams),
            'error_estimate': rep['error_estimate'], 'error_target': rep['error_target'],
            'clamped': rep['clamped'], 'warnings': list(rep['warnings']),
            'distances_reused': reused,
            'seconds': {'flatten': round(t_setup if origin != 'geodesic cache' else 0.0, 4),
                        'geodesic': round(t_query, 4),
                        'total': round(time.perf_counter() - t0, 4)},
            'core_seconds': rep['seconds'],
        }
        meshio.store_report(me, REPORT_KEY, report)
        say(1.0, 'done')
    return report


def md_used(md):
    """(n,) bool: vertices on some triangle."""
    used = np.zeros(md.n_vertices, bool)
    used[md.F.ravel()] = True
    return used


def summary_line(r):
    """One line for the status bar."""
    solver = "scikit-fmm" if r['solver'] == 'skfmm' else "numpy sweeping"
    reached, paths = r.get('islands_reached'), r.get('paths_islands', 0)
    flat = "reused distances" if r.get('distances_reused') else "reused flattening" \
        if r['flattening'] != 'computed' else f"flattened ({r['boundary'].lower()})"
    if r.get('planar_islands') == reached:
        how = "exact (flat mesh, no grid)"
    elif paths == reached and r.get('steiner_points'):
        # closed parts (and parts the map cannot resolve) are answered on the surface: no grid
        how, flat = f"surface paths ({r.get('steiner_points')} points per edge)", None
    else:
        # a mix: the grid of the parts that marched (none if every part took paths or its plane)
        parts = [f"grid {r['grid'][0]}x{r['grid'][1]} ({solver})" +
                 (f" on the mesh subdivided {r['refined']['levels']} times" if r.get('refined') else "")
                 ] if r['grid'][0] else []
        parts += [f"surface paths on {paths} island(s)"] if paths else []
        parts += [f"exact on {r['planar_islands']} flat island(s)"] if r.get('planar_islands') else []
        how = ", ".join(parts)
    return (f"Geodesic distance on {r['object']!r} from {r['source_description']}: max "
            f"{r['distance_range'][1]:.4g}, {how}, " + (f"{flat}, " if flat else "") +
            f"{r['seconds']['total']:.2f} s, estimated mean error {100 * r['error_estimate']:.2g}%")


# ----------------------------------------------------------------------------------------------
# operator and panel
# ----------------------------------------------------------------------------------------------
TARGET_HELP = ("Estimated mean relative error to aim for: the automatic grid and the surface paths' points "
               "are chosen for it, and a result above it is warned. Larger answers faster: at 1 % a new "
               "source on a scan takes about a tenth of the time it takes at the default 0.1 %")


class MESH_OT_conformal_geodesic_distance(bpy.types.Operator):
    """Geodesic distance from the selected vertices (or the active vertex, or the vertex nearest the
    3D cursor) by fast marching on the conformal map; bake it as the attribute 'geodesic_distance'"""
    bl_idname = 'mesh.conformal_geodesic_distance'
    bl_label = "Geodesic Distance"
    bl_options = {'REGISTER', 'UNDO'}

    grid: IntProperty(name="Grid Size", default=0, min=0, max=4096,
                      description="Grid nodes along the longer side of the flattened domain (0: the "
                                  "add-on preference, or automatic from the mesh resolution)")
    source: EnumProperty(name="Source", items=SOURCE_ITEMS, default='AUTO',
                         description="Where the distances are measured from")
    boundary: EnumProperty(name="Boundary", items=BOUNDARY_ITEMS, default='UNIFORM',
                           description="Boundary mode of the conformal map the distances are computed on")
    bands: IntProperty(name="Iso-line Bands", default=10, min=0, max=200,
                       description="Darken every other of this many equal distance bands in the colour "
                                   "attribute (0: plain colour map)")
    use_seams: BoolProperty(name="Cut Along Seams", default=False,
                            description="Cut the surface along the edges marked as seams and measure "
                                        "distances on the cut surface; distances do not cross between "
                                        "pieces")
    target_error: FloatProperty(name="Target Error", default=100 * ERROR_TARGET, min=0.01, max=5.0,
                                subtype='PERCENTAGE', precision=2, description=TARGET_HELP)

    @classmethod
    def poll(cls, context):
        # Deliberately permissive: a wrong selection gets an ERROR report that says what to do.
        return True

    def execute(self, context):
        try:
            with meshio.Progress(context) as progress:
                report = geodesic_object(context, None, source=self.source, grid=self.grid,
                                         boundary=self.boundary, bands=self.bands,
                                         use_seams=self.use_seams, progress=progress,
                                         error_target=self.target_error / 100.0)
        except ConformalError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self.report({'INFO'}, summary_line(report))
        for w in report['warnings']:
            self.report({'WARNING'}, w)
        return {'FINISHED'}


class ConformalGeodesicSettings(bpy.types.PropertyGroup):
    grid: IntProperty(name="Grid Size", default=0, min=0, max=4096,
                      description="Grid nodes along the longer side (0: preference or automatic)")
    source: EnumProperty(name="Source", items=SOURCE_ITEMS, default='AUTO')
    bands: IntProperty(name="Iso-line Bands", default=10, min=0, max=200)
    use_seams: BoolProperty(name="Cut Along Seams", default=False)
    target_error: FloatProperty(name="Target Error", default=100 * ERROR_TARGET, min=0.01, max=5.0,
                                subtype='PERCENTAGE', precision=2, description=TARGET_HELP)


GEODESIC_ROWS = [
    ("Sources", 'source_description'),
    ("Max distance", lambda r: f"{r['distance_range'][1]:.4g}"),
    ("Grid", lambda r: ("none: flat, exact" if r.get('planar_islands') == r.get('islands_reached')
                        else f"surface paths, {r['steiner_points']} points per edge" if r.get('paths_islands')
                        == r.get('islands_reached') and r.get('steiner_points')
                        else f"{r['grid'][0]} x {r['grid'][1]}" if r['grid'][0]
                        else "none: surface paths, flat parts exact")),
    ("Solver", 'solver'),
    ("Flattening", 'flattening'),
    ("Error estimate", lambda r: f"{100 * r['error_estimate']:.2g} %" if 'error_estimate' in r else "-"),
    ("Warnings", lambda r: str(len(r.get('warnings', []))) if r.get('warnings') else "none"),
    ("Time", lambda r: f"{r['seconds']['total']:.2f} s" if r.get('seconds') else "-"),
]


class _GeodesicPanel:
    bl_region_type = 'UI'
    bl_label = "Geodesic Distance"

    def draw(self, context):
        from .sidebar import draw_report
        layout = self.layout
        settings = context.scene.conformal_geodesic
        flat = getattr(context.scene, 'conformal_flatten', None)
        col = layout.column()
        col.prop(settings, 'source')
        col.prop(settings, 'grid')
        col.prop(settings, 'bands')
        col.prop(settings, 'use_seams')
        col.prop(settings, 'target_error')
        op = col.operator(MESH_OT_conformal_geodesic_distance.bl_idname, icon='DRIVER_DISTANCE')
        op.source, op.grid, op.bands = settings.source, settings.grid, settings.bands
        op.use_seams, op.target_error = settings.use_seams, settings.target_error
        if flat is not None:
            op.boundary = flat.boundary
        obj = context.active_object
        report = meshio.load_report(obj.data, REPORT_KEY) if obj is not None and obj.type == 'MESH' else None
        if report is not None:
            draw_report(layout.box(), report, GEODESIC_ROWS)


_registered = []


def register():
    from .sidebar import register_tool
    _registered[:] = register_tool(ConformalGeodesicSettings, 'conformal_geodesic',
                                   MESH_OT_conformal_geodesic_distance, _GeodesicPanel,
                                   'conformal_geodesic')


def unregister():
    from .sidebar import unregister_tool
    clear_solvers()
    unregister_tool(ConformalGeodesicSettings, 'conformal_geodesic',
                    MESH_OT_conformal_geodesic_distance, _registered)
    _registered.clear()
