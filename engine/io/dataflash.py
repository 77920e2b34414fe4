"""ArduPilot DataFlash logs (``.bin``, and the text ``.log`` form) through the optional
``pymavlink`` package (extra ``ardupilot``).

The ``IMU`` messages (``TimeUS`` in microseconds, instance ``I``, ``GyrX..Z`` in rad/s,
``AccX..Z`` in m/s^2, temperature ``T`` in degC) become channels ``gyro_x .. accel_z`` (with
several IMUs: ``imu0_gyro_x, imu1_gyro_x, ...``, each instance's first ``n`` samples, ``n``
the fewest of any instance) and the temperatures auxiliary channels (``ImuLog.aux``). The
stamps of the first instance give ``fs`` through the loader's time checks. ``PARM`` messages
(``EK3_GYRO_P_NSE``, ...) are kept in ``meta["params"]`` (the last value of each).
"""

from __future__ import annotations

import os
import tempfile
from pathlib import Path
from typing import Any

import numpy as np

from ._assemble import LoadOptions, RawLog, finish_log
from .log import ImuLog, LoadError
from .timecols import PROFILES, split_instances
from .ulog import missing_extra

__all__ = ["read_dataflash", "DATAFLASH_MAGIC", "is_dataflash_text"]

#: The first bytes of a DataFlash ``.bin``: message header 0xA3 0x95 and FMT's id 128.
DATAFLASH_MAGIC = b"\xa3\x95\x80"
_FIELDS = ("GyrX", "GyrY", "GyrZ", "AccX", "AccY", "AccZ", "T")


def is_dataflash_text(head: bytes) -> bool:
    """True for the text form of a DataFlash log (its first line is an ``FMT`` message)."""
    return head.startswith(b"FMT,") or head.startswith(b"FMT, ")


def read_dataflash(path: Path | Any, src: str, channel: Any, opts: LoadOptions) -> ImuLog:
    """Read the ``IMU`` messages of a DataFlash log into an :class:`ImuLog`."""
    try:
        from pymavlink import DFReader
    except ImportError:
        raise missing_extra(src, "an ArduPilot DataFlash log", "pymavlink", "ardupilot") from None
    if not isinstance(path, Path):  # content (an upload): DFReader reads paths only
        data = path.getvalue()
        fd, tmp = tempfile.mkstemp(prefix="gmwm_df_", suffix=".bin")
        try:
            with os.fdopen(fd, "wb") as f:
                f.write(data)
            return read_dataflash(Path(tmp), src, channel, opts)
        finally:
            os.unlink(tmp)
    with open(path, "rb") as fh:
        text = is_dataflash_text(fh.read(8))
    reader = (DFReader.DFReader_text if text else DFReader.DFReader_binary)(str(path))
    rows: dict[str, list[float]] = {k: [] for k in ("TimeUS", "I", *_FIELDS)}
    params: dict[str, float] = {}
    while (m := reader.recv_match(type=["IMU", "PARM"])) is not None:
        if m.get_type() == "PARM":
            params[str(m.Name)] = float(f"{m.Value:.7g}")  # float32 in the log
            continue
        d = m.to_dict()
        for k in rows:
            rows[k].append(float(d.get(k, 0.0)))
    if not rows["TimeUS"]:
        raise LoadError(
            f"file '{src}' holds no IMU messages: enable IMU logging (LOG_BITMASK) or pass "
            "a log of a flight or bench run with the IMU logged"
        )
    prof = PROFILES[0]  # the mavlogdump profile: the same IMU message, the same names/units
    cols = {prof.rename[k]: np.asarray(rows[k]) for k in _FIELDS}
    units = {k: prof.units[k] for k in cols}
    notes: list[str] = ["ArduPilot DataFlash IMU messages"]
    time: tuple[str, np.ndarray, tuple[float, bool]] | None = (
        "TimeUS",
        np.asarray(rows["TimeUS"]),
        (1e6, True),
    )
    out, time, _ = split_instances(src, "I", np.asarray(rows["I"]), cols, time, None, notes)
    units = {k: units[k.split("_", 1)[1] if k.startswith("imu") else k] for k in out}
    aux = [k for k in out if k.endswith("temperature")]
    meta = {"params": params, "instances": int(np.unique(rows["I"]).size)}
    raw = RawLog(out, units, time=time, meta=meta, notes=notes, aux=aux)
    return finish_log(src, raw, fmt="dataflash", channel=channel, opts=opts)
