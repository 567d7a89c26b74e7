"""Metric reconstruction from travel times through the conformal plane (docs/math.md §6).

An unknown isotropic metric ``xi`` (a positive weight per point of the surface: a path's travel time
is the integral of ``xi ds``) is recovered from measured travel times between source and sensor
points. The surface is flattened conformally; since a surface length element is ``ds = |dx_uv| / mu``,
a travel time in the plane is the integral of the *effective weight* ``w = xi / mu`` along the path.
The plane is covered by a regular grid (nodes at ``origin + (j h, i h)``, array index ``[i, j]``), and
travel times on it solve the eikonal equation ``|grad T| = w`` by fast marching (scikit-fmm, order 2).

The unknown is ``g = log xi`` pulled back to the plane, a tensor-product cubic B-spline on a coarse
control grid. That is the paper's ``xi_flat`` with the map back ``xi = xi_flat * mu`` folded in:
``w = exp(g) / mu`` on the grid, and ``xi = exp(g)`` at each vertex's UV position. We minimise

    sum_i ((T_i - d_i) / (noise * d_mean))^2
        + smoothness * integral |grad g|^2 dA  +  curvature * A * integral |Hess g|^2 dA

over the control values (``A`` the domain's UV area, so every term is dimensionless; ``noise`` is the
expected relative error of the times, so more measurements weigh more against the prior). The
Dirichlet term is the paper's smoothness term; the Dirichlet integral is invariant under conformal
maps, so computed in the plane it equals the one on the surface. The thin-plate term leaves affine
``g`` free and keeps the field from inventing bumps to fit the discretisation error of the times; a
constant metric costs nothing in either. Both act on ``log xi`` rather than ``xi`` (the paper's
``|grad xi|^2``), which makes them independent of the metric's units.

The Jacobian of each travel time with respect to the grid weights comes from the adjoint of the
linearised upwind eikonal update (the adjoint state method): the solution of the transposed,
triangular system is the discrete geodesic path density, i.e. the length of the path through each
cell, as in back-tracing ``grad T``. The least-squares problem is solved by a trust-region
Gauss-Newton method (``scipy.optimize.least_squares``).

Units: ``uv`` and ``h`` are in UV units, ``mu`` in UV units per surface unit, times in surface length
units times the metric.
"""
import math
import os
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.interpolate import BSpline
from scipy.optimize import least_squares

from .errors import ConformalError
from .io.obj import text_lines

SEED_CELLS = 5.5        # source seed disk radius, in grid cells (docs/math.md §4, step 2);
                         # not an integer, so grid nodes rarely sit exactly on the seed circle
DEFAULT_CELLS = 96       # grid cells along the longer side of the UV bounding box
DEFAULT_CONTROL = 8      # B-spline control values along the longer side
SOLVERS = ('auto', 'skfmm', 'sweep')
DEFAULT_NOISE = 0.005    # expected relative error of the times (sets the data term's weight)
DEFAULT_SMOOTHNESS = 1.0  # weight of the Dirichlet term
DEFAULT_CURVATURE = 10.0  # weight of the thin-plate term


