"""Building blocks of the "Conformal" sidebar tab, shared by every tool: sections, sub-panels, tool
registration and report rows. Imports no operator, so operators may use it; the panels themselves are
in ``addon/ui.py``.

- ``add_section(label, draw)`` / ``remove_section(draw)``: ``draw(layout, context)`` is called under a
  box with ``label`` in both main panels, in the order sections were added. Call them from your
  module's ``register()``/``unregister()``.
- ``sub_panel_classes``/``register_tool``/``unregister_tool``: sub-panels with ``bl_parent_id`` set to
  ``PARENT_IDS['VIEW_3D']`` and ``PARENT_IDS['IMAGE_EDITOR']``.
- ``draw_report(layout, report, rows)`` draws a stored report dict as label rows.
"""
import bpy
from bpy.props import PointerProperty

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


def sections():
    """The (label, draw) pairs added so far, in order."""
    return list(_sections)


def fmt(x, spec='.4g'):
    """A report value as text ("-" for None)."""
    if x is None:
        return "-"
    if isinstance(x, (int, float)):
        return format(x, spec)
    return str(x)


def draw_report(layout, report, rows):
    """Draw ``rows``, a list of (label, key or callable(report) -> str), from ``report`` (dict)."""
    col = layout.column(align=True)
    for label, key in rows:
        value = key(report) if callable(key) else fmt(report.get(key))
        row = col.row()
        row.label(text=label)
        row.label(text=value)
