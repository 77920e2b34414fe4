"""Uploads bounded while they arrive: the app's file dropper.

Panel's ``FileDropper`` sends a file in chunks (``chunk_size`` bytes, one websocket message
each) and keeps every chunk until the last one arrived, then joins them (and decodes ``text/*``
files to a str): the size limit could only be checked after the whole file was in memory,
and a 190 MB upload peaked at 884 MB of the server's memory. :class:`BoundedFileDropper`
keeps the chunks in one growing buffer, counts them as they arrive and drops an upload as soon
as it is certain to exceed the server's limit (``gmwm-app --max-upload-mb``): at its first
chunk when the announced chunk count already says so, else at the chunk that crosses the
limit. The value is the file's bytes, never decoded (the loaders read bytes).

The browser refuses a too-large file first (FilePond's ``max_file_size``, shown in the
widget), so an honest page never sends it; the server-side count is for any other client.

Unfinished uploads are bounded too: a session's dropper holds one upload in progress (a new
one drops the partial one), a partial upload that receives no chunk for
:data:`STALLED_S` seconds is dropped (swept at any dropper's next chunk), the session's end
drops its partial upload (:meth:`BoundedFileDropper.drop_partial`), and all the droppers of
the process together hold at most :func:`uploads_budget` bytes: an upload beyond it is refused
with a message saying to try again shortly.
"""

from __future__ import annotations

import time
import weakref
from typing import Any

import panel as pn
import param

from engine.io import available_memory
from gmwm_app.limits import UPLOAD_CHUNK_BYTES, upload_refusal
from gmwm_app.limits import current as current_limits

__all__ = ["BoundedFileDropper", "browser_size_limit", "uploads_budget", "STALLED_S"]

#: A partial upload that receives no chunk for this long (s) is dropped.
STALLED_S = 60.0
#: Share of the memory available that the unfinished uploads of all sessions may hold.
UPLOADS_MEMORY_SHARE = 0.25

_DROPPERS: weakref.WeakSet[BoundedFileDropper] = weakref.WeakSet()


def uploads_budget() -> int:
    """Bytes the unfinished uploads of every session of this process may hold together: a
    quarter of the memory available now (at least one upload of the configured limit).

    Integration point: when the engine offers the process-wide memory budget shared
    by the loaders, this is the share of it the uploads take."""
    limit = current_limits().max_upload_bytes
    mem = available_memory()
    return limit if mem is None else max(limit, int(UPLOADS_MEMORY_SHARE * mem))


def held_by_all() -> int:
    """Bytes of unfinished uploads held now by every dropper of the process."""
    return sum(d.held_bytes() for d in list(_DROPPERS))


def browser_size_limit(max_bytes: int) -> str:
    """FilePond's ``maxFileSize`` for a limit of ``max_bytes`` (in KB of 1000 bytes, rounded
    down, at least 1 KB)."""
    return f"{max(1, int(max_bytes // 1000))}KB"


class BoundedFileDropper(pn.widgets.FileDropper):
    """A ``FileDropper`` whose uploads are counted while they arrive and refused past the
    server's upload limit (:func:`gmwm_app.limits.current`).

    ``value`` maps the file name to its bytes (``bytes``, not decoded). A refused upload
    leaves ``value`` unchanged and sets :attr:`refused` to the message (watch it to show it).
    """

    refused = param.String(default="", doc="The message of the latest refused upload.")

    _rename = {**pn.widgets.FileDropper._rename, "refused": None}  # server side only

    def __init__(self, **params: Any) -> None:
        limit = current_limits().max_upload_bytes
        params.setdefault("chunk_size", UPLOAD_CHUNK_BYTES)
        params.setdefault("max_file_size", browser_size_limit(limit))
        super().__init__(**params)
        self._received: dict[str, bytearray] = {}
        self._last_chunk: dict[str, float] = {}
        _DROPPERS.add(self)

    def held_bytes(self) -> int:
        """Bytes of unfinished uploads held now."""
        return sum(len(b) for b in list(self._received.values()))

    def drop_partial(self, *_args: Any) -> None:
        """Drop the unfinished uploads (the session ended)."""
        self._received.clear()
        self._last_chunk.clear()

    def _drop_stalled(self, now: float) -> None:
        for name, t in list(self._last_chunk.items()):
            if now - t > STALLED_S:
                self._received.pop(name, None)
                self._last_chunk.pop(name, None)

    def _refuse(self, name: str, n_bytes: int, at_least: bool) -> None:
        self._received.pop(name, None)
        self.refused = upload_refusal(name, n_bytes, at_least=at_least)

    def _process_event(self, event: Any) -> None:
        if event.event_name != "upload_event":
            super()._process_event(event)
            return
        data = event.data
        name = str(data["name"])
        chunk, total = int(data["chunk"]), int(data["total_chunks"])
        payload = data["data"]
        limit = current_limits().max_upload_bytes
        now = time.monotonic()
        for d in list(_DROPPERS):
            d._drop_stalled(now)
        if chunk == 1:
            self.drop_partial()  # one upload in progress per session: a new one replaces it
            # the browser's chunks are chunk_size bytes but the last: total - 1 full chunks
            announced = (total - 1) * self.chunk_size
            if announced > limit:
                self._refuse(name, announced, at_least=True)
                return
            if held_by_all() + announced > uploads_budget():
                self.refused = _busy_refusal(name)
                return
            self._received[name] = bytearray()
        buf = self._received.get(name)
        if buf is None:  # the rest of a refused upload (or chunks without a first one)
            return
        size = len(buf) + len(payload)
        if self.held_bytes() + len(payload) > limit:
            self._refuse(name, size, at_least=chunk < total)
            return
        if held_by_all() + len(payload) > uploads_budget():
            self._received.pop(name, None)
            self.refused = _busy_refusal(name)
            return
        buf += payload
        self._last_chunk[name] = now
        if chunk < total:
            return
        del self._received[name]
        self._last_chunk.pop(name, None)
        content = bytes(buf)  # the one copy: the loaders share it (io.BytesIO, no copy)
        del buf
        self.value[name] = content
        self.mime_type[name] = str(data.get("type") or "")
        self.param.trigger("mime_type", "value")


def _busy_refusal(name: str) -> str:
    """The message refusing an upload while other sessions' uploads fill the budget."""
    return (
        f"the server is receiving too many uploads at once to take {name or 'this file'} "
        "now: try again in a minute"
    )
