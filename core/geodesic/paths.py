"""Shortest paths on a triangle mesh's surface through Steiner points on its edges (docs/geodesic.md,
"Refined seed" and "Sphere mode"): the graph joins every pair of points on the boundary of each
triangle by the straight segment inside it (and across a flat convex patch of several triangles,
such as an n-gon cut into a fan, every pair of points on the patch's boundary: ``planar_patches``),
so every graph path is a path on the surface (an upper bound of the geodesic distance, exact as the
points per edge ``k`` grow), and Richardson's
extrapolation from ``k`` and ``(k - 1) / 2`` points per edge removes most of the excess.

``steiner_distances``: the paths from source vertices or a point, on any set of triangles (the
planar solver's refined seed uses it on a window around the source). ``surface_paths``: the
distances on a whole mesh (or island) at a given ``k`` (``path_points``: the largest that fits a
number of graph links), with the error estimate; sphere mode, the planar solver's small coarse
islands and its closed parts use it.
"""
import numpy as np

STEINER_ORDER = 1.85  # the Steiner paths' excess falls as k^-1.85 (measured on spot: k = 4, 10, 16, 30)
STEINER = 15         # Steiner points per edge in the refined seed's shortest paths (``steiner_distances``)
GRADE_ANGLE = np.radians(10.0)  # ``edge_grading``: an edge at a corner narrower than this gets more points
GRADE_MAX = 8        # at most this many times the points
GRADE_EXTRA = 0.25   # the graded points may always add this fraction to the graph's links (its k^2 terms),
GRADE_EXTRA_MAX = 15.0  # and up to this much where ``PATH_BUDGET`` has room (a small mesh of slivers)
PATCH_LINKS = 2_000_000  # links across flat convex patches (``patch_links``) a graph may add
PATCH_MIN = 3         # ... of at least this many triangles (an n-gon's fan; not a quad's two)
PATCH_MAX = 1000      # ... the largest this many patches at most
PATCH_NORMAL = 1e-10  # two triangles are coplanar when their unit normals' dot product is within this of 1
SHORT_AREA = 0.01    # ``thin_warning``: thin triangles left short of their graded points over this area
SHORT_FACES = 8      # fraction, and at least this many of them, are warned about


def mesh_edges(F):
    """The edges of the triangles ``F`` (m,3): ``(ue (e,2) sorted pairs in np.unique's order, inv (m,3)
    the edge of each side)``, side ``s`` joining corners ``s`` and ``s + 1``. Two sides are one edge
    when they join the same two vertices: true of a mesh, not of an intrinsic triangulation (use
    ``intrinsic_edges``)."""
    Ed = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), 1)
    ue, inv = np.unique(Ed, axis=0, return_inverse=True)
    return ue, inv.reshape(3, len(F)).T


def intrinsic_edges(T):
    """``mesh_edges`` of an intrinsic triangulation ``T`` (``core.mesh.intrinsic``), from its own edge
    ids: flips can join two vertices by two different edges (of different lengths, on different
    sides of the surface), which a vertex pair cannot tell apart. Taken as one edge, their Steiner
    points were shared, a shortcut between two places of the surface: on a noisy marching-cubes bust
    (77 such pairs in 27k triangles) the plain paths came out 2 % below the exact distance.
    ``(ue (e,2), inv (m,3))`` as ``mesh_edges``: ``ue[e]`` the sorted ends of edge ``e``."""
    F = np.asarray(T.F, np.int64)
    inv = np.asarray(T.FE, np.int64)[:, [2, 0, 1]]          # side s (corners s, s + 1) is opposite s + 2
    ue = np.zeros((int(inv.max()) + 1 if inv.size else 0, 2), np.int64)
    for s_ in range(3):
        ue[inv[:, s_]] = np.sort(F[:, [s_, (s_ + 1) % 3]], axis=1)
    return ue, inv


def _areas(V, F, lengths=None):
    """(m,) areas of the triangles ``F`` (m,3) of ``V`` (n,3), or from their side ``lengths`` (m,3)."""
    if lengths is not None:
        from ..mesh.intrinsic import face_areas as areas_from_lengths
        return areas_from_lengths(lengths)
    from ..mesh.geometry import face_areas
    return face_areas(V, F)


def edge_corner_angles(V, F, inv, e, lengths=None):
    """(e,) the smallest corner angle (radians, at least 1e-12) at either end of each of the ``e`` edges
    of the triangles ``F`` (m,3) (``inv`` (m,3): the edge of each side, as ``mesh_edges`` gives it;
    vertices ``V`` (n,3), or the triangles' ``lengths`` (m,3), opposite each corner, of an intrinsic
    triangulation), over the triangles that share it."""
    if lengths is not None:
        from ..mesh.intrinsic import corner_angles as angles_from_lengths
        ang = angles_from_lengths(lengths)
    else:
        from ..mesh.geometry import corner_angles
        ang = corner_angles(V, F)
    amin = np.full(e, np.pi)
    for s_ in range(3):
        np.minimum.at(amin, inv[:, s_], np.minimum(ang[:, s_], ang[:, (s_ + 1) % 3]))
    return np.maximum(np.nan_to_num(amin, nan=0.0), 1e-12)


def edge_grading(V, F, ue, inv, extra_max=GRADE_EXTRA, amin=None):
    """Per-edge multipliers (e,) int64 of the Steiner points on the edges ``ue`` (e,2) of the triangles
    ``F`` (m,3) (``inv`` (m,3): the edge of each side, side ``s`` joining corners ``s`` and ``s + 1``;
    vertices ``V`` (n,3)): an edge carries ``(k + 1) m_e - 1`` points instead of ``k``. A geodesic that
    crosses a fan of thin triangles (a CAD cap's 7.5-degree corners) passes many short segments
    between points spaced by the edges' length, and the paths' excess there is large and falls slowly
    with ``k`` (the extrapolation and its estimate no longer hold). So an edge whose smallest corner at
    either end is below ``GRADE_ANGLE`` gets ``m_e = GRADE_ANGLE / angle`` rounded up to a power of 2, at
    most ``GRADE_MAX`` (1 elsewhere: most meshes are unchanged, or nearly). The extra links (``m_a m_b``
    per pair of sides, over the uniform graph's) stay within ``extra_max``: the largest ceiling on
    ``m_e`` that fits, and if even 2 does not, the angle is lowered until it fits. ``amin``: the
    edges' ``edge_corner_angles`` if the caller has them."""
    if amin is None:
        amin = edge_corner_angles(V, F, inv, len(ue))

    def mult(limit, cap=GRADE_MAX):
        want = np.maximum(limit / amin, 1.0)
        return np.minimum(2.0 ** np.ceil(np.log2(want) - 1e-9), cap).astype(np.int64)

    def extra(mu):
        return grade_extra(mu, inv)

    cap = GRADE_MAX
    while cap >= 2:
        if extra(mult(GRADE_ANGLE, cap)) <= extra_max:
            return mult(GRADE_ANGLE, cap)
        cap //= 2
    lo, hi = 0.0, GRADE_ANGLE         # the largest angle whose doubled points fit (extra grows with it)
    for _ in range(30):
        mid = 0.5 * (lo + hi)
        lo, hi = (mid, hi) if extra(mult(mid, 2)) <= extra_max else (lo, mid)
    return mult(lo, 2)


def grade_extra(mult, inv):
    """The links a grading adds to a Steiner graph, as a fraction of the uniform graph's ``k^2`` terms:
    per triangle ``m_a m_b + m_b m_c + m_a m_c - 3`` over 3 (``mult`` (e,) the edge multipliers,
    ``inv`` (m,3) the edge of each side), averaged over the triangles."""
    mm = mult[inv]
    return float((mm[:, 0] * mm[:, 1] + mm[:, 1] * mm[:, 2] + mm[:, 0] * mm[:, 2] - 3).sum()) \
        / (3.0 * max(len(inv), 1))


