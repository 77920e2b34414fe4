"""Kalibr ``imu.yaml``: :func:`kalibr_imu` / :func:`write_kalibr` write one (noise densities
and random walks in SI, per axis and the conservative choice over axes); :func:`read_kalibr`
and :func:`kalibr_models` read one back into models that simulate the sensor.

``*_noise_density`` is N and ``*_random_walk`` is K of :data:`engine.units.QUANTITIES`
(docs/conventions.md, "Units and datasheet conversions"), in rad/s and m/s^2.
"""

from __future__ import annotations

import math
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .._files import write_atomic
from ..fit import GMWMResult
from ..io.kalibr import read_kalibr
from ..io.log import channel_axis
from ..models import RW, WN, Model
from ..units import ExportError, process_values, si_factor, to_datasheet
from .common import text_lines, yaml_float, yaml_str

__all__ = ["KalibrImu", "kalibr_imu", "write_kalibr", "read_kalibr", "kalibr_models"]

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
        lines.append(f"rostopic: {yaml_str(self.rostopic)}")
        lines.append(
            f"update_rate: {yaml_float(self.update_rate)}  # Hz (the IMU rate; densities do not "
            "depend on it)"
        )
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
            lines.append(
                f"{key}: {yaml_float(self.values[key])}  # from {self.chosen.get(key, '-')}"
            )
            if axes:
                flow = ", ".join(f"{yaml_str(a)}: {yaml_float(v)}" for a, v in axes.items())
                lines.append(f"{key}_per_axis: {{{flow}}}")
            lines.append("")
        return text_lines(lines).rstrip() + "\n"

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
        vals = res.params  # by unique name, every value set
        labels = res.model.labels
        procs = res.model.processes
        wn = [lab for lab, p in zip(labels, procs, strict=True) if p.code == WN.code]
        if not wn:
            raise ExportError(
                f"the model of {ch!r} ({res.model.spec()}) has no WN term: the "
                "noise density needs one; fit a model with WN"
            )
        nd = to_datasheet(WN.code, vals[f"{wn[0]}.sigma2"], res.fs) * f_si
        rw = [lab for lab, p in zip(labels, procs, strict=True) if p.code == RW.code]
        if rw:
            rwd = to_datasheet(RW.code, vals[f"{rw[0]}.gamma2"], res.fs) * f_si
            src_rw = f"{ch}: {rw[0]}"
        else:
            gm = [(lab, p) for lab, p in zip(labels, procs, strict=True) if p.nonlinear]
            if not gm:
                raise ExportError(
                    f"the model of {ch!r} ({res.model.spec()}) has neither RW nor "
                    "GM/AR1: the random walk cannot be set; fit a model with RW "
                    "(e.g. WN+RW or GM+WN+RW)"
                )
            lab, p = gm[0]  # most persistent first
            try:
                gmv = process_values(p, res.fs)  # AR1 as the GM it samples
            except ValueError:  # AR1 with phi outside (0, 1)
                gmv = {"T_c": math.nan, "sqrt(q)": math.nan}
            tc = gmv["T_c"]
            rwd = gmv["sqrt(q)"] * f_si if tc > 0 else math.nan
            if not math.isfinite(rwd):
                raise ExportError(
                    f"the model of {ch!r} has no RW and its {lab} term has no "
                    "positive correlation time: fit a model with RW"
                )
            src_rw = f"{ch}: {lab} driving noise sqrt(2 beta sigma2_gm) (no RW in the model)"
            warnings.append(
                f"{ch}: no RW term; random walk set from {lab}'s driving noise "
                f"(correlation time {tc:.4g} s)"
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
            "or allow a partial file (allow_partial=True)"
        )
    values, chosen = {}, {}
    for key in _KALIBR_KEYS:
        if key in per_axis:
            axis = max(per_axis[key], key=lambda a: per_axis[key][a])
            values[key] = per_axis[key][axis]
            chosen[key] = chan_of[(key, axis)]
    return KalibrImu(
        values=values,
        chosen=chosen,
        per_axis=per_axis,
        sources=sources,
        update_rate=float(update_rate) if update_rate is not None else float(fs0),
        rostopic=rostopic,
        comments=_header_comments(fits, source),
        warnings=warnings,
    )


def _header_comments(fits: Mapping[str, GMWMResult], source: str | None) -> list[str]:
    """The header comments of an ``imu.yaml``: origin, channels and models, conventions."""
    models = sorted({r.model.spec() for r in fits.values()})
    return [
        "Kalibr IMU noise model from a GMWM fit (engine.formats.kalibr_imu)",
        f"source: {source or 'in-memory fits'}; channels: {', '.join(fits)}; "
        f"model(s): {'; '.join(models)}",
        "noise_density = sqrt(sigma2_WN / fs) (continuous-time white noise density), "
        "random_walk = sqrt(gamma2_RW * fs); SI units",
        "per-axis values are in *_per_axis; the main keys hold the max over axes "
        "(conservative choice). Kalibr's own advice is to inflate them further for "
        "unmodelled effects (temperature, vibration).",
    ]


def write_kalibr(
    path: str | os.PathLike[str], fits: Mapping[str, GMWMResult], **kwargs: Any
) -> Path:
    """Write :func:`kalibr_imu` as a YAML file; returns the path."""
    p = Path(path)
    write_atomic(p, kalibr_imu(fits, **kwargs).to_yaml())
    return p


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
            out[name] = WN.from_datasheet({"N": float(n)}, fs) + RW.from_datasheet(
                {"K": float(k)}, fs
            )
    if not out:
        raise ExportError("Kalibr file has no gyroscope_* or accelerometer_* noise keys")
    return out
