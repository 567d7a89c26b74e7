"""Mesh data <-> numpy through the fast paths, for every operator of the add-on.

All reads and writes use ``foreach_get``/``foreach_set`` on attribute arrays with matching dtypes
(float32 positions and UVs, int32 corner vertices), which is about 100x faster than the per-element
collections (docs/blender.md, "Mesh I/O cost"). Everything works on the *base* mesh ``object.data``:
modifiers are ignored.

Edit mode: ``mesh.attributes`` then refers to the edit-mode BMesh, whose layers are not the mesh
arrays. Wrap the whole read-compute-write job in ``object_mode(obj)``: it leaves Edit (or any other)
mode, which writes the edit mesh back, and returns to the user's mode afterwards, also on failure.
Selection lives in the mesh's own attributes, so it survives the round trip. Typical use:
``with object_mode(obj): md = read_mesh(obj); ...; write_uv(obj.data, loop_uv)``.
"""
from contextlib import contextmanager
from dataclasses import dataclass
import json

import bpy
import numpy as np

from ..core.errors import ConformalError
from ..core.mesh.triangulate import triangulate
from .colormap import colormap, normalise


@dataclass
class MeshArrays:
    """The base mesh as numpy arrays.

    ``V`` (n,3) float64 positions (object space); ``corner_verts`` (c,) int64 vertex per corner (loop);
    ``sizes`` (p,) int64 corners per polygon; ``loop_start`` (p,) int64 first corner of each polygon;
    ``tri_corners`` (m,3) int64 corner indices of the triangles, counter-clockwise like the polygons;
    ``tri_poly`` (m,) int64 polygon of each triangle."""
    V: np.ndarray
    corner_verts: np.ndarray
    sizes: np.ndarray
    loop_start: np.ndarray
    tri_corners: np.ndarray = None
    tri_poly: np.ndarray = None

    @property
    def F(self):
        """(m,3) int64 vertex indices of the triangles."""
        return self.corner_verts[self.tri_corners]

    @property
    def n_vertices(self):
        return len(self.V)


# --- objects and modes ---------------------------------------------------------------------------
def mesh_object(context, obj=None):
    """The object to work on (``obj`` or the active object), checked to be a mesh. Raises
    ``ConformalError`` with a message for the user otherwise."""
    obj = obj if obj is not None else getattr(context, 'active_object', None)
    if obj is None:
        raise ConformalError("no active object: select a mesh object and make it active")
    if obj.type != 'MESH':
        raise ConformalError(f"the active object {obj.name!r} is a {obj.type.lower()}, not a mesh: "
                             "select a mesh object (or convert it to a mesh)")
    if obj.data.library is not None and not obj.data.is_editable:
        raise ConformalError(f"mesh {obj.data.name!r} is linked from a library and cannot be "
                             "changed: make it local first")
    return obj


def _set_mode(obj, mode):
    with bpy.context.temp_override(active_object=obj, object=obj):
        bpy.ops.object.mode_set(mode=mode)


@contextmanager
def object_mode(obj):
    """Run the body in Object mode, then return ``obj`` to the mode it was in (also on errors).
    Leaving Edit mode writes the edit mesh to ``obj.data``, so the body reads current data."""
    mode = obj.mode
    if mode != 'OBJECT':
        _set_mode(obj, 'OBJECT')
    try:
        yield obj
    finally:
        if mode != 'OBJECT' and obj.mode != mode:
            _set_mode(obj, mode)


# --- reading -------------------------------------------------------------------------------------
FLT_MAX = float(np.finfo(np.float32).max)


def read_positions(me):
    """(n,3) float64 vertex positions of mesh ``me`` (call in Object mode). A coordinate at +-FLT_MAX
    is read as +-inf: it is what Blender stores when "inf" is typed into a number field (the UI clamps
    to the float32 range), and it must be reported as an infinite coordinate, not as a vertex so far
    away that every face looks degenerate."""
    buf = np.empty(len(me.vertices) * 3, np.float32)
    me.attributes['position'].data.foreach_get('vector', buf)
    V = buf.reshape(-1, 3).astype(np.float64)
    big = np.abs(V) >= FLT_MAX
    if big.any():
        V[big] = np.copysign(np.inf, V[big])
    return V


def read_corner_verts(me):
    """(c,) int64 vertex index of each corner (loop)."""
    buf = np.empty(len(me.loops), np.int32)
    if len(buf):
        me.attributes['.corner_vert'].data.foreach_get('value', buf)
    return buf.astype(np.int64)


