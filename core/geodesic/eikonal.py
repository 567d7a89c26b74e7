"""A pure-numpy eikonal solver: fast sweeping, vectorised along grid diagonals.

Fallback for ``core.geodesic`` where scikit-fmm is not installed (PyPI has scikit-fmm wheels only for
Windows). It solves ``|grad T| = 1 / speed`` on a regular 2D grid of spacing ``h`` with Godunov upwind
differences, first order and then second order (one-sided ``(3T - 4T1 + T2) / 2h`` where the upwind
neighbour two nodes away is usable, as scikit-fmm's ``order=2``).

Gauss-Seidel sweeping visits the nodes in four diagonal orders (i+j ascending, i+j descending, i-j
ascending, i-j descending). The upwind stencil of a node only reaches nodes whose ``i+j`` (or ``i-j``)
differs by 1 or 2, so all nodes on one diagonal are independent and update together as one numpy
operation: a sweep is a Python loop over ``ny + nx`` diagonals, not over nodes.
"""
import numpy as np

from ..errors import ConformalError

PAD = 2


class _Sweeper:
    """Index set-up for one grid: for the free nodes, grouped by diagonal, the padded flat indices
    ``idx`` and the neighbour indices ``nb`` (k,8) in the order x-1, y-1, x+1, y+1, x-2, y-2, x+2,
    y+2. ``orders`` holds the four sweep orders as lists of (idx, nb) pairs."""

    def __init__(self, shape, free):
        ny, nx = shape
        W = nx + 2 * PAD
        ii, jj = np.nonzero(free)
        flat = (ii + PAD) * W + (jj + PAD)
        offs = np.array([-1, -W, 1, W, -2, -2 * W, 2, 2 * W])
        self.orders = []
        for key in (ii + jj, ii - jj):
            o = np.argsort(key, kind='stable')
            k = key[o]
            cuts = np.flatnonzero(np.diff(k)) + 1
            groups = [(g, g[:, None] + offs[None, :]) for g in np.split(flat[o], cuts)]
            self.orders.append(groups)
            self.orders.append(groups[::-1])


def _update(T, idx, nb, fh, order):
    """Godunov upwind candidate values at nodes ``idx`` (k,) with neighbours ``nb`` (k,8); ``fh``
    (k,) = h / speed. Per axis the upwind neighbour is the smaller one, ``t1``; at order 2 the
    one-sided second-order difference ``1.5 (T - (4 t1 - t2) / 3)`` is used where the node two steps
    further, ``t2``, is smaller still. As in fast marching, an axis takes part when its ``t1`` is below
    the candidate; the two-axis quadratic falls back to the better single axis when it has no root."""
    G = T[nb]
    m, p = G[:, 0:2], G[:, 2:4]
    t1 = np.minimum(m, p)                                      # (k,2): x, y
    if order == 2:
        t2 = np.where(m <= p, G[:, 4:6], G[:, 6:8])
        second = t2 <= t1
        a2 = np.where(second, 2.25, 1.0)                       # alpha^2
        with np.errstate(invalid='ignore'):
            v = np.where(second, (4.0 * t1 - t2) * (1.0 / 3.0), t1)
    else:
        a2 = np.ones_like(t1)
        v = t1
    vx, vy = v[:, 0], v[:, 1]
    ax, ay = a2[:, 0], a2[:, 1]
    with np.errstate(invalid='ignore', over='ignore'):
        cx = vx + fh / np.sqrt(ax)
        cy = vy + fh / np.sqrt(ay)
        first_x = t1[:, 0] <= t1[:, 1]
        one = np.where(first_x, cx, cy)                        # the axis with the smaller neighbour
        other_t1 = np.where(first_x, t1[:, 1], t1[:, 0])
        # both axes: (ax + ay) T^2 - 2 (ax vx + ay vy) T + ax vx^2 + ay vy^2 - fh^2 = 0
        A = ax + ay
        B = ax * vx + ay * vy
        dv = vx - vy
        disc = A * fh * fh - ax * ay * dv * dv                 # = B^2 - A C
        two = (B + np.sqrt(disc)) / A
    both = np.isfinite(other_t1) & (other_t1 < one)
    return np.where(both, np.where(disc >= 0, two, np.minimum(cx, cy)), one)


