"""Issue 16 (latency): the faster topology helpers give the same answers as the plain COO graphs they
replaced, and ``check_mesh`` reports the number of parts the disk dispatch of ``unwrap`` relies on."""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from meshgen import grid, uv_sphere
from core.atlas.unwrap import unwrap
from core.mesh import topology
from core.mesh.validate import check_mesh


def _reference_face_components(F, n):
    tw = topology.twin_halfedges(F, n)
    t = np.arange(3 * len(F)) // 3
    ok = tw >= 0
    A = sp.coo_matrix((np.ones(ok.sum()), (t[ok], tw[ok] // 3)), shape=(len(F), len(F)))
    return connected_components(A, directed=False)


def _reference_fans(F, n):
    tw = topology.twin_halfedges(F, n)
    c = np.arange(3 * len(F))
    ok = tw >= 0
    other = (tw[ok] // 3) * 3 + (tw[ok] % 3 + 1) % 3
    k, lab = connected_components(sp.coo_matrix((np.ones(ok.sum()), (c[ok], other)),
                                                shape=(3 * len(F), 3 * len(F))), directed=False)
    cv = np.empty(k, np.int64)
    cv[lab] = F.ravel()
    return np.bincount(cv, minlength=n)


def _pieces():
    """Three parts: a grid, a sphere with its faces shuffled, and a bow tie (two triangles sharing
    one vertex: a pinched fan)."""
    V1, F1 = grid(6)
    V2, F2, _ = uv_sphere(6, 10)
    F2 = F2[np.random.default_rng(3).permutation(len(F2))]
    V3 = np.array([[5.0, 0, 0], [6, 0, 0], [5.5, 1, 0], [5, 2, 0], [6, 2, 0]])
    F3 = np.array([[0, 1, 2], [2, 4, 3]])
    V = np.vstack([V1, V2, V3])
    F = np.vstack([F1, F2 + len(V1), F3 + len(V1) + len(V2)])
    return V, F


def test_face_components_and_fans_match_the_coo_graphs():
    V, F = _pieces()
    n = len(V)
    got_k, got = topology.face_components(F, n)
    ref_k, ref = _reference_face_components(F, n)
    assert got_k == ref_k == 4                   # grid, sphere and the two triangles of the bow tie
    assert np.array_equal(got, ref)
    fans = topology.vertex_fans(F, n)
    assert np.array_equal(fans, _reference_fans(F, n))
    assert fans.max() == 2 and int((fans == 2).sum()) == 1     # the bow tie's shared vertex
    # a single triangle and a mesh without interior edges have one part per triangle
    assert topology.face_components(np.array([[0, 1, 2]]), 3)[0] == 1
    assert topology.face_components(np.array([[0, 1, 2], [3, 4, 5]]), 6)[0] == 2


def test_check_mesh_counts_parts_and_unwrap_dispatch_uses_it():
    V, F = grid(6)
    assert check_mesh(V, F, kind='surface').parts == 1
    V2 = np.vstack([V, V + [20.0, 0, 0]])
    F2 = np.vstack([F, F + len(V)])
    assert check_mesh(V2, F2, kind='surface', allow_parts=True).parts == 2
    one = unwrap(V, F, boundary='area')
    two = unwrap(V2, F2, boundary='area')
    assert one.report['path'] == 'disk' and one.report['flips'] == 0
    assert two.report['path'] == 'islands' and two.report['islands'] == 2 and two.report['flips'] == 0


def test_disk_dispatch_checks_once_and_flattens_the_same(monkeypatch):
    """``unwrap``'s disk path hands its check's boundary loop to ``flatten`` (``checked_loop``): the
    mesh is checked once, and the map is the one ``flatten`` makes after its own check."""
    import core.atlas.unwrap as unwrap_mod
    import core.disk.flatten as flatten_mod
    from core.disk.flatten import flatten
    from core.surfaces import make_surface
    V, F = make_surface('bump3', 17)
    calls = []
    real = check_mesh

    def counting(*a, **k):
        calls.append(k.get('kind'))
        return real(*a, **k)
    monkeypatch.setattr(unwrap_mod, 'check_mesh', counting)
    monkeypatch.setattr(flatten_mod, 'check_mesh', counting)
    res = unwrap(V, F, boundary='uniform', fit='true_scale', bound=True)
    assert res.report['path'] == 'disk' and len(calls) == 1
    monkeypatch.undo()
    ref = flatten(V, F, boundary='uniform', bound=True)
    assert np.array_equal(res.uv, ref.uv)
    assert res.report['bound_vertex'] == ref.report['bound_vertex']
    loop = check_mesh(V, F).boundary
    again = flatten(V, F, boundary='uniform', bound=True, checked_loop=loop)
    assert np.array_equal(again.uv, ref.uv) and again.report['mu_ratio'] == ref.report['mu_ratio']
