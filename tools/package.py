"""Build the Blender extension zips with Blender's own extension tool (``blender_ext.py`` from the bpy
wheel, run with plain Python), one zip per platform, each with the third-party wheels it needs.

    .venv/bin/python tools/package.py [--out dist] [--no-wheels]

Steps:
1. Fetch the wheels into ``wheels/`` (kept between runs, never committed):
   - scipy (pinned in requirements.txt) for every platform, ``pip download --only-binary=:all:``;
   - scikit-fmm: the cp311 Windows wheel from PyPI, and the Linux wheel built here from the sdist
     (PyPI has no Linux or macOS wheels). macOS gets none: the core's fallback eikonal solver is used.
   numpy is not shipped: Blender bundles it.
2. Stage the extension in ``build/extension``: ``__init__.py``, ``core/``, ``addon/`` and a copy of
   ``blender_manifest.toml`` with the ``wheels`` and ``platforms`` lists written in.
3. ``blender_ext.py build --split-platforms`` into ``--out``, then ``blender_ext.py validate`` on each zip.

Blender 4.2 to 5.0 run Python 3.11 (checked on PyPI: bpy 4.2.0-5.0.1 are cp311-only, bpy 5.1 is
cp313), so the wheels are cp311 and the manifest's ``blender_version_max`` is "5.1.0" (exclusive).

``--no-wheels`` skips step 1 and builds one zip without wheels (for tests and development, where scipy
comes from the Python environment). Exit code 0 on success, 1 on failure with one line on stderr."""
import argparse
import glob
import os
import re
import shutil
import subprocess
import sys
import tomllib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
PYTHON_VERSION = '3.11'
PLATFORMS = {
    # Blender platform: pip --platform tags, most specific first
    'linux-x64': ['manylinux_2_17_x86_64', 'manylinux2014_x86_64'],
    'windows-x64': ['win_amd64'],
    'macos-arm64': ['macosx_12_0_arm64'],
    'macos-x64': ['macosx_10_13_x86_64'],
}
STAGE_ITEMS = ['__init__.py', 'blender_manifest.toml', 'core', 'addon', 'LICENSE', 'LICENSE.txt',
               'COPYING']


class PackageError(Exception):
    pass


def pinned(name):
    """The ``==`` version of ``name`` in requirements.txt."""
    with open(os.path.join(ROOT, 'requirements.txt')) as fh:
        for line in fh:
            m = re.match(rf'\s*{re.escape(name)}\s*==\s*([^\s#;]+)', line, re.I)
            if m:
                return m.group(1)
    raise PackageError(f"{name} is not pinned with == in requirements.txt")


def blender_ext_paths():
    """(blender_ext.py, tags.py) from the installed bpy module."""
    import bpy
    scripts = bpy.utils.system_resource('SCRIPTS')
    tool = os.path.join(scripts, 'addons_core', 'bl_pkg', 'cli', 'blender_ext.py')
    tags = os.path.join(scripts, 'modules', '_bpy_internal', 'extensions', 'tags.py')
    for p in (tool, tags):
        if not os.path.exists(p):
            raise PackageError(f"{p} not found: install bpy (requirements.txt) in this Python")
    return tool, tags


