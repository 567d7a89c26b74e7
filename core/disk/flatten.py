"""Conformal flattening of a disk with boundary scale factors (docs/math.md).

Sign convention: ``u = log mu`` is the log of the local scale (UV length per surface length). With
the positive semidefinite ``L`` the flat-target Yamabe equation reads ``L u = -Omega`` inside and the
target boundary curvature is ``k~ = k + (L u)_B``. docs/math.md writes steps 2-3 for ``-u``;
the two agree for ``u_B = 0`` and the certified bound is the same, but the lengths
``l~ = exp((u_i + u_j)/2) l`` need ``u = log mu``.

The construction follows Boundary First Flattening: choose boundary log scale factors ``u_B``, solve
the discrete Yamabe equation for the interior, build the boundary curve with the target curvature and
lengths, and extend it conformally (x harmonic, y its conjugate harmonic). Boundary modes:

- ``free``: LSCM with two pinned vertices (a baseline).
- ``area``: ``u_B = 0``, boundary lengths kept.
- ``uniform``: the paper's objective, the most uniform conformal factor ``mu = exp(u)``. See
  ``core.uniform``.
"""
import time
from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from ..background import beside
from ..blas import one_thread
from ..errors import ConformalError
from ..mesh.geometry import angle_sums, face_areas, folded_faces
from ..mesh.laplacian import cotan_laplacian
from ..mesh.measures import (SQUASHED_QC, folded_flips, flip_warning, jacobians_from_frames, local_frames,
                             measures_from_jacobians, signed_uv_areas, squashed_count)
from ..mesh.flat_metric import flat_cone_metric, unfold
from ..mesh.intrinsic import intrinsic_delaunay
from ..mesh.solve import Factor, FactorJob, factor_all, fill_order, sub_order
from ..mesh.topology import boundary_loops
from .lscm import lscm
from .uniform import optimise, vertex_bound
from ..mesh.validate import check_mesh, degenerate_faces, normalise_scale, DEFAULT_MAX_FACES

BOUNDARY_MODES = ('free', 'area', 'uniform')
FIT_MODES = ('true_scale', 'unit_square')
OPERATOR_MODES = ('auto', 'intrinsic', 'extrinsic')
AUTO_BOUND_FACES = 20_000      # above this the certified bound is computed only on request
QC_WARN = 1.5                  # a map with qc_mean above this gets a warning
MU_WARN = 1e-4                 # ... and one with mu_ratio below this (texel density varies 10^4-fold)


@dataclass
class FlattenResult:
    """``uv`` (n,2) float64 UV per vertex (counter-clockwise like the faces); ``mu`` (m,) realised
    conformal factor per triangle (total UV area normalised to the 3D area; NaN on triangles outside
    ``real_faces``); ``u`` (n,) log scale
    factor per vertex from the Yamabe solve (None for ``free``); ``report`` dict of measures, bound
    and timings (seconds)."""
    uv: np.ndarray
    mu: np.ndarray
    u: np.ndarray = None
    report: dict = field(default_factory=dict)


START_TIE = 1e-9        # relative tolerance of the boundary start's distance key (float noise)


def geometric_start(V, loop):
    """The boundary loop ``loop`` (nb,) int rolled to start at the vertex farthest from the loop's
    centroid (3D; ties within ``START_TIE`` of the largest squared distance go to the lowest index).

    ``uniform``'s smooth basis is a Fourier series in the arc length from ``loop[0]``, and its trust
    region is a box in those coefficients: a box is not invariant under a phase shift, so a start chosen
    by vertex index made the optimum (a whole face of equally good maps) depend on the numbering (up to
    0.18 in log mu on ridge). A start chosen by the geometry is the same for any vertex order, face
    order, rigid motion and scale."""
    P = V[loop]
    d = ((P - P.mean(axis=0)) ** 2).sum(axis=1)
    top = np.nonzero(d >= d.max() * (1 - START_TIE))[0]
    return np.roll(loop, -int(top[np.argmin(loop[top])]))


