"""Import this repository as the package ``conformal_flatten`` without installing it, the way Blender
imports the extension (``bl_ext.<repo>.conformal_flatten``), so that ``addon``'s relative imports of
``core`` work from tests, the demo and benchmarks."""
import importlib.util
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
NAME = 'conformal_flatten'


def load():
    """Return the package module (registered in sys.modules as ``conformal_flatten``)."""
    if NAME in sys.modules:
        return sys.modules[NAME]
    spec = importlib.util.spec_from_file_location(NAME, os.path.join(ROOT, '__init__.py'),
                                                  submodule_search_locations=[ROOT])
    mod = importlib.util.module_from_spec(spec)
    sys.modules[NAME] = mod
    spec.loader.exec_module(mod)
    return mod
