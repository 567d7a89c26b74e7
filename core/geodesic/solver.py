"""Geodesic distance on a surface by weighted fast marching on its conformal plane (docs/math.md,
"Geodesic distance on the conformal plane"; the method and its measured accuracy: docs/geodesic.md).

A conformal map scales lengths by ``mu`` (UV units per surface unit) and keeps angles, so a surface length
element is ``ds = |dx_uv| / mu`` and the geodesic distance ``T`` solves the eikonal equation
``|grad_uv T| = 1 / mu`` on the flat UV domain: a travel time with speed ``mu`` on a regular grid.

``GeodesicSolver(V, F, ...)`` does the per-mesh work once and keeps it; ``distance(sources)`` answers
any number of source sets from it. ``geodesic_distance`` is its one-shot wrapper.

Set-up (``GeodesicSolver``):

1. Charts. A single connected part without seams is flattened as one disk (``core.disk.flatten``);
   several parts, or ``seams`` (cuts), go through ``core.atlas.islands.unwrap`` (one flattening per
   island, unpacked, true scale). A given ``uv`` is split into its connected parts. Distances are
   measured on the cut surface: infinite between islands.
2. Per chart, which answers: a flat island, shortest paths in its plane (``core.geodesic.planar``,
   ``PlanarChart``: exact, no grid); else the grid, or shortest surface paths through Steiner points
   (``core.geodesic.paths.surface_paths``) where they cost at most about half the grid's query time
   at the grid size its error target asks for (``paths_choice``: small, coarse islands whose map
   varies a lot). The rest of this list is the grid's.
   Per chart: rotate the map to its smallest bounding rectangle (``align_uv``), take the realised
   per-triangle ``mu = sqrt(A_uv / A_3d)`` (``face_mu``) and the per-vertex ``mu``
   (``core.mesh.measures.vertex_mu``), choose the grid size for the error target (``choose_grid``),
   rasterise ``mu`` with linear interpolation onto the grid (``Grid``); nodes outside the domain are
   masked, except a one-node rim with extrapolated ``mu`` so that boundary vertices can be sampled.
3. The error estimate of every chart (``error_estimate``) from its local resolution, the grid cell
   in surface units ``h / mu``, the non-convexity of its domain and the mesh's own floor.

A query (``GeodesicSolver.distance``):

4. Seed each source with exact times in a disk of ``SEED_RADIUS`` cells (smaller where ``mu`` varies
   fast, ``seed_radius``): the flat-chart time ``|x - s| * mean(1/mu)`` along the straight UV segment,
   bounded by the 3D Euclidean distance below and the edge-path bound above, and equal to the 3D
   distance in the triangles around the source (exact there: the geodesic is a straight segment in
   the triangle). ``calibrate_phi`` sets the level-set values on the seed's rim so that scikit-fmm's
   first front values are exact (no point-source offset, scikit-fmm issue #22).
   A seed node takes the chart time only if the straight UV segment stays in the domain (``_visible``).
5. March with scikit-fmm ``travel_time(order=2)`` or, without scikit-fmm, the numpy fast sweeping
   solver of ``core.geodesic.eikonal``, without the rim nodes that bridge gaps of the domain
   (``bridging_rim``, ``boundary_bridges``: links that cross the boundary twice far apart along it;
   they get extrapolated times, ``extrapolate_rim``). Sources whose ``mu`` differ
   by more than a factor 2 march separately and the minimum is taken. With ``mu_mode='metric'`` (the
   default) the march is repeated with the exact metric of the map: the map is affine on each
   triangle, so the surface length of a UV step ``du`` is ``sqrt(du^T G du)`` with one constant
   ``G`` (2x2) per triangle (``face_metric_inverse``); for the gradient direction ``g`` of the
   previous march the anisotropic eikonal equals the isotropic one with speed
   ``sqrt(g^T G^-1 g)`` (``directional_mu``). This removes the mesh's floor (the smooth per-vertex
   ``mu`` against the per-triangle, slightly anisotropic metric): the error then falls with the grid.
   On a grid the user gives, the direction ``g`` is fitted per triangle to one unfolded source where
   its nodes' times allow (``core.geodesic.directions.point_source_mu``); elsewhere it is taken from
   the neighbours' differences.
6. Sample the travel time back to the vertices bilinearly, then clamp each vertex between two exact
   bounds: the 3D distance to the nearest source (below) and the shortest edge path (Dijkstra, above).
"""
import time

import numpy as np

from ..errors import ConformalError
from ..mesh.geometry import cross, edge_graph, face_areas
from ..mesh.measures import signed_uv_areas, vertex_mu
from ..mesh.topology import twin_halfedges
from .directions import point_source_mu
from .planar import plane_coordinates, planar_paths
from ..atlas.unfold import unfold_flat_disk
from .paths import (PATH_BUDGET, PATH_ERROR_9, PATH_K, PATH_K_MAX, STEINER, STEINER_ORDER, SteinerGraph,
                    mesh_edges, path_points, path_triangulation, richardson_excess, start_k, target_k,
                    thin_warning, steiner_distances, surface_paths)

SOLVERS = ('auto', 'skfmm', 'sweep')
METHODS = ('auto', 'grid', 'paths')
PATH_COST = 2.0      # 'auto': surface paths where their links are at most this many per grid node update
# ... and at an error target looser than the default (``target_k`` below 9 points), where both meet it:
# the paths where they are about as fast as the march. A query of bump at n = 65: the k = 3 pair's 419k
# links in 31 ms (74 ns a link), its grid of 143k nodes in 66 ms with one march (460 ns a node, the
# seed and the sampling included)
PATH_COST_LOOSE = 6.0
CUT_PATH_BUDGET = 3_000_000  # links for a part the flattening cut (suzanne's face: k = 29, 2.8M links)
MU_MODES = ('metric', 'vertex', 'face')
GRID_MIN, GRID_MAX = 64, 4096
GRID_AUTO_MIN = 256          # the automatic grid never goes below this (nodes along the longer side)
GRID_AUTO_MAX = 4096         # nor above this; a warning says when the error target needs more
GRID_NODES_PER_EDGE = 6.0    # nor below this many nodes per mean UV edge (8 before the nineteenth round)
ERROR_TARGET = 1e-3          # default target for the estimated mean relative error (0.1 %)
RIM = 1
# SEED_RADIUS: the default radius of the exact seed disk around a source, in grid cells (one meaning
# everywhere in core.geodesic). The sweep's second-order stencil is less accurate on strongly curved
# fronts than fast marching's, so it starts from a larger disk, SWEEP_SEED_RADIUS (docs/geodesic.md).
SEED_RADIUS = 24.0
SEED_MIN_CELLS = 3.0  # the seed's radius is never below this many cells (``seed_radius``)
HIDDEN_MIN_CELLS = 10.0  # nor its level below this many for hidden nodes (``hidden_seed_level``)
UNRESOLVED = 2.0     # a triangle whose surface cell h / mu exceeds this times its mean edge is not resolved
METRIC_PASSES = 2    # mu_mode 'metric': marches with the exact metric after the isotropic first one
DIRECTION_NODES = 1024  # the re-marches take gradient directions at most this fine (nodes along a side)
SWEEP_SEED_RADIUS = 36.0
# Refined seed (docs/geodesic.md, "Refined seed"): where the chart's cell at a source is coarse in
# surface units (fewer than FINE_NODES nodes per edge of the source's triangles), the seed comes from
# shortest paths on the mesh through Steiner points, over the triangles within FINE_WINDOW cells (UV
# radius) of the source, at most FINE_MAX_FACES of them (the nearest).
FINE_NODES = 4.0
SEED_NODES = 512      # ... counted as on a grid of at most this many nodes along the longer side
FINE_WINDOW = 48.0
FINE_MAX_FACES = 3000
FINE_ANISO = 1.1      # or where a triangle at the source has a metric anisotropy sqrt(l_max / l_min) above
# this (1.15 before the twenty-first round: a lifted hemisphere's rim source at 1.13-1.15 took the plain
# seed and came out 0.19 % short everywhere; 0.04 % with the refined one)
# On a grid the user gives, the refined seed's paths take this many Steiner points per edge (STEINER on an
# automatic grid): their error (as k^-STEINER_ORDER) is a floor under the grid's, and at STEINER it held
# a lifted hemisphere's rim sources at 0.03-0.055 % mean from 512 to 1024 (one rising); at 31 they fall,
# 0.017-0.019 -> 0.015-0.017 % (docs/geodesic.md, "Thirty-ninth session"). At most FINE_MAX_FACES
# triangles: about 11M links for the two graphs, within the paths' memory budget. On a given grid finer
# than FINE_GIVEN_NODES the points grow as the square root of its size over the same window, its links as
# the points squared (``fine_seed_paths``: at 4096 the grid's own arrays still set most of the peak)
FINE_STEINER_GIVEN = 31
FINE_GIVEN_NODES = 1024
# On a grid the user gives, every source takes the refined seed (not on a similarity chart, whose straight
# segments are exact): the plain seed's deficit is an offset that does not fall with the grid (a voxel
# figure's far source at a given 2048 / 4096: 0.031 / 0.042 % mean plain, 0.015 / 0.020 % refined;
# docs/geodesic.md, "Forty-second session")
FINE_GIVEN_ALL = True
FINE_BAND = 8.0      # cells (at the node's own mu) inside tau where grid nodes take every Steiner path
FINE_EDGES = 16.0     # the window reaches at least this many mean 3D edges of the source's triangles
# Spots (docs/geodesic.md, "Spots"): triangles whose surface cell h / mu exceeds SPOT_CELL times their mean
# edge, or whose metric anisotropy exceeds SPOT_ANISO. The vertices of their triangles and of the
# triangles next to them take shortest paths through SPOT_STEINER points per edge over the triangles
# within SPOT_RINGS rings, from the grid times of the nodes in the outermost ring (and from the sources
# inside); when the window would hold more than SPOT_MAX_FACES triangles, only the worst spots.
SPOT_CELL = 0.5
SPOT_ANISO = 2.0
SPOT_RINGS = 2
SPOT_STEINER = 15
SPOT_MAX_FACES = 2000
# On a grid the user gives, a spot is a triangle whose surface cell exceeds ``spot_cell_given`` of its
# mean edge (SPOT_CELL_GIVEN up to SPOT_GIVEN_NODES nodes a side: four nodes an edge, so that the
# window's outer ring, where its paths start from the grid, is resolved; on finer grids, where the
# metric jumps by more than SPOT_JUMP in log to a neighbour (``mu_jump``), the spots of that size, see
# ``spot_cell_given``), the window takes every spot up to SPOT_MAX_FACES_GIVEN triangles,
# and its paths are extrapolated from the graph of (SPOT_STEINER - 1) / 2 points too (Richardson, as
# ``SurfacePaths``): the two graphs hold about 920 links a triangle (``path_links``), so 18M at most,
# within the paths' memory budget (PATH_BUDGET). Under-resolved triangles then take the paths' accuracy,
# not the on-mesh march's first order, and the error falls with the grid (docs/geodesic.md,
# "Thirty-eighth session" and "Forty-fourth session")
SPOT_CELL_GIVEN = 0.25
SPOT_GIVEN_NODES = 512
SPOT_JUMP = 0.02
SPOT_MAX_FACES_GIVEN = 20_000
# ... and round its deep spots, whose surface cell exceeds SPOT_DEEP_CELL of their mean edge, the window
# reaches SPOT_RINGS_DEEP rings (the repaired vertices stay those of the spots' triangles and their
# neighbours): the paths there start from grid nodes where the grid resolves the surface, not from the
# marginal cells next to a deep spot, whose times came out low (docs/geodesic.md, "Forty-third session")
SPOT_DEEP_CELL = 1.0
SPOT_RINGS_DEEP = 8


# --------------------------------------------------------------------------------------------------
# conformal factor of a given map
def face_mu(V: np.ndarray, F: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Per-triangle scale ``mu_T = sqrt(A_uv / A_3d)`` (m,) of the map ``uv`` (n,2): UV units per
    surface unit, with no normalisation (so it is consistent with the UV coordinates as given).
    Raises ConformalError if a triangle is degenerate or flipped relative to the majority."""
    a = signed_uv_areas(uv, F)
    A = face_areas(V, F)
    sign = np.sign(np.median(a))
    bad = (a * sign <= 0) | (A <= 0)
    if bad.any():
        raise ConformalError(f"the UV map has {int(bad.sum())} flipped or degenerate triangles: "
                             "geodesic distances need a fold-free map (flatten again, or use "
                             "boundary 'area' or 'uniform')", 'degenerate', 'area_boundary')
    return np.sqrt(np.abs(a) / A)


def face_metric_inverse(V: np.ndarray, F: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """The inverse of each triangle's pulled-back metric, (m,3) as ``(a, b, c)`` of the symmetric 2x2
    ``G^-1 = [[a, b], [b, c]]`` (UV units squared per surface unit squared).

    The map ``uv`` (n,2) is affine on each triangle of ``F`` (m,3), so a UV displacement ``du`` has the
    surface length ``sqrt(du^T G du)`` with a constant ``G = J^T J`` per triangle (``J`` (3,2) the
    differential of the inverse map, UV to 3D). The surface eikonal ``|grad_X T| = 1`` becomes
    ``grad_uv T^T G^-1 grad_uv T = 1`` (docs/math.md, "Geodesic distance on the conformal plane"); for an
    exactly conformal triangle ``G^-1 = mu^2 I``. With ``E3`` (3,2) the 3D edge vectors and ``E2`` (2,2)
    the UV ones, ``G^-1 = E2 (E3^T E3)^-1 E2^T``. A triangle of (nearly) zero area, such as a cap
    whose corners a Boolean left in a line, gets a huge, finite metric."""
    X = V[F]
    U = uv[F]
    e1, e2 = X[:, 1] - X[:, 0], X[:, 2] - X[:, 0]
    g11, g12, g22 = (e1 * e1).sum(1), (e1 * e2).sum(1), (e2 * e2).sum(1)
    # det(E3^T E3) = |e1 x e2|^2: never negative, and without the cancellation of g11 g22 - g12^2
    det = np.maximum((cross(e1, e2) ** 2).sum(1), 1e-24 * g11 * g22 + np.finfo(float).tiny)
    i11, i12, i22 = g22 / det, -g12 / det, g11 / det                  # (E3^T E3)^-1
    p = U[:, 1] - U[:, 0]                                              # E2 columns
    q = U[:, 2] - U[:, 0]
    # E2 K E2^T with E2 = [p q] (columns): sum_kl E2[:,k] K_kl E2[:,l]
    a = i11 * p[:, 0] ** 2 + 2 * i12 * p[:, 0] * q[:, 0] + i22 * q[:, 0] ** 2
    b = i11 * p[:, 0] * p[:, 1] + i12 * (p[:, 0] * q[:, 1] + q[:, 0] * p[:, 1]) + i22 * q[:, 0] * q[:, 1]
    c = i11 * p[:, 1] ** 2 + 2 * i12 * p[:, 1] * q[:, 1] + i22 * q[:, 1] ** 2
    return np.stack([a, b, c], 1)


def metric_anisotropy(ginv: np.ndarray) -> np.ndarray:
    """How far each triangle's pulled-back metric is from conformal: ``sqrt(l_max / l_min)`` (m,) of the
    eigenvalues of ``G^-1`` (``face_metric_inverse``, (m,3) as ``(a, b, c)``), the ratio of the longest
    to the shortest surface length of a unit UV step. 1 for an exactly conformal triangle."""
    a, b, c = ginv.T
    half, dev = (a + c) / 2, np.sqrt(((a - c) / 2) ** 2 + b * b)
    return np.sqrt((half + dev) / np.maximum(half - dev, 1e-300 * half))


def fine_seed_paths(size: int, given: bool) -> tuple[int, float, int]:
    """The refined seed's Steiner points per edge, its window's reach in mean 3D edges and its most
    triangles, ``(k, edges, faces)``, on a chart's grid of ``size`` nodes along the longer side
    (``given``: the user's). An automatic grid: ``(STEINER, FINE_EDGES, FINE_MAX_FACES)``. A given one:
    ``FINE_STEINER_GIVEN`` points up to ``FINE_GIVEN_NODES`` nodes, then as the square root of the size
    (odd: 45 at 2048, 63 at 4096), so that the paths' error (as ``k^-STEINER_ORDER``, carried outward
    from the window as an offset) keeps falling under the grid's, over the same window at every size
    (``FINE_EDGES``, ``FINE_MAX_FACES``). Measured, mean % at a given 2048 / 4096 (docs/geodesic.md,
    "Forty-second session"): edgebump's curvature source 0.0014 / 0.0009 % with this window, 0.0033 /
    0.0099 % when its reach fell as ``k^-1/2`` (the grid then took over inside the bump, where its
    re-marches undershoot); a lifted hemisphere's curvature source 0.0141 / 0.0097 against 0.0161 /
    0.0113. At 4096 the grid's own arrays dominate the memory either way."""
    if not given:
        return STEINER, FINE_EDGES, FINE_MAX_FACES
    k = FINE_STEINER_GIVEN
    if size > FINE_GIVEN_NODES:
        k = 2 * int(np.ceil((FINE_STEINER_GIVEN * np.sqrt(size / FINE_GIVEN_NODES) - 1) / 2)) + 1
    return k, FINE_EDGES, FINE_MAX_FACES


def spot_cell_given(size: int) -> float:
    """The surface cell, in mean edges of a triangle, above which a triangle whose metric jumps to a
    neighbour (``mu_jump`` above ``SPOT_JUMP``) is a spot on a grid the user gives of ``size`` nodes
    along the longer side: ``SPOT_CELL_GIVEN`` up to ``SPOT_GIVEN_NODES``, then ``SPOT_CELL_GIVEN *
    SPOT_GIVEN_NODES / size``, so that every finer grid keeps the spots of a grid of
    ``SPOT_GIVEN_NODES`` (the triangles it resolves at under four nodes an edge) and refines only the
    triangles the grid already serves. Elsewhere a spot stays a cell above ``SPOT_CELL_GIVEN``.

    Why: the grid's error grows along a path at a rate of about ``c / p`` in a triangle that ``p``
    nodes an edge resolve, first order, from the jumps of the piecewise constant metric at the
    triangles' edges (measured on a hand scan, log mu jumping by 0.05 a triangle, far source, given
    2048: -0.06 % at 4-8 nodes, -0.03 % at 8-16, -0.007 % above 16), while the windows' paths stay
    near +0.005 %. On a map whose conformal factor spans many octaves each band of ``p`` holds about
    the same area at every size, so with a threshold fixed in nodes an edge a finer grid handed
    triangles from the paths to the grid's worst band, and the error did not fall (the hand: 0.0111 /
    0.0152 / 0.0163 / 0.0140 % at 512-4096). Where the metric hardly jumps (a flat mesh: none) the
    grid is the better answer at a few nodes an edge, and the paths' error would not fall with it
    (docs/geodesic.md, "Forty-fourth session")."""
    return SPOT_CELL_GIVEN * min(1.0, SPOT_GIVEN_NODES / max(float(size), 1.0))


def metric_excess(aniso: np.ndarray, area: np.ndarray) -> float:
    """The ``area``-weighted (m,) mean of ``metric_anisotropy - 1`` (m,), each capped at ``ANISO_CAP``:
    the part of the metric that the directional-speed re-marches do not follow (dimensionless; 0 for
    a conformal map)."""
    return float((area * (np.minimum(aniso, ANISO_CAP) - 1.0)).sum() / area.sum())


def directional_mu(T, valid, face, ginv, step=1, fit=None):
    """The speed (ny, nx) that makes the isotropic eikonal ``|grad T| = 1 / mu`` agree with the
    anisotropic one ``grad T^T G^-1 grad T = 1`` for the gradient direction ``g`` of a travel-time
    field ``T`` (ny, nx): ``mu = sqrt(g^T G^-1 g)``, ``G^-1`` (m,3) per triangle (``face_metric_inverse``)
    at each node's triangle ``face`` (ny, nx). The gradient is a central difference where both
    neighbours are finite and ``valid``, else one-sided; nodes with no usable neighbour on either axis
    get the isotropic ``sqrt(sqrt(det G^-1))``. NaN-free; 1 at unused nodes.

    ``step`` (cells): the neighbours are ``step`` nodes away (where they lie in the node's triangle;
    elsewhere the one-node gradient is used). The re-marches are a fixed-point iteration whose gain on a
    direction error grows as its wavelength shrinks (measured: on a fine grid the passes diverge on
    anisotropic triangles); a difference over ``step`` nodes keeps the directions at the resolution of
    a coarser grid (``DIRECTION_NODES``), where the passes settle.

    ``fit``: ``(metric, h)``, each triangle's ``G`` (m,3) and the grid spacing (UV units): where a
    triangle's times fit one unfolded point source (``core.geodesic.directions.point_source_mu``), its
    nodes take the fit's directions instead of the differences (the differences' noise left the
    passes' fixed point below the true times, more so the finer the grid: docs/geodesic.md,
    "Forty-first session")."""
    f = np.where(face >= 0, face, 0)
    a, b, cc = ginv[f, 0], ginv[f, 1], ginv[f, 2]          # each node's triangle's G^-1, once
    mu = _directional_mu(T, valid, face, (a, b, cc), 1)
    if step > 1:
        wide = _directional_mu(T, valid, face, (a, b, cc), int(step), strict=True)
        mu = np.where(np.isfinite(wide), wide, mu)
    if fit is not None:
        fitted_mu, fitted = point_source_mu(T, valid, face, ginv, *fit)
        mu = np.where(fitted, fitted_mu, mu)
    return mu


def _directional_mu(T, valid, face, node, s, strict=False):
    """``directional_mu`` with neighbours ``s`` nodes away, ``node`` the (a, b, c) of ``G^-1`` at each node
    (ny, nx each); ``strict``: only neighbours in the node's own triangle, NaN where an axis has none
    (the caller falls back to ``s = 1``)."""
    Tf = np.where(valid & np.isfinite(T), T, np.nan)          # finite or NaN from here on
    pad = np.pad(Tf, s, constant_values=np.nan)
    fpad = np.pad(face, s, constant_values=-1)
    c = pad[s:-s, s:-s]
    fc = fpad[s:-s, s:-s]

    def diff(lo, hi, flo, fhi):
        # the gradient inside the node's own triangle: neighbours in another triangle are used only
        # when neither neighbour on that axis is in it (the gradient jumps across triangle edges)
        lo_s = np.where(flo == fc, lo, np.nan)
        hi_s = np.where(fhi == fc, hi, np.nan)
        if strict:
            lo, hi = lo_s, hi_s
        else:
            none = np.isnan(lo_s) & np.isnan(hi_s)
            lo, hi = np.where(none, lo, lo_s), np.where(none, hi, hi_s)
        # central where both neighbours are there (NaN otherwise), else one-sided: the forward
        # difference where only ``hi`` is, the backward one where only ``lo`` is
        d = 0.5 * (hi - lo)
        d = np.where(np.isnan(d), hi - c, d)
        return np.where(np.isnan(d), c - lo, d)

    n2 = 2 * s
    gx = diff(pad[s:-s, :-n2], pad[s:-s, n2:], fpad[s:-s, :-n2], fpad[s:-s, n2:])
    gy = diff(pad[:-n2, s:-s], pad[n2:, s:-s], fpad[:-n2, s:-s], fpad[n2:, s:-s])
    nrm = np.hypot(gx, gy)
    a, b, cc = node
    ok = np.isfinite(nrm) & (nrm > 0)
    with np.errstate(invalid='ignore', divide='ignore'):
        x, y = gx / nrm, gy / nrm
        mu = np.sqrt(np.maximum(a * x * x + 2 * b * x * y + cc * y * y, 1e-300))
    if strict:
        return np.where(valid & (face >= 0), np.where(ok, mu, np.nan), 1.0)
    mu = np.where(ok, mu, np.sqrt(np.sqrt(np.maximum(a * cc - b * b, 1e-300))))   # isotropic fallback
    return np.where(valid & (face >= 0), mu, 1.0)


# --------------------------------------------------------------------------------------------------
# spots the grid resolves poorly: shortest paths on the mesh from the grid around them
def surface_points(V, F, uv, faces, pts):
    """3D points (k,3) of the UV points ``pts`` (k,2), each in its triangle ``faces`` (k,) of the map
    ``uv`` (n,2) of the mesh ``V`` (n,3), ``F`` (m,3): the same barycentric coordinates in 3D."""
    W = uv[F[faces]]
    A = np.stack([W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]], axis=2)
    b = np.linalg.solve(A, (pts - W[:, 0])[:, :, None])[:, :, 0]
    return V[F[faces, 0]] * (1 - b.sum(1))[:, None] + V[F[faces, 1]] * b[:, :1] + V[F[faces, 2]] * b[:, 1:]


