"""The ``uniform`` boundary mode: boundary scale factors for the most uniform conformal factor.

The paper's objective is to maximise ``min mu / max mu``. In the log scale ``u`` this is: minimise
``max(u) - min(u)`` over the boundary values ``u_B``, with the interior given by the Yamabe equation
``L_II u_I = -Omega_I - L_IB u_B`` (docs/math.md §2). Because ``u = u0 + harmonic(u_B)`` is affine
in ``u_B``, the vertex-level problem is a linear program; ``vertex_bound`` solves it exactly (active set
over the interior vertices) and reports the certified optimum.

The realised per-triangle ratio of the final map is what matters, and a raw LP optimum is jagged along
the boundary. ``optimise`` therefore works in a smooth, low-dimensional basis of ``u_B`` (Fourier modes
of the boundary arc length, which are the eigenvectors of the boundary loop's Laplacian for uniform
spacing) and runs a sequential linear program on the *realised* per-triangle log scale
``s_T = 0.5 log(A_uv / A_3d)``: each step linearises ``s_T`` through the vertex response
``H = harmonic(Phi)`` (one multi-RHS solve with the prefactored ``L_II``) averaged over each triangle,
solves the min-max LP inside a trust region (an active set of rows, each grid cell of the UV map
represented by its highest and lowest triangle, plus a small smoothness term), builds the map
(boundary curve, harmonic x, conjugate y: one solve with ``L_II`` and one with the Neumann
Laplacian) and keeps the step, or a half or quarter of it, only if the realised ratio improves with
no flipped triangle and conformality inside the budget.
"""
import numpy as np
import scipy.sparse as sp

from ..errors import ConformalError
from ..mesh.geometry import face_means
from ..mesh.measures import singular_values


def _highs_core():
    """HiGHS's own binding (``highspy._core``: a model kept between rounds, re-solved from its last
    basis), imported on first use (``area`` does not need it), or None when it is not installed."""
    try:
        from highspy import _core
    except ImportError:                  # pragma: no cover - without it every round solves from scratch
        return None
    return _core


class _RowLP:
    """A linear program whose rows arrive in rounds: minimise ``cost . x`` subject to ``lo <= x <= hi``
    and ``row_lo <= A x <= row_hi`` for every block of rows added so far. With ``highspy`` the model
    is kept and each ``solve`` after ``add_rows`` restarts the dual simplex from the previous optimal
    basis (new rows only cut off the old optimum, so few pivots follow); without it the whole program
    is solved again by scipy's ``linprog`` (the same HiGHS simplex, from scratch).

    cost, lo, hi: (k,) with +-inf for free bounds. ``presolve``: HiGHS's presolve (off for the small
    programs of ``optimise``, as before). ``scale``: HiGHS's scaling of rows and columns (the model
    programs turn it off, see ``_MinmaxLP``)."""

    def __init__(self, cost, lo, hi, presolve=False, scale=True):
        self.cost, self.lo, self.hi = (np.asarray(a, float) for a in (cost, lo, hi))
        self.presolve = presolve
        self.blocks = []
        self.h = None
        _highs = self._highs = _highs_core()
        if _highs is not None:
            h = self.h = _highs._Highs()
            h.setOptionValue('output_flag', False)
            h.setOptionValue('solver', 'simplex')
            h.setOptionValue('presolve', 'on' if presolve else 'off')
            h.setOptionValue('simplex_dual_edge_weight_strategy', 1)     # Devex: cheaper on dense rows
            if not scale:
                h.setOptionValue('simplex_scale_strategy', 0)
            inf = _highs.kHighsInf
            k = len(self.cost)
            h.addVars(k, np.where(np.isfinite(self.lo), self.lo, -inf),
                      np.where(np.isfinite(self.hi), self.hi, inf))
            h.changeColsCost(k, np.arange(k, dtype=np.int32), self.cost)

    def add_rows(self, A, row_lo, row_hi):
        """Add the rows ``row_lo <= A x <= row_hi``; A (r,k) dense or sparse, or the CSR arrays
        ``(starts (r,), index, value)`` of its nonzeros; bounds (r,) (+-inf)."""
        row_lo, row_hi = np.asarray(row_lo, float), np.asarray(row_hi, float)
        if isinstance(A, tuple):
            starts, index, value = A
        elif sp.issparse(A):
            A = sp.csr_matrix(A)
            starts, index, value = A.indptr[:-1].astype(np.int32), A.indices.astype(np.int32), A.data
        else:                                  # dense rows: CSR arrays without scipy's checks
            A = np.asarray(A, float)
            r, k = A.shape
            starts = np.arange(0, r * k, k, dtype=np.int32)
            index = np.tile(np.arange(k, dtype=np.int32), r)
            value = np.ascontiguousarray(A).ravel()
        if self.h is None:                     # kept for linprog, which takes them all at each solve
            self.blocks.append((sp.csr_matrix((value, index, np.r_[starts, len(value)]),
                                              shape=(len(starts), len(self.cost))), row_lo, row_hi))
            return
        inf = self._highs.kHighsInf
        self.h.addRows(len(row_lo), np.where(np.isfinite(row_lo), row_lo, -inf),
                       np.where(np.isfinite(row_hi), row_hi, inf), len(value), starts, index, value)

    def solve(self):
        """The optimal ``x`` (k,), or None if the program has no optimum (infeasible, unbounded,
        solver failure)."""
        if self.h is not None:
            self.h.run()
            if self.h.getModelStatus() != self._highs.HighsModelStatus.kOptimal:
                return None
            return np.array(self.h.getSolution().col_value)
        from scipy.optimize import linprog   # only without highspy: scipy.optimize costs 0.1 s to import
        A = sp.vstack([sp.csr_matrix(b[0]) for b in self.blocks]).tocsr()
        lo = np.concatenate([b[1] for b in self.blocks])
        hi = np.concatenate([b[2] for b in self.blocks])
        up, dn = np.isfinite(hi), np.isfinite(lo)
        bounds = [(a if np.isfinite(a) else None, b if np.isfinite(b) else None)
                  for a, b in zip(self.lo, self.hi)]
        res = linprog(self.cost, A_ub=sp.vstack([A[up], -A[dn]]).tocsr(), b_ub=np.r_[hi[up], -lo[dn]],
                      bounds=bounds, method='highs-ds', options=dict(presolve=self.presolve))
        return res.x if res.status == 0 else None