# --------------------------------------------------------------------------------------------------
# The grid over the UV domain
# --------------------------------------------------------------------------------------------------
@dataclass
class PlaneGrid:
    """A regular grid over a UV domain, built on ``core.geodesic.Grid``. ``origin`` (2,) UV of node
    [0,0]; ``h`` spacing (UV units); ``shape`` (ny, nx); ``inside`` (ny,nx) bool nodes in a triangle
    of the mesh; ``valid`` (ny,nx) bool nodes the fast marching uses (inside, and the one-node rim
    around the domain so that boundary points can be sampled); ``mu`` (ny,nx) conformal factor at the
    valid nodes (NaN elsewhere); ``raster`` the ``core.geodesic.Grid`` (triangle of each node)."""
    origin: np.ndarray
    h: float
    shape: tuple
    inside: np.ndarray = None
    valid: np.ndarray = None
    mu: np.ndarray = None
    raster: object = None

    def coords(self):
        """Node coordinates ``x`` (nx,) and ``y`` (ny,)."""
        ny, nx = self.shape
        return self.origin[0] + self.h * np.arange(nx), self.origin[1] + self.h * np.arange(ny)

    def corner_weights(self, P):
        """Bilinear corners of points ``P`` (k,2): flat node indices (k,4) and weights (k,4), the
        weights of corners that are not valid set to 0 (not renormalised)."""
        ny, nx = self.shape
        s = (np.asarray(P, np.float64) - self.origin) / self.h
        j0 = np.clip(np.floor(s[:, 0]).astype(np.int64), 0, nx - 2)
        i0 = np.clip(np.floor(s[:, 1]).astype(np.int64), 0, ny - 2)
        fx = np.clip(s[:, 0] - j0, 0.0, 1.0)
        fy = np.clip(s[:, 1] - i0, 0.0, 1.0)
        base = i0 * nx + j0
        idx = np.stack([base, base + 1, base + nx, base + nx + 1], 1)
        wts = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], 1)
        if self.valid is not None:
            wts = wts * self.valid.ravel()[idx]
        return idx, wts

    def bilinear(self, P):
        """Bilinear interpolation of node values at points ``P`` (k,2): flat node indices (k,4) and
        weights (k,4). Corners that are not valid get weight 0 and the others are renormalised.
        Raises ``ConformalError`` if a point has no valid corner."""
        idx, wts = self.corner_weights(P)
        tot = wts.sum(1)
        if (tot <= 1e-12).any():
            raise ConformalError("a point lies outside the flattened domain at this grid size: "
                                 "increase the grid")
        return idx, wts / tot[:, None]

    def field(self, uv, F, values):
        """Per-vertex ``values`` (n,) interpolated linearly onto the valid nodes (extrapolated on the
        rim) and clipped to the range of ``values``: (ny,nx), NaN at the other nodes."""
        out = self.raster.interpolate(uv, F, values)
        return np.where(self.valid, np.clip(out, values.min(), values.max()), np.nan)


def make_grid(uv, F, mu_vertex, cells=DEFAULT_CELLS):
    """Build the ``PlaneGrid`` for a flattened mesh: ``uv`` (n,2), ``F`` (m,3), ``mu_vertex`` (n,)
    positive conformal factor per vertex (UV units per surface unit); ``cells`` grid cells along the
    longer side of the UV bounding box (plus two nodes of margin on each side). Rasterisation is
    ``core.geodesic.Grid``'s."""
    from .geodesic.solver import Grid, GRID_MIN
    cells = int(cells)
    if cells + 5 < GRID_MIN:
        raise ConformalError(f"grid size must be at least {GRID_MIN - 5} cells, got {cells}")
    R = Grid(uv, cells + 5, pad=2).rasterise(uv, F)
    inside = R.inside.copy()
    if inside.sum() < 4:
        raise ConformalError(f"a {cells}-cell grid is too coarse for this mesh: use more cells")
    valid = R.rim()
    grid = PlaneGrid(origin=np.asarray(R.origin, np.float64), h=float(R.h), shape=R.shape,
                     inside=inside, valid=valid, raster=R)
    grid.mu = np.exp(grid.field(uv, F, np.log(mu_vertex)))
    return grid


# --------------------------------------------------------------------------------------------------
# The B-spline parameterisation of log xi
# --------------------------------------------------------------------------------------------------
def _knots(a, b, K):
    return np.r_[[a] * 3, np.linspace(a, b, K - 2), [b] * 3]


class SplineField:
    """Cubic tensor-product B-spline over the grid's box with ``(Ky, Kx)`` control values
    (``K >= 4`` each). ``B`` (ny*nx, Ky*Kx) sparse evaluates it at the nodes; ``at(P)`` at points."""

    def __init__(self, grid, control=DEFAULT_CONTROL):
        x, y = grid.coords()
        ext = max(x[-1] - x[0], y[-1] - y[0])
        self.Kx = max(4, int(round(control * (x[-1] - x[0]) / ext)))
        self.Ky = max(4, int(round(control * (y[-1] - y[0]) / ext)))
        self.tx = _knots(x[0], x[-1], self.Kx)
        self.ty = _knots(y[0], y[-1], self.Ky)
        self.box = (x[0], x[-1], y[0], y[-1])
        Bx = BSpline.design_matrix(x, self.tx, 3)
        By = BSpline.design_matrix(y, self.ty, 3)
        self.B = sp.kron(By, Bx, format='csr')
        self.size = self.Kx * self.Ky

    def at(self, P):
        """Design matrix (k, Ky*Kx) dense at points ``P`` (k,2) (clamped to the box)."""
        x0, x1, y0, y1 = self.box
        px = np.clip(P[:, 0], x0, x1)
        py = np.clip(P[:, 1], y0, y1)
        Bx = BSpline.design_matrix(px, self.tx, 3).toarray()
        By = BSpline.design_matrix(py, self.ty, 3).toarray()
        return np.einsum('kp,kq->kpq', By, Bx).reshape(len(P), -1)


