"""Cutting a triangle mesh along seams into islands, and the checks of a flat layout that every path
uses: ``cut_along_seams`` (the split vertices and islands, ``Cut``), ``glued_pieces`` (its
inverse: islands glued back where they were cut beyond the seams), ``seam_pairs``,
``boundary_crossings`` (a layout's boundary self-crossings: with no flip, none means no overlap) and
``shelf_pack`` (islands side by side). Below ``islands`` and ``charts``; imports nothing of the atlas."""
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..errors import ConformalError
from ..mesh import topology


@dataclass
class Cut:
    """A triangle mesh cut along seams. ``F`` (m,3) int64 split-vertex ids per corner; ``vert_of``
    (N,) int64 input vertex of each split vertex; ``face_island`` (m,) int64 island of each triangle;
    ``vert_island`` (N,) island of each split vertex; ``n_islands``. Split vertices are numbered
    island by island, so island i owns ids ``vert_start[i]:vert_start[i+1]``."""
    F: np.ndarray
    vert_of: np.ndarray
    face_island: np.ndarray
    vert_island: np.ndarray
    n_islands: int

    @property
    def vert_start(self):
        """(n_islands+1,) first split vertex of each island."""
        return np.r_[0, np.cumsum(np.bincount(self.vert_island, minlength=self.n_islands))]

    def island_faces(self):
        """List of (k_i,) int64 triangle indices of each island, in input order."""
        order = np.argsort(self.face_island, kind='stable')
        cuts = np.cumsum(np.bincount(self.face_island, minlength=self.n_islands))[:-1]
        return np.split(order, cuts)


