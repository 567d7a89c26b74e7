"""Geodesic distance on a surface by weighted fast marching on its conformal plane (DESIGN.md section 4).

A conformal map scales lengths by ``mu`` (UV units per surface unit) and keeps angles, so a surface length
element is ``ds = |dx_uv| / mu`` and the geodesic distance ``T`` solves the eikonal equation
``|grad_uv T| = 1 / mu`` on the flat UV domain: a travel time with speed ``mu`` on a regular grid.

Steps of ``geodesic_distance``:

1. Flatten (``core.flatten``) unless a UV map is given. Rotate the map to its smallest bounding
   rectangle (``align_uv``). Compute the realised per-triangle ``mu = sqrt(A_uv / A_3d)`` from the map
   itself, so any UV scale works, average it to the vertices (area-weighted, in log) and rasterise it
   with linear interpolation onto a regular grid over the UV bounding box. Nodes outside the domain are
   masked, except a one-node rim with extrapolated ``mu`` so that boundary vertices can be sampled.
2. Seed each source with exact times in a disk of ``SEED_RADIUS`` cells (smaller where ``mu`` varies
   fast, ``seed_radius``): ``T = |x - s| * mean(1/mu)`` along the straight segment (Simpson), the flat
   chart at the source. The seed's rim is the metric circle ``T = tau``; ``calibrate_phi`` sets the
   level-set values there so that scikit-fmm's first front values are exact. Fast marching then
   continues from exact data: the point-source offset of fast marching (about 0.3 cells, scikit-fmm
   issue #22) and the first-order error of its contour start do not arise.
3. March with scikit-fmm ``travel_time(order=2)`` or, when scikit-fmm is missing, the pure-numpy second
   order fast sweeping solver of ``core.eikonal`` (the seed and its ring held fixed). Sources whose
   ``mu`` differ by more than a factor 2 march separately and the minimum is taken.
4. Sample the travel time back to the vertices bilinearly; vertices inside a seed disk take their chart
   time directly.
"""
import time

import numpy as np

from ..errors import ConformalError
from ..mesh.geometry import face_areas

SOLVERS = ('auto', 'skfmm', 'sweep')
MU_MODES = ('vertex', 'face')
GRID_MIN, GRID_MAX = 64, 4096
RIM = 1
# default seed disk radius in cells: the sweep's second-order stencil is less accurate on strongly
# curved fronts than fast marching's, so it starts from a larger exact disk (see docs/geodesic.md)
SEED_RADIUS = {'skfmm': 24.0, 'sweep': 36.0}


# --------------------------------------------------------------------------------------------------
# conformal factor of a given map
def face_mu(V, F, uv):
    """Per-triangle scale ``mu_T = sqrt(A_uv / A_3d)`` (m,) of the map ``uv`` (n,2): UV units per
    surface unit, with no normalisation (so it is consistent with the UV coordinates as given).
    Raises ConformalError if a triangle is degenerate or flipped relative to the majority."""
    W = uv[F]
    e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    a = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    A = face_areas(V, F)
    sign = np.sign(np.median(a))
    bad = (a * sign <= 0) | (A <= 0)
    if bad.any():
        raise ConformalError(f"the UV map has {int(bad.sum())} flipped or degenerate triangles: "
                             "geodesic distances need a fold-free map (flatten again, or use "
                             "boundary 'area' or 'uniform')")
    return np.sqrt(np.abs(a) / A)


def vertex_mu(V, F, mu_face):
    """Per-vertex ``mu`` (n,): the 3D-area-weighted geometric mean of the incident triangles' ``mu``."""
    A = face_areas(V, F)
    n = len(V)
    w = np.bincount(F.ravel(), np.repeat(A, 3), minlength=n)
    s = np.bincount(F.ravel(), np.repeat(A * np.log(mu_face), 3), minlength=n)
    with np.errstate(invalid='ignore', divide='ignore'):
        out = np.exp(s / w)
    out[w <= 0] = 1.0   # unreferenced vertices: never sampled as anything meaningful
    return out


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


