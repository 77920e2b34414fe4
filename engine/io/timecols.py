"""The roles of a log's columns: time, instance, auxiliary (temperature), bookkeeping, signal.

Converters and apps write IMU logs with columns that are not signals: time stamps in seconds,
milliseconds, microseconds or nanoseconds (``timestamp``, ``TimeUS``, ``seconds_elapsed``),
an instance column (``I``: several IMUs interleaved), counters and flags (``error_count``,
``*_integral_dt``), and temperatures. This module recognises them, so that a time column is
never analysed as a signal and gives ``fs``; instances become per-instance channels; a
temperature is kept as an auxiliary channel of the log (``ImuLog.aux``); ``name[0]`` headers
become ``name_x`` (``name_0`` beyond three elements).

The converters and apps people use have a :class:`Profile` each (:data:`PROFILES`: PX4's
``ulog2csv``, ArduPilot's ``mavlogdump.py --format csv``, Sensor Logger, phyphox), recognised
from the header, which names their signals' units and their time column.
"""

from __future__ import annotations

import re
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import PurePath
from typing import Any

import numpy as np

from .log import LoadError

__all__ = [
    "Profile",
    "PROFILES",
    "time_divisor",
    "spacing_divisor",
    "header_field",
    "is_temperature",
    "is_bookkeeping",
    "Layout",
    "column_layout",
    "split_instances",
]

_UNIT_SUFFIX = r"s|sec|ms|msec|us|usec|µs|ns|nsec"
_TIME_RE = re.compile(
    r"(time|t|ts|timestamp|stamp|sec|seconds|seconds_elapsed|elapsed|time_elapsed"
    r"|timestamp_sample|time_boot|time_since_boot)(?:_?(" + _UNIT_SUFFIX + r"))?"
    r"|(" + _UNIT_SUFFIX.replace("s|sec|", "") + r")"
)
_TIME_DIV = {
    "s": 1.0,
    "sec": 1.0,
    "seconds": 1.0,
    "ms": 1e3,
    "msec": 1e3,
    "us": 1e6,
    "usec": 1e6,
    "µs": 1e6,
    "ns": 1e9,
    "nsec": 1e9,
}
_INSTANCE_RE = re.compile(r"i|inst|instance|imu_instance|multi_id")
_BOOKKEEPING_RE = re.compile(
    r"index|idx|id|device_id|seq|sequence|sample|samples|sample_count|count|.*_count"
    r"|.*clip.*|.*_integral_dt|.*timestamp_relative|.*_timestamp_relative|status|flags?"
    r"|health|.*_health|calibration_count|error_count|rate_hz"
)
_TEMP_RE = re.compile(r"temp|tmp|temperature|.*_temp|temp_.*|.*temperature.*|imu_temp\w*")
_INDEX_RE = re.compile(r"(.*?)\s*\[(\d+)\]")


def time_divisor(name: str, unit: str = "") -> tuple[float, bool] | None:
    """(divisor to seconds, explicit) if ``name`` names a time column, else None.

    Explicit when the name (``time_ms``, ``TimeUS``, ``timestamp_ns``) or the header's unit
    (``time [ms]``) says the unit; otherwise the loader infers it from the stamps' spacing
    (:func:`spacing_divisor`).
    """
    m = _TIME_RE.fullmatch(name.strip().lower())
    if m is None:
        return None
    suffix = m.group(2) or m.group(3) or unit.strip().lower()
    return _TIME_DIV.get(suffix, 1.0), suffix in _TIME_DIV


