"""Packaging: tools/package.py builds the zips with Blender's own extension tool, Blender's validate
command accepts them, and Blender installs the zip of its own Python line and runs the operators from
the installed copy.

The installed zip is the real Linux one of the running Python's line (cp311 in `make test`, cp313 in
`make test-blender52`), with its scipy and scikit-fmm wheels (cached in wheels/, like `make package`).
The manifest rewriting and the other line's range are checked on wheel-less builds."""
import json
import os
import subprocess
import sys
import tomllib
import zipfile

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PY = '{}.{}'.format(*sys.version_info[:2])
VERSION = tomllib.load(open(os.path.join(ROOT, 'blender_manifest.toml'), 'rb'))['version']
CP = 'cp' + PY.replace('.', '')
# Blender runs Python 3.11 from 4.2 to 5.0 and Python 3.13 from 5.1 (max is exclusive)
RANGES = {'3.11': ('4.2.0', '5.1.0'), '3.13': ('5.1.0', '5.3.0')}


@pytest.fixture(scope='module')
def built_zip(tmp_path_factory):
    from tools import package
    tmp = tmp_path_factory.mktemp('pkg')
    built = package.build(str(tmp / 'dist'), wheels=True, stage_dir=str(tmp / 'stage'), pythons=[PY],
                          platforms=['linux-x64'], log=lambda *a: None)
    assert [(os.path.basename(z), py, plat) for z, py, plat in built] == \
        [(f'conformal_flatten-{VERSION}-{CP}-linux_x64.zip', PY, 'linux-x64')]
    return built[0][0]


def version(text):
    return tuple(int(x) for x in text.split('.'))


def test_zip_layout_and_manifest(built_zip):
    import bpy
    with zipfile.ZipFile(built_zip) as z:
        names = z.namelist()
        manifest = tomllib.loads(z.read('blender_manifest.toml').decode())
    assert '__init__.py' in names                     # register() at the zip root, next to the manifest
    assert 'addon/ops_flatten.py' in names and 'core/disk/flatten.py' in names
    assert not any(n.startswith(('tests/', 'bench/', 'tools/', 'docs/', '.venv/')) for n in names)
    assert not any('__pycache__' in n for n in names)
    assert manifest['id'] == 'conformal_flatten'
    assert (manifest['blender_version_min'], manifest['blender_version_max']) == RANGES[PY]
    # the running Blender is one this zip serves
    lo, hi = map(version, RANGES[PY])
    assert lo <= tuple(bpy.app.version) < hi
    assert manifest['platforms'] == ['linux-x64']
    wheels = sorted(os.path.basename(w) for w in manifest['wheels'])
    assert len(wheels) == 4
    assert wheels[0].startswith(f'cvxopt-1.3.2-{CP}-{CP}-') and 'manylinux' in wheels[0]
    assert wheels[1].startswith(f'highspy-1.16.0-{CP}-{CP}-') and 'manylinux' in wheels[1]
    assert wheels[2].startswith(f'scikit_fmm-2025.6.23-{CP}-{CP}-') and wheels[2].endswith('linux_x86_64.whl')
    assert wheels[3].startswith(f'scipy-1.15.3-{CP}-{CP}-') and 'manylinux' in wheels[3]
    assert {'wheels/' + w for w in wheels} <= set(names)
    assert len(tomllib.loads(open(os.path.join(ROOT, 'blender_manifest.toml')).read()).get('wheels', [])) == 0
    assert len(manifest['tagline']) <= 64 and manifest['tagline'][-1].isalnum()


def test_every_python_line_without_wheels(tmp_path):
    """One zip per Python line, with its Blender range; the ranges meet, so no Blender from 4.2 on is
    left without a zip."""
    from tools import package
    built = package.build(str(tmp_path / 'dist'), wheels=False, stage_dir=str(tmp_path / 'stage'),
                          log=lambda *a: None)
    got = {}
    for path, py, plat in built:
        cp = py.replace('.', '')
        assert plat is None and os.path.basename(path) == f"conformal_flatten-{VERSION}-cp{cp}.zip"
        with zipfile.ZipFile(path) as z:
            m = tomllib.loads(z.read('blender_manifest.toml').decode())
        assert 'wheels' not in m and 'platforms' not in m
        got[py] = (m['blender_version_min'], m['blender_version_max'])
    assert got == RANGES
    assert RANGES['3.11'][1] == RANGES['3.13'][0]


def test_validate_accepts_zip(built_zip):
    from tools import package
    tool, tags = package.blender_ext_paths()
    out = subprocess.run([sys.executable, tool, 'validate', '--valid-tags', tags, built_zip],
                         capture_output=True, text=True)
    assert out.returncode == 0, out.stdout + out.stderr
    # and it rejects a broken manifest, so the check above means something
    bad = built_zip.replace('.zip', '-bad.zip')
    with zipfile.ZipFile(built_zip) as zin, zipfile.ZipFile(bad, 'w') as zout:
        for item in zin.infolist():
            data = zin.read(item.filename)
            if item.filename == 'blender_manifest.toml':
                data = data.replace(b'tagline = "', b'tagline = "Ends with a full stop.')
            zout.writestr(item, data)
    out = subprocess.run([sys.executable, tool, 'validate', '--valid-tags', tags, bad],
                         capture_output=True, text=True)
    assert out.returncode != 0


