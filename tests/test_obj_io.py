"""OBJ reading and writing (core/io/obj.py): the whole-buffer parser gives exactly what the line-by-line
reader gives (the reference semantics, and the error wording) on any text, and writing round-trips
exactly."""
import os

import numpy as np
from hypothesis import given, settings, HealthCheck, strategies as st

from core.errors import ConformalError
from core.io import obj
from core.io.obj import read_obj, write_obj, write_values

DATA = os.path.join(os.path.dirname(__file__), 'data')


def _read(fn, path):
    try:
        m = fn(path)
    except ConformalError as exc:
        return str(exc)
    return m.V, m.corner_verts, m.sizes, m.corner_uvs, m.lines


def _same(path):
    ref, got = _read(obj._read_lines, path), _read(read_obj, path)
    if isinstance(ref, str) or isinstance(got, str):
        assert ref == got
        return ref
    for a, b in zip(ref, got):
        assert a.dtype == b.dtype and a.shape == b.shape and np.array_equal(a, b, equal_nan=True)
    return got


def test_fast_path_reads_the_test_meshes_like_the_line_reader():
    names = sorted(n for n in os.listdir(DATA) if n.endswith('.obj'))
    assert names
    for name in names:
        path = os.path.join(DATA, name)
        with open(path, 'rb') as fh:
            assert obj._read_fast(fh.read()) is not None, name      # the fast path is what runs
        _same(path)


def test_forms_signs_and_line_ends(tmp_path):
    text = ("# a comment\r\nmtllib x.mtl\r\no thing\r\nv 0 0 0\r\nv 1 0 0\r\nv 1 1 0\r\nv 0 1 0\r\n"
            "vt 0 0\r\nvt 1 0\r\nvt 1 1\r\nvn 0 0 1\r\n"
            "f 1/1/1 2/2/1 3/3/1\r\nf -4//1 -2//1 -1//1\r\nf 1/-3 3/-1 4/\r\nl 1 2 -1\r\n\r\n"
            "v\t2  2\t0\n  f 5 2 3\n\tvt 0.5 0.5\ns off\nf 5/-1 3/4 4")
    path = tmp_path / 'forms.obj'
    path.write_bytes(text.encode())
    m = _same(str(path))
    V, corners, sizes, cuv, lines = m
    assert V.shape == (5, 3) and list(sizes) == [3, 3, 3, 3, 3]
    assert corners.tolist() == [0, 1, 2, 0, 2, 3, 0, 2, 3, 4, 1, 2, 4, 2, 3]
    assert cuv.tolist() == [0, 1, 2, -1, -1, -1, 0, 2, -1, -1, -1, -1, 3, 3, -1]
    assert lines.tolist() == [[0, 1], [1, 3]]


obj_lines = st.one_of(
    st.builds(lambda a, b, c, s: f"v{s}{a}{s}{b} {c}", *[st.sampled_from(['0', '1.5', '-2e3', 'nan', '1_0',
                                                                          '.5', 'x', '1e400', '+3'])] * 3,
              st.sampled_from([' ', '\t', '  ', '\x0b', '\xa0'])),
    st.builds(lambda idx, s: 'f ' + s.join(idx), st.lists(st.one_of(
        st.integers(-6, 9).map(str),
        st.builds(lambda a, b: f"{a}/{b}", st.integers(-4, 9), st.integers(-4, 9)),
        st.builds(lambda a, b: f"{a}/{b}/{a}", st.integers(-4, 9), st.integers(-4, 9)),
        st.builds(lambda a: f"{a}//1", st.integers(1, 9)),
        st.sampled_from(['+1', '--1', '1-2', '/1', '1/', '-', '1//', '1/x', '0', '99999999999999999999'])),
        max_size=6), st.sampled_from([' ', '\t', '  '])),
    st.builds(lambda a, b: f"l {a} {b}", st.integers(-3, 9), st.integers(-3, 9)),
    st.sampled_from(['vt 0 0', 'vt', 'vn 0 0 1', '# comment é', '', 'o thing', 'usemtl x', 'f', 'v 1 2',
                     'v 1 2 3 4', 'v 1 2 3 0.5 0.5 0.5', '  v 1 1 1', '\tf 1 2 3', '   ', 'vtx 1',
                     'fo 1 2 3', '\x00\xff garbage', '\ufeffv 1 2 3', '\x0cv 2 2 2', 'l 1/2 2/1']),
)


index = st.one_of(st.integers(1, 12), st.integers(-6, -1))
clean_lines = st.one_of(
    st.builds(lambda a, b, c: f"v {a!r} {b!r} {c!r}", *[st.floats(allow_nan=False, width=64)] * 3),
    st.builds(lambda a, b, c: f"v {a!r} {b!r} {c!r}", *[st.floats(allow_nan=False, width=64)] * 3),
    st.builds(lambda idx: 'f ' + ' '.join(idx), st.lists(st.one_of(
        index.map(str), st.builds(lambda a, b: f"{a}/{b}", index, index),
        st.builds(lambda a, b: f"{a}/{b}/{a}", index, index), st.builds(lambda a: f"{a}//{a}", index)),
        min_size=3, max_size=6)),
    st.sampled_from(['vt 0 0', 'vn 0 0 1', '# comment', '', 'o thing', 'l 1 2 3']),
)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(obj_lines, max_size=14), st.sampled_from(['\n', '\r\n', '\r']), st.booleans())
def test_fast_reader_equals_the_line_reader(tmp_path, lines, eol, last_eol):
    path = tmp_path / 'fuzz.obj'
    path.write_bytes((eol.join(lines) + (eol if last_eol else '')).encode('utf-8', 'replace'))
    _same(str(path))


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(st.lists(clean_lines, min_size=1, max_size=30), st.sampled_from(['\n', '\r\n']))
def test_fast_reader_equals_the_line_reader_on_valid_files(tmp_path, lines, eol):
    """Well-formed files (the fast parser's own domain; references out of range are still errors)."""
    path = tmp_path / 'clean.obj'
    path.write_bytes((eol.join(lines) + eol).encode())
    with open(path, 'rb') as fh:
        assert obj._read_fast(fh.read()) is not None
    _same(str(path))


