"""``bpy.ops.mesh.conformal_geodesic_distance``: geodesic distance from source vertices, by fast
marching on the conformal plane (``core.geodesic``), baked as point attributes.

Sources (``source='AUTO'``): in Edit mode the selected vertices, else the active vertex; with none
(and in Object mode) the vertex nearest the 3D cursor. ``'SELECTED'`` uses the mesh's vertex
selection in any mode, ``'CURSOR'`` the vertex nearest the cursor.

Output on the base mesh (modifiers are ignored): the FLOAT point attribute ``geodesic_distance`` (mesh
units, object space), the colour attribute ``geodesic_distance_color`` (colour map of the preferences,
optionally with iso-line bands), the mesh custom property ``geodesic_distance_range`` and a JSON report
``conformal_geodesic_report``.

Reusing the flattening: the conformal map a run computed is kept in the hidden point attribute
``.conformal_geodesic_uv`` with a hash of the positions and polygons; the next run on an unchanged
mesh with the same boundary mode skips the flattening. A whole-mesh, single-island result of the
flatten operator (``uv.conformal_flatten``) on the unchanged mesh is reused the same way. Everything is
computed before anything is written: on bad input the operator reports the core's message as an ERROR
and the mesh is untouched."""
import json
import time

import bpy
import numpy as np
from bpy.props import EnumProperty, IntProperty

from ..core.errors import ConformalError
from ..core.disk.flatten import flatten
from ..core.geodesic.solver import face_mu, geodesic_distance
from . import meshio
from .colormap import colormap
from .apply import REPORT_KEY as FLATTEN_REPORT_KEY
from .job import mesh_hash
from .ops_flatten import BOUNDARY_ITEMS
from .prefs import get_prefs

REPORT_KEY = 'conformal_geodesic_report'
ATTR_NAME = 'geodesic_distance'
COLOR_NAME = ATTR_NAME + '_color'
RANGE_KEY = ATTR_NAME + '_range'
UV_CACHE = '.conformal_geodesic_uv'          # FLOAT2 point attribute: the conformal map last used
CACHE_KEY = 'conformal_geodesic_cache'       # JSON {mesh_hash, boundary} describing UV_CACHE
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
    d = np.linalg.norm(V - np.array(loc[:]), axis=1)
    d[~used] = np.inf
    return int(np.argmin(d))


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
# the conformal map: reuse or compute
# ----------------------------------------------------------------------------------------------
def _read_float2(me, name):
    attr = me.attributes.get(name)
    if attr is None or attr.domain != 'POINT' or attr.data_type != 'FLOAT2':
        return None
    buf = np.empty(len(me.vertices) * 2, np.float32)
    attr.data.foreach_get('vector', buf)
    return buf.reshape(-1, 2).astype(np.float64)


