"""Wavefront OBJ reading and writing.

Vertices are identified by their ``v`` index, so UV seams (``vt`` indices) in the input do not split
the mesh. Faces may be n-gons in any ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn`` form."""
import os
import tempfile

import numpy as np

from ..errors import ConformalError
from ..mesh.triangulate import triangulate


class ObjMesh:
    """Polygons as read: ``V`` (n,3) float64, ``corner_verts`` (c,) int64, ``sizes`` (p,) int64;
    ``corner_uvs`` (c,) int64 the ``vt`` index of each corner (-1 where the face gives none);
    ``lines`` (k,2) int64 the edges of ``l`` polylines (loose edges)."""

    def __init__(self, V, corner_verts, sizes, corner_uvs=None, lines=None):
        self.V, self.corner_verts, self.sizes = V, corner_verts, sizes
        self.corner_uvs = np.full(len(corner_verts), -1, np.int64) if corner_uvs is None else corner_uvs
        self.lines = np.zeros((0, 2), np.int64) if lines is None else lines

    def polygons(self):
        """List of (k,) int64 vertex indices, one per polygon."""
        return np.split(self.corner_verts, np.cumsum(self.sizes)[:-1])

    def triangles(self):
        """(F (m,3) int64, tri_poly (m,) int64): the polygons triangulated."""
        tri, tri_poly = triangulate(self.corner_verts, self.sizes, self.V)
        return self.corner_verts[tri], tri_poly


def text_lines(path):
    """Yield ``(line number from 1, line)`` of a text file; a file that cannot be opened raises
    ``ConformalError`` (on the first iteration)."""
    try:
        fh = open(path, 'r', encoding='utf-8', errors='replace')
    except OSError as exc:
        raise ConformalError(f"cannot read {path}: {exc.strerror}") from None
    with fh:
        yield from enumerate(fh, 1)


def read_obj(path):
    """Read an OBJ file into an ``ObjMesh``. Raises ``ConformalError`` on unreadable input."""
    V, corners, sizes, cuv, lines = [], [], [], [], []
    nvt = 0
    for lineno, line in text_lines(path):
        p = line.split()
        if not p:
            continue
        try:
            if p[0] == 'v':
                V.append((float(p[1]), float(p[2]), float(p[3])))
            elif p[0] == 'vt':
                nvt += 1
            elif p[0] == 'f':
                parts = [q.split('/') for q in p[1:]]
                idx = [int(q[0]) for q in parts]
                if len(idx) < 3:
                    raise ValueError("a face needs at least 3 corners")
                if 0 in idx:
                    raise ValueError("OBJ indices start at 1")
                nv = len(V)
                idx = [i - 1 if i > 0 else nv + i for i in idx]
                tex = [int(q[1]) if len(q) > 1 and q[1] else 0 for q in parts]
                tex = [t - 1 if t > 0 else (nvt + t if t < 0 else -1) for t in tex]
                corners.extend(idx)
                cuv.extend(tex)
                sizes.append(len(idx))
            elif p[0] == 'l':
                idx = [int(q.split('/')[0]) for q in p[1:]]
                nv = len(V)
                idx = [i - 1 if i > 0 else nv + i for i in idx]
                lines.extend(zip(idx[:-1], idx[1:]))
        except (ValueError, IndexError) as exc:
            raise ConformalError(f"{path} line {lineno}: cannot parse {line.strip()[:60]!r} ({exc})") \
                from None
    if not V or not sizes:
        raise ConformalError(f"{path} has no vertices or no faces: the mesh is empty")
    V = np.array(V, dtype=np.float64)
    corners = np.array(corners, dtype=np.int64)
    if corners.min() < 0 or corners.max() >= len(V):
        raise ConformalError(f"{path}: a face refers to a vertex that does not exist")
    lines = np.array(lines, dtype=np.int64).reshape(-1, 2)
    if len(lines) and (lines.min() < 0 or lines.max() >= len(V)):
        raise ConformalError(f"{path}: a line ('l') refers to a vertex that does not exist")
    return ObjMesh(V, corners, np.array(sizes, dtype=np.int64), np.array(cuv, dtype=np.int64), lines)


def _index_lists(F):
    return [list(map(int, f)) for f in (np.asarray(F, np.int64) + 1 if isinstance(F, np.ndarray)
                                        else (np.asarray(f, np.int64) + 1 for f in F))]


def write_obj(path, V, F, UV=None, UV_faces=None):
    """Write ``V`` (n,3) and faces ``F`` ((m,k) array or a list of polygons). With ``UV`` (n,2) and no
    ``UV_faces``: one ``vt`` per vertex and ``f v/vt`` with the same index. With ``UV`` (t,2) and
    ``UV_faces`` (the same structure as ``F``, 0-based ``vt`` indices): per-corner UVs, as needed when
    islands split vertices. Written to a temporary file first, so a failure leaves no partial output."""
    V = np.asarray(V, np.float64)
    F = _index_lists(F)
    T = F if UV_faces is None else _index_lists(UV_faces)
    lines = [f"v {x!r} {y!r} {z!r}\n" for x, y, z in V.tolist()]      # repr: exact round trip
    if UV is not None:
        lines += [f"vt {u!r} {v!r}\n" for u, v in np.asarray(UV, float).tolist()]
        lines += ['f ' + ' '.join(f"{i}/{j}" for i, j in zip(f, t)) + '\n' for f, t in zip(F, T)]
    else:
        lines += ['f ' + ' '.join(str(i) for i in f) + '\n' for f in F]
    write_text(path, ''.join(lines))


def write_values(path, values):
    """Write one number per line (``values`` (n,), ``repr``: exact round trip), atomically like
    ``write_text``."""
    write_text(path, ''.join(f"{v!r}\n" for v in np.asarray(values, np.float64).tolist()))


def write_text(path, text):
    """Write ``text`` to ``path`` through a temporary file in the same folder renamed into place, so a
    failure leaves neither a partial output nor the temporary file. Raises ``ConformalError``."""
    folder = os.path.dirname(os.path.abspath(path))
    try:
        fd, tmp = tempfile.mkstemp(prefix='.conformal-', suffix='.tmp', dir=folder)
    except OSError as exc:
        raise ConformalError(f"cannot write {path}: {exc.strerror}") from None
    try:
        with os.fdopen(fd, 'w') as fh:
            fh.write(text)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)          # mkstemp makes 0600; an output file gets the usual mode
        os.replace(tmp, path)
    except OSError as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise ConformalError(f"cannot write {path}: {exc.strerror}") from None
