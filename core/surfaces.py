"""The test surfaces of docs/math.md §7: height fields z = f(x, y) on an n x n grid over [-2,2]^2."""
import numpy as np

from .errors import ConformalError
from .mesh.subdivide import subdivide  # noqa: F401  (the test surfaces' subdivision, kept here)

SURFACES = {
    'bump': lambda x, y: np.exp(-0.2 * x**2 - 0.5 * y**2),
    'bump3': lambda x, y: 3 * np.exp(-0.2 * x**2 - 0.5 * y**2),
    'edgebump': lambda x, y: 1.5 * np.exp(-((x - 1.6)**2 + y**2) / 0.3),
    'ridge': lambda x, y: np.exp(-4 * (x - 1.2)**2) + np.exp(-4 * (y + 1.2)**2),
    'saddle': lambda x, y: 0.4 * (x**2 - y**2),
    'flat': lambda x, y: 0.0 * x,
    # beyond the paper's surfaces: checks of generality, on shapes the method was not tuned on
    'waves': lambda x, y: 0.3 * np.sin(2 * x) * np.cos(1.5 * y),
    'monkey': lambda x, y: 0.1 * (x**3 - 3 * x * y**2),
    'cliff': lambda x, y: 0.8 * np.tanh(3 * (x + y - 1.5)),
}


def grid_faces(n):
    """(2(n-1)^2, 3) int64 triangles of the n x n grid: quads split as (a,b,c), (a,c,d)."""
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1), indexing='ij')
    a = (i * n + j).ravel()
    b, c, d = a + 1, a + n + 1, a + n
    return np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)


def make_surface(name, n):
    """Surface ``name`` on an n x n grid: ``V`` (n*n,3) float64, ``F`` (2(n-1)^2,3) int64. Vertex
    k = i*n + j sits at x = t[j], y = t[i], t = linspace(-2, 2, n)."""
    if name not in SURFACES:
        raise ConformalError(f"unknown surface {name!r}: choose one of {', '.join(SURFACES)}")
    if int(n) < 2:
        raise ConformalError(f"grid size must be at least 2, got {n}")
    n = int(n)
    t = np.linspace(-2, 2, n)
    X, Y = np.meshgrid(t, t)          # X[i,j] = t[j], Y[i,j] = t[i]
    Z = SURFACES[name](X, Y)
    V = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1).astype(np.float64)
    return V, grid_faces(n)


# --- closed test shapes (sphere mode) --------------------------------------------------------------
def icosphere(freq=8):
    """Geodesic sphere: each icosahedron face split into ``freq**2`` triangles, projected to the unit
    sphere. Returns ``V`` (10 freq^2 + 2, 3) and ``F`` (20 freq^2, 3), counter-clockwise seen from
    outside."""
    k = int(freq)
    if k < 1:
        raise ConformalError("icosphere frequency must be at least 1")
    g = (1 + 5 ** 0.5) / 2
    P = np.array([[-1, g, 0], [1, g, 0], [-1, -g, 0], [1, -g, 0], [0, -1, g], [0, 1, g],
                  [0, -1, -g], [0, 1, -g], [g, 0, -1], [g, 0, 1], [-g, 0, -1], [-g, 0, 1]], float)
    T = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8],
                  [3, 8, 9], [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    ii, jj = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing='ij')
    keep = ii + jj <= k
    ii, jj = ii[keep], jj[keep]
    idx = -np.ones((k + 1, k + 1), np.int64)
    idx[ii, jj] = np.arange(len(ii))
    a, b = np.meshgrid(np.arange(k), np.arange(k), indexing='ij')
    up = a + b <= k - 1
    dn = a + b <= k - 2
    loc = np.r_[np.stack([idx[a[up], b[up]], idx[a[up] + 1, b[up]], idx[a[up], b[up] + 1]], 1),
                np.stack([idx[a[dn] + 1, b[dn]], idx[a[dn] + 1, b[dn] + 1], idx[a[dn], b[dn] + 1]], 1)]
    w = np.stack([k - ii - jj, ii, jj], 1) / k
    pts = np.einsum('pk,fkd->fpd', w, P[T]).reshape(-1, 3)
    faces = (loc[None] + (np.arange(len(T)) * len(ii))[:, None, None]).reshape(-1, 3)
    pts /= np.linalg.norm(pts, axis=1)[:, None]
    _, first, inv = np.unique(np.round(pts, 9), axis=0, return_index=True, return_inverse=True)
    order = np.argsort(first)
    rank = np.empty_like(order)
    rank[order] = np.arange(len(order))
    V = pts[first[order]]
    F = rank[inv.ravel()][faces]
    nrm = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    out = (nrm * V[F].mean(1)).sum(1) < 0
    F[out] = F[out][:, ::-1]
    return V, F