def _qc_mean(system, uv, keep=slice(None)):
    """Area-weighted mean of s1/s2 over the triangles ``keep``."""
    J = system.jacobians(uv)[keep]
    A = system.A[keep]
    s = singular_values(J)
    qc = s[:, 0] / np.maximum(s[:, 1], np.finfo(float).tiny)
    return float((qc * A).sum() / A.sum())


def _face_log_scale(system, uv, keep=slice(None)):
    """Realised log scale 0.5 log(A_uv / A_3d) of the triangles ``keep``, or None if any flips."""
    W = uv[system.F[keep]]
    e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    a = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    if not np.all(a > 0):
        return None
    return 0.5 * np.log(a / system.A[keep])


def boundary_basis(system, n_freq):
    """Smooth basis ``Phi`` (nb, 2*n_freq) of boundary functions: cos and sin of 2 pi k s / S for
    k = 1..n_freq, with s the arc length along the boundary loop and S its length. Each column has
    max |value| 1. The constant is left out: it only rescales the whole map."""
    l = system.l
    s = np.r_[0.0, np.cumsum(l[:-1])] / l.sum()
    k = np.arange(1, n_freq + 1)
    ang = 2 * np.pi * s[:, None] * k[None, :]
    return np.concatenate([np.cos(ang), np.sin(ang)], axis=1), np.r_[k, k].astype(float)


