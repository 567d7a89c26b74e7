"""Conformal Flatten: Blender extension entry point.

Nothing here imports bpy at module level, so ``core`` stays importable without Blender."""


def register():
    from .addon import register as _register
    _register()


def unregister():
    from .addon import unregister as _unregister
    _unregister()
