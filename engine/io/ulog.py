"""PX4 ULog flight logs (``.ulg``) through the optional ``pyulog`` package (extra ``px4``).

The IMU topics a PX4 log holds, chosen by ``topic=`` (default: the first present of):

* ``sensor_combined``: one gyroscope (``gyro_rad``, rad/s) and accelerometer
  (``accelerometer_m_s2``, m/s^2) on one clock: channels ``gyro_x .. accel_z``;
* ``sensor_gyro`` / ``sensor_accel``: every instance (``x, y, z``, ``temperature`` in degC):
  channels ``gyro_x`` or, with several instances, ``imu0_gyro_x, imu1_gyro_x, ...``; the
  temperatures are auxiliary channels (``ImuLog.aux``);
* ``vehicle_imu``: the integrated ``delta_angle`` (rad) and ``delta_velocity`` (m/s) divided by
  their intervals (``delta_angle_dt``, ``delta_velocity_dt`` in us) to rad/s and m/s^2.

Stamps are microseconds (``timestamp_sample`` when the topic has it, else ``timestamp``);
they give ``fs`` and go through the loader's time checks (gaps, duplicates, jitter). The
vehicle's parameters (``EKF2_GYR_NOISE``, ...) are kept in ``meta["params"]``.
"""

from __future__ import annotations

import io
from pathlib import Path
from typing import Any

import numpy as np

from ._assemble import LoadOptions, RawLog, finish_log
from .log import ImuLog, LoadError
from .timecols import split_instances

__all__ = ["read_ulog", "ULOG_MAGIC", "ULOG_TOPICS", "missing_extra"]

#: The first bytes of every ULog file.
ULOG_MAGIC = b"ULog\x01\x12\x35"
#: The IMU topics read, in the order of preference.
ULOG_TOPICS = ("sensor_combined", "sensor_gyro", "sensor_accel", "vehicle_imu")


def missing_extra(src: str, what: str, package: str, extra: str) -> LoadError:
    """The error for a format whose optional reader package is not installed."""
    return LoadError(
        f"file '{src}' is {what}: reading it needs the optional package {package}; install "
        f"it with: pip install 'gmwm-app[{extra}]' (or pip install {package})"
    )


def read_ulog(path: Path | io.BytesIO, src: str, channel: Any, opts: LoadOptions) -> ImuLog:
    """Read the IMU topic of a ULog into an :class:`ImuLog` (see the module docstring)."""
    try:
        from pyulog import ULog
    except ImportError:
        raise missing_extra(src, "a PX4 ULog", "pyulog", "px4") from None
    handle = path if isinstance(path, io.BytesIO) else str(path)
    ulog = ULog(handle, list(ULOG_TOPICS))
    present = sorted({d.name for d in ulog.data_list})
    topic = opts.topic or next((t for t in ULOG_TOPICS if t in present), None)
    if topic is None or topic not in present:
        have = ", ".join(present) or "none"
        want = f"topic '{opts.topic}'" if opts.topic else "an IMU topic"
        raise LoadError(
            f"file '{src}' has no {want} (IMU topics read: {', '.join(ULOG_TOPICS)}; found: "
            f"{have}): log sensor_combined (SDLOG_PROFILE default) or pass topic="
        )
    sets = sorted((d for d in ulog.data_list if d.name == topic), key=lambda d: d.multi_id)
    notes = [f"PX4 ULog topic '{topic}' ({len(sets)} instance(s))"]
    cols: dict[str, np.ndarray] = {}
    units: dict[str, str] = {}
    aux: list[str] = []
    inst: list[np.ndarray] = []
    stamps: list[np.ndarray] = []
    for d in sets:
        data = d.data
        t = np.asarray(data.get("timestamp_sample", data["timestamp"]), dtype=np.float64)
        part = _topic_columns(topic, data, units)
        if "temperature" in data:
            part["temperature"] = np.asarray(data["temperature"], dtype=np.float64)
            units["temperature"] = "degC"
        for k, v in part.items():
            cols.setdefault(k, np.empty(0))
            cols[k] = np.concatenate([cols[k], v])
        inst.append(np.full(t.size, d.multi_id))
        stamps.append(t)
    tname = "timestamp_sample" if "timestamp_sample" in sets[0].data else "timestamp"
    time: tuple[str, np.ndarray, tuple[float, bool]] | None = (
        tname,
        np.concatenate(stamps),
        (1e6, True),
    )
    out, time, _ = split_instances(
        src, "multi_id", np.concatenate(inst), cols, time, None, notes if len(sets) > 1 else []
    )
    units = {k: units.get(k.split("_", 1)[1] if k.startswith("imu") else k, "") for k in out}
    aux = [k for k in out if k.endswith("temperature")]
    params = {str(k): float(f"{v:.7g}") for k, v in ulog.initial_parameters.items()}  # float32
    meta = {"topic": topic, "instances": len(sets), "params": params}
    raw = RawLog(out, units, time=time, meta=meta, notes=notes, aux=aux)
    return finish_log(src, raw, fmt="ulog", channel=channel, opts=opts)


def _topic_columns(topic: str, data: dict[str, np.ndarray], units: dict[str, str]) -> dict:
    """The signal columns of one instance of ``topic`` (rad/s, m/s^2), by channel name."""
    out: dict[str, np.ndarray] = {}
    if topic == "sensor_combined":
        for k, a in enumerate("xyz"):
            out[f"gyro_{a}"] = np.asarray(data[f"gyro_rad[{k}]"], dtype=np.float64)
            units[f"gyro_{a}"] = "rad/s"
        for k, a in enumerate("xyz"):
            out[f"accel_{a}"] = np.asarray(data[f"accelerometer_m_s2[{k}]"], dtype=np.float64)
            units[f"accel_{a}"] = "m/s^2"
    elif topic in ("sensor_gyro", "sensor_accel"):
        kind, unit = ("gyro", "rad/s") if topic == "sensor_gyro" else ("accel", "m/s^2")
        for a in "xyz":
            out[f"{kind}_{a}"] = np.asarray(data[a], dtype=np.float64)
            units[f"{kind}_{a}"] = unit
    else:  # vehicle_imu: integrated increments over intervals in microseconds
        for field, kind, unit in (
            ("delta_angle", "gyro", "rad/s"),
            ("delta_velocity", "accel", "m/s^2"),
        ):
            dt = np.asarray(data[f"{field}_dt"], dtype=np.float64) * 1e-6
            with np.errstate(divide="ignore", invalid="ignore"):
                for k, a in enumerate("xyz"):
                    out[f"{kind}_{a}"] = np.asarray(data[f"{field}[{k}]"]) / dt
                    units[f"{kind}_{a}"] = unit
    return out
