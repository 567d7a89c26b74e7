"""Wavefront OBJ reading and writing.

Vertices are identified by their ``v`` index, so UV seams (``vt`` indices) in the input do not split
the mesh. Faces may be n-gons in any ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn`` form."""
import os

import numpy as np

from .errors import ConformalError
from .triangulate import triangulate


class ObjMesh:
    """Polygons as read: ``V`` (n,3) float64, ``corner_verts`` (c,) int64, ``sizes`` (p,) int64."""

    def __init__(self, V, corner_verts, sizes):
        self.V, self.corner_verts, self.sizes = V, corner_verts, sizes

    def triangles(self):
        """(F (m,3) int64, tri_poly (m,) int64): the polygons triangulated."""
        tri, tri_poly = triangulate(self.corner_verts, self.sizes, self.V)
        return self.corner_verts[tri], tri_poly


def read_obj(path):
    """Read an OBJ file into an ``ObjMesh``. Raises ``ConformalError`` on unreadable input."""
    V, corners, sizes = [], [], []
    try:
        fh = open(path, 'r', encoding='utf-8', errors='replace')
    except OSError as exc:
        raise ConformalError(f"cannot read {path}: {exc.strerror}") from None
    with fh:
        for lineno, line in enumerate(fh, 1):
            p = line.split()
            if not p:
                continue
            try:
                if p[0] == 'v':
                    V.append((float(p[1]), float(p[2]), float(p[3])))
                elif p[0] == 'f':
                    idx = [int(q.split('/')[0]) for q in p[1:]]
                    if len(idx) < 3:
                        raise ValueError("a face needs at least 3 corners")
                    nv = len(V)
                    idx = [i - 1 if i > 0 else nv + i for i in idx]
                    corners.extend(idx)
                    sizes.append(len(idx))
            except (ValueError, IndexError) as exc:
                raise ConformalError(f"{path} line {lineno}: cannot parse {line.strip()[:60]!r} ({exc})") from None
    if not V or not sizes:
        raise ConformalError(f"{path} has no vertices or no faces: the mesh is empty")
    V = np.array(V, dtype=np.float64)
    corners = np.array(corners, dtype=np.int64)
    if corners.min() < 0 or corners.max() >= len(V):
        raise ConformalError(f"{path}: a face refers to a vertex that does not exist")
    return ObjMesh(V, corners, np.array(sizes, dtype=np.int64))


def write_obj(path, V, F, UV=None):
    """Write ``V`` (n,3) and faces ``F`` ((m,k) array or a list of polygons); with ``UV`` (n,2) one ``vt`` per vertex and ``f v/vt``.
    Written to a temporary file first, so a failure leaves no partial output."""
    V = np.asarray(V, np.float64)
    F = [list(map(int, f)) for f in (np.asarray(F, np.int64) + 1 if isinstance(F, np.ndarray)
                                      else (np.asarray(f, np.int64) + 1 for f in F))]
    tmp = f"{path}.tmp{os.getpid()}"
    try:
        with open(tmp, 'w') as fh:
            fh.write(''.join(f"v {x:.9g} {y:.9g} {z:.9g}\n" for x, y, z in V.tolist()))
            if UV is not None:
                fh.write(''.join(f"vt {u:.9g} {v:.9g}\n" for u, v in np.asarray(UV, float).tolist()))
                fh.write(''.join('f ' + ' '.join(f"{i}/{i}" for i in f) + '\n' for f in F))
            else:
                fh.write(''.join('f ' + ' '.join(str(i) for i in f) + '\n' for f in F))
        os.replace(tmp, path)
    except OSError as exc:
        if os.path.exists(tmp):
            os.remove(tmp)
        raise ConformalError(f"cannot write {path}: {exc.strerror}") from None
