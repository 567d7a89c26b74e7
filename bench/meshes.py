"""Where the benchmarks find the public test meshes (the corpus described in docs/robustness.md).

The meshes are not part of the repository. ``corpus_dir()`` is the folder named by the environment
variable ``CONFORMAL_MESHES``, or else the ``shared/meshes`` folder that sits beside the repository in
the developers' workspace. Benchmarks say so and carry on with what they have when it is missing;
the tests never use it (their meshes are copies in tests/data/)."""
import os

ROOT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))


def corpus_dir() -> str:
    """The folder of the public test meshes (it may not exist)."""
    return os.environ.get('CONFORMAL_MESHES') or os.path.join(os.path.dirname(ROOT), 'shared', 'meshes')


def loop_subdivide(V, F):
    """One step of Loop's subdivision of a triangle mesh with boundary: ``V`` (n,3), ``F`` (m,3) ->
    (n + e, 3), (4m, 3). Even vertices move by Loop's weights (3/16 at valence 3, else 3/(8k)), odd
    ones are 3/8, 3/8, 1/8, 1/8 of their edge's ends and opposite corners; on the boundary the
    curve rules (1/8, 3/4, 1/8 and midpoints). The first n vertices are the input's."""
    import numpy as np
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    n = len(V)
    H = np.sort(np.stack([F, F[:, [1, 2, 0]]], 2).reshape(-1, 2), 1)     # edge (k, k+1) of each face
    E, inv, count = np.unique(H, axis=0, return_inverse=True, return_counts=True)
    inv = inv.ravel()
    border = count == 1
    mid = 3 / 8 * (V[E[:, 0]] + V[E[:, 1]])
    np.add.at(mid, inv, V[F[:, [2, 0, 1]].ravel()] / 8)                    # the corner opposite each edge
    mid[border] = 0.5 * (V[E[border, 0]] + V[E[border, 1]])
    valence = np.bincount(E.ravel(), minlength=n)
    ring = np.zeros_like(V)
    np.add.at(ring, E[:, 0], V[E[:, 1]])
    np.add.at(ring, E[:, 1], V[E[:, 0]])
    beta = np.where(valence == 3, 3 / 16, 3 / (8 * np.maximum(valence, 1)))
    even = (1 - valence * beta)[:, None] * V + beta[:, None] * ring
    on_border = np.zeros(n, bool)
    on_border[E[border].ravel()] = True
    side = np.zeros_like(V)
    np.add.at(side, E[border, 0], V[E[border, 1]])
    np.add.at(side, E[border, 1], V[E[border, 0]])
    even[on_border] = 0.75 * V[on_border] + side[on_border] / 8
    ab, bc, ca = (inv.reshape(-1, 3) + n).T
    a, b, c = F.T
    F2 = np.concatenate([np.c_[a, ab, ca], np.c_[b, bc, ab], np.c_[c, ca, bc], np.c_[ab, bc, ca]])
    return np.r_[even, mid], F2


# head-like disks cut from the public meshes (not the held-out scans): direction, height (mesh units)
HEAD_CUTS = {'spot': ((0, 0, 1), 0.546), 'cow': ((1, 0, 0), 3.2), 'cheburashka': ((0, 1, 0), 0.71)}


def cut_disk(V, F, direction, height):
    """The part of a mesh beyond a plane: the faces whose centroid lies above ``height`` (mesh units)
    along ``direction`` (3,), their largest edge-connected piece, re-indexed. Returns (V', F'). With
    the benchmarks' settings (``bench/cones.py --cuts``) the pieces are disks: head-like patches of
    the public meshes."""
    import numpy as np
    from core.mesh import topology
    d = np.asarray(direction, np.float64)
    d = d / np.linalg.norm(d)
    keep = F[V[F].mean(1) @ d > height]
    _, labels = topology.face_components(keep, len(V))
    keep = keep[labels == np.bincount(labels).argmax()]
    used = np.unique(keep)
    new = np.full(len(V), -1, np.int64)
    new[used] = np.arange(len(used))
    return V[used], new[keep]


