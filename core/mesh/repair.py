"""Internal repair of messy triangle meshes: the user's arrays are never modified.

``repair(V, F)`` returns a clean copy to compute on, with index maps back to the input:

- faces with a repeated vertex (exactly degenerate) are dropped; their corners take UVs from the
  other corners of the same input vertex;
- duplicate faces (the same three vertices, either orientation) are dropped, the first one is kept;
- vertices in no face (loose vertices) are left out;
- faces are re-oriented per edge-connected component so that every shared edge runs opposite ways in
  its two faces (the orientation that keeps most faces as they are wins); a non-orientable component
  (a Moebius strip) is cut along the edges that disagree with a spanning tree's orientation;
- edges shared by three or more faces (non-manifold edges) join none of their faces: the mesh splits
  into islands along them;
- every vertex is split into its wedges: the fans of corners joined through shared edges. A
  non-manifold vertex (several fans touching at one point) thus becomes one vertex per fan.

Zero-area faces with three different vertices are kept: the intrinsic mollification of the
operators (``core.mesh.intrinsic``) gives them a valid metric. Everything is vectorised.
"""
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import breadth_first_order, connected_components

from ..errors import ConformalError
from . import topology


@dataclass
class Repaired:
    """A repaired copy of a mesh. ``V`` (n2,3) float64 positions (``V_in[vert_map]``); ``F`` (m2,3) int64
    triangles, counter-clockwise after re-orientation; ``face_map`` (m2,) input face of each triangle;
    ``vert_map`` (n2,) input vertex of each vertex; ``flipped`` (m2,) True where the triangle's corner
    order is the reverse of its input face (``F[i] == wedge ids of F_in[face_map[i]][[0, 2, 1]]``);
    ``dropped`` (k,) input faces left out (repeated vertex or duplicate); ``twin_of_dropped`` (k,) for
    each dropped duplicate the kept input face with the same vertices (-1 for a repeated-vertex face);
    ``repairs`` list of dicts ``{'repair': name, 'count': int, 'note': str}``; empty for a clean mesh."""
    V: np.ndarray
    F: np.ndarray
    face_map: np.ndarray
    vert_map: np.ndarray
    flipped: np.ndarray
    dropped: np.ndarray
    twin_of_dropped: np.ndarray
    repairs: list = field(default_factory=list)

    @property
    def changed(self) -> bool:
        """True if anything was repaired (else ``F`` equals the input faces on ``vert_map`` ids)."""
        return bool(self.repairs)


def _orientation_parity(n_nodes, rows, cols, par):
    """Orientation parity (n_nodes,) int8 of every face and its component label (n_nodes,), for the
    face graph's edges ``rows``-``cols`` with parity ``par`` (1 when the two faces run the shared edge
    the same way, so one of them must flip). The faces that the input already orients alike (joined
    by edges of parity 0) form groups that keep their relative orientation; a spanning forest of the
    groups (``_tree_parity``) orients them against each other. On an orientable mesh that is the only
    answer; on a non-orientable one (a Moebius strip) the edges left disagreeing, where the cut goes,
    are edges where the input's own windings disagree, so no face is turned for nothing."""
    agree = par == 0
    G = sp.coo_matrix((np.ones(int(agree.sum()), np.int8), (rows[agree], cols[agree])),
                      shape=(n_nodes, n_nodes)).tocsr()
    n_groups, group = connected_components(G, directed=False)
    group = group.astype(np.int64)               # (int32 labels: their pair keys would overflow)
    a, b = group[rows[~agree]], group[cols[~agree]]
    apart = a != b
    acc, lab = _tree_parity(n_groups, a[apart], b[apart], np.ones(int(apart.sum()), np.int8))
    return acc[group], lab[group]


