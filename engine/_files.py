"""Opening a user's file safely: regular files only.

Every reader of the engine opens the files it is given through here (the loaders of
:mod:`engine.io`, the streamed readers of :mod:`engine.wv.stream`, ``read_datasheet``, sessions),
so that the command line and the app refuse the same things with the same one-line message and
keep no checks of their own:

* anything but a regular file: opening a FIFO for reading waits for a writer forever, a
  character device such as ``/dev/zero`` never ends, a socket cannot be read, and a directory is
  not a file. :func:`open_regular` opens with ``O_NONBLOCK`` and checks the opened descriptor
  with ``fstat`` (so a FIFO put in place after a check cannot block either), then clears
  ``O_NONBLOCK`` for ordinary reads;
* a file that cannot fit in memory is refused by the readers before anything is parsed, with
  :func:`engine._limits.check_memory` (the one place that knows the memory available).

Messages name the file as the caller gave it (``src``) and never quote its content.

Writing goes through here too, so that no output of the command line or of an engine writer
can destroy data:

* :func:`check_not_input` refuses an output that is one of the inputs (the same file: same
  device and inode, symlinks and hard links included);
* :func:`atomic_output` (and :func:`write_atomic` for text or bytes) writes a temporary file
  in the output's folder and renames it over the output only once it is complete: a full disk,
  a crash or an interrupt leaves the previous file (or none), never a truncated one, and the
  error names the file.
"""

from __future__ import annotations

import os
import stat
from collections.abc import Iterable, Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO

from ._limits import check_memory

__all__ = [
    "file_kind",
    "check_regular",
    "open_regular",
    "read_regular",
    "same_file",
    "check_not_input",
    "atomic_output",
    "write_atomic",
]

_KINDS = (
    (stat.S_ISFIFO, "a FIFO (named pipe)"),
    (stat.S_ISCHR, "a character device"),
    (stat.S_ISBLK, "a block device"),
    (stat.S_ISSOCK, "a socket"),
    (stat.S_ISDIR, "a directory"),
)


def file_kind(mode: int) -> str:
    """What a file of ``st_mode`` ``mode`` is, as words: ``"a regular file"``, ``"a FIFO (named
    pipe)"``, ``"a character device"``, ``"a block device"``, ``"a socket"``, ``"a directory"``
    or ``"a special file"``."""
    if stat.S_ISREG(mode):
        return "a regular file"
    return next((words for test, words in _KINDS if test(mode)), "a special file")


def _refusal(src: str, mode: int) -> str:
    return f"'{src}' is not a regular file (it is {file_kind(mode)}): give the path of a file"


def check_regular(
    path: str | os.PathLike[str],
    src: str | None = None,
    *,
    error: type[Exception] = ValueError,
) -> os.stat_result:
    """The ``stat`` of ``path``, which must be an existing regular file (symlinks followed).

    Parameters
    ----------
    path : str or path-like
        The file.
    src : str, optional
        The file as the user gave it, for messages (default: ``path``).
    error : exception type
        Raised with the message (``LoadError`` for the loaders, ``ValueError`` by default).

    Returns
    -------
    os.stat_result

    Raises
    ------
    error
        Missing or unreadable path, or not a regular file: one line naming ``src``, saying
        what it is and what to give instead, e.g. ``'x.h5' is not a regular file (it is a
        FIFO (named pipe)): give the path of a file``.
    """
    src = os.fspath(path) if src is None else src
    try:
        st = os.stat(path)
    except (FileNotFoundError, NotADirectoryError):
        raise error(f"cannot read '{src}': no such file (check the path)") from None
    except PermissionError:
        raise error(f"cannot read '{src}' (permission denied): check its permissions") from None
    except (OSError, ValueError) as exc:  # ValueError: a NUL byte in the path
        why = getattr(exc, "strerror", None) or "invalid path"
        raise error(f"cannot read '{src}' ({why}): check the path") from None
    if not stat.S_ISREG(st.st_mode):
        raise error(_refusal(src, st.st_mode))
    return st


def open_regular(
    path: str | os.PathLike[str],
    src: str | None = None,
    *,
    error: type[Exception] = ValueError,
) -> BinaryIO:
    """Open a regular file for binary reading, refusing anything else without blocking.

    The path is checked with :func:`check_regular` (for a clear message), then opened with
    ``O_NONBLOCK`` and the opened descriptor checked again with ``fstat``: what is read is the
    file that was checked, and a FIFO swapped in between cannot make the open wait. Parameters
    and errors as :func:`check_regular`.

    Returns
    -------
    BinaryIO
        An unbuffered-open, buffered-read binary file object (close it, e.g. ``with``).
    """
    src = os.fspath(path) if src is None else src
    check_regular(path, src, error=error)
    flags = os.O_RDONLY | getattr(os, "O_NONBLOCK", 0) | getattr(os, "O_BINARY", 0)
    try:
        fd = os.open(path, flags | getattr(os, "O_CLOEXEC", 0))
    except OSError as exc:
        why = exc.strerror or "cannot open"
        raise error(f"cannot read '{src}' ({why}): check the path and its permissions") from None
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):
            raise error(_refusal(src, mode))
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(
    path: str | os.PathLike[str],
    src: str | None = None,
    *,
    error: type[Exception] = ValueError,
    factor: float = 1.0,
) -> bytes:
    """The whole content of a regular file, after checking that ``factor`` times its size fits
    in the available memory (:func:`check_memory`). Parameters and errors as
    :func:`check_regular`."""
    src = os.fspath(path) if src is None else src
    with open_regular(path, src, error=error) as fh:
        check_memory(int(factor * os.fstat(fh.fileno()).st_size), src, error=error)
        return fh.read()