def test_manifest_wheel_list():
    from tools import package
    with open(os.path.join(ROOT, 'blender_manifest.toml')) as fh:
        text = fh.read()
    wheels = ['/x/wheels/scipy-1.15.3-cp311-cp311-win_amd64.whl',
              '/x/wheels/scikit_fmm-2025.6.23-cp311-cp311-linux_x86_64.whl']
    once = package.manifest_with(text, wheels, ['linux-x64', 'windows-x64'], ('5.1.0', '5.3.0'))
    twice = package.manifest_with(once, wheels, ['linux-x64', 'windows-x64'], ('5.1.0', '5.3.0'))
    assert once == twice
    m = tomllib.loads(once)
    assert (m['blender_version_min'], m['blender_version_max']) == ('5.1.0', '5.3.0')
    assert m['wheels'] == ['./wheels/scipy-1.15.3-cp311-cp311-win_amd64.whl',
                           './wheels/scikit_fmm-2025.6.23-cp311-cp311-linux_x86_64.whl']
    assert m['platforms'] == ['linux-x64', 'windows-x64']
    assert '/wheels/' not in m['build']['paths_exclude_pattern']     # the staged copy ships them
    assert 'wheels' not in tomllib.loads(text)                       # the source manifest has none


INSTALL_SCRIPT = r'''
import json, os, sys
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo='user_default',
                                         enable_on_install=True)
pkg = [m for m in sys.modules if m.endswith('.conformal_flatten')]
prefs = bpy.context.preferences.addons[pkg[0]].preferences
res = {'package': pkg, 'colormap': prefs.colormap, 'blender': bpy.app.version_string}
# where Blender unpacked the zip's wheels
local = os.path.join(bpy.utils.user_resource('EXTENSIONS'), '.local', 'lib')
site = [os.path.join(d, 'site-packages') for d in sorted(os.listdir(local))] if os.path.isdir(local) else []
res['site'] = site
res['site_modules'] = sorted({n for s in site for n in os.listdir(os.path.join(local, s))})
# flatten
bpy.ops.mesh.primitive_grid_add(x_subdivisions=12, y_subdivisions=12)
obj = bpy.context.object
obj.data.vertices[40].co.z = 0.3
bpy.ops.uv.conformal_flatten(boundary='AREA')
res['flatten'] = json.loads(obj.data['conformal_flatten_report'])
res['flatten_attrs'] = sorted(a.name for a in obj.data.attributes if not a.name.startswith('.'))
# geodesic distance from the vertex nearest the 3D cursor
bpy.context.scene.cursor.location = (0.0, 0.0, 0.0)
res['geodesic_ret'] = sorted(bpy.ops.mesh.conformal_geodesic_distance(grid=256, source='CURSOR'))
res['geodesic'] = json.loads(obj.data['conformal_geodesic_report'])
# sphere on a closed mesh
bpy.ops.mesh.primitive_ico_sphere_add(subdivisions=3)
sph = bpy.context.object
sph.data.vertices[0].co *= 1.3
res['sphere_ret'] = sorted(bpy.ops.uv.conformal_sphere())
res['sphere'] = json.loads(sph.data['conformal_sphere_report'])
res['sphere_keys'] = [k.name for k in sph.data.shape_keys.key_blocks]
res['modules'] = {m: getattr(sys.modules.get(m), '__file__', None) for m in ('scipy', 'skfmm')}
# the CHOLMOD backend comes from the zip's cvxopt wheel
import importlib
res['cholmod'] = importlib.import_module(pkg[0] + '.core.mesh.solve').backend(10 ** 6)
print('RESULT ' + json.dumps(res))
'''


def test_blender_installs_zip_and_runs_operators(built_zip, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / 'user'))
    out = subprocess.run([sys.executable, '-c', INSTALL_SCRIPT, built_zip], capture_output=True,
                         text=True, env=env, cwd=str(tmp_path), timeout=600)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    line = [ln for ln in out.stdout.splitlines() if ln.startswith('RESULT ')][-1]
    res = json.loads(line[len('RESULT '):])
    assert res['package'] == ['bl_ext.user_default.conformal_flatten']
    assert res['colormap'] == 'PERCEPTUAL'
    # the zip's wheels were unpacked for this Python
    assert res['site'] == [f'python{PY}/site-packages']
    assert {'scipy', 'skfmm', 'cvxopt', 'highspy'} <= set(res['site_modules'])
    assert res['cholmod'] == 'cholmod'
    assert res['flatten']['flips'] == 0 and res['flatten']['triangles'] == 2 * 12 * 12
    assert {'conformal_factor', 'conformal_factor_color', 'UVMap'} <= set(res['flatten_attrs'])
    assert res['geodesic_ret'] == ['FINISHED'] and res['geodesic']['solver'] == 'skfmm'
    assert res['geodesic']['distance_range'][1] > 0.5
    assert res['sphere_ret'] == ['FINISHED'] and res['sphere']['flips'] == 0
    assert res['sphere_keys'] == ['Basis', 'Sphere']
