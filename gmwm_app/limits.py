"""Server limits of the app: the largest accepted upload and the folders server paths may name.

``gmwm-app`` configures them from ``--max-upload-mb`` and ``--data-dir`` (default folders: the
current directory, the folder of the bundled demo log and, in a checkout, the shared ``data``
folder next to the repository when it exists). Without :func:`configure` (scripts, tests)
uploads are limited to :data:`DEFAULT_MAX_UPLOAD_MB` and any server path may be read.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from dataclasses import dataclass
from pathlib import Path

__all__ = [
    "DEFAULT_MAX_UPLOAD_MB",
    "UPLOAD_CHUNK_BYTES",
    "MAX_MESSAGE_BYTES",
    "ServerLimits",
    "configure",
    "current",
    "default_data_dirs",
    "check_path",
    "public_path",
    "check_upload_size",
    "check_candidates",
    "DEFAULT_MAX_CANDIDATES",
    "DEFAULT_SESSION_JOBS",
    "upload_refusal",
]

#: Upload limit (MB) when none is configured.
DEFAULT_MAX_UPLOAD_MB = 200.0
#: An upload reaches the server in chunks of this many bytes, one websocket message each
#: (:class:`gmwm_app.upload.BoundedFileDropper`); ``gmwm-app`` refuses larger messages.
UPLOAD_CHUNK_BYTES = 8_000_000
#: Largest message a browser may send the server (bytes): two upload chunks. An upload arrives
#: in chunks of ``UPLOAD_CHUNK_BYTES`` (one message each); every other message a page sends is
#: small. It bounds each websocket message (Tornado refuses a larger one before buffering it),
#: all the websocket messages of one Bokeh message together, and the decompressed size of the
#: inline compressed values of one message (:func:`gmwm_app.server_guard.bound_messages`).
MAX_MESSAGE_BYTES = 2 * UPLOAD_CHUNK_BYTES

_REPO = Path(__file__).resolve().parents[1]


#: Candidate models one ranking may fit (the Model selection tab), when none is configured.
DEFAULT_MAX_CANDIDATES = 128
#: Computations of one session that may occupy the shared worker threads at once.
DEFAULT_SESSION_JOBS = 2


@dataclass(frozen=True)
class ServerLimits:
    """``max_upload_mb``: largest upload (MB, 1 MB = 1e6 bytes); ``data_dirs``: folders that
    server paths must lie in (None: any path); ``allowed_files``: single files allowed besides
    (the ``gmwm-app FILE`` argument); ``max_candidates``: candidate models one ranking may
    fit; ``session_jobs``: computations of one session running at once in the shared worker
    threads (the others wait their turn, so that no session takes every thread)."""

    max_upload_mb: float = DEFAULT_MAX_UPLOAD_MB
    data_dirs: tuple[Path, ...] | None = None
    allowed_files: tuple[Path, ...] = ()
    max_candidates: int = DEFAULT_MAX_CANDIDATES
    session_jobs: int = DEFAULT_SESSION_JOBS

    @property
    def max_upload_bytes(self) -> int:
        return int(self.max_upload_mb * 1e6)


_LIMITS = ServerLimits()


def default_data_dirs() -> list[Path]:
    """The current directory, the bundled demo's folder and ``<repo>/../shared/data`` (the
    real logs next to a checkout), those that exist."""
    from engine.demo import demo_dir

    out = [Path.cwd(), demo_dir(), _REPO.parent / "shared" / "data"]
    return [p.resolve() for p in out if p.is_dir()]


def configure(
    *,
    max_upload_mb: float | None = None,
    data_dirs: Iterable[str | os.PathLike[str]] | None = None,
    allowed_files: Iterable[str | os.PathLike[str]] = (),
    max_candidates: int | None = None,
    session_jobs: int | None = None,
) -> ServerLimits:
    """Set the limits of this process (every session); returns them.

    ``data_dirs=None`` lifts the folder restriction; ``None`` for a number keeps its default.
    """
    global _LIMITS
    mb = DEFAULT_MAX_UPLOAD_MB if max_upload_mb is None else float(max_upload_mb)
    if not mb > 0:
        raise ValueError(f"the upload limit must be a positive number of MB, got {max_upload_mb}")
    cands = DEFAULT_MAX_CANDIDATES if max_candidates is None else int(max_candidates)
    jobs = DEFAULT_SESSION_JOBS if session_jobs is None else int(session_jobs)
    if cands < 1 or jobs < 1:
        raise ValueError(
            f"the candidate and job limits must be at least 1, got {max_candidates}, {session_jobs}"
        )
    dirs = None if data_dirs is None else tuple(Path(d).expanduser().resolve() for d in data_dirs)
    files = tuple(Path(f).expanduser().resolve() for f in allowed_files)
    _LIMITS = ServerLimits(mb, dirs, files, cands, jobs)
    return _LIMITS


def current() -> ServerLimits:
    """The limits in force."""
    return _LIMITS


def check_path(path: str | os.PathLike[str]) -> Path:
    """The server file ``path`` names (``~`` expanded), if it lies in a configured folder;
    else ValueError.

    A relative path is looked up in each configured folder in turn (as :func:`public_path`
    names files), then in the current directory; the single files allowed besides are also
    found by their name. The message names the path as given and lists no folder of the
    server; whether the path exists is checked after, so that a page's user learns nothing
    of the server's files outside the folders."""
    p = Path(path).expanduser()
    lim = _LIMITS
    if lim.data_dirs is None:
        return p
    if not p.is_absolute():
        for d in lim.data_dirs:
            q = (d / p).resolve()
            if q.is_relative_to(d) and q.exists():
                return d / p
        for f in lim.allowed_files:
            if f.name == os.fspath(path):
                return f
    r = p.resolve()
    if r in lim.allowed_files or any(r.is_relative_to(d) for d in lim.data_dirs):
        return p
    raise ValueError(
        f"'{os.fspath(path)}' is outside the folders this server may read: only files under "
        "the server's data folders can be opened by path; upload the file instead (or, on "
        "the server, start gmwm-app with --data-dir FOLDER)"
    )


