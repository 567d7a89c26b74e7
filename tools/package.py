"""Build the Blender extension zips with Blender's own extension tool (``blender_ext.py`` from the bpy
wheel, run with plain Python): one zip per Python line and platform, each with the third-party wheels
it needs and the range of Blender versions that runs that Python.

    .venv/bin/python tools/package.py [--out dist] [--python 3.11 --python 3.13] [--platform linux-x64]
                                      [--no-wheels]

Python lines (``PYTHON_LINES``; checked on PyPI: bpy 4.2.0-5.0.1 are cp311-only, bpy 5.1.0-5.2.3 cp313):
- Python 3.11: Blender 4.2 LTS, 4.3, 4.4, 4.5 LTS and 5.0 (``blender_version_min = "4.2.0"``,
  ``blender_version_max = "5.1.0"``, exclusive);
- Python 3.13: Blender 5.1 and 5.2 LTS (``"5.1.0"`` to ``"5.3.0"``, exclusive).

Steps, for each Python line:
1. Fetch the wheels into ``wheels/`` (kept between runs, never committed):
   - scipy (pinned in requirements.txt) for every platform, ``pip download --only-binary=:all:``;
   - scikit-fmm: the Windows wheel from PyPI where there is one (cp311 only), and the Linux wheel built
     from the sdist (PyPI has no Linux or macOS wheels): in this Python when it is that line, else in
     the Python 3.13 root of ``tools/py313.sh`` (needs root; ``make package`` sets it up). Platforms
     without a scikit-fmm wheel get none: the core's fallback eikonal solver is used.
   numpy is not shipped: Blender bundles it.
2. Stage the extension in ``build/extension-pyXY``: ``__init__.py``, ``core/``, ``addon/`` and a copy of
   ``blender_manifest.toml`` with the line's Blender range and the ``wheels`` and ``platforms`` lists.
3. ``blender_ext.py build --split-platforms``, the zips renamed ``<id>-<version>-cpXY-<platform>.zip``
   into ``--out``, then ``blender_ext.py validate`` on each zip. A table says which zip serves which
   Blender versions.

``--no-wheels`` skips step 1 and builds one zip per line without wheels (development, where scipy
comes from the Python environment). Exit code 0 on success, 1 on failure with a message on stderr."""
import argparse
import glob
import os
import re
import shutil
import subprocess
import sys
import tomllib

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
# Python line -> (blender_version_min, blender_version_max exclusive, the Blender releases in that range)
PYTHON_LINES = {
    '3.11': ('4.2.0', '5.1.0', '4.2 LTS, 4.3, 4.4, 4.5 LTS, 5.0'),
    '3.13': ('5.1.0', '5.3.0', '5.1, 5.2 LTS'),
}
PLATFORMS = {
    # Blender platform: pip --platform tags, most specific first
    'linux-x64': ['manylinux_2_17_x86_64', 'manylinux2014_x86_64'],
    'windows-x64': ['win_amd64'],
    'macos-arm64': ['macosx_12_0_arm64'],
    'macos-x64': ['macosx_10_13_x86_64'],
}
STAGE_ITEMS = ['__init__.py', 'blender_manifest.toml', 'core', 'addon', 'LICENSE', 'LICENSE.txt',
               'COPYING']
PY313 = os.path.join(ROOT, 'tools', 'py313.sh')


class PackageError(Exception):
    pass


def this_python():
    return '{}.{}'.format(*sys.version_info[:2])


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
        raise PackageError(f"{' '.join(map(str, cmd[:4]))} ... failed:\n{proc.stdout[-2000:]}"
                           f"{proc.stderr[-2000:]}")
    return proc.stdout


def pip(*args):
    return run([sys.executable, '-m', 'pip', *args, '--disable-pip-version-check'])


def have(wheel_dir, pattern):
    return sorted(glob.glob(os.path.join(wheel_dir, pattern)))


def _download(wheel_dir, spec, python, platform_tags):
    cp = 'cp' + python.replace('.', '')
    args = ['download', spec, '--no-deps', '--only-binary=:all:', '--python-version', python,
            '--implementation', 'cp', '--abi', cp, '-d', wheel_dir]
    for t in platform_tags:
        args += ['--platform', t]
    pip(*args)