class DiskSystem:
    """The prefactored linear algebra of one disk mesh. ``V`` (n,3), ``F`` (m,3), ``loop`` (nb,) the
    boundary with the surface on its left.

    Attributes: ``L`` cotan Laplacian, ``B``/``I`` boundary and interior indices, ``Omega`` (n,) angle
    defect, ``k`` (nb,) boundary turning angles, ``l`` (nb,) boundary edge lengths (edge j runs from
    B[j] to B[j+1])."""

    def __init__(self, V, F, loop, neumann=True, operators='auto'):
        if operators not in OPERATOR_MODES:
            raise ConformalError(f"unknown operators {operators!r}: use one of {', '.join(OPERATOR_MODES)}")
        self.V, self.F = V, F
        n = self.n = len(V)
        self.B = geometric_start(V, np.asarray(loop, np.int64))
        mask = np.zeros(n, bool)
        mask[self.B] = True
        self.I = np.nonzero(~mask)[0]
        self.A = face_areas(V, F)
        self._frames = None                    # every map is measured: made while factorising
        T = None
        self.operators = {'mode': operators, 'intrinsic': False}
        if operators != 'extrinsic':
            # mollify only when asked ('intrinsic', which flatten() uses on zero-area triangles): on
            # valid needles it would bend an exact map (a flat needle strip maps isometrically)
            T = intrinsic_delaunay(V, F, mollify_delta=1e-4 if operators == 'intrinsic' else 0.0)
            rep = T.report
            use = operators == 'intrinsic' or rep['negative_before'] > rep['negative_boundary_after']
            if use:
                self.operators.update(intrinsic=True, **{k: T.report[k] for k in (
                    'flips', 'eps', 'negative_before', 'negative_after', 'converged')})
            else:
                self.operators['negative_weights'] = T.report['negative_before']
                T = None
        if T is not None:
            L = T.cotan_laplacian()            # CSC of a symmetric matrix: its arrays are L's CSR arrays
            self.L = sp.csr_matrix((L.data, L.indices, L.indptr), shape=L.shape)
            del L
            s = T.angle_sums()
        else:
            self.L = cotan_laplacian(V, F)
            s = angle_sums(V, F)
        del T                                  # only L and the angle sums are needed from here on
        LI = self.L[self.I]
        self.L_II = LI[:, self.I].tocsc()
        self.L_IB = LI[:, self.B].tocsc()
        del LI                                 # a Laplacian-sized copy: not alive while factoring
        keep = np.arange(n) != self.B[0]
        self._keep = keep
        if neumann and len(self.I):
            # L_II for the Yamabe and harmonic solves, L without one vertex for the conjugate; on big
            # meshes both in one nested dissection order of the vertices (docs/scale.md)
            # (above PARALLEL_MAX rows: in turn, the second on a thread that the first one's solves
            # overlap, FactorJob; below: on two threads at once)
            order = fill_order(V, self.L)
            self._II, self._neumann = factor_all(self.L_II, self.L[keep][:, keep], defer_last=True,
                                                 orders=(sub_order(order, self.I), sub_order(order, keep)),
                                                 meanwhile=self._make_frames)
        else:
            self._II = Factor(self.L_II) if len(self.I) else None
            self._neumann = None
        self.Omega = np.where(mask, 0.0, 2 * np.pi - s)
        self.k = np.pi - s[self.B]
        self.l = np.linalg.norm(V[np.roll(self.B, -1)] - V[self.B], axis=1)

    def _make_frames(self):
        """The triangles' own frames (``local_frames``), for the Jacobians of every map measured."""
        self._frames, _ = local_frames(self.V, self.F)

    @property
    def conjugate_pending(self):
        """True while the Neumann factorisation still runs on its own thread (big meshes, see
        ``factor_all(defer_last=True)``): until ``conjugate`` is first called, solves with ``L_II``
        overlap it."""
        return isinstance(self._neumann, FactorJob)

    # --- step 2: interior log scale factors -----------------------------------------------------
    def solve_II(self, b):
        """``L_II^-1 b`` for (nI,) or (nI,r) ``b`` (zeros without interior vertices)."""
        if self._II is None:
            return np.zeros_like(b)
        return self._II.solve(b)

    def yamabe(self, uB):
        """Per-vertex log scale ``u = log mu`` (n,) with boundary values ``uB`` (nb,):
        ``L_II u_I = -Omega_I - L_IB u_B`` (flat interior: ``Omega~ = Omega + L u = 0``)."""
        u = np.zeros(self.n)
        u[self.B] = uB
        u[self.I] = self.solve_II(-self.Omega[self.I] - self.L_IB @ uB)
        return u

    def harmonic(self, fB):
        """Harmonic extension (n,) or (n,r) of boundary values ``fB`` (nb,) or (nb,r)."""
        f = np.empty((self.n,) + np.shape(fB)[1:])
        f[self.B] = fB
        x = self.solve_II(self.L_IB @ fB)
        np.negative(x, out=x)
        f[self.I] = x
        return f

    # --- steps 3-4: the boundary curve ---------------------------------------------------------
    def boundary_curve(self, u):
        """Closed boundary polygon (nb,2) with turning angles ``k~ = k + (L u)_B`` and lengths closest
        to ``l~ = exp((u_i + u_j)/2) l`` in the weighted least-squares sense."""
        uB = u[self.B]
        kt = self.k + (self.L @ u)[self.B]
        if abs(kt.sum() - 2 * np.pi) > 1e-6 * max(1.0, np.abs(kt).sum()):
            raise ConformalError(f"target boundary curvature sums to {kt.sum():.6f}, not 2*pi: "
                                 "the mesh is not a topological disk", 'bad_topology')
        lt = np.exp(0.5 * (uB + np.roll(uB, -1))) * self.l
        phi = np.cumsum(kt)
        T = np.stack([np.cos(phi), np.sin(phi)], axis=1)
        M = T.T @ (lt[:, None] * T)
        ls = lt - lt * (T @ np.linalg.solve(M, T.T @ lt))
        if (ls <= 0).any():
            raise ConformalError("the boundary scale factors are too extreme to close the boundary "
                                 "curve", 'solve_failed', 'area_boundary')
        P = np.zeros((len(ls), 2))
        P[1:] = np.cumsum(ls[:-1, None] * T[:-1], axis=0)
        return P

    # --- step 5: conformal extension ---------------------------------------------------------
    def conjugate(self, x):
        """Conjugate harmonic ``y`` (n,) of ``x`` (n,): least-squares ``grad y = n x grad x``, i.e.
        ``L y = div(n x grad x)``, with y fixed at one boundary vertex.

        On a triangle, ``A_T grad phi_i . (n x grad phi_j) = +-1/2`` for ``i != j`` (the sign of the
        pair's orientation) whatever its shape, so the right-hand side cancels at every interior vertex
        and is ``b[B_j] = (x[B_(j-1)] - x[B_(j+1)]) / 2`` on the boundary loop (docs/math.md §2): the
        same for the mesh's triangles and the intrinsic ones, and no per-triangle geometry is kept
        for it."""
        if self._neumann is None:
            self._neumann = Factor(self.L[self._keep][:, self._keep])
        elif isinstance(self._neumann, FactorJob):
            self._neumann = self._neumann.result()
        b = np.zeros(self.n)
        b[self.B] = 0.5 * (x[np.roll(self.B, 1)] - x[np.roll(self.B, -1)])
        y = np.zeros(self.n)
        y[self._keep] = self._neumann.solve(b[self._keep])
        return y

    def extend(self, P):
        """UV (n,2) from the boundary polygon ``P`` (nb,2). Both ways of extending are averaged: x
        harmonic with y its conjugate, and y harmonic with x its negative conjugate (each shifted to
        match the polygon on average along the boundary). Each alone turns with the polygon only up
        to discretisation error; the average ``(A(Px) + i A(Py)) / 2`` with ``A(f) = h(f) + i c(h(f))``
        is exactly rotation-equivariant, so the map does not depend on where the boundary loop starts
        (i.e. on the vertex numbering)."""
        H = self.harmonic(P)                                    # (n,2): h(Px), h(Py)
        x1, y2 = H[:, 0], H[:, 1]
        y1 = self.conjugate(x1)
        x2 = -self.conjugate(y2)
        y1 += np.mean(P[:, 1] - y1[self.B])
        x2 += np.mean(P[:, 0] - x2[self.B])
        return np.stack([0.5 * (x1 + x2), 0.5 * (y1 + y2)], axis=1)

    def jacobians(self, uv):
        """Per-triangle Jacobians (m,2,2) of a UV map (n,2); the triangles' own frames are cached."""
        if self._frames is None:
            self._frames, _ = local_frames(self.V, self.F)
        with np.errstate(divide='ignore', invalid='ignore'):       # zero-area triangles: inf/NaN
            return jacobians_from_frames(self._frames, self.F, uv)

    def map_from_u(self, u):
        """UV (n,2) of the conformal map with log scale factor ``u`` (n,)."""
        return self.extend(self.boundary_curve(u))


