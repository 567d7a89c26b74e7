"""``bpy.ops.uv.conformal_sphere``: map a closed genus-0 mesh conformally to the sphere (core.sphere),
with the Moebius transformation chosen for the most uniform conformal factor.

Writes, once everything is computed (a failure leaves the mesh untouched):

- shape key "Sphere" (a "Basis" key is added first if the mesh has none): the sphere with the mesh's
  surface area (radius sqrt(A / 4 pi)), centred at the mesh's area centroid, so the key's value slides
  between mesh and sphere;
- FLOAT_VECTOR point attribute ``sphere_position``: the unit-sphere position of each vertex;
- with ``bake``: mu per vertex as ``conformal_factor`` and ``conformal_factor_color`` (as the flatten
  operator does);
- spherical UVs (longitude, latitude) per corner into the active UV map, all in [0,1], split along a
  seam near longitude 180 degrees, poles on vertices (``core.sphere.layout``); UV flips are reported
  separately from the sphere map's folds.

A map with folded triangles, poor conformality or an unconverged Moebius optimiser is reported as
WARNING (the core's ``report['warnings']``), as is a UV layout with flipped triangles.

Synchronous ``execute``, like the flatten operator (headless scripts and tests run the same path)."""
import time

import bpy
import numpy as np
from bpy.props import BoolProperty, EnumProperty

from ..core.errors import ConformalError
from ..core.sphere.layout import every_edge_twice, sphere_layout
from ..core.sphere.map import sphere_map
from . import meshio
from .prefs import get_prefs

REPORT_KEY = 'conformal_sphere_report'
SHAPE_KEY = 'Sphere'
POSITION_ATTR = 'sphere_position'
MU_ATTR = 'conformal_factor'

MOEBIUS_ITEMS = [
    ('UNIFORM', "Uniform", "Most uniform conformal factor: maximise min mu / max mu over the Moebius group"),
    ('CENTER', "Center", "Area-centroid centring (Baden, Crane and Kazhdan 2018)"),
    ('AREA', "Area", "Least mean |log area ratio| (Choi)"),
    ('NONE', "None", "The map as computed, no Moebius normalisation"),
]


# --- the computation (core) -------------------------------------------------------------------------
def compute_sphere(md, moebius='UNIFORM', progress=None):
    """Map ``md`` (``meshio.MeshArrays`` with triangles) to the sphere and lay it out
    (``core.sphere.layout.sphere_layout``). Returns that dict plus ``result`` (the core's
    ``SphereResult``). Raises ``ConformalError``."""
    res = sphere_map(md.V, md.F, moebius=moebius.lower(), progress=progress)
    out = sphere_layout(md.V, md.F, res.S, res.mu, md.corner_verts, md.sizes, md.tri_corners)
    out['result'] = res
    return out


# --- writing ---------------------------------------------------------------------------------------
def write_shape_key(obj, name, positions):
    """Set shape key ``name`` of ``obj`` to ``positions`` (n,3), adding "Basis" first if the mesh has
    no shape keys. Returns the key block."""
    if obj.data.shape_keys is None:
        obj.shape_key_add(name='Basis', from_mix=False)
    kb = obj.data.shape_keys.key_blocks.get(name)
    if kb is None:
        kb = obj.shape_key_add(name=name, from_mix=False)
    kb.data.foreach_set('co', np.ascontiguousarray(positions, np.float32).ravel())
    obj.data.update()
    return kb


