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
"""

from __future__ import annotations

import os
import stat
from typing import BinaryIO

from ._limits import check_memory

__all__ = [
    "file_kind",
    "check_regular",
    "open_regular",
    "read_regular",
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
