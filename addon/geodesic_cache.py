"""What the Geodesic Distance operator keeps between runs (``ops_geodesic``): the ``GeodesicSolver`` of
the last few meshes and options (flattening, grids, rasterised conformal factor, surface-path graphs),
and the last few distance fields each of them answered. Plain Python state of the add-on session; the
core holds none."""
import copy

import numpy as np

from ..core.geodesic.solver import ERROR_TARGET

SOLVER_CACHE_SIZE = 4
_solvers = {}          # cache key -> GeodesicSolver, most recently used last
RESULT_CACHE_SIZE = 8
_results = {}          # (id of a kept solver, its sources) -> (dist, report), most recently used last


def solver_key(digest, boundary, grid, use_seams, seams, error_target=ERROR_TARGET):
    """The cache key of a solver: the mesh hash (``job.mesh_hash``: positions and polygons),
    the options that change the charts, grids or Steiner points, and the seams when they cut."""
    import hashlib
    h = hashlib.blake2b(digest_size=8)
    if use_seams and seams is not None:
        h.update(np.ascontiguousarray(np.sort(seams, axis=1), np.int64).tobytes())
    return (digest, boundary, int(grid or 0), bool(use_seams), float(error_target), h.hexdigest())


def cached_solver(key):
    """The kept ``GeodesicSolver`` for ``key`` (``solver_key``), or None."""
    gs = _solvers.pop(key, None)
    if gs is not None:
        _solvers[key] = gs                      # most recently used last
    return gs


def keep_solver(key, gs):
    """Keep ``gs`` for ``key``, dropping the least recently used beyond ``SOLVER_CACHE_SIZE`` (and the
    results of a solver no longer kept)."""
    old = _solvers.pop(key, None)
    if old is not None and old is not gs:
        _forget_results(old)
    _solvers[key] = gs
    while len(_solvers) > SOLVER_CACHE_SIZE:
        _forget_results(_solvers.pop(next(iter(_solvers))))


def clear_solvers():
    """Forget every kept solver and result (on unregister, and for tests)."""
    _solvers.clear()
    _results.clear()


def _forget_results(gs):
    """Drop the kept results of the solver ``gs`` (it is no longer kept: its id may be reused)."""
    for key in [k for k in _results if k[0] == id(gs)]:
        del _results[key]


def solver_distance(gs, sources, progress=None):
    """``gs.distance(sources)`` for a kept solver (``keep_solver``), and whether it was reused: the
    same solver asked the same source vertices again (a redo that changes only the bands or the colour
    map) answers from its last results, at most ``RESULT_CACHE_SIZE`` in all, without marching again.
    Returns ``(dist (n,), report, reused)``; both are copies."""
    key = (id(gs), np.unique(np.asarray(sources, np.int64)).tobytes())
    got = _results.pop(key, None)
    reused = got is not None
    if not reused:
        dist, rep = gs.distance(sources, progress=progress)
        got = (dist.copy(), copy.deepcopy(rep))
    _results[key] = got                          # most recently used last
    while len(_results) > RESULT_CACHE_SIZE:
        _results.pop(next(iter(_results)))
    return got[0].copy(), copy.deepcopy(got[1]), reused
