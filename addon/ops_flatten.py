"""``bpy.ops.uv.conformal_flatten``: flatten mesh objects conformally, island by island, write per-corner
UVs and bake the conformal factor mu.

What is flattened:

- Objects: in Object mode the active object and every other selected mesh object; in Edit mode every
  object in Edit mode. Linked duplicates (objects sharing one mesh) are flattened once.
- Faces: in Edit mode only the selected faces, as Blender's unwrap does; the UVs of the other faces
  are left bitwise as they were. With no face selected (or all of them) the whole mesh is flattened.
- Islands: edges marked as seams (``use_seam``) and loose parts split the faces into islands; every
  island is flattened on its own (``core.islands.unwrap``) with the chosen boundary mode, holes filled
  virtually (or cut open, or refused), and the islands are arranged without overlap by Blender's own
  ``bpy.ops.uv.pack_islands`` (the core's shelf packing is the fallback). By default all islands keep
  their true relative scale: one texel density everywhere. A mesh (or selection) that is one disk
  without seams is flattened directly by ``core.flatten`` and fitted without packing.

A run has three steps: ``read`` (main thread, bpy), ``compute`` (pure numpy: runs in any thread and
can be cancelled between steps and islands through a ``CancelToken``), ``apply`` (main thread, bpy:
writes). Everything is computed before anything is written, so on bad input the operator reports
the core's message as an ERROR (a ``RuntimeError`` in scripts) and every mesh is untouched; a
cancelled run writes nothing.

``execute`` (scripts, ``blender --background``, the bpy module, the redo panel) runs the steps
synchronously. ``invoke`` (the UI) runs ``compute`` in a worker thread polled by a modal timer for
big meshes, so Esc cancels a long run; modal handlers never fire in background mode, where
``invoke`` falls back to ``execute``."""
from contextlib import contextmanager
from dataclasses import dataclass, field
import threading
import time

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty, FloatProperty

from ..core.mesh import topology
from ..core.errors import ConformalError
from ..core.disk.flatten import flatten
from ..core.mesh.geometry import face_areas
from ..core.atlas.islands import unwrap
from ..core.mesh.measures import jacobians, measures_from_jacobians
from ..core.mesh.validate import check_loose_edges
from . import meshio
from .colormap import colormap as colormap_rgba, normalise
from .prefs import get_prefs

REPORT_KEY = 'conformal_flatten_report'
ATTR_NAME = 'conformal_factor'           # FLOAT point attribute; colour: ATTR_NAME + '_color'
RANGE_KEY = ATTR_NAME + '_range'         # mesh custom property [min, max] of the baked values
THREAD_MIN_TRIANGLES = 20_000            # invoke() computes smaller jobs synchronously
MAX_ISLAND_REPORTS = 100                 # per-island entries kept in the stored report
NO_VALUE_RGBA = (0.5, 0.5, 0.5, 1.0)     # colour of vertices without a baked value

BOUNDARY_ITEMS = [
    ('UNIFORM', "Uniform", "Most uniform conformal factor: maximise min mu / max mu (the paper's objective)"),
    ('AREA', "Area", "Keep the boundary lengths (u = 0 on the boundary): least area distortion in L2"),
    ('FREE', "Free", "Free-boundary least-squares conformal map (LSCM), like Blender's Conformal unwrap"),
]
FIT_ITEMS = [
    ('UNIT_SQUARE', "Unit Square", "Fit the UVs into the 0-1 square, keeping the aspect ratio"),
    ('TRUE_SCALE', "True Scale", "UV area equals the surface area, in mesh units"),
]
PACKER_ITEMS = [
    ('BLENDER', "Pack Islands", "Blender's Pack Islands (exact shapes, rotation); the core's shelf "
                                "packing if it fails"),
    ('SHELF', "Shelf", "The core's shelf packing of the islands' bounding boxes (fast)"),
]
SHAPE_ITEMS = [
    ('AABB', "Bounding Box", "Pack Islands uses bounding boxes, as Blender's Unwrap does (fast)"),
    ('CONCAVE', "Exact Shape", "Pack Islands uses the exact island shapes (tighter; seconds for a few "
                               "dozen islands)"),
    ('CONVEX', "Convex Hull", "Pack Islands uses the islands' convex hulls (can be much slower)"),
]


def mesh_hash(md):
    """A short hash of the base mesh's positions and polygons (``meshio.MeshArrays``), stored in the
    report so other tools can tell whether the mesh changed since it was flattened."""
    import hashlib
    h = hashlib.blake2b(digest_size=12)
    for a in (md.V.astype(np.float32), md.corner_verts.astype(np.int32), md.sizes.astype(np.int32)):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def compute_flatten(md, boundary='UNIFORM', fit='UNIT_SQUARE', progress=None):
    """Flatten ``md`` (``meshio.MeshArrays`` with triangles) as one disk. Returns ``(result, loop_uv
    (c,2), mu_vertex (n,))``: the core's ``FlattenResult``, the per-corner UVs and the per-vertex
    conformal factor sqrt(UV area / 3D area) over each vertex's star. Raises ``ConformalError``."""
    F = md.F
    result = flatten(md.V, F, boundary=boundary.lower(), fit=fit.lower(), progress=progress)
    loop_uv = result.uv[md.corner_verts]
    mu_vertex = meshio.face_to_vertex(F, result.mu, face_areas(md.V, F), md.n_vertices, power=2.0)
    return result, loop_uv, mu_vertex


