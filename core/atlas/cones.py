"""Cone singularities and seams for the L-inf objective (issue #13; the math is in docs/cones.md).

A cone is a vertex where the flattened map has total angle ``2*pi - kappa_i`` instead of ``2*pi``.
With target curvature ``kappa`` (nonzero only at cones) the log scale ``u = log mu`` solves

    L u = kappa - Omega            (closed: sum kappa = sum Omega = 2*pi*chi; u up to a constant)

with the cotan Laplacian ``L`` (positive semidefinite) and the angle defect ``Omega``. On a surface
with boundary the boundary is kept at ``u_B = 0`` (lengths kept) and ``kappa`` is free. ``u`` is affine
in ``kappa``: ``u = u0 + G[:, S] kappa_S`` with ``G`` the grounded Green's function, of which only the
columns of the cones are ever computed (one solve each with the one factorisation of ``L``).

Pipeline of ``cone_unwrap``:

1. placement (``place_cones``): a look-ahead greedy (the most extreme vertices of ``u`` screened in
   one batch, the best scored by the 1%/99% spread of the per-triangle scale (the worse of its
   per-triangle and area-weighted readings, ``face_spread``) with bounded area-L2 angles,
   ``ConeSystem.l2_angles``) and BFF's greedy, each under two sets of curvature bounds
   (``L2_BOUNDS``, ``WIDE_BOUNDS``), and the L2 start (a nearly sparse curvature,
   ``sparse_curvature``, its peaks thinned by backward elimination, ``eliminate``); then cone moves
   over 3-rings (``move_cones``). ``L`` is the intrinsic Delaunay Laplacian.
2. cut graph (``core.atlas.cutgraph.cut_graph``): 2g homology loops plus a short tree through the
   cones and the boundary, pruned and straightened. A wedge over ``2*pi`` (a negative cone) gets a
   new branch through its middle (``through_corner``).
3. layout of the cut disk for several angle sets on the same cones (area-L2, L-inf with floors,
   BFF's, corrections for the exact metric); the best realised p1/p99 (the worse reading) without flips,
   squashed triangles or overlap is kept (a set whose linear estimate is ``SKIP_MARGIN`` below the
   best clean layout so far is not laid out). The layout is the exact flat cone metric (Newton on the
   discrete conformal equation on the cut disk's intrinsic Delaunay triangulation, one log scale per
   surface vertex, so both sides of a seam have equal lengths and differ by a rigid motion) unfolded
   in the plane; if Newton fails, BFF-style: the closed-surface ``u`` gives the boundary lengths
   ``exp((u_i+u_j)/2) l_ij`` and turning angles ``k + (L u)_B``, the polygon is closed with a length
   change shared by both copies of every seam edge, and extended harmonically. An overlapping layout
   is split into charts (``split_overlaps``) and glued back where the pieces do not overlap
   (``merge_charts``). Other placements are laid out too when the best one realises clearly less
   than their estimate (``ALT_MARGIN``).
4. measures per triangle (``core.mesh.measures``) and overlap (boundary self-crossings).
"""
import time
from dataclasses import dataclass, field
from functools import lru_cache
from itertools import combinations

import numpy as np
from scipy.optimize import linprog

from ..disk.flatten import planar_map
from ..errors import ConformalError
from ..mesh import topology
from ..mesh.geometry import angle_sums, face_areas
from ..mesh.intrinsic import corner_angles as corner_angles_l
from ..mesh.intrinsic import face_areas as face_areas_l
from ..mesh.intrinsic import intrinsic_delaunay
from ..mesh.flat_metric import flat_cone_metric, unfold
from ..mesh.laplacian import cotan_laplacian
from ..mesh.measures import (SQUASHED_QC, jacobians, measures_from_jacobians, shape_anisotropy,
                             signed_uv_areas, singular_values, squashed_faces)
from ..mesh.solve import Factor
from ..mesh.validate import (DEFAULT_MAX_FACES, as_arrays, check_arrays, check_mesh, degenerate_faces,
                             normalise_scale)
from .cutgraph import cut_graph, inner_mask, is_disk, reroute_leaf, side_pairs, straighten, through_corner
from .charts import MAX_SPLITS, _cut_twins, _piece_crossings, merge_charts, split_overlaps  # noqa: F401
from .cut import boundary_crossings, cut_along_seams

KAPPA_MAX = 3.5                    # a cone keeps an angle of at least 2*pi - 3.5 (LP bound)
KAPPA_MIN = -2.0                   # sharper cones spike u and hurt the realised map (LP bound)
KAPPA_LEAF = 0.4                   # a cone at a leaf of the cut needs kappa > 0 (one wedge)
ANGLE_FLOORS = (-2.0, -1.0, 0.1)   # lower bounds of the angle candidates laid out and compared
BIG_MESH = 20_000                  # above this many vertices: no L2 start, fewer layouts (and the
                                   # automatic mode: BFF's greedy only, no cone moves)
DEGENERATE_QC = SQUASHED_QC        # a layout triangle with s1/s2 above this counts as degenerate
REPAIR_ROUNDS = 3                  # local clamped-weight re-solves of a folded harmonic layout
MOLLIFY = 1e-4                     # intrinsic mollification of zero-area triangles (relative)
UNTANGLE_ROUNDS = 3                # then sweeps of single-vertex moves over the corners still folded
UNTANGLE_MARGIN = 0.5              # ... each to this fraction of its best clearance (``untangle``)
QC_WARN = 1.1                      # the layout's qc_mean above this is reported (the discrete
                                   # conformal map of a coarse mesh with strong cones is not exact)
L2_BOUNDS = (-3.0, 3.5)            # curvature bounds of the area-L2 angles (placement, first run)
WIDE_BOUNDS = (-5.5, 5.5)          # second placement run (MovingCones' cones reach -5.8 .. 4.8 rad;
                                   # wedges over 2*pi are split by the cut; a horn's tip needs a cone
                                   # angle near 0: 5.5 leaves 0.78 rad)
SOFT_FLOORS = (-2.0, -1.0, 0.0)     # raised lower bounds of cones next to a flipped triangle
SOFT_STEP = 0.5                    # ... a cone below SOFT_FLOORS[0] is first raised by this (``_next_floor``)
SOFT_ROUNDS = 5                    # layouts with raised floors at most (``softened``)
NUDGE_TRIES = 4                    # ... or a cone next to flips moved to a neighbour (``nudged``)
MAX_LAYOUTS = 24                   # exact layouts of angle candidates in one ``cone_unwrap`` at most:
                                   # 1-7 on the corpus and its head cuts, 20 on the cow (its tail);
                                   # a noisy scan whose every layout folds ran through 56 of them,
                                   # 3.6 s each (docs/cones.md, "Noisy scans")
QUANTILE_STRIDE = 8                # long rows: the tails' thresholds from every 8th value
QUANTILE_STRIDE_MIN = 256          # ... of rows of at least 8 * 256 values (``_tails``)
VERIFY = 3                         # screened candidates (moves, greedy look-ahead) scored exactly
MOVE_RADIUS = 2                    # cone moves: each cone tries the vertices within this many edges
MOVE_SWEEPS = 16                   # ... in passes until none moves (then one pass a ring wider), at most
MOVE_OPENING = 2                   # ... and a second descent opened by this many passes a ring wider
CORRECTIONS = 1                    # fixed-point steps of the angles for the exact metric's log scale
                                   # (a second step realised the first's ratio to 0.0005 on 13 rows)
CORNER_MARGIN = 0.15              # a cone's corners are kept this far below pi (rad): kappa_floor
WEDGE_MAX = 2 * np.pi - 0.2        # a wedge of the cut disk above this gets split by another branch
SPARSE_LAMBDA = 0.1                # the L2 start's penalty weight (times 1/n; sparse_curvature)
SPARSE_ITERS = 15                  # reweighting rounds of the L2 start
TOP_UPS = 2                        # automatic mode: re-placements with a raised estimate when the
TOP_UP_MARGIN = 0.02               # layout misses the target (``cone_unwrap``)
ALT_MARGIN = 0.02                  # another placement is laid out when its estimate beats the realised
                                   # ratio of the best clean layout by this much
POLYHEDRAL_DEFECT = 1e-3           # an interior vertex with a larger angle defect (rad) is a corner
                                   # of a polyhedral mesh (``polyhedral_cones``)
SKIP_MARGIN = 0.02                 # an angle candidate whose estimate is this far below the realised
                                   # ratio of the best clean layout is not laid out (realised ratios
                                   # stayed within +0.012 of their estimates on every corpus row)
COLUMN_BYTES = 512 << 20            # the Green's columns kept at most (bytes; ``ConeSystem.columns``)
GRAM_VERTICES = 1024               # vertices in the table of their columns' products (``ConeSystem.gram``)
SPARSE_POOL = 3                    # the L2 start places SPARSE_POOL times the cones, then thins them


@dataclass
class ConeResult:
    """``uv`` (m,3,2) float64 UV of every corner of the input triangles (mesh units, UV area = 3D
    area); ``seams`` (k,2) int64 the cut's edges as vertex pairs of the input; ``cones`` (c,) int64
    cone vertices of the input; ``kappa`` (c,) float64 their curvature in radians (the flattened
    angle is ``2*pi - kappa``); ``u`` (n,) float64 log scale per input vertex from the cone solve
    (NaN on vertices in no face); ``report`` dict of measures, seam length, timings (seconds) and
    ``warnings`` (list of str, empty when the result meets its targets)."""
    uv: np.ndarray
    seams: np.ndarray
    cones: np.ndarray
    kappa: np.ndarray
    u: np.ndarray
    report: dict = field(default_factory=dict)


