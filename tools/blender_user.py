"""Isolate a bpy process from the user's Blender configuration (development scripts only).

``private_user_resources(prefix)`` points ``BLENDER_USER_RESOURCES`` at a new temporary folder, unless
the variable is already set, and removes that folder when the process exits. Call it before anything
imports bpy (tests/conftest.py, tools/demo.py, bench/meshio.py)."""
import atexit
import os
import shutil
import tempfile


def private_user_resources(prefix='cf-blender-user-'):
    """The folder ``BLENDER_USER_RESOURCES`` names after the call (str): the one already set, or a new
    temporary folder starting with ``prefix``, removed at exit."""
    path = os.environ.get('BLENDER_USER_RESOURCES')
    if path:
        return path
    path = tempfile.mkdtemp(prefix=prefix)
    os.environ['BLENDER_USER_RESOURCES'] = path
    atexit.register(shutil.rmtree, path, True)
    return path
