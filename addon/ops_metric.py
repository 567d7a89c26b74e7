"""``bpy.ops.mesh.conformal_reconstruct_metric``: recover an isotropic metric on the active mesh from
measured travel times (paper section 8) and bake it as attributes.

The travel times come from a CSV file, one measurement per row: ``source_vertex,sensor_vertex,time``
with 0-based vertex indices of the mesh (Blender's vertex order, which is an imported OBJ's order),
time in mesh length units times the metric, and an optional header line. The result is baked as the
FLOAT point attribute ``recovered_metric`` and the colour attribute ``recovered_metric_color``.

Like the flatten operator the job is synchronous (``execute``) and computes everything before it
writes anything: a bad file (its line number is reported) or a bad mesh gives an ERROR report and
leaves the mesh untouched."""
import os
import time

import bpy
import numpy as np
from bpy.props import EnumProperty, FloatProperty, IntProperty, StringProperty

from ..core.errors import ConformalError
from ..core.metric import DEFAULT_CELLS, DEFAULT_NOISE, read_times, reconstruct
from . import meshio
from .job import mesh_hash
from .ops_flatten import BOUNDARY_ITEMS
from .prefs import get_prefs

ATTR_NAME = 'recovered_metric'            # FLOAT point attribute; colour: ATTR_NAME + '_color'
REPORT_KEY = 'recovered_metric_report'    # mesh custom property (JSON)


def reconstruct_object(context, obj, filepath, boundary='UNIFORM', cells=DEFAULT_CELLS,
                       noise=DEFAULT_NOISE, colormap=None):
    """Recover the metric of mesh object ``obj`` (None: the active object) from the CSV file
    ``filepath`` and bake it. Returns the report dict (also stored as JSON in
    ``obj.data[REPORT_KEY]``). Raises ``ConformalError`` with nothing written."""
    t0 = time.perf_counter()
    obj = meshio.mesh_object(context, obj)
    me = obj.data
    if not filepath:
        raise ConformalError("no travel-time file given: choose a CSV file with rows "
                             "'source_vertex,sensor_vertex,time'")
    path = bpy.path.abspath(filepath)
    if not os.path.isfile(path):
        raise ConformalError(f"cannot read {path}: no such file")
    colormap = colormap or get_prefs(context).colormap
    with meshio.object_mode(obj), meshio.Progress(context) as progress:
        md = meshio.read_mesh(obj)
        src, sns, times = read_times(path, md.n_vertices)
        progress(0.02, 'read mesh and times')
        res = reconstruct(md.V, md.F, src, sns, times, boundary=boundary.lower(), cells=cells,
                          noise=noise, progress=lambda f, msg: progress(0.02 + 0.93 * f, msg))
        xi = res.xi
        if xi.shape != (md.n_vertices,) or not np.all(np.isfinite(xi)):
            raise ConformalError("the reconstruction produced non-finite values: check the times")
        # Everything is computed: from here on, only writes.
        lo, hi = meshio.bake_scalar(me, ATTR_NAME, xi, colormap_name=colormap, log=True)
        progress(1.0, 'done')
        core = res.report
        report = {
            'object': obj.name, 'mesh': me.name, 'file': os.path.basename(path),
            'boundary': boundary, 'vertices': md.n_vertices, 'measurements': core['measurements'],
            'sources': core['sources'], 'sensors': core['sensors'], 'grid': core['grid'],
            'rms_relative_misfit': core['rms_relative_misfit'],
            'rms_relative_misfit_constant': core['rms_relative_misfit_constant'],
            'constant_fit': core['constant_fit'], 'iterations': core['iterations'],
            'metric_range': [lo, hi],
            'seconds': {'total': round(time.perf_counter() - t0, 4)},
            'core_seconds': core['seconds'], 'mesh_hash': mesh_hash(md),
        }
        meshio.store_report(me, REPORT_KEY, report)
    return report


def summary_line(r):
    lo, hi = r['metric_range']
    return (f"Recovered metric on {r['object']!r} from {r['measurements']} travel times "
            f"({r['sources']} sources, {r['sensors']} sensors): {lo:.4g} - {hi:.4g}, rms misfit "
            f"{r['rms_relative_misfit']:.2e} (constant {r['rms_relative_misfit_constant']:.2e}), "
            f"{r['iterations']} iterations, {r['seconds']['total']:.2f} s")


class MESH_OT_conformal_reconstruct_metric(bpy.types.Operator):
    """Recover an isotropic metric on the active mesh from a CSV file of travel times between vertices
    (through the conformal plane); bake it as the attribute 'recovered_metric'"""
    bl_idname = 'mesh.conformal_reconstruct_metric'
    bl_label = "Metric from Travel Times"
    bl_options = {'REGISTER', 'UNDO'}

    filepath: StringProperty(name="Travel Times", subtype='FILE_PATH', default='',
                             description="CSV file with rows 'source_vertex,sensor_vertex,time' "
                                         "(0-based vertex indices, optional header line)")
    filter_glob: StringProperty(default='*.csv;*.txt', options={'HIDDEN'})
    boundary: EnumProperty(name="Boundary", items=BOUNDARY_ITEMS, default='UNIFORM',
                           description="How the mesh is flattened before the reconstruction")
    cells: IntProperty(name="Grid Cells", default=DEFAULT_CELLS, min=59, max=1024,
                       description="Grid cells along the longer side of the flattened domain")
    noise: FloatProperty(name="Noise Level", default=DEFAULT_NOISE, min=1e-5, max=1.0,
                         precision=4, description="Expected relative error of the travel times; "
                                                  "raise it for noisy measurements (smoother result)")

    @classmethod
    def poll(cls, context):
        # Deliberately permissive: a wrong selection gets an ERROR report that says what to do.
        return True

    def invoke(self, context, event):
        context.window_manager.fileselect_add(self)
        return {'RUNNING_MODAL'}

    def execute(self, context):
        try:
            report = reconstruct_object(context, None, self.filepath, self.boundary, self.cells,
                                        self.noise)
        except ConformalError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self.report({'INFO'}, summary_line(report))
        return {'FINISHED'}


def draw_section(layout, context):
    """The panel section: the button and the last report of the active mesh."""
    from .sidebar import draw_report
    layout.operator(MESH_OT_conformal_reconstruct_metric.bl_idname, icon='FILE')
    obj = context.active_object
    report = meshio.load_report(obj.data, REPORT_KEY) if obj is not None and obj.type == 'MESH' else None
    if report is not None:
        draw_report(layout, report, [
            ("File", 'file'),
            ("Measurements", 'measurements'),
            ("Metric range", lambda r: "{:.3g} - {:.3g}".format(*r['metric_range'])),
            ("Rms misfit", lambda r: f"{r['rms_relative_misfit']:.2e}"),
        ])


CLASSES = (MESH_OT_conformal_reconstruct_metric,)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    from .sidebar import add_section
    add_section("Metric from Travel Times", draw_section)


def unregister():
    from .sidebar import remove_section
    remove_section(draw_section)
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
