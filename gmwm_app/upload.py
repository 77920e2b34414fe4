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
"""

from __future__ import annotations

from typing import Any

import panel as pn
import param

from gmwm_app.limits import UPLOAD_CHUNK_BYTES, upload_refusal
from gmwm_app.limits import current as current_limits

__all__ = ["BoundedFileDropper", "browser_size_limit"]


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

    def held_bytes(self) -> int:
        """Bytes of unfinished uploads held now."""
        return sum(len(b) for b in self._received.values())

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
        if chunk == 1:
            self._received.pop(name, None)  # a new upload of that name replaces a partial one
            # the browser's chunks are chunk_size bytes but the last: total - 1 full chunks
            announced = (total - 1) * self.chunk_size
            if announced > limit:
                self._refuse(name, announced, at_least=True)
                return
            self._received[name] = bytearray()
        buf = self._received.get(name)
        if buf is None:  # the rest of a refused upload (or chunks without a first one)
            return
        size = len(buf) + len(payload)
        if self.held_bytes() + len(payload) > limit:
            self._refuse(name, size, at_least=chunk < total)
            return
        buf += payload
        if chunk < total:
            return
        del self._received[name]
        content = bytes(buf)  # the one copy: the loaders share it (io.BytesIO, no copy)
        del buf
        self.value[name] = content
        self.mime_type[name] = str(data.get("type") or "")
        self.param.trigger("mime_type", "value")