def _difference_rows(ins, stencil):
    """Sparse rows (r, ny*nx) applying ``stencil`` [(di, dj, coef), ...] at every node whose stencil
    nodes are all ``ins``."""
    ny, nx = ins.shape
    ids = np.arange(ny * nx).reshape(ny, nx)
    mi = max(di for di, _, _ in stencil)
    mj = max(dj for _, dj, _ in stencil)
    ok = np.ones((ny - mi, nx - mj), bool)
    for di, dj, _ in stencil:
        ok &= ins[di:ny - mi + di, dj:nx - mj + dj]
    base = ids[:ny - mi, :nx - mj][ok]
    k = len(base)
    rows = np.tile(np.arange(k), len(stencil))
    cols = np.concatenate([base + di * nx + dj for di, dj, _ in stencil])
    vals = np.concatenate([np.full(k, c, np.float64) for _, _, c in stencil])
    return sp.csr_matrix((vals, (rows, cols)), shape=(k, ny * nx))


def smoothness_root(grid, spline, dirichlet=1.0, curvature=0.0):
    """R (Ky*Kx, Ky*Kx) with ``|R c|^2 = dirichlet * D(g) + curvature * A * H(g)`` for the spline
    ``g = B c``, by finite differences over the inside nodes: ``D = integral |grad g|^2 dA`` (the
    paper's smoothness term; conformally invariant) and ``H = integral |Hess g|^2 dA`` (thin plate;
    affine g are free), scaled by the domain area ``A`` to be dimensionless."""
    ins = grid.inside
    h = grid.h
    area = ins.sum() * h * h
    terms = []
    if dirichlet > 0:
        for st in ([(0, 0, -1.0), (0, 1, 1.0)], [(0, 0, -1.0), (1, 0, 1.0)]):
            terms.append(math.sqrt(dirichlet) * _difference_rows(ins, st))
    if curvature > 0:
        f = math.sqrt(curvature * area) / h
        terms.append(f * _difference_rows(ins, [(0, 0, 1.0), (0, 1, -2.0), (0, 2, 1.0)]))
        terms.append(f * _difference_rows(ins, [(0, 0, 1.0), (1, 0, -2.0), (2, 0, 1.0)]))
        terms.append(f * math.sqrt(2.0) * _difference_rows(
            ins, [(0, 0, 1.0), (0, 1, -1.0), (1, 0, -1.0), (1, 1, 1.0)]))
    if not terms:
        return np.zeros((0, spline.size))
    DB = (sp.vstack(terms).tocsr() @ spline.B)
    Q = (DB.T @ DB).toarray()
    e, U = np.linalg.eigh(0.5 * (Q + Q.T))
    return np.sqrt(np.maximum(e, 0.0))[:, None] * U.T


# --------------------------------------------------------------------------------------------------
# Forward problem: fast marching from one source, and its adjoint
# --------------------------------------------------------------------------------------------------
def _sample_soft(grid, field, P, fallback):
    """Bilinear samples (k,) of ``field`` at points ``P`` (k,2) over valid corners; ``fallback``
    where a point has no valid corner."""
    idx, wts = grid.corner_weights(P)
    tot = wts.sum(1)
    vals = np.where(wts > 0, field.ravel()[idx], 0.0)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(tot > 1e-12, (wts * vals).sum(1) / tot, fallback)


def _solver(solver):
    if solver not in SOLVERS:
        raise ConformalError(f"unknown eikonal solver {solver!r}: use one of {', '.join(SOLVERS)}")
    if solver == 'sweep':
        return 'sweep'
    try:
        import skfmm  # noqa: F401
        return 'skfmm'
    except ImportError:
        if solver == 'skfmm':
            raise ConformalError("scikit-fmm is not installed: use the 'sweep' solver") from None
        return 'sweep'


