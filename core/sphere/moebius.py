"""Moebius transformations of the unit sphere, and the choice of one for sphere mode (docs/math.md §5).

Parametrisation
---------------
Rotations leave the conformal factor unchanged, so a Moebius transformation matters only through a
point ``c`` of the open unit ball: ``phi_c`` is the hyperbolic translation of the ball that moves ``c``
to the origin (Ahlfors). On the sphere it reads

    phi_c(x) = (1 - |c|^2) (x - c) / |x - c|^2 - c,        |x| = 1,

and it scales lengths at ``x`` by the Poisson kernel ``P(c, x) = (1 - |c|^2) / |x - c|^2``: the region
near ``c / |c|`` grows, the opposite region shrinks. ``-log P(c, x)`` is the Busemann function of the
ideal point ``x``, convex along hyperbolic geodesics.

Objectives (``m`` triangles; ``l_t = log mu_t``, ``mu_t = sqrt(flat sphere area / 3D area)``)
---------------------------------------------------------------------------------------------
- ``none``: ``c = 0`` (the map as computed).
- ``center``: area-centroid centring (Baden, Crane and Kazhdan 2018): the 3D-area-weighted centroid of
  the mapped vertices moves to the origin. It is the minimiser of the convex ``sum_i w_i B_{x_i}(c)``,
  so L-BFGS finds the unique optimum.
- ``area``: Choi's mean ``|log area ratio|`` over triangles (areas normalised to equal totals).
- ``uniform``: the paper's objective, maximise ``min mu / max mu``, i.e. minimise ``max l - min l``.

The L-inf objective is non-smooth and not convex in ``c``. ``optimise`` uses a surrogate that is
accurate everywhere, not only near the start: a triangle's log scale after ``phi_c`` is its current
log scale plus the mean of ``log P(c, x_k)`` over its three vertices (exact for small triangles). The
common ``log(1 - |c|^2)`` drops out of every ratio. On that surrogate it runs a log-sum-exp soft
max - min with a continuation in the sharpness ``beta`` and analytic gradients (scipy BFGS) from
several starts (the three baselines, and points towards the smallest-mu region). The best exact
candidate is then refined to a local minimax optimum of the *exact* objective (``_polish``):
trust-region sequential linear programming on the epigraph form (minimise ``hi - lo`` subject to
``lo <= l_t <= hi``), the per-triangle log scales linearised by central differences in the three
ball parameters and re-linearised after every accepted step, until the predicted gain or the trust
radius vanishes (``converged`` in the info). Every candidate is measured exactly and the baselines are
candidates, so ``uniform`` is never worse than the best baseline that folds nothing.

Folds. Faces that the map folded stay out of the objective. A Moebius map keeps the orientation of
small triangles but can turn a needle whose vertices lie near a great circle, so no candidate may fold
a face that the map did not fold: the baselines and the soft results are rejected if they do, and the
polish carries orientation constraints (``orientation >= ORIENT_MARGIN``) for the least well oriented
faces, adding every face that a step would fold and solving the step again.
"""
import numpy as np
import scipy.sparse as sp
from scipy.optimize import linprog, minimize

MOEBIUS_MODES = ('none', 'center', 'area', 'uniform')


def logsumexp(x):
    """log(sum(exp(x))) of a 1-D array, without overflow."""
    mx = float(x.max())
    return mx + float(np.log(np.exp(x - mx).sum()))


# --- the transformation ----------------------------------------------------------------------------
def ball_map(c, X):
    """``phi_c(X)``: the hyperbolic translation moving ``c`` (3,) (|c| < 1) to 0, applied to points
    ``X`` (k,3) of the closed unit ball. Returns (k,3)."""
    c = np.asarray(c, np.float64)
    X = np.asarray(X, np.float64)
    d = X - c
    d2 = (d * d).sum(1)
    c2 = float(c @ c)
    x2 = (X * X).sum(1)
    den = 1.0 - 2.0 * np.einsum('ij,j->i', X, c) + x2 * c2
    return ((1.0 - c2) * d - d2[:, None] * c) / den[:, None]


