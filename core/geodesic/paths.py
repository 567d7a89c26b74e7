"""Shortest paths on a triangle mesh's surface through Steiner points on its edges (docs/geodesic.md,
"Refined seed" and "Sphere mode"): the graph joins every pair of points on the boundary of each
triangle by the straight segment inside it, so every graph path is a path on the surface (an upper
bound of the geodesic distance, exact as the points per edge ``k`` grow), and Richardson's
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


class SteinerGraph:
    """The shortest-path graph on the surface of the triangles ``F`` (m,3) (vertices ``V`` (n,3)) through
    ``k`` Steiner points on every edge (the graph of the module's docstring), built once and searched
    from any sources (``search``).

    Attributes: ``k``; ``n`` vertices; ``P`` (N,3) the graph points (the n vertices first); ``own``
    (m, 3 + 3k) the points on each triangle's boundary; ``ue`` (e,2) the edges, sorted; ``pid`` (e,k)
    the indices of their points; ``G`` the links both ways as a (N+1, N+1) CSR matrix (mesh units) over
    the points numbered by ``rank`` (N,), whose last row is a virtual source that ``search`` joins to
    surface points (its ``SPARE`` slots are rewritten per search). ``search`` takes and returns points
    in the order of ``P``."""

    SPARE = 256   # link slots of the virtual source (a point in a triangle needs 3 + 3k of them)

    def __init__(self, V, F, k=STEINER):
        import scipy.sparse as sp
        V = np.asarray(V, np.float64)
        F = np.asarray(F, np.int64)
        n, m = len(V), len(F)
        self.k, self.n = k, n
        Ed = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), 1)
        ue, inv = np.unique(Ed, axis=0, return_inverse=True)
        inv = inv.reshape(3, m).T                                            # (m,3) edge of each side
        t = np.arange(1, k + 1) / (k + 1)
        P = V[ue[:, 0]][:, None] * (1 - t)[None, :, None] + V[ue[:, 1]][:, None] * t[None, :, None]
        pts = np.concatenate([V, P.reshape(-1, 3)])
        pid = n + np.arange(len(ue) * k).reshape(len(ue), k)
        own = np.concatenate([F, pid[inv].reshape(m, 3 * k)], 1)              # (m, 3 + 3k)
        # segments inside each triangle between points on two different sides (each such pair belongs to
        # one triangle only), plus the chain of consecutive points along every edge (once per edge): no
        # pair appears twice, and the memory is (m (3k+3)^2 / 2) index pairs at most
        side = np.r_[[0b101, 0b011, 0b110], np.repeat([0b001, 0b010, 0b100], k)]      # sides of each slot
        ia, ib = np.triu_indices(own.shape[1], 1)
        cross = (side[ia] & side[ib]) == 0
        ia, ib = ia[cross], ib[cross]
        chain = np.concatenate([ue[:, :1], pid, ue[:, 1:]], 1)                         # (e, k+2)
        a = np.r_[own[:, ia].ravel(), chain[:, :-1].ravel()]
        b = np.r_[own[:, ib].ravel(), chain[:, 1:].ravel()]
        N = len(pts)
        w = np.maximum(np.linalg.norm(pts[a] - pts[b], axis=1), 1e-300)      # csgraph drops explicit zeros
        # the graph numbers its points along a Morton (Z-order) curve of their positions, so that the
        # rows Dijkstra relaxes one after another lie close in memory (spot, k = 9: 64 -> 54 ms a search
        # of this graph);
        # ``rank`` (N,) is each point's number in the graph
        self.rank = rank = morton_rank(pts)
        a, b = rank[a], rank[b]
        G = sp.coo_matrix((np.r_[w, w], (np.r_[a, b], np.r_[b, a])), shape=(N, N)).tocsr()
        # the virtual source's row, appended by hand (a COO matrix would sum its repeated self-links)
        self.G = sp.csr_matrix((np.r_[G.data, np.ones(self.SPARE)],
                                np.r_[G.indices, np.full(self.SPARE, N, G.indices.dtype)],
                                np.r_[G.indptr, G.indptr[-1] + self.SPARE]), shape=(N + 1, N + 1))
        self.P, self.own, self.ue, self.pid, self.N = pts, own, ue, pid, N

    def search(self, src=None, X=None, src_faces=None):
        """(N,) shortest path lengths from source vertices ``src`` (an index or (s,) indices: the distance
        to the nearest) and/or surface points: one point ``X`` (3,) in the triangles ``src_faces`` (its
        star), or points ``X`` (p,3) each in its triangle ``src_faces`` (p,)."""
        from scipy.sparse.csgraph import dijkstra
        N, rank = self.N, self.rank
        sv = None if src is None else np.unique(np.atleast_1d(src)).astype(np.int64)
        if X is None or src_faces is None:                    # vertex sources only (X ignored)
            return dijkstra(self.G, directed=True, indices=rank[sv], min_only=True)[rank]
        # the virtual source joined to the source vertices (length 0: 1e-300, as csgraph drops zeros)
        # and to every point on the boundary of each source point's triangle(s) (the straight segment)
        X = np.asarray(X, np.float64)
        if X.ndim == 1:
            cand = np.unique(self.own[np.asarray(src_faces)].ravel())
            wx = np.linalg.norm(self.P[cand] - X, axis=1)
        else:
            cand = self.own[np.asarray(src_faces)]                                 # (p, 3 + 3k)
            wx = np.linalg.norm(self.P[cand] - X[:, None], axis=2).ravel()
            cand = cand.ravel()
        if sv is not None:
            cand, wx = np.r_[cand, sv], np.r_[wx, np.zeros(len(sv))]
        wx = np.maximum(wx, 1e-300)
        cand = rank[cand]
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
    (``distances``). The coarse graph's points are the vertices and fine points 1, 3, ... (0-based) of
    every edge, in the same edge order (both from np.unique of the same sorted edges)."""

    def __init__(self, V, F, k):
        if k < 3 or k % 2 == 0:
            raise ValueError(f"Richardson's extrapolation needs an odd k >= 3, got {k}")
        self.k = k
        self.fine = SteinerGraph(V, F, k)
        self.coarse = SteinerGraph(V, F, (k - 1) // 2)
        n = self.fine.n
        fine_at = np.full(self.coarse.N, -1, np.int64)
        fine_at[:n] = np.arange(n)
        fine_at[self.coarse.pid.ravel()] = self.fine.pid[:, 1::2].ravel()
        self.fine_at = fine_at
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
        fine_at = self.fine_at
        ok = np.isfinite(dC) & np.isfinite(dS[fine_at])
        corr = np.zeros(len(dS))
        corr[fine_at[ok]] = (dC[ok] - dS[fine_at[ok]]) / (2.0 ** STEINER_ORDER - 1.0)
        # fine points 0, 2, ..., k-1 of each edge: the mean of their two neighbours (vertex or shared point)
        chain = np.concatenate([fine.ue[:, :1], fine.pid, fine.ue[:, 1:]], 1)            # (e, k+2)
        corr[chain[:, 1:-1:2]] = 0.5 * (corr[chain[:, 0:-2:2]] + corr[chain[:, 2::2]])
        dS = dS - np.maximum(corr, 0.0)
        dv = np.full(n, np.inf)
        ev = np.zeros(n)
        dv[self.used] = dS[self.used]
        ev[self.used] = np.maximum(corr[self.used], 0.0)
        return dv, dS, ev


def steiner_distances(V, F, src=None, X=None, src_faces=None, k=STEINER, extrapolate=False, excess=False):
    """Shortest paths on the surface of the triangles ``F`` (m,3) (vertices ``V`` (n,3)) from source
    vertices ``src`` (an index or (s,) indices: the distance to the nearest) and/or surface points
    ``X`` in ``src_faces`` (as ``SteinerGraph.search``), through ``k`` Steiner points on
    every edge: a graph joining every pair of points (vertices and Steiner points) on the boundary of
    each triangle by the straight segment inside it. Each graph path is a path on the surface, so the
    distances are upper bounds of the geodesic ones, and tend to them as ``k`` grows (docs/geodesic.md,
    "Refined seed"). ``extrapolate`` (``k`` odd): Richardson's extrapolation from the graph of
    ``(k - 1) / 2`` points per edge too (``SurfacePaths``: no longer an upper bound). The graphs are
    built for this one search: keep a ``SurfacePaths`` to search one mesh many times.
    Returns ``(dv (n,) at the vertices, inf off F; dS (p,) at every graph point; P (p,3) the points;
    own (m, 3 + 3k) the points on each triangle's boundary)``, and with ``excess`` (and
    ``extrapolate``) also ``ev`` (n,): the estimated excess of the ``k``-point paths over the geodesic
    at the vertices (the correction subtracted; 0 off F)."""
    n = len(V)
    if extrapolate and k >= 3 and k % 2 == 1:
        pair = SurfacePaths(V, F, k)
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
        return dv, dS, graph.P, graph.own, ev
    return dv, dS, graph.P, graph.own


# The extrapolated distances' mean error measured 3.3-4.5x below the plain k-point paths' excess (the
# Richardson correction) on spot and cheburashka at k = 9 (three sources each), 4.9x on spot at k = 15
# (k = 3 still gives 0.37-0.42 % mean there, against the heat method's 1.6-1.8 %):
# ``surface_paths`` divides the excess by this to estimate the error it returns (slightly cautious).
# Not at k = 3: its coarse graph has one point per edge, too few for the extrapolation to gain (the
# extrapolated error equals the excess there: 0.94-0.96x on spot and cheburashka, three sources each,
# where k = 5 to 13 gain 2.7-3.3x); ``extrapolation_gain`` says which applies.
EXTRAPOLATION_GAIN = 2.5
PATH_K = (9, 7, 5, 3)       # Steiner points per edge that ``surface_paths`` tries, best first (odd)
PATH_K_MAX = 31            # the most Steiner points per edge ``surface_paths`` refines to for its target
PATH_BUDGET = 12_000_000  # graph links (point pairs, both graphs) ``surface_paths`` may build; ~1 GB peak
# ``surface_paths`` also refines when the plain paths' excess at some vertex beyond two mean edges of
# the sources is above this (relative): on sliver triangles (a thin box's sides, 1:7) k = 9 met the
# mean target (0.07 %) with one vertex 2.4 % off (excess 3.9 %); elsewhere the worst excess is
# 0.2-1.7 % (spot, cow, cheburashka, box, cylinder, torus) and the worst error 0.6-1.1x it
PATH_WORST = 0.015


def extrapolation_gain(k):
    """How much closer the extrapolated paths at ``k`` points per edge are than the plain ones (the
    divisor of the excess in the error estimate)."""
    return 1.0 if k <= 3 else EXTRAPOLATION_GAIN


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


def surface_paths(V, F, sources, k, X=None, faces=None, target=None, k_max=PATH_K_MAX, cache=None):
    """Geodesic distances on the whole surface of ``F`` (m,3) (vertices ``V`` (n,3), mesh units) to the
    nearest of the source vertices ``sources`` (s,) and the surface points ``X`` (p,3) in the
    triangles ``faces`` (p,): shortest paths through ``k`` (odd) Steiner points per edge,
    Richardson-extrapolated (``SurfacePaths``). With a ``target`` (mean relative error) that the
    estimate exceeds, or where the plain paths' relative excess at a vertex beyond two mean edges of
    the sources exceeds ``PATH_WORST`` (a bound on the worst error), once more with the ``k`` (odd, at
    most ``k_max``, within ``PATH_BUDGET``) that the excess's fall as ``k^-STEINER_ORDER`` predicts for
    0.8 of the target (and of ``PATH_WORST``). ``cache``: a dict kept by the caller between searches
    of the same ``V``, ``F``: it keeps the graphs of every ``k`` used (built once, then each search
    is two Dijkstra runs), the mean edge and the edge count. Returns ``(dist (n,) float64, inf
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
    cache = {} if cache is None else cache
    if 'edge' not in cache:
        cache['edge'] = float(np.linalg.norm(V[F] - V[np.roll(F, 1, axis=1)], axis=2).mean())
    edge = cache['edge']
    graphs = cache.setdefault('graphs', {})
    while True:
        pair = graphs.get(k)
        if pair is None:
            pair = graphs[k] = SurfacePaths(V, F, k)
        dv, _, ev = pair.distances(src, X, faces)
        far = np.isfinite(dv) & (dv > edge)
        rel = ev[far] / (dv[far] + ev[far])
        estimate = float(np.mean(rel)) / extrapolation_gain(k) if far.any() else 0.0
        worst = float(rel[dv[far] > 2 * edge].max(initial=0.0))
        if target is None or (estimate <= target and worst <= PATH_WORST):
            return dv, estimate, k
        want = k * max(estimate / (0.8 * target), worst / (0.8 * PATH_WORST)) ** (1.0 / STEINER_ORDER)
        if 'n_edges' not in cache:
            from ..mesh.topology import unique_edges
            cache['n_edges'] = len(unique_edges(F)[0])
        k_new = path_points(len(F), cache['n_edges'], k_min=k + 2, k_max=min(int(np.ceil(want)) | 1, k_max))
        if k_new is None:
            return dv, estimate, k
        k, target = k_new, None
