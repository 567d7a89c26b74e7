"""Conformal Flatten core: numpy/scipy/scikit-fmm only, never bpy.

Conformal maps with an as-uniform-as-possible conformal factor (Aflalo, Kimmel and Zibulevsky 2013).
Functions take and return numpy arrays and small result objects; the formulas are in docs/math.md.
``unwrap`` is the single entry for UV work (disk, islands, holes, selections); ``flatten`` is the disk
primitive it calls.
"""
__version__ = "0.2.0"

from .errors import ConformalError  # noqa: E402
from .disk.flatten import DiskSystem, flatten, FlattenResult, BOUNDARY_MODES  # noqa: E402
from .atlas.unwrap import unwrap, UnwrapResult  # noqa: E402
from .mesh.measures import uv_measures  # noqa: E402
from .surfaces import make_surface  # noqa: E402
from .mesh.validate import check_mesh  # noqa: E402

__all__ = ['__version__', 'ConformalError', 'unwrap', 'UnwrapResult', 'DiskSystem', 'flatten',
           'FlattenResult', 'BOUNDARY_MODES', 'uv_measures', 'make_surface', 'check_mesh']
