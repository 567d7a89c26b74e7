"""Property-based robustness tests (hypothesis, fixed seed, bounded examples): random small meshes,
random soups, flipped orientations and degenerate pieces. The core either returns a valid result or
raises its own ``ConformalError``; any other exception fails the test. CF_FUZZ_EXAMPLES=N raises the
number of examples for a longer local hunt (CI uses the fixed default)."""
import os

import numpy as np
from hypothesis import HealthCheck, given, settings, strategies as st

from meshgen import grid
from core.errors import ConformalError
from core.disk.flatten import flatten
from core.atlas.islands import cut_along_seams, unwrap
from core.io.obj import read_obj
from core.mesh.triangulate import triangulate
from core.mesh.validate import check_mesh
from core.mesh import topology

FUZZ = settings(derandomize=True, database=None, deadline=None,
                max_examples=int(os.environ.get('CF_FUZZ_EXAMPLES', 60)),
                suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])

coords = st.one_of(st.integers(-2, 2).map(float),
                   st.floats(-3, 3, allow_nan=False, allow_infinity=False),
                   st.sampled_from([np.nan, np.inf, -np.inf, 1e-300, 1e300]))


@st.composite
def soups(draw):
    """Arbitrary small triangle soups: any coordinates, any indices (some out of range)."""
    n = draw(st.integers(0, 8))
    V = np.array(draw(st.lists(st.tuples(coords, coords, coords), min_size=n, max_size=n)),
                 dtype=np.float64).reshape(-1, 3)
    m = draw(st.integers(0, 10))
    F = np.array(draw(st.lists(st.tuples(*[st.integers(-1, n)] * 3), min_size=m, max_size=m)),
                 dtype=np.int64).reshape(-1, 3)
    return V, F


@st.composite
def damaged_grids(draw):
    """A small height field grid with random damage: deleted, flipped, duplicated and extra faces,
    merged (coincident) vertices, moved vertices, non-finite coordinates."""
    n = draw(st.integers(2, 6))
    V, F = grid(n)
    V = V.copy()
    V[:, 2] = np.array(draw(st.lists(st.floats(-1, 1), min_size=len(V), max_size=len(V))))
    F = F.copy()
    m = len(F)
    ops = draw(st.lists(st.sampled_from(['delete', 'flip', 'dup', 'extra', 'merge', 'move', 'nan',
                                         'collapse', 'none']), max_size=4))
    for op in ops:
        m = len(F)
        if m == 0:
            break
        t = draw(st.integers(0, m - 1))
        i, j = draw(st.integers(0, len(V) - 1)), draw(st.integers(0, len(V) - 1))
        if op == 'delete':
            F = np.delete(F, t, axis=0)
        elif op == 'flip':
            F[t] = F[t, ::-1]
        elif op == 'dup':
            F = np.vstack([F, F[t:t + 1]])
        elif op == 'extra':
            k = draw(st.integers(0, len(V) - 1))
            F = np.vstack([F, [[i, j, k]]])
        elif op == 'merge':
            V[i] = V[j]
        elif op == 'move':
            V[i] = V[j] + draw(st.floats(-1e-9, 1e-9))
        elif op == 'nan':
            V[i, 0] = np.nan
        elif op == 'collapse':
            F[F == i] = j
    return V, F


def _valid_uv(res, n, m, F=None):
    """Finite UVs on every vertex of a face (a loose vertex's are NaN, ``flatten``)."""
    on = np.ones(n, bool)
    if F is not None:
        on[:] = False
        on[np.asarray(F, np.int64).ravel()] = True
    assert res.uv.shape == (n, 2) and np.isfinite(res.uv[on]).all() and np.isnan(res.uv[~on]).all()
    assert res.mu.shape == (m,)
    assert isinstance(res.report['flips'], int)


def _edge_seams(draw, F):
    E, _ = topology.unique_edges(F)
    if len(E) == 0:
        return None
    pick = draw(st.lists(st.integers(0, len(E) - 1), max_size=6))
    return E[pick] if pick else None


@FUZZ
@given(soups())
def test_soups_check_and_flatten(mesh):
    V, F = mesh
    for kind in ('disk', 'sphere', 'surface'):
        try:
            check_mesh(V, F, kind=kind)
        except ConformalError:
            pass
    try:
        _valid_uv(flatten(V, F, boundary='area'), len(V), len(F), F)
    except ConformalError:
        pass
    try:
        res = unwrap(V, F, boundary='area')
        assert np.isfinite(res.uv).all()
    except ConformalError:
        pass


@FUZZ
@given(damaged_grids(), st.sampled_from(['area', 'free']))
def test_damaged_grids_flatten(mesh, boundary):
    V, F = mesh
    try:
        _valid_uv(flatten(V, F, boundary=boundary), len(V), len(F), F)
    except ConformalError:
        pass


@FUZZ
@given(damaged_grids(), st.data(), st.sampled_from(['fill', 'cut', 'error']))
def test_damaged_grids_unwrap_with_random_seams(mesh, data, holes):
    V, F = mesh
    seams = None
    if len(F) and F.min() >= 0 and F.max() < len(V):
        seams = _edge_seams(data.draw, F)
    try:
        res = unwrap(V, F, seams=seams, boundary='area', holes=holes, on_error='skip')
    except ConformalError:
        return
    assert np.isfinite(res.uv).all() and res.uv.shape == (len(res.vert_of), 2)
    assert res.F.shape == F.shape and np.array_equal(res.vert_of[res.F], F)
    assert res.uv.min() >= -1e-12 and res.uv.max() <= 1 + 1e-12          # packed in the unit square


