"""Small mesh generators shared by the robustness tests (numpy only)."""
import numpy as np

from core.surfaces import make_surface


def uv_sphere(n_lat=16, n_lon=32):
    """Latitude/longitude unit sphere with a vertex at each pole. Returns ``V`` (n,3), ``F`` (m,3)
    counter-clockwise seen from outside, and ``seams`` (k,2): the equator ring (n_lat even) and one
    meridian from pole to pole."""
    th = np.pi * np.arange(1, n_lat) / n_lat
    ph = 2 * np.pi * np.arange(n_lon) / n_lon
    T, P = np.meshgrid(th, ph, indexing='ij')
    ring = np.stack([np.sin(T) * np.cos(P), np.sin(T) * np.sin(P), np.cos(T)], -1).reshape(-1, 3)
    V = np.vstack([[0, 0, 1.0], ring, [0, 0, -1.0]])
    south = len(V) - 1

    def rid(i, j):
        return 1 + i * n_lon + (j % n_lon)

    j = np.arange(n_lon)
    F = [np.stack([np.zeros(n_lon, np.int64), rid(0, j), rid(0, j + 1)], 1)]
    for i in range(n_lat - 2):
        a, b, c, d = rid(i, j), rid(i + 1, j), rid(i + 1, j + 1), rid(i, j + 1)
        F += [np.stack([a, b, c], 1), np.stack([a, c, d], 1)]
    F.append(np.stack([np.full(n_lon, south), rid(n_lat - 2, j + 1), rid(n_lat - 2, j)], 1))
    F = np.concatenate(F).astype(np.int64)
    e = n_lat // 2 - 1
    equator = np.stack([rid(e, j), rid(e, j + 1)], 1)
    mer = np.r_[0, [rid(i, 0) for i in range(n_lat - 1)], south]
    meridian = np.stack([mer[:-1], mer[1:]], 1)
    return V, F, np.concatenate([equator, meridian]).astype(np.int64)


def compact(V, F):
    """Drop vertices in no face; returns ``V``, ``F`` renumbered."""
    used = np.unique(F)
    remap = np.full(len(V), -1, np.int64)
    remap[used] = np.arange(len(used))
    return V[used], remap[F]


def two_holes(name='bump', n=33):
    """Height field ``name`` with two holes (a square and a disk) punched out."""
    V, F = make_surface(name, n)
    inside = ((np.abs(V[:, 0] + 0.9) < 0.4) & (np.abs(V[:, 1]) < 0.4)) | \
             (np.hypot(V[:, 0] - 0.9, V[:, 1] - 0.3) < 0.5)
    return compact(V, F[~inside[F].any(1)])


def grid(n=5):
    """Flat n x n grid on [0,1]^2: ``V`` (n*n,3), ``F`` (2(n-1)^2,3)."""
    V, F = make_surface('flat', n)
    return V, F


def coverage(uv, F, res=256, eps=1e-9):
    """Rasterise triangles ``F`` (m,3) of ``uv`` (n,2) at the centres of a res x res grid over their
    bounding box. Returns (k,) int: for every sample point inside at least one triangle, how many
    triangles contain it. A value above 1 is an overlap. Vectorised over candidate (triangle, sample)
    pairs from each triangle's bounding box."""
    lo, hi = uv.min(0), uv.max(0)
    h = (hi - lo).max() / res
    W = (uv[F] - lo) / h - 0.5                      # sample (i, j) sits at integer coordinates
    bmin = np.ceil(W.min(1)).astype(np.int64)
    bmax = np.floor(W.max(1)).astype(np.int64)
    nx = np.maximum(bmax[:, 0] - bmin[:, 0] + 1, 0)
    ny = np.maximum(bmax[:, 1] - bmin[:, 1] + 1, 0)
    cnt = nx * ny
    t = np.repeat(np.arange(len(F)), cnt)
    k = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    px = bmin[t, 0] + k % nx[t]
    py = bmin[t, 1] + k // nx[t]
    a, b, c = W[t, 0], W[t, 1], W[t, 2]

    def side(p, q):
        return (q[:, 0] - p[:, 0]) * (py - p[:, 1]) - (q[:, 1] - p[:, 1]) * (px - p[:, 0])

    s1, s2, s3 = side(a, b), side(b, c), side(c, a)
    inside = ((s1 > eps) & (s2 > eps) & (s3 > eps)) | ((s1 < -eps) & (s2 < -eps) & (s3 < -eps))
    key = px[inside] * (res + 10) + py[inside]
    return np.unique(key, return_counts=True)[1]


