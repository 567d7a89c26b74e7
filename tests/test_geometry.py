"""Discrete geometry and topology (docs/math.md §1)."""
import numpy as np
import pytest

from core.mesh.geometry import angle_sums, corner_angles, face_areas
from core.mesh.laplacian import cotan_laplacian, face_gradients, gradient, divergence
from core.surfaces import make_surface
from core.mesh.topology import boundary_loops, euler_characteristic
from core.mesh.validate import check_mesh


def octahedron():
    """A closed genus-0 mesh, counter-clockwise seen from outside."""
    P = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], float)
    T = np.array([[0, 2, 4], [2, 1, 4], [1, 3, 4], [3, 0, 4], [2, 0, 5], [1, 2, 5], [3, 1, 5], [0, 3, 5]])
    return P, T


@pytest.mark.parametrize('name', ['bump', 'bump3', 'edgebump', 'ridge', 'saddle'])
def test_gauss_bonnet_disk(name):
    V, F = make_surface(name, 33)
    info = check_mesh(V, F)
    s = angle_sums(V, F)
    B = np.zeros(len(V), bool)
    B[info.boundary] = True
    k = np.pi - s[B]
    Omega = 2 * np.pi - s[~B]
    assert abs(k.sum() + Omega.sum() - 2 * np.pi) < 1e-10
    assert info.euler == 1


def test_gauss_bonnet_closed():
    V, F = octahedron()
    assert euler_characteristic(F) == 2
    assert abs((2 * np.pi - angle_sums(V, F)).sum() - 4 * np.pi) < 1e-12
    assert boundary_loops(F, len(V)) == []


def test_angles_sum_to_pi_and_areas():
    rng = np.random.default_rng(3)
    V = rng.normal(size=(30, 3))
    F = np.array([[0, 1, 2], [3, 4, 5], [6, 7, 8]])
    th = corner_angles(V, F)
    assert np.allclose(th.sum(1), np.pi)
    P = V[F]
    A = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    assert np.allclose(face_areas(V, F), A)


def test_cotan_laplacian_properties():
    V, F = make_surface('saddle', 17)
    L = cotan_laplacian(V, F)
    assert abs(L - L.T).max() < 1e-12
    assert np.abs(L @ np.ones(len(V))).max() < 1e-10
    rng = np.random.default_rng(0)
    f = rng.normal(size=len(V))
    assert f @ (L @ f) > 0
    # equals the P1 stiffness matrix: L f = div grad f
    G, N, A = face_gradients(V, F)
    assert np.allclose(L @ f, divergence(G, F, A, gradient(G, F, f), len(V)))
    # linear functions are harmonic on a flat mesh, away from the boundary
    Vf, Ff = make_surface('flat', 9)
    info = check_mesh(Vf, Ff)
    Lf = cotan_laplacian(Vf, Ff)
    interior = np.setdiff1d(np.arange(len(Vf)), info.boundary)
    assert np.abs((Lf @ (2 * Vf[:, 0] - 3 * Vf[:, 1]))[interior]).max() < 1e-12


def test_boundary_loop_orientation():
    V, F = make_surface('flat', 5)
    loop = boundary_loops(F, len(V))[0]
    P = V[loop, :2]
    signed = 0.5 * np.sum(P[:, 0] * np.roll(P[:, 1], -1) - np.roll(P[:, 0], -1) * P[:, 1])
    assert len(loop) == 16 and signed > 0        # counter-clockwise, surface on the left


def test_signed_uv_areas_and_vertex_mu():
    from core.mesh.measures import signed_uv_areas, vertex_mu
    uv = np.array([[0.0, 0], [2, 0], [0, 1], [2, 1]])
    F = np.array([[0, 1, 2], [1, 3, 2]])
    assert np.allclose(signed_uv_areas(uv, F), [1.0, 1.0])
    assert np.allclose(signed_uv_areas(uv, F[:, ::-1]), [-1.0, -1.0])
    # geometric mean weighted by area; a NaN triangle is left out; an unused vertex is NaN
    mu = vertex_mu(F, np.array([1.0, 4.0]), np.array([1.0, 3.0]), 5)
    assert mu[0] == pytest.approx(1.0) and mu[3] == pytest.approx(4.0)
    assert mu[1] == pytest.approx(np.exp(0.75 * np.log(4.0)))
    assert np.isnan(mu[4])
    mu = vertex_mu(F, np.array([np.nan, 4.0]), np.array([1.0, 3.0]), 4)
    assert np.isnan(mu[0]) and mu[1] == pytest.approx(4.0)


def test_cross_is_numpys_cross_bit_for_bit():
    """core.mesh.geometry.cross (used by the per-triangle geometry) gives exactly np.cross's numbers,
    with broadcasting (one normal against three edge vectors per triangle)."""
    from core.mesh.geometry import cross
    rng = np.random.default_rng(7)
    a, b = rng.standard_normal((500, 3)), rng.standard_normal((500, 3)) * 1e3
    E = rng.standard_normal((500, 3, 3))
    assert np.array_equal(cross(a, b), np.cross(a, b))
    assert np.array_equal(cross(a[:, None, :], E), np.cross(a[:, None, :], E))
    assert np.allclose(np.einsum('md,md->m', cross(a, b), a), 0.0, atol=1e-9)


def test_norm3_is_numpys_norm_bit_for_bit():
    """core.mesh.geometry.norm3 gives exactly np.linalg.norm's lengths along the last axis."""
    from core.mesh.geometry import norm3
    rng = np.random.default_rng(8)
    x = rng.standard_normal((400, 3, 3)) * rng.uniform(1e-3, 1e3, (400, 3, 1))
    assert np.array_equal(norm3(x), np.linalg.norm(x, axis=2))
    assert np.array_equal(norm3(x[:, 0]), np.linalg.norm(x[:, 0], axis=1))
    assert norm3(np.array([3.0, 4.0, 12.0])) == 13.0


def test_squashed_faces_count_the_maps_squash_not_the_meshs_own_needles():
    """``shape_anisotropy`` is 1 for an equilateral triangle and about length / width for a needle, in
    any scale and orientation; ``squashed_faces`` counts a fat triangle mapped to a sliver, and leaves
    out a needle of the mesh mapped to a fat triangle (its Jacobian is ill-conditioned by its own
    shape) and a needle mapped to itself."""
    from core.mesh.measures import jacobians, shape_anisotropy, singular_values, squashed_faces
    h = np.sqrt(3) / 2
    V = np.array([[0, 0, 0], [1, 0, 0], [0.5, h, 0], [2, 0, 0], [3, 0, 0], [2.5, 1e-5, 0]], float)
    F = np.array([[0, 1, 2], [3, 4, 5]])
    R = np.linalg.qr(np.random.default_rng(1).standard_normal((3, 3)))[0]
    for W in (V, 7.5 * V @ R.T):
        an = shape_anisotropy(W, F)
        assert abs(an[0] - 1) < 1e-9 and 0.5e5 < an[1] < 2e5
    sliver = np.array([[0, 0], [1, 0], [0.5, 1e-5], [2, 0], [3, 0], [2.5, h]])
    same = V[:, :2]
    an = shape_anisotropy(V, F)
    got = squashed_faces(singular_values(jacobians(V, F, sliver)[0]), an, 1e3)
    assert got.tolist() == [True, False]
    got = squashed_faces(singular_values(jacobians(V, F, same)[0]), an, 1e3)
    assert got.tolist() == [False, False]
    line = np.array([[0, 0, 0], [1, 0, 0], [2, 0, 0]], float)
    assert shape_anisotropy(line, np.array([[0, 1, 2]]))[0] == np.inf