def normalise_uv(F, uv, area, fit='true_scale'):
    """Centre, rotate to principal axes and scale a UV map (n,2) of the triangles ``F`` (m,3).
    ``true_scale``: total UV area equals ``area``, the triangles' total 3D area (squared mesh units).
    ``unit_square``: fit into [0,1]^2 keeping the aspect ratio."""
    if fit not in FIT_MODES:
        raise ConformalError(f"unknown fit {fit!r}: use one of {', '.join(FIT_MODES)}")
    W = uv[F]
    e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    a = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0])
    c = (W.mean(axis=1) * a[:, None]).sum(0) / a.sum()
    uv = uv - c
    wt = np.bincount(F.ravel(), np.repeat(np.abs(a), 3), minlength=len(uv))
    C = (uv * wt[:, None]).T @ uv
    w, R = np.linalg.eigh(C)
    R = R[:, ::-1]
    # an eigenvector's sign is arbitrary: choose the one with the positive third moment along the
    # main axis, so that the result does not depend on the order of vertices or faces. A shape that
    # is its own mirror image across the second axis has no third moment along the first (round-off
    # would pick the sign): then the moment along the second axis decides (a half turn), and for a
    # shape that is its own half turn, the first vertex off the second axis (the order of vertices
    # decides between two congruent maps)
    if (wt * (uv @ R[:, 0]) ** 3).sum() < 0:
        R[:, 0] *= -1
    if np.linalg.det(R) < 0:
        R[:, 1] *= -1
    p = uv @ R
    m3 = (wt[:, None] * p ** 3).sum(0)
    tie = np.abs(m3) <= 1e-9 * (wt[:, None] * np.abs(p) ** 3).sum(0)
    if tie[0]:
        used = wt > 0
        off = used & (np.abs(p[:, 0]) > 1e-6 * np.abs(p[used, 0]).max())
        if (m3[1] < 0) if not tie[1] else (off.any() and p[np.argmax(off), 0] < 0):
            R = -R
    uv = uv @ R
    if fit == 'true_scale':
        return uv * np.sqrt(area / a.sum())
    lo, hi = uv.min(0), uv.max(0)
    size = (hi - lo).max()
    return (uv - lo) / size + (1 - (hi - lo) / size) / 2


