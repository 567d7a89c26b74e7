"""The sparse solve layer (core.mesh.solve: CHOLMOD through cvxopt, SuperLU fallback) and the
``uniform`` mode's fast paths on flat meshes (core.disk.uniform)."""
import numpy as np
import pytest
import scipy.sparse as sp

from core import flatten, make_surface
from core.disk.flatten import DiskSystem
from core.disk.uniform import vertex_bound
from core.errors import ConformalError
from core.mesh import solve
from core.mesh.laplacian import cotan_laplacian
from core.mesh.validate import check_mesh, normalise_scale


def _interior_laplacian(name='bump', n=33):
    V, F = make_surface(name, n)
    info = check_mesh(V, F, kind='disk')
    L = cotan_laplacian(V, F)
    inner = np.setdiff1d(np.arange(len(V)), info.boundary)
    return L[inner][:, inner].tocsc()


def maze(slots=6, rows=24, corridor=3, bend=0.0):
    """A flat serpentine (z = bend * a smooth bump): a grid of unit cells with ``slots`` one-cell-wide
    slots cut alternately from the bottom and the top edge, ``corridor`` cells between them. A disk
    with a long boundary. Returns V (n,3), F (m,3)."""
    nx = slots * (corridor + 1) + corridor
    keep = np.ones((nx, rows), bool)
    for k in range(slots):
        c = corridor + k * (corridor + 1)
        if k % 2 == 0:
            keep[c, :rows - corridor] = False
        else:
            keep[c, corridor:] = False
    i, j = np.nonzero(keep)
    q = np.stack([i * (rows + 1) + j, (i + 1) * (rows + 1) + j, (i + 1) * (rows + 1) + j + 1,
                  i * (rows + 1) + j + 1], 1)
    F = np.concatenate([q[:, [0, 1, 2]], q[:, [0, 2, 3]]])
    X, Y = np.meshgrid(np.arange(nx + 1.0), np.arange(rows + 1.0), indexing='ij')
    V = np.stack([X.ravel(), Y.ravel(), bend * np.sin(X.ravel() / 7) * np.cos(Y.ravel() / 5)], 1)
    used = np.unique(F)
    remap = np.full(len(V), -1)
    remap[used] = np.arange(len(used))
    return V[used], remap[F]


def test_backend_by_size_and_cholmod_when_installed(monkeypatch):
    import cvxopt  # noqa: F401  (requirements.txt pins it; a platform without a wheel falls back)
    monkeypatch.delenv('CONFORMAL_SOLVER', raising=False)
    assert solve.BLAS_THREADS == 1                         # cvxopt's own OpenBLAS, found and limited
    assert solve.backend() == 'cholmod' and solve.backend(solve.CHOLMOD_MIN) == 'cholmod'
    assert solve.backend(solve.CHOLMOD_MIN - 1) == 'superlu'
    small = _interior_laplacian(n=17)                      # 225 rows
    assert solve.Factor(small).backend == 'superlu'
    assert solve.Factor(small, method='cholmod').backend == 'cholmod'
    assert solve.Factor(_interior_laplacian(n=41)).backend == 'cholmod'      # 1521 rows
    monkeypatch.setenv('CONFORMAL_SOLVER', 'cholmod')
    assert solve.Factor(small).backend == 'cholmod'


def test_forced_superlu(monkeypatch):
    monkeypatch.setenv('CONFORMAL_SOLVER', 'superlu')
    assert solve.backend() == 'superlu' and solve.backend(10**7) == 'superlu'
    assert solve.Factor(_interior_laplacian()).backend == 'superlu'


@pytest.mark.parametrize('method', solve.BACKENDS)
def test_solves_match_residual_and_each_other(method):
    K = _interior_laplacian('saddle', 41)
    rng = np.random.default_rng(0)
    b1 = rng.standard_normal(K.shape[0])
    B = rng.standard_normal((K.shape[0], 11))              # >= SPLIT_RHS: the threaded SuperLU path
    f = solve.Factor(K, method=method)
    x1, X = f.solve(b1), f.solve(B)
    assert x1.shape == b1.shape and X.shape == B.shape
    scale = np.abs(K).max() * np.abs(X).max()
    assert np.abs(K @ x1 - b1).max() < 1e-10 * scale
    assert np.abs(K @ X - B).max() < 1e-10 * scale
    assert np.allclose(X[:, 3], f.solve(B[:, 3]), rtol=0, atol=1e-12 * np.abs(X).max())
    ref = sp.linalg.spsolve(K, B)
    assert np.abs(X - ref).max() < 1e-9 * np.abs(ref).max()


