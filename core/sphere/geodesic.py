"""Geodesic distances on a closed genus-0 mesh (docs/math.md, "Sphere mode"; docs/geodesic.md, "Sphere
mode"): shortest surface paths (``core.geodesic.paths``) where they fit their memory budget, else fast
marching on two overlapping stereographic charts of its conformal sphere map.
"""
import time

import numpy as np

from ..errors import ConformalError
from ..mesh.geometry import edge_graph, face_areas
from ..geodesic.paths import PATH_K, PATH_K_MAX, STEINER_ORDER, path_points, surface_paths, thin_warning
from ..geodesic.solver import ERROR_TARGET, PATH_ERROR_9, error_estimate, mu_spread, typical_distance
from ..mesh.topology import unique_edges
from ..mesh.validate import check_mesh
from .map import _repaired, sphere_map

# --- geodesic distances through the sphere ----------------------------------------------------------
# Two stereographic charts, each a regular grid: N (w = (x + i y) / (1 + z), the north pole at 0) and
# S (w' = (x - i y) / (1 - z) = 1 / w, the south pole at 0), each over the disk |w| <= R, so that they
# overlap in the band of latitudes -beta..beta (R = tan((90 + beta) / 2 degrees)). A surface length
# element is ds = |dw| / speed with speed = mu_S (1 + |w|^2) / 2, mu_S the sphere length per surface
# length. Fast marching runs in buckets of time: a path that crosses the whole overlap band needs at
# least W = (R - 1/R) / (largest speed in the band), so within a bucket [tau, tau + W] every optimal
# path segment lies in one chart; both charts march from the contour T = tau, the results are
# exchanged through the overlap (bilinear sampling), and the nodes up to tau + W are final.
GEO_OVERLAP_DEG = 25.0
GEO_METHODS = ('auto', 'charts', 'paths')
UNRESOLVED_MAX = 0.01    # 'auto' takes the surface paths above this unresolved area fraction


class _Chart:
    """One stereographic chart as a ``core.geodesic.Grid`` over [-R, R]^2 with the speed field."""

    def __init__(self, which, S, F, logmu_v, R, nodes):
        from ..geodesic.solver import Grid
        self.which = which
        self.R = R
        w = self.coords_of(S)
        keep = (np.abs(w[F]) <= 2.0 * R).all(1)
        box = np.array([[-R, -R], [R, R]])
        self.G = G = Grid(box, nodes, pad=1)
        uv = np.stack([w.real, w.imag], 1)
        G.rasterise(uv, F[keep])
        ny, nx = G.shape
        jj, ii = np.meshgrid(np.arange(nx), np.arange(ny))
        self.w = (G.origin[0] + jj * G.h) + 1j * (G.origin[1] + ii * G.h)
        self.valid = G.inside & (np.abs(self.w) <= R)
        lm = G.interpolate(uv, F[keep], logmu_v)
        lm = np.where(self.valid, lm, 0.0)
        self.speed = np.where(self.valid, np.exp(lm) * 0.5 * (1.0 + np.abs(self.w) ** 2), 1.0)
        self.h = G.h

    def coords_of(self, X):
        """Chart coordinates (k,) complex of unit vectors X (k,3)."""
        if self.which == 'N':
            with np.errstate(divide='ignore', invalid='ignore'):
                return (X[:, 0] + 1j * X[:, 1]) / (1.0 + X[:, 2])
        with np.errstate(divide='ignore', invalid='ignore'):
            return (X[:, 0] - 1j * X[:, 1]) / (1.0 - X[:, 2])

    def node_coords(self, w):
        """Continuous node coordinates (k,2) (column, row) of chart points w (k,) complex."""
        return self.G.coords(np.stack([w.real, w.imag], 1))

    def sample(self, T, w):
        from ..geodesic.solver import bilinear
        return bilinear(np.where(self.valid, T, np.nan), self.node_coords(w), self.valid)


