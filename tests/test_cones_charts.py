"""Charts of an overlapping cone layout glued back where they do not overlap (core.atlas.cones.merge_charts;
docs/cones.md, "Charts")."""
import numpy as np

from core.atlas.cones import _piece_crossings, merge_charts
from core.atlas.islands import cut_along_seams
from core.mesh.measures import signed_uv_areas


def spiral_sheet(turns=1.5, cols=40, rows=3):
    """A grid strip (rows x cols quads) whose 'layout' winds ``turns`` times around the origin: no
    triangle is flipped, but the strip overlaps itself once it passes a full turn. Returns (F (m,3),
    uv (n,2), column of each vertex (n,))."""
    r, t = np.meshgrid(np.linspace(1.0, 2.0, rows + 1), np.linspace(0, 2 * np.pi * turns, cols + 1),
                       indexing='ij')
    uv = np.stack([r * np.cos(t), r * np.sin(t)], -1).reshape(-1, 2)
    col = np.tile(np.arange(cols + 1), rows + 1)
    idx = np.arange((rows + 1) * (cols + 1)).reshape(rows + 1, cols + 1)
    a, b, c, d = idx[:-1, :-1], idx[:-1, 1:], idx[1:, :-1], idx[1:, 1:]
    F = np.r_[np.stack([a, d, b], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)]
    return F, uv, col


def column_seam(F, col, k):
    """The radial edges of grid column ``k``: (rows,2) vertex pairs."""
    E = np.sort(np.r_[F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]], 1)
    E = np.unique(E, axis=0)
    return E[(col[E[:, 0]] == k) & (col[E[:, 1]] == k)]


def test_merge_glues_charts_until_they_would_overlap():
    F, uv, col = spiral_sheet()
    n = len(uv)
    base = column_seam(F, col, 8)                      # a seam of the cut tree: never glued
    splits = np.concatenate([column_seam(F, col, k) for k in range(4, 40, 4) if k != 8])
    seams = np.r_[base, splits]
    cut = cut_along_seams(F, n, seams)
    uvc = uv[cut.vert_of]
    assert cut.n_islands == 10
    new, uv2, seams2 = merge_charts(F, n, cut, uvc, seams, base)
    # the layout is the same per corner; glued only along split seams, the base seam stays
    assert np.array_equal(uv2[new.F], uvc[cut.F])
    keys = {tuple(e) for e in np.sort(seams2, 1).tolist()}
    assert all(tuple(e) in keys for e in np.sort(base, 1).tolist())
    # the base seam leaves 0.3 turns and 1.2 turns; the 1.2 turns need two charts; the greedy glue
    # keeps at most 4 of the 10 pieces
    assert 3 <= new.n_islands <= 4
    # no chart overlaps itself: boundary crossings 0, no flips, and no chart turns more than once
    assert all(c == 0 for c, _, _ in _piece_crossings(new.F, uv2, new.face_island, new.n_islands))
    assert (signed_uv_areas(uv2, new.F) > 0).all()
    for i in range(new.n_islands):
        cols = col[new.vert_of[new.F[new.face_island == i]]]
        assert cols.max() - cols.min() < 40 / 1.5      # under one full turn (40 columns = 1.5 turns)


def test_merge_keeps_a_layout_without_overlap_in_one_piece():
    F, uv, col = spiral_sheet(turns=0.8)
    n = len(uv)
    seams = np.concatenate([column_seam(F, col, k) for k in (5, 13, 30)])
    cut = cut_along_seams(F, n, seams)
    new, uv2, seams2 = merge_charts(F, n, cut, uv[cut.vert_of], seams, np.zeros((0, 2), np.int64))
    assert new.n_islands == 1 and len(seams2) == 0
    assert np.allclose(uv2[new.F], uv[F])


def flat_annulus(segments=32):
    """A flat square plate (side 2) with a round hole (radius 0.5, ``segments`` sides), Delaunay
    triangulated: ``V`` (n,3) on z = 0, ``F`` (m,3) counter-clockwise."""
    from scipy.spatial import Delaunay
    th = 2 * np.pi * np.arange(segments) / segments
    s = np.linspace(-1, 1, 9)[:-1]
    P = np.r_[np.c_[0.5 * np.cos(th), 0.5 * np.sin(th)],
              np.c_[s, -np.ones(8)], np.c_[np.ones(8), s], np.c_[-s, np.ones(8)], np.c_[-np.ones(8), -s]]
    F = Delaunay(P).simplices
    F = F[np.linalg.norm(P[F].mean(1), axis=1) > 0.5]
    e1, e2 = P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]]
    back = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] < 0
    F[back] = F[back][:, ::-1]
    return np.c_[P, np.zeros(len(P))], F


def test_a_flat_annulus_closes_up_in_one_chart():
    """A flat plate with a hole needs one cut from its rim to the hole, and its isometric layout closes
    up on it: the cut's two copies lie on one line up to rounding. They touch but do not cross, and
    ``boundary_crossings`` took their rounding for crossings, so the layout was split into two charts
    (through a polygon, where the plate is n-gons). Now: one chart, no split, every edge kept. Two
    segments a millionth of a radian apart still cross."""
    from core.atlas.cones import cone_unwrap
    from core.atlas.cut import boundary_crossings
    V, F = flat_annulus()
    res = cone_unwrap(V, F, target_ratio=0.5)
    r = res.report
    assert r['charts'] == 1 and r['chart_splits'] == 0 and r['overlaps'] == 0 and r['flips'] == 0
    e3 = np.linalg.norm(V[F] - V[np.roll(F, 1, axis=1)], axis=2)
    e2 = np.linalg.norm(res.uv - np.roll(res.uv, 1, axis=1), axis=2)
    assert np.abs(e2 / e3 - 1).max() < 1e-9
    # two loops sharing a side up to rounding touch; tilted by a millionth of a radian they cross
    for eps, crosses in ((1e-16, False), (1e-6, True)):
        uv = np.array([[0.0, 0.0], [1.0, 0.0], [0.5, -5.0], [0.9, eps], [0.1, -eps], [0.5, 5.0]])
        assert (boundary_crossings(uv, [np.arange(3), np.arange(3, 6)]) > 0) == crosses