def test_cholmod_block_solve_matches_cvxopt_per_column(monkeypatch):
    """CHOLMOD's multi-column solve through ctypes (core.mesh.cholmod_block) is what runs on Linux
    (cvxopt's wheel exports CHOLMOD there), and it gives cvxopt's own per-column answers, across
    several blocks and with a block narrower than the right-hand sides."""
    from core.mesh.cholmod_block import BlockSolver
    block = BlockSolver.load()
    assert block is not None
    K = _interior_laplacian('ridge', 41)
    rng = np.random.default_rng(1)
    B = rng.standard_normal((K.shape[0], 13))
    f = solve.Factor(K, method='cholmod')
    monkeypatch.setattr(solve, 'CHOLMOD_BLOCK_BYTES', 8 * K.shape[0] * 5)     # blocks of 5, 5, 3
    X = f.solve(B)
    x1 = f.solve(B[:, 7])
    monkeypatch.setattr(BlockSolver, 'load', classmethod(lambda cls: None))   # cvxopt's own loop
    ref, ref1 = f.solve(B), f.solve(B[:, 7])
    assert X.shape == B.shape and x1.shape == (K.shape[0],)
    tol = 1e-12 * np.abs(ref).max()
    assert np.abs(X - ref).max() < tol and np.abs(x1 - ref1).max() < tol
    assert np.abs(K @ X - B).max() < 1e-10 * np.abs(K).max() * np.abs(X).max()
    with pytest.raises(ValueError):                         # a capsule that is not a real factor
        block.solve(object(), B)


def test_fortran_order_and_integer_rhs():
    K = _interior_laplacian()
    f = solve.Factor(K)
    B = np.asfortranarray(np.arange(2 * K.shape[0]).reshape(K.shape[0], 2) % 7)
    X = f.solve(B)
    assert np.abs(K @ X - B).max() < 1e-9 * np.abs(B).max()


def test_indefinite_falls_back_to_superlu_and_singular_raises():
    # symmetric, nonsingular, indefinite: CHOLMOD refuses it, LU solves it (a cotan Laplacian of a
    # mesh with very obtuse triangles can be like this)
    K = sp.csc_matrix(np.array([[1.0, 2.0, 0.0], [2.0, 1.0, 0.5], [0.0, 0.5, 3.0]]))
    f = solve.Factor(K, method='cholmod')
    assert f.backend == 'superlu'
    b = np.array([1.0, -2.0, 0.5])
    assert np.allclose(K @ f.solve(b), b)
    with pytest.raises(ConformalError) as exc:
        solve.Factor(sp.csc_matrix(np.ones((3, 3))), method='cholmod')
    assert exc.value.code == 'degenerate'


def test_non_symmetric_goes_to_superlu():
    K = _interior_laplacian().tolil()
    K[0, 1] += 1e-3
    f = solve.Factor(K.tocsc(), method='cholmod')
    assert f.backend == 'superlu'
    b = np.ones(K.shape[0])
    assert np.abs(K.tocsc() @ f.solve(b) - b).max() < 1e-9


def test_flatten_same_map_on_both_backends(monkeypatch):
    V, F = make_surface('edgebump', 33)
    monkeypatch.setenv('CONFORMAL_SOLVER', 'cholmod')
    a = flatten(V, F, boundary='area')
    monkeypatch.setenv('CONFORMAL_SOLVER', 'superlu')
    b = flatten(V, F, boundary='area')
    assert np.abs(a.uv - b.uv).max() < 1e-9 * np.abs(a.uv).max()
    assert a.report['mu_ratio'] == pytest.approx(b.report['mu_ratio'], rel=1e-9)


def test_flat_maze_uniform_returns_area_certified():
    """A nearly flat mesh with a long boundary: the optimiser returns the area map at once, certified
    (its ratio is within ``min_gain`` of 1), with no boundary response solved."""
    V, F = maze(bend=1e-3)
    info = check_mesh(V, F, kind='disk')
    assert len(info.boundary) > 0.4 * len(V)             # a long boundary
    area = flatten(V, F, boundary='area')
    uni = flatten(V, F, boundary='uniform')
    rep = uni.report
    assert 'planar' not in rep
    assert rep['iterations'] == 0 and rep['maps_built'] == 0 and 'area_certified' in rep
    assert np.allclose(uni.uv, area.uv)
    assert rep['flips'] == 0 and rep['mu_ratio'] > 1 - 1e-6 and rep['qc_mean'] < 1 + 1e-6