def _seed(chart, ws, radius):
    """Exact local times (ny, nx) (inf elsewhere) around the sources at chart points ``ws`` (k,),
    within ``radius`` + 3 cells: chart distance times the Simpson mean of 1/speed, and the time
    ``tau`` up to which the seed disks are complete."""
    from ..geodesic.solver import bilinear
    G = chart.G
    ny, nx = G.shape
    P = chart.node_coords(ws)
    w = int(np.ceil(radius)) + 3
    off = np.arange(-w, w + 1)
    oi, oj = np.meshgrid(off, off, indexing='ij')
    ci = np.rint(P[:, 1]).astype(np.int64)[:, None] + oi.ravel()[None]
    cj = np.rint(P[:, 0]).astype(np.int64)[:, None] + oj.ravel()[None]
    src = np.repeat(np.arange(len(P)), oi.size)
    ci, cj = ci.ravel(), cj.ravel()
    ok = (ci >= 0) & (ci < ny) & (cj >= 0) & (cj < nx)
    ci, cj, src = ci[ok], cj[ok], src[ok]
    ok = chart.valid[ci, cj]
    ci, cj, src = ci[ok], cj[ok], src[ok]
    if not len(ci):
        return np.full(G.shape, np.inf), np.inf
    Q = np.stack([cj, ci], 1).astype(np.float64)
    inv = 1.0 / chart.speed
    f = (bilinear(inv, P[src], chart.valid) + 4.0 * bilinear(inv, 0.5 * (P[src] + Q), chart.valid)
         + bilinear(inv, Q, chart.valid)) / 6.0
    T = np.full(G.shape, np.inf)
    np.minimum.at(T, (ci, cj), np.linalg.norm(Q - P[src], axis=1) * G.h * f)
    tau = radius * G.h / float(chart.speed[ci, cj].max())
    return T, tau


def _march(phi, chart, solver, T0=None, narrow=0.0):
    """Travel time (ny, nx) from the zero contour of ``phi`` in ``chart`` (inf where not reached).
    With scikit-fmm the march stops ``narrow`` beyond the contour (0: no limit); otherwise
    ``core.geodesic.solver.eikonal_march`` runs (the numpy sweep holds ``T0``'s finite nodes fixed and
    returns full
    times). Returns (T, solver used)."""
    from ..geodesic.solver import eikonal_march as march
    mask = ~chart.valid
    if solver in ('auto', 'skfmm'):
        try:
            import skfmm
        except ImportError:
            skfmm = None
        if skfmm is not None:
            T = skfmm.travel_time(np.ma.MaskedArray(phi, mask), np.where(mask, 1.0, chart.speed),
                                  dx=chart.h, order=2, narrow=narrow)
            T = np.ma.filled(np.ma.MaskedArray(T), np.inf).astype(np.float64)
            T[mask] = np.inf
            return T, 'skfmm'
    if T0 is None:
        T0 = np.where(phi < 0, 0.0, np.inf)
    return march(T0, phi < 0, phi, chart.speed, mask, chart.h, solver)


def _chart_resolution(V, F, S, charts):
    """How well the ``charts`` resolve the mesh (V (n,3), F (m,3)): ``(unresolved, cell)``, the area
    fraction whose surface cell (the chart's cell over its speed there, in the chart where the
    triangle's centroid is more interior) is above twice the triangle's mean edge (docs/geodesic.md,
    "Sphere mode"), and the area-weighted mean surface cell (mesh units) over the other triangles."""
    cen = S[F].mean(1)
    cen /= np.linalg.norm(cen, axis=1)[:, None]
    edge = np.linalg.norm(V[F] - V[np.roll(F, 1, axis=1)], axis=2).mean(1)
    cell = np.empty(len(F))
    ok = np.isfinite(cen).all(1)
    cell[~ok] = np.nan
    for c, sel in zip(charts, (ok & (cen[:, 2] >= 0), ok & (cen[:, 2] < 0))):
        sp_c = c.sample(c.speed, c.coords_of(cen[sel]))
        cell[sel] = c.h / np.where(np.isfinite(sp_c) & (sp_c > 0), sp_c, np.nan)
    A = face_areas(V, F)
    good = cell <= 2.0 * edge
    unresolved = float(A[~good].sum() / A.sum())
    mean_cell = float((A[good] * cell[good]).sum() / A[good].sum()) if good.any() else float('nan')
    return unresolved, mean_cell


