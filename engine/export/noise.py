"""The numbers every filter export needs, per sensor and axis, in SI, from the one datasheet
table (:mod:`engine.units`): white-noise density N and random walk K (the Kalibr extraction of
:func:`~engine.export.kalibr.kalibr_imu`), the model's bias-instability (Allan floor) B, and
the most persistent Gauss-Markov term (correlation time T_c, stationary std sigma_gm,
driving-noise density sqrt(q)). :func:`imu_noise` multiplies every noise value (never a time)
by the explicit ``inflate`` factor and says so in the header it returns.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

from ..fit import GMWMResult
from ..units import ExportError, datasheet_rows, si_factor
from .common import channel_axis
from .kalibr import kalibr_imu

__all__ = ["ImuNoise", "imu_noise", "noise_for", "check_inflate", "SENSORS"]

#: Sensor kinds in file order, with their SI signal unit.
SENSORS = {"gyroscope": "rad/s", "accelerometer": "m/s^2"}


def check_inflate(inflate: float) -> float:
    """The ``inflate`` factor as a float; refuses a non-finite or non-positive one."""
    f = float(inflate)
    if not (math.isfinite(f) and f > 0):
        raise ExportError(f"inflate must be a positive number, got {inflate!r}")
    return f


@dataclass(frozen=True, eq=False)
class ImuNoise:
    """Per-axis noise numbers in SI, already multiplied by ``inflate`` (times are not).

    Attributes
    ----------
    values : dict
        ``values[kind][quantity][axis]`` with ``kind`` in :data:`SENSORS` and ``quantity`` in
        ``N`` [u/sqrt(Hz)], ``K`` [u/s/sqrt(Hz)], ``sigma2`` (per-sample WN variance, u^2,
        multiplied by ``inflate**2``), ``B`` [u] (Allan floor), ``T_c`` [s], ``sigma_gm`` [u],
        ``sqrt(q)`` [u/s/sqrt(Hz)] (the GM keys only where the channel's model has GM/AR1).
    fs : float
        Sampling frequency of the log (Hz).
    inflate : float
    header : list of str
        Comment lines: source, channels, models, inflate.
    warnings : list of str
    """

    values: dict[str, dict[str, dict[str, float]]]
    fs: float
    inflate: float
    header: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)

    def conservative(self, kind: str, quantity: str) -> float:
        """Largest value over the axes (the file value of a one-number key)."""
        d = self.values.get(kind, {}).get(quantity)
        if not d:
            raise ExportError(f"no {kind} {quantity} in the fits")
        return max(d.values())

    def xyz(self, kind: str, quantity: str, factor: float = 1.0) -> list[float]:
        """Values on axes x, y, z times ``factor``; an axis that was not fitted gets the max
        over the fitted ones."""
        d = self.values[kind][quantity]
        return [d.get(a, max(d.values())) * factor for a in "xyz"]

    def need(self, quantity: str, fmt: str, hint: str) -> None:
        """Refuse when some channel lacks ``quantity`` (e.g. a GM term)."""
        for kind, q in self.values.items():
            n = len(q.get("N", {}))
            if len(q.get(quantity, {})) < n:
                raise ExportError(f"{fmt} needs {quantity} on every {kind} channel: {hint}")


def _row(rows: list, proc: str, quantity: str, symbol: str) -> float:
    for r in rows:
        if r.process == proc and r.quantity == quantity and r.symbol == symbol:
            return float(r.value)
    return math.nan


def imu_noise(
    fits: Mapping[str, GMWMResult],
    *,
    units: Mapping[str, str] | None = None,
    inflate: float = 1.0,
    source: str = "",
    fmt: str = "",
    allow_partial: bool = False,
) -> ImuNoise:
    """Gather N, K, sigma2, B and the GM numbers per sensor and axis in SI (see
    :class:`ImuNoise`); N and K as :func:`~engine.export.kalibr.kalibr_imu` extracts them
    (K from the GM driving noise when a model has no RW, with a warning).

    Raises
    ------
    ExportError
        As :func:`~engine.export.kalibr.kalibr_imu`, or a bad ``inflate``.
    """
    f = check_inflate(inflate)
    kal = kalibr_imu(fits, units=units, source=source, allow_partial=allow_partial)
    vals: dict[str, dict[str, dict[str, float]]] = {}
    for key, axes in kal.per_axis.items():
        kind, _, what = key.partition("_")
        q = "N" if what == "noise_density" else "K"
        vals.setdefault(kind, {})[q] = {a: v * f for a, v in axes.items()}
    for ch, res in fits.items():
        unit = (units or {}).get(ch, res.wv.unit) or ""
        kind, f_si = si_factor(unit, ch)
        ax = channel_axis(ch)
        rows = datasheet_rows(res.model, res.fs, unit, channel=ch, n_levels=res.wv.n_levels)
        d = vals.setdefault(kind, {})
        labels, procs = res.model.labels, res.model.processes
        wn = [lab for lab, p in zip(labels, procs, strict=True) if p.code == "WN"][0]
        d.setdefault("sigma2", {})[ax] = res.model.values()[f"{wn}.sigma2"] * f_si**2 * f * f
        d.setdefault("B", {})[ax] = (
            _row(rows, "model", "bias instability (Allan floor, SI)", "B") * f
        )
        gm = [lab for lab, p in zip(labels, procs, strict=True) if p.code in ("GM", "AR1")]
        if gm:
            tc = _row(rows, gm[0], "correlation time", "T_c")
            if math.isfinite(tc) and tc > 0:
                d.setdefault("T_c", {})[ax] = tc
                sg = _row(rows, gm[0], "stationary std", "sigma_gm")
                d.setdefault("sigma_gm", {})[ax] = sg * f_si * f
                name = "driving-noise density (SI)"
                d.setdefault("sqrt(q)", {})[ax] = _row(rows, gm[0], name, "sqrt(q)") * f
    models = sorted({r.model.spec() for r in fits.values()})
    header = [
        f"{fmt or 'IMU noise'} from a GMWM fit (engine.export, gmwm export)",
        f"source: {source or 'in-memory fits'}; channels: {', '.join(fits)}; "
        f"model(s): {'; '.join(models)}; log rate {kal.update_rate:g} Hz",
        f"inflate = {f!r}: every noise value below is the fitted value x {f!r} "
        "(variances x inflate^2; times and rates unchanged)",
    ]
    return ImuNoise(vals, kal.update_rate, f, header, list(kal.warnings))


def noise_for(
    fits: Mapping[str, GMWMResult],
    fmt: str,
    options: Mapping[str, Any],
    allow_partial: bool = False,
) -> ImuNoise:
    """:func:`imu_noise` with a writer's options (``units``, ``inflate``, ``source``)."""
    return imu_noise(
        fits,
        units=options.get("units"),
        inflate=options.get("inflate", 1.0),
        source=options.get("source", ""),
        fmt=fmt,
        allow_partial=allow_partial,
    )
