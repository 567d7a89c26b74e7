"""The L2 start of the cone placement: a nearly sparse curvature, its peaks and backward elimination
(core.atlas.cones.sparse_curvature, _peaks, _screen_removals, eliminate; docs/cones.md, "Placement")."""
import numpy as np

from core.atlas.cones import ConeSystem, _peaks, _score, _screen_removals, eliminate, sparse_curvature
from core.surfaces import blob
from test_cones import rounded_cube


def test_sparse_curvature_concentrates_at_the_cube_corners():
    V, F, corners = rounded_cube(8, 0.3)
    sy = ConeSystem(V, F)
    u, kap = sparse_curvature(sy)
    # kappa = L u + Omega: Gauss-Bonnet by construction, and u is the solve's
    assert abs(kap.sum() - 4 * np.pi) < 1e-8
    assert np.allclose(sy.L @ u + sy.Omega, kap)
    # nearly all of it sits in the corners' one-rings, and the 8 peaks are the corners
    near = sy.rings(corners, 1)
    assert kap[near].sum() > 0.9 * 4 * np.pi
    assert np.abs(kap[~near]).sum() < 0.1 * 4 * np.pi
    assert sorted(_peaks(sy, kap, 8)) == sorted(corners.tolist())


def test_screened_removals_are_the_exact_angles_without_active_bounds():
    V, F = blob(6)
    sy = ConeSystem(V, F)
    sy.bounds = (-50.0, 50.0)
    S = [3, 50, 120, 200, 260, 330]
    approx = _screen_removals(sy, S)
    exact = [_score(sy, S[:i] + S[i + 1:])[0] for i in range(len(S))]
    assert np.allclose(approx, exact, rtol=1e-7, atol=0)


def test_elimination_keeps_the_best_subset_of_a_pool():
    V, F, corners = rounded_cube(6, 0.3)
    sy = ConeSystem(V, F)
    rng = np.random.default_rng(3)
    ok = np.nonzero(sy.eligible & ~sy.rings(corners, 2))[0]
    pool = corners.tolist() + rng.choice(ok, 10, replace=False).tolist()
    S, kap, spread = eliminate(sy, pool, 8)
    # the ten decoys go, the corners stay; the spread reported is the exact score of the set
    assert sorted(S) == sorted(corners.tolist())
    assert np.isclose(spread, _score(sy, S)[0]) and abs(kap.sum() - 4 * np.pi) < 1e-9
    # with a target it goes on thinning below the count only while the target holds
    S2, _, s2 = eliminate(sy, pool, 12, target_ratio=spread - 1e-9)
    assert len(S2) < 12 and s2 >= spread - 1e-9 and set(corners.tolist()) <= set(S2)
    S3, _, _ = eliminate(sy, pool, 12, target_ratio=1.0)
    assert len(S3) == 12