def _march_charts(charts, S, src, logmu_v, R, solver, source_radius, flips):
    """Distances (n,) at the vertices by fast marching on the two ``charts`` in buckets of time (the
    module's comment), from the source vertices ``src`` (s,) at sphere points ``S[src]``; ``logmu_v``
    (n,) the per-vertex log sphere scale, ``R`` the charts' radius, ``flips`` the sphere map's folds
    (named in the error if the front stops). Returns ``(dist, solver used, buckets, bucket width)``."""
    from ..geodesic.solver import calibrate_phi
    other = [charts[1], charts[0]]
    # node positions of each chart in the other chart's coordinates (the band only)
    for c, o in zip(charts, other):
        wo = np.where(c.valid, 1.0 / np.where(c.w == 0, 1.0, c.w), np.inf)
        c.band = c.valid & (np.abs(wo) <= R * (1.0 - 2.0 * o.h / R))
        c.band_w = wo[c.band]
    # bucket width W: the shortest time to cross the overlap band. Measured by one march in chart N
    # from the disk |w| <= 1/R to the circle |w| = R (the band is the same set in chart S, and a
    # crossing reversed is a crossing), less two cells for the interpolation between the charts.
    cN = charts[0]
    phi = np.where(cN.valid, (np.abs(cN.w) - 1.0 / R), 1.0)
    Tb = _march(phi, cN, solver)[0]
    rim = cN.valid & (np.abs(cN.w) >= R - 1.5 * cN.h)
    vmax = max(float(c.speed[c.valid].max()) for c in charts)
    W = float(np.min(Tb[rim])) - 2.0 * max(c.h for c in charts) / vmax
    if not W > 0:
        raise ConformalError("the overlap band of the two charts is too thin for this grid: "
                             "increase the grid size or the overlap")
    # seeds: each source in every chart its seed window reaches (the window is clipped to the
    # chart), so that both charts know the first contour wherever it lies in their domain
    xs = S[src]
    T, tau = [], np.inf
    for c in charts:
        ws = c.coords_of(xs)
        with np.errstate(invalid='ignore'):
            inside = np.abs(ws) <= R + (source_radius + 4) * c.h
        if inside.any():
            Tc, tc = _seed(c, ws[inside], source_radius)
            tau = min(tau, tc)
        else:
            Tc = np.full(c.G.shape, np.inf)
        T.append(Tc)
    # nodes of the seed windows beyond tau keep their exact local times: they place the contour
    used = None
    buckets = 0
    while True:
        buckets += 1
        new = []
        for c, Tc in zip(charts, T):
            known = np.isfinite(Tc) & (Tc <= tau) & c.valid
            if not known.any():
                new.append(np.full(c.G.shape, np.inf))
                continue
            far = 4.0 * c.h
            phi = np.where(np.isfinite(Tc), (Tc - tau) * c.speed, far)
            phi = np.where(c.valid, np.minimum(phi, far), far)
            phi = calibrate_phi(phi, c.valid, c.h)
            if not (phi[c.valid] < 0).any() or not (phi[c.valid] > 0).any():
                new.append(Tc.copy())
                continue
            Tm, used = _march(phi, c, solver, T0=np.where(known, Tc, np.inf))
            Tn = np.where(known, Tc, np.fmin(Tc, (Tm + tau) if used == 'skfmm' else Tm))
            Tn[~c.valid] = np.inf
            new.append(Tn)
        # exchange through the overlap
        for k, (c, o) in enumerate(zip(charts, other)):
            Ti = o.sample(new[1 - k], c.band_w)
            Tb = new[k][c.band]
            new[k][c.band] = np.fmin(Tb, np.where(np.isfinite(Ti), Ti, np.inf))
        T = new
        tau = tau + W
        left = sum(int((c.valid & ~(T[k] <= tau)).sum()) for k, c in enumerate(charts))
        if left == 0 or buckets > 10000:
            break
        # the next contour must exist: jump over empty buckets
        lo = min(float(np.min(np.where(c.valid & (T[k] > tau - W), T[k], np.inf)))
                 for k, c in enumerate(charts))
        if not np.isfinite(lo):
            why = (f" (the sphere map folds {flips} triangles: cut the mesh along seams and use the planar "
                   "solver)" if flips else "")
            raise ConformalError("the fast marching front stopped before covering the sphere: "
                                 "increase the grid size" + why)
    # sample at the vertices from the chart where each is more interior
    dist = np.empty(len(S))
    north = S[:, 2] >= 0
    for c, sel in zip(charts, (north, ~north)):
        dist[sel] = c.sample(T[charts.index(c)], c.coords_of(S[sel]))
    # the sources themselves and their neighbourhoods: exact local times (chart N or S)
    for c, sel in zip(charts, (north, ~north)):
        near = sel.copy()
        if not near.any():
            continue
        ws = c.coords_of(xs)
        here = np.abs(ws) <= R
        if not here.any():
            continue
        ws, s_here = ws[here], src[here]
        wv = c.coords_of(S[near])
        from scipy.spatial import cKDTree
        d, j = cKDTree(np.stack([ws.real, ws.imag], 1)).query(np.stack([wv.real, wv.imag], 1))
        close = d <= source_radius * c.h
        if close.any():
            idx = np.nonzero(near)[0][close]
            sp_v = np.exp(logmu_v[idx]) * 0.5 * (1 + np.abs(wv[close]) ** 2)
            sp_s = np.exp(logmu_v[s_here[j[close]]]) * 0.5 * (1 + np.abs(ws[j[close]]) ** 2)
            local = d[close] * 0.5 * (1.0 / sp_v + 1.0 / sp_s)
            dist[idx] = np.fmin(dist[idx], local)
    return dist, used, buckets, W