def bilinear(field, pts, valid=None):
    """Bilinear samples (k,) of ``field`` (ny, nx) at continuous node coordinates ``pts`` (k,2)
    (column, row). Invalid nodes (``valid`` False or non-finite values) are left out and the weights
    renormalised; a point with no valid corner gets NaN."""
    ny, nx = field.shape
    x = np.clip(pts[:, 0], 0, nx - 1 - 1e-9)
    y = np.clip(pts[:, 1], 0, ny - 1 - 1e-9)
    j, i = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    fx, fy = x - j, y - i
    num = np.zeros(len(pts))
    den = np.zeros(len(pts))
    for di, dj, w in ((0, 0, (1 - fx) * (1 - fy)), (0, 1, fx * (1 - fy)),
                      (1, 0, (1 - fx) * fy), (1, 1, fx * fy)):
        v = field[i + di, j + dj]
        ok = np.isfinite(v)
        if valid is not None:
            ok &= valid[i + di, j + dj]
        num += np.where(ok, w * np.where(ok, v, 0.0), 0.0)
        den += np.where(ok, w, 0.0)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(den > 1e-12, num / np.maximum(den, 1e-300), np.nan)


def default_grid(V, F, uv):
    """Automatic grid size (nodes along the longer UV side): about 8 nodes per mean UV edge length,
    rounded up to a multiple of 64 and clipped to 256..2048."""
    E = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    le = np.linalg.norm(uv[E[:, 0]] - uv[E[:, 1]], axis=1).mean()
    ext = np.ptp(uv[np.unique(F)], axis=0).max()
    g = 8.0 * ext / max(le, 1e-300)
    return int(np.clip(64 * np.ceil(g / 64), 256, 2048))


# --------------------------------------------------------------------------------------------------
# sources
def _source_points(V, F, uv, sources, points):
    """UV positions (k,2) of the sources: vertex indices ``sources`` and surface points ``points`` =
    (faces (p,), barycentric (p,3))."""
    n = len(V)
    pos = []
    if sources is not None:
        s = np.atleast_1d(np.asarray(sources))
        if s.size:
            if not np.issubdtype(s.dtype, np.integer):
                raise ConformalError("source vertices must be integer indices")
            if s.min() < 0 or s.max() >= n:
                raise ConformalError(f"source vertex out of range: the mesh has {n} vertices (0..{n - 1})")
            pos.append(uv[s.astype(np.int64)])
    if points is not None:
        pf, pb = points
        pf = np.atleast_1d(np.asarray(pf, np.int64))
        pb = np.atleast_2d(np.asarray(pb, np.float64))
        if pb.shape != (len(pf), 3):
            raise ConformalError("surface points need one face index and 3 barycentric coordinates each")
        if len(pf) and (pf.min() < 0 or pf.max() >= len(F)):
            raise ConformalError(f"source face out of range: the mesh has {len(F)} triangles")
        if not np.allclose(pb.sum(1), 1.0, atol=1e-6) or (pb < -1e-9).any():
            raise ConformalError("barycentric coordinates must be non-negative and sum to 1")
        pos.append(np.einsum('kc,kcd->kd', pb, uv[F[pf]]))
    if not pos or not sum(len(p) for p in pos):
        raise ConformalError("no source given: pass at least one source vertex or surface point")
    return np.concatenate(pos)


def _local_times(grid, inv_mu, valid, S, radius_nodes, pts=None):
    """Flat-chart times (``_chart_time``, ``inv_mu`` the grid field 1/mu) from the sources ``S`` (k,2,
    node coordinates). With ``pts`` None:
    on the grid, over a window of ``radius_nodes + 2`` around each source, returns (ny, nx) with inf
    outside the windows. With ``pts`` (q,2 node coordinates): at those points (q,), from the nearest
    source in node units only (others inf)."""
    h = grid.h
    if pts is None:
        w = int(np.ceil(radius_nodes)) + 2
        off = np.arange(-w, w + 1)
        oi, oj = np.meshgrid(off, off, indexing='ij')
        inside = (oi ** 2 + oj ** 2 <= (w + 1) ** 2).ravel()
        oi, oj = oi.ravel()[inside], oj.ravel()[inside]
        ny, nx = grid.shape
        out = np.full(grid.shape, np.inf)
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
            np.minimum.at(out, (ii, jj), _chart_time(inv_mu, valid, Sb[src], P, h))
        return out
    # at arbitrary points: nearest sources by a KD-tree
    from scipy.spatial import cKDTree
    d, k = cKDTree(S).query(pts)
    T = np.full(len(pts), np.inf)
    near = d <= radius_nodes + 1
    if near.any():
        T[near] = _chart_time(inv_mu, valid, S[k[near]], pts[near], h)
    return T


def _chart_time(inv_mu, valid, S, P, h):
    """Flat-chart time from ``S`` (k,2) to ``P`` (k,2) (node coordinates): ``|P - S| h`` times the
    mean of ``1/mu`` along the segment (Simpson's rule on the grid field ``inv_mu`` = 1/mu)."""
    d = np.linalg.norm(P - S, axis=1) * h
    inv = (bilinear(inv_mu, S, valid) + 4 * bilinear(inv_mu, 0.5 * (S + P), valid)
           + bilinear(inv_mu, P, valid)) / 6.0
    return d * inv


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


