"""Charts of an overlapping flat layout (docs/cones.md, "Charts"): ``split_overlaps`` cuts a layout
whose boundary crosses itself along shortest interior paths until no piece overlaps, then
``merge_charts`` glues pieces back where their union does not overlap; each piece keeps its
coordinates. Used by the cone layouts (``cones``) and by ``islands`` for an island's map that
overlaps itself without folding."""
import numpy as np

from ..mesh import topology
from ..mesh.geometry import weighted_graph
from .cut import boundary_crossings, cut_along_seams, shelf_pack
from .cutgraph import avoiding, inner_mask, is_disk

MAX_SPLITS = 30                    # an overlapping layout is split into at most MAX_SPLITS + 1 charts
                                   # (then glued back where the pieces do not overlap: ``merge_charts``;
                                   # rocker-arm x1's one click needed 16 splits for 6 charts)


def _cut_twins(Fc, twin):
    """Twins (3m,) of the half-edges of ``Fc`` (m,3), a cut of a manifold oriented mesh (its faces
    in the same order, e.g. ``cut_along_seams``'s) whose own twins are ``twin`` (3m,): two half-edges
    stay twins unless the cut separated their ends. Equal to ``topology.twin_halfedges`` of ``Fc``
    without its sort (a half-edge b->a of the cut maps to the mesh's unique one)."""
    start = Fc.ravel()
    end = Fc[:, [1, 2, 0]].ravel()
    h = np.flatnonzero(twin >= 0)
    t = twin[h]
    keep = (start[h] == end[t]) & (end[h] == start[t])
    out = np.full(len(start), -1, np.int64)
    out[h[keep]] = t[keep]
    return out


def _piece_crossings(Fc, uvc, face_island, n_islands, segments=False, twin=None):
    """Boundary self-crossings of every piece (island) of a cut layout: list of (count, segments
    (k,2) of split-vertex pairs, boundary loops) per piece. ``twin`` (3m,) optional: the half-edge
    twins of the mesh that ``Fc`` (m,3) is a cut of (``_cut_twins``)."""
    # one pass over all pieces: they share no split vertex, so the loops of the whole cut layout,
    # grouped by piece, are each piece's own loops in the same order (longest first)
    owner = np.full(len(uvc), -1, np.int64)
    owner[Fc.ravel()] = np.repeat(face_island, 3)
    by_piece = [[] for _ in range(n_islands)]
    tw = None if twin is None else _cut_twins(Fc, twin)
    for lp in topology.boundary_loops(Fc, len(uvc), twin=tw):
        by_piece[owner[lp[0]]].append(lp)
    out = []
    for loops in by_piece:
        cnt, seg = boundary_crossings(uvc, loops, return_segments=True)
        out.append((cnt, seg, loops))
    return out


def _interior_path(V, vert_of, E, onb, p, q, N, lp=None, inner=None):
    """Shortest path (list of split vertices) from ``p`` to ``q`` over the edges ``E`` (k,2) with their
    3D lengths, or None. Edges touching a boundary vertex (``onb`` (N,) bool) other than ``p`` and
    ``q`` cost ten times their length (such a path splits a piece into more than two, which is
    allowed), the boundary edges of ``lp`` (the loop) are never used, and an edge whose mesh
    vertices are a pair of ``inner`` (k,2: a polygon's diagonal) costs the total length on top."""
    from scipy.sparse.csgraph import dijkstra
    if p == q:
        return None
    end = np.zeros(N, bool)
    end[[p, q]] = True
    if lp is not None:
        a, b = lp, np.roll(lp, -1)
        bkey = np.minimum(a, b) * N + np.maximum(a, b)
        E = E[~np.isin(np.minimum(E[:, 0], E[:, 1]) * N + np.maximum(E[:, 0], E[:, 1]), bkey)]
    w = np.maximum(np.linalg.norm(V[vert_of[E[:, 0]]] - V[vert_of[E[:, 1]]], axis=1), 1e-300)
    touch = (onb[E[:, 0]] & ~end[E[:, 0]]) | (onb[E[:, 1]] & ~end[E[:, 1]])
    w = np.where(touch, 10 * w, w)
    w = avoiding(w, np.sort(vert_of[E], 1), inner, len(V))
    G = weighted_graph(E, w, N)
    dist, pred = dijkstra(G, directed=False, indices=p, return_predecessors=True)
    if not np.isfinite(dist[q]):
        return None
    path = [q]
    while path[-1] != p:
        path.append(int(pred[path[-1]]))
    return path


