"""Sidebar panels (tab "Conformal") in the 3D Viewport and the UV Editor.

The panel shows the flatten options (stored per scene in ``scene.conformal_flatten``), the button, and
the last report of the active mesh: mu ratio, certified bound, flips, conformality, time.

Hooks for other modules (geodesic, sphere, metric), which need no registration order:

- ``add_section(label, draw)`` / ``remove_section(draw)``: ``draw(layout, context)`` is called under a
  box with ``label`` in both panels, in the order sections were added. Call them from your module's
  ``register()``/``unregister()``.
- Or register your own sub-panels with ``bl_parent_id`` set to ``PARENT_IDS['VIEW_3D']`` and
  ``PARENT_IDS['IMAGE_EDITOR']``.
- ``draw_report(layout, report, rows)`` draws a stored report dict as label rows.
"""

import bpy
from bpy.props import BoolProperty, EnumProperty, PointerProperty

from . import meshio
from .ops_flatten import BOUNDARY_ITEMS, FIT_ITEMS, REPORT_KEY, UV_OT_conformal_flatten

CATEGORY = "Conformal"
PARENT_IDS = {'VIEW_3D': 'VIEW3D_PT_conformal_flatten', 'IMAGE_EDITOR': 'IMAGE_PT_conformal_flatten'}

_sections = []          # (label, draw) pairs


def sub_panel_classes(mixin, name):
    """One sub-panel class per editor (3D Viewport and UV Editor sidebars, tab "Conformal") under the
    main panel, from a ``mixin`` with ``bl_label`` and ``draw``; ``name`` gives their ``bl_idname``s
    (``VIEW3D_PT_<name>``, ``IMAGE_PT_<name>``). Register and unregister them like any class."""
    out = []
    for space, parent in PARENT_IDS.items():
        idname = f"{'VIEW3D' if space == 'VIEW_3D' else 'IMAGE'}_PT_{name}"
        out.append(type(idname, (mixin, bpy.types.Panel), {
            'bl_idname': idname, 'bl_space_type': space, 'bl_category': CATEGORY,
            'bl_parent_id': parent}))
    return out


def register_tool(settings_cls, scene_attr, operator_cls, panel_mixin, panel_name):
    """Register a tool: its settings as ``Scene.<scene_attr>``, its operator and its sidebar
    sub-panels (``sub_panel_classes``). Returns the panel classes, for ``unregister_tool``."""
    bpy.utils.register_class(settings_cls)
    setattr(bpy.types.Scene, scene_attr, PointerProperty(type=settings_cls))
    bpy.utils.register_class(operator_cls)
    panels = sub_panel_classes(panel_mixin, panel_name)
    for cls in panels:
        bpy.utils.register_class(cls)
    return panels


def unregister_tool(settings_cls, scene_attr, operator_cls, panels):
    """Undo ``register_tool``, in reverse order."""
    for cls in reversed(panels):
        bpy.utils.unregister_class(cls)
    bpy.utils.unregister_class(operator_cls)
    delattr(bpy.types.Scene, scene_attr)
    bpy.utils.unregister_class(settings_cls)


def add_section(label, draw):
    """Add ``draw(layout, context)`` as a boxed section called ``label`` to both panels."""
    remove_section(draw)
    _sections.append((label, draw))


def remove_section(draw):
    """Remove a section added with ``add_section`` (no error if absent)."""
    _sections[:] = [(lab, d) for lab, d in _sections if d is not draw]


def _fmt(x, spec='.4g'):
    if x is None:
        return "-"
    if isinstance(x, (int, float)):
        return format(x, spec)
    return str(x)


def draw_report(layout, report, rows):
    """Draw ``rows``, a list of (label, key or callable(report) -> str), from ``report`` (dict)."""
    col = layout.column(align=True)
    for label, key in rows:
        value = key(report) if callable(key) else _fmt(report.get(key))
        row = col.row()
        row.label(text=label)
        row.label(text=value)


def geodesic_solver_label():
    """Which eikonal solver geodesic distances will use (``core.geodesic.solver.solver_name``)."""
    from ..core.geodesic.solver import solver_name
    return solver_name()


FLATTEN_ROWS = [
    ("Mu ratio", 'mu_ratio'),
    ("Certified bound", 'bound_vertex'),
    ("Flips", 'flips'),
    ("Qc mean", lambda r: _fmt(r.get('qc_mean'), '.4f')),
    ("Mu range", lambda r: "-" if not r.get('conformal_factor_range') else
        "{:.3g} - {:.3g}".format(*r['conformal_factor_range'])),
    ("Time", lambda r: f"{r['seconds']['total']:.2f} s" if r.get('seconds') else "-"),
]


class ConformalFlattenSettings(bpy.types.PropertyGroup):
    boundary: EnumProperty(name="Boundary", items=BOUNDARY_ITEMS, default='UNIFORM')
    fit: EnumProperty(name="Fit", items=FIT_ITEMS, default='UNIT_SQUARE')
    bake: BoolProperty(name="Bake Conformal Factor", default=True)


class _ConformalPanel:
    bl_region_type = 'UI'
    bl_category = CATEGORY
    bl_label = "Conformal Flatten"

    def draw(self, context):
        layout = self.layout
        settings = context.scene.conformal_flatten
        col = layout.column()
        col.prop(settings, 'boundary')
        col.prop(settings, 'fit')
        col.prop(settings, 'bake')
        op = col.operator(UV_OT_conformal_flatten.bl_idname, icon='UV')
        op.boundary, op.fit, op.bake = settings.boundary, settings.fit, settings.bake

        obj = context.active_object
        report = meshio.load_report(obj.data, REPORT_KEY) if obj is not None and obj.type == 'MESH' else None
        box = layout.box()
        if report is None:
            box.label(text="No flatten report for the active mesh", icon='INFO')
        else:
            box.label(text=f"Last: {report.get('boundary', '?').title()}, "
                           f"{report.get('triangles', 0):,} triangles")
            draw_report(box, report, FLATTEN_ROWS)
        layout.label(text=f"Geodesic solver: {geodesic_solver_label()}")

        for label, draw in list(_sections):
            sub = layout.box()
            sub.label(text=label)
            try:
                draw(sub, context)
            except Exception as exc:         # one broken section must not hide the panel
                sub.label(text=f"error: {exc}", icon='ERROR')


class VIEW3D_PT_conformal_flatten(_ConformalPanel, bpy.types.Panel):
    bl_idname = PARENT_IDS['VIEW_3D']
    bl_space_type = 'VIEW_3D'


class IMAGE_PT_conformal_flatten(_ConformalPanel, bpy.types.Panel):
    bl_idname = PARENT_IDS['IMAGE_EDITOR']
    bl_space_type = 'IMAGE_EDITOR'


CLASSES = (ConformalFlattenSettings, VIEW3D_PT_conformal_flatten, IMAGE_PT_conformal_flatten)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.conformal_flatten = PointerProperty(type=ConformalFlattenSettings)


def unregister():
    del bpy.types.Scene.conformal_flatten
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
