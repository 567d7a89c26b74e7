"""Work on its own thread, joined where its result is needed.

Numpy's loops, SuperLU and HiGHS release the GIL, so work handed to a ``Background`` runs on the
second core while the caller goes on (docs/scale.md)."""
import threading


class Background:
    """``fn(*args, **kwargs)`` on its own daemon thread. ``result()`` waits and returns its value, or
    raises the exception it raised; it may be called from several threads."""

    def __init__(self, fn, *args, **kwargs):
        self._out = None
        self._thread = threading.Thread(target=self._run, args=(fn, args, kwargs), daemon=True)
        self._thread.start()

    def _run(self, fn, args, kwargs):
        try:
            self._out = (fn(*args, **kwargs), None)
        except BaseException as exc:           # handed to the caller of result()
            self._out = (None, exc)

    def result(self):
        self._thread.join()
        value, exc = self._out
        if exc is not None:
            raise exc
        return value