def same_file(a: str | os.PathLike[str], b: str | os.PathLike[str]) -> bool:
    """Whether ``a`` and ``b`` are the same existing file (device and inode, symlinks
    followed: a symlink or a hard link to a file is that file)."""
    try:
        sa, sb = os.stat(a), os.stat(b)
    except (OSError, ValueError):
        return False
    return (sa.st_dev, sa.st_ino) == (sb.st_dev, sb.st_ino)


def check_not_input(
    output: str | os.PathLike[str] | None,
    inputs: Iterable[str | os.PathLike[str] | None],
    *,
    what: str = "the output",
    error: type[Exception] = ValueError,
) -> None:
    """Refuse an output that is one of the ``inputs`` (see :func:`same_file`).

    Parameters
    ----------
    output : path or None
        The file to be written (None and ``"-"``, stdout, pass).
    inputs : iterable of paths
        The files the command reads (None entries are skipped).
    what : str
        How the caller names the output in the message (``"-o out.yaml"``).
    error : exception type
        Raised with a one-line message naming both paths.
    """
    if output is None or str(output) == "-":
        return
    for src in inputs:
        if src is not None and same_file(output, src):
            same = "" if str(src) == str(output) else f" (through the path '{output}')"
            raise error(
                f"{what} is the input file '{src}'{same}: writing it would destroy the input; "
                "choose another output file"
            )


def _write_refusal(path: str | os.PathLike[str], exc: OSError) -> str:
    why = exc.strerror or type(exc).__name__
    return (
        f"cannot write '{os.fspath(path)}' ({why}): nothing was written and any previous "
        "file of that name is unchanged; free space or choose another folder"
    )


@contextmanager
def atomic_output(
    path: str | os.PathLike[str], *, error: type[Exception] = OSError
) -> Iterator[Path]:
    """Write a file atomically: yields a temporary path in the same folder (same suffix, so
    that writers that add one, such as ``numpy.save``, keep it), renamed over ``path`` when
    the block ends without an error; removed otherwise.

    A symlink ``path`` stays a symlink: its target is replaced. A ``path`` that exists and is
    not a regular file (``/dev/null``, ``/dev/stdout``, a FIFO) is yielded as it is and written
    in place: renaming over it would replace the device by a file (as root, ``-o /dev/null``
    turned /dev/null into a regular file for every process of the machine). An ``OSError``
    while writing or renaming (a full disk: ENOSPC) becomes ``error`` with one line naming
    ``path``.
    """
    final = Path(os.path.realpath(path))
    try:
        special = not stat.S_ISREG(os.stat(final).st_mode)
    except OSError:  # a new file
        special = False
    if special:  # /dev/null, /dev/stdout, a FIFO: in place (a rename would replace the device)
        try:
            yield final
        except OSError as exc:
            raise error(_write_refusal(path, exc)) from exc
        return
    # a random name (os.urandom: the secrets module, which says the same, costs the gmwm command
    # 0.02 s of imports, hmac and hashlib, for every sub-command)
    tmp = final.with_name(f".{final.name}.{os.urandom(4).hex()}.tmp{final.suffix}")
    try:
        # created here, so that the umask gives it a new file's mode, and no other file is
        # ever written through this name (O_EXCL)
        os.close(os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | os.O_CLOEXEC, 0o666))
        yield tmp
        if final.exists():  # a replaced file keeps its mode
            os.chmod(tmp, stat.S_IMODE(os.stat(final).st_mode))
        os.replace(tmp, final)
    except OSError as exc:
        _remove(tmp)
        raise error(_write_refusal(path, exc)) from exc
    except BaseException:
        _remove(tmp)
        raise


def write_atomic(
    path: str | os.PathLike[str],
    data: str | bytes,
    *,
    encoding: str = "utf-8",
    error: type[Exception] = OSError,
) -> Path:
    """Write ``data`` (text, encoded with ``encoding``, or bytes) to ``path`` atomically
    (:func:`atomic_output`), flushed to the disk before the rename; returns the path."""
    raw = data.encode(encoding) if isinstance(data, str) else bytes(data)
    with atomic_output(path, error=error) as tmp:
        with open(tmp, "wb") as fh:
            fh.write(raw)
            fh.flush()
            if stat.S_ISREG(os.fstat(fh.fileno()).st_mode):  # a device has nothing to sync
                os.fsync(fh.fileno())
    return Path(path)


def _remove(p: Path) -> None:
    try:
        os.unlink(p)
    except OSError:
        pass
