"""Shared libraries that Python wheels bundle beside their package.

``auditwheel`` (Linux) puts them in ``<package>.libs`` next to the package, ``delocate`` (macOS) in
the package's ``.dylibs``, ``delvewheel`` (Windows) in ``<package>.libs`` or, in older wheels,
``.libs``. ``core.blas`` finds the OpenBLAS copies there and ``core.mesh.cholmod_block`` cvxopt's
CHOLMOD."""
import glob
import importlib.util
import os


def bundled_libraries(package, pattern):
    """Paths (list of str, sorted within each folder) of the files matching ``pattern`` (a glob, e.g.
    '*openblas*') that the installed ``package`` (a top-level name) bundles; empty if it is not
    installed or bundles none."""
    try:
        spec = importlib.util.find_spec(package)
    except (ImportError, ValueError):
        return []
    if spec is None or not spec.submodule_search_locations:
        return []
    here = list(spec.submodule_search_locations)[0]
    found = []
    for folder in (os.path.join(here, os.pardir, f'{package}.libs'), os.path.join(here, '.dylibs'),
                   os.path.join(here, '.libs')):
        found += sorted(glob.glob(os.path.join(folder, pattern)))
    return found
