"""Combinatorics of a triangle mesh: edges, half-edge twins, boundary loops, components, Euler
characteristic and vertex fans. ``F`` is (m,3) int64, counter-clockwise."""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components


def halfedges(F):
    """(3m,2) directed half-edges; row 3*t+k runs from F[t,k] to F[t,k+1]."""
    return np.stack([F, F[:, [1, 2, 0]]], axis=2).reshape(-1, 2)


def repeated_vertex(F):
    """(m,) bool: the triangles of ``F`` (m,3) that name one vertex twice or more (no area by index)."""
    F = np.asarray(F)
    return (F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 2] == F[:, 0])


def duplicate_rows(F):
    """(k,) indices of rows of ``F`` (m,3) whose sorted vertex triple repeats an earlier row."""
    S = np.sort(F, axis=1)
    order = np.lexsort((S[:, 2], S[:, 1], S[:, 0]))
    S = S[order]
    same = np.r_[False, (S[1:] == S[:-1]).all(axis=1)]
    return np.sort(order[same])


def _keys(H, n):
    return H[:, 0].astype(np.int64) * n + H[:, 1]


def twin_halfedges(F, n):
    """(3m,) index of the opposite half-edge of each half-edge, -1 on the boundary. Assumes that no
    directed half-edge appears twice (checked by ``validate``).

    One sort of the undirected keys pairs the two half-edges of each edge (no search: half the time
    at 70k triangles); where an edge has more than two, the reverse of each is searched for instead."""
    F = np.asarray(F, np.int64)
    _, order, starts, counts = _sorted_edge_keys(F, n)
    if len(counts) and counts.max() > 2:
        return _twin_by_search(F, n)
    return _paired(F, order, starts, counts)[0]


def _paired(F, order, starts, counts):
    """From the sorted undirected half-edge keys of ``F`` (m,3) (``_sorted_edge_keys``): ``twin``
    (3m,), the other half-edge of each edge of two half-edges running opposite ways, else -1, and how
    many edges have two half-edges running the same way."""
    twin = np.full(3 * len(F), -1, np.int64)
    pair = starts[counts == 2]
    h0, h1 = order[pair], order[pair + 1]
    u = F.ravel()
    same = u[h0] == u[h1]
    twin[h0[~same]], twin[h1[~same]] = h1[~same], h0[~same]
    return twin, int(same.sum())


def _twin_by_search(F, n):
    """``twin_halfedges`` by a search for the reverse key of each half-edge (meshes with edges of more
    than two half-edges)."""
    H = halfedges(F)
    key = _keys(H, n)
    order = np.argsort(key)
    skey = key[order]
    rkey = _keys(H[:, ::-1], n)
    pos = np.searchsorted(skey, rkey)
    pos = np.minimum(pos, len(skey) - 1)
    found = skey[pos] == rkey
    return np.where(found, order[pos], -1)