class _MinmaxLP:
    """min (t1 - t0) [+ reg . e] s.t. t0 <= s_i + J_i d <= t1 for the rows added so far, with d = a - c
    inside the box ``|d| <= delta`` (the trust region) and, with ``reg_w``, ``e >= |d|`` (two rows of
    two entries each per coefficient), rows arriving in rounds (``_RowLP``). J (r,K), s (r,), c (K,).
    Variables d (K), [e (K),] t1, t0: each face row holds K + 1 entries (the split d = d+ - d- would
    double them, and HiGHS's work per pivot grows with them)."""

    def __init__(self, K, c, delta, reg_w):
        self.K, self.c, self.reg = K, c, reg_w is not None
        box = np.full(K, float(delta))
        if reg_w is None:
            cost, lo, hi = np.r_[np.zeros(K), 1.0, -1.0], np.r_[-box, -np.inf, -np.inf], \
                np.r_[box, np.inf, np.inf]
        else:
            cost, lo, hi = np.r_[np.zeros(K), reg_w, 1.0, -1.0], np.r_[-box, np.zeros(K), -np.inf, -np.inf], \
                np.r_[box, box, np.inf, np.inf]
        # unscaled: every entry of a face row is a mean response of basis columns of max |value| 1, and
        # the t columns are -1, so the rows are of one scale already; HiGHS's scaling only adds work
        # (bump3 at n = 65: 59 -> 51 ms over its two programs, docs/scale.md)
        self.lp = _RowLP(cost, lo, hi, scale=False)
        self.t1 = len(cost) - 2
        if self.reg:                    # e - d >= 0 and e + d >= 0
            k = np.arange(K)
            cols = np.r_[k, K + k, k, K + k]
            rows = np.r_[k, k, K + k, K + k]
            vals = np.r_[-np.ones(K), np.ones(K), np.ones(K), np.ones(K)]
            self.lp.add_rows(sp.csr_matrix((vals, (rows, cols)), shape=(2 * K, len(cost))),
                             np.zeros(2 * K), np.full(2 * K, np.inf))

    def add(self, s, J, side):
        """Add one side of the rows of faces with model values ``s`` (r,) and responses ``J`` (r,K):
        ``side`` +1 the upper rows (``s + J d <= t1``), -1 the lower rows (``s + J d >= t0``)."""
        r = len(s)
        if r == 0:
            return
        K = self.K
        index = np.empty((r, K + 1), np.int32)
        index[:, :K] = np.arange(K, dtype=np.int32)
        index[:, K] = self.t1 if side > 0 else self.t1 + 1
        value = np.empty((r, K + 1))
        value[:, :K] = J
        value[:, K] = -1.0
        A = (np.arange(0, r * (K + 1), K + 1, dtype=np.int32), index.ravel(), value.ravel())
        if side > 0:
            self.lp.add_rows(A, np.full(r, -np.inf), -s)
        else:
            self.lp.add_rows(A, -s, np.full(r, np.inf))

    def solve(self):
        """(a (K,), predicted spread) at the optimum, or (None, None)."""
        x = self.lp.solve()
        if x is None:
            return None, None
        self.bounds = x[-2], x[-1]
        return self.c + x[:self.K], x[-2] - x[-1]


def _model_lp(s, JF, c, delta, reg_w, active=200, max_rounds=6, max_add=1000, seed=16, batch=64, tol=1e-9):
    """Minimise the spread of the linear model ``s + JF (a - c)`` over all faces, inside the box
    ``|a - c| <= delta``, by an active set of rows: start from the ``active`` lowest and highest
    faces and add the faces the model says exceed the current bounds (at most ``max_add`` a round,
    worst first). Returns the best (a, model spread over all faces) seen, or (None, None).

    Each round's program (the rows of the active set) is solved exactly but without handing it all to
    the solver: the solver's model starts from the upper rows of the ``seed`` highest faces and the
    lower rows of the ``seed`` lowest, and takes in, at most ``batch`` a side at a time, the active
    set's rows (one side of a face: upper or lower) that its optimum violates by more than ``tol``
    (relative), until none does; the model is kept between rounds and re-solved from its last basis
    (``_RowLP``). The optimum of a program is the optimum of any subset of its rows that it
    satisfies, so the rounds see the same optima as with every active row in the solver
    (bench/flatten_table.py unchanged), at a fraction of the cost."""
    order = np.argsort(s)
    k = min(active, len(s))
    rows = np.unique(np.r_[order[:k], order[-k:]])
    lp = _MinmaxLP(JF.shape[1], c, delta, reg_w)
    inside = {1: np.zeros(len(s), bool), -1: np.zeros(len(s), bool)}
    q = min(seed, k)
    for side, first in ((1, order[-q:]), (-1, order[:q])):
        inside[side][first] = True
        lp.add(s[first], JF[first], side)
    best = (None, None)
    fresh = False                                 # a is the optimum of the solver's rows as they are
    for _ in range(max_rounds):
        s_r, J_r = s[rows], JF[rows]              # the round's rows, sliced once (not per solve)
        in_r = {side: inside[side][rows] for side in (1, -1)}
        while True:                               # the exact optimum over ``rows``
            if not fresh:                         # (a new round alone adds no row: no solve again)
                a, _ = lp.solve()
                if a is None:
                    return best
                fresh = True
            t1, t0 = lp.bounds
            m = s_r + J_r @ (a - c)
            added = 0
            for side, viol in ((1, m - t1), (-1, t0 - m)):
                out = np.nonzero((viol > tol * max(t1 - t0, 1e-12)) & ~in_r[side])[0]
                pick = out[np.argsort(-viol[out])[:batch]]
                add = rows[pick]
                inside[side][add] = True
                in_r[side][pick] = True
                lp.add(s_r[pick], J_r[pick], side)
                added += len(add)
            if not added:
                break
            fresh = False
        model = s + JF @ (a - c)
        spread = float(model.max() - model.min())
        if best[1] is None or spread < best[1]:
            best = (a, spread)
        lo, hi = model[rows].min(), model[rows].max()
        excess = np.maximum(model - hi, lo - model)
        out = np.nonzero(excess > 1e-4 * max(hi - lo, 1e-12))[0]
        if len(out) == 0:
            break
        rows = np.union1d(rows, out[np.argsort(-excess[out])[:max_add]])
    return best