def torus(n_u=24, n_v=12, R=1.0, r=0.35):
    """Closed torus (genus 1): ``V`` (n_u*n_v,3), ``F`` (2*n_u*n_v,3) counter-clockwise from outside."""
    u = 2 * np.pi * np.arange(n_u) / n_u
    v = 2 * np.pi * np.arange(n_v) / n_v
    U, W = np.meshgrid(u, v, indexing='ij')
    V = np.stack([(R + r * np.cos(W)) * np.cos(U), (R + r * np.cos(W)) * np.sin(U), r * np.sin(W)],
                 -1).reshape(-1, 3)
    i, j = np.meshgrid(np.arange(n_u), np.arange(n_v), indexing='ij')
    a = (i * n_v + j).ravel()
    b = (((i + 1) % n_u) * n_v + j).ravel()
    c = (((i + 1) % n_u) * n_v + (j + 1) % n_v).ravel()
    d = (i * n_v + (j + 1) % n_v).ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)]).astype(np.int64)
    return V, F


def needle_mesh(eps, name='bump', n=9):
    """Height field with one quad replaced by four triangles around a vertex at relative distance
    ``eps`` from the middle of the quad's first edge: the triangle on that edge is a needle of aspect
    about 1/eps (a genuine, valid triangle for eps > 0; zero area for eps = 0)."""
    V, F = make_surface(name, n)
    i = j = n // 3
    a, b, c, d = i * n + j, i * n + j + 1, (i + 1) * n + j + 1, (i + 1) * n + j
    F = F[~(np.isin(F, [a, b, c, d]).sum(1) == 3)]
    mid, cen = 0.5 * (V[a] + V[b]), V[[a, b, c, d]].mean(0)
    p = mid + eps * np.linalg.norm(V[b] - V[a]) * (cen - mid) / np.linalg.norm(cen - mid)
    q = len(V)
    return np.vstack([V, p]), np.vstack([F, [[a, b, q], [b, c, q], [c, d, q], [d, a, q]]]).astype(np.int64)


def box(n=10, size=(2.0, 1.0, 0.3)):
    """Closed box [0,sx] x [0,sy] x [0,sz], each face an n x n grid of cells split in two triangles
    (a thin box has sliver triangles on its sides): ``V`` (k,3), ``F`` (m,3), outward."""
    V, F = voxels(np.ones((1, 1, 1), bool), n)
    return V * np.asarray(size, float), F


def bevel_box(segments=3, radius=0.2):
    """The unit cube with its edges and corners rounded (radius ``radius``, ``segments`` rows of quads
    across each bevel), as Blender's Bevel modifier leaves a box: each face's middle is one flat quad
    of two triangles beside thin bevel strips, a coarse CAD-like part. ``V`` (k,3), ``F`` (m,3),
    outward."""
    k = 2 * segments + 1
    V, F = voxels(np.ones((1, 1, 1), bool), k)
    c = np.r_[np.linspace(0.0, radius, segments + 1), np.linspace(1.0 - radius, 1.0, segments + 1)]
    P = c[np.rint(V * k).astype(np.int64)]
    q = np.clip(P, radius, 1.0 - radius)
    d = P - q
    norm = np.linalg.norm(d, axis=1)
    return q + radius * d / np.maximum(norm, 1e-300)[:, None], F


def voxels(filled, k=4):
    """Boundary surface of a set of unit voxels ``filled`` (nx,ny,nz) bool, each square face a k x k
    grid of cells split in two triangles, welded and outward: ``V``, ``F``."""
    filled = np.asarray(filled, bool)
    t = np.linspace(0.0, 1.0, k + 1)
    a, b = np.meshgrid(t, t, indexing='ij')
    P = np.stack([a.ravel(), b.ravel()], 1)
    i, j = np.meshgrid(np.arange(k), np.arange(k), indexing='ij')
    q = (i * (k + 1) + j).ravel()
    Fq = np.r_[np.stack([q, q + k + 1, q + k + 2], 1), np.stack([q, q + k + 2, q + 1], 1)]
    pad = np.pad(filled, 1)
    Vs, Fs = [], []
    for ax in range(3):
        u, v = [d for d in range(3) if d != ax]
        for sgn in (-1, 1):
            empty = ~np.roll(pad, -sgn, axis=ax)[1:-1, 1:-1, 1:-1]
            for c in np.argwhere(filled & empty):
                Q = np.repeat(c[None].astype(float), len(P), 0)
                Q[:, ax] += sgn > 0
                Q[:, u] += P[:, 0]
                Q[:, v] += P[:, 1]
                Fs.append(Fq + len(Vs) * len(P))
                Vs.append(Q)
    V, F = np.concatenate(Vs), np.concatenate(Fs)
    _, first, inv = np.unique(np.round(V * 4 * k).astype(np.int64), axis=0, return_index=True,
                              return_inverse=True)
    V, F = V[first], inv.ravel()[F]
    N = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    probe = np.floor(V[F].mean(1) + 0.25 * N / np.linalg.norm(N, axis=1, keepdims=True)).astype(int)
    ok = (probe >= 0).all(1) & (probe < filled.shape).all(1)
    inward = np.zeros(len(F), bool)
    inward[ok] = filled[tuple(probe[ok].T)]
    F[inward] = F[inward][:, ::-1]
    return V, F


