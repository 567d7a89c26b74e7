"""Conformal Flatten core: numpy/scipy/scikit-fmm only, never bpy.

Conformal maps with an as-uniform-as-possible conformal factor (Aflalo, Kimmel and Zibulevsky 2013).
Functions take and return numpy arrays and small result objects; see DESIGN notes in README.
"""
from .errors import ConformalError
from .disk.flatten import flatten, FlattenResult, BOUNDARY_MODES
from .mesh.measures import uv_measures
from .surfaces import make_surface
from .mesh.validate import check_mesh

__all__ = ['ConformalError', 'flatten', 'FlattenResult', 'BOUNDARY_MODES', 'uv_measures',
           'make_surface', 'check_mesh']
