"""The one mapping helper every parallel path of the engine uses, and its progress line.

:func:`parallel_map` maps a module-level function over a list of independent tasks, in order:

* in process (``workers <= 1``, or fewer than 4 tasks);
* on a local pool of ``workers`` spawned processes (the embedded default), each with one BLAS
  thread;
* on any :class:`concurrent.futures.Executor` given as ``executor=``: a
  :class:`~concurrent.futures.ThreadPoolExecutor`, a process pool, or a Dask cluster's
  ``Client.get_executor()`` (:func:`dask_executor` opens one from a scheduler address).

Every task carries its own seed (the callers spawn one ``SeedSequence`` child per replicate),
so the results do not depend on the executor, the number of workers, the chunking or the
order in which the tasks finish. Dask (``pip install "gmwm-app[dask]"``) is imported only by
:func:`dask_executor`: ``import engine`` never imports it.
"""

from __future__ import annotations

import math
import multiprocessing
import os
import sys
import threading
import time
import warnings
from collections.abc import Callable, Iterator, Sequence
from concurrent.futures import Executor, Future, ProcessPoolExecutor, as_completed
from contextlib import contextmanager
from typing import Any, TextIO

from ._blas import one_blas_thread

__all__ = [
    "parallel_map",
    "ProgressLine",
    "dask_executor",
    "executor_workers",
    "main_importable",
    "end_with_parent",
]

_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
#: glibc's trim threshold, which Dask sets to 64 KiB for its workers (and, once a LocalCluster
#: has started, in this process's environment). Set at all, it turns off glibc's dynamic mmap
#: threshold, so every array above 128 KiB is a fresh mmap whose pages fault in again: the
#: study's replicates ran 3-5x slower (bench_dask.py). Neither our pool nor our LocalCluster
#: sets it.
_MALLOC_TRIM = "MALLOC_TRIM_THRESHOLD_"


def main_importable() -> bool:
    """Can a spawned worker process start? Not when ``__main__`` names a file that does not
    exist (``python - < script``): spawn re-runs the main file in every worker."""
    main_file = getattr(sys.modules.get("__main__"), "__file__", None)
    return main_file is None or os.path.exists(main_file)


#: How often (seconds) a worker checks that the process that started it is still alive.
PARENT_POLL_S = 0.5


def end_with_parent(parent: int) -> None:
    """Worker initializer: end this worker (``os._exit``) as soon as ``parent`` (the process
    that started it) is gone, checked every :data:`PARENT_POLL_S` seconds by a daemon thread.

    Without it, a ``gmwm batch`` killed with SIGKILL left its workers waiting on their queue
    forever (and the resource tracker with them: it ends when the last of them has).
    ``PR_SET_PDEATHSIG`` is not used: it follows the thread that started the worker, which
    in a server's thread pool may end long before the process.
    """
    if os.getppid() != parent:
        os._exit(1)

    def watch() -> None:
        while True:
            time.sleep(PARENT_POLL_S)
            if os.getppid() != parent:
                os._exit(1)

    threading.Thread(target=watch, name="gmwm-parent-watch", daemon=True).start()


def _run_chunk(fn: Callable[[Any], Any], chunk: Sequence[Any]) -> list[Any]:
    return [fn(it) for it in chunk]


@contextmanager
def _local_pool(workers: int) -> Iterator[ProcessPoolExecutor]:
    """``workers`` spawned processes with one BLAS thread each: forked workers that inherit a
    multithreaded BLAS spin on each other's small matrix products (10x slower). The pool
    starts its processes as tasks are submitted, so the variables stay set until it is shut
    down. Without ``MALLOC_TRIM_THRESHOLD_`` (see :data:`_MALLOC_TRIM`)."""
    saved = {k: os.environ.get(k) for k in (*_THREAD_VARS, _MALLOC_TRIM)}
    os.environ.update({k: "1" for k in _THREAD_VARS})
    os.environ.pop(_MALLOC_TRIM, None)
    ex = ProcessPoolExecutor(
        max_workers=workers,
        mp_context=multiprocessing.get_context("spawn"),
        initializer=end_with_parent,
        initargs=(os.getpid(),),
    )
    try:
        yield ex
    except BaseException:  # Ctrl-C, a failed task or a cancel: drop the queued tasks
        ex.shutdown(wait=False, cancel_futures=True)
        raise
    else:
        ex.shutdown(wait=True)
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


