"""The numbers every filter export needs, per sensor and axis, in SI: white-noise density N,
bias random walk K, the model's bias-instability (Allan floor) B, and a Gauss-Markov bias
(correlation time T_c, stationary std sigma_gm, driving-noise density sqrt(q)).

:func:`imu_noise` takes them, by ``projection``:

* ``"bound"`` (the filter formats' default): the fit projected onto the consumer's noise model
  and over-bounded (:func:`~engine.formats.projection.project`), with intervals;
* ``"plain"``: the same rule without the bound;
* ``"fit"``: the fit's own terms converted one by one (the Kalibr extraction of
  :func:`~engine.formats.kalibr.kalibr_imu`, the most persistent GM term), as before the
  projection existed.

It multiplies every noise value (never a time) by the explicit ``inflate`` factor and says so
in the header it returns.
"""

from __future__ import annotations

import math
import warnings as _warnings
from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from ..fit import GMWMResult
from ..io.log import channel_axis
from ..models import WN
from ..units import ExportError, datasheet_rows, si_factor
from .catalog import FLEET_CONSUMERS, FORMATS
from .kalibr import kalibr_imu
from .options import PROJECTIONS, ExportOptions, FleetUnit, check_inflate
from .projection import Projection, consumer_of, project
from .tails import TailFactors

__all__ = [
    "ImuNoise",
    "imu_noise",
    "noise_for",
    "check_inflate",
    "SENSORS",
    "PROJECTIONS",
    "FleetUnit",
    "fleet_noise",
    "FLEET_CONSUMERS",
]

