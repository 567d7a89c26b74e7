"""Wavefront OBJ reading and writing.

Vertices are identified by their ``v`` index, so UV seams (``vt`` indices) in the input do not split
the mesh. Faces may be n-gons in any ``v``, ``v/vt``, ``v//vn`` or ``v/vt/vn`` form."""
import os
import tempfile
import warnings

import numpy as np

from ..errors import ConformalError
from ..mesh.triangulate import triangulate


class ObjMesh:
    """Polygons as read: ``V`` (n,3) float64, ``corner_verts`` (c,) int64, ``sizes`` (p,) int64;
    ``corner_uvs`` (c,) int64 the ``vt`` index of each corner (-1 where the face gives none);
    ``lines`` (k,2) int64 the edges of ``l`` polylines (loose edges); ``v_text`` the ``v`` lines as
    read (bytes, one line per vertex; None when the file was read line by line), so that a command
    writing the same vertices back need not format them again (``write_obj(..., v_text=...)``)."""

    def __init__(self, V, corner_verts, sizes, corner_uvs=None, lines=None, v_text=None):
        self.V, self.corner_verts, self.sizes, self.v_text = V, corner_verts, sizes, v_text
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
    """Read an OBJ file into an ``ObjMesh``. Raises ``ConformalError`` on unreadable input.

    The whole file is parsed at once with numpy (``_read_fast``); a file the fast parser does not
    accept exactly as written (odd whitespace, ``+1``, malformed tokens...) is read line by line
    (``_read_lines``), which also words the errors. Both give the same result on every file."""
    try:
        with open(path, 'rb') as fh:
            data = fh.read()
    except OSError as exc:
        raise ConformalError(f"cannot read {path}: {exc.strerror}") from None
    parts = _read_fast(data)
    if parts is None:
        return _read_lines(path)
    mesh = _mesh(path, *parts[:5])
    mesh.v_text = parts[5]
    return mesh


def _mesh(path, V, corners, sizes, cuv, lines):
    """``ObjMesh`` from parsed arrays after the checks every reader shares."""
    if not len(V) or not len(sizes):
        raise ConformalError(f"{path} has no vertices or no faces: the mesh is empty")
    V = np.asarray(V, dtype=np.float64).reshape(-1, 3)
    try:                                   # an index beyond int64 refers to no vertex either
        corners = np.asarray(corners, dtype=np.int64)
    except OverflowError:
        corners = np.array([-1])
    if corners.min() < 0 or corners.max() >= len(V):
        raise ConformalError(f"{path}: a face refers to a vertex that does not exist")
    try:
        lines = np.asarray(lines, dtype=np.int64).reshape(-1, 2)
    except OverflowError:
        lines = np.array([[-1, -1]])
    if len(lines) and (lines.min() < 0 or lines.max() >= len(V)):
        raise ConformalError(f"{path}: a line ('l') refers to a vertex that does not exist")
    try:
        cuv = np.asarray(cuv, dtype=np.int64)
    except OverflowError:
        raise ConformalError(f"{path}: a face refers to a texture coordinate ('vt') that does not exist") \
            from None
    return ObjMesh(V, corners, np.asarray(sizes, dtype=np.int64), cuv, lines)


def _read_lines(path):
    """``read_obj`` line by line: the reference semantics and the error wording."""
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
    return _mesh(path, V, corners, sizes, cuv, lines)


_SP, _TAB, _NL, _SLASH, _MINUS = 32, 9, 10, 47, 45


def _parse_numbers(sub, dtype):
    """The whitespace-separated numbers of the byte array ``sub`` as a (k,) ``dtype`` array, or None
    where one does not parse. numpy 1.x stops at a bad number with a warning (the caller then sees too
    few values); numpy 2.x raises ValueError."""
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')        # numpy 1.x warns where it stops on a bad number
        try:
            return np.fromstring(sub.tobytes(), dtype=dtype, sep=' ')
        except ValueError:
            return None