def cow_head():
    """The head of tests/data/cow.obj: faces whose centroid lies at x > 3.2 (horns, ears, muzzle),
    the largest edge-connected piece; a disk of about 2k triangles (a stand-in for a scanned head)."""
    import os

    from core.io.obj import read_obj
    from core.mesh import topology
    m = read_obj(os.path.join(os.path.dirname(os.path.abspath(__file__)), 'data', 'cow.obj'))
    F, _ = m.triangles()
    F = F[m.V[F].mean(1)[:, 0] > 3.2]
    count, label = topology.face_components(F, len(m.V))
    F = F[label == np.argmax(np.bincount(label, minlength=count))]
    used = np.unique(F)
    new = np.full(len(m.V), -1)
    new[used] = np.arange(len(used))
    return m.V[used], new[F]


def capped_cylinder(n=48, rings=12, r=1.0, height=1.5):
    """A closed n-sided prism (a CAD cylinder): ``rings`` rows of quads split in two on the side, each cap
    a fan of n thin triangles (360/n degrees at its centre): ``V`` (n (rings + 1) + 2, 3) with the
    bottom ring first and the bottom and top centres last, ``F`` outward."""
    th = 2 * np.pi * np.arange(n) / n
    z = np.linspace(0.0, height, rings + 1)
    V = np.c_[np.tile(r * np.cos(th), rings + 1), np.tile(r * np.sin(th), rings + 1), np.repeat(z, n)]
    i, j = np.meshgrid(np.arange(n), np.arange(rings), indexing='ij')
    a, b = (j * n + i).ravel(), (j * n + (i + 1) % n).ravel()
    F = [np.c_[a, b, b + n], np.c_[a, b + n, a + n]]
    bot, top = len(V), len(V) + 1
    V = np.r_[V, [[0.0, 0.0, 0.0], [0.0, 0.0, height]]]
    k = np.arange(n)
    F += [np.c_[np.full(n, bot), (k + 1) % n, k],
          np.c_[np.full(n, top), rings * n + k, rings * n + (k + 1) % n]]
    return V, np.concatenate(F)


def closed_end_tube(n=24, rings=40, height=8.0, seed=0):
    """A test tube (a disk): an open n-sided tube of radius 1 and ``height``, closed at the top by a fan,
    its inner rings moved along the axis by up to 0.3 of their spacing and its quads split along random
    diagonals (an irregular triangulation). Its conformal map shrinks the closed end by about
    ``exp(-height)``. Returns V ((rings + 1) n + 1, 3) with the open rim first, F (2 rings n + n, 3)."""
    rng = np.random.default_rng(seed)
    th = 2 * np.pi * np.arange(n) / n
    z = np.repeat(np.linspace(0.0, height, rings + 1), n).reshape(rings + 1, n)
    z[1:-1] += rng.uniform(-0.3, 0.3, (rings - 1, n)) * (height / rings)
    V = np.c_[np.tile(np.cos(th), rings + 1), np.tile(np.sin(th), rings + 1), z.ravel()]
    i, j = np.meshgrid(np.arange(n), np.arange(rings), indexing='ij')
    a, b = (j * n + i).ravel(), (j * n + (i + 1) % n).ravel()
    flip = (rng.random(len(a)) < 0.5)[:, None]
    lower = np.where(flip, np.c_[a, b, a + n], np.c_[a, b, b + n])
    upper = np.where(flip, np.c_[b, b + n, a + n], np.c_[a, b + n, a + n])
    k = np.arange(n)
    cap = np.c_[np.full(n, len(V)), rings * n + k, rings * n + (k + 1) % n]
    return np.r_[V, [[0.0, 0.0, height]]], np.concatenate([lower, upper, cap])


