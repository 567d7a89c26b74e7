"""Thread counts of the OpenBLAS copies that numpy, scipy and cvxopt bundle.

OpenBLAS's worker threads spin (``sched_yield``) for a while after each call that used them. The
core's dense products are small: a few dozen columns, or 2x2 and 3x3 blocks. So on a small mesh the
spinning worker only takes the second core, which the work ``core.background.beside`` hands to a
thread (the certified bound, the boundary response) would use. Measured with numpy's and scipy's
OpenBLAS on one thread (docs/scale.md, "Eighteenth round"):
- ``flatten(uniform, bound)`` on edgebump at n = 65: 88 ms -> 64 ms;
- ``unwrap`` of the 19-island teapot: 514 ms -> 392 ms;
- process CPU time falls to the wall time;
- the 1M-triangle bump: no change.

``one_thread()`` holds numpy's and scipy's OpenBLAS at one thread while the core's entry points run.
As a context manager or a decorator, it sets each library's count back when the outermost holder
leaves, also when several threads enter. These counts belong to the whole process: in Blender, other
add-ons' numpy runs on one thread meanwhile. ``set_threads(paths, n)`` sets the count of the
libraries at ``paths`` (cvxopt's private copy is held at one thread for good, ``core.mesh.solve``).
"""
import contextlib
import ctypes
import threading

from .native import bundled_libraries

# the names of OpenBLAS's thread count functions in the builds the wheels bundle (plain, 64-bit
# integer interface, scipy-openblas)
_SUFFIXES = ('', '64_')
_PREFIXES = ('openblas_', 'scipy_openblas_')


def library_paths(package):
    """Paths (list of str) of the OpenBLAS libraries bundled with the installed ``package`` (a
    top-level name: 'numpy', 'scipy', 'cvxopt'; ``core.native``). Empty if none is found."""
    return bundled_libraries(package, '*openblas*')


def _functions(path):
    """(set, get) thread count functions of the OpenBLAS at ``path``, or None."""
    try:
        lib = ctypes.CDLL(path)
    except OSError:
        return None
    for prefix in _PREFIXES:
        for suffix in _SUFFIXES:
            try:
                setter = getattr(lib, f'{prefix}set_num_threads{suffix}')
                getter = getattr(lib, f'{prefix}get_num_threads{suffix}')
            except AttributeError:
                continue
            setter.argtypes, setter.restype = [ctypes.c_int], None
            getter.argtypes, getter.restype = [], ctypes.c_int
            return setter, getter
    return None


def set_threads(paths, n):
    """Set the thread count of every OpenBLAS at ``paths`` to ``n``; returns the count the last one
    reports after, or None where none was found."""
    out = None
    for path in paths:
        fns = _functions(path)
        if fns is not None:
            fns[0](int(n))
            out = int(fns[1]())
    return out


class _OneThread:
    """The process's hold on numpy's and scipy's OpenBLAS thread counts (see ``one_thread``)."""

    def __init__(self):
        self._lock = threading.Lock()
        self._depth = 0
        self._libs = None
        self._saved = []

    def enter(self):
        with self._lock:
            if self._libs is None:
                self._libs = [f for p in library_paths('numpy') + library_paths('scipy')
                              if (f := _functions(p)) is not None]
            if self._depth == 0:
                self._saved = [(setter, getter()) for setter, getter in self._libs]
                for setter, _ in self._libs:
                    setter(1)
            self._depth += 1

    def leave(self):
        with self._lock:
            self._depth -= 1
            if self._depth == 0:
                for setter, n in self._saved:
                    setter(n)
                self._saved = []


_HOLD = _OneThread()


@contextlib.contextmanager
def one_thread():
    """numpy's and scipy's OpenBLAS on one thread inside the block (a context manager, or a decorator
    of a function), set back as they were when the outermost holder leaves."""
    _HOLD.enter()
    try:
        yield
    finally:
        _HOLD.leave()
