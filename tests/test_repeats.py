"""Repeated islands (``core.atlas.repeats``): a copy of an island, moved, renumbered or mirrored, takes
the original's map, and that map is right for the copy (measured on the copy's own triangles)."""
import numpy as np
import pytest

from core.atlas.islands import unwrap
from core.atlas.repeats import match
from core.mesh.measures import signed_uv_areas, uv_measures


def patch(nx=13, ny=7):
    """A curved, asymmetric open patch: V (n,3), F (m,3) counter-clockwise seen from +z."""
    x, y = np.meshgrid(np.linspace(0, 1.6, nx), np.linspace(0, 0.9, ny), indexing='ij')
    z = 0.3 * np.exp(-((x - 0.55) ** 2 + (y - 0.35) ** 2) / 0.08) + 0.1 * x * y
    V = np.stack([x.ravel(), y.ravel(), z.ravel()], 1)
    i, j = np.meshgrid(np.arange(nx - 1), np.arange(ny - 1), indexing='ij')
    a = (i * ny + j).ravel()
    b, c, d = a + ny, a + ny + 1, a + 1
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return V, F


def moved_copy(V, F, seed, mirror=False):
    """The patch rotated, translated, its vertices and triangles renumbered and each triangle's corners
    turned; ``mirror``: reflected, with the triangles' corners reversed (normals outward)."""
    rng = np.random.default_rng(seed)
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    W = V * ([-1.0, 1.0, 1.0] if mirror else 1.0)
    G = F[:, [0, 2, 1]] if mirror else F
    W = W @ Q.T + rng.standard_normal(3) * 5
    p = rng.permutation(len(V))
    inv = np.empty_like(p)
    inv[p] = np.arange(len(p))
    G = inv[G][rng.permutation(len(G))]
    turn = rng.integers(0, 3, len(G))
    G = np.take_along_axis(G, (np.arange(3)[None, :] + turn[:, None]) % 3, 1)
    return W[p], G


def two_islands(copy):
    V, F = patch()
    W, G = copy
    return np.concatenate([V, W]), np.concatenate([F, G + len(V)]), len(F)


@pytest.mark.parametrize('mirror', [False, True])
def test_a_moved_or_mirrored_copy_takes_the_map_and_it_is_conformal_on_the_copy(mirror):
    V0, F0 = patch()
    V, F, m = two_islands(moved_copy(V0, F0, 3, mirror))
    res = unwrap(V, F, boundary='uniform', bound=True, pack=True)
    assert res.report['islands'] == 2 and res.report['repeated_islands'] == 1
    first, second = res.islands
    assert 'repeat_of' in second and 'repeat_of' not in first
    Vs = V[res.vert_of]
    own = [uv_measures(Vs, res.F[rows], res.uv) for rows in (np.arange(m), np.arange(m, 2 * m))]
    # the copy's UVs, measured on the copy's own triangles: no flip, the same ratio and conformality,
    # and its triangles turn the same way in UV as in the input (counter-clockwise), mirrored or not
    assert own[1]['flips'] == 0 == own[0]['flips']
    assert (signed_uv_areas(res.uv, res.F) > 0).all()
    assert own[1]['mu_ratio'] == pytest.approx(own[0]['mu_ratio'], rel=1e-9)
    assert own[1]['qc_mean'] == pytest.approx(own[0]['qc_mean'], rel=1e-9)
    assert own[0]['mu_ratio'] == pytest.approx(first['mu_ratio'], rel=1e-9)
    # and it is the map the copy gets when solved on its own, up to a motion of the plane
    alone = unwrap(*moved_copy(V0, F0, 3, mirror), boundary='uniform', bound=True)
    assert alone.report['repeated_islands'] == 0
    assert second['mu_ratio'] == pytest.approx(alone.islands[0]['mu_ratio'], rel=1e-6)
    assert second['bound_vertex'] == pytest.approx(alone.islands[0]['bound_vertex'], rel=1e-6)
    a = res.uv[res.F[m:]].reshape(-1, 2)
    b = alone.uv[alone.F].reshape(-1, 2)
    a, b = a - a.mean(0), b - b.mean(0)
    a, b = a / np.linalg.norm(a), b / np.linalg.norm(b)      # both layouts are scaled to the unit square
    U, _, Wt = np.linalg.svd(a.T @ b)
    assert np.abs(a @ U @ Wt - b).max() < 1e-6


