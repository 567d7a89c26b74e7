"""Add-on preferences: the default grid size (used by the geodesic and metric tools), the colour map
used when baking, and the size limit for flattening. ``get_prefs(context)`` works even when the
add-on was registered by hand (tests, the bpy module), by falling back to the defaults."""
import bpy
from bpy.props import EnumProperty, IntProperty

from .colormap import COLORMAPS

# The top package: 'conformal_flatten' under tools/devpkg, 'bl_ext.<repo>.conformal_flatten' when
# Blender installs the extension. AddonPreferences must use it as bl_idname.
ADDON_ID = __package__.rpartition('.')[0]

DEFAULT_GRID_SIZE = 0           # 0: automatic, follows the mesh resolution
DEFAULT_COLORMAP = 'PERCEPTUAL'
DEFAULT_MAX_FACES = 5_000_000   # meshes over this many triangles are refused with a clear message

COLORMAP_ITEMS = [(k, label, desc) for k, (label, desc) in COLORMAPS.items()]


class ConformalFlattenPreferences(bpy.types.AddonPreferences):
    bl_idname = ADDON_ID

    grid_size: IntProperty(
        name="Default Grid Size", default=DEFAULT_GRID_SIZE, min=0, max=4096,
        description="Grid nodes along the longer side of the UV grid used for geodesic distances "
                    "(0: automatic, from the mesh resolution)")
    colormap: EnumProperty(
        name="Colour Map", items=COLORMAP_ITEMS, default=DEFAULT_COLORMAP,
        description="Colour map for baked colour attributes")
    max_faces: IntProperty(
        name="Size Limit (triangles)", default=DEFAULT_MAX_FACES, min=1,
        description="Refuse meshes with more triangles than this, before any work starts "
                    "(protects against running out of memory)")

    def draw(self, context):
        col = self.layout.column()
        col.use_property_split = True
        col.prop(self, 'grid_size')
        col.prop(self, 'colormap')
        col.prop(self, 'max_faces')


class _Defaults:
    grid_size = DEFAULT_GRID_SIZE
    colormap = DEFAULT_COLORMAP
    max_faces = DEFAULT_MAX_FACES


def get_prefs(context=None):
    """The add-on's preferences, or an object with the default values when the add-on is not
    enabled through Blender's add-on system."""
    context = context or bpy.context
    addon = context.preferences.addons.get(ADDON_ID)
    prefs = getattr(addon, 'preferences', None) if addon is not None else None
    return prefs if prefs is not None else _Defaults()


def register():
    bpy.utils.register_class(ConformalFlattenPreferences)


def unregister():
    bpy.utils.unregister_class(ConformalFlattenPreferences)
