"""``bpy.ops.uv.conformal_flatten``: flatten mesh objects conformally, island by island, write per-corner
UVs and bake the conformal factor mu.

What is flattened:

- Objects: in Object mode the active object and every other selected mesh object; in Edit mode every
  object in Edit mode. Linked duplicates (objects sharing one mesh) are flattened once.
- Faces: in Edit mode only the selected faces, as Blender's unwrap does; the UVs of the other faces
  are left bitwise as they were. With no face selected (or all of them) the whole mesh is flattened.
- Islands: edges marked as seams (``use_seam``) and loose parts split the faces into islands; every
  island is flattened on its own (``core.unwrap``) with the chosen boundary mode, holes filled
  virtually (or cut open, or refused), and the islands are arranged without overlap by Blender's own
  ``bpy.ops.uv.pack_islands`` (the core's shelf packing is the fallback). By default all islands keep
  their true relative scale: one texel density everywhere. Which path a mesh takes (a disk
  flattened directly, or islands) is the core's decision: this module never looks at topology.

A run has three steps: ``read`` (main thread, bpy: ``targets.py``), ``compute`` (``job.py``: one call
of ``core.unwrap`` per mesh, no bpy, runs in any thread and can be cancelled between steps and islands
through a ``CancelToken``), ``apply`` (main thread, bpy: ``apply.py`` writes). Everything is
computed before anything is written, so on bad input the operator reports the problem and what to do
(the remedy worded by ``wording.py``) as an ERROR (a ``RuntimeError`` in scripts) and every mesh is
untouched; a cancelled run writes nothing.

``execute`` (scripts, ``blender --background``, the bpy module, the redo panel) runs the steps
synchronously. ``invoke`` (the UI) runs ``compute`` in a worker thread polled by a modal timer for
big meshes, so Esc cancels a long run; modal handlers never fire in background mode, where
``invoke`` falls back to ``execute``."""
import time

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty

from ..core.errors import ConformalError
from . import meshio, targets
from .apply import apply_all
from .job import Cancelled, FlattenOptions, Worker
from .prefs import get_prefs
from .report import run_summary, warnings_of
from .wording import message

THREAD_MIN_TRIANGLES = 20_000            # invoke() computes smaller jobs synchronously

