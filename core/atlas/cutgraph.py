"""Cut graphs: the seams that open a closed surface (or one with boundary) into a disk through a set
of cone vertices (docs/cones.md, "Cut graph").

The cut is the union of

1. a system of 2g loops for genus g (tree-cotree on the dual graph, Erickson-Whittlesey: the primal
   tree is a shortest-path tree, the cotree a maximum spanning tree of the dual under the lengths of
   the loops the primal edges close, so the 2g left-over edges close the shortest loop system through
   the root);
2. a short tree joining the cones, the boundary loops and the loop system (Mehlhorn's 2-approximation
   of the Steiner tree: one multi-source Dijkstra, a minimum spanning tree of the terminals' Voronoi
   bridges, each bridge expanded to its path);
3. pruning: an edge path that ends at a vertex that is neither a cone nor on the boundary is removed.

All functions take ``V`` (n,3) float64 positions and ``F`` (m,3) int64 triangles (manifold,
counter-clockwise); edge lengths are in mesh units. Edges are (k,2) int64 vertex pairs of ``F``.
"""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import dijkstra, minimum_spanning_tree, connected_components

from ..mesh import topology
from ..mesh.geometry import weighted_graph


def inner_mask(E, inner, n):
    """(e,) bool: the edges ``E`` (e,2) (sorted pairs) that are among ``inner`` (k,2) vertex pairs (the
    diagonals of polygons cut into triangles), over ``n`` vertices; all False for None."""
    if inner is None or not len(inner):
        return np.zeros(len(E), bool)
    inner = np.sort(np.asarray(inner, np.int64).reshape(-1, 2), 1)
    return np.isin(E[:, 0] * n + E[:, 1], inner[:, 0] * n + inner[:, 1])


def avoiding(w, E, inner, n):
    """The edge weights ``w`` (e,) of the edges ``E`` (e,2) (sorted pairs over ``n`` vertices) with the
    total weight added to every edge of ``inner`` (k,2 vertex pairs: polygons' diagonals), so that a
    shortest path takes one only where no path avoids them (a seam through a polygon gives it two
    UVs at one corner, which a polygon cannot hold). ``w`` itself where there is none."""
    on = inner_mask(E, inner, n)
    return w + on * (w.sum() + 1.0) if on.any() else w


def polygon_sides(F, n, poly):
    """(m,3) bool: side ``s`` of triangle ``t`` of ``F`` (m,3) (corners ``s`` and ``s + 1``, over ``n``
    vertices) lies inside a polygon: the triangle across it has the same ``poly`` (m,) id (a quad's
    diagonal, an n-gon's fan)."""
    tw = topology.twin_halfedges(F, n).reshape(-1, 3)
    across = np.where(tw >= 0, tw // 3, 0)
    return (tw >= 0) & (poly[across] == poly[:, None])


def side_pairs(F, sides):
    """The sides marked in ``sides`` (m,3) bool (side ``s`` of triangle ``t``: corners ``s`` and
    ``s + 1`` of ``F`` (m,3)) as sorted vertex pairs (k,2), unique."""
    t, c = np.nonzero(sides)
    return np.unique(np.sort(np.stack([F[t, c], F[t, (c + 1) % 3]], 1), 1), axis=0)


def inner_pairs(F, n, poly):
    """The diagonals of the polygons ``poly`` (m,) cut into the triangles ``F`` (m,3), as sorted vertex
    pairs (k,2) (``polygon_sides``)."""
    return side_pairs(F, polygon_sides(F, n, np.asarray(poly)))


def edge_list(V, F, inner=None):
    """Undirected edges ``E`` (e,2) (E[:,0] < E[:,1]), their weights (e,), and the (n,n) CSR graph
    whose entry (i,j) is the index of edge ij plus one. The weight is the edge's length, ``avoiding``
    the polygons' diagonals ``inner`` (k,2) (``cone_unwrap``'s)."""
    n = len(V)
    E, _ = topology.unique_edges(F)
    w = avoiding(np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1), E, inner, n)
    idx = np.arange(1, len(E) + 1)
    Gi = sp.coo_matrix((np.r_[idx, idx], (np.r_[E[:, 0], E[:, 1]], np.r_[E[:, 1], E[:, 0]])),
                       shape=(n, n)).tocsr()
    return E, w, Gi