#: Sensor kinds in file order, with their SI signal unit.
SENSORS = {"gyroscope": "rad/s", "accelerometer": "m/s^2"}


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
        Comment lines: source, channels, models, projection and bound, each value with its
        interval, inflate.
    warnings : list of str
    projections : dict of str to Projection
        Per channel (empty with ``projection="fit"``).
    fs_filter : float or None
        The consumer's rate (Hz): the filter rate given, else None (the log's rate).
    """

    values: dict[str, dict[str, dict[str, float]]]
    fs: float
    inflate: float
    header: list[str] = field(default_factory=list)
    warnings: list[str] = field(default_factory=list)
    projections: dict[str, Projection] = field(default_factory=dict)
    fs_filter: float | None = None

    @property
    def rate(self) -> float:
        """The consumer's rate (Hz) for per-sample and per-step values and the rate keys:
        ``fs_filter`` when given, else the log's ``fs``. Densities do not depend on it."""
        return self.fs if self.fs_filter is None else self.fs_filter

    def rate_line(self) -> str:
        """The header line that says which rate the file's per-sample values and rate keys
        use."""
        if self.fs_filter is None:
            return (
                f"consumer rate {self.fs:g} Hz: the log's sampling rate (--filter-rate HZ for "
                "another)"
            )
        return (
            f"consumer rate {self.rate:g} Hz (--filter-rate; the log's is {self.fs:g} Hz): "
            "densities do not depend on it; per-sample values and rate keys use it"
        )

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
    projection: str = "fit",
    consumer: str = "WN+RW",
    fs_filter: float | None = None,
    horizon_s: float | None = None,
    band: Any = None,
    confidence: float | None = None,
    ci: str | None = "asymptotic",
    data: str = "low",
    tc: float | None = None,
    tails: Mapping[str, TailFactors] | None = None,
) -> ImuNoise:
    """Gather N, K, sigma2, B and the Gauss-Markov numbers per sensor and axis in SI (see
    :class:`ImuNoise` and the module docstring for ``projection``).

    Parameters
    ----------
    projection : {"bound", "plain", "fit"}
    consumer : str
        The consumer's noise model or format (:func:`~engine.formats.projection.consumer_of`).
    fs_filter, horizon_s, band, confidence, ci, data, tc
        Passed to :func:`~engine.formats.projection.project`; ``tails`` per channel (its
        ``tails``; a channel without one has none). ``fs_filter`` is also the
        consumer's rate of the per-sample values (``sigma2``; :attr:`ImuNoise.rate`).

    Raises
    ------
    ExportError
        As :func:`~engine.formats.kalibr.kalibr_imu` or
        :func:`~engine.formats.projection.project`, or a bad ``inflate`` or ``projection``.
    """
    f = check_inflate(inflate)
    if projection not in PROJECTIONS:
        raise ExportError(f"projection must be one of {', '.join(PROJECTIONS)}, got {projection!r}")
    if projection == "fit":
        return _fit_noise(fits, units, f, source, fmt, allow_partial, fs_filter, consumer)
    cons = consumer_of(consumer)
    if not fits:
        raise ExportError("no fitted channel to export")
    fss = {ch: r.fs for ch, r in fits.items()}
    fs0 = next(iter(fss.values()))
    if any(not math.isclose(v, fs0, rel_tol=1e-9) for v in fss.values()):
        raise ExportError(
            f"the channels have different sampling frequencies {fss}: the filter files take "
            "one rate"
        )
    vals: dict[str, dict[str, dict[str, float]]] = {}
    projs: dict[str, Projection] = {}
    warnings: list[str] = []
    chan_of: dict[tuple[str, str], str] = {}
    fs_rate = None if fs_filter is None else float(fs_filter)
    for ch, res in fits.items():
        unit = (units or {}).get(ch, res.wv.unit) or ""
        kind, f_si = si_factor(unit, ch)
        ax = channel_axis(ch)
        if (kind, ax) in chan_of:
            raise ExportError(
                f"two {kind} channels map to axis {ax!r} ({chan_of[(kind, ax)]}, {ch}): "
                "export one of them"
            )
        chan_of[(kind, ax)] = ch
        p = project(
            res,
            cons,
            fs_filter=fs_filter,
            horizon_s=horizon_s,
            band=band,
            confidence=confidence,
            bound=projection == "bound",
            channel=ch,
            unit=unit,
            ci=ci,
            data=data,
            tc=tc,
            tails=(tails or {}).get(ch),
        )
        projs[ch] = p
        warnings += p.warnings
        if p.misfit:
            warnings.append(p.misfit)
        d = vals.setdefault(kind, {})
        n = p.value("N")
        d.setdefault("N", {})[ax] = n * f
        d.setdefault("sigma2", {})[ax] = n * n * (fs_rate or res.fs) * f * f
        if "K" in p.params:
            d.setdefault("K", {})[ax] = p.value("K") * f
        if "T_c" in p.params:
            tcp, sb = p.value("T_c"), p.value("sigma_b")
            d.setdefault("T_c", {})[ax] = tcp
            d.setdefault("sigma_gm", {})[ax] = sb * f
            d.setdefault("sqrt(q)", {})[ax] = math.sqrt(2.0 / tcp) * sb * f
        rows = datasheet_rows(res.model, res.fs, unit, channel=ch, n_levels=res.wv.n_levels)
        d.setdefault("B", {})[ax] = (
            _row(rows, "model", "bias instability (Allan floor, SI)", "B") * f
        )
    _both_sensors(vals, fits, allow_partial, consumer)
    models = sorted({r.model.spec() for r in fits.values()})
    p0 = next(iter(projs.values()))
    what = (
        "projected onto the consumer's noise model by the rule and over-bounded "
        "(engine.formats.projection; --projection plain: the rule alone, fit: the fit's own terms)"
        if projection == "bound"
        else "projected onto the consumer's noise model by the rule, not bounded "
        "(--projection plain)"
    )
    header = [
        f"{fmt or 'IMU noise'} from a GMWM fit (engine.export, gmwm export)",
        f"source: {source or 'in-memory fits'}; channels: {', '.join(fits)}; "
        f"model(s): {'; '.join(models)}; log rate {fs0:g} Hz",
        f"consumer model {cons}, filter rate {p0.fs_filter:g} Hz: {what}",
        "rule: an AR1/GM faster than the filter step is white noise (its WN equivalent joins "
        "N); slower GM, RW and drift form the consumer's bias; file values are the max over "
        "axes where the consumer takes one number",
    ]
    for p in projs.values():
        header += p.header_lines()
    header.append(
        f"inflate = {f!r}: every noise value below is the projected value x {f!r} "
        "(variances x inflate^2; times and rates unchanged)"
    )
    out = ImuNoise(vals, float(fs0), f, header, warnings, projs, fs_rate)
    header.insert(3, out.rate_line())
    for w in dict.fromkeys(w for p in projs.values() for w in p.warnings if "filter rate" in w):
        _warnings.warn(w, UserWarning, stacklevel=3)
    return out


