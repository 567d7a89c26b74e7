"""Conformal Flatten core: numpy/scipy/scikit-fmm only, never bpy.

Conformal maps with an as-uniform-as-possible conformal factor (Aflalo, Kimmel and Zibulevsky 2013).
Functions take and return numpy arrays and small result objects; the formulas are in docs/math.md.
``unwrap`` is the single entry for UV work (disk, islands, holes, selections); ``flatten`` is the disk
primitive it calls.
"""
__version__ = "0.2.0"

from .errors import ConformalError  # noqa: E402

# the public names, imported on first use (PEP 562) so that ``python -m core COMMAND`` loads only what
# the command needs
_LAZY = {'DiskSystem': 'disk.flatten', 'flatten': 'disk.flatten', 'FlattenResult': 'disk.flatten',
         'BOUNDARY_MODES': 'disk.flatten', 'unwrap': 'atlas.unwrap', 'UnwrapResult': 'atlas.unwrap',
         'uv_measures': 'mesh.measures', 'make_surface': 'surfaces', 'check_mesh': 'mesh.validate'}

__all__ = ['__version__', 'ConformalError', 'unwrap', 'UnwrapResult', 'DiskSystem', 'flatten',
           'FlattenResult', 'BOUNDARY_MODES', 'uv_measures', 'make_surface', 'check_mesh']


def __getattr__(name):
    if name in _LAZY:
        import importlib
        value = getattr(importlib.import_module(f'.{_LAZY[name]}', __name__), name)
        globals()[name] = value
        return value
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def __dir__():
    return sorted(set(globals()) | set(_LAZY))