def resolve_solver(solver):
    """'skfmm' or 'sweep' for a requested ``solver`` ('auto' picks scikit-fmm if it imports)."""
    if solver not in SOLVERS:
        raise ConformalError(f"unknown solver {solver!r}: use one of {', '.join(SOLVERS)}")
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


def march(T_seed, seed, phi, speed, mask, h, solver='auto'):
    """Travel times on the grid from the seed nodes (``seed`` (ny, nx) True) whose exact times are
    ``T_seed`` (ny, nx); ``phi`` (ny, nx) is negative exactly on the seed, its zero contour the
    seed's rim. With 'skfmm' the result is the time from that rim (add the rim time); with 'sweep'
    it is the full time. ``speed`` (ny, nx) > 0,
    nodes with ``mask`` True excluded (returned inf), spacing ``h``. ``solver``: 'skfmm' (scikit-fmm
    travel time from the zero contour of ``phi``, order 2, plus the seed rim time), 'sweep'
    (``core.eikonal.sweep``, pure numpy, order 2, the seed held fixed), or 'auto' (scikit-fmm if it
    imports). Returns (T, solver name)."""
    solver = resolve_solver(solver)
    if solver == 'skfmm':
        import skfmm
        T = skfmm.travel_time(np.ma.MaskedArray(phi, mask), np.where(mask, 1.0, speed), dx=h, order=2)
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


def seed_radius(mu, valid, h, source_radius):
    """Seed disk radius in cells: ``source_radius``, reduced where ``log mu`` varies fast, so that
    the straight-line chart time inside the disk stays accurate (radius times the largest
    ``|grad_uv log mu|`` at most 0.15), and at least 3 cells."""
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
    cap = 0.15 / (g * h) if g > 0 else np.inf
    return float(max(3.0, min(source_radius, cap)))


def _groups(mu_s):
    """Split sources into groups whose ``mu`` differ by less than a factor 2 (one march each)."""
    b = np.floor(np.log2(mu_s / mu_s.min()) + 1e-12).astype(np.int64)
    return [np.flatnonzero(b == k) for k in np.unique(b)]


