"""Input checks. Each failure raises ``ConformalError`` with what is wrong and what to do."""
from dataclasses import dataclass, field

import numpy as np

from ..errors import ConformalError
from .geometry import face_areas, norm3
from . import topology

DEFAULT_MAX_FACES = 5_000_000


@dataclass
class MeshInfo:
    """What ``check_mesh`` found: counts, the boundary loops (each (k,) int64, surface on the left),
    the Euler characteristic and ``parts``, the number of edge-connected pieces."""
    n_vertices: int
    n_faces: int
    loops: list = field(default_factory=list)
    euler: int = 0
    parts: int = 1

    @property
    def boundary(self):
        """(k,) int64 vertices of the outer (longest) boundary loop, or an empty array."""
        return self.loops[0] if self.loops else np.zeros(0, np.int64)


def _examples(idx, k=5):
    idx = np.asarray(idx).ravel()[:k].tolist()
    return ', '.join(str(i) for i in idx)


def _plural(n, word):
    if n == 1:
        return f"1 {word}"
    return f"{n} {word[:-2]}ices" if word.endswith('vertex') else f"{n} {word}s"


def as_arrays(V, F):
    """Convert to ``V`` (n,3) float64 and ``F`` (m,3) int64, or raise ``ConformalError``."""
    try:
        V = np.asarray(V, dtype=np.float64)
        F = np.asarray(F, dtype=np.int64)
    except (TypeError, ValueError) as exc:
        raise ConformalError(f"mesh arrays are not numeric: {exc}") from None
    if V.size == 0 or F.size == 0:
        raise ConformalError("mesh is empty: it has no vertices or no faces; give a mesh with at least "
                             "one triangle", 'empty_mesh')
    if V.ndim != 2 or V.shape[1] != 3:
        raise ConformalError(f"vertex array must have shape (n,3), got {V.shape}")
    if F.ndim != 2 or F.shape[1] != 3:
        raise ConformalError(f"face array must have shape (m,3) triangles, got {F.shape}")
    return V, F


def normalise_scale(V):
    """``V`` (n,3) finite, moved to the centre of its bounding box and divided by its largest half
    extent, so that lengths are O(1) whatever the mesh's units (1e-100 or 1e100), without overflow.
    Returns (``Vn`` (n,3) float64 in [-1,1]^3, ``size`` the half extent in mesh units, so that
    ``V ~ centre + size * Vn``); a single point gives (``V``, 1.0)."""
    lo, hi = V.min(0), V.max(0)
    centre = lo / 2 + hi / 2
    size = float(np.max(hi / 2 - lo / 2))
    if not size > 0:
        return V, 1.0
    return (V / 2 - centre / 2) / size * 2, size


def degenerate_faces(V, F, rel=1e-12):
    """(m,) bool: triangles of ``F`` (m,3) with a repeated vertex or an area at most ``rel`` times the
    squared mean edge length (scale-free: measured on the normalised mesh)."""
    F = np.asarray(F, np.int64)
    rep = topology.repeated_vertex(F)
    Vn = normalise_scale(np.asarray(V, np.float64))[0]   # the test must not under- or overflow
    A = face_areas(Vn, F)
    el = norm3(Vn[F[:, 1]] - Vn[F[:, 0]])
    scale2 = max(float(np.mean(el)) ** 2, np.finfo(float).tiny)
    return rep | (A <= rel * scale2)


