"""``python -m core flatten`` and ``make-surface``: outputs, JSON report, errors."""
import json
import os
import subprocess
import sys

import numpy as np
import pytest

from core.mesh.measures import uv_measures
from conftest import ROOT


def run(*args):
    return subprocess.run([sys.executable, '-m', 'core', *args], cwd=ROOT, capture_output=True,
                          text=True, timeout=300)


def read_uv_obj(path):
    V, VT, F = [], [], []
    for line in open(path):
        p = line.split()
        if p and p[0] == 'v':
            V.append([float(x) for x in p[1:4]])
        elif p and p[0] == 'vt':
            VT.append([float(x) for x in p[1:3]])
        elif p and p[0] == 'f':
            F.append([[int(i) - 1 for i in q.split('/')] for q in p[1:]])
    return np.array(V), np.array(VT), F


def test_make_surface_and_flatten_roundtrip(tmp_path):
    surf = tmp_path / 'ridge.obj'
    out = tmp_path / 'out.obj'
    assert run('make-surface', 'ridge', '33', str(surf)).returncode == 0
    res = run('flatten', str(surf), str(out), '--boundary', 'uniform', '--json')
    assert res.returncode == 0, res.stderr
    report = json.loads(res.stdout.strip().splitlines()[-1])
    V, VT, F = read_uv_obj(out)
    assert V.shape == (33 * 33, 3) and VT.shape == (33 * 33, 2)
    Fi = np.array([[c[0] for c in f] for f in F])
    Ft = np.array([[c[1] for c in f] for f in F])
    assert (Fi == Ft).all()                     # one vt per vertex
    m = uv_measures(V, Fi, VT)
    assert m['flips'] == 0
    assert abs(m['mu_ratio'] - report['mu_ratio']) < 1e-6
    assert report['boundary'] == 'uniform' and 'bound_vertex' in report


def test_obj_with_uv_seams_and_ngons(tmp_path):
    # a 3x3 grid of quads with a pentagon, corners referencing vt and vn in mixed forms
    src = tmp_path / 'poly.obj'
    lines = []
    for i in range(4):
        for j in range(4):
            lines.append(f"v {j} {i} {0.1 * i * j}")
    lines += ["vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1", "vn 0 0 1"]
    quads = []
    for i in range(3):
        for j in range(3):
            a = i * 4 + j + 1
            quads.append([a, a + 1, a + 5, a + 4])
    # merge two quads of the last row into one hexagon-like polygon (a 6-gon)
    q1, q2 = quads.pop(), quads.pop()
    hexa = [q2[0], q2[1], q1[1], q1[2], q1[3], q2[3]]
    for q in quads:
        forms = [f"{q[0]}/1/1", f"{q[1]}//1", f"{q[2]}/3", f"{q[3]}"]
        lines.append('f ' + ' '.join(forms))
    lines.append('f ' + ' '.join(f"{v}/2" for v in hexa))
    src.write_text('\n'.join(lines) + '\n')
    out = tmp_path / 'out.obj'
    res = run('flatten', str(src), str(out), '--boundary', 'area')
    assert res.returncode == 0, res.stderr
    V, VT, F = read_uv_obj(out)
    assert len(V) == 16 and len(VT) == 16
    assert sorted(len(f) for f in F) == [4] * 7 + [6]      # polygons written back as polygons


@pytest.mark.parametrize('case, message', [
    ('missing', 'cannot read'),
    ('closed', 'closed'),
    ('garbage', 'cannot parse'),
    ('bad_mode', 'invalid choice'),
])
def test_errors_exit_2_with_one_line(tmp_path, case, message):
    src = tmp_path / 'in.obj'
    out = tmp_path / 'out.obj'
    args = ['flatten', str(src), str(out)]
    if case == 'closed':
        src.write_text("v 1 0 0\nv -1 0 0\nv 0 1 0\nv 0 -1 0\nv 0 0 1\nv 0 0 -1\n"
                       "f 1 3 5\nf 3 2 5\nf 2 4 5\nf 4 1 5\nf 3 1 6\nf 2 3 6\nf 4 2 6\nf 1 4 6\n")
    elif case == 'garbage':
        src.write_text("v 1 0 zero\n")
    elif case == 'bad_mode':
        src.write_text("v 0 0 0\n")
        args += ['--boundary', 'nope']
    res = run(*args)
    assert res.returncode == 2
    assert res.stdout == ''
    lines = res.stderr.strip().splitlines()
    assert len(lines) == 1 and message in lines[0] and 'Traceback' not in res.stderr
    assert not out.exists()
    assert not any(p.name.startswith('out.obj') for p in tmp_path.iterdir())


def test_obj_round_trip_is_exact(tmp_path):
    """Issue 12: floats are written with repr, so a mesh far from the origin comes back exactly (with
    %.9g a mesh translated by 1e6 came back with 93% zero-area faces)."""
    from core import make_surface
    from core.io.obj import read_obj, write_obj
    V, F = make_surface('bump', 9)
    V = V * 1e-3 + 1e6
    uv = np.random.default_rng(0).uniform(-1, 1, (len(V), 2)) * np.pi
    path = tmp_path / 'far.obj'
    write_obj(str(path), V, F, uv)
    back = read_obj(str(path))
    assert np.array_equal(back.V, V)
    assert np.array_equal(back.corner_verts.reshape(-1, 3), F)


def test_help_cites_files_in_the_repository():
    from core.cli import build_parser
    text = build_parser().format_help()
    assert 'DESIGN' not in text
    for name in ('flatten', 'make-surface', 'unwrap'):
        sub = build_parser()._subparsers._group_actions[0].choices[name].format_help()
        assert 'DESIGN' not in sub


def test_output_file_has_the_usual_mode(tmp_path):
    """Outputs are written atomically through a temporary file, but end with the mode the umask gives
    (not the temporary file's 0600)."""
    from core.io.obj import write_text
    out = tmp_path / 'x.txt'
    old = os.umask(0o022)
    try:
        write_text(str(out), 'x\n')
    finally:
        os.umask(old)
    assert (out.stat().st_mode & 0o777) == 0o644 and out.read_text() == 'x\n'