def _both_sensors(
    kinds: Collection[str], fits: Mapping[str, GMWMResult], allow_partial: bool, consumer: str
) -> None:
    """Refuse a file of one sensor (``kinds``: the sensors the fits give) unless
    ``allow_partial`` or the format's record says its writer writes a partial file
    (:attr:`~engine.formats.Format.partial`); the message offers ``allow_partial`` only where
    it applies: not for a format whose record does not take it
    (:meth:`~engine.formats.Format.takes`; ``consumer`` a format or a consumer model name).

    Raises
    ------
    ExportError
        Fewer than the two sensors (gyroscope and accelerometer) without ``allow_partial``.
    """
    f = FORMATS.get(consumer.strip().lower())
    if len(kinds) >= 2 or allow_partial or (f is not None and f.partial):
        return
    hint = (
        ", or allow a partial file (allow_partial=True)"
        if f is None or f.takes("allow_partial")
        else f" (the {f.name} format takes no partial file)"
    )
    raise ExportError(
        f"the filter file needs gyroscope and accelerometer noise; the fits give only "
        f"{' and '.join(sorted(kinds))} ({', '.join(fits)}). Add the other channels{hint}"
    )


def _fit_noise(
    fits: Mapping[str, GMWMResult],
    units: Mapping[str, str] | None,
    f: float,
    source: str,
    fmt: str,
    allow_partial: bool,
    fs_filter: float | None = None,
    consumer: str = "WN+RW",
) -> ImuNoise:
    """``projection="fit"``: N and K as :func:`~engine.formats.kalibr.kalibr_imu` extracts
    them (K from the GM driving noise when a model has no RW, with a warning), the most
    persistent GM term's numbers."""
    kal = kalibr_imu(fits, units=units, source=source, allow_partial=True)
    _both_sensors({k.partition("_")[0] for k in kal.per_axis}, fits, allow_partial, consumer)
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
        wn = [lab for lab, p in zip(labels, procs, strict=True) if p.code == WN.code][0]
        rate = res.fs if fs_filter is None else float(fs_filter)  # N^2 x the consumer's rate
        d.setdefault("sigma2", {})[ax] = (
            res.params[f"{wn}.sigma2"] * f_si**2 * f * f * rate / res.fs
        )
        d.setdefault("B", {})[ax] = (
            _row(rows, "model", "bias instability (Allan floor, SI)", "B") * f
        )
        gm = [lab for lab, p in zip(labels, procs, strict=True) if p.nonlinear]
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
        "projection fit: the fit's own terms converted one by one (no projection, no bound)",
        f"inflate = {f!r}: every noise value below is the fitted value x {f!r} "
        "(variances x inflate^2; times and rates unchanged)",
    ]
    out = ImuNoise(vals, kal.update_rate, f, header, list(kal.warnings), fs_filter=fs_filter)
    header.insert(3, out.rate_line())
    return out


