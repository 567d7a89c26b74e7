"""Polthier's midedge discrete conformal map and the paper's restricted boundary family.

A baseline that reproduces Aflalo, Kimmel and Zibulevsky (2013), sections 3 to 5. It is not a user
mode: the add-on and the CLI flatten with ``core.flatten``.

The discrete setting (non-conforming, Crouzeix-Raviart):

- ``u`` is piecewise linear and continuous: one value per vertex (P1).
- ``v`` is piecewise linear but lives on the *midedge grid*: one value per edge, taken at the edge's
  midpoint; it is continuous across an edge only at that midpoint (P1 non-conforming).
- ``f = u + i v`` is discrete holomorphic when, in every triangle T, ``grad_T v = n_T x grad_T u``
  (the Cauchy-Riemann relation; ``n_T`` the unit normal, so this is a 90-degree rotation in T's
  plane). Such a ``v`` exists, on a simply connected domain, exactly when ``u`` is discrete harmonic
  (cotan Laplacian row zero) at every vertex encircled by the domain.
- On T the map is then a similarity with scale ``|grad_T u|``: the per-triangle conformal factor
  (paper eq. 3.2) is ``mu_T = |grad_T u|``, and the area factor is ``mu_T**2``. The image of T's
  medial triangle (the midpoints of its edges) is T's medial triangle scaled by ``mu_T``.

Algorithm 1 (``midedge_map``): cut (remove) one face, set ``u = -1`` and ``u = +1`` at two of its
vertices, make ``u`` discrete harmonic at every other vertex with the natural (Neumann) condition on
every boundary, the mesh's own boundary included, and recover ``v`` on the midedges. Nothing
controls the boundary: this is the map of the paper's section 4 (Figures 1-2).

Section 5 (``restricted_map``, ``optimise_restricted``, ``lp_restricted``): ``u`` takes Dirichlet
values ``u_B`` on the boundary loop, in [0, 1], rising monotonically from 0 at a start vertex to 1 at
the loop's midpoint and falling monotonically back; ``u`` is harmonic inside and ``v`` its midedge
conjugate. Every such map is conformal (discretely) and, because ``u_B`` has one maximum and one
minimum, ``u`` has no interior critical point and the map folds nowhere. The boundary values are
chosen to make ``mu`` as uniform as possible.
"""
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..errors import ConformalError
from ..mesh.geometry import face_areas
from ..mesh.laplacian import cotan_laplacian, face_gradients, gradient
from ..mesh.measures import uv_measures
from ..mesh.solve import Factor
from ..mesh.validate import check_mesh


@dataclass
class MidedgeMap:
    """A midedge conformal map.

    ``E`` (k,2) int64 edges (vertex pairs, ``E[:,0] < E[:,1]``); ``FE`` (m,3) int64 edge of each
    face opposite each corner (``FE[t,c]`` joins ``F[t,c+1]`` and ``F[t,c+2]``); ``keep`` (m,) bool,
    the faces the map covers (all but the cut face); ``u`` (n,) vertex values (NaN at a vertex no kept
    face uses); ``v`` (k,) midedge values (NaN on edges of no kept face); ``uv_mid`` (k,2) image of
    every edge midpoint, ``(u at the midpoint, v)``; ``mu`` (m,) per-triangle conformal factor
    ``|grad u|`` normalised so that the total image area of the kept faces equals their 3D area (NaN
    on the cut face); ``report`` dict."""
    E: np.ndarray
    FE: np.ndarray
    keep: np.ndarray
    u: np.ndarray
    v: np.ndarray
    uv_mid: np.ndarray
    mu: np.ndarray
    report: dict = field(default_factory=dict)

    def midedge_mesh(self, V, F):
        """The medial triangles of the kept faces as a mesh: ``Vm`` (k,3) 3D edge midpoints, ``Fm``
        (m_kept,3) int64 (counter-clockwise like ``F``), ``UVm`` (k,2) their images. Each medial
        triangle maps affinely with exactly the Jacobian of the non-conforming map on its face, so
        ``core.measures.uv_measures(Vm, Fm, UVm)`` gives the map's per-triangle measures."""
        Vm = 0.5 * (V[self.E[:, 0]] + V[self.E[:, 1]])
        return Vm, self.FE[self.keep], self.uv_mid

    def vertex_uv(self, V, F):
        """A conforming (one value per vertex) version of the map, (n,2): ``u`` itself, and at each
        vertex the area-weighted mean over its kept faces of the linear extension of ``v`` from the
        face's three midpoints (``v(P_c) = v_{c+1} + v_{c+2} - v_c``). Used to sample the map at
        vertices, e.g. for geodesics; the per-face values differ by O(h^2)."""
        n = len(V)
        Fk, FEk = F[self.keep], self.FE[self.keep]
        A = face_areas(V, Fk)
        vv = self.v[FEk]
        at = vv[:, [1, 2, 0]] + vv[:, [2, 0, 1]] - vv
        w = np.bincount(Fk.ravel(), np.repeat(A, 3), minlength=n)
        y = np.bincount(Fk.ravel(), (at * A[:, None]).ravel(), minlength=n)
        with np.errstate(invalid='ignore', divide='ignore'):
            y = y / w
        return np.stack([self.u, y], axis=1)