@pytest.mark.parametrize('mode', ['free', 'area', 'uniform'])
def test_planar_mesh_is_its_own_map(mode):
    """A mesh lying in a plane (here tilted and moved) needs no solve in any mode: the map is the mesh
    itself, an isometry, with the certified bound 1; the same map as the solves give."""
    V, F = maze()
    Q = np.linalg.qr(np.random.default_rng(4).normal(size=(3, 3)))[0]
    V = V @ Q.T * 0.37 + np.array([3.0, -1.0, 2.0])
    r = flatten(V, F, boundary=mode, bound=mode == 'uniform')
    rep = r.report
    assert 'planar' in rep and rep['solver'] is None and 'factor' not in rep['seconds']
    assert rep['flips'] == 0 and rep['mu_ratio'] > 1 - 1e-12 and rep['qc_mean'] < 1 + 1e-12
    E = np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]
    assert np.allclose(np.linalg.norm(r.uv[E[:, 0]] - r.uv[E[:, 1]], axis=1),
                       np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1), rtol=1e-12)
    if mode == 'uniform':
        assert rep['bound_vertex'] == 1.0
    # a lift out of the plane by more than the tolerance: the solves, with the same map up to a
    # rotation (the maze is symmetric: ``normalise_uv``'s orientation is a tie) and small differences
    V2 = V + 1e-6 * np.outer(np.sin(np.arange(len(V))), Q[:, 2])
    s = flatten(V2, F, boundary=mode)
    assert 'planar' not in s.report
    U, _, Wt = np.linalg.svd(s.uv.T @ r.uv)
    assert np.abs(s.uv @ (U @ Wt) - r.uv).max() < 1e-4 * np.abs(r.uv).max()


def test_curved_mesh_still_optimised():
    V, F = make_surface('ridge', 33)
    r = flatten(V, F, boundary='uniform').report
    assert 'area_certified' not in r and r['iterations'] >= 1
    assert r['mu_ratio'] > r['ratio_area_mode']


def test_nearly_flat_bound_says_so_quickly():
    V, F = maze(bend=0.05)
    info = check_mesh(V, F, kind='disk')
    V, _ = normalise_scale(V)
    system = DiskSystem(V, F, info.boundary)
    u0 = system.yamabe(np.zeros(len(system.B)))
    assert 1e-12 < np.ptp(u0) < 1e-3
    with pytest.raises(ConformalError) as exc:
        vertex_bound(system)
    assert exc.value.code == 'solve_failed' and 'nearly flat' in str(exc.value)
    r = flatten(V, F, boundary='uniform', bound=True).report
    assert r['bound_vertex'] is None and 'nearly flat' in r['bound_note']


def test_bound_invariant_to_vertex_order_and_matches_flatten():
    V, F = make_surface('saddle', 25)
    info = check_mesh(V, F, kind='disk')
    Vn, _ = normalise_scale(V)
    b = vertex_bound(DiskSystem(Vn, F, info.boundary))
    perm = np.random.default_rng(1).permutation(len(V))
    inv = np.argsort(perm)
    V2, F2 = V[perm], inv[F]
    info2 = check_mesh(V2, F2, kind='disk')
    V2n, _ = normalise_scale(V2)
    b2 = vertex_bound(DiskSystem(V2n, F2, info2.boundary))
    assert b == pytest.approx(b2, rel=1e-7)
    assert 0 < b < 1
    r = flatten(V, F, boundary='uniform').report
    assert r['bound_vertex'] == pytest.approx(b, rel=1e-9)
    assert r['vertex_ratio'] <= b * (1 + 1e-6)        # no map beats the certified vertex optimum


def _bump_system(n=65):
    V, F = make_surface('bump', n)
    info = check_mesh(V, F, kind='disk')
    L = cotan_laplacian(V, F)
    inner = np.setdiff1d(np.arange(len(V)), info.boundary)
    return V, L, inner


