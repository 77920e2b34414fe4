"""Datasheet check: the manufacturer's noise model against the empirical WV (GMWM paper, sec. V).

A datasheet states a few numbers: angle (gyroscope) or velocity (accelerometer) random walk,
bias instability, rate (or acceleration) random walk, sometimes quantization. They are a model:
:class:`DatasheetSpec` (:mod:`engine.inference.datasheet_spec`, with :func:`parse_datasheet`)
holds them in SI units (converted through the one datasheet table, :mod:`engine.units`),
:func:`check_datasheet` draws its implied wavelet variance at the
empirical WV's scales and says, per scale, whether it lies inside, above or below the
empirical ``level`` interval; :func:`read_datasheet` loads a Kalibr ``imu.yaml``, a ``gmwm``
JSON report, a datasheet CSV (``gmwm export --format json | datasheet-csv``) or a saved
:meth:`DatasheetSpec.to_dict` into the same object.

The datasheet model (docs/conventions.md, "Units and datasheet conversions"), ``dt = 1/fs``, signal
unit ``u``, ``tau`` in samples:

* white noise ``WN(sigma2 = N^2 / dt)``: WV ``sigma2 / tau`` (N from ARW/VRW);
* random walk ``RW(gamma2 = K^2 dt)``: WV ``gamma2 (tau^2 + 2) / (12 tau)`` (K from RRW);
* quantization ``QN(q2 = (Q / dt)^2)``: WV ``6 q2 / tau^2``;
* bias instability B: **not a GMWM process**. It is drawn as its Allan-deviation floor, the
  constant ``AVAR = (BI_FACTOR B)^2`` with ``BI_FACTOR = 0.664`` (IEEE Std 952, flicker
  noise), i.e. the constant WV ``(0.664 B)^2 / 2`` at every scale (``nu2_j = AVAR / 2``), as
  in docs/case-studies.md (NavChip). Flicker noise reaches that floor only at averaging
  times well above its corner, and below it; the floor is therefore an upper bound of the
  flicker WV at short scales, where white noise dominates anyway. The verdict treats the
  floor like any other term: the datasheet WV is the sum of the four.

Verdicts compare the datasheet WV with the empirical interval ``[ci_low, ci_high]`` (Percival's
eta3 chi-square interval at ``level``): ``inside``, ``above`` (datasheet too pessimistic) or
``below`` (too optimistic). When the datasheet is the true model, each scale is inside with
probability about ``level`` (the eta3 interval is approximate at the longest scales).
"""

from __future__ import annotations

import csv
import io as _io
import json
import math
import os
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from .._files import read_regular
from ..io.kalibr import read_kalibr
from ..io.log import channel_axis
from ..units import SI_UNIT, ExportError, squared
from ..wv.classical import eta3_interval
from .datasheet_keys import DATASHEET_KEYS, DatasheetError
from .datasheet_keys import QUANTITY_OF as _QUANTITY
from .datasheet_keys import UNITS as _UNITS
from .datasheet_keys import canon_unit as _canon
from .datasheet_keys import convert_value as _convert
from .datasheet_spec import DatasheetSpec, parse_datasheet

if TYPE_CHECKING:  # pragma: no cover
    from ..fit import GMWMResult
    from ..wv import WaveletVariance

__all__ = [
    "DatasheetError",
    "DatasheetSpec",
    "DatasheetCheck",
    "parse_datasheet",
    "read_datasheet",
    "check_datasheet",
    "DATASHEET_KEYS",
]


# --------------------------------------------------------------------------- files
def _from_rows(rows: Sequence[Mapping[str, Any]], kind: str | None, where: str) -> DatasheetSpec:
    """First row per symbol N/K/Q/B whose unit is a unit of that symbol."""
    vals: dict[str, float] = {}
    given: dict[str, str] = {}
    kinds = set()
    for r in rows:
        sym, unit, value = r.get("symbol"), str(r.get("unit") or ""), r.get("value")
        if sym not in _UNITS or sym in vals or value in (None, ""):
            continue
        if _canon(unit) not in _UNITS[sym]:
            continue
        k, v = _convert(sym, float(value), unit, f"{where} {r.get('process', '')} {sym}")
        if kind is not None and k != kind:
            continue
        vals[sym], given[sym] = v, f"{float(value):g} {unit}"
        kinds.add(k)
    if not vals:
        raise DatasheetError(f"{where}: no datasheet value (symbols N, K, Q, B with a sensor unit)")
    return DatasheetSpec(kinds.pop(), vals, given, where)