def finger(n=65, height=1.2, width=0.2):
    """A square [-1, 1]^2 on an n x n grid of vertices (quads split along one diagonal) lifted into a
    narrow bump, a finger: ``z = height exp(-((x - 0.3)^2 + y^2) / width^2)``. Its conformal map shrinks
    the finger's top about 1000-fold (mu ratio 8e-4 at n = 65), so that a grid the user gives cannot
    resolve it there (deep spots) while it resolves the rest. Returns V (n^2, 3) (row-major in y, x),
    F (2 (n - 1)^2, 3)."""
    x, y = np.meshgrid(np.linspace(-1.0, 1.0, n), np.linspace(-1.0, 1.0, n))
    z = height * np.exp(-((x - 0.3) ** 2 + y ** 2) / width ** 2)
    i, j = np.meshgrid(np.arange(n - 1), np.arange(n - 1))
    a = (j * n + i).ravel()
    F = np.r_[np.c_[a, a + 1, a + n + 1], np.c_[a, a + n + 1, a + n]]
    return np.c_[x.ravel(), y.ravel(), z.ravel()], F.astype(np.int64)


def icosphere(level=3):
    """Unit sphere (V (n,3), F (m,3), counter-clockwise seen from outside): the icosahedron with every
    triangle split in four ``level`` times, the new vertices pushed onto the sphere."""
    t = (1 + 5 ** 0.5) / 2
    V = np.array([[-1, t, 0], [1, t, 0], [-1, -t, 0], [1, -t, 0], [0, -1, t], [0, 1, t], [0, -1, -t],
                  [0, 1, -t], [t, 0, -1], [t, 0, 1], [-t, 0, -1], [-t, 0, 1]], float)
    F = np.array([[0, 11, 5], [0, 5, 1], [0, 1, 7], [0, 7, 10], [0, 10, 11], [1, 5, 9], [5, 11, 4],
                  [11, 10, 2], [10, 7, 6], [7, 1, 8], [3, 9, 4], [3, 4, 2], [3, 2, 6], [3, 6, 8], [3, 8, 9],
                  [4, 9, 5], [2, 4, 11], [6, 2, 10], [8, 6, 7], [9, 8, 1]])
    V = V / np.linalg.norm(V, axis=1)[:, None]
    for _ in range(level):
        E = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
        ue, inv = np.unique(E, axis=0, return_inverse=True)
        mid = V[ue].mean(1)
        V = np.concatenate([V, mid / np.linalg.norm(mid, axis=1)[:, None]])
        a, b, c = F.T
        ab, bc, ca = (len(V) - len(ue) + inv.ravel()).reshape(3, -1)
        F = np.concatenate([np.stack(x, 1) for x in ((a, ab, ca), (ab, b, bc), (ca, bc, c), (ab, bc, ca))])
    return V, F


def jagged_cap(level=5, jitter=0.02, seed=1):
    """A hemisphere of the ``icosphere`` tilted at random and cut along its triangles (those whose
    centroid lies above the cut plane): a disk whose boundary zigzags, like a scan cut out of a bigger
    one; vertices jittered by ``jitter`` mean edge lengths. Returns V (n,3), F (m,3)."""
    V, F = icosphere(level)
    rng = np.random.default_rng(seed)
    V = V @ np.linalg.qr(rng.standard_normal((3, 3)))[0].T
    used, Fl = np.unique(F[V[F].mean(1)[:, 2] > 0.0], return_inverse=True)
    V, F = V[used], Fl.reshape(-1, 3)
    e = np.linalg.norm(V[F[:, 0]] - V[F[:, 1]], axis=1).mean()
    return V + rng.standard_normal(V.shape) * jitter * e, F


