"""The measures of docs/math.md §3, for a UV map or a map to the sphere."""
import numpy as np

from .geometry import cross, folded_faces, norm3

SQUASHED_QC = 1e3        # a map that shears a triangle past this s1/s2 squashes it (``squashed_faces``)


def _local_frames(P):
    """P (m,3,3) triangles -> Q (m,3,2) the same triangles in their own plane, and areas (m,)."""
    e1, e2 = P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]
    nrm = cross(e1, e2)
    dbl = norm3(nrm)
    x = e1 / np.maximum(norm3(e1), np.finfo(float).tiny)[:, None]
    y = cross(nrm / np.maximum(dbl, np.finfo(float).tiny)[:, None], x)
    Q = np.zeros((len(P), 3, 2))
    Q[:, 1] = np.c_[(e1 * x).sum(1), (e1 * y).sum(1)]
    Q[:, 2] = np.c_[(e2 * x).sum(1), (e2 * y).sum(1)]
    return Q, 0.5 * dbl


def local_frames(V, F):
    """Each triangle in its own plane: corner 0 at the origin, corner 1 on the x axis. Returns
    (p, q, r) (m,) each, with corners at (0,0), (p,0), (q,r), and the areas (m,)."""
    Q, A = _local_frames(V[F])
    return (Q[:, 1, 0], Q[:, 2, 0], Q[:, 2, 1]), A


def jacobians_from_frames(frames, F, UV):
    """Per-triangle 2x2 Jacobians (m,2,2) to the UV plane, from ``local_frames``' (p, q, r)."""
    p, q, r = frames
    W = UV[F]
    d1, d2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    J = np.empty((len(F), 2, 2))
    J[:, :, 0] = d1 / p[:, None]
    J[:, :, 1] = (d2 - J[:, :, 0] * q[:, None]) / r[:, None]
    return J


def jacobians(V, F, UV):
    """Per-triangle 2x2 Jacobians (m,2,2) from each triangle's own plane to the UV plane, and the
    3D areas (m,)."""
    frames, A = local_frames(V, F)
    return jacobians_from_frames(frames, F, UV), A


def singular_values(J):
    """Singular values (m,2), largest first, of 2x2 matrices J (m,2,2), in closed form."""
    a, b, c, d = J[:, 0, 0], J[:, 0, 1], J[:, 1, 0], J[:, 1, 1]
    Qc = np.hypot(0.5 * (a + d), 0.5 * (c - b))
    Rc = np.hypot(0.5 * (a - d), 0.5 * (c + b))
    return np.stack([Qc + Rc, np.abs(Qc - Rc)], axis=1)


def shape_anisotropy(V, F):
    """(m,) how thin each triangle of ``V`` (n,3), ``F`` (m,3) is: s1/s2 of the affine map from an
    equilateral triangle onto it (1 for an equilateral triangle, about length / width for a needle or
    a cap; inf at zero area). Dimensionless and independent of scale and orientation."""
    (p, q, r), _ = local_frames(V, F)
    M = np.zeros((len(F), 2, 2))
    M[:, 0, 0] = p
    M[:, 0, 1] = (2.0 * q - p) / np.sqrt(3.0)
    M[:, 1, 1] = 2.0 * r / np.sqrt(3.0)
    s = singular_values(M)
    with np.errstate(divide='ignore', invalid='ignore'):
        return np.where(s[:, 1] > 0, s[:, 0] / s[:, 1], np.inf)


def squashed_faces(sv, anisotropy, limit):
    """(m,) bool: the triangles that a map with singular values ``sv`` (m,2) (largest first) shears past
    ``s1/s2 > limit``, leaving out those whose own shape is already that thin (``anisotropy`` (m,) of
    ``shape_anisotropy`` at least ``limit``). A needle or a cap has an ill-conditioned Jacobian under any
    map that does not keep its exact shape (a conformal metric with a varying scale inflates a cap), and
    it has next to no area to show a texture on."""
    return (sv[:, 1] * limit <= sv[:, 0]) & (anisotropy < limit)


def squashed_count(V, F, J, qc_max, limit=SQUASHED_QC):
    """How many triangles of ``V`` (n,3), ``F`` (m,3) the map with Jacobians ``J`` (m,2,2) squashes
    (``squashed_faces`` at ``limit``); 0 without a look when the map's ``qc_max`` is not above it."""
    if qc_max <= limit:
        return 0
    return int(squashed_faces(singular_values(J), shape_anisotropy(V, F), limit).sum())


def determinants(J):
    """Determinants (m,) of 2x2 matrices J (m,2,2)."""
    return J[:, 0, 0] * J[:, 1, 1] - J[:, 0, 1] * J[:, 1, 0]


def conformal_factor(V, F, UV):
    """Per-triangle conformal factor ``mu`` (m,): sqrt|det J|, normalised so that the total UV area
    equals the total 3D area (dimensionless)."""
    J, A = jacobians(V, F, UV)
    det = np.abs(determinants(J))
    c = np.sqrt((det * A).sum() / A.sum())
    return np.sqrt(det) / c