def spacing_divisor(median_step: float) -> tuple[float, str] | None:
    """The unit of unitless time stamps from their median step, or None for seconds.

    A step of at most 2 is read as seconds (rates of 0.5 Hz and up; ``save_log`` writes
    seconds). A larger step would make an IMU log slower than 0.5 Hz in seconds, so it is
    read in the first of
    milliseconds, microseconds, nanoseconds that gives a rate of at least 10 Hz (step 4000:
    microseconds, 250 Hz; step 10: milliseconds, 100 Hz; step 2e6: nanoseconds, 500 Hz).

    Returns
    -------
    (divisor, unit) or None
        ``divisor`` turns the stamps into seconds; None: they are seconds already.
    """
    if not median_step > 2.0:
        return None
    for div, unit in ((1e3, "milliseconds"), (1e6, "microseconds")):
        if div / median_step >= 10.0:
            return div, unit
    return 1e9, "nanoseconds"


def header_field(token: str, unit_re: re.Pattern[str]) -> tuple[str, str]:
    """(name, unit) of a header field: ``gyro_x [deg/s]`` -> (``gyro_x``, ``deg/s``), and an
    array element ``gyro_rad[1]`` -> (``gyro_rad_y``, ``""``) (``_0, _1, ...`` past index 2,
    see :func:`column_layout`), not a unit ``1``."""
    tok = token.strip()
    m = _INDEX_RE.fullmatch(tok)
    if m and m.group(1):
        k = int(m.group(2))
        return f"{m.group(1)}_{'xyz'[k] if k < 3 else k}", ""
    u = unit_re.fullmatch(tok)
    return (u.group(1).strip(), u.group(2)) if u else (tok, "")


def is_temperature(name: str) -> bool:
    """True for a temperature column name (``temperature``, ``imu_temp``, ``temp_c``)."""
    return _TEMP_RE.fullmatch(name.strip().lower()) is not None


def is_bookkeeping(name: str) -> bool:
    """True for counters, flags, ids and integration intervals (never a signal)."""
    return _BOOKKEEPING_RE.fullmatch(name.strip().lower()) is not None


@dataclass(frozen=True)
class Profile:
    """The column layout of one converter's or app's CSV files.

    Attributes
    ----------
    name : str
        Shown in notes and ``meta["profile"]``.
    signature : tuple of str
        Column names (case-sensitive) that all appear in the header of such a file.
    time : tuple of str
        Its time columns, the preferred one first, with their divisor to seconds (``None``:
        from the spacing).
    rename : mapping
        Column name to channel name (``GyrX`` -> ``gyro_x``).
    units : mapping
        Channel name (after ``rename``) to unit; ``"<gyro>"``/``"<accel>"`` keys apply to
        every channel of a file whose name says gyroscope/accelerometer.
    aux : tuple of str
        Temperature columns that the generic names would not catch (``T``).
    drop : tuple of str
        Further columns that are not signals (health flags, rates).
    """

    name: str
    signature: tuple[str, ...]
    time: tuple[tuple[str, float | None], ...] = ()
    rename: Mapping[str, str] = field(default_factory=dict)
    units: Mapping[str, str] = field(default_factory=dict)
    aux: tuple[str, ...] = ()
    drop: tuple[str, ...] = ()

    def matches(self, names: list[str]) -> bool:
        """True if every signature column is in ``names``."""
        return all(s in names for s in self.signature)