def scan_patch(n=1500, seed=3):
    """A scan-like open disk: ``n`` jittered points in the unit disk, denser (about 3x) around
    (0.35, 0.35), Delaunay-triangulated and lifted by a smooth height field (a dome with a ridge and a
    dimple) plus noise of 0.2 % of the size. The dense patch has small triangles where the map's grid
    cell is coarse in surface units, so a source there takes the geodesic solver's refined seed while
    one elsewhere does not. Returns V (k,3), F (m,3) counter-clockwise."""
    from scipy.spatial import Delaunay
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1, 1, (8 * n, 2))
    P = P[(P ** 2).sum(1) < 0.95]
    dens = 1 + 2 * np.exp(-((P - 0.35) ** 2).sum(1) / 0.03)
    P = P[rng.uniform(size=len(P)) < dens / dens.max()][:n]
    t = np.linspace(0, 2 * np.pi, int(4 * np.sqrt(n)), endpoint=False)
    P = np.vstack([np.c_[np.cos(t), np.sin(t)], P])
    x, y = P[:, 0], P[:, 1]
    z = 0.6 * np.sqrt(np.maximum(1 - 0.8 * (x ** 2 + y ** 2), 0))
    z += 0.25 * np.exp(-x ** 2 / 0.01 - (y + 0.05) ** 2 / 0.12)
    z -= 0.12 * np.exp(-((x + 0.35) ** 2 + (y - 0.3) ** 2) / 0.02)
    V = np.c_[P, z + rng.normal(scale=0.002, size=len(P))]
    F = Delaunay(P).simplices
    e1, e2 = P[F[:, 1]] - P[F[:, 0]], P[F[:, 2]] - P[F[:, 0]]
    A = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]                  # the signed area (2D cross product)
    return V, np.where((A < 0)[:, None], F[:, [0, 2, 1]], F)


def steep_rim(n=3000, seed=1, power=0.25, height=0.8):
    """A scan-like disk whose rim stands vertical: ``n`` random points in the unit disk (and a ring of
    ``4 sqrt(n)`` on its edge), Delaunay-triangulated in the plane and lifted to
    ``z = height (1 - r^2)^power`` (``power`` 0.5, ``height`` 1: a hemisphere). Near the rim the lift
    stretches the plane's triangles into needles (corners down to a fraction of a degree). Returns V
    (k,3), F (m,3) counter-clockwise in the plane."""
    from scipy.spatial import Delaunay
    rng = np.random.default_rng(seed)
    P = rng.uniform(-1, 1, (3 * n, 2))
    P = P[(P ** 2).sum(1) < 0.97][:n]
    t = np.linspace(0, 2 * np.pi, int(4 * np.sqrt(n)), endpoint=False)
    P = np.vstack([np.c_[np.cos(t), np.sin(t)], P])
    from core.surfaces import _ccw
    z = height * np.maximum(1 - (P ** 2).sum(1), 0) ** power
    return np.c_[P, z], _ccw(P, Delaunay(P).simplices)



def cylinder_hull(n=3000, seed=1):
    """A closed CAD-like part of slivers: ``core.surfaces.hull_part('cylinder', n, seed)``, smaller than
    the benchmark's. Returns ``V`` (k,3), ``F`` (m,3)."""
    from core.surfaces import hull_part
    return hull_part('cylinder', n, seed)


def with_coincident_vertices(V, F, count=100, seed=0):
    """``V``, ``F`` (a closed or open manifold mesh) with ``count`` vertices doubled where a mesher
    leaves them (marching cubes does, thousands of times): for an interior edge (a, b) with faces
    (a, b, c) and (b, a, d), a new vertex a' at a's point takes a's place in those two faces, and the
    zero-area triangles (a', c, a) and (a, d, a') close the gap, joined by the zero-length edge a a'.
    The edges are chosen with no vertex in common. Returns ``V2`` (n + k,3), ``F2`` (m + 2k,3) and
    ``twin`` (k,): the vertex a each new one copies."""
    rng = np.random.default_rng(seed)
    F = np.array(F, np.int64)
    m = len(F)
    H = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    third = np.concatenate([F[:, 2], F[:, 0], F[:, 1]])
    face = np.tile(np.arange(m), 3)
    key = {(a, b): (f, c) for (a, b), f, c in zip(H.tolist(), face.tolist(), third.tolist())}
    used = np.zeros(len(V), bool)
    Vn, Fn, twin = [np.asarray(V, np.float64)], [], []
    n = len(V)
    for i in rng.permutation(len(H)).tolist():
        a, b = H[i]
        if (b, a) not in key:
            continue
        (f1, c), (f2, d) = key[(a, b)], key[(b, a)]
        if used[[a, b, c, d]].any():
            continue
        used[[a, b, c, d]] = True
        F[f1][F[f1] == a] = n
        F[f2][F[f2] == a] = n
        Fn += [[n, c, a], [a, d, n]]
        twin.append(a)
        n += 1
        if len(twin) == count:
            break
    twin = np.array(twin, np.int64)
    return np.vstack(Vn + [np.asarray(V)[twin]]), np.vstack([F, np.array(Fn, np.int64)]), twin
