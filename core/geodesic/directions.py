"""Gradient directions for the re-marches, fitted per triangle to an unfolded point source.

Inside one triangle the map is affine, so the surface metric in the plane is one constant ``G`` (2x2,
surface length squared per UV length squared; ``face_metric_inverse`` gives ``G^-1``). A front whose
shortest paths cross the triangle straight, as they do on the unfolded surface, is the distance from
one point ``c`` of that plane (the unfolded source): ``T(x) = |x - c|_G``. Then

    T^2 - x^T G x = -2 c^T G x + c^T G c

is affine in ``x``. Fitting an affine function ``p . x + r`` to ``T^2 - x^T G x`` over the grid nodes
of the triangle (least squares, ``x`` centred on the nodes' mean) gives ``c = -G^-1 p / 2``, and the
gradient direction at every node, ``G (x - c)``, from all of the triangle's nodes at once rather than
from the differences of two neighbours, whose noise the next pass turns into an undershoot (the
eikonal solution takes the cheapest of the noisy speeds). The constant ``r`` is left free
(``T^2 = |x - c|_G^2 + k``), which absorbs a small offset of the times; a source behind a saddle
vertex (``T = t0 + |x - c|_G``) is fitted approximately and kept only if the residual test passes.

A triangle is fitted only where the fit explains its times: at least ``FIT_MIN_NODES`` nodes, and an
RMS residual at most ``FIT_RESIDUAL`` times the spread (standard deviation) of its nodes' times.
Where two fronts meet inside a triangle, or its nodes are too few, the caller keeps the differences.
"""
import numpy as np

FIT_MIN_NODES = 6      # a triangle's nodes are fitted when it holds at least this many
FIT_RESIDUAL = 0.05    # ... and the fit's RMS residual is at most this share of their times' spread
CHUNK = 1 << 21        # nodes summed at a time (the sums are per triangle; memory stays flat)


def point_source_mu(T, valid, face, ginv, metric, h):
    """The directional speed ``sqrt(g^T G^-1 g)`` (``directional_mu``) for the gradient direction
    ``g`` of the point-source fit of ``T`` in each node's triangle (see the module's docstring).

    T: (ny, nx) travel times, surface units (inf or NaN where unknown). valid: (ny, nx) bool, the
    nodes that may be used. face: (ny, nx) int, each node's triangle (-1 outside). ginv, metric: (m,3)
    the ``(a, b, c)`` of each triangle's ``G^-1`` (UV units squared per surface unit squared) and of
    ``G`` (its inverse: the chart's ``seed_metric``). h: the grid spacing, UV units. Returns ``(mu
    (ny, nx), fitted (ny, nx) bool)``: ``mu`` is 1 where ``fitted`` is False (the caller's
    differences go there)."""
    ny, nx = T.shape
    m = len(ginv)
    Tr, fr = T.ravel(), face.ravel()
    use = np.flatnonzero((valid & (face >= 0) & np.isfinite(T)).ravel())
    mu = np.ones(ny * nx)
    fitted = np.zeros(ny * nx, bool)
    if not len(use):
        return mu.reshape(T.shape), fitted.reshape(T.shape)
    a, b, c = ginv[:, 0], ginv[:, 1], ginv[:, 2]
    good = np.isfinite(metric).all(1) & np.isfinite(ginv).all(1)
    G = np.where(good[:, None], metric, 0.0) * (h * h)        # G in node units, (m,3)
    chunks = [use[i:i + CHUNK] for i in range(0, len(use), CHUNK)]

    def nodes(ch):
        """Triangle (k,) and column, row (k,) as floats of the nodes ``ch``."""
        row, col = np.divmod(ch, nx)
        return fr[ch], col.astype(np.float64), row.astype(np.float64)
    first = nodes(chunks[0]) if len(chunks) == 1 else None     # one chunk: its nodes read once
    # the triangles' node counts and centres (node units), then the sums of the centred fit
    cnt = np.zeros(m)
    centre = np.zeros((m, 2))
    for ch in chunks:
        t, col, row = first or nodes(ch)
        cnt += np.bincount(t, minlength=m)
        centre[:, 0] += np.bincount(t, col, m)
        centre[:, 1] += np.bincount(t, row, m)
    n = np.maximum(cnt, 1.0)
    centre /= n[:, None]

    def pieces(ch):
        """Triangle (k,), centred position x, y (k,) each, time (k,), G (k,3) of the nodes ``ch``."""
        t, col, row = first or nodes(ch)
        col -= centre[t, 0]
        row -= centre[t, 1]
        return t, col, row, Tr[ch], G[t]
    one = pieces(chunks[0]) if first else None                 # ... and gathered once
    S = np.zeros((8, m))              # xx, xy, yy, xz, yz, z, T, T^2
    for ch in chunks:
        t, x, y, Tv, g = one or pieces(ch)
        xx, xy, yy = x * x, x * y, y * y
        z = Tv * Tv - (g[:, 0] * xx + 2 * g[:, 1] * xy + g[:, 2] * yy)
        for k, w in enumerate((xx, xy, yy, x * z, y * z, z, Tv, Tv * Tv)):
            S[k] += np.bincount(t, w, m)
    sxx, sxy, syy, sxz, syz, sz, st, stt = S
    D = sxx * syy - sxy * sxy
    good &= (cnt >= FIT_MIN_NODES) & (D > 1e-6 * (sxx + syy) ** 2)
    D = np.where(good, D, 1.0)
    p = (syy * sxz - sxy * syz) / D
    q = (sxx * syz - sxy * sxz) / D
    # the unfolded source relative to the centre: c = -G^-1 (p, q) / 2 (node units)
    cx = -0.5 * (a * p + b * q) / (h * h)
    cy = -0.5 * (b * p + c * q) / (h * h)
    k0 = sz / n - (G[:, 0] * cx * cx + 2 * G[:, 1] * cx * cy + G[:, 2] * cy * cy)
    spread = np.sqrt(np.maximum(stt / n - (st / n) ** 2, 0.0))
    res = np.zeros(m)
    speed = []
    for ch in chunks:
        t, x, y, Tv, g = one or pieces(ch)
        dx, dy = x - cx[t], y - cy[t]
        gx = g[:, 0] * dx + g[:, 1] * dy                    # G (x - c): the gradient's direction
        gy = g[:, 1] * dx + g[:, 2] * dy
        dgd = dx * gx + dy * gy
        res += np.bincount(t, (np.sqrt(np.maximum(dgd + k0[t], 0.0)) - Tv) ** 2, m)
        gg = gx * gx + gy * gy
        with np.errstate(invalid='ignore', divide='ignore'):
            # g^T G^-1 g for the unit g = G d / |G d| (G in UV units, h^2 times less): d^T G d / |G d|^2
            speed.append(h * np.sqrt(dgd / gg))
    good &= np.sqrt(res / n) <= FIT_RESIDUAL * spread
    for ch, val in zip(chunks, speed):
        ok = good[fr[ch]] & np.isfinite(val) & (val > 0)
        mu[ch[ok]] = val[ok]
        fitted[ch[ok]] = True
    return mu.reshape(T.shape), fitted.reshape(T.shape)
