"""Work on its own thread, joined where its result is needed.

Numpy's loops, SuperLU, CHOLMOD's solves and HiGHS release the GIL, so work handed to a
``Background`` runs on the second core while the caller goes on (docs/scale.md). On small islands the
two threads' Python work contends for the GIL and the overlap is lost, so ``beside`` runs the work
inline there."""
import threading

THREAD_MIN_FACES = 4_000    # beside: work for a mesh of fewer triangles runs inline (docs/scale.md)


def _outcome(fn, args, kwargs):
    """(value, None) of ``fn(*args, **kwargs)``, or (None, the exception it raised)."""
    try:
        return fn(*args, **kwargs), None
    except BaseException as exc:               # handed to the caller of result()
        return None, exc


class Done:
    """Work run inline, at construction, with the interface of ``Background``: ``result()`` returns
    its value or raises its exception."""

    def __init__(self, fn, *args, **kwargs):
        self._out = _outcome(fn, args, kwargs)

    def result(self):
        value, exc = self._out
        if exc is not None:
            raise exc
        return value


class Background(Done):
    """``fn(*args, **kwargs)`` on its own daemon thread. ``result()`` waits and returns its value, or
    raises the exception it raised; it may be called from several threads."""

    def __init__(self, fn, *args, **kwargs):
        self._out = None
        self._thread = threading.Thread(target=self._run, args=(fn, args, kwargs), daemon=True)
        self._thread.start()

    def _run(self, fn, args, kwargs):
        self._out = _outcome(fn, args, kwargs)

    def result(self):
        self._thread.join()
        return super().result()


def beside(faces, fn, *args, **kwargs):
    """``fn(*args, **kwargs)`` as a ``Background`` for a mesh of ``faces`` triangles, or run inline
    (``Done``) below ``THREAD_MIN_FACES``. Measured with the BLAS on one thread (``core.blas``): on
    islands of a few hundred triangles the thread costs 5-10 % (its Python work waits for the GIL the
    caller holds); at 8k triangles it gains up to 15 % (edgebump: the bound is as long as the
    optimiser); from 33k 10-20 %."""
    return (Background if faces >= THREAD_MIN_FACES else Done)(fn, *args, **kwargs)
