"""Midpoint subdivision (core/mesh/subdivide.py): the same surface on four times the triangles, with
surface points and seam edges carried over."""
import numpy as np
import pytest

from core.errors import ConformalError
from core.mesh.subdivide import subdivide, subdivide_pairs, subdivide_points
from core.surfaces import make_surface


def test_points_and_seams_follow_the_subdivision():
    """Random surface points land in a child triangle at the same 3D position with barycentric
    coordinates in [0, 1] summing to 1; the children keep their parent's area and winding; an edge
    becomes its two halves through the midpoint; a pair that is no edge (or out of range) is refused."""
    V, F = make_surface('edgebump', 9)
    V2, F2 = subdivide(V, F)
    assert np.array_equal(V2[:len(V)], V) and len(F2) == 4 * len(F)

    def normals(V, F):
        return np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    n2 = normals(V2, F2).reshape(4, len(F), 3)
    assert np.allclose(np.linalg.norm(n2, axis=2).sum(0), np.linalg.norm(normals(V, F), axis=1), rtol=1e-12)
    assert (np.einsum('kfd,fd->kf', n2, normals(V, F)) > 0).all()
    rng = np.random.default_rng(1)
    f = rng.integers(0, len(F), 500)
    b = rng.dirichlet([1, 1, 1], 500)
    f2, b2 = subdivide_points(len(F), f, b)
    X = np.einsum('kc,kcd->kd', b, V[F[f]])
    X2 = np.einsum('kc,kcd->kd', b2, V2[F2[f2]])
    assert np.abs(X - X2).max() < 1e-12 and (b2 >= 0).all() and np.allclose(b2.sum(1), 1)
    pairs = subdivide_pairs(F, len(V), F[:10, [1, 0]])
    assert np.array_equal(pairs[0::2, 0], F[:10, 1]) and np.array_equal(pairs[1::2, 1], F[:10, 0])
    mid = pairs[0::2, 1]
    assert np.array_equal(pairs[1::2, 0], mid)
    assert np.allclose(V2[mid], 0.5 * (V[F[:10, 0]] + V[F[:10, 1]]))
    for bad in ([[0, 80]], [[0, len(V) + 5]]):
        with pytest.raises(ConformalError):
            subdivide_pairs(F, len(V), bad)