def _build_fmm_linux(wheel_dir, fmm_v, python, log):
    """Build the Linux scikit-fmm wheel for ``python`` from the sdist: here when this Python is that
    line, else inside the Python 3.13 root of tools/py313.sh (the repository is mounted there)."""
    spec = ['wheel', f'scikit-fmm=={fmm_v}', '--no-deps', '--no-binary', 'scikit-fmm', '-w',
            os.path.abspath(wheel_dir)]
    if sys.platform == 'linux' and python == this_python():
        log(f"building scikit-fmm {fmm_v} for linux-x64, Python {python}, from the sdist")
        pip(*spec)
        return
    if sys.platform == 'linux' and python == '3.13':
        ok = subprocess.run(['bash', PY313, 'ready'], capture_output=True, text=True)
        if ok.returncode == 0:
            log(f"building scikit-fmm {fmm_v} for linux-x64, Python 3.13, from the sdist in the "
                f"Python 3.13 root (tools/py313.sh)")
            run(['bash', PY313, 'run', 'python', '-m', 'pip', *spec, '--disable-pip-version-check'])
            return
        raise PackageError(
            "the Linux scikit-fmm wheel for Python 3.13 (Blender 5.1, 5.2 LTS) is built from its sdist "
            "in a Python 3.13 environment, and there is none here: " + (ok.stderr.strip() or "?") +
            "\n  build it with `tools/py313.sh setup` (root, Debian packages; `make package` does it when "
            "it can), or package the Python 3.11 line only: tools/package.py --python 3.11")
    raise PackageError(f"the Linux scikit-fmm wheel for Python {python} is built from its sdist and "
                       f"needs Linux and Python {python} (or the 3.13 root of tools/py313.sh)")


def fetch_wheels(wheel_dir, python='3.11', platforms=None, log=print):
    """Download or build every wheel for ``python`` and ``platforms`` into ``wheel_dir`` (skipping
    those already there). Returns {platform: [wheel paths to ship]}."""
    os.makedirs(wheel_dir, exist_ok=True)
    scipy_v, fmm_v = pinned('scipy'), pinned('scikit-fmm')
    cp = 'cp' + python.replace('.', '')
    out = {}
    for plat in platforms or PLATFORMS:
        def scipy_here(plat=plat):
            return [w for w in have(wheel_dir, f'scipy-{scipy_v}-{cp}-*.whl')
                    if _wheel_platform_matches(w, plat)]
        if not scipy_here():
            log(f"downloading scipy {scipy_v} for {plat}, Python {python}")
            _download(wheel_dir, f'scipy=={scipy_v}', python, PLATFORMS[plat])
        if not scipy_here():
            raise PackageError(f"no scipy {scipy_v} wheel for {plat}, Python {python}")
        out[plat] = [scipy_here()[0]] + [w for name in OPTIONAL_WHEELS
                                         for w in _optional_wheel(name, wheel_dir, python, plat, log)]
    # scikit-fmm: Windows wheel from PyPI (cp311 only), Linux wheel built from the sdist, none for macOS.
    if 'windows-x64' in out:
        win = have(wheel_dir, f'scikit_fmm-{fmm_v}-{cp}-*win_amd64.whl')
        if not win and python == '3.11':
            log(f"downloading scikit-fmm {fmm_v} for windows-x64, Python {python}")
            _download(wheel_dir, f'scikit-fmm=={fmm_v}', python, ['win_amd64'])
            win = have(wheel_dir, f'scikit_fmm-{fmm_v}-{cp}-*win_amd64.whl')
            if not win:
                raise PackageError(f"no scikit-fmm {fmm_v} wheel for windows-x64, Python {python}")
        out['windows-x64'] += win[:1]
    if 'linux-x64' in out:
        lin = have(wheel_dir, f'scikit_fmm-{fmm_v}-{cp}-*linux_x86_64.whl')
        if not lin:
            _build_fmm_linux(wheel_dir, fmm_v, python, log)
            lin = have(wheel_dir, f'scikit_fmm-{fmm_v}-{cp}-*linux_x86_64.whl')
        if not lin:
            raise PackageError(f"the scikit-fmm wheel for linux-x64, Python {python}, is missing after "
                               "the build")
        out['linux-x64'] += lin[:1]
    return out


