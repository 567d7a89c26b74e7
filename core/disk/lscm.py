"""Free-boundary least-squares conformal map (LSCM), the ``free`` boundary mode.

Minimises the conformal energy ``E_C(x, y) = E_D(x) + E_D(y) - A(x, y)``: Dirichlet energy with the
cotan Laplacian ``L`` minus the signed UV area ``A``, which depends only on boundary edges. With two
boundary vertices pinned the (2n,2n) system is symmetric positive definite; it is factored once.
This is the same minimiser as the least-squares formulation Blender's 'Conformal' unwrap uses."""
import numpy as np
import scipy.sparse as sp

from ..mesh.solve import Factor


def conformal_energy_matrix(L, loop):
    """(2n,2n) sparse matrix ``Q`` with ``E_C = 1/2 z^T Q z`` for ``z = [x; y]``. ``loop`` (k,) is the
    boundary loop with the surface on its left."""
    n = L.shape[0]
    i = loop
    j = np.roll(loop, -1)
    # A = 1/2 sum (x_i y_j - x_j y_i) = z^T M z with M symmetric
    r = np.r_[i, n + j, j, n + i]
    c = np.r_[n + j, i, n + i, j]
    v = np.r_[np.full(len(i), 0.25), np.full(len(i), 0.25), np.full(len(i), -0.25), np.full(len(i), -0.25)]
    M = sp.coo_matrix((v, (r, c)), shape=(2 * n, 2 * n)).tocsc()
    return (sp.block_diag([L, L]) - 2 * M).tocsc()


def lscm(V, L, loop):
    """Free-boundary conformal map. ``V`` (n,3), ``L`` cotan Laplacian, ``loop`` outer boundary.
    Returns UV (n,2), with two boundary vertices far apart pinned at (0,0) and (d,0), where d is their
    3D distance. LSCM's map depends on its pins (on ridge, n = 65, the two diagonals of the square give
    mu_ratio 0.086 and 0.060); they are found from the lowest-numbered boundary vertex, whatever the
    loop's start, so ``free`` is the same baseline it always was (it depends on the numbering, as every
    two-pin LSCM does, Blender's included)."""
    n = len(V)
    Q = conformal_energy_matrix(L, loop)
    P = V[loop]
    # two pins far apart: the farthest from the lowest-numbered one, then the farthest from that one
    a = loop[np.argmax(np.linalg.norm(P - V[loop.min()], axis=1))]
    b = loop[np.argmax(np.linalg.norm(P - V[a], axis=1))]
    d = np.linalg.norm(V[a] - V[b])
    pinned = np.array([a, b, n + a, n + b])
    zp = np.array([0.0, d, 0.0, 0.0])
    free = np.setdiff1d(np.arange(2 * n), pinned)
    rhs = -(Q[free][:, pinned] @ zp)
    z = np.empty(2 * n)
    z[pinned] = zp
    z[free] = Factor(Q[free][:, free]).solve(rhs)
    return np.stack([z[:n], z[n:]], axis=1)