def march(grid, w, src, solver='auto'):
    """Travel times (ny,nx) from the UV point ``src`` (2,) through the weight field ``w`` (ny,nx)
    (``|grad T| = w``; only valid nodes are used; +inf elsewhere).

    Seed: within ``SEED_CELLS + 2`` cells of the source the time is the straight-line chart time
    ``|x - s| (w_s + 4 w_mid + w_x) / 6`` (Simpson's rule along the segment); the seed is the metric
    disk ``T < tau = SEED_CELLS h w_s``. ``solver`` 'skfmm' marches (order 2) from its rim, with the
    level set calibrated by ``core.geodesic.calibrate_phi`` so that scikit-fmm starts the nodes next
    to the rim at their exact times (no point-source offset), and adds ``tau`` back; 'sweep' runs
    ``core.eikonal`` (pure numpy) from the fixed seed times; 'auto' picks scikit-fmm if it imports.
    Also returns the bool (ny,nx) mask of seed nodes (inside the disk or next to it)."""
    from .geodesic.solver import calibrate_phi, eikonal_march
    solver = _solver(solver)
    x, y = grid.coords()
    h = grid.h
    r = SEED_CELLS * h
    d = np.hypot(x[None, :] - src[0], y[:, None] - src[1])
    idx, wts = grid.bilinear(src[None])
    w_src = float(sample(w, idx, wts)[0])
    tau = r * w_src
    win = (d < r + 2 * h) & grid.valid
    ii, jj = np.nonzero(win)
    P = np.stack([x[jj], y[ii]], 1)
    w_mid = _sample_soft(grid, w, 0.5 * (P + src), w_src)
    T_loc = d[ii, jj] * (w_src + 4 * w_mid + w[ii, jj]) / 6.0
    # distance to the rim as scikit-fmm sees it (its start time is distance times w)
    D = d - r
    D[ii, jj] = (T_loc - tau) / w[ii, jj]
    neg = (D < 0) & grid.valid
    if not neg.any():
        raise ConformalError("a source seed covers no grid node: increase the grid size")
    speed = 1.0 / np.where(grid.valid, w, 1.0)
    T_seed = np.full(grid.shape, np.inf)
    T_seed[ii, jj] = T_loc
    phi = calibrate_phi(D, grid.valid, h)
    try:
        T, used = eikonal_march(T_seed, neg, phi, speed, ~grid.valid, h, solver)
    except ValueError as exc:
        raise ConformalError(f"fast marching failed from source at UV {tuple(np.round(src, 4))}: "
                             f"{exc}") from None
    if used == 'skfmm':
        T = T + tau
    T[~grid.valid] = np.inf
    T[ii, jj] = np.where(neg[ii, jj], T_loc, T[ii, jj])
    seed = neg.copy()
    seed[:, :-1] |= neg[:, 1:]
    seed[:, 1:] |= neg[:, :-1]
    seed[:-1, :] |= neg[1:, :]
    seed[1:, :] |= neg[:-1, :]
    seed &= grid.valid
    return T, seed


def adjoint_sensitivity(grid, w, T, seed, idx, wts):
    """Jacobian of sampled travel times with respect to the node weights.

    ``T`` (ny,nx), ``seed`` from ``march``; ``idx``, ``wts`` (k,4) bilinear sampling of k sensors.
    Returns S (ny*nx, k): ``S[:, q] = d T(sensor q) / d w``. The upwind update at each node is
    linearised, ``sum_a a (dT_i - dT_a) = (sum_a a^2 / w_i) dw_i`` with ``a = T_i - T_a`` over the
    upwind neighbours, which is triangular in the order of T; seed nodes follow ``dT = (T / w) dw``.
    The transposed system is solved once per sensor; the column is the discrete path density."""
    ny, nx = grid.shape
    N = ny * nx
    Tf = T.ravel()
    wf = w.ravel()
    vid = np.flatnonzero(np.isfinite(Tf))               # reached valid nodes
    pos = np.full(N, -1, np.int64)
    pos[vid] = np.arange(len(vid))
    Tp = np.pad(T, 1, constant_values=np.inf)
    cand = []
    ii, jj = np.divmod(vid, nx)
    for (di, dj) in ((0, -1), (0, 1)), ((-1, 0), (1, 0)):
        t1 = Tp[ii + 1 + di[0], jj + 1 + di[1]]
        t2 = Tp[ii + 1 + dj[0], jj + 1 + dj[1]]
        first = t1 <= t2
        tn = np.where(first, t1, t2)
        nb = np.where(first, (ii + di[0]) * nx + jj + di[1], (ii + dj[0]) * nx + jj + dj[1])
        a = Tf[vid] - tn
        a = np.where(np.isfinite(a) & (a > 0), a, 0.0)
        cand.append((a, nb))
    (ax, nbx), (ay, nby) = cand
    s = ax + ay
    fixed = seed.ravel()[vid] | (s <= 0)
    reg = ~fixed
    k = len(vid)
    # number the reached nodes in increasing T: upwind neighbours come first, so A is lower
    # triangular in this numbering and A^T is solved by back substitution
    rank = np.empty(k, np.int64)
    rank[np.argsort(Tf[vid], kind='stable')] = np.arange(k)
    pos[vid] = rank
    rr = rank
    rows = [rr]
    cols = [rr]
    vals = [np.ones(k)]
    for a, nb in ((ax, nbx), (ay, nby)):
        use = reg & (a > 0)
        rows.append(rr[use])
        cols.append(pos[nb[use]])
        vals.append(-a[use] / s[use])
    A = sp.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(k, k))
    coef = np.where(fixed, Tf[vid] / wf[vid],
                    (ax ** 2 + ay ** 2) / np.where(reg, s, 1.0) / wf[vid])
    coef = np.where(fixed & ~seed.ravel()[vid], 0.0, coef)
    nsens = len(idx)
    pidx = pos[idx]
    used = wts > 0
    if (pidx[used] < 0).any():
        raise ConformalError("a sensor is not reached by the fast marching from its source: the "
                             "flattened domain is disconnected there")
    pidx = np.where(used, pidx, 0)
    rhs = np.zeros((k, nsens))
    np.add.at(rhs, (pidx.ravel(), np.repeat(np.arange(nsens), 4)), np.where(used, wts, 0.0).ravel())
    lam = spla.spsolve_triangular(A.T.tocsr(), rhs, lower=False, unit_diagonal=True)
    lam = lam.reshape(k, nsens)[rank]
    S = np.zeros((N, nsens))
    S[vid] = coef[:, None] * lam
    return S