def _tree_parity(n_nodes, rows, cols, par):
    """Orientation parity (n_nodes,) int8 of every face relative to its component's root, along a
    spanning forest of the face graph (edges ``rows``-``cols`` with parity ``par``: 1 when the two faces
    run the shared edge the same way, so one of them must flip)."""
    G = sp.coo_matrix((np.ones(len(rows)), (rows, cols)), shape=(n_nodes, n_nodes)).tocsr()
    G = ((G + G.T) > 0).astype(np.int8)
    ncomp, lab = connected_components(G, directed=False)
    roots = np.unique(lab, return_index=True)[1]
    roots = roots[np.bincount(lab)[lab[roots]] > 1]                  # the components with edges
    if len(roots) <= 1:
        pred = np.full(n_nodes, -1, np.int64)
        if len(roots):
            p = breadth_first_order(G, int(roots[0]), directed=False, return_predecessors=True)[1]
            pred[p >= 0] = p[p >= 0]
    else:
        # one breadth-first search from a virtual node joined to every component's root: the same
        # trees as a search from each root (within a component the queue keeps its own order), in
        # one pass (a search per component cost the whole graph each time: 0.8 s for 2000 hair cards)
        hub = np.full(len(roots), n_nodes)
        Gc = G.tocoo()
        H = sp.csr_matrix((np.ones(Gc.nnz + 2 * len(roots), np.int8),
                           (np.r_[Gc.row, hub, roots], np.r_[Gc.col, roots, hub])),
                          shape=(n_nodes + 1, n_nodes + 1))
        p = breadth_first_order(H, n_nodes, directed=True, return_predecessors=True)[1][:n_nodes]
        pred = np.where((p >= 0) & (p < n_nodes), p, -1).astype(np.int64)
    # parity of each tree edge (node, pred[node])
    key = np.minimum(rows, cols) * n_nodes + np.maximum(rows, cols)
    order = np.argsort(key)
    has = pred >= 0
    node = np.nonzero(has)[0]
    qk = np.minimum(node, pred[node]) * n_nodes + np.maximum(node, pred[node])
    acc = np.zeros(n_nodes, np.int8)
    acc[node] = par[order[np.searchsorted(key[order], qk)]]
    # pointer jumping: parity to the root is the xor of the tree edges' parities on the way up
    p = pred.copy()
    while (p >= 0).any():
        up = p >= 0
        acc[up] ^= acc[p[up]]
        p[up] = p[p[up]]
    return acc, lab