def test_a_different_shape_is_solved_on_its_own():
    V0, F0 = patch()
    W, G = moved_copy(V0, F0, 5)
    bent = W.copy()
    bent[np.argmax(W[:, 0])] += 1e-3                     # one vertex moved: not the same shape
    V, F, _ = two_islands((bent, G))
    res = unwrap(V, F, boundary='area')
    assert res.report['repeated_islands'] == 0
    assert match(V0, F0, None, W, G, None) is not None
    assert match(V0, F0, None, bent, G, None) is None
    # the same positions with another triangulation (a diagonal flipped) are another mesh
    G2 = F0.copy()
    (a, b, c), d = F0[0], F0[len(F0) // 2, 2]              # the quad's triangles a b c and a c d
    G2[[0, len(F0) // 2]] = [[a, b, d], [b, c, d]]
    assert match(V0, F0, None, V0, G2, None) is None


def test_a_symmetric_shape_is_not_matched_without_its_axes():
    """A square patch has two equal moments: its principal frame is not determined, so no copy of it is
    matched (nothing is reused that is not checked)."""
    V0, F0 = patch(9, 9)
    V0 = V0 * [0.9 / 1.6, 1.0, 0.0]                        # flat square: equal moments in x and y
    W, G = moved_copy(V0, F0, 7)
    assert match(V0, F0, None, W, G, None) is None
    # numbered alike (an array modifier's copy, moved) it is matched vertex for vertex
    rng = np.random.default_rng(2)
    Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
    Q *= np.sign(np.linalg.det(Q))
    got = match(V0, F0, None, V0 @ Q.T + 3.0, F0, None)
    assert got is not None and (got[0] == np.arange(len(V0))).all() and not got[3]
    assert (got[1] == np.arange(len(F0))).all() and not got[2].any()
    # ... but not if a vertex moved, nor a curved patch mirrored with its triangles kept (their
    # orientation reversed: not a rotation; the flat square mirrored is one, turned over)
    bent = V0 @ Q.T
    bent[5] += 1e-3
    assert match(V0, F0, None, bent, F0, None) is None
    V1, F1 = patch()
    assert match(V1, F1, None, V1 * [-1.0, 1.0, 1.0], F1, None) is None


def test_automatic_seams_place_the_cones_of_a_repeated_part_once():
    """An array of one closed part (copies numbered alike, each rotated and moved) with automatic
    seams: the first copy is placed and laid out, the others take its cones, seams and layout, which
    are right for them (no flip, the same measures on their own triangles)."""
    from core import unwrap as core_unwrap
    from core.surfaces import blob
    V0, F0 = blob(5)
    V0 = V0 * [1.0, 0.8, 0.6]                             # an ellipsoid-like blob with distinct axes
    rng = np.random.default_rng(4)
    Vs, Fs = [], []
    for k in range(3):
        Q, _ = np.linalg.qr(rng.standard_normal((3, 3)))
        Q *= np.sign(np.linalg.det(Q))
        Vs.append(V0 @ Q.T + 4.0 * k)
        Fs.append(F0 + k * len(V0))
    V, F = np.concatenate(Vs), np.concatenate(Fs)
    res = core_unwrap(V, F, cones='auto')
    assert [r.get('repeat_of') for r in res.islands] == [None, 'part 1', 'part 1']
    assert res.report['flips'] == 0 and res.report['overlaps'] == 0
    m = len(F0)
    corners = np.arange(3 * m).reshape(m, 3)
    own = [uv_measures(V[F[k * m:(k + 1) * m]].reshape(-1, 3), corners,
                       res.uv_corner[k * m:(k + 1) * m].reshape(-1, 2)) for k in range(3)]
    assert all(o['flips'] == 0 for o in own)
    for key in ('qc_mean', 'mu_ratio_p1_p99'):
        assert own[1][key] == pytest.approx(own[0][key], rel=1e-9) == own[2][key]
    cones = [sorted(v - k * len(V0) for v, _ in res.cones if k * len(V0) <= v < (k + 1) * len(V0))
             for k in range(3)]
    assert cones[0] == cones[1] == cones[2] and len(cones[0]) >= 3
    # each copy's corner UVs have the same side lengths as the first's (a rigid motion of them)
    W = res.uv_corner
    sides = [np.linalg.norm(W[k * m:(k + 1) * m] - W[k * m:(k + 1) * m][:, [1, 2, 0]], axis=2)
             for k in range(3)]
    assert np.allclose(sides[1], sides[0], rtol=1e-9, atol=0) and np.allclose(sides[2], sides[0], rtol=1e-9)
    area = [signed_uv_areas(W[k * m:(k + 1) * m].reshape(-1, 2), np.arange(3 * m).reshape(m, 3))
            for k in range(3)]
    assert all((a > 0).all() for a in area)
