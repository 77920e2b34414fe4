"""Reading a Kalibr ``imu.yaml``: :func:`read_kalibr` (PyYAML, through :mod:`engine._yaml`).

A reader, so it lives with the loaders: the datasheet check (:mod:`engine.inference`) reads
a Kalibr file as a datasheet, and the Kalibr export format (:mod:`engine.formats.kalibr`)
reads back what it writes, both from here.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Any

from .._files import read_regular
from .._yaml import read_yaml_mapping
from ..errors import ExportError

__all__ = ["read_kalibr"]

_IMU_BLOCK = re.compile(r"imu\d+")


def read_kalibr(source: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a Kalibr ``imu.yaml`` (path, or the YAML text itself) into a dict.

    Any YAML (PyYAML's ``safe_load``: flow maps, comments, anchors, quoted keys ...), and an
    OpenCV ``%YAML:1.0`` file. The keys of the first ``imuN:`` block (Kalibr's imu-chain
    output, OpenVINS's ``kalibr_imu_chain.yaml``) count as top-level keys where the top level
    has no key of that name.

    Raises
    ------
    ExportError
        Unreadable file, text that is not YAML, or a document that is not ``key: value``.
    """
    text = str(source)
    where = "Kalibr YAML"
    if isinstance(source, os.PathLike) or (
        "\n" not in text and ":" not in text.split("/")[0] and Path(text).exists()
    ):
        data = read_regular(source, error=ExportError)  # no FIFO or device: engine._files
        where = f"Kalibr file '{source}'"
        try:
            text = data.decode("utf-8")
        except UnicodeDecodeError:
            raise ExportError(f"{where} is not UTF-8 text") from None
    doc = read_yaml_mapping(text, where, error=ExportError)
    out = {str(k): v for k, v in doc.items()}
    block = next(
        (v for k, v in out.items() if _IMU_BLOCK.fullmatch(k) and isinstance(v, dict)), None
    )
    if block is not None:
        out.update({str(k): v for k, v in block.items() if str(k) not in out})
    return out