def default_sphere_grid(n_vertices):
    """Nodes per side of each chart's grid: about 4 per sqrt(vertex), rounded up to a multiple of 64,
    clipped to 256..768."""
    return int(np.clip(64 * np.ceil(4.0 * np.sqrt(n_vertices) / 64), 256, 768))


def _mesh_cache(cache, V, F):
    """The dict of the surface paths' graphs for the mesh ``V`` (n,3), ``F`` (m,3): ``cache`` itself
    (emptied first if it held another mesh's, told apart by a hash of both arrays), or a new dict."""
    if cache is None:
        return {}
    import hashlib
    key = hashlib.blake2b(np.ascontiguousarray(V).tobytes() + np.ascontiguousarray(F).tobytes(),
                          digest_size=16).hexdigest()
    if cache.get('mesh') != key:
        cache.clear()
        cache['mesh'] = key
    return cache


def _on_repaired(fixed, root, V, src, S, **options):
    """``sphere_geodesic`` of the input mesh (vertices ``V`` (n,3)) answered on its repaired copy
    ``fixed`` (``core.mesh.repair.Repaired``; ``root`` (n,) or None, the vertices merged into others):
    every wedge of a source vertex (of its root's, for a merged one) is a source, an input vertex takes
    the nearest of its wedges' distances (its root's; inf for a loose vertex, in no face), ``S`` (n,3)
    in the input's numbering is carried over, and ``report['repairs']`` lists the repairs."""
    n = len(V)
    at = np.arange(n) if root is None else root              # the input vertex that stands for each
    loose = np.setdiff1d(at[src], fixed.vert_map)
    if len(loose):
        raise ConformalError(f"source vertex {int(loose[0])} is in no face (a loose vertex): choose a "
                             "vertex of the surface")
    wedges = np.flatnonzero(np.isin(fixed.vert_map, at[src]))
    S2 = None if S is None else np.asarray(S, np.float64)[fixed.vert_map]
    d2, report = sphere_geodesic(fixed.V, fixed.F, wedges, S=S2, **options)
    d = np.full(n, np.inf)
    np.minimum.at(d, fixed.vert_map, d2)
    report['repairs'] = list(fixed.repairs) + report.get('repairs', [])
    return d[at], report


# 'auto' answers by the paths when they get at least this many Steiner points per edge (graded): on a
# smooth closed mesh of 120k triangles (random points on a lumpy sphere) the paths fitted k = 5, and
# their thin triangles' grading brought them to k = 3: 0.37 % mean against the charts' 0.034 %. The
# paths' k = 5 gives 0.11-0.19 % on spot and cheburashka, k = 7 about 0.07 %.
SPHERE_PATH_K = 7


def _paths_points(V, F, k, cache):
    """The Steiner points per edge the surface paths would build on ``F`` (m,3) from ``k``
    (``path_points``): ``graded_k`` on the triangulation they would search (``path_triangulation``),
    with ``cache`` the dict ``surface_paths`` is then given."""
    from ..geodesic.paths import graded_k, path_triangulation
    tri = path_triangulation(V, F, cache)
    if tri is None:
        return graded_k(V, F, k, cache)
    return graded_k(V, tri[0], k, cache.setdefault('intrinsic', {}), tri[1], tri[3])