# what to do about an extreme scale variation (the words every warning of it ends with)
SCALE_REMEDY = "mark seams that cut long or closed parts apart, or let the tool choose cones and seams"


def scale_variation(mu_ratio):
    """The core of the warning for a ``mu_ratio`` below ``MU_WARN`` or NaN (str), or None at or above
    it; the warnings add ``SCALE_REMEDY``."""
    if mu_ratio >= MU_WARN:
        return None
    return (f"extreme scale variation: mu_ratio {mu_ratio:.2g} (texel density varies more than "
            f"{1 / MU_WARN:.0e}-fold)")


def _warnings(report, qc_limit=QC_WARN):
    """The honest-report warnings (list of str) for a measured map's ``report``."""
    w = []
    if report.get('flips', 0):
        w.append(flip_warning(report))
    if not report.get('qc_mean', 1.0) <= qc_limit:
        w.append(f"poor conformality: qc_mean {report.get('qc_mean'):.3f} is above {qc_limit}")
    if not np.isfinite(report.get('mu_ratio', np.nan)) or not report.get('mu_ratio', 0) > 0:
        w.append("the conformal factor is not finite and positive on every triangle")
    elif scale_variation(report['mu_ratio']):
        w.append(f"{scale_variation(report['mu_ratio'])}; {SCALE_REMEDY}")
    return w