def sample(T, idx, wts):
    """Bilinear samples (k,) of the node field ``T`` (ny,nx) with ``idx``, ``wts`` (k,4)."""
    vals = np.where(wts > 0, T.ravel()[idx], 0.0)
    return (vals * wts).sum(1)


# --------------------------------------------------------------------------------------------------
# The inverse problem on the grid
# --------------------------------------------------------------------------------------------------
class PlaneProblem:
    """Travel-time misfit on a ``PlaneGrid`` for a list of measurements.

    ``src_uv``, ``sns_uv`` (k,2) the UV points of each measurement's source and sensor; ``times``
    (k,) measured travel times. Sources with the same UV point share one fast marching."""

    def __init__(self, grid, src_uv, sns_uv, times, control=DEFAULT_CONTROL, solver='auto'):
        self.grid = grid
        self.solver = _solver(solver)
        self.spline = SplineField(grid, control)
        self.times = np.asarray(times, np.float64)
        keys, inv = np.unique(np.round(np.asarray(src_uv, np.float64), 12), axis=0, return_inverse=True)
        self.sources = keys
        self.groups = [np.flatnonzero(inv.ravel() == s) for s in range(len(keys))]
        self.idx, self.wts = grid.bilinear(np.asarray(sns_uv, np.float64))
        self.mu_flat = np.where(grid.valid, grid.mu, 1.0).ravel()
        self.evaluations = 0
        self._last = None

    def weights(self, c):
        """Grid weights ``w = exp(g) / mu`` (ny,nx) for control values ``c``."""
        g = self.spline.B @ c
        return (np.exp(np.clip(g, -30, 30)) / self.mu_flat).reshape(self.grid.shape)

    def forward(self, c):
        """Predicted travel times (k,) for control values ``c``. Keeps the fields for ``jacobian``."""
        self.evaluations += 1
        w = self.weights(c)
        pred = np.empty(len(self.times))
        fields = []
        for s, rows in zip(self.sources, self.groups):
            T, seed = march(self.grid, w, s, self.solver)
            vals = sample(T, self.idx[rows], self.wts[rows])
            if not np.all(np.isfinite(vals)):
                raise ConformalError("a sensor is not reached by the fast marching from its source: "
                                     "the flattened domain is disconnected there")
            pred[rows] = vals
            fields.append((T, seed))
        self._last = (c.copy(), w, fields)
        return pred

    def jacobian(self, c):
        """Jacobian (k, ncontrol) of the predicted times with respect to ``c``."""
        if self._last is None or not np.array_equal(self._last[0], c):
            self.forward(c)
        _, w, fields = self._last
        J = np.zeros((len(self.times), self.spline.size))
        for (T, seed), rows in zip(fields, self.groups):
            S = adjoint_sensitivity(self.grid, w, T, seed, self.idx[rows], self.wts[rows])
            # d w / d g = w, then d g / d c = B
            J[rows] = (self.spline.B.T @ (w.ravel()[:, None] * S)).T
        return J