# Optional compiled helpers of the core, shipped where PyPI has their wheels; without them the core
# falls back (fallback named in the log). Their wheels need newer platform tags than scipy's.
OPTIONAL_WHEELS = {
    'cvxopt': dict(           # CHOLMOD (supernodal, OpenBLAS) through cvxopt.cholmod, core.mesh.solve
        abi={'3.11': 'cp311-cp311', '3.13': 'cp313-cp313'},
        fallback='SuperLU will be used',
        # its cp313 macOS wheels need macOS 14 / 15, newer than Blender's minimum: not shipped there
        tags={'linux-x64': ['manylinux_2_17_x86_64', 'manylinux2014_x86_64'],
              'windows-x64': ['win_amd64'],
              'macos-arm64': ['macosx_11_0_arm64'],
              'macos-x64': ['macosx_10_9_x86_64']}),
    'highspy': dict(          # HiGHS's own binding: uniform's warm-started programs, core.disk.uniform
        abi={'3.11': 'cp311-cp311', '3.13': 'cp313-cp313'},
        fallback="scipy's linprog will be used (the same solver, from scratch each round)",
        tags={'linux-x64': ['manylinux_2_28_x86_64', 'manylinux_2_24_x86_64'],
              'windows-x64': ['win_amd64'],
              'macos-arm64': ['macosx_11_0_arm64'],
              'macos-x64': ['macosx_10_9_x86_64', 'macosx_10_13_x86_64']}),
}


def _optional_wheel(name, wheel_dir, python, plat, log):
    """The wheel of the optional package ``name`` (``OPTIONAL_WHEELS``) for ``plat`` and ``python``.
    Returns [path], or [] with a note when PyPI has none."""
    spec = OPTIONAL_WHEELS[name]
    v = pinned(name)

    def here():
        return [w for w in have(wheel_dir, f"{name}-{v}-{spec['abi'][python]}-*.whl")
                if _wheel_platform_matches(w, plat)]
    if not here():
        log(f"downloading {name} {v} for {plat}, Python {python}")
        try:
            _download(wheel_dir, f'{name}=={v}', python, spec['tags'][plat])
        except PackageError as exc:
            log(f"  no {name} wheel for {plat}, Python {python}: {spec['fallback']} ({exc})")
    return here()[:1]


def _wheel_platform_matches(path, plat):
    tag = os.path.basename(path)[:-4].split('-')[-1]
    return {'linux-x64': 'linux' in tag and 'x86_64' in tag, 'windows-x64': tag == 'win_amd64',
            'macos-arm64': tag.startswith('macosx') and tag.endswith('arm64'),
            'macos-x64': tag.startswith('macosx') and tag.endswith('x86_64')}[plat]


def manifest_with(text, wheels, platforms, versions=None):
    """The manifest ``text`` with top-level ``wheels`` and ``platforms`` arrays replaced/added, and,
    given ``versions`` = (min, max), ``blender_version_min``/``blender_version_max`` set to them."""
    for key in ('wheels', 'platforms'):
        text = re.sub(rf'(?ms)^{key}\s*=\s*\[.*?\]\s*\n', '', text)
    if versions is not None:
        for key, value in zip(('blender_version_min', 'blender_version_max'), versions):
            text, n = re.subn(rf'(?m)^{key}\s*=\s*"[^"]*"', f'{key} = "{value}"', text)
            if n != 1:
                raise PackageError(f"blender_manifest.toml has no single top-level {key}")
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


def stage(stage_dir, wheels, platforms, versions=None):
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
        fh.write(manifest_with(text, wheels, platforms, versions))