def compose_point(cs):
    """The ball point ``p`` (3,) with ``phi_p`` equal, up to a rotation, to ``phi_{c_k} o ... o phi_{c_1}``
    for the list ``cs`` of ball points applied in order: ``p`` is the point that the composition
    moves to the origin."""
    p = np.zeros((1, 3))
    for c in reversed(list(cs)):
        p = ball_map(-np.asarray(c, np.float64), p)
    return p[0]


def _from_q(q):
    """Unconstrained q (3,) -> ball point c = tanh(|q|/2) q/|q| (|q| is the hyperbolic distance of
    c from the origin) and the Jacobian dc/dq (3,3)."""
    r = float(np.linalg.norm(q))
    if r < 1e-9:
        return 0.5 * q, 0.5 * np.eye(3)
    h = q / r
    t = np.tanh(0.5 * r)
    c = t * h
    J = (t / r) * (np.eye(3) - np.outer(h, h)) + 0.5 * (1.0 - t * t) * np.outer(h, h)
    return c, J


def _to_q(c):
    c = np.asarray(c, np.float64)
    r = float(np.linalg.norm(c))
    if r < 1e-12:
        return 2.0 * c
    r = min(r, 1.0 - 1e-12)
    return (2.0 * np.arctanh(r) / r) * c


# --- exact per-triangle log scale ------------------------------------------------------------------
def log_scale(S, F, A):
    """Per-triangle ``l_t = 0.5 log(a_t / A_t)`` (m,) with ``a_t`` the area of the flat triangle of the
    sphere points ``S`` (n,3) and ``A`` (m,) the 3D areas (not normalised)."""
    P = S[F]
    a = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    return 0.5 * np.log(np.maximum(a, np.finfo(float).tiny) / A)


def exact_ratio(S, F, A, c=None):
    """Realised ``min mu / max mu`` of ``phi_c(S)`` (``c`` None: of ``S``)."""
    if c is not None and np.any(c):
        S = ball_map(c, S)
    l = log_scale(S, F, A)
    return float(np.exp(l.min() - l.max()))


def _area_objective(l, A):
    """Choi's mean |log area ratio| with areas normalised to equal totals; ``l`` per-triangle log scale."""
    la = 2.0 * l + np.log(A)
    r = la - logsumexp(la) - np.log(A / A.sum())
    return float(np.abs(r).mean())


# --- the surrogate ----------------------------------------------------------------------------------
class _Surrogate:
    """Log scales of ``phi_c(S)`` predicted from ``S``: ``l_t(c) = l0_t + mean_k log P(c, s_k)`` up to
    the shared term ``log(1 - |c|^2)``. ``S`` (n,3) unit vectors, ``F`` (m,3), ``A`` (m,) 3D areas;
    ``faces`` (k,) optional subset of the faces to work on."""

    def __init__(self, S, F, A, faces=None):
        if faces is not None:
            F, A = F[faces], A[faces]
        used, Fl = np.unique(F, return_inverse=True)
        Fl = Fl.reshape(-1, 3)
        self.S, self.F, self.A = S[used], Fl, A
        self.n = n = len(used)
        m = len(Fl)
        self.l0 = log_scale(self.S, Fl, A)
        # face -> vertex averaging, (n,m): wv = P @ wt
        self.P = sp.csr_matrix((np.full(3 * m, 1.0 / 3.0), (Fl.ravel(), np.repeat(np.arange(m), 3))),
                               shape=(n, m))

    def hard_range(self, q):
        """Exact max - min of the surrogate log scales at ball point c(q)."""
        l, _ = self.terms(_from_q(q)[0], grad=False)
        return float(l.max() - l.min())

    def terms(self, c, grad=True):
        """(l (m,), gradient data): l_t(c) without the shared term, and per-vertex d/dc of
        -2 log|s_k - c| (n,3)."""
        d = self.S - c
        d2 = np.maximum((d * d).sum(1), 1e-300)
        lv = -np.log(d2)                     # log P up to the shared term
        l = self.l0 + lv[self.F].mean(1)
        return l, (2.0 * d / d2[:, None] if grad else None)

    def face_to_grad(self, wt, gv):
        """sum_t wt_t * d l_t / dc, (3,), from per-face weights (m,)."""
        return np.einsum('i,ij->j', self.P @ wt, gv)

    def soft_range(self, q, beta):
        """Soft max - min of l over triangles at ball point c(q); value and gradient in q."""
        c, J = _from_q(q)
        l, gv = self.terms(c)
        hi = logsumexp(beta * l)
        lo = logsumexp(-beta * l)
        val = (hi + lo) / beta
        wt = np.exp(beta * l - hi) - np.exp(-beta * l - lo)
        g = self.face_to_grad(wt, gv)
        return val, J.T @ g

    def area_mean(self, q, eps=1e-3):
        """Smoothed Choi objective mean_t sqrt(r_t^2 + eps^2); value and gradient in q."""
        c, J = _from_q(q)
        l, gv = self.terms(c)
        la = 2.0 * l + np.log(self.A)
        lse = logsumexp(la)
        r = la - lse - np.log(self.A / self.A.sum())
        s = np.sqrt(r * r + eps * eps)
        m = len(r)
        val = s.mean()
        dr = r / s / m                       # d val / d r_t
        p = np.exp(la - lse)                 # d lse / d la_t
        wt = 2.0 * (dr - dr.sum() * p)       # d val / d l_t
        return val, J.T @ self.face_to_grad(wt, gv)