def parallel_map(
    fn: Callable[[Any], Any],
    items: Sequence[Any],
    workers: int = 1,
    *,
    executor: Executor | None = None,
    progress: Callable[[int, int], None] | None = None,
    chunksize: int | None = None,
    each: Callable[[int, Any], None] | None = None,
) -> list[Any]:
    """``[fn(item) for item in items]``, in parallel, in the order of ``items``.

    Parameters
    ----------
    fn : callable
        A module-level (picklable) function of one task.
    items : sequence
        The tasks; each carries everything ``fn`` needs, its seed included, so the results do
        not depend on where or in which order they run.
    workers : int
        Processes of the embedded local pool (``1``: in process). Ignored with ``executor``.
    executor : concurrent.futures.Executor, optional
        Where the tasks run instead of the local pool (not shut down here): e.g. a Dask
        ``Client.get_executor()``, on which a task lost with a worker is run again.
    progress : callable (done, total), optional
        Called in this process after every task (a chunk's tasks are counted when the chunk
        returns). An exception raised by it cancels the tasks not yet started and propagates
        (a user's cancel).
    each : callable (index, result), optional
        Called in this process with every task's result as soon as it is back (in the order
        they complete), before ``progress``: e.g. to write each result as it completes.
    chunksize : int, optional
        Tasks per submitted job. Default: about four jobs per local worker; one task per job
        on an ``executor`` (the finest progress, and a lost worker loses one task).

    Returns
    -------
    list
        ``fn(item)`` for every item, in order.
    """
    items = list(items)
    total = len(items)
    if executor is None and (workers <= 1 or total < 4 or not main_importable()):
        out = []
        with one_blas_thread():  # as in a worker: the same numbers wherever a task runs
            for it in items:
                out.append(fn(it))
                if each is not None:
                    each(len(out) - 1, out[-1])
                if progress is not None:
                    progress(len(out), total)
        return out
    if chunksize is None:
        chunksize = 1 if executor is not None else max(1, total // (4 * max(1, workers)))
    chunks = [items[i : i + chunksize] for i in range(0, total, chunksize)]
    if executor is not None:
        return _collect(executor, fn, chunks, total, progress, own=False, each=each)
    with _local_pool(workers) as pool:
        return _collect(pool, fn, chunks, total, progress, own=True, each=each)


def _collect(
    ex: Executor,
    fn: Callable[[Any], Any],
    chunks: list[list[Any]],
    total: int,
    progress: Callable[[int, int], None] | None,
    own: bool,
    each: Callable[[int, Any], None] | None = None,
) -> list[Any]:
    futs: dict[Future, int] = {}
    try:
        start = 0
        for chunk in chunks:
            futs[ex.submit(_run_chunk, fn, chunk)] = start
            start += len(chunk)
        out: list[Any] = [None] * total
        done = 0
        for f in as_completed(futs):
            res = f.result()
            out[futs[f] : futs[f] + len(res)] = res
            if each is not None:
                for k, r in enumerate(res):
                    each(futs[f] + k, r)
            done += len(res)
            if progress is not None:
                progress(done, total)
        return out
    except BaseException:
        if not own:  # someone else's executor: cancel our tasks, keep the executor
            for f in futs:
                f.cancel()
        raise


def executor_workers(executor: Executor | None, workers: int) -> int:
    """How many workers run the tasks: a Dask executor's cluster size, a pool's size, else
    ``workers``."""
    client = getattr(executor, "_client", None)  # distributed.cfexecutor.ClientExecutor
    if client is not None:
        try:
            return len(client.scheduler_info()["workers"])
        except Exception:  # noqa: BLE001 - a description only
            return workers
    n = getattr(executor, "_max_workers", None)
    return int(n) if isinstance(n, int) else workers


@contextmanager
def dask_executor(address: str, workers: int = 2) -> Iterator[Executor]:
    """A Dask cluster's executor (``Client.get_executor()``), closed on exit.

    Parameters
    ----------
    address : str
        ``"local"``: start a ``LocalCluster`` of ``workers`` processes (one thread each) on
        this machine (without Dask's ``MALLOC_TRIM_THRESHOLD_``, which slows NumPy code with
        large temporaries 3-5x); otherwise a running scheduler's address
        (``tcp://host:8786``), e.g. one started by ``dask scheduler`` or by dask-jobqueue.
        Its workers need this package (the same version) and must see the input files at the
        same paths.
    workers : int
        Worker processes of ``"local"``.

    Raises
    ------
    ImportError
        Without Dask: install the extra, ``pip install "gmwm-app[dask]"``.
    """
    try:
        from distributed import Client, LocalCluster
    except ImportError as e:
        raise ImportError(
            "scheduler= needs Dask's distributed scheduler: pip install 'gmwm-app[dask]' "
            "(or 'dask[distributed]')"
        ) from e
    cluster = None
    if address == "local":
        import dask

        no_trim = {f"distributed.nanny.pre-spawn-environ.{_MALLOC_TRIM}": None}  # see above
        with warnings.catch_warnings(), dask.config.set(no_trim):
            # its HTTP server moves off a busy port: no news
            warnings.filterwarnings("ignore", message="Port .* is already in use")
            cluster = LocalCluster(
                n_workers=max(1, int(workers)),
                threads_per_worker=1,
                processes=True,
                dashboard_address=None,
            )
        client = Client(cluster)
    else:
        try:
            client = Client(address, timeout="10s")
        except OSError as e:
            raise OSError(f"cannot reach the Dask scheduler at {address!r}: {e}") from None
    try:
        # pure=False: every call is its own task, never merged with an equal-looking one
        yield client.get_executor(pure=False)
    finally:
        client.close()
        if cluster is not None:
            cluster.close()


class ProgressLine:
    """A progress line on a stream: a bar on a terminal, a line per 10 % otherwise.

    ``ProgressLine(total, stream, label)(done, total)`` is a ``progress`` callback of
    :func:`parallel_map`; :meth:`update` counts ``k`` more. ``stream=None`` prints nothing.
    """

    def __init__(
        self, total: int, stream: TextIO | None, label: str = "progress", noun: str = ""
    ) -> None:
        self.total, self.stream, self.label = total, stream, label
        self.noun = f" {noun}" if noun else ""
        self.done = 0
        self.t0 = time.perf_counter()
        self.tty = bool(stream is not None and hasattr(stream, "isatty") and stream.isatty())
        self._next_pct = 10

    def __call__(self, done: int, total: int) -> None:
        self.total = total
        self.update(done - self.done)

    def update(self, k: int = 1) -> None:
        """Count ``k`` more tasks done and print the line when due."""
        self.done += k
        if self.stream is None or self.total <= 0:
            return
        el = time.perf_counter() - self.t0
        eta = el / self.done * (self.total - self.done) if self.done else math.nan
        pct = 100.0 * self.done / self.total
        if self.tty:
            w = 30
            fill = int(w * self.done / self.total)
            self.stream.write(
                f"\r{self.label} [{'#' * fill}{'.' * (w - fill)}] "
                f"{self.done}/{self.total}{self.noun} {el:6.0f} s, ETA {eta:5.0f} s"
            )
            if self.done == self.total:
                self.stream.write("\n")
            self.stream.flush()
        elif pct >= self._next_pct or self.done == self.total:
            while self._next_pct <= pct:
                self._next_pct += 10
            self.stream.write(
                f"{self.label}: {self.done}/{self.total}{self.noun} ({pct:.0f} %), "
                f"{el:.0f} s, ETA {eta:.0f} s\n"
            )
            self.stream.flush()
