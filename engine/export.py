"""Exports of GMWM fits for navigation filters and reports.

* :func:`datasheet_table`: one row per datasheet quantity and channel (angle/velocity random
  walk, rate/acceleration random walk, quantization, rate ramp, Gauss-Markov correlation time
  and driving-noise PSD, bias-instability floor), in the log's unit, in SI and in the usual
  datasheet unit, with intervals when parameter intervals are given;
* :func:`kalibr_imu` / :func:`write_kalibr`: a Kalibr ``imu.yaml`` (noise densities and random
  walks in SI, per axis and the conservative choice over axes); :func:`read_kalibr` and
  :func:`kalibr_models` read one back into models that simulate the sensor;
* :func:`fit_report`: a JSON report of every channel's fit;
* :func:`curves_csv`: CSV of the empirical WV with its interval and the implied WV, total and
  per process.

Conversions (CONVENTIONS, "Units and datasheet conversions"; ``dt = 1/fs``, signal unit u):

* white noise density ``N = sqrt(sigma2 dt)`` [u/sqrt(Hz)]; ARW [deg/sqrt(h)] ``= 60 N`` with N
  in (deg/s)/sqrt(Hz); VRW [m/s/sqrt(h)] ``= 60 N`` with N in (m/s^2)/sqrt(Hz);
* random walk ``K = sqrt(gamma2 / dt)`` [u/s/sqrt(Hz)]; RRW [deg/h/sqrt(h)] ``= 216000 K``
  with K in (deg/s)/sqrt(s); [m/s/h/sqrt(h)] likewise for accelerometers;
* quantization ``Q = sqrt(q2) dt`` [u s]; rate ramp ``R = |omega| / dt`` [u/s];
* Gauss-Markov: correlation time ``1/beta`` [s], stationary std ``sqrt(sigma2_gm)`` [u],
  driving-noise PSD ``q = 2 beta sigma2_gm`` [u^2/s] and its root ``sqrt(q)`` [u/s/sqrt(Hz)]
  (the density of the white noise w in ``db/dt = -beta b + w``);
* **bias-instability floor** ``B = min_T ADEV(T) / 0.664`` with ADEV the Allan deviation
  implied by the fitted model (``AVAR(T) = 2 nu2(tau)`` at ``tau = 2 T fs`` samples), over the
  analysed scales ``T = 1/fs .. 2^(J-1)/fs``. ``0.664 = sqrt(2 ln 2 / pi)`` is the ratio of the
  Allan deviation floor of flicker (1/f) bias noise to its coefficient (IEEE Std 952, annex
  C), so B is the datasheet "bias instability" a reader of the model's Allan curve would
  quote. When the implied ADEV has no minimum inside the scales (it still decreases at the
  longest one), B is an upper bound and the row says so.

Units of the log are converted to SI with :func:`si_factor` (``deg/s``, ``rad/s``, ``deg/h``,
``g``, ``mg``, ``m/s^2`` ...); an unknown or missing unit is an :class:`ExportError` naming the
channel and the accepted units.
"""

from __future__ import annotations

import csv
import io as _io
import json
import math
import os
import re
from collections.abc import Mapping, Sequence
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .fit import GMWMResult
from .models import RW, WN, Model

if TYPE_CHECKING:  # pragma: no cover
    from .inference import ParamInterval
    from .io import ImuLog

__all__ = [
    "ExportError",
    "DatasheetRow",
    "si_factor",
    "channel_axis",
    "datasheet_table",
    "datasheet_text",
    "datasheet_csv",
    "allan_floor",
    "KalibrImu",
    "kalibr_imu",
    "write_kalibr",
    "read_kalibr",
    "kalibr_models",
    "fit_report",
    "write_report",
    "curves_csv",
    "export",
    "BI_FACTOR",
]

BI_FACTOR = math.sqrt(2.0 * math.log(2.0) / math.pi)  # 0.6643... (IEEE Std 952)
G0 = 9.80665  # standard gravity, m/s^2
_DEG = math.pi / 180.0

# unit -> (sensor, factor to SI): rad/s for rates, m/s^2 for accelerations
_SI: dict[str, tuple[str, float]] = {
    "rad/s": ("gyroscope", 1.0),
    "mrad/s": ("gyroscope", 1e-3),
    "deg/s": ("gyroscope", _DEG),
    "dps": ("gyroscope", _DEG),
    "deg/h": ("gyroscope", _DEG / 3600.0),
    "deg/hr": ("gyroscope", _DEG / 3600.0),
    "rad/h": ("gyroscope", 1.0 / 3600.0),
    "rpm": ("gyroscope", 2.0 * math.pi / 60.0),
    "m/s^2": ("accelerometer", 1.0),
    "g": ("accelerometer", G0),
    "mg": ("accelerometer", 1e-3 * G0),
    "ug": ("accelerometer", 1e-6 * G0),
    "cm/s^2": ("accelerometer", 1e-2),
    "mm/s^2": ("accelerometer", 1e-3),
    "gal": ("accelerometer", 1e-2),
}


class ExportError(ValueError):
    """A fit cannot be exported as asked (unknown unit, missing process ...); says how to fix."""


def _norm_unit(unit: str) -> str:
    u = unit.strip().lower().replace(" ", "").replace("°", "deg").replace("µ", "u")
    u = u.replace("²", "^2").replace("**", "^").replace("sec", "s").replace("degree", "deg")
    u = re.sub(r"^degs?(?=/)", "deg", u)
    u = u.replace("/s/s", "/s^2").replace("/s2", "/s^2").replace("s-2", "/s^2")
    u = u.replace("ms^-2", "m/s^2").replace("m/s^-2", "m/s^2").replace("m//s^2", "m/s^2")
    u = u.replace("rad.s^-1", "rad/s").replace("deg.s^-1", "deg/s")
    return u


