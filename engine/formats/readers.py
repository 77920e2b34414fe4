"""Read a filter's noise file back into the noise model it states, for ``gmwm check``: every
filter format :mod:`engine.formats` writes, and the consumers' own hand-written files of those
formats (a VINS or ORB-SLAM3 settings file with OpenCV ``%YAML:1.0`` and ``!!opencv-matrix``
entries, a PX4 ``.params`` dump, an ArduPilot ``.param``).

:func:`read_filter_noise` returns a :class:`FilterNoise`: per sensor kind and axis the
consumer's parameters in SI (``N`` [u/sqrt(Hz)], ``K`` [u/s/sqrt(Hz)], or ``sigma_b`` [u] and
``T_c`` [s] of a Gauss-Markov bias), converted back with the same conventions the writers use
(docs/fit-to-filter.md): per-sample values (VINS, gz-sim, ``sensor_msgs/Imu``) are divided
by ``sqrt(rate)``, per-step values (PX4, ArduPilot) by ``sqrt(filter rate)``. The rate is the
file's own when it states one (a rate key, ``EKF2_PREDICT_US``, our header's ``consumer
rate``), else the log's (VINS, gz-sim, ROS files written by hand: the IMU rate is the log's),
else the consumer's default (PX4 100 Hz, ``EKF2_PREDICT_US`` = 10000 us; ArduPilot EKF3 83.3
Hz, one prediction per 12 ms). :meth:`FilterNoise.spec` gives the
:class:`~engine.inference.DatasheetSpec` of one channel for the check.
"""

from __future__ import annotations

import csv
import dataclasses
import functools
import io
import json
import math
import os
import re
import xml.etree.ElementTree as ET
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .._files import read_regular
from .._yaml import read_yaml_mapping
from ..inference.datasheet_check import DatasheetError, DatasheetSpec, read_datasheet
from ..io.kalibr import read_kalibr
from ..io.log import channel_axis
from ..units import DISPLAY, SI_UNIT, ExportError, si_factor
from .ins import MGAL

__all__ = ["FilterNoise", "read_filter_noise", "read_check_file", "PX4_DEFAULT_RATE"]

#: PX4 EKF2's default prediction rate (EKF2_PREDICT_US = 10000 us).
PX4_DEFAULT_RATE = 100.0
#: ArduPilot EKF3's prediction rate (one step per 12 ms of IMU data).
EK3_DEFAULT_RATE = 1000.0 / 12.0
_G, _A = "gyroscope", "accelerometer"
_NUM = r"([-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?)"


@dataclass(frozen=True)
class FilterNoise:
    """A filter file's noise model.

    Attributes
    ----------
    fmt : str
        The format read (a name of :data:`engine.formats.FORMATS`).
    values : dict
        ``values[kind][axis][param]`` in SI, axis ``x``/``y``/``z`` or ``*`` (one number for
        the sensor); params ``N``, ``K``, ``sigma_b``, ``T_c``.
    rate : float or None
        The rate (Hz) per-sample or per-step values were converted with.
    notes : list of str
        How the rate was found, and what was assumed.
    """

    fmt: str
    values: dict[str, dict[str, dict[str, float]]]
    rate: float | None = None
    notes: list[str] = field(default_factory=list)

    def spec(self, kind: str | None, channel: str | None, source: str) -> DatasheetSpec:
        """The datasheet of one channel: its axis's values (or the sensor's one number)."""
        kinds = [k for k in (_G, _A) if k in self.values]
        if kind is None:
            if len(kinds) != 1:
                raise DatasheetError(f"{source} has {' and '.join(kinds)} values: choose one")
            kind = kinds[0]
        if kind not in self.values:
            raise DatasheetError(f"{source} ({self.fmt}) has no {kind}_* keys: no {kind} values")
        d = self.values[kind]
        ax = channel_axis(channel) if channel else "*"
        v = d.get(ax) or d.get("*") or next(iter(d.values()))
        where = f"{source} ({self.fmt}{', ' + '; '.join(self.notes) if self.notes else ''})"
        vals: dict[str, float] = {k: v[k] for k in ("N", "K") if k in v}
        gm = ((v["T_c"], v["sigma_b"]),) if "T_c" in v and "sigma_b" in v else ()
        return DatasheetSpec(kind, vals, {}, where, gm=gm)