def summarise(mu, qc, A, orient):
    """The report numbers from per-triangle ``mu``, ``qc`` (m,), areas ``A`` and signed orientation
    (positive = agrees with the majority)."""
    w = A / A.sum()
    p1, p99 = np.percentile(mu, [1, 99])                # one partition for both (the same numbers)
    return {
        'faces': int(len(mu)),
        'flips': int((orient <= 0).sum()),
        'mu_ratio': float(mu.min() / mu.max()),
        'mu_ratio_p1_p99': float(p1 / p99),
        'qc_mean': float((qc * w).sum()),
        'qc_max': float(qc.max()),
    }


def measures_from_jacobians(J, A):
    """docs/math.md §3 measures from per-triangle Jacobians ``J`` (m,2,2) and 3D areas ``A`` (m,):
    (report dict, per-triangle ``mu`` (m,))."""
    s = singular_values(J)
    det = determinants(J)
    c = np.sqrt((np.abs(det) * A).sum() / A.sum())
    mu = np.sqrt(np.abs(det)) / c
    with np.errstate(over='ignore'):                 # a triangle mapped to a segment: inf
        qc = s[:, 0] / np.maximum(s[:, 1], np.finfo(float).tiny)
    orient = det * np.sign(np.median(det))
    return summarise(mu, qc, A, orient), mu


def uv_measures(V, F, UV, squash_limit=None):
    """docs/math.md §3 measures of a UV map: dict with faces, flips, mu_ratio, mu_ratio_p1_p99,
    qc_mean (area-weighted) and qc_max, and with flips ``flips_folded`` (``folded_flips``). ``V``
    (n,3), ``F`` (m,3), ``UV`` (n,2). With ``squash_limit`` (an s1/s2) also ``squashed``: how many
    triangles the map shears past it (``squashed_count``)."""
    J, A = jacobians(V, F, UV)
    rep = measures_from_jacobians(J, A)[0]
    if squash_limit is not None:
        rep['squashed'] = squashed_count(V, F, J, rep['qc_max'], squash_limit)
    if rep['flips']:
        rep['flips_folded'] = folded_flips(V, F, J)
    return rep


def folded_flips(V, F, J, mask=None):
    """How many of the triangles that the map with Jacobians ``J`` (m,2,2) flips (against the
    majority's orientation, as ``measures_from_jacobians`` counts them; only on ``mask`` (m,) bool if
    given) are folded over in the mesh ``V`` (n,3), ``F`` (m,3) itself (``folded_faces``): crumpled
    spots of the input, where smoothing or cleaning the mesh is the remedy."""
    det = determinants(J)
    on = np.ones(len(F), bool) if mask is None else mask
    flipped = on & (det * np.sign(np.median(det[on])) <= 0)
    return int((flipped & folded_faces(V, F)).sum())


def folded_note(report):
    """The words a flip warning adds when some flipped triangles are folded over in the mesh itself
    (``report['flips_folded']``), or ''."""
    k = report.get('flips_folded', 0)
    return (f", {k} of them folded over in the mesh itself (their normal opposes their neighbours'): "
            "smooth or clean the mesh there") if k else ""


def flip_warning(report, subject=None):
    """The warning (str) for the ``report['flips']`` flipped UV triangles of a measured map, with its
    ``folded_note``, or None when there are none. ``subject`` (e.g. "island 3") starts the sentence."""
    n = report.get('flips', 0)
    if not n:
        return None
    words = f"{n} flipped (folded) UV triangle(s)" + folded_note(report)
    return words if subject is None else f"{subject} has {words}"


def signed_uv_areas(uv, F):
    """Signed UV areas (m,) of the triangles ``F`` (m,3) under the map ``uv`` (n,2): positive for a
    counter-clockwise image, in squared UV units."""
    W = uv[F]
    e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    return 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])


def vertex_mu(F, mu, A, n):
    """The one per-vertex conformal factor (n,): at each vertex, the area-weighted geometric mean of
    the per-triangle ``mu`` (m,) of the triangles ``F`` (m,3) around it, with weights ``A`` (m,) (the
    3D areas). The geometric mean because mu is a ratio of lengths: log mu is what varies smoothly.
    Triangles whose mu is not finite and positive (e.g. temporary hole fill, NaN) are left out;
    vertices with no such triangle get NaN."""
    mu = np.asarray(mu, np.float64)
    ok = np.isfinite(mu) & (mu > 0)
    w = np.repeat(np.where(ok, np.asarray(A, np.float64), 0.0), 3)
    lg = np.repeat(np.log(np.where(ok, mu, 1.0)), 3)
    den = np.bincount(F.ravel(), w, minlength=n)
    num = np.bincount(F.ravel(), w * lg, minlength=n)
    with np.errstate(invalid='ignore', divide='ignore'):
        return np.where(den > 0, np.exp(num / np.where(den > 0, den, 1.0)), np.nan)
