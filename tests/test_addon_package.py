"""Packaging: tools/package.py builds a zip with Blender's own extension tool, Blender's validate
command accepts it, and Blender installs it and runs the operator from the installed copy.

The test builds without third-party wheels (``--no-wheels``: no network, a few seconds); scipy and
scikit-fmm then come from this Python environment. ``make package`` adds the per-platform wheels;
the manifest rewriting it relies on is tested here too."""
import json
import os
import subprocess
import sys
import tomllib
import zipfile

import pytest

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


@pytest.fixture(scope='module')
def built_zip(tmp_path_factory):
    from tools import package
    tmp = tmp_path_factory.mktemp('pkg')
    zips = package.build(str(tmp / 'dist'), wheels=False, stage_dir=str(tmp / 'stage'),
                         log=lambda *a: None)
    assert len(zips) == 1
    return zips[0]


def test_zip_layout_and_manifest(built_zip):
    with zipfile.ZipFile(built_zip) as z:
        names = z.namelist()
        manifest = tomllib.loads(z.read('blender_manifest.toml').decode())
    assert '__init__.py' in names                     # register() at the zip root, next to the manifest
    assert 'addon/ops_flatten.py' in names and 'core/disk/flatten.py' in names
    assert not any(n.startswith(('tests/', 'bench/', 'tools/', 'docs/', '.venv/')) for n in names)
    assert not any('__pycache__' in n for n in names)
    assert manifest['id'] == 'conformal_flatten'
    assert manifest['blender_version_min'] == '4.2.0'
    assert manifest['blender_version_max'] == '5.1.0'
    assert len(manifest['tagline']) <= 64 and manifest['tagline'][-1].isalnum()


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
    once = package.manifest_with(text, wheels, ['linux-x64', 'windows-x64'])
    twice = package.manifest_with(once, wheels, ['linux-x64', 'windows-x64'])
    assert once == twice
    m = tomllib.loads(once)
    assert m['wheels'] == ['./wheels/scipy-1.15.3-cp311-cp311-win_amd64.whl',
                           './wheels/scikit_fmm-2025.6.23-cp311-cp311-linux_x86_64.whl']
    assert m['platforms'] == ['linux-x64', 'windows-x64']
    assert '/wheels/' not in m['build']['paths_exclude_pattern']     # the staged copy ships them
    assert 'wheels' not in tomllib.loads(text)                       # the source manifest has none


INSTALL_SCRIPT = r'''
import json, sys
import bpy
bpy.ops.wm.read_factory_settings(use_empty=True)
bpy.ops.extensions.package_install_files(filepath=sys.argv[1], repo='user_default',
                                         enable_on_install=True)
bpy.ops.mesh.primitive_grid_add(x_subdivisions=12, y_subdivisions=12)
obj = bpy.context.object
obj.data.vertices[40].co.z = 0.3
bpy.ops.uv.conformal_flatten(boundary='AREA')
pkg = [m for m in sys.modules if m.endswith('.conformal_flatten')]
prefs = bpy.context.preferences.addons[pkg[0]].preferences
print('RESULT ' + json.dumps({'package': pkg, 'colormap': prefs.colormap,
      'report': json.loads(obj.data['conformal_flatten_report']),
      'attrs': sorted(a.name for a in obj.data.attributes if not a.name.startswith('.'))}))
'''


def test_blender_installs_zip_and_runs_operator(built_zip, tmp_path):
    env = dict(os.environ, BLENDER_USER_RESOURCES=str(tmp_path / 'user'))
    out = subprocess.run([sys.executable, '-c', INSTALL_SCRIPT, built_zip], capture_output=True,
                         text=True, env=env, cwd=str(tmp_path), timeout=300)
    assert out.returncode == 0, out.stdout[-3000:] + out.stderr[-3000:]
    line = [ln for ln in out.stdout.splitlines() if ln.startswith('RESULT ')][-1]
    res = json.loads(line[len('RESULT '):])
    assert res['package'] == ['bl_ext.user_default.conformal_flatten']
    assert res['colormap'] == 'PERCEPTUAL'
    assert res['report']['flips'] == 0 and res['report']['triangles'] == 2 * 12 * 12
    assert {'conformal_factor', 'conformal_factor_color', 'UVMap'} <= set(res['attrs'])