def _xyz(v: Any) -> dict[str, float]:
    if isinstance(v, (list, tuple)) and len(v) == 3:
        return {a: float(x) for a, x in zip("xyz", v, strict=True)}
    return {"*": float(v)}


def _rate_comment(text: str) -> float | None:
    """The consumer rate our writers state in their header (``consumer rate 200 Hz``)."""
    m = re.search(r"consumer rate " + _NUM + " Hz", text)
    return float(m.group(1)) if m else None


@functools.lru_cache(maxsize=8)
def _yaml_doc(text: str) -> dict[Any, Any]:
    """The mapping of a YAML (or OpenCV ``%YAML:1.0``) settings file, parsed once for the
    readers that try it; empty when the text is not a YAML mapping (another reader's format)."""
    try:
        return read_yaml_mapping(text, "the file", error=ExportError)
    except ExportError:
        return {}


def _find(doc: Any, key: str) -> Any:
    """The value of ``key`` at any depth of a YAML document (the first in document order),
    else None."""
    if isinstance(doc, dict):
        if key in doc:
            return doc[key]
        doc = list(doc.values())
    if isinstance(doc, list):
        for v in doc:
            found = _find(v, key)
            if found is not None:
                return found
    return None


def _number(v: Any) -> float | None:
    return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None


def _scalar(text: str, key: str) -> float | None:
    """The number of ``key`` in a YAML/OpenCV settings file (at any depth), else None."""
    return _number(_find(_yaml_doc(text), key))


def _flow(text: str, key: str) -> list[float] | float | None:
    """The list of numbers (``key: [a, b, c]``) or the number of ``key`` in a YAML settings
    file (at any depth), else None."""
    v = _find(_yaml_doc(text), key)
    if isinstance(v, list) and v and all(_number(x) is not None for x in v):
        return [float(x) for x in v]
    return _number(v)


def _vins(text: str, fs: float | None) -> FilterNoise:
    keys = {"acc_n": (_A, "N"), "gyr_n": (_G, "N"), "acc_w": (_A, "K"), "gyr_w": (_G, "K")}
    got = {k: _scalar(text, k) for k in keys}
    if all(v is None for v in got.values()):
        raise ExportError("no acc_n/gyr_n/acc_w/gyr_w")
    rate = _rate_comment(text) or fs
    notes = []
    if rate is None:
        raise ExportError("VINS values are per sample: the IMU rate is needed (the log's)")
    if _rate_comment(text) is None:
        notes.append(f"per-sample values at the log's rate {rate:g} Hz")
    vals: dict[str, dict[str, dict[str, float]]] = {}
    for k, v in got.items():
        if v is not None:
            kind, q = keys[k]
            vals.setdefault(kind, {}).setdefault("*", {})[q] = v / math.sqrt(rate)
    return FilterNoise("vins", vals, rate, notes)


def _orbslam3(text: str, fs: float | None) -> FilterNoise:
    keys = {
        "IMU.NoiseGyro": (_G, "N"),
        "IMU.NoiseAcc": (_A, "N"),
        "IMU.GyroWalk": (_G, "K"),
        "IMU.AccWalk": (_A, "K"),
    }
    got = {k: _scalar(text, k) for k in keys}
    if all(v is None for v in got.values()):
        raise ExportError("no IMU.NoiseGyro/NoiseAcc/GyroWalk/AccWalk")
    vals: dict[str, dict[str, dict[str, float]]] = {}
    for k, v in got.items():
        if v is not None:
            kind, q = keys[k]
            vals.setdefault(kind, {}).setdefault("*", {})[q] = v
    return FilterNoise("orbslam3", vals, _scalar(text, "IMU.Frequency"))