# ------------------------------------------------------------------------------------------------
# the cone system: u as an affine function of the cone curvatures
# ------------------------------------------------------------------------------------------------
class ConeSystem:
    """The factorised Yamabe system of one connected manifold mesh ``V`` (n,3), ``F`` (m,3).

    Closed: ``L u = kappa - Omega`` grounded at vertex ``ground`` (u there is 0), valid when ``sum
    kappa = 2*pi*chi`` (``needs_sum``). With boundary: ``u_B = 0`` on every boundary vertex, ``Omega``
    is the interior angle defect, ``kappa`` is free. Attributes: ``L``, ``Omega`` (n,), ``A`` (m,)
    areas, ``chi``, ``u0`` (n,) the solution without cones, ``eligible`` (n,) bool vertices that may
    become cones (interior vertices)."""

    def __init__(self, V, F, ground=0, intrinsic=True):
        self.V, self.F = V, F
        n = self.n = len(V)
        self.intrinsic = None
        # zero-area triangles (three different vertices in a line) get a valid intrinsic metric by
        # mollification and are left out of every measure (docs/robustness.md)
        self.degenerate = degenerate_faces(V, F)
        self.anisotropy = shape_anisotropy(V, F)         # (m,) how thin each triangle is (1: equilateral)
        if intrinsic or self.degenerate.any():
            # the intrinsic Delaunay Laplacian (nonnegative interior weights: no spikes of u next to
            # needle triangles); Omega does not change under intrinsic flips (docs/robustness.md)
            T = intrinsic_delaunay(V, F, mollify_delta=MOLLIFY if self.degenerate.any() else 0.0)
            self.L = T.cotan_laplacian().tocsr()
            self.intrinsic = T
        else:
            self.L = cotan_laplacian(V, F)
        self.A = face_areas(V, F)
        loops = topology.boundary_loops(F, n)
        self.loops = loops
        self.chi = topology.euler_characteristic(F)
        bnd = np.zeros(n, bool)
        for lp in loops:
            bnd[lp] = True
        self.boundary = bnd
        self.Omega = np.where(bnd, 0.0, 2 * np.pi - angle_sums(V, F))
        self.needs_sum = not loops
        fixed = bnd.copy() if loops else np.eye(1, n, int(ground), dtype=bool)[0]
        self.free = np.nonzero(~fixed)[0]
        # big meshes: CHOLMOD (its solves take half of SuperLU's time: one per Green's column and per
        # conjugate gradient step of the exact layout; docs/cones.md, "Speed")
        self._fac = Factor(self.L[self.free][:, self.free], method='cholmod' if n > BIG_MESH else None)
        self.eligible = ~bnd
        self.bounds = L2_BOUNDS        # curvature bounds of l2_angles (set by place_cones)
        self.total = 2 * np.pi * self.chi if self.needs_sum else None
        self._cols = {}                # vertex -> its row in self._Gt (the Green's columns solved so far)
        self._Gt = np.empty((0, n))
        self._last = (None, None)      # the last ``columns`` request and its answer (half repeat it)
        self._gram_pos = None          # vertex -> its row in the table of products (``gram``)
        self.u0 = self.solve(-self.Omega)
        # per-vertex area (a third of the incident triangles), for area-weighted statistics
        self.vertex_area = np.bincount(F.ravel(), np.repeat(self.A / 3, 3), minlength=n)
        self._w = self.vertex_area / self.vertex_area.sum()
        # a negative cone widens its corners by about (2*pi - kappa) / (angle sum): an obtuse corner
        # (a needle's) at a cone must stay below pi - CORNER_MARGIN, or the input triangle comes out
        # reflex and flips (cheburashka). Lower bound per vertex on kappa, (n,) radians.
        from ..mesh.geometry import corner_angles
        theta_max = np.zeros(n)
        np.maximum.at(theta_max, F.ravel(), corner_angles(V, F).ravel())
        with np.errstate(divide='ignore', invalid='ignore'):
            floor = 2 * np.pi - (2 * np.pi - self.Omega) * (np.pi - CORNER_MARGIN) / theta_max
        self.kappa_floor = np.where(np.isfinite(floor), floor, -np.inf)

    def solve(self, b):
        """Grounded solve: x (n,) or (n,r) with ``(L x)_free = b_free`` and x = 0 on the fixed set."""
        x = np.zeros(np.shape(b))
        x[self.free] = self._fac.solve(np.asarray(b)[self.free])
        return x

    def columns(self, S):
        """(n,k) Green's columns ``G[:, S]`` (the response of u to unit curvature at each cone).

        Every column is solved once and kept as a row of one (capacity, n) array (``_cols`` maps a
        vertex to its row there: a column is contiguous, so gathering any k of them reads k blocks
        instead of k scattered values in each of n rows, half the time of the gather from an (n,
        capacity) store); the result is a C-ordered (n,k) copy (the products with it round exactly
        as with the columns stacked, so the results do not change). Callers must not write into
        the result. A request for the same cones as the last one gets the same array back (the
        placement asks for ``u_of`` and the angles of one set in turn)."""
        S = [int(s) for s in S]
        if tuple(S) == self._last[0]:
            return self._last[1]
        self._solve_columns(S)
        if not S:
            return np.zeros((self.n, 0))
        idx = [self._cols[s] for s in S]
        rows = self._Gt[:len(idx)] if idx == list(range(len(idx))) else self._Gt[idx]
        G = np.ascontiguousarray(rows.T)
        self._last = (tuple(S), G)
        return G

    def _solve_columns(self, S):
        """Solve and store the Green's columns of the vertices ``S`` (list of int) not stored yet;
        afterwards every one of ``S`` has its row ``self._cols[s]`` in ``self._Gt``."""
        new = list(dict.fromkeys(s for s in S if s not in self._cols))
        if new:
            B = np.zeros((self.n, len(new)))
            B[new, np.arange(len(new))] = 1.0
            X = self.solve(B)
            limit = max(COLUMN_BYTES // (8 * self.n), 2 * len(S))
            if len(self._cols) + len(new) > limit:
                # the store is full: keep only this request's columns (the others are solved again if
                # asked for; a fine mesh's cone moves ask for thousands, each used once)
                keep = list(dict.fromkeys(s for s in S if s in self._cols))
                Gt = np.empty((min(limit, max(2 * (len(keep) + len(new)), 8)), self.n))
                Gt[:len(keep)] = self._Gt[[self._cols[s] for s in keep]]
                self._Gt, self._cols = Gt, {s: j for j, s in enumerate(keep)}
            k0 = len(self._cols)
            if k0 + len(new) > self._Gt.shape[0]:             # grow the store (doubling, up to the limit)
                Gt = np.empty((max(min(2 * self._Gt.shape[0], limit), k0 + len(new), 8), self.n))
                Gt[:k0] = self._Gt[:k0]
                self._Gt = Gt
            self._Gt[k0:k0 + len(new)] = X.T
            for j, s in enumerate(new):
                self._cols[s] = k0 + j

    def rows(self, S):
        """(k,n) the Green's columns of the vertices ``S`` as rows (a gather of the store's rows: no
        transposed copy, unlike ``columns``)."""
        S = [int(s) for s in S]
        self._solve_columns(S)
        return self._Gt[[self._cols[s] for s in S]]

    def gram(self, S):
        """The area-weighted products of the cones' Green's columns ``g_s`` (``columns``): ``(M (k,k),
        m (k,), b (k,))`` with ``M[i, j] = sum_v w_v g_i(v) g_j(v)``, ``m[i] = sum_v w_v g_i(v)`` and
        ``b[i] = sum_v w_v g_i(v) u0(v)``, ``w`` the vertex areas normalised to sum 1. Each product is
        computed once and kept per vertex and per pair of vertices (a cone move changes one column:
        k new products, not k^2 over all n vertices), in a table of at most ``GRAM_VERTICES``
        vertices that starts again when full."""
        S = [int(s) for s in S]
        k = len(S)
        pos = self._gram_pos
        if pos is None or len(set(S) - pos.keys()) + len(pos) > GRAM_VERTICES:     # (start again)
            cap = max(GRAM_VERTICES, k)
            self._gram_pos = {}
            self._gram_M = np.full((cap, cap), np.nan)
            self._gram_m, self._gram_b = np.empty(cap), np.empty(cap)
        pos = self._gram_pos
        new = [s for s in dict.fromkeys(S) if s not in pos]
        self._solve_columns(S)
        if new:
            rows = self._Gt[[self._cols[s] for s in new]]           # (r, n)
            j0 = len(pos)
            self._gram_m[j0:j0 + len(new)] = rows @ self._w
            self._gram_b[j0:j0 + len(new)] = rows @ (self._w * self.u0)
            for j, s in enumerate(new):
                pos[s] = j0 + j
        idx = np.array([pos[s] for s in S], np.int64)
        M = self._gram_M[np.ix_(idx, idx)]
        miss = np.isnan(M)
        if miss.any():
            # the missing products, the cone that lacks most first (a moved cone: its row and column
            # at once), each against the cones it lacks
            while miss.any():
                i = int(np.argmax(miss.sum(1)))
                js = np.nonzero(miss[i])[0]
                gi = self._Gt[self._cols[S[i]]] * self._w
                vals = self._Gt[[self._cols[S[j]] for j in js.tolist()]] @ gi
                self._gram_M[idx[i], idx[js]] = vals
                self._gram_M[idx[js], idx[i]] = vals
                miss[i, js] = miss[js, i] = False
            M = self._gram_M[np.ix_(idx, idx)]
        return M, self._gram_m[idx], self._gram_b[idx]

    def u_of(self, S, kappa):
        """Log scale u (n,) with curvature ``kappa`` (k,) at cones ``S`` (k,)."""
        return self.u0 + self.columns(S) @ np.asarray(kappa, np.float64)

    def dirichlet_angles(self, S):
        """BFF's cone angles (L2 flavour): ``u`` equal on every cone (0 with a boundary), sum rule on a
        closed surface. Returns kappa (k,)."""
        S = np.asarray(S, np.int64)
        k = len(S)
        G = self.columns(S)[S]
        if self.needs_sum:
            M = np.zeros((k + 1, k + 1))
            M[:k, :k] = G
            M[:k, k] = -1.0
            M[k, :k] = 1.0
            rhs = np.r_[-self.u0[S], self.total]
            return np.linalg.lstsq(M, rhs, rcond=None)[0][:k]
        return np.linalg.lstsq(G, -self.u0[S], rcond=None)[0]

    def l2_angles(self, S, lower=None, upper=None, shift=None):
        """Cone curvatures kappa (k,) minimising the area-weighted spread ``sum_i a_i (u_i - c)^2``
        of the log scale over all vertices (``a_i`` a third of the incident triangles' area, ``c``
        free), subject to the sum rule on a closed surface and ``lower <= kappa <= upper``
        (default ``self.bounds``: ``L2_BOUNDS`` or ``WIDE_BOUNDS``); ``shift`` (n,) optional, added to
        ``u`` (the exact metric's correction,
        see ``cone_unwrap``): a bounded least-squares problem in k+1 unknowns built from the
        cones' Green's columns. Cheap, and on spot, rocker-arm and cheburashka a better start for the
        per-triangle 1%/99% spread than BFF's rule or the L-inf angles (docs/cones.md)."""
        from scipy.optimize import lsq_linear
        S = np.asarray(S, np.int64)
        k = len(S)
        if k == 0:
            return np.zeros(0)
        lo = np.maximum(self.bounds[0] if lower is None else lower, self.kappa_floor[S])
        hi = np.maximum(self.bounds[1] if upper is None else upper, lo)
        # u - c = u0 + A [kappa; c] with A = [G, -1]: M = A^T W A and g = A^T W (u0 + shift) from the
        # columns' cached products (``gram``)
        w = self._w
        Mg, mg, bg = self.gram(S)
        M = np.empty((k + 1, k + 1))
        M[:k, :k] = Mg
        M[:k, k] = M[k, :k] = -mg
        M[k, k] = w.sum()
        u = self.u0 if shift is None else self.u0 + shift
        g = np.r_[bg, -(w @ u)]
        if shift is not None:
            g[:k] += self._Gt[[self._cols[s] for s in S.tolist()]] @ (w * shift)
        # ||W^1/2 (u0 + A x)||^2 = ||R x + R^-T g||^2 + const with M = R^T R (eigen square root:
        # M is only semidefinite without cones that move u)
        ev, Q = np.linalg.eigh(M)
        ev = np.maximum(ev, 1e-14 * max(ev.max(), 1e-300))
        R = (Q * np.sqrt(ev)).T
        b = -(Q.T @ g) / np.sqrt(ev)
        if self.needs_sum:
            big = 1e3 * np.sqrt(ev.max())
            R = np.r_[R, big * np.r_[np.ones(k), 0.0][None]]
            b = np.r_[b, big * self.total]
        bl = np.r_[np.broadcast_to(lo, (k,)), -np.inf]
        bu = np.r_[np.broadcast_to(hi, (k,)), np.inf]
        if self.needs_sum and bu[:k].sum() < self.total:
            bu[:k] = np.maximum(bu[:k], self.total / k + 1e-9)
        if self.needs_sum and bl[:k].sum() > self.total:
            bl[:k] = np.minimum(bl[:k], self.total / k - 1e-9)
        x = lsq_linear(R, b, bounds=(bl, bu), method='bvls').x
        kap = x[:k]
        if self.needs_sum:
            kap = kap + (self.total - kap.sum()) / k                # the sum rule to round-off
        return kap

    def rings(self, S, depth=1):
        """(n,) bool: the vertices within ``depth`` edges of the cones ``S``."""
        mark = np.zeros(self.n, bool)
        mark[np.asarray(S, np.int64)] = True
        if not hasattr(self, '_adj'):
            self._adj = topology.vertex_adjacency(self.F, self.n).tocsr()
        for _ in range(depth):
            mark = mark | (self._adj @ mark.astype(np.int8) > 0)
        return mark

    def linf_angles(self, S, rows=None, kappa0=None, batch=200, max_rounds=30, lower=None):
        """Cone curvatures kappa (k,) minimising ``max u - min u`` over the vertices ``rows`` ((n,)
        bool; default: all but the cones' one-rings), subject to the sum rule (closed) and
        ``lower <= kappa <= KAPPA_MAX`` (``lower`` (k,) or None: ``KAPPA_MIN``). A linear program in
        k+2 unknowns solved by HiGHS with an active set of rows. Returns (kappa, range) or
        (None, inf) if infeasible."""
        S = np.asarray(S, np.int64)
        k = len(S)
        if self.needs_sum and k * KAPPA_MAX < self.total - 1e-9:
            return None, np.inf
        lower = np.full(k, KAPPA_MIN) if lower is None else np.asarray(lower, np.float64)
        lower = np.minimum(np.maximum(lower, self.kappa_floor[S]), KAPPA_MAX)
        if rows is None:
            rows = ~self.rings(S, 1)
        idx = np.nonzero(rows)[0]
        G = self.columns(S)[idx]
        u0 = self.u0[idx]
        if kappa0 is None:
            kappa0 = self.dirichlet_angles(S) if k else np.zeros(0)
            kappa0 = np.clip(kappa0, lower, KAPPA_MAX)
        u = u0 + G @ kappa0
        order = np.argsort(u)
        active = np.zeros(len(idx), bool)
        active[order[:batch]] = True
        active[order[-batch:]] = True
        c = np.r_[np.zeros(k), -1.0, 1.0]                 # minimise hi - lo
        bounds = [(float(a), KAPPA_MAX) for a in lower] + [(None, None), (None, None)]
        A_eq = b_eq = None
        if self.needs_sum:
            A_eq = np.r_[np.ones(k), 0.0, 0.0][None]
            b_eq = [self.total]
        kappa, span = None, np.inf
        for _ in range(max_rounds):
            a = np.nonzero(active)[0]
            Ga = G[a]
            A_ub = np.block([[Ga, np.zeros((len(a), 1)), -np.ones((len(a), 1))],
                             [-Ga, np.ones((len(a), 1)), np.zeros((len(a), 1))]])
            b_ub = np.r_[-u0[a], u0[a]]
            res = linprog(c, A_ub=A_ub, b_ub=b_ub, A_eq=A_eq, b_eq=b_eq, bounds=bounds, method='highs')
            if res.status != 0:
                return None, np.inf
            kappa, lo, hi = res.x[:k], res.x[k], res.x[k + 1]
            u = u0 + G @ kappa
            span = float(u.max() - u.min())
            tol = 1e-9 * max(1.0, span)
            viol = (u > hi + tol) | (u < lo - tol)
            viol &= ~active
            if not viol.any():
                break
            worst = np.argsort(-np.maximum(u - hi, lo - u) * viol)[:batch]
            active[worst[viol[worst]]] = True
        return kappa, span

    def trimmed_angles(self, S, trim=0.01, rounds=3, depth=0, lower=None):
        """L-inf angles that ignore the tails: ``linf_angles`` re-solved ``rounds`` times, each time
        without the vertices holding the top and bottom ``trim / 2`` of the area (the per-triangle
        1%/99% spread is what counts, not the few triangles at the cones), and without the cones'
        ``depth``-rings (0: the cones only; wider rings let their u spike, which folds the layout next
        to strong cones on cheburashka). ``lower``: per-cone lower bounds, as in ``linf_angles``.
        Returns (kappa, spread) with the best ``face_spread`` seen, or (None, 0) if infeasible."""
        rows = ~self.rings(S, depth)
        best = (None, 0.0)
        for _ in range(rounds):
            kap, _ = self.linf_angles(S, rows, lower=lower)
            if kap is None:
                break
            u = self.u_of(S, kap)
            sp_ = face_spread(self.F, self.A, u)
            if sp_ > best[1]:
                best = (kap, sp_)
            order = np.argsort(u)
            c = np.cumsum(self.vertex_area[order]) / self.vertex_area.sum()
            drop = order[(c < trim / 2) | (c > 1 - trim / 2)]
            if not rows[drop].any():
                break
            rows[drop] = False
        return best


def face_spread(F, A, u, q=1.0):
    """The vertex-level estimate of the realised ``p1/p99`` (q = 1) from the log scale ``u`` (n,): the
    q% / (100-q)% spread ``exp(p_q - p_{100-q})`` of the per-triangle log scale (mean of the corners'
    u), the worse of its two readings: area-weighted (weights ``A`` (m,)) and per triangle (every
    triangle counts once, DESIGN section 3). Why both: where the triangles are finer than average
    (spot's face, cheburashka's ears) the area-weighted tails hide the triangles that hold the
    extremes of the scale, and a placement scored by area alone left the per-triangle reading 0.05 to
    0.1 below it (docs/cones.md, "Both readings of p1/p99")."""
    return float(_batch_spread(F, A, u[:, None], q)[0])


def _weighted_quantiles(X, weights, q):
    """The weighted ``q`` and ``1 - q`` quantiles of every row of ``X`` (c,m), for each of the
    nonnegative weight vectors ``weights`` (sequence of (m,)): a list of (lo, hi), (c,) each, lo the
    first value in increasing order whose cumulative weight reaches ``q`` of the total, hi the first
    reaching ``1 - q``. (Rows: each sample's values are contiguous, which the selection and the
    gathers below read along; the numbers are those of the same computation down columns.)

    Only the two tails are sorted, once for all the weightings (``face_spread`` runs once per greedy
    cone on big meshes, ``_batch_spread`` on every screened candidate: the full sort took a quarter of
    a one-click unwrap on small meshes, cheburashka 11 of 40 s). Each tail holds the values beyond a
    threshold per row, taken at about ``k`` values from the end: from every ``QUANTILE_STRIDE``-th
    value of a long row (a partition of an eighth of it: the partition of the whole row was a fifth
    of a placement), else by ``np.argpartition``. ``k`` is doubled until each tail holds more than
    ``q`` of every weighting's total; a tail that would need more than half of the values falls back
    to the full sort. The tails are sorted and summed from their ends, so the numbers are those of
    the full sort (``test_fast_paths_equal_the_plain_computations``)."""
    nrow, m = X.shape
    rows = np.arange(nrow)
    totals = [float(w.sum()) for w in weights]
    padded = [np.r_[w, 0.0] for w in weights]           # index m: the padding of a short tail
    k = min(m, int(2 * q * m) + 32)
    while 2 * k <= m:
        tails = _tails(X, k)
        if all((w[t].sum(1) > q * tot * (1 + 1e-9)).all() for t in tails for w, tot in zip(padded, totals)):
            o_lo, o_hi = tails
            out = []
            for w, t in zip(padded, totals):
                j = (np.cumsum(w[o_lo], axis=1) < q * t).sum(1)       # the first reaching q of the weight
                j1 = (np.cumsum(w[o_hi], axis=1) <= q * t).sum(1)     # from the top: 1 - q reached
                out.append((X[rows, o_lo[rows, j]], X[rows, o_hi[rows, j1]]))
            return out
        k *= 2
    order = np.argsort(X, axis=1)
    out = []
    for w in weights:
        c = np.cumsum(w[order], axis=1)
        c /= c[:, -1:]
        out.append((X[rows, order[rows, (c < q).sum(1).clip(0, m - 1)]],
                    X[rows, order[rows, (c < 1 - q).sum(1).clip(0, m - 1)]]))
    return out


def _tails(X, k):
    """The low and the high tail of every row of ``X`` (c,m), at least about ``k`` values each: index
    arrays (c, t) into the row, the low tail in increasing order of value, the high one in decreasing
    order, padded at the end with ``m``."""
    nrow, m = X.shape
    if m < QUANTILE_STRIDE * QUANTILE_STRIDE_MIN:
        part = np.argpartition(X, (k - 1, m - k), axis=1)
        lo_i, hi_i = part[:, :k], part[:, m - k:]
        return (np.take_along_axis(lo_i, np.argsort(np.take_along_axis(X, lo_i, 1), axis=1), 1),
                np.take_along_axis(hi_i, np.argsort(-np.take_along_axis(X, hi_i, 1), axis=1), 1))
    sub = X[:, ::QUANTILE_STRIDE]
    ks = max(k // QUANTILE_STRIDE, 1)
    ms = sub.shape[1]
    part = np.partition(sub, (ks - 1, ms - ks), axis=1)
    lo_t, hi_t = part[:, ks - 1:ks], part[:, ms - ks:ms - ks + 1]
    r, c = np.nonzero((X <= lo_t) | (X >= hi_t))        # both tails in one pass
    v = X[r, c]
    out = []
    for side in (v <= lo_t[r, 0], v >= hi_t[r, 0]):
        rs, cs = r[side], c[side]
        cnt = np.bincount(rs, minlength=nrow)
        pos = np.arange(len(rs)) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        idx = np.full((nrow, int(cnt.max(initial=1))), m)
        idx[rs, pos] = cs
        key = np.full(idx.shape, np.inf)
        key[rs, pos] = v[side] if not out else -v[side]
        out.append(np.take_along_axis(idx, np.argsort(key, axis=1), 1))
    return out


def weighted_spread(x, w, q=1.0):
    """Weighted ``q``% / ``(100-q)``% percentile ratio of positive per-triangle values ``x`` (m,) with
    weights ``w`` (m,) (e.g. the realised scale ``mu`` and the 3D areas: the area-weighted reading of
    'p1/p99' in docs/cones.md). NaN entries are ignored."""
    ok = np.isfinite(x) & (x > 0)
    [(lo, hi)] = _weighted_quantiles(np.log(x[ok])[None], [w[ok]], q / 100)
    return float(np.exp(lo[0] - hi[0]))


def realised_spread(measured):
    """The worse of a layout's two readings of its realised p1/p99 (``measured`` or a report dict:
    'mu_ratio_p1_p99' per triangle, 'mu_ratio_p1_p99_area' area-weighted): the figure ``face_spread``
    estimates, by which layouts are ranked and targets checked."""
    return min(measured['mu_ratio_p1_p99'], measured.get('mu_ratio_p1_p99_area', np.inf))


def _score(system, S):
    """(spread, kappa): the 1%/99% spread of the per-triangle scale with the area-L2 angles
    (``ConeSystem.l2_angles``) on cones ``S``."""
    kap = system.l2_angles(S)
    return face_spread(system.F, system.A, system.u_of(S, kap)), kap


def _greedy(system, target_ratio, max_cones, candidates, report):
    """Greedy cone placement. ``candidates`` > 0: the look-ahead rule (the ``candidates`` most extreme
    vertices of ``u``, half at each end, are scored by ``_score`` and the best is kept); 0: BFF's rule
    (the vertex of largest ``|u - u_cone|`` with BFF's angles, u equal at the cones). Returns (cones
    list, history list of (count, spread))."""
    S = []
    w = system.vertex_area / system.vertex_area.sum()
    if system.needs_sum:
        u = system.solve(system.total * w - system.Omega)
    else:
        u = system.u0.copy()
    history = [(0, face_spread(system.F, system.A, u))]
    best = history[-1][1]
    min_cones = 3 if system.needs_sum and system.chi > 0 else 0
    half = max(1, candidates // 2)
    kap = np.zeros(0)
    while len(S) < max_cones:
        if target_ratio is not None and best >= target_ratio and len(S) >= min_cones:
            break
        report(0.35 * len(S) / max(1, max_cones), f"placing cone {len(S) + 1}")
        ok = system.eligible.copy()
        if S:
            ok &= ~system.rings(S, 1)
            if not ok.any():
                # a coarse mesh whose cones' one-rings cover it (a 12-triangle cube: two opposite
                # corners) may still need more cones: then a neighbour of a cone may be one too
                ok = system.eligible.copy()
                ok[S] = False
        idx = np.nonzero(ok)[0]
        if not len(idx):
            break
        if candidates:
            order = idx[np.argsort(u[idx] - (w * u).sum())]
            cand = np.unique(np.r_[order[:half], order[-half:]])
            # screened in one batch (``_screen``), the best few scored exactly
            approx = _screen(system, S, kap, cand)
            trial = None
            for v in cand[np.argsort(-approx)[:VERIFY]].tolist():
                sc, kk = _score(system, S + [v])
                if trial is None or sc > trial[0]:
                    trial = (sc, v, kk)
            best, v, kap = trial
            S.append(v)
        else:
            ref = u[S[0]] if S else np.median(u[system.eligible])
            S.append(int(idx[np.argmax(np.abs(u[idx] - ref))]))
            kap = system.dirichlet_angles(S)
            u = system.u_of(S, kap)
            best = face_spread(system.F, system.A, u)
            history.append((len(S), best))
            continue
        u = system.u_of(S, kap)
        history.append((len(S), best))
    return S, history


def _batch_spread(F, A, U, q=1.0):
    """``face_spread`` of every column of ``U`` (n,c) at once (the worse of the area-weighted and the
    per-triangle spreads). Returns (c,)."""
    return _batch_spread_rows(F, A, np.ascontiguousarray(U.T), q)


def _batch_spread_rows(F, A, Ut, q=1.0):
    """``_batch_spread`` of the rows of ``Ut`` (c,n), C-ordered (the face means are gathered row by row)."""
    # = face_means(U, F).T, to the bit: the corners summed in place in the same order (no temporaries)
    M = np.take(Ut, F[:, 0], axis=1)
    M += np.take(Ut, F[:, 1], axis=1)
    M += np.take(Ut, F[:, 2], axis=1)
    M /= 3.0
    (lo, hi), (lo1, hi1) = _weighted_quantiles(M, (A, np.ones(len(F))), q / 100)
    return np.exp(np.minimum(lo - hi, lo1 - hi1))


def bordered_solve(A0, B, d, r0, r):
    """Solve, for each column ``c`` of ``B``, the symmetric system ``[[A0, b], [b^T, d_c]] [y; z] =
    [r0; r_c]`` with ``b = B[:, c]``: one factorisation of the common block ``A0`` (p,p) for all the
    bordered systems (block elimination: ``z = (r_c - b.A0^-1 r0) / (d_c - b.A0^-1 b)``, ``y = A0^-1
    (r0 - b z)``) instead of one of each (p+1, p+1) system. B (p,c), d (c,), r0 (p,), r (c,). Every
    system's diagonal gets ``1e-12`` times the largest entry of all of them (the regularisation the
    stacked systems had). Returns (y (c,p), z (c,)), or None if a system is singular. A common block
    too ill-conditioned for the elimination (a closed surface's first cone: only the constant and
    the multiplier) is solved system by system, as a stack."""
    p, c = B.shape
    eps = 1e-12 * max(np.abs(A0).max(initial=0.0), np.abs(B).max(initial=0.0), np.abs(d).max(initial=0.0))
    A = A0 + eps * np.eye(p)
    dd = d + eps
    if p and np.linalg.cond(A) < 1e8:
        Y = np.linalg.solve(A, np.c_[r0, B])
        y0, Z = Y[:, 0], Y[:, 1:]
        s = dd - np.einsum('pc,pc->c', B, Z)           # the Schur complements
        if (np.abs(s) > 1e-8 * np.abs(dd)).all():
            z = (r - B.T @ y0) / s
            return (y0[None] - (Z * z).T), z
    K = np.zeros((c, p + 1, p + 1))
    K[:, :p, :p] = A
    K[:, :p, p] = K[:, p, :p] = B.T
    K[:, p, p] = dd
    rhs = np.c_[np.broadcast_to(r0, (c, p)), r]
    try:
        x = np.linalg.solve(K, rhs[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return None
    return x[:, :p], x[:, p]


def pinned_solves(K, rhs, k):
    """The solutions (k, p) of the symmetric system ``K x = rhs`` (K (p,p), rhs (p,)) with, in turn,
    each of the first ``k`` unknowns held at 0 (its row and column replaced by the identity's), every
    diagonal regularised by ``1e-12`` times the largest entry. One inverse serves all of them: with
    ``x = K^-1 rhs``, holding unknown ``i`` gives ``x - K^-1[:, i] x_i / K^-1[i, i]``. A ``K`` too
    ill-conditioned for that is solved system by system. Returns None if a system is singular."""
    p = len(rhs)
    eps = 1e-12 * max(np.abs(K).max(), 1.0)
    Kr = K + eps * np.eye(p)
    if np.linalg.cond(Kr) < 1e8:
        Ki = np.linalg.inv(Kr)
        x = Ki @ rhs
        piv = np.diag(Ki)[:k]
        if (np.abs(piv) > 1e-8 * np.abs(Ki).max()).all():
            X = x[None] - (Ki[:, :k] * (x[:k] / piv)).T
            X[np.arange(k), np.arange(k)] = 0.0
            return X
    i = np.arange(k)
    Ks = np.repeat(Kr[None], k, axis=0)
    Ks[i, i, :] = 0.0
    Ks[i, :, i] = 0.0
    Ks[i, i, i] = 1.0 + eps
    R = np.repeat(rhs[None], k, axis=0)
    R[i, i] = 0.0
    try:
        return np.linalg.solve(Ks, R[..., None])[..., 0]
    except np.linalg.LinAlgError:
        return None


def _screen_moves(system, S, kap, i, cand):
    """Approximate spread (c,) of moving cone ``S[i]`` to each vertex of ``cand`` (c,) (``_screen``
    with the other cones and their angles)."""
    return _screen(system, S[:i] + S[i + 1:], np.delete(np.asarray(kap, np.float64), i), cand)


def _screen(system, others, ko, cand):
    """Approximate spread (c,) of adding a cone at each vertex of ``cand`` (c,) to the cones
    ``others`` (list) with angles ``ko`` (k,): the area-L2 angles re-solved in one batch with the
    cones now at a bound held there (the active set of ``ko``) and the new cone's angle then clipped
    to its bounds; one KKT system of size about k per candidate, all bordering one common block
    (``bordered_solve``). Exact when no bound is active. ``_score`` checks the best few. The
    columns are read as the store's rows (``ConeSystem.rows``), so the candidates' log scales come
    out row by row, as ``_batch_spread_rows`` reads them."""
    n = system.n
    w = system._w
    others = np.asarray(others, np.int64)
    ko = np.asarray(ko, np.float64)
    blo, bhi = system.bounds
    lo_o = np.maximum(blo, system.kappa_floor[others])
    at_bound = (np.abs(ko - lo_o) < 1e-7) | (np.abs(ko - bhi) < 1e-7)
    R = system.rows(others) if len(others) else np.zeros((0, n))       # (k, n)
    r0 = system.u0 + ko[at_bound] @ R[at_bound]
    Rf = R[~at_bound]                                                  # (f, n): the free angles
    C = system.rows(cand)                                              # (c, n) the candidates' columns
    WC = C * w
    f1 = len(Rf) + 1                                                   # the free angles, the constant
    # P = [G_free, -1] (n, f+1): P^T W P from the cached products, P^T W g and P^T W r0 from the rows
    PtWP = np.empty((f1, f1))
    if len(Rf):
        Mg, mg, _ = system.gram(others[~at_bound])
        PtWP[:-1, :-1] = Mg
        PtWP[:-1, -1] = PtWP[-1, :-1] = -mg
    PtWP[-1, -1] = w.sum()
    PtWG = np.r_[Rf @ WC.T, -WC.sum(1)[None]]                           # (f+1, c)
    gWg = np.einsum('cn,cn->c', C, WC)
    wr = w * r0
    PtWr = np.r_[Rf @ wr, -wr.sum()]
    gWr = C @ wr
    # the KKT system of each candidate: the block of the others' free angles, the constant and (closed)
    # the sum rule's multiplier, common to all, bordered by the candidate's own row
    A0 = np.zeros((f1 + 1, f1 + 1)) if system.needs_sum else PtWP
    r0_c = -PtWr
    if system.needs_sum:
        A0[:f1, :f1] = PtWP
        A0[:f1 - 1, f1] = A0[f1, :f1 - 1] = 1.0
        r0_c = np.r_[-PtWr, system.total - ko[at_bound].sum()]
    B = PtWG if not system.needs_sum else np.r_[PtWG, np.ones((1, len(cand)))]
    x = bordered_solve(A0, B, gWg, r0_c, -gWr)
    if x is None:
        return np.zeros(len(cand))
    kv = np.clip(x[1], np.maximum(blo, system.kappa_floor[cand]), bhi)
    kf = np.clip(x[0][:, :f1 - 1], lo_o[~at_bound], bhi)
    Ut = r0[None] + kf @ Rf + kv[:, None] * C                          # (c, n)
    return _batch_spread_rows(system.F, system.A, Ut)


def sparse_curvature(system, lam=SPARSE_LAMBDA, iters=SPARSE_ITERS, eps=(1.0, 1e-3)):
    """The L2 start (docs/cones.md, "Placement"): a curvature ``kappa`` (n,) on all vertices that
    keeps the area-weighted spread of ``u`` small and is nearly sparse. Minimises
    ``sum_i a_i u_i^2 + lam/n sum_i w_i kappa_i^2`` with ``kappa = L u + Omega`` (so the sum rule holds
    by construction; ``a_i`` the vertex areas normalised to sum 1, ``u_B = 0`` and no penalty on a
    boundary), reweighted ``iters`` times with ``w_i = 1/(|kappa_i| + e)^2`` (a log/L0-like penalty,
    ``e`` from ``eps[0]`` down to ``eps[1]`` geometrically): each round one sparse solve of
    ``(diag a + lam/n L W L) u = -lam/n L W Omega`` on the free vertices. Returns (u (n,), kappa (n,))."""
    import scipy.sparse as sp
    n = system.n
    a = system.vertex_area / system.vertex_area.sum()
    L = system.L.tocsr()
    free = ~system.boundary
    idx = np.nonzero(free)[0]
    w = free.astype(np.float64)
    u = np.zeros(n)
    kap = system.Omega.copy()
    for it in range(iters):
        e = eps[0] * (eps[1] / eps[0]) ** (it / max(1, iters - 1))
        LW = L.T @ sp.diags(w * lam / n)
        M = (sp.diags(a) + LW @ L).tocsr()[idx][:, idx].tocsc()
        u[idx] = Factor(M).solve(-(LW @ system.Omega)[idx])
        kap = L @ u + system.Omega
        w = np.where(free, 1.0 / (np.abs(kap) + e) ** 2, 0.0)
    return u, kap


def _peaks(system, kap, count, depth=2):
    """``count`` vertices (list) where the curvature ``kap`` (n,) concentrates: the largest
    ``|kappa|`` summed over a one-ring, then the vertex of that ring with the largest ``kappa`` of the
    same sign; each pick blocks its ``depth``-ring."""
    system.rings([0])
    ring = kap + system._adj @ kap
    ok = system.eligible.copy()
    S = []
    for _ in range(count):
        idx = np.nonzero(ok)[0]
        if not len(idx):
            break
        v = int(idx[np.argmax(np.abs(ring[idx]))])
        near = np.nonzero(system.rings([v], 1) & ok)[0]
        v = int(near[np.argmax(np.abs(kap[near]) * (np.sign(kap[near]) == np.sign(ring[v])))])
        S.append(v)
        ok &= ~system.rings([v], depth)
    return S


def _screen_removals(system, S):
    """Approximate spread (k,) of the cones ``S`` (list) without each one in turn: the area-L2 angles of
    the rest, without bounds, solved as a stack of KKT systems of size about k (the removed cone's
    angle held at 0: ``pinned_solves``). ``_score`` checks the best few."""
    n, k = system.n, len(S)
    w = system.vertex_area / system.vertex_area.sum()
    G = system.columns(S)
    P = np.c_[G, -np.ones(n)]
    M = P.T @ (w[:, None] * P)
    g = P.T @ (w * system.u0)
    size = k + 1 + (1 if system.needs_sum else 0)
    K = np.zeros((size, size))
    K[:k + 1, :k + 1] = M
    rhs = np.zeros(size)
    rhs[:k + 1] = -g
    if system.needs_sum:
        K[:k, -1] = K[-1, :k] = 1.0
        rhs[-1] = system.total
    x = pinned_solves(K, rhs, k)
    if x is None:
        return np.zeros(k)
    U = system.u0[:, None] + G @ x[:, :k].T
    return _batch_spread(system.F, system.A, U)


def eliminate(system, S, count, target_ratio=None, verify=None, report=None):
    """Backward elimination: drop cones from ``S`` (list) one at a time, the one whose removal keeps
    the best spread (screened in one batch, ``_screen_removals``; within 3 of ``count`` the
    ``verify`` best are scored exactly by ``_score``, above it only the screen's best), down to
    ``count`` cones; with ``target_ratio``, further while the spread stays at or above it. Returns
    (S list, kappa (k,), spread)."""
    S = list(S)
    verify = VERIFY if verify is None else verify
    best, kap = _score(system, S)
    start = len(S)
    while len(S) > 3:
        if len(S) <= count and target_ratio is None:
            break
        if report:
            report((start - len(S)) / max(1, start - count), "thinning the cones")
        approx = _screen_removals(system, S)
        trial = None
        # far above the count the screen alone decides (exact without active bounds)
        for i in np.argsort(-approx)[:verify if len(S) <= count + 3 else 1].tolist():
            T = S[:i] + S[i + 1:]
            sc, kk = _score(system, T)
            if trial is None or sc > trial[0]:
                trial = (sc, T, kk)
        if len(S) <= count and trial[0] < target_ratio:
            break
        best, S, kap = trial
    return S, kap, best


def move_cones(system, S, kap, best, radius=MOVE_RADIUS, sweeps=MOVE_SWEEPS, verify=None, report=None,
               both=True):
    """Local search over the k-rings of the cones (MovingCones-style moves, scored by the 1%/99%
    spread of the per-triangle scale, ``face_spread``, with the area-L2 angles re-solved): in a pass,
    for each cone in turn, every eligible vertex within k edges (not next to another cone) is
    screened at once (``_screen_moves``), the ``verify`` best are scored exactly (``_score``) and the
    cone moves to the best one if it beats ``best``. A variable-neighbourhood descent: passes at
    ``k = radius`` until no cone moves, then one pass at ``radius + 1``; if that moved a cone, back to
    ``radius``, else stop; at most ``sweeps`` passes. ``both``: two descents from the same cones,
    one of them opened by ``MOVE_OPENING`` passes at ``radius + 1``; the better is kept (the
    automatic mode and meshes over ``BIG_MESH`` vertices run the first only: time; on spot x2 and
    rocker-arm x1 the first was the better). Why: a fixed count of wider passes stops short of a
    local optimum, and which optimum a descent reaches depends on its first steps, with neither
    opening better on every mesh (the placement's estimate, narrow / wide opening: rocker-arm 18
    cones 0.628 / 0.620, cheburashka 16 0.280 / 0.343, spot 16 0.407 / 0.420; two passes at 3
    alone: 0.614, 0.330, 0.405; docs/cones.md). ``S`` list of cone ids, ``kap`` (k,) their angles,
    ``best`` their spread. Returns (S, kap, best, moves made)."""
    runs = []
    openings = (0, MOVE_OPENING) if both and sweeps > 1 else (0,)
    for j, opening in enumerate(openings):
        def step(f, msg, j=j):
            if report:
                report((j + f) / len(openings), msg)
        runs.append(_descent(system, list(S), kap, best, radius, sweeps, opening,
                             VERIFY if verify is None else verify, step))
    return max(runs, key=lambda r: r[2])


def _descent(system, S, kap, best, radius, sweeps, opening, verify, report):
    """One descent of ``move_cones``: ``opening`` passes over the ``radius + 1``-rings, then the
    passes at ``radius`` (one wider pass after each stall). Returns (S, kap, best, moves made)."""
    moves = 0
    k = radius + 1 if opening else radius
    for sweep in range(sweeps):
        moved = False
        for i in range(len(S)):
            report(1 - 0.5 ** (sweep + i / len(S)), "moving cones")   # passes: not known ahead
            others = S[:i] + S[i + 1:]
            blocked = system.rings(others, 1) if others else np.zeros(system.n, bool)
            near = system.rings([S[i]], k)
            near[S[i]] = False
            cand = np.nonzero(near & system.eligible & ~blocked)[0]
            if not len(cand):
                continue
            approx = _screen_moves(system, S, kap, i, cand)
            for j in np.argsort(-approx)[:verify]:
                T = S[:i] + [int(cand[j])] + S[i + 1:]
                sc, kk = _score(system, T)
                if sc > best + 1e-9:
                    best, kap, S, moved = sc, kk, T, True
                    moves += 1
        if sweep + 1 < opening:
            continue                        # the opening's wide passes
        if sweep + 1 == opening:
            k = radius                      # the opening ends: the narrow descent starts
        elif moved:
            k = radius
        elif k == radius:
            k = radius + 1                  # stalled: one pass over the wider rings
        else:
            break
    return S, kap, best, moves


def place_cones(system, target_ratio=0.5, max_cones=48, sweeps=MOVE_SWEEPS, progress=None, candidates=None,
                bounds=None, sparse=True):
    """Cone placement: greedy runs under each set of curvature bounds, refined by cone moves over
    k-rings (docs/cones.md, "Placement").

    1. Greedy with a look-ahead: ``candidates`` vertices are tried for the next cone, the most
       extreme of ``u`` at each end (half the highest, half the lowest, outside the cones'
       one-rings); they are screened in one batch (``_screen``) and the best ``VERIFY`` scored by the
       1%/99% spread of the per-triangle scale (``face_spread``) with the angles
       re-solved (``l2_angles``); the best is kept. And BFF's greedy (the vertex of largest
       ``|u - u_cone|``; it finds the exact corners of a cube). Each stops when the spread reaches
       ``target_ratio`` (None: never) or at ``max_cones``; the run that reaches the target with fewer
       cones, else the better spread (``_score``), is kept.
    2. Both greedy runs under each of ``bounds`` (default ``(L2_BOUNDS, WIDE_BOUNDS)``: the area-L2
       angles' curvature range; neither range wins on every mesh, so both are tried).
    3. ``sparse``: the L2 start under each of ``bounds``: ``SPARSE_POOL`` times the greedy's cone count
       placed where a nearly sparse curvature concentrates (``sparse_curvature``, ``_peaks``), thinned
       by backward elimination (``eliminate``) to that count (with a target, further while the spread
       stays at or above it).
    4. ``sweeps`` passes of cone moves (``move_cones``, ``MOVE_RADIUS``-rings): on the best greedy run
       and the best L2 start with a fixed budget (``target_ratio`` None), on the best one only
       otherwise (time).
       With a target, when the moves lift the spread ``TOP_UP_MARGIN`` past it, the cones are thinned
       by backward elimination while it stays that far above (``eliminate``) and moved once more.
    Why the area-L2 angles score the placement and not L-inf or trimmed L-inf ones: on a fixed cone
    set the area-L2 angles are within 0.01 of a direct optimisation of the 1%/99% spread, the L-inf
    ones far below it (docs/cones.md); the gap to MovingCones is where the cones are.
    ``system``: ``ConeSystem``; its ``bounds`` is left at the kept run's and ``alternates`` lists the
    other runs' (cones, kappa, bounds), the fallback of ``cone_unwrap``. ``candidates``: per greedy
    step (default 12). On meshes over ``BIG_MESH`` vertices the L2 start is not run, and with a
    target (the automatic mode: time) only BFF's greedy runs, under ``L2_BOUNDS`` (``cone_unwrap``
    gives it no moves). Returns (cones (c,), kappa (c,), history list of (count, spread))."""
    report = progress or (lambda f, msg: None)
    quick = system.n > BIG_MESH and target_ratio is not None

    def rank(S, spread):
        """The order of the runs: reaching the target first, then fewer cones (only among runs that
        reach it), then the spread."""
        hit = target_ratio is not None and spread >= target_ratio
        return hit, -len(S) if hit else 0, spread
    if candidates is None:
        candidates = 0 if quick else 12
    if bounds is None:
        bounds = (L2_BOUNDS,) if quick else (L2_BOUNDS, WIDE_BOUNDS)
    # greedy runs under each bound set; cone moves on every run with a fixed budget (target None),
    # on the best run only in the automatic mode (its time matters more: up to max_cones cones)
    results = []
    total = len(bounds) + (len(bounds) if target_ratio is None else 1)
    for b, lim in enumerate(bounds):
        system.bounds = lim
        runs = []
        for c in sorted({candidates, 0}, reverse=True):
            S, hist = _greedy(system, target_ratio, max_cones, c,
                              lambda f, msg, b=b: report((b + f) / total, msg))
            sc = _score(system, S)[0] if S else hist[-1][1]
            runs.append((rank(S, sc), S, hist))
        key, S, history = max(runs, key=lambda r: r[0])
        if not S:
            return np.zeros(0, np.int64), np.zeros(0), history
        results.append([key, list(S), _score(system, S)[1], history, lim])
    results.sort(key=lambda r: r[0], reverse=True)
    moved = results[:1]
    if sparse and system.n <= BIG_MESH:
        # the L2 start: SPARSE_POOL times the cones where a nearly sparse curvature concentrates,
        # thinned by backward elimination to the greedy's count (with a target: while it holds).
        # Automatic mode (time): twice the cones, under the best greedy run's bounds only.
        count = max_cones if target_ratio is None else len(results[0][1])
        report(0.5, "sparse start")
        _, kap_all = sparse_curvature(system)
        pool = _peaks(system, kap_all, (SPARSE_POOL if target_ratio is None else 2) * max(count, 3))
        sparse_runs = []
        for lim in (bounds if target_ratio is None else [results[0][4]]):
            system.bounds = lim
            S, kap, sc = eliminate(system, pool, count, target_ratio)
            sparse_runs.append([rank(S, sc), list(S), kap, [(len(S), sc)], lim])
        sparse_runs.sort(key=lambda r: r[0], reverse=True)
        # fixed budget: the best greedy and the best L2 start are moved; automatic: the best of all
        moved = results[:1] + sparse_runs[:1] if target_ratio is None else \
            [max(results[0], sparse_runs[0], key=lambda r: r[0])]
        results += sparse_runs
    for b, r in enumerate(moved):
        if not sweeps:
            break
        system.bounds = r[4]
        S, kap, best, _ = move_cones(system, r[1], r[2], r[0][2], radius=MOVE_RADIUS, sweeps=sweeps,
                                     report=lambda f, msg, b=b: report((len(bounds) + b + f) / total, msg),
                                     both=target_ratio is None and system.n <= BIG_MESH)
        r[3] = r[3] + [(len(S), best)]
        r[:3] = [rank(S, best), S, kap]
        if r[0][0] and best >= target_ratio + TOP_UP_MARGIN:
            # the greedy stopped at the target, and the moves lifted the spread past it (on a fine
            # mesh far past: its greedy is weak): fewer cones reach the target. Thinned while the
            # spread stays TOP_UP_MARGIN above the target, the rest moved once more.
            def step(f, msg, b=b):
                report((len(bounds) + b + f) / total, msg)
            S2, k2, b2 = eliminate(system, S, len(S), target_ratio + TOP_UP_MARGIN, report=step)
            if len(S2) < len(S):
                S2, k2, b2, _ = move_cones(system, S2, k2, b2, radius=MOVE_RADIUS, sweeps=sweeps, report=step,
                                           both=False)
                r[3] = r[3] + [(len(S2), b2)]
                r[:3] = [rank(S2, b2), list(S2), k2]
    results.sort(key=lambda r: r[0], reverse=True)
    key, S, kap, history, lim = results[0]
    system.bounds = lim
    system.alternates = [(np.array(r[1], np.int64), np.asarray(r[2], np.float64), r[4]) for r in results[1:]]
    system.alternate_scores = [r[0][2] for r in results[1:]]
    system.alternate_moved = [any(r is q for q in moved) or not sweeps for r in results[1:]]
    S, kap = np.array(S, np.int64), np.asarray(kap, np.float64)
    return S, kap, history


# ------------------------------------------------------------------------------------------------
# layout of the cut disk
# ------------------------------------------------------------------------------------------------
def _boundary_data(Vc, Fc, loop, uc, vert_of=None, Lu=None, cache=None):
    """Turning angles ``k~`` (nb,) and target lengths ``l~`` (nb,) of the cut disk's boundary ``loop``
    (edge j from loop[j] to loop[j+1]) for the log scale ``uc`` (N,) on the split vertices.

    ``k~ = k + (L u)_B`` with the cut disk's own cotan ``L`` (``_disk_laplacian``). ``Lu`` (n,): the
    closed surface's ``L u`` from the operator ``u`` was solved with (the intrinsic Delaunay
    Laplacian), with ``vert_of`` (N,) the input vertex of each split vertex: the difference to the
    cut disk's split is shared equally by the copies of each vertex, so that the copies' turning angles sum to
    ``Omega + (L u)`` of the closed operator (the cone curvature; 0 on a seam between cones) and the
    two sides of a seam stay congruent."""
    L = _disk_laplacian(Vc, Fc, cache)
    s = angle_sums(Vc, Fc)
    Luc = L @ uc
    if Lu is not None:
        n = len(Lu)
        copies = np.bincount(vert_of, minlength=n)
        resid = Lu - np.bincount(vert_of, Luc, minlength=n)
        Luc = Luc + (resid / np.maximum(copies, 1))[vert_of]
    kt = np.pi - s[loop] + Luc[loop]
    l = np.linalg.norm(Vc[np.roll(loop, -1)] - Vc[loop], axis=1)
    lt = np.exp(0.5 * (uc[loop] + uc[np.roll(loop, -1)])) * l
    return kt, lt, L


def _flip_edge(T, e):
    """Flip the interior edge ``e`` of the intrinsic triangulation ``T`` in place (faces ``t = (a, b, c)``
    and ``s = (d, c, b)`` with ``e = b-c`` become ``(a, b, d)`` and ``(d, c, a)``), if the quad
    ``a, b, d, c`` is convex in the intrinsic metric (angles at ``b`` and ``c`` below ``pi``). Returns
    whether it flipped."""
    F, FE, EF, EC, el = T.F, T.FE, T.EF, T.EC, T.edge_lengths
    t, k, s, j = int(EF[e, 0]), int(EC[e, 0]), int(EF[e, 1]), int(EC[e, 1])
    if s < 0 or t == s or F[t, k] == F[s, j]:
        return False
    nx, pv = (1, 2, 0), (2, 0, 1)
    k1, k2, j1, j2 = nx[k], pv[k], nx[j], pv[j]
    ang_t, ang_s = corner_angles_l(el[FE[t]][None])[0], corner_angles_l(el[FE[s]][None])[0]
    # b = F[t, k1] = F[s, j2], c = F[t, k2] = F[s, j1]
    if ang_t[k1] + ang_s[j2] >= np.pi - 1e-6 or ang_t[k2] + ang_s[j1] >= np.pi - 1e-6:
        return False
    l_e, l_ca, l_ab = el[e], el[FE[t, k1]], el[FE[t, k2]]
    l_bd, l_dc = el[FE[s, j1]], el[FE[s, j2]]
    At = face_areas_l(np.array([[l_e, l_ca, l_ab]]))[0]
    As = face_areas_l(np.array([[l_e, l_bd, l_dc]]))[0]
    xa, xd = (l_ab ** 2 - l_ca ** 2 + l_e ** 2) / (2 * l_e), (l_bd ** 2 - l_dc ** 2 + l_e ** 2) / (2 * l_e)
    l_new = float(np.hypot(xa - xd, 2 * At / l_e + 2 * As / l_e))
    a, d = F[t, k], F[s, j]
    e_ca, e_bd = FE[t, k1], FE[s, j1]
    side_bd = 0 if (EF[e_bd, 0] == s and EC[e_bd, 0] == j1) else 1
    side_ca = 0 if (EF[e_ca, 0] == t and EC[e_ca, 0] == k1) else 1
    F[t, k2], F[s, j2] = d, a
    FE[t, k], FE[t, k1], FE[s, j], FE[s, j1] = e_bd, e, e_ca, e
    EF[e_bd, side_bd], EC[e_bd, side_bd] = t, k
    EF[e_ca, side_ca], EC[e_ca, side_ca] = s, j
    EF[e, 0], EC[e, 0], EF[e, 1], EC[e, 1] = t, k1, s, j1
    el[e] = l_new
    T._cache.clear()                  # the cached per-face areas and gradients are for the old faces
    return True


def raise_low_degree(T):
    """Give every interior vertex of degree below 3 of the intrinsic triangulation ``T`` (in place) a
    third edge, by flipping an edge opposite it. Intrinsic Delaunay flips can leave a vertex of
    positive curvature with two triangles only (cow: a vertex of degree 3 and angle sum 3.9 rad); a
    flat metric then needs both triangles' angles there to be ``pi`` (degenerate), so Newton on the
    exact metric cannot converge and a harmonic layout puts the vertex on a segment (a squashed input
    triangle). Returns the number of flips (0 on most meshes: the vertices are found by one
    ``bincount``)."""
    deg = np.bincount(T.F.ravel(), minlength=T.n)
    onb = np.zeros(T.n, bool)
    bnd = T.EF[:, 1] < 0
    onb[T.edge_vertices()[bnd].ravel()] = True
    low = np.nonzero((deg > 0) & (deg < 3) & ~onb)[0]
    flips = 0
    for v in low:
        if np.count_nonzero(T.F == v) >= 3:      # an earlier flip gave it a third edge
            continue
        for t in np.nonzero((T.F == v).any(1))[0]:
            k = int(np.nonzero(T.F[t] == v)[0][0])
            if _flip_edge(T, int(T.FE[t, k])):
                flips += 1
                break
    if flips:
        T.report['flips'] = T.report.get('flips', 0) + flips
    return flips


def _disk_laplacian(Vc, Fc, cache=None):
    """The cut disk's Laplacian (N,N), for its boundary data and for the UVs' harmonic extension:
    the intrinsic Delaunay cotan Laplacian of the cut disk (its boundary, i.e. the cut, is never
    flipped), which has no negative interior weights, so the extension keeps the maximum principle
    next to needle triangles (docs/robustness.md). Kept in ``cache`` for the same cut disk."""
    key = (len(Vc), hash(Fc.tobytes()))
    if cache is not None and cache.get('disk_key') == key:
        return cache['disk']
    zero = degenerate_faces(Vc, Fc).any()
    T = intrinsic_delaunay(Vc, Fc, mollify_delta=MOLLIFY if zero else 0.0)
    T.report['degree_flips'] = raise_low_degree(T)
    L = T.cotan_laplacian().tocsr() if T.report['flips'] or zero else cotan_laplacian(Vc, Fc)
    if cache is not None:
        cache['disk_key'], cache['disk'], cache['disk_T'] = key, L, T
    return L


def paired_polygon(kt, lt, pair):
    """Closed boundary polygon (nb,2) with turning angles ``kt`` (nb,) (sum 2*pi) and lengths closest
    to ``lt`` (nb,): the change ``delta = P s`` is shared by the two copies of a seam edge (``pair``
    (nb,) class of each boundary edge; seam copies share a class) and minimises ``sum delta^2 / lt``
    subject to closing the polygon (docs/cones.md, "Layout"). Raises ``ConformalError`` if a length
    would become non-positive."""
    phi = np.cumsum(kt)
    T = np.stack([np.cos(phi), np.sin(phi)], axis=1)
    nc = int(pair.max()) + 1
    w = np.bincount(pair, 1.0 / lt, minlength=nc)               # W = P^T diag(1/lt) P (diagonal)
    A = np.stack([np.bincount(pair, T[:, 0], minlength=nc), np.bincount(pair, T[:, 1], minlength=nc)])
    r = T.T @ lt                                                # the gap of the unclosed polygon
    M = (A / w) @ A.T
    # M is singular where the pairs cannot move the end point (no holonomy, e.g. a torus without
    # cones); there the gap is zero up to round-off anyway
    ev, Q = np.linalg.eigh(M)
    inv = np.where(ev > 1e-10 * lt.sum(), 1.0 / np.where(ev > 0, ev, 1.0), 0.0)
    lam = Q @ (inv * (Q.T @ r))
    s = -(A.T @ lam) / w
    ls = lt + s[pair]
    if (ls <= 0).any():
        raise ConformalError("the cone scale factors are too extreme to close the cut boundary",
                             'solve_failed')
    P = np.zeros((len(ls), 2))
    P[1:] = np.cumsum(ls[:-1, None] * T[:-1], axis=0)
    return P


def clamped_laplacian(L, mark):
    """``L`` (N,N) with the negative off-diagonal weights (obtuse pairs of angles, needle triangles)
    of the edges touching ``mark`` ((N,) bool) raised to zero: a local repair of a harmonic map that
    folds there (positive weights keep the maximum principle). Symmetric; rows still sum to 0."""
    import scipy.sparse as sp
    W = (-L).tocoo()
    off = W.row != W.col
    touch = mark[W.row] | mark[W.col]
    w = np.where(off, np.where(touch, np.maximum(W.data, 0.0), W.data), 0.0)
    Wm = sp.coo_matrix((w, (W.row, W.col)), shape=L.shape).tocsc()
    return (sp.diags(np.asarray(Wm.sum(axis=1)).ravel()) - Wm).tocsc()


def _harmonic(L, loop, PB, cache=None):
    """Harmonic extension (N,2) of boundary values ``PB`` (nb,2) on ``loop`` with the cotan ``L``.
    ``cache``: optional dict; the factorisation of ``L_II`` is kept there for the same loop."""
    N = L.shape[0]
    mask = np.zeros(N, bool)
    mask[loop] = True
    I = np.nonzero(~mask)[0]
    X = np.zeros((N, 2))
    X[loop] = PB
    if len(I):
        LI = L[I]
        key = (N, loop.tobytes(), id(L))
        fac = cache['fac'] if cache is not None and cache.get('fac_key') == key else None
        if fac is None:
            fac = Factor(LI[:, I])
            if cache is not None:
                cache['fac_key'], cache['fac'] = key, fac
        X[I] = -fac.solve(LI[:, loop] @ PB)
    return X


def _folded(uv, F):
    """(m,) bool: the triangles ``F`` (m,3) that the layout ``uv`` (N,2) turns over or flattens (signed
    area at most 1e-14 of the total absolute area)."""
    area = signed_uv_areas(uv, F)
    return area <= 1e-14 * np.abs(area).sum()


def _relax_folds(Fc, loop, uv, Lc, rounds=REPAIR_ROUNDS, Vc=None):
    """Local repair of an exact layout ``uv`` (N,2), in place: the input triangles are laid out with
    straight edges between the vertices of the intrinsic triangulation, so a needle triangle can come
    out flipped or flat. The vertices within ``1 + round`` rings of such triangles (not on the cut
    disk's boundary ``loop``, so seam copies stay congruent) are re-placed by a map with nonnegative
    weights (a convex combination of the neighbours). With ``Vc`` (N,3) the weights live on the input
    triangles ``Fc`` themselves (their cotan weights clamped at 0, plus a small uniform weight that
    keeps every vertex attached), whose orientation is what gets measured; without it, on the
    intrinsic ``Lc`` (``clamped_laplacian``). The layout with the fewest folded triangles is kept.
    Returns the number of rounds used."""
    import scipy.sparse as sp
    N = len(uv)
    onb = np.zeros(N, bool)
    onb[loop] = True
    adj = None
    if Vc is not None and degenerate_faces(Vc, Fc).any():
        Vc = None                            # zero-area input triangles have no cotan weights
    if Vc is not None:
        W = -clamped_laplacian(cotan_laplacian(Vc, Fc), np.ones(N, bool))
        W.setdiag(0)
        W.eliminate_zeros()
        E, _ = topology.unique_edges(Fc)
        floor = 1e-3 * float(np.abs(W.data).mean()) if W.nnz else 1.0
        U = sp.coo_matrix((np.full(len(E), floor), (E[:, 0], E[:, 1])), shape=(N, N))
        W = (W + U + U.T).tocsr()
        Lp = (sp.diags(np.asarray(W.sum(axis=1)).ravel()) - W).tocsr()
    else:
        Lp = clamped_laplacian(Lc, np.ones(N, bool)).tocsr()

    bad = _folded(uv, Fc)
    best = (int(bad.sum()), uv.copy())
    for r in range(rounds):
        if not bad.any():
            return r
        if adj is None:
            adj = topology.vertex_adjacency(Fc, N)
        mark = np.zeros(N, bool)
        mark[Fc[bad].ravel()] = True
        for _ in range(1 + r):
            mark |= adj @ mark.astype(np.int8) > 0
        mark &= ~onb
        M = np.nonzero(mark)[0]
        if not len(M):
            break
        R = np.nonzero(~mark)[0]
        try:
            uv[M] = Factor(Lp[M][:, M].tocsc()).solve(-(Lp[M][:, R] @ uv[R]))
        except (ConformalError, RuntimeError, ValueError):
            break
        bad = _folded(uv, Fc)
        if bad.sum() < best[0]:
            best = (int(bad.sum()), uv.copy())
    uv[:] = best[1]
    return rounds


RING_ENUMERATE = 40   # ``ring_clearance`` enumerates the vertices of rings up to this many triangles
_BOX = np.array([[-1.0, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0]])   # p within [-1, 1]^2, as rows of A x >= -1


@lru_cache(maxsize=None)
def _choose(n, k):
    """(k, C(n, k)) int: every ``k`` of ``range(n)``, as rows of indices (kept per size)."""
    out = np.array(list(combinations(range(n), k)), np.int64).reshape(-1, k).T
    out.setflags(write=False)
    return out


def ring_clearance(g, h):
    """The largest ``t`` such that some point ``p`` of the box ``[-1, 1]^2`` has ``g p + h >= t`` (the
    Chebyshev centre of the kernel of a vertex's ring, ``g`` (r,2) unit normals, ``h`` (r,)): the
    linear program in ``(p, t)`` solved exactly at its vertices, every three active constraints of
    the ``r`` ring's and the box's four (a ring holds a few to a few dozen triangles; scipy's
    ``linprog`` took 2 ms a call, 43 s of a 4k-triangle CAD-like part's 65 s unwrap). A ring of more
    than ``RING_ENUMERATE`` triangles (the triples grow as r^3) goes to ``linprog``. Returns ``t``
    (-inf if no vertex is feasible)."""
    r = len(g)
    if r > RING_ENUMERATE:
        res = linprog([0, 0, -1], A_ub=np.c_[-g, np.ones(r)], b_ub=h,
                      bounds=[(-1, 1), (-1, 1), (None, None)], method='highs')
        return float(res.x[2]) if res.status == 0 else -np.inf
    # constraints as rows of A x >= b, x = (p0, p1, t)
    A = np.empty((r + 4, 3))
    A[:r, :2], A[:r, 2], A[r:] = g, -1.0, _BOX
    b = np.empty(r + 4)
    b[:r], b[r:] = -h, -1.0
    idx = _choose(r + 4, 3).T                    # (C, 3): every three constraints
    M = A[idx]
    ok = np.abs(np.linalg.det(M)) > 1e-12
    if not ok.any():
        return -np.inf
    x = np.linalg.solve(M[ok], b[idx][ok][..., None])[..., 0]
    feas = (x @ A.T >= b - 1e-9).all(1)
    return float(x[feas, 2].max()) if feas.any() else -np.inf


def l1_nearest(g, c):
    """The point ``p`` (2,) of least ``|p|_1`` with ``g p >= c`` (``g`` (r,2), ``c`` (r,)), or None if no
    candidate is feasible: the minimum of a convex piecewise-linear function over a polygon lies at
    the origin, at a corner (two constraints active) or where an edge crosses an axis, and those are
    all tried (``untangle``'s second linear program, solved exactly)."""
    cand = [np.zeros((1, 2))]
    if len(g) >= 2:
        idx = _choose(len(g), 2).T               # (C, 2): every two constraints
        M = g[idx]
        ok = np.abs(np.linalg.det(M)) > 1e-12
        if ok.any():
            cand.append(np.linalg.solve(M[ok], c[idx][ok][..., None])[..., 0])
    for ax in (0, 1):                                   # on the axis p[1 - ax] = 0
        a = g[:, ax]
        nz = np.abs(a) > 1e-12
        q = np.zeros((int(nz.sum()), 2))
        q[:, ax] = c[nz] / a[nz]
        cand.append(q)
    P = np.concatenate(cand)
    feas = (P @ g.T >= c - 1e-9).all(1)
    if not feas.any():
        return None
    P = P[feas]
    return P[np.argmin(np.abs(P).sum(1))]


def untangle(Fc, uv, pinned, rounds=UNTANGLE_ROUNDS, margin=UNTANGLE_MARGIN):
    """Last local repair of a layout ``uv`` (N,2), in place: each free vertex (``pinned`` (N,) bool
    False: not a copy of a vertex on the cut, whose copies must stay congruent; a vertex on the mesh's
    own boundary is free) of a folded triangle of ``Fc`` (m,3) moves the least (L1) that puts it at
    least ``margin`` times its best clearance on the left of the opposite edge of every triangle
    around it. The best clearance is the largest ``t`` such that the vertex can stand ``t`` from each
    of those edges (a Chebyshev centre of the ring's kernel, a linear program); a ring without a
    kernel is left alone. Needed where ``_relax_folds`` cannot reach: a needle triangle with two
    corners on the cut, so that only its third corner may move. The loop runs over the corners of
    folded triangles only (a handful). Returns the number of vertices moved."""
    moved = 0
    fixed = np.asarray(pinned, bool)
    bad = _folded(uv, Fc)
    if not bad.any():
        return 0
    # the corners at each vertex, once: (triangle, corner) sorted by vertex
    order = np.argsort(Fc.ravel(), kind='stable')
    first = np.searchsorted(Fc.ravel()[order], np.arange(len(uv) + 1))
    for _ in range(rounds):
        verts = np.unique(Fc[bad])
        verts = verts[~fixed[verts]]
        if not len(verts):
            break
        for v in verts.tolist():
            rows, k = np.divmod(order[first[v]:first[v + 1]], 3)
            # in the ring's own frame (centred on v, its size as unit): the solver's tolerances are
            # absolute, and a folded ring can be a millionth of the layout (beast at 8 cones)
            p0 = uv[v]
            a = uv[Fc[rows, (k + 1) % 3]] - p0                # (r,2) the corners after v (ccw)
            b = uv[Fc[rows, (k + 2) % 3]] - p0
            size = float(max(np.abs(a).max(), np.abs(b).max()))
            if not size > 0:
                continue
            a, b = a / size, b / size
            d = b - a
            ln = np.linalg.norm(d, axis=1)
            if not (ln > 0).all():
                continue
            # clearance of p from edge a->b: ((b - a) x (p - a)) / |b - a| = (g . p + h) / |b - a|
            g = np.stack([-d[:, 1], d[:, 0]], 1) / ln[:, None]
            h = (a[:, 0] * b[:, 1] - a[:, 1] * b[:, 0]) / ln
            # max t  s.t.  g p + h >= t   (p within the ring's box)
            t = ring_clearance(g, h)
            if not t > 1e-9:
                continue
            # min |p|_1  s.t.  g p + h >= margin t
            p = l1_nearest(g, margin * t - h)
            if p is not None:
                uv[v] = p0 + size * p
                moved += 1
        bad = _folded(uv, Fc)
        if not bad.any():
            break
    return moved


def _untangle_layout(Fc, uv, vert_of, seams, n, info):
    """``untangle`` the cut disk's layout ``uv`` (N,2) in place, with the copies of vertices on the cut
    ``seams`` (k,2) pinned (``vert_of`` (N,) their mesh vertices, of ``n``; a vertex only on the mesh's
    own boundary may move). Records in ``info``: ``folded_raw``, the triangles of ``Fc`` folded before
    (for ``softened``), and ``untangled``, the number of vertices moved."""
    on = np.zeros(n, bool)
    on[np.asarray(seams, np.int64).ravel()] = True
    info['folded_raw'] = np.nonzero(signed_uv_areas(uv, Fc) <= 0)[0]
    info['untangled'] = untangle(Fc, uv, on[vert_of])


def _wedge_middle(Vc, Fc, loop, corner, avoid=None):
    """The neighbour of boundary vertex ``corner`` of the cut disk that halves its wedge by angle
    (walking the fan of triangles from the next boundary vertex to the previous one); ``avoid`` (N,)
    bool optional: neighbours not taken while another is inside the wedge (across a polygon's
    diagonal)."""
    from ..mesh.geometry import corner_angles
    tris = np.nonzero((Fc == corner).any(1))[0]
    ang = corner_angles(Vc, Fc[tris])
    k = np.argmax(Fc[tris] == corner, axis=1)
    r = np.arange(len(tris))
    p, q, a = Fc[tris][r, (k + 1) % 3], Fc[tris][r, (k + 2) % 3], ang[r, k]
    step = {int(x): (int(y), float(z)) for x, y, z in zip(p, q, a)}
    i = int(np.nonzero(loop == corner)[0][0])
    v, total, seq = int(loop[(i + 1) % len(loop)]), 0.0, []
    while v in step:
        v, da = step[v]
        total += da
        seq.append((v, total))
    half = total / 2
    inner = [(abs(t - half), v) for v, t in seq[:-1]]
    if avoid is not None and any(not avoid[v] for _, v in inner):
        inner = [(d, v) for d, v in inner if not avoid[v]]
    return min(inner)[1] if inner else None


def layout_cut(V, F, u, seams, cones, kappa, max_branches=16, cache=None, Lu=None, exact=True,
               fac0=None, inner=None):
    """Cut ``(V, F)`` along ``seams`` (k,2) and lay the disk out for the cone curvatures ``kappa`` (c,)
    at ``cones`` (c,), with the closed-surface linear log scale ``u`` (n,) (``Lu``: its ``L u``).

    ``exact``: the exact flat cone metric (``flat_cone_metric``) unfolded (``unfold``); if Newton
    fails, the BFF-style layout of the linear ``u`` (a paired boundary polygon extended
    harmonically). A cone whose wedge exceeds ``WEDGE_MAX`` (a negative cone at a leaf of the cut, or
    one split unevenly; the exact metric's wedge when there is one, else the linear estimate) gets a
    new branch of the cut through the middle of that wedge (``through_corner``, else
    ``reroute_leaf``), at most ``max_branches`` times; the branches avoid the edges ``inner`` (k,2:
    polygons' diagonals) where they can.
    Returns (cut (``islands.Cut``), loop (nb,), uv (N,2) per split vertex, seams (k',2), info dict)."""
    n = len(V)
    seams = np.asarray(seams, np.int64).reshape(-1, 2)
    cache = {} if cache is None else cache
    added = 0
    failed = set()
    kap_all = np.zeros(n)
    kap_all[np.asarray(cones, np.int64)] = kappa
    fixed = np.zeros(n, bool)
    twin = _mesh_twins(F, n, cache)             # the working mesh's half-edge twins, for its cuts
    bl = topology.boundary_loops(F, n, twin=twin)
    for lp in bl:
        fixed[lp] = True
    if not bl:
        fixed[0] = True                      # the ground of ConeSystem, whose factor is ``fac0``
    reuse = None                             # the cut of a new branch, checked already
    warm = None                              # the last exact metric (n,) of this cone set
    while True:
        cut = reuse if reuse is not None else cut_along_seams(F, n, seams, twin=twin)
        reuse = None
        Fc, vert_of = cut.F, cut.vert_of
        twc = _cut_twins(Fc, twin)
        if cut.n_islands != 1 or not is_disk(Fc, len(vert_of), twin=twc):
            raise ConformalError("the cut graph does not open the surface into a disk", 'bad_topology')
        loop = topology.boundary_loops(Fc, len(vert_of), twin=twc)[0]
        Vc, uc = V[vert_of], u[vert_of]
        kt, lt, Lc = _boundary_data(Vc, Fc, loop, uc, vert_of, Lu, cache)
        wedge = np.pi - kt
        got = None
        if exact and (n <= BIG_MESH or not (wedge > WEDGE_MAX).any() or added >= max_branches):
            # (big meshes: the linear wedges steer the branches; one exact solve at the end)
            T = cache['disk_T']
            big = n > BIG_MESH
            cold = u - u[fixed].mean()
            if big and 'newton_shift' in cache:
                # big meshes, another angle set on the same cones: start from the last exact metric's
                # difference to its linear start (the same solution, fewer damped Newton steps)
                got = flat_cone_metric(T, vert_of, n, 2 * np.pi - kap_all, fixed,
                                       cold + cache['newton_shift'], fac0=fac0, krylov=True)
            if got is None and warm is not None:
                # a new branch changes the cut near it only: the last branch's exact metric is a
                # start a few Newton steps from this one
                got = flat_cone_metric(T, vert_of, n, 2 * np.pi - kap_all, fixed, warm, fac0=fac0, krylov=big)
            if got is None:
                got = flat_cone_metric(T, vert_of, n, 2 * np.pi - kap_all, fixed, cold, fac0=fac0, krylov=big)
            if got is None:
                got = flat_cone_metric(T, vert_of, n, 2 * np.pi - kap_all, fixed, np.zeros(n), krylov=big)
            if got is not None and big:
                cache['newton_shift'] = got[0] - cold
            if got is not None:
                warm = got[0]
                ang = corner_angles_l(got[1][T.FE])
                wedge = np.bincount(T.F.ravel(), ang.ravel(), minlength=len(vert_of))[loop]
        bad = np.nonzero((wedge > WEDGE_MAX) & ~np.isin(vert_of[loop], list(failed)))[0]
        if len(bad) == 0 or added >= max_branches:
            break
        cc = int(loop[bad[np.argmax(wedge[bad])]])
        c = int(vert_of[cc])
        avoid = None
        if inner is not None and len(inner):
            # the corner's neighbours across a polygon's diagonal (a branch along it would split
            # the polygon)
            across = np.asarray(inner)[(np.asarray(inner) == c).any(1)].ravel()
            avoid = np.isin(vert_of, across[across != c])
        w0 = _wedge_middle(Vc, Fc, loop, cc, avoid)
        if w0 is None:
            failed.add(c)
            continue
        deg = np.bincount(seams.ravel(), minlength=n)
        pos = np.asarray(cones)[(np.asarray(kappa) > 0) & (deg[np.asarray(cones, np.int64)] == 1)]
        stop = np.zeros(n, bool)
        stop[np.asarray(cones, np.int64)] = True
        for lp in bl:
            stop[lp] = True
        protect = np.zeros(n, bool)
        protect[np.asarray(cones, np.int64)[np.asarray(kappa) < 0]] = True
        new = through_corner(V, F, seams, c, int(vert_of[w0]), stop, protect, inner)
        c2 = None
        if new is not None:
            c2 = cut_along_seams(F, n, new, twin=twin)
            if c2.n_islands != 1 or not is_disk(c2.F, len(c2.vert_of), twin=_cut_twins(c2.F, twin)):
                new, c2 = None, None
        if new is None:
            new = reroute_leaf(V, F, seams, c, int(vert_of[w0]), pos[pos != c], stop, protect, inner)
        if new is None:
            failed.add(c)                    # try the next corner; this one keeps its wedge
            continue
        # the straightened branch, else the branch as found, whichever still opens the surface into a
        # disk (straightening can make a path touch the boundary or the cut elsewhere: teapot's lid)
        reuse = None
        for cand in (straighten(F, new, stop, inner), new):
            cand = np.unique(np.sort(np.asarray(cand, np.int64).reshape(-1, 2), 1), axis=0)
            c3 = c2 if c2 is not None and np.array_equal(np.unique(np.sort(new, 1), axis=0), cand) \
                else cut_along_seams(F, n, cand, twin=twin)
            if c3.n_islands == 1 and is_disk(c3.F, len(c3.vert_of), twin=_cut_twins(c3.F, twin)):
                seams, reuse = cand, c3
                break
        if reuse is None:
            failed.add(c)                    # no branch keeps a disk: this corner keeps its wedge
            continue
        added += 1
    a, b = vert_of[loop], vert_of[np.roll(loop, -1)]
    key = np.minimum(a, b) * n + np.maximum(a, b)
    _, pair = np.unique(key, return_inverse=True)
    info = {'repair_rounds': 0, 'branches_added': added, 'max_wedge': float(wedge.max()),
            'pair': pair.ravel(), 'exact': False}
    if got is not None:
        uv = unfold(cache['disk_T'], got[1])
        if np.isfinite(uv).all():
            info['exact'] = True
            info['flat_triangles'] = got[2]
            info['u_exact'] = got[0]
            info['repair_rounds'] = _relax_folds(Fc, loop, uv, Lc, Vc=Vc)
            _untangle_layout(Fc, uv, vert_of, seams, n, info)
            return cut, loop, uv, seams, info
    P = paired_polygon(kt, lt, pair.ravel())
    uv = _harmonic(Lc, loop, P, cache)
    repaired = 0
    for _ in range(REPAIR_ROUNDS):
        area = signed_uv_areas(uv, Fc)
        bad = area * np.sign(np.median(area)) <= 0
        if not bad.any():
            break
        mark = np.zeros(len(uv), bool)
        mark[Fc[bad].ravel()] = True
        adj = topology.vertex_adjacency(Fc, len(uv))
        for _ in range(2 + repaired):
            mark |= adj @ mark.astype(np.int8) > 0
        uv = _harmonic(clamped_laplacian(Lc, mark), loop, P)
        repaired += 1
    info['repair_rounds'] = repaired
    _untangle_layout(Fc, uv, vert_of, seams, n, info)
    return cut, loop, uv, seams, info


# ------------------------------------------------------------------------------------------------
# the public entry point
# ------------------------------------------------------------------------------------------------
def _evaluate(Vw, Fw, system, S, kappa, seams, cache=None, split=True, u=None, inner=None):
    """Lay out and measure one set of cone angles on the cut ``seams``: dict with cut, loop, uv (N,2)
    per split vertex (UV area = 3D area), seams, info, measured (``measures_from_jacobians``),
    crossings (boundary self-crossings) and u (n,). ``u`` (n,): the angles' linear log scale
    (``system.u_of(S, kappa)``) if the caller has it already. ``inner`` (k,2): polygons' diagonals,
    which new cuts avoid where they can."""
    u = system.u_of(S, kappa) if u is None else u
    u = u - np.median(u)
    cut, loop, uvc, seams, info = layout_cut(Vw, Fw, u, seams, S, kappa, cache=cache,
                                             max_branches=16 if len(Vw) <= BIG_MESH else 4,
                                             Lu=system.L @ u, fac0=system._fac, inner=inner)
    crossings = boundary_crossings(uvc, [loop])
    splits = 0
    if crossings and split:
        cut, uvc, seams, crossings, splits = split_overlaps(Vw, Fw, cut, uvc, seams,
                                                            twin=_mesh_twins(Fw, len(Vw), cache), inner=inner)
    info['charts'], info['splits'] = int(cut.n_islands), splits
    Fc = cut.F
    W = uvc[Fc]
    e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    a_uv = 0.5 * (e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]).sum()
    if not a_uv > 0:
        raise ConformalError("the cut disk's layout has no positive UV area: the mesh is numerically "
                             "degenerate", 'degenerate', 'clean_mesh')
    uvc = (uvc - uvc.mean(0)) * np.sqrt(system.A.sum() / a_uv)
    good = ~system.degenerate                  # zero-area input triangles have no Jacobian
    J, A = jacobians(Vw[cut.vert_of], Fc[good], uvc)
    measured, mu = measures_from_jacobians(J, A)
    measured['mu_ratio_p1_p99_area'] = weighted_spread(mu, A)
    # a triangle squashed to (nearly) nothing is as unusable as a flipped one (the mesh's own needles
    # and caps left out: the exact metric inflates a cap, docs/cones.md)
    squashed = np.zeros(len(Fc), bool)
    squashed[good] = squashed_faces(singular_values(J), system.anisotropy[good], DEGENERATE_QC)
    measured['degenerate'] = int(squashed.sum())
    W = uvc[Fc]
    e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
    folded = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] <= 0
    measured['flips'] += int(folded[~good].sum())
    # seam edges along polygons' diagonals: such a polygon cannot hold its corners' two UVs
    measured['seams_inside_polygons'] = int(inner_mask(np.sort(seams, 1), inner, len(Vw)).sum()) \
        if len(seams) else 0
    bad = np.nonzero(squashed | folded)[0]
    # where the layout folded before ``untangle`` patched it: the cones next to those triangles are
    # the ones ``softened`` relaxes (a patched fold still marks a cone whose metric degenerates)
    soft = np.union1d(bad, info.get('folded_raw', np.zeros(0, np.int64)))
    return {'cut': cut, 'loop': loop, 'uv': uvc, 'seams': seams, 'info': info, 'measured': measured,
            'crossings': crossings, 'u': u, 'bad': bad, 'soft': soft, 'kappa': kappa}


def _mesh_twins(F, n, cache):
    """``topology.twin_halfedges(F, n)`` (3m,), kept in ``cache`` (dict) for the same ``F`` (m,3)."""
    key = (n, F.shape, hash(F.tobytes()))
    if cache.get('twin_key') != key:
        cache['twin_key'], cache['twin'] = key, topology.twin_halfedges(F, n)
    return cache['twin']


def _split_nonmanifold(V, F):
    """Split vertices where separate fans of faces touch (one copy per fan). Returns (F2 (m,3),
    vert_of (N,), count of split vertices)."""
    n = len(V)
    fans = topology.vertex_fans(F, n)
    if not (fans > 1).any():
        return F, np.arange(n), 0
    cut = cut_along_seams(F, n)
    return cut.F, cut.vert_of, int((fans > 1).sum())


def cone_unwrap(V, F, *, cones=None, target_ratio=0.5, max_cones=48, sweeps=MOVE_SWEEPS,
                max_faces=DEFAULT_MAX_FACES, progress=None, inner=None):
    """Conformal UVs with cone singularities and an automatic cut (docs/cones.md).

    V: (n,3) float positions. F: (m,3) int triangles, counter-clockwise; one connected manifold piece,
    closed (any genus) or with boundary (non-manifold vertices are split internally and reported;
    the input is never modified). cones: None (automatic placement), (c,) int vertex ids (the angles
    are solved for the L-inf objective), or a pair ``(ids (c,), kappa (c,))`` with given curvatures in
    radians (closed: they must sum to 2*pi*chi). target_ratio: stop adding cones when the estimated
    1%/99% spread of the scale reaches it (None: place exactly ``max_cones``). sweeps: passes of
    local cone moves after the greedy placement. progress: optional ``progress(fraction, message)``.
    inner: optional (m,3) bool, side ``s`` of triangle ``t`` (corners ``s`` and ``s + 1``) lies inside
    a polygon (a quad's diagonal): the cut avoids those edges where it can, since a seam through a
    polygon would give one of its corners two UVs.
    Returns ``ConeResult``. Raises ``ConformalError`` on bad input."""
    report_progress = progress or (lambda f, msg: None)
    t0 = time.perf_counter()
    timings = {}
    V, F = as_arrays(V, F)
    n_in, m = len(V), len(F)
    if not (target_ratio is None or 0 < target_ratio <= 1):
        raise ConformalError(f"target_ratio must be in (0, 1] or None, got {target_ratio}")
    if int(max_cones) < 0:
        raise ConformalError(f"max_cones must be non-negative, got {max_cones}")
    warnings = []
    # a non-manifold vertex is split (one copy per fan); every other problem is an error
    check_arrays(V, F, max_faces)                 # indices, coordinates, size: before any topology
    Fs, vert_of0, n_split = _split_nonmanifold(V, F)
    Vs = V[vert_of0]
    # drop vertices in no face (allowed: they get no UV and NaN u)
    check_mesh(Vs, Fs, kind='surface', max_faces=max_faces, allow_loose=True, allow_degenerate=True)
    keep = np.zeros(len(Vs), bool)
    keep[Fs.ravel()] = True
    newid = -np.ones(len(Vs), np.int64)
    newid[keep] = np.arange(keep.sum())
    Fw = newid[Fs]
    orig = vert_of0[keep]                     # input vertex of each working vertex
    inner_w = None
    if inner is not None:
        inner_w = side_pairs(Fw, np.asarray(inner, bool).reshape(m, 3))
    Vw, unit = normalise_scale(Vs[keep])
    n = len(Vw)
    if degenerate_faces(Vw, Fw).all():
        raise ConformalError("every triangle has zero area", 'degenerate', 'clean_mesh')
    if n_split:
        warnings.append(f"{n_split} non-manifold vertex(es) were split (one copy per fan of faces)")
    timings['check'] = time.perf_counter() - t0
    report_progress(0.02, 'factorising the Laplacian')
    t = time.perf_counter()
    system = ConeSystem(Vw, Fw)
    timings['factor'] = time.perf_counter() - t
    genus = topology.genus(system.chi, len(system.loops))
    t = time.perf_counter()
    history = []
    if cones is None and system.loops and planar_map(Vw, Fw) is not None:
        # a planar disk is its own conformal map (u = 0, an isometry): no cone can gain
        S, kappa = np.zeros(0, np.int64), np.zeros(0)
    elif cones is None:
        # big meshes: the automatic mode places by BFF's greedy without moves (time, ``place_cones``)
        S, kappa, history = place_cones(system, target_ratio, int(max_cones),
                                        sweeps if n <= BIG_MESH or target_ratio is None else 0,
                                        progress=lambda f, msg: report_progress(0.05 + 0.6 * f, msg))
        if n <= BIG_MESH:
            S, kappa = _drop_weak(system, S, kappa)
    else:
        S, kappa = _user_cones(system, cones, orig, n_in)
    timings['placement'] = time.perf_counter() - t
    if system.needs_sum and len(S) and abs(kappa.sum() - system.total) > 1e-6:
        raise ConformalError(f"the cone curvatures sum to {kappa.sum():.6f}, not 2*pi*chi = "
                             f"{system.total:.6f} (Gauss-Bonnet)")
    if system.needs_sum and genus == 0 and len(S) < 2:
        raise ConformalError("a closed genus-0 surface needs at least 3 cones (each below 2*pi, summing "
                             "to 4*pi)")
    given = isinstance(cones, tuple) and len(cones) == 2

    def lay_out(S, kappa, bar=0.0, quick=False, only=False):
        """Cut the mesh through the cones ``S`` and lay out the angle candidates on that cut
        (the placement's ``kappa`` first; ``quick``: then only its exact-metric correction and its
        softened sets; ``only``: ``kappa`` alone, beyond ``MAX_LAYOUTS`` if that is spent);
        ``bar``: the ratio of a clean layout of other cones in hand (a candidate
        estimated ``SKIP_MARGIN`` below it, or below this cut's best clean one, is skipped).
        Returns (best (key, label, kappa, evaluation) or None, list of what was tried, the best
        layout with defects as [ratio, evaluation] or [])."""
        report_progress(0.7, 'cutting')
        t = time.perf_counter()
        seams0 = cut_graph(Vw, Fw, S, inner=inner_w)
        timings['cut'] = timings.get('cut', 0.0) + time.perf_counter() - t
        report_progress(0.75, 'laying out the cut disk')
        t = time.perf_counter()
        deg = np.bincount(seams0.ravel(), minlength=n)

        def big_done():
            """Big mesh: the first clean layout is kept, so no further candidate is computed."""
            return n > BIG_MESH and best is not None and best[0][0]

        def candidates():
            """Angle sets to lay out after the placement's: L-inf angles with floors, BFF's (lazily: on
            a big mesh nothing more is computed once a layout is clean)."""
            if given or not len(S):
                return
            # the cut is fixed by the cones; a leaf of it is one wedge, so its kappa must be positive
            leaf = deg[S] <= 1
            if leaf.any():
                low = np.where(leaf, KAPPA_LEAF, system.bounds[0])
                yield 'l2, leaves >= 0.4', system.l2_angles(S, lower=low)
            for floor in ANGLE_FLOORS:
                if big_done():
                    return
                k2, _ = system.trimmed_angles(S, lower=np.where(leaf, KAPPA_LEAF, max(floor, KAPPA_MIN)),
                                              rounds=3 if n <= BIG_MESH else 1)
                if k2 is not None:
                    yield f'linf, kappa >= {floor}', k2
            if n <= BIG_MESH:
                yield 'bff', system.dirichlet_angles(S)

        best = None
        tried = []
        cache = {}

        def corrected():
            """Angle sets that account for the exact metric: the realised log scale differs from the
            linear one by ``d = u_exact - u_linear``, nearly independent of small angle changes; the area-L2
            angles are re-solved for ``u_linear + d`` (a fixed-point step), from the best layout so far."""
            for it in range(CORRECTIONS if n <= BIG_MESH and not given and len(S) else 0):
                if best is None or 'u_exact' not in best[3]['info']:
                    return
                ue = best[3]['info']['u_exact']
                d = ue - system.u_of(S, best[2])
                yield f'l2, exact-metric correction {it + 1}', system.l2_angles(S, shift=d - np.median(d))

        last = {}
        dirty = []                       # (ratio, evaluation) of the best layout with defects

        def softened():
            """Angle sets for a layout that still flips: a cone with a flipped triangle within one ring
            (a strong negative cone whose exact metric degenerates a neighbour) gets a higher lower
            bound (``_next_floor`` of its curvature in that layout, raised again if it still flips) and
            the area-L2 angles are re-solved; up to ``SOFT_ROUNDS`` rounds."""
            floors = {}
            ev = dirty[1] if dirty else None
            for _ in range(SOFT_ROUNDS if not given and len(S) else 0):
                # while the best layout is not clean, or a defective one had the better ratio
                if ev is None or (best[0][0] and best[0][2] >= dirty[0]):
                    return
                near = _cones_near_flips(system, Fw, ev, S)
                if not near.any():
                    return
                for i in np.nonzero(near)[0].tolist():
                    floors[i] = _next_floor(floors.get(i, ev['kappa'][i]))
                low = np.full(len(S), system.bounds[0])
                low[list(floors)] = list(floors.values())
                yield (f"l2, {len(floors)} cone(s) next to flips >= {max(floors.values()):.2f}",
                       system.l2_angles(S, lower=low))
                ev = last['ev'] if last.get('ev') is not None and len(last['ev']['soft']) else None

        import itertools
        first = [('given' if given else 'placement', kappa)]
        # a big mesh keeps its first clean layout: the placement's angles, softened where they flip,
        # before the other sets (a small mesh lays out every set and keeps the best)
        if only:
            sets = (first,)
        elif quick:
            sets = (first, corrected(), softened())
        elif n > BIG_MESH:
            sets = (first, softened(), candidates())
        else:
            sets = (first, candidates(), corrected(), softened())
        seen = []
        for label, kap in itertools.chain(*sets):
            if big_done():
                break                                   # big mesh: the first valid layout is kept
            if budget[0] >= MAX_LAYOUTS and not only:
                tried.append({'angles': label, 'skipped': True, 'budget': True})
                break
            if any(np.array_equal(kap, k0) for k0 in seen):
                continue                                # (leaves' angles equal to the placement's)
            seen.append(kap)
            u_lin = system.u_of(S, kap)
            est = face_spread(Fw, system.A, u_lin)
            if est < max(bar, clean_ratio(best)) - SKIP_MARGIN:
                # a layout realises at most about its estimate: this one cannot beat the clean best
                tried.append({'angles': label, 'estimate': est, 'skipped': True})
                continue
            budget[0] += 1
            try:
                ev = _evaluate(Vw, Fw, system, S, kap, seams0, cache, u=u_lin, inner=inner_w)
            except ConformalError as exc:
                tried.append({'angles': label, 'error': exc.problem})
                continue
            last['ev'] = ev
            me = ev['measured']
            tried.append({'angles': label, 'estimate': est, 'flips': me['flips'], 'overlaps': ev['crossings'],
                          'degenerate': me['degenerate'], 'mu_ratio_p1_p99': me['mu_ratio_p1_p99'],
                          'mu_ratio_p1_p99_area': me['mu_ratio_p1_p99_area'],
                          'qc_mean': me['qc_mean'], 'exact': ev['info']['exact'],
                          'charts': ev['info']['charts'],
                          'seams_inside_polygons': me['seams_inside_polygons']})
            defects = me['flips'] + ev['crossings'] + me['degenerate'] + me['seams_inside_polygons']
            key = (defects == 0, -defects, realised_spread(me))
            if defects and len(ev['soft']) and (not dirty or key[2] > dirty[0]):
                dirty[:] = [key[2], ev]
            if best is None or key > best[0]:
                best = (key, label, kap, ev)
        return best, tried, dirty

    def retry(candidates, note, until_clean=False):
        """Lay out the cone sets ``candidates`` (pairs of cones and angles) quickly, within the layout
        budget, keeping the best layout; ``until_clean``: stop at the first clean one."""
        nonlocal best, S, tried
        for S2, k2 in candidates:
            if budget[0] >= MAX_LAYOUTS:
                break
            best2, tried2, _ = lay_out(S2, k2, clean_ratio(best), quick=True)
            tried += [dict(c, angles=f"{c['angles']} ({note})") for c in tried2]
            if best2 is not None and best2[0] > best[0]:
                best, S = best2, S2
            if until_clean and best[0][0]:
                break

    t_lay = time.perf_counter()
    budget = [0]                         # exact layouts computed so far (at most MAX_LAYOUTS)
    best, tried, dirty = lay_out(S, kappa)
    kept_bounds = system.bounds
    alts = getattr(system, 'alternates', [])
    for j, ((S2, k2, bounds), est) in enumerate(zip(alts, getattr(system, 'alternate_scores',
                                                                 [np.inf] * len(alts)))):
        # the other placements (greedy / L2 start, other curvature bounds), while the best one has
        # no clean layout, realises less than another placement's estimate (ALT_MARGIN below it),
        # or misses the target that another placement's estimate reaches (a clean layout that meets
        # the target keeps the placement's cones: the fewest that reach it)
        if cones is not None or n > BIG_MESH or budget[0] >= MAX_LAYOUTS:
            break
        missed = target_ratio is not None and best is not None and best[0][2] < target_ratio <= est
        if best is not None and best[0][0] and best[0][2] >= est - ALT_MARGIN and not missed:
            continue
        if best is not None and best[0][0] and target_ratio is not None and best[0][2] >= target_ratio:
            continue        # the target holds, cleanly, with the placement's (fewest) cones
        system.bounds = bounds
        if not system.alternate_moved[j]:
            # (only the best placement, with a fixed budget the best greedy run and the best L2
            # start, were moved; this one is moved now, as ``place_cones`` would have)
            S2, k2, _, _ = move_cones(system, list(S2), k2, est, radius=MOVE_RADIUS, sweeps=sweeps,
                                      both=target_ratio is None)
            S2 = np.array(S2, np.int64)
        S2, k2 = _drop_weak(system, S2, k2)
        best2, tried2, dirty2 = lay_out(S2, k2, clean_ratio(best))
        tried += [dict(c, angles=f"{c['angles']} ({len(S2)} cones, bounds {bounds})") for c in tried2]
        if best2 is not None and (best is None or best2[0] > best[0]):
            best, S, dirty, kept_bounds = best2, S2, dirty2, bounds
    aim = target_ratio
    for _ in range(TOP_UPS if cones is None and target_ratio is not None and n <= BIG_MESH else 0):
        # automatic mode: the layout realises less than the placement's estimate promised, so the
        # target is missed; place again for an estimate raised by the shortfall (more cones), and keep
        # that if its layout is clean and better
        if best is None or not best[0][0] or best[0][2] >= target_ratio or len(S) >= int(max_cones) \
                or budget[0] >= MAX_LAYOUTS:
            break
        aim = min(aim + (target_ratio - best[0][2]) + TOP_UP_MARGIN, 0.99)
        S2, k2, h2 = place_cones(system, aim, int(max_cones), sweeps,
                                 progress=lambda f, msg: report_progress(0.05 + 0.6 * f, msg))
        S2, k2 = _drop_weak(system, S2, k2)
        if len(S2) <= len(S):
            break
        best2, tried2, dirty2 = lay_out(S2, k2, clean_ratio(best))
        tried += [dict(c, angles=f"{c['angles']} ({len(S2)} cones, top-up for {aim:.3f})") for c in tried2]
        if best2 is not None and best2[0] > best[0]:
            best, S, history, dirty, kept_bounds = best2, S2, h2, dirty2, system.bounds
    if cones is None and n <= BIG_MESH and dirty and best is not None and budget[0] < MAX_LAYOUTS and \
            not (best[0][0] and best[0][2] >= dirty[0]):
        # a layout with a squashed or flipped triangle next to a cone realised more than the best
        # clean one: the same cones with that cone moved to a neighbour (``nudged``)
        system.bounds = kept_bounds
        retry(nudged(system, Fw, dirty[1], S), "a cone next to flips moved")
    if cones is None and n <= BIG_MESH and best is not None and not best[0][0] and len(S) < int(max_cones) \
            and budget[0] < MAX_LAYOUTS:
        # the best layout still squashes or flips a triangle away from every cone (curvature
        # concentrated at a vertex the placement left out): a cone added at one of its corners
        system.bounds = kept_bounds
        retry(added(system, Fw, best[3], S), "a cone added at a defect", until_clean=True)
    iso = polyhedral_cones(system, int(max_cones)) if cones is None and n <= BIG_MESH else None
    if iso is not None and not (best is not None and best[0][0] and best[3]['measured']['qc_mean'] <= QC_WARN
                                and (target_ratio is None or best[0][2] >= target_ratio)):
        # a polyhedral mesh (a CAD part, a box) whose best layout folds, misses the target or is far
        # from conformal: its corners as cones with their own angle defects unfold it isometrically
        # (u = 0: a net of the part), kept if that layout is better
        best2, tried2, _ = lay_out(*iso, clean_ratio(best), only=True)
        tried += [dict(c, angles=f"{c['angles']} ({len(iso[0])} corners: the isometric net)") for c in tried2]
        if best2 is not None and (best is None or best2[0] > best[0]):
            best, S = best2, iso[0]
    timings['layout'] = time.perf_counter() - t_lay - timings['cut']
    if best is None:
        raise ConformalError(f"no layout of the cut disk could be built: {tried[0]['error']}",
                             'solve_failed')
    _, angles_used, kappa, ev = best
    cut, uvc, seams, linfo = ev['cut'], ev['uv'], ev['seams'], ev['info']
    measured, crossings, u = ev['measured'], ev['crossings'], ev['u']
    t = time.perf_counter()
    E, _ = topology.unique_edges(Fw)
    total_len = float(np.linalg.norm(Vw[E[:, 0]] - Vw[E[:, 1]], axis=1).sum())
    seam_len = float(np.linalg.norm(Vw[seams[:, 0]] - Vw[seams[:, 1]], axis=1).sum()) if len(seams) else 0.0
    rows = ~system.rings(S, 1) if len(S) else np.ones(n, bool)
    timings['measure'] = time.perf_counter() - t
    timings['total'] = time.perf_counter() - t0
    rep = {
        'vertices': n_in, 'faces': m, 'genus': int(genus), 'boundary_loops': len(system.loops),
        'euler': int(system.chi), 'split_vertices': n_split,
        'cones': int(len(S)), 'kappa_sum': float(kappa.sum()) if len(S) else 0.0,
        'kappa_min': float(kappa.min()) if len(S) else 0.0,
        'kappa_max': float(kappa.max()) if len(S) else 0.0,
        **measured,
        'overlaps': int(crossings),
        'seam_edges': int(len(seams)), 'seam_length': seam_len * unit, 'seam_fraction': seam_len / total_len,
        'branches_added': linfo['branches_added'], 'max_wedge': linfo['max_wedge'],
        'repair_rounds': linfo['repair_rounds'], 'exact_layout': linfo['exact'],
        'charts': linfo['charts'], 'chart_splits': linfo['splits'],
        'vertex_ratio': float(np.exp(u.min() - u.max())),
        'vertex_ratio_outside_rings': float(np.exp(u[rows].min() - u[rows].max())) if rows.any() else None,
        'estimated_p1_p99': face_spread(Fw, system.A, u),
        'target_ratio': target_ratio,
        'placement': [(int(c), float(s)) for c, s in history],
        'seconds': {k: round(v, 4) for k, v in timings.items()},
    }
    rep['angles'] = angles_used
    rep['angle_candidates'] = tried
    rep['layouts'] = budget[0]
    if measured['flips']:
        warnings.append(f"{measured['flips']} triangle(s) are flipped in the layout")
    if measured['degenerate']:
        warnings.append(f"{measured['degenerate']} triangle(s) are squashed nearly flat in the layout "
                        f"(s1/s2 > {DEGENERATE_QC:g})")
    if crossings:
        warnings.append(f"the layout overlaps itself ({crossings} boundary crossing(s))")
    if budget[0] >= MAX_LAYOUTS and (measured['flips'] or crossings or measured['degenerate']):
        warnings.append(f"no clean layout in {MAX_LAYOUTS} tries (the most computed): on a noisy scan, "
                        "smooth it first or use fewer cones; or mark seams yourself")
    spread = realised_spread(measured)
    if target_ratio is not None and cones is None and spread < target_ratio:
        warnings.append(f"the 1%/99% scale ratio {spread:.3f} (the worse of per triangle and area-weighted) "
                        f"is below the target {target_ratio} with {len(S)} cones (max_cones={max_cones})")
    if measured['qc_mean'] > QC_WARN:
        warnings.append(f"the map is not conformal enough: qc_mean {measured['qc_mean']:.3f}")
    rep['warnings'] = warnings
    # outputs on the input's indices
    uv = (uvc * unit)[cut.F]                                 # (m,3,2) per corner of the input triangles
    seams_in = np.unique(np.sort(orig[seams], 1), axis=0) if len(seams) else np.zeros((0, 2), np.int64)
    u_in = np.full(n_in, np.nan)
    u_in[orig] = u                                          # (a split vertex: its last copy)
    report_progress(1.0, 'done')
    return ConeResult(uv=uv, seams=seams_in, cones=orig[S], kappa=kappa, u=u_in, report=rep)


def polyhedral_cones(system, max_cones, tol=POLYHEDRAL_DEFECT):
    """The corners of a polyhedral mesh as cones: (S (c,) int, kappa (c,) rad) with ``S`` the
    interior vertices whose angle defect exceeds ``tol`` in size and ``kappa`` their defects, or None
    if there are none or more than ``max_cones``. With these cones the log scale is ``u = 0``
    (closed: the defects left out, each below ``tol``, are spread over the cones so that the sum is
    ``2 pi chi``): the cut surface unfolds isometrically."""
    S = np.nonzero(system.eligible & (np.abs(system.Omega) > tol))[0]
    if not 0 < len(S) <= max_cones:
        return None
    kappa = system.Omega[S].copy()
    if system.needs_sum:
        kappa += (system.total - kappa.sum()) / len(S)
    return S.astype(np.int64), kappa


def flat_part(V, F, uv, target_ratio=0.5):
    """``cone_unwrap`` of a part with no interior vertex (``V`` (n,3), ``F`` (m,3)) that
    ``unfold.unfold_flat_disk`` laid out as ``uv`` (n,2), without its machinery: no cone can be
    placed (cones are interior vertices) and the map is that isometry. The report is the one
    ``cone_unwrap`` gives such a part. A triangle soup or a mesh of hair cards is thousands of such
    parts: 11 ms each through ``cone_unwrap``. Returns ``ConeResult``."""
    from ..mesh.geometry import angle_sums
    n, m = len(V), len(F)
    rep = {'vertices': n, 'faces': m, 'genus': 0, 'boundary_loops': 1, 'euler': 1, 'split_vertices': 0,
           'cones': 0, 'kappa_sum': 0.0, 'kappa_min': 0.0, 'kappa_max': 0.0, 'flips': 0, 'mu_ratio': 1.0,
           'mu_ratio_p1_p99': 1.0, 'qc_mean': 1.0, 'qc_max': 1.0, 'mu_ratio_p1_p99_area': 1.0,
           'degenerate': 0, 'seams_inside_polygons': 0, 'overlaps': 0, 'seam_edges': 0, 'seam_length': 0.0,
           'seam_fraction': 0.0,
           'branches_added': 0, 'max_wedge': float(angle_sums(V, F, n).max()), 'repair_rounds': 0,
           'exact_layout': True, 'charts': 1, 'chart_splits': 0, 'vertex_ratio': 1.0,
           'vertex_ratio_outside_rings': 1.0, 'estimated_p1_p99': 1.0, 'target_ratio': target_ratio,
           'placement': [], 'seconds': {'total': 0.0}, 'angles': 'placement', 'angle_candidates': [],
           'layouts': 0, 'warnings': []}
    W = uv[F]
    return ConeResult(uv=W - W.reshape(-1, 2).mean(0), seams=np.zeros((0, 2), np.int64),
                      cones=np.zeros(0, np.int64), kappa=np.zeros(0), u=np.zeros(n), report=rep)


def clean_ratio(best):
    """The realised ratio of a kept layout ``(key, label, kappa, evaluation)`` if it is clean, else 0."""
    return best[0][2] if best is not None and best[0][0] else 0.0


def _cones_near_flips(system, Fw, ev, S):
    """(k,) bool: the cones ``S`` within one ring of a triangle that the layout ``ev`` (``_evaluate``)
    flips or squashes (``ev['bad']``; else the flips of ``ev['uv']`` on ``ev['cut'].F``, whose faces
    keep the order of ``Fw`` (m,3))."""
    bad = ev.get('soft', ev.get('bad'))
    if bad is None:
        W = ev['uv'][ev['cut'].F]
        e1, e2 = W[:, 1] - W[:, 0], W[:, 2] - W[:, 0]
        bad = np.nonzero(e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0] <= 0)[0]
    S = np.asarray(S, np.int64)                 # an empty cone list is a float array otherwise
    if not len(bad) or not len(S):
        return np.zeros(len(S), bool)
    return system.rings(np.unique(Fw[bad]), 1)[S]


def nudged(system, Fw, ev, S, tries=NUDGE_TRIES):
    """Cone sets for a layout ``ev`` (``_evaluate``) that flips or squashes a triangle next to a
    cone: one such cone moved to one of its neighbours (eligible, outside the other cones'
    one-rings), the ``tries`` best of these moves by ``_score``, with the area-L2 angles. Why: the
    exact metric of a strong negative cone can open one corner of its one-ring to a straight angle
    at one vertex and not at the next (the cow cut at 7 cones: softened to -4.5, 0.246; the cone
    moved one edge, clean at 0.299). Yields (S2 (k,) int, kappa (k,)), best first."""
    S = list(np.asarray(S).tolist())
    scored = []
    for i in np.nonzero(_cones_near_flips(system, Fw, ev, np.asarray(S)))[0].tolist():
        others = S[:i] + S[i + 1:]
        near = system.rings([S[i]], 1) & system.eligible
        if others:
            near &= ~system.rings(others, 1)
        near[S[i]] = False
        for v in np.nonzero(near)[0].tolist():
            T = S[:i] + [v] + S[i + 1:]
            sc, kap = _score(system, T)
            scored.append((sc, T, kap))
    scored.sort(key=lambda r: r[0], reverse=True)
    for _, T, kap in scored[:tries]:
        yield np.array(T, np.int64), kap


def added(system, Fw, ev, S, tries=NUDGE_TRIES):
    """Cone sets for a layout ``ev`` (``_evaluate``) that flips or squashes triangles: a cone added at
    one of their corners that is eligible and outside the cones' one-rings (a triangle next to a cone
    is ``nudged``'s case), the corner of largest angle defect ``|Omega|`` first, at most ``tries``,
    with the area-L2 angles. Why:
    on a coarse mesh one vertex can hold most of a feature's curvature (Suzanne's brow: 2.96 rad);
    left out of the cones, the exact metric around it degenerates (Suzanne's head at 30 cones: one
    triangle squashed in every angle set; with that vertex a cone, clean at 0.482).
    Yields (S2 (k,) int, kappa (k,))."""
    S = list(np.asarray(S).tolist())
    bad = ev.get('soft', ev.get('bad'))
    if bad is None or not len(bad):
        return
    free = system.eligible.copy()
    if S:
        free &= ~system.rings(S, 1)
    verts = np.unique(Fw[bad])
    verts = verts[free[verts]]
    for v in verts[np.argsort(-np.abs(system.Omega[verts]), kind='stable')][:tries].tolist():
        T = np.array(S + [v], np.int64)
        yield T, system.l2_angles(T)


def _next_floor(f):
    """The next lower bound (rad) of a cone whose layout flips, from its curvature or its last bound
    ``f``: a strong negative cone is raised gently (``SOFT_STEP``; a cow's head at 9 cones: -5.5 ->
    -5.0 is clean at 0.405, -2.0 at once realised 0.219), then by ``SOFT_FLOORS``."""
    if f + SOFT_STEP < SOFT_FLOORS[0]:
        return f + SOFT_STEP
    return next((s for s in SOFT_FLOORS if s > f + 1e-9), SOFT_FLOORS[-1])


def _drop_weak(system, S, kappa, tol=0.02):
    """Remove cones with |kappa| < tol and re-solve the angles of the rest."""
    weak = np.abs(kappa) < tol
    if not weak.any() or len(S) == 0:
        return S, kappa
    S2 = S[~weak]
    k2, _ = system.linf_angles(S2)
    if k2 is None:
        return S, kappa
    return S2, k2


def _user_cones(system, cones, orig, n_in):
    """Working-vertex cone ids and curvatures from the user's ``cones``: (c,) ids or (ids, kappa)."""
    if isinstance(cones, tuple) and len(cones) == 2:
        ids, kap = np.asarray(cones[0]), np.asarray(cones[1], np.float64)
    else:
        ids, kap = np.asarray(cones), None
    if ids.ndim != 1 or (len(ids) and (not np.issubdtype(ids.dtype, np.integer) or ids.min() < 0
                                       or ids.max() >= n_in)):
        raise ConformalError(f"cones must be vertex indices in 0..{n_in - 1}")
    if len(np.unique(ids)) != len(ids):
        raise ConformalError("cones name the same vertex twice")
    work = -np.ones(n_in, np.int64)
    work[orig] = np.arange(len(orig))
    S = work[ids]
    if (S < 0).any():
        raise ConformalError("a cone is a vertex in no face")
    if not system.eligible[S].all():
        raise ConformalError("a cone lies on the boundary: cones must be interior vertices")
    if kap is None:
        kap, _ = system.linf_angles(S)
        if kap is None:
            raise ConformalError(f"no cone angles on these {len(S)} vertices satisfy Gauss-Bonnet with every "
                                 "angle positive: add cones")
    elif kap.shape != S.shape or not np.isfinite(kap).all():
        raise ConformalError("cone curvatures must be one finite number per cone")
    return S.astype(np.int64), kap