def fit_constant(problem):
    """Least-squares constant metric ``xi = c`` for the problem's times: travel times scale with the
    metric, so ``c = <d, T1> / <T1, T1>`` with ``T1`` the times of ``xi = 1``. Returns (c, T1)."""
    T1 = problem.forward(np.zeros(problem.spline.size))
    den = float(T1 @ T1)
    if not den > 0:
        raise ConformalError("every source coincides with its sensor: the travel times say nothing "
                             "about the metric")
    return float(problem.times @ T1) / den, T1


def solve_plane(problem, noise=DEFAULT_NOISE, smoothness=DEFAULT_SMOOTHNESS, curvature=DEFAULT_CURVATURE,
                max_iter=60, progress=None):
    """Minimise the misfit plus smoothness over the control values, starting from the best constant.
    Returns (c (ncontrol,), report dict)."""
    t0 = time.perf_counter()
    report_progress = progress or (lambda f, msg: None)
    const, T1 = fit_constant(problem)
    if not const > 0:
        raise ConformalError("the travel times are all zero: cannot recover a metric")
    d = problem.times
    dmean = float(np.mean(d[d > 0])) if (d > 0).any() else 1.0
    sw = 1.0 / (noise * dmean)
    R = smoothness_root(problem.grid, problem.spline, smoothness, curvature)

    def fun(c):
        return np.r_[(problem.forward(c) - d) * sw, R @ c]

    def jac(c):
        report_progress(min(0.95, len(history) / max_iter), 'fitting the metric')
        history.append(1)
        return np.vstack([problem.jacobian(c) * sw, R])

    history = []
    c0 = np.full(problem.spline.size, math.log(const))
    res0 = fun(c0)
    with np.errstate(all='ignore'):
        sol = least_squares(fun, c0, jac=jac, method='trf', x_scale=1.0, max_nfev=max_iter,
                            xtol=1e-6, ftol=1e-8, gtol=1e-8)
    c = sol.x
    pred = problem.forward(c)
    rel = (pred - d) / dmean
    report = {
        'constant_fit': const,
        'rms_relative_misfit_constant': float(np.sqrt(np.mean(((const * T1 - d) / dmean) ** 2))),
        'rms_relative_misfit': float(np.sqrt(np.mean(rel ** 2))),
        'max_relative_misfit': float(np.abs(rel).max()),
        'objective_start': float(0.5 * res0 @ res0),
        'objective': float(sol.cost),
        'smoothness_term': float(0.5 * np.sum((R @ c) ** 2)),
        'iterations': int(sol.njev or 0),
        'function_evaluations': int(sol.nfev),
        'forward_solves': int(problem.evaluations),
        'status': sol.message,
        'seconds': round(time.perf_counter() - t0, 3),
    }
    return c, report


# --------------------------------------------------------------------------------------------------
# On a mesh
# --------------------------------------------------------------------------------------------------
@dataclass
class MetricResult:
    """``xi`` (n,) recovered metric per vertex; ``uv`` (n,2) the flattening used; ``report`` dict
    (misfits, iterations, grid, timings in seconds)."""
    xi: np.ndarray
    uv: np.ndarray
    report: dict = field(default_factory=dict)


def vertex_areas(V, F):
    """Barycentric vertex areas (n,): a third of each adjacent triangle's area."""
    from .mesh.geometry import face_areas
    return np.bincount(F.ravel(), np.repeat(face_areas(V, F) / 3.0, 3), minlength=len(V))


def vertex_mu(V, F, uv):
    """Per-vertex conformal factor (n,) of the map ``uv`` (UV units per surface unit): the realised
    per-triangle scale ``sqrt(A_uv / A_3d)`` averaged over each vertex's triangles in log, weighted by
    area (``core.mesh.measures.vertex_mu``); 1 on vertices in no triangle."""
    from .geodesic.solver import face_mu
    from .mesh.geometry import face_areas
    from .mesh.measures import vertex_mu as average
    out = average(F, face_mu(V, F, uv), face_areas(V, F), len(V))
    return np.where(np.isfinite(out), out, 1.0)