def test_fill_order_is_a_permutation_that_cuts_fill():
    V, L, inner = _bump_system(65)
    K = L[inner][:, inner].tocsc()
    assert solve.fill_order(V[inner], K) is None                 # below ND_MIN: the solver orders
    order = solve.fill_order(V[inner], K, min_size=0, leaf=16)
    assert np.array_equal(np.sort(order), np.arange(K.shape[0]))
    # the same matrix with its rows shuffled: factored in the given order, SuperLU's fill is that of
    # the nested dissection, far below the shuffled natural order and no worse than MMD's
    shuffle = np.random.default_rng(0).permutation(K.shape[0])
    Ks = K[shuffle][:, shuffle].tocsc()
    order = solve.fill_order(V[inner][shuffle], Ks, min_size=0, leaf=16)
    nd = solve.Factor(Ks, method='superlu', order=order)
    mmd = solve.Factor(Ks, method='superlu')
    natural = sp.linalg.splu(Ks, permc_spec='NATURAL', diag_pivot_thresh=0.0,
                             options=dict(SymmetricMode=True))
    fill = {name: f.L.nnz + f.U.nnz for name, f in (('nd', nd._lu), ('mmd', mmd._lu), ('natural', natural))}
    assert nd.backend == 'superlu' and nd.ordering == 'given' and mmd.ordering == 'mmd'
    assert fill['nd'] < 0.1 * fill['natural'] and fill['nd'] < 1.2 * fill['mmd'], fill
    rng = np.random.default_rng(1)
    B = rng.standard_normal((K.shape[0], 9))                 # >= SPLIT_RHS: threaded solve, reordered
    X = nd.solve(B)
    ref = sp.linalg.spsolve(Ks, B)
    assert np.abs(X - ref).max() < 1e-9 * np.abs(ref).max()
    assert np.allclose(nd.solve(B[:, 4]), X[:, 4], rtol=0, atol=1e-12 * np.abs(X).max())
    # CHOLMOD takes the same order as its user ordering: the same solutions
    chol = solve.Factor(Ks, method='cholmod', order=order)
    assert chol.backend == 'cholmod' and chol.ordering == 'given'
    assert np.abs(chol.solve(B) - ref).max() < 1e-9 * np.abs(ref).max()


def test_sub_order_keeps_the_relative_order():
    order = np.array([4, 0, 3, 1, 2])
    assert solve.sub_order(order, np.array([0, 2, 3])).tolist() == [0, 2, 1]    # rows 0, 3, 2
    mask = np.array([True, True, False, True, True])
    assert solve.sub_order(order, mask).tolist() == [3, 0, 2, 1]
    assert solve.sub_order(None, mask) is None
    with pytest.raises(ConformalError):
        solve.Factor(sp.identity(3, format='csc'), order=np.arange(4))


@pytest.mark.parametrize('method', solve.BACKENDS)
def test_flatten_same_map_with_nested_dissection(monkeypatch, method):
    """The big-mesh path (one nested dissection order for both factorisations) gives the map of the
    solver's own ordering, with either backend."""
    V, F = make_surface('ridge', 49)
    monkeypatch.setenv('CONFORMAL_SOLVER', method)
    a = flatten(V, F, boundary='area')
    monkeypatch.setattr(solve, 'ND_MIN', 100)
    b = flatten(V, F, boundary='area')
    assert a.report['solver'] == b.report['solver'] == method
    assert np.abs(a.uv - b.uv).max() < 1e-9 * np.abs(a.uv).max()
    for key in ('mu_ratio', 'qc_mean', 'flips'):
        assert b.report[key] == pytest.approx(a.report[key], rel=1e-9)


def test_cholmod_factorize_without_the_gil_matches_cvxopt(monkeypatch):
    """The numeric factorisation through ctypes (``BlockSolver.factorize``, the GIL free) fills
    cvxopt's symbolic factor with the factor cvxopt's own ``numeric`` computes: the same solves to
    1e-12, also for two factorisations at once on two threads; a matrix that is not positive
    definite raises ArithmeticError there, and ``Factor`` falls back to SuperLU."""
    from concurrent.futures import ThreadPoolExecutor

    from core.mesh.cholmod_block import BlockSolver
    assert BlockSolver.load() is not None
    K1, K2 = _interior_laplacian('ridge', 41), _interior_laplacian('bump', 37)
    B1 = np.random.default_rng(2).standard_normal((K1.shape[0], 3))
    B2 = np.random.default_rng(3).standard_normal((K2.shape[0], 3))
    with ThreadPoolExecutor(2) as ex:
        f1, f2 = ex.map(lambda K: solve.Factor(K, method='cholmod'), (K1, K2))
    X1, X2 = f1.solve(B1), f2.solve(B2)
    monkeypatch.setattr(BlockSolver, 'load', classmethod(lambda cls: None))   # cvxopt's numeric
    g1, g2 = solve.Factor(K1, method='cholmod'), solve.Factor(K2, method='cholmod')
    assert f1.backend == g1.backend == 'cholmod'
    for X, g, B in ((X1, g1, B1), (X2, g2, B2)):
        ref = g.solve(B)
        assert np.abs(X - ref).max() < 1e-12 * np.abs(ref).max()
    monkeypatch.undo()
    from cvxopt import cholmod, spmatrix
    A = spmatrix([1.0, 2.0, 1.0], [0, 1, 1], [0, 0, 1], (2, 2))             # eigenvalues 1 +- 2
    with pytest.raises(ArithmeticError):
        BlockSolver.load().factorize(cholmod.symbolic(A), np.array([0, 2, 3]), np.array([0, 1, 1]),
                                     np.array([1.0, 2.0, 1.0]))