def _face_means(H, T):
    """Mean (t, K) of the rows of H (n, K) at the corners of the triangles T (t, 3): a third of each, in
    increasing vertex order (the sums of the sparse averaging matrix this replaces, to the bit)."""
    T = np.sort(T, axis=1)
    third = 1.0 / 3.0
    return third * H[T[:, 0]] + third * H[T[:, 1]] + third * H[T[:, 2]]


def _representatives(system, uv, s, keep, bins):
    """Indices into ``s`` (the counted triangles) of the highest and the lowest triangle in each cell
    of a ``bins`` x ``bins`` grid over the UV map ``uv`` (n,2)."""
    C = face_means(uv, system.F[keep])
    lo, hi = C.min(0), C.max(0)
    ij = np.minimum(((C - lo) / np.maximum(hi - lo, 1e-300) * bins).astype(np.int64), bins - 1)
    cell = ij[:, 0] * bins + ij[:, 1]
    # per-cell extremes by scatter (no sort of all m triangles: 0.7 s at 400k): of equal values the
    # lowest index for the minimum and the highest for the maximum
    nc, m = bins * bins, len(s)
    index = np.arange(m)
    low = np.full(nc, np.inf)
    np.minimum.at(low, cell, s)
    at = s == low[cell]
    first = np.full(nc, m)
    np.minimum.at(first, cell[at], index[at])
    high = np.full(nc, -np.inf)
    np.maximum.at(high, cell, s)
    at = s == high[cell]
    last = np.full(nc, -1)
    np.maximum.at(last, cell[at], index[at])
    return np.unique(np.r_[first[first < m], last[last >= 0]])