def unique_edges(F):
    """Undirected edges ``E`` (e,2) with E[:,0] < E[:,1], and how many triangles hold each, (e,)."""
    H = np.sort(halfedges(F), axis=1)
    n = int(F.max()) + 1
    key, counts = np.unique(_keys(H, n), return_counts=True)
    return np.stack([key // n, key % n], axis=1), counts


def edge_table(F, n):
    """One sort of the 3m undirected half-edge keys of ``F`` (m,3), shared by the topology checks.

    Returns ``(E, counts, twin, same_way)``: the undirected edges ``E`` (e,2) with E[:,0] < E[:,1] in
    increasing order and how many triangles hold each (e,) (as ``unique_edges``); ``twin`` (3m,), the
    opposite half-edge of each half-edge or -1 (as ``twin_halfedges``; meaningful only when no edge has
    more than two triangles and ``same_way`` is 0); ``same_way`` how many edges have two half-edges
    running the same way (inconsistent orientation). Half-edge 3t+k runs from F[t,k] to F[t,k+1]."""
    F = np.asarray(F, np.int64)
    key, order, starts, counts = _sorted_edge_keys(F, n)
    ukey = key[order][starts]
    E = np.stack([ukey // n, ukey % n], axis=1)
    twin, same_way = _paired(F, order, starts, counts)
    return E, counts, twin, same_way


def _sorted_edge_keys(F, n):
    """The 3m undirected half-edge keys of ``F`` (m,3) on ``n`` vertices (min * n + max), sorted once:
    ``(key (3m,), order (3m,), starts (e,), counts (e,))``, ``starts`` the first sorted position of
    each edge and ``counts`` how many half-edges it has."""
    u = F.ravel()
    v = F[:, [1, 2, 0]].ravel()
    key = np.minimum(u, v) * np.int64(n) + np.maximum(u, v)
    order = np.argsort(key)
    skey = key[order]
    first = np.ones(len(key), bool)
    first[1:] = skey[1:] != skey[:-1]
    starts = np.flatnonzero(first)
    return key, order, starts, np.diff(np.r_[starts, len(key)])


def two_sided_edges(F, n):
    """The edges of ``F`` (m,3) on ``n`` vertices held by exactly two triangles, whichever way their
    half-edges run: ``(h0, h1)`` (e2,) the two half-edges of each (half-edge 3t+k runs from F[t,k] to
    F[t,k+1]), and ``key`` (e2,) its undirected key min * n + max."""
    F = np.asarray(F, np.int64)
    key, order, starts, counts = _sorted_edge_keys(F, n)
    pair = starts[counts == 2]
    return order[pair], order[pair + 1], key[order[pair]]


def boundary_loops(F, n, twin=None):
    """Boundary loops as a list of (k,) int arrays of vertex indices, longest first (ties: lowest
    vertex first). Each loop runs with the surface on its left (the faces' counter-clockwise direction)
    and starts at its lowest vertex index, so the result does not depend on the order of the faces."""
    H = halfedges(F)
    tw = twin_halfedges(F, n) if twin is None else twin
    B = H[tw < 0]
    if len(B) == 0:
        return []
    nxt = {}
    for a, b in B.tolist():
        nxt.setdefault(a, b)
    loops, seen = [], set()
    for start in B[:, 0].tolist():
        if start in seen:
            continue
        loop, v = [], start
        while v not in seen:
            seen.add(v)
            loop.append(v)
            v = nxt.get(v)
            if v is None:
                break
        loop = np.array(loop, dtype=np.int64)
        loops.append(np.roll(loop, -int(np.argmin(loop))))      # canonical start: the lowest vertex
    # longest first, ties by the lowest vertex: the same loops whatever the face order
    loops.sort(key=lambda lp: (-len(lp), int(lp[0])))
    return loops


def vertex_adjacency(F, n):
    """(n,n) sparse 0/1 adjacency of the mesh's edges."""
    H = halfedges(F)
    A = sp.coo_matrix((np.ones(len(H)), (H[:, 0], H[:, 1])), shape=(n, n)).tocsr()
    return ((A + A.T) > 0).astype(np.int8)


def connected_components_of(F, n):
    """(count, labels (n,)) of the vertex graph. Vertices in no face are components of their own."""
    return connected_components(vertex_adjacency(F, n), directed=False)


def _sorted_rows_csr(rows, cols, size):
    """(size,size) CSR 0/1 matrix of the links ``rows`` -> ``cols`` (k,), ``rows`` non-decreasing:
    built directly (no COO sort), for ``connected_components``, whose labels depend only on the links."""
    indptr = np.zeros(size + 1, np.int64)
    np.cumsum(np.bincount(rows, minlength=size), out=indptr[1:])
    return sp.csr_matrix((np.ones(len(cols)), cols, indptr), shape=(size, size))


def face_components(F, n, twin=None):
    """(count, labels (m,)) of triangles connected through shared edges."""
    m = len(F)
    tw = twin_halfedges(F, n) if twin is None else twin
    h = np.flatnonzero(tw >= 0)                      # increasing, so their triangles h // 3 are sorted
    return connected_components(_sorted_rows_csr(h // 3, tw[h] // 3, m), directed=False)


def split_duplicates(V, F, part=None):
    """How many vertices of the triangles ``F`` (m,3) sit at exactly the same point ``V`` (n,3) as a
    vertex of another connected part (``part`` (m,): each triangle's part, ``face_components``, if the
    caller has it): a surface split there without a seam, as a triangle soup (an STL import) or an
    export with split normals leaves it. 0 for one part."""
    F = np.asarray(F, np.int64)
    if part is None:
        count, part = face_components(F, len(V))
        if count < 2:
            return 0
    label = np.full(len(V), -1, np.int64)
    label[F.ravel()] = np.repeat(np.asarray(part, np.int64), 3)
    used = np.unique(F)
    _, grp = np.unique(np.asarray(V)[used], axis=0, return_inverse=True)
    grp = grp.ravel()
    lab = label[used]
    # a group of coincident vertices spans several parts if its labels differ
    lo = np.full(grp.max() + 1, np.iinfo(np.int64).max)
    hi = np.full(grp.max() + 1, -1)
    np.minimum.at(lo, grp, lab)
    np.maximum.at(hi, grp, lab)
    return int((lo[grp] != hi[grp]).sum())


def euler_characteristic(F, n_edges=None):
    """V - E + F over the vertices referenced by ``F`` (``n_edges``: the edge count, if known)."""
    nv = int(np.count_nonzero(np.bincount(F.ravel())))
    ne = len(unique_edges(F)[0]) if n_edges is None else n_edges
    return nv - ne + len(F)


def genus(chi, n_loops=0):
    """The genus of a connected orientable surface of Euler characteristic ``chi`` with ``n_loops``
    boundary loops: ``(2 - chi - n_loops) / 2``."""
    return (2 - chi - n_loops) // 2


def vertex_fans(F, n, twin=None):
    """(n,) number of edge-connected fans of triangles around each vertex. A manifold vertex has 1;
    2 or more means the surface pinches there (a non-manifold vertex)."""
    m = len(F)
    tw = twin_halfedges(F, n) if twin is None else twin
    # corner c = 3t+k sits at F[t,k]; half-edge 3t+k leaves it. Its twin 3t'+k' arrives at the same
    # vertex, which is corner 3t'+(k'+1)%3 of the other triangle.
    c = np.flatnonzero(tw >= 0)
    other = (tw[c] // 3) * 3 + (tw[c] % 3 + 1) % 3
    ncomp, lab = connected_components(_sorted_rows_csr(c, other, 3 * m), directed=False)
    # a fan's corners all sit at one vertex (links join corners of the same vertex): count the fans
    # of each vertex through the vertex of each component
    comp_vertex = np.empty(ncomp, np.int64)
    comp_vertex[lab] = F.ravel()
    return np.bincount(comp_vertex, minlength=n)


def edge_mask(E, pairs):
    """(e,) bool: which edges of ``E`` (e,2) are among the undirected vertex ``pairs`` (k,2)."""
    E = np.asarray(E, np.int64).reshape(-1, 2)
    pairs = np.asarray(pairs, np.int64).reshape(-1, 2)
    if len(E) == 0 or len(pairs) == 0:
        return np.zeros(len(E), bool)
    n = int(max(E.max(), pairs.max())) + 1
    return np.isin(_keys(np.sort(E, axis=1), n), _keys(np.sort(pairs, axis=1), n))