# ----------------------------------------------------------------------------------------------
# options, cancellation
# ----------------------------------------------------------------------------------------------
@dataclass
class FlattenOptions:
    """Everything a run needs besides the objects (the operator's properties)."""
    boundary: str = 'UNIFORM'
    fit: str = 'UNIT_SQUARE'
    bake: bool = True
    fill_holes: bool = True
    cut_holes: bool = False
    keep_relative_scale: bool = True
    skip_bad_islands: bool = False
    packer: str = 'BLENDER'
    pack_shape: str = 'AABB'
    pack_rotate: bool = True
    margin: float = 0.001
    shared_layout: bool = False
    colormap: str = None
    max_faces: int = 5_000_000

    @property
    def holes(self):
        """The core's hole mode: 'fill', 'cut' or 'error'."""
        return 'fill' if self.fill_holes else ('cut' if self.cut_holes else 'error')


class Cancelled(Exception):
    """The run was cancelled (Esc or ``CancelToken.cancel``); nothing was written."""


class CancelToken:
    """Thread-safe cancellation flag, checked by ``compute_job`` between the core's steps and between
    islands (every progress report of the core)."""

    def __init__(self):
        self._event = threading.Event()

    def cancel(self):
        self._event.set()

    @property
    def cancelled(self):
        return self._event.is_set()

    def check(self):
        """Raise ``Cancelled`` if the run was cancelled."""
        if self._event.is_set():
            raise Cancelled("cancelled: nothing was written")


# ----------------------------------------------------------------------------------------------
# objects and modes
# ----------------------------------------------------------------------------------------------
def target_objects(context):
    """The mesh objects to flatten, one per mesh (linked duplicates once), the active one first: in
    Edit mode the objects in Edit mode, otherwise the active object and the selected ones. Returns a
    list of (object, [names of all the target objects using its mesh]). Raises ``ConformalError``
    when there is no active object or no mesh among them."""
    active = getattr(context, 'active_object', None)
    if active is None:
        raise ConformalError("no active object: select a mesh object and make it active")
    view_layer = context.view_layer
    if active.mode == 'EDIT':
        cands = [active] + [o for o in view_layer.objects if o.mode == 'EDIT' and o is not active]
    else:
        cands = [active] + [o for o in (getattr(context, 'selected_objects', None) or [])
                            if o is not active]
    meshes = [o for o in cands if o.type == 'MESH']
    if not meshes:
        meshio.mesh_object(context, active)          # raises "... is a curve, not a mesh: ..."
        raise ConformalError("no mesh object is selected: select mesh objects")
    by_mesh = {}
    for o in meshes:
        meshio.mesh_object(context, o)               # raises for meshes linked from a library
        by_mesh.setdefault(o.data.as_pointer(), []).append(o)
    return [(objs[0], [o.name for o in objs]) for objs in by_mesh.values()]


@contextmanager
def _selected_only(context, objs):
    """For the body, exactly ``objs`` are selected and ``objs[0]`` is active (mode switches and UV
    operators act on the selected/active objects); the selection and the active object are put back
    afterwards."""
    view_layer = context.view_layer
    active = view_layer.objects.active
    selected = [o for o in view_layer.objects if o.select_get()]
    try:
        for o in selected:
            o.select_set(False)
        for o in objs:
            o.select_set(True)
        view_layer.objects.active = objs[0]
        yield
    finally:
        for o in objs:
            o.select_set(False)
        for o in selected:
            o.select_set(True)
        view_layer.objects.active = active


def _enter_mode(context, objs, mode):
    """Put exactly ``objs`` (all in Object mode) into ``mode``."""
    with _selected_only(context, objs):
        bpy.ops.object.mode_set(mode=mode)


@contextmanager
def _in_edit_mode(context, objs):
    """For the body, exactly ``objs`` are in Edit mode, selected, ``objs[0]`` active; back to Object
    mode afterwards."""
    with _selected_only(context, objs):
        bpy.ops.object.mode_set(mode='EDIT')
        try:
            yield
        finally:
            bpy.ops.object.mode_set(mode='OBJECT')


@contextmanager
def objects_in_object_mode(context, obj):
    """Run the body with every object that shares ``obj``'s mode in Object mode (leaving Edit mode
    writes the edit meshes), then put exactly those objects back into their mode, also on errors."""
    mode = obj.mode
    if mode == 'OBJECT':
        yield
        return
    in_mode = [obj] + [o for o in context.view_layer.objects if o.mode == mode and o is not obj]
    meshio._set_mode(obj, 'OBJECT')
    if obj.mode != 'OBJECT':                 # the override did not reach it: use the view layer
        _enter_mode(context, [obj], 'OBJECT')
    try:
        yield
    finally:
        alive = []
        for o in in_mode:
            try:
                if o.mode == 'OBJECT' and o.name in context.view_layer.objects:
                    alive.append(o)
            except ReferenceError:
                pass
        if alive:
            _enter_mode(context, alive, mode)


