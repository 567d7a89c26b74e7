"""Folds of a sphere map undone where the surrounding map allows (docs/sphere.md, "Untangling").

The sphere map is harmonic for the intrinsic Delaunay Laplacian (``core.sphere.map``), and it is
piecewise linear on the *intrinsic* triangles; the faces written out are the mesh's own. An obtuse
face (one angle of 150-175 degrees) whose vertex lies close to the opposite edge turns over at the
slightest error in the image of that edge: cheburashka's map folds 4 of its 13334 faces, a noisy
figure's 4.

``untangle`` relaxes the vertices around every folded face, ``RINGS`` rings deep, by Gauss-Seidel
sweeps on the mesh's own conformal energy (its cotan Dirichlet energy: for a fixed ring the signed
area term of the conformal energy is constant), each step kept inside the set of positions where all
of the vertex's faces face outwards with at least ``KEEP`` of their 3D aspect (a small quadratic
program in the gnomonic chart at the vertex, solved exactly by enumerating its active sets). A patch
is kept only if it has fewer folds, its area-weighted qc grows by at most ``QC_GROWTH`` (relative)
or ``QC_SLACK`` (absolute), and none of its faces leaves the range of scales of the map's unfolded
faces (by ``SCALE_SLACK``): a needle unfolded at the bottom of a deep fold can need a scale far below
every other face's, a new extreme of mu for the Moebius choice that follows. Otherwise the map stays
as it was there, and the folds stay reported.
Where more than ``MAX_FOLDED`` of the faces fold (a mesh of slivers, ``core.surfaces.hull_part``: 7-11
%), the map is poor everywhere and nothing is tried.

Vertices are updated a colour class at a time (no two of a class share a face), so that a class is
one vectorised step; the classes follow keys of the vertices' own geometry, so the result does not
depend on the numbering of the mesh."""
import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from ..mesh.geometry import face_areas

RINGS = 3          # rings around the folded faces that are relaxed
SWEEPS = 30        # Gauss-Seidel sweeps over the patch
KEEP = 0.25        # a face's image keeps at least this fraction of its 3D aspect (2 area / edge^2)
QC_GROWTH = 0.1    # a patch is kept if its area-weighted qc grows by at most 10 % ...
QC_SLACK = 0.1     # ... or by 0.1
SCALE_SLACK = 1e-3  # and no face's scale leaves the map's range (of the unfolded faces) by more than 0.1 %
QP_ENTRIES = 4_000_000  # entries of the batched quadratic programs' largest array (32 MB)
MAX_FOLDED = 0.02  # above this fraction of folded faces the map is broken throughout (a mesh of
                   # slivers), not locally: no relaxation is tried


