"""The exact flat metric of a disk with prescribed angle sums, by Newton's method on the discrete
conformal (Yamabe) equation, and its layout in the plane (docs/cones.md, "Exact layout").

``flat_cone_metric`` finds one log scale per vertex such that the scaled edge lengths of an intrinsic
triangulation give every free vertex its target angle sum (2 pi for a smooth point, 2 pi - kappa at
a cone); ``unfold`` lays the triangles of such a flat metric out face by face. The cone pipeline
(``core.atlas.cones``) lays its cut disks out with them, and ``core.disk.flatten`` a disk whose
linear map shears a sliver.
"""
import numpy as np

from ..errors import ConformalError
from .intrinsic import corner_angles as corner_angles_l
from .intrinsic import corner_cotangents as corner_cotangents_l
from .intrinsic import layout
from .solve import Factor

REFACTOR = 0.5                     # Newton: factor the Hessian again when |r| fell by less than this
KRYLOV_ETA = 0.1                   # big meshes' inexact Newton: relative tolerance of the inner solve
KRYLOV_ITERS = 12                  # its conjugate gradient iterations before the Hessian is factored


def _free_pattern(a0, a1, free_mask):
    """The sparsity pattern of the cotan Hessian ``sum_e W_e (d_a - d_b)(d_a - d_b)^T`` on the free
    vertices, built once per cut disk. ``a0``, ``a1`` (E,) the surface vertices of each edge of the
    cut disk's triangulation; ``free_mask`` (n,) bool. Returns (slot (2E + n,) position of each
    entry (off-diagonal a-b, b-a per edge, then the diagonal of every surface vertex) in the CSR
    data, or -1 where a row or column is fixed; indices; indptr; size)."""
    n = len(free_mask)
    rows = np.r_[a0, a1, np.arange(n)]
    cols = np.r_[a1, a0, np.arange(n)]
    at = np.full(n, -1, np.int64)
    nf = int(free_mask.sum())
    at[free_mask] = np.arange(nf)
    fr, fc = at[rows], at[cols]
    keep = (fr >= 0) & (fc >= 0)
    key = fr[keep] * nf + fc[keep]
    uniq, inv = np.unique(key, return_inverse=True)
    slot = np.full(len(rows), -1, np.int64)
    slot[keep] = inv.ravel()
    indptr = np.zeros(nf + 1, np.int64)
    np.cumsum(np.bincount(uniq // nf, minlength=nf), out=indptr[1:])
    return slot, (uniq % nf).astype(np.int32), indptr, nf


def _pcg(H, b, fac, rtol, maxiter):
    """Preconditioned conjugate gradients for ``H x = b`` (``H`` (k,k) sparse symmetric positive
    definite, ``b`` (k,)) with the factorisation ``fac`` of a nearby matrix as preconditioner, until
    ``|b - H x| <= rtol |b|`` or ``maxiter`` iterations. Returns (x (k,), |b - H x| / |b| reached;
    inf if ``H`` is not positive definite along a search direction)."""
    x = np.zeros_like(b)
    res = b.copy()
    bn = float(np.linalg.norm(b))
    rel = 1.0
    z = fac.solve(res)
    p = z.copy()
    rz = float(res @ z)
    for _ in range(maxiter):
        Hp = H @ p
        pHp = float(p @ Hp)
        if not pHp > 0:
            return x, np.inf
        a = rz / pHp
        x += a * p
        res -= a * Hp
        rel = float(np.linalg.norm(res)) / bn
        if rel <= rtol:
            break
        z = fac.solve(res)
        rz2 = float(res @ z)
        p = z + (rz2 / rz) * p
        rz = rz2
    return x, rel


def flat_cone_metric(T, vert_of, n, target, fixed, u0, max_iter=40, tol=1e-12, fac0=None, krylov=False):
    """Exact flat cone metric by Newton's method on the discrete conformal (Yamabe) equation
    (docs/cones.md, "Exact layout").

    ``T``: the cut disk's intrinsic triangulation (``IntrinsicTriangulation`` on N split vertices);
    ``vert_of`` (N,) the surface vertex of each split vertex; ``n`` surface vertices. The unknown is
    one log scale ``u`` (n,) per surface vertex (the same on every copy, so the two sides of a seam
    keep equal lengths); the lengths are ``l~_e = exp((u_a + u_b)/2) l_e``. ``target`` (n,) the
    angle sums wanted (radians: ``2*pi - kappa``); ``fixed`` (n,) bool vertices whose ``u`` stays at
    ``u0`` (n,) (a ground vertex, or the surface's boundary). Newton step: ``L(u) du = s(u) - target``
    (``s`` the angle sums, ``L(u)`` the cotan Laplacian of the current lengths, the Hessian of the
    convex discrete conformal energy), with backtracking that lowers the residual; the Hessian is
    factored again only when the residual stops falling fast (chord steps in between). ``fac0``: an
    optional first factorisation of a nearby Hessian on the same free vertices (the closed surface's
    Laplacian of ``ConeSystem``), which saves the first factorisation. A triangle whose lengths
    break the triangle inequality counts with the angles (pi, 0, 0) (the energy's convex extension;
    it lays out flat). ``tol`` (rad) on the angle sums: 1e-12, because a residual of 5e-11 left the
    rotation along a seam varying by 1e-9 rad (the seam test's bound); a result that stalls above it
    is still accepted up to 1e-7. ``krylov`` (big meshes): inexact Newton instead of chord steps:
    every step solves with the current Hessian by conjugate gradients preconditioned with the last
    factorisation (``fac0`` at first; forcing term ``min(KRYLOV_ETA, |r|)``, at most
    ``KRYLOV_ITERS`` iterations), so the steps stay Newton steps (quadratic convergence) and the
    Hessian is factored only when the conjugate gradients stall (spot subdivided twice: 6 steps and
    no factorisation, against 22 chord steps and one factorisation). Returns (u (n,), edge lengths
    (E,), count of such flat triangles) or None when it does not converge."""
    import scipy.sparse as sp
    a0, a1 = vert_of[T.edge_vertices()].T
    Fo = vert_of[T.F]
    free = np.nonzero(~fixed)[0]
    nxt, prv = np.array([1, 2, 0]), np.array([2, 0, 1])

    def state(u):
        el = T.edge_lengths * np.exp(0.5 * (u[a0] + u[a1]))
        l = el[T.FE]
        valid = (l.sum(1, keepdims=True) - 2 * l > 0).all(1)
        # an invalid triangle has the angles (pi, 0, 0) (the convex extension of the energy)
        r = np.bincount(Fo.ravel(), corner_angles_l(l).ravel(), minlength=n) - target
        r[fixed] = 0.0
        return el, l, r, valid

    u = np.array(u0, np.float64)
    st = state(u)
    fac, fresh, last = fac0, False, np.inf
    if krylov:
        slot, indices, indptr, nf = _free_pattern(a0, a1, ~fixed)
        use = slot >= 0
        slot = slot[use]
        FE = T.FE.ravel()
        n_edges = len(a0)
    for _ in range(max_iter):
        el, l, r, valid = st
        norm = float(np.linalg.norm(r))
        if float(np.abs(r).max()) < tol:
            break
        if krylov:
            # inexact Newton: the current Hessian, solved by conjugate gradients preconditioned with
            # the last factorisation; factored again only when they stall
            with np.errstate(divide='ignore', invalid='ignore'):
                w = 0.5 * corner_cotangents_l(l)
            w[~valid] = 0.0
            We = np.bincount(FE, w.ravel(), minlength=n_edges)          # cotan weight per edge
            Wd = np.bincount(a0, We, minlength=n) + np.bincount(a1, We, minlength=n)
            data = np.bincount(slot, np.r_[-We, -We, Wd][use], minlength=len(indices))
            H = sp.csr_matrix((data, indices, indptr), shape=(nf, nf))
            ok = False
            if fac is not None:
                # the inner tolerance falls with |r| (superlinear convergence); a step that gained
                # KRYLOV_ETA is taken even if that tolerance is not reached
                du, rel = _pcg(H, r[free], fac, min(KRYLOV_ETA, norm), KRYLOV_ITERS)
                ok = rel <= KRYLOV_ETA
            fresh = not ok
            if not ok:
                try:
                    fac = Factor(H.tocsc())
                except (ConformalError, RuntimeError, ValueError):
                    return None
                du = fac.solve(r[free])
        elif fac is None or norm > REFACTOR * last:
            # the Hessian is factored again only when the residual stops falling fast (a chord step
            # with the previous factorisation costs one solve; a factorisation of a 100k mesh ~1 s)
            with np.errstate(divide='ignore', invalid='ignore'):
                w = 0.5 * corner_cotangents_l(l)
            w[~valid] = 0.0
            i, j = Fo[:, nxt].ravel(), Fo[:, prv].ravel()
            w = w.ravel()
            H = sp.csc_matrix((np.r_[-w, -w, w, w], (np.r_[i, j, i, j], np.r_[j, i, i, j])), shape=(n, n))
            try:
                fac, fresh = Factor(H[free][:, free].tocsc()), True
            except (ConformalError, RuntimeError, ValueError):
                return None
        else:
            fresh = False
        if not krylov:
            du = fac.solve(r[free])
        last = norm
        if not np.isfinite(du).all():
            return None
        t = 1.0
        while t > 1e-3:
            u2 = u.copy()
            u2[free] += t * du
            st2 = state(u2)
            if np.linalg.norm(st2[2]) < (1 - 1e-4 * t) * norm:
                break
            t *= 0.5
        else:
            if fresh:
                break                              # no progress: converged to round-off or stuck
            fac, last = None, np.inf               # a stale Hessian: factor again
            continue
        u, st = u2, st2
    ok = float(np.abs(st[2]).max()) < max(1e3 * tol, 1e-7)     # as before the tighter tol (1e-12)
    return (u, st[0], int((~st[3]).sum())) if ok else None


def unfold(T, el):
    """Lay out the triangles of a flat disk ``T`` (``IntrinsicTriangulation``) with edge lengths
    ``el`` (E,) in the plane, face by face across interior edges (breadth first, one array step per
    ring of faces). Returns positions (N,2), counter-clockwise like the faces; units of ``el``.

    Each face carries a rigid motion (complex ``rot``, ``tr``: plane = rot * local + tr) composed from
    its parent's and the two local copies of the shared edge, so no rotation is ever read off placed
    positions: errors grow with the number of steps, not geometrically (reading the rotation off the
    placed edge amplified them by the ratio of the lengths at every step: a strip of 10 x 150
    vertices came out with its lengths off by up to 2.2)."""
    F, FE, EF, EC = T.F, T.FE, T.EF, T.EC
    m, N = len(F), T.n
    Z = layout(el[FE]) @ np.array([1.0, 1j])                    # (m,3) complex local copies
    rot = np.zeros(m, complex)
    tr = np.zeros(m, complex)
    pos = np.full(N, np.nan + 0j)
    placed = np.zeros(m, bool)
    rot[0] = 1.0
    pos[F[0]] = Z[0]
    placed[0] = True
    front = np.array([0])
    nxt, prv = np.array([1, 2, 0]), np.array([2, 0, 1])
    while len(front):
        e = FE[front].ravel()
        f0 = np.repeat(front, 3)
        c0 = np.tile(np.arange(3), len(front))                  # the corner of f0 opposite e
        side = (EF[e, 0] == f0).astype(np.int64)                # the other side of each edge
        f2, c = EF[e, side], EC[e, side]
        ok = f2 >= 0
        ok[ok] = ~placed[f2[ok]]
        f2, c, f0, c0 = f2[ok], c[ok], f0[ok], c0[ok]
        f2, first = np.unique(f2, return_index=True)
        c, f0, c0 = c[first], f0[first], c0[first]
        if not len(f2):
            break
        i = F[f2, nxt[c]]                                       # the shared edge, i -> j in f2
        ci0 = np.where(F[f0, prv[c0]] == i, prv[c0], nxt[c0])    # i's corner in f0
        cj0 = 3 - c0 - ci0
        r = (Z[f0, cj0] - Z[f0, ci0]) / (Z[f2, prv[c]] - Z[f2, nxt[c]])
        r /= np.abs(r)
        rot[f2] = rot[f0] * r
        tr[f2] = rot[f0] * Z[f0, ci0] + tr[f0] - rot[f2] * Z[f2, nxt[c]]
        k = F[f2, c]
        newk = np.isnan(pos[k])
        kk, first = np.unique(k[newk], return_index=True)
        pos[kk] = (rot[f2] * Z[f2, c] + tr[f2])[newk][first]
        placed[f2] = True
        front = f2
    return np.stack([pos.real, pos.imag], axis=1)