def check_measurements(n, sources, sensors, times):
    """Validate measurement arrays: ``sources``, ``sensors`` (k,) vertex indices in [0,n), ``times``
    (k,) finite and non-negative. Returns them as int64/float64 arrays."""
    src = np.asarray(sources).ravel()
    sns = np.asarray(sensors).ravel()
    t = np.asarray(times, np.float64).ravel()
    if not (len(src) == len(sns) == len(t)):
        raise ConformalError(f"sources, sensors and times must have the same length, got "
                             f"{len(src)}, {len(sns)}, {len(t)}")
    if len(t) == 0:
        raise ConformalError("no travel time measurements given")
    for name, a in (('source', src), ('sensor', sns)):
        if not np.issubdtype(a.dtype, np.integer):
            raise ConformalError(f"{name} vertices must be integers")
        bad = np.flatnonzero((a < 0) | (a >= n))
        if len(bad):
            raise ConformalError(f"measurement {bad[0]}: {name} vertex {a[bad[0]]} is not a vertex "
                                 f"of the mesh (it has {n} vertices, 0-based)")
    bad = np.flatnonzero(~np.isfinite(t) | (t < 0))
    if len(bad):
        raise ConformalError(f"measurement {bad[0]}: travel time {t[bad[0]]} is not a finite "
                             "non-negative number")
    return src.astype(np.int64), sns.astype(np.int64), t


def reconstruct(V, F, sources, sensors, times, boundary='uniform', cells=DEFAULT_CELLS,
                control=DEFAULT_CONTROL, noise=DEFAULT_NOISE, smoothness=DEFAULT_SMOOTHNESS,
                curvature=DEFAULT_CURVATURE, max_iter=60, solver='auto', flat=None, progress=None):
    """Recover an isotropic metric on a disk mesh from travel times.

    ``V`` (n,3), ``F`` (m,3) a disk-topology triangle mesh; ``sources``, ``sensors`` (k,) vertex
    indices of each measurement; ``times`` (k,) travel times (surface length units times the metric).
    ``boundary``: flattening mode (see ``core.flatten``); ``flat``: an existing ``FlattenResult`` of
    this mesh with ``fit='true_scale'`` to reuse. ``cells``: grid cells along the longer UV side;
    ``control``: B-spline control values along it. ``noise``: expected relative error of the times
    (the data term is ``sum ((T - d) / (noise * mean d))^2``); ``smoothness``, ``curvature``: weights
    of the Dirichlet and thin-plate terms of ``log xi`` (see the module docstring); raise ``noise``
    for noisy measurements. ``solver``: eikonal solver, 'auto', 'skfmm' or 'sweep' (pure numpy).
    Returns ``MetricResult`` with ``xi`` (n,)."""
    from .disk.flatten import flatten
    t0 = time.perf_counter()
    report_progress = progress or (lambda f, msg: None)
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    src, sns, t = check_measurements(len(V), sources, sensors, times)
    if int(control) < 4:
        raise ConformalError(f"control grid must have at least 4 values per side, got {control}")
    if not (smoothness >= 0 and curvature >= 0 and math.isfinite(smoothness + curvature)):
        raise ConformalError(f"smoothness and curvature weights must be finite and non-negative, got "
                             f"{smoothness}, {curvature}")
    if not (noise > 0 and math.isfinite(noise)):
        raise ConformalError(f"the noise level must be a positive number, got {noise}")
    report_progress(0.0, 'flattening')
    if flat is None:
        flat = flatten(V, F, boundary=boundary, fit='true_scale', bound=False, exact=False)
        flat_mode = boundary
    else:
        flat_mode = flat.report.get('boundary', 'given')
    t_flat = time.perf_counter() - t0
    uv = flat.uv
    mu_v = vertex_mu(V, F, uv)
    report_progress(0.05, 'building the grid')
    grid = make_grid(uv, F, mu_v, cells)
    problem = PlaneProblem(grid, uv[src], uv[sns], t, control=control, solver=solver)
    c, rep = solve_plane(problem, noise=noise, smoothness=smoothness, curvature=curvature,
                         max_iter=max_iter,
                         progress=lambda f, msg: report_progress(0.05 + 0.9 * f, msg))
    xi = np.exp(problem.spline.at(uv) @ c)
    report = {'boundary': flat_mode, 'vertices': len(V), 'faces': len(F), 'measurements': len(t),
              'sources': int(len(np.unique(src))), 'sensors': int(len(np.unique(sns))),
              'grid': list(grid.shape), 'control': [problem.spline.Ky, problem.spline.Kx],
              'solver': problem.solver, 'noise': noise, 'smoothness': smoothness,
              'curvature': curvature,
              'mu_ratio': float(mu_v.min() / mu_v.max())}
    report.update(rep)
    report['seconds'] = {'flatten': round(t_flat, 3), 'fit': rep['seconds'],
                         'total': round(time.perf_counter() - t0, 3)}
    report_progress(1.0, 'done')
    return MetricResult(xi=xi, uv=uv, report=report)