def blob(freq=24, bumps=((0, 0, 1, 1.2), (1, 0, 0, 0.8), (0, -1, 0, 1.0), (-0.6, 0.6, -0.5, 0.9)),
         width=0.12):
    """Star-shaped sphere with protrusions: the icosphere scaled radially by ``1 + sum h_k exp(-(1 -
    d_k . x) / width)`` for bumps ``(dx, dy, dz, h)``. Returns ``V``, ``F`` like ``icosphere``."""
    V, F = icosphere(freq)
    r = np.ones(len(V))
    for dx, dy, dz, h in bumps:
        d = np.array([dx, dy, dz], float)
        d /= np.linalg.norm(d)
        r += h * np.exp(-(1.0 - V @ d) / width)
    return V * r[:, None], F


def _ellipse_points(rng, n, a=1.0, b=1.3):
    """``n`` random points in the ellipse ``(x/a)^2 + (y/b)^2 < 0.97``, about 3x denser around
    (0.3, 0.4), after a ring of ``4 sqrt(n)`` points on the ellipse itself. Returns (k,2)."""
    P = rng.uniform(-1, 1, (n * 3, 2)) * [a, b]
    P = P[(P[:, 0] / a) ** 2 + (P[:, 1] / b) ** 2 < 1]
    dens = 1 + 2 * np.exp(-((P[:, 0] - 0.3) ** 2 + (P[:, 1] - 0.4) ** 2) / 0.05)
    P = P[rng.uniform(size=len(P)) < dens / dens.max()][:n]
    t = np.linspace(0, 2 * np.pi, int(np.sqrt(n) * 4), endpoint=False)
    P = P[(P[:, 0] / a) ** 2 + (P[:, 1] / b) ** 2 < 0.97]
    return np.vstack([np.c_[a * np.cos(t), b * np.sin(t)], P])


def _face_height(P):
    """A face-like height field over (k,2) points: a dome, a nose ridge, two eye dimples, lips."""
    x, y = P[:, 0], P[:, 1]
    z = 0.6 * np.sqrt(np.maximum(1 - x ** 2 - 0.8 * y ** 2 / 1.69, 0))
    z += 0.25 * np.exp(-(x ** 2) / 0.01 - ((y + 0.05) ** 2) / 0.12) * (y > -0.4)
    z -= 0.12 * (np.exp(-((x - 0.35) ** 2 + (y - 0.3) ** 2) / 0.02)
                 + np.exp(-((x + 0.35) ** 2 + (y - 0.3) ** 2) / 0.02))
    z += 0.06 * np.exp(-(x ** 2) / 0.05 - ((y + 0.6) ** 2) / 0.01)
    return z


def _compact(V, F):
    """``(V[used], F)`` renumbered: the vertices of no triangle dropped."""
    used = np.unique(F)
    new = np.full(len(V), -1, np.int64)
    new[used] = np.arange(len(used))
    return V[used], new[F]


def _ccw(P, F):
    """The triangles ``F`` (m,3) turned counter-clockwise in the plane of the points ``P`` (k,2)."""
    A = (P[F[:, 1], 0] - P[F[:, 0], 0]) * (P[F[:, 2], 1] - P[F[:, 0], 1]) - \
        (P[F[:, 1], 1] - P[F[:, 0], 1]) * (P[F[:, 2], 0] - P[F[:, 0], 0])
    return np.where((A < 0)[:, None], F[:, [0, 2, 1]], F)