def _path_edges(pred, v):
    """Edges (k,2) of the predecessor path from ``v`` back to its source."""
    out = []
    while pred[v] >= 0:
        out.append((pred[v], v))
        v = pred[v]
    return out


def homology_loops(V, F, root=None, inner=None):
    """Edges (k,2) of 2g loops through ``root`` that cut every handle of a closed or bounded surface
    (empty for genus 0). A surface with boundary is capped first (a virtual vertex per boundary loop);
    loop pieces through a cap are dropped, which leaves paths between boundary points: together with
    the boundary (which the cut keeps open anyway) they still cut every handle."""
    F = np.asarray(F, np.int64)
    n = len(V)
    loops = topology.boundary_loops(F, n)
    Vc, Fc = V, F
    if loops:
        caps = []
        extra = []
        for j, lp in enumerate(loops):
            c = n + j
            extra.append(V[lp].mean(0))
            caps.append(np.stack([np.roll(lp, -1), lp, np.full(len(lp), c)], 1))
        Vc = np.vstack([V, np.array(extra)])
        Fc = np.vstack([F] + caps)
    nc = len(Vc)
    chi = topology.euler_characteristic(Fc)
    genus = topology.genus(chi)
    if genus <= 0:
        return np.zeros((0, 2), np.int64)
    E, w, Gi = edge_list(Vc, Fc, inner)
    if loops:
        w = np.where((E >= n).any(1), w.max() * 10 + 1, w)       # keep caps off the short loops
    if root is None:
        root = 0
    dist, pred = dijkstra(weighted_graph(E, w, nc), directed=False, indices=int(root),
                          return_predecessors=True)
    in_tree = np.zeros(len(E), bool)
    child = np.nonzero(pred >= 0)[0]
    tree_e = np.asarray(Gi[child, pred[child]]).ravel() - 1
    in_tree[tree_e] = True
    # dual graph: faces joined across non-tree edges, weighted by the loop length that edge closes
    m = len(Fc)
    H = topology.halfedges(Fc)
    tw = topology.twin_halfedges(Fc, nc)
    h = np.nonzero((tw >= 0) & (np.arange(len(H)) < tw))[0]
    he = np.asarray(Gi[H[h, 0], H[h, 1]]).ravel() - 1
    keep = ~in_tree[he]
    h, he = h[keep], he[keep]
    loop_len = dist[E[he, 0]] + dist[E[he, 1]] + w[he]
    big = loop_len.max() + 1.0
    D = sp.coo_matrix((big - loop_len + 1e-9, (h // 3, tw[h] // 3)), shape=(m, m)).tocsr()
    T = minimum_spanning_tree(D).tocoo()          # maximum spanning tree of the loop lengths
    in_cotree = np.zeros(len(E), bool)
    pair = {}
    for a, b, e in zip(h // 3, tw[h] // 3, he):
        pair[(min(a, b), max(a, b))] = e
    for a, b in zip(T.row.tolist(), T.col.tolist()):
        in_cotree[pair[(min(a, b), max(a, b))]] = True
    left = np.nonzero(~in_tree & ~in_cotree)[0]
    out = []
    for e in left.tolist():
        a, b = E[e]
        out.append((a, b))
        out += _path_edges(pred, a)
        out += _path_edges(pred, b)
    out = np.array(out, np.int64).reshape(-1, 2)
    out = out[(out < n).all(1)]                     # drop pieces through the caps
    out = np.unique(np.sort(out, 1), axis=0)
    # edges used by both tree paths of one loop cancel only in homology; the pruning removes tails
    return out


def steiner_tree(V, F, groups, inner=None):
    """A short tree of mesh edges (k,2) joining vertex ``groups`` (list of (k_i,) int arrays; each
    group is one terminal: a cone is a group of one vertex, a boundary loop or a loop system a group
    of many). Mehlhorn's approximation: Voronoi regions of the terminals by one multi-source Dijkstra,
    the minimum spanning tree of the shortest bridges between regions, bridges expanded to paths."""
    groups = [np.unique(np.asarray(g, np.int64)) for g in groups if len(g)]
    if len(groups) <= 1:
        return np.zeros((0, 2), np.int64)
    n = len(V)
    E, w, _ = edge_list(V, F, inner)
    label = -np.ones(n, np.int64)
    for i, g in enumerate(groups):
        label[g] = i
    src = np.nonzero(label >= 0)[0]
    dist, pred, sources = dijkstra(weighted_graph(E, w, n), directed=False, indices=src, min_only=True,
                                   return_predecessors=True)
    region = np.where(sources >= 0, label[np.maximum(sources, 0)], -1)
    ra, rb = region[E[:, 0]], region[E[:, 1]]
    cross = np.nonzero((ra != rb) & (ra >= 0) & (rb >= 0))[0]
    if len(cross) == 0:
        return np.zeros((0, 2), np.int64)
    cost = dist[E[cross, 0]] + dist[E[cross, 1]] + w[cross]
    a, b = np.minimum(ra[cross], rb[cross]), np.maximum(ra[cross], rb[cross])
    k = len(groups)
    order = np.lexsort((cost, b, a))
    key = a[order] * k + b[order]
    first = order[np.r_[True, key[1:] != key[:-1]]]            # the shortest bridge of each pair
    M = sp.coo_matrix((cost[first] + 1e-12, (a[first], b[first])), shape=(k, k)).tocsr()
    T = minimum_spanning_tree(M).tocoo()
    best = {(int(a[i]), int(b[i])): int(cross[i]) for i in first.tolist()}
    out = []
    for p, q in zip(T.row.tolist(), T.col.tolist()):
        e = best[(min(p, q), max(p, q))]
        x, y = E[e]
        out.append((x, y))
        out += _path_edges(pred, x)
        out += _path_edges(pred, y)
    out = np.array(out, np.int64).reshape(-1, 2)
    return np.unique(np.sort(out, 1), axis=0)


def prune(edges, keep, n):
    """Remove dangling paths: repeatedly drop edges ending at a degree-1 vertex not in ``keep``
    ((n,) bool: cones and boundary vertices). Returns the remaining edges (k,2)."""
    edges = np.unique(np.sort(np.asarray(edges, np.int64).reshape(-1, 2), 1), axis=0)
    alive = np.ones(len(edges), bool)
    while True:
        deg = np.bincount(edges[alive].ravel(), minlength=n)
        leaf = (deg == 1) & ~keep
        drop = alive & (leaf[edges[:, 0]] | leaf[edges[:, 1]])
        if not drop.any():
            return edges[alive]
        alive &= ~drop


def cut_graph(V, F, cones, root=None, inner=None):
    """Seam edges (k,2) that cut the manifold, connected surface ``(V, F)`` into a disk whose boundary
    passes through every vertex of ``cones`` (c,) int: 2g homology loops, a short tree joining the
    cones, the boundary loops and the loops, pruned of dangling ends. A closed genus-0 surface with
    fewer than two cones gets a one-edge cut at its cone (or vertex 0) so that it still opens.
    ``inner`` (k,2): vertex pairs the cut avoids where it can (polygons' diagonals, ``edge_list``)."""
    F = np.asarray(F, np.int64)
    n = len(V)
    cones = np.unique(np.asarray(cones, np.int64))
    loops = topology.boundary_loops(F, n)
    if root is None:
        root = int(cones[0]) if len(cones) else (int(loops[0][0]) if loops else 0)
    H = homology_loops(V, F, root, inner)
    groups = [np.array([c]) for c in cones.tolist()] + list(loops)
    if len(H):
        groups.append(np.unique(H))
    T = steiner_tree(V, F, groups, inner)
    keep = np.zeros(n, bool)
    keep[cones] = True
    for lp in loops:
        keep[lp] = True
    cut = straighten(F, prune(np.vstack([H, T]), keep, n), keep, inner)
    if len(cut) == 0 and not loops:
        # genus 0, closed, at most one cone: slit one edge at the cone so that the surface opens
        v = int(cones[0]) if len(cones) else 0
        nb = F[(F == v).any(1)].ravel()
        nb = nb[nb != v]
        pairs = np.sort(np.stack([np.full(len(nb), v), nb], 1), 1)
        off = ~inner_mask(pairs, inner, n)
        cut = pairs[[int(np.argmax(off))]]
    return cut


def is_disk(F, n, twin=None):
    """True if ``F`` (m,3) over ``n`` vertices (unused vertices allowed) is one connected piece with
    one boundary loop and Euler characteristic 1. One sort of the edge keys (``topology.edge_table``)
    gives the edge count and, on a manifold consistently oriented ``F``, the twins for the loops;
    ``twin`` (3m,) optional: those twins, known to the caller (``F`` manifold and oriented; an edge
    then has two half-edges, or one on the boundary), which saves the sort."""
    F = np.asarray(F, np.int64)
    if twin is None:
        E, counts, twin, same_way = topology.edge_table(F, n)
        manifold = same_way == 0 and (counts <= 2).all()
        n_edges = len(E)
    else:
        manifold = True
        n_edges = (3 * len(F) + int((twin < 0).sum())) // 2
    loops = topology.boundary_loops(F, n, twin=twin if manifold else None)
    if len(loops) != 1:
        return False
    used = np.zeros(n, bool)
    used[F.ravel()] = True
    if int(used.sum()) - n_edges + len(F) != 1:               # the Euler characteristic
        return False
    ncomp = connected_components(topology.vertex_adjacency(F, n), directed=False)[0]
    return ncomp - int((~used).sum()) == 1


def twig(edges, start, stop):
    """The path (list of vertices) of the cut graph ``edges`` (k,2) from the leaf ``start`` to the
    first vertex that is in ``stop`` ((n,) bool, e.g. cones and boundary) or has degree other than 2."""
    n = len(stop)
    deg = np.bincount(edges.ravel(), minlength=n)
    nbrs = {}
    for a, b in edges.tolist():
        nbrs.setdefault(a, []).append(b)
        nbrs.setdefault(b, []).append(a)
    path, prev, v = [start], -1, start
    while True:
        nxt = [w for w in nbrs.get(v, []) if w != prev]
        if not nxt:
            return path
        prev, v = v, nxt[0]
        path.append(v)
        if stop[v] or deg[v] != 2:
            return path


def reroute_leaf(V, F, edges, corner, start, leaves, stop, protect=None, inner=None):
    """Make the cut graph pass *through* vertex ``corner`` (so that its angle is split in two) by
    moving the twig of one leaf: ``start`` is a vertex next to ``corner``, inside the wedge to split;
    ``leaves`` candidate leaf vertices (positive cones); ``stop`` (n,) bool ends of twigs. The twig of
    the nearest leaf reachable from ``start`` without touching the rest of the cut is removed, and
    the path leaf - ... - start - corner added, so the cut stays a tree. ``protect`` (n,) bool: vertices
    (negative cones) that must keep two cut edges: a twig ending at one of degree 2 is not moved.
    ``inner``: as ``cut_graph``'s. Returns the new edges (k,2), or None if no leaf is reachable."""
    n = len(V)
    E, w, _ = edge_list(V, F, inner)
    on_cut = np.zeros(n, bool)
    on_cut[edges.ravel()] = True
    twigs = {int(d): twig(edges, int(d), stop) for d in leaves}
    deg = np.bincount(edges.ravel(), minlength=n)
    if protect is not None:
        twigs = {d: t for d, t in twigs.items() if not (protect[t[-1]] and deg[t[-1]] <= 2)}
    for d in sorted(twigs, key=lambda d: np.linalg.norm(V[d] - V[start])):
        tw = twigs[d]
        free = on_cut.copy()
        free[tw[:-1]] = False                       # the twig goes; its end point stays
        free[corner] = True
        ok = ~(free[E[:, 0]] | free[E[:, 1]])
        if free[start]:
            continue
        dist, pred = dijkstra(weighted_graph(E[ok], w[ok], n), directed=False, indices=int(start),
                              return_predecessors=True)
        if not np.isfinite(dist[d]):
            continue
        path = [d]
        while pred[path[-1]] >= 0:
            path.append(int(pred[path[-1]]))
        path.append(int(corner))
        tw_e = {(min(a, b), max(a, b)) for a, b in zip(tw[:-1], tw[1:])}
        kept = [e for e in map(tuple, edges.tolist()) if e not in tw_e]
        new = kept + [(min(a, b), max(a, b)) for a, b in zip(path[:-1], path[1:])]
        return np.unique(np.array(new, np.int64).reshape(-1, 2), axis=0)
    return None


def straighten(F, edges, keep, inner=None):
    """Remove spikes of the cut: where a path a - v - b turns back along a triangle (a, v, b) at a
    vertex v of degree 2 that is not in ``keep`` ((n,) bool), the edge a - b replaces it. Such a turn
    leaves v one wedge of a single corner and the other of nearly 2*pi, which a linearised layout
    overlaps. The cut stays a tree with the same terminals; an edge a - b of ``inner`` (k,2: a
    polygon's diagonal) is not taken. Returns edges (k,2)."""
    F = np.asarray(F, np.int64)
    edges = np.asarray(edges, np.int64).reshape(-1, 2)
    on = np.zeros(max(int(F.max()), int(edges.max()) if len(edges) else 0) + 1, bool)
    on[edges.ravel()] = True
    near = F[on[F].sum(1) >= 2]                      # only triangles with two cut vertices matter
    tri = set(map(tuple, np.sort(near, axis=1).tolist()))
    E = {tuple(e) for e in np.sort(edges, 1).tolist()}
    skip = set() if inner is None else {tuple(e) for e in np.sort(np.asarray(inner, np.int64).reshape(-1, 2),
                                                                   1).tolist()}
    changed = True
    while changed:
        changed = False
        nbrs = {}
        for a, b in E:
            nbrs.setdefault(a, []).append(b)
            nbrs.setdefault(b, []).append(a)
        for v, nb in nbrs.items():
            if len(nb) != 2 or keep[v]:
                continue
            a, b = nb
            ab = (min(a, b), max(a, b))
            if ab in E or ab in skip or tuple(sorted((a, b, v))) not in tri:
                continue
            if (min(a, v), max(a, v)) not in E or (min(b, v), max(b, v)) not in E:
                continue                                    # v changed in this round already
            E.discard((min(a, v), max(a, v)))
            E.discard((min(b, v), max(b, v)))
            E.add(ab)
            changed = True
    return np.array(sorted(E), np.int64).reshape(-1, 2)


def through_corner(V, F, edges, corner, start, stop, protect=None, inner=None):
    """Make the cut graph ``edges`` (k,2) pass *through* the leaf ``corner`` (a negative cone whose
    single wedge exceeds 2*pi) by a new branch, keeping a tree of the same topology.

    The branch leaves ``corner`` by ``start`` (its neighbour in the middle of the wedge) and follows
    the shortest path off the cut to the nearest cut vertex ``x`` that is not on one of ``corner``'s
    own branches (up to the next stop or branch point).
    That closes one cycle (the branch plus the cut's path from ``x`` back to ``corner``); the cycle
    is opened again by removing its longest segment between two ``stop`` vertices ((n,) bool: cones,
    boundary) or branch points, except the segments that end at ``corner`` and those ending at a
    ``protect`` vertex ((n,) bool: negative cones) of degree 2, and dangling ends are pruned (``keep``
    = ``stop``). Returns the new edges (k',2), or None if no such branch exists. The caller checks that
    the surface still opens into a disk (``is_disk``). ``inner``: as ``cut_graph``'s."""
    n = len(V)
    edges = np.unique(np.sort(np.asarray(edges, np.int64).reshape(-1, 2), 1), axis=0)
    E, w, _ = edge_list(V, F, inner)
    on_cut = np.zeros(n, bool)
    on_cut[edges.ravel()] = True
    if on_cut[start]:
        return None
    own = np.zeros(n, bool)                                # corner and its branches up to the
    own[corner] = True                                     # next cone, boundary or branch point
    deg = np.bincount(edges.ravel(), minlength=n)
    for e in edges[(edges == corner).any(1)]:
        prev, v = int(corner), int(e[0] if e[1] == corner else e[1])
        while True:
            own[v] = True
            if stop[v] or deg[v] != 2:
                break
            nxt = [int(x) for x in edges[(edges == v).any(1)].ravel() if x != v and x != prev]
            if not nxt:
                break
            prev, v = v, nxt[0]
    # off-cut vertices, plus steps onto allowed cut vertices (which end a path: they are sinks)
    ok = ~(own[E[:, 0]] | own[E[:, 1]]) & ~(on_cut[E[:, 0]] & on_cut[E[:, 1]])
    dist, pred = dijkstra(weighted_graph(E[ok], w[ok], n), directed=False, indices=int(start),
                          return_predecessors=True)
    target = on_cut & ~own & np.isfinite(dist)
    if not target.any():
        return None
    x = int(np.argmin(np.where(target, dist, np.inf)))
    path = [x]
    while pred[path[-1]] >= 0:
        path.append(int(pred[path[-1]]))
    if path[-1] != start or any(on_cut[v] for v in path[1:]):
        return None                                         # the path crossed the cut: give up
    branch = [(min(a, b), max(a, b)) for a, b in zip(path[:-1], path[1:])]
    branch.append((min(int(corner), int(start)), max(int(corner), int(start))))
    # the cut's own path from x to corner (breadth first in the cut graph)
    adj = sp.coo_matrix((np.ones(2 * len(edges)), (np.r_[edges[:, 0], edges[:, 1]],
                                                   np.r_[edges[:, 1], edges[:, 0]])), shape=(n, n)).tocsr()
    from scipy.sparse.csgraph import breadth_first_order
    _, pr = breadth_first_order(adj, x, directed=False, return_predecessors=True)
    if pr[corner] < 0 and corner != x:
        return None
    cyc = [int(corner)]
    while cyc[-1] != x:
        cyc.append(int(pr[cyc[-1]]))
    new = np.unique(np.r_[edges, np.array(branch, np.int64)], axis=0)
    deg = np.bincount(new.ravel(), minlength=n)
    # segments of the cut's path between stops / branch points
    marks = [i for i, v in enumerate(cyc) if i == 0 or i == len(cyc) - 1 or stop[v] or deg[v] != 2]
    segs = []
    for i0, i1 in zip(marks[:-1], marks[1:]):
        a, b = cyc[i0], cyc[i1]
        if a == corner or b == corner:
            continue
        if protect is not None and any(protect[v] and deg[v] <= 2 for v in (a, b)):
            continue
        seg = cyc[i0:i1 + 1]
        length = float(np.linalg.norm(np.diff(V[seg], axis=0), axis=1).sum())
        segs.append((length, seg))
    if not segs:
        return None
    _, seg = max(segs, key=lambda t: t[0])
    drop = {(min(a, b), max(a, b)) for a, b in zip(seg[:-1], seg[1:])}
    kept = np.array([e for e in map(tuple, new.tolist()) if e not in drop], np.int64).reshape(-1, 2)
    return prune(kept, stop, n)