# ----------------------------------------------------------------------------------------------
# read (main thread)
# ----------------------------------------------------------------------------------------------
@dataclass
class MeshJob:
    """One mesh to flatten, read in Object mode. ``tri_sel`` (m,) bool marks the triangles to flatten
    (None: all); ``seams`` (k,2) vertex pairs: the seam edges of those faces; ``loose_edges`` (k,2):
    edges in no face (checked on whole-mesh runs); ``counts`` (vertices, edges, corners, polygons)
    detect a mesh changed between read and apply."""
    obj: object
    users: list
    md: meshio.MeshArrays
    tri_sel: np.ndarray
    seams: np.ndarray
    loose_edges: np.ndarray
    counts: tuple
    selection: str

    @property
    def n_triangles(self):
        return int(len(self.md.tri_corners) if self.tri_sel is None else self.tri_sel.sum())


def read_job(obj, users=None, use_selection=None):
    """Read mesh object ``obj`` (in Object mode) into a ``MeshJob``. ``use_selection``: only the
    selected faces (default: when ``obj`` was in Edit mode; pass it explicitly inside
    ``objects_in_object_mode``). Raises ``ConformalError`` (no faces)."""
    me = obj.data
    md = meshio.read_mesh(me)
    E = meshio.read_edges(me)
    seam = meshio.read_seams(me)
    ce = meshio.read_corner_edges(me)
    sel = meshio.read_selection(me, 'FACE') if use_selection else None
    selection = 'all'
    if sel is not None:
        if sel.all():
            sel = None
        elif not sel.any():
            sel, selection = None, 'all (no face selected)'
        else:
            selection = 'selected faces'
    if sel is None:
        tri_sel = None
        corner_on = np.ones(len(ce), bool)
    else:
        tri_sel = sel[md.tri_poly]
        corner_on = np.repeat(sel, md.sizes)
    edge_used = np.zeros(len(E), bool)
    edge_used[ce[corner_on]] = True
    if sel is None:
        loose = E[~edge_used]
    else:
        loose = np.zeros((0, 2), np.int64)
    return MeshJob(obj=obj, users=list(users or [obj.name]), md=md, tri_sel=tri_sel,
                   seams=E[seam & edge_used], loose_edges=loose,
                   counts=(len(me.vertices), len(me.edges), len(me.loops), len(me.polygons)),
                   selection=selection)


# ----------------------------------------------------------------------------------------------
# compute (pure numpy, any thread)
# ----------------------------------------------------------------------------------------------
@dataclass
class JobResult:
    """What ``compute_job`` found for one ``MeshJob``. ``tris`` (k,) the flattened triangles (islands
    that failed with ``skip_bad_islands`` left out); ``uv_tri`` (k,3,2) their corner UVs (the core's
    layout: fitted, or shelf-packed); ``island`` (k,) island of each; ``direct``: one disk flattened
    by ``core.flatten`` (``result`` is its FlattenResult), else ``result`` is the core's
    UnwrapResult."""
    tris: np.ndarray
    uv_tri: np.ndarray
    island: np.ndarray
    direct: bool
    result: object
    islands: list = field(default_factory=list)
    core_report: dict = field(default_factory=dict)
    seconds: float = 0.0


def _single_disk(F, n):
    """Cheap test: ``F`` (m,3) is one edge-connected piece with one boundary loop. Input too broken to
    judge counts as a disk: ``core.flatten`` then validates it and reports what is wrong."""
    try:
        if topology.face_components(F, n)[0] != 1:
            return False
        return len(topology.boundary_loops(F, n)) == 1
    except Exception:          # noqa: BLE001  (validation, with a proper message, comes next)
        return True


def _addon_wording(msg):
    """The core's advice phrased with the operator's option names."""
    return (msg.replace("fill the holes (holes='fill', CLI --holes fill)", "enable Fill Holes")
               .replace("cut them open (holes='cut')", "enable Cut Holes"))