def scan_like(name):
    """Scan-like open meshes, standing in for real scans in the benchmarks and tests:
    random points with a denser patch, Delaunay-triangulated in the plane and lifted, with noise of
    0.2 % of the size. 'facescan' (5.4k vertices, 10.4k triangles): a face-like height field over an
    ellipse; 'faceholes': the same with the eye regions cut out (two holes); 'deepcap': a cap of
    0.72 pi of a sphere (4.4k vertices, 8.6k triangles); 'steepface': the face with three times the
    relief over other random points (10.4k triangles), so that its flanks stand nearly vertical and the
    plane's triangles become needles there, as on a range scan seen from the front. Returns (V, F) or
    None for another name."""
    from scipy.spatial import Delaunay
    rng = np.random.default_rng(7)
    P = _ellipse_points(rng, 6000)
    F = _ccw(P, Delaunay(P).simplices)
    V = np.c_[P, _face_height(P) + rng.normal(scale=0.002, size=len(P))]
    if name == 'facescan':
        return V, F
    if name == 'steepface':
        rng = np.random.default_rng(3)
        P = _ellipse_points(rng, 6000)
        V = np.c_[P, 3 * _face_height(P) + rng.normal(scale=0.003, size=len(P))]
        return V, _ccw(P, Delaunay(P).simplices)
    Q = _ellipse_points(rng, 5000, 1.0, 1.0)
    if name == 'deepcap':
        r, ph = np.linalg.norm(Q, axis=1), np.arctan2(Q[:, 1], Q[:, 0])
        th = r * 0.72 * np.pi
        V2 = np.c_[np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)]
        return V2 * (1 + 0.003 * rng.normal(size=(len(Q), 1))), _ccw(Q, Delaunay(Q).simplices)
    if name == 'faceholes':
        rng = np.random.default_rng(11)
        P = _ellipse_points(rng, 6000)
        F = Delaunay(P).simplices
        C = P[F].mean(1)
        eye = ((C[:, 0] - 0.35) ** 2 + (C[:, 1] - 0.3) ** 2 < 0.012) | \
            ((C[:, 0] + 0.35) ** 2 + (C[:, 1] - 0.3) ** 2 < 0.012)
        P, F = _compact(P, F[~eye])
        F = _ccw(P, F)
        return np.c_[P, _face_height(P) + rng.normal(scale=0.002, size=len(P))], F
    return None


def hull_part(kind='cylinder', n=6000, seed=1, p=16.0):
    """A closed CAD-like part standing in for CAD meshes in the benchmarks and tests: the convex hull of
    ``n`` random points on a rounded solid whose faces are nearly flat (the superellipse of exponent
    ``p``), so its triangles are what a hull of random points gives (slivers down to a thousandth of
    a degree over most of the area). ``kind`` 'cylinder' (radius 0.5, height 2:
    ``(r / 0.5)^p + |z|^p = 1``) or 'box' (2 x 1.2 x 0.7). Returns ``V`` (k,3), ``F`` (m,3)
    counter-clockwise seen from outside, every vertex used; the box, like a CAD export, also has a
    few zero-area triangles (qhull's triangulated flat facets) wound either way."""
    from scipy.spatial import ConvexHull
    D = np.random.default_rng(seed).normal(size=(n, 3))
    if kind == 'cylinder':
        s = ((np.hypot(D[:, 0], D[:, 1]) / 0.5) ** p + np.abs(D[:, 2]) ** p) ** (1 / p)
    elif kind == 'box':
        s = ((np.abs(D) / [1.0, 0.6, 0.35]) ** p).sum(1) ** (1 / p)
    else:
        raise ConformalError(f"unknown hull part {kind!r}: use 'cylinder' or 'box'")
    X = D / s[:, None]
    hull = ConvexHull(X)
    F = hull.simplices
    # wound by qhull's outward facet normals (a sliver's own cross product can point either way)
    N = np.cross(X[F[:, 1]] - X[F[:, 0]], X[F[:, 2]] - X[F[:, 0]])
    F = np.where(((N * hull.equations[:, :3]).sum(1) < 0)[:, None], F[:, [0, 2, 1]], F)
    return _compact(X, F)