def geodesic_distance(V, F, sources=None, points=None, uv=None, boundary='uniform', grid=None,
                      solver='auto', mu_mode='vertex', source_radius=None, calibrate=True, progress=None):
    """Geodesic distances from a set of sources to every vertex, by fast marching on the conformal plane.

    V (n,3) float, F (m,3) int triangles (a disk). ``sources``: vertex indices (k,) and/or ``points``:
    surface points as (faces (p,), barycentric (p,3)). With several sources the result is the distance
    to the nearest. ``uv`` (n,2): a fold-free conformal map to reuse (any scale); None flattens with
    ``boundary`` ('uniform', 'area' or 'free'). ``grid``: nodes along the longer UV side (None:
    ``default_grid``). ``solver``: 'auto' (scikit-fmm if installed, else the numpy sweep), 'skfmm' or
    'sweep'. ``mu_mode``: 'vertex' (per-vertex mu interpolated linearly, default) or 'face' (per
    triangle, piecewise constant). ``source_radius``: radius of the exact seed disk in grid cells
    (None: ``SEED_RADIUS`` of the solver; ``seed_radius`` may reduce it). ``calibrate``: make scikit-fmm's start values on the seed rim
    exact (``calibrate_phi``). ``progress(fraction, message)``: optional callback.

    Returns ``(dist, report)``: ``dist`` (n,) float64 in mesh units (vertices on no triangle get NaN);
    ``report`` dict: grid [ny, nx], cell (UV units), masked_fraction, solver, sources, seed_radius
    (cells), marches, seconds {flatten, rasterise, solve, sample, total}."""
    say = progress or (lambda f, msg: None)
    t0 = time.perf_counter()
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    if V.ndim != 2 or V.shape[1] != 3 or F.ndim != 2 or F.shape[1] != 3 or not len(F):
        raise ConformalError("expected V (n,3) positions and F (m,3) triangles")
    if F.min() < 0 or F.max() >= len(V):
        raise ConformalError("a triangle refers to a vertex that does not exist")
    if mu_mode not in MU_MODES:
        raise ConformalError(f"unknown mu_mode {mu_mode!r}: use one of {', '.join(MU_MODES)}")
    solver = resolve_solver(solver)
    if source_radius is None:
        source_radius = SEED_RADIUS[solver]
    if not source_radius >= 1.0:
        raise ConformalError("source_radius must be at least 1 grid cell")
    _source_points(V, F, np.zeros((len(V), 2)), sources, points)      # validate before any work
    report = {}
    seconds = {}
    if uv is None:
        from ..disk.flatten import flatten
        say(0.0, 'flattening')
        res = flatten(V, F, boundary=boundary, fit='true_scale', bound=False)
        uv = res.uv
        report['boundary'] = boundary
        report['mu_ratio'] = res.report.get('mu_ratio')
        seconds['flatten'] = time.perf_counter() - t0
    else:
        uv = np.asarray(uv, np.float64)
        if uv.shape != (len(V), 2) or not np.isfinite(uv).all():
            raise ConformalError(f"uv must be ({len(V)},2) finite coordinates, got shape {uv.shape}")
        report['boundary'] = 'given'
    say(0.3, 'rasterising')
    t = time.perf_counter()
    on_mesh = np.zeros(len(V), bool)
    on_mesh[F.ravel()] = True
    uv = align_uv(uv, on_mesh)
    S_uv = _source_points(V, F, uv, sources, points)
    mu_f = face_mu(V, F, uv)
    if grid is None:
        grid = default_grid(V, F, uv)
    G = Grid(uv[on_mesh], grid).rasterise(uv, F)
    valid = G.rim(RIM)
    if mu_mode == 'vertex':
        mu = G.interpolate(uv, F, vertex_mu(V, F, mu_f))
    else:
        mu = G.interpolate(uv, F, face_values=mu_f)
    mu = np.where(valid, np.clip(mu, mu_f.min(), mu_f.max()), 1.0)
    seconds['rasterise'] = time.perf_counter() - t
    t = time.perf_counter()
    S = G.coords(S_uv)
    mu_s = bilinear(mu, S, valid)
    if not np.isfinite(mu_s).all():
        raise ConformalError("a source lies outside the flattened domain")
    radius = seed_radius(mu, valid, G.h, source_radius)
    inv_mu = 1.0 / mu
    P = G.coords(uv)
    T = np.full(G.shape, np.inf)
    near = np.full(len(V), np.inf)
    used = None
    groups = _groups(mu_s)
    for g, idx in enumerate(groups):
        say(0.4 + 0.5 * g / len(groups), 'marching')
        # exact chart times in the seed disk T < tau (radius >= `radius` cells for every source)
        tau = radius * G.h / float(mu_s[idx].min())
        reach = radius * float(mu_s[idx].max() / mu_s[idx].min())
        Tloc = _local_times(G, inv_mu, valid, S[idx], reach)
        # signed distance to the seed rim, in UV units at each node's own speed
        h_far = 4.0 * G.h
        phi = np.where(np.isfinite(Tloc) & valid, (Tloc - tau) * mu, h_far)
        phi = np.minimum(phi, h_far)
        seed = phi < 0
        if not seed.any():
            raise ConformalError("the source seed covers no grid node: increase the grid size")
        if calibrate:
            phi = calibrate_phi(phi, valid, G.h)
        Tm, used = march(Tloc, seed, phi, mu, ~valid, G.h, solver)
        Tg = np.where(seed, Tloc, Tm + tau) if used == 'skfmm' else Tm
        np.minimum(T, Tg, out=T)
        # vertices inside a seed disk take their exact chart time
        nv = _local_times(G, inv_mu, valid, S[idx], reach + 2, pts=P)
        near = np.where(nv <= tau, np.fmin(near, nv), near)
    T[~valid] = np.inf
    seconds['solve'] = time.perf_counter() - t
    t = time.perf_counter()
    dist = bilinear(np.where(valid, T, np.nan), P, valid)
    dist = np.fmin(dist, near)
    dist[~on_mesh] = np.nan
    bad = int((~np.isfinite(dist[on_mesh])).sum())
    if bad:
        raise ConformalError(f"{bad} vertices were not reached by the front: the UV domain is not "
                             "connected at this grid size; increase the grid")
    seconds['sample'] = time.perf_counter() - t
    seconds['total'] = time.perf_counter() - t0
    ny, nx = G.shape
    report.update({
        'grid': [ny, nx], 'cell': G.h, 'masked_fraction': float(1 - G.inside.mean()),
        'solver': used, 'mu_mode': mu_mode, 'sources': int(len(S_uv)), 'seed_radius': radius,
        'marches': len(groups), 'seconds': {k: round(v, 4) for k, v in seconds.items()},
    })
    return dist, report