def check_arrays(V, F, max_faces=DEFAULT_MAX_FACES):
    """The checks that have no repair: numeric arrays of the right shapes, not empty, at most
    ``max_faces`` triangles, face indices of existing vertices, finite coordinates. Returns ``V`` (n,3)
    float64 and ``F`` (m,3) int64; raises ``ConformalError``."""
    V, F = as_arrays(V, F)
    n, m = len(V), len(F)
    if max_faces is not None and m > max_faces:
        raise ConformalError(f"mesh has {m:,} triangles, over the limit of {max_faces:,}", 'too_large',
                             'raise_limit')
    if F.min() < 0 or F.max() >= n:
        bad = np.nonzero((F < 0).any(1) | (F >= n).any(1))[0]
        raise ConformalError(f"mesh has {_plural(len(bad), 'face')} with indices of missing vertices "
                             f"(faces {_examples(bad)}): face indices must lie in 0..{n - 1}")
    finite = np.isfinite(V).all(axis=1)
    if not finite.all():
        bad = np.nonzero(~finite)[0]
        raise ConformalError(f"mesh has {_plural(len(bad), 'vertex')} with NaN or infinite coordinates "
                             f"(vertices {_examples(bad)})", 'bad_coordinates', 'fix_coordinates')
    return V, F


def loose_edge_count(E, F) -> int:
    """How many edges of ``E`` (k,2) int belong to no triangle of ``F`` (m,3)."""
    E = np.asarray(E, dtype=np.int64).reshape(-1, 2)
    if len(E) == 0:
        return 0
    F = np.asarray(F, dtype=np.int64)
    n = int(max(E.max(), F.max() if F.size else 0)) + 1
    H = np.sort(topology.halfedges(F), axis=1) if F.size else np.zeros((0, 2), np.int64)
    return int((~np.isin(np.sort(E, axis=1) @ np.array([n, 1]), H @ np.array([n, 1]))).sum())