def noise_for(
    fits: Mapping[str, GMWMResult],
    fmt: str,
    options: ExportOptions,
    allow_partial: bool = False,
    consumer: str = "WN+RW",
    *,
    tc: float | None = None,
) -> ImuNoise:
    """:func:`imu_noise` of a writer's options (its projection, bound, rate, inflate, units,
    source and tail factors); with :attr:`~ExportOptions.fleet` (the units beside ``fits``),
    the fleet's :func:`fleet_noise`. ``tc`` fixes the Gauss-Markov bias's correlation time (s)."""
    o = options

    def one(unit_fits: Mapping[str, GMWMResult], source: str, tails: Any) -> ImuNoise:
        return imu_noise(
            unit_fits,
            units=o.units,
            inflate=o.inflate,
            source=source,
            fmt=fmt,
            allow_partial=allow_partial,
            projection=o.projection,
            consumer=consumer,
            fs_filter=o.filter_rate,
            horizon_s=o.horizon_s,
            band=o.band,
            confidence=o.confidence,
            ci=o.ci,
            data=o.data,
            tc=tc,
            tails=tails,
        )

    nz = one(fits, o.source, o.tail_factors)
    if not o.fleet:
        return nz
    units = [(o.source or "unit 1", nz)]
    units += [(u.source, one(u.fits, u.source, u.tails)) for u in o.fleet]
    return fleet_noise(units, fmt)


def fleet_noise(units: Sequence[tuple[str, ImuNoise]], fmt: str = "") -> ImuNoise:
    """The fleet file's numbers: per sensor and axis the largest N and K (and per-sample
    ``sigma2``, Allan floor ``B``) over the units' own bounded numbers.

    A WN+RW (or white-noise) file's WV grows with each of N and K, so the fleet file's WV is
    at least every unit's file's, hence at least every unit's fitted WV and empirical lower
    limit (times its tail factors) over the band: no unit is exported overconfident. A unit
    quieter than the largest gets a cautious file (docs/filters.md, "One file for a fleet").

    Parameters
    ----------
    units : sequence of (source, ImuNoise)
        Each unit's :func:`imu_noise` (same consumer, channels and options).
    fmt : str
        The format's name for messages.

    Which formats can be written for a fleet is their record's
    (:attr:`engine.formats.Format.fleet_file`, checked by :func:`engine.formats.export`): the
    units' numbers here are WN+RW or white noise.

    Raises
    ------
    ExportError
        A unit without an axis of the first.
    """
    (src0, nz0), rest = units[0], units[1:]
    vals: dict[str, dict[str, dict[str, float]]] = {}
    lines: list[str] = []
    for kind, qs in nz0.values.items():
        for q, axes in qs.items():
            for ax, v0 in axes.items():
                got = [(v0, src0)]
                for src, nz in rest:
                    v = nz.values.get(kind, {}).get(q, {}).get(ax)
                    if v is None:
                        raise ExportError(
                            f"fleet unit {src}: no {kind} axis {ax} (the first unit, {src0}, "
                            "has it): give every unit the same channels"
                        )
                    got.append((v, src))
                top, who = max(got)
                vals.setdefault(kind, {}).setdefault(q, {})[ax] = top
                if q in ("N", "K") and math.isfinite(top):
                    low = min(v for v, _ in got)
                    lines.append(
                        f"fleet {kind} {q} {ax}: {top:.4g} from {who} (units {low:.4g} .. "
                        f"{top:.4g}, x{top / low:.2f})"
                        if low > 0
                        else f"fleet {kind} {q} {ax}: {top:.4g} from {who}"
                    )
    names = [src for src, _ in units]
    header = [
        nz0.header[0] + f"; a fleet file of {len(units)} units",
        f"fleet file: per axis the largest N and K of the {len(units)} units' own exports "
        f"({', '.join(names)}), so its WV is at least each unit's own file's and bounds what "
        "each of them bounds: no unit is overconfident, a quieter unit is cautious "
        "(docs/filters.md, One file for a fleet)",
        *lines,
        f"the lines below are the first unit's export ({src0}); each unit's is in its own file",
        *nz0.header[1:],
    ]
    warnings = list(nz0.warnings) + [f"{src}: {w}" for src, nz in rest for w in nz.warnings]
    return ImuNoise(vals, nz0.fs, nz0.inflate, header, warnings, nz0.projections, nz0.fs_filter)