def sphere_object(context, obj, moebius='UNIFORM', bake=True, colormap=None):
    """Map mesh object ``obj`` (None: the active object) to the sphere and write the results (module
    docstring). Returns the report dict (also stored as JSON in ``obj.data[REPORT_KEY]``). Raises
    ``ConformalError`` with nothing written."""
    t0 = time.perf_counter()
    obj = meshio.mesh_object(context, obj)
    me = obj.data
    colormap = colormap or get_prefs(context).colormap
    with meshio.object_mode(obj), meshio.Progress(context) as progress:
        md = meshio.read_mesh(obj)
        progress(0.02, 'read mesh')
        t = time.perf_counter()
        out = compute_sphere(md, moebius, progress=lambda f, msg: progress(0.02 + 0.9 * f, msg))
        t_map = time.perf_counter() - t
        # everything is computed: from here on, only writes
        t = time.perf_counter()
        write_shape_key(obj, SHAPE_KEY, out['key'])
        meshio.write_point_vector(me, POSITION_ATTR, out['unit'])
        uv_name = meshio.write_uv(me, out['loop_uv'])
        rng = None
        if bake:
            rng = meshio.bake_scalar(me, MU_ATTR, out['mu_vertex'], colormap_name=colormap, log=True)
        t_write = time.perf_counter() - t
        progress(1.0, 'done')
        core = out['result'].report
        warnings = list(core.get('warnings', []))
        if out['uv_flips']:
            warnings.append(f"{out['uv_flips']} UV triangles are flipped in the spherical UV layout")
        report = {
            'object': obj.name, 'mesh': me.name, 'moebius': moebius, 'uv_map': uv_name,
            'shape_key': SHAPE_KEY, 'vertices': md.n_vertices, 'polygons': int(len(md.sizes)),
            'triangles': int(len(md.tri_corners)),
            'mu_ratio': core.get('mu_ratio'), 'mu_ratio_p1_p99': core.get('mu_ratio_p1_p99'),
            'baselines': core.get('baselines'), 'qc_mean': core.get('qc_mean'),
            'qc_max': core.get('qc_max'), 'flips': core.get('flips'),
            'flipped_faces': core.get('flipped_faces', [])[:100],
            'uv_flips': out['uv_flips'], 'u_scale': out['u_scale'],
            'moebius_converged': core.get('moebius_converged'), 'warnings': warnings,
            'pole_polygons': out['pole_polygons'], 'radius': out['radius'],
            'centre': [float(x) for x in out['centre']],
            'baked': bool(bake), 'conformal_factor_range': list(rng) if rng else None,
            'seconds': {'map': round(t_map, 4), 'write': round(t_write, 4),
                        'total': round(time.perf_counter() - t0, 4)},
            'core_seconds': core.get('seconds'),
            'repairs': core.get('repairs', []),
        }
        meshio.store_report(me, REPORT_KEY, report)
    return report


def summary_line(r):
    parts = [f"Conformal sphere {r['object']!r} ({r['moebius'].lower()}): {r['triangles']} triangles",
             f"mu ratio {r['mu_ratio']:.4g}"]
    if r.get('baselines'):
        parts.append("baselines " + ", ".join(f"{k} {v:.3g}" for k, v in r['baselines'].items()))
    parts += [f"{r['flips']} sphere flips", f"{r['uv_flips']} UV flips", f"qc mean {r['qc_mean']:.4f}",
              f"{r['seconds']['total']:.2f} s"]
    if r.get('repairs'):        # done on an internal copy: the mesh itself is not changed
        parts.append("repaired internally: " + ", ".join(f"{x['count']} {x['repair'].replace('_', ' ')}"
                                                         for x in r['repairs']))
    return ', '.join(parts)


class UV_OT_conformal_sphere(bpy.types.Operator):
    """Map the active closed mesh conformally to the sphere, with the most uniform scale; add a
    "Sphere" shape key, write spherical UVs and bake mu"""
    bl_idname = 'uv.conformal_sphere'
    bl_label = "Conformal Sphere"
    bl_options = {'REGISTER', 'UNDO'}

    moebius: EnumProperty(name="Moebius", items=MOEBIUS_ITEMS, default='UNIFORM',
                          description="How the Moebius transformation of the sphere is chosen")
    bake: BoolProperty(name="Bake Conformal Factor", default=True,
                       description="Write mu as the point attribute 'conformal_factor' and the colour "
                                   "attribute 'conformal_factor_color'")

    @classmethod
    def poll(cls, context):
        return True          # a wrong selection gets an ERROR report that says what to do

    def execute(self, context):
        try:
            report = sphere_object(context, None, self.moebius, self.bake)
        except ConformalError as exc:
            self.report({'ERROR'}, str(exc))
            return {'CANCELLED'}
        for w in report['warnings']:
            self.report({'WARNING'}, w)
        self.report({'WARNING'} if report['warnings'] else {'INFO'}, summary_line(report))
        return {'FINISHED'}


