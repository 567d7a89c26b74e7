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
# more plane cuts of the public meshes, by name: (mesh, direction, height). Disks with one or two
# boundary loops (the rocker arm's and cheburashka's halves are annuli), or several (the ogre's head,
# five holes); the cow's rear keeps its one non-manifold vertex (two fans touching: a pinch)
PART_CUTS = {'spot-rear': ('spot', (0, 0, -1), 0.0), 'cow-rear': ('cow', (-1, 0, 0), 0.5),
             'cheburashka-half': ('cheburashka', (0, 0, 1), 0.5),
             'rocker-half': ('rocker-arm', (0, 0, 1), 0.1), 'ogre-head': ('ogre', (0, 1, 0), 22.0)}


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



def scan_like(name):
    """The scan-like meshes of ``core.surfaces.scan_like`` (``SCANS``)."""
    from core.surfaces import scan_like as make
    return make(name)


SCANS = ('facescan', 'faceholes', 'deepcap', 'steepface')
HULLS = ('cylinderhull', 'boxhull')  # closed CAD-like parts of slivers (``core.surfaces.hull_part``)
