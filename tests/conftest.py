"""Shared pytest set-up: the repository root on sys.path, so ``import core`` works."""
import os
import sys

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
if ROOT not in sys.path:
    sys.path.insert(0, ROOT)

DATA = os.path.join(ROOT, 'tests', 'data')


# --- Blender (bpy) fixtures ------------------------------------------------------------------------
# Isolate Blender from the user's configuration. This must happen before anything imports bpy, and
# conftest is imported before the test modules. `make test` sets it too.
import pytest  # noqa: E402

from tools.blender_user import private_user_resources  # noqa: E402

private_user_resources('cf-blender-user-')


@pytest.fixture(scope='session')
def bpy_pkg():
    """The repository imported as the package ``conformal_flatten`` (tools/devpkg), not registered."""
    import bpy  # noqa: F401  (imported here so pure-core test runs do not pay for it)
    from tools import devpkg
    return devpkg.load()


def _reset_blender():
    import bpy
    bpy.ops.wm.read_factory_settings(use_empty=True)


@pytest.fixture(autouse=True)
def _fresh_blender_scene(request):
    """Every test marked ``bpy`` (all add-on tests: ``pytestmark = pytest.mark.bpy``) starts from
    Blender's factory settings with an empty scene, so no test sees another's objects or settings.
    Autouse fixtures run before the others, so ``addon`` registers into the fresh scene."""
    if request.node.get_closest_marker('bpy') is not None:
        _reset_blender()
        request.node._cf_scene_reset = True
    yield


def _reset_unless_done(request):
    if not getattr(request.node, '_cf_scene_reset', False):
        _reset_blender()


@pytest.fixture
def addon(bpy_pkg, request):
    """An empty factory scene with the add-on registered (and enabled in the preferences, so
    ``AddonPreferences`` work); unregistered afterwards. Yields the package module."""
    import bpy
    _reset_unless_done(request)
    bpy_pkg.register()
    prefs_addons = bpy.context.preferences.addons
    entry = prefs_addons.get('conformal_flatten')
    if entry is None:
        entry = prefs_addons.new()
        entry.module = 'conformal_flatten'
    try:
        yield bpy_pkg
    finally:
        bpy_pkg.unregister()
        entry = prefs_addons.get('conformal_flatten')
        if entry is not None:
            prefs_addons.remove(entry)


@pytest.fixture
def blank_blender(bpy_pkg, request):
    """An empty factory scene, add-on not registered (for register/unregister tests)."""
    _reset_unless_done(request)
    yield bpy_pkg


class BlenderHelpers:
    """Helpers for add-on tests (the ``bl`` fixture): build mesh objects from numpy, snapshot every
    data array of a mesh to prove an operation left it untouched."""

    @staticmethod
    def mesh_object(name, V, polygons, active=True):
        """Link a new mesh object built from ``V`` (n,3) and a list of polygons (vertex index lists or
        an (m,k) array); make it active and selected. Returns the object."""
        import bpy
        import numpy as np
        polys = [list(map(int, p)) for p in np.asarray(polygons).tolist()] \
            if isinstance(polygons, np.ndarray) else [list(map(int, p)) for p in polygons]
        me = bpy.data.meshes.new(name)
        me.from_pydata(np.asarray(V, float).tolist(), [], polys)
        me.update()
        obj = bpy.data.objects.new(name, me)
        bpy.context.scene.collection.objects.link(obj)
        if active:
            for o in bpy.context.view_layer.objects:
                o.select_set(False)
            bpy.context.view_layer.objects.active = obj
            obj.select_set(True)
        return obj

    _FIELDS = {'FLOAT': ('value', 1, 'f4'), 'INT': ('value', 1, 'i4'), 'BOOLEAN': ('value', 1, 'bool'),
               'INT8': ('value', 1, 'i1'), 'FLOAT_VECTOR': ('vector', 3, 'f4'),
               'FLOAT2': ('vector', 2, 'f4'), 'INT32_2D': ('value', 2, 'i4'),
               'FLOAT_COLOR': ('color', 4, 'f4'), 'BYTE_COLOR': ('color', 4, 'f4'),
               'QUATERNION': ('value', 4, 'f4')}

    @classmethod
    def mesh_snapshot(cls, me):
        """Every attribute array (by name, with domain and type), the custom property names and the
        element counts of mesh ``me``, read in Object mode. Compare two snapshots with
        ``assert_same``."""
        import numpy as np
        snap = {'#counts': (len(me.vertices), len(me.edges), len(me.loops), len(me.polygons)),
                '#props': sorted(me.keys()), '#uv_layers': [u.name for u in me.uv_layers]}
        for a in me.attributes:
            field, width, dt = cls._FIELDS.get(a.data_type, (None, 0, None))
            if field is None:
                snap[a.name] = (a.domain, a.data_type, None)
                continue
            buf = np.empty(len(a.data) * width, dt)
            a.data.foreach_get(field, buf)
            snap[a.name] = (a.domain, a.data_type, buf)
        for k in me.keys():
            snap['#prop:' + k] = repr(me[k].to_list() if hasattr(me[k], 'to_list') else me[k])
        return snap

    @staticmethod
    def assert_same(before, after):
        import numpy as np
        assert before.keys() == after.keys(), (sorted(before.keys() ^ after.keys()))
        for k in before:
            b, a = before[k], after[k]
            if isinstance(b, tuple) and len(b) == 3 and isinstance(b[2], np.ndarray):
                assert b[:2] == a[:2], k
                np.testing.assert_array_equal(b[2], a[2], err_msg=k)
            else:
                assert b == a, k

    @classmethod
    def all_meshes_snapshot(cls):
        import bpy
        return {me.name: cls.mesh_snapshot(me) for me in bpy.data.meshes}


@pytest.fixture
def bl():
    return BlenderHelpers


def pytest_sessionfinish(session, exitstatus):
    """With CONFORMAL_NO_SKIP=1 (set by `make test` and `make test-blender52`, the CI legs) a skipped
    test fails the run: every test, the add-on ones included, must run there."""
    if os.environ.get('CONFORMAL_NO_SKIP') != '1':
        return
    reporter = session.config.pluginmanager.get_plugin('terminalreporter')
    skipped = len(reporter.stats.get('skipped', [])) if reporter is not None else 0
    if skipped and session.exitstatus == 0:
        print(f"\nCONFORMAL_NO_SKIP=1: {skipped} test(s) skipped, which fails this run")
        session.exitstatus = 1