def cached_uv(me, md, boundary, digest):
    """The per-vertex conformal map (n,2) that can be reused for ``md`` with ``boundary`` mode, and
    where it came from ('geodesic cache' or 'flatten operator'); (None, None) if there is none."""
    try:
        cache = json.loads(me.get(CACHE_KEY) or 'null')
    except (TypeError, ValueError):
        cache = None
    if cache and cache.get('mesh_hash') == digest and cache.get('boundary') == boundary:
        uv = _read_float2(me, UV_CACHE)
        if uv is not None and np.isfinite(uv).all():
            return uv, 'geodesic cache'
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
                return uv, 'flatten operator'
    return None, None


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
                    colormap_name=None, progress=None):
    """Compute and bake geodesic distances on mesh object ``obj`` (default: the active object); see
    the module docstring. ``grid`` 0: the add-on preference, else automatic. Returns the report dict
    (also stored as JSON in ``obj.data[REPORT_KEY]``). Raises ``ConformalError`` with nothing
    written. Usable from scripts without the operator."""
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
        mode = boundary.lower()
        uv, reused = cached_uv(me, md, boundary, digest)
        t_flat = 0.0
        if uv is not None:
            try:
                face_mu(md.V, md.F, uv)           # a stored map that folds is not reused
            except ConformalError:
                uv, reused = None, None
        if uv is None:
            say(0.0, 'flattening')
            t = time.perf_counter()
            res = flatten(md.V, md.F, boundary=mode, fit='true_scale', bound=False,
                          progress=lambda f, m: say(0.5 * f, m))
            t_flat = time.perf_counter() - t
            uv = res.uv
        lo_p = 0.5 if reused is None else 0.05
        dist, rep = geodesic_distance(md.V, md.F, sources, uv=uv, grid=grid,
                                      progress=lambda f, m: say(lo_p + (0.95 - lo_p) * f, m))
        # --- everything computed: write
        ok = np.isfinite(dist)
        meshio.write_point_float(me, ATTR_NAME, np.where(ok, dist, 0.0))
        meshio.write_point_color(me, COLOR_NAME, distance_colors(dist, bands, colormap_name))
        lo, hi = (float(dist[ok].min()), float(dist[ok].max())) if ok.any() else (0.0, 0.0)
        me[RANGE_KEY] = [lo, hi]
        if reused != 'geodesic cache':
            attr = me.attributes.get(UV_CACHE)
            if attr is not None and (attr.domain != 'POINT' or attr.data_type != 'FLOAT2'):
                me.attributes.remove(attr)
                attr = None
            if attr is None:
                attr = me.attributes.new(UV_CACHE, 'FLOAT2', 'POINT')
            attr.data.foreach_set('vector', np.ascontiguousarray(uv, np.float32).ravel())
            me[CACHE_KEY] = json.dumps({'mesh_hash': digest, 'boundary': boundary})
        me.update()
        ny, nx = rep['grid']
        report = {
            'object': obj.name, 'mesh': me.name, 'vertices': md.n_vertices,
            'triangles': int(len(md.tri_corners)), 'sources': [int(s) for s in sources[:100]],
            'source_count': int(len(sources)), 'source_description': described,
            'boundary': boundary, 'flattening': reused or 'computed', 'grid': [nx, ny],
            'cell': rep['cell'], 'masked_fraction': rep['masked_fraction'], 'solver': rep['solver'],
            'distance_range': [lo, hi], 'bands': int(bands), 'mesh_hash': digest,
            'seconds': {'flatten': round(t_flat, 4), 'geodesic': rep['seconds'].get('total'),
                        'total': round(time.perf_counter() - t0, 4)},
            'core_seconds': rep['seconds'],
        }
        meshio.store_report(me, REPORT_KEY, report)
        say(1.0, 'done')
    return report


def summary_line(r):
    """One line for the status bar."""
    solver = "scikit-fmm" if r['solver'] == 'skfmm' else "numpy sweeping"
    flat = "reused flattening" if r['flattening'] != 'computed' else f"flattened ({r['boundary'].lower()})"
    return (f"Geodesic distance on {r['object']!r} from {r['source_description']}: max "
            f"{r['distance_range'][1]:.4g}, grid {r['grid'][0]}x{r['grid'][1]} ({solver}), {flat}, "
            f"{r['seconds']['total']:.2f} s")


# ----------------------------------------------------------------------------------------------
# operator and panel
# ----------------------------------------------------------------------------------------------
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

    @classmethod
    def poll(cls, context):
        # Deliberately permissive: a wrong selection gets an ERROR report that says what to do.
        return True

    def execute(self, context):
        try:
            with meshio.Progress(context) as progress:
                report = geodesic_object(context, None, source=self.source, grid=self.grid,
                                         boundary=self.boundary, bands=self.bands, progress=progress)
        except ConformalError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self.report({'INFO'}, summary_line(report))
        return {'FINISHED'}


class ConformalGeodesicSettings(bpy.types.PropertyGroup):
    grid: IntProperty(name="Grid Size", default=0, min=0, max=4096,
                      description="Grid nodes along the longer side (0: preference or automatic)")
    source: EnumProperty(name="Source", items=SOURCE_ITEMS, default='AUTO')
    bands: IntProperty(name="Iso-line Bands", default=10, min=0, max=200)


GEODESIC_ROWS = [
    ("Sources", 'source_description'),
    ("Max distance", lambda r: f"{r['distance_range'][1]:.4g}"),
    ("Grid", lambda r: f"{r['grid'][0]} x {r['grid'][1]}"),
    ("Solver", 'solver'),
    ("Flattening", 'flattening'),
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
        op = col.operator(MESH_OT_conformal_geodesic_distance.bl_idname, icon='DRIVER_DISTANCE')
        op.source, op.grid, op.bands = settings.source, settings.grid, settings.bands
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
    unregister_tool(ConformalGeodesicSettings, 'conformal_geodesic',
                    MESH_OT_conformal_geodesic_distance, _registered)
    _registered.clear()