def _crossing_pairs(uv, seg):
    """Pairs of the segments ``seg`` (k,2) (vertex pairs, positions ``uv``) that cross each other."""
    P, Q = uv[seg[:, 0]], uv[seg[:, 1]]

    def orient(p, q, r):
        return np.sign((q[..., 0] - p[..., 0]) * (r[..., 1] - p[..., 1])
                       - (q[..., 1] - p[..., 1]) * (r[..., 0] - p[..., 0]))
    a, b = np.triu_indices(len(seg), 1)
    x = (orient(P[a], Q[a], P[b]) * orient(P[a], Q[a], Q[b]) < 0) & \
        (orient(P[b], Q[b], P[a]) * orient(P[b], Q[b], Q[a]) < 0)
    return [(seg[i], seg[j]) for i, j in zip(a[x], b[x])]


def split_overlaps(V, F, cut, uvc, seams, max_splits=MAX_SPLITS, twin=None, inner=None):
    """Split an overlapping layout into charts (docs/cones.md, "Charts"). The layout of the cut disk
    is one flat metric, so any piece of it is laid out by the same coordinates: a piece whose boundary
    crosses itself is cut in two along the shortest interior path between the middles of the two
    boundary arcs that the first crossing pair separates, which puts the two crossing segments into
    different pieces; repeated up to ``max_splits`` times. The pieces are then moved apart (shelf
    packing). ``V`` (n,3), ``F`` (m,3) the working mesh; ``cut`` (``islands.Cut``) and ``uvc`` (N,2)
    its cut disk and layout; ``seams`` (k,2); ``twin`` (3m,) optional: ``F``'s half-edge twins
    (``topology.twin_halfedges``); ``inner`` (k,2): polygons' diagonals, which the splitting paths avoid
    where they can. Returns (cut, uvc, seams, crossings left, splits)."""
    n = len(V)
    if twin is None:
        twin = topology.twin_halfedges(F, n)
    splits = 0
    base = np.asarray(seams, np.int64).reshape(-1, 2)
    while True:
        pieces = _piece_crossings(cut.F, uvc, cut.face_island, cut.n_islands, twin=twin)
        bad = [i for i, (c, _, _) in enumerate(pieces) if c]
        if not bad or splits >= max_splits:
            break
        added = None
        for i in bad:
            cnt, seg, loops = pieces[i]
            if len(loops) != 1:
                continue
            lp = loops[0]
            pos = -np.ones(len(uvc), np.int64)
            pos[lp] = np.arange(len(lp))
            for s1, s2 in _crossing_pairs(uvc, seg):
                a, b = int(pos[s1[0]]), int(pos[s2[0]])
                if a < 0 or b < 0:
                    continue
                nl = len(lp)
                Fi = cut.F[cut.face_island == i]
                E0, _ = topology.unique_edges(Fi)
                onb = np.zeros(len(uvc), bool)
                onb[lp] = True
                path = first = None
                arc1, arc2 = (b - a) % nl, (a - b) % nl
                for f1, f2 in ((2, 2), (1, 2), (3, 2), (2, 1), (2, 3), (1, 1), (3, 3)):
                    p = int(lp[(a + arc1 * f1 // 4) % nl])
                    q = int(lp[(b + arc2 * f2 // 4) % nl])
                    path = _interior_path(V, cut.vert_of, E0, onb, p, q, len(uvc), lp, inner)
                    if path is None:
                        continue
                    pv = np.sort(np.stack([cut.vert_of[path[:-1]], cut.vert_of[path[1:]]], 1), 1)
                    if not inner_mask(pv, inner, n).any():
                        break                     # (a path through a polygon: the next pair first)
                    first, path = first or path, None
                path = path or first
                if path is None:
                    continue
                pv = cut.vert_of[np.array(path)]
                added = np.sort(np.stack([pv[:-1], pv[1:]], axis=1), axis=1)
                break
            if added is not None:
                break
        if added is None:
            break
        seams = np.unique(np.r_[seams, added], axis=0)
        new = cut_along_seams(F, n, seams, twin=twin)
        uv2 = np.zeros((len(new.vert_of), 2))
        uv2[new.F.ravel()] = uvc[cut.F.ravel()]
        cut, uvc = new, uv2
        splits += 1
    if cut.n_islands > 1:
        cut, uvc, seams = merge_charts(F, n, cut, uvc, seams, base, twin=twin)
    left = sum(c for c, _, _ in _piece_crossings(cut.F, uvc, cut.face_island, cut.n_islands, twin=twin))
    if cut.n_islands > 1:
        # move the pieces apart
        lo = np.full((cut.n_islands, 2), np.inf)
        hi = np.full((cut.n_islands, 2), -np.inf)
        vi = cut.vert_island
        np.minimum.at(lo, vi, uvc)
        np.maximum.at(hi, vi, uvc)
        size = hi - lo
        off, _ = shelf_pack(size, 0.02 * np.sqrt((size[:, 0] * size[:, 1]).sum()))
        uvc = uvc - lo[vi] + off[vi]
    return cut, uvc, seams, int(left), splits


def _is_path(keys, n):
    """True if the edges ``keys`` (k,) (vertex pairs as ``a*n + b``) form one simple path."""
    E = np.stack([keys // n, keys % n], 1)
    verts, inv = np.unique(E, return_inverse=True)
    if len(verts) != len(E) + 1 or np.bincount(inv.ravel()).max() > 2:
        return False
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components
    inv = inv.reshape(-1, 2)
    g = sp.coo_matrix((np.ones(len(E)), (inv[:, 0], inv[:, 1])), shape=(len(verts),) * 2)
    return connected_components(g, directed=False)[0] == 1


def merge_charts(F, n, cut, uvc, seams, base, twin=None):
    """Glue charts of one flat layout back together where that does not overlap (docs/cones.md,
    "Charts"). ``F`` (m,3) the working mesh with ``n`` vertices; ``cut`` (``islands.Cut``) and ``uvc``
    (N,2) its pieces (disks), all laid out by the same flat metric and not yet moved apart, so two
    pieces that share a split seam have equal coordinates on both sides of it; ``seams`` (k,2) the cut
    with the splits; ``base`` (k0,2) the seams that must stay (the cut tree). Greedy: pairs of pieces
    joined by split seams, the longest shared seam first, are glued when the shared seam is one path
    (the union is a disk) and the union's boundary crosses itself no more often than the two pieces'
    boundaries did. ``twin`` (3m,) optional: ``F``'s half-edge twins (saves a sort per call).
    Returns (cut, uvc, seams)."""
    seams = np.unique(np.sort(np.asarray(seams, np.int64).reshape(-1, 2), 1), axis=0)
    w = np.array([n, 1])
    bkey = np.unique(np.sort(np.asarray(base, np.int64).reshape(-1, 2), 1) @ w)
    skey = seams @ w
    keep = np.ones(len(seams), bool)
    extra = ~np.isin(skey, bkey)
    if not extra.any():
        return cut, uvc, seams
    # the two triangles beside every split seam edge, and the pieces they are in
    H = np.stack([F, np.roll(F, -1, 1)], 2).reshape(-1, 2)
    hkey = np.sort(H, 1) @ w
    hit = np.isin(hkey, skey[extra])
    order = np.argsort(hkey[hit], kind='stable')
    hk, hf = hkey[hit][order], np.repeat(np.arange(len(F)), 3)[hit][order]
    same = np.nonzero(hk[:-1] == hk[1:])[0]
    ek, fa, fb = hk[same], cut.face_island[hf[same]], cut.face_island[hf[same + 1]]
    pieces = _piece_crossings(cut.F, uvc, cut.face_island, cut.n_islands, twin=twin)
    cross = np.array([c for c, _, _ in pieces])
    loops = {i: list(lp) for i, (_, _, lp) in enumerate(pieces)}
    lab = np.arange(cut.n_islands)
    failed = set()
    changed = True
    while changed:
        changed = False
        pa, pb = lab[fa], lab[fb]
        two = (pa != pb) & np.isin(ek, skey[keep])
        if not two.any():
            break
        pairs, inv, cnt = np.unique(np.stack([np.minimum(pa, pb)[two], np.maximum(pa, pb)[two]], 1),
                                    axis=0, return_inverse=True, return_counts=True)
        inv, keys = inv.ravel(), ek[two]
        done = set()
        for j in np.argsort(-cnt, kind='stable').tolist():
            a, b = int(pairs[j, 0]), int(pairs[j, 1])
            if a in done or b in done or (a, b) in failed:
                continue
            shared = keys[inv == j]
            c = None
            if _is_path(shared, n):
                c = boundary_crossings(uvc, loops[a] + loops[b])
            else:                            # glued along several paths: the union must still be a disk
                trial = keep & ~np.isin(skey, shared)
                sub = cut_along_seams(F[np.isin(lab[cut.face_island], [a, b])], n, seams[trial], strict=False)
                if sub.n_islands == 1 and is_disk(sub.F, len(sub.vert_of)):
                    c = boundary_crossings(uvc, loops[a] + loops[b])
            if c is None or c > cross[a] + cross[b]:
                failed.add((a, b))
                continue
            keep &= ~np.isin(skey, shared)
            lab[lab == b] = a
            cross[a] = c
            loops[a] = loops[a] + loops.pop(b)
            failed = {p for p in failed if a not in p}
            done.update((a, b))
            changed = True
    if keep.all():
        return cut, uvc, seams
    seams = seams[keep]
    new = cut_along_seams(F, n, seams, twin=twin)
    uv2 = np.zeros((len(new.vert_of), 2))
    uv2[new.F.ravel()] = uvc[cut.F.ravel()]
    return new, uv2, seams