def _kalibr_like(text: str, fs: float | None) -> FilterNoise:
    d = read_kalibr(text)
    vals: dict[str, dict[str, dict[str, float]]] = {}
    for kind in (_G, _A):
        for q, suffix in (("N", "noise_density"), ("K", "random_walk")):
            key = f"{kind}_{suffix}"
            per = d.get(f"{key}_per_axis")
            if isinstance(per, dict):
                for ax, v in per.items():
                    vals.setdefault(kind, {}).setdefault(str(ax), {})[q] = float(v)
            if key in d:
                vals.setdefault(kind, {}).setdefault("*", {})[q] = float(d[key])
    if not vals:
        raise ExportError("no *_noise_density/*_random_walk keys")
    return FilterNoise("kalibr", vals, d.get("update_rate"))


def _basalt(text: str, fs: float | None) -> FilterNoise:
    d = json.loads(text)
    v0 = d.get("value0") if isinstance(d, dict) else None
    if not isinstance(v0, dict) or not any(k.endswith("_noise_std") for k in v0):
        raise ExportError("no value0.*_noise_std")
    vals: dict[str, dict[str, dict[str, float]]] = {}
    for kind, short in ((_A, "accel"), (_G, "gyro")):
        for q, key in (("N", "noise_std"), ("K", "bias_std")):
            if f"{short}_{key}" in v0:
                for ax, v in _xyz(v0[f"{short}_{key}"]).items():
                    vals.setdefault(kind, {}).setdefault(ax, {})[q] = v
    return FilterNoise("basalt", vals, v0.get("imu_update_rate"))


def _params(text: str, fmt: str) -> FilterNoise:
    """PX4 ``.params`` (``vid<TAB>cid<TAB>NAME<TAB>VALUE<TAB>type``) or ArduPilot ``.param``
    (``NAME,VALUE``)."""
    names = {
        "px4": {
            "EKF2_GYR_NOISE": (_G, "N"),
            "EKF2_ACC_NOISE": (_A, "N"),
            "EKF2_GYR_B_NOISE": (_G, "K"),
            "EKF2_ACC_B_NOISE": (_A, "K"),
        },
        "ardupilot": {
            "EK3_GYRO_P_NSE": (_G, "N"),
            "EK3_ACC_P_NSE": (_A, "N"),
            "EK3_GBIAS_P_NSE": (_G, "K"),
            "EK3_ABIAS_P_NSE": (_A, "K"),
        },
    }[fmt]
    got: dict[str, float] = {}
    for line in text.splitlines():
        line = line.split("#", 1)[0].strip()
        parts = re.split(r"[\t ,]+", line) if line else []
        for i, p in enumerate(parts[:-1]):
            if p in names or p == "EKF2_PREDICT_US":
                try:
                    got[p] = float(parts[i + 1])
                except ValueError:
                    pass
    if not any(k in got for k in names):
        raise ExportError(f"no {', '.join(names)}")
    notes = []
    if "EKF2_PREDICT_US" in got and got["EKF2_PREDICT_US"] > 0:
        rate = 1e6 / got["EKF2_PREDICT_US"]
        notes.append(f"filter rate {rate:g} Hz from EKF2_PREDICT_US")
    else:
        m = re.search(r"filter rate " + _NUM + " Hz", text)
        if m:
            rate = float(m.group(1))
        else:
            rate = PX4_DEFAULT_RATE if fmt == "px4" else EK3_DEFAULT_RATE
            notes.append(f"filter rate {rate:.4g} Hz assumed (the EKF's default)")
    vals: dict[str, dict[str, dict[str, float]]] = {}
    for k, (kind, q) in names.items():
        if k in got:
            vals.setdefault(kind, {}).setdefault("*", {})[q] = got[k] / math.sqrt(rate)
    return FilterNoise(fmt, vals, rate, notes)