def compute_job(job, opts, progress=None, token=None):
    """Flatten the faces of ``job`` (``MeshJob``) with ``opts`` (``FlattenOptions``). Pure numpy: no
    bpy, safe in a worker thread. ``progress(fraction, message)`` is called between steps;
    ``token`` (``CancelToken``) is checked at each of them and raises ``Cancelled``. Returns
    ``JobResult``; raises ``ConformalError`` for bad input."""
    token = token or CancelToken()
    report = progress or (lambda f, msg: None)

    def step(f, msg):
        token.check()
        report(f, msg)

    t0 = time.perf_counter()
    step(0.0, 'preparing')
    md = job.md
    F_all = md.F
    if job.tri_sel is None:
        tris = np.arange(len(F_all))
        V, F, seams = md.V, F_all, job.seams
    else:
        tris = np.nonzero(job.tri_sel)[0]
        used = np.unique(F_all[tris])
        remap = np.full(md.n_vertices, -1, np.int64)
        remap[used] = np.arange(len(used))
        V, F, seams = md.V[used], remap[F_all[tris]], remap[job.seams]
    if len(job.loose_edges):
        check_loose_edges(job.loose_edges, F_all)
    boundary = opts.boundary.lower()
    if len(seams) == 0 and _single_disk(F, len(V)):
        res = flatten(V, F, boundary=boundary, fit=opts.fit.lower(), progress=step,
                      max_faces=opts.max_faces)
        if not np.isfinite(res.uv).all():
            raise ConformalError("the flattening produced non-finite UVs: the mesh is too degenerate; "
                                 "try the 'area' boundary mode or clean the mesh")
        island_rep = {'island': 1, 'triangles': len(F), 'loops': 1}
        island_rep.update({k: res.report.get(k) for k in ('flips', 'mu_ratio', 'qc_mean', 'qc_max')})
        out = JobResult(tris=tris, uv_tri=res.uv[F], island=np.zeros(len(F), np.int64), direct=True,
                        result=res, islands=[island_rep], core_report=res.report)
    else:
        try:
            res = unwrap(V, F, seams, boundary=boundary, holes=opts.holes,
                         island_scale='true' if opts.keep_relative_scale else 'normalise',
                         pack=True, margin=0.01, fit=opts.fit.lower(),
                         on_error='skip' if opts.skip_bad_islands else 'raise',
                         tri_poly=md.tri_poly[tris], progress=step, max_faces=opts.max_faces)
        except ConformalError as exc:
            raise ConformalError(_addon_wording(str(exc))) from None
        ok = res.ok
        uv_tri = res.uv[res.F]
        if not np.isfinite(uv_tri[ok]).all():
            raise ConformalError("the flattening produced non-finite UVs: the mesh is too degenerate; "
                                 "try the 'area' boundary mode or clean the mesh")
        for r in res.islands:
            if 'error' in r:
                r['error'] = _addon_wording(r['error'])
        out = JobResult(tris=tris[ok], uv_tri=uv_tri[ok], island=res.face_island[ok], direct=False,
                        result=res, islands=res.islands, core_report=res.report)
    step(1.0, 'flattened')
    out.seconds = time.perf_counter() - t0
    return out


# ----------------------------------------------------------------------------------------------
# apply (main thread)
# ----------------------------------------------------------------------------------------------
def _job_loops(job, res):
    """(k,3) corner (loop) indices of the flattened triangles."""
    return job.md.tri_corners[res.tris]


def _write_uvs(me, loops, uv_tri):
    """Write the corner UVs ``uv_tri`` (k,3,2) of the corners ``loops`` (k,3) into the active UV map;
    the other corners keep their float32 values bit for bit. Returns the layer's name."""
    old = meshio.read_uv(me)
    new = np.zeros((len(me.loops), 2), np.float32) if old is None else old.astype(np.float32)
    new[loops.ravel()] = uv_tri.reshape(-1, 2)
    return meshio.write_uv(me, new)