# --- panel -----------------------------------------------------------------------------------------
_closed_cache = {}


def is_closed_mesh(obj):
    """True if ``obj`` is a mesh whose every edge has exactly two faces (cached per mesh and element
    counts; in Edit mode the last Object-mode answer is used, or True if there is none)."""
    if obj is None or obj.type != 'MESH':
        return False
    me = obj.data
    key = (me.as_pointer(), len(me.vertices), len(me.edges), len(me.loops))
    if key in _closed_cache:
        return _closed_cache[key]
    if obj.mode == 'EDIT':
        return True
    if len(me.polygons) == 0 or len(me.edges) == 0:
        ans = False
    else:
        ce = np.empty(len(me.loops), np.int32)
        me.attributes['.corner_edge'].data.foreach_get('value', ce)
        ans = every_edge_twice(ce, len(me.edges))
    if len(_closed_cache) > 64:
        _closed_cache.clear()
    _closed_cache[key] = ans
    return ans


class ConformalSphereSettings(bpy.types.PropertyGroup):
    moebius: EnumProperty(name="Moebius", items=MOEBIUS_ITEMS, default='UNIFORM')
    bake: BoolProperty(name="Bake Conformal Factor", default=True)


SPHERE_ROWS = [
    ("Mu ratio", 'mu_ratio'),
    ("Best baseline", lambda r: "-" if not r.get('baselines') else
        "{1:.4g} ({0})".format(*max(r['baselines'].items(), key=lambda kv: kv[1]))),
    ("Sphere flips", 'flips'),
    ("UV flips", lambda r: "-" if r.get('uv_flips') is None else str(r['uv_flips'])),
    ("Qc mean", lambda r: "-" if r.get('qc_mean') is None else f"{r['qc_mean']:.4f}"),
    ("Time", lambda r: f"{r['seconds']['total']:.2f} s" if r.get('seconds') else "-"),
]


class _SpherePanel:
    bl_region_type = 'UI'
    bl_label = "Conformal Sphere"

    @classmethod
    def poll(cls, context):
        return is_closed_mesh(context.active_object)

    def draw(self, context):
        from .sidebar import draw_report
        layout = self.layout
        settings = context.scene.conformal_sphere
        col = layout.column()
        col.prop(settings, 'moebius')
        col.prop(settings, 'bake')
        op = col.operator(UV_OT_conformal_sphere.bl_idname, icon='SPHERE')
        op.moebius, op.bake = settings.moebius, settings.bake
        report = meshio.load_report(context.active_object.data, REPORT_KEY)
        if report is not None:
            box = layout.box()
            box.label(text=f"Last: {report.get('moebius', '?').title()}, "
                           f"{report.get('triangles', 0):,} triangles")
            draw_report(box, report, SPHERE_ROWS)
            for w in report.get('warnings') or []:
                box.label(text=w, icon='ERROR')


_registered = []


def register():
    from .sidebar import register_tool
    _registered[:] = register_tool(ConformalSphereSettings, 'conformal_sphere', UV_OT_conformal_sphere,
                                   _SpherePanel, 'conformal_sphere')


def unregister():
    from .sidebar import unregister_tool
    unregister_tool(ConformalSphereSettings, 'conformal_sphere', UV_OT_conformal_sphere, _registered)
    _registered.clear()