def _line_bytes(buf, starts, ends, pick):
    """The bytes of the lines ``pick`` (bool per line) of ``buf`` (uint8), each ending in a newline,
    concatenated (a new, writable uint8 array), and the offsets of their first bytes in that array."""
    rows = np.flatnonzero(pick)
    if len(rows) and rows[-1] - rows[0] + 1 == len(rows):     # one block of lines (the usual OBJ)
        out = buf[starts[rows[0]]:ends[rows[-1]] + 1].copy()
    else:
        out = buf[np.repeat(pick, ends - starts + 1)]
    lens = (ends - starts + 1)[pick]
    first = np.zeros(len(lens), np.int64)
    np.cumsum(lens[:-1], out=first[1:])
    return out, first


def _token_lines(sub, first):
    """(start offsets of the whitespace-separated tokens of ``sub``, line of each token) for
    newline-terminated lines starting at ``first``."""
    ws = (sub == _SP) | (sub == _TAB) | (sub == _NL)
    tok = np.flatnonzero(~ws & np.r_[True, ws[:-1]])
    return tok, np.searchsorted(first, tok, side='right') - 1


def _read_fast(data):
    """Whole-buffer parse of OBJ bytes: (V (n*3,) float64, corners, sizes, corner uvs, line edges),
    or None when the text needs the line-by-line reader (anything it would not parse identically)."""
    if b'\r' in data:
        data = data.replace(b'\r\n', b'\n').replace(b'\r', b'\n')
    if not data.endswith(b'\n'):
        data += b'\n'
    buf = np.frombuffer(data, np.uint8)
    ends = np.flatnonzero(buf == _NL)
    starts = np.r_[0, ends[:-1] + 1]
    length = ends - starts
    c0 = buf[starts]
    if ((c0 == _SP) | (c0 == _TAB)).any():
        import re                      # indented lines: strip the indentation, which split() ignores
        return _read_fast(re.sub(rb'(?m)^[ \t]+', b'', data))

    def at(k):
        return np.where(length > k, buf[np.minimum(starts + k, len(buf) - 1)], _NL)
    c1, c2 = at(1), at(2)

    def sep(c):
        return (c == _SP) | (c == _TAB) | (c == _NL)

    def odd(c):                        # a byte str.split() might treat as whitespace
        return ((c < 32) & ~sep(c)) | (c >= 127)
    key = (c0 == ord('v')) | (c0 == ord('f')) | (c0 == ord('l'))
    if odd(c0).any() or (key & (odd(c1) | ((c1 == ord('t')) & odd(c2)))).any():
        return None
    is_v = (c0 == ord('v')) & sep(c1)
    is_vt = (c0 == ord('v')) & (c1 == ord('t')) & sep(c2)
    is_f = (c0 == ord('f')) & sep(c1)
    is_l = (c0 == ord('l')) & sep(c1)
    nv_before = np.cumsum(is_v) - is_v
    nvt_before = np.cumsum(is_vt) - is_vt

    # vertices: exactly three numbers after 'v' on every line, parsed in one call
    sub, first = _line_bytes(buf, starts, ends, is_v)
    nv = len(first)
    if nv:
        if odd(sub).any():
            return None
        tok, line = _token_lines(sub, first)
        if len(tok) != 4 * nv or (np.bincount(line, minlength=nv) != 4).any():
            return None
        v_text = sub.tobytes()
        sub[first] = _SP
        V = _parse_numbers(sub, np.float64)
        if V is None or len(V) != 3 * nv:
            return None
    else:
        V, v_text = np.zeros(0), b''

    # faces: tokens 'a', 'a/b', 'a//c', 'a/b/c' of optionally signed integers
    sub, first = _line_bytes(buf, starts, ends, is_f)
    nf = len(first)
    if nf:
        sub[first] = _SP
        digit = (sub >= 48) & (sub <= 57)
        slash, minus = sub == _SLASH, sub == _MINUS
        ws = (sub == _SP) | (sub == _TAB) | (sub == _NL)
        if not (digit | slash | minus | ws).all():
            return None
        brk = ws | slash                           # fields: runs between whitespace and slashes
        run = np.flatnonzero(~brk & np.r_[True, brk[:-1]])
        run_end = np.flatnonzero(~brk & np.r_[brk[1:], True]) + 1
        mpos = np.flatnonzero(minus)               # a minus only leads a field, before a digit
        if (slash[1:] & ws[:-1]).any() or (run_end - run > 16).any() or \
                (len(mpos) and not (brk[mpos - 1].all() and digit[mpos + 1].all())):
            return None
        sub[slash] = _SP
        val = _parse_numbers(sub, np.int64)
        if val is None or len(val) != len(run):
            return None
        f0 = ws[run - 1]                           # the first field of a token (the v index)
        f1 = np.zeros(len(run), bool)              # the second (vt): one slash after a first field
        f1[1:] = ~f0[1:] & f0[:-1] & (run[1:] - run_end[:-1] == 1)
        tok = run[f0]
        sizes = np.diff(np.r_[np.searchsorted(tok, first), len(tok)])
        idx = val[f0]
        if (sizes < 3).any() or (idx == 0).any():
            return None
        negative = (idx < 0).any()
        line_of = np.repeat(np.flatnonzero(is_f), sizes) if negative or f1.any() else None
        corners = np.where(idx > 0, idx - 1, nv_before[line_of] + idx) if negative else idx - 1
        cuv = np.full(len(tok), -1, np.int64)
        if f1.any():
            t1 = (np.cumsum(f0) - 1)[f1]
            tv = val[f1]
            rel = nvt_before[line_of[t1]] + tv
            cuv[t1] = np.where(tv > 0, tv - 1, np.where(tv < 0, rel, -1))
    else:
        corners = cuv = sizes = np.zeros(0, np.int64)

    # polylines ('l'): rare and short, parsed line by line
    edges = []
    for k in np.flatnonzero(is_l).tolist():
        text = data[starts[k]:ends[k]].decode('utf-8', 'replace')
        try:
            idx = [int(q.split('/')[0]) for q in text.split()[1:]]
        except ValueError:
            return None
        n_k = int(nv_before[k])
        idx = [i - 1 if i > 0 else n_k + i for i in idx]
        edges.extend(zip(idx[:-1], idx[1:]))
    return V, corners, sizes, cuv, edges, v_text