def midedge_edges(F):
    """Edges of ``F`` (m,3): ``E`` (k,2) int64 with ``E[:,0] < E[:,1]`` and ``FE`` (m,3) int64, the
    edge opposite each corner."""
    F = np.asarray(F, np.int64)
    n = int(F.max()) + 1
    a, b = F[:, [1, 2, 0]], F[:, [2, 0, 1]]
    key = np.minimum(a, b) * n + np.maximum(a, b)
    uniq, inv = np.unique(key.ravel(), return_inverse=True)
    return np.stack([uniq // n, uniq % n], axis=1), inv.reshape(-1, 3).astype(np.int64)


def cr_gradient(G, FE, v):
    """Per-triangle gradient (m,3) of a Crouzeix-Raviart function with midedge values ``v`` (k,).
    ``G`` (m,3,3) hat-function gradients from ``face_gradients``. The CR basis function of the edge
    opposite corner c is ``1 - 2 phi_c``, so ``grad v = -2 sum_c v_{FE[t,c]} G[t,c]``."""
    return -2.0 * np.einsum('mk,mkd->md', v[FE], G)


def conjugate_midedge(V, F, u, keep=None, FE=None, n_edges=None):
    """Midedge conjugate ``v`` (k,) of the vertex function ``u`` (n,) over the faces ``keep`` (m,)
    bool (default all), by least squares on the per-face Cauchy-Riemann differences: in face T, for
    the midpoints ``m_a``, ``m_b`` of the edges opposite corners a, b,
    ``v(m_b) - v(m_a) = (n_T x grad_T u) . (P_a - P_b) / 2``. When ``u`` is discrete harmonic at every
    vertex the kept faces encircle, these differences are consistent and the solution satisfies them
    to solver precision. ``v`` is 0 at the first kept edge, NaN on edges of no kept face.
    Returns ``(v, residual)``, the largest violated difference relative to the largest difference."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    if FE is None:
        E, FE = midedge_edges(F)
        n_edges = len(E)
    keep = np.ones(len(F), bool) if keep is None else np.asarray(keep, bool)
    Fk, FEk = F[keep], FE[keep]
    G, N, _ = face_gradients(V, Fk)
    X = np.cross(N, gradient(G, Fk, u))
    P = V[Fk]
    rows, cols, vals, rhs = [], [], [], []
    mk = len(Fk)
    for r, (a, b) in enumerate(((0, 1), (1, 2), (2, 0))):
        idx = r * mk + np.arange(mk)
        rows += [idx, idx]
        cols += [FEk[:, b], FEk[:, a]]
        vals += [np.ones(mk), -np.ones(mk)]
        rhs.append(0.5 * np.einsum('md,md->m', X, P[:, a] - P[:, b]))
    D = sp.coo_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                      shape=(3 * mk, n_edges)).tocsr()
    d = np.concatenate(rhs)
    used = np.zeros(n_edges, bool)
    used[FEk.ravel()] = True
    idx = np.nonzero(used)[0]
    free = idx[1:]
    Df = D[:, free]
    K = (Df.T @ Df).tocsc()
    v = np.full(n_edges, np.nan)
    v[idx[0]] = 0.0
    v[free] = Factor(K).solve(Df.T @ d)
    res = np.abs(D[:, idx] @ v[idx] - d).max() / max(np.abs(d).max(), np.finfo(float).tiny)
    return v, float(res)


def _assemble(V, F, u, keep, E, FE, report):
    """Conjugate, midedge images and normalised conformal factor of a harmonic ``u``."""
    v, res = conjugate_midedge(V, F, u, keep, FE, len(E))
    uv_mid = np.stack([0.5 * (u[E[:, 0]] + u[E[:, 1]]), v], axis=1)
    G, _, A = face_gradients(V, F)
    g = np.linalg.norm(gradient(G, F, np.nan_to_num(u)), axis=1)
    c = np.sqrt((g[keep] ** 2 * A[keep]).sum() / A[keep].sum())
    if not c > 0:
        raise ConformalError("the midedge map is degenerate (u is constant): choose other pins")
    mu = np.where(keep, g / c, np.nan)
    report['cr_residual'] = res
    return MidedgeMap(E=E, FE=FE, keep=keep, u=u, v=v, uv_mid=uv_mid, mu=mu, report=report)


def midedge_map(V, F, cut_face=0, pins=(0, 1), values=(-1.0, 1.0)):
    """Algorithm 1, the uncontrolled midedge map. ``V`` (n,3), ``F`` (m,3) a connected triangle mesh
    (disk or closed genus 0). ``cut_face``: the face removed. ``pins``: two corners (0..2) of that face
    whose vertices get ``u = values``; every other vertex, including all boundary vertices, gets the
    natural condition ``(L' u)_i = 0`` with ``L'`` the cotan Laplacian without the cut face.
    Returns ``MidedgeMap``; its ``report`` holds ``cr_residual`` and ``seconds``."""
    t0 = time.perf_counter()
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n, m = len(V), len(F)
    if not 0 <= int(cut_face) < m:
        raise ConformalError(f"cut_face {cut_face} is out of range: the mesh has {m} faces")
    if len(set(pins)) != 2 or not all(0 <= p <= 2 for p in pins):
        raise ConformalError(f"pins must be two different corners 0, 1 or 2 of the cut face, got {pins}")
    keep = np.ones(m, bool)
    keep[cut_face] = False
    Fk = F[keep]
    live = np.zeros(n, bool)
    live[Fk.ravel()] = True
    D = F[cut_face, list(pins)]
    if not live[D].all():
        raise ConformalError("a pinned vertex of the cut face belongs to no other face: pin the other "
                             "corners or cut another face")
    L = cotan_laplacian(V, Fk, n)
    free = np.nonzero(live)[0]
    free = free[~np.isin(free, D)]
    u = np.full(n, np.nan)
    u[D] = values
    u[free] = Factor(L[free][:, free]).solve(-(L[free][:, D] @ np.asarray(values, float)))
    E, FE = midedge_edges(F)
    mm = _assemble(V, F, u, keep, E, FE, {'cut_face': int(cut_face), 'pinned': D.tolist()})
    mm.report['seconds'] = time.perf_counter() - t0
    return mm


# ---------------------------------------------------------------------------------------------------
# Section 5: the restricted boundary family
# ---------------------------------------------------------------------------------------------------

class RestrictedFamily:
    """The maps of section 5 on a disk ``V`` (n,3), ``F`` (m,3). The boundary loop (surface on its
    left) is rotated to begin at vertex ``start`` (default: the loop's first vertex); ``h = nb // 2``
    is its midpoint. Boundary values are parametrised by non-negative weights ``z = (a (h,), b (nb-h,))``:
    ``d = a / sum a`` are the rises ``u_B[k+1] - u_B[k]`` for k < h, ``e = b / sum b`` the falls after
    the midpoint, so ``u_B[0] = 0``, ``u_B[h] = 1`` and ``u_B`` is in [0, 1] and monotone on each half
    for every ``z >= 0``. The cotan Laplacian's interior block is factored once."""

    def __init__(self, V, F, start=None):
        self.V = np.asarray(V, np.float64)
        self.F = np.asarray(F, np.int64)
        info = check_mesh(self.V, self.F, kind='disk')
        loop = info.boundary
        if start is not None:
            hit = np.nonzero(loop == int(start))[0]
            if len(hit) == 0:
                raise ConformalError(f"start vertex {start} is not on the boundary loop")
            loop = np.roll(loop, -hit[0])
        self.B = loop
        n = self.n = len(self.V)
        nb = self.nb = len(loop)
        if nb < 4:
            raise ConformalError("the boundary loop needs at least 4 vertices")
        self.h = nb // 2
        mask = np.zeros(n, bool)
        mask[loop] = True
        self.I = np.nonzero(~mask)[0]
        L = cotan_laplacian(self.V, self.F)
        self.L_II = L[self.I][:, self.I].tocsc()
        self.L_IB = L[self.I][:, self.B].tocsc()
        self._II = Factor(self.L_II)
        self.G, self.N, self.A = face_gradients(self.V, self.F)
        self.w = self.A / self.A.sum()
        self.E, self.FE = midedge_edges(self.F)

    # -- parametrisation -------------------------------------------------------------------------
    def boundary_values(self, z):
        """``u_B`` (nb,) from weights ``z`` (nb,) >= 0."""
        h = self.h
        a, b = z[:h], z[h:]
        d, e = a / a.sum(), b / b.sum()
        uB = np.empty(self.nb)
        uB[0] = 0.0
        uB[1:h + 1] = np.cumsum(d)
        uB[h + 1:] = 1.0 - np.cumsum(e)[:-1]
        return uB

    def weights_from_values(self, uB):
        """Inverse of ``boundary_values`` for a valid ``u_B`` (monotone halves, 0 at 0, 1 at h)."""
        h = self.h
        d = np.diff(uB[:h + 1])
        e = -np.diff(np.r_[uB[h:], 0.0])
        return np.r_[d, e]

    def ramp(self):
        """The starting point: ``u_B`` linear in arc length on each half (a 'hat' on the loop)."""
        l = np.linalg.norm(self.V[np.roll(self.B, -1)] - self.V[self.B], axis=1)
        return np.r_[l[:self.h], l[self.h:]]

    def harmonic(self, uB):
        """``u`` (n,) harmonic with boundary values ``uB`` (nb,)."""
        u = np.empty(self.n)
        u[self.B] = uB
        u[self.I] = self._II.solve(-(self.L_IB @ uB))
        return u

    def grad_mu2(self, u):
        """Per-triangle gradients ``g`` (m,3) and ``|g|^2`` (m,)."""
        g = gradient(self.G, self.F, u)
        return g, np.einsum('md,md->m', g, g)

    # -- objective -------------------------------------------------------------------------------
    def soft_objective(self, z, p):
        """Smoothed L-inf objective and its gradient in ``z``: ``f = log ||mu||_p + log ||1/mu||_p``
        with area-weighted p-norms (the log of soft-max over soft-min), so ``exp(-f)`` rises to
        ``min mu / max mu`` as p grows. Scale- and shift-invariant in ``u``."""
        uB = self.boundary_values(z)
        u = self.harmonic(uB)
        g, s = self.grad_mu2(u)
        s = np.maximum(s, 1e-300)
        ls = np.log(s)
        lw = np.log(self.w)
        x1 = 0.5 * p * ls + lw
        x2 = -0.5 * p * ls + lw
        m1, m2 = x1.max(), x2.max()
        e1, e2 = np.exp(x1 - m1), np.exp(x2 - m2)
        S1, S2 = e1.sum(), e2.sum()
        f = (m1 + np.log(S1) + m2 + np.log(S2)) / p
        # df/ds_T = (pi1 - pi2) / (2 s_T);  ds/dg = 2 g
        dg = ((e1 / S1 - e2 / S2) / s)[:, None] * g
        du = np.bincount(self.F.ravel(), np.einsum('md,mkd->mk', dg, self.G).ravel(), minlength=self.n)
        duB = du[self.B] - self.L_IB.T @ self._II.solve(du[self.I])
        return f, self._chain(z, duB)

    def _chain(self, z, duB):
        """Gradient in ``z`` of a function of ``u_B`` with gradient ``duB`` (nb,)."""
        h = self.h
        a, b = z[:h], z[h:]
        # u_B[k] = sum_{j<k} d_j (k = 1..h);  u_B[h+k] = 1 - sum_{j<k} e_j (k = 1..nb-h-1)
        gd = np.cumsum(duB[1:h + 1][::-1])[::-1]
        ge = -np.r_[np.cumsum(duB[h + 1:][::-1])[::-1], 0.0]
        d, e = a / a.sum(), b / b.sum()
        ga = (gd - gd @ d) / a.sum()
        gb = (ge - ge @ e) / b.sum()
        return np.r_[ga, gb]

    def ratio(self, u):
        """Realised ``min mu / max mu`` over triangles of the harmonic ``u``."""
        s = self.grad_mu2(u)[1]
        return float(np.sqrt(s.min() / s.max()))

    def map(self, uB, report=None):
        """The ``MidedgeMap`` with boundary values ``uB`` (nb,)."""
        u = self.harmonic(uB)
        return _assemble(self.V, self.F, u, np.ones(len(self.F), bool), self.E, self.FE,
                         dict(report or {}, start=int(self.B[0])))


def restricted_map(V, F, uB=None, start=None):
    """A map of the restricted family with boundary values ``uB`` (nb,) along the boundary loop
    rotated to ``start`` (default: the arc-length ramp). Returns ``MidedgeMap``."""
    fam = RestrictedFamily(V, F, start)
    if uB is None:
        uB = fam.boundary_values(fam.ramp())
    uB = np.asarray(uB, np.float64)
    if uB.shape != (fam.nb,):
        raise ConformalError(f"uB must have one value per boundary vertex ({fam.nb}), got {uB.shape}")
    return fam.map(uB)


def optimise_restricted(V, F, start=None, p_schedule=(8, 32, 128, 512), maxiter=400, family=None,
                        z0=None):
    """Section 5.3: the smoothed max-min problem over the restricted family, solved with scipy's
    bound-constrained L-BFGS-B on the weights ``z >= 0`` (the monotonicity and [0,1] constraints are
    built into the parametrisation, so no penalty is needed), with a continuation in ``p``.
    Returns ``(MidedgeMap, report)``; report: ``ratio_initial``, ``ratio`` (realised per triangle),
    ``iterations``, ``evaluations``, ``seconds``, ``p_schedule``."""
    from scipy.optimize import minimize
    t0 = time.perf_counter()
    fam = family or RestrictedFamily(V, F, start)
    z = fam.ramp() if z0 is None else np.asarray(z0, np.float64)
    r0 = fam.ratio(fam.harmonic(fam.boundary_values(z)))
    best_z, best_r = z, r0
    nit = nfev = 0
    for p in p_schedule:
        scale = z.mean()
        res = minimize(lambda y, scale=scale, p=p: fam.soft_objective(y * scale, p), z / scale, jac=True,
                       method='L-BFGS-B', bounds=[(0.0, None)] * fam.nb,
                       options=dict(maxiter=maxiter, maxcor=20, ftol=1e-12, gtol=1e-9))
        z = res.x * scale
        nit += res.nit
        nfev += res.nfev
        r = fam.ratio(fam.harmonic(fam.boundary_values(z)))
        if r > best_r:
            best_z, best_r = z, r
    uB = fam.boundary_values(best_z)
    report = {'ratio_initial': r0, 'ratio': best_r, 'iterations': int(nit), 'evaluations': int(nfev),
              'p_schedule': list(p_schedule)}
    mm = fam.map(uB, report)
    report['seconds'] = time.perf_counter() - t0
    mm.report.update(report)
    return mm, report


def lp_restricted(V, F, start=None, rounds=6, family=None, z0=None, directions=8):
    """Section 5.2, an LP relaxation of the max-min problem, solved by scipy's HiGHS. The unknowns
    are all vertex values ``u`` and a bound ``t``; constraints: ``u`` harmonic inside, ``u_B`` in
    [0,1], monotone on each half, ``u_B[0] = 0``, ``u_B[h] = 1``; for every triangle the norm of its
    gradient at most 1, relaxed to a polygon with ``directions`` sides (``g . c_k <= 1``); and
    ``g_T . d_T >= t`` with ``d_T`` the unit gradient direction of the previous round (the lower
    bound ``|g| >= t`` is not convex, so it is linearised around the current map). Maximise ``t``.
    Each round is one sparse LP; the round with the best realised ratio is kept (the starting map
    if every LP fails). Slow: about a minute per round at 65 x 65 on this machine, and the realised
    ratio stays below the smoothed solver's (see docs/paper.md). Returns ``(MidedgeMap, report)``."""
    from scipy.optimize import linprog
    t0 = time.perf_counter()
    fam = family or RestrictedFamily(V, F, start)
    n, m, B, h, nb = fam.n, len(fam.F), fam.B, fam.h, fam.nb
    z = fam.ramp() if z0 is None else np.asarray(z0, np.float64)
    u = fam.harmonic(fam.boundary_values(z))
    r0 = fam.ratio(u)
    # gradient operator in each triangle's own 2D frame: (2m, n)
    P = fam.V[fam.F]
    ex = P[:, 1] - P[:, 0]
    ex /= np.linalg.norm(ex, axis=1)[:, None]
    ey = np.cross(fam.N, ex)
    gx = np.einsum('mkd,md->mk', fam.G, ex)
    gy = np.einsum('mkd,md->mk', fam.G, ey)
    rows = np.repeat(np.arange(m), 3)
    Gx = sp.csr_matrix((gx.ravel(), (rows, fam.F.ravel())), shape=(m, n))
    Gy = sp.csr_matrix((gy.ravel(), (rows, fam.F.ravel())), shape=(m, n))
    ang = np.pi * (2 * np.arange(directions) + 1) / directions
    # g . c_k <= 1 for unit c_k: a polygon circumscribing the unit disk (|g| <= 1/cos(pi/K))
    upper = sp.vstack([np.cos(a) * Gx + np.sin(a) * Gy for a in ang]).tocsr()
    col_t = sp.csr_matrix((m * directions, 1))
    A_up = sp.hstack([upper, col_t])
    b_up = np.full(m * directions, 1.0)
    # harmonic interior rows: L_I u = 0
    L = cotan_laplacian(fam.V, fam.F)
    A_eq = sp.hstack([L[fam.I], sp.csr_matrix((len(fam.I), 1))])
    b_eq = np.zeros(len(fam.I))
    fix = sp.csr_matrix(([1.0], ([0], [B[0]])), shape=(1, n + 1))
    A_eq = sp.vstack([A_eq, fix]).tocsr()
    b_eq = np.r_[b_eq, 0.0]
    # monotone: u_B[k] - u_B[k+1] <= 0 (k < h);  u_B[k+1] - u_B[k] <= 0 (k >= h)
    k = np.arange(nb)
    nxt = np.roll(B, -1)
    sgn = np.where(k < h, 1.0, -1.0)
    A_mono = sp.csr_matrix((np.r_[sgn, -sgn], (np.r_[k, k], np.r_[B, nxt])), shape=(nb, n + 1))
    bounds = [(None, None)] * n + [(None, None)]
    for i in B:
        bounds[i] = (0.0, None)
    c = np.zeros(n + 1)
    c[-1] = -1.0
    best_u, best_r, history = u, -np.inf, []
    for _ in range(rounds):
        g = np.stack([Gx @ u, Gy @ u], axis=1)
        dvec = g / np.maximum(np.linalg.norm(g, axis=1), 1e-300)[:, None]
        low = sp.hstack([-(sp.diags(dvec[:, 0]) @ Gx + sp.diags(dvec[:, 1]) @ Gy),
                         sp.csr_matrix(np.ones((m, 1)))])
        A_ub = sp.vstack([A_up, low, A_mono]).tocsr()
        b_ub = np.r_[b_up, np.zeros(m), np.zeros(nb)]
        res = linprog(c, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds, method='highs')
        if res.status != 0:
            history.append({'status': int(res.status), 'message': res.message})
            break
        u = res.x[:n]
        r = fam.ratio(u)
        history.append({'t': float(res.x[-1]), 'ratio': r})
        if r > best_r:
            best_u, best_r = u, r
    if not np.isfinite(best_r):
        best_r = r0
    report = {'ratio_initial': r0, 'ratio': best_r, 'rounds': history}
    uB = best_u[B] - best_u[B[0]]
    mm = fam.map(uB / uB[h], report)
    report['seconds'] = time.perf_counter() - t0
    mm.report.update(report)
    return mm, report


def map_measures(V, F, mm):
    """docs/math.md §3 measures of a midedge map on its medial triangles (dict from
    ``core.measures.uv_measures``) plus ``area_ratio``: min over max of the per-triangle ratio image
    area / 3D area (``mu_ratio**2`` for an exact midedge map)."""
    Vm, Fm, UVm = mm.midedge_mesh(V, F)
    out = uv_measures(Vm, Fm, UVm)
    P, W = Vm[Fm], UVm[Fm]
    a3 = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    a2 = 0.5 * np.abs(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    q = a2 / a3
    out['area_ratio'] = float(q.min() / q.max())
    return out
