"""The BLAS (OpenBLAS) thread pool of this process: read it, limit it.

The engine's BLAS calls are small (a sum of squares of a 32k-sample block, matrices of a few
dozen rows). OpenBLAS splits a dot product of more than 10,000 elements over its threads,
which costs more than it saves at this size and becomes 4-30x slower as soon as another
thread or process keeps a core busy (its threads spin waiting for each other). So the
wavelet variance calls BLAS on the whole block only when the pool has one thread, and otherwise
in chunks that OpenBLAS keeps in the calling thread
(:func:`engine.wv._kernel.second_difference_sums`); the ``gmwm`` command and the app limit the
pool to one thread. Library users keep whatever their process has configured.

Uses threadpoolctl when installed, else OpenBLAS's own ``*_num_threads`` functions through
ctypes (the libraries are found in ``/proc/self/maps``, Linux).
"""

from __future__ import annotations

import ctypes
from collections.abc import Iterator
from contextlib import contextmanager
from functools import lru_cache
from typing import Any

__all__ = ["blas_threads", "set_blas_threads", "one_blas_thread"]

_SET = (
    "scipy_openblas_set_num_threads64_",
    "scipy_openblas_set_num_threads",
    "openblas_set_num_threads64_",
    "openblas_set_num_threads",
)
_GET = (
    "scipy_openblas_get_num_threads64_",
    "scipy_openblas_get_num_threads",
    "openblas_get_num_threads64_",
    "openblas_get_num_threads",
)


@lru_cache(maxsize=1)
def _openblas_libs() -> tuple[Any, ...]:
    """The OpenBLAS libraries loaded in this process (NumPy's, SciPy's ...)."""
    import numpy  # noqa: F401 - its BLAS must be loaded to be found

    paths: set[str] = set()
    try:
        with open("/proc/self/maps") as f:
            for line in f:
                parts = line.split()
                if len(parts) >= 6 and "openblas" in parts[-1].lower() and ".so" in parts[-1]:
                    paths.add(parts[-1])
    except OSError:
        return ()
    libs = []
    for path in sorted(paths):
        try:
            libs.append(ctypes.CDLL(path))
        except OSError:
            continue
    return tuple(libs)


def _numpy_blas() -> Any:
    """NumPy's OpenBLAS library (the one ``np.dot`` calls), or None."""
    libs = _openblas_libs()
    for lib in libs:  # scipy-openblas (NumPy's wheels) first, by name
        if getattr(lib, _GET[0], None) is not None or getattr(lib, _GET[1], None) is not None:
            return lib
    return libs[0] if libs else None


def blas_threads() -> int | None:
    """Threads of NumPy's OpenBLAS pool, or None when unknown (another BLAS, not Linux)."""
    lib = _numpy_blas()
    if lib is None:
        return None
    for name in _GET:
        fn = getattr(lib, name, None)
        if fn is not None:
            return int(fn())
    return None


def set_blas_threads(n: int = 1) -> bool:
    """Limit the BLAS thread pools of this process to ``n`` threads.

    Parameters
    ----------
    n : int
        Threads per pool (1: BLAS runs in the calling thread).

    Returns
    -------
    bool
        True when a limit was set.
    """
    try:
        from threadpoolctl import threadpool_limits
    except ImportError:
        pass
    else:
        threadpool_limits(int(n), user_api="blas")
        return True
    done = False
    for lib in _openblas_libs():
        for name in _SET:
            fn = getattr(lib, name, None)
            if fn is not None:
                fn(int(n))
                done = True
                break
    return done


@contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the block with NumPy's BLAS on one thread, then restore the previous count.

    The tasks of :func:`engine._parallel.parallel_map` run like this in process, as they do in
    the pool's and Dask's workers, so a result does not depend on where its task ran (the WV
    kernel sums in chunks on a multi-threaded BLAS: the last bit can differ).
    """
    prev = blas_threads()
    if prev is None or prev == 1:
        yield
        return
    set_blas_threads(1)
    try:
        yield
    finally:
        set_blas_threads(prev)