@one_thread()
def flatten(V, F, boundary='uniform', fit='true_scale', max_faces=DEFAULT_MAX_FACES, bound=None,
            progress=None, real_faces=None, operators='auto', checked_loop=None, exact=True,
            **options) -> FlattenResult:
    """Flatten a disk-topology triangle mesh conformally.

    V: (n,3) float positions. F: (m,3) int triangles, counter-clockwise. boundary: 'free', 'area' or
    'uniform'. fit: 'true_scale' (UV area = 3D area, mesh units) or 'unit_square'. bound: compute
    the vertex-level L-inf certificate (default: for 'uniform' up to AUTO_BOUND_FACES triangles; if its
    linear program fails the report says so and the map is still returned). progress: optional
    callable ``progress(fraction, message)``. real_faces: optional (m,) bool; only these triangles
    count in the objective and the measures (the others are temporary fill, e.g. of holes).
    operators: 'auto' (intrinsic Delaunay operators where the mesh has non-Delaunay edges or needs
    mollification, docs/math.md), 'intrinsic' (always) or 'extrinsic' (the mesh's own cotan weights).
    Zero-area triangles are accepted: the intrinsic mollification gives them a valid metric, and they
    are left out of the objective and the measures (``report['degenerate_faces']``). Loose vertices
    (in no triangle) are left out: their UVs (and ``u``) are NaN, and ``report['repairs']`` says so.
    checked_loop: the boundary loop (k,) of a caller that has just run ``check_mesh`` on these very
    arrays with checks at least as strict as the disk check (``unwrap``'s disk dispatch); the checks
    are then not repeated. Extra ``options`` go to ``core.disk.uniform.optimise``.
    Returns ``FlattenResult``; ``report['warnings']`` (list of str) lists flips, qc_mean above 1.5,
    fallbacks; ``report['planar']`` says when the mesh lies in a plane (``planar_map``: its own
    coordinates are the map, no solve); ``report['layout']`` when the exact discrete conformal layout
    replaced a linear map that sheared a sliver (``_exact_layouts``; ``exact=False``: never, the linear
    map only, as the geodesic solver, sphere mode and the metric reconstruction ask, whose error models
    were measured on it). Raises ``ConformalError`` on bad input."""
    loose = _loose_vertices(V, F)
    if loose is not None:
        # vertices in no face take no part: the map of the rest, NaN UVs for them, the repair listed
        used, remap = loose
        res = flatten(np.asarray(V)[used], remap[np.asarray(F, np.int64)], boundary, fit, max_faces, bound,
                      progress, real_faces, operators, None if checked_loop is None else
                      remap[np.asarray(checked_loop, np.int64)], exact, **options)
        n = len(V)
        uv = np.full((n, 2), np.nan)
        uv[used] = res.uv
        u = None
        if res.u is not None:
            u = np.full(n, np.nan)
            u[used] = res.u
        res.report['vertices'] = n
        res.report['repairs'] = [{'repair': 'loose_vertices_ignored', 'count': int(n - len(used)),
                                  'note': 'vertices in no face are left out (their UVs are NaN)'}] + \
            res.report.get('repairs', [])
        return FlattenResult(uv=uv, mu=res.mu, u=u, report=res.report)
    # LSCM has no maximum principle to restore and measures slightly worse on the intrinsic
    # triangulation of smooth grids (bench/flatten_table.py): 'auto' tries the mesh's own weights first
    first, second = ('extrinsic', 'intrinsic') if boundary == 'free' else ('auto', 'extrinsic')
    res = _flatten(V, F, boundary, fit, max_faces, bound, progress, real_faces,
                   first if operators == 'auto' else operators, checked_loop, **options)
    r = res.report
    if operators == 'auto' and r['operators'].get('intrinsic') != (second == 'intrinsic') and \
            not r.get('degenerate_faces') and (r['flips'] or not r['qc_mean'] <= QC_WARN or 'fallback' in r):
        # the first operators did not give a clean map here: try the others and keep the better
        alt = _flatten(V, F, boundary, fit, max_faces, bound, progress, real_faces, second, checked_loop,
                       **options)
        if _quality_key(alt.report) < _quality_key(r):
            alt.report['operators']['tried_first'] = {k: r[k] for k in ('flips', 'qc_mean', 'mu_ratio')}
            res = alt
    r = res.report
    if exact and boundary != 'free' and res.u is not None and not r.get('planar') and \
            not r['qc_max'] <= EXACT_QC \
            and r['mu_ratio'] < EXACT_GAP * r.get('vertex_ratio', 0.0):
        # the optimiser's boundary scale was chosen against the linear map's sheared triangles: in
        # ``uniform`` mode the area map's (u_B = 0) is laid out exactly too, and the better kept
        scales = {boundary: res.u}
        if boundary == 'uniform':
            scales['area'] = np.zeros_like(res.u)
        for alt in _exact_layouts(V, F, res, scales, fit, real_faces):
            if _quality_key(alt.report) < _quality_key(res.report):
                res = alt
    return res


# a linear map that shears a triangle beyond EXACT_QC, where the triangles' ratio falls below EXACT_GAP
# times the vertices' (the sheared triangles, not the scale, set it), also gets the exact layout
EXACT_QC = 10.0
EXACT_GAP = 0.5


def _exact_layouts(V, F, res, scales, fit, real_faces):
    """The exact discrete conformal maps with the boundary scales ``scales`` {name: u (n,)} (the
    boundary values held, the interior angle sums 2 pi, ``u`` the start of the rest; Newton on one
    intrinsic Delaunay triangulation, ``core.mesh.flat_metric.flat_cone_metric``, laid out face by face),
    each measured like the linear map ``res``: a list of ``FlattenResult`` (those whose Newton
    converged). On a sliver the linear map can shear a triangle far from its shape; the exact metric
    lays out every intrinsic triangle with its own angles (docs/robustness.md)."""
    t0 = time.perf_counter()
    F = np.asarray(F, np.int64)
    Vn, unit = normalise_scale(np.asarray(V, np.float64))
    n = len(Vn)
    loops = boundary_loops(F, n)
    if len(loops) != 1:
        return []
    degenerate = degenerate_faces(Vn, F)
    T = intrinsic_delaunay(Vn, F, mollify_delta=1e-4 if degenerate.any() else 0.0)
    fixed = np.zeros(n, bool)
    fixed[loops[0]] = True
    mask = None if real_faces is None else np.asarray(real_faces, bool)
    if degenerate.any():
        mask = ~degenerate if mask is None else mask & ~degenerate
    frames, A = local_frames(Vn, F)
    base = {k: v for k, v in res.report.items()
            if k not in ('flips_folded', 'squashed', 'degenerate_flips', 'warnings', 'seconds')}
    kept = [w for w in res.report.get('warnings', []) if w not in _warnings(res.report)]
    out = []
    for name, u in scales.items():
        got = flat_cone_metric(T, np.arange(n), n, np.full(n, 2 * np.pi), fixed, u - u[fixed].mean()) \
            if np.isfinite(u).all() else None
        uv = None if got is None else unfold(T, got[1])
        if uv is None or not np.isfinite(uv).all():
            continue
        r = dict(base, layout={'exact': True, 'flat_triangles': int(got[2]), 'boundary_scale': name,
                               'linear': {k: res.report[k] for k in ('flips', 'qc_max', 'mu_ratio')}})
        timings = dict(res.report.get('seconds', {}), exact_layout=time.perf_counter() - t0)
        out.append(_measured(r, uv, got[0], F, mask, A, lambda uv: jacobians_from_frames(frames, F, uv), fit,
                             unit, list(kept), timings, t0 - timings.get('total', 0.0), V=Vn,
                             degenerate=degenerate))
    return out