def sweep(T0, speed, h, mask=None, order=2, tol=1e-9, max_iter=60, first_iter=1, info=None):
    """Solve ``|grad T| = 1 / speed`` with fixed values ``T0`` where ``T0`` is finite.

    T0 (ny, nx): initial times, finite at the fixed (source) nodes, inf elsewhere. speed (ny, nx) > 0.
    h: grid spacing. mask (ny, nx) bool or None: True nodes are excluded (obstacles, returned inf).
    order: 1 or 2. ``first_iter`` rounds of four first-order sweeps (None: to convergence) give a
    first guess from above, then rounds of the requested order run until the largest change is at
    most ``tol`` times the largest finite time (at most ``max_iter`` rounds). Values only decrease
    (``T = min(T, update)``), which keeps the second-order sweeps from oscillating. ``info``: an
    optional dict that receives ``rounds`` (per phase). Returns T (ny, nx) float64 (inf at masked
    nodes and at nodes no front reaches)."""
    T0 = np.asarray(T0, np.float64)
    speed = np.asarray(speed, np.float64)
    if T0.ndim != 2 or speed.shape != T0.shape:
        raise ConformalError("eikonal sweep needs 2D T0 and speed arrays of the same shape")
    if order not in (1, 2):
        raise ConformalError("order must be 1 or 2")
    ny, nx = T0.shape
    mask = np.zeros(T0.shape, bool) if mask is None else np.asarray(mask, bool)
    fixed = np.isfinite(T0) & ~mask
    if not fixed.any():
        raise ConformalError("eikonal sweep needs at least one fixed node")
    free = ~mask & ~fixed
    if (speed[free] <= 0).any() or not np.isfinite(speed[free]).all():
        raise ConformalError("speed must be positive and finite at every unmasked node")
    Tp = np.full((ny + 2 * PAD, nx + 2 * PAD), np.inf)
    Tp[PAD:-PAD, PAD:-PAD] = np.where(fixed, T0, np.inf)
    fhp = np.zeros_like(Tp)
    fhp[PAD:-PAD, PAD:-PAD] = np.where(free, h / np.where(free, speed, 1.0), 0.0)
    T = Tp.ravel()
    fh = fhp.ravel()
    S = _Sweeper(T0.shape, free)
    orders = [[(idx, nb, fh[idx]) for idx, nb in groups] for groups in S.orders]
    rounds = []
    if order == 1 or first_iter == 0:
        phases = ((order, max_iter),)
    else:
        phases = ((1, max_iter if first_iter is None else first_iter), (2, max_iter))
    for o, limit in phases:
        done = 0
        for done in range(1, limit + 1):  # noqa: B007  (the count is kept after the loop)
            change = 0.0
            for groups in orders:
                for idx, nb, f in groups:
                    old = T[idx]
                    new = np.minimum(_update(T, idx, nb, f, o), old)
                    moved = new < old
                    if moved.any():
                        change = max(change, float((old[moved] - new[moved]).max()))
                        T[idx] = new
            fin = np.isfinite(T)
            if change <= tol * float(T[fin].max()):
                break
        rounds.append(done)
    out = Tp[PAD:-PAD, PAD:-PAD].copy()
    out[mask] = np.inf
    if info is not None:
        info['rounds'] = rounds
    return out


def travel_time(phi, speed, h, mask=None, order=2, **kw):
    """Travel time from the zero contour of ``phi`` (ny, nx), like ``skfmm.travel_time`` but
    unsigned and with masked nodes as inf. Nodes next to the contour (on either side) start from
    their distance to it, ``1/d^2 = sum over axes 1/d_axis^2`` with ``d_axis`` the nearer crossing
    along that axis by linear interpolation of ``phi``, divided by their speed."""
    phi = np.asarray(phi, np.float64)
    mask = np.zeros(phi.shape, bool) if mask is None else np.asarray(mask, bool)
    inv2 = np.zeros(phi.shape)
    for axis in (0, 1):
        d_axis = np.full(phi.shape, np.inf)
        for shift in (1, -1):
            q = np.roll(phi, shift, axis=axis)          # the neighbour at index - shift
            qm = np.roll(mask, shift, axis=axis)
            edge = [slice(None)] * 2
            edge[axis] = slice(0, 1) if shift == 1 else slice(-1, None)
            ok = (phi * q < 0) & ~mask & ~qm
            ok[tuple(edge)] = False                       # no wrap-around
            with np.errstate(invalid='ignore', divide='ignore'):
                d = np.where(ok, phi / (phi - q), np.inf)
            d_axis = np.minimum(d_axis, d)
        inv2 += np.where(np.isfinite(d_axis), 1.0 / np.maximum(d_axis, 1e-6) ** 2, 0.0)
    if not (inv2 > 0).any():
        raise ConformalError("phi has no zero contour on the grid")
    T0 = np.full(phi.shape, np.inf)
    near = inv2 > 0
    T0[near] = h / np.sqrt(inv2[near]) / speed[near]
    return sweep(T0, speed, h, mask=mask, order=order, **kw)