def _pick(names: list[str], channel: str | None, where: str) -> str:
    """The channel to read: ``channel``, or the file's only one."""
    if channel is not None and not (len(names) == 1 and channel not in names):
        if channel not in names:
            raise DatasheetError(f"{where} has no channel {channel!r}; channels: {names}")
        return channel
    if len(names) != 1:
        raise DatasheetError(f"{where} has channels {names}: choose one (channel=)")
    return names[0]


def _from_kalibr(
    d: Mapping[str, Any], kind: str | None, channel: str | None, where: str
) -> DatasheetSpec:
    kinds = [k for k in SI_UNIT if f"{k}_noise_density" in d or f"{k}_random_walk" in d]
    if not kinds:
        raise DatasheetError(f"{where}: no gyroscope_* or accelerometer_* noise keys")
    if kind is None:
        if len(kinds) > 1:
            raise DatasheetError(
                f"{where} has gyroscope and accelerometer keys: choose one (kind=; the CLI "
                "and the app use the channel's unit)"
            )
        kind = kinds[0]
    if kind not in kinds:
        raise DatasheetError(f"{where} has no {kind}_* keys")
    vals, given = {}, {}
    for sym, suffix in (("N", "noise_density"), ("K", "random_walk")):
        key = f"{kind}_{suffix}"
        v = d.get(key)
        axes = d.get(f"{key}_per_axis")
        ax = channel_axis(channel) if channel else None
        if isinstance(axes, Mapping) and ax in axes:
            key, v = f"{key}_per_axis.{ax}", axes[ax]
        if v is None:
            continue
        if not isinstance(v, (int, float)) or isinstance(v, bool) or not v >= 0:
            raise DatasheetError(f"{where}: {key} = {v!r} is not a non-negative number")
        vals[sym], given[sym] = (
            float(v),
            f"{float(v):g} {_QUANTITY[sym].unit(SI_UNIT[kind])}",
        )
    return DatasheetSpec(kind, vals, given, where)


def read_datasheet(
    source: str | os.PathLike[str], *, channel: str | None = None, kind: str | None = None
) -> DatasheetSpec:
    """Read datasheet values from a file.

    Parameters
    ----------
    source : path
        A Kalibr ``imu.yaml`` (``*_noise_density`` = N, ``*_random_walk`` = K, SI), a
        ``gmwm`` JSON report (``gmwm export --format json``: the datasheet rows of a channel),
        a datasheet CSV (``--format datasheet-csv``), or a :meth:`DatasheetSpec.to_dict` JSON
        (also the ``datasheet`` entry of ``gmwm check --json``).
    channel : str, optional
        Channel of a report/CSV with several; in a Kalibr file, the axis of the ``*_per_axis``
        values (``gyro_x`` -> ``x``) when present.
    kind : {"gyroscope", "accelerometer"}, optional
        The sensor to read from a file that has both.

    Raises
    ------
    DatasheetError
        Unreadable file, unknown format, missing or bad key (the message names file and key).
    """

    p = Path(source)
    where = str(p)
    raw = read_regular(p, where, error=DatasheetError)  # no FIFO or device: engine._files
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise DatasheetError(f"datasheet file '{p}' is not UTF-8 text") from None
    suffix = p.suffix.lower()
    if suffix == ".json":
        try:
            d = json.loads(text)
        except json.JSONDecodeError as exc:
            raise DatasheetError(f"{where}: not JSON ({exc})") from exc
        if isinstance(d, Mapping) and isinstance(d.get("datasheet"), Mapping):
            d = d["datasheet"]
        if not isinstance(d, Mapping):
            raise DatasheetError(f"{where}: a JSON object is expected")
        if d.get("schema") == "gmwm-datasheet/1":
            also = d.get("also")
            if kind is not None and d.get("kind") != kind and isinstance(also, Mapping):
                d = also
            vals = d.get("values")
            if not isinstance(vals, Mapping):
                raise DatasheetError(f"{where}: key 'values' missing or not an object")
            rows: list[dict[str, Any]] = []
            for s, vu in vals.items():
                if not isinstance(vu, list) or len(vu) != 2:
                    raise DatasheetError(f"{where}: values.{s} is not [value, unit]")
                rows.append({"symbol": s, "value": vu[0], "unit": vu[1]})
            return _from_rows(rows, kind, where)
        if d.get("schema") == "gmwm-report/1":
            chans = d.get("channels")
            if not isinstance(chans, Mapping) or not chans:
                raise DatasheetError(f"{where}: key 'channels' missing or empty")
            ch = _pick(list(chans), channel, where)
            stored = chans[ch].get("datasheet") if isinstance(chans[ch], Mapping) else None
            if not isinstance(stored, list):
                raise DatasheetError(f"{where}: channels.{ch}.datasheet missing")
            return _from_rows(stored, kind, f"{where} [{ch}]")
        raise DatasheetError(
            f"{where}: unknown JSON (schema {d.get('schema')!r}); expected a gmwm report "
            "(gmwm-report/1) or a datasheet (gmwm-datasheet/1)"
        )
    if suffix == ".csv":
        rows = list(csv.DictReader(_io.StringIO(text)))
        need = {"channel", "symbol", "value", "unit"}
        if not rows or not need <= set(rows[0]):
            raise DatasheetError(f"{where}: a datasheet CSV needs columns {sorted(need)}")
        ch = _pick(list(dict.fromkeys(r["channel"] for r in rows)), channel, where)
        return _from_rows([r for r in rows if r["channel"] == ch], kind, f"{where} [{ch}]")
    if suffix in (".yaml", ".yml") or "_noise_density" in text:
        try:
            d = read_kalibr(text)
        except ExportError as exc:
            raise DatasheetError(f"{where}: {exc}") from exc
        return _from_kalibr(d, kind, channel, where)
    raise DatasheetError(
        f"{where}: unknown datasheet file (use a Kalibr .yaml, a gmwm JSON report or "
        "datasheet .json, or a datasheet .csv)"
    )