def _loose_vertices(V, F):
    """``(used (k,), remap (n,))`` of a mesh whose vertices ``V`` (n,3) include some in no triangle of
    ``F`` (m,3) (loose vertices: the used ones in order, and each vertex's index among them, -1 if
    loose), or None if every vertex is used or the arrays are not ones ``check_mesh`` accepts (it then
    names what is wrong)."""
    try:
        F = np.asarray(F, np.int64)
        n = len(V)
        if F.ndim != 2 or F.shape[1] != 3 or not len(F) or F.min() < 0 or F.max() >= n:
            return None
    except (TypeError, ValueError):
        return None
    on = np.zeros(n, bool)
    on[F.ravel()] = True
    if on.all():
        return None
    used = np.flatnonzero(on)
    remap = np.full(n, -1, np.int64)
    remap[used] = np.arange(len(used))
    return used, remap


def _optimise(system, V, F, mask, progress, options):
    """``optimise`` on the triangles ``mask`` (m,) bool or None. Where the area map folds and the mesh
    has triangles folded over in itself (``folded_faces``: a crumpled spot of a scan, whose flip is
    the mesh's, not the map's), the optimiser runs again without them: they keep whatever
    orientation the map gives them, and the measures report them (``flips_folded``). Returns ``(u,
    uv, info)``; raises ``ConformalError`` as ``optimise`` does."""
    try:
        return optimise(system, progress=progress, real_faces=mask, **options)
    except ConformalError as exc:
        folded = folded_faces(V, F) if 'folds' in exc.problem else None
        keep = None if folded is None else ~folded if mask is None else mask & ~folded
        if folded is None or not folded.any() or not keep.any():
            raise
        u, uv, info = optimise(system, progress=progress, real_faces=keep, **options)
        info['folded_left_out'] = int(folded.sum() if mask is None else (folded & mask).sum())
        return u, uv, info


def _quality_key(r):
    """Sort key of a measured map report (lower is better): the map's own defects (flips and
    triangles squashed nearly flat, ``squashed``), qc_mean over budget, -mu_ratio. A flip of a
    triangle that is folded over in the mesh itself (``flips_folded``: a crumpled spot of a scan) is
    the mesh's, whichever operators ran: it does not count here."""
    mu = r.get('mu_ratio', 0.0)
    own = r.get('flips', 0) - r.get('flips_folded', 0) + r.get('degenerate_flips', 0) + r.get('squashed', 0)
    return (own, not r.get('qc_mean', np.inf) <= QC_WARN, -(mu if np.isfinite(mu) else 0.0))