def test_big_indices_and_many_faces_match(tmp_path):
    """A mesh large enough that indices have several digits, with quads, negative indices and vt."""
    rng = np.random.default_rng(3)
    n = 1200
    V = rng.normal(size=(n, 3))
    parts = ['v %r %r %r\n' % tuple(p) for p in V.tolist()] + ['vt 0.5 0.5\n'] * 30
    for k in range(2000):
        size = 3 + k % 3
        idx = rng.choice(n, size, replace=False) + 1
        form = k % 4
        if form == 0:
            toks = [str(i) for i in idx]
        elif form == 1:
            toks = [f"{i - n - 1}/{rng.integers(1, 31)}" for i in idx]
        elif form == 2:
            toks = [f"{i}//{i}" for i in idx]
        else:
            toks = [f"{i}/{-rng.integers(1, 31)}/7" for i in idx]
        parts.append('f ' + ' '.join(toks) + '\n')
    path = tmp_path / 'big.obj'
    path.write_text(''.join(parts))
    with open(path, 'rb') as fh:
        assert obj._read_fast(fh.read()) is not None
    V2, corners, sizes, cuv, _ = _same(str(path))
    assert np.array_equal(V2, V) and len(sizes) == 2000 and (cuv[sizes[0]:] >= -1).all()


def test_write_round_trip_is_exact(tmp_path):
    rng = np.random.default_rng(0)
    V = np.concatenate([rng.normal(size=(50, 3)) * 10.0 ** rng.integers(-300, 300, (50, 1)),
                        [[0.1, -0.0, 5e-324], [1e6 + 1e-9, 1.0, 2.0 ** 60]]])
    F = rng.integers(0, len(V), (40, 3))
    uv = rng.uniform(-1, 1, (len(V), 2)) * np.pi
    path = tmp_path / 'x.obj'
    write_obj(str(path), V, F, uv)
    back = read_obj(str(path))
    assert np.array_equal(back.V, V) and np.array_equal(back.corner_verts.reshape(-1, 3), F)
    assert np.array_equal(back.corner_uvs.reshape(-1, 3), F)
    text = path.read_text().splitlines()
    vt = np.array([[float(x) for x in s.split()[1:]] for s in text if s.startswith('vt ')])
    assert np.array_equal(vt, uv)


def test_write_polygons_with_corner_uvs(tmp_path):
    V = np.arange(18, dtype=float).reshape(6, 3)
    polys = [np.array([0, 1, 2, 3]), np.array([2, 3, 4]), np.array([1, 2, 4, 5, 0])]
    uv_polys = [np.array([0, 1, 2, 3]), np.array([4, 5, 6]), np.array([7, 8, 9, 10, 11])]
    UV = np.linspace(0, 1, 24).reshape(12, 2)
    path = tmp_path / 'p.obj'
    write_obj(str(path), V, polys, UV=UV, UV_faces=uv_polys)
    back = read_obj(str(path))
    assert back.sizes.tolist() == [4, 3, 5]
    assert np.array_equal(back.corner_verts, np.concatenate(polys))
    assert np.array_equal(back.corner_uvs, np.concatenate(uv_polys))
    write_obj(str(path), V, polys)                  # no UVs: plain 'f a b c' lines
    assert read_obj(str(path)).corner_uvs.tolist() == [-1] * 12
    assert 'f 1 2 3 4\n' in path.read_text()


def test_write_values_exact(tmp_path):
    x = np.random.default_rng(1).normal(size=100) * 1e-7 + 3.0
    path = tmp_path / 'v.txt'
    write_values(str(path), x)
    assert np.array_equal(np.array([float(s) for s in path.read_text().split()]), x)


def test_vertex_text_written_back_as_read(tmp_path):
    """The flatten command writes the input's own ``v`` lines back (same numbers, same text)."""
    src = tmp_path / 'in.obj'
    src.write_text("# x\nv 0 0 0\nv 1.0 0 0\r\nv\t1 1e0  0\nv 0 1 0.30000000000000004\nf 1 2 3 4\n")
    mesh = read_obj(str(src))
    assert mesh.v_text.count(b'\n') == 4
    out = tmp_path / 'out.obj'
    uv = mesh.V[:, :2] * 2
    write_obj(str(out), mesh.V, mesh.polygons(), uv, v_text=mesh.v_text)
    back = read_obj(str(out))
    assert np.array_equal(back.V, mesh.V) and np.array_equal(back.corner_verts, mesh.corner_verts)
    text = out.read_text()
    assert text.startswith("v 0 0 0\nv 1.0 0 0\nv\t1 1e0  0\nv 0 1 0.30000000000000004\nvt ")
    # text that does not match the vertices (another count) is not used: V is formatted instead
    write_obj(str(out), mesh.V[:3], [[0, 1, 2]], v_text=mesh.v_text)
    assert np.array_equal(read_obj(str(out)).V, mesh.V[:3])
    assert obj._read_lines(str(src)).v_text is None