def _pack_with_blender(context, objs, faces, opts):
    """Arrange the islands of the faces ``faces[i]`` ((p,) bool) of mesh objects ``objs`` (Object
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
        with _in_edit_mode(context, objs):
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


def _bake(me, mu_vertex, colormap_name):
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


def _final_measures(job, res, uv_tri):
    """Measures and per-triangle mu of the written layout ``uv_tri`` (k,3,2), on the real (flattened)
    faces only, as a triangle soup so that split vertices need no bookkeeping."""
    k = len(res.tris)
    Vs = job.md.V[job.md.F[res.tris]].reshape(-1, 3)
    Fs = np.arange(3 * k).reshape(k, 3)
    UVs = uv_tri.reshape(-1, 2).astype(np.float64)
    return measures_from_jacobians(*jacobians(Vs, Fs, UVs))


def _island_summary(r):
    keep = ('island', 'triangles', 'vertices', 'loops', 'holes', 'flips', 'mu_ratio', 'qc_mean',
            'qc_max', 'overlaps', 'bound_vertex', 'error')
    return {k: r[k] for k in keep if k in r}


class FlattenRun:
    """One operator call: ``read`` -> ``compute`` (or ``start``/``done``/``cancel`` in a worker thread)
    -> ``apply``. ``objects``: list of (object, user names) (default ``target_objects(context)``)."""

    def __init__(self, context, opts, objects=None):
        self.opts = opts
        self.targets = objects if objects is not None else target_objects(context)
        self.jobs = None
        self.results = None
        self.error = None
        self.token = CancelToken()
        self.fraction, self.message = 0.0, ''
        self.thread = None
        self.t0 = time.perf_counter()
        self.t_read = 0.0

    # read ---------------------------------------------------------------------------------------
    def read(self, context):
        """Read every target mesh (leaves and restores the objects' mode)."""
        t = time.perf_counter()
        first = self.targets[0][0]
        edit = first.mode == 'EDIT'
        with objects_in_object_mode(context, first):
            self._read_all(edit)
        self.t_read = time.perf_counter() - t

    def _read_all(self, use_selection):
        self.jobs = [read_job(obj, users, use_selection) for obj, users in self.targets]

    @property
    def n_triangles(self):
        return sum(j.n_triangles for j in self.jobs or [])

    # compute ------------------------------------------------------------------------------------
    def compute(self, progress=None):
        """Compute every job (no bpy). Raises ``ConformalError`` or ``Cancelled``."""
        total = max(1, self.n_triangles)
        done = 0
        results = []
        for i, job in enumerate(self.jobs):
            base, span = done / total, job.n_triangles / total
            name = job.users[0]

            def sub(f, msg, base=base, span=span, name=name):
                self.fraction = base + span * f
                self.message = f"{name}: {msg}" if len(self.jobs) > 1 else msg
                if progress is not None:
                    progress(self.fraction, self.message)

            try:
                results.append(compute_job(job, self.opts, sub, self.token))
            except ConformalError as exc:
                msg = str(exc)
                if len(self.jobs) > 1:
                    msg = f"object {name!r}: {msg}"
                raise ConformalError(msg) from None
            done += job.n_triangles
        self.token.check()
        self.results = results
        return results

    def _worker(self):
        try:
            self.compute()
        except (ConformalError, Cancelled) as exc:
            self.error = exc
        except Exception as exc:        # noqa: BLE001  (reported to the user by the modal operator)
            self.error = exc

    def start(self):
        """Run ``compute`` in a daemon worker thread."""
        self.thread = threading.Thread(target=self._worker, name='conformal_flatten', daemon=True)
        self.thread.start()

    @property
    def done(self):
        return self.thread is not None and not self.thread.is_alive()

    def cancel(self):
        """Ask the computation to stop at its next step; ``apply`` is then refused."""
        self.token.cancel()

    # apply --------------------------------------------------------------------------------------
    def apply(self, context):
        """Write the results (leaves and restores the objects' mode). Returns the per-mesh reports."""
        first = self.targets[0][0]
        with objects_in_object_mode(context, first):
            return self._apply_all(context)

    def _apply_all(self, context):
        if self.token.cancelled:
            raise Cancelled("cancelled: nothing was written")
        if self.results is None:
            raise ConformalError("nothing was computed")
        opts = self.opts
        for job in self.jobs:
            try:
                me = job.obj.data
            except ReferenceError:
                raise ConformalError("an object was deleted while it was being flattened: nothing was "
                                     "written") from None
            if (len(me.vertices), len(me.edges), len(me.loops), len(me.polygons)) != job.counts:
                raise ConformalError(f"mesh {me.name!r} changed while it was being flattened: nothing "
                                     "was written; run the operator again")
        t = time.perf_counter()
        uv_names = []
        for job, res in zip(self.jobs, self.results):
            uv_names.append(_write_uvs(job.obj.data, _job_loops(job, res), res.uv_tri))
        # arrange the islands
        packer = {}
        pairs = [(j, r) for j, r in zip(self.jobs, self.results) if not r.direct or opts.shared_layout]
        if opts.shared_layout and len(self.jobs) > 1 and opts.packer == 'SHELF':
            pairs = []      # each mesh keeps its own shelf layout; noted in the reports
        groups = [pairs] if opts.shared_layout else [[p] for p in pairs]
        for group in groups:
            if not group:
                continue
            how, note = 'shelf', None
            if opts.packer == 'BLENDER':
                objs = [j.obj for j, _ in group]
                faces = []
                for j, r in group:
                    f = np.zeros(len(j.md.sizes), bool)
                    f[j.md.tri_poly[r.tris]] = True
                    faces.append(f)
                note = _pack_with_blender(context, objs, faces, opts)
                how = 'pack_islands' if note is None else 'shelf'
                if note is not None:
                    note = f"Pack Islands failed ({note}); the core's shelf packing is kept"
            if opts.fit == 'TRUE_SCALE' and how == 'pack_islands':
                self._rescale_true(group)
            for j, _ in group:
                packer[j.obj.data.as_pointer()] = (how, note)
        t_write = time.perf_counter() - t
        # measure what was written, bake, report
        reports = []
        colormap = opts.colormap or get_prefs(context).colormap
        for job, res, uv_name in zip(self.jobs, self.results, uv_names):
            me = job.obj.data
            how, note = packer.get(me.as_pointer(), ('none' if res.direct else 'shelf', None))
            reports.append(self._finish(job, res, uv_name, how, note, colormap, t_write))
        return reports

    def _rescale_true(self, group):
        """After Pack Islands (which fits the unit square), scale the group's UVs back to mesh units
        (UV area = 3D area over the flattened faces), one factor for the whole group."""
        a3, auv = 0.0, 0.0
        data = []
        for job, res in group:
            me = job.obj.data
            uv = meshio.read_uv(me)
            loops = _job_loops(job, res)
            W = uv[loops]
            e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
            auv += float(np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum() / 2)
            a3 += float(face_areas(job.md.V, job.md.F[res.tris]).sum())
            data.append((me, uv, loops))
        if not auv > 0:
            return
        s = np.sqrt(a3 / auv)
        for me, uv, loops in data:
            new = uv.astype(np.float32)
            idx = np.unique(loops)
            new[idx] = (uv[idx] * s).astype(np.float32)
            meshio.write_uv(me, new)

    def _finish(self, job, res, uv_name, packer, pack_note, colormap, t_write):
        me = job.obj.data
        md = job.md
        opts = self.opts
        loops = _job_loops(job, res)
        uv_tri = meshio.read_uv(me)[loops]
        F_done = md.F[res.tris]
        if res.direct:
            core = res.core_report
            meas = {k: core.get(k) for k in ('faces', 'flips', 'mu_ratio', 'mu_ratio_p1_p99', 'qc_mean',
                                              'qc_max')}
            mu_tri = res.result.mu
        else:
            meas, mu_tri = _final_measures(job, res, uv_tri)
        rng = None
        if opts.bake:
            mu_vertex = meshio.face_to_vertex(F_done, mu_tri, face_areas(md.V, F_done), md.n_vertices,
                                              power=2.0)
            rng = _bake(me, mu_vertex, colormap)
        core = res.core_report
        isl = res.islands
        ok_isl = [r for r in isl if 'error' not in r]
        report = {
            'object': job.users[0], 'objects': job.users, 'mesh': me.name,
            'boundary': opts.boundary, 'fit': opts.fit, 'uv_map': uv_name,
            'vertices': md.n_vertices, 'polygons': int(len(md.sizes)),
            'triangles': int(len(res.tris)), 'selection': job.selection,
            'flattened_polygons': int(len(np.unique(md.tri_poly[res.tris]))),
            'islands': len(isl), 'islands_failed': len(isl) - len(ok_isl),
            'seams': int(len(job.seams)),
            'holes': opts.holes,
            'holes_filled': int(sum(r.get('holes', {}).get('filled', 0) for r in ok_isl)),
            'holes_cut': int(sum(r.get('holes', {}).get('cut', 0) for r in ok_isl)),
            'relative_scale': 'true' if (opts.keep_relative_scale or res.direct) else 'normalised',
            'packer': packer, 'pack_note': pack_note,
            'mu_ratio': meas.get('mu_ratio'), 'mu_ratio_p1_p99': meas.get('mu_ratio_p1_p99'),
            'bound_vertex': core.get('bound_vertex') if res.direct else None,
            'vertex_ratio': core.get('vertex_ratio') if res.direct else None,
            'qc_mean': meas.get('qc_mean'), 'qc_max': meas.get('qc_max'), 'flips': meas.get('flips'),
            'mu_triangle_range': [float(np.nanmin(mu_tri)), float(np.nanmax(mu_tri))],
            'baked': bool(opts.bake), 'conformal_factor_range': list(rng) if rng else None,
            'seconds': {'read': round(self.t_read, 4), 'flatten': round(res.seconds, 4),
                        'write': round(t_write, 4), 'total': round(time.perf_counter() - self.t0, 4)},
            'core_seconds': core.get('seconds'), 'mesh_hash': mesh_hash(md),
            'island_reports': [_island_summary(r) for r in isl[:MAX_ISLAND_REPORTS]],
        }
        meshio.store_report(me, REPORT_KEY, report)
        return report

    # synchronous --------------------------------------------------------------------------------
    def run(self, context, progress=None):
        """read + compute + apply in this thread, with one mode switch. Returns the reports."""
        first = self.targets[0][0]
        edit = first.mode == 'EDIT'
        with objects_in_object_mode(context, first):
            t = time.perf_counter()
            self._read_all(edit)
            self.t_read = time.perf_counter() - t
            if progress is not None:
                progress(0.02, 'read meshes')
            self.compute(None if progress is None else
                         (lambda f, msg: progress(0.02 + 0.9 * f, msg)))
            reports = self._apply_all(context)
            if progress is not None:
                progress(1.0, 'done')
            return reports


def flatten_object(context, obj, boundary='UNIFORM', fit='UNIT_SQUARE', bake=True, colormap=None,
                   **options):
    """Flatten mesh object ``obj`` (or the active object) and write the result (see the module
    docstring; Edit mode: its selected faces). Extra ``options`` are ``FlattenOptions`` fields.
    Returns the report dict (also stored as JSON in ``obj.data[REPORT_KEY]``). Raises
    ``ConformalError`` with nothing written. Usable from scripts without the operator."""
    obj = meshio.mesh_object(context, obj)
    opts = FlattenOptions(boundary=boundary, fit=fit, bake=bake, colormap=colormap, **options)
    run = FlattenRun(context, opts, objects=[(obj, [obj.name])])
    with meshio.Progress(context) as progress:
        return run.run(context, progress)[0]


def summary_line(r):
    """One line for the status bar: islands, holes, ratio, bound, flips, conformality, range, time."""
    parts = [f"Conformal flatten {r['object']!r} ({r['boundary'].lower()}): {r['triangles']} triangles"]
    n_isl = r.get('islands')
    if n_isl and n_isl > 1:
        parts.append(f"{n_isl} islands")
    if r.get('islands_failed'):
        parts.append(f"{r['islands_failed']} island(s) skipped")
    if r.get('holes_filled'):
        parts.append(f"filled {r['holes_filled']} hole{'s' if r['holes_filled'] != 1 else ''}")
    if r.get('holes_cut'):
        parts.append(f"cut {r['holes_cut']} hole{'s' if r['holes_cut'] != 1 else ''} open")
    if r.get('selection') == 'selected faces':
        parts.append(f"{r.get('flattened_polygons')} selected faces")
    parts.append(f"mu ratio {r['mu_ratio']:.4g}")
    if r.get('bound_vertex') is not None:
        parts.append(f"certified bound {r['bound_vertex']:.4g}")
    parts.append(f"{r['flips']} flips")
    parts.append(f"qc mean {r['qc_mean']:.4f}")
    if r.get('conformal_factor_range'):
        lo, hi = r['conformal_factor_range']
        parts.append(f"mu in [{lo:.4g}, {hi:.4g}]")
    parts.append(f"{r['seconds']['total']:.2f} s")
    return ', '.join(parts)


def run_summary(reports):
    """The operator's INFO line for one or several meshes."""
    if len(reports) == 1:
        return summary_line(reports[0])
    isl = sum(r['islands'] for r in reports)
    holes = sum(r['holes_filled'] for r in reports)
    flips = sum(r['flips'] for r in reports)
    worst_qc = max(r['qc_mean'] for r in reports)
    worst_mu = min(r['mu_ratio'] for r in reports)
    total = max(r['seconds']['total'] for r in reports)
    text = (f"Conformal flatten: {len(reports)} meshes ({', '.join(r['object'] for r in reports)}), "
            f"{isl} islands")
    if holes:
        text += f", filled {holes} hole{'s' if holes != 1 else ''}"
    return text + (f", worst mu ratio {worst_mu:.4g}, {flips} flips, worst qc mean {worst_qc:.4f}, "
                   f"{total:.2f} s")


def warnings_of(reports):
    """WARNING lines: skipped islands, packing fallbacks."""
    out = []
    for r in reports:
        for isl in r.get('island_reports', []):
            if 'error' in isl:
                out.append(f"{r['object']!r}: skipped {isl['error']}")
        if r.get('pack_note'):
            out.append(f"{r['object']!r}: {r['pack_note']}")
    return out


# ----------------------------------------------------------------------------------------------
# operator
# ----------------------------------------------------------------------------------------------
class UV_OT_conformal_flatten(bpy.types.Operator):
    """Flatten the selected meshes conformally with the most uniform scale, island by island (seams),
    only the selected faces in Edit mode; write UVs and bake mu. Esc cancels a long run"""
    bl_idname = 'uv.conformal_flatten'
    bl_label = "Conformal Flatten"
    bl_options = {'REGISTER', 'UNDO'}

    boundary: EnumProperty(name="Boundary", items=BOUNDARY_ITEMS, default='UNIFORM',
                           description="How the boundary of each flattened island is chosen")
    fit: EnumProperty(name="Fit", items=FIT_ITEMS, default='UNIT_SQUARE',
                      description="How the UVs are scaled")
    bake: BoolProperty(name="Bake Conformal Factor", default=True,
                       description="Write mu as the point attribute 'conformal_factor' and the colour "
                                   "attribute 'conformal_factor_color'")
    fill_holes: BoolProperty(name="Fill Holes", default=True,
                             description="Fill the holes of an island virtually for the computation (a "
                                         "temporary cap, removed afterwards); the longest boundary "
                                         "loop stays the outer boundary")
    cut_holes: BoolProperty(name="Cut Holes", default=False,
                            description="When Fill Holes is off: cut every hole open to the outer "
                                        "boundary along a shortest edge path (instead of an error)")
    keep_relative_scale: BoolProperty(name="Keep Relative Scale", default=True,
                                      description="All islands keep their true size relative to each "
                                                  "other: one texel density everywhere. Off: every "
                                                  "island gets the same UV area")
    skip_bad_islands: BoolProperty(name="Skip Bad Islands", default=False,
                                   description="Flatten the islands that can be flattened and leave the "
                                               "others' UVs as they were (with a warning), instead of "
                                               "an error")
    packer: EnumProperty(name="Packing", items=PACKER_ITEMS, default='BLENDER',
                         description="How the islands are arranged without overlap")
    pack_shape: EnumProperty(name="Pack Shape", items=SHAPE_ITEMS, default='AABB',
                             description="Shape Pack Islands uses for each island")
    pack_rotate: BoolProperty(name="Rotate Islands", default=True,
                              description="Pack Islands may rotate islands (a rotation keeps the map "
                                          "conformal)")
    margin: FloatProperty(name="Margin", default=0.001, min=0.0, max=1.0, precision=3,
                          description="Space between packed islands (Pack Islands' scaled margin)")
    shared_layout: BoolProperty(name="Shared Layout", default=False,
                                description="Pack the islands of all the meshes into one UV layout "
                                            "(one texel density across objects) instead of one "
                                            "layout per mesh")

    @classmethod
    def poll(cls, context):
        # Deliberately permissive: a wrong selection gets an ERROR report that says what to do.
        return True

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        col = layout.column()
        col.prop(self, 'boundary')
        col.prop(self, 'fit')
        col.prop(self, 'bake')
        col = layout.column(heading="Islands")
        col.prop(self, 'fill_holes')
        sub = col.row()
        sub.active = not self.fill_holes
        sub.prop(self, 'cut_holes')
        col.prop(self, 'keep_relative_scale')
        col.prop(self, 'skip_bad_islands')
        col = layout.column(heading="Packing")
        col.prop(self, 'packer')
        sub = col.column()
        sub.active = self.packer == 'BLENDER'
        sub.prop(self, 'pack_shape')
        sub.prop(self, 'pack_rotate')
        sub.prop(self, 'margin')
        col.prop(self, 'shared_layout')

    def flatten_options(self, context):
        return FlattenOptions(boundary=self.boundary, fit=self.fit, bake=self.bake,
                              fill_holes=self.fill_holes, cut_holes=self.cut_holes,
                              keep_relative_scale=self.keep_relative_scale,
                              skip_bad_islands=self.skip_bad_islands, packer=self.packer,
                              pack_shape=self.pack_shape, pack_rotate=self.pack_rotate,
                              margin=self.margin, shared_layout=self.shared_layout,
                              colormap=get_prefs(context).colormap,
                              max_faces=get_prefs(context).max_faces)

    def _done(self, reports):
        for w in warnings_of(reports):
            self.report({'WARNING'}, w)
        self.report({'INFO'}, run_summary(reports))
        return {'FINISHED'}

    def execute(self, context):
        try:
            run = FlattenRun(context, self.flatten_options(context))
            with meshio.Progress(context) as progress:
                reports = run.run(context, progress)
        except ConformalError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        return self._done(reports)

    # UI: worker thread + modal timer, Esc cancels ------------------------------------------------
    def invoke(self, context, event):
        if bpy.app.background or context.window is None:
            return self.execute(context)
        try:
            run = FlattenRun(context, self.flatten_options(context))
            run.read(context)
        except ConformalError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        if run.n_triangles < THREAD_MIN_TRIANGLES:
            try:
                with meshio.Progress(context) as progress:
                    run.compute(progress)
                    reports = run.apply(context)
            except ConformalError as exc:
                self.report({'ERROR'}, str(exc))
                return {'CANCELLED'}
            return self._done(reports)
        self._run = run
        wm = context.window_manager
        wm.progress_begin(0, 1000)
        self._timer = wm.event_timer_add(0.1, window=context.window)
        wm.modal_handler_add(self)
        run.start()
        return {'RUNNING_MODAL'}

    def _cleanup(self, context):
        wm = context.window_manager
        if getattr(self, '_timer', None) is not None:
            wm.event_timer_remove(self._timer)
            self._timer = None
        wm.progress_end()
        try:
            context.workspace.status_text_set(None)
        except (AttributeError, RuntimeError):
            pass

    def modal(self, context, event):
        run = self._run
        if event.type in {'ESC', 'RIGHTMOUSE'} and event.value == 'PRESS':
            run.cancel()
            self._cleanup(context)
            self.report({'WARNING'}, "Conformal flatten cancelled: nothing was written")
            return {'CANCELLED'}
        if event.type != 'TIMER':
            return {'RUNNING_MODAL'}        # block other input while the meshes are being flattened
        context.window_manager.progress_update(int(1000 * min(1.0, run.fraction)))
        try:
            context.workspace.status_text_set(f"Conformal: {run.message} (Esc to cancel)")
        except (AttributeError, RuntimeError):
            pass
        if not run.done:
            return {'RUNNING_MODAL'}
        self._cleanup(context)
        if isinstance(run.error, Cancelled):
            self.report({'WARNING'}, "Conformal flatten cancelled: nothing was written")
            return {'CANCELLED'}
        if run.error is not None:
            msg = str(run.error) if isinstance(run.error, ConformalError) else \
                f"internal error: {type(run.error).__name__}: {run.error}"
            self.report({'ERROR'}, msg)
            return {'CANCELLED'}
        try:
            reports = run.apply(context)
        except (ConformalError, Cancelled) as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        return self._done(reports)


def _holes_text(r):
    if r.get('holes_filled'):
        return f"{r['holes_filled']} filled"
    if r.get('holes_cut'):
        return f"{r['holes_cut']} cut open"
    return "none"


ISLAND_ROWS = [
    ("Islands", lambda r: f"{r['islands']}" + (f" ({r['islands_failed']} skipped)"
                                               if r.get('islands_failed') else "")),
    ("Holes", _holes_text),
    ("Faces", lambda r: "selected" if r.get('selection') == 'selected faces' else "all"),
    ("Packing", lambda r: {'pack_islands': "Pack Islands", 'shelf': "shelf",
                           'none': "none (one disk)"}.get(r.get('packer'), "-")),
    ("Objects", lambda r: str(len(r.get('objects') or [r.get('object')]))),
]


def draw_islands_section(layout, context):
    """Sidebar section (``ui.add_section``): islands, holes and packing of the active mesh's last
    flatten."""
    from .ui import draw_report
    obj = getattr(context, 'active_object', None)
    report = meshio.load_report(obj.data, REPORT_KEY) if obj is not None and obj.type == 'MESH' else None
    if report is None or 'islands' not in report:
        layout.label(text="Seams split the mesh into islands")
        return
    draw_report(layout, report, ISLAND_ROWS)


def menu_unwrap(self, context):
    self.layout.separator()
    self.layout.operator(UV_OT_conformal_flatten.bl_idname, text="Conformal Flatten (Uniform)")


CLASSES = (UV_OT_conformal_flatten,)


def register():
    from . import ui             # not at module level: ui imports this module
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.IMAGE_MT_uvs_unwrap.append(menu_unwrap)
    ui.add_section("Islands", draw_islands_section)


def unregister():
    from . import ui
    ui.remove_section(draw_islands_section)
    bpy.types.IMAGE_MT_uvs_unwrap.remove(menu_unwrap)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
