"""Small intrinsically flat islands, laid out without the disk pipeline.

An island that is a disk with every vertex on its boundary has no interior vertex, so no curvature
inside: its metric is flat and its conformal map, in every boundary mode, is the isometry that
unfolds it triangle by triangle across its edges (its triangles form a tree). Hair cards, foliage
quads, strips and the triangles of a triangle soup are such islands, thousands to a mesh; the disk
pipeline took 2-6 ms for each. ``unfold_flat_disk`` unfolds one and checks that the result is a
map (no flipped triangle, no boundary crossing: a long curled strip can unfold onto itself), so a
caller can fall back to the full pipeline where it is not.
"""
import numpy as np

from ..mesh import topology
from .cut import boundary_crossings

FLAT_TREE_MAX = 64        # triangles in an island unfolded this way at most (a Python walk)


def unfold_flat_disk(V, F, max_faces=FLAT_TREE_MAX):
    """The isometric layout (n,2) of the island ``V`` (n,3), ``F`` (m,3) (one connected piece,
    counter-clockwise, no degenerate triangle) if it is a disk of at most ``max_faces`` triangles
    with every vertex on its boundary and its unfolding is one-to-one, else None. The layout keeps
    every side length (to round-off), is counter-clockwise and centred on the mean of its vertices."""
    n, m = len(V), len(F)
    if m > max_faces or n != m + 2:              # a disk of m triangles with no interior vertex
        return None
    P = np.asarray(V, np.float64)
    side = np.linalg.norm(P[F] - P[np.roll(F, -1, axis=1)], axis=2)
    if not (side > 0).all():                     # a zero-length side (coincident vertices)
        return None
    twin = topology.twin_halfedges(F, n)
    loops = topology.boundary_loops(F, n, twin=twin)
    if len(loops) != 1 or len(loops[0]) != n:
        return None
    uv = np.full((n, 2), np.nan)

    def third(i, j, k):
        """Place corner k of a counter-clockwise triangle (i, j, k), i and j placed."""
        e = uv[j] - uv[i]
        d2 = float(e @ e)
        lik, ljk = P[k] - P[i], P[k] - P[j]
        a2, b2 = float(lik @ lik), float(ljk @ ljk)
        x = (a2 - b2 + d2) / (2.0 * d2)
        y = np.sqrt(max(a2 / d2 - x * x, 0.0))
        uv[k] = uv[i] + x * e + y * np.array([-e[1], e[0]])

    a, b, c = F[0]
    uv[a] = 0.0
    uv[b] = [np.linalg.norm(P[b] - P[a]), 0.0]
    third(a, b, c)
    seen = np.zeros(m, bool)
    seen[0] = True
    stack = [0]
    while stack:
        t = stack.pop()
        for s in range(3):
            h = twin[3 * t + s]
            if h < 0 or seen[h // 3]:
                continue
            u = h // 3
            seen[u] = True
            r = h % 3                                 # the side of u on the shared edge: corners r, r + 1
            i, j, k = F[u, r], F[u, (r + 1) % 3], F[u, (r + 2) % 3]
            third(i, j, k)
            stack.append(u)
    if not seen.all() or not np.isfinite(uv).all():
        return None
    W = uv[F]
    e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    if not (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] > 0).all() or boundary_crossings(uv, loops):
        return None
    return uv - uv.mean(0)