def orientation(S: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(m,) signed volume of the flat triangles of ``S`` (n,3) unit vectors and the origin: negative
    or zero where the face ``F`` (m,3) is folded (its image faces inwards)."""
    P = S[F]
    return np.einsum('ij,ij->i', np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), P.mean(1))


def _corner_targets(V, F):
    """Per corner (m,3): the complex ratio ``Z`` that places the corner on its opposite edge
    ``a -> b`` as in 3D (``v = a + Z (b - a)``), the weight ``W`` = |b - a|^2 / (2 area) of that
    triangle in the corner's energy (its two cotangents at a and b), and the 3D aspect
    2 area / |b - a|^2."""
    P = V[F]
    a, b = P[:, [1, 2, 0]], P[:, [2, 0, 1]]
    E, D = b - a, P - a
    E2 = np.maximum((E * E).sum(2), np.finfo(float).tiny)
    cr = np.linalg.norm(np.cross(E, D), axis=2)                   # 2 area, the same for the 3 corners
    Z = ((D * E).sum(2) + 1j * cr) / E2
    W = E2 / np.maximum(cr, 1e-12 * E2)
    return Z, W, cr / E2


def _vertex_keys(V, F):
    """(n,) distinct integer keys of the vertices of ``V`` (n,3), ``F`` (m,3) that do not depend on
    their numbering, on a rigid motion or on the scale: ranks of a hash of each vertex's angle sum and
    of its edges' lengths over the mean edge (ties, on symmetric meshes, broken by the index). The
    colouring and so the order of the Gauss-Seidel steps follow them: the result is the same for any
    numbering of the same mesh (2 % apart on cheburashka's mu_ratio with keys drawn by index)."""
    from ..mesh.geometry import corner_angles
    n = len(V)
    ang = np.bincount(F.ravel(), corner_angles(V, F).ravel(), minlength=n)
    e = np.linalg.norm(V[F[:, [1, 2, 0]]] - V[F], axis=2)
    length = np.bincount(F.ravel(), e.ravel(), minlength=n) / max(e.mean(), np.finfo(float).tiny)
    h = np.sin(ang * 12.9898 + length * 78.233) * 43758.5453
    return np.argsort(np.lexsort((np.arange(n), h - np.floor(h))), kind='stable')


def _colour(F, verts, n, key):
    """Colour classes of ``verts`` (k,) (lists of vertex arrays): no two vertices of a class share a
    face of ``F`` (m,3). Each class is a maximal independent set of the vertices still uncoloured,
    found by local maxima of the distinct keys ``key`` (n,) (``_vertex_keys``)."""
    mark = np.zeros(n, bool)
    mark[verts] = True
    E = np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]
    E = E[mark[E].all(1)]
    A = sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n)).tocsr()
    A = (A + A.T).tocsr()
    colour = np.full(n, -1, np.int64)
    left = np.asarray(verts, np.int64)
    classes = []
    while len(left):
        cand, taken = left, []
        while len(cand):
            k = np.full(n, -1, np.int64)
            k[cand] = key[cand]
            rows = A[cand]
            best = np.full(len(cand), -1, np.int64)
            np.maximum.at(best, np.repeat(np.arange(len(cand)), np.diff(rows.indptr)), k[rows.indices])
            win = k[cand] > best
            taken.append(cand[win])
            blocked = np.zeros(n, bool)
            blocked[A[cand[win]].indices] = True
            cand = cand[~win & ~blocked[cand]]
        cls = np.concatenate(taken)
        colour[cls] = len(classes)
        classes.append(cls)
        left = left[colour[left] < 0]
    return classes


def _qp(n_, c_, mask):
    """Batched ``min |x|`` subject to ``c_k + n_k . x >= 0`` (rows ``mask``): ``n_`` (B,D,2), ``c_``
    (B,D). Returns ``x`` (B,2) and ``ok`` (B,) (feasible). The optimum of a 2D quadratic program
    has at most two active constraints, so it is the nearest feasible of: the origin, the feet of
    the perpendiculars to each line, and the crossings of every two lines."""
    B, D = c_.shape
    nn = (n_ * n_).sum(2)
    safe = np.where(mask, nn, 1.0)
    feet = -(c_ / safe)[..., None] * n_                                        # (B,D,2)
    i, j = np.triu_indices(D, 1)
    det = n_[:, i, 0] * n_[:, j, 1] - n_[:, i, 1] * n_[:, j, 0]
    good = mask[:, i] & mask[:, j] & (np.abs(det) > 1e-12 * np.sqrt(safe[:, i] * safe[:, j]))
    dd = np.where(good, det, 1.0)
    cx = (-c_[:, i] * n_[:, j, 1] + c_[:, j] * n_[:, i, 1]) / dd
    cy = (-n_[:, i, 0] * c_[:, j] + n_[:, j, 0] * c_[:, i]) / dd
    X = np.concatenate([np.zeros((B, 1, 2)), feet, np.stack([cx, cy], 2)], 1)    # (B,C,2)
    valid = np.concatenate([np.ones((B, 1), bool), mask, good], 1)
    G = c_[:, None, :] + np.einsum('bcx,bdx->bcd', X, n_)
    feas = valid & (np.where(mask[:, None, :], G >= -1e-12 * np.sqrt(safe)[:, None, :], True)).all(2)
    r2 = np.where(feas, (X * X).sum(2), np.inf)
    k = np.argmin(r2, 1)
    return X[np.arange(B), k], np.isfinite(r2[np.arange(B), k])