def check_mesh(V, F, kind='disk', max_faces=DEFAULT_MAX_FACES, allow_loose=False, allow_parts=False,
               allow_degenerate=False) -> MeshInfo:
    """Validate a triangle mesh for ``kind`` 'disk' (one boundary loop, Euler characteristic 1),
    'sphere' (closed, genus 0) or 'surface' (manifold only). ``allow_parts`` (only with 'surface')
    accepts several connected pieces. ``allow_degenerate`` accepts zero-area triangles with three
    different vertices (the caller handles them, e.g. by intrinsic mollification). Returns ``MeshInfo``."""
    V, F = check_arrays(V, F, max_faces)
    n, m = len(V), len(F)
    rep = topology.repeated_vertex(F)
    zero = rep if allow_degenerate else degenerate_faces(V, F)
    if zero.any():
        bad = np.nonzero(zero)[0]
        raise ConformalError(f"mesh has {_plural(len(bad), 'zero-area face')} (faces {_examples(bad)}): "
                             "merge vertices by distance or dissolve degenerate faces", 'degenerate')
    bad = topology.duplicate_rows(F)
    if len(bad):
        raise ConformalError(f"mesh has {_plural(len(bad), 'duplicate face')} (faces {_examples(bad)}): "
                             "delete the duplicate faces (merge by distance)", 'bad_topology')
    E, ecount, twin, same_way = topology.edge_table(F, n)     # one sort for the edge checks below
    if (ecount > 2).any():
        bad = E[ecount > 2]
        ex = ', '.join(f"({a}, {b})" for a, b in bad[:3].tolist())
        raise ConformalError(f"mesh has {_plural(len(bad), 'non-manifold edge')} shared by 3 or more "
                             f"faces, e.g. {ex}: select them (Select All by Trait > Non Manifold) and "
                             "separate or delete faces", 'bad_topology')
    if same_way:
        H = topology.halfedges(F)
        uh, hc = np.unique(H[:, 0] * n + H[:, 1], return_counts=True)
        k = uh[hc > 1][:3]
        ex = ', '.join(f"({a}, {b})" for a, b in zip((k // n).tolist(), (k % n).tolist()))
        raise ConformalError(f"faces are not consistently oriented ({_plural(int((hc > 1).sum()), 'edge')} "
                             f"run the same way in both faces, e.g. {ex}): recalculate normals",
                             'bad_topology')
    used = np.zeros(n, bool)
    used[F.ravel()] = True
    if not used.all() and not allow_loose:
        bad = np.nonzero(~used)[0]
        raise ConformalError(f"mesh has {_plural(len(bad), 'loose vertex')} in no face "
                             f"(vertices {_examples(bad)}): delete loose geometry", 'bad_topology')
    fans = topology.vertex_fans(F, n, twin)
    if (fans > 1).any():
        bad = np.nonzero(fans > 1)[0]
        raise ConformalError(f"mesh has {_plural(len(bad), 'non-manifold vertex')} where separate "
                             f"fans of faces touch (vertices {_examples(bad)}): split or rip them apart",
                             'bad_topology')
    ncomp, part = topology.face_components(F, n, twin)
    if ncomp > 1 and not (allow_parts and kind == 'surface'):
        dup = topology.split_duplicates(V, F, part)
        if dup > 0.5 * len(np.unique(F)):               # split nearly everywhere: a triangle soup
            raise ConformalError(f"mesh has {ncomp} separate parts, and {_plural(dup, 'vertex')} of them "
                                 "sit on a vertex of another part (the surface is split there, as a "
                                 "triangle soup is): merge vertices by distance (Mesh > Clean Up > Merge "
                                 "by Distance)",
                                 'bad_topology')
        verb = 'map' if kind == 'sphere' else 'flatten'
        raise ConformalError(f"mesh has {ncomp} separate parts: {verb} one connected piece at a time "
                             "(separate by loose parts)" + ("" if kind == 'sphere' else
                                                            ", or flatten the islands one by one"),
                             'bad_topology')
    loops = topology.boundary_loops(F, n, twin)
    chi = topology.euler_characteristic(F, len(E))
    info = MeshInfo(n_vertices=n, n_faces=m, loops=loops, euler=chi, parts=int(ncomp))
    if kind == 'disk':
        if not loops:
            raise ConformalError("mesh is closed (it has no boundary)", 'no_boundary', 'use_sphere')
        if len(loops) > 1:
            raise ConformalError(f"mesh has {len(loops)} boundary loops; disk mode needs exactly one: "
                                 "mark seams or fill holes", 'holes')
        if chi != 1:
            genus = topology.genus(chi, len(loops))
            raise ConformalError(f"mesh has one boundary loop but genus {genus} (Euler characteristic "
                                 f"{chi}, a disk has 1): mark seams that cut it into a disk", 'genus')
    elif kind == 'sphere':
        if loops:
            raise ConformalError(f"mesh is open ({_plural(len(loops), 'boundary loop')}); sphere mode "
                                 "needs a closed mesh: use disk mode, or fill the holes", 'bad_topology')
        if chi != 2:
            genus = topology.genus(chi)
            raise ConformalError(f"mesh has genus {genus} (Euler characteristic {chi}); sphere mode needs "
                                 "genus 0: mark seams and use disk mode", 'genus')
    elif kind != 'surface':
        raise ConformalError(f"unknown mesh kind {kind!r}: use 'disk', 'sphere' or 'surface'")
    return info


def check_loose_edges(E, F):
    """Raise ``ConformalError`` if any edge of ``E`` (k,2) int (all edges of the mesh, as Blender or
    an OBJ ``l`` line gives them) belongs to no triangle of ``F`` (m,3)."""
    E = np.asarray(E, dtype=np.int64).reshape(-1, 2)
    if len(E) == 0:
        return
    F = np.asarray(F, dtype=np.int64)
    n = int(max(E.max(), F.max() if F.size else 0)) + 1
    H = np.sort(topology.halfedges(F), axis=1) if F.size else np.zeros((0, 2), np.int64)
    used = np.isin(np.sort(E, axis=1) @ np.array([n, 1]), H @ np.array([n, 1]))
    if not used.all():
        bad = np.nonzero(~used)[0]
        ex = ', '.join(f"({a}, {b})" for a, b in E[bad[:3]].tolist())
        raise ConformalError(f"mesh has {_plural(len(bad), 'loose edge')} in no face, e.g. {ex}: "
                             "delete loose geometry (Select All by Trait > Loose Geometry)", 'bad_topology')
