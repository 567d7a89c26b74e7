"""Blender side of Conformal Flatten: operators, panels, properties and mesh <-> numpy.

Modules listed in ``MODULES`` each provide ``register()`` and ``unregister()``; they are registered
in this order and unregistered in reverse."""
import importlib

MODULES = (
    'prefs',
    'ops_flatten',
    'ui',
    'ops_sphere',
    'ops_metric',
    'ops_geodesic',
)


def _modules():
    return [importlib.import_module(f'.{name}', __package__) for name in MODULES]


def register():
    for mod in _modules():
        mod.register()


def unregister():
    for mod in reversed(_modules()):
        mod.unregister()