def _flatten(V, F, boundary, fit, max_faces, bound, progress, real_faces, operators, checked_loop=None,
             **options):
    """``flatten`` with one choice of operators."""
    if boundary not in BOUNDARY_MODES:
        raise ConformalError(f"unknown boundary mode {boundary!r}: use one of {', '.join(BOUNDARY_MODES)}")
    if fit not in FIT_MODES:
        raise ConformalError(f"unknown fit {fit!r}: use one of {', '.join(FIT_MODES)}")
    report_progress = progress or (lambda f, msg: None)
    timings = {}
    t0 = time.perf_counter()
    loop = check_mesh(V, F, kind='disk', max_faces=max_faces, allow_degenerate=True).boundary \
        if checked_loop is None else np.asarray(checked_loop, np.int64)
    F = np.asarray(F, np.int64)
    # work in units where the mesh spans [-1,1]: the same numbers at any scale (1e-100 or 1e100)
    V, unit = normalise_scale(np.asarray(V, np.float64))
    mask = None if real_faces is None else np.asarray(real_faces, bool)
    if mask is not None and (mask.shape != (len(F),) or not mask.any()):
        raise ConformalError("real_faces must be one boolean per triangle, with at least one True")
    warnings = []
    degenerate = degenerate_faces(V, F)
    if degenerate.any():
        mask = ~degenerate if mask is None else mask & ~degenerate
        if not mask.any():
            raise ConformalError("every triangle has zero area", 'degenerate', 'clean_mesh')
        operators = 'intrinsic'
    timings['check'] = time.perf_counter() - t0
    uv = planar_map(V, F) if mask is None else None
    if uv is not None:
        # a mesh lying in a plane is its own conformal map in every mode: an isometry (u = 0, mu = 1
        # on every triangle), so the optimum of ``uniform`` and its certified bound are both 1
        report = {'boundary': boundary, 'vertices': len(V), 'faces': len(F),
                  'boundary_vertices': int(len(loop)), 'operators': {'mode': operators, 'intrinsic': False},
                  'solver': None,
                  'planar': 'the mesh lies in a plane: its own coordinates are the map (no solve)'}
        if bound or (bound is None and boundary == 'uniform' and len(F) <= AUTO_BOUND_FACES):
            report['bound_vertex'] = 1.0
        frames, A = local_frames(V, F)
        return _measured(report, uv, None if boundary == 'free' else np.zeros(len(V)), F, None, A,
                         lambda uv: jacobians_from_frames(frames, F, uv), fit, unit, warnings, timings, t0)
    report_progress(0.05, 'factorising the Laplacian')
    t = time.perf_counter()
    system = DiskSystem(V, F, loop, neumann=boundary != 'free', operators=operators)
    timings['factor'] = time.perf_counter() - t
    report_progress(0.25, 'solving')
    report = {'boundary': boundary, 'vertices': len(V), 'faces': len(F),
              'boundary_vertices': int(len(loop)), 'operators': system.operators,
              'solver': system._II.backend if system._II is not None else None}
    if degenerate.any():
        report['degenerate_faces'] = int(degenerate.sum())
    u = None
    job = None
    if boundary == 'uniform' and (bound or (bound is None and len(F) <= AUTO_BOUND_FACES)):
        job = beside(len(F), _bound, system, mask)     # it needs only the system: beside optimise
    t = time.perf_counter()
    if boundary == 'free':
        uv = lscm(V, system.L, system.B)
    elif boundary == 'area':
        u = system.yamabe(np.zeros(len(system.B)))
        uv = system.map_from_u(u)
    else:
        try:
            u, uv, opt = _optimise(system, V, F, mask, report_progress, options)
            report.update(opt)
        except ConformalError as exc:
            if exc.code not in ('invalid_input', 'solve_failed', 'degenerate') and 'folds' not in exc.problem:
                raise
            # the area map already folds: keep the better of it and LSCM, and say so
            u, uv, which = _fallback(system, V, mask)
            warnings.append(f"the uniform optimiser could not start ({exc.problem}); the {which} map "
                            "is returned instead")
            report['fallback'] = which
    timings['solve'] = time.perf_counter() - t
    if bound is None:
        bound = boundary == 'uniform' and len(F) <= AUTO_BOUND_FACES and 'fallback' not in report
    if bound:
        report_progress(0.9, 'certifying the bound')
        t = time.perf_counter()
        value, error, timings['bound'] = job.result() if job is not None else _bound(system, mask)
        timings['bound_wait'] = time.perf_counter() - t
        report['bound_vertex'] = value
        if error is not None:
            report['bound_note'] = str(error)
    elif job is not None:
        job.result()                           # not wanted after all (the optimiser fell back)
    report_progress(0.95, 'measuring')
    return _measured(report, uv, u, F, mask, system.A, system.jacobians, fit, unit, warnings, timings, t0,
                     V=V, degenerate=degenerate)