def seam_edge_counts(F, seams, n, count, part):
    """(count,) int: how many of the edges ``seams`` ((k,2) vertex pairs on ``n`` vertices, or None;
    checked by ``seam_pairs``) lie in each part of the triangles ``F`` (m,3), ``part`` (m,) the part
    of each triangle. An edge counts once per part it lies in."""
    out = np.zeros(count, np.int64)
    S = np.sort(seam_pairs(seams, n), axis=1)
    if not len(S):
        return out
    from ..mesh.topology import halfedges
    H = np.sort(halfedges(F), axis=1)
    on = np.isin(H[:, 0] * n + H[:, 1], S[:, 0] * n + S[:, 1])
    pairs = np.unique(np.c_[np.asarray(part)[np.flatnonzero(on) // 3], H[on]], axis=0)
    np.add.at(out, pairs[:, 0], 1)
    return out


def seam_pairs(seams, n):
    """Check seams and return them as (k,2) int64 vertex pairs. ``seams``: (k,2) array-like of
    vertex indices, or None. Raises ``ConformalError`` naming the bad seams."""
    if seams is None:
        return np.zeros((0, 2), np.int64)
    try:
        S = np.asarray(seams, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise ConformalError(f"seams are not numeric: {exc}") from None
    if S.size == 0:
        return np.zeros((0, 2), np.int64)
    if S.ndim != 2 or S.shape[1] != 2:
        raise ConformalError(f"seams must be a (k,2) array of vertex index pairs, got shape {S.shape}")
    bad = ~np.isfinite(S).all(1) | (S != np.round(S)).any(1)
    if not bad.any():
        bad = (S < 0).any(1) | (S >= n).any(1)
    if bad.any():
        i = int(np.nonzero(bad)[0][0])
        raise ConformalError(f"{int(bad.sum())} seam(s) name vertices that do not exist, e.g. seam {i} "
                             f"{tuple(S[i].tolist())}: seam vertex indices must be integers in 0..{n - 1}")
    S = S.astype(np.int64)
    loop = S[:, 0] == S[:, 1]
    if loop.any():
        i = int(np.nonzero(loop)[0][0])
        raise ConformalError(f"seam {i} joins vertex {S[i, 0]} to itself: a seam is an edge between two "
                             "different vertices")
    return S


def _seam_halfedges(F, n, seams, strict=True):
    """(3m,) bool: half-edges whose undirected edge is a seam. With ``strict``, raises if a seam is
    not an edge of ``F``; otherwise such seams are ignored."""
    S = seam_pairs(seams, n)
    H = topology.halfedges(F)
    if len(S) == 0:
        return np.zeros(len(H), bool)
    hkey = np.minimum(H[:, 0], H[:, 1]) * n + np.maximum(H[:, 0], H[:, 1])
    skey = np.minimum(S[:, 0], S[:, 1]) * n + np.maximum(S[:, 0], S[:, 1])
    found = np.isin(skey, hkey)
    if strict and not found.all():
        bad = np.nonzero(~found)[0]
        ex = ', '.join(f"({a}, {b})" for a, b in S[bad[:3]].tolist())
        raise ConformalError(f"{len(bad)} seam(s) are not edges of the mesh, e.g. {ex}: a seam must join "
                             "two vertices of one face")
    return np.isin(hkey, skey)


def cut_along_seams(F, n, seams=None, strict=True, twin=None):
    """Cut the triangle mesh ``F`` (m,3) with ``n`` vertices along ``seams`` ((k,2) vertex pairs or
    None). The mesh must be manifold and consistently oriented (``check_mesh``). ``strict``: a seam
    that is not an edge of ``F`` is an error (else ignored, e.g. seams outside a selection).
    ``twin`` (3m,) optional: ``topology.twin_halfedges(F, n)``, if the caller has it (repeated cuts
    of one mesh). Returns ``Cut``."""
    F = np.asarray(F, np.int64)
    m = len(F)
    tw = topology.twin_halfedges(F, n) if twin is None else twin
    join = (tw >= 0) & ~_seam_halfedges(F, n, seams, strict)
    h = np.nonzero(join)[0]
    ones = np.ones(len(h), np.int8)
    n_isl, face_island = connected_components(
        sp.coo_matrix((ones, (h // 3, tw[h] // 3)), shape=(m, m)), directed=False)
    # corner 3t+k sits at F[t,k]; the twin of half-edge h (leaving that corner) ends at the same vertex
    other = (tw[h] // 3) * 3 + (tw[h] % 3 + 1) % 3
    _, wedge = connected_components(sp.coo_matrix((ones, (h, other)), shape=(3 * m, 3 * m)),
                                    directed=False)
    Fr = F.ravel()
    _, first = np.unique(wedge, return_index=True)
    w_vert, w_isl = Fr[first], face_island[first // 3]
    order = np.lexsort((w_vert, w_isl))
    newid = np.empty(len(order), np.int64)
    newid[order] = np.arange(len(order))
    return Cut(F=newid[wedge].reshape(m, 3), vert_of=w_vert[order], face_island=face_island.astype(np.int64),
               vert_island=w_isl[order].astype(np.int64), n_islands=int(n_isl))


def glued_pieces(F, Fs, island, seams, n):
    """The surface the answers are on, rebuilt from a flattening's islands: the islands (``island``
    (m,)) of the triangles ``F`` (m,3) on ``n`` input vertices, with split vertex ids ``Fs`` (m,3),
    glued back across every edge held by exactly two triangles (neither naming a vertex twice) that is
    not in ``seams`` ((k,2) vertex pairs or None). Returns ``(piece (m,), n_pieces, glued (N,), joined
    (n_pieces,) bool)``: the piece of each triangle, the glued id of each split vertex, and the pieces
    in which the flattening cut more than the seams and the mesh's non-manifold edges do (two islands,
    or two split copies of a vertex, glued together)."""
    m, N = len(F), int(Fs.max()) + 1 if len(Fs) else 0
    h1, h2, key = topology.two_sided_edges(F, n)
    ok = ~topology.repeated_vertex(F)
    good = ok[h1 // 3] & ok[h2 // 3]
    if seams is not None and len(seams):
        S = np.sort(np.asarray(seams, np.int64), axis=1)
        good &= ~np.isin(key, S[:, 0] * n + S[:, 1])
    h1, h2 = h1[good], h2[good]
    t1, t2 = h1 // 3, h2 // 3
    Fr, Sr = F.ravel(), Fs.ravel()
    a1, b1 = h1, 3 * t1 + (h1 % 3 + 1) % 3                     # corners of the edge's ends in t1
    a2, b2 = h2, 3 * t2 + (h2 % 3 + 1) % 3
    same = Fr[a1] == Fr[a2]                                    # both run the same way (misoriented)
    c_a2, c_b2 = np.where(same, a2, b2), np.where(same, b2, a2)
    ja, jb = np.r_[Sr[a1], Sr[b1]], np.r_[Sr[c_a2], Sr[c_b2]]
    ones = np.ones(len(ja), np.int8)
    _, glued = connected_components(sp.coo_matrix((ones, (ja, jb)), shape=(N, N)), directed=False)
    n_isl = int(island.max()) + 1 if m else 0
    ones = np.ones(len(t1), np.int8)
    n_pieces, piece_of = connected_components(
        sp.coo_matrix((ones, (island[t1], island[t2])), shape=(n_isl, n_isl)), directed=False)
    piece = piece_of[island]
    joined = np.zeros(n_pieces, bool)
    joined[piece[t1[island[t1] != island[t2]]]] = True
    split = ja != jb
    joined[piece[np.r_[t1, t1][split]]] = True
    return piece, n_pieces, glued, joined


COLLINEAR = 1e-10    # ``boundary_crossings``: sin of the angle under which three points count as collinear


def boundary_crossings(uv, loops, return_segments=False):
    """Number of pairs of boundary segments that cross each other in the UV plane. ``uv`` (n,2),
    ``loops`` list of (k,) vertex loops. Together with zero flipped triangles, zero crossings means
    the map of a disk is one-to-one (no overlap). With ``return_segments``, returns (count, (k,2)
    int64 vertex pairs of the segments involved)."""
    if not loops:
        return (0, np.zeros((0, 2), np.int64)) if return_segments else 0
    a = np.concatenate(loops)
    b = np.concatenate([np.roll(lp, -1) for lp in loops])
    P, Q = uv[a], uv[b]
    lo_x, hi_x = np.minimum(P[:, 0], Q[:, 0]), np.maximum(P[:, 0], Q[:, 0])
    lo_y, hi_y = np.minimum(P[:, 1], Q[:, 1]), np.maximum(P[:, 1], Q[:, 1])
    order = np.argsort(lo_x, kind='stable')
    a, b, P, Q = a[order], b[order], P[order], Q[order]
    lo_x, hi_x, lo_y, hi_y = lo_x[order], hi_x[order], lo_y[order], hi_y[order]

    def orient(p, q, r):
        # 0 within COLLINEAR of a straight angle: the two copies of a cut that a layout closes up on (a
        # flat annulus laid out isometrically) lie on one line up to rounding, and meet the boundary
        # at one point: they touch, they do not cross
        d1, d2 = q - p, r - p
        x = d1[:, 0] * d2[:, 1] - d1[:, 1] * d2[:, 0]
        return np.where(np.abs(x) <= COLLINEAR * np.hypot(*d1.T) * np.hypot(*d2.T), 0.0, np.sign(x))

    count = 0
    hits = []
    i = np.arange(len(a))
    d = 1
    while len(i):
        i = i[i + d < len(a)]
        j = i + d
        i = i[lo_x[j] <= hi_x[i]]           # sorted by lo_x: once a pair misses, later ones miss too
        j = i + d
        cand = (lo_y[j] <= hi_y[i]) & (lo_y[i] <= hi_y[j])
        cand &= (a[i] != a[j]) & (a[i] != b[j]) & (b[i] != a[j]) & (b[i] != b[j])
        ci, cj = i[cand], j[cand]
        if len(ci):
            x = (orient(P[ci], Q[ci], P[cj]) * orient(P[ci], Q[ci], Q[cj]) < 0) & \
                (orient(P[cj], Q[cj], P[ci]) * orient(P[cj], Q[cj], Q[ci]) < 0)
            count += int(x.sum())
            if return_segments and x.any():
                hits += [np.stack([a[ci[x]], b[ci[x]]], 1), np.stack([a[cj[x]], b[cj[x]]], 1)]
        d += 1
    if return_segments:
        return count, (np.concatenate(hits) if hits else np.zeros((0, 2), np.int64))
    return count


def shelf_pack(sizes, margin):
    """Place boxes ``sizes`` (k,2) (width, height) in rows ("shelves"), tallest first, rows about as
    wide as the square root of the total area. ``margin`` is the gap between boxes and around them.
    Returns (offsets (k,2) of the boxes' lower-left corners, (width, height) of the layout)."""
    sizes = np.asarray(sizes, np.float64)
    k = len(sizes)
    off = np.zeros((k, 2))
    if k == 0:
        return off, (0.0, 0.0)
    padded = sizes + margin
    row_w = max(float(padded[:, 0].max()), float(np.sqrt((padded[:, 0] * padded[:, 1]).sum())))
    x = y = margin
    row_h = 0.0
    for i in np.argsort(-sizes[:, 1], kind='stable').tolist():
        if x > margin and x + padded[i, 0] > row_w + margin:
            y += row_h
            x, row_h = margin, 0.0
        off[i] = (x, y)
        x += padded[i, 0]
        row_h = max(row_h, padded[i, 1])
    width = float((off[:, 0] + sizes[:, 0]).max() + margin)
    height = float((off[:, 1] + sizes[:, 1]).max() + margin)
    return off, (width, height)