def _relax(S, F, verts, Z, W, aspect, real, corners, start):
    """One vectorised Gauss-Seidel step of the vertices ``verts`` (k,) (no two on one face): each moves
    to its ring's conformal target, projected onto the positions that keep its faces outwards."""
    cnt = start[verts + 1] - start[verts]
    D = int(cnt.max())
    per = max(1, QP_ENTRIES // (D * (1 + D + D * (D - 1) // 2)))     # the candidates' (B, C, D) arrays
    if len(verts) > per:
        for lo in range(0, len(verts), per):
            _relax(S, F, verts[lo:lo + per], Z, W, aspect, real, corners, start)
        return
    B = len(verts)
    idx = start[verts][:, None] + np.arange(D)[None, :]
    mask = np.arange(D)[None, :] < cnt[:, None]
    cor = corners[np.where(mask, idx, start[verts][:, None])]               # (B,D) corner ids
    t, k = cor // 3, cor % 3
    mask &= real[t]
    s = S[verts]
    h = np.where(np.abs(s[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]])
    u = np.cross(s, h)
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    w = np.cross(s, u)
    Pa, Pb = S[F[t, (k + 1) % 3]], S[F[t, (k + 2) % 3]]                       # (B,D,3)
    da, db = np.einsum('bdx,bx->bd', Pa, s), np.einsum('bdx,bx->bd', Pb, s)
    chartable = ~(mask & ((da <= 0) | (db <= 0))).any(1)
    da, db = np.where(da > 0, da, 1.0), np.where(db > 0, db, 1.0)
    Qa, Qb = Pa / da[..., None], Pb / db[..., None]
    a = np.stack([np.einsum('bdx,bx->bd', Qa, u), np.einsum('bdx,bx->bd', Qa, w)], 2)
    b = np.stack([np.einsum('bdx,bx->bd', Qb, u), np.einsum('bdx,bx->bd', Qb, w)], 2)
    za, zb = a[..., 0] + 1j * a[..., 1], b[..., 0] + 1j * b[..., 1]
    wk = np.where(mask, W[t, k], 0.0)
    zt = (wk * (za + Z[t, k] * (zb - za))).sum(1) / np.maximum(wk.sum(1), np.finfo(float).tiny)
    xt = np.stack([zt.real, zt.imag], 1)
    ab2 = ((a - b) ** 2).sum(2)
    delta = np.maximum(KEEP * aspect[t, k], 1e-6) * ab2
    A_, B_ = a - xt[:, None, :], b - xt[:, None, :]
    n_ = np.stack([A_[..., 1] - B_[..., 1], B_[..., 0] - A_[..., 0]], 2)
    cross0 = A_[..., 0] * B_[..., 1] - A_[..., 1] * B_[..., 0]
    x = np.zeros((B, 2))
    done = ~chartable
    for f in (1.0, 0.1, 1e-3):                      # a smaller margin where the full one is out of reach
        todo = np.flatnonzero(~done)
        if not len(todo):
            break
        xs, ok = _qp(n_[todo], (cross0 - f * delta)[todo], mask[todo])
        x[todo[ok]] = xs[ok] + xt[todo[ok]]
        done[todo[ok]] = True
    move = done & chartable
    p = s[move] + x[move, :1] * u[move] + x[move, 1:] * w[move]
    S[verts[move]] = p / np.linalg.norm(p, axis=1, keepdims=True)


def _scale(S, F, A3):
    """(m,) unnormalised scale of each face ``F`` (m,3): sqrt(area of its flat image in ``S`` / its 3D
    area ``A3`` (m,))."""
    return np.sqrt(face_areas(S, F) / np.maximum(A3, np.finfo(float).tiny))


def untangle(S: np.ndarray, F: np.ndarray, V: np.ndarray, real: np.ndarray | None = None,
             qc=None) -> tuple:
    """Undo the folds of the sphere map ``S`` (n,3) unit vectors of the mesh ``V`` (n,3), ``F`` (m,3)
    where the map around them allows (module docstring). ``real`` (m,) bool: the faces with a 3D area
    (the others neither count nor constrain). ``qc(S, faces)``: per-face qc of the given faces (for
    the acceptance test). Returns ``(S (n,3), info)`` with ``folds_before``, ``folds_after``,
    ``patches_kept``, ``patches_dropped``, ``moved`` (vertices)."""
    n, m = len(S), len(F)
    real = np.ones(m, bool) if real is None else np.asarray(real, bool)
    fold0 = (orientation(S, F) <= 0) & real
    info = {'folds_before': int(fold0.sum()), 'folds_after': int(fold0.sum()), 'patches_kept': 0,
            'patches_dropped': 0, 'moved': 0}
    if not fold0.any() or fold0.sum() > MAX_FOLDED * real.sum():
        return S, info
    Z, W, aspect = _corner_targets(V, F)
    Fr = F.ravel()
    corners = np.argsort(Fr, kind='stable')
    start = np.r_[0, np.cumsum(np.bincount(Fr, minlength=n))]
    patch = np.zeros(n, bool)
    patch[F[fold0]] = True
    for _ in range(RINGS):
        patch[F[patch[F].any(1)]] = True
    classes = _colour(F, np.flatnonzero(patch), n, _vertex_keys(V, F))
    S1 = S.copy()
    for _ in range(SWEEPS):
        for cls in classes:
            _relax(S1, F, cls, Z, W, aspect, real, corners, start)
    # keep a connected patch only if it folds less and its conformality holds
    moved = np.linalg.norm(S1 - S, axis=1) > 0
    if not moved.any():
        return S, info
    faces = np.flatnonzero(moved[F].any(1) & real)
    E = np.r_[F[faces][:, [0, 1]], F[faces][:, [1, 2]], F[faces][:, [2, 0]]]
    E = E[moved[E].all(1)]
    _, lab = connected_components(sp.coo_matrix((np.ones(len(E)), (E[:, 0], E[:, 1])), shape=(n, n)),
                                  directed=False)
    flab = np.where(moved[F[faces]], lab[F[faces]], -1).max(1)
    area = face_areas(V, F)
    A3 = area[faces]
    q0, q1 = qc(S, faces), qc(S1, faces)
    # no face may leave the range of scales of the unfolded faces before: the Moebius choice that
    # follows would see a new extreme (mu_ratio) where a fold was
    good = real & ~fold0
    r_all = _scale(S, F[good], area[good])
    lo, hi = (1 - SCALE_SLACK) * r_all.min(), (1 + SCALE_SLACK) * r_all.max()
    r1 = _scale(S1, F[faces], A3)
    f0, f1 = fold0[faces], (orientation(S1, F[faces]) <= 0)
    out = S1
    for c in np.unique(flab):
        sel = flab == c
        wa = A3[sel] / max(A3[sel].sum(), np.finfo(float).tiny)
        before, after = (q0[sel] * wa).sum(), (q1[sel] * wa).sum()
        if f1[sel].sum() < f0[sel].sum() and after <= max((1 + QC_GROWTH) * before, before + QC_SLACK) \
                and lo <= r1[sel].min() and r1[sel].max() <= hi:
            info['patches_kept'] += 1
        else:
            info['patches_dropped'] += 1
            back = moved & (lab == c)
            out[back] = S[back]
    info['moved'] = int((np.linalg.norm(out - S, axis=1) > 0).sum())
    info['folds_after'] = int(((orientation(out, F) <= 0) & real).sum())
    return out, info