def _ellipse_points(rng, n, a=1.0, b=1.3):
    """``n`` random points in the ellipse ``(x/a)^2 + (y/b)^2 < 0.97``, about 3x denser around
    (0.3, 0.4), after a ring of ``4 sqrt(n)`` points on the ellipse itself. Returns (k,2)."""
    import numpy as np
    P = rng.uniform(-1, 1, (n * 3, 2)) * [a, b]
    P = P[(P[:, 0] / a) ** 2 + (P[:, 1] / b) ** 2 < 1]
    dens = 1 + 2 * np.exp(-((P[:, 0] - 0.3) ** 2 + (P[:, 1] - 0.4) ** 2) / 0.05)
    P = P[rng.uniform(size=len(P)) < dens / dens.max()][:n]
    t = np.linspace(0, 2 * np.pi, int(np.sqrt(n) * 4), endpoint=False)
    P = P[(P[:, 0] / a) ** 2 + (P[:, 1] / b) ** 2 < 0.97]
    return np.vstack([np.c_[a * np.cos(t), b * np.sin(t)], P])


def _face_height(P):
    """A face-like height field over (k,2) points: a dome, a nose ridge, two eye dimples, lips."""
    import numpy as np
    x, y = P[:, 0], P[:, 1]
    z = 0.6 * np.sqrt(np.maximum(1 - x ** 2 - 0.8 * y ** 2 / 1.69, 0))
    z += 0.25 * np.exp(-(x ** 2) / 0.01 - ((y + 0.05) ** 2) / 0.12) * (y > -0.4)
    z -= 0.12 * (np.exp(-((x - 0.35) ** 2 + (y - 0.3) ** 2) / 0.02)
                 + np.exp(-((x + 0.35) ** 2 + (y - 0.3) ** 2) / 0.02))
    z += 0.06 * np.exp(-(x ** 2) / 0.05 - ((y + 0.6) ** 2) / 0.01)
    return z


def _ccw(P, F):
    """The triangles ``F`` (m,3) turned counter-clockwise in the plane of the points ``P`` (k,2)."""
    import numpy as np
    A = (P[F[:, 1], 0] - P[F[:, 0], 0]) * (P[F[:, 2], 1] - P[F[:, 0], 1]) - \
        (P[F[:, 1], 1] - P[F[:, 0], 1]) * (P[F[:, 2], 0] - P[F[:, 0], 0])
    return np.where((A < 0)[:, None], F[:, [0, 2, 1]], F)


def scan_like(name):
    """Scan-like open meshes of our own, standing in for the held-out scans (which we do not use):
    random points with a denser patch, Delaunay-triangulated in the plane and lifted, with noise of
    0.2 % of the size. 'facescan' (5.4k vertices, 10.4k triangles): a face-like height field over an
    ellipse; 'faceholes': the same with the eye regions cut out (two holes); 'deepcap': a cap of
    0.72 pi of a sphere (4.4k vertices, 8.6k triangles). Returns (V, F) or None for another name."""
    import numpy as np
    from scipy.spatial import Delaunay
    rng = np.random.default_rng(7)
    P = _ellipse_points(rng, 6000)
    F = _ccw(P, Delaunay(P).simplices)
    V = np.c_[P, _face_height(P) + rng.normal(scale=0.002, size=len(P))]
    if name == 'facescan':
        return V, F
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
        F = F[~eye]
        used = np.unique(F)
        remap = np.full(len(P), -1)
        remap[used] = np.arange(len(used))
        P, F = P[used], _ccw(P[used], remap[F])
        return np.c_[P, _face_height(P) + rng.normal(scale=0.002, size=len(P))], F
    return None


SCANS = ('facescan', 'faceholes', 'deepcap')