# --------------------------------------------------------------------------- the check
def _verdicts(curve: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> tuple[str, ...]:
    return tuple(
        "below" if c < a else ("above" if c > b else "inside")
        for c, a, b in zip(curve, lo, hi, strict=True)
    )


@dataclass(frozen=True, eq=False)
class DatasheetCheck:
    """A datasheet model against an empirical WV, scale by scale.

    Attributes
    ----------
    wv : WaveletVariance
        The empirical WV (its unit is the signal's).
    datasheet : DatasheetSpec
    level : float
        Interval level.
    ci_low, ci_high : ndarray, shape (J,)
        Empirical interval at ``level`` [unit^2].
    datasheet_wv : ndarray, shape (J,)
        The datasheet model's WV [unit^2].
    components : dict of str to ndarray
        Its terms (``QN``, ``WN``, ``RW``, ``BI floor``).
    verdict : tuple of str
        Per scale ``inside``, ``above`` or ``below``.
    fit_wv : ndarray or None
        The fitted GMWM model's implied WV, when a fit was given.
    fit_verdict : tuple of str or None
    fit_model : str
        The fit's model with values (``""`` without fit).
    """

    wv: WaveletVariance
    datasheet: DatasheetSpec
    level: float
    ci_low: np.ndarray
    ci_high: np.ndarray
    datasheet_wv: np.ndarray
    components: dict[str, np.ndarray]
    verdict: tuple[str, ...]
    fit_wv: np.ndarray | None = None
    fit_verdict: tuple[str, ...] | None = None
    fit_model: str = ""

    @property
    def tau_s(self) -> np.ndarray:
        """WV scales in seconds (``2^j / fs``)."""
        return np.asarray(self.wv.tau_s, float)

    @property
    def allan_tau_s(self) -> np.ndarray:
        """Allan averaging times ``T = tau / 2`` [s] of the scales."""
        return self.tau_s / 2.0

    @property
    def datasheet_adev(self) -> np.ndarray:
        """The datasheet model's Allan deviation ``sqrt(2 nu2)`` at ``T = tau/2`` [unit]."""
        return np.sqrt(2.0 * self.datasheet_wv)

    @property
    def empirical_adev(self) -> np.ndarray:
        """Empirical Allan deviation ``sqrt(2 nu2)`` [unit]."""
        return np.sqrt(2.0 * np.asarray(self.wv.variance, float))

    @property
    def ratio(self) -> np.ndarray:
        """Datasheet WV / empirical WV per scale."""
        with np.errstate(divide="ignore", invalid="ignore"):
            return self.datasheet_wv / np.asarray(self.wv.variance, float)

    def summary(self) -> dict[str, Any]:
        """Counts per verdict, the expected count outside, and the contiguous bands outside.

        Returns
        -------
        dict
            ``n_scales``, ``inside``, ``above``, ``below``, ``outside``, ``expected_outside``
            (``(1 - level) J`` if the datasheet were the true model), ``bands`` (list of
            ``{"verdict", "tau_s_from", "tau_s_to", "n_scales", "ratio_min", "ratio_max"}``),
            and ``fit_outside`` with a fit.
        """
        v = self.verdict
        bands: list[dict[str, Any]] = []
        t, r = self.tau_s, self.ratio
        i = 0
        while i < len(v):
            j = i
            while j + 1 < len(v) and v[j + 1] == v[i]:
                j += 1
            if v[i] != "inside":
                bands.append(
                    {
                        "verdict": v[i],
                        "tau_s_from": float(t[i]),
                        "tau_s_to": float(t[j]),
                        "n_scales": j - i + 1,
                        "ratio_min": float(np.min(r[i : j + 1])),
                        "ratio_max": float(np.max(r[i : j + 1])),
                    }
                )
            i = j + 1
        out: dict[str, Any] = {
            "n_scales": len(v),
            "inside": v.count("inside"),
            "above": v.count("above"),
            "below": v.count("below"),
            "outside": len(v) - v.count("inside"),
            "expected_outside": (1.0 - self.level) * len(v),
            "bands": bands,
        }
        if self.fit_verdict is not None:
            out["fit_outside"] = len(self.fit_verdict) - self.fit_verdict.count("inside")
        return out

    def text_summary(self) -> str:
        """One or two readable lines: how many scales are outside, and where."""
        s = self.summary()
        lvl = f"{100 * self.level:g} %"
        head = (
            f"datasheet model outside the empirical {lvl} interval at {s['outside']} of "
            f"{s['n_scales']} scales ({s['above']} above, {s['below']} below; "
            f"{s['expected_outside']:.2g} expected if it were the true model)"
        )
        bands = "; ".join(
            f"{b['verdict']} at tau = {b['tau_s_from']:.4g}..{b['tau_s_to']:.4g} s "
            f"(datasheet/empirical WV {b['ratio_min']:.3g}..{b['ratio_max']:.3g})"
            for b in s["bands"]
        )
        out = head + (f"\n  {bands}" if bands else "")
        if "fit_outside" in s:
            out += f"\n  GMWM fit ({self.fit_model}) outside at {s['fit_outside']} scales"
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready: the datasheet, per-scale arrays with units, verdicts and the summary."""
        u = self.wv.unit or "u"
        d: dict[str, Any] = {
            "datasheet": self.datasheet.to_dict(),
            "unit": self.wv.unit,
            "wv_unit": squared(u),
            "adev_unit": u,
            "level": float(self.level),
            "fs": float(self.wv.fs),
            "n": int(self.wv.n),
            "tau_samples": [int(x) for x in self.wv.tau_samples],
            "tau_s": [float(x) for x in self.tau_s],
            "allan_tau_s": [float(x) for x in self.allan_tau_s],
            "empirical_wv": [float(x) for x in self.wv.variance],
            "ci_low": [float(x) for x in self.ci_low],
            "ci_high": [float(x) for x in self.ci_high],
            "datasheet_wv": [float(x) for x in self.datasheet_wv],
            "components": {k: [float(x) for x in c] for k, c in self.components.items()},
            "empirical_adev": [float(x) for x in self.empirical_adev],
            "datasheet_adev": [float(x) for x in self.datasheet_adev],
            "verdict": list(self.verdict),
            "summary": self.summary(),
        }
        if self.fit_wv is not None:
            d["fit_model"] = self.fit_model
            d["fit_wv"] = [float(x) for x in self.fit_wv]
            d["fit_verdict"] = list(self.fit_verdict or ())
        return d

    def table(self) -> str:
        """Readable table with units: per scale the WVs, the interval and the verdicts."""
        u = squared(self.wv.unit or "u")
        lvl = f"{100 * self.level:g}%"
        lines = [
            f"datasheet ({self.datasheet.describe()}) vs empirical WV; N = {self.wv.n} samples, "
            f"fs = {self.wv.fs:g} Hz; WV in {u}, ADEV in {self.wv.unit or 'u'}",
            f"{'tau [s]':>10} {'WV':>11} {lvl + ' low':>11} {lvl + ' high':>11} "
            f"{'datasheet':>11} {'ADEV emp':>10} {'ADEV ds':>10}  verdict"
            + (f"  {'GMWM':>11}  fit" if self.fit_wv is not None else ""),
        ]
        emp, ds = self.empirical_adev, self.datasheet_adev
        for j in range(len(self.verdict)):
            row = (
                f"{self.tau_s[j]:>10.4g} {self.wv.variance[j]:>11.4e} {self.ci_low[j]:>11.4e} "
                f"{self.ci_high[j]:>11.4e} {self.datasheet_wv[j]:>11.4e} {emp[j]:>10.4g} "
                f"{ds[j]:>10.4g}  {self.verdict[j]:<7}"
            )
            if self.fit_wv is not None and self.fit_verdict is not None:
                row += f"  {self.fit_wv[j]:>11.4e}  {self.fit_verdict[j]}"
            lines.append(row)
        return "\n".join([*lines, self.text_summary()])


def check_datasheet(
    wv: WaveletVariance,
    datasheet: DatasheetSpec | str | Mapping[str, tuple[float, str]],
    *,
    fit: GMWMResult | None = None,
    level: float = 0.95,
) -> DatasheetCheck:
    """Compare a datasheet's noise model with an empirical WV, scale by scale.

    Parameters
    ----------
    wv : WaveletVariance
        Empirical WV of one channel; its ``unit`` must be known (gyroscope or accelerometer).
    datasheet : DatasheetSpec, str or mapping
        The values: an object, a string for :func:`parse_datasheet`, or ``{key: (value,
        unit)}`` for :meth:`DatasheetSpec.from_values`.
    fit : GMWMResult, optional
        A GMWM fit of the same WV, drawn beside the datasheet model with its own verdicts.
    level : float
        Interval level in (0, 1) (default 0.95). A classical WV's interval is recomputed
        (eta3) when its own level differs; a robust WV must already be at ``level``.

    Returns
    -------
    DatasheetCheck

    Raises
    ------
    DatasheetError
        Unknown unit, sensor kind mismatch, bad level, a fit of another WV.

    Examples
    --------
    A gyroscope simulated from its own datasheet passes at every scale; a datasheet that
    promises a third of its angle random walk (a ninth of its white noise) falls below the
    interval at every scale up to 41 s, where the random walk takes over:

    >>> import numpy as np
    >>> import engine as eg
    >>> spec = eg.inference.parse_datasheet("arw=0.3 deg/sqrt(h), rrw=3 deg/h/sqrt(h)")
    >>> x = spec.model(100.0, "rad/s").simulate(2**15, rng=np.random.default_rng(1), fs=100.0)
    >>> wv = eg.wavelet_variance(x, fs=100.0, unit="rad/s")
    >>> s = eg.check_datasheet(wv, spec).summary()
    >>> s["n_scales"], s["inside"], s["outside"]
    (14, 14, 0)
    >>> chk = eg.check_datasheet(wv, "arw=0.1 deg/sqrt(h), rrw=3 deg/h/sqrt(h)")
    >>> [(b["verdict"], b["n_scales"], b["tau_s_to"]) for b in chk.summary()["bands"]]
    [('below', 12, 40.96)]
    """
    if not 0 < level < 1:
        raise DatasheetError(f"level must be in (0, 1), got {level}")
    if not isinstance(datasheet, DatasheetSpec):
        datasheet = (
            parse_datasheet(datasheet)
            if isinstance(datasheet, str)
            else DatasheetSpec.from_values(datasheet)
        )
    datasheet = datasheet.for_unit(wv.unit)
    lo, hi = np.asarray(wv.ci_low, float), np.asarray(wv.ci_high, float)
    if not math.isclose(level, 1.0 - wv.alpha, rel_tol=0, abs_tol=1e-12):
        if wv.robust:
            raise DatasheetError(
                f"the robust WV's intervals are at {1 - wv.alpha:g}; compute it at level {level}"
            )
        lo, hi = eta3_interval(np.asarray(wv.variance, float), wv.n_coef, wv.tau_samples, 1 - level)
    tau = np.asarray(wv.tau_samples, float)
    model = datasheet.model(wv.fs, wv.unit)
    comps: dict[str, np.ndarray] = dict(model.components(tau, wv.fs)) if model is not None else {}
    if "B" in datasheet.values:
        comps["BI floor"] = np.full(tau.shape, datasheet.floor_wv(wv.unit))
    total = np.sum(list(comps.values()), axis=0) if comps else np.zeros_like(tau)
    fit_wv = fit_verdict = None
    fit_model = ""
    if fit is not None:
        fit_wv = np.asarray(fit.implied, float)
        if fit_wv.shape != tau.shape or not np.allclose(fit.wv.tau_samples, wv.tau_samples):
            raise DatasheetError(
                f"the fit has {fit_wv.size} scales, the WV {tau.size}: fit the same WV"
            )
        fit_verdict = _verdicts(fit_wv, lo, hi)
        fit_model = fit.model.spec()
    # fields in declaration order: wv, datasheet, level, interval, datasheet WV and terms,
    # verdicts, then the fit's WV, verdicts and model
    return DatasheetCheck(
        wv,
        datasheet,
        float(level),
        lo,
        hi,
        total,
        comps,
        _verdicts(total, lo, hi),
        fit_wv,
        fit_verdict,
        fit_model,
    )