BOUNDARY_ITEMS = [
    ('UNIFORM', "Uniform", "Most uniform conformal factor: maximise min mu / max mu (the paper's objective)"),
    ('AREA', "Area", "Keep the boundary lengths (u = 0 on the boundary): least area distortion in L2"),
    ('FREE', "Free", "Free-boundary least-squares conformal map (LSCM), like Blender's Conformal unwrap"),
]
FIT_ITEMS = [
    ('UNIT_SQUARE', "Unit Square", "Fit the UVs into the 0-1 square, keeping the aspect ratio"),
    ('TRUE_SCALE', "True Scale", "UV area equals the surface area, in mesh units"),
]
SEAM_ITEMS = [
    ('KEEP', "Keep", "Use the mesh's own seams (Edge > Mark Seam); a closed part needs seams that cut it "
                     "open"),
    ('AUTO', "Automatic", "Choose seams through cone singularities for the most uniform scale, on any "
                          "mesh (closed ones too), and mark them as the mesh's seams"),
]
HOLES_ITEMS = [
    ('AUTO', "Automatic", "An island with holes is flattened both ways, its holes filled virtually and "
                          "cut open, and the better map is kept"),
    ('FILL', "Fill", "Fill the holes of an island virtually for the computation (a temporary cap, "
                     "removed afterwards); the longest boundary loop stays the outer boundary"),
    ('CUT', "Cut", "Cut every hole open to the outer boundary along a shortest edge path"),
    ('ERROR', "Refuse", "Stop with an error on an island with holes"),
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


class FlattenRun(Worker):
    """One operator call: ``read`` -> ``compute`` (or ``start``/``done``/``cancel`` in a worker thread,
    see ``job.Worker``) -> ``apply``. ``objects``: list of (object, user names) (default
    ``targets.target_objects(context)``)."""

    def __init__(self, context, opts, objects=None):
        if opts.colormap is None:
            opts.colormap = get_prefs(context).colormap
        super().__init__(jobs=None, opts=opts)
        self.targets = objects if objects is not None else targets.target_objects(context)
        self.t0 = time.perf_counter()
        self.t_read = 0.0

    def read(self, context):
        """Read every target mesh (leaves and restores the objects' mode)."""
        t = time.perf_counter()
        first = self.targets[0][0]
        edit = first.mode == 'EDIT'
        with targets.objects_in_object_mode(context, first):
            self._read_all(edit)
        self.t_read = time.perf_counter() - t

    def _read_all(self, use_selection):
        self.jobs = [targets.read_job(obj, users, use_selection) for obj, users in self.targets]

    def apply(self, context):
        """Write the results (leaves and restores the objects' mode). Returns the per-mesh reports."""
        first = self.targets[0][0]
        with targets.objects_in_object_mode(context, first):
            return self._apply_all(context)

    def _apply_all(self, context):
        if self.token.cancelled:
            raise Cancelled("cancelled: nothing was written")
        if self.results is None:
            raise ConformalError("nothing was computed")
        for job in self.jobs:
            try:
                me = job.obj.data
            except ReferenceError:
                raise ConformalError("an object was deleted while it was being flattened: nothing was "
                                     "written") from None
            if (len(me.vertices), len(me.edges), len(me.loops), len(me.polygons)) != job.counts:
                raise ConformalError(f"mesh {me.name!r} changed while it was being flattened: nothing "
                                     "was written; run the operator again")
        return apply_all(context, self.jobs, self.results, self.skipped, self.opts, self.t0, self.t_read)

    def run(self, context, progress=None):
        """read + compute + apply in this thread, with one mode switch. Returns the reports."""
        first = self.targets[0][0]
        edit = first.mode == 'EDIT'
        with targets.objects_in_object_mode(context, first):
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
    seams: EnumProperty(name="Seams", items=SEAM_ITEMS, default='KEEP',
                        description="Where the mesh is cut open into islands")
    cones: IntProperty(name="Cones", default=0, min=0, max=256,
                       description="With automatic seams: the number of cone singularities per part "
                                   "(0: as few as reach the target ratio)")
    target_ratio: FloatProperty(name="Target Ratio", default=0.5, min=0.01, max=1.0, precision=2,
                                description="With automatic seams and Cones 0: the ratio of the 1st to "
                                            "the 99th percentile of the scale to reach")
    holes: EnumProperty(name="Holes", items=HOLES_ITEMS, default='AUTO',
                        description="What to do with an island that has holes (several boundary loops)")
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
        col = layout.column(heading="Seams")
        col.prop(self, 'seams')
        sub = col.column()
        sub.active = self.seams == 'AUTO'
        sub.prop(self, 'cones')
        sub.prop(self, 'target_ratio')
        col = layout.column(heading="Islands")
        col.prop(self, 'holes')
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
                              holes=self.holes,
                              keep_relative_scale=self.keep_relative_scale,
                              skip_bad_islands=self.skip_bad_islands, packer=self.packer,
                              pack_shape=self.pack_shape, pack_rotate=self.pack_rotate,
                              margin=self.margin, shared_layout=self.shared_layout,
                              seams=self.seams, cones=self.cones, target_ratio=self.target_ratio,
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
            self.report({'ERROR'}, message(exc))
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
            self.report({'ERROR'}, message(exc))
            return {'CANCELLED'}
        if run.n_triangles < THREAD_MIN_TRIANGLES:
            try:
                with meshio.Progress(context) as progress:
                    run.compute(progress)
                    reports = run.apply(context)
            except ConformalError as exc:
                self.report({'ERROR'}, message(exc))
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
            msg = message(run.error) if isinstance(run.error, ConformalError) else \
                f"internal error: {type(run.error).__name__}: {run.error}"
            self.report({'ERROR'}, msg)
            return {'CANCELLED'}
        try:
            reports = run.apply(context)
        except (ConformalError, Cancelled) as exc:
            self.report({'ERROR'}, message(exc))
            return {'CANCELLED'}
        return self._done(reports)


def menu_unwrap(self, context):
    self.layout.separator()
    self.layout.operator(UV_OT_conformal_flatten.bl_idname, text="Conformal Flatten (Uniform)")


CLASSES = (UV_OT_conformal_flatten,)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.IMAGE_MT_uvs_unwrap.append(menu_unwrap)


def unregister():
    bpy.types.IMAGE_MT_uvs_unwrap.remove(menu_unwrap)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