def public_path(path: str | os.PathLike[str]) -> str:
    """How a server file is named to the page's user (links, downloaded sessions): relative
    to the configured folder that holds it, or its name for a single allowed file, so that
    the server's folders are never shown; :func:`check_path` finds it again from that name.
    Without configured folders (a local app), the absolute path."""
    r = Path(path).expanduser().resolve()
    lim = _LIMITS
    if lim.data_dirs is None:
        return str(r)
    for d in lim.data_dirs:
        if r.is_relative_to(d):
            return r.relative_to(d).as_posix()
    return r.name


def upload_refusal(name: str, n_bytes: int, at_least: bool = False) -> str:
    """The message refusing an upload of ``n_bytes`` (``at_least``: its size is not known yet,
    only that it is larger) named ``name``."""
    lim = _LIMITS
    what = f"the uploaded file {name}" if name else "the uploaded file"
    mb = f"{n_bytes / 1e6:.1f}" if n_bytes >= 1e6 else f"{n_bytes / 1e6:.3g}"
    size = f"over {mb} MB" if at_least else f"{mb} MB"
    return (
        f"{what} is {size}, more than this server accepts ({lim.max_upload_mb:g} MB): put it "
        "in a data folder of the server and load it by path, or start gmwm-app with a larger "
        "--max-upload-mb"
    )


def check_upload_size(n_bytes: int, name: str = "") -> None:
    """ValueError when an upload of ``n_bytes`` is larger than the configured limit."""
    if n_bytes > _LIMITS.max_upload_bytes:
        raise ValueError(upload_refusal(name, n_bytes))


def check_candidates(n: int, spec: str) -> None:
    """ValueError when a ranking of ``spec`` would fit ``n`` candidate models, more than the
    configured :attr:`ServerLimits.max_candidates`."""
    most = _LIMITS.max_candidates
    if n > most:
        raise ValueError(
            f"{spec} has {n} candidate models; this server ranks at most {most} at once: rank "
            "a smaller maximal model (fewer GM terms) or list the candidates separated by "
            "commas (or, on the server, start gmwm-app with a larger --max-candidates)"
        )
