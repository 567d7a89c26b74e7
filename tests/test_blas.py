"""core.blas: numpy's and scipy's OpenBLAS held at one thread while the core's entry points run, and
set back after (the counts belong to the whole process: in Blender, to everyone's numpy)."""
import sys
import threading

import numpy as np
import pytest

from core import flatten, make_surface, unwrap
from core.background import Background, Done, beside
from core.blas import _functions, library_paths, one_thread, set_threads

LINUX = sys.platform.startswith('linux')


def _libs():
    paths = library_paths('numpy') + library_paths('scipy')
    return paths, [f for p in paths if (f := _functions(p)) is not None]


def _counts(libs):
    return [getter() for _, getter in libs]


@pytest.fixture
def two_threads():
    """numpy's and scipy's OpenBLAS at two threads for the test, set back as they were after."""
    paths, libs = _libs()
    before = _counts(libs)
    set_threads(paths, 2)
    yield libs
    for (setter, _), n in zip(libs, before):
        setter(n)


def test_numpy_and_scipy_openblas_are_found_on_linux():
    if not LINUX:
        pytest.skip("the wheels' OpenBLAS layout is checked on Linux (CI)")
    _, libs = _libs()
    assert len(libs) == 2                                  # numpy's copy and scipy's


def test_one_thread_inside_and_restored_after_nested_and_threaded(two_threads):
    libs = two_threads
    assert _counts(libs) == [2] * len(libs)
    with one_thread():
        assert _counts(libs) == [1] * len(libs)
        with one_thread():
            assert _counts(libs) == [1] * len(libs)
        assert _counts(libs) == [1] * len(libs)            # the outer hold is still there
    assert _counts(libs) == [2] * len(libs)
    # holders in several threads, leaving in another order than they came
    entered, release = threading.Barrier(3), threading.Event()

    def hold():
        with one_thread():
            entered.wait()
            release.wait()
    workers = [threading.Thread(target=hold) for _ in range(2)]
    for w in workers:
        w.start()
    entered.wait()
    assert _counts(libs) == [1] * len(libs)
    release.set()
    for w in workers:
        w.join()
    assert _counts(libs) == [2] * len(libs)


def test_one_thread_set_back_when_the_work_raises(two_threads):
    libs = two_threads
    with pytest.raises(ZeroDivisionError), one_thread():
        raise ZeroDivisionError
    assert _counts(libs) == [2] * len(libs)


@pytest.mark.parametrize('entry', ['flatten', 'unwrap'])
def test_entry_points_run_on_one_blas_thread_and_set_it_back(two_threads, entry):
    libs = two_threads
    seen = []

    def progress(fraction, message):
        seen.append(_counts(libs))
    V, F = make_surface('bump3', 17)
    if entry == 'flatten':
        r = flatten(V, F, boundary='uniform', bound=True, progress=progress)
        assert r.report['bound_vertex'] > 0
    else:
        unwrap(V, F, boundary='uniform', progress=progress)
    assert seen and all(c == [1] * len(libs) for c in seen)
    assert _counts(libs) == [2] * len(libs)


def test_beside_inline_below_the_threshold_and_errors_alike():
    out = beside(10, np.add, 1, 2)
    assert type(out) is Done and out.result() == 3
    big = beside(10**9, np.add, 1, 2)
    assert isinstance(big, Background) and big.result() == 3
    for faces in (10, 10**9):
        job = beside(faces, lambda: 1 / 0)
        with pytest.raises(ZeroDivisionError):
            job.result()