def _matlab(text: str, fs: float | None) -> FilterNoise:
    vals: dict[str, dict[str, dict[str, float]]] = {}
    for kind, fn in ((_G, "gyroparams"), (_A, "accelparams")):
        m = re.search(fn + r"\((.*?)\);", text, re.S)
        if not m:
            continue
        for q, key in (("N", "NoiseDensity"), ("K", "RandomWalk")):
            mm = re.search(r"'" + key + r"',\s*\[([^\]]*)\]", m.group(1))
            if mm:
                xs = [float(v) for v in mm.group(1).split()]
                for ax, v in _xyz(xs).items():
                    vals.setdefault(kind, {}).setdefault(ax, {})[q] = v
    if not vals:
        raise ExportError("no gyroparams/accelparams")
    m = re.search(r"^fs = " + _NUM, text, re.M)
    return FilterNoise("matlab", vals, float(m.group(1)) if m else None)


def _gazebo(text: str, fs: float | None) -> FilterNoise:
    root = ET.fromstring(text)
    vals: dict[str, dict[str, dict[str, float]]] = {}
    for kind in (_G, _A):

        def get(name: str, kind: str = kind) -> float | None:
            el = root.find(kind + name)
            return float(el.text) if el is not None and el.text else None

        n, rw, tc = get("NoiseDensity"), get("RandomWalk"), get("BiasCorrelationTime")
        if rw is None:
            rw = get("BiasRandomWalk")
        if n is None:
            continue
        d = vals.setdefault(kind, {}).setdefault("*", {"N": n})
        if rw is not None and tc:
            d["T_c"], d["sigma_b"] = tc, rw * math.sqrt(tc / 2.0)
    if not vals:
        raise ExportError("no gyroscopeNoiseDensity/accelerometerNoiseDensity")
    return FilterNoise("gazebo", vals)


def _gz_sim(text: str, fs: float | None) -> FilterNoise:
    root = ET.fromstring(text)
    imu = root if root.tag == "imu" else root.find(".//imu")
    if imu is None:
        raise ExportError("no <imu>")
    m = re.search(r"<update_rate>" + _NUM, text)
    rate = float(m.group(1)) if m else fs
    notes = [] if m else [f"per-sample stddev at the log's rate {fs:g} Hz"] if fs else []
    if rate is None:
        raise ExportError("gz-sim stddev is per sample: the IMU rate is needed (the log's)")
    vals: dict[str, dict[str, dict[str, float]]] = {}
    for tag, kind in (("angular_velocity", _G), ("linear_acceleration", _A)):
        for ax in "xyz":
            nz = imu.find(f"{tag}/{ax}/noise")
            if nz is None:
                continue

            def g(name: str, nz: ET.Element = nz) -> float:
                el = nz.find(name)
                return float(el.text) if el is not None and el.text else 0.0

            d = vals.setdefault(kind, {}).setdefault(ax, {})
            d["N"] = g("stddev") / math.sqrt(rate)
            tc, dyn = g("dynamic_bias_correlation_time"), g("dynamic_bias_stddev")
            if tc > 0:
                d["T_c"], d["sigma_b"] = tc, dyn * math.sqrt(tc / 2.0)
    if not vals:
        raise ExportError("no <noise> in <imu>")
    return FilterNoise("gz-sim", vals, rate, notes)


def _kfgins(text: str, fs: float | None) -> FilterNoise:
    if "imunoise" not in _yaml_doc(text):
        raise ExportError("no imunoise")
    d = {k: _flow(text, k) for k in ("arw", "vrw", "gbstd", "abstd", "corrtime")}
    if d["arw"] is None or d["vrw"] is None or not isinstance(d["corrtime"], float):
        raise ExportError("no imunoise.arw/vrw/corrtime")
    tc = float(d["corrtime"]) * 3600.0
    deg = math.pi / 180.0
    vals: dict[str, dict[str, dict[str, float]]] = {}
    for kind, nkey, bkey, nf, bf in (
        (_G, "arw", "gbstd", 1.0 / DISPLAY[(_G, "N")].factor, deg / 3600.0),
        (_A, "vrw", "abstd", 1.0 / DISPLAY[(_A, "N")].factor, MGAL),
    ):
        for ax, n in _xyz(d[nkey]).items():
            vals.setdefault(kind, {})[ax] = {"N": n * nf}
        for ax, b in _xyz(d[bkey] if d[bkey] is not None else 0.0).items():
            vals[kind].setdefault(ax, {}).update({"T_c": tc, "sigma_b": b * bf})
    return FilterNoise("kf-gins", vals)