_XYZ = "xyz"
PROFILES: tuple[Profile, ...] = (
    Profile(  # mavlogdump.py --format csv --types IMU 00000001.BIN
        "mavlogdump (ArduPilot IMU)",
        ("TimeUS", "GyrX", "AccX"),
        time=(("TimeUS", 1e6), ("timestamp", 1.0)),
        rename={
            **{f"Gyr{a.upper()}": f"gyro_{a}" for a in _XYZ},
            **{f"Acc{a.upper()}": f"accel_{a}" for a in _XYZ},
            "T": "temperature",
        },
        units={
            **{f"gyro_{a}": "rad/s" for a in _XYZ},
            **{f"accel_{a}": "m/s^2" for a in _XYZ},
            "temperature": "degC",
        },
        aux=("T",),
        drop=("EG", "EA", "GH", "AH", "GHz", "AHz"),
    ),
    Profile(  # ulog2csv -m sensor_combined flight.ulg -> flight_sensor_combined_0.csv
        "ulog2csv (PX4 sensor_combined)",
        ("timestamp", "gyro_rad_x", "accelerometer_m_s2_x"),
        time=(("timestamp", 1e6),),
        rename={
            **{f"gyro_rad_{a}": f"gyro_{a}" for a in _XYZ},
            **{f"accelerometer_m_s2_{a}": f"accel_{a}" for a in _XYZ},
        },
        units={**{f"gyro_{a}": "rad/s" for a in _XYZ}, **{f"accel_{a}": "m/s^2" for a in _XYZ}},
    ),
    Profile(  # ulog2csv -m sensor_gyro / sensor_accel (x, y, z; temperature)
        "ulog2csv (PX4 sensor_gyro/sensor_accel)",
        ("timestamp", "timestamp_sample", "device_id", "x", "y", "z"),
        time=(("timestamp_sample", 1e6), ("timestamp", 1e6)),
        units={"<gyro>": "rad/s", "<accel>": "m/s^2", "temperature": "degC"},
    ),
    Profile(  # Sensor Logger (iOS/Android): Gyroscope.csv, Accelerometer.csv
        "Sensor Logger",
        ("time", "seconds_elapsed", "x", "y", "z"),
        time=(("time", 1e9), ("seconds_elapsed", 1.0)),
        units={"<gyro>": "rad/s", "<accel>": "m/s^2"},
    ),
    Profile(  # phyphox "Gyroscope rotation rate" export: "Time (s)","Gyroscope x (rad/s)",...
        "phyphox",
        ("Time",),
        time=(("Time", 1.0),),
    ),
)


@dataclass
class Layout:
    """What :func:`column_layout` found: signal and auxiliary columns, the time column."""

    cols: dict[str, Any]
    units: dict[str, str]
    time: tuple[str, np.ndarray, tuple[float, bool]] | None
    aux: list[str]
    rows: np.ndarray | None
    profile: str | None


def _kind_of_file(src: str) -> str | None:
    stem = PurePath(src).name.lower()
    if "gyr" in stem:
        return "<gyro>"
    if "acc" in stem:
        return "<accel>"
    return None


def column_layout(
    src: str,
    cols: dict[str, Any],
    units: dict[str, str],
    rows: np.ndarray | None,
    notes: list[str],
) -> Layout:
    """Sort a table's columns into time, instances, auxiliary, bookkeeping and signals.

    Parameters
    ----------
    src : str
        The file's name (messages; ``gyro``/``acc`` in it gives the unit of a profile's
        ``x, y, z`` columns).
    cols : dict of str to ndarray
        Every column of the table, by header name (equal lengths).
    units : dict of str to str
        Units from the header.
    rows : ndarray or None
        File line of every row (kept in step when instances are split).
    notes : list of str
        Appended to: what was recognised and dropped.

    Returns
    -------
    Layout
        ``cols`` holds the signals then the auxiliary columns (``aux`` names them); ``time``
        is the first time column (the profile's preferred one) as ``(name, stamps,
        (divisor, explicit))``.
    """
    names = list(cols)
    prof = next((p for p in PROFILES if p.matches(names)), None)
    units = dict(units)
    time: tuple[str, np.ndarray, tuple[float, bool]] | None = None
    times: list[str] = []
    if prof is not None:
        for tname, pdiv in prof.time:
            if tname in cols:
                d = time_divisor(tname, units.get(tname, "")) if pdiv is None else (pdiv, True)
                time = time or (tname, cols[tname], d or (1.0, False))
                times.append(tname)
    for name in names:
        div = time_divisor(name, units.get(name, ""))
        if div is not None and name not in times and not (prof is not None and name in prof.aux):
            time = time or (name, cols[name], div)
            times.append(name)
    inst = next((k for k in names if _INSTANCE_RE.fullmatch(k.strip().lower())), None)
    dropped = [
        k
        for k in names
        if k not in times
        and k != inst
        and (is_bookkeeping(k) or (prof is not None and k in prof.drop))
        and not (prof is not None and k in prof.aux)
    ]
    aux_src = [
        k
        for k in names
        if k not in times
        and k not in dropped
        and k != inst
        and (is_temperature(k) or (prof is not None and k in prof.aux))
    ]
    signals = [k for k in names if k not in times and k not in dropped and k not in aux_src]
    signals = [k for k in signals if k != inst]
    if len(times) > 1:
        notes.append(
            f"time column '{times[0]}' gives fs; other time column(s) not analysed: "
            + ", ".join(times[1:])
        )
    if dropped:
        notes.append("counter/flag column(s) not analysed: " + ", ".join(dropped))
    rename = dict(prof.rename) if prof is not None else {}
    out: dict[str, Any] = {}
    for k in signals + aux_src:
        new = rename.get(k, k)
        out[new] = cols[k]
        units[new] = units.get(k, "") or _profile_unit(prof, new, src)
    aux = [rename.get(k, k) for k in aux_src]
    if prof is not None:
        notes.append(f"columns read in the {prof.name} layout")
    if inst is not None:
        out, time, rows = split_instances(src, inst, np.asarray(cols[inst]), out, time, rows, notes)
        aux = [k for k in out if any(k.endswith("_" + a) for a in aux)]
        units = {k: units.get(_base(k), units.get(k, "")) for k in out}
    if not [k for k in out if k not in aux] and aux:
        raise LoadError(
            f"file '{src}' has only time and temperature column(s) ({', '.join(aux)}): "
            "no IMU signal to analyse"
        )
    return Layout(out, units, time, aux, rows, prof.name if prof is not None else None)