class SteinerGraph:
    """The shortest-path graph on the surface of the triangles ``F`` (m,3) (vertices ``V`` (n,3)) through
    ``k`` Steiner points on every edge (the graph of the module's docstring), built once and searched
    from any sources (``search``).

    Attributes: ``k``; ``n`` vertices; ``P`` (N,3) the graph points (the n vertices first); ``ue``
    (e,2) the edges' ends, each pair sorted; ``inv`` (m,3) the edge of each triangle's side; ``count``
    (e,) the points on each edge (``k``, or ``(k + 1) m_e - 1`` with a ``grade``) and ``start`` (e,)
    the index of its first (the points of an edge are consecutive, from ``ue[:, 0]`` to ``ue[:, 1]``);
    without a grade also
    ``pid`` (e,k) their indices and ``own`` (m, 3 + 3k) the points on each triangle's boundary; ``G``
    the links both ways as a (N+1, N+1) CSR matrix (mesh units) over the points numbered by ``rank``
    (N,), whose last row is a virtual source that ``search`` joins to surface points (its ``SPARE``
    slots are rewritten per search). ``search`` takes and returns points in the order of ``P``.
    ``grade`` (e,) int: per-edge multipliers over the sorted edges (``edge_grading``), or None;
    ``edges``: ``(ue, inv)`` if the caller has them (``mesh_edges``). ``lengths`` (m,3): ``F`` is an
    intrinsic triangulation with these side lengths (opposite each corner, ``core.mesh.intrinsic``):
    each link is measured in its triangle's planar copy, ``P`` is then only where the points would lie
    on the chords between ``V``'s vertices (it orders the graph), and searches take vertex sources
    only (``intrinsic`` True)."""

    SPARE = 256   # link slots of the virtual source (a point in a triangle needs 3 + 3k of them)

    def __init__(self, V, F, k=STEINER, grade=None, edges=None, lengths=None, patches=None, spare=None):
        V = np.asarray(V, np.float64)
        F = np.asarray(F, np.int64)
        n = len(V)
        self.k, self.n = k, n
        if spare is not None:               # room for this many links of the virtual source (``search_from``)
            self.SPARE = max(int(spare), SteinerGraph.SPARE)
        self.intrinsic = lengths is not None
        ue, inv = mesh_edges(F) if edges is None else edges
        if lengths is not None:
            from ..mesh.intrinsic import layout
            lengths = np.asarray(lengths, np.float64)
            el = np.zeros(len(ue))
            for s_ in range(3):
                el[inv[:, s_]] = lengths[:, (s_ + 2) % 3]        # side s_ is opposite corner s_ + 2
        count = np.full(len(ue), k, np.int64) if grade is None else (k + 1) * np.asarray(grade, np.int64) - 1
        start = n + np.r_[0, np.cumsum(count)[:-1]].astype(np.int64)
        eid = np.repeat(np.arange(len(ue)), count)                           # the edge of each point
        t = (np.arange(len(eid)) - (start[eid] - n) + 1) / (count[eid] + 1)
        pts = np.concatenate([V, V[ue[eid, 0]] * (1 - t)[:, None] + V[ue[eid, 1]] * t[:, None]])
        N = len(pts)
        # the graph numbers its points along a Morton (Z-order) curve of their positions, so that the
        # rows Dijkstra relaxes one after another lie close in memory (spot, k = 9: 64 -> 54 ms a search
        # of this graph);
        # ``rank`` (N,) is each point's number in the graph
        self.rank = rank = morton_rank(pts)
        rk = rank.astype(_index_type(N))           # the links' ends, in the matrix's index type
        # segments inside each triangle between points on two different sides (each such pair belongs to
        # one triangle only, except where an intrinsic triangulation puts one vertex opposite an edge
        # in both of the edge's triangles: that vertex and the edge's points are joined twice, by two
        # segments of their own), plus the chain of consecutive points along every edge (once per
        # edge); triangles are taken by the points on their three sides (one group without a grade).
        # ``links``: (rank of one end, rank of the other, length) per block
        links = []
        sig = count[inv]
        keys, group = np.unique(sig, axis=0, return_inverse=True)
        group = group.ravel()
        for g, (c0, c1, c2) in enumerate(keys):
            fs = np.flatnonzero(group == g)
            own = np.concatenate([F[fs]] + [start[inv[fs, j]][:, None] + np.arange(c)[None]
                                            for j, c in enumerate((c0, c1, c2))], 1)
            side = np.r_[[0b101, 0b011, 0b110], np.repeat([0b001, 0b010, 0b100], [c0, c1, c2])]
            ia, ib = np.triu_indices(own.shape[1], 1)
            cross = (side[ia] & side[ib]) == 0
            ia, ib = ia[cross], ib[cross]
            if lengths is not None:
                # the segment's length in the triangle's own planar copy (its points by their place
                # along each side, which runs from ue[:, 0] to ue[:, 1])
                L = layout(lengths[fs])                                      # (f,3,2)
                Q = [L]
                for j, c in enumerate((c0, c1, c2)):
                    t = (np.arange(c) + 1.0) / (c + 1.0)
                    fwd = F[fs, j] == ue[inv[fs, j], 0]
                    tt = np.where(fwd[:, None], t[None], 1.0 - t[None])[..., None]
                    Q.append(L[:, j, None] * (1.0 - tt) + L[:, (j + 1) % 3, None] * tt)
                Q = np.concatenate(Q, 1)
                ro = rk[own]
                links.append((ro[:, ia].ravel(), ro[:, ib].ravel(),
                              np.linalg.norm(Q[:, ia] - Q[:, ib], axis=2).ravel()))
            else:
                links.extend(_triangle_links(own, ia, ib, pts, rk))
            if grade is None:
                self.own = own                                               # (m, 3 + 3k), in F's order
        self.patches = []
        if lengths is None:
            # a flat convex patch of several triangles (a CAD face, an n-gon's fan): straight links
            # between the points on its boundary, across the triangles inside it
            given = patches is not None
            pairs, self.patches = patch_links(patches if given else planar_patches(V, F, ue, inv), ue, n,
                                              count, start, None if given else PATCH_LINKS)
            links.extend((rk[a], rk[b], _norm(pts[a] - pts[b])) for a, b in pairs)
            del pairs
        for c in np.unique(count):
            es = np.flatnonzero(count == c)
            chain = np.concatenate([ue[es, :1], start[es][:, None] + np.arange(c)[None], ue[es, 1:]], 1)
            a, b = chain[:, :-1].ravel(), chain[:, 1:].ravel()
            w = np.repeat(el[es] / (c + 1.0), c + 1) if lengths is not None else _norm(pts[a] - pts[b])
            links.append((rk[a], rk[b], w))
        self.G = _link_matrix(links, N, self.SPARE)
        del links
        self.P, self.F, self.ue, self.inv, self.count, self.start, self.N = pts, F, ue, inv, count, start, N
        if grade is None:
            self.pid = start[:, None] + np.arange(k)[None]                    # (e,k)
        else:
            self.own = self.pid = None

    def boundary(self, faces):
        """The points on the boundary of each triangle of ``faces`` (p,): (q,) point indices and (q,) the
        position in ``faces`` each belongs to (its corners, then the points of its three sides)."""
        faces = np.asarray(faces, np.int64)
        if self.own is not None:
            cand = self.own[faces]
            return cand.ravel(), np.repeat(np.arange(len(faces)), cand.shape[1])
        e = self.inv[faces]                                                  # (p,3)
        cnt = self.count[e].ravel()
        owner = np.repeat(np.repeat(np.arange(len(faces)), 3), cnt)
        first = np.repeat(self.start[e].ravel(), cnt)
        offs = np.arange(len(first)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        cand = np.r_[self.F[faces].ravel(), first + offs]
        owner = np.r_[np.repeat(np.arange(len(faces)), 3), owner]
        order = np.argsort(owner, kind='stable')
        return cand[order], owner[order]

    def search(self, src=None, X=None, src_faces=None):
        """(N,) shortest path lengths from source vertices ``src`` (an index or (s,) indices: the distance
        to the nearest) and/or surface points: one point ``X`` (3,) in the triangles ``src_faces`` (its
        star), or points ``X`` (p,3) each in its triangle ``src_faces`` (p,)."""
        from scipy.sparse.csgraph import dijkstra
        rank = self.rank
        sv = None if src is None else np.unique(np.atleast_1d(src)).astype(np.int64)
        if X is None or src_faces is None:                    # vertex sources only (X ignored)
            return dijkstra(self.G, directed=True, indices=rank[sv], min_only=True)[rank]
        # the virtual source joined to the source vertices (length 0: 1e-300, as csgraph drops zeros)
        # and to every point on the boundary of each source point's triangle(s) (the straight segment)
        if self.intrinsic:
            raise ValueError("an intrinsic triangulation's graph takes vertex sources only")
        X = np.asarray(X, np.float64)
        cand, owner = self.boundary(np.atleast_1d(src_faces))
        if X.ndim == 1:
            cand = np.unique(cand)
            wx = np.linalg.norm(self.P[cand] - X, axis=1)
        else:
            wx = np.linalg.norm(self.P[cand] - X[owner], axis=1)
        if sv is not None:
            cand, wx = np.r_[cand, sv], np.r_[wx, np.zeros(len(sv))]
        return self.search_from(cand, wx)

    def search_from(self, points, lengths):
        """(N,) shortest path lengths from a virtual source joined to the graph points ``points`` (p,)
        (indices into ``P``) by links of ``lengths`` (p,) (mesh units, >= 0): the smallest over the
        points of its length plus the path from it (a source at several points, or times given at
        them)."""
        from scipy.sparse.csgraph import dijkstra
        N, rank = self.N, self.rank
        wx = np.maximum(np.asarray(lengths, np.float64), 1e-300)   # csgraph drops zero lengths
        cand = rank[np.asarray(points, np.int64)]
        G = self.G
        if len(cand) <= self.SPARE:
            # rewrite the virtual source's row in place; its unused slots stay self-links
            lo = G.indptr[N]
            G.indices[lo:lo + self.SPARE] = N
            G.data[lo:lo + self.SPARE] = 1.0
            G.indices[lo:lo + len(cand)] = cand
            G.data[lo:lo + len(cand)] = wx
        else:
            import scipy.sparse as sp
            lo = G.indptr[N]
            G = sp.csr_matrix((np.r_[G.data[:lo], wx], np.r_[G.indices[:lo], cand],
                               np.r_[G.indptr[:N + 1], lo + len(cand)]), shape=G.shape)
        return dijkstra(G, directed=True, indices=N)[rank]


def planar_patches(V, F, ue, inv, min_size=PATCH_MIN, max_patches=PATCH_MAX):
    """The flat convex patches of a mesh, for ``SteinerGraph``'s ``patch_links``. A patch is a connected
    set of at least ``min_size`` coplanar triangles of ``F`` (m,3) (vertices ``V`` (n,3); unit normals
    within ``PATCH_NORMAL``, either orientation) that is a disk whose boundary angles are all at most
    pi: a convex polygon, so the straight segment between any two points on its boundary lies on the
    surface. A patch is left out where a triangle outside it joins two of its boundary edges (a fold
    back onto it). ``ue`` (e,2), ``inv`` (m,3): ``mesh_edges``. Returns a list, the largest first and
    at most ``max_patches``, of (bnd (b,) its boundary edges, bv (c,) its boundary vertices, opp (b,)
    the corner of its triangle on each boundary edge off that edge, tin (b,) that triangle)."""
    from scipy.sparse import coo_matrix
    from scipy.sparse.csgraph import connected_components
    from ..mesh.geometry import corner_angles, unit_face_normals
    m = len(F)
    N, ok = unit_face_normals(V, F)
    # the (at most two) triangles of each edge
    fe = inv.ravel()
    ft = np.repeat(np.arange(m), 3)
    order = np.argsort(fe, kind='stable')
    fe, ft = fe[order], ft[order]
    two = np.r_[False, fe[1:] == fe[:-1]]                  # the second triangle of an edge
    t1, t2 = ft[np.flatnonzero(two) - 1], ft[two]
    flat = ok[t1] & ok[t2] & (np.abs((N[t1] * N[t2]).sum(1)) > 1.0 - PATCH_NORMAL)
    if not flat.any():
        return []
    _, comp = connected_components(coo_matrix((np.ones(int(flat.sum())), (t1[flat], t2[flat])), shape=(m, m)),
                                   directed=False)
    size = np.bincount(comp)
    big = np.flatnonzero(size >= min_size)
    big = big[np.argsort(-size[big], kind='stable')][:max_patches]
    if not len(big):
        return []
    rank = np.full(len(size), -1)
    rank[big] = np.arange(len(big))
    sel = np.flatnonzero(rank[comp] >= 0)
    sel = sel[np.argsort(rank[comp[sel]], kind='stable')]
    out = []
    for tris in np.split(sel, np.cumsum(size[big])[:-1]):
        es, side_count = np.unique(inv[tris].ravel(), return_counts=True)
        bnd = es[side_count == 1]                            # boundary edges of the patch
        verts, local = np.unique(F[tris], return_inverse=True)
        if len(verts) - len(es) + len(tris) != 1:            # not a disk
            continue
        s = np.bincount(local.ravel(), corner_angles(V, F[tris]).ravel(), minlength=len(verts))
        bv = np.unique(ue[bnd])
        if (s[np.searchsorted(verts, bv)] > np.pi + 1e-9).any():    # not convex
            continue
        # the patch's triangle on each boundary edge, and the triangle across it (or -1)
        pos = np.searchsorted(fe, bnd)
        nxt = np.minimum(pos + 1, len(fe) - 1)
        tA, tB = ft[pos], np.where((pos + 1 < len(fe)) & (fe[nxt] == bnd), ft[nxt], -1)
        inside = np.isin(tA, tris)
        tin, tout = np.where(inside, tA, tB), np.where(inside, tB, tA)
        ends = ue[bnd]
        off = ~(F[tin][:, :, None] == ends[:, None, :]).any(2)             # the corner off each edge
        across = tout >= 0
        off_out = ~(F[tout[across]][:, :, None] == ends[across][:, None, :]).any(2)
        if (off.sum(1) != 1).any() or (off_out.sum(1) != 1).any():
            continue
        if np.isin(F[tout[across]][off_out], bv).any():     # a triangle outside joins two of its edges
            continue
        out.append((bnd, bv, F[tin][off], tin))
    return out


def patch_links(patches, ue, n, count, start, budget=PATCH_LINKS):
    """Links across the ``patches`` (``planar_patches``) for ``SteinerGraph``: every pair of graph points
    on a patch's boundary (its boundary vertices, and the ``count`` (e,) points of each boundary edge
    from ``start`` (e,)) by the straight segment, but for the pairs the triangle links and the edge
    chains already join (each is linked once): on one edge, in one triangle, or the two ends
    of a mesh edge (``ue`` (e,2), ``n`` vertices). Patches are taken in order, each if its links fit in
    what is left of ``budget`` (None: every one). Returns (list of (a (l,), b (l,)) point index pairs,
    the patches taken). Without them an n-gon cut into a fan of needles is crossed through the Steiner
    points of every needle: the Blender cone's 0.50 % mean error, falling as 1/k."""
    links, taken, used = [], [], 0
    edge_key = ue[:, 0] * n + ue[:, 1]
    for patch in patches:
        bnd, bv, opp, tin = patch
        cnt = count[bnd]
        pe = np.repeat(np.arange(len(bnd)), cnt)
        pts = np.r_[bv, start[bnd][pe] + np.arange(len(pe)) - np.repeat(np.cumsum(cnt) - cnt, cnt)]
        edge_of = np.r_[np.full(len(bv), -1), pe]            # boundary vertices: -1
        npt = len(pts)
        if budget is not None and npt * (npt - 1) // 2 + used > budget:
            continue
        i, j = np.triu_indices(npt, 1)
        keep = np.ones(len(i), bool)
        ei, ej = edge_of[i], edge_of[j]
        both = (ei >= 0) & (ej >= 0)
        keep[both] = (ei[both] != ej[both]) & (tin[ei[both]] != tin[ej[both]])
        # a vertex and the points of an edge: not of its own edges, nor of the edge it is opposite
        ends = ue[bnd]
        for vi, ex in ((i, ej), (j, ei)):
            vx = np.flatnonzero((edge_of[vi] < 0) & (ex >= 0))
            u, e = pts[vi[vx]], ex[vx]
            keep[vx[(ends[e] == u[:, None]).any(1) | (opp[e] == u)]] = False
        vv = np.flatnonzero((ei < 0) & (ej < 0))
        a, b = pts[i[vv]], pts[j[vv]]
        keep[vv[np.isin(np.minimum(a, b) * n + np.maximum(a, b), edge_key)]] = False
        links.append((pts[i[keep]], pts[j[keep]]))
        taken.append(patch)
        used += int(keep.sum())
    return links, taken


def _index_type(N):
    """The index type of a link matrix over ``N`` points (and its virtual source): 32-bit when it fits."""
    return np.int32 if N + 1 < 2 ** 31 else np.int64


def _norm(D):
    """Lengths (l,) of the vectors ``D`` (l,3): ``sqrt((x^2 + y^2) + z^2)``, as ``np.linalg.norm`` sums
    them (the same values to the bit)."""
    return np.sqrt(D[:, 0] * D[:, 0] + D[:, 1] * D[:, 1] + D[:, 2] * D[:, 2])


TRIANGLE_CHUNK = 1 << 20    # ``_triangle_links``: at most about this many links a block


def _triangle_links(own, ia, ib, pts, rank):
    """The links between the points ``own[:, ia]`` and ``own[:, ib]`` of each triangle (row) of ``own``
    (f,q) (indices into ``pts`` (N,3)): blocks of (rank (l,) of one end, rank (l,) of the other, 3D
    length (l,)), ``rank`` (N,) the points' numbers in the graph. Each coordinate is gathered once per
    triangle point and then paired within the row (a triangle's q points, not its ~q^2 / 3 links, are
    read from ``pts``); the lengths are ``_norm``'s, to the bit."""
    step = max(1, TRIANGLE_CHUNK // max(len(ia), 1))
    for lo in range(0, len(own), step):
        o = own[lo:lo + step]
        ro = rank[o]
        w = None
        for axis in range(3):
            c = pts[o, axis]
            d = c[:, ia] - c[:, ib]
            d *= d
            w = d if w is None else w + d
        yield ro[:, ia].ravel(), ro[:, ib].ravel(), np.sqrt(w, out=w).ravel()


def _link_matrix(links, N, spare):
    """The (N+1, N+1) CSR matrix of the ``links`` (blocks of (rank a (l,), rank b (l,), length (l,)):
    points by their number in the graph, mesh units) both ways; its last row (the virtual source of
    ``search_from``) holds ``spare`` placeholder links. Built in 32-bit indices straight into one COO
    triple with the spare row, the blocks freed as they are copied: the peak resident memory of a
    build rises by about 52 bytes a link (spot's head cut at k = 31; 63 when the blocks held point
    indices, the lengths were taken here and the rows were sorted: ``PATH_BUDGET``). The conversion
    to CSR skips scipy's search for repeated entries (a sort of every row: 0.15 s at 10M links), which
    summed them: a pair of points joined twice (through two triangles of an intrinsic triangulation,
    see ``SteinerGraph``; ``patch_links`` adds none) keeps both links, and Dijkstra takes the
    shorter. The columns of a row stay in the order the links came."""
    import scipy.sparse as sp
    L = sum(len(a) for a, _, _ in links)
    itype = _index_type(N)
    rows = np.empty(2 * L + spare, itype)
    cols = np.empty(2 * L + spare, itype)
    data = np.empty(2 * L + spare, np.float64)
    at = 0
    while links:
        ra, rb, w = links.pop(0)
        c = len(ra)
        rows[at:at + c], cols[at:at + c] = ra, rb
        rows[L + at:L + at + c], cols[L + at:L + at + c] = rb, ra
        np.maximum(w, 1e-300, out=data[at:at + c])                # csgraph drops explicit zeros
        data[L + at:L + at + c] = data[at:at + c]
        at += c
        del ra, rb, w
    # the spare row: distinct columns while the graph has that many points, each rewritten per search;
    # a smaller graph's row is appended by hand
    fits = N + 1 >= spare
    rows[2 * L:] = N
    cols[2 * L:] = np.arange(spare) if fits else N
    data[2 * L:] = 1.0
    if fits:
        coo = sp.coo_matrix((data, (rows, cols)), shape=(N + 1, N + 1))
        coo.has_canonical_format = True      # repeated pairs stay apart (see above)
        return coo.tocsr()
    G = sp.coo_matrix((data[:2 * L], (rows[:2 * L], cols[:2 * L])), shape=(N, N))
    G.has_canonical_format = True
    G = G.tocsr()
    return sp.csr_matrix((np.r_[G.data, np.ones(spare)], np.r_[G.indices, np.full(spare, N, G.indices.dtype)],
                          np.r_[G.indptr, G.indptr[-1] + spare]), shape=(N + 1, N + 1))


def morton_rank(P, bits=10):
    """(N,) int64: the rank of each point of ``P`` (N,3) along a Morton (Z-order) curve of its bounding
    box quantised to ``2^bits`` cells per axis (ties in the input order)."""
    lo, span = P.min(axis=0), np.ptp(P, axis=0).max()
    q = ((P - lo) / (span if span > 0 else 1.0) * ((1 << bits) - 1)).astype(np.int64)
    code = np.zeros(len(P), np.int64)
    for bit in range(bits):
        for axis in range(3):
            code |= ((q[:, axis] >> bit) & 1) << (3 * bit + axis)
    rank = np.empty(len(P), np.int64)
    rank[np.argsort(code, kind='stable')] = np.arange(len(P))
    return rank


class SurfacePaths:
    """Richardson's pair of ``SteinerGraph``: ``k`` (odd, at least 3) and ``(k - 1) / 2`` points per edge on
    the triangles ``F`` (m,3) (vertices ``V`` (n,3)), built once and searched from any sources
    (``distances``); ``graded``: both with the edge multipliers of ``edge_grading`` (``(k + 1) m_e - 1``
    and ``(k + 1) / 2 m_e - 1`` points), adding at most ``GRADE_EXTRA`` to the links or, where
    ``PATH_BUDGET`` has room for the pair, up to ``GRADE_EXTRA_MAX``. The coarse graph's points are the
    vertices and fine points 1, 3, ... (0-based) of every edge, in the same edge order (both graphs
    take the same ``edges``: ``mesh_edges``, or ``intrinsic_edges`` given). ``lengths`` (m,3): ``F`` is
    an intrinsic triangulation with these side lengths (``SteinerGraph``)."""

    def __init__(self, V, F, k, graded=False, lengths=None, edges=None):
        if k < 3 or k % 2 == 0:
            raise ValueError(f"Richardson's extrapolation needs an odd k >= 3, got {k}")
        self.k = k
        F = np.asarray(F, np.int64)
        edges = mesh_edges(F) if edges is None else edges
        grade = None
        self.short = (0.0, 0)
        self.grade_need = 0.0
        if graded:
            ue, inv = edges
            V = np.asarray(V, np.float64)
            room = grading_room(len(F), len(ue), k)
            amin = edge_corner_angles(V, F, inv, len(ue), lengths)
            grade = edge_grading(V, F, ue, inv, room, amin)
            # the thin triangles the budget left short of their points: the paths' excess there is
            # not what the extrapolation and its estimate assume (``thin_warning``)
            full = edge_grading(V, F, ue, inv, np.inf, amin)
            self.grade_need = grade_extra(full, inv)      # what the full grading adds (``surface_paths``)
            short = (grade[inv] < full[inv]).any(1)
            if short.any():
                A = _areas(V, F, lengths)
                self.short = (float(A[short].sum() / max(A.sum(), 1e-300)), int(short.sum()))
        self.fine = fine = SteinerGraph(V, F, k, grade, edges, lengths)
        # the coarse graph links across the same flat patches as the fine one (Richardson's pair must
        # differ only in its points: with the budget choosing for each, the coarse graph took more
        # patches and came out shorter than the fine one)
        self.coarse = coarse = SteinerGraph(V, F, (k - 1) // 2, grade, edges, lengths, patches=fine.patches)
        n = fine.n
        fine_at = np.full(coarse.N, -1, np.int64)
        fine_at[:n] = np.arange(n)
        e = np.repeat(np.arange(len(coarse.ue)), coarse.count)               # the edge of each coarse point
        j = np.arange(len(e)) - (coarse.start[e] - n)
        fine_at[n:] = fine.start[e] + 2 * j + 1
        self.fine_at = fine_at
        # fine points 0, 2, ... of every edge and their two neighbours along it (a point or an end)
        e = np.repeat(np.arange(len(fine.ue)), fine.count)
        j = np.arange(len(e)) - (fine.start[e] - n)
        even = j % 2 == 0
        p, e, j = n + np.flatnonzero(even), e[even], j[even]
        self.even = p
        self.before = np.where(j > 0, p - 1, fine.ue[e, 0])
        self.after = np.where(j < fine.count[e] - 1, p + 1, fine.ue[e, 1])
        self.used = np.unique(F)

    def distances(self, src=None, X=None, src_faces=None):
        """``(dv (n,) at the vertices, inf off F; dS (N,) at every fine graph point; ev (n,) the estimated
        excess of the ``k``-point paths at the vertices, the correction subtracted, 0 off F)``: the
        excess ``d_k - d`` taken as ``(d_(k-1)/2 - d_k) / (2^STEINER_ORDER - 1)`` at the shared points,
        linearly interpolated along the edge between them (Richardson's extrapolation: no longer an
        upper bound, about 8x closer on spot, bunny, edgebump)."""
        fine, n = self.fine, self.fine.n
        dS = fine.search(src, X, src_faces)
        dC = self.coarse.search(src, X, src_faces)
        corr = np.zeros(len(dS))
        corr[self.fine_at] = richardson_excess(dC, dS[self.fine_at])
        # fine points 0, 2, ..., k-1 of each edge: the mean of their two neighbours (vertex or shared point)
        corr[self.even] = 0.5 * (corr[self.before] + corr[self.after])
        dS = dS - np.maximum(corr, 0.0)
        dv = np.full(n, np.inf)
        ev = np.zeros(n)
        dv[self.used] = dS[self.used]
        ev[self.used] = np.maximum(corr[self.used], 0.0)
        return dv, dS, ev


def richardson_excess(d_half, d_k):
    """The estimated excess (q,) of the ``k``-point paths ``d_k`` (q,) over the geodesic at points that
    the graph of ``(k - 1) / 2`` points per edge shares, from its paths ``d_half`` (q,):
    ``(d_half - d_k) / (2^STEINER_ORDER - 1)`` (Richardson's extrapolation), 0 where either is not
    finite. It may be negative; callers subtract only a positive excess."""
    ok = np.isfinite(d_half) & np.isfinite(d_k)
    out = np.zeros(len(d_k))
    out[ok] = (d_half[ok] - d_k[ok]) / (2.0 ** STEINER_ORDER - 1.0)
    return out


def steiner_distances(V, F, src=None, X=None, src_faces=None, k=STEINER, extrapolate=False, excess=False,
                      graded=False):
    """Shortest paths on the surface of the triangles ``F`` (m,3) (vertices ``V`` (n,3)) from source
    vertices ``src`` (an index or (s,) indices: the distance to the nearest) and/or surface points
    ``X`` in ``src_faces`` (as ``SteinerGraph.search``), through ``k`` Steiner points on
    every edge: a graph joining every pair of points (vertices and Steiner points) on the boundary of
    each triangle by the straight segment inside it. Each graph path is a path on the surface, so the
    distances are upper bounds of the geodesic ones, and tend to them as ``k`` grows (docs/geodesic.md,
    "Refined seed"). ``extrapolate`` (``k`` odd): Richardson's extrapolation from the graph of
    ``(k - 1) / 2`` points per edge too (``SurfacePaths``: no longer an upper bound), with ``graded``
    more points on the edges of thin triangles (``edge_grading``, as ``SurfacePaths`` grades them).
    The graphs are built for this one search: keep a ``SurfacePaths`` to search one mesh many times.
    Returns ``(dv (n,) at the vertices, inf off F; dS (p,) at every graph point; P (p,3) the points;
    graph, the ``SteinerGraph`` searched (``graph.boundary`` gives the points on each triangle's
    boundary; its first n points are the vertices))``, and with ``excess`` (and ``extrapolate``) also
    ``ev`` (n,): the estimated excess of the ``k``-point paths over the geodesic at the vertices (the
    correction subtracted; 0 off F)."""
    n = len(V)
    if extrapolate and k >= 3 and k % 2 == 1:
        pair = SurfacePaths(V, F, k, graded=graded)
        dv, dS, ev = pair.distances(src, X, src_faces)
        graph = pair.fine
    else:
        graph = SteinerGraph(V, F, k)
        dS = graph.search(src, X, src_faces)
        dv = np.full(n, np.inf)
        used = np.unique(F)
        dv[used] = dS[used]
        ev = np.zeros(n)
    if excess:
        return dv, dS, graph.P, graph, ev
    return dv, dS, graph.P, graph


# ``surface_paths`` divides the plain k-point paths' mean excess (the Richardson correction) by this to
# estimate the mean error of the extrapolated distances. Measured at k = 9 against exact MMP, four
# random sources per mesh (docs/geodesic.md, "Twenty-first round"): 3.1-5.6x on spot, cheburashka and
# bump (regular meshes), but 1.6-3.1x on scan-like meshes (random points, Delaunay-triangulated and
# lifted: facescan, faceholes, deepcap and four more of that kind), 1.8-2.4x on the cow's head cut and
# 1.2-2.5x on suzanne. It was 2.5, from spot and cheburashka alone: on the scans the estimate was then
# up to 1.5x below the error, and paths at 0.10-0.14 % mean came back with no refinement and no warning.
# Not at k = 3: its coarse graph has one point per edge, too few for the extrapolation to gain (the
# extrapolated error equals the excess there: 0.94-0.96x on spot and cheburashka, three sources each);
# ``extrapolation_gain`` says which applies.
EXTRAPOLATION_GAIN = 1.6
# At k = 3 (what a target of 0.67 % or looser starts from, ``target_k``) the error over the excess
# spreads more: the worst source set's mean over the mean estimate at gain 1 was 0.58-1.33 on 17
# meshes (the generated surfaces, the head cuts, the scan-like faces, spot, suzanne, teapot, the
# bunny), and 2.1 on saddle's far set (a source at a corner of the square: the extrapolation
# overshoots there). Dividing by this instead leaves that one set 1.6x under its estimate.
EXTRAPOLATION_GAIN_3 = 0.75
# The same on an intrinsic Delaunay triangulation (``path_triangulation``): 1.38-3.5 at k = 9 on the
# scan-like meshes (deepcap, facescan, faceholes, a lifted hemisphere, faces at one to three times the
# relief), against exact MMP, eight random sources and a three-source set each; 1.6 left two deepcap
# sources at 0.103-0.110 % under estimates of 0.095 %.
EXTRAPOLATION_GAIN_INTRINSIC = 1.35
# The links ``grading_room`` measures the graded points' room against: the budget they were tuned with
# (the twenty-first round). ``PATH_BUDGET`` grew with the graphs' leaner build; the grading's room did
# not (that would change every needle mesh's graphs and times, unmeasured).
GRADE_BUDGET = 12_000_000
PATH_K = (9, 7, 5, 3)       # Steiner points per edge that ``surface_paths`` tries, best first (odd)
PATH_K_MAX = 31            # the most Steiner points per edge ``surface_paths`` refines to for its target
PATH_BUDGET = 20_000_000  # graph links (point pairs, both graphs) ``surface_paths`` may build: about
# 52 bytes a link at the peak of building (``_link_matrix``; 57-63 before the thirty-first round's
# build), 31 kept, so ~1 GB. It was 12M at 97
# bytes a link; on an 83k-triangle scan-like face (twice the relief) the paths then stopped at k = 5,
# 0.19 % mean error (estimate 0.24 %); at 20M they take k = 7, 0.093 % (estimate 0.17 %)
# (counted by ``path_links`` without the grading, which adds at most ``GRADE_EXTRA``, or what 0.9 of
# the budget leaves, see ``SurfacePaths``)
# ``surface_paths`` also refines when the plain paths' excess at some vertex beyond two mean edges of
# the sources is above this (relative): on sliver triangles (a thin box's sides, 1:7) k = 9 met the
# mean target (0.07 %) with one vertex 2.4 % off (excess 3.9 %); elsewhere the worst excess is
# 0.2-1.7 % (spot, cow, cheburashka, box, cylinder, torus) and the worst error 0.6-1.1x it
PATH_WORST = 0.015
# ``coarse_k``: with a target, the Steiner points' spacing on the area-weighted mean edge is at most this
# fraction of the median distance. On a bevelled cube (big faces of two triangles, 188 in all) k = 21,
# where the default stopped at 9 (0.13-0.16 % mean, estimated 0.05-0.10 %); meshes whose paths cross
# more than about 4 such edges are not affected (it asks for k <= 9)
PATH_SPACING = 0.03
# The error target ``PATH_WORST`` and ``PATH_SPACING`` were set for. With a looser ``target``,
# ``surface_paths`` loosens both in proportion to it (the spacing as the paths' error falls with the
# points, ``k^-STEINER_ORDER``), and ``target_k`` starts from fewer points: a target of 0.5 % is not
# held to the points that 0.1 % needs (docs/geodesic.md, "Error target")
PATH_TARGET = 1e-3
PATH_ERROR_9 = 7e-4  # expected mean error of the paths at k = 9 (measured 0.02-0.07 %; falls as k^-1.85)


def target_k(target):
    """The fewest Steiner points per edge of ``PATH_K`` (odd) whose expected mean error,
    ``PATH_ERROR_9 (9 / k)^STEINER_ORDER``, is within 0.8 of the mean relative error ``target``:
    ``PATH_K[0]`` (9) at the default 0.1 % and tighter, 7 from 0.14 %, 5 from 0.26 %, 3 from 0.67 %.
    Measured against exact MMP (the worst source set's mean; docs/geodesic.md, "Error target", 18
    meshes): k = 5 0.09-0.53 %, k = 3 0.31-0.76 % (1.56 % on saddle's far corner, warned)."""
    for k in sorted(PATH_K):
        if PATH_ERROR_9 * (PATH_K[0] / k) ** STEINER_ORDER <= 0.8 * target:
            return k
    return PATH_K[0]


# At the default target and tighter ones (``target_k`` at ``PATH_K[0]``), a query starts from the points
# whose expected mean error is at most this share of the target (``start_k``): ``PATH_ERROR_9`` is a mean
# over meshes, and a mesh's worst source set came out at up to 1.2x its own estimate at k = 9 (suzanne
# 0.084 % against 0.075 %, its face island 0.095 %), so a start at the target itself would leave such
# meshes at the target's edge. Before, the start was the most points the chart's cost test bought
# (k = 17-31 on the head cuts, 0.008 % mean at 25x heat's one-shot time).
PATH_START_SHARE = 0.4


def start_k(target, k_max=PATH_K_MAX):
    """The Steiner points per edge (odd) a surface-paths query starts from for the mean relative error
    ``target``: ``target_k`` where that is below ``PATH_K[0]`` (a looser target than the default), else
    the fewest odd ``k`` from ``PATH_K[0]`` up to ``k_max`` with ``PATH_ERROR_9 (9 / k)^STEINER_ORDER``
    at most ``PATH_START_SHARE`` of it: 13 at the default 0.1 %, 19 at 0.05 %. The estimate of the
    answer then decides whether the query refines (``surface_paths``). Between 0.13 % (11) and 0.14 %
    (7) the start drops: the looser targets keep ``target_k``'s rule (0.8 of the target), measured on
    18 meshes within their targets (docs/geodesic.md, "Error target")."""
    k = target_k(target)
    if k < PATH_K[0]:
        return k
    want = PATH_K[0] * (PATH_ERROR_9 / (PATH_START_SHARE * target)) ** (1.0 / STEINER_ORDER)
    return int(min(max(np.ceil(want - 1e-9), PATH_K[0]), k_max)) | 1


def _loosen(target):
    """How much looser ``target`` is than ``PATH_TARGET`` (at least 1)."""
    return max(1.0, target / PATH_TARGET)


def coarse_k(V, F, lengths, dist, cache, spacing=PATH_SPACING):
    """The fewest Steiner points per edge (odd) for which their spacing on the area-weighted mean edge
    of the triangles ``F`` (m,3) (on ``V`` (n,3), or with side ``lengths`` (m,3)) is at most
    ``spacing`` of the median of the distances ``dist`` (k,): on a coarse mesh a path crosses a
    few edges, and its excess does not fall as ``k^-STEINER_ORDER``, which the extrapolation and its
    estimate assume (a bevelled cube's big faces: as k^-1.25, 0.13-0.16 % mean at k = 9 under
    estimates of 0.05-0.10 %). The area-weighted edge is kept in ``cache``."""
    if 'area_edge' not in cache:
        if lengths is None:
            lengths = np.linalg.norm(V[F] - V[np.roll(F, 1, axis=1)], axis=2)
        a = _areas(V, F, lengths)
        cache['area_edge'] = float((a * lengths.mean(1)).sum() / max(a.sum(), 1e-300))
    med = float(np.median(dist)) if len(dist) else 0.0
    if not med > 0:
        return 0
    return int(np.ceil(cache['area_edge'] / (spacing * med))) | 1


def extrapolation_gain(k, intrinsic=False):
    """How much closer the extrapolated paths at ``k`` points per edge are than the plain ones (the
    divisor of the excess in the error estimate); ``intrinsic``: on an intrinsic triangulation."""
    if k <= 3:
        return EXTRAPOLATION_GAIN_3
    return EXTRAPOLATION_GAIN_INTRINSIC if intrinsic else EXTRAPOLATION_GAIN


def path_links(n_faces, n_edges, k):
    """Point pairs of the Steiner graph with ``k`` points per edge on a mesh of ``n_faces`` triangles and
    ``n_edges`` edges: per triangle 3 k^2 (points on two different sides) + 3 k (a corner and a point of
    the opposite side), per edge the k + 1 links along it."""
    return n_faces * (3 * k * k + 3 * k) + n_edges * (k + 1)


def path_points(n_faces, n_edges, budget=None, k_min=PATH_K[-1], k_max=PATH_K[0]):
    """The largest odd ``k`` in ``k_min..k_max`` (default: ``PATH_K``) whose graph and Richardson's
    coarse one, ``(k - 1) / 2`` points per edge, fit in ``budget`` links (None: ``PATH_BUDGET``); None
    if none does."""
    budget = PATH_BUDGET if budget is None else budget
    for k in range(k_max if k_max % 2 else k_max - 1, k_min - 1, -2):
        if path_links(n_faces, n_edges, k) + path_links(n_faces, n_edges, (k - 1) // 2) <= budget:
            return k
    return None


def grading_room(n_faces, n_edges, k):
    """The links ``edge_grading`` may add to the pair of graphs at ``k`` points per edge (a fraction of
    their ``k^2`` terms, as ``grade_extra`` counts them): ``GRADE_EXTRA``, or up to ``GRADE_EXTRA_MAX``
    what 0.9 of ``PATH_BUDGET``, at most ``GRADE_BUDGET``, leaves over the uniform graphs."""
    base = path_links(n_faces, n_edges, k) + path_links(n_faces, n_edges, (k - 1) // 2)
    return min(GRADE_EXTRA_MAX, max(GRADE_EXTRA, 0.9 * min(PATH_BUDGET, GRADE_BUDGET) / base - 1.0))


def graded_fit(n_faces, n_edges, need, k_max, k_min=PATH_K[-1]):
    """The largest odd ``k`` in ``k_min..k_max`` whose ``grading_room`` holds a full grading that adds
    ``need`` (``grade_extra``), or None."""
    return next((j for j in range(k_max if k_max % 2 else k_max - 1, k_min - 1, -2)
                 if grading_room(n_faces, n_edges, j) >= need), None)


def full_grading(V, F, lengths=None, edges=None):
    """The grading every thin triangle of ``F`` (m,3) asks for, with no budget: ``(ue, inv, amin, full)``
    (``mesh_edges``, ``edge_corner_angles`` and ``edge_grading`` of vertices ``V`` (n,3), or of the
    triangles' side ``lengths`` (m,3) and ``edges`` (``intrinsic_edges``) of an intrinsic
    triangulation). ``grade_extra(full, inv)`` is what it adds to the graphs' links."""
    F = np.asarray(F, np.int64)
    ue, inv = mesh_edges(F) if edges is None else edges
    amin = edge_corner_angles(V, F, inv, len(ue), lengths)
    return ue, inv, amin, edge_grading(V, F, ue, inv, np.inf, amin)


def graded_k(V, F, k, cache=None, lengths=None, edges=None):
    """The Steiner points per edge to build for a requested ``k`` (odd) on the triangles ``F`` (m,3)
    (vertices ``V`` (n,3)): ``k``; or, where its graphs would leave thin triangles over ``SHORT_AREA``
    of the area short of their graded points (``edge_grading`` within ``grading_room``), the largest
    odd ``k' < k`` (at least ``PATH_K[-1]``) at which every thin triangle gets them, if there is one.
    ``lengths`` (m,3) and ``edges``: the triangles' side lengths (opposite each corner) and edges
    (``intrinsic_edges``) of an intrinsic triangulation. Measured on scans whose flanks stand nearly
    vertical (needles over a third of the area, 10k triangles, against exact MMP): fully graded at
    k = 11, mean 0.069-0.086 % and max 1.1-1.6 %; short of the grading at k = 13 and 15, 0.065-0.11 %
    and 4.0-4.5 %. ``cache``: a dict kept between calls (the answer per ``k``)."""
    cache = {} if cache is None else cache
    got = cache.setdefault('graded_k', {})
    if k in got:
        return got[k]
    F = np.asarray(F, np.int64)
    ue, inv, amin, full = full_grading(V, F, lengths, edges)
    need = grade_extra(full, inv)
    out = k
    if need > grading_room(len(F), len(ue), k):
        fit = graded_fit(len(F), len(ue), need, k - 2)
        if fit is not None:
            short = (edge_grading(V, F, ue, inv, grading_room(len(F), len(ue), k), amin)[inv]
                     < full[inv]).any(1)
            A = _areas(V, F, lengths)
            if A[short].sum() >= SHORT_AREA * A.sum():
                out = fit
    got[k] = out
    return out


# The mollification ``path_triangulation`` gives the zero-area triangles with three distinct vertices
# left after coincident vertices are merged (relative to the mean edge; 0 on a mesh without them).
PATH_MOLLIFY = 1e-9


def path_triangulation(V, F, cache=None):
    """The triangles the surface paths search instead of ``F`` (m,3) (vertices ``V`` (n,3)):
    ``(F' (m',3), lengths (m',3), root, edges)``, the intrinsic Delaunay triangulation of the same
    surface (edge flips, no mollification: the same metric to round-off) with its side lengths opposite
    each corner, its edges (``intrinsic_edges``: flips may join two vertices twice) and ``root`` (n,)
    the vertex that stands for each vertex or None (``coincident_roots``:
    vertices at one point, joined by edges of zero length, are merged first, and ``PATH_MOLLIFY``
    mollifies the zero-area triangles left); or None, to search ``F`` itself. The intrinsic one is
    taken where ``F``'s thin triangles would add more than ``GRADE_EXTRA`` to the graphs' links when
    fully graded (``edge_grading``), and it needs less. On a CAD-like closed mesh (the convex hull of
    random points on a rounded cylinder, 12k triangles, 80 % of the area in corners below 10 degrees)
    the extrinsic graphs at k = 9 were 87 % off on the mean against exact MMP; the intrinsic ones
    0.063 % (docs/geodesic.md, "Intrinsic paths"). Flipping keeps the vertices, so distances at them
    need no mapping beyond ``root``. ``cache``: a dict kept between calls."""
    cache = {} if cache is None else cache
    if 'triangulation' in cache:
        return cache['triangulation']
    from ..errors import ConformalError
    from ..mesh.intrinsic import intrinsic_delaunay
    from ..mesh.repair import oriented_faces
    from ..mesh.validate import degenerate_faces
    out = None
    _, inv, _, full = full_grading(V, F)
    need = grade_extra(full, inv)
    if need > GRADE_EXTRA:
        # coincident vertices (edges of zero length) are merged first: flipping around them gave
        # 0.3-1.4 % mean errors on a marching-cubes part under estimates of 0.1 %
        from ..mesh.repair import coincident_roots
        root = coincident_roots(V, F)
        Fw = F
        if root is not None:
            from ..mesh.topology import repeated_vertex
            Fw = root[F]
            Fw = Fw[~repeated_vertex(Fw)]
        try:
            # flips need one winding; a distance does not depend on it (triangles wound the wrong way
            # are turned, as sphere mode and the planar solver turn them)
            T = intrinsic_delaunay(V, oriented_faces(V, Fw), mollify_delta=PATH_MOLLIFY if
                                   degenerate_faces(V, Fw).any() else 0.0)
        except ConformalError:              # not a manifold the flips can walk: the mesh's own triangles
            T = None
        lengths = None if T is None else T.l
        if T is not None and (T.report['flips'] or root is not None) and np.isfinite(lengths).all():
            edges = intrinsic_edges(T)
            _, inv2, _, full2 = full_grading(V, T.F, lengths, edges)
            if grade_extra(full2, inv2) < need:
                out = (T.F, lengths, root, edges)
    cache['triangulation'] = out
    return out


def thin_warning(short, where=""):
    """The warning (str) for surface paths whose thin triangles the budget left short of their graded
    points (``short``: (area fraction, count), ``SurfacePaths.short``), or None under ``SHORT_AREA``
    and ``SHORT_FACES``. Measured: a closed 2 x 1 x 0.05 box of 19200 triangles (40:1 slivers on its
    sides, 12 % of the area) gave 0.25-0.37 % mean and 24 % max against an estimate of 0.07 %."""
    area, count = short if short else (0.0, 0)
    if area < SHORT_AREA or count < SHORT_FACES:
        return None
    return (f"{count} thin triangles{where} ({100 * area:.2g}% of the area, corners below "
            f"{np.degrees(GRADE_ANGLE):.0f} degrees) get fewer Steiner points than they need within the "
            "memory budget: distances across them may be off by more than the estimate (several "
            "percent near them); remesh those triangles into better shapes")


def surface_paths(V, F, sources, k, X=None, faces=None, target=None, k_max=PATH_K_MAX, cache=None,
                  fit_grading=True):
    """Geodesic distances on the whole surface of ``F`` (m,3) (vertices ``V`` (n,3), mesh units) to the
    nearest of the source vertices ``sources`` (s,) and the surface points ``X`` (p,3) in the
    triangles ``faces`` (p,): shortest paths through ``k`` (odd) Steiner points per edge,
    Richardson-extrapolated (``SurfacePaths``). With a ``target`` (mean relative error) that the
    estimate exceeds, or where the plain paths' relative excess at a vertex beyond two mean edges of
    the sources exceeds ``PATH_WORST`` (a bound on the worst error), once more with the ``k`` (odd, at
    most ``k_max``, within ``PATH_BUDGET``) that the excess's fall as ``k^-STEINER_ORDER`` predicts for
    0.8 of the target (and of ``PATH_WORST``; both guards, it and ``coarse_k``'s spacing, loosen with a
    target above ``PATH_TARGET``); the refined answer is kept only if its estimate is not above the
    first one's. Vertex sources search the intrinsic Delaunay triangulation where the
    mesh's triangles are thin (``path_triangulation``; its graphs kept in ``cache['intrinsic']``).
    ``fit_grading``: start from ``graded_k(k)`` instead of ``k``, and refine
    a fully graded graph only as far as its full grading fits (off: ``k`` as given). ``cache``: a dict
    kept by the caller between searches of the same ``V``, ``F``: it keeps the graphs of every ``k``
    used (built once, then each search is two Dijkstra runs), the mean edge and the edge count, the
    ``graded_k`` answers, and ``short`` of the graph last used
    (``SurfacePaths.short``, for ``thin_warning``). Returns ``(dist (n,) float64, inf
    off F and where no path reaches; estimate; k used)``: ``estimate`` is the mean relative excess of
    the plain ``k``-point paths over the vertices beyond one mean edge of the sources (the correction
    Richardson subtracts) over ``extrapolation_gain(k)``: the estimated mean relative error of ``dist``
    (docs/geodesic.md, "Sphere mode")."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    src = None if sources is None or not len(np.atleast_1d(sources)) else \
        np.unique(np.atleast_1d(np.asarray(sources, np.int64)))
    if X is not None and not len(X):
        X = faces = None
    top = cache = {} if cache is None else cache
    if 'edge' not in cache:
        cache['edge'] = float(np.linalg.norm(V[F] - V[np.roll(F, 1, axis=1)], axis=2).mean())
    edge = cache['edge']
    lengths = edges = None
    if X is None:
        # vertex sources: on a mesh of thin triangles, the paths search its intrinsic Delaunay
        # triangulation (the same surface, other edges), with a cache of its own
        tri = path_triangulation(V, F, cache)
        if tri is not None:
            F, lengths, root, edges = tri
            cache = cache.setdefault('intrinsic', {})
            if root is not None:
                src = np.unique(root[src])
    try:
        out = _surface_paths(V, F, lengths, edges, src, k, X, faces, target, k_max, cache, fit_grading, edge)
    finally:
        top['short'] = cache.get('short', (0.0, 0))
    if lengths is not None and root is not None:      # merged vertices: their group's distance
        out = (out[0][root],) + tuple(out[1:])
    return out


def _surface_paths(V, F, lengths, edges, src, k, X, faces, target, k_max, cache, fit_grading, edge):
    """``surface_paths`` on the triangles ``F`` (m,3) with side ``lengths`` (m,3) and ``edges``
    (``intrinsic_edges``), or None (``V``'s, ``mesh_edges``)."""
    graphs = cache.setdefault('graphs', {})
    if fit_grading:
        k = graded_k(V, F, k, cache, lengths, edges)
    first = None
    while True:
        pair = graphs.get(k)
        if pair is None:
            pair = graphs[k] = SurfacePaths(V, F, k, graded=True, lengths=lengths, edges=edges)
        dv, _, ev = pair.distances(src, X, faces)
        far = np.isfinite(dv) & (dv > edge)
        rel = ev[far] / (dv[far] + ev[far])
        estimate = float(np.mean(rel)) / extrapolation_gain(k, lengths is not None) if far.any() else 0.0
        worst = float(rel[dv[far] > 2 * edge].max(initial=0.0))
        if first is not None and first[1] < estimate:
            # the refined graph did worse: its thin triangles got fewer graded points within the
            # budget than the first graph's (a scan's steep rim of needles). Keep the first answer.
            cache['short'] = graphs[first[2]].short
            return first
        cache['short'] = pair.short
        loose = 1.0 if target is None else _loosen(target)
        k_min = coarse_k(V, F, lengths, dv[far], cache, PATH_SPACING * loose ** (1.0 / STEINER_ORDER)) \
            if target is not None and far.any() else 0
        if target is None or (estimate <= target and worst <= PATH_WORST * loose and k >= k_min):
            return dv, estimate, k
        want = max(k * max(estimate / (0.8 * target), worst / (0.8 * PATH_WORST * loose))
                   ** (1.0 / STEINER_ORDER), k_min)
        if 'n_edges' not in cache:
            cache['n_edges'] = len(pair.fine.ue)
        k_hi = min(int(np.ceil(want)) | 1, k_max)
        if fit_grading and pair.short[1] == 0:
            # a graph whose thin triangles all got their graded points stays so: more points per edge
            # with fewer on the needles gave worse maxima (a scan's steep flank: 1.1 % at k = 11 fully
            # graded, 4.2 % at k = 13 and 15 short of them)
            k_hi = graded_fit(len(F), cache['n_edges'], pair.grade_need, k_hi, k + 2) or k
        k_new = path_points(len(F), cache['n_edges'], k_min=k + 2, k_max=k_hi)
        if k_new is None:
            return dv, estimate, k
        first = (dv, estimate, k)
        k, target = k_new, None