def read_loop_start(me):
    """(p,) int64 first corner of each polygon; polygons store their corners contiguously, in order."""
    buf = np.empty(len(me.polygons), np.int32)
    me.polygons.foreach_get('loop_start', buf)
    return buf.astype(np.int64)


def read_mesh(obj_or_mesh, triangles=True):
    """Read the base mesh into ``MeshArrays``; with ``triangles`` also triangulate the polygons
    (``core.triangulate``: fans for quads, ear-clipping for n-gons). Call inside ``object_mode``.
    Raises ``ConformalError`` for a mesh without faces."""
    me = obj_or_mesh.data if isinstance(obj_or_mesh, bpy.types.Object) else obj_or_mesh
    if len(me.polygons) == 0:
        raise ConformalError(f"mesh {me.name!r} has no faces: there is nothing to flatten")
    V = read_positions(me)
    cv = read_corner_verts(me)
    start = read_loop_start(me)
    sizes = np.diff(np.r_[start, len(cv)])
    md = MeshArrays(V=V, corner_verts=cv, sizes=sizes, loop_start=start)
    if triangles:
        md.tri_corners, md.tri_poly = triangulate(cv, sizes, V)
    return md


def read_selection(me, domain='POINT'):
    """(k,) bool selection of the vertices ('POINT') or faces ('FACE') (Object mode arrays)."""
    name, count = {'POINT': ('.select_vert', len(me.vertices)),
                   'FACE': ('.select_poly', len(me.polygons))}[domain]
    out = np.zeros(count, bool)
    attr = me.attributes.get(name)
    if attr is not None:
        attr.data.foreach_get('value', out)
    return out


# --- writing -------------------------------------------------------------------------------------
def active_uv_layer(me, create_name='UVMap'):
    """The active UV map of ``me``, created as ``create_name`` if the mesh has none."""
    layer = me.uv_layers.active
    if layer is None:
        layer = me.uv_layers.new(name=create_name)
        me.uv_layers.active = layer
    return layer


def write_uv(me, loop_uv, layer_name=None):
    """Write per-corner UVs ``loop_uv`` (c,2) into the UV map ``layer_name`` (created if missing) or the
    active UV map (created as "UVMap" if none). Returns the layer's name."""
    loop_uv = np.asarray(loop_uv)
    if loop_uv.shape != (len(me.loops), 2):
        raise ValueError(f"loop_uv must have shape ({len(me.loops)}, 2), got {loop_uv.shape}")
    if layer_name is None:
        layer = active_uv_layer(me)
    else:
        layer = me.uv_layers.get(layer_name) or me.uv_layers.new(name=layer_name)
    layer.uv.foreach_set('vector', np.ascontiguousarray(loop_uv, np.float32).ravel())
    me.update()
    return layer.name


def read_uv(me, layer_name=None):
    """(c,2) float64 per-corner UVs of ``layer_name`` or the active UV map (None if there is none)."""
    layer = me.uv_layers.active if layer_name is None else me.uv_layers.get(layer_name)
    if layer is None:
        return None
    buf = np.empty(len(me.loops) * 2, np.float32)
    layer.uv.foreach_get('vector', buf)
    return buf.reshape(-1, 2).astype(np.float64)


def _ensure_attribute(me, name, data_type, domain, color=False):
    attr = me.attributes.get(name)
    if attr is not None and (attr.data_type != data_type or attr.domain != domain):
        me.attributes.remove(attr)
        attr = None
    if attr is None:
        coll = me.color_attributes if color else me.attributes
        attr = coll.new(name=name, type=data_type, domain=domain)
    return attr


def write_point_float(me, name, values):
    """Write ``values`` (n,) as the FLOAT point attribute ``name`` (replaced if it has another type)."""
    values = np.asarray(values)
    if values.shape != (len(me.vertices),):
        raise ValueError(f"values must have shape ({len(me.vertices)},), got {values.shape}")
    attr = _ensure_attribute(me, name, 'FLOAT', 'POINT')
    attr.data.foreach_set('value', np.ascontiguousarray(values, np.float32))
    me.update()
    return attr


def write_point_vector(me, name, values):
    """Write ``values`` (n,3) as the FLOAT_VECTOR point attribute ``name``."""
    values = np.asarray(values)
    if values.shape != (len(me.vertices), 3):
        raise ValueError(f"values must have shape ({len(me.vertices)}, 3), got {values.shape}")
    attr = _ensure_attribute(me, name, 'FLOAT_VECTOR', 'POINT')
    attr.data.foreach_set('vector', np.ascontiguousarray(values, np.float32).ravel())
    me.update()
    return attr