def sphere_geodesic(V, F, sources, S=None, moebius='uniform', grid=None, solver='auto',
                    overlap=GEO_OVERLAP_DEG, source_radius=8.0, progress=None, method='auto', cache=None):
    """Geodesic distances on a closed genus-0 mesh: shortest surface paths whenever they fit their
    memory budget, else fast marching through its conformal sphere (``method``, below).

    V (n,3), F (m,3); ``sources`` vertex indices (k,) (the result is the distance to the nearest).
    ``S`` (n,3): a sphere map to reuse (from ``sphere_map``); None computes one with ``moebius`` if
    the charts are needed (the mesh is checked as ``sphere_map`` checks it either way).
    ``grid``: nodes per side of each chart (None: ``default_sphere_grid``). ``solver``: as
    ``core.geodesic.solver.eikonal_march`` ('auto', 'skfmm', 'sweep'). ``overlap``: half-width of the
    band the two
    charts share, in degrees of latitude. ``source_radius``: exact seed disk radius, in cells.
    Every distance is clamped between the 3D distance to the nearest source and the shortest edge path
    (``report['clamped']`` counts them). Returns ``(dist (n,) float64 in mesh units, report dict)``; the
    report's ``warnings`` (list of str) name a folded sphere map, an area fraction above 1 % that the
    charts do not resolve (``unresolved_fraction``: surface cell above twice the triangle's mean edge),
    and more than 1 % of the vertices clamped.

    ``cache``: an optional dict the caller keeps between calls (a repeated query, Blender's repeated
    clicks): the surface paths' graphs and grading are kept in it and reused while ``V`` and ``F`` are
    the same (it is emptied for another mesh), so a new source costs the searches only.

    ``method``: 'charts' marches on the two charts; 'paths' takes shortest paths on the mesh through
    Steiner points, Richardson-extrapolated (``core.geodesic.paths.surface_paths``); 'auto' (default)
    takes the paths wherever they fit the memory budget with at least ``SPHERE_PATH_K`` points per
    edge once their thin triangles are graded (``_paths_points``), and with fewer where the charts do
    not resolve the surface (the sphere map folds a triangle, or more than ``UNRESOLVED_MAX`` of the
    area is unresolved) or where the paths' expected error at the points they get (``PATH_ERROR_9``
    times ``(9 / k)^STEINER_ORDER``) is below the charts' estimate; otherwise it marches. Why:
    measured against exact distances, the paths are 4-15x more accurate than the march even where
    the charts resolve the surface (the blobs of bench/sphere.py: 0.026-0.032 % against 0.12-0.41 %
    mean, max 0.25 % against 1.1-3.8 %) at 2-3x its time, and where they do not the march fails
    (spot, cheburashka: docs/geodesic.md, "Sphere mode"); the paths' error estimate is their own, the
    march's the planar solver's model (cruder, 1-5x cautious where the charts resolve the surface).
    Why the whole mesh and not a patch of the unresolved region: a geodesic may cross that
    region and come back, so the march cannot be mended locally. ``report['method']`` says which
    ran; ``report['error_estimate']`` (mean relative) is the paths' estimate or the march's;
    ``unresolved_fraction``, ``grid`` and ``sphere`` (the map's measures) are None or absent when the
    charts were not built."""
    from ..mesh.measures import vertex_mu
    say = progress or (lambda f, msg: None)
    t0 = time.perf_counter()
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n = len(V)
    src = np.atleast_1d(np.asarray(sources))
    if src.size == 0:
        raise ConformalError("no source given: pass at least one source vertex")
    if not np.issubdtype(src.dtype, np.integer) or src.min() < 0 or src.max() >= n:
        raise ConformalError(f"source vertices must be indices in 0..{n - 1}")
    # a distance does not depend on a triangle's winding: faces wound the wrong way are turned; a
    # messy mesh is answered on its repaired copy, as ``sphere_map`` maps it (``_repaired``)
    F, fixed, root = _repaired(V, F)
    if fixed is not None:
        return _on_repaired(fixed, root, V, src, S, moebius=moebius, grid=grid, solver=solver,
                            overlap=overlap, source_radius=source_radius, progress=progress, method=method,
                            cache=cache)
    if method not in GEO_METHODS:
        raise ConformalError(f"method must be one of {', '.join(GEO_METHODS)}, got {method!r}")
    if not 5.0 <= overlap <= 60.0:
        raise ConformalError("overlap must be between 5 and 60 degrees")
    report = {}
    k = path_points(len(F), len(unique_edges(F)[0]))
    kept = _mesh_cache(cache, V, F)            # the paths' graphs and grading, if they answer
    k_graded = _paths_points(V, F, k, kept) if method == 'auto' and k is not None else None
    direct = method == 'paths' or (k_graded is not None and k_graded >= SPHERE_PATH_K)
    if S is None and direct:
        # the paths need no sphere map: only the input check that mapping would make
        check_mesh(V, F, kind='sphere', allow_degenerate=True)
    elif S is None:
        say(0.0, 'mapping to the sphere')
        res = sphere_map(V, F, moebius=moebius)
        S = res.S
        report['sphere'] = {k: res.report[k] for k in ('moebius', 'mu_ratio', 'qc_mean', 'flips')}
    if S is not None:
        S = np.asarray(S, np.float64)
        S = S / np.linalg.norm(S, axis=1)[:, None]
        if S.shape != V.shape:
            raise ConformalError(f"S must have shape {V.shape}, got {S.shape}")
    unresolved = flips = charts = None
    if not direct:
        if grid is None:
            grid = default_sphere_grid(n)
        # sphere length per surface length, per triangle (unnormalised) and per vertex
        P = S[F]
        a_s = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
        area = face_areas(V, F)
        mu_f = np.sqrt(np.maximum(a_s, np.finfo(float).tiny) / area)
        logmu_v = np.log(vertex_mu(F, mu_f, area, n))
        R = float(np.tan(np.radians(45.0 + 0.5 * overlap)))
        say(0.2, 'rasterising the charts')
        charts = [_Chart('N', S, F, logmu_v, R, grid), _Chart('S', S, F, logmu_v, R, grid)]
        # how well the charts resolve the surface, and which method answers (see the docstring)
        unresolved, mean_cell = _chart_resolution(V, F, S, charts)
        if 'sphere' in report:
            flips = int(report['sphere']['flips'] or 0)
        else:
            from .map import _count_flips
            flips = int(_count_flips(F, S))
        # the paths with the points the budget leaves them, where their expected error is below the
        # charts' estimate (a marching-cubes surface of 33k triangles: paths at 5 points 0.13 % mean
        # against the charts' 0.26 %, estimates 0.21 % and 0.27 %)
        paths_expected = PATH_ERROR_9 * (PATH_K[0] / k_graded) ** STEINER_ORDER if k_graded else np.inf
        chart_expected = error_estimate(mean_cell, typical_distance(V), mu_spread(F, mu_f, area), 0.0,
                                        unresolved, 0.0, 0)
        direct = method == 'auto' and k is not None and (flips > 0 or unresolved > UNRESOLVED_MAX
                                                         or paths_expected < chart_expected)
    thin = None
    if direct:
        say(0.3, 'shortest surface paths')
        t = time.perf_counter()
        dist, estimate, k = surface_paths(V, F, src, k or PATH_K[-1], target=ERROR_TARGET, cache=kept)
        thin = thin_warning(kept.get('short'))
        used, buckets, W, chosen = None, 0, None, 'paths'
    else:
        say(0.3, 'marching')
        t = time.perf_counter()
        dist, used, buckets, W = _march_charts(charts, S, src, logmu_v, R, solver, source_radius, flips)
        # the planar solver's model (``error_estimate``) with the charts' cell and the spread of the
        # per-vertex mu they march with; the unresolved area counts as on-mesh. Against exact MMP
        # (source 7): the blobs of bench/sphere.py 0.42-1.06 % for 0.12-0.31 %, a random closed
        # triangulation of 10k triangles 0.35 % for 0.29 %, spot 1.42 % for 1.42 % (cheburashka
        # 1.14 % for 6.9 %: 40 % of it unresolved, which warns on its own)
        fin = np.isfinite(dist)
        estimate = error_estimate(mean_cell, float(np.median(dist[fin])) if fin.any() else 1.0,
                                  mu_spread(F, mu_f, area), 0.0, unresolved, 0.0, 0)
        chosen, k = 'charts', None
    seconds_march = time.perf_counter() - t
    dist[src] = 0.0
    if not np.isfinite(dist).all():
        bad = int((~np.isfinite(dist)).sum())
        raise ConformalError(f"{bad} vertices were not reached by the front: increase the grid size")
    # exact bounds: the 3D distance to the nearest source below, the shortest edge path above
    from scipy.sparse.csgraph import dijkstra
    from scipy.spatial import cKDTree
    E3, _ = cKDTree(V[src]).query(V)
    upper = dijkstra(edge_graph(V, F, n), indices=np.unique(src), min_only=True)
    dist_raw = dist
    low, high = dist < E3, dist > upper
    clamped = {'below_euclid': int(low.sum()), 'above_edges': int(high.sum())}
    dist = np.clip(dist, E3, np.maximum(upper, E3))
    warnings = []
    if chosen == 'charts':
        if estimate > ERROR_TARGET:
            warnings.append(f"the sphere march's error estimate is {100 * estimate:.2g}% (target "
                            f"{100 * ERROR_TARGET:.2g}%): use method='paths' if memory allows, or cut the "
                            "mesh along seams and use the planar solver")
        if flips:
            warnings.append(f"the sphere map folds {flips} triangles: distances through them are unreliable; "
                            "use method='paths', or cut the mesh along seams and use the planar solver")
        if unresolved > UNRESOLVED_MAX:
            warnings.append(f"the sphere charts do not resolve {100 * unresolved:.2g}% of the surface (grid "
                            "cells larger than twice the triangles, where the sphere map shrinks the "
                            "surface): expect errors of several percent there; use method='paths' or a "
                            "larger grid, or cut the mesh along seams and use the planar solver")
    elif estimate > ERROR_TARGET:
        why = ("the mesh is too large for more Steiner points per edge in the memory budget"
               if k < PATH_K_MAX else f"even {k} Steiner points per edge are too few for this mesh")
        warnings.append(f"the surface paths' error estimate is {100 * estimate:.2g}% (target "
                        f"{100 * ERROR_TARGET:.2g}%): {why}")
    if thin:
        warnings.append(thin)
    # an edge path is the geodesic where the geodesic runs along edges (chains of them on an
    # icosphere's great circles): a good march passes it there by its local error (0.1-0.2 % within a
    # few edges of the source on icosphere(10), 1.2 % of the vertices). As for the paths below, only a
    # clamp from above by more than ten times the error target counts.
    nv = int(clamped['below_euclid'] + (dist_raw - upper > 10.0 * ERROR_TARGET * upper).sum())
    if chosen == 'paths':
        # the extrapolated paths are no upper bound: where the geodesic is nearly straight they fall
        # a little below the 3D distance (the blobs: 1.5 % of the vertices; a capped CAD cylinder: 2.4 %
        # by 0.1-0.5 %, at 0.07 % mean error and 0.86 % max); only a clamp by more than ten times the
        # error target says something is wrong (a thin box before the graded points: 5 % max error)
        off = 10.0 * ERROR_TARGET
        nv = int(((E3 - dist_raw > off * E3) | (dist_raw - upper > off * upper)).sum())
    if nv > 0.01 * n:
        what = 'the sphere march is' if chosen == 'charts' else 'the surface paths are'
        warnings.append(f"{nv} vertices ({100 * nv / n:.2g}%) fell outside the exact bounds (3D distance, "
                        f"edge paths) and were clamped: {what} inaccurate on this mesh")
    report.update({'method': chosen, 'steiner_points': k, 'error_estimate': estimate,
                   'error_target': ERROR_TARGET,
                   'grid': list(charts[0].G.shape) if charts else None,
                   'cell': [c.h for c in charts] if charts else None, 'charts': 2 if charts else 0,
                   'overlap_deg': overlap, 'buckets': buckets, 'bucket_width': W, 'solver': used,
                   'sources': int(src.size), 'clamped': clamped, 'unresolved_fraction': unresolved,
                   'warnings': warnings,
                   'seconds': {'march': round(seconds_march, 4),
                               'total': round(time.perf_counter() - t0, 4)}})
    return dist, report