def _format_rows(A, fmt, head):
    """Lines ``head`` + the row's values as ``fmt`` joined by spaces, one line per row of ``A``
    (r,k), in one %-format call; '' for no rows."""
    if not len(A):
        return ''
    line = head + ' '.join([fmt] * A.shape[1]) + '\n'
    return (line * len(A)) % tuple(A.ravel().tolist())


def _int_lines(values, seps, line_first, head=b'f ', chunk=1 << 20):
    """ASCII bytes of non-negative integers ``values`` (t,), each followed by its separator byte
    ``seps`` (t,) uint8 (b'/', b' ' or b'\\n'), with ``head`` before the values that start a line
    (``line_first`` (t,) bool). Vectorised: the digits of 0..max(values) are written once into a
    table (one row per number, left-aligned), and each value's row is gathered, followed by its
    separator, with the padding dropped by one boolean mask (``chunk`` values at a time, so the
    temporary rows stay near 10 bytes per value)."""
    values = np.asarray(values, np.int64)
    if not len(values):
        return b''
    if values.min() < 0:
        raise ValueError("negative index")
    k = np.arange(int(values.max()) + 1, dtype=np.int64)
    powers = 10 ** np.arange(19, dtype=np.int64)
    nd = np.maximum(np.searchsorted(powers, k, side='right'), 1)           # digits of each number
    D = int(nd[-1])
    table = np.empty((len(k), D), np.uint8)                                 # left-aligned digits
    for j in range(D):
        table[:, j] = 48 + (k // powers[np.maximum(nd - 1 - j, 0)]) % 10
    table_rows = table.view(f'V{D}').ravel()                                # one item per row: fast gathers
    H = len(head)
    seps = np.asarray(seps, np.uint8)
    line_first = np.asarray(line_first, bool)
    width = np.arange(D + 1)
    out = []
    for c0 in range(0, len(values), chunk):
        v = values[c0:c0 + chunk]
        r = len(v)
        rows = np.empty((r, H + D + 1), np.uint8)
        rows[:, :H] = np.frombuffer(head, np.uint8)
        rows[:, H:H + D] = table_rows[v].view(np.uint8).reshape(r, D)
        lens = nd[v]
        rows[np.arange(r), H + lens] = seps[c0:c0 + chunk]
        keep = np.empty(rows.shape, bool)
        keep[:, :H] = line_first[c0:c0 + chunk, None]
        np.less_equal(width, lens[:, None], out=keep[:, H:])
        out.append(rows[keep].tobytes())
    return b''.join(out)


def _face_text(F, T=None):
    """``f`` lines (ASCII bytes) of faces ``F`` ((m,k) int array or list of 0-based polygons), with
    ``vt`` indices ``T`` (the same structure) written as ``v/vt`` when given."""
    if isinstance(F, np.ndarray) and F.ndim == 2:
        corners = np.asarray(F, np.int64).ravel()
        sizes = np.full(len(F), F.shape[1])
    else:
        polys = [np.asarray(f, np.int64).ravel() for f in F]
        corners = np.concatenate(polys) if polys else np.zeros(0, np.int64)
        sizes = np.array([len(f) for f in polys], np.int64)
    if not len(corners):
        return b''
    last = np.zeros(len(corners), bool)
    last[np.cumsum(sizes) - 1] = True
    first = np.zeros(len(corners), bool)
    first[np.cumsum(sizes) - sizes] = True
    sep = np.where(last, ord('\n'), ord(' ')).astype(np.uint8)
    if T is None:
        return _int_lines(corners + 1, sep, first)
    tex = (np.asarray(T, np.int64).ravel() if isinstance(T, np.ndarray) and T.ndim == 2
           else np.concatenate([np.asarray(t, np.int64).ravel() for t in T]))
    if len(tex) != len(corners):
        raise ConformalError(f"UV_faces has {len(tex)} corners, the faces {len(corners)}")
    vals = np.stack([corners + 1, tex + 1], 1).ravel()
    seps = np.stack([np.full(len(sep), ord('/'), np.uint8), sep], 1).ravel()
    return _int_lines(vals, seps, np.stack([first, np.zeros(len(first), bool)], 1).ravel())


def write_obj(path, V, F, UV=None, UV_faces=None, v_text=None):
    """Write ``V`` (n,3) and faces ``F`` ((m,k) array or a list of polygons). With ``UV`` (n,2) and no
    ``UV_faces``: one ``vt`` per vertex and ``f v/vt`` with the same index. With ``UV`` (t,2) and
    ``UV_faces`` (the same structure as ``F``, 0-based ``vt`` indices): per-corner UVs, as needed when
    islands split vertices. Numbers are written with 17 significant digits (an exact round trip).
    ``v_text`` (optional): the ``v`` lines of ``V`` as read (``ObjMesh.v_text``), written as they are
    instead of formatting ``V`` again (one line per vertex, checked).
    Written to a temporary file first, so a failure leaves no partial output."""
    V = np.asarray(V, np.float64).reshape(-1, 3)
    if v_text is not None and v_text.count(b'\n') == len(V) and (not V.size or v_text.endswith(b'\n')):
        parts = [v_text]
    else:
        parts = [_format_rows(V, '%.17g', 'v ').encode('ascii')]
    if UV is not None:
        parts.append(_format_rows(np.asarray(UV, np.float64).reshape(-1, 2), '%.17g', 'vt ').encode('ascii'))
        parts.append(_face_text(F, F if UV_faces is None else UV_faces))
    else:
        parts.append(_face_text(F))
    write_text(path, b''.join(parts))


def write_values(path, values):
    """Write one number per line (``values`` (n,), 17 significant digits: an exact round trip),
    atomically like ``write_text``."""
    write_text(path, _format_rows(np.asarray(values, np.float64).reshape(-1, 1), '%.17g', ''))


def write_text(path, text):
    """Write ``text`` (str, or bytes written as they are) to ``path`` through a temporary file in the
    same folder renamed into place, so a failure leaves neither a partial output nor the temporary
    file. Raises ``ConformalError``."""
    folder = os.path.dirname(os.path.abspath(path))
    try:
        fd, tmp = tempfile.mkstemp(prefix='.conformal-', suffix='.tmp', dir=folder)
    except OSError as exc:
        raise ConformalError(f"cannot write {path}: {exc.strerror}") from None
    try:
        with os.fdopen(fd, 'wb' if isinstance(text, bytes) else 'w') as fh:
            fh.write(text)
        umask = os.umask(0)
        os.umask(umask)
        os.chmod(tmp, 0o666 & ~umask)          # mkstemp makes 0600; an output file gets the usual mode
        os.replace(tmp, path)
    except OSError as exc:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise ConformalError(f"cannot write {path}: {exc.strerror}") from None
