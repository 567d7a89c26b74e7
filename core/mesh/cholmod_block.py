"""Many right-hand sides in one CHOLMOD solve, for factors made by cvxopt's ``cholmod`` module.

cvxopt's ``cholmod.solve`` passes its dense right-hand sides to CHOLMOD one column at a time, so a
solve of r columns reads the whole factor 2r times; on big meshes that pass is memory-bound (0.07 s
per column for the 1M bump's ``L_II``, whose factor has 34M entries). CHOLMOD's own ``cholmod_solve``
takes a block of columns and runs the supernodal triangular solves as dense matrix-matrix products,
reading the factor twice per block (docs/scale.md, "Eighteenth round"). ``ctypes`` reaches
``cholmod_l_solve`` of the CHOLMOD that cvxopt uses, with the very factor cvxopt computed, and
``cholmod_l_factorize``, which fills a factor that cvxopt's ``symbolic`` analysed: cvxopt's
``numeric`` holds the GIL for the whole factorisation, this call does not, so two factorisations
(or one and the caller's solves) run on two cores (docs/scale.md, "Twentieth round"). That
CHOLMOD is linked into the extension and exported (the cp311 Linux wheel), or a library beside it (the
cp313 Linux wheels, macOS).

``BlockSolver.load()`` returns a solver, or None where CHOLMOD's symbols are not reachable (Windows:
linked into the extension, not exported) or a check on a small system fails; the caller then keeps
cvxopt's per-column solve. ctypes releases the GIL for the call, so other threads run while a
block is solved; each call has its own ``cholmod_common`` (cheap to start), so two threads may solve
at once.
"""
import ctypes
import threading

import numpy as np

from ..native import bundled_libraries

CHOLMOD_A = 0           # cholmod_solve's system: A x = b (the factor's permutation included)
CHOLMOD_REAL = 1        # xtype of a real dense matrix
COMMON_BYTES = 1 << 16  # room for cholmod_common (about 2.3 kB in CHOLMOD 3; its size is not exported)
CAPSULE = b'CHOLMOD FACTOR D L'      # cvxopt's name for the factor of a real matrix


# cholmod_common's leading fields (unchanged since CHOLMOD 1): the int ``supernodal`` at byte 48,
# ``final_asis`` at 52 and ``print`` at 144, whose defaults (1, 1, 3) are checked before ``print`` is
# set to 0 (as cvxopt does): a matrix that is not positive definite falls back to SuperLU silently
COMMON_INTS = {'supernodal': (48, 1), 'final_asis': (52, 1), 'print': (144, 3)}
CHOLMOD_LONG = 2        # itype of int64 indices (the ``cholmod_l_`` interface cvxopt uses)
LOWER = -1              # stype: only the lower triangle is stored (cvxopt's ``uplo='L'``)


class _Sparse(ctypes.Structure):
    """CHOLMOD's ``cholmod_sparse`` (compressed columns; unchanged since CHOLMOD 1)."""
    _fields_ = [('nrow', ctypes.c_size_t), ('ncol', ctypes.c_size_t), ('nzmax', ctypes.c_size_t),
                ('p', ctypes.c_void_p), ('i', ctypes.c_void_p), ('nz', ctypes.c_void_p),
                ('x', ctypes.c_void_p), ('z', ctypes.c_void_p), ('stype', ctypes.c_int),
                ('itype', ctypes.c_int), ('xtype', ctypes.c_int), ('dtype', ctypes.c_int),
                ('sorted', ctypes.c_int), ('packed', ctypes.c_int)]


class _FactorHead(ctypes.Structure):
    """The first two fields of CHOLMOD's ``cholmod_factor`` (unchanged since CHOLMOD 1): its order
    ``n`` and ``minor``, the column where a factorisation stopped (``n`` when it succeeded)."""
    _fields_ = [('n', ctypes.c_size_t), ('minor', ctypes.c_size_t)]


