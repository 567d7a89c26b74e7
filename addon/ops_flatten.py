"""``bpy.ops.uv.conformal_flatten``: flatten the active mesh conformally, write per-corner UVs and bake
the conformal factor mu.

The job is synchronous (``execute``), so it runs the same way from the UI, from
``blender --background`` scripts and from the bpy module, where modal operators and timers never run.
Everything is computed before anything is written: on bad input the operator reports the core's
message as an ERROR (a ``RuntimeError`` in scripts) and the mesh is untouched."""
import time

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty

from ..core.errors import ConformalError
from ..core.flatten import flatten
from ..core.geometry import face_areas
from . import meshio
from .prefs import get_prefs

REPORT_KEY = 'conformal_flatten_report'
ATTR_NAME = 'conformal_factor'           # FLOAT point attribute; colour: ATTR_NAME + '_color'
RANGE_KEY = ATTR_NAME + '_range'         # mesh custom property [min, max] of the baked values

BOUNDARY_ITEMS = [
    ('UNIFORM', "Uniform", "Most uniform conformal factor: maximise min mu / max mu (the paper's objective)"),
    ('AREA', "Area", "Keep the boundary lengths (u = 0 on the boundary): least area distortion in L2"),
    ('FREE', "Free", "Free-boundary least-squares conformal map (LSCM), like Blender's Conformal unwrap"),
]
FIT_ITEMS = [
    ('UNIT_SQUARE', "Unit Square", "Fit the UVs into the 0-1 square, keeping the aspect ratio"),
    ('TRUE_SCALE', "True Scale", "UV area equals the surface area, in mesh units"),
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
    """Flatten ``md`` (``meshio.MeshArrays`` with triangles). Returns ``(result, loop_uv (c,2),
    mu_vertex (n,))``: the core's ``FlattenResult``, the per-corner UVs and the per-vertex conformal
    factor sqrt(UV area / 3D area) over each vertex's star. Raises ``ConformalError``."""
    F = md.F
    result = flatten(md.V, F, boundary=boundary.lower(), fit=fit.lower(), progress=progress)
    loop_uv = result.uv[md.corner_verts]
    mu_vertex = meshio.face_to_vertex(F, result.mu, face_areas(md.V, F), md.n_vertices, power=2.0)
    return result, loop_uv, mu_vertex


def flatten_object(context, obj, boundary='UNIFORM', fit='UNIT_SQUARE', bake=True, colormap=None):
    """Flatten mesh object ``obj`` and write the result (see the module docstring). Returns the report
    dict (also stored as JSON in ``obj.data[REPORT_KEY]``). Raises ``ConformalError`` with nothing
    written. Usable from scripts without the operator."""
    t0 = time.perf_counter()
    obj = meshio.mesh_object(context, obj)
    me = obj.data
    colormap = colormap or get_prefs(context).colormap
    with meshio.object_mode(obj), meshio.Progress(context) as progress:
        t = time.perf_counter()
        md = meshio.read_mesh(obj)
        t_read = time.perf_counter() - t
        progress(0.02, 'read mesh')
        t = time.perf_counter()
        result, loop_uv, mu_vertex = compute_flatten(
            md, boundary, fit, progress=lambda f, msg: progress(0.02 + 0.93 * f, msg))
        t_solve = time.perf_counter() - t
        if not np.isfinite(loop_uv).all():
            raise ConformalError("the flattening produced non-finite UVs: the mesh is too degenerate; "
                                 "try the 'area' boundary mode or clean the mesh")
        # Everything is computed: from here on, only writes.
        t = time.perf_counter()
        uv_name = meshio.write_uv(me, loop_uv)
        rng = None
        if bake:
            rng = meshio.bake_scalar(me, ATTR_NAME, mu_vertex, colormap_name=colormap, log=True)
        t_write = time.perf_counter() - t
        progress(1.0, 'done')
        core = result.report
        report = {
            'object': obj.name, 'mesh': me.name, 'boundary': boundary, 'fit': fit,
            'uv_map': uv_name, 'vertices': md.n_vertices, 'polygons': int(len(md.sizes)),
            'triangles': int(len(md.tri_corners)),
            'mu_ratio': core.get('mu_ratio'), 'mu_ratio_p1_p99': core.get('mu_ratio_p1_p99'),
            'bound_vertex': core.get('bound_vertex'), 'vertex_ratio': core.get('vertex_ratio'),
            'qc_mean': core.get('qc_mean'), 'qc_max': core.get('qc_max'), 'flips': core.get('flips'),
            'mu_triangle_range': [float(result.mu.min()), float(result.mu.max())],
            'baked': bool(bake), 'conformal_factor_range': list(rng) if rng else None,
            'seconds': {'read': round(t_read, 4), 'flatten': round(t_solve, 4),
                        'write': round(t_write, 4), 'total': round(time.perf_counter() - t0, 4)},
            'core_seconds': core.get('seconds'), 'mesh_hash': mesh_hash(md),
        }
        meshio.store_report(me, REPORT_KEY, report)
    return report


def summary_line(r):
    """One line for the status bar: ratio, bound, flips, conformality, range, time."""
    parts = [f"Conformal flatten {r['object']!r} ({r['boundary'].lower()}): {r['triangles']} triangles",
             f"mu ratio {r['mu_ratio']:.4g}"]
    if r.get('bound_vertex') is not None:
        parts.append(f"certified bound {r['bound_vertex']:.4g}")
    parts.append(f"{r['flips']} flips")
    parts.append(f"qc mean {r['qc_mean']:.4f}")
    if r.get('conformal_factor_range'):
        lo, hi = r['conformal_factor_range']
        parts.append(f"mu in [{lo:.4g}, {hi:.4g}]")
    parts.append(f"{r['seconds']['total']:.2f} s")
    return ', '.join(parts)


class UV_OT_conformal_flatten(bpy.types.Operator):
    """Flatten the active mesh conformally with the most uniform scale; write UVs and bake mu"""
    bl_idname = 'uv.conformal_flatten'
    bl_label = "Conformal Flatten"
    bl_options = {'REGISTER', 'UNDO'}

    boundary: EnumProperty(name="Boundary", items=BOUNDARY_ITEMS, default='UNIFORM',
                           description="How the boundary of the flattened disk is chosen")
    fit: EnumProperty(name="Fit", items=FIT_ITEMS, default='UNIT_SQUARE',
                      description="How the UVs are scaled")
    bake: BoolProperty(name="Bake Conformal Factor", default=True,
                       description="Write mu as the point attribute 'conformal_factor' and the colour "
                                   "attribute 'conformal_factor_color'")

    @classmethod
    def poll(cls, context):
        # Deliberately permissive: a wrong selection gets an ERROR report that says what to do.
        return True

    def execute(self, context):
        try:
            report = flatten_object(context, None, self.boundary, self.fit, self.bake)
        except ConformalError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        self.report({'INFO'}, summary_line(report))
        return {'FINISHED'}


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