def simulate_times(V, F, xi, sources, sensors, boundary='uniform', cells=4 * DEFAULT_CELLS, flat=None):
    """Forward model: travel times (k,) between vertex pairs ``sources[i]``, ``sensors[i]`` (k,) for
    the per-vertex metric ``xi`` (n,) on the disk mesh ``V`` (n,3), ``F`` (m,3), by fast marching on a
    ``cells`` grid over the conformal plane. ``flat``: an existing true-scale ``FlattenResult``."""
    from .disk.flatten import flatten
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    xi = np.asarray(xi, np.float64)
    if xi.shape != (len(V),) or not np.all(np.isfinite(xi)) or not np.all(xi > 0):
        raise ConformalError(f"the metric must be {len(V)} finite positive values, one per vertex")
    src, sns, _ = check_measurements(len(V), sources, sensors, np.zeros(len(np.ravel(sources))))
    if flat is None:
        flat = flatten(V, F, boundary=boundary, fit='true_scale', bound=False, exact=False)
    uv = flat.uv
    grid = make_grid(uv, F, vertex_mu(V, F, uv), cells)
    w = np.exp(grid.field(uv, F, np.log(xi))) / grid.mu
    out = np.empty(len(src))
    for s in np.unique(src):
        rows = np.flatnonzero(src == s)
        T, _ = march(grid, w, uv[s])
        idx, wts = grid.bilinear(uv[sns[rows]])
        out[rows] = sample(T, idx, wts)
    return out


# --------------------------------------------------------------------------------------------------
# Measurement files
# --------------------------------------------------------------------------------------------------
def _numeric(text):
    try:
        float(text)
        return True
    except ValueError:
        return False


def parse_times(lines, n, name='times'):
    """Parse CSV lines ``source_vertex,sensor_vertex,time`` (0-based vertex indices in [0,n), time
    finite and >= 0). The first line may be a header; blank lines and lines starting with '#' are
    skipped. Returns (sources (k,) int64, sensors (k,) int64, times (k,) float64). Raises
    ``ConformalError`` naming the line number of the first bad row."""
    src, sns, tim = [], [], []
    for lineno, line in enumerate(lines, 1):
        text = line.strip().lstrip('\ufeff') if lineno == 1 else line.strip()
        if not text or text.startswith('#'):
            continue
        parts = [p.strip() for p in text.split(',')]
        where = f"{name} line {lineno}"
        if lineno == 1 and not _numeric(parts[0]):
            continue                                  # the optional header line
        if len(parts) != 3:
            raise ConformalError(f"{where}: expected 3 comma-separated fields "
                                 f"'source_vertex,sensor_vertex,time', got {len(parts)}: {text[:60]!r}")
        try:
            a, b = int(parts[0]), int(parts[1])
        except ValueError:
            raise ConformalError(f"{where}: vertex indices must be integers, got "
                                 f"{parts[0][:20]!r}, {parts[1][:20]!r}") from None
        try:
            t = float(parts[2])
        except ValueError:
            raise ConformalError(f"{where}: time {parts[2][:20]!r} is not a number") from None
        for label, v in (('source', a), ('sensor', b)):
            if not 0 <= v < n:
                raise ConformalError(f"{where}: {label} vertex {v} is not a vertex of the mesh "
                                     f"(it has {n} vertices, numbered from 0)")
        if not math.isfinite(t):
            raise ConformalError(f"{where}: time is {parts[2]!r}, not a finite number")
        if t < 0:
            raise ConformalError(f"{where}: time {t:g} is negative")
        src.append(a)
        sns.append(b)
        tim.append(t)
    if not tim:
        raise ConformalError(f"{name}: no measurements found (expected rows "
                             "'source_vertex,sensor_vertex,time')")
    return np.array(src, np.int64), np.array(sns, np.int64), np.array(tim, np.float64)


def read_times(path, n):
    """Read a travel-time CSV file (see ``parse_times``) for a mesh with ``n`` vertices."""
    lines = [line.rstrip('\r\n') for _, line in text_lines(path)]
    return parse_times(lines, n, name=os.path.basename(path))