class _Dense(ctypes.Structure):
    """CHOLMOD's ``cholmod_dense`` (column-major values at ``x``; unchanged since CHOLMOD 1)."""
    _fields_ = [('nrow', ctypes.c_size_t), ('ncol', ctypes.c_size_t), ('nzmax', ctypes.c_size_t),
                ('d', ctypes.c_size_t), ('x', ctypes.c_void_p), ('z', ctypes.c_void_p),
                ('xtype', ctypes.c_int), ('dtype', ctypes.c_int)]


def _libraries(module):
    """Files that may hold the CHOLMOD of cvxopt's ``cholmod`` extension ``module`` (its path): the
    extension itself (the cp311 Linux wheel links CHOLMOD in and exports it), then the CHOLMOD library
    cvxopt bundles (``cvxopt.libs`` in the cp313 Linux wheels, ``.dylibs`` on macOS; ``core.native``)."""
    return [module] + bundled_libraries('cvxopt', 'libcholmod*')


class BlockSolver:
    """``solve(factor, b, out=None)``: ``A^-1 b`` for cvxopt's CHOLMOD factor ``factor`` of a real
    (k,k) matrix ``A`` and ``b`` (k,r) float64, written into ``out`` (k,r) when given (copied once
    from CHOLMOD's result) and returned; without ``out``, a new (k,r) Fortran-ordered array."""

    _loaded = None
    _lock = threading.Lock()

    def __init__(self, lib):
        self._lib = lib
        # own prototypes of the two C-API calls (ctypes.pythonapi's shared ones are left as they are)
        self._capsule_name = ctypes.PYFUNCTYPE(ctypes.c_char_p, ctypes.py_object)(
            ('PyCapsule_GetName', ctypes.pythonapi))
        self._capsule_pointer = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object, ctypes.c_char_p)(
            ('PyCapsule_GetPointer', ctypes.pythonapi))
        lib.cholmod_l_start.argtypes = [ctypes.c_void_p]
        lib.cholmod_l_finish.argtypes = [ctypes.c_void_p]
        lib.cholmod_l_solve.restype = ctypes.POINTER(_Dense)
        lib.cholmod_l_solve.argtypes = [ctypes.c_int, ctypes.c_void_p, ctypes.POINTER(_Dense),
                                        ctypes.c_void_p]
        lib.cholmod_l_free_dense.argtypes = [ctypes.POINTER(ctypes.POINTER(_Dense)), ctypes.c_void_p]
        lib.cholmod_l_factorize.restype = ctypes.c_int
        lib.cholmod_l_factorize.argtypes = [ctypes.POINTER(_Sparse), ctypes.c_void_p, ctypes.c_void_p]

    @classmethod
    def load(cls):
        """The solver for the installed cvxopt, or None if it cannot be used here (checked once per
        process: symbols present, and a 3x3 system solved the same as cvxopt's own solve)."""
        with cls._lock:
            if cls._loaded is None:
                cls._loaded = cls._try_load() or False
            return cls._loaded or None

    @classmethod
    def _try_load(cls):
        try:
            from cvxopt import cholmod, matrix, spmatrix
        except ImportError:
            return None
        for path in _libraries(cholmod.__file__):
            try:
                lib = ctypes.CDLL(path)
                lib.cholmod_l_solve            # noqa: B018  (AttributeError where it is not exported)
                lib.cholmod_l_factorize        # noqa: B018
                solver = cls(lib)
                rows, cols, vals = [0, 1, 1, 2, 2], [0, 0, 1, 1, 2], [4.0, 1.0, 3.0, 1.0, 5.0]
                A = spmatrix(vals, rows, cols, (3, 3))
                fac = cholmod.symbolic(A)
                cholmod.numeric(A, fac)
                b = np.array([[1.0, 0.5], [2.0, -1.0], [3.0, 0.25]], order='F')
                want = matrix(b)
                cholmod.solve(fac, want)
                mine = cholmod.symbolic(A)
                solver.factorize(mine, np.array([0, 2, 4, 5]), np.array(rows), np.array(vals))
                if np.allclose(solver.solve(fac, b), np.asarray(want), rtol=1e-12, atol=0) and \
                        np.allclose(solver.solve(mine, b), np.asarray(want), rtol=1e-12, atol=0):
                    return solver
            except (OSError, AttributeError, ValueError, TypeError, ArithmeticError):
                continue
        return None

    def _factor(self, factor):
        """The ``cholmod_factor`` pointer inside cvxopt's capsule ``factor`` (of a real matrix)."""
        name = self._capsule_name(factor)
        if name != CAPSULE:
            raise ValueError(f"not cvxopt's factor of a real matrix: {name!r}")
        return self._capsule_pointer(factor, name)

    def factorize(self, factor, indptr, indices, data):
        """Fill ``factor`` (cvxopt's ``symbolic`` of the same pattern, ``uplo='L'``) with the
        numeric factorisation of the symmetric matrix whose lower triangle, in compressed columns
        with sorted rows, is ``indptr`` (k+1,), ``indices`` (nnz,), ``data`` (nnz,), without
        holding the GIL. What cvxopt's ``numeric`` does, with CHOLMOD's default parameters (those
        that matter here were fixed by the analysis: supernodal, the order). Raises
        ArithmeticError(column) where the matrix is not positive definite, ValueError where CHOLMOD
        fails (out of memory, a pattern that is not the analysed one)."""
        L = self._factor(factor)
        p = np.ascontiguousarray(indptr, np.int64)
        i = np.ascontiguousarray(indices, np.int64)
        x = np.ascontiguousarray(data, np.float64)
        k = len(p) - 1
        A = _Sparse(k, k, len(x), p.ctypes.data, i.ctypes.data, None, x.ctypes.data, None, LOWER,
                    CHOLMOD_LONG, CHOLMOD_REAL, 0, 1, 1)
        common = ctypes.create_string_buffer(COMMON_BYTES)
        self._lib.cholmod_l_start(common)
        at = {name: np.frombuffer(common, np.int32, 1, offset) for name, (offset, _) in COMMON_INTS.items()}
        if all(int(at[name][0]) == value for name, (_, value) in COMMON_INTS.items()):
            at['print'][0] = 0
        try:
            ok = self._lib.cholmod_l_factorize(ctypes.byref(A), L, common)
        finally:
            self._lib.cholmod_l_finish(common)
        head = ctypes.cast(L, ctypes.POINTER(_FactorHead)).contents
        if not ok or head.n != k:
            raise ValueError("CHOLMOD's factorisation failed")
        if head.minor < k:
            raise ArithmeticError(int(head.minor))

    def solve(self, factor, b, out=None):
        L = self._factor(factor)
        b = np.asfortranarray(b, dtype=np.float64)
        k, r = b.shape
        B = _Dense(k, r, k * r, k, b.ctypes.data, None, CHOLMOD_REAL, 0)
        common = ctypes.create_string_buffer(COMMON_BYTES)
        self._lib.cholmod_l_start(common)
        try:
            X = self._lib.cholmod_l_solve(CHOLMOD_A, L, ctypes.byref(B), common)
            if not X:
                raise ArithmeticError("CHOLMOD's solve failed")
            try:
                x = X.contents
                if (x.nrow, x.ncol, x.d) != (k, r, k):
                    raise ArithmeticError("CHOLMOD's solve returned a matrix of another shape")
                got = np.ctypeslib.as_array(ctypes.cast(x.x, ctypes.POINTER(ctypes.c_double)),
                                            shape=(r, k)).T
                if out is None:
                    out = got.copy(order='F')
                else:
                    out[...] = got
            finally:
                self._lib.cholmod_l_free_dense(ctypes.byref(X), common)
        finally:
            self._lib.cholmod_l_finish(common)
        return out