def _grow(F, faces, rings, n):
    """(m,) bool: the triangles ``faces`` (bool (m,)) of ``F`` (m,3) and those within ``rings`` rings
    (sharing a vertex) of them; ``n`` the vertex count."""
    inw = faces.copy()
    for _ in range(rings):
        vs = np.zeros(n, bool)
        vs[F[inw].ravel()] = True
        inw |= vs[F].any(1)
    return inw


def mu_jump(F: np.ndarray, n: int, mu_face: np.ndarray) -> np.ndarray:
    """(m,) the largest ``|log mu_T - log mu_N|`` between each triangle T of ``F`` (m,3) and the
    triangles N sharing an edge with it (0 where it has none), for the per-triangle conformal factor
    ``mu_face`` (m,): the jump of the piecewise constant metric that the grid's march crosses at the
    triangle's edges (dimensionless). ``n``: the vertex count."""
    twin = twin_halfedges(F, n)
    lm = np.log(mu_face)
    h = np.flatnonzero(twin >= 0)
    J = np.zeros(len(F))
    np.maximum.at(J, h // 3, np.abs(lm[h // 3] - lm[twin[h] // 3]))
    return J


class SpotWindow:
    """Where a chart's grid is coarse against the triangles (surface cell ``h / mu`` above
    ``SPOT_CELL`` mean edges) or its metric far from conformal (anisotropy above ``SPOT_ANISO``), the
    march is off by first order in a cell over a few triangles, and the error shows at the vertices
    there (docs/geodesic.md, "Spots": a scan's spot of largest angle defect, +4.35 % at two vertices).
    There the vertices of the spot's triangles and of their neighbours (``inner``) take the shortest
    paths through ``SPOT_STEINER`` points per edge within the triangles of ``SPOT_RINGS`` rings
    (``SteinerGraph``), started from the grid times of the nodes inside the outermost ring (each node
    joined by straight segments to the points on its triangle's boundary; it lies in that flat
    triangle), from the sampled times of the ring's outer vertices (near a coarse spot the ring's
    triangles hold few nodes) and from the sources inside the window. Every path from outside to an
    inner vertex crosses that ring, so the window's values are those of the grid there plus the mesh's
    own paths, early or late.

    Where the window would hold more than ``SPOT_MAX_FACES`` triangles, it is built round the worst
    spots only (a severity threshold, the larger of cell / ``SPOT_CELL`` and anisotropy /
    ``SPOT_ANISO``, found by bisection). On a grid the user gives (``ch.given``) a spot is a cell above
    ``SPOT_CELL_GIVEN`` mean edges (``spot_cell_given(ch.size)`` where ``mu_jump`` exceeds
    ``SPOT_JUMP``), the window may hold ``SPOT_MAX_FACES_GIVEN`` triangles, and the paths are
    extrapolated from a second graph of half the points (``coarse``), so that the triangles the grid
    cannot resolve take the paths' accuracy rather than ``MeshRelax``'s first order; round a deep spot
    (a cell above ``SPOT_DEEP_CELL`` mean edges) the window reaches ``SPOT_RINGS_DEEP`` rings, so that
    its paths start where the grid resolves the surface, and the vertices a refined seed holds seed its
    paths with their values. ``ch`` a ``Chart`` (its grid
    rasterised). ``active`` False when the chart has no spot."""

    def __init__(self, ch):
        G = ch.grid
        F, n = ch.F, len(ch.V)
        cell, max_faces = (SPOT_CELL_GIVEN, SPOT_MAX_FACES_GIVEN) if ch.given else (SPOT_CELL, SPOT_MAX_FACES)
        if ch.given:                # where the metric jumps, the spots of a grid of SPOT_GIVEN_NODES
            cell = np.where(mu_jump(F, n, ch.mu_face) > SPOT_JUMP, spot_cell_given(ch.size), cell)
        surface_cell = G.h / ch.mu_face / mean_edges(ch.V, F)
        severity = surface_cell / cell
        if ch.ginv is not None:
            severity = np.maximum(severity, metric_anisotropy(ch.ginv) / SPOT_ANISO)
        deep = surface_cell > SPOT_DEEP_CELL if ch.given else None

        def window(spot, less=0):
            # the spots' triangles and SPOT_RINGS rings round them (SPOT_RINGS_DEEP round deep ones)
            win = _grow(F, spot, SPOT_RINGS - less, n)
            if deep is not None and (spot & deep).any():
                win |= _grow(F, spot & deep, SPOT_RINGS_DEEP - less, n)
            return win
        spot = severity > 1.0
        self.active = bool(spot.any())
        if not self.active:
            return
        win = window(spot)
        if win.sum() > max_faces:
            # too many: the worst spots, by a severity threshold found by bisection (in log)
            lo, hi = 0.0, float(np.log(severity.max()))
            for _ in range(12):
                mid = 0.5 * (lo + hi)
                if window(severity > np.exp(mid)).sum() > max_faces:
                    lo = mid
                else:
                    hi = mid
            spot = severity > np.exp(hi)
            win = window(spot)
            self.active = bool(spot.any())
            if not self.active:
                return
        within = window(spot, 1)                # all but the outermost ring
        outer = win & ~within
        inner = np.zeros(n, bool)
        inner[F[_grow(F, spot, 1, n)].ravel()] = True
        self.inner = np.flatnonzero(inner)
        self.faces = np.flatnonzero(win)
        self.used, Fl = np.unique(F[self.faces], return_inverse=True)
        self.inner_local = np.searchsorted(self.used, self.inner)
        # the grid nodes inside the outermost ring's triangles, their 3D points, and their links to the
        # points on their triangle's boundary
        face = np.where(G.inside & ch.march_on, G.face, -1).ravel()
        nodes = np.flatnonzero(face >= 0)
        nodes = nodes[outer[face[nodes]]]
        W = ch.uv[F[face[nodes]]]
        A = np.stack([W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]], axis=2)
        det = A[:, 0, 0] * A[:, 1, 1] - A[:, 0, 1] * A[:, 1, 0]
        nodes = nodes[np.abs(det) > 1e-12 * np.einsum('kij,kij->k', A, A)]      # no node of a UV needle
        f = face[nodes]
        ny, nx = G.shape
        X = surface_points(ch.V, F, ch.uv, f, G.origin + np.c_[nodes % nx, nodes // nx] * G.h)
        # and the vertices of the outermost ring that no inner-ring triangle holds (their sampled times)
        mid = np.zeros(n, bool)
        mid[F[within].ravel()] = True
        ring = np.zeros(n, bool)
        ring[F[outer].ravel()] = True
        self.ring = np.flatnonzero(ring & ~mid)
        self.ring_local = np.searchsorted(self.used, self.ring)
        # the graph, and on a given grid Richardson's pair (half the points, across the same flat
        # patches); the virtual source of each has room for every seed (each node is joined to the
        # 3 + 3k points on its triangle's boundary), so a search rewrites it in place
        Fw = Fl.reshape(-1, 3)

        def room(k):
            return len(nodes) * (3 + 3 * k) + len(self.ring) + ch.given * len(self.used) + SteinerGraph.SPARE
        self.graph = SteinerGraph(ch.V[self.used], Fw, SPOT_STEINER, spare=room(SPOT_STEINER))
        k_half = (SPOT_STEINER - 1) // 2
        self.coarse = SteinerGraph(ch.V[self.used], Fw, k_half, patches=self.graph.patches,
                                   spare=room(k_half)) if ch.given else None
        # per graph: the points each node is joined to, the links' lengths, and the node of each link
        self.links = [self._node_links(g, np.searchsorted(self.faces, f), X, nodes)
                      for g in (self.graph, self.coarse) if g is not None]

    @staticmethod
    def _node_links(graph, faces, X, nodes):
        """(points (q,), lengths (q,), nodes (q,)): each grid node ``nodes`` (p,), at the 3D point ``X``
        (p,3) in the window's triangle ``faces`` (p,), joined by straight segments to the points of
        ``graph`` on that triangle's boundary."""
        cand, owner = graph.boundary(faces)
        return cand, np.linalg.norm(graph.P[cand] - X[owner], axis=1), nodes[owner]

    def _search(self, graph, links, T, dist, loc, X_pts, pt_faces, held):
        """(k,) the ``graph``'s shortest paths to the window's inner vertices from its seeds (see
        ``repair``); ``links`` the graph's ``_node_links``; ``held`` (h,) local vertices seeded with their
        values in ``dist``; None when nothing seeds it."""
        cand0, length, node = links
        t = T.ravel()[node]
        ok = np.isfinite(t)
        cand, w = cand0[ok], t[ok] + length[ok]
        tv = dist[self.ring]
        okv = np.isfinite(tv)
        cand, w = np.r_[cand, self.ring_local[okv], held], np.r_[w, tv[okv], dist[self.used[held]]]
        at = np.searchsorted(self.used, loc)
        mine = (at < len(self.used)) & (self.used[np.minimum(at, len(self.used) - 1)] == loc)
        cand, w = np.r_[cand, at[mine]], np.r_[w, np.zeros(int(mine.sum()))]
        if len(pt_faces):
            lf = np.searchsorted(self.faces, pt_faces)
            inw = (lf < len(self.faces)) & (self.faces[np.minimum(lf, len(self.faces) - 1)] == pt_faces)
            if inw.any():
                c2, o2 = graph.boundary(lf[inw])
                cand = np.r_[cand, c2]
                w = np.r_[w, np.linalg.norm(graph.P[c2] - X_pts[inw][o2], axis=1)]
        if not len(cand):
            return None
        return graph.search_from(cand, w)[self.inner_local]

    def repair(self, T, dist, keep, loc, X_pts, pt_faces, bound=None):
        """Set ``dist`` (k,) at the inner vertices (not where ``keep`` (k,) is True) to the window's
        shortest paths from the grid times ``T`` (ny, nx) of the outermost ring's nodes, from the
        sampled times ``dist`` of its outer vertices, and from the sources inside the window: local
        vertices ``loc`` (a,) and surface points ``X_pts`` (b,3) in local faces ``pt_faces`` (b,). On a
        given grid (the coarse graph) the window's vertices that ``keep`` holds (a refined seed's, whose
        paths have more points than the window's) seed it with their values too, and the paths' excess
        is extrapolated away at the vertices, which both graphs share:
        ``d_k - max(0, d_(k-1)/2 - d_k) / (2^STEINER_ORDER - 1)``. ``bound`` (k,), optional: lengths of
        paths that exist (a refined seed's, where another source may be nearer: the solver's ``claim``),
        which the window's values never exceed (a lifted hemisphere's three sources at a given 1024:
        three window vertices 0.8-2.2 % high without it). Returns the number of vertices set."""
        held = np.zeros(0, np.int64)
        if self.coarse is not None:
            held = np.flatnonzero(keep[self.used] & np.isfinite(dist[self.used]))
        d = self._search(self.graph, self.links[0], T, dist, loc, X_pts, pt_faces, held)
        if d is None:
            return 0
        dc = None if self.coarse is None else self._search(self.coarse, self.links[1], T, dist, loc, X_pts,
                                                            pt_faces, held)
        if dc is not None:
            d = d - np.maximum(richardson_excess(dc, d), 0.0)
        sel = np.isfinite(d) & ~keep[self.inner]
        if bound is not None:
            d = np.fmin(d, bound[self.inner])
        dist[self.inner[sel]] = d[sel]
        return int(sel.sum())


# --------------------------------------------------------------------------------------------------
# on-mesh fast marching where the grid does not resolve the surface
class MeshRelax:
    """Fast marching on the mesh itself (planar-front triangle updates), restricted to a set of free
    vertices, relaxed in place: used where the grid's surface cell ``h / mu`` is larger than the
    triangles (docs/geodesic.md, "Under-resolved regions").

    For a triangle with corners ``C``, ``A``, ``B`` and known times ``T_A``, ``T_B``, the update of
    ``C`` is the time of the plane front through ``A`` and ``B`` with unit surface gradient: with
    the Gram matrix ``M`` of the edge vectors ``e_A = A - C``, ``e_B = B - C`` (3D, mesh units),
    ``Q = M^-1`` and ``r = (T_A, T_B)``, ``t`` is the larger root of
    ``(1^T Q 1) t^2 - 2 (1^T Q r) t + r^T Q r - 1 = 0``, accepted when the front reaches ``C`` from
    inside the triangle (both coefficients of ``Q (r - t 1)`` non-positive), else the edge updates
    ``T_A + |e_A|``, ``T_B + |e_B|``. Every (triangle, corner) update of the free vertices runs at
    once (numpy), repeated until nothing decreases: the monotone scheme's fixed point, which
    sequential fast marching reaches in one ordered pass.

    ``V`` (k,3), ``F`` (m,3) one chart's mesh; ``faces`` (q,) the triangles with a free corner."""

    def __init__(self, V, F, faces):
        self.faces = faces
        c, a, b = [], [], []
        for k in range(3):
            c.append(F[faces, k])
            a.append(F[faces, (k + 1) % 3])
            b.append(F[faces, (k + 2) % 3])
        self.c, self.a, self.b = np.concatenate(c), np.concatenate(a), np.concatenate(b)
        eA, eB = V[self.a] - V[self.c], V[self.b] - V[self.c]
        m11, m12, m22 = (eA * eA).sum(1), (eA * eB).sum(1), (eB * eB).sum(1)
        det = np.maximum(m11 * m22 - m12 * m12, 1e-300)
        self.q11, self.q12, self.q22 = m22 / det, -m12 / det, m11 / det
        self.la, self.lb = np.sqrt(m11), np.sqrt(m22)

    def relax(self, T, free, max_iter=100_000):
        """Lower ``T`` (k,) at the ``free`` (k,) bool vertices to the fixed point of the triangle
        updates (the others are boundary data); ``T`` at free vertices should start at inf. Returns
        the number of rounds."""
        q11, q12, q22 = self.q11, self.q12, self.q22
        s1 = q11 + 2 * q12 + q22                                   # 1^T Q 1
        target = free[self.c]
        c, a, b = self.c[target], self.a[target], self.b[target]
        q11, q12, q22, s1 = q11[target], q12[target], q22[target], s1[target]
        la, lb = self.la[target], self.lb[target]
        for it in range(1, max_iter + 1):
            ta, tb = T[a], T[b]
            with np.errstate(invalid='ignore', over='ignore'):
                s2 = (q11 + q12) * ta + (q12 + q22) * tb           # 1^T Q r
                s3 = q11 * ta * ta + 2 * q12 * ta * tb + q22 * tb * tb - 1.0
                disc = s2 * s2 - s1 * s3
                t = (s2 + np.sqrt(np.maximum(disc, 0.0))) / s1
                al = q11 * (ta - t) + q12 * (tb - t)
                be = q12 * (ta - t) + q22 * (tb - t)
                ok = (np.isfinite(ta) & np.isfinite(tb) & (disc >= 0) & (al <= 0) & (be <= 0)
                      & (t >= np.maximum(ta, tb)))
            cand = np.minimum(np.where(ok, t, np.inf), np.minimum(ta + la, tb + lb))
            new = T.copy()
            np.minimum.at(new, c, cand)
            changed = new < T * (1 - 1e-13) - 1e-300
            T[:] = new
            if not changed.any():
                return it
        return max_iter


# --------------------------------------------------------------------------------------------------
# grid
class Grid:
    """A regular grid of nodes over the UV bounding box, ``pad`` nodes of margin on each side.
    ``shape`` (ny, nx); node (i, j) sits at UV ``origin + (j*h, i*h)``. After ``rasterise``: ``face``
    (ny, nx) int index of the triangle containing each node, -1 outside; ``inside`` (ny, nx) bool."""

    def __init__(self, uv, grid, pad=2):
        lo, hi = uv.min(0), uv.max(0)
        ext = hi - lo
        if not np.all(ext > 0):
            raise ConformalError("the UV map is degenerate (zero extent): cannot build a grid")
        grid = int(grid)
        if grid < GRID_MIN or grid > GRID_MAX:
            raise ConformalError(f"grid size {grid} is out of range: use {GRID_MIN}..{GRID_MAX} nodes")
        self.h = float(ext.max() / (grid - 1 - 2 * pad))
        self.origin = lo - pad * self.h
        nx, ny = (np.ceil(ext / self.h - 1e-9).astype(int) + 1 + 2 * pad)
        self.shape = (int(ny), int(nx))

    def coords(self, pts):
        """Continuous node coordinates (k,2) (column, row) of UV points (k,2)."""
        return (pts - self.origin) / self.h

    def rasterise(self, uv, F):
        """Fill ``face`` and ``inside`` by scanning each triangle row by row: for every (triangle,
        grid row) pair the row's span inside the triangle is found from the three edges, and the
        nodes in the span are assigned to the triangle. Nodes on a shared edge go to either side."""
        ny, nx = self.shape
        W = self.coords(uv)[F]                                   # (m,3,2) node units
        ylo = np.ceil(W[:, :, 1].min(1) - 1e-9).astype(np.int64)
        yhi = np.floor(W[:, :, 1].max(1) + 1e-9).astype(np.int64)
        nrow = np.maximum(yhi - ylo + 1, 0)
        t = np.repeat(np.arange(len(F)), nrow)                   # (triangle, row) pairs
        row = ylo[t] + np.arange(len(t)) - np.repeat(np.cumsum(nrow) - nrow, nrow)
        y = row.astype(np.float64)
        xl = np.full(len(t), np.inf)
        xr = np.full(len(t), -np.inf)
        for a, b in ((0, 1), (1, 2), (2, 0)):
            pa, pb = W[t, a], W[t, b]
            dy = pb[:, 1] - pa[:, 1]
            lo_, hi_ = np.minimum(pa[:, 1], pb[:, 1]), np.maximum(pa[:, 1], pb[:, 1])
            hit = (y >= lo_ - 1e-9) & (y <= hi_ + 1e-9)
            with np.errstate(invalid='ignore', divide='ignore'):
                s = np.clip((y - pa[:, 1]) / dy, 0.0, 1.0)
            s = np.where(np.abs(dy) > 1e-12, s, 0.0)
            x = pa[:, 0] + s * (pb[:, 0] - pa[:, 0])
            flat = hit & (np.abs(dy) <= 1e-12)                   # horizontal edge on this row
            xl = np.where(hit, np.minimum(xl, np.where(flat, np.minimum(pa[:, 0], pb[:, 0]), x)), xl)
            xr = np.where(hit, np.maximum(xr, np.where(flat, np.maximum(pa[:, 0], pb[:, 0]), x)), xr)
        j0 = np.maximum(np.ceil(xl - 1e-9), 0).astype(np.int64)
        j1 = np.minimum(np.floor(xr + 1e-9), nx - 1).astype(np.int64)
        ok = (row >= 0) & (row < ny) & np.isfinite(xl)
        cnt = np.where(ok, np.maximum(j1 - j0 + 1, 0), 0)
        k = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        idx = np.repeat(row * nx + j0, cnt) + k
        face = np.full(ny * nx, -1, np.int32)
        face[idx] = np.repeat(t, cnt)
        self.face = face.reshape(ny, nx)
        self.inside = self.face >= 0
        return self

    def rim(self, width=1):
        """Give the outside nodes near the domain (``width`` rounds of 8-neighbour dilation) the
        triangle of a neighbour already in use, so fields extrapolate linearly there. Returns the
        boolean mask (ny, nx) of the nodes in use (inside and rim)."""
        ny, nx = self.face.shape
        for _ in range(width):
            face = self.face
            out = face.copy()
            for di in (-1, 0, 1):
                for dj in (-1, 0, 1):
                    if di == 0 and dj == 0:
                        continue
                    src = face[max(di, 0):ny + min(di, 0), max(dj, 0):nx + min(dj, 0)]
                    dst = out[max(-di, 0):ny + min(-di, 0), max(-dj, 0):nx + min(-dj, 0)]
                    take = (dst < 0) & (src >= 0)
                    dst[take] = src[take]
            self.face = out
        return self.face >= 0

    def interpolate(self, uv, F, values=None, face_values=None):
        """Grid field (ny, nx) at the nodes in use: per-vertex ``values`` (n,) interpolated linearly in
        each node's triangle (extrapolated on the rim), or per-face ``face_values`` (m,) piecewise
        constant. NaN at unused nodes."""
        out = np.full(self.shape, np.nan)
        act = self.face >= 0
        f = self.face[act]
        if face_values is not None:
            out[act] = face_values[f]
            return out
        # plane through the three vertex values of each used triangle, in node coordinates
        W = self.coords(uv)[F]
        e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
        det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        v = values[F]
        d1, d2 = v[:, 1] - v[:, 0], v[:, 2] - v[:, 0]
        gx = (d1 * e2[:, 1] - d2 * e1[:, 1]) / det
        gy = (d2 * e1[:, 0] - d1 * e2[:, 0]) / det
        c0 = v[:, 0] - gx * W[:, 0, 0] - gy * W[:, 0, 1]
        ii, jj = np.nonzero(act)
        out[ii, jj] = c0[f] + gx[f] * jj + gy[f] * ii
        return out


def align_uv(uv, used=None):
    """Rotate a UV map (n,2) to its minimum-area bounding rectangle (the rotation is a similarity,
    so distances do not change): the grid then covers the domain tightly and straight boundary
    runs lie along grid axes, where fast marching is most accurate. ``used`` (n,) bool: the vertices
    that count (default all). Returns the rotated (n,2)."""
    from scipy.spatial import ConvexHull, QhullError
    try:
        pts = uv if used is None else uv[used]
        H = pts[ConvexHull(pts).vertices]
    except (QhullError, ValueError):
        return uv
    E = np.roll(H, -1, axis=0) - H
    ang = np.unique(np.mod(np.arctan2(E[:, 1], E[:, 0]), np.pi / 2))
    c, s = np.cos(ang), np.sin(ang)
    x = H[:, 0, None] * c + H[:, 1, None] * s              # (hull, angles) rotated by -ang
    y = -H[:, 0, None] * s + H[:, 1, None] * c
    area = (x.max(0) - x.min(0)) * (y.max(0) - y.min(0))
    k = int(np.argmin(area))
    R = np.array([[c[k], -s[k]], [s[k], c[k]]])
    return uv @ R


def bilinear(field, pts, valid=None, corner_ok=None):
    """Bilinear samples (k,) of ``field`` (ny, nx) at continuous node coordinates ``pts`` (k,2)
    (column, row). Invalid nodes (``valid`` False or non-finite values, or ``corner_ok`` (k,4) False
    for that point's corner in the order (0,0), (0,1), (1,0), (1,1)) are left out and the weights
    renormalised; a point with no valid corner gets NaN."""
    ny, nx = field.shape
    x = np.clip(pts[:, 0], 0, nx - 1 - 1e-9)
    y = np.clip(pts[:, 1], 0, ny - 1 - 1e-9)
    j, i = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = x - j, y - i
    num = np.zeros(len(pts))
    den = np.zeros(len(pts))
    for q, (di, dj, w) in enumerate(((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)),
                                     (1, 0, (1 - fx) * fy), (1, 1, fx * fy))):
        v = field[i + di, j + dj]
        ok = np.isfinite(v)
        if valid is not None:
            ok &= valid[i + di, j + dj]
        if corner_ok is not None:
            ok &= corner_ok[:, q]
        num += np.where(ok, w * np.where(ok, v, 0.0), 0.0)
        den += np.where(ok, w, 0.0)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(den > 1e-12, num / np.maximum(den, 1e-300), np.nan)


def default_grid(V, F, uv):
    """Automatic grid size (nodes along the longer UV side): about ``GRID_NODES_PER_EDGE`` nodes per
    mean UV edge length, rounded up to a multiple of 64 and clipped to 256..2048."""
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    le = np.linalg.norm(uv[E[:, 0]] - uv[E[:, 1]], axis=1).mean()
    ext = np.ptp(uv[np.unique(F)], axis=0).max()
    g = GRID_NODES_PER_EDGE * ext / max(le, 1e-300)
    return int(np.clip(64 * np.ceil(g / 64), 256, 2048))




def _local_times(grid, inv_mu, valid, S, radius_nodes, pts=None, domain=None, metric=None, straight=False):
    """Flat-chart times (``_chart_time``, ``inv_mu`` the grid field 1/mu) from the sources ``S`` (k,2,
    node coordinates). With ``pts`` None:
    on the grid, over a window of ``radius_nodes + 2`` around each source, returns (ny, nx) with inf
    outside the windows. With ``pts`` (q,2 node coordinates): at those points (q,), from the nearest
    source in node units only (others inf). ``domain`` (ny, nx) bool: the inside nodes; segments that
    leave them give inf (``_visible``). ``straight`` (grid only): also the times along every segment,
    also those that leave the domain (for ``hidden_seed_level``): returns the two grids."""
    h = grid.h
    if pts is None:
        w = int(np.ceil(radius_nodes)) + 2
        off = np.arange(-w, w + 1)
        oi, oj = np.meshgrid(off, off, indexing='ij')
        inside = (oi ** 2 + oj ** 2 <= (w + 1) ** 2).ravel()
        oi, oj = oi.ravel()[inside], oj.ravel()[inside]
        ny, nx = grid.shape
        out = np.full(grid.shape, np.inf)
        out_all = np.full(grid.shape, np.inf) if straight else None
        step = max(1, 2_000_000 // len(oi))                      # sources per block
        for s0 in range(0, len(S), step):
            Sb = S[s0:s0 + step]
            ii = (np.rint(Sb[:, 1]).astype(np.int64)[:, None] + oi[None, :]).ravel()
            jj = (np.rint(Sb[:, 0]).astype(np.int64)[:, None] + oj[None, :]).ravel()
            src = np.repeat(np.arange(len(Sb)), len(oi))
            keep = (ii >= 0) & (ii < ny) & (jj >= 0) & (jj < nx)
            ii, jj, src = ii[keep], jj[keep], src[keep]
            keep = valid[ii, jj]
            ii, jj, src = ii[keep], jj[keep], src[keep]
            P = np.stack([jj, ii], 1).astype(np.float64)
            if straight:
                T = _chart_time(inv_mu, valid, Sb[src], P, h, None, metric)
                np.minimum.at(out_all, (ii, jj), T)
                if domain is not None:
                    T = np.where(_visible(domain, Sb[src], P), T, np.inf)
            else:
                T = _chart_time(inv_mu, valid, Sb[src], P, h, domain, metric)
            np.minimum.at(out, (ii, jj), T)
        return (out, out_all) if straight else out
    # at arbitrary points: nearest sources by a KD-tree
    from scipy.spatial import cKDTree
    d, k = cKDTree(S).query(pts)
    T = np.full(len(pts), np.inf)
    near = d <= radius_nodes + 1
    if near.any():
        T[near] = _chart_time(inv_mu, valid, S[k[near]], pts[near], h, domain, metric)
    return T


def _chart_time(inv_mu, valid, S, P, h, inside=None, metric=None):
    """Flat-chart time from ``S`` (k,2) to ``P`` (k,2) (node coordinates): ``|P - S| h`` times the
    mean of ``1/mu`` along the segment (Simpson's rule on the grid field ``inv_mu`` = 1/mu). With
    ``inside`` (ny, nx) bool: inf where the segment leaves the domain (``_visible``), since a straight
    line across a gap of the domain is no path on the surface. With ``metric`` (``face`` (ny, nx), ``G``
    (m,3) per triangle): the segment's exact surface length in the per-triangle metric instead."""
    d = np.linalg.norm(P - S, axis=1) * h
    inv = (bilinear(inv_mu, S, valid) + 4 * bilinear(inv_mu, 0.5 * (S + P), valid)
           + bilinear(inv_mu, P, valid)) / 6.0
    T = d * inv
    if metric is not None and len(S):
        # the exact surface length of the straight UV segment: the midpoint rule over half-cell
        # pieces, each in the metric G of the triangle of its nearest node (a path on the surface)
        face, gmet = metric
        ny, nx = face.shape
        D = P - S
        K = int(np.clip(np.ceil(2 * np.linalg.norm(D, axis=1).max()), 1, 256))
        L = np.zeros(len(S))
        du = D * (h / K)
        d00, d0, d1, d11 = du[:, 0] ** 2, du[:, 0], du[:, 1], du[:, 1] ** 2
        g0, g1, g2 = (np.ascontiguousarray(gmet[:, c]) for c in range(3))
        flat = face.ravel()
        block = max(1, 1_000_000 // len(S))                  # pieces at once (k, len(S))
        for k0 in range(0, K, block):
            frac = (np.arange(k0, min(K, k0 + block)) + 0.5) / K
            i = np.clip(np.rint(S[:, 1] + frac[:, None] * D[:, 1]).astype(np.int64), 0, ny - 1)
            j = np.clip(np.rint(S[:, 0] + frac[:, None] * D[:, 0]).astype(np.int64), 0, nx - 1)
            i *= nx
            i += j
            f = flat[i]                                      # the triangle of each piece's nearest node
            fi = np.maximum(f, 0)
            seg = g0[fi] * d00                               # |du|_G, term by term in the order
            seg += 2 * g1[fi] * d0 * d1                      # g0 du0^2 + 2 g1 du0 du1 + g2 du1^2
            seg += g2[fi] * d11
            np.sqrt(seg, out=seg)
            seg[f < 0] = np.nan
            for piece in seg:                                # summed in turn, as the pieces lie
                L += piece
        T = np.where(np.isfinite(L), L, T)
    if inside is not None:
        T = np.where(_visible(inside, S, P), T, np.inf)
    return T


def _visible(inside, S, P, skip=0.6, chunk=200_000):
    """(k,) bool: the segments ``S`` -> ``P`` (k,2 node coordinates) stay on inside nodes: samples every
    half cell, each at its nearest node, must be ``inside`` (ny, nx), except within ``skip`` cells of
    either end (an end on the boundary may round to a node just outside)."""
    ny, nx = inside.shape
    out = np.ones(len(S), bool)
    L = np.linalg.norm(P - S, axis=1)
    if not len(S) or L.max() <= 2 * skip:
        return out
    t = np.linspace(0.0, 1.0, int(np.ceil(L.max() / 0.25)) + 1)[1:-1]
    # a segment whose bounding box (one node wider) holds no outside node is seen whatever its samples
    # round to: count the outside nodes of each box from one summed-area table, and sample only the
    # others (a seed window away from the boundary: none), at the same fractions ``t``
    lo, hi = np.minimum(S, P), np.maximum(S, P)
    j0 = np.clip(np.floor(lo[:, 0]).astype(np.int64) - 1, 0, nx - 1)
    j1 = np.clip(np.ceil(hi[:, 0]).astype(np.int64) + 1, 0, nx - 1) + 1
    i0 = np.clip(np.floor(lo[:, 1]).astype(np.int64) - 1, 0, ny - 1)
    i1 = np.clip(np.ceil(hi[:, 1]).astype(np.int64) + 1, 0, ny - 1) + 1
    r0, c0 = i0.min(), j0.min()                                # the table over the boxes' union only
    C = np.zeros((i1.max() - r0 + 1, j1.max() - c0 + 1), np.int64)
    C[1:, 1:] = np.cumsum(np.cumsum(~inside[r0:i1.max(), c0:j1.max()], axis=0), axis=1)
    i0, i1, j0, j1 = i0 - r0, i1 - r0, j0 - c0, j1 - c0
    near = np.flatnonzero(C[i1, j1] - C[i0, j1] - C[i1, j0] + C[i0, j0] > 0)
    step = max(1, chunk // max(len(t), 1))
    for a in range(0, len(near), step):
        rows = near[a:a + step]
        s_, p_, l_ = S[rows], P[rows], L[rows]
        Q = s_[:, None, :] + t[None, :, None] * (p_ - s_)[:, None, :]          # (c, K, 2)
        check = (t[None, :] * l_[:, None] > skip) & ((1 - t[None, :]) * l_[:, None] > skip)
        j = np.clip(np.rint(Q[..., 0]).astype(np.int64), 0, nx - 1)
        i = np.clip(np.rint(Q[..., 1]).astype(np.int64), 0, ny - 1)
        out[rows] = ~(check & ~inside[i, j]).any(1)
    return out


# --------------------------------------------------------------------------------------------------
def calibrate_phi(D, valid, h):
    """Level-set values whose contour initialisation in scikit-fmm reproduces given distances.

    scikit-fmm starts a node next to the zero contour at ``d = (sum over axes 1/l_axis^2)^-1/2``,
    ``l_axis = h |phi_i| / (|phi_i| + |phi_n|)`` for the neighbour ``n`` across the contour on that
    axis (the nearer crossing if both are). With ``phi = D`` that is exact only where the contour
    crosses both axes; next to a single crossing it overestimates by ``1/cos`` of the front's angle,
    an error of up to ~0.3 cells that then travels outward (the point-source offset). This keeps the
    signs of ``D`` (ny, nx) and rescales ``phi`` on the outer side of the contour (``D > 0``) so that
    ``d = D`` there exactly: given the inner neighbours, the condition is a quadratic in ``1/phi_i``,
    solved in closed form. Both sides cannot be exact at once (across a single crossing the two
    starting values always add up to one cell); the outer side is the one the front leaves from.
    ``valid`` (ny, nx) marks the unmasked nodes. Returns phi (ny, nx)."""
    phi = np.where(valid, D, 1.0).astype(np.float64)
    tiny = 1e-9 * h
    phi = np.where(np.abs(phi) < tiny, np.where(phi < 0, -tiny, tiny), phi)
    ny, nx = phi.shape
    pad = np.pad(phi, 1, constant_values=np.nan)
    vpad = np.pad(valid, 1, constant_values=False)
    ii, jj = np.nonzero(valid & (phi > 0) & (phi < h))      # only these can start exactly
    a = np.zeros(len(ii))          # sum over axes of q^2, q = |phi| of the nearer crossing neighbour
    b = np.zeros(len(ii))          # sum of q
    k = np.zeros(len(ii))          # number of crossing axes
    for di, dj in ((0, 1), (1, 0)):
        q = np.zeros(len(ii))
        for sgn in (1, -1):
            nb = pad[ii + 1 + sgn * di, jj + 1 + sgn * dj]
            ok = vpad[ii + 1 + sgn * di, jj + 1 + sgn * dj] & (nb < 0)
            q = np.where(ok, np.maximum(q, -np.where(ok, nb, 0.0)), q)
        a += q * q
        b += q
        k += q > 0
    ring = k > 0
    a, b, k = a[ring], b[ring], k[ring]
    ii, jj = ii[ring], jj[ring]
    target = phi[ii, jj]
    # (1/h^2) sum (1 + q u)^2 = 1/D^2 with u = 1/phi_i:  a u^2 + 2 b u + k - h^2/D^2 = 0
    c = k - (h / target) ** 2
    with np.errstate(invalid='ignore', divide='ignore'):
        u = (-b + np.sqrt(np.maximum(b * b - a * c, 0.0))) / a
    ok = (c < 0) & (u > 0) & np.isfinite(u)
    phi[ii[ok], jj[ok]] = 1.0 / u[ok]
    return phi


class _Unseeded(Exception):
    """Internal: a source the chart's grid cannot seed (no grid node within its exact seed, or outside
    the rasterised domain). ``GeodesicSolver.distance`` answers that chart by surface paths instead;
    it never leaves the module."""


def resolve_solver(solver):
    """'skfmm' or 'sweep' for a requested ``solver`` ('auto' picks scikit-fmm if it imports)."""
    if solver not in SOLVERS:
        raise ConformalError(f"unknown solver {solver!r}: use one of {', '.join(SOLVERS)}", 'invalid_input')
    if solver == 'sweep':
        return solver
    try:
        import skfmm  # noqa: F401
    except ImportError:
        if solver == 'skfmm':
            raise ConformalError("scikit-fmm is not installed: use solver 'sweep' or 'auto'") from None
        return 'sweep'
    return 'skfmm'


def solver_name():
    """A label of the solver ``solver='auto'`` will use (for user interfaces)."""
    return "scikit-fmm" if resolve_solver('auto') == 'skfmm' else "built-in fast sweeping (no scikit-fmm)"


def eikonal_march(T_seed, seed, phi, speed, mask, h, solver='auto'):
    """Travel times on the grid from the seed nodes (``seed`` (ny, nx) True) whose exact times are
    ``T_seed`` (ny, nx); ``phi`` (ny, nx) is negative exactly on the seed, its zero contour the
    seed's rim. With 'skfmm' the result is the time from that rim (add the rim time); with 'sweep'
    it is the full time. ``speed`` (ny, nx) > 0,
    nodes with ``mask`` True excluded (returned inf), spacing ``h``. ``solver``: 'skfmm' (scikit-fmm
    travel time from the zero contour of ``phi``, order 2, plus the seed rim time), 'sweep'
    (``core.eikonal.sweep``, pure numpy, order 2, the seed held fixed), or 'auto' (scikit-fmm if it
    imports). Returns (T, solver name). Raises ``_Unseeded`` where scikit-fmm finds no seed rim on
    the unmasked nodes or a node it cannot reach (an island of near-degenerate triangles: the caller
    answers it by surface paths instead)."""
    solver = resolve_solver(solver)
    if solver == 'skfmm':
        import skfmm
        try:
            T = skfmm.travel_time(np.ma.MaskedArray(phi, mask), np.where(mask, 1.0, speed), dx=h, order=2)
        except (ValueError, RuntimeError) as exc:     # 'no zero contour', 'Unreachable voxel'
            raise _Unseeded(f"the march could not start: {exc}") from None
        T = np.ma.filled(np.ma.MaskedArray(T), np.inf).astype(np.float64)
        T[mask] = np.inf
        return T, 'skfmm'
    from .eikonal import sweep
    # hold the same nodes as scikit-fmm does: the seed and its outer ring (4-neighbours)
    held = seed.copy()
    held[1:] |= seed[:-1]
    held[:-1] |= seed[1:]
    held[:, 1:] |= seed[:, :-1]
    held[:, :-1] |= seed[:, 1:]
    held &= ~mask & np.isfinite(T_seed)
    T = sweep(np.where(held, T_seed, np.inf), speed, h, mask=mask, order=2)
    return T, 'sweep'


def log_mu_slope(mu, valid, h):
    """How fast ``log mu`` varies on a chart's grid: the 99.9th percentile of its central differences
    over ``valid`` (ny, nx) nodes (``mu`` (ny, nx), spacing ``h``), per UV unit. A property of the
    chart, made once when it is rasterised (``seed_radius`` of every query uses it)."""
    lm = np.log(np.where(valid, mu, 1.0))
    g = 0.0
    for axis in (0, 1):
        a = [slice(None)] * 2
        b = [slice(None)] * 2
        a[axis], b[axis] = slice(2, None), slice(None, -2)
        both = valid[tuple(a)] & valid[tuple(b)]
        if both.any():
            d = np.abs(lm[tuple(a)] - lm[tuple(b)])[both] / (2 * h)
            g = max(g, float(np.percentile(d, 99.9)))
    return g


def seed_radius(slope, h, source_radius):
    """Seed disk radius in cells: ``source_radius``, reduced where ``log mu`` varies fast, so that
    the straight-line chart time inside the disk stays accurate (radius times the largest
    ``|grad_uv log mu|``, ``slope`` of ``log_mu_slope``, at most 0.15), and at least 3 cells."""
    cap = 0.15 / (slope * h) if slope > 0 else np.inf
    return float(max(SEED_MIN_CELLS, min(source_radius, cap)))


def hidden_seed_level(T_seen, T_straight, march_on, tau, tau_min):
    """The seed's level, at most ``tau``: below the straight-segment time ``T_straight`` (ny, nx) of
    every node the march will take (``march_on``) whose segment leaves the domain (``T_seen`` inf:
    ``_visible``), but not below ``tau_min`` unless ``tau`` is. The march starts at the level ``tau``
    from the seed's nodes, so a node inside that level but hidden from the source (behind a notch of
    a jagged boundary, the source on it) would start at ``tau`` too: too late by up to the seed's
    radius, and so would everything the front reaches through it (a hemisphere cut along its
    triangles, boundary source: +30 % at 2-5 edges from the source). Below the level every node is
    seen, down to ``tau_min``: a level of a few cells costs the march accuracy everywhere (bump's far
    corner: 0.0054 % mean at 24 cells, 0.0129 % at 3, 0.0108 % at 10), where a hidden node near the
    source costs it only behind the node."""
    hidden = march_on & np.isfinite(T_straight) & ~np.isfinite(T_seen)
    if not hidden.any():
        return tau
    return float(min(tau, max(tau_min, (1.0 - 1e-9) * T_straight[hidden].min())))


def bridging_rim(G, F, valid):
    """(ny, nx) bool: the rim nodes (valid, not inside) that link across a gap of the domain: a
    4-neighbour in use whose triangle shares no vertex with the rim node's own (the triangle it was
    extended from). Where cells are larger than triangles this also flags some harmless rim nodes;
    they are then only extrapolated, not marched through. ``G`` a rasterised ``Grid`` with its rim,
    ``F`` (m,3) the chart's triangles, ``valid`` (ny, nx) the nodes in use."""
    face = G.face
    rim = valid & ~G.inside
    ii, jj = np.nonzero(rim)
    ny, nx = face.shape
    bad = np.zeros(len(ii), bool)
    own = F[face[ii, jj]]                                       # (r,3)
    for di, dj in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        a, b = ii + di, jj + dj
        ok = (a >= 0) & (a < ny) & (b >= 0) & (b < nx)
        a, b = np.where(ok, a, 0), np.where(ok, b, 0)
        nb_face = face[a, b]
        use = ok & valid[a, b] & (nb_face >= 0)
        other = F[np.where(use, nb_face, 0)]
        share = (own[:, :, None] == other[:, None, :]).any((1, 2))
        bad |= use & ~share
    out = np.zeros(face.shape, bool)
    out[ii[bad], jj[bad]] = True
    return out


GAP_ARC = 2.5   # cells: a grid link whose two ends meet the boundary this far apart along it bridges a gap


def _boundary_edges(P, F):
    """The chart's boundary edges in node coordinates: start ``A`` (e,2), end ``B`` (e,2), arc position
    of the start along its loop ``s0`` (e,), length ``ln`` (e,), loop ``lid`` (e,), and the loops'
    lengths (l,) (node units). ``P`` (k,2) vertex node coordinates, ``F`` (m,3)."""
    from ..mesh.topology import boundary_loops
    A, B, s0, ln, lid, tot = [], [], [], [], [], []
    for k, L in enumerate(boundary_loops(F, len(P))):
        L = np.asarray(L)
        a, b = P[L], P[np.roll(L, -1)]
        seg = np.linalg.norm(b - a, axis=1)
        A.append(a)
        B.append(b)
        s0.append(np.r_[0.0, np.cumsum(seg)[:-1]])
        ln.append(seg)
        lid.append(np.full(len(L), k))
        tot.append(seg.sum())
    if not A:
        z = np.zeros(0)
        return np.zeros((0, 2)), np.zeros((0, 2)), z, z, np.zeros(0, np.int64), z
    return (np.concatenate(A), np.concatenate(B), np.concatenate(s0), np.concatenate(ln),
            np.concatenate(lid), np.asarray(tot))


def _arc_apart(lid_a, s_a, lid_b, s_b, tot, gap):
    """(q,) bool: boundary points (loop, arc position) farther apart than ``gap`` along the boundary
    (on different loops: always)."""
    d = np.abs(s_a - s_b)
    d = np.minimum(d, tot[lid_a] - d)
    return (lid_a != lid_b) | (d > gap)


def boundary_bridges(G, uv, F, valid, fine, gap=GAP_ARC):
    """Grid links that cross a gap of the UV domain, found from the boundary itself: the boundary edges'
    crossings of the grid's links (a horizontal link joins nodes (i, j), (i, j+1); a vertical one (i, j),
    (i+1, j)), each with its position along its boundary loop (arc length, cells). A link that crosses
    the boundary twice, at points more than ``gap`` cells apart along it, jumps a gap narrower than a
    cell (between two parts of the domain, or the two sides of a slit or a tapering notch, however
    near its tip: the sides' triangles may share the tip vertex there). A rim node (valid, outside)
    is anchored at its nearest boundary point; it bridges when a link of it crosses the boundary, or
    reaches another rim node's anchor, more than ``gap`` cells along the boundary from its own anchor.

    ``G`` a rasterised ``Grid`` with its rim, ``uv`` (k,2), ``F`` (m,3) the chart, ``valid`` (ny, nx)
    the nodes in use, ``fine`` (m,) bool (cells well below the triangle's edges). Returns ``(inside,
    rim)`` (ny, nx) bool: inside nodes at an end of a bridging link whose triangle is ``fine`` (left out
    of the march and of sampling), and bridging rim nodes (left out of the march)."""
    ny, nx = G.shape
    out_in = np.zeros(G.shape, bool)
    out_rim = np.zeros(G.shape, bool)
    P = G.coords(uv)
    A, B, s0, ln, lid, tot = _boundary_edges(P, F)
    if not len(A):
        return out_in, out_rim
    keys, arcs, lids = [], [], []
    for ax in (0, 1):
        # ax 0: rows y = i crossed -> horizontal links keyed by their left node; ax 1: columns x = j
        # crossed -> vertical links keyed by their lower node (offset by ny * nx)
        c, o = 1 - ax, ax
        lo = np.minimum(A[:, c], B[:, c])
        hi = np.maximum(A[:, c], B[:, c])
        n0 = np.ceil(lo).astype(np.int64)
        cnt = np.maximum(np.ceil(hi).astype(np.int64) - n0, 0)
        e = np.repeat(np.arange(len(A)), cnt)
        line = n0[e] + np.arange(len(e)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        t = (line - A[e, c]) / (B[e, c] - A[e, c])
        x = A[e, o] + t * (B[e, o] - A[e, o])
        other = np.floor(x).astype(np.int64)
        i, j = (line, other) if ax == 0 else (other, line)
        ok = (i >= 0) & (i < ny - ax) & (j >= 0) & (j < nx - (1 - ax))
        keys.append((i * nx + j + ax * ny * nx)[ok])
        arcs.append((s0[e] + t * ln[e])[ok])
        lids.append(lid[e][ok])
    key, arc, lk = np.concatenate(keys), np.concatenate(arcs), np.concatenate(lids)
    order = np.lexsort((arc, key))
    key, arc, lk = key[order], arc[order], lk[order]

    def ends(k):
        """The two end nodes ((rows, cols), (rows, cols)) of links ``k``."""
        vert = (k >= ny * nx).astype(np.int64)
        k = k - vert * ny * nx
        i, j = k // nx, k % nx
        return (i, j), (i + vert, j + 1 - vert)

    # links crossed twice with the crossings far apart along the boundary
    same = key[1:] == key[:-1]
    far = same & _arc_apart(lk[1:], arc[1:], lk[:-1], arc[:-1], tot, gap)
    bad = np.unique(key[1:][far])
    face, inside = G.face, G.inside
    for (i, j) in ends(bad):
        use = valid[i, j]
        i, j = i[use], j[use]
        fin = inside[i, j]
        f_ok = fine[np.maximum(face[i, j], 0)]
        out_in[i[fin & f_ok], j[fin & f_ok]] = True
        out_rim[i[~fin], j[~fin]] = True
    # rim nodes: anchored at their nearest boundary point
    ri, rj = np.nonzero(valid & ~inside)
    if not len(ri):
        return out_in, out_rim
    from scipy.spatial import cKDTree
    m = np.maximum(np.ceil(ln / 0.25).astype(np.int64), 1)
    e = np.repeat(np.arange(len(A)), m)
    t = (np.arange(len(e)) - np.repeat(np.cumsum(m) - m, m)) / m[e]
    pts = A[e] + t[:, None] * (B[e] - A[e])
    _, near = cKDTree(pts).query(np.c_[rj, ri].astype(np.float64))
    anc_s = np.full(G.shape, np.nan)
    anc_l = np.full(G.shape, -1, np.int64)
    anc_s[ri, rj] = s0[e[near]] + t[near] * ln[e[near]]
    anc_l[ri, rj] = lid[e[near]]
    rim = valid & ~inside
    # links crossed once: the crossing against the rim end's anchor
    single = np.ones(len(key), bool)
    single[1:] &= ~same
    single[:-1] &= ~same
    (i0, j0), (i1, j1) = ends(key[single])
    for (a, b) in ((i0, j0), (i1, j1)):
        r = rim[a, b]
        hit = r & _arc_apart(anc_l[a, b], np.nan_to_num(anc_s[a, b]), lk[single], arc[single], tot, gap)
        out_rim[a[hit], b[hit]] = True
    # rim-rim links not crossed: their anchors far apart
    crossed = np.zeros(2 * ny * nx, bool)
    crossed[key] = True
    for ax in (0, 1):
        if ax == 0:
            a_, b_ = (slice(None), slice(None, -1)), (slice(None), slice(1, None))
            cr = crossed[:ny * nx].reshape(ny, nx)[:, :-1]
        else:
            a_, b_ = (slice(None, -1), slice(None)), (slice(1, None), slice(None))
            cr = crossed[ny * nx:].reshape(ny, nx)[:-1, :]
        both = rim[a_] & rim[b_] & ~cr
        ii, jj = np.nonzero(both)
        if not len(ii):
            continue
        la, sa = anc_l[a_][ii, jj], anc_s[a_][ii, jj]
        lb, sb = anc_l[b_][ii, jj], anc_s[b_][ii, jj]
        hit = _arc_apart(la, sa, lb, sb, tot, gap)
        for sl in (a_, b_):
            sub = out_rim[sl]
            sub[ii[hit], jj[hit]] = True
    return out_in, out_rim


def sample_corners(G, F, P, fine):
    """(k,4) bool: which of the four bilinear corner nodes of each vertex (node coordinates ``P``
    (k,2)) may give it a value. Where the vertex's triangles are ``fine`` (m,) (cells well below their
    edges), a corner node must lie in a triangle with a corner in the vertex's one-ring: a node
    across a narrow gap of the domain (two sides of a hole, a notch), or a rim node extended from the
    other side, is no sample of this side. Elsewhere every corner may. ``G`` a rasterised ``Grid``
    with its rim, ``F`` (m,3) the chart's triangles."""
    import scipy.sparse as sp
    k = len(P)
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    A = sp.coo_matrix((np.ones(2 * len(E) + k, bool), (np.r_[E[:, 0], E[:, 1], np.arange(k)],
                                                       np.r_[E[:, 1], E[:, 0], np.arange(k)])),
                      shape=(k, k)).tocsr()
    vfine = np.zeros(k, bool)
    vfine[F[fine].ravel()] = True
    ny, nx = G.face.shape
    x = np.clip(P[:, 0], 0, nx - 1 - 1e-9)
    y = np.clip(P[:, 1], 0, ny - 1 - 1e-9)
    j, i = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    out = np.ones((k, 4), bool)
    idx = np.flatnonzero(vfine)
    if not len(idx):
        return out
    for q, (di, dj) in enumerate(((0, 0), (0, 1), (1, 0), (1, 1))):
        f = G.face[i[idx] + di, j[idx] + dj]
        has = f >= 0
        near = np.zeros(len(idx), bool)
        for c in range(3):
            cols = F[np.where(has, f, 0), c]
            near |= np.asarray(A[idx, cols]).ravel().astype(bool)
        out[idx, q] = ~has | near
    return out


def extrapolate_rim(T, inside, rim, h, inv_mu):
    """Travel times at the rim nodes (outside the domain, next to it) from the inside ones, for
    sampling boundary vertices: per axis direction with two inside nodes ``2 T1 - T2`` (linear
    extrapolation, second order), averaged over the directions that have them; else the nearest
    inside neighbour plus one cell ``T1 + h / mu``. ``T`` (ny, nx) with finite values inside,
    ``inside``, ``rim`` (ny, nx) bool, ``inv_mu`` (ny, nx) = 1/mu. Returns (ny, nx): ``T`` with the
    rim filled (inf where no inside neighbour)."""
    ny, nx = T.shape
    Tin = np.where(inside, T, np.inf)
    pad = np.pad(Tin, 2, constant_values=np.inf)
    ii, jj = np.nonzero(rim)
    lin_sum = np.zeros(len(ii))
    lin_cnt = np.zeros(len(ii))
    step = np.full(len(ii), np.inf)
    for di, dj in ((0, 1), (0, -1), (1, 0), (-1, 0)):
        t1 = pad[ii + 2 + di, jj + 2 + dj]
        t2 = pad[ii + 2 + 2 * di, jj + 2 + 2 * dj]
        both = np.isfinite(t1) & np.isfinite(t2)
        lin_sum += np.where(both, 2 * np.where(both, t1, 0) - np.where(both, t2, 0), 0.0)
        lin_cnt += both
        step = np.minimum(step, t1 + h * inv_mu[ii, jj])
    out = T.copy()
    with np.errstate(invalid='ignore', divide='ignore'):
        lin = np.where(lin_cnt > 0, lin_sum / np.maximum(lin_cnt, 1), np.inf)
    out[ii, jj] = np.where(lin_cnt > 0, np.minimum(lin, step), step)
    return out



def _groups(mu_s):
    """Split sources into groups whose ``mu`` differ by less than a factor 2 (one march each)."""
    b = np.floor(np.log2(mu_s / mu_s.min()) + 1e-12).astype(np.int64)
    return [np.flatnonzero(b == k) for k in np.unique(b)]




# --------------------------------------------------------------------------------------------------
# accuracy model: error estimate from the local resolution, and the grid size for an error target
# Fitted on exact polyhedral distances (MMP) and exact corridor distances: docs/geodesic.md "Error
# estimate", bench/geodesic_real.py --calibrate. Two terms: (1) the grid, first order in the cell where
# geodesics bend round reflex boundary corners (a convex domain is far more accurate), measured C = 0.03-
# 0.05 on a corridor with two reflex corners (reflex 1), 0.2 on woody (3.6), 0.16-0.35 on alligator (22);
# (2) a floor set by the mesh, which no grid removes: the per-vertex mu interpolated over a triangle is
# not the triangle's own mu (measured floor / spread = 0.010 edgebump, 0.022 ridge, 0.031 bump and waves,
# 0.096 spot's largest island; 0.1 keeps the estimate conservative).
ERR_GRID_C0 = 0.02     # grid term: (C0 + C1 min(reflex, REFLEX_CAP)) * mean surface cell / median distance
ERR_GRID_C1 = 0.05
REFLEX_CAP = 6.0
ERR_RELAX = 0.005      # on-mesh term: ERR_RELAX * area fraction of the under-resolved triangles
ERR_MESH = 0.1         # mesh term: ERR_MESH * mu_spread (area-weighted mean of the per-triangle spread)
ERR_ANISO = 0.006      # metric term: ERR_ANISO * metric_excess (area-weighted mean anisotropy - 1)
ANISO_CAP = 4.0        # a triangle's anisotropy counts at most this much in ``metric_excess`` (slivers)
# the metric term with fewer re-marches (an automatic grid takes as few as its target allows,
# ``metric_passes_for``): the isotropic march alone leaves about PASS_ERROR[0] * excess (measured
# 0.04-0.127 on the surfaces at n = 65 and a head cut, the most on ridge), one re-march about
# PASS_ERROR[1] * excess^2 (measured 0.65-1.1, cheburashka's head the most)
PASS_ERROR = (0.13, 1.1)
PASS_SHARE = 0.5       # a re-march is left out where the metric term stays within this share of the target
TYPICAL_DISTANCE = 0.35  # before a query, the median distance is taken as this times the 3D bbox diagonal
NODE_BUDGET = 4096 * 4096  # automatic grids of all islands together use at most this many nodes
# Finer triangles for a grid on a map far from conformal (``refine_levels``): the metric term of a chart
# that the grid marches falls by half with each midpoint subdivision of the mesh (spot's head cut:
# metric_excess 0.133, 0.064, 0.031 at 0, 1, 2 levels). Where the largest one is above REFINE_TRIGGER of
# the target (the share above which a forced grid is warned that the map is far from conformal, and
# 'auto' takes the surface paths), the solver takes the levels that bring it within REFINE_SHARE of the
# target, at most REFINE_LEVELS of them and REFINE_MAX_FACES triangles in all
REFINE_TRIGGER = 0.5
REFINE_SHARE = 0.25
REFINE_LEVELS = 3
REFINE_MAX_FACES = 50_000   # (an unseeded source's surface paths on the finer mesh keep k >= 13)


def reflex_turning(uv: np.ndarray, F: np.ndarray) -> float:
    """How non-convex a UV domain is: the sum over its boundary vertices of the interior angle beyond
    pi (the UV corner angles around the vertex, minus pi, where positive), divided by pi. ``uv``
    (k,2), ``F`` (m,3). 0 for a convex domain, 1 for two right-angled reflex corners; holes count."""
    from ..mesh.geometry import corner_angles
    from ..mesh.topology import boundary_loops
    loops = boundary_loops(F, len(uv))
    if not loops:
        return 0.0
    ang = corner_angles(np.c_[uv, np.zeros(len(uv))], F)
    total = np.bincount(F.ravel(), ang.ravel(), minlength=len(uv))
    b = np.concatenate([np.asarray(L, np.int64) for L in loops])
    return float(np.clip(total[b] - np.pi, 0.0, None).sum() / np.pi)


def mu_spread(F: np.ndarray, mu_face: np.ndarray, area: np.ndarray) -> float:
    """How far the smooth (per-vertex, ``core.mesh.measures.vertex_mu``) conformal factor departs from
    the mesh's own per-triangle one: the ``area``-weighted mean over the triangles ``F`` (m,3) of the
    largest ``|log mu_vertex - log mu_T|`` at their corners (dimensionless). ``mu_face`` (m,)."""
    lv = np.log(vertex_mu(F, mu_face, area, int(F.max()) + 1))
    s = np.abs(lv[F] - np.log(mu_face)[:, None]).max(1)
    return float((area * s).sum() / area.sum())


def surface_cell(mu_face: np.ndarray, area: np.ndarray, h: float, where: np.ndarray | None = None) -> float:
    """The grid's mean cell size in surface units (mesh units): the area-weighted (``area`` (m,)) mean
    over the triangles (those of ``where`` (m,) bool, default all) of ``h / mu_T`` for a grid spacing
    ``h`` (UV units) and the realised scale ``mu_face`` (m,) (UV units per surface unit)."""
    if where is not None:
        if not where.any():
            return 0.0
        mu_face, area = mu_face[where], area[where]
    return float((area * (h / mu_face)).sum() / area.sum())


def grid_coefficient(reflex: float) -> float:
    """The grid term's coefficient for a domain of ``reflex_turning`` ``reflex``."""
    return ERR_GRID_C0 + ERR_GRID_C1 * min(reflex, REFLEX_CAP)


def metric_error(excess: float, passes: int = METRIC_PASSES) -> float:
    """The metric term of the estimate (dimensionless) for a map of ``metric_excess`` ``excess``
    marched with ``passes`` re-marches: ``ERR_ANISO * excess`` after ``METRIC_PASSES``, at least
    ``PASS_ERROR[passes] * excess^(passes + 1)`` after fewer."""
    term = ERR_ANISO * excess
    if passes < METRIC_PASSES:
        term = max(term, PASS_ERROR[passes] * excess ** (passes + 1))
    return float(term)


def metric_passes_for(excess: float, target: float) -> int:
    """The fewest re-marches (0 to ``METRIC_PASSES``) whose metric term (``metric_error``) on a map of
    ``metric_excess`` ``excess`` stays within ``PASS_SHARE`` of the error ``target`` (each re-march is
    a whole march: a nearly conformal map, bump's, needs none for a 0.1 % target)."""
    for passes in range(METRIC_PASSES):
        if metric_error(excess, passes) <= PASS_SHARE * target:
            return passes
    return METRIC_PASSES


def error_estimate(cell: float, distance: float, spread: float, reflex: float, free: float = 0.0,
                   excess: float = 0.0, passes: int = METRIC_PASSES) -> float:
    """Estimated mean relative error (dimensionless) of the distances on a chart whose mean surface
    cell is ``cell`` (``surface_cell`` over the resolved triangles, mesh units), for a query whose
    median distance is ``distance`` (mesh units), on a map with ``mu_spread`` ``spread`` and
    ``metric_excess`` ``excess`` marched with ``passes`` re-marches over a domain with
    ``reflex_turning`` ``reflex``, with the area fraction ``free`` under-resolved (on-mesh fast
    marching): ``grid_coefficient(reflex) * cell / distance + ERR_MESH * spread + metric_error(excess,
    passes) + ERR_RELAX * free``."""
    return float(grid_coefficient(reflex) * cell / max(distance, 1e-300) + ERR_MESH * spread
                 + metric_error(excess, passes) + ERR_RELAX * free)


def typical_distance(V: np.ndarray) -> float:
    """The median distance assumed before a query (mesh units): ``TYPICAL_DISTANCE`` times the
    diagonal of the bounding box of the points ``V`` (k,3)."""
    return float(TYPICAL_DISTANCE * np.linalg.norm(np.ptp(V, axis=0)))


def default_grid_for_target(V, F, uv, mu_face, spread, reflex, target=ERROR_TARGET, pad=2):
    """Automatic grid size (nodes along the longer UV side) for one chart, ``V`` (k,3), ``F`` (mi,3),
    ``uv`` (k,2), ``mu_face`` (mi,): the smallest multiple of 64 whose ``error_estimate`` (at the
    ``typical_distance``; the grid term over the triangles that grid resolves, the others counted by
    the on-mesh term) meets ``target``, at least ``default_grid`` (8 nodes per mean UV edge) and
    ``GRID_AUTO_MIN``, at most ``GRID_AUTO_MAX``. When the mesh term alone uses up the target, the grid
    terms are only brought to half the mesh term (a finer grid would not help). The metric term
    (``ERR_ANISO``) is left out: it does not fall with the grid (a chart where it is large goes to
    surface paths, ``paths_choice``). Returns (grid, limit, estimate): ``limit`` None when the target
    is met, 'cap' when the cap stops it, 'mesh' when the mesh does."""
    area = face_areas(V, F)
    ext = float(np.ptp(uv[np.unique(F)], axis=0).max())
    base = max(default_grid(V, F, uv), GRID_AUTO_MIN)
    floor = ERR_MESH * spread
    room, limit = target - floor, None
    if room < 0.5 * floor:
        room, limit = 0.5 * floor, 'mesh'
    edge = mean_edges(V, F)
    dist = typical_distance(V)
    est = None
    for g in range(int(64 * np.ceil(base / 64)), GRID_AUTO_MAX + 1, 64):
        h = ext / (g - 1 - 2 * pad)                     # the Grid's spacing
        un = unresolved_faces(mu_face, edge, h)
        est = error_estimate(surface_cell(mu_face, area, h, ~un), dist, 0.0, reflex,
                             float(area[un].sum() / area.sum()))
        if est <= room:
            return g, limit, est
    return GRID_AUTO_MAX, limit or 'cap', est


def mean_edges(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Mean 3D edge length (m,) of each triangle of ``F`` (m,3), mesh units."""
    return np.linalg.norm(V[F] - V[np.roll(F, 1, axis=1)], axis=2).mean(1)


def unresolved_faces(mu_face: np.ndarray, edge: np.ndarray, h: float) -> np.ndarray:
    """(m,) bool: triangles whose surface cell ``h / mu_T`` is above ``UNRESOLVED`` times their mean
    edge ``edge`` (m,): the grid does not resolve them, on-mesh fast marching does (``MeshRelax``)."""
    return (h / mu_face) > UNRESOLVED * edge


# --------------------------------------------------------------------------------------------------
# charts: one flat grid per island
def closed_parts(F, count, face_island):
    """(count,) bool: the connected parts (``face_island`` (m,) of the triangles ``F`` (m,3)) that have
    no boundary edge (an edge of one triangle only). Edges are counted undirected, unlike
    ``core.mesh.topology.twin_halfedges``, so a part with inconsistent orientation is not opened."""
    from ..mesh.topology import halfedges
    H = np.sort(halfedges(F), axis=1)
    _, inv, cnt = np.unique(H, axis=0, return_inverse=True, return_counts=True)
    open_part = np.zeros(count, bool)
    open_part[np.repeat(face_island, 3)[cnt[inv.ravel()] == 1]] = True
    return ~open_part


def _seamed_parts(F, seams, n, count, face_island):
    """(count,) bool: the connected parts (``face_island`` (m,) of the triangles ``F`` (m,3) on ``n``
    vertices) that hold an edge of ``seams`` ((k,2) vertex pairs or None; checked by ``seam_pairs``)."""
    from ..atlas.cut import seam_edge_counts
    return seam_edge_counts(F, seams, n, count, face_island) > 0


def _pinched(F, n):
    """True if the triangles ``F`` (m,3) on ``n`` vertices pinch at a vertex (separate fans of
    triangles touch there, ``vertex_fans``)."""
    from ..mesh.topology import vertex_fans
    return bool((vertex_fans(F, n) > 1).any())


def _fits_paths(F):
    """True if surface paths fit their budget on the triangles ``F`` (m,3) (``path_points``)."""
    from ..mesh.topology import unique_edges
    return path_points(len(F), len(unique_edges(F)[0])) is not None


def _cut_parts(Fo, res, seams, n):
    """The pieces of the surface that the flattening ``res`` (``core.atlas.islands.unwrap`` of the
    open triangles ``Fo`` (mo,3) on ``n`` input vertices, cut along ``seams``) cut beyond the seams and
    the repair of the mesh (which splits non-manifold vertices and edges, ``core.mesh.repair``: the
    surface every answer is on): a hole cut open, an overlapping map split, or an island's map that
    still overlaps itself (its report's ``overlaps``; a few flipped triangles only disturb the grid
    locally); and small enough for surface paths, which answer them uncut. Returns ``(piece (mo,),
    cut (pieces,) bool, glued (N,))`` (``core.atlas.cut.glued_pieces``)."""
    from ..atlas.cut import glued_pieces
    piece, _, glued, cut = glued_pieces(Fo, res.F, res.face_island, seams, n)
    bad = np.array([r.get('overlaps', 0) > 0 for r in res.islands], bool)
    if bad.any():
        cut[np.unique(piece[bad[res.face_island]])] = True
    for p in np.flatnonzero(cut):
        cut[p] = _fits_paths(Fo[piece == p])
    return piece, cut, glued


def _paths_pieces(vert_of, Fs, uvs, island, piece, cut, glued):
    """The split arrays of a flattening (``vert_of`` (N,), ``Fs`` (mo,3), ``uvs`` (N,2), ``island``
    (mo,)) with the pieces ``cut`` (pieces,) bool (``piece`` (mo,) of each triangle) glued back
    (``glued`` (N,) the glued id of each split vertex): their vertices are one per glued id, their uv
    NaN (no chart), one island each after the others (renumbered from 0). Returns ``(vert_of, Fs,
    uvs, island)``."""
    tri = cut[piece]
    keep = np.unique(Fs[~tri])
    new = np.full(len(vert_of), -1, np.int64)
    new[keep] = np.arange(len(keep))
    g, ginv = np.unique(glued[Fs[tri]], return_inverse=True)
    vert_of_g = np.empty(int(glued.max()) + 1, np.int64)
    vert_of_g[glued] = np.asarray(vert_of)[:len(glued)]   # glued copies are copies of one input vertex
    Fs2 = np.empty_like(Fs)
    Fs2[~tri] = new[Fs[~tri]]
    Fs2[tri] = len(keep) + ginv.reshape(-1, 3)
    isl_keep = np.unique(island[~tri])
    isl2 = np.empty_like(island)
    isl2[~tri] = np.searchsorted(isl_keep, island[~tri])
    isl2[tri] = len(isl_keep) + np.searchsorted(np.unique(piece[tri]), piece[tri])
    return (np.r_[np.asarray(vert_of, np.int64)[keep], vert_of_g[g]], Fs2,
            np.vstack([uvs[keep], np.full((len(g), 2), np.nan)]), isl2)


def _append_closed(F, shut, part, vert_of, Fs, uvs, face_island, n):
    """The split arrays of the open parts (``vert_of`` (N,), ``Fs``, ``uvs`` (N,2), ``face_island`` over
    the open triangles in input order) extended by the closed parts ``shut`` (count,) bool (``part``
    (m,) the part of each triangle of ``F`` (m,3)): their vertices unsplit, their uv NaN (no chart),
    one island each after the open ones. Returns ``(vert_of, Fs (m,3), uvs, face_island (m,))`` over
    all the triangles."""
    closed_f = shut[part]
    cv = np.unique(F[closed_f])
    new = np.full(n, -1, np.int64)
    new[cv] = len(vert_of) + np.arange(len(cv))
    Fs_all = np.empty_like(F)
    Fs_all[~closed_f] = Fs
    Fs_all[closed_f] = new[F[closed_f]]
    isl = np.empty(len(F), np.int64)
    base = int(face_island.max()) + 1 if len(face_island) else 0
    isl[~closed_f] = face_island
    isl[closed_f] = base + np.cumsum(shut)[part[closed_f]] - 1
    return (np.r_[np.asarray(vert_of, np.int64), cv], Fs_all,
            np.vstack([uvs, np.full((len(cv), 2), np.nan)]), isl)


class PathsChart:
    """A part of the mesh answered by surface paths only (no flat chart, no grid): a closed part, or an
    open one the flattening had to cut (``_cut_parts``). ``verts`` (k,) split vertices, ``V`` (k,3),
    ``F`` (mi,3) local triangles, ``faces`` (mi,) input triangles, ``paths_k`` the Steiner points per
    edge (``path_points``; None if the part is too large). ``budget``: for a cut part, the links that
    buy it more points, up to ``PATH_K_MAX`` (``CUT_PATH_BUDGET``: as many as the cost test of
    ``paths_choice`` bought such islands when they were cut charts), if that is more than 9."""

    def __init__(self, V, F, verts, faces, budget=None):
        from ..mesh.topology import unique_edges
        self.V, self.F, self.verts, self.faces = V, F, verts, faces
        m, ne = len(F), len(unique_edges(F)[0])
        self.paths_k = path_points(m, ne)
        if budget is not None:
            self.paths_k = max(self.paths_k or 0, path_points(m, ne, budget, PATH_K[-1], PATH_K_MAX) or 0) \
                or None
        self.size, self.limit, self.nodes, self.metric_passes = 0, None, 0.0, 0
        self.paths_cache = {}               # the surface paths' graphs, built by the first query

    def rasterise(self, mu_mode):
        return self


class PlanarChart:
    """A flat part of the mesh (``plane_coordinates``) answered exactly by shortest paths in its plane
    (``core.geodesic.planar``), with no grid: ``verts`` (k,) split vertices, ``V`` (k,3), ``F`` (mi,3)
    local triangles, ``faces`` (mi,) input triangles, ``paths`` its ``PlanarPaths`` (the plane
    coordinates ``paths.P`` (k,2); it builds the corners' visibility at the first query and keeps it)."""

    def __init__(self, V, F, verts, faces, paths):
        self.V, self.F, self.verts, self.faces, self.paths = V, F, verts, faces, paths
        self.size, self.limit, self.nodes, self.metric_passes, self.paths_k = 0, None, 0.0, 0, None

    def rasterise(self, mu_mode):
        return self

    def distances(self, loc, src_faces, bary):
        """Distances (k,) from the local source vertices ``loc`` (a,) and the points in local faces
        ``src_faces`` (b,) with barycentric coordinates ``bary`` (b,3)."""
        P = self.paths.P
        pts = np.concatenate([P[loc], np.einsum('kc,kcd->kd', bary, P[self.F[src_faces]])])
        return self.paths.distances(pts, np.r_[loc, np.full(len(src_faces), -1)])


def _budget_k(ch, k_max=PATH_K[0]):
    """The most Steiner points per edge up to ``k_max`` (odd) whose graphs fit ``PATH_BUDGET`` on the
    chart ``ch`` (at least ``PATH_K[-1]``); its edge count is counted once and kept with its graphs."""
    if 'n_edges' not in ch.paths_cache:
        from ..mesh.topology import unique_edges
        ch.paths_cache['n_edges'] = len(unique_edges(ch.F)[0])
    return path_points(len(ch.F), ch.paths_cache['n_edges'], k_max=k_max) or PATH_K[-1]


def paths_choice(ch, method, grid, mu_mode):
    """Steiner points per edge (int) if the chart ``ch`` is to be answered by surface paths
    (``core.geodesic.paths``), else None. 'grid': never; 'paths': always (the most ``path_points``
    allows, at least ``PATH_K[-1]``); 'auto' with an automatic grid: the largest odd ``k`` up to
    ``PATH_K_MAX`` whose graph and Richardson's coarse one have at most ``PATH_COST`` links per node
    update of the grid the target asks for (its nodes times its marches; and at most
    ``PATH_BUDGET``), if that ``k`` is at least ``PATH_K[0]`` (at a looser target: at least the fewer
    points it needs, ``target_k``, a query then starting from those, and ``PATH_COST_LOOSE`` links a
    node update, where both methods meet the target and the faster is taken). A link costs about a
    quarter of a node update (spot: 2M links in 0.5 s; a query of its 832-node grid ~1 s for ~1M
    updates), so the paths run where they take at most about half the march's time, with at most as
    many points as that time buys (a query starts from the fewer its target needs, ``start_k``).
    That picks small, coarse islands whose map varies a lot, where the automatic grid grows large
    and its estimate is least reliable (suzanne's face: grid 2240, 0.8-1.9 % mean, 10 s a query), and
    leaves fine meshes to the grid (bump at n = 65: 2.7M links at k = 9 against 0.8M updates).
    'auto' also gives the paths (the most ``path_points`` allows, if any) a chart whose map is so far from
    conformal per triangle that its metric term alone (``ERR_ANISO`` times ``metric_excess``) is
    above half the target: the grid's re-marches do not follow that metric (a given ``uv`` stretched
    by 1.05-1.3: 0.03-0.44 % mean, growing with the grid), the paths do not use the map at all."""
    if method == 'grid' or (method == 'auto' and grid is not None):
        return None
    from ..mesh.topology import unique_edges
    m, ne = len(ch.F), len(unique_edges(ch.F)[0])
    if method == 'paths':
        return path_points(m, ne) or PATH_K[-1]
    if path_points(m, ne, k_min=PATH_K[0]) and path_triangulation(ch.V, ch.F, ch.paths_cache) is not None:
        # thin triangles (needles on a scan's steep flanks): the grid's re-marches undershoot on them
        # and at the boundary beside them (a lifted hemisphere's rim: 2.2 % max, rising with the
        # grid), and the paths search the intrinsic Delaunay triangulation there (0.62 %), from the
        # points the target needs (the scan-like faces refined from 9 to 11-13 on every query)
        return path_points(m, ne, k_min=PATH_K[0], k_max=start_k(ch.target)) or PATH_K[0]
    marches = 1 + (ch.planned_passes if mu_mode == 'metric' else 0)
    # (a target looser than the default needs fewer points, ``target_k``: the paths are weighed at those,
    # and taken where they are about as fast as the grid, ``PATH_COST_LOOSE``)
    k_t = target_k(ch.target)
    cost = PATH_COST if k_t >= PATH_K[0] else PATH_COST_LOOSE
    k = path_points(m, ne, min(PATH_BUDGET, cost * ch.nodes * marches), k_t, PATH_K_MAX)
    if k is None and k_t >= PATH_K[0]:
        # a query at the default target starts from ``start_k`` points (13): the paths also where that
        # pair costs at most ``PATH_COST_LOOSE`` links a node update of the march, as at a looser target
        # (cheburashka's head cut: its 1216 grid 0.84 s a query, 0.056 % worst-set mean; the paths
        # 0.38 s, 0.018 %)
        k = path_points(m, ne, min(PATH_BUDGET, PATH_COST_LOOSE * ch.nodes * marches), start_k(ch.target),
                        PATH_K_MAX)
    if k is None:
        kb = path_points(m, ne)
        # a map the grid cannot follow (its metric term alone above half the target), or a grid held
        # at the cap short of the target whose estimate is over twice the paths' expected error: the
        # paths at the largest k that fits
        if kb is not None and (ERR_ANISO * ch.excess > 0.5 * ch.target or (
                ch.limit == 'cap' and ch.grid_estimate is not None
                and PATH_ERROR_9 * (PATH_K[0] / kb) ** STEINER_ORDER < 0.5 * ch.grid_estimate)):
            return kb
    return k


def marching(charts):
    """True if every chart of ``charts`` (list) is marched on a grid (a ``Chart`` not answered by
    surface paths)."""
    return all(isinstance(ch, Chart) and not ch.paths_k for ch in charts)


def refine_levels(charts, grid, method, given_uv, target, faces):
    """Midpoint subdivisions (0..``REFINE_LEVELS``) of the mesh for a grid the user asks for (``grid``
    given, or ``method`` 'grid') on the solver's own map (``given_uv`` False), where the largest metric
    term (``ERR_ANISO`` times ``metric_excess``, which halves with each) of the ``charts`` that march is
    above ``REFINE_TRIGGER`` of ``target``: the fewest that bring it within ``REFINE_SHARE`` of it, as
    long as the ``faces`` triangles, four times as many a level, stay within ``REFINE_MAX_FACES``, and
    only when every chart marches (``marching``: the whole mesh is subdivided). The re-marches do not
    follow a metric far from conformal on the triangles, and that error does not fall with the grid
    (spot's head cut: 0.11, 0.08, 0.09, 0.11 % mean at 512-4096, its far source rising); on the finer
    triangles of the same surface it does. 'auto' with an automatic grid answers such charts by
    surface paths instead."""
    if given_uv or (grid is None and method != 'grid'):
        return 0
    if not marching(charts):
        # a part answered by surface paths (or exactly, in its plane) would only get slower paths on
        # the finer mesh (suzanne's head by its seams: 0.04 -> 0.05 %)
        return 0
    term = max((ERR_ANISO * ch.excess for ch in charts), default=0.0)
    if not term > REFINE_TRIGGER * target:
        return 0
    levels = min(REFINE_LEVELS, int(np.ceil(np.log2(term / (REFINE_SHARE * target)))))
    while levels and faces * 4 ** levels > REFINE_MAX_FACES:
        levels -= 1
    return levels


class Chart:
    """One island's flat chart and its rasterised ``mu``, kept for any number of queries.

    ``verts`` (k,) the split vertices of the island (indices into the solver's split arrays);
    ``V`` (k,3) their positions; ``F`` (mi,3) the island's triangles in local indices; ``faces`` (mi,)
    their indices in the input ``F``; ``uv`` (k,2) the map, rotated to its smallest bounding
    rectangle; ``mu_face`` (mi,) realised per-triangle scale; ``spread`` (``mu_spread``), ``reflex``
    (``reflex_turning``); ``size`` the grid size and ``limit`` (None, 'cap', 'mesh' or 'budget': what
    kept the automatic grid from the target). After ``rasterise``: ``grid`` (``Grid``) with ``mu``,
    ``inv_mu``, ``valid`` and ``march_on`` (ny, nx); ``P`` (k,2) node coordinates of the vertices;
    ``cell`` the mean grid cell in surface units; ``error_estimate`` (mean relative, at the typical
    distance; a query re-estimates it from its own distances)."""

    def __init__(self, V, F, uv, verts, faces, grid, target, mu_mode='metric', align=True):
        self.verts, self.faces, self.V, self.F = verts, faces, V, F
        self.paths_k = None                     # set by the solver: Steiner points if paths answer
        self.paths_cache = {}                   # the surface paths' graphs, built by the first query
        self.uv = uv = align_uv(uv) if align else uv
        self.mu_face = mu_f = face_mu(V, F, uv)
        self.area = face_areas(V, F)
        # the mesh terms of the error: the smooth mu's spread (none when marching with the exact
        # per-triangle metric), and the metric's anisotropy, which no march here follows exactly
        self.spread = 0.0 if mu_mode == 'metric' else mu_spread(F, mu_f, self.area)
        self.metric_inv = face_metric_inverse(V, F, uv)
        self.excess = metric_excess(metric_anisotropy(self.metric_inv), self.area)
        self.reflex = reflex_turning(uv, F)
        self.target = target
        self.limit, self.grid_estimate = None, None
        # re-marches with the exact metric: as few as the target allows on an automatic grid, all of
        # them on a given one (its error then falls with the grid)
        self.given = grid is not None                   # a grid the user gave: its error should fall with it
        self.planned_passes = METRIC_PASSES if self.given else metric_passes_for(self.excess, target)
        if grid is None:
            grid, self.limit, self.grid_estimate = default_grid_for_target(V, F, uv, mu_f, self.spread,
                                                                           self.reflex, target)
        self.size = int(grid)
        ext = np.ptp(uv, axis=0)
        self.nodes = float(self.size) ** 2 * float(ext.min() / ext.max())       # about, for the budget

    def rasterise(self, mu_mode):
        """Build the grid of ``size`` nodes and the fields on it (see the class docstring)."""
        uv, F, mu_f = self.uv, self.F, self.mu_face
        G = Grid(uv, self.size).rasterise(uv, F)
        self.valid = valid = G.rim(RIM)
        if mu_mode in ('vertex', 'metric'):
            mu = G.interpolate(uv, F, vertex_mu(F, mu_f, self.area, len(self.V)))
        else:
            mu = G.interpolate(uv, F, face_values=mu_f)
        self.mu = np.where(valid, np.clip(mu, mu_f.min(), mu_f.max()), 1.0)
        self.mu_slope = log_mu_slope(self.mu, valid, G.h)
        self.ginv = self.metric_inv if mu_mode == 'metric' else None
        if self.ginv is not None:
            # the re-marches change nothing where every triangle is conformal and mu is the same on all
            # of them (an isometric map of a planar mesh): skip them there
            a, b, c = self.ginv.T
            lv = np.log(vertex_mu(F, mu_f, self.area, len(self.V)))
            dev = (np.abs(a - c) + 2 * np.abs(b)) / (a + c) + np.abs(lv[F] - np.log(mu_f)[:, None]).max(1)
            if float(dev.max()) < 1e-6:
                self.ginv = None
        E = mean_edges(self.V, F)
        fine = (G.h / mu_f) < 0.5 * E
        gap_in, gap_rim = boundary_bridges(G, uv, F, valid, fine)
        self.gap = gap_in
        self.corner_ok = sample_corners(G, F, G.coords(uv), fine)
        self.march_on = valid & ~bridging_rim(G, F, valid) & ~self.gap & ~gap_rim
        self.metric_passes = self.planned_passes if self.ginv is not None else 0
        self.seed_metric = None
        if self.ginv is not None:
            a, b, c = self.ginv.T
            # (a triangle the map squashes to a needle has det 0 to round-off, or below it: a huge, finite
            # metric, its condition at most about 1e12; ((a + c) / 2)^2 bounds det, and stays positive
            # where round-off leaves a = 0)
            det = np.maximum(a * c - b * b, 1e-12 * (0.5 * (a + c)) ** 2 + np.finfo(float).tiny)
            self.seed_metric = (G.face, np.stack([c / det, -b / det, a / det], 1))     # G = (G^-1)^-1
        # triangles the grid does not resolve (surface cell above UNRESOLVED times their mean edge):
        # their vertices take on-mesh fast marching from the resolved ones (``MeshRelax``)
        self.unresolved = unresolved_faces(mu_f, E, G.h)
        self.free_frac = float(self.area[self.unresolved].sum() / self.area.sum())
        self.free = None
        if self.unresolved.any():
            self.free = np.zeros(len(self.V), bool)
            self.free[F[self.unresolved].ravel()] = True
            self.relax = MeshRelax(self.V, F, np.flatnonzero(self.free[F].any(1)))
        self.inv_mu = 1.0 / self.mu
        self.grid = G
        self.P = G.coords(uv)
        self.cell = surface_cell(mu_f, self.area, G.h, ~self.unresolved)
        self.error_estimate = error_estimate(self.cell, typical_distance(self.V), self.spread, self.reflex,
                                             self.free_frac, self.excess, self.metric_passes)
        return self

    def node_points(self, ii, jj):
        """3D positions (q,3) of grid nodes (``ii``, ``jj``) (q,), each in the plane of its triangle
        (``grid.face``; rim nodes extrapolate their neighbour's), and that triangle (q,)."""
        f = self.grid.face[ii, jj]
        W = self.P[self.F[f]]                                  # (q,3,2) node coordinates
        e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
        det = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
        dx, dy = jj - W[:, 0, 0], ii - W[:, 0, 1]
        b1 = (dx * e2[:, 1] - dy * e2[:, 0]) / det
        b2 = (e1[:, 0] * dy - e1[:, 1] * dx) / det
        X = self.V[self.F[f]]
        return X[:, 0] + b1[:, None] * (X[:, 1] - X[:, 0]) + b2[:, None] * (X[:, 2] - X[:, 0]), f


# --------------------------------------------------------------------------------------------------
def _check_mesh_arrays(V, F):
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or not len(F):
        raise ConformalError("expected V (n,3) positions and F (m,3) triangles", 'invalid_input')
    if F.min() < 0 or F.max() >= len(V):
        raise ConformalError("a triangle refers to a vertex that does not exist", 'invalid_input')
    if not np.isfinite(V[np.unique(F)]).all():
        raise ConformalError("some vertex coordinates are NaN or infinite", 'bad_coordinates',
                             'fix_coordinates')
    return V, F


def _parse_sources(n, m, sources, points):
    """Validated vertex sources (k,) int64 and surface points (faces (p,) int64, barycentric (p,3))."""
    s = np.zeros(0, np.int64)
    if sources is not None:
        s = np.atleast_1d(np.asarray(sources))
        if s.size:
            if not np.issubdtype(s.dtype, np.integer):
                raise ConformalError("source vertices must be integer indices")
            if s.min() < 0 or s.max() >= n:
                raise ConformalError(f"source vertex out of range: the mesh has {n} vertices (0..{n - 1})")
        s = s.astype(np.int64).ravel()
    pf, pb = np.zeros(0, np.int64), np.zeros((0, 3))
    if points is not None:
        pf = np.atleast_1d(np.asarray(points[0], np.int64))
        pb = np.atleast_2d(np.asarray(points[1], np.float64))
        if pb.shape != (len(pf), 3):
            raise ConformalError("surface points need one face index and 3 barycentric coordinates each")
        if len(pf) and (pf.min() < 0 or pf.max() >= m):
            raise ConformalError(f"source face out of range: the mesh has {m} triangles")
        if not np.allclose(pb.sum(1), 1.0, atol=1e-6) or (pb < -1e-9).any():
            raise ConformalError("barycentric coordinates must be non-negative and sum to 1")
    if not len(s) and not len(pf):
        raise ConformalError("no source given: pass at least one source vertex or surface point")
    return s, pf, pb


class GeodesicSolver:
    """Geodesic distances on one mesh from any sources: flattening, grids and rasterised ``mu`` are
    computed once here and reused by every ``distance`` call.

    V (n,3) float, F (m,3) int triangles. ``uv`` (n,2): a fold-free conformal map to reuse (any scale;
    each connected part is its own chart); None flattens: a single part without ``seams`` with
    ``core.disk.flatten`` (``boundary`` 'uniform', 'area' or 'free'), else (several parts, seams,
    holes, loose vertices) every island of ``core.atlas.islands.unwrap`` (holes filled virtually;
    ``seams`` (k,2) vertex pairs cut the surface; distances are measured
    on the cut surface). Distances between islands are infinite. A closed part that no seam touches
    has no flat chart: surface paths answer it on the closed surface (``PathsChart``), unless
    ``method`` is 'grid' (then it needs seams or sphere mode). ``grid``: nodes along the longer UV
    side of every chart (64..4096), None: per chart from ``error_target`` (``default_grid_for_target``).
    ``solver``: 'auto' (scikit-fmm if installed, else the numpy sweep), 'skfmm' or 'sweep'.
    ``mu_mode``: 'metric' (default: a first march with the per-vertex mu interpolated linearly, then
    ``METRIC_PASSES`` re-marches with the exact per-triangle metric of the map for the previous
    march's gradient directions, ``directional_mu``, on an automatic grid only as many as
    ``error_target`` needs, ``metric_passes_for``; skipped on charts where the map is an exact
    similarity), 'vertex' (the first march only) or 'face' (piecewise constant per-triangle mu).
    An island that the solver's own flattening folds (flipped triangles) is answered by surface
    paths, which need no map (``report['folded_parts']``), unless a grid or ``method`` 'grid' is asked
    for; a given ``uv`` that folds is an error. So is a single open part pinched at a vertex
    (``report['pinched_parts']``): the paths go through the pinch, which a flattening would split.
    ``error_target``: the estimated mean relative error to reach (default 1e-3); a chart
    whose estimate stays above it gets a warning in every report. ``progress(fraction, message)``:
    optional callback. ``method``: 'grid' marches on every chart; 'paths' answers every island by
    shortest surface paths through Steiner points (``core.geodesic.paths.surface_paths``, at least
    ``PATH_K[-1]`` points per edge); 'auto' (default) takes the paths on an island where they are
    cheaper than the grid its error target needs (``paths_choice``: small, coarse islands whose map
    varies a lot, where the grid grows large and still misses, such as suzanne's), else the grid.
    ``steiner_points``: the Steiner points per edge (odd, 3..``PATH_K_MAX``) on every island answered by
    surface paths, without refinement toward ``error_target`` (a speed and accuracy knob: fewer points
    answer faster and less accurately; the estimate still says how well); None (default): chosen per
    island and refined toward the target. Raises ``ConformalError``.

    Attributes: ``charts`` (list of ``Chart``), ``vert_of`` (N,) input vertex of each split vertex,
    ``face_island`` (m,), ``report`` (dict: set-up figures, including ``seconds`` {flatten,
    rasterise})."""

    def __init__(self, V: np.ndarray, F: np.ndarray, uv: np.ndarray | None = None, boundary: str = 'uniform',
                 grid: int | None = None, solver: str = 'auto', mu_mode: str = 'metric',
                 seams: np.ndarray | None = None, error_target: float = ERROR_TARGET, progress=None,
                 method: str = 'auto', steiner_points: int | None = None, refine: bool = True):
        say = progress or (lambda f, msg: None)
        if method not in METHODS:
            raise ConformalError(f"unknown method {method!r}: use one of {', '.join(METHODS)}")
        if steiner_points is not None and not (isinstance(steiner_points, (int, np.integer))
                                               and 3 <= steiner_points <= PATH_K_MAX and steiner_points % 2):
            raise ConformalError(f"steiner_points must be an odd number of points per edge from 3 to "
                                 f"{PATH_K_MAX}, got {steiner_points!r}")
        self.steiner_points = None if steiner_points is None else int(steiner_points)
        t0 = time.perf_counter()
        V, F = _check_mesh_arrays(V, F)
        if mu_mode not in MU_MODES:
            raise ConformalError(f"unknown mu_mode {mu_mode!r}: use one of {', '.join(MU_MODES)}")
        if not (np.isfinite(error_target) and error_target > 0):
            raise ConformalError(f"error_target must be a positive fraction, got {error_target}")
        if grid is not None and not GRID_MIN <= int(grid) <= GRID_MAX:
            raise ConformalError(f"grid size {grid} is out of range: use {GRID_MIN}..{GRID_MAX} nodes")
        self.solver = resolve_solver(solver)
        self.mu_mode, self.error_target = mu_mode, float(error_target)
        self.n, self.m = len(V), len(F)
        self.V, self.F = V, F
        self.on_mesh = np.zeros(self.n, bool)
        self.on_mesh[F.ravel()] = True
        self.turned = None                             # (m,) faces turned to one orientation, or None
        cut_face = np.zeros(len(F), bool)              # triangles of parts answered uncut (``_cut_parts``)
        report = {'mu_mode': mu_mode, 'error_target': self.error_target}
        seconds = {}
        if uv is not None:
            if seams is not None:
                raise ConformalError("seams need the solver to flatten: pass uv=None with seams")
            uv = np.asarray(uv, np.float64)
            if uv.shape != (self.n, 2) or not np.isfinite(uv[self.on_mesh]).all():
                raise ConformalError(f"uv must be ({self.n},2) finite coordinates, got shape {uv.shape}")
            from ..mesh.topology import face_components
            count, face_island = face_components(F, self.n)
            vert_of, Fs, uvs = np.arange(self.n), F, uv
            report['boundary'] = 'given'
        else:
            from ..mesh.topology import face_components
            from ..mesh.repair import oriented_faces
            F2 = oriented_faces(V, F)
            self.turned = None if F2 is F else (F2 != F).any(1)
            F = self.F = F2
            count, face_island = face_components(F, self.n)
            # closed parts (no boundary edge) that no seam touches have no flat chart: surface paths
            # answer them on the closed surface (``method`` 'grid' keeps the error that asks for seams)
            shut = np.zeros(count, bool)
            if method != 'grid':
                shut = closed_parts(F, count, face_island) & ~_seamed_parts(F, seams, self.n, count,
                                                                            face_island)
            part = face_island
            shut_cut = 0                                # parts in ``shut`` that are cut open ones
            say(0.0, 'flattening')
            from ..mesh.topology import boundary_loops
            Fo = F[~shut[face_island]]
            single = bool(len(Fo)) and count == 1 and seams is None and self.on_mesh.all()
            pinched = single and _pinched(F, self.n)
            if not len(Fo):
                vert_of, Fs, uvs, face_island = np.zeros(0, np.int64), Fo, np.zeros((0, 2)), \
                    np.zeros(0, np.int64)
            elif pinched and method != 'grid' and _fits_paths(F):
                # a disk pinched at a vertex (two fans of triangles touch there): a flattening would
                # split the vertex, and paths through it would be lost; the surface paths take the
                # surface as it is
                shut[:] = cut_face[:] = True
                shut_cut = 1
                report['cut_parts'], report['pinched_parts'] = 1, 1
                vert_of, Fs, uvs, face_island = np.zeros(0, np.int64), Fo[:0], np.zeros((0, 2)), \
                    np.zeros(0, np.int64)
            elif single and not pinched and len(boundary_loops(F, self.n)) == 1:
                from ..atlas.islands import boundary_crossings
                from ..disk.flatten import flatten
                res = flatten(V, F, boundary=boundary, fit='true_scale', bound=False, exact=False)
                vert_of, Fs, uvs = np.arange(self.n), F, res.uv
                report['mu_ratio'] = res.report.get('mu_ratio')
                folded = boundary_crossings(res.uv, boundary_loops(F, self.n)) > 0
                if folded and method != 'grid' and _fits_paths(F):
                    # the map overlaps itself (a ramp of more than a turn): no grid can hold it (a few
                    # flipped triangles without an overlap reach the chart, which sends the island to
                    # surface paths too: ``folded_parts``)
                    shut[:] = cut_face[:] = True
                    shut_cut = 1
                    report['cut_parts'] = 1
                    vert_of, Fs, uvs, face_island = np.zeros(0, np.int64), Fo[:0], np.zeros((0, 2)), \
                        np.zeros(0, np.int64)
                elif folded:
                    report['folded_chart'] = True
            else:
                from ..atlas.islands import unwrap
                # holes filled virtually (a hole cut open would be a wall the distances cannot cross)
                res = unwrap(V, Fo, seams=seams, boundary=boundary, fit='true_scale', pack=False,
                             allow_loose=True, holes='fill', exact=False)
                vert_of, Fs, uvs, face_island = res.vert_of, res.F, res.uv, res.face_island
                if method != 'grid':
                    # pieces the flattening cut all the same (a filled map that overlapped and was split
                    # into charts, or halved): surface paths on the whole piece instead, glued back
                    piece, cut, glued = _cut_parts(Fo, res, seams, self.n)
                    if cut.any():
                        vert_of, Fs, uvs, face_island = _paths_pieces(vert_of, Fs, uvs, face_island, piece,
                                                                      cut, glued)
                        cut_face[~shut[part]] = cut[piece]
                    report['cut_parts'] = int(cut.sum())
                else:
                    report['cut_parts'] = 0
            if shut.any():
                vert_of, Fs, uvs, face_island = _append_closed(F, shut, part, vert_of, Fs, uvs, face_island,
                                                               self.n)
            count = int(face_island.max()) + 1
            report['boundary'] = boundary
            report['closed_parts'] = int(shut.sum()) - shut_cut
            seconds['flatten'] = time.perf_counter() - t0
        say(0.3, 'rasterising')
        t = time.perf_counter()
        self.vert_of, self.Fs = np.asarray(vert_of, np.int64), np.asarray(Fs, np.int64)
        self.face_island = np.asarray(face_island, np.int64)
        Vs = V[self.vert_of]
        self.Vs = Vs
        N = len(self.vert_of)
        self.chart_of_split = np.full(N, -1, np.int64)
        self.local_of_split = np.full(N, -1, np.int64)
        self.charts = []
        order = np.argsort(face_island, kind='stable')
        cuts = np.flatnonzero(np.diff(face_island[order])) + 1
        exact_flat = method == 'auto' and grid is None and self.steiner_points is None
        for c, faces in enumerate(np.split(order, cuts)):
            Fg = self.Fs[faces]
            verts, Fl = np.unique(Fg, return_inverse=True)
            Fl = Fl.reshape(-1, 3)
            if not np.isfinite(uvs[verts]).all():          # a closed or cut part (``_append_closed``)
                ch = PathsChart(Vs[verts], Fl, verts, faces, CUT_PATH_BUDGET if cut_face[faces[0]] else None)
                if ch.paths_k is None:
                    from ..mesh import topology
                    genus = topology.genus(topology.euler_characteristic(Fl))
                    raise ConformalError(
                        f"island {c + 1} of {len(cuts) + 1} ({len(faces)} triangles) is closed" +
                        (f", has genus {genus}" if genus > 0 else "") + " and is too large for surface paths",
                        'no_boundary', 'seam_handles' if genus > 0 else 'mark_seams')
            else:
                # a flat island in its plane, or with no interior vertex (a hair card bent out of its
                # plane, a strip) in its isometric unfolding: a flat domain with the same distances
                P = None
                if exact_flat:
                    P = plane_coordinates(Vs[verts], Fl)
                    P = unfold_flat_disk(Vs[verts], Fl) if P is None else P
                flat = planar_paths(P, Fl) if P is not None else None
                if flat is not None:            # a flat island: exact, no grid (``PlanarChart``)
                    if report['boundary'] == 'given':
                        face_mu(Vs[verts], Fl, uvs[verts])      # a given map is checked all the same
                    ch = PlanarChart(Vs[verts], Fl, verts, faces, flat)
                else:
                    try:
                        ch = Chart(Vs[verts], Fl, uvs[verts], verts, faces, grid, self.error_target, mu_mode)
                    except ConformalError as exc:
                        own = report['boundary'] != 'given'
                        if not (exc.code == 'degenerate' and own and method != 'grid' and grid is None
                                and _fits_paths(Fl)):
                            raise (exc.with_context(f"island {c + 1} of {len(cuts) + 1} ({len(faces)} "
                                                    "triangles)") if len(cuts) else exc) from None
                        # the solver's own flattening folded this island (a few flipped triangles): the
                        # surface paths need no map (a cap cut from cheburashka: 1 flipped triangle)
                        ch = PathsChart(Vs[verts], Fl, verts, faces)
                        report['folded_parts'] = report.get('folded_parts', 0) + 1
            self.chart_of_split[verts] = c
            self.local_of_split[verts] = np.arange(len(verts))
            self.charts.append(ch)
        for ch in self.charts:
            if isinstance(ch, (PathsChart, PlanarChart)):
                continue
            ch.paths_k = paths_choice(ch, method, grid, mu_mode)
            if ch.paths_k:                      # a token grid: the island is answered by paths
                ch.size, ch.limit, ch.nodes = GRID_MIN, None, float(GRID_MIN) ** 2
        self.fine = None
        levels = refine_levels(self.charts, grid, method, uv is not None, self.error_target, len(F)) \
            if refine else 0
        if levels:
            # a grid on a map far from conformal per triangle: the same surface on finer triangles
            # (``refine_levels``); queries go to that solver, and this one keeps the input's numbering
            # (``vert_of``, ``charts``, the edge graph) without grids of its own
            try:
                self.fine = _FinerSolver(V, F, seams, levels, dict(
                    boundary=boundary, grid=grid, solver=solver, mu_mode=mu_mode, error_target=error_target,
                    progress=progress, method=method, steiner_points=steiner_points))
            except ConformalError as exc:       # the coarse charts answer, with their warning
                report['refine_failed'] = str(exc)
            else:
                fine = self.fine.solver
                if len(fine.charts) != len(self.charts) or not marching(fine.charts):
                    # the finer map came out otherwise (an island whose map now overlaps itself is
                    # answered by surface paths there): the grid the user asked for marches here
                    report['refine_failed'] = "the finer triangles' map has other charts"
                    self.fine = None
                else:
                    report['refined'] = {'levels': levels, 'triangles': int(len(fine.F))}
                    seconds['refine'] = self.fine.seconds
        if grid is None:                        # automatic grids: all islands within the node budget
            total = sum(ch.nodes for ch in self.charts)
            if total > NODE_BUDGET:
                k = np.sqrt(NODE_BUDGET / total)
                for ch in self.charts:
                    if isinstance(ch, Chart) and not ch.paths_k:
                        ch.size = int(max(GRID_MIN, 64 * np.floor(ch.size * k / 64)))
                        ch.limit = ch.limit or 'budget'
        for ch in self.charts:
            if self.fine is None:
                ch.rasterise(mu_mode)
        # the edge graph of the cut surface, for the upper bound (Dijkstra)
        self.graph = edge_graph(Vs, self.Fs, N)
        seconds['rasterise'] = time.perf_counter() - t
        self.report = report
        self.seconds = seconds

    # ----------------------------------------------------------------------------------------------
    def _warning(self, chart, est, k_used=None):
        """The warning for ``chart`` (index) whose estimate ``est`` is above the target, or None;
        ``k_used``: the Steiner points per edge its surface paths took (None: it marched)."""
        if est <= self.error_target:
            return None
        ch = self.charts[chart]
        where = f" on island {chart + 1} of {len(self.charts)}" if len(self.charts) > 1 else ""
        if ch.paths_k:
            return f"estimated mean error {100 * est:.3g}%{where} is above the target " \
                f"{100 * self.error_target:.3g}% ({self._paths_limit(ch, k_used)}"
        msg = (f"estimated mean error {100 * est:.3g}%{where} is above the target "
               f"{100 * self.error_target:.3g}% (grid {ch.size}")
        if ERR_ANISO * ch.excess > 0.5 * self.error_target:
            return msg + (f"; the map alone accounts for {100 * ERR_ANISO * ch.excess:.2g}%: it is far from "
                          f"conformal on its triangles, mean anisotropy {1 + ch.excess:.3g}): use the "
                          "automatic grid (surface paths answer such a map), or a conformal map (uv=None)")
        if ch.limit == 'mesh' or ERR_MESH * ch.spread > 0.5 * self.error_target:
            return msg + (f"; the mesh alone accounts for {100 * ERR_MESH * ch.spread:.2g}%: its conformal "
                          "factor varies too much across triangles): subdivide the mesh, or use a more "
                          "uniform map (boundary 'uniform')")
        if ch.limit == 'cap':
            msg += f", the automatic grid is capped at {GRID_AUTO_MAX}"
        elif ch.limit == 'budget':
            msg += f", the islands' automatic grids share a budget of {NODE_BUDGET:,} nodes"
        return msg + "): use a larger grid, or a more uniform map (boundary 'uniform')"

    def _paths_limit(self, ch, k):
        """What held the surface paths of the chart ``ch`` at ``k`` Steiner points per edge, and what to
        do, for ``_warning``. The memory budget buys about ``sqrt(PATH_BUDGET / 3 m)`` points per edge
        on ``m`` triangles and the paths' error falls as ``k^-STEINER_ORDER`` (``target_k``): on the same
        surface, more triangles (a subdivision) leave fewer points and a larger error, fewer triangles
        more points."""
        k = k or ch.paths_k
        if self.steiner_points:
            return (f"surface paths at {k} Steiner points per edge, as asked): use more points per edge, "
                    "or let the tool choose them for the target (steiner_points=None)")
        n_edges = ch.paths_cache.get('n_edges') or len(mesh_edges(ch.F)[0])
        if k < PATH_K_MAX and path_points(len(ch.F), n_edges, k_min=k + 2, k_max=PATH_K_MAX) is None:
            return (f"surface paths at {k} Steiner points per edge, the most the memory budget allows on "
                    f"{len(ch.F):,} triangles): raise the error target, or use a mesh with fewer triangles "
                    "(a finer mesh leaves fewer points per edge and a larger error)")
        return f"surface paths at {k} Steiner points per edge): raise the error target"

    def _upper_bound(self, src_split, pf, pb):
        """Shortest edge-path lengths (N,) on the cut surface from the split source vertices and the
        surface points (faces ``pf``, barycentric ``pb``): an upper bound of the geodesic distance."""
        from scipy.sparse.csgraph import dijkstra
        G = self.graph
        N = G.shape[0]
        if len(pf):
            import scipy.sparse as sp
            k = len(pf)
            corners = self.Fs[pf]                                            # (k,3)
            X = np.einsum('kc,kcd->kd', pb, self.Vs[corners])
            w = np.maximum(np.linalg.norm(self.Vs[corners] - X[:, None], axis=2), 1e-300)
            rows = np.repeat(N + np.arange(k), 3)
            A = sp.coo_matrix((w.ravel(), (rows, corners.ravel())), shape=(N + k, N + k))
            G = (sp.block_diag([G, sp.csr_matrix((k, k))]) + A).tocsr()
            idx = np.r_[src_split, N + np.arange(k)]
        else:
            idx = src_split
        return dijkstra(G, directed=True, indices=idx, min_only=True)[:N]

    def distance(self, sources=None, points=None, source_radius: float | None = None, calibrate: bool = True,
                 clamp: bool = True, progress=None) -> tuple[np.ndarray, dict]:
        """Geodesic distances (n,) from the nearest source, in mesh units.

        ``sources``: vertex indices (k,); ``points``: surface points as (faces (p,), barycentric
        (p,3)); at least one in all. ``source_radius``: exact seed disk radius in grid cells (None:
        ``SEED_RADIUS``, or ``SWEEP_SEED_RADIUS`` for the sweep; ``seed_radius`` may reduce it).
        ``calibrate``: exact scikit-fmm start values on the seed rim (``calibrate_phi``). ``clamp``:
        bound every vertex by the 3D distance below and the edge-path distance above.

        Returns ``(dist, report)``: ``dist`` (n,) float64: NaN at vertices in no triangle, inf on
        islands without a source. ``report``: grid [ny, nx] (the largest chart), cell (UV units),
        masked_fraction, solver, sources, seed_radius (cells), on_mesh (vertices given on-mesh fast
        marching from the resolved ones: ``MeshRelax``), marches, metric_passes, islands, islands_reached,
        error_estimate (mean relative, dimensionless), error_target, clamped {below_euclid,
        above_edges} (vertex counts), filled_from_edges (vertices no grid node reached, given edge
        paths from their neighbours), paths_islands (islands answered by surface paths), paths_fallback
        (of those, grid islands where a source lay too coarse to seed: warned), planar_islands (flat
        islands answered exactly in their plane: ``PlanarChart``), warnings (list of str),
        seconds {rasterise, solve, sample, total} and, for the set-up, flatten. Raises
        ``ConformalError``."""
        say = progress or (lambda f, msg: None)
        t0 = time.perf_counter()
        if source_radius is None:
            source_radius = SEED_RADIUS if self.solver == 'skfmm' else SWEEP_SEED_RADIUS
        if not source_radius >= 1.0:
            raise ConformalError("source_radius must be at least 1 grid cell")
        s, pf, pb = _parse_sources(self.n, self.m, sources, points)
        if len(pf) and self.turned is not None:
            pb = np.where(self.turned[pf, None], pb[:, ::-1], pb)        # the corners of turned faces
        if self.fine is not None:                       # the same surface on finer triangles
            return self.fine.distance(self.n, self.m, self.report['refined'], s, pf, pb,
                                      source_radius=source_radius, calibrate=calibrate, clamp=clamp,
                                      progress=progress)
        if len(s) and not self.on_mesh[s].all():
            raise ConformalError(f"source vertex {int(s[~self.on_mesh[s]][0])} is in no triangle")
        is_src = np.isin(self.vert_of, s)                       # split copies of the source vertices
        src_split = np.flatnonzero(is_src)
        # 3D positions of all sources (vertices and points) for the Euclidean bound
        X_src = np.concatenate([self.V[s], np.einsum('kc,kcd->kd', pb, self.Vs[self.Fs[pf]])])
        from scipy.spatial import cKDTree
        tree = cKDTree(X_src)
        by_vertex = np.argsort(s, kind='stable')               # X_src row of a source vertex, by search
        upper = self._upper_bound(src_split, pf, pb) if clamp else None
        N = len(self.vert_of)
        dist_s = np.full(N, np.inf)
        marches, radii, reached = 0, [], 0
        hybrid, refined = 0, 0
        path_est, path_k, paths_used, unseeded, thin, planar = {}, [], {}, [], [], []
        active = np.unique(np.r_[self.chart_of_split[src_split], self.face_island[pf]]).astype(np.int64)
        for k, c in enumerate(active):
            say(0.05 + 0.85 * k / len(active), 'marching')
            ch = self.charts[c]
            loc = self.local_of_split[src_split[self.chart_of_split[src_split] == c]]
            mine = self.face_island[pf] == c
            src_faces = np.searchsorted(ch.faces, pf[mine]) if mine.any() else np.zeros(0, np.int64)
            if isinstance(ch, PlanarChart):             # a flat island: exact
                dist_s[ch.verts] = ch.distances(loc, src_faces, pb[mine])
                planar.append(c)
                reached += 1
                continue
            # rows of X_src of this chart's sources, in S_uv's order (a refined seed must not claim
            # vertices that another source is nearer to)
            sel = self.vert_of[src_split[self.chart_of_split[src_split] == c]]
            own = np.r_[by_vertex[np.searchsorted(s[by_vertex], sel)], len(s) + np.flatnonzero(mine)]
            d = None
            coarse = not ch.paths_k and ch.free is not None and \
                (ch.free[loc].any() or ch.unresolved[src_faces].any())
            if not ch.paths_k and not coarse:
                S_uv = ch.uv[loc]
                if mine.any():
                    S_uv = np.concatenate([S_uv, np.einsum('kc,kcd->kd', pb[mine], ch.uv[ch.F[src_faces]])])
                try:
                    d, r, nm, _, nf = self._march_chart(ch, S_uv, loc, src_faces, tree, X_src, upper,
                                                        source_radius, calibrate, own=own)
                except _Unseeded:
                    coarse = True
            if d is None:
                # an island answered by surface paths: by choice (``paths_choice``), or because a source
                # lies where the grid does not resolve the surface (a cell larger than the triangles
                # there, or no node inside its exact seed: the march from there misses by percents)
                if not ch.paths_k:
                    unseeded.append(c)
                # the points asked for (as many as the memory budget allows), the chart's own, or for an
                # unseeded grid chart the most up to PATH_K[0] that fit
                k0 = _budget_k(ch, self.steiner_points) if self.steiner_points else \
                    ch.paths_k or _budget_k(ch)
                if not self.steiner_points:
                    # the points the target needs (``start_k``), if fewer than the chart's: the estimate
                    # of the answer decides whether the query refines
                    k0 = min(k0, start_k(self.error_target))
                Xp = np.einsum('kc,kcd->kd', pb[mine], ch.V[ch.F[src_faces]]) if mine.any() else None
                d, path_est[c], k_used = surface_paths(ch.V, ch.F, loc, k0, X=Xp,
                                                       faces=src_faces if mine.any() else None,
                                                       target=None if self.steiner_points else
                                                       self.error_target, cache=ch.paths_cache,
                                                       fit_grading=not self.steiner_points)
                path_k.append(k_used)
                paths_used[c] = k_used
                thin.append(thin_warning(ch.paths_cache.get('short'),
                                         f" on island {c + 1} of {len(self.charts)}" if len(self.charts) > 1
                                         else ""))
                dist_s[ch.verts] = d
                reached += 1
                continue
            refined += nf
            if ch.free is not None:
                hybrid += int(ch.free.sum())
            dist_s[ch.verts] = d
            marches += nm
            radii.append(r)
            reached += 1
        t = time.perf_counter()
        filled = self._fill_unreached(dist_s, active)
        clamped = {'below_euclid': 0, 'above_edges': 0}
        if clamp:
            E, _ = tree.query(self.Vs)
            fin = np.isfinite(dist_s)
            low = fin & (dist_s < E)
            high = fin & (dist_s > upper)
            # counted where the bound moves a value by more than round-off (an exact planar island's
            # values meet the Euclidean bound to the last bits where the source is in plain view)
            clamped = {'below_euclid': int((low & (dist_s < E * (1 - 1e-12))).sum()),
                       'above_edges': int((high & (dist_s > upper * (1 + 1e-12))).sum())}
            dist_s = np.where(low, E, dist_s)
            dist_s = np.where(high, upper, dist_s)
        dist = np.full(self.n, np.inf)
        np.minimum.at(dist, self.vert_of, dist_s)
        dist[~self.on_mesh] = np.nan
        t_sample = time.perf_counter() - t
        # the grid reported is the largest of the charts that marched (an island answered by paths or
        # in its plane keeps an unused grid: reporting it named a grid no distance came from)
        marched = [self.charts[c] for c in active if c not in path_est and c not in planar]
        G = max(marched, key=lambda ch: ch.size) if marched else None
        if G is not None and not G.size:
            G = None
        ny, nx = G.grid.shape if G is not None else (0, 0)
        # the error estimate of each reached chart, at the median distance of this query
        ests = []
        for c in active:
            ch = self.charts[c]
            if c in path_est:
                ests.append(path_est[c])
                continue
            if c in planar:                             # exact up to round-off
                ests.append(0.0)
                continue
            dc = dist_s[ch.verts]
            dc = dc[np.isfinite(dc) & (dc > 0)]
            ests.append(error_estimate(ch.cell, float(np.median(dc)) if len(dc) else 0.0, ch.spread,
                                       ch.reflex, ch.free_frac, ch.excess, ch.metric_passes))
        est = max(ests)
        warnings = [self._warning(c, e, paths_used.get(c)) for c, e in zip(active, ests)]
        warnings = [w for w in warnings + thin if w]
        if unseeded:
            where = "" if len(self.charts) == 1 else \
                f" on island{'s' if len(unseeded) > 1 else ''} {', '.join(str(c + 1) for c in unseeded)}"
            warnings.append(f"a source lies where the grid does not resolve the surface{where} (its cells "
                            "are larger than the triangles there): those distances come from surface paths "
                            "on the mesh instead; use a larger grid, or a more uniform map (cones, seams)")
        if self.report.get('folded_chart'):
            warnings.append("the flat map of the mesh overlaps itself, so one grid cannot hold it: "
                            "distances may cross between its layers; use method='auto' (surface paths) "
                            "or seams that cut it into pieces that lie flat")
        if filled:
            warnings.append(f"{filled} vertices lie in UV slivers thinner than a grid cell: their distances "
                            "are edge paths from their neighbours (an upper bound); use a larger grid")
        if len(active) < len(self.charts):
            warnings.append(f"{len(self.charts) - len(active)} of {len(self.charts)} islands have no source: "
                            "their distances are infinite (distances do not cross between islands)")
        total = time.perf_counter() - t0
        seconds = dict(self.seconds)
        seconds.update({'solve': total - t_sample, 'sample': t_sample,
                        'total': total + sum(self.seconds.values())})
        report = dict(self.report)
        report.update({
            'grid': [ny, nx], 'cell': G.grid.h if G is not None else None,
            'masked_fraction': float(1 - G.grid.inside.mean()) if G is not None else None,
            'solver': self.solver, 'sources': int(len(X_src)),
            'seed_radius': float(min(radii)) if radii else None,
            'on_mesh': hybrid, 'refined_sources': refined, 'marches': marches,
            'metric_passes': max([self.charts[c].metric_passes for c in active if c not in path_est],
                                 default=0),
            'paths_islands': len(path_est), 'paths_fallback': len(unseeded), 'planar_islands': len(planar),
            'steiner_points': max(path_k) if path_k else None,
            'islands': len(self.charts), 'islands_reached': reached,
            'error_estimate': est, 'clamped': clamped, 'filled_from_edges': filled, 'warnings': warnings,
            'seconds': {k: round(v, 4) for k, v in seconds.items()},
        })
        return dist, report

    def _march_chart(self, ch, S_uv, loc, src_faces, tree, X_src, upper, source_radius, calibrate,
                     refine=True, own=None):
        """Distances (k,) at one chart's vertices from the sources on it: ``S_uv`` (q,2) their UV
        positions (vertex sources ``loc`` (a,) local indices first, then the surface points in local
        faces ``src_faces`` (b,)). ``refine``: seed from a finer grid where the chart's cell is coarse at a
        source (``_fine_seed``). ``own`` (q,): the rows of ``X_src`` of these sources (a refined seed
        keeps only the vertices no other source is nearer to in 3D). Returns (dist (k,), seed radius in
        cells, number of marches, the grid's travel times (ny, nx), number of refined sources)."""
        G, mu, valid, inv_mu = ch.grid, ch.mu, ch.valid, ch.inv_mu
        march_on = ch.march_on                      # inside nodes and the rim nodes that bridge no gap
        rim = valid & ~march_on
        S = G.coords(S_uv)
        mu_s = bilinear(mu, S, valid)
        if not np.isfinite(mu_s).all():
            raise _Unseeded("a source lies outside the rasterised domain")
        radius = seed_radius(ch.mu_slope, G.h, source_radius)
        src_local = np.zeros(len(ch.V), bool)
        src_local[loc] = True
        T = np.full(G.shape, np.inf)
        near = np.full(len(ch.V), np.inf)
        fixed = np.full(len(ch.V), np.inf)         # vertices inside a refined seed: its values, as they are
        claim = np.full(len(ch.V), np.inf)         # ... where another source may be nearer (see below)
        used = None
        fine = (self._fine_seed(ch, S_uv, loc, src_faces, tree, X_src, upper, source_radius, calibrate)
                if refine else [None] * len(S))
        # a source with a refined seed marches alone, the plain ones of similar mu together: a source
        # that needs the refined seed keeps it beside plain sources (a scan's multi-source set: 11.5 %
        # max error before), and refined seeds marched as one group came out up to 6.6 % long
        # (docs/geodesic.md "Mixed groups")
        groups = []
        for idx in _groups(mu_s):
            groups += [np.array([i]) for i in idx if fine[i] is not None]
            plain = idx[[fine[i] is None for i in idx]]
            if len(plain):
                groups.append(plain)
        n_fine, fine_marches, n_marches = 0, 0, 0
        pocket = np.zeros(G.shape, bool)            # nodes of the march that no front reaches
        for idx in groups:
            reach = radius * float(mu_s[idx].max() / mu_s[idx].min())
            sub = [fine[i] for i in idx]
            if all(f is not None for f in sub):
                # every source of the group has a refined seed: exact up to its radius tau
                tau = min(f[2] for f in sub)
                Tloc = np.minimum.reduce([f[0] for f in sub])
                tv = np.minimum.reduce([f[1] for f in sub])
                if ch.ginv is None:
                    # the map is a similarity (a planar mesh): the straight chart segment is exact, and
                    # shorter than the Steiner paths (their excess is largest there); elsewhere its
                    # length, from a coarse grid's nodes, is no bound (tried: edgebump's peak 0.05 %
                    # -> 0.16 %)
                    wide = FINE_WINDOW * float(mu_s[idx].max() / mu_s[idx].min())
                    Ts = _local_times(G, inv_mu, valid, S[idx], wide, domain=march_on)
                    Ts = self._exact_seed(ch, Ts, tree, X_src, upper, src_local, src_faces)
                    Tloc = np.where(np.isfinite(Tloc), np.fmin(Tloc, Ts), Tloc)
                    nv = _local_times(G, inv_mu, valid, S[idx], wide + 2, pts=ch.P, domain=march_on)
                    tv = np.fmin(tv, np.maximum(nv, tree.query(ch.V)[0]))
                # a vertex keeps the window's value only where no other source can be nearer: at most
                # the 3D distance to every source outside the group (multi-source sets; ridge at grid
                # 512: max error 15.5 % -> 0.35 %); elsewhere in the window the value still bounds the
                # marches' from above (``claim``: a lifted hemisphere's multi-source set at 512 / 1024 /
                # 2048, 0.031 / 0.037 / 0.032 % -> 0.028 / 0.027 / 0.026 % mean)
                d_other = np.inf
                if own is not None:
                    Xg = X_src[own[idx]]
                    rest = X_src[np.linalg.norm(X_src[:, None] - Xg[None], axis=2).min(1) > 0]
                    if len(rest):
                        from scipy.spatial import cKDTree
                        d_other = cKDTree(rest).query(ch.V)[0]
                fixed = np.where((tv <= tau) & (tv <= d_other), np.fmin(fixed, tv), fixed)
                claim = np.where((tv <= tau) & (tv > d_other), np.fmin(claim, tv), claim)
                n_fine += len(sub)
                fine_marches += sum(f[3] for f in sub)
            else:
                tau = radius * G.h / float(mu_s[idx].min())
                Tloc, Tstraight = _local_times(G, inv_mu, valid, S[idx], reach, domain=march_on,
                                               metric=ch.seed_metric, straight=True)
                tau = hidden_seed_level(Tloc, Tstraight, march_on, tau,
                                        HIDDEN_MIN_CELLS * G.h / float(mu_s[idx].min()))
                Tloc = self._exact_seed(ch, Tloc, tree, X_src, upper, src_local, src_faces)
                sub = None
            h_far = 4.0 * G.h
            phi = np.where(np.isfinite(Tloc) & valid, (Tloc - tau) * mu, h_far)
            phi = np.minimum(phi, h_far)
            seed = phi < 0
            if not (seed & march_on).any():
                raise _Unseeded("the source seed covers no grid node")
            if not (march_on & ~seed).any():
                # the exact seed holds every node (a small chart inside a refined seed's window):
                # nothing is left to march
                Tg = np.where(seed, Tloc, np.inf)
                passes = -1
            else:
                if calibrate:
                    phi = calibrate_phi(phi, valid, G.h)
                # march without the rim nodes that bridge gaps of the domain (the front would jump
                # between parts that are far apart on the surface); those get extrapolated values
                Tm, used = eikonal_march(Tloc, seed & march_on, phi, mu, ~march_on, G.h, self.solver)
                pocket |= march_on & ~seed & ~np.isfinite(Tm)
                Tg = np.where(seed, Tloc, Tm + tau) if used == 'skfmm' else np.where(seed, Tloc, Tm)
                passes = ch.metric_passes
            n_marches += 1 + passes
            for _ in range(passes):
                # march again with the exact per-triangle metric, for the gradient direction of the
                # previous pass (docs/geodesic.md, "Exact metric")
                # on a grid the user gives, each triangle's directions are fitted to one unfolded
                # source (automatic grids meet their target without: the fit moved their means by
                # 0.002 % at most and cost 14-19 % of a query, docs/geodesic.md)
                sp_ = directional_mu(np.where(march_on, Tg, np.inf), march_on, G.face, ch.ginv,
                                     max(1, max(G.shape) // DIRECTION_NODES),
                                     (ch.seed_metric[1], G.h) if ch.given else None)
                phi2 = np.where(np.isfinite(Tloc) & valid, (Tloc - tau) * sp_, h_far)
                phi2 = np.minimum(phi2, h_far)
                phi2 = np.where(seed, np.minimum(phi2, -1e-9 * G.h), np.maximum(phi2, 1e-9 * G.h))
                if calibrate:
                    phi2 = calibrate_phi(phi2, valid, G.h)
                Tm, used = eikonal_march(Tloc, seed & march_on, phi2, sp_, ~march_on, G.h, self.solver)
                Tg = np.where(seed, Tloc, Tm + tau) if used == 'skfmm' else np.where(seed, Tloc, Tm)
            if rim.any():
                Tg = np.where(rim & ~seed, extrapolate_rim(Tg, march_on, rim, G.h, inv_mu), Tg)
            np.minimum(T, Tg, out=T)
            if sub is None:
                nv = _local_times(G, inv_mu, valid, S[idx], reach + 2, pts=ch.P, domain=march_on,
                                  metric=ch.seed_metric)
                near = np.where(nv <= tau, np.fmin(near, nv), near)
        T[~valid] = np.inf
        sample = valid & ~ch.gap               # nodes that face a gap are no sample of either side
        dist = bilinear(np.where(sample, T, np.nan), ch.P, sample, ch.corner_ok)
        if len(groups) > 1 and pocket.any():
            # a pocket of the domain that no march reaches (cut off by masked nodes) holds only the
            # times of seeds that cover it, from their own sources; its vertices are filled from their
            # neighbours instead, as with a single source (spot's head cut, a multi-source set at grid
            # 1024: +40 % at a boundary vertex before)
            touch = bilinear(pocket.astype(np.float64), ch.P, sample, ch.corner_ok) > 0
            dist[touch] = np.inf
        dist = np.where(np.isfinite(fixed), fixed, np.fmin(dist, near))
        # (a vertex no march reached stays unreached, to be filled from its neighbours as alone)
        dist = np.where(np.isfinite(dist), np.fmin(dist, claim), dist)
        if ch.free is not None:                     # under-resolved triangles: on-mesh fast marching
            # (not where a refined seed's window gave the shortest paths: those are exact to the
            # Steiner points' excess; the on-mesh march is first order, +4.7 % at a vertex 0.1 units
            # from a source in a lifted hemisphere's dense patch at grid 384)
            free = ch.free & ~np.isfinite(fixed)
            dist = np.where(np.isnan(dist) & ~free, np.inf, dist)
            dist[free] = np.inf
            ch.relax.relax(dist, free)
        spots = getattr(ch, 'spots', None)
        if spots is None:
            spots = ch.spots = SpotWindow(ch)
        if spots.active:
            pf = np.asarray(src_faces, np.int64)
            X_pts = surface_points(ch.V, ch.F, ch.uv, pf, S_uv[len(loc):]) if len(pf) else np.zeros((0, 3))
            seeded = np.isfinite(fixed) | np.isfinite(near)      # a seed's own values stay
            spots.repair(T, dist, seeded, np.asarray(loc, np.int64), X_pts, pf, claim)
        return dist, radius, n_marches + fine_marches, T, n_fine

    def _fine_seed(self, ch, S_uv, loc, src_faces, tree, X_src, upper, source_radius, calibrate):
        """Refined seeds (docs/geodesic.md, "Refined seed"). Where the chart's cell at a source is coarse
        in surface units (``h / mu`` above ``1 / FINE_NODES`` of the mean edge of the source's triangles,
        ``mu`` the smallest of theirs), or a triangle at the source has a metric anisotropy
        ``sqrt(l_max / l_min)`` above ``FINE_ANISO``, or on any grid the user gives (not on a similarity
        chart, whose straight segments are exact), the grid's isotropic or directional speeds leave a
        deficit near the source that travels outward. There the seed takes shortest paths on the mesh
        through ``STEINER`` points per edge, Richardson-extrapolated (``steiner_distances``), over the
        triangles within ``FINE_WINDOW`` cells (UV) or ``FINE_EDGES`` mean 3D edges (not on a
        similarity chart) of the source (the connected part holding it, at most ``FINE_MAX_FACES``, the
        nearest in 3D); on a grid the user gives, the points, edges and triangles of
        ``fine_seed_paths``. They hold up to ``tau``, the 3D distance from the source to the window's
        cut boundary: no geodesic shorter than that leaves the window. A grid node within ``FINE_BAND`` of
        its cells inside ``tau`` takes the shortest path to a point of its triangle's boundary plus the
        straight segment to it in the triangle; deeper nodes the path through a corner; nodes more than
        4 cells beyond ``tau`` inf.

        ``S_uv`` (q,2) the sources' UV positions (vertex sources ``loc`` (a,) first, then points in the
        local faces ``src_faces`` (b,)). Returns a list (q,) of None (not refined) or ``(Tn, tv, tau,
        marches)``: ``Tn`` (ny, nx) times at the chart's grid nodes (inf outside the window), ``tv``
        (k,) at the chart's vertices (inf outside), ``tau`` (mesh units), marches used (0)."""
        G, h = ch.grid, ch.grid.h
        out = [None] * len(S_uv)
        cache = getattr(ch, 'fine_cache', None)
        if cache is None:
            Fc = ch.F
            E = np.sort(np.concatenate([Fc[:, [0, 1]], Fc[:, [1, 2]], Fc[:, [2, 0]]]), 1)
            key = E[:, 0] * len(ch.V) + E[:, 1]
            u, cnt = np.unique(key, return_counts=True)
            aniso = np.ones(len(Fc)) if ch.ginv is None else metric_anisotropy(ch.ginv)
            W = ch.uv[Fc]
            uv_edge = (np.linalg.norm(W - np.roll(W, 1, axis=1), axis=2)).mean(1)
            cache = ch.fine_cache = {'bkeys': u[cnt == 1], 'edge': mean_edges(ch.V, Fc), 'aniso': aniso,
                                     'uv_edge': uv_edge}
        nV = len(ch.V)
        k_fine, reach_edges, max_faces = fine_seed_paths(ch.size, ch.given)
        for i in range(len(S_uv)):
            if i < len(loc):
                star = np.flatnonzero((ch.F == loc[i]).any(1))
                Xs = ch.V[loc[i]]
            else:
                f = int(src_faces[i - len(loc)])
                star = np.array([f])
                Xs = surface_points(ch.V, ch.F, ch.uv, star, S_uv[i][None])[0]
            if not len(star):
                continue
            mu_min = float(ch.mu_face[star].min())
            per_edge = float(cache['edge'][star].mean()) * mu_min / h       # nodes per edge at the source
            if ch.ginv is not None:
                # read at the coarser of this grid and a SEED_NODES one: where the metric varies, a plain
                # seed on a finer grid can be worse than the refined one on a coarser grid, so the choice
                # must not flip as the grid grows (a similarity chart's straight segments are exact)
                per_edge *= min(1.0, SEED_NODES / max(G.shape))
            coarse = per_edge < FINE_NODES or (cache['aniso'][star] > FINE_ANISO).any()
            if not (coarse or (FINE_GIVEN_ALL and ch.given and ch.ginv is not None)):
                continue
            # the window: triangles within FINE_WINDOW cells (UV) or FINE_EDGES mean edges (3D, the same
            # at every grid) of the source
            wr = FINE_WINDOW * h
            dist_v = np.linalg.norm(ch.uv - S_uv[i], axis=1)
            dist_3 = np.linalg.norm(ch.V - Xs, axis=1)
            # (not on a similarity chart: its straight chart segments are exact, the Steiner paths not)
            r3 = reach_edges * float(cache['edge'][star].mean()) if ch.ginv is not None else -1.0
            fsel = np.flatnonzero((dist_v[ch.F] <= wr).any(1) | (dist_3[ch.F] <= r3).any(1))
            if len(fsel) > max_faces:                   # the nearest triangles (3D) only
                dmin = dist_3[ch.F[fsel]].min(1)
                fsel = np.sort(fsel[np.argsort(dmin, kind='stable')[:max_faces]])
            fsel = np.union1d(fsel, star)
            # the connected part of the window that holds the source
            import scipy.sparse as sp
            from scipy.sparse.csgraph import connected_components
            Fw = ch.F[fsel]
            sv, Fl = np.unique(Fw, return_inverse=True)
            Fl = Fl.reshape(-1, 3)
            k = len(sv)
            adj = sp.coo_matrix((np.ones(2 * len(Fl)), (np.r_[Fl[:, 0], Fl[:, 1]],
                                                         np.r_[Fl[:, 1], Fl[:, 2]])), shape=(k, k))
            _, lab = connected_components(adj, directed=False)
            own = lab[Fl[np.searchsorted(fsel, star[0]), 0]]
            keepf = lab[Fl[:, 0]] == own
            fsel = fsel[keepf]
            Fw = ch.F[fsel]
            if np.isin(star, fsel).sum() < len(star):
                continue
            sv, Fl = np.unique(Fw, return_inverse=True)
            Fl = Fl.reshape(-1, 3)
            # the window's cut boundary: its boundary edges that are not the chart's
            E = np.sort(np.concatenate([Fw[:, [0, 1]], Fw[:, [1, 2]], Fw[:, [2, 0]]]), 1)
            key = E[:, 0] * nV + E[:, 1]
            u, first, cnt = np.unique(key, return_index=True, return_counts=True)
            cut = E[first[(cnt == 1) & ~np.isin(u, cache['bkeys'])]]
            if len(cut):
                a, b = ch.V[cut[:, 0]], ch.V[cut[:, 1]]
                d = b - a
                t = np.clip(((Xs - a) * d).sum(1) / np.maximum((d * d).sum(1), 1e-300), 0.0, 1.0)
                tau = float(np.linalg.norm(a + t[:, None] * d - Xs, axis=1).min())
            else:
                tau = np.inf
            if tau < 3.0 * h / mu_min:                  # the window would not reach past the coarse seed
                continue
            # shortest paths on the window's surface through Steiner points on its edges (exact in
            # the limit; an upper bound, a path on the surface, at any STEINER)
            # (a point source's triangle by its row in the window: ``Fw`` is ``ch.F[fsel]``, ``fsel`` sorted)
            dv, dS, pts3, graph = steiner_distances(ch.V, Fw, loc[i] if i < len(loc) else None, Xs,
                                                    np.searchsorted(fsel, star) if i >= len(loc) else None,
                                                    k_fine, extrapolate=True, graded=True)
            tau = min(tau, float(np.max(dv[sv][np.isfinite(dv[sv])])))
            # the chart's grid nodes in the window: the shortest path to a point on their triangle's
            # boundary, then the straight segment inside the triangle
            # the window's grid nodes (valid nodes of its triangles, rim nodes included), from the
            # chart's nodes sorted by triangle (computed once per chart)
            if 'node_order' not in cache:
                fl = G.face.ravel()
                order = np.argsort(fl, kind='stable')
                cache['node_order'] = order
                cache['face_start'] = np.searchsorted(fl[order], np.arange(len(ch.F) + 1))
            st = cache['face_start']
            cnt = st[fsel + 1] - st[fsel]
            at = np.repeat(st[fsel] - np.cumsum(cnt) + cnt, cnt) + np.arange(int(cnt.sum()))
            flat = cache['node_order'][at]
            ii, jj = flat // G.shape[1], flat % G.shape[1]
            fnode = G.face[ii, jj]
            row = np.full(len(ch.F), -1, np.int64)
            row[fsel] = np.arange(len(fsel))
            ok = ch.valid[ii, jj]
            ii, jj, fnode = ii[ok], jj[ok], fnode[ok]
            X, _ = ch.node_points(ii, jj)
            # only nodes that can lie within tau (their 3D distance bounds the geodesic one from below),
            # with a margin of cells for the level set's outer side; in chunks (q nodes x 3 + 3 STEINER)
            near = np.linalg.norm(X - Xs, axis=1) <= tau + 4.0 * h / mu_min
            ii, jj, fnode, X = ii[near], jj[near], fnode[near], X[near]
            # the path through a corner of the node's triangle first (an upper bound): nodes it puts
            # more than a band of cells inside tau are deep in the seed, where only the front's start
            # matters, and keep it; the others take every point of their triangle's boundary
            corner = ch.F[fnode]                     # the graph's first points are the vertices
            to_corner = np.linalg.norm(pts3[corner] - X[:, None], axis=2)
            val = (dS[corner] + to_corner).min(1)
            # a node whose distance is more than 4 of its cells beyond tau (the corner's distance less the
            # straight segment to it bounds it from below) only gets the far level-set value: inf
            cell = h / ch.mu_face[fnode]
            val = np.where((dS[corner] - to_corner).max(1) > tau + 4.0 * cell, np.inf, val)
            band = np.flatnonzero(np.isfinite(val) & (val > tau - FINE_BAND * cell))
            for c0 in range(0, len(band), 5_000):
                sl = band[c0:c0 + 5_000]
                cand, owner = graph.boundary(row[fnode[sl]])
                best = np.full(len(sl), np.inf)
                np.minimum.at(best, owner, dS[cand] + np.linalg.norm(pts3[cand] - X[sl][owner], axis=1))
                val[sl] = best
            Tn = np.full(G.shape, np.inf)
            Tn[ii, jj] = val
            tv = np.full(nV, np.inf)
            tv[sv] = dv[sv]
            nm = 0
            out[i] = (Tn, tv, tau, nm)
        return out

    def _fill_unreached(self, dist_s, charts):
        """Vertices of the ``charts`` (indices) that no grid node reached (UV slivers thinner than a
        cell) get the shortest path through the edges from the reached ones: a Dijkstra run from a
        virtual node joined to every reached vertex by an edge of its distance. ``dist_s`` (N,) is
        changed in place; returns the number of vertices filled."""
        import scipy.sparse as sp
        from scipy.sparse.csgraph import dijkstra
        verts = np.concatenate([self.charts[c].verts for c in charts])
        bad = verts[~np.isfinite(dist_s[verts])]
        if not len(bad):
            return 0
        good = verts[np.isfinite(dist_s[verts])]
        if not len(good):
            raise ConformalError("no vertex was reached by the front: the UV domain is too thin for "
                                 "this grid", 'not_reached', 'larger_grid')
        N = len(dist_s)
        link = sp.coo_matrix((np.maximum(dist_s[good], 1e-300), (np.full(len(good), N), good)),
                             shape=(N + 1, N + 1))
        G = (sp.block_diag([self.graph, sp.csr_matrix((1, 1))]) + link).tocsr()
        via = dijkstra(G, directed=True, indices=N)[:N]
        dist_s[bad] = via[bad]
        if not np.isfinite(dist_s[bad]).all():
            raise ConformalError(f"{int((~np.isfinite(dist_s[bad])).sum())} vertices were not reached "
                                 "by the front", 'not_reached', 'larger_grid')
        return int(len(bad))

    def _exact_seed(self, ch, Tloc, tree, X_src, upper, src_local, src_faces):
        """Bound the seed window's chart times ``Tloc`` (ny, nx) by exact values: not below the 3D
        distance to the nearest source, not above the edge-path bound through the node's triangle
        (``upper``, None: skip), and equal to the 3D distance in a triangle that has a source vertex
        as a corner or holds a source point (the geodesic is a straight segment there)."""
        ii, jj = np.nonzero(np.isfinite(Tloc))
        if not len(ii):
            return Tloc
        X, f = ch.node_points(ii, jj)
        E, _ = tree.query(X)
        t = np.maximum(Tloc[ii, jj], E)
        corners = ch.F[f]                                                   # (q,3) local
        star = src_local[corners].any(1) | np.isin(f, src_faces)
        inside = ch.grid.inside[ii, jj]
        t = np.where(star & inside, E, t)
        if upper is not None:
            up = upper[ch.verts[corners]] + np.linalg.norm(ch.V[corners] - X[:, None], axis=2)
            t = np.minimum(t, up.min(1))
        out = Tloc.copy()
        out[ii, jj] = t
        return out


def geodesic_distance(V: np.ndarray, F: np.ndarray, sources=None, points=None, uv: np.ndarray | None = None,
                      boundary: str = 'uniform', grid: int | None = None, solver: str = 'auto',
                      mu_mode: str = 'metric', source_radius: float | None = None, calibrate: bool = True,
                      progress=None, seams: np.ndarray | None = None, clamp: bool = True,
                      error_target: float = ERROR_TARGET, method: str = 'auto',
                      steiner_points: int | None = None) -> tuple[np.ndarray, dict]:
    """Geodesic distances from a set of sources to every vertex, by fast marching on the conformal
    plane or surface paths: ``GeodesicSolver(V, F, uv, boundary, grid, solver, mu_mode, seams,
    error_target, method=method, steiner_points=steiner_points).distance(sources, points,
    source_radius, calibrate, clamp)``, for one
    query. V (n,3), F (m,3).

    Returns ``(dist, report)``: ``dist`` (n,) float64 in mesh units (NaN at vertices in no triangle,
    inf on islands without a source); ``report`` as ``GeodesicSolver.distance``, with the set-up's
    ``boundary`` (and ``mu_ratio`` when it flattened). Raises ``ConformalError``."""
    say = progress or (lambda f, msg: None)
    V, F = _check_mesh_arrays(V, F)
    _parse_sources(len(V), len(F), sources, points)                   # validate before any work
    gs = GeodesicSolver(V, F, uv=uv, boundary=boundary, grid=grid, solver=solver, mu_mode=mu_mode,
                        seams=seams, error_target=error_target, progress=lambda f, m: say(0.4 * f, m),
                        method=method, steiner_points=steiner_points)
    return gs.distance(sources, points, source_radius=source_radius, calibrate=calibrate, clamp=clamp,
                       progress=lambda f, m: say(0.4 + 0.6 * f, m))


def nearest_vertex(V: np.ndarray, point, used: np.ndarray | None = None) -> int:
    """Index of the vertex of ``V`` (n,3) nearest ``point`` (3,) (e.g. the 3D cursor in object space),
    among ``used`` ((n,) bool, e.g. vertices of some face; default all)."""
    d = np.linalg.norm(np.asarray(V, np.float64) - np.asarray(point, np.float64), axis=1)
    if used is not None:
        d[~np.asarray(used, bool)] = np.inf
    return int(np.argmin(d))


class _FinerSolver:
    """A ``GeodesicSolver`` on the input mesh subdivided ``levels`` times at its edge midpoints
    (``core.mesh.subdivide``: the same surface, the input's vertices first), for ``refine_levels``.
    ``V`` (n,3), ``F`` (m,3) the input, ``seams`` (k,2) or None, ``options`` the solver's keywords."""

    def __init__(self, V, F, seams, levels, options):
        from ..mesh.subdivide import subdivide, subdivide_pairs
        t = time.perf_counter()
        self.levels = levels
        for _ in range(levels):
            if seams is not None:
                seams = subdivide_pairs(F, len(V), seams)
            V, F = subdivide(V, F)
        self.solver = GeodesicSolver(V, F, seams=seams, refine=False, **options)
        self.seconds = time.perf_counter() - t

    def distance(self, n, m, refined, s, pf, pb, **kw):
        """``GeodesicSolver.distance`` for the input mesh of ``n`` vertices and ``m`` triangles, from its
        source vertices ``s`` (k,) (the same numbers here) and surface points in its triangles ``pf``
        (p,) at barycentric ``pb`` (p,3) (in the child triangle that holds each): the distances (n,) of
        its vertices, and the fine solver's report with ``refined`` (levels, triangles)."""
        from ..mesh.subdivide import subdivide_points
        for _ in range(self.levels):
            pf, pb = subdivide_points(m, pf, pb)
            m *= 4
        dist, rep = self.solver.distance(s if len(s) else None, (pf, pb) if len(pf) else None, **kw)
        rep = dict(rep, refined=refined)
        return dist[:n], rep