def _ros_imu(text: str, fs: float | None) -> FilterNoise:
    d = {
        k: _flow(text, k) for k in ("angular_velocity_covariance", "linear_acceleration_covariance")
    }
    if d["angular_velocity_covariance"] is None:
        raise ExportError("no angular_velocity_covariance")
    rate = _rate_comment(text) or fs
    if rate is None:
        raise ExportError("sensor_msgs/Imu covariances are per sample: the IMU rate is needed")
    notes = [] if _rate_comment(text) else [f"per-sample variances at the log's rate {rate:g} Hz"]
    vals: dict[str, dict[str, dict[str, float]]] = {}
    for key, kind in (("angular_velocity_covariance", _G), ("linear_acceleration_covariance", _A)):
        c = d.get(key)
        if not isinstance(c, list) or len(c) != 9 or c[0] < 0:
            continue
        for i, ax in enumerate("xyz"):
            vals.setdefault(kind, {})[ax] = {"N": math.sqrt(float(c[4 * i]) / rate)}
    return FilterNoise("ros-imu", vals, rate, notes)


#: Readers by format name, tried in this order on a file of unknown format.
READERS = {
    "kf-gins": _kfgins,
    "ros-imu": _ros_imu,
    "vins": _vins,
    "orbslam3": _orbslam3,
    "basalt": _basalt,
    "gz-sim": _gz_sim,
    "gazebo": _gazebo,
    "matlab": _matlab,
    "px4": lambda t, fs: _params(t, "px4"),
    "ardupilot": lambda t, fs: _params(t, "ardupilot"),
    "kalibr": _kalibr_like,
}


def read_filter_noise(text: str, fs: float | None = None) -> FilterNoise:
    """The noise model of a filter file's text (module docstring); ``fs`` is the log's rate,
    used when a per-sample file states none.

    Raises
    ------
    ExportError
        No reader recognises the text (the message lists the formats tried).
    """
    for reader in READERS.values():
        try:
            return reader(text, fs)
        except (ExportError, ValueError, TypeError, KeyError, AttributeError):
            continue
        except (ET.ParseError, json.JSONDecodeError):
            continue
    raise ExportError(f"not a filter file of a known format ({', '.join(READERS)})")


def _with_gm(spec: DatasheetSpec, rows: Sequence[Mapping[str, Any]], where: str) -> DatasheetSpec:
    """``spec`` with the Gauss-Markov (and AR1) terms of datasheet rows: per process label its
    ``T_c`` [s] and ``sigma_gm`` (in a signal unit), so that a GM model's white noise is not
    read as 0 (its fast GM carries it)."""
    terms: dict[str, dict[str, tuple[float, str]]] = {}
    for r in rows:
        if r.get("symbol") in ("T_c", "sigma_gm") and r.get("value") not in (None, ""):
            terms.setdefault(str(r.get("process")), {})[str(r["symbol"])] = (
                float(r["value"]),
                str(r.get("unit") or ""),
            )
    gm = []
    for lab, t in terms.items():
        if "T_c" not in t or "sigma_gm" not in t:
            continue
        v, u = t["sigma_gm"]
        try:
            k, f = si_factor(u)
        except ExportError as e:
            raise DatasheetError(f"{where} {lab} sigma_gm: {e}") from e
        if k != spec.kind:
            continue
        gm.append((t["T_c"][0], v * f))
    if not gm:
        return spec
    return dataclasses.replace(spec, gm=tuple(gm))