def optimise(system, n_freq=None, max_iter=10, max_maps=8, qc_slack=None, active=200, reg=1e-3,
             bins=64, progress=None, real_faces=None, min_gain=1e-3):
    """Maximise the realised ``min mu / max mu`` over smooth boundary scale factors.

    system: ``DiskSystem``. n_freq: Fourier modes of u_B (default grows with the boundary length, at most
    16). max_iter: outer steps (each builds at most three maps); max_maps: maps built in all. qc_slack:
    allowed rise of the area-weighted mean quasi-conformal distortion over the ``area`` map (default: half
    its excess over 1, at least 0.002). active: faces per side the LP starts from. reg: weight of the
    step-length term (per unit of |coefficient| times frequency, relative to the spread). real_faces:
    optional (m,) bool; only these triangles count in the objective and the conformality budget. bins: the
    LP sees, in each cell of a bins x bins grid over the current UV map, only the highest and the lowest
    triangle (the response rows are smooth, so neighbours are near-duplicates); the realised map is always
    measured on every triangle. min_gain: if the ``area`` map's realised ratio is already at least ``1 -
    min_gain`` (a flat or nearly flat mesh), no ratio can beat it by more than ``min_gain`` (the ratio is
    at most 1): the ``area`` map is returned at once, with ``area_certified`` in the dict (docs/scale.md).
    Returns ``u`` (n,), ``uv`` (n,2) and a dict for the report (``qc_budget`` in it once a step was
    checked against the budget)."""
    progress = progress or (lambda f, msg: None)
    nb = len(system.B)
    if n_freq is None:
        n_freq = int(np.clip(nb // 8, 1, 16))
    Phi, freq = boundary_basis(system, n_freq)
    keep = slice(None) if real_faces is None else np.asarray(real_faces, bool)

    def log_scale(uv):
        s = _face_log_scale(system, uv, keep)
        return s

    # the boundary response H (n, K) of u to the coefficients needs only L_II. With the Neumann factor
    # still on its way (big meshes) it is solved first, overlapping that factorisation;
    # otherwise once the area map shows a gain is possible. (On a thread beside the area map's
    # measures it gained nothing: both are memory-bound; 1M triangles 5.9-6.3 s against 5.3-5.4 s
    # inline, 8k-400k triangles the same or 1-4 ms slower, docs/scale.md)
    H = system.harmonic(Phi) if system.conjugate_pending else None
    u0 = system.yamabe(np.zeros(nb))
    uv0 = system.map_from_u(u0)
    s0 = log_scale(uv0)
    if s0 is None:
        raise ConformalError("the area-preserving map already folds: the mesh has triangles too "
                             "degenerate to flatten; clean it up (merge by distance, dissolve degenerate)")
    spread0 = float(s0.max() - s0.min())
    flat = spread0 <= -np.log1p(-min_gain)
    progress(0.15, 'boundary response')
    budget = []

    def qc_budget():
        """The conformality budget, measured on the area map the first time a step needs it (a
        round that predicts no gain never pays for it: 0.6 s at 1M triangles)."""
        if not budget:
            qc0 = _qc_mean(system, uv0, keep)
            budget.append(qc0 + (max(0.5 * (qc0 - 1.0), 0.002) if qc_slack is None else qc_slack))
        return budget[0]
    if flat:
        return u0, uv0, {'ratio_area_mode': float(np.exp(-spread0)), 'iterations': 0, 'maps_built': 0,
                         'basis_size': int(Phi.shape[1]), 'qc_budget': round(qc_budget(), 5),
                         'area_certified': f"the area map's ratio is within {min_gain:g} of 1"}
    Fk = system.F[keep]
    reps0 = _representatives(system, uv0, s0, keep, bins)      # the first round's
    if H is None:
        H = system.harmonic(Phi)
    # the linear model of s_T (face means of H) is needed only on each round's representatives,
    # never the whole (m, K) matrix (256 MB at 1M triangles)
    best = dict(c=np.zeros(Phi.shape[1]), u=u0, uv=uv0, s=s0, spread=float(s0.max() - s0.min()))
    delta = best['spread']
    reg_w = reg * best['spread'] * freq if reg else None
    it, maps = 0, 0
    for it in range(1, max_iter + 1):
        progress(0.2 + 0.7 * it / max_iter, f'optimising boundary scale ({it})')
        if maps >= max_maps:
            break
        reps = reps0 if it == 1 else _representatives(system, best['uv'], best['s'], keep, bins)
        a, predicted = _model_lp(best['s'][reps], _face_means(H, Fk[reps]), best['c'], delta, reg_w, active)
        if a is None or best['spread'] - predicted < 1e-3 * best['spread']:
            break                         # no gain in this box, nor in any smaller one
        accepted = False
        for t in (1.0, 0.5, 0.25):
            cand = best['c'] + t * (a - best['c'])
            u = u0 + H @ cand
            maps += 1
            try:
                uv = system.map_from_u(u)
            except ConformalError:
                continue
            s_new = log_scale(uv)
            if s_new is None:
                continue
            spread = float(s_new.max() - s_new.min())
            if spread >= best['spread'] * (1 - 1e-4):
                continue
            qc = _qc_mean(system, uv, keep)
            if qc > qc_budget():
                continue
            best = dict(c=cand, u=u, uv=uv, s=s_new, spread=spread)
            accepted = True
            break
        if not accepted:
            delta *= 0.25
            if delta < 1e-3 * best['spread']:
                break
    opt = {
        'ratio_area_mode': float(np.exp(-(s0.max() - s0.min()))),
        'iterations': it,
        'maps_built': maps,
        'basis_size': int(Phi.shape[1]),
    }
    if budget:                            # measured only if a step needed it
        opt['qc_budget'] = round(budget[0], 5)
    return best['u'], best['uv'], opt


def vertex_bound(system, tol=1e-9, batch=32, max_rounds=100, real_faces=None, flat=1e-12, near_flat=1e-3,
                 start=8):
    """Certified vertex-level optimum: the ratio ``exp(-(max u - min u))`` at the best ``u_B`` over all
    boundary values (the linear program of docs/math.md §2). Active set over interior vertices: the
    program starts from the ``start`` lowest and highest interior vertices of the ``area`` map and
    adds rows of ``-L_II^-1 L_IB`` for the (at most ``batch``) vertices that violate the current
    bounds most, until none does by more than ``tol`` (relative). The model is kept between rounds
    and re-solved from its last basis (``_RowLP``). real_faces: optional (m,) bool; only vertices of
    these triangles are constrained.

    The optimum spread lies in [0, s], with ``s`` the spread of the ``area`` map's ``u`` (u_B = 0 is
    feasible): if ``s <= flat`` (a flat mesh) the ratio ``exp(-s)`` is returned at once, certified
    to ``flat``. If ``s < near_flat`` the program is ill-conditioned (measured: minutes, then
    HiGHS fails on a bent maze) and ConformalError('solve_failed') says at once that the optimum
    lies in [exp(-s), 1]. If ``s < 0.01`` the program is solved for ``u / s`` and scaled back (``u`` is linear
    in ``Omega``), so a nearly flat mesh is solved to the same relative accuracy as a curved one."""
    nb, nI = len(system.B), len(system.I)
    u0 = system.yamabe(np.zeros(nb))
    if nI == 0:
        return 1.0
    counted = np.ones(nI, bool)
    if real_faces is not None:
        used = np.zeros(system.n, bool)
        used[system.F[np.asarray(real_faces, bool)]] = True
        counted = used[system.I]
    uI = u0[system.I]
    scale = max(float(uI[counted].max(initial=0.0)) - float(uI[counted].min(initial=0.0)), 0.0)
    if scale <= flat:
        return float(np.exp(-scale))
    if scale < near_flat:
        raise ConformalError(f"the mesh is nearly flat: the bound lies between {np.exp(-scale):.6f} (the "
                             "area map's vertex ratio) and 1; its linear program is not solved",
                             'solve_failed')
    scale = min(scale, 1e-2)            # rescale only nearly flat meshes: curved ones solve as they are
    uI = uI / scale
    order = np.argsort(uI)
    order = order[counted[order]]
    inside = {1: np.zeros(nI, bool), -1: np.zeros(nI, bool)}
    # variables uB (nb), t1; minimise t1 subject to 0 <= uB <= t1 and 0 <= u_i <= t1 for the interior
    # vertices taken in so far: the upper row of a vertex once it is above t1, the lower once below 0
    # (starting from the ``start`` highest and lowest of the area map). The lower end is pinned at 0
    # without loss: the harmonic extension of a constant is that constant (the rows of L sum to 0), so
    # shifting uB shifts every u_i, and ``0 <= uB`` is a bound on the variables instead of nb rows
    inf = np.inf
    lp = _RowLP(np.r_[np.zeros(nb), 1.0], np.zeros(nb + 1), np.full(nb + 1, inf))
    lp.add_rows(sp.hstack([sp.identity(nb, format='csr'), sp.csr_matrix(-np.ones((nb, 1)))]).tocsr(),
                np.full(nb, -inf), np.zeros(nb))

    def add(hi, lo):
        """Take in the upper rows of the vertices ``hi`` and the lower rows of ``lo``."""
        idx = np.unique(np.r_[hi, lo])
        rows = _response_rows(system, idx)
        for side, which in ((1, hi), (-1, lo)):
            if len(which) == 0:
                continue
            inside[side][which] = True
            K = len(which)
            Rw = rows[np.searchsorted(idx, which)]
            if side > 0:
                lp.add_rows(np.hstack([Rw, -np.ones((K, 1))]), np.full(K, -inf), -uI[which])
            else:
                lp.add_rows(np.hstack([Rw, np.zeros((K, 1))]), -uI[which], np.full(K, inf))
    add(order[-start:], order[:start])
    for _ in range(max_rounds):
        x = lp.solve()
        if x is None:
            raise ConformalError("the bound's linear program failed", 'solve_failed')
        uB, t1, t0 = x[:nb], x[nb], 0.0
        u = uI + _harmonic_interior(system, uB)
        new = []
        for side, viol in ((1, u - t1), (-1, t0 - u)):
            viol = np.where(counted & ~inside[side], viol, -np.inf)
            cand = np.nonzero(viol > tol * max(1.0, t1 - t0))[0]
            new.append(cand[np.argsort(-viol[cand])[:batch]])
        if not len(new[0]) and not len(new[1]):
            return float(np.exp(-(t1 - t0) * scale))
        add(*new)
    return float(np.exp(-(t1 - t0) * scale))


def _harmonic_interior(system, uB):
    """Interior values (nI,) of the harmonic extension of ``uB`` (nb,)."""
    return -system.solve_II(system.L_IB @ uB)


def _response_rows(system, R):
    """Rows ``R`` of the interior response ``-L_II^-1 L_IB`` (|R|, nb), via |R| solves with the
    symmetric ``L_II``."""
    E = np.zeros((len(system.I), len(R)))
    E[R, np.arange(len(R))] = 1.0
    Z = system.solve_II(E)
    return -(system.L_IB.T @ Z).T