def _vertex_weights(F, A, n):
    return np.bincount(F.ravel(), np.repeat(A / 3.0, 3), minlength=n)


def center_point(S, F, A):
    """Ball point ``c`` (3,) of area-centroid centring: ``sum_i w_i phi_c(s_i) = 0`` with ``w_i`` the
    vertex share of the 3D area. Minimises the convex ``sum_i w_i log(|s_i - c|^2 / (1 - |c|^2))``."""
    w = _vertex_weights(F, A, len(S))
    w = w / w.sum()

    def fun(q):
        c, J = _from_q(q)
        d = S - c
        d2 = np.maximum((d * d).sum(1), 1e-300)
        c2 = float(c @ c)
        val = float(np.dot(w, np.log(d2))) - np.log(1.0 - c2)
        g = -2.0 * (w[:, None] * d / d2[:, None]).sum(0) + 2.0 * c / (1.0 - c2)
        return val, J.T @ g

    res = minimize(fun, np.zeros(3), jac=True, method='BFGS', options=dict(maxiter=200, gtol=1e-10))
    return _from_q(res.x)[0]


# --- the optimiser ----------------------------------------------------------------------------------
BETAS = (8.0, 32.0, 128.0, 512.0, 2048.0)
AREA_SAMPLE = 40_000      # faces used by the mean-|log area| surrogate on larger meshes (every k-th face)
CUBE_CELLS = 20           # the binned surrogate keeps the extreme faces of 6 * CUBE_CELLS^2 cells
ACTIVE = 0.25             # log-scale band around the extremes used by the local polish (times the spread)
ACTIVE_CAP = 1500         # at most this many faces per side in the local polish
FD_STEP = 1e-5            # central-difference step in q (hyperbolic distance)
POLISH_RADIUS = 0.25      # trust radius of one polish step in q (hyperbolic distance)
ORIENT_MARGIN = 1e-9      # smallest orientation a guarded face may reach in the polish
GUARD_START = 64          # the least well oriented faces are guarded from the start
POLISH_ITERS = 200        # at most this many linear programs in the local polish
POLISH_RTOL = 1e-12       # predicted gain (log ratio) or trust radius below this: converged


def _soft_descent(sur, q0, betas=BETAS, maxiter=40):
    q = np.asarray(q0, np.float64).copy()
    for beta in betas:
        res = minimize(sur.soft_range, q, args=(beta,), jac=True, method='BFGS',
                       options=dict(maxiter=maxiter, gtol=1e-7))
        if np.all(np.isfinite(res.x)):
            q = res.x
    return q


