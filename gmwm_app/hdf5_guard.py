"""A watchdog for HDF5 files: the app reads their metadata in a helper process first.

The HDF5 C library can loop forever or crash on a damaged file. Seen here (h5py 3.16, HDF5
2.0): a randomly corrupted copy of a valid log whose global heap makes the read of a
variable-length string attribute loop in C while holding the GIL, so a single upload froze the
whole server, every session with it, and no signal could stop it. So before the app's loader
touches an HDF5 file (a server path or an upload), :func:`check_hdf5` has a helper process
open it, read every attribute and the first elements of every dataset; a file that the helper
does not finish within the time limit, or that kills it, is refused with a message, and the
helper is replaced. The helper is started once and kept (0.4 s to start; a check then takes
milliseconds), one check at a time.
"""

from __future__ import annotations

import io
import multiprocessing
import os
import signal
import threading
from multiprocessing.connection import Connection
from typing import Any

__all__ = [
    "HDF5_MAGIC",
    "TIMEOUT_S",
    "is_hdf5",
    "walk_hdf5",
    "check_hdf5",
    "start_helper",
    "stop_helper",
    "helper_pid",
]

#: The HDF5 signature (at offset 0 in the files h5py writes; 512, 1024 ... after a user block).
HDF5_MAGIC = b"\x89HDF\r\n\x1a\n"
#: How long the helper may take to read a file's metadata (s).
TIMEOUT_S = 15.0
#: Elements read from the start of each dataset (the chunk index and the first chunk).
HEAD = 4096

_LOCK = threading.Lock()
_HELPER: dict[str, Any] = {}  # "proc", "conn", "pid" (the process that started it)


def is_hdf5(head: bytes, name: str = "") -> bool:
    """True when a file starting with ``head`` (or named ``name``) is HDF5.

    Parameters
    ----------
    head : bytes
        The file's first bytes (at least 8, up to 2048 to see a user block's signature).
    name : str
        The file name: ``.h5``, ``.hdf5``, ``.he5`` count as HDF5 whatever the content.
    """
    if name.lower().endswith((".h5", ".hdf5", ".he5")):
        return True
    return any(head[k : k + 8] == HDF5_MAGIC for k in (0, 512, 1024, 2048))


def walk_hdf5(source: str | bytes) -> int:
    """Open an HDF5 file, read every attribute and the first :data:`HEAD` elements of every
    dataset; return the number of objects (run in the helper process).

    Parameters
    ----------
    source : str or bytes
        A path or the file's content.
    """
    import h5py
    import numpy as np

    n = 0
    with h5py.File(io.BytesIO(source) if isinstance(source, bytes) else source, "r") as f:
        objects: list[Any] = [f]
        f.visititems(lambda _name, obj: objects.append(obj))
        for obj in objects:
            for key in obj.attrs:
                obj.attrs.get(key)
            if isinstance(obj, h5py.Dataset) and obj.shape:
                np.asarray(obj[: min(obj.shape[0], HEAD)])
            n += 1
    return n


def _serve(conn: Connection) -> None:  # pragma: no cover - runs in the helper process
    # Ctrl+C in the server's terminal reaches the whole process group: the server stops and
    # closes the pipe (EOF below ends the helper); a KeyboardInterrupt here would only print
    # a traceback of the helper's wait
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    while True:
        try:
            kind = conn.recv()  # "path" (then the path) or "bytes" (then the content)
            source = conn.recv() if kind == "path" else conn.recv_bytes()
        except (EOFError, OSError, KeyboardInterrupt):
            return
        try:
            conn.send(("ok", walk_hdf5(source)))
        except Exception as e:  # noqa: BLE001 - reported; the loader gives its own message
            conn.send(("error", f"{type(e).__name__}: {e}"))


def _helper() -> tuple[Any, Connection]:
    if _HELPER.get("pid") != os.getpid():  # started by the parent of a forked server process
        _HELPER.clear()  # (its helper and pipe belong to that parent: not touched here)
    proc = _HELPER.get("proc")
    if proc is None or not proc.is_alive():
        ctx = multiprocessing.get_context("spawn")
        parent, child = ctx.Pipe()
        proc = ctx.Process(target=_serve, args=(child,), daemon=True, name="gmwm-hdf5-guard")
        proc.start()
        child.close()
        _HELPER.update(proc=proc, conn=parent, pid=os.getpid())
    return proc, _HELPER["conn"]


def stop_helper() -> None:
    """Stop the helper process (it is started again by the next check)."""
    if _HELPER.pop("pid", None) != os.getpid():
        _HELPER.clear()
        return
    proc, conn = _HELPER.pop("proc", None), _HELPER.pop("conn", None)
    if conn is not None:
        conn.close()
    if proc is not None and proc.is_alive():
        proc.kill()
        proc.join(5)


def helper_pid() -> int | None:
    """The process id of this process's helper while it is alive (the one process the app
    keeps), else None."""
    proc = _HELPER.get("proc") if _HELPER.get("pid") == os.getpid() else None
    return proc.pid if proc is not None and proc.is_alive() else None


def start_helper() -> None:
    """Start the helper now (a server does it at start, so the first file does not wait)."""
    with _LOCK:
        _helper()


def check_hdf5(
    source: str | bytes | bytearray | memoryview, name: str, timeout: float | None = None
) -> None:
    """Refuse an HDF5 file whose metadata the HDF5 library cannot read in ``timeout`` seconds
    or on which it crashes, without risking this process.

    Other read errors pass: the loader then reports them with its own message.

    Parameters
    ----------
    source : str or bytes-like
        A path or the file's content (sent to the helper as a buffer, not copied here).
    name : str
        The file name, for the message.
    timeout : float, optional
        Time limit (s) for the helper (default :data:`TIMEOUT_S`).

    Raises
    ------
    ValueError
        The file hangs or crashes the HDF5 library; the message says so.
    """
    timeout = TIMEOUT_S if timeout is None else timeout
    with _LOCK:
        _, conn = _helper()
        try:
            if isinstance(source, str):
                conn.send("path")
                conn.send(source)
            else:  # the buffer itself: no pickled copy of a large upload
                conn.send("bytes")
                conn.send_bytes(source)
            if not conn.poll(timeout):
                stop_helper()
                raise ValueError(
                    f"file '{name}' could not be read: the HDF5 library did not finish reading "
                    f"its metadata in {timeout:g} s, so the file is probably damaged; nothing "
                    "was loaded (check that the file is complete, or export it again)"
                )
            conn.recv()
        except (EOFError, OSError, BrokenPipeError):
            stop_helper()
            raise ValueError(
                f"file '{name}' could not be read: it crashed the HDF5 library (the file is "
                "damaged); nothing was loaded (check that the file is complete, or export it "
                "again)"
            ) from None