def write_point_color(me, name, rgba, make_active=True):
    """Write linear RGBA ``rgba`` (n,4) as the FLOAT_COLOR point colour attribute ``name``; with
    ``make_active`` it becomes the active and the render colour attribute (shown by the viewport's
    Attribute colour mode)."""
    rgba = np.asarray(rgba)
    if rgba.shape != (len(me.vertices), 4):
        raise ValueError(f"rgba must have shape ({len(me.vertices)}, 4), got {rgba.shape}")
    attr = _ensure_attribute(me, name, 'FLOAT_COLOR', 'POINT', color=True)
    attr.data.foreach_set('color', np.ascontiguousarray(rgba, np.float32).ravel())
    if make_active:
        me.color_attributes.active_color_name = attr.name
        names = [a.name for a in me.color_attributes]
        me.color_attributes.render_color_index = names.index(attr.name)
    me.update()
    return attr


def bake_scalar(me, name, values, colormap_name='PERCEPTUAL', log=True, centre=None):
    """Bake a per-vertex scalar field ``values`` (n,): FLOAT point attribute ``name``, colour attribute
    ``name + '_color'`` through ``colormap_name`` (log scale if ``log``), and the value range as the
    mesh custom property ``name + '_range'`` = [min, max]. Returns (min, max)."""
    values = np.asarray(values, float)
    lo, hi = float(np.nanmin(values)), float(np.nanmax(values))
    rgba = colormap(normalise(values, lo, hi, log=log, centre=centre), colormap_name)
    write_point_float(me, name, values)
    write_point_color(me, name + '_color', rgba)
    me[name + '_range'] = [lo, hi]
    return lo, hi


# --- reports -------------------------------------------------------------------------------------
def store_report(idblock, key, report):
    """Store a JSON-serialisable dict as a JSON string custom property ``key`` of an ID (mesh/object),
    so it is saved with the file, undone with the data, and readable by the panel and by scripts."""
    idblock[key] = json.dumps(report, default=_json_default)


def load_report(idblock, key):
    """The dict stored by ``store_report``, or None."""
    if idblock is None:
        return None
    raw = idblock.get(key)
    if not raw:
        return None
    try:
        return json.loads(raw)
    except (TypeError, ValueError):
        return None


def _json_default(x):
    if isinstance(x, np.generic):
        return x.item()
    if isinstance(x, np.ndarray):
        return x.tolist()
    return str(x)


# --- progress ------------------------------------------------------------------------------------
class Progress:
    """``wm.progress_begin/update/end`` as a context manager; the object is the callable
    ``progress(fraction, message)`` the core takes. ``message`` also goes to the status bar when there
    is a UI."""

    def __init__(self, context, lo=0.0, hi=1.0):
        self.wm = getattr(context, 'window_manager', None)
        self.workspace = getattr(context, 'workspace', None)
        self.lo, self.hi = lo, hi

    def __enter__(self):
        if self.wm is not None:
            self.wm.progress_begin(0, 1000)
        return self

    def __call__(self, fraction, message=''):
        if self.wm is not None:
            self.wm.progress_update(int(1000 * (self.lo + (self.hi - self.lo) * float(fraction))))
        if message and self.workspace is not None and not bpy.app.background:
            try:
                self.workspace.status_text_set(f"Conformal: {message}")
            except (AttributeError, RuntimeError):
                pass

    def __exit__(self, *exc):
        if self.wm is not None:
            self.wm.progress_end()
        if self.workspace is not None and not bpy.app.background:
            try:
                self.workspace.status_text_set(None)
            except (AttributeError, RuntimeError):
                pass
        return False


# --- edges, seams and selections (islands, Edit-mode selections) ---------------------------------
SELECTION_ATTRIBUTES = ('.select_vert', '.select_edge', '.select_poly',
                        '.uv_select_vert', '.uv_select_edge', '.uv_select_face')
_UV_SELECTION = SELECTION_ATTRIBUTES[3:]


def read_edges(me):
    """(e,2) int64 vertex pairs of the mesh's edges (call in Object mode)."""
    buf = np.empty(2 * len(me.edges), np.int32)
    attr = me.attributes.get('.edge_verts')
    if attr is not None and attr.data_type == 'INT32_2D':
        attr.data.foreach_get('value', buf)
    else:
        me.edges.foreach_get('vertices', buf)
    return buf.reshape(-1, 2).astype(np.int64)