def area_point(S, F, A):
    """Ball point (3,) minimising Choi's mean |log area ratio| (surrogate, re-linearised once; on
    meshes with more than ``AREA_SAMPLE`` faces the mean runs over every k-th face)."""
    step = max(1, len(F) // AREA_SAMPLE)
    Fs, As = F[::step], A[::step]
    cs = []
    T = S
    for _ in range(2):
        sur = _Surrogate(T, Fs, As)
        res = minimize(sur.area_mean, np.zeros(3), jac=True, method='BFGS',
                       options=dict(maxiter=100, gtol=1e-8))
        c = _from_q(res.x)[0]
        cs.append(c)
        T = _unit(ball_map(c, T))
    return compose_point(cs)


def _unit(X):
    return X / np.linalg.norm(X, axis=1)[:, None]


def _binned_faces(S, F, l, cells=CUBE_CELLS):
    """Faces (k,) holding the largest and the smallest ``l`` in each cell of a cube-map grid over the
    sphere (by face centroid direction): max and min over these equal max and min over all faces up
    to the variation of a Moebius factor inside one cell."""
    x = S[F].mean(1)
    ax = np.abs(x).argmax(1)
    r = np.arange(len(x))
    big = x[r, ax]
    u = x[r, (ax + 1) % 3] / np.abs(big)
    v = x[r, (ax + 2) % 3] / np.abs(big)
    side = ax * 2 + (big > 0)
    iu = np.clip(((u + 1) * 0.5 * cells).astype(np.int64), 0, cells - 1)
    iv = np.clip(((v + 1) * 0.5 * cells).astype(np.int64), 0, cells - 1)
    cell = (side * cells + iu) * cells + iv
    order = np.lexsort((l, cell))
    cs = cell[order]
    first = np.r_[True, cs[1:] != cs[:-1]]
    last = np.r_[cs[1:] != cs[:-1], True]
    return np.unique(np.r_[order[first], order[last]])


def _starts(sur, extra=(0.25, 0.5)):
    """Extra start points: towards the smallest-mu faces, at hyperbolic distances ``extra`` times
    the spread of log mu."""
    l0 = sur.l0
    low = np.argsort(l0)[:max(1, len(l0) // 100)]
    x = sur.S[sur.F[low]].mean(1).mean(0)
    nx = np.linalg.norm(x)
    if nx < 1e-9:
        return []
    spread = float(l0.max() - l0.min())
    return [np.tanh(0.5 * t * spread) * x / nx for t in extra]


def flip_count(S: np.ndarray, F: np.ndarray, c: np.ndarray | None = None) -> int:
    """Triangles ``F`` (m,3) whose flat image under ``phi_c(S)`` (``S`` (n,3) unit vectors; ``c`` None:
    ``S`` itself) faces the centre. A Moebius map keeps small triangles' orientation but can turn a
    needle whose vertices lie near a great circle."""
    if c is not None and np.any(c):
        S = ball_map(c, S)
    P = S[F]
    return int(((np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]) * P.mean(1)).sum(1) <= 0).sum())


def _active(l, band, cap=ACTIVE_CAP):
    """Faces (k,) within ``band`` of the largest or smallest ``l`` (m,), at most ``cap`` per side."""
    o = np.argsort(l)
    lo = o[:min(cap, int(np.searchsorted(l[o], l[o[0]] + band, side='right')))]
    hi_n = min(cap, len(l) - int(np.searchsorted(l[o], l[o[-1]] - band, side='left')))
    return np.unique(np.r_[lo, o[len(o) - hi_n:]])


def orientation(S: np.ndarray, F: np.ndarray, c: np.ndarray | None = None) -> np.ndarray:
    """Scale-free orientation of the flat triangles of ``phi_c(S)`` (``S`` (n,3) unit vectors, ``F``
    (k,3)): ``det(a, b, c) / (|a - b| |b - c| |c - a|)`` (k,), positive when the image faces outwards;
    about the distance of the three points from a great circle relative to the triangle's size."""
    if c is not None and np.any(c):
        S = ball_map(c, S)
    P = S[F]
    det = np.einsum('ij,ij->i', P[:, 0], np.cross(P[:, 1], P[:, 2]))
    e = np.linalg.norm(P - P[:, [1, 2, 0]], axis=2).prod(1)
    return det / np.maximum(e, np.finfo(float).tiny)


def _slp_step(T, F, A, act, guard, rho):
    """One linear program of the local minimax refinement (sequential linear programming), at the map
    ``T`` (n,3) itself (c = 0): with ``l_t(q)`` the exact per-triangle log scales of ``phi_c(q)(T)`` on
    the faces ``act`` (k,) and ``o_g(q)`` the orientations of the faces ``guard`` (g,), both linearised
    by central differences, minimise ``hi - lo`` subject to ``lo <= l_t + J_t q <= hi``,
    ``o_g + G_g q >= min(o_g, ORIENT_MARGIN)`` and ``|q_i| <= rho``. Returns (ball point c (3,),
    predicted decrease of max l - min l on ``act``, whether the LP solver succeeded)."""
    sel = np.r_[act, guard]
    used, Fl = np.unique(F[sel], return_inverse=True)
    Fl = Fl.reshape(-1, 3)
    Tv = T[used]
    na = len(act)
    Fa, Fg, Aa = Fl[:na], Fl[na:], A[act]

    def vals(q):
        X = ball_map(_from_q(q)[0], Tv)
        return np.r_[log_scale(X, Fa, Aa), orientation(X, Fg)]

    v = vals(np.zeros(3))
    J = np.empty((len(sel), 3))
    for k in range(3):
        e = np.zeros(3)
        e[k] = FD_STEP
        J[:, k] = (vals(e) - vals(-e)) / (2.0 * FD_STEP)
    l, o, Jl, Jo = v[:na], v[na:], J[:na], J[na:]
    g = len(o)
    # variables (q0, q1, q2, hi, lo); rows: l + Jl q - hi <= 0, lo - l - Jl q <= 0, -Jo q <= o - margin
    A_ub = np.zeros((2 * na + g, 5))
    A_ub[:na, :3], A_ub[:na, 3] = Jl, -1.0
    A_ub[na:2 * na, :3], A_ub[na:2 * na, 4] = -Jl, 1.0
    A_ub[2 * na:, :3] = -Jo
    b_ub = np.r_[-l, l, np.maximum(o - ORIENT_MARGIN, 0.0)]           # q = 0 is always feasible
    res = linprog(np.array([0.0, 0.0, 0.0, 1.0, -1.0]), A_ub=A_ub, b_ub=b_ub,
                  bounds=[(-rho, rho)] * 3 + [(None, None)] * 2, method='highs')
    if res.status != 0:
        return np.zeros(3), 0.0, False
    return _from_q(res.x[:3])[0], float(l.max() - l.min() - res.fun), True


def _polish(T, F, A, best_r, iters=POLISH_ITERS):
    """Local minimax refinement of the exact objective on the map ``T`` (n,3) whose faces ``F`` are
    all oriented: trust-region sequential linear programming (``_slp_step``), re-linearised at the
    current map after every accepted step. Only faces within ``2 rho`` (plus a margin) of an extreme
    take part (a face's log scale moves by at most |q| under ``phi_c(q)``). Faces that would fold join
    the orientation guard and the step is solved again, so no triangle is ever folded. A step is
    accepted if the exact ratio over all faces improves; the trust radius ``rho`` grows after a step
    that achieves most of its predicted gain and shrinks after a rejected one. Converged: the
    predicted gain (first-order optimality) or the trust radius falls below ``POLISH_RTOL``. Returns
    (list of ball points applied, T, ratio, exact evaluations, converged, guarded faces)."""
    cs, evals, converged = [], 0, False
    rho = POLISH_RADIUS
    guard = np.argsort(orientation(T, F))[:GUARD_START]
    l = log_scale(T, F, A)
    for _ in range(iters):
        act = _active(l, 2.0 * np.sqrt(3.0) * rho + 1e-2)
        c, pred, ok = _slp_step(T, F, A, act, guard, rho)
        if not ok:
            break
        if pred <= POLISH_RTOL * max(float(l.max() - l.min()), 1.0) or rho < POLISH_RTOL:
            converged = True
            break
        bad = np.nonzero(orientation(T, F, c) <= 0)[0]
        if len(bad):
            guard = np.union1d(guard, bad)
            continue
        l_new = log_scale(_unit(ball_map(c, T)), F, A)
        evals += 1
        r = float(np.exp(l_new.min() - l_new.max()))
        actual = np.log(r) - np.log(best_r)
        if actual <= 0:
            rho *= 0.25
            continue
        cs.append(c)
        T = _unit(ball_map(c, T))
        l = l_new
        best_r = r
        if actual > 0.75 * pred and np.abs(_to_q(c)).max() > 0.9 * rho:
            rho = min(2.0 * rho, POLISH_RADIUS)
        elif actual < 0.25 * pred:
            rho *= 0.5
    return cs, T, best_r, evals, converged, len(guard)


def optimise(S: np.ndarray, F: np.ndarray, A: np.ndarray, mode: str = 'uniform', progress=None,
             starts: int = 3) -> tuple:
    """Choose the Moebius transformation for sphere points ``S`` (n,3) (unit vectors) of the mesh
    faces ``F`` (m,3) with 3D areas ``A`` (m,). ``mode``: one of ``MOEBIUS_MODES``. ``starts``: how
    many of the candidate start points (baselines and points towards the smallest mu) run the full
    soft max-min continuation.

    Returns ``(S2 (n,3) transformed unit vectors, info dict)``; ``info`` has the ball point ``c``
    (list of 3 floats; ``phi_c`` maps it to the centre), and for ``uniform``: the realised ratio of
    every baseline (``baselines``), the chosen ``ratio``, the number of exact objective
    ``evaluations``, ``converged`` (the local minimax refinement reached first-order optimality),
    ``guarded_faces`` (faces under an orientation constraint) and ``excluded_flipped`` (faces the map
    folded, left out of the objective)."""
    report = progress or (lambda f, msg: None)
    S = _unit(np.asarray(S, np.float64))
    F = np.asarray(F, np.int64)
    A = np.asarray(A, np.float64)
    info = {'mode': mode}
    if mode == 'none':
        info['c'] = [0.0, 0.0, 0.0]
        return S, info
    if mode == 'center':
        c = center_point(S, F, A)
        info['c'] = c.tolist()
        return _unit(ball_map(c, S)), info
    if mode == 'area':
        c = area_point(S, F, A)
        info['c'] = c.tolist()
        return _unit(ball_map(c, S)), info
    if mode != 'uniform':
        from ..errors import ConformalError
        raise ConformalError(f"unknown Moebius mode {mode!r}: use one of {', '.join(MOEBIUS_MODES)}")

    # faces the map folded stay folded under any Moebius map: leave them out of the objective
    P = S[F]
    flipped = (np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]) * P.mean(1)).sum(1) <= 0
    if flipped.all():                        # nothing is oriented: no objective to optimise
        info.update(c=[0.0, 0.0, 0.0], ratio=exact_ratio(S, F, A), evaluations=1, converged=False)
        return S, info
    if flipped.any():
        F, A = F[~flipped], A[~flipped]
        info['excluded_flipped'] = int(flipped.sum())
    report(0.0, 'Moebius baselines')
    base = {'none': np.zeros(3), 'center': center_point(S, F, A), 'area': area_point(S, F, A)}
    ratios = {k: exact_ratio(S, F, A, c) for k, c in base.items()}
    info['baselines'] = {k: round(v, 6) for k, v in ratios.items()}
    # a candidate that folds a triangle the map did not fold is never chosen
    allowed = {k: flip_count(S, F, c) == 0 for k, c in base.items()}
    best_name = max((k for k in ratios if allowed[k]), key=ratios.get)
    best_c, best_r = base[best_name], ratios[best_name]
    evals = len(base)

    # soft max-min on the binned surrogate from the most promising starts
    report(0.2, 'soft max-min over the Moebius group')
    sur = _Surrogate(S, F, A, faces=_binned_faces(S, F, log_scale(S, F, A)))
    cand = list(base.values()) + _starts(sur)
    qs = [_to_q(c) for c in cand]
    qs.sort(key=sur.hard_range)
    for k, q0 in enumerate(qs[:starts]):
        report(0.2 + 0.5 * k / starts, 'soft max-min over the Moebius group')
        c = _from_q(_soft_descent(sur, q0))[0]
        r = exact_ratio(S, F, A, c)
        evals += 1
        if r > best_r and flip_count(S, F, c) == 0:
            best_c, best_r, best_name = c, r, 'soft'

    # re-linearise at the best point and polish the exact objective locally
    report(0.75, 'polishing the exact min/max')
    T = _unit(ball_map(best_c, S)) if np.any(best_c) else S
    cs, T, best_r, ev, converged, guarded = _polish(T, F, A, best_r)
    evals += ev
    info['c'] = compose_point([best_c] + cs).tolist()
    info['ratio'] = best_r
    info['evaluations'] = int(evals)
    info['converged'] = bool(converged)
    info['guarded_faces'] = int(guarded)
    return T, info
