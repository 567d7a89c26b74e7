"""Sidebar panels (tab "Conformal") in the 3D Viewport and the UV Editor.

The panel shows the flatten options (stored per scene in ``scene.conformal_flatten``), the button, the
last report of the active mesh (mu ratio, certified bound, flips, conformality, time) and the sections
other tools add. This module imports the operators; no operator imports it (the shared building
blocks, ``add_section``, ``register_tool``, ``draw_report``, are in ``addon/sidebar.py``).
"""

import bpy
from bpy.props import BoolProperty, EnumProperty, FloatProperty, IntProperty, PointerProperty

from . import meshio
from .apply import REPORT_KEY
from .ops_flatten import BOUNDARY_ITEMS, FIT_ITEMS, HOLES_ITEMS, SEAM_ITEMS, UV_OT_conformal_flatten
from .sidebar import (CATEGORY, PARENT_IDS, add_section, draw_report, fmt as _fmt,
                      remove_section, sections)

def geodesic_solver_label():
    """Which eikonal solver geodesic distances will use (``core.geodesic.solver.solver_name``)."""
    from ..core.geodesic.solver import solver_name
    return solver_name()


FLATTEN_ROWS = [
    ("Mu ratio", 'mu_ratio'),
    ("Certified bound", 'bound_vertex'),
    ("Flips", 'flips'),
    ("Qc mean", lambda r: _fmt(r.get('qc_mean'), '.4f')),
    ("Cones", lambda r: "-" if r.get('cones') is None else
        f"{r['cones']} (seams {100 * (r.get('seam_fraction') or 0):.1f}% of edge length"
        + (f", {r['feature_edges']} on feature curves)" if r.get('feature_edges') else ")")),
    ("Mu range", lambda r: "-" if not r.get('conformal_factor_range') else
        "{:.3g} - {:.3g}".format(*r['conformal_factor_range'])),
    ("Time", lambda r: f"{r['seconds']['total']:.2f} s" if r.get('seconds') else "-"),
]


class ConformalFlattenSettings(bpy.types.PropertyGroup):
    boundary: EnumProperty(name="Boundary", items=BOUNDARY_ITEMS, default='UNIFORM')
    fit: EnumProperty(name="Fit", items=FIT_ITEMS, default='UNIT_SQUARE')
    bake: BoolProperty(name="Bake Conformal Factor", default=True)
    seams: EnumProperty(name="Seams", items=SEAM_ITEMS, default='KEEP')
    cones: IntProperty(name="Cones", default=0, min=0, max=256,
                       description="Cones per part with automatic seams (0: as few as reach the target)")
    target_ratio: FloatProperty(name="Target Ratio", default=0.5, min=0.01, max=1.0, precision=2)
    holes: EnumProperty(name="Holes", items=HOLES_ITEMS, default='AUTO')


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
        col.prop(settings, 'seams')
        sub = col.column(align=True)
        sub.active = settings.seams == 'AUTO'
        sub.prop(settings, 'cones')
        sub.prop(settings, 'target_ratio')
        col.prop(settings, 'holes')
        op = col.operator(UV_OT_conformal_flatten.bl_idname, icon='UV')
        op.boundary, op.fit, op.bake = settings.boundary, settings.fit, settings.bake
        op.seams, op.cones, op.target_ratio = settings.seams, settings.cones, settings.target_ratio
        op.holes = settings.holes

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

        for label, draw in sections():
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
    obj = getattr(context, 'active_object', None)
    report = meshio.load_report(obj.data, REPORT_KEY) if obj is not None and obj.type == 'MESH' else None
    if report is None or 'islands' not in report:
        layout.label(text="Seams split the mesh into islands")
        return
    draw_report(layout, report, ISLAND_ROWS)


CLASSES = (ConformalFlattenSettings, VIEW3D_PT_conformal_flatten, IMAGE_PT_conformal_flatten)


def register():
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.types.Scene.conformal_flatten = PointerProperty(type=ConformalFlattenSettings)
    add_section("Islands", draw_islands_section)


def unregister():
    remove_section(draw_islands_section)
    del bpy.types.Scene.conformal_flatten
    for cls in reversed(CLASSES):
        bpy.utils.unregister_class(cls)