def _measured(report, uv, u, F, mask, A, jacobians, fit, unit, warnings, timings, t0, V=None,
              degenerate=None):
    """The ``FlattenResult`` of a map ``uv`` (n,2) with log scale ``u`` (n,) or None: normalised
    (``fit``, ``unit`` the mesh's scale), measured per triangle on ``mask`` (None: all) with the 3D
    areas ``A`` (m,) and ``jacobians(uv)`` (m,2,2), and its report completed (measures, warnings,
    seconds since ``t0``). With the positions ``V`` (n,3), flipped triangles that are folded over in
    the mesh itself (``folded_faces``) are counted too (``flips_folded``); with ``degenerate`` (m,)
    bool, the zero-area triangles turned over (``degenerate_flips``)."""
    if degenerate is not None and degenerate.any():
        # a zero-area triangle has no Jacobian; it still must not turn over in UV (the sign does not
        # change with the similarity ``normalise_uv`` applies)
        report['degenerate_flips'] = int((signed_uv_areas(uv, F[degenerate]) < 0).sum())
    Fm = F if mask is None else F[mask]
    uv = normalise_uv(Fm, uv, (A if mask is None else A[mask]).sum(), fit)
    J = jacobians(uv)
    measured, mu_real = measures_from_jacobians(*((J, A) if mask is None else (J[mask], A[mask])))
    report.update(measured)
    if V is not None and measured.get('flips'):
        report['flips_folded'] = folded_flips(V, F, J, mask)
    if V is not None and not measured['qc_max'] <= SQUASHED_QC:
        # triangles squashed nearly flat (a defect like a flip; the mesh's own needles left out)
        report['squashed'] = squashed_count(V, Fm, J if mask is None else J[mask], measured['qc_max'])
    if u is not None:
        used = np.unique(Fm)
        report['vertex_ratio'] = float(np.exp(u[used].min() - u[used].max()))
    mu = np.full(len(F), np.nan)
    mu[np.arange(len(F)) if mask is None else mask] = mu_real
    if fit == 'true_scale':
        uv = uv * unit
    report['warnings'] = warnings + _warnings(report)
    timings['total'] = time.perf_counter() - t0
    report['seconds'] = {k: round(v, 4) for k, v in timings.items()}
    return FlattenResult(uv=uv, mu=mu, u=u, report=report)


PLANAR_TOL = 1e-9         # a mesh within this distance of a plane (units of its half span) is planar


def planar_map(V, F, tol=PLANAR_TOL):
    """The mesh's own coordinates in its plane (n,2), when ``V`` (n,3) lies within ``tol`` of a plane
    and every triangle of ``F`` (m,3) keeps a positive area there (counter-clockwise); else None.

    Such a mesh is flat: the conformal map of every boundary mode is the mesh itself up to a
    similarity (``area`` and ``uniform``: an isometry, u = 0), which the solves would only reproduce
    to round-off. ``V`` in units of its half span (``normalise_scale``)."""
    c = V.mean(axis=0)
    w, R = np.linalg.eigh((V - c).T @ (V - c))         # ascending: R[:, 0] is the normal
    if np.abs((V - c) @ R[:, 0]).max() > tol:
        return None
    P = (V - c) @ R[:, 1:]
    a = signed_uv_areas(P, F)
    if a.sum() < 0:
        P[:, 1], a = -P[:, 1], -a
    return P if (a > 0).all() else None


def certified_bound(V, F, operators, real_faces=None):
    """The certified vertex bound that ``flatten(V, F, bound=True)`` reports for a map made with
    ``operators`` (the ``mode`` of its ``report['operators']``: 'auto', 'intrinsic' or 'extrinsic'),
    computed on its own: for a caller that made several maps and wants the certificate of the one it
    keeps (``unwrap``'s retries). The same system as that map's, so the same value. ``V`` (n,3),
    ``F`` (m,3) a disk, ``real_faces`` as in ``flatten``. Returns (value or None, note or None)."""
    r = _flatten(V, F, 'area', 'true_scale', None, True, None, real_faces, operators).report
    return r.get('bound_vertex'), r.get('bound_note')


def _bound(system, mask):
    """``vertex_bound(system, real_faces=mask)`` as (value or None, the ConformalError or None, seconds
    it took); any other exception propagates. The bound depends only on the system, not on the
    optimiser's map, and most of its time is spent in HiGHS and in sparse solves: from
    ``THREAD_MIN_FACES`` triangles it runs on its own thread beside ``optimise`` (``beside``;
    docs/scale.md, latency)."""
    t = time.perf_counter()
    try:
        value, error = vertex_bound(system, real_faces=mask), None
    except ConformalError as exc:
        value, error = None, exc
    return value, error, time.perf_counter() - t


def _fallback(system, V, mask):
    """When the area map folds: (u or None, uv (n,2), name) of whichever of the area map and LSCM has
    fewer flipped triangles among ``mask`` (None: all)."""
    keep = slice(None) if mask is None else mask
    cands = []
    try:
        u = system.yamabe(np.zeros(len(system.B)))
        cands.append((u, system.map_from_u(u), 'area'))
    except ConformalError:
        pass
    cands.append((None, lscm(V, system.L, system.B), 'free (LSCM)'))

    def folds(c):
        a = signed_uv_areas(c[1], system.F[keep])
        return int((a * np.sign(a.sum()) <= 0).sum())
    return min(cands, key=folds)