def build(out_dir, wheels=True, wheel_dir=None, stage_dir=None, pythons=None, platforms=None,
          log=print):
    """Build and validate the zips of the Python lines ``pythons`` (default: all of PYTHON_LINES) for
    ``platforms`` (default: all of PLATFORMS). Returns [(zip path, python, platform or None)]."""
    tool, tags = blender_ext_paths()
    wheel_dir = wheel_dir or os.path.join(ROOT, 'wheels')
    stage_root = stage_dir or os.path.join(ROOT, 'build')
    pythons = list(pythons or PYTHON_LINES)
    platforms = list(platforms or PLATFORMS)
    for py in pythons:
        if py not in PYTHON_LINES:
            raise PackageError(f"no Python line {py}: choose from {', '.join(PYTHON_LINES)}")
    for plat in platforms:
        if plat not in PLATFORMS:
            raise PackageError(f"no platform {plat}: choose from {', '.join(PLATFORMS)}")
    # every wheel first, so a missing one fails before anything is written into out_dir
    shipped = {py: fetch_wheels(wheel_dir, py, platforms, log) if wheels else {} for py in pythons}
    os.makedirs(out_dir, exist_ok=True)
    with open(os.path.join(ROOT, 'blender_manifest.toml'), 'rb') as fh:
        manifest = tomllib.load(fh)
    prefix = f"{manifest['id']}-{manifest['version']}"
    for old in glob.glob(os.path.join(out_dir, prefix + '*.zip')):
        os.remove(old)
    built = []
    for py in pythons:
        cp = 'cp' + py.replace('.', '')
        sdir = os.path.join(stage_root, f'extension-{cp}')
        tmp_out = os.path.join(stage_root, f'zips-{cp}')
        shutil.rmtree(tmp_out, ignore_errors=True)
        os.makedirs(tmp_out)
        wheel_list = sorted({w for ws in shipped[py].values() for w in ws})
        stage(sdir, wheel_list, platforms if wheels else [], PYTHON_LINES[py][:2])
        run([sys.executable, tool, 'validate', '--valid-tags', tags, sdir])
        cmd = [sys.executable, tool, 'build', '--source-dir', sdir, '--output-dir', tmp_out,
               '--valid-tags', tags]
        if wheels:
            cmd.append('--split-platforms')
        run(cmd)
        for plat in (platforms if wheels else [None]):
            suffix = '' if plat is None else '-' + plat.replace('-', '_')
            src = os.path.join(tmp_out, prefix + suffix + '.zip')
            if not os.path.exists(src):
                raise PackageError(f"blender_ext build wrote no {os.path.basename(src)}")
            dst = os.path.join(out_dir, f'{prefix}-{cp}{suffix}.zip')
            shutil.move(src, dst)
            run([sys.executable, tool, 'validate', '--valid-tags', tags, dst])
            built.append((dst, py, plat))
        shutil.rmtree(tmp_out, ignore_errors=True)
    import bpy
    log(table(built) + f"\nevery zip validated by blender_ext.py of bpy {bpy.app.version_string}")
    return built


def table(built):
    """Which zip serves which Blender versions."""
    rows = [('zip', 'platform', 'Python', 'Blender', 'manifest range', 'MB')]
    for path, py, plat in built:
        lo, hi, names = PYTHON_LINES[py]
        rows.append((os.path.basename(path), plat or 'any', py, names, f'>= {lo}, < {hi}',
                     f'{os.path.getsize(path) / 1e6:.1f}'))
    widths = [max(len(r[i]) for r in rows) for i in range(len(rows[0]))]
    lines = ['  '.join(c.ljust(w) for c, w in zip(r, widths)).rstrip() for r in rows]
    lines.insert(1, '  '.join('-' * w for w in widths))
    return '\n'.join(lines)


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.split('\n\n')[0])
    ap.add_argument('--out', default=os.path.join(ROOT, 'dist'), help="output folder for the zips")
    ap.add_argument('--python', action='append', choices=list(PYTHON_LINES),
                    help="a Python line to package (repeatable; default: all)")
    ap.add_argument('--platform', action='append', choices=list(PLATFORMS),
                    help="a platform to package (repeatable; default: all)")
    ap.add_argument('--no-wheels', action='store_true',
                    help="one zip per Python line without third-party wheels (development)")
    ap.add_argument('--wheel-dir', default=None, help="wheel cache (default: wheels/)")
    ap.add_argument('--stage-dir', default=None, help="staging folder (default: build/)")
    args = ap.parse_args(argv)
    try:
        build(args.out, wheels=not args.no_wheels, wheel_dir=args.wheel_dir, stage_dir=args.stage_dir,
              pythons=args.python, platforms=args.platform)
    except PackageError as exc:
        print(f"package: {exc}", file=sys.stderr)
        return 1
    return 0


if __name__ == '__main__':
    sys.exit(main())