def run(cmd, **kw):
    proc = subprocess.run(cmd, capture_output=True, text=True, **kw)
    if proc.returncode != 0:
        raise PackageError(f"{' '.join(map(str, cmd[:4]))} ... failed:\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    return proc.stdout


def pip(*args):
    return run([sys.executable, '-m', 'pip', *args, '--disable-pip-version-check'])


def have(wheel_dir, pattern):
    return sorted(glob.glob(os.path.join(wheel_dir, pattern)))


def fetch_wheels(wheel_dir, log=print):
    """Download or build every wheel into ``wheel_dir`` (skipping those already there). Returns the
    list of wheel paths to ship."""
    os.makedirs(wheel_dir, exist_ok=True)
    scipy_v, fmm_v = pinned('scipy'), pinned('scikit-fmm')
    pyver = PYTHON_VERSION.replace('.', '')
    out = []
    for plat, tags in PLATFORMS.items():
        found = [w for w in have(wheel_dir, f'scipy-{scipy_v}-cp{pyver}-*.whl')
                 if _wheel_platform_matches(w, plat)]
        if not found:
            log(f"downloading scipy {scipy_v} for {plat}")
            args = ['download', f'scipy=={scipy_v}', '--no-deps', '--only-binary=:all:',
                    '--python-version', PYTHON_VERSION, '--implementation', 'cp', '--abi', f'cp{pyver}',
                    '-d', wheel_dir]
            for t in tags:
                args += ['--platform', t]
            pip(*args)
            found = [w for w in have(wheel_dir, f'scipy-{scipy_v}-cp{pyver}-*.whl')
                     if _wheel_platform_matches(w, plat)]
        if not found:
            raise PackageError(f"no scipy {scipy_v} wheel for {plat}")
        out.append(found[0])
    # scikit-fmm: Windows wheel from PyPI, Linux wheel built from the sdist, nothing for macOS.
    win = have(wheel_dir, f'scikit_fmm-{fmm_v}-cp{pyver}-*win_amd64.whl')
    if not win:
        log(f"downloading scikit-fmm {fmm_v} for windows-x64")
        pip('download', f'scikit-fmm=={fmm_v}', '--no-deps', '--only-binary=:all:', '--python-version',
            PYTHON_VERSION, '--implementation', 'cp', '--abi', f'cp{pyver}', '--platform', 'win_amd64',
            '-d', wheel_dir)
        win = have(wheel_dir, f'scikit_fmm-{fmm_v}-cp{pyver}-*win_amd64.whl')
    lin = have(wheel_dir, f'scikit_fmm-{fmm_v}-cp{pyver}-*linux_x86_64.whl')
    if not lin:
        if sys.platform != 'linux' or sys.version_info[:2] != (3, 11):
            raise PackageError("the Linux scikit-fmm wheel is built from its sdist and needs Linux and "
                               "Python 3.11: run `make package` there")
        log(f"building scikit-fmm {fmm_v} for linux-x64 from the sdist")
        pip('wheel', f'scikit-fmm=={fmm_v}', '--no-deps', '--no-binary', 'scikit-fmm', '-w', wheel_dir)
        lin = have(wheel_dir, f'scikit_fmm-{fmm_v}-cp{pyver}-*linux_x86_64.whl')
    if not win or not lin:
        raise PackageError("scikit-fmm wheels missing after download/build")
    return out + [win[0], lin[0]]


def _wheel_platform_matches(path, plat):
    tag = os.path.basename(path)[:-4].split('-')[-1]
    return {'linux-x64': 'linux' in tag and 'x86_64' in tag, 'windows-x64': tag == 'win_amd64',
            'macos-arm64': tag.startswith('macosx') and tag.endswith('arm64'),
            'macos-x64': tag.startswith('macosx') and tag.endswith('x86_64')}[plat]


def manifest_with(text, wheels, platforms):
    """The manifest ``text`` with top-level ``wheels`` and ``platforms`` arrays replaced/added."""
    for key in ('wheels', 'platforms'):
        text = re.sub(rf'(?ms)^{key}\s*=\s*\[.*?\]\s*\n', '', text)
    if wheels:       # the repository excludes its wheel cache; the staged copy ships wheels/
        text = re.sub(r'(?m)^\s*"/wheels/",?\s*\n', '', text)
    extra = ''
    if platforms:
        extra += 'platforms = [' + ', '.join(f'"{p}"' for p in platforms) + ']\n'
    if wheels:
        extra += 'wheels = [\n' + ''.join(f'  "./wheels/{os.path.basename(w)}",\n' for w in wheels) + ']\n'
    m = re.search(r'(?m)^\[', text)
    text = text[:m.start()] + extra + '\n' + text[m.start():] if m else text + '\n' + extra
    tomllib.loads(text)            # still valid TOML
    return text


def stage(stage_dir, wheels, platforms):
    if os.path.exists(stage_dir):
        shutil.rmtree(stage_dir)
    os.makedirs(stage_dir)
    ignore = shutil.ignore_patterns('__pycache__', '*.pyc')
    for item in STAGE_ITEMS:
        src = os.path.join(ROOT, item)
        if os.path.isdir(src):
            shutil.copytree(src, os.path.join(stage_dir, item), ignore=ignore)
        elif os.path.exists(src):
            shutil.copy2(src, os.path.join(stage_dir, item))
    if wheels:
        os.makedirs(os.path.join(stage_dir, 'wheels'))
        for w in wheels:
            shutil.copy2(w, os.path.join(stage_dir, 'wheels'))
    with open(os.path.join(ROOT, 'blender_manifest.toml')) as fh:
        text = fh.read()
    with open(os.path.join(stage_dir, 'blender_manifest.toml'), 'w') as fh:
        fh.write(manifest_with(text, wheels, platforms))


def build(out_dir, wheels=True, wheel_dir=None, stage_dir=None, log=print):
    """Build and validate. Returns the list of zip paths."""
    tool, tags = blender_ext_paths()
    wheel_dir = wheel_dir or os.path.join(ROOT, 'wheels')
    stage_dir = stage_dir or os.path.join(ROOT, 'build', 'extension')
    shipped = fetch_wheels(wheel_dir, log) if wheels else []
    platforms = list(PLATFORMS) if wheels else []
    stage(stage_dir, shipped, platforms)
    with open(os.path.join(stage_dir, 'blender_manifest.toml'), 'rb') as fh:
        manifest = tomllib.load(fh)
    os.makedirs(out_dir, exist_ok=True)
    prefix = f"{manifest['id']}-{manifest['version']}"
    for old in glob.glob(os.path.join(out_dir, prefix + '*.zip')):
        os.remove(old)
    run([sys.executable, tool, 'validate', '--valid-tags', tags, stage_dir])
    cmd = [sys.executable, tool, 'build', '--source-dir', stage_dir, '--output-dir', out_dir,
           '--valid-tags', tags]
    if wheels:
        cmd.append('--split-platforms')
    run(cmd)
    zips = sorted(glob.glob(os.path.join(out_dir, prefix + '*.zip')))
    if not zips:
        raise PackageError(f"blender_ext build wrote no zip into {out_dir}")
    for z in zips:
        run([sys.executable, tool, 'validate', '--valid-tags', tags, z])
        log(f"{os.path.relpath(z)}: {os.path.getsize(z) / 1e6:.1f} MB, validated")
    return zips


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--out', default=os.path.join(ROOT, 'dist'), help="output folder for the zips")
    ap.add_argument('--no-wheels', action='store_true',
                    help="build one zip without third-party wheels (tests, development)")
    ap.add_argument('--wheel-dir', default=None, help="wheel cache (default: wheels/)")
    ap.add_argument('--stage-dir', default=None, help="staging folder (default: build/extension)")
    args = ap.parse_args(argv)
    try:
        build(args.out, wheels=not args.no_wheels, wheel_dir=args.wheel_dir, stage_dir=args.stage_dir)
    except PackageError as exc:
        print(f"package: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