def si_factor(unit: str, channel: str = "") -> tuple[str, float]:
    """Sensor kind and factor to SI of a signal unit.

    Parameters
    ----------
    unit : str
        E.g. ``"deg/s"``, ``"rad/s"``, ``"deg/h"``, ``"g"``, ``"mg"``, ``"m/s^2"``.
    channel : str
        Channel name, for the error message.

    Returns
    -------
    (kind, factor)
        ``kind`` is ``"gyroscope"`` (SI: rad/s) or ``"accelerometer"`` (SI: m/s^2); SI value
        = factor x value.

    Raises
    ------
    ExportError
        Missing or unknown unit.
    """
    where = f" of channel {channel!r}" if channel else ""
    known = "deg/s, rad/s, deg/h, mrad/s, g, mg, ug, m/s^2"
    if not unit or not unit.strip():
        raise ExportError(
            f"the unit{where} is unknown: SI conversion needs it; give it with "
            f"units={{{channel or 'name'!r}: 'deg/s'}} (CLI: --units) among {known}"
        )
    got = _SI.get(_norm_unit(unit))
    if got is None:
        raise ExportError(
            f"unknown unit {unit!r}{where}: cannot convert to SI; use one of "
            f"{known} (CLI: --units NAME=UNIT)"
        )
    return got


def channel_axis(name: str) -> str:
    """Axis letter of a channel name (``gyro_x`` -> ``x``, ``imu/acc[1]`` -> ``y``), else the
    name itself."""
    n = name.strip().lower()
    m = re.search(r"\[(\d)\]$", n)
    if m and int(m.group(1)) < 3:
        return "xyz"[int(m.group(1))]
    m = re.search(r"(?:^|[^a-z])([xyz])$", n) or re.search(r"([xyz])$", n)
    return m.group(1) if m else name


def _per_s(u: str) -> str:
    if u.endswith("/s"):
        return u + "^2"
    m = re.fullmatch(r"(.*)/s\^(\d)", u)
    if m:
        return f"{m.group(1)}/s^{int(m.group(2)) + 1}"
    return f"{u}/s" if u else "u/s"


def _times_s(u: str) -> str:
    if u.endswith("/s"):
        return u[:-2]
    m = re.fullmatch(r"(.*)/s\^(\d)", u)
    if m:
        k = int(m.group(2)) - 1
        return f"{m.group(1)}/s" + (f"^{k}" if k > 1 else "")
    return f"{u}*s" if u else "u*s"


def _sq(u: str) -> str:
    u = u or "u"
    return f"({u})^2" if any(c in u for c in "/* ^") else f"{u}^2"