def read_corner_edges(me):
    """(c,) int64 edge of each corner (the edge from the corner's vertex to the next corner's)."""
    buf = np.empty(len(me.loops), np.int32)
    if len(buf):
        attr = me.attributes.get('.corner_edge')
        if attr is not None:
            attr.data.foreach_get('value', buf)
        else:
            me.loops.foreach_get('edge_index', buf)
    return buf.astype(np.int64)


def read_seams(me):
    """(e,) bool: edges marked as UV seams (``use_seam``). Reads the boolean edge attribute directly
    (``uv_seam`` in Blender 5, ``.uv_seam`` before); a mesh without seams has no such attribute."""
    out = np.zeros(len(me.edges), bool)
    for name in ('uv_seam', '.uv_seam'):
        attr = me.attributes.get(name)
        if attr is not None and attr.domain == 'EDGE' and attr.data_type == 'BOOLEAN':
            attr.data.foreach_get('value', out)
            return out
    if len(out):
        me.edges.foreach_get('use_seam', out)
    return out


def read_point_float(me, name):
    """(n,) float64 values of the FLOAT point attribute ``name``, or None if it is absent or has
    another type or domain."""
    attr = me.attributes.get(name)
    if attr is None or attr.domain != 'POINT' or attr.data_type != 'FLOAT':
        return None
    buf = np.empty(len(me.vertices), np.float32)
    attr.data.foreach_get('value', buf)
    return buf.astype(np.float64)


def save_attributes(me, names=SELECTION_ATTRIBUTES):
    """Snapshot of the BOOLEAN attributes ``names`` of ``me``: name -> (domain, values) or None when
    absent. ``restore_attributes`` puts them back bitwise (and removes those that were absent)."""
    saved = {}
    for name in names:
        attr = me.attributes.get(name)
        if attr is None or attr.data_type != 'BOOLEAN':
            saved[name] = None
            continue
        buf = np.zeros(len(attr.data), bool)
        attr.data.foreach_get('value', buf)
        saved[name] = (attr.domain, buf)
    return saved


def restore_attributes(me, saved):
    """Undo changes to the attributes snapshotted by ``save_attributes``."""
    for name, entry in saved.items():
        attr = me.attributes.get(name)
        if entry is None:
            if attr is not None:
                me.attributes.remove(attr)
            continue
        domain, values = entry
        if attr is not None and (attr.domain != domain or attr.data_type != 'BOOLEAN'
                                 or len(attr.data) != len(values)):
            me.attributes.remove(attr)
            attr = None
        if attr is None:
            attr = me.attributes.new(name, 'BOOLEAN', domain)
        attr.data.foreach_set('value', values)
    me.update()


def _set_bool(me, name, domain, values):
    attr = me.attributes.get(name)
    if attr is not None and (attr.domain != domain or attr.data_type != 'BOOLEAN'):
        me.attributes.remove(attr)
        attr = None
    if attr is None:
        attr = me.attributes.new(name, 'BOOLEAN', domain)
    attr.data.foreach_set('value', np.ascontiguousarray(values, bool))


def select_faces_only(me, faces, corner_verts=None, corner_edges=None):
    """Select exactly the polygons ``faces`` ((p,) bool), their vertices and edges, and drop the
    separate UV selection so that UV tools in sync-select mode act on these faces (Object mode).
    Snapshot the selection with ``save_attributes`` first to put it back."""
    faces = np.asarray(faces, bool)
    cv = read_corner_verts(me) if corner_verts is None else corner_verts
    ce = read_corner_edges(me) if corner_edges is None else corner_edges
    start = read_loop_start(me)
    sizes = np.diff(np.r_[start, len(cv)])
    corner_on = np.repeat(faces, sizes)
    verts = np.zeros(len(me.vertices), bool)
    verts[cv[corner_on]] = True
    edges = np.zeros(len(me.edges), bool)
    edges[ce[corner_on]] = True
    _set_bool(me, '.select_vert', 'POINT', verts)
    _set_bool(me, '.select_edge', 'EDGE', edges)
    _set_bool(me, '.select_poly', 'FACE', faces)
    for name in _UV_SELECTION:
        attr = me.attributes.get(name)
        if attr is not None:
            me.attributes.remove(attr)
    me.update()