def repair(V, F) -> Repaired:
    """Repair ``V`` (n,3), ``F`` (m,3) (checked arrays: finite, indices in range) for computing.
    Returns ``Repaired``; the input arrays are not modified."""
    V = np.asarray(V, np.float64)
    F_in = np.asarray(F, np.int64)
    n, m = len(V), len(F_in)
    repairs = []
    # 1. exactly degenerate faces (a repeated vertex)
    rep = topology.repeated_vertex(F_in)
    # 2. duplicate faces
    S = np.sort(F_in, axis=1)
    key = (S[:, 0] * n + S[:, 1]) * n + S[:, 2] if n < 2 ** 20 else None
    if key is not None:
        _, first, inv = np.unique(key, return_index=True, return_inverse=True)
    else:
        _, first, inv = np.unique(S, axis=0, return_index=True, return_inverse=True)
    inv = inv.ravel()
    dup = first[inv] != np.arange(m)
    dup &= ~rep
    drop = rep | dup
    if rep.any():
        repairs.append({'repair': 'degenerate_faces_dropped', 'count': int(rep.sum()),
                        'note': 'faces with a repeated vertex left out; their corners share UVs'})
    if dup.any():
        repairs.append({'repair': 'duplicate_faces_dropped', 'count': int(dup.sum()),
                        'note': 'faces repeating the vertices of another face left out; they share its UVs'})
    keep = np.nonzero(~drop)[0]
    dropped = np.nonzero(drop)[0]
    twin_of_dropped = np.where(dup[dropped], first[inv[dropped]], -1)
    Fk = F_in[keep]
    mk = len(Fk)
    used = np.zeros(n, bool)
    used[Fk.ravel()] = True
    loose = int(n - used.sum())
    if loose:
        repairs.append({'repair': 'loose_vertices_ignored', 'count': loose,
                        'note': 'vertices in no face are left out'})
    if mk == 0:
        z = np.zeros(0, np.int64)
        return Repaired(V[:0], np.zeros((0, 3), np.int64), z, z, np.zeros(0, bool), dropped,
                        twin_of_dropped, repairs)
    # 3. undirected edges and their half-edges
    H = topology.halfedges(Fk)                                     # (3mk,2), half-edge 3t+k
    lo, hi = np.minimum(H[:, 0], H[:, 1]), np.maximum(H[:, 0], H[:, 1])
    ekey = lo * n + hi
    _, eid, ecount = np.unique(ekey, return_inverse=True, return_counts=True)
    eid = eid.ravel()
    n_nm_edges = int((ecount > 2).sum())
    if n_nm_edges:
        repairs.append({'repair': 'non_manifold_edges_split', 'count': n_nm_edges,
                        'note': 'edges with 3 or more faces join none of them: the mesh splits into '
                                'islands there'})
    # pairs of half-edges on manifold interior edges
    pair_h = np.nonzero(ecount[eid] == 2)[0]
    pair_h = pair_h[np.argsort(eid[pair_h], kind='stable')]
    h1, h2 = pair_h[0::2], pair_h[1::2]
    same_dir = H[h1, 0] == H[h2, 0]                               # both faces run the edge the same way
    # 4. orientation per component
    flip_par, flab = _orientation_parity(mk, h1 // 3, h2 // 3, same_dir.astype(np.int8))
    # keep the majority of each component unflipped
    ncomp = int(flab.max()) + 1
    flips_per = np.bincount(flab, flip_par, minlength=ncomp)
    size = np.bincount(flab, minlength=ncomp)
    invert = flips_per * 2 > size
    flipped = (flip_par.astype(bool) ^ invert[flab])
    # ties: the component's lowest input face keeps its orientation (order independent of face order)
    tie = flips_per * 2 == size
    if tie.any():
        first_face = np.full(ncomp, np.iinfo(np.int64).max)
        np.minimum.at(first_face, flab, keep)
        pos = np.searchsorted(keep, first_face)
        ref = flip_par[pos].astype(bool)
        flipped = np.where(tie[flab], flip_par.astype(bool) ^ ref[flab], flipped)
    consistent = (same_dir ^ (flipped[h1 // 3] != flipped[h2 // 3]))
    consistent = ~consistent                                     # runs opposite ways after flipping
    if flipped.any():
        repairs.append({'repair': 'faces_reoriented', 'count': int(flipped.sum()),
                        'note': 'faces turned to agree with their neighbours (per connected part)'})
    if (~consistent).any():
        repairs.append({'repair': 'non_orientable_edges_cut', 'count': int((~consistent).sum()),
                        'note': 'a non-orientable part (Moebius-like) is cut where orientations disagree'})
    # 5. wedges: corners joined across consistent manifold edges
    j1, j2 = h1[consistent], h2[consistent]
    # half-edge h of the input order; after a flip its corners move: map each half-edge to the two
    # corners (in Fo) at its ends
    t1, k1 = j1 // 3, j1 % 3
    t2, k2 = j2 // 3, j2 % 3
    c1a, c1b = 3 * t1 + k1, 3 * t1 + (k1 + 1) % 3               # corners (input order) of start, end
    c2a, c2b = 3 * t2 + k2, 3 * t2 + (k2 + 1) % 3
    # the ends of half-edge j1 are vertices H[j1]; match corners by vertex
    same = H[j1, 0] == H[j2, 0]
    r1 = np.r_[c1a, c1b]
    r2 = np.r_[np.where(same, c2a, c2b), np.where(same, c2b, c2a)]
    ones = np.ones(len(r1), np.int8)
    _, wedge = connected_components(sp.coo_matrix((ones, (r1, r2)), shape=(3 * mk, 3 * mk)), directed=False)
    Fr = Fk.ravel()
    uw, first_c = np.unique(wedge, return_index=True)
    w_vert = Fr[first_c]
    # number wedges by (input vertex, first corner): a clean mesh keeps its vertex order
    order = np.lexsort((first_c, w_vert))
    newid = np.empty(len(order), np.int64)
    newid[order] = np.arange(len(order))
    vert_map = w_vert[order]
    Fw = newid[wedge].reshape(mk, 3)
    F2 = np.where(flipped[:, None], Fw[:, [0, 2, 1]], Fw)
    n_wedges = np.bincount(vert_map, minlength=n)
    split = np.nonzero(n_wedges > 1)[0]
    if len(split):
        repairs.append({'repair': 'vertices_split', 'count': int(len(split)),
                        'note': 'non-manifold vertices (separate fans touching, or on split edges) are '
                                f'split into {int(n_wedges[split].sum())} vertices'})
    return Repaired(V[vert_map], F2.astype(np.int64), keep, vert_map, flipped, dropped,
                    twin_of_dropped.astype(np.int64), repairs)


def zero_area_note(count: int) -> dict:
    """The repairs entry for ``count`` zero-area triangles kept and handled by mollification."""
    return {'repair': 'zero_area_faces_mollified', 'count': int(count),
            'note': 'zero-area triangles get a valid intrinsic metric (mollification) and are left out '
                    'of the measures'}


def require_faces(R):
    """Raise ``ConformalError`` ('empty_mesh') if the repair ``R`` (``repair``, ``repair_merged``)
    left no triangle: every face repeated a vertex."""
    if len(R.F) == 0:
        raise ConformalError("mesh has no triangle with three different vertices", 'empty_mesh')


def oriented_faces(V, F):
    """``F`` (m,3) with the triangles that ``repair`` turns (faces that disagree with their neighbours,
    per part) turned the same way, in the input's numbering: for answers that do not depend on a
    triangle's winding (geodesic distances) but need one orientation to be computed. Returns ``F``
    itself if no triangle is turned, else a copy."""
    return turned_faces(F, repair(V, F))


def turned_faces(F, R):
    """``F`` (m,3) with the triangles that the repair ``R`` (``repair(V, F)``) turned, turned the same
    way in the input's numbering; ``F`` itself if none is."""
    if not R.flipped.any():
        return F
    F = np.array(F, np.int64)
    turn = R.face_map[R.flipped]
    F[turn] = F[turn][:, ::-1]
    return F


def coincident_roots(V, F):
    """``root`` (n,): for the vertices ``V`` (n,3) of the triangles ``F`` (m,3), the lowest-numbered
    vertex at the same point reached through edges of zero length (``degenerate_faces``' tolerance),
    each vertex itself otherwise; or None if no edge has zero length (a marching-cubes mesh has
    thousands: the same point twice, joined by an edge)."""
    from .validate import degenerate_faces
    deg = degenerate_faces(V, F)
    if not deg.any():
        return None
    E = np.concatenate([F[deg][:, [0, 1]], F[deg][:, [1, 2]], F[deg][:, [2, 0]]])
    tol = 1e-12 * float(np.linalg.norm(V[F[:, 1]] - V[F[:, 0]], axis=1).mean())
    E = E[np.linalg.norm(V[E[:, 0]] - V[E[:, 1]], axis=1) <= tol]
    if not len(E):
        return None
    n = len(V)
    G = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n))
    _, label = connected_components(G, directed=False)
    root = np.full(n, n, np.int64)
    np.minimum.at(root, label, np.arange(n))            # the lowest vertex of each group, by label
    return root[label]


def repair_merged(V, F):
    """``repair`` of ``V`` (n,3), ``F`` (m,3) after vertices at one point, joined by an edge of zero length,
    are merged (``coincident_roots``): ``(Repaired, root)``, ``root`` (n,) the vertex each input vertex
    was merged into (None if none was). The faces the merge collapses are dropped as faces with a
    repeated vertex, and the merged vertices are in no face; the repairs list says
    ``coincident_vertices_merged`` for them instead (the counts of ``degenerate_faces_dropped`` and
    ``loose_vertices_ignored`` are the input's own). Their zero-area triangles would otherwise reach
    the operators as fake curvature: on a marching-cubes part the cones went to them (48 cones and a
    1 %/99 % scale ratio of 0.08 in 48 s, against 10 cones, 0.56 and 8 s once merged)."""
    F = np.asarray(F, np.int64)
    root = coincident_roots(V, F)
    merged = 0 if root is None else int((root != np.arange(len(root))).sum())
    if not merged:                         # no zero-length edge, or only those of repeated-vertex faces
        return repair(V, F), None
    R = repair(V, root[F])
    collapsed = topology.repeated_vertex(root[F]) & ~topology.repeated_vertex(F)
    less = {'loose_vertices_ignored': merged, 'degenerate_faces_dropped': int(collapsed.sum())}
    kept = []
    for r in R.repairs:
        count = r['count'] - less.get(r['repair'], 0)
        if count > 0:
            kept.append(dict(r, count=count))
    R.repairs = [{'repair': 'coincident_vertices_merged', 'count': merged,
                  'note': 'vertices at the same point, joined by an edge of zero length, are merged and '
                          'their zero-area triangles left out'}] + kept
    return R, root