@pytest.mark.parametrize('method', ['superlu', 'cholmod'])
def test_deferred_factor_in_turn_gives_the_same_map(monkeypatch, method):
    """Above PARALLEL_MAX rows the two factorisations run in turn, the second on its own thread
    (FactorJob) while the first one's solves go on: the same map, and a singular matrix still raises
    ConformalError, from result(). Both backends release the GIL while they factor (CHOLMOD through
    ``cholmod_block``)."""
    V, F = make_surface('ridge', 49)
    monkeypatch.setenv('CONFORMAL_SOLVER', method)
    a = [flatten(V, F, boundary=mode, bound=False) for mode in ('area', 'uniform')]
    monkeypatch.setattr(solve, 'PARALLEL_MAX', 100)
    monkeypatch.setattr(solve, 'WORKERS', 2)
    info = check_mesh(V, F, kind='disk')
    system = DiskSystem(normalise_scale(V)[0], F, info.boundary)
    assert system.conjugate_pending and isinstance(system._neumann, solve.FactorJob)
    system.conjugate(np.zeros(system.n))
    assert not system.conjugate_pending
    b = [flatten(V, F, boundary=mode, bound=False) for mode in ('area', 'uniform')]
    for x, y in zip(a, b):
        assert np.abs(x.uv - y.uv).max() < 1e-10 * np.abs(x.uv).max()
        for key in ('mu_ratio', 'qc_mean', 'flips'):
            assert y.report[key] == pytest.approx(x.report[key], rel=1e-10)
    job = solve.FactorJob(sp.csc_matrix((3, 3)))
    with pytest.raises(ConformalError):
        job.result()


@pytest.mark.parametrize('branch', ['threads', 'in_turn', 'deferred'])
def test_factor_all_runs_meanwhile_once_and_factors_the_same(monkeypatch, branch):
    """``factor_all(meanwhile=...)`` calls it exactly once on the calling thread, whichever way the
    factorisations run (two threads at once, in turn, the last deferred), and the factors solve as the
    ones made alone; the disk system's triangle frames made that way are those made afterwards."""
    K = _interior_laplacian('bump', 33)
    K2 = (K + sp.identity(K.shape[0])).tocsc()
    monkeypatch.setattr(solve, 'WORKERS', 2)
    if branch == 'threads':
        monkeypatch.setattr(solve, 'PARALLEL_MIN', 10)
    elif branch == 'in_turn':
        monkeypatch.setattr(solve, 'PARALLEL_MIN', 10 ** 9)
    else:
        monkeypatch.setattr(solve, 'PARALLEL_MAX', 100)
    import threading
    calls = []
    fs = solve.factor_all(K, K2, defer_last=True, meanwhile=lambda: calls.append(threading.get_ident()))
    assert calls == [threading.get_ident()]
    assert isinstance(fs[1], solve.FactorJob) == (branch == 'deferred')
    fs = [f.result() if isinstance(f, solve.FactorJob) else f for f in fs]
    b = np.random.default_rng(3).standard_normal(K.shape[0])
    for M, f in zip((K, K2), fs):
        assert np.abs(f.solve(b) - solve.Factor(M).solve(b)).max() < 1e-10 * np.abs(b).max()
    V, F = make_surface('bump', 33)
    system = DiskSystem(normalise_scale(V)[0], F, check_mesh(V, F, kind='disk').boundary)
    made = system._frames
    system._frames = None
    system._make_frames()
    assert made is not None and all(np.array_equal(x, y) for x, y in zip(made, system._frames))