@FUZZ
@given(st.integers(2, 7), st.data())
def test_cut_along_random_seams_keeps_corners(n, data):
    V, F = grid(n)
    seams = _edge_seams(data.draw, F)
    cut = cut_along_seams(F, len(V), seams)
    assert np.array_equal(cut.vert_of[cut.F], F)
    assert cut.n_islands >= 1 and len(cut.vert_of) >= len(V)
    # each island's triangles use only that island's vertices
    assert (cut.vert_island[cut.F] == cut.face_island[:, None]).all()


@settings(derandomize=True, database=None, deadline=None, max_examples=8,
          suppress_health_check=[HealthCheck.too_slow])
@given(damaged_grids())
def test_damaged_grids_uniform_mode(mesh):
    V, F = mesh
    try:
        _valid_uv(flatten(V, F, boundary='uniform'), len(V), len(F), F)
    except ConformalError:
        pass


@FUZZ
@given(st.lists(st.integers(3, 8), min_size=1, max_size=6), st.data())
def test_triangulate_random_polygons(sizes, data):
    c = int(np.sum(sizes))
    nv = data.draw(st.integers(3, 12))
    corner_verts = np.array(data.draw(st.lists(st.integers(0, nv - 1), min_size=c, max_size=c)))
    V = np.array(data.draw(st.lists(st.tuples(coords, coords, coords), min_size=nv, max_size=nv)))
    for pos in (None, V):
        tri, tri_poly = triangulate(corner_verts, sizes, pos)
        assert tri.shape == (c - 2 * len(sizes), 3) and len(tri_poly) == len(tri)
        start = np.r_[0, np.cumsum(sizes)[:-1]]
        s, k = start[tri_poly], np.asarray(sizes)[tri_poly]
        assert ((tri >= s[:, None]) & (tri < (s + k)[:, None])).all()      # corners of its polygon
        # every polygon is covered: its triangles use distinct corners
        assert (np.sort(tri, 1)[:, 1:] != np.sort(tri, 1)[:, :-1]).all()


obj_lines = st.one_of(
    st.builds(lambda a, b, c: f"v {a} {b} {c}", coords, coords, coords),
    st.builds(lambda idx: 'f ' + ' '.join(idx), st.lists(
        st.one_of(st.integers(-5, 9).map(str), st.builds(lambda a, b: f"{a}/{b}", st.integers(-3, 9),
                                                         st.integers(-3, 9)),
                  st.builds(lambda a: f"{a}//1", st.integers(1, 9))), max_size=6)),
    st.builds(lambda a, b: f"l {a} {b}", st.integers(-3, 9), st.integers(-3, 9)),
    st.sampled_from(['vt 0 0', 'vn 0 0 1', '# comment', '', 'o thing', 'usemtl x', 'f', 'v 1 2',
                     'v x y z', 's off', '\x00\xff garbage']),
)


@FUZZ
@given(st.lists(obj_lines, max_size=14))
def test_read_obj_random_text(tmp_path_factory, lines):
    path = tmp_path_factory.mktemp('obj') / 'fuzz.obj'
    path.write_text('\n'.join(lines) + '\n', encoding='utf-8', errors='replace')
    try:
        mesh = read_obj(str(path))
    except ConformalError:
        return
    assert mesh.V.shape[1] == 3 and mesh.sizes.min() >= 3
    assert mesh.corner_verts.min() >= 0 and mesh.corner_verts.max() < len(mesh.V)
    assert len(mesh.corner_uvs) == len(mesh.corner_verts)
    try:
        F, _ = mesh.triangles()
        unwrap(mesh.V, F, boundary='area', on_error='skip')
    except ConformalError:
        pass


@st.composite
def punched_spheres(draw):
    """A coarse UV sphere or torus with random faces deleted (holes of any shape, pieces, pinches)
    and random seams."""
    from meshgen import torus, uv_sphere
    if draw(st.booleans()):
        V, F, _ = uv_sphere(draw(st.sampled_from([4, 6, 8])), draw(st.sampled_from([6, 8, 12])))
    else:
        V, F = torus(draw(st.sampled_from([6, 8, 12])), draw(st.sampled_from([4, 6])))
    drop = draw(st.lists(st.integers(0, len(F) - 1), max_size=len(F) // 2))
    F = np.delete(F, drop, axis=0)
    return V, F


@FUZZ
@given(punched_spheres(), st.data(), st.sampled_from(['fill', 'cut', 'error']),
       st.sampled_from(['true', 'normalise']))
def test_punched_surfaces_unwrap(mesh, data, holes, island_scale):
    V, F = mesh
    seams = _edge_seams(data.draw, F) if len(F) else None
    try:
        res = unwrap(V, F, seams=seams, boundary='area', holes=holes, island_scale=island_scale,
                     on_error='skip', allow_loose=True)
    except ConformalError:
        return
    assert np.isfinite(res.uv).all() and np.array_equal(res.vert_of[res.F], F)
    ok = [r for r in res.islands if 'error' not in r]
    assert len(ok) == res.report['flattened'] >= 1
    for r in res.islands:
        assert ('error' in r) or r['faces'] == r['triangles']


@settings(derandomize=True, database=None, deadline=None, max_examples=12)
@given(st.integers(-250, 250))
def test_unwrap_is_scale_invariant(exponent):
    from meshgen import two_holes
    V, F = two_holes('bump', 9)
    ref = unwrap(V, F, boundary='area')
    res = unwrap(V * 10.0 ** exponent, F, boundary='area')
    assert np.allclose(res.uv, ref.uv, atol=1e-9)
    true = unwrap(V * 10.0 ** exponent, F, boundary='area', fit='true_scale')
    assert np.isfinite(true.uv).all()