def _base(name: str) -> str:
    m = re.fullmatch(r"imu\d+_(.*)", name)
    return m.group(1) if m else name


def _profile_unit(prof: Profile | None, name: str, src: str) -> str:
    if prof is None:
        return ""
    if name in prof.units:
        return prof.units[name]
    kind = _kind_of_file(src)
    if kind is not None and kind in prof.units and name.lower() in ("x", "y", "z"):
        return prof.units[kind]
    return ""


def split_instances(
    src: str,
    inst_name: str,
    inst: np.ndarray,
    cols: dict[str, Any],
    time: tuple[str, np.ndarray, tuple[float, bool]] | None,
    rows: np.ndarray | None,
    notes: list[str],
) -> tuple[dict[str, Any], tuple[str, np.ndarray, tuple[float, bool]] | None, np.ndarray | None]:
    """Rows of several sensors interleaved (an instance column): one channel per instance.

    One instance: the column is dropped. Several (``I`` = 0, 1, 2): channel ``gyro_x`` of
    instance k becomes ``imu{k}_gyro_x``; every instance keeps its first ``n`` rows, ``n``
    the fewest rows of any instance (a note says how many were dropped), and the time stamps
    and line numbers are the first instance's.
    """
    values = np.unique(inst)
    if values.size <= 1:
        notes.append(f"instance column '{inst_name}' (one instance) not analysed")
        return cols, time, rows
    picks = [np.flatnonzero(inst == v) for v in values]
    n = min(p.size for p in picks)
    out: dict[str, Any] = {}
    for v, p in zip(values, picks, strict=True):
        tag = int(v) if float(v).is_integer() else v
        for k, a in cols.items():
            out[f"imu{tag}_{k}"] = np.asarray(a)[p[:n]]
    extra = sum(p.size - n for p in picks)
    notes.append(
        f"instance column '{inst_name}': {values.size} sensors interleaved, split into "
        f"channels imu<k>_<name> ({n} samples each"
        + (f"; {extra} surplus row(s) of the longer instances dropped)" if extra else ")")
    )
    first = picks[0][:n]
    if time is not None:
        time = (time[0], np.asarray(time[1])[first], time[2])
    return out, time, None if rows is None else rows[first]