def _from_projection(projs: Any, kind: str | None, where: str) -> DatasheetSpec | None:
    """The first stored projection of a ``gmwm`` JSON report (``WN+RW`` or ``WN+GM``, in SI)
    as a datasheet: what a filter fed from this report assumes. None when there is none."""
    if not isinstance(projs, Mapping):
        return None
    for name, p in projs.items():
        if not isinstance(p, Mapping) or p.get("sensor") not in SI_UNIT:
            continue
        if kind is not None and p["sensor"] != kind:
            continue
        par = p.get("params") or {}

        def val(k: str, par: Mapping[str, Any] = par) -> float | None:
            v = par.get(k, {}).get("value") if isinstance(par.get(k), Mapping) else None
            return float(v) if isinstance(v, (int, float)) and not isinstance(v, bool) else None

        n = val("N")
        if n is None:
            continue
        src = f"{where} projection {name} ({p.get('consumer')})"
        if p.get("consumer") == "WN+RW" and val("K") is not None:
            return DatasheetSpec(p["sensor"], {"N": n, "K": val("K") or 0.0}, {}, src)
        if p.get("consumer") == "WN+GM" and val("T_c") and val("sigma_b") is not None:
            return DatasheetSpec(
                p["sensor"], {"N": n}, {}, src, gm=((val("T_c") or 1.0, val("sigma_b") or 0.0),)
            )
        if p.get("consumer") == "WN":
            return DatasheetSpec(p["sensor"], {"N": n}, {}, src)
    return None


def _report_spec(p: Path, channel: str | None, kind: str | None) -> DatasheetSpec | None:
    """A ``gmwm`` JSON report's stored projection (what a filter fed from it assumes) or a
    datasheet CSV's rows with their GM terms; None for another file."""
    text = read_regular(p, str(p), error=DatasheetError).decode("utf-8", "replace")
    if p.suffix.lower() == ".csv":
        rows = list(csv.DictReader(io.StringIO(text)))
        spec = read_datasheet(p, channel=channel, kind=kind)
        names = list(dict.fromkeys(r.get("channel") for r in rows))
        ch = channel if channel in names else names[0] if len(names) == 1 else channel
        return _with_gm(spec, [r for r in rows if r.get("channel") == ch], str(p))
    try:
        d = json.loads(text)
    except json.JSONDecodeError:
        return None
    if not isinstance(d, dict) or d.get("schema") != "gmwm-report/1":
        return None
    chans = d.get("channels") or {}
    names = list(chans)
    ch = channel if channel in names else names[0] if len(names) == 1 else channel
    c = chans.get(ch) if isinstance(chans.get(ch), dict) else None
    if c is None:
        return None
    stored = _from_projection(c.get("projections"), kind, f"{p} [{ch}]")
    if stored is None and isinstance(c.get("datasheet"), list):
        return _with_gm(read_datasheet(p, channel=ch, kind=kind), c["datasheet"], str(p))
    return stored


def read_check_file(
    source: str | os.PathLike[str],
    *,
    channel: str | None = None,
    kind: str | None = None,
    fs: float | None = None,
) -> DatasheetSpec:
    """The datasheet ``gmwm check --datasheet-file`` compares with the log: a ``gmwm`` JSON
    report through its stored projection, a datasheet CSV with its GM terms, a saved datasheet
    (:func:`~engine.inference.read_datasheet`), or
    a filter file of any format :mod:`engine.formats` writes, written by us or by hand
    (:func:`read_filter_noise`).

    Raises
    ------
    DatasheetError
        Unreadable file, or no reader recognises it (the message names the file).
    """
    p = Path(source)
    suffix = p.suffix.lower()
    if suffix in (".json", ".csv"):
        spec = _report_spec(p, channel, kind)
        if spec is not None:
            return spec
        try:
            return read_datasheet(p, channel=channel, kind=kind)
        except DatasheetError:
            if suffix == ".csv":
                raise
    raw = read_regular(p, str(p), error=DatasheetError)
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise DatasheetError(f"datasheet file '{p}' is not UTF-8 text") from None
    try:
        fn = read_filter_noise(text, fs)
    except ExportError as e:
        try:
            return read_datasheet(p, channel=channel, kind=kind)
        except DatasheetError as e2:
            raise DatasheetError(f"{p}: {e2}; and {e}") from None
    return fn.spec(kind, channel, str(p))
