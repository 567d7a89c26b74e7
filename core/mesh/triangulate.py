"""Polygons to triangles. Polygons come packed like Blender's: ``corner_verts`` (c,) vertex index per
corner and ``sizes`` (p,) corners per polygon, polygons stored one after another.

Triangles are kept; quads are split along a diagonal that neither folds them nor repeats an existing
edge (a vertex shared by only two quads would otherwise give duplicate triangles); larger polygons
are ear-clipped in their best-fit plane, so concave n-gons triangulate without overlaps. The result
refers to corners, so per-corner data (UVs) can be written back to the polygons unchanged."""
import numpy as np


def _ear_clip(P):
    """Triangulate one simple polygon with 2D corners P (k,2), counter-clockwise. Returns (k-2,3) local
    corner indices."""
    k = len(P)
    idx = list(range(k))
    out = []

    def cross(o, a, b):
        return (a[0] - o[0]) * (b[1] - o[1]) - (a[1] - o[1]) * (b[0] - o[0])

    guard = 0
    while len(idx) > 3 and guard < 4 * k * k:
        guard += 1
        found = False
        for t in range(len(idx)):
            i0, i1, i2 = idx[t - 1], idx[t], idx[(t + 1) % len(idx)]
            a, b, c = P[i0], P[i1], P[i2]
            if cross(a, b, c) <= 0:
                continue
            inside = False
            for j in idx:
                if j in (i0, i1, i2):
                    continue
                p = P[j]
                if cross(a, b, p) >= 0 and cross(b, c, p) >= 0 and cross(c, a, p) >= 0:
                    inside = True
                    break
            if not inside:
                out.append((i0, i1, i2))
                idx.pop(t)
                found = True
                break
        if not found:       # numerically degenerate polygon: finish as a fan
            break
    for t in range(1, len(idx) - 1):
        out.append((idx[0], idx[t], idx[t + 1]))
    return np.array(out, dtype=np.int64)


def _edge_keys(a, b, n):
    return np.minimum(a, b) * n + np.maximum(a, b)


def _quad_normal_cos(P0, P1, P2, P3):
    """Cosine between the normals of triangles (P0,P1,P2) and (P0,P2,P3), (q,); -1 when either has
    zero area (the split is unusable)."""
    n1 = np.cross(P1 - P0, P2 - P0)
    n2 = np.cross(P2 - P0, P3 - P0)
    l1, l2 = np.linalg.norm(n1, axis=1), np.linalg.norm(n2, axis=1)
    ok = (l1 > 0) & (l2 > 0)
    cos = np.full(len(P0), -1.0)
    cos[ok] = (n1[ok] * n2[ok]).sum(1) / (l1[ok] * l2[ok])
    return cos


def _choose_quad_diagonals(tri, tri_poly, first, sizes, start, corner_verts, V):
    """Split each quad (a,b,c,d) along a-c (the default) or b-d, in place in ``tri``. b-d is used when
    a-c would fold or degenerate the quad (with ``V``), or when the a-c diagonal joins two vertices
    that are already joined by a polygon edge or by another quad's diagonal: that happens around a
    vertex shared by only two quads, and would create duplicate triangles and a non-manifold edge."""
    quads = np.nonzero(sizes == 4)[0]
    if len(quads) == 0:
        return
    s = start[quads]
    a, b, c, d = (corner_verts[s + k] for k in range(4))
    flip = np.zeros(len(quads), bool)
    if V is not None:
        V = np.asarray(V, np.float64)
        with np.errstate(all='ignore'):          # NaN or huge coordinates: keep a-c (checked later)
            cos_ac = _quad_normal_cos(V[a], V[b], V[c], V[d])
            cos_bd = _quad_normal_cos(V[b], V[c], V[d], V[a])
            flip = (cos_ac <= 0) & (cos_bd > cos_ac)
    n = int(corner_verts.max()) + 1
    nxt = np.arange(len(corner_verts)) + 1
    ends = start + sizes
    nxt[ends - 1] = start
    poly_edges = np.unique(_edge_keys(corner_verts, corner_verts[nxt], n))
    # a repeated quad (the same four vertices) must stay a visible duplicate: it follows its original
    _, qfirst, inv = np.unique(np.sort(np.stack([a, b, c, d], 1), axis=1), axis=0, return_index=True,
                               return_inverse=True)
    orig = qfirst[inv.ravel()]
    dup = orig != np.arange(len(quads))
    ac, bd = _edge_keys(a, c, n), _edge_keys(b, d, n)
    for _ in range(2):
        diag = np.where(flip, bd, ac)
        other = np.where(flip, ac, bd)
        conflict = np.isin(diag, poly_edges)
        key = np.where(dup, -1 - np.arange(len(diag)), diag)      # duplicates do not count
        _, kinv, cnt = np.unique(key, return_inverse=True, return_counts=True)
        order = np.arange(len(diag))
        first_of = np.full(len(cnt), len(diag))
        np.minimum.at(first_of, kinv, order)
        conflict |= (cnt[kinv] > 1) & (order != first_of[kinv])
        conflict &= ~np.isin(other, poly_edges) & ~dup
        if not conflict.any():
            break
        flip ^= conflict
    chosen = np.where(flip, bd, ac)
    flip[dup] = ac[dup] != chosen[orig[dup]]
    r = first[quads[flip]]
    sq = s[flip]
    tri[r] = np.stack([sq + 1, sq + 2, sq + 3], axis=1)
    tri[r + 1] = np.stack([sq + 1, sq + 3, sq], axis=1)


def triangulate(corner_verts, sizes, V=None):
    """Triangulate packed polygons.

    corner_verts: (c,) int vertex index per corner. sizes: (p,) int >= 3. V: optional (n,3) positions,
    used to ear-clip polygons of 5 or more corners (without it they are fanned).
    Returns ``tri_corners`` (m,3) int64 corner indices and ``tri_poly`` (m,) int64 polygon index."""
    corner_verts = np.asarray(corner_verts, np.int64)
    sizes = np.asarray(sizes, np.int64)
    start = np.r_[0, np.cumsum(sizes)[:-1]]
    ntri = sizes - 2
    tri_poly = np.repeat(np.arange(len(sizes)), ntri)
    # fan: corner 0, j+1, j+2 for j = 0..size-3
    first = np.r_[0, np.cumsum(ntri)[:-1]]
    j = np.arange(len(tri_poly)) - np.repeat(first, ntri)
    s = start[tri_poly]
    tri = np.stack([s, s + j + 1, s + j + 2], axis=1)
    _choose_quad_diagonals(tri, tri_poly, first, sizes, start, corner_verts, V)
    if V is not None:
        for p in np.nonzero(sizes >= 5)[0].tolist():
            c = np.arange(start[p], start[p] + sizes[p])
            Q = V[corner_verts[c]]
            with np.errstate(all='ignore'):      # NaN or huge coordinates: keep the fan
                nrm = np.cross(Q - Q.mean(0), np.roll(Q, -1, 0) - Q.mean(0)).sum(0)
                length = np.linalg.norm(nrm)
                if not (np.isfinite(length) and length > 0):
                    continue
                nrm /= length
                ax = np.cross(nrm, [1.0, 0, 0]) if abs(nrm[0]) < 0.9 else np.cross(nrm, [0, 1.0, 0])
                ax /= np.linalg.norm(ax)
                ay = np.cross(nrm, ax)
                P2 = np.c_[Q @ ax, Q @ ay]
                if not np.isfinite(P2).all():
                    continue
                local = _ear_clip(P2)
            rows = np.nonzero(tri_poly == p)[0]
            tri[rows] = c[local]
    return tri, tri_poly