@dataclass(frozen=True)
class DatasheetRow:
    """One datasheet quantity of one channel.

    ``low``/``high`` are the interval bounds (NaN when no interval is available);
    ``process`` is the process label (``WN``, ``GM_1`` ...) or ``model`` for quantities of the
    whole model (bias-instability floor).
    """

    channel: str
    process: str
    quantity: str
    symbol: str
    value: float
    unit: str
    low: float = math.nan
    high: float = math.nan
    note: str = ""

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary (NaN as None)."""
        d = asdict(self)
        for k in ("value", "low", "high"):
            d[k] = _num(d[k])
        return d


def _num(v: Any) -> float | None:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return None
    return f if math.isfinite(f) else None


def _intervals_map(intervals: Sequence[ParamInterval] | None) -> dict[str, tuple[float, float]]:
    if not intervals:
        return {}
    return {iv.name: (float(iv.low), float(iv.high)) for iv in intervals}


def _map_iv(iv: tuple[float, float] | None, fn: Any) -> tuple[float, float]:
    """Interval of a monotone function of one parameter (either direction)."""
    if iv is None or not all(math.isfinite(v) for v in iv):
        return math.nan, math.nan
    try:
        a, b = fn(iv[0]), fn(iv[1])
    except (ValueError, ZeroDivisionError, OverflowError):
        return math.nan, math.nan
    return (min(a, b), max(a, b))


def _abs_iv(iv: tuple[float, float] | None) -> tuple[float, float] | None:
    if iv is None:
        return None
    lo, hi = iv
    if lo <= 0 <= hi:
        return 0.0, max(abs(lo), abs(hi))
    return tuple(sorted((abs(lo), abs(hi))))  # type: ignore[return-value]


def allan_floor(res: GMWMResult, *, points_per_octave: int = 16) -> dict[str, Any]:
    """Minimum of the model-implied Allan deviation over the analysed scales.

    Returns
    -------
    dict
        ``adev_min`` [u], ``T_s`` (Allan averaging time of the minimum, s), ``bias_instability``
        (``adev_min / 0.664``, u), ``at_edge`` (True when the minimum is at the shortest or
        longest scale: no floor inside, an upper bound), ``T_range_s``.
    """
    j = res.wv.n_levels
    fs = res.fs
    # Allan times T = m / fs, m = 2^(k) samples for k in [0, J - 1] -> WV at tau = 2m
    k = np.linspace(0.0, max(j - 1, 0), max(j - 1, 0) * points_per_octave + 1)
    m = 2.0**k
    avar = 2.0 * res.model.wv(2.0 * m, fs)
    avar = np.where(np.isfinite(avar) & (avar > 0), avar, np.inf)
    i = int(np.argmin(avar))
    adev = float(math.sqrt(avar[i])) if math.isfinite(avar[i]) else math.nan
    return {
        "adev_min": adev,
        "T_s": float(m[i] / fs),
        "bias_instability": adev / BI_FACTOR,
        "at_edge": bool(i == 0 or i == m.size - 1),
        "T_range_s": [float(m[0] / fs), float(m[-1] / fs)],
    }


def datasheet_table(
    fits: GMWMResult | Mapping[str, GMWMResult],
    *,
    intervals: Sequence[ParamInterval] | Mapping[str, Sequence[ParamInterval]] | None = None,
    units: Mapping[str, str] | None = None,
    si: bool = True,
) -> list[DatasheetRow]:
    """Datasheet quantities of fitted models, per channel, with units and intervals.

    Parameters
    ----------
    fits : GMWMResult or mapping of channel name to GMWMResult
        One fit, or one per channel (a single fit is named after ``wv.unit``-less ``"x"``).
    intervals : sequence of ParamInterval, or mapping of channel to them, optional
        Parameter intervals (:func:`engine.inference.param_intervals`); quantities that are
        monotone functions of one parameter get the mapped interval.
    units : mapping of str to str, optional
        Signal unit per channel; default ``fit.wv.unit``.
    si : bool
        Add SI and datasheet-unit rows (needs a known unit; unknown units give only the
        native rows, with a note).

    Returns
    -------
    list of DatasheetRow
        In channel order, then the model's process order, then the bias-instability floor.
    """
    if isinstance(fits, GMWMResult):
        fits = {"x": fits}
        if intervals is not None and not isinstance(intervals, Mapping):
            intervals = {"x": intervals}
    elif intervals is not None and not isinstance(intervals, Mapping):
        raise ExportError("with several channels give intervals as {channel: [ParamInterval]}")
    rows: list[DatasheetRow] = []
    for ch, res in fits.items():
        unit = (units or {}).get(ch, res.wv.unit) or ""
        ivs = _intervals_map((intervals or {}).get(ch))  # type: ignore[union-attr]
        rows += _channel_rows(ch, res, unit, ivs, si)
    return rows


def _channel_rows(
    ch: str, res: GMWMResult, unit: str, ivs: dict[str, tuple[float, float]], si: bool
) -> list[DatasheetRow]:
    fs = res.fs
    dt = 1.0 / fs
    u = unit or "u"
    kind, f_si = None, math.nan
    note_si = ""
    if si:
        try:
            kind, f_si = si_factor(unit, ch)
        except ExportError as e:
            note_si = f"no SI rows: {e}"
    gyro = kind == "gyroscope"
    su = "rad/s" if gyro else "m/s^2"
    rows: list[DatasheetRow] = []

    def add(
        proc: str,
        qty: str,
        sym: str,
        val: float,
        un: str,
        iv: tuple[float, float] = (math.nan, math.nan),
        note: str = "",
    ) -> None:
        rows.append(
            DatasheetRow(ch, proc, qty, sym, float(val), un, float(iv[0]), float(iv[1]), note)
        )

    for lab, p in zip(res.model.labels, res.model.processes, strict=True):
        v = dict(zip(p.param_names, p.values, strict=True))
        iv = {name: ivs.get(f"{lab}.{name}") for name in p.param_names}
        if p.code == "WN":

            def n_of(s2: float) -> float:
                return math.sqrt(max(s2, 0.0) * dt)

            n, n_iv = n_of(v["sigma2"]), _map_iv(iv["sigma2"], n_of)
            add(lab, "white noise density", "N", n, f"{u}/sqrt(Hz)", n_iv)
            if kind:
                add(
                    lab,
                    "white noise density (SI)",
                    "N",
                    n * f_si,
                    f"{su}/sqrt(Hz)",
                    _scale(n_iv, f_si),
                )
                if gyro:
                    c = 60.0 / _DEG
                    add(
                        lab,
                        "angle random walk",
                        "ARW",
                        n * f_si * c,
                        "deg/sqrt(h)",
                        _scale(n_iv, f_si * c),
                    )
                else:
                    add(
                        lab,
                        "velocity random walk",
                        "VRW",
                        n * f_si * 60.0,
                        "m/s/sqrt(h)",
                        _scale(n_iv, f_si * 60.0),
                    )
        elif p.code == "RW":

            def k_of(g2: float) -> float:
                return math.sqrt(max(g2, 0.0) / dt)

            k, k_iv = k_of(v["gamma2"]), _map_iv(iv["gamma2"], k_of)
            add(
                lab,
                "rate random walk" if gyro or not kind else "acceleration random walk",
                "K",
                k,
                f"{_per_s(u)}/sqrt(Hz)",
                k_iv,
            )
            if kind:
                add(
                    lab,
                    "random walk (SI)",
                    "K",
                    k * f_si,
                    f"{_per_s(su)}/sqrt(Hz)",
                    _scale(k_iv, f_si),
                )
                c = 216000.0 * (1.0 / _DEG if gyro else 1.0)
                add(
                    lab,
                    "rate random walk" if gyro else "acceleration random walk",
                    "RRW" if gyro else "AccRW",
                    k * f_si * c,
                    "deg/h/sqrt(h)" if gyro else "m/s/h/sqrt(h)",
                    _scale(k_iv, f_si * c),
                )
        elif p.code == "QN":

            def q_of(q2: float) -> float:
                return math.sqrt(max(q2, 0.0)) * dt

            q, q_iv = q_of(v["q2"]), _map_iv(iv["q2"], q_of)
            add(lab, "quantization", "Q", q, _times_s(u), q_iv)
            if kind:
                add(lab, "quantization (SI)", "Q", q * f_si, _times_s(su), _scale(q_iv, f_si))
        elif p.code == "DR":
            r, r_iv = abs(v["omega"]) * fs, _map_iv(_abs_iv(iv["omega"]), lambda w: w * fs)
            add(
                lab,
                "rate ramp" if gyro or not kind else "acceleration ramp",
                "R",
                r,
                _per_s(u),
                r_iv,
            )
            if kind:
                add(lab, "ramp (SI)", "R", r * f_si, _per_s(su), _scale(r_iv, f_si))
                if gyro:
                    c = 3600.0**2 / _DEG
                    add(lab, "rate ramp", "R", r * f_si * c, "deg/h^2", _scale(r_iv, f_si * c))
        elif p.code in ("GM", "AR1"):
            if p.code == "GM":
                beta, s2 = v["beta"], v["sigma2_gm"]
                tc_iv = _map_iv(iv["beta"], lambda b: 1.0 / b)
                std_iv = _map_iv(iv["sigma2_gm"], lambda s: math.sqrt(max(s, 0.0)))
            else:
                phi, s2i = v["phi"], v["sigma2"]
                if not 0 < phi < 1:
                    add(
                        lab,
                        "AR1 coefficient (no correlation time: phi outside (0, 1))",
                        "phi",
                        phi,
                        "1",
                    )
                    continue
                beta = -math.log(phi) * fs
                s2 = s2i / (1.0 - phi * phi)
                tc_iv = _map_iv(
                    iv["phi"], lambda ph: -dt / math.log(ph) if 0 < ph < 1 else math.nan
                )
                std_iv = (math.nan, math.nan)
            q = 2.0 * beta * s2
            add(lab, "correlation time", "T_c", 1.0 / beta, "s", tc_iv)
            add(lab, "stationary std", "sigma_gm", math.sqrt(s2), u, std_iv)
            add(lab, "driving-noise PSD", "q", q, f"{_sq(u)}/s", note="q = 2 beta sigma2_gm")
            add(lab, "driving-noise density", "sqrt(q)", math.sqrt(q), f"{_per_s(u)}/sqrt(Hz)")
            if kind:
                add(
                    lab,
                    "driving-noise density (SI)",
                    "sqrt(q)",
                    math.sqrt(q) * f_si,
                    f"{_per_s(su)}/sqrt(Hz)",
                )
    fl = allan_floor(res)
    note = (
        f"min over T = {fl['T_range_s'][0]:.4g}..{fl['T_range_s'][1]:.4g} s of the implied "
        f"ADEV / 0.664, at T = {fl['T_s']:.4g} s"
    )
    if fl["at_edge"]:
        note += "; no floor inside the analysed scales: an upper bound"
    b = fl["bias_instability"]
    add("model", "bias instability (Allan floor)", "B", b, u, note=note)
    if kind:
        add("model", "bias instability (Allan floor, SI)", "B", b * f_si, su, note=note)
        if gyro:
            add(
                "model",
                "bias instability (Allan floor)",
                "B",
                b * f_si / _DEG * 3600.0,
                "deg/h",
                note=note,
            )
        else:
            add(
                "model", "bias instability (Allan floor)", "B", b * f_si / G0 * 1e3, "mg", note=note
            )
    if note_si:
        rows.append(DatasheetRow(ch, "model", "units", "", math.nan, "", note=note_si))
    return rows


def _scale(iv: tuple[float, float], c: float) -> tuple[float, float]:
    return iv[0] * c, iv[1] * c


def datasheet_text(rows: Sequence[DatasheetRow]) -> str:
    """A readable table of :func:`datasheet_table` rows."""
    out = [f"{'channel':<10} {'process':<8} {'quantity':<40} {'value':>12} {'interval':>27}  unit"]
    for r in rows:
        if not math.isfinite(r.value):
            out.append(f"{r.channel:<10} {r.process:<8} {r.note}")
            continue
        ivl = (
            f"[{r.low:.4g}, {r.high:.4g}]" if math.isfinite(r.low) and math.isfinite(r.high) else ""
        )
        out.append(
            f"{r.channel:<10} {r.process:<8} {r.quantity:<40} {r.value:>12.5g} {ivl:>27}  {r.unit}"
        )
    return "\n".join(out)


def datasheet_csv(rows: Sequence[DatasheetRow]) -> str:
    """CSV of :func:`datasheet_table` rows (empty cells for missing intervals)."""
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(["channel", "process", "quantity", "symbol", "value", "low", "high", "unit", "note"])
    for r in rows:
        w.writerow(
            [
                r.channel,
                r.process,
                r.quantity,
                r.symbol,
                _fmt(r.value),
                _fmt(r.low),
                _fmt(r.high),
                r.unit,
                r.note,
            ]
        )
    return buf.getvalue()


def _fmt(v: float) -> str:
    return repr(float(v)) if math.isfinite(v) else ""


# ------------------------------------------------------------------------------ Kalibr
_KALIBR_KEYS = (
    "accelerometer_noise_density",
    "accelerometer_random_walk",
    "gyroscope_noise_density",
    "gyroscope_random_walk",
)


@dataclass(frozen=True, eq=False)
class KalibrImu:
    """The numbers of a Kalibr ``imu.yaml``, in SI.

    Attributes
    ----------
    values : dict of str to float
        ``gyroscope_noise_density`` [rad/s/sqrt(Hz)], ``gyroscope_random_walk``
        [rad/s^2/sqrt(Hz)], ``accelerometer_noise_density`` [m/s^2/sqrt(Hz)],
        ``accelerometer_random_walk`` [m/s^3/sqrt(Hz)]: the conservative choice (max over
        axes).
    chosen : dict of str to str
        The channel each value comes from.
    per_axis : dict of str to dict of str to float
        Each key's value per axis (``{"x": ..., "y": ..., "z": ...}``).
    sources : dict of str to str
        Where each per-axis value comes from (``gyro_x: RW``, or ``gyro_x: GM_1 driving noise``).
    update_rate : float
        Sampling frequency (Hz).
    rostopic : str
        IMU topic for Kalibr.
    comments : list of str
        Header comments (source, model, conventions).
    warnings : list of str
        Things the user should know (fallbacks).
    """

    values: dict[str, float]
    chosen: dict[str, str]
    per_axis: dict[str, dict[str, float]]
    sources: dict[str, str]
    update_rate: float
    rostopic: str = "/imu0"
    comments: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def to_yaml(self) -> str:
        """The ``imu.yaml`` text (YAML 1.1 floats, readable by Kalibr's PyYAML)."""
        unit = {"noise_density": "/sqrt(Hz)", "random_walk": "/sqrt(Hz)"}
        si = {
            "gyroscope_noise_density": "rad/s",
            "gyroscope_random_walk": "rad/s^2",
            "accelerometer_noise_density": "m/s^2",
            "accelerometer_random_walk": "m/s^3",
        }
        lines = [f"# {c}" for c in self.comments]
        lines += [f"# warning: {w}" for w in self.warnings]
        lines.append(f"rostopic: {self.rostopic}")
        lines.append(f"update_rate: {_yfloat(self.update_rate)}  # Hz (the log's sampling rate)")
        lines.append("")
        for key in _KALIBR_KEYS:
            if key not in self.values:
                continue
            kind = "noise_density" if key.endswith("noise_density") else "random_walk"
            axes = self.per_axis.get(key, {})
            lines.append(
                f"# {key} [{si[key]}{unit[kind]}]: conservative choice = max over "
                f"axes {', '.join(axes) or '-'}; largest on {self.chosen.get(key, '-')}"
            )
            lines.append(f"{key}: {_yfloat(self.values[key])}  # from {self.chosen.get(key, '-')}")
            if axes:
                flow = ", ".join(f"{a}: {_yfloat(v)}" for a, v in axes.items())
                lines.append(f"{key}_per_axis: {{{flow}}}")
            lines.append("")
        return "\n".join(lines).rstrip() + "\n"

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready dictionary."""
        return {
            "rostopic": self.rostopic,
            "update_rate": self.update_rate,
            **self.values,
            "chosen": dict(self.chosen),
            "per_axis": self.per_axis,
            "sources": dict(self.sources),
            "warnings": list(self.warnings),
        }


def _yfloat(v: float) -> str:
    """A float that YAML 1.1 (PyYAML) reads as a float: ``1.0e-05``, not ``1e-05``."""
    v = float(v)
    if not math.isfinite(v):
        return ".nan" if v != v else (".inf" if v > 0 else "-.inf")
    s = repr(v)
    if "e" in s:
        mant, exp = s.split("e")
        if "." not in mant:
            mant += ".0"
        if exp[0] not in "+-":
            exp = "+" + exp
        s = f"{mant}e{exp}"
    elif "." not in s:
        s += ".0"
    return s


def kalibr_imu(
    fits: Mapping[str, GMWMResult],
    *,
    units: Mapping[str, str] | None = None,
    rostopic: str = "/imu0",
    update_rate: float | None = None,
    source: str = "",
    allow_partial: bool = False,
) -> KalibrImu:
    """Kalibr IMU noise parameters from per-channel fits.

    ``*_noise_density`` is the white-noise density ``N = sqrt(sigma2 / fs)`` of the WN term and
    ``*_random_walk`` the random-walk density ``K = sqrt(gamma2 fs)`` of the RW term, both
    converted to SI. A channel whose model has no RW uses the driving-noise density
    ``sqrt(2 beta sigma2_gm)`` of its most persistent GM/AR1 term instead (a slow Gauss-Markov
    bias behaves like a random walk over a filter's horizon), with a warning. The file's value
    of each key is the largest over the axes (conservative), and comments say which axis.

    Parameters
    ----------
    fits : mapping of channel name to GMWMResult
        Gyroscope and accelerometer channels (the kind is read from the unit).
    units : mapping, optional
        Unit per channel (default ``fit.wv.unit``).
    rostopic : str
        ``rostopic`` entry.
    update_rate : float, optional
        Default: the fits' sampling frequency (all channels must agree).
    source : str
        Log name for the header comment.
    allow_partial : bool
        Allow a file without gyroscope or without accelerometer keys (Kalibr needs all four).

    Raises
    ------
    ExportError
        Unknown units, a model without WN, a channel with neither RW nor GM/AR1, mixed sampling
        frequencies, or a missing sensor without ``allow_partial``.
    """
    if not fits:
        raise ExportError("no fitted channel to export")
    fss = {ch: r.fs for ch, r in fits.items()}
    fs0 = next(iter(fss.values()))
    if any(not math.isclose(f, fs0, rel_tol=1e-9) for f in fss.values()):
        raise ExportError(
            f"the channels have different sampling frequencies {fss}: Kalibr's "
            "update_rate is one number"
        )
    per_axis: dict[str, dict[str, float]] = {}
    sources: dict[str, str] = {}
    chan_of: dict[tuple[str, str], str] = {}
    warnings: list[str] = []
    for ch, res in fits.items():
        unit = (units or {}).get(ch, res.wv.unit) or ""
        kind, f_si = si_factor(unit, ch)
        axis = channel_axis(ch)
        vals = res.model.values()
        labels = res.model.labels
        procs = res.model.processes
        wn = [lab for lab, p in zip(labels, procs, strict=True) if p.code == "WN"]
        if not wn:
            raise ExportError(
                f"the model of {ch!r} ({res.model.spec()}) has no WN term: the "
                "noise density needs one; fit a model with WN"
            )
        nd = math.sqrt(vals[f"{wn[0]}.sigma2"] / res.fs) * f_si
        rw = [lab for lab, p in zip(labels, procs, strict=True) if p.code == "RW"]
        if rw:
            rwd = math.sqrt(vals[f"{rw[0]}.gamma2"] * res.fs) * f_si
            src_rw = f"{ch}: {rw[0]}"
        else:
            gm = [(lab, p) for lab, p in zip(labels, procs, strict=True) if p.code in ("GM", "AR1")]
            if not gm:
                raise ExportError(
                    f"the model of {ch!r} ({res.model.spec()}) has neither RW nor "
                    "GM/AR1: the random walk cannot be set; fit a model with RW "
                    "(e.g. WN+RW or GM+WN+RW)"
                )
            lab, p = gm[0]  # most persistent first
            if p.code == "GM":
                beta, s2 = p.beta, p.sigma2_gm
            else:
                beta = -math.log(p.phi) * res.fs if 0 < p.phi < 1 else math.nan
                s2 = p.sigma2 / (1 - p.phi**2)
            rwd = math.sqrt(2 * beta * s2) * f_si if beta > 0 else math.nan
            if not math.isfinite(rwd):
                raise ExportError(
                    f"the model of {ch!r} has no RW and its {lab} term has no "
                    "positive correlation time: fit a model with RW"
                )
            src_rw = f"{ch}: {lab} driving noise sqrt(2 beta sigma2_gm) (no RW in the model)"
            warnings.append(
                f"{ch}: no RW term; random walk set from {lab}'s driving noise "
                f"(correlation time {1 / beta:.4g} s)"
            )
        for key, val, src in (
            (f"{kind}_noise_density", nd, f"{ch}: {wn[0]}"),
            (f"{kind}_random_walk", rwd, src_rw),
        ):
            if axis in per_axis.get(key, {}):
                raise ExportError(
                    f"two {kind} channels map to axis {axis!r} "
                    f"({chan_of[(key, axis)]}, {ch}): export one of them"
                )
            per_axis.setdefault(key, {})[axis] = float(val)
            chan_of[(key, axis)] = ch
            if not val > 0:
                warnings.append(
                    f"{ch}: {key} estimated as 0 ({src.split(': ', 1)[-1]} on the "
                    "boundary); the conservative value comes from another axis"
                )
            sources[f"{key}[{axis}]"] = src
    missing = [k for k in _KALIBR_KEYS if k not in per_axis]
    if missing and not allow_partial:
        have = sorted({k.split("_")[0] for k in per_axis})
        raise ExportError(
            f"Kalibr needs gyroscope and accelerometer noise; the fits give only "
            f"{' and '.join(have)} ({', '.join(fits)}). Add the other channels, "
            "or allow a partial file (allow_partial=True, CLI --partial)"
        )
    values, chosen = {}, {}
    for key in _KALIBR_KEYS:
        if key in per_axis:
            axis = max(per_axis[key], key=lambda a: per_axis[key][a])
            values[key] = per_axis[key][axis]
            chosen[key] = chan_of[(key, axis)]
    rate = float(update_rate) if update_rate is not None else float(fs0)
    models = sorted({r.model.spec() for r in fits.values()})
    comments = [
        "Kalibr IMU noise model from a GMWM fit (engine.export.kalibr_imu)",
        f"source: {source or 'in-memory fits'}; channels: {', '.join(fits)}; "
        f"model(s): {'; '.join(models)}",
        "noise_density = sqrt(sigma2_WN / fs) (continuous-time white noise density), "
        "random_walk = sqrt(gamma2_RW * fs); SI units",
        "per-axis values are in *_per_axis; the main keys hold the max over axes "
        "(conservative choice). Kalibr's own advice is to inflate them further for "
        "unmodelled effects (temperature, vibration).",
    ]
    return KalibrImu(
        values=values,
        chosen=chosen,
        per_axis=per_axis,
        sources=sources,
        update_rate=rate,
        rostopic=rostopic,
        comments=comments,
        warnings=warnings,
    )


def write_kalibr(
    path: str | os.PathLike[str], fits: Mapping[str, GMWMResult], **kwargs: Any
) -> Path:
    """Write :func:`kalibr_imu` as a YAML file; returns the path."""
    p = Path(path)
    p.write_text(kalibr_imu(fits, **kwargs).to_yaml())
    return p


def _yscalar(s: str) -> Any:
    s = s.strip()
    if len(s) >= 2 and s[0] == s[-1] and s[0] in "'\"":
        return s[1:-1]
    low = s.lower()
    if low in (".nan", "nan"):
        return math.nan
    if low in (".inf", "+.inf", "inf"):
        return math.inf
    if low in ("-.inf", "-inf"):
        return -math.inf
    if low in ("true", "false"):
        return low == "true"
    try:
        return int(s)
    except ValueError:
        pass
    try:
        return float(s)
    except ValueError:
        return s


def _strip_comment(line: str) -> str:
    quote = ""
    for i, c in enumerate(line):
        if c in "'\"":
            quote = "" if quote == c else (quote or c)
        elif c == "#" and not quote and (i == 0 or line[i - 1] in " \t"):
            return line[:i]
    return line


def read_kalibr(source: str | os.PathLike[str]) -> dict[str, Any]:
    """Read a Kalibr ``imu.yaml`` (path, or the YAML text itself) into a dict.

    Reads the flat ``key: value`` layout of Kalibr IMU files, with flow mappings/lists
    (``{x: 1.0, y: 2.0}``); indented blocks (nested mappings) are skipped. No YAML library
    is needed.

    Raises
    ------
    ExportError
        Unreadable file, or a line that is not ``key: value``.
    """
    text = str(source)
    if isinstance(source, os.PathLike) or (
        "\n" not in text and ":" not in text.split("/")[0] and Path(text).is_file()
    ):
        try:
            text = Path(source).read_text()
        except (OSError, UnicodeDecodeError) as exc:
            raise ExportError(f"cannot read Kalibr file '{source}': {exc}") from exc
    out: dict[str, Any] = {}
    for i, raw in enumerate(text.splitlines(), start=1):
        line = _strip_comment(raw).rstrip()
        if not line.strip() or line.strip() == "---" or line[0] in " \t-":
            continue
        key, sep, val = line.partition(":")
        if not sep or not key.strip():
            raise ExportError(f"Kalibr YAML line {i}: {raw.strip()!r} is not 'key: value'")
        val = val.strip()
        if val.startswith("{") and val.endswith("}"):
            items = [it for it in val[1:-1].split(",") if it.strip()]
            d = {}
            for it in items:
                k, s2, v = it.partition(":")
                if not s2:
                    raise ExportError(f"Kalibr YAML line {i}: {it.strip()!r} is not 'key: value'")
                d[k.strip()] = _yscalar(v)
            out[key.strip()] = d
        elif val.startswith("[") and val.endswith("]"):
            out[key.strip()] = [_yscalar(v) for v in val[1:-1].split(",") if v.strip()]
        else:
            out[key.strip()] = _yscalar(val) if val else None
    return out


def kalibr_models(
    kalibr: str | os.PathLike[str] | Mapping[str, Any], *, per_axis: bool = False
) -> dict[str, Model]:
    """Models (per sample, SI units) that simulate the sensor described by a Kalibr file.

    ``WN(sigma2 = N^2 fs) + RW(gamma2 = K^2 / fs)`` with ``fs = update_rate``, for
    ``"gyroscope"`` and ``"accelerometer"`` (rad/s and m/s^2); with ``per_axis=True`` one model
    per ``"gyroscope_x"`` ... from the ``*_per_axis`` entries.

    Raises
    ------
    ExportError
        Missing ``update_rate`` or noise keys, non-positive values.
    """
    d = kalibr if isinstance(kalibr, Mapping) else read_kalibr(kalibr)
    fs = d.get("update_rate")
    if not isinstance(fs, (int, float)) or isinstance(fs, bool) or not fs > 0:
        raise ExportError(f"Kalibr file: update_rate = {fs!r} is not a positive number of Hz")
    out: dict[str, Model] = {}
    for sensor in ("gyroscope", "accelerometer"):
        nk, rk = f"{sensor}_noise_density", f"{sensor}_random_walk"
        if nk not in d and rk not in d:
            continue
        pairs: dict[str, tuple[Any, Any]] = {}
        if per_axis:
            na, ra = d.get(f"{nk}_per_axis") or {}, d.get(f"{rk}_per_axis") or {}
            for ax in na:
                pairs[f"{sensor}_{ax}"] = (na.get(ax), ra.get(ax))
        else:
            pairs[sensor] = (d.get(nk), d.get(rk))
        for name, (n, k) in pairs.items():
            for key, v in ((nk, n), (rk, k)):
                if (
                    not isinstance(v, (int, float))
                    or isinstance(v, bool)
                    or not v >= 0
                    or not math.isfinite(v)
                ):
                    raise ExportError(
                        f"Kalibr file: {key} of {name} = {v!r} is not a non-negative number"
                    )
            out[name] = WN(sigma2=float(n) ** 2 * fs) + RW(gamma2=float(k) ** 2 / fs)
    if not out:
        raise ExportError("Kalibr file has no gyroscope_* or accelerometer_* noise keys")
    return out


# ------------------------------------------------------------------------------ report / CSV
def _clean(o: Any) -> Any:
    """NaN/Inf -> None, NumPy -> Python, recursively (strict JSON)."""
    if isinstance(o, dict):
        return {str(k): _clean(v) for k, v in o.items()}
    if isinstance(o, (list, tuple)):
        return [_clean(v) for v in o]
    if isinstance(o, np.ndarray):
        return _clean(o.tolist())
    if isinstance(o, (np.floating, float)):
        return _num(o)
    if isinstance(o, np.integer):
        return int(o)
    if isinstance(o, np.bool_):
        return bool(o)
    return o


def fit_report(
    fits: Mapping[str, GMWMResult],
    *,
    intervals: Mapping[str, Sequence[ParamInterval]] | None = None,
    log: ImuLog | None = None,
    units: Mapping[str, str] | None = None,
    source: str = "",
    kalibr: bool = True,
) -> dict[str, Any]:
    """A JSON-ready report of every channel's fit.

    Returns
    -------
    dict
        ``schema`` (``"gmwm-report/1"``), ``engine_version``, ``source``, ``log`` (fs, n,
        units, time report and notes when ``log`` is given), and ``channels``: per channel the
        unit, sensor kind and axis, the fit (:meth:`GMWMResult.to_dict`), its intervals, the
        datasheet rows and the Allan floor; ``kalibr`` (or the reason it is missing).
        NaN values are ``null``.
    """
    from ._version import __version__

    units = dict(units or {})
    chans: dict[str, Any] = {}
    for ch, res in fits.items():
        unit = units.get(ch, res.wv.unit) or ""
        try:
            kind: str | None = si_factor(unit, ch)[0]
        except ExportError:
            kind = None
        ivs = (intervals or {}).get(ch)
        chans[ch] = {
            "unit": unit,
            "sensor": kind,
            "axis": channel_axis(ch),
            "fit": res.to_dict(),
            "intervals": [iv.to_dict() for iv in ivs] if ivs else None,
            "datasheet": [
                r.to_dict()
                for r in datasheet_table(
                    {ch: res}, intervals={ch: ivs} if ivs else None, units={ch: unit}
                )
            ],
            "allan_floor": allan_floor(res),
        }
    out: dict[str, Any] = {
        "schema": "gmwm-report/1",
        "engine_version": __version__,
        "source": source or (log.source if log is not None else ""),
        "channels": chans,
    }
    if log is not None:
        out["log"] = {
            "fs": log.fs,
            "fs_source": log.fs_source,
            "n": log.n,
            "units": dict(log.units),
            "format": log.meta.get("format"),
            "time_report": log.meta.get("time_report"),
            "segment": log.meta.get("segment"),
            "scale": log.meta.get("scale"),
            "notes": log.meta.get("notes", []),
        }
    if kalibr:
        try:
            out["kalibr"] = kalibr_imu(
                fits, units=units or None, source=out["source"], allow_partial=True
            ).to_dict()
        except ExportError as e:
            out["kalibr"] = {"error": str(e)}
    return _clean(out)


def write_report(
    path: str | os.PathLike[str], fits: Mapping[str, GMWMResult], **kwargs: Any
) -> Path:
    """Write :func:`fit_report` as strict JSON (no NaN); returns the path."""
    p = Path(path)
    p.write_text(json.dumps(fit_report(fits, **kwargs), indent=1, allow_nan=False) + "\n")
    return p


def curves_csv(fits: GMWMResult | Mapping[str, GMWMResult]) -> str:
    """CSV of the empirical WV, its interval and the implied WV (total and per process).

    Columns: ``channel, level, tau_samples, tau_s, wv, ci_low, ci_high, implied`` then one
    column per process label (``GM_1, WN, RW`` ...; the union over channels, empty where a
    channel's model lacks the process), and ``wv_unit``. Numbers are written with 17
    significant digits (exact round trip).
    """
    if isinstance(fits, GMWMResult):
        fits = {"x": fits}
    labels: list[str] = []
    for res in fits.values():
        labels += [lab for lab in res.components if lab not in labels]
    buf = _io.StringIO()
    w = csv.writer(buf, lineterminator="\n")
    w.writerow(
        [
            "channel",
            "level",
            "tau_samples",
            "tau_s",
            "wv",
            "ci_low",
            "ci_high",
            "implied",
            *labels,
            "wv_unit",
        ]
    )
    for ch, res in fits.items():
        wv = res.wv
        for i in range(wv.n_levels):
            comp = [_fmt(res.components[lab][i]) if lab in res.components else "" for lab in labels]
            w.writerow(
                [
                    ch,
                    int(wv.levels[i]),
                    int(wv.tau_samples[i]),
                    _fmt(wv.tau_s[i]),
                    _fmt(wv.variance[i]),
                    _fmt(wv.ci_low[i]),
                    _fmt(wv.ci_high[i]),
                    _fmt(res.implied[i]),
                    *comp,
                    _sq(wv.unit) if wv.unit else "",
                ]
            )
    return buf.getvalue()


FORMATS = ("kalibr", "json", "csv", "datasheet", "datasheet-csv")


def export(
    path: str | os.PathLike[str] | None,
    fits: Mapping[str, GMWMResult],
    fmt: str,
    *,
    intervals: Mapping[str, Sequence[ParamInterval]] | None = None,
    log: ImuLog | None = None,
    units: Mapping[str, str] | None = None,
    source: str = "",
    rostopic: str = "/imu0",
    allow_partial: bool = False,
) -> str:
    """Export fits in one format; writes ``path`` (unless None) and returns the text.

    Parameters
    ----------
    fmt : {"kalibr", "json", "csv", "datasheet", "datasheet-csv"}
        Kalibr ``imu.yaml``, JSON report, CSV of the WV and implied curves, readable
        datasheet table, datasheet CSV.
    """
    if fmt == "kalibr":
        text = kalibr_imu(
            fits, units=units, rostopic=rostopic, source=source, allow_partial=allow_partial
        ).to_yaml()
    elif fmt == "json":
        text = (
            json.dumps(
                fit_report(fits, intervals=intervals, log=log, units=units, source=source),
                indent=1,
                allow_nan=False,
            )
            + "\n"
        )
    elif fmt == "csv":
        text = curves_csv(fits)
    elif fmt in ("datasheet", "datasheet-csv"):
        rows = datasheet_table(fits, intervals=intervals, units=units)
        text = datasheet_text(rows) + "\n" if fmt == "datasheet" else datasheet_csv(rows)
    else:
        raise ExportError(f"unknown export format {fmt!r}: use one of {', '.join(FORMATS)}")
    if path is not None:
        Path(path).write_text(text)
    return text
