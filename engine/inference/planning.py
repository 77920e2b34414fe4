"""Plan a calibration run: how long to record for the IEEE quantities to reach a precision.

The efficient GMWM has a known asymptotic covariance for any model and any length: with the
model-implied WV covariance ``V(N)`` of a log of ``N`` samples (:func:`engine.fit.asymptotic.
wv_cov_model`) and the Jacobian ``A`` of the implied WV, the parameters' covariance is
``(A' V^-1 A)^-1`` (the GMWM paper, Corollary 1), and every IEEE quantity's interval follows
by the delta method, exactly as a fit's own table (:func:`engine.fit.ieee.ieee_table`) makes
it. :func:`plan_run` evaluates that table on a grid of lengths for a model with values (no
data is simulated), and finds the shortest length at which each target holds. The guide
``docs/planning.md`` compares the plan with Monte Carlo and with the rules of thumb.
"""

from __future__ import annotations

import math
import re
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from statistics import NormalDist
from typing import Any

import numpy as np

from ..fit.asymptotic import free_params, inverse_cov, param_cov, wv_cov_model
from ..fit.ieee import IEEE_KEYS, IeeeTable, ieee_table, white_share
from ..fit.result import FitError
from ..models import Model, Process, parse_model
from ..units import allan_floor
from ..wv import WaveletVariance
from ..wv.classical import default_levels

__all__ = ["PlanTarget", "RunPlan", "drift_at_zero", "parse_targets", "plan_run", "plan_precision"]

#: Quantities a target may name, with the words a user may write for them.
_ALIASES: dict[str, str] = {
    "n": "N",
    "arw": "N",
    "vrw": "N",
    "wn": "N",
    "b": "B",
    "bi": "B",
    "adev_min": "ADEV_min",
    "bi_min": "ADEV_min",
    "k": "K",
    "rrw": "K",
    "rw": "K",
    "q": "Q",
    "qn": "Q",
    "r": "R",
    "ramp": "R",
    "dr": "R",
}
#: The plan's asymptotic covariance holds from this many correlation times of the slowest
#: GM/AR1 term (tests/benchmarks/plan_span_mc.py, docs/planning.md: below it the realised spread
#: of the estimates exceeds the plan's, 1.45x at 10 correlation times; from 50 on it equals it).
#: :func:`plan_run` plans no target shorter than that.
SPAN_GM = 50.0

#: The bias instability's asymptotic interval holds from a log this many times the averaging
#: time of the model's Allan floor (tests/benchmarks/plan_b_scan.py, docs/planning.md: at the 19
#: times that the asymptotics alone give for "B within 30 %", the few-degree-of-freedom WV
#: levels at and above the floor make the fitted GM and random walk spread 1.22-1.70x the plan's
#: sd of log B; at 40 times, 0.99-1.08x on four models, one not tuned on).
#: :func:`plan_run` plans no B or ADEV_min target shorter.
SPAN_B = 40.0
#: The quantities read off the Allan floor, to which :data:`SPAN_B` applies.
_FLOOR_KEYS = ("B", "ADEV_min")

#: The rate ramp's asymptotic interval holds once a fit of the log puts the drift at 0 (its
#: WV coefficient ``omega^2``, about normal with sd ``2 s omega^2`` for the plan's sd ``s`` of
#: ``log R_hat``, on its boundary) in at most this share of logs: ``Phi(-1 / (2 s))`` at most 1 %,
#: so ``s <= 0.215`` (R within 52 % at 95 %). Shorter, the share at 0 and the spread are not the
#: plan's (tests/benchmarks/plan_drift_scan.py, docs/planning.md: 11.5 % of WN+DR fits at 0 where
#: the plan said R within [0.34, 2.97] R). :func:`plan_run` plans no R target shorter.
DRIFT_AT_ZERO = 0.01

#: The quantities planned for: the model's own (a plan has no data, so no ``ADEV_data``).
_PLANNED = ("N", "B", "ADEV_min", "K", "Q", "R")


@dataclass(frozen=True)
class PlanTarget:
    """A precision target: the ``level`` interval of ``key`` within ``rel`` of its value.

    Attributes
    ----------
    key : str
        An IEEE key (:data:`engine.fit.ieee.IEEE_KEYS`): ``N``, ``B``, ``ADEV_min``, ``K``,
        ``Q`` or ``R``.
    rel : float
        Relative half-width, e.g. 0.1 for "within 10 %".
    """

    key: str
    rel: float

    def __str__(self) -> str:
        return f"{self.key} within {100 * self.rel:g} %"


def parse_targets(text: str) -> tuple[PlanTarget, ...]:
    """Targets from ``"K within 10 %, N within 2 %, B within 20 %"``.

    Each item is ``QUANTITY within P %`` (or ``QUANTITY P%`` / ``QUANTITY=P%``), the quantity an
    IEEE key or a datasheet word (``arw``, ``vrw``, ``bi``, ``rrw``, ``bi_min`` ...).

    Raises
    ------
    ValueError
        An item that is not of that form, an unknown quantity or a percentage not in (0, 100).

    Examples
    --------
    >>> [str(t) for t in parse_targets("K within 10 %, arw 2%")]
    ['K within 10 %', 'N within 2 %']
    """
    out: list[PlanTarget] = []
    for item in (s.strip() for s in text.split(",")):
        if not item:
            continue
        m = re.fullmatch(r"([A-Za-z_]+)\s*(?:within|=|:)?\s*([0-9.eE+-]+)\s*%", item)
        if m is None:
            raise ValueError(
                f"target {item!r} is not of the form 'QUANTITY within P %' (e.g. 'K within 10 %')"
            )
        word, pct = m.group(1), m.group(2)
        key = _ALIASES.get(word.lower(), word if word in IEEE_KEYS else "")
        if key not in _PLANNED:
            raise ValueError(
                f"target {item!r}: unknown quantity {word!r}; use one of N (arw/vrw), B (bi), "
                "ADEV_min (bi_min), K (rrw), Q, R"
            )
        try:
            rel = float(pct) / 100.0
        except ValueError:
            raise ValueError(f"target {item!r}: {pct!r} is not a percentage") from None
        if not 0.0 < rel < 1.0:
            raise ValueError(f"target {item!r}: the percentage must be in (0, 100)")
        if any(t.key == key for t in out):
            raise ValueError(f"target {item!r}: {key} has a target already")
        out.append(PlanTarget(key, rel))
    return tuple(out)


@dataclass(frozen=True)
class _PlannedFit:
    """What :func:`engine.fit.ieee.ieee_table` reads of a fit, for a model at a length:
    the true model, the WV it implies at that length, that WV's covariance ``vmat`` and the
    efficient weights (its inverse)."""

    model: Model
    wv: WaveletVariance
    vmat: np.ndarray
    omega: np.ndarray
    at_bound: list[str] = field(default_factory=list)

    @property
    def fs(self) -> float:
        return self.wv.fs

    @property
    def param_records(self) -> list[Any]:  # pragma: no cover - not read by ieee_table
        return []


def _planned_fit(model: Model, fs: float, n: int, unit: str, levels: int | None) -> _PlannedFit:
    j = default_levels(n) if levels is None else min(levels, default_levels(n))
    tau = 2.0 ** np.arange(1, j + 1)
    nu = model.wv(tau, fs)
    # no data, so no empirical interval (ADEV_data is not planned): skip eta3's quantiles
    wv = WaveletVariance.from_arrays(nu, n=n, fs=fs, unit=unit, ci_low=nu, ci_high=nu)
    vmat = wv_cov_model(model, wv)
    return _PlannedFit(model, wv, vmat, inverse_cov(vmat))


def plan_precision(
    model: Model | str,
    fs: float,
    n: int,
    *,
    unit: str = "",
    level: float = 0.95,
    levels: int | None = None,
) -> IeeeTable:
    """The IEEE table an efficient GMWM fit of ``model`` on ``n`` samples is expected to give.

    Values are the model's own; intervals are the asymptotic ``level`` intervals of the
    efficient GMWM at that length (no data is simulated).

    Parameters
    ----------
    model : Model or str
        Every value set, e.g. ``"WN(sigma2=1e-6)+RW(gamma2=1e-12)"``.
    fs : float
        Sampling frequency (Hz).
    n : int
        Log length in samples (at least 16).
    unit : str
        Signal unit (``deg/s``, ``m/s^2`` ...): gives the datasheet units.
    level : float
        Two-sided interval level.
    levels : int, optional
        Number of WV levels the fit will use (default: all, ``floor(log2(n - 1))``).
    """
    m = _valued(model)
    if n < 16:
        raise ValueError(f"a log of {n} samples is too short to plan for (at least 16)")
    pf = _planned_fit(m, float(fs), int(n), unit, levels)
    return ieee_table(pf, level=level, vmat=pf.vmat)


def _valued(model: Model | Process | str) -> Model:
    m = parse_model(model) if isinstance(model, str) else model
    if isinstance(m, Process):
        m = Model((m,))
    if not m.is_set:
        raise FitError(
            f"the model {m.spec()} has no values: give every parameter "
            "(e.g. 'WN(sigma2=1e-6)+RW(gamma2=1e-12)'), a datasheet, a fit or a pilot log"
        )
    return m


def _rel(table: IeeeTable, key: str) -> float:
    """Relative half-width of a quantity's interval (its larger side): NaN when it has none,
    or for a bias instability whose floor lies at the edge of the scales (an upper bound)."""
    q = table.get(key)
    if q is None or not (q.has_interval and q.value > 0):
        return math.nan
    if key in ("B", "ADEV_min", "ADEV_data") and "edge" in q.note:
        return math.nan
    return max(q.high / q.value - 1.0, 1.0 - q.low / q.value)


@dataclass(frozen=True)
class RunPlan:
    """How precisely a log of each length gives the IEEE quantities (:func:`plan_run`).

    Attributes
    ----------
    model : Model
        The model planned for (values set), at ``fs`` in ``unit``.
    fs : float
        Sampling frequency (Hz).
    unit : str
        Signal unit.
    level : float
        Interval level of the precisions.
    targets : tuple of PlanTarget
    lengths : ndarray of int
        Log lengths evaluated (samples), increasing.
    precision : dict of str to ndarray
        Per quantity, the relative half-width of its ``level`` interval at each length.
    required : dict of str to int or None
        Per target key, the length to record (samples): the shortest that meets it and is at
        least ``valid_from``; None when no length up to ``max_hours`` does.
    tables : tuple of IeeeTable
        The full expected table (values, intervals, datasheet units) at each length.
    asymptotic : dict of str to int or None
        Per target key, the shortest length meeting it by the asymptotic covariance alone
        (shorter than ``required`` when that is below ``valid_from``): to the sample where it
        is the length to record, to 0.5 % where a bound sets that.
    achieved : dict of str to float
        Per target key, the precision at the ``required`` length (NaN when None).
    valid_from : int
        The shortest length (samples) at which the asymptotic covariance holds:
        :data:`SPAN_GM` correlation times of the slowest GM/AR1 term (0 without one).
    valid_why : str
        What sets ``valid_from`` (``"50 correlation times of GM (20 s)"``), or "".
    floor_from : int
        The shortest length (samples) at which the asymptotic interval of B and ADEV_min
        holds: :data:`SPAN_B` times the averaging time of the model's Allan floor (0 when the
        model has no floor within ``max_hours``).
    floor_why : str
        What sets ``floor_from`` (``"40 times B's averaging time (52 min)"``), or "".
    drift_from : int
        The shortest length (samples) at which the asymptotic interval of R holds: where at
        most :data:`DRIFT_AT_ZERO` of the fits put the drift at 0 (:func:`drift_at_zero`; 0
        without a drift).
    drift_why : str
        What sets ``drift_from`` (``"where 1 % of fits put the drift at 0 (R within 52.4 %)"``),
        or "".
    boundary : dict of str to float
        Per B, ADEV_min or R target, the share of efficient fits of the ``required`` length
        expected to report no value there: no floor inside the scales (B, ADEV_min:
        :func:`no_floor_share`) or the drift at 0 (R: :func:`drift_at_zero`).
    """

    model: Model
    fs: float
    unit: str
    level: float
    targets: tuple[PlanTarget, ...]
    lengths: np.ndarray
    precision: dict[str, np.ndarray]
    required: dict[str, int | None]
    tables: tuple[IeeeTable, ...] = field(repr=False)
    asymptotic: dict[str, int | None] = field(default_factory=dict)
    achieved: dict[str, float] = field(default_factory=dict)
    valid_from: int = 0
    valid_why: str = ""
    floor_from: int = 0
    floor_why: str = ""
    drift_from: int = 0
    drift_why: str = ""
    boundary: dict[str, float] = field(default_factory=dict)

    def valid_for(self, key: str) -> tuple[int, str]:
        """The shortest length (samples) at which the asymptotic precision of ``key`` holds,
        and what sets it: the larger of ``valid_from`` and, for B and ADEV_min,
        ``floor_from``, for R ``drift_from`` ((0, "") when nothing bounds it)."""
        bounds = [(self.valid_from, self.valid_why)]
        if key in _FLOOR_KEYS:
            bounds.append((self.floor_from, self.floor_why))
        if key == "R":
            bounds.append((self.drift_from, self.drift_why))
        return max(bounds)

    @property
    def hours(self) -> np.ndarray:
        """The lengths in hours."""
        return self.lengths / self.fs / 3600.0

    @property
    def record_n(self) -> int | None:
        """The length meeting every target (samples), None when one cannot be met."""
        if not self.required:
            return None
        vals = list(self.required.values())
        return None if any(v is None for v in vals) else max(v for v in vals if v is not None)

    def table(self) -> str:
        """Readable: the targets' required lengths, then the precision at each length."""
        t0 = self.tables[-1]  # the longest tabulated
        lines = [
            f"Run plan for {self.model.spec(values=True)} at {self.fs:g} Hz"
            + (f" ({self.unit})" if self.unit else ""),
            f"  efficient GMWM, asymptotic {100 * self.level:g} % intervals",
        ]
        for t in self.targets:
            n = self.required.get(t.key)
            if n is None:
                got = f"not reached within {_hours_text(self.lengths[-1] / self.fs)}"
            else:
                p = self.achieved[t.key]
                got = f"{_hours_text(n / self.fs)} ({n} samples), +-{100 * p:.3g} % there"
            lines.append(f"  {str(t):<22} needs {got}")
            a = self.asymptotic.get(t.key)
            if n is not None and a is not None and a < n:
                lines.append(
                    f"  {'':<22} ({_hours_text(a / self.fs)} would meet it by the asymptotic "
                    f"covariance, which holds from {self.valid_for(t.key)[1]})"
                )
            if n is not None and math.isfinite(self.boundary.get(t.key, math.nan)):
                lines.append(f"  {'':<22} ({self._boundary_text(t.key)})")
        keys = [k for k in self.precision if np.isfinite(self.precision[k]).any()]
        head = "  length        " + "".join(f"{k:>11}" for k in keys)
        lines += ["", "  precision (half-width of the interval, % of the value):", head]
        for i, n in enumerate(self.lengths):
            row = "".join(_pct(self.precision[k][i]) for k in keys)
            mark = "*" if n < self.valid_from else ""
            lines.append(f"  {_hours_text(n / self.fs) + mark:<14}{row}")
        if self.valid_from > self.lengths[0]:
            lines.append(
                f"  * shorter than {_hours_text(self.valid_from / self.fs)} "
                f"({self.valid_why}): the realised spread exceeds these figures"
            )
        for own in ([k for k in keys if k in _FLOOR_KEYS], [k for k in keys if k == "R"]):
            bound, why = self.valid_for(own[0]) if own else (0, "")
            if own and bound > max(self.lengths[0], self.valid_from):
                lines.append(
                    f"  {' and '.join(own)} shorter than {_hours_text(bound / self.fs)} "
                    f"({why}): the realised spread exceeds these figures"
                )
        vals = [
            f"{k} = {q.datasheet_value:.4g} {q.datasheet_unit}"
            for k, q in t0.quantities.items()
            if k in keys
        ]
        lines += ["", "  values: " + ", ".join(vals)]
        return "\n".join(lines)

    def _boundary_text(self, key: str) -> str:
        """How many fits of the length to record report no value of ``key``."""
        what = (
            "put the drift at 0"
            if key == "R"
            else "report no floor inside the scales (B at their edge)"
        )
        share = self.boundary[key]
        pct = "under 0.1" if share < 0.001 else f"{100 * share:.2g}"
        return f"{pct} % of the fits of that length {what}"

    def sentences(self, n_log: int = 0) -> list[str]:
        """One sentence per target: the length it needs and, for a log of ``n_log`` samples
        (0: none), the precision that log gives (Markdown, the app's Plan tab).

        Parameters
        ----------
        n_log : int
            Length of the log at hand (samples).
        """
        now = (
            plan_precision(self.model, self.fs, n_log, unit=self.unit, level=self.level)
            if n_log >= 16
            else None
        )
        out = []
        for t in self.targets:
            n = self.required.get(t.key)
            a = self.asymptotic.get(t.key)
            valid, why = self.valid_for(t.key)
            if n is None:
                need = f"is not reached within {_hours_text(self.lengths[-1] / self.fs)}"
            else:
                need = f"needs {_hours_text(n / self.fs)} of log"
                if a is not None and a < n:
                    need += f" ({why}: a shorter log is too short for the plan's asymptotics)"
                if math.isfinite(self.boundary.get(t.key, math.nan)):
                    need += f"; {self._boundary_text(t.key)}"
            have = ""
            q = now.get(t.key) if now is not None else None
            if q is not None and q.has_interval and q.value > 0:
                rel = _rel(now, t.key) if now is not None else math.nan
                gives = (
                    f"+-{100 * rel:.3g} %" if rel < 9.99 else "no usable value (beyond a factor 10)"
                )
                if rel < 9.99 and n_log < valid:
                    gives += " or worse (shorter than " + why + ")"
                have = f"; this log ({_hours_text(n_log / self.fs)}) gives {gives}"
            out.append(f"**{t}** {need}{have}.")
        return out

    def to_dict(self) -> dict[str, Any]:
        """JSON-ready (``gmwm plan --json``)."""

        def num(v: float) -> float | None:
            return float(v) if math.isfinite(v) else None

        t0 = self.tables[-1]
        return {
            "model": self.model.spec(values=True),
            "fs": self.fs,
            "unit": self.unit,
            "level": self.level,
            "targets": [
                {
                    "key": t.key,
                    "within": t.rel,
                    "samples": n,
                    "hours": None if n is None else n / self.fs / 3600.0,
                    "precision": num(self.achieved.get(t.key, math.nan)),
                    "asymptotic_samples": self.asymptotic.get(t.key),
                    "valid_from_samples": self.valid_for(t.key)[0],
                    "valid_from": self.valid_for(t.key)[1],
                    "boundary_share": num(self.boundary.get(t.key, math.nan)),
                }
                for t, n in ((t, self.required.get(t.key)) for t in self.targets)
            ],
            "record_samples": self.record_n,
            "valid_from_samples": self.valid_from,
            "valid_from": self.valid_why,
            "floor_from_samples": self.floor_from,
            "floor_from": self.floor_why,
            "drift_from_samples": self.drift_from,
            "drift_from": self.drift_why,
            "lengths": [int(n) for n in self.lengths],
            "hours": [float(h) for h in self.hours],
            "precision": {k: [num(v) for v in a] for k, a in self.precision.items()},
            "values": {
                k: {
                    "value": q.value,
                    "unit": q.unit,
                    "datasheet_value": q.datasheet_value,
                    "datasheet_unit": q.datasheet_unit,
                }
                for k, q in t0.quantities.items()
            },
        }


def _pct(p: float) -> str:
    """A precision as a table cell: '-' without an interval, '>999%' when uninformative."""
    if not math.isfinite(p):
        return f"{'-':>11}"
    return f"{'>999%':>11}" if p >= 9.99 else f"{100 * p:>10.3g}%"


def _hours_text(seconds: float) -> str:
    if seconds < 120:
        return f"{seconds:.3g} s"
    if seconds < 7200:
        return f"{seconds / 60:.3g} min"
    return f"{seconds / 3600:.3g} h"


def plan_run(
    model: Model | str,
    fs: float,
    targets: str | tuple[PlanTarget, ...] = "",
    *,
    unit: str = "",
    level: float = 0.95,
    lengths: np.ndarray | list[int] | None = None,
    max_hours: float = 1000.0,
) -> RunPlan:
    """How long to record: the precision of every IEEE quantity against the log length.

    Parameters
    ----------
    model : Model or str
        The sensor's model with every value set (from a datasheet, a fit, a pilot log).
    fs : float
        Sampling frequency (Hz).
    targets : str or tuple of PlanTarget
        E.g. ``"K within 10 %, N within 2 %, B within 20 %"`` (:func:`parse_targets`).
    unit : str
        Signal unit, for the datasheet units (``deg/s``, ``m/s^2`` ...).
    level : float
        Level of the intervals the targets speak of.
    lengths : array of int, optional
        Lengths (samples) to tabulate; default a doubling grid of durations from 1 min to
        ``max_hours``.
    max_hours : float
        The longest log considered when searching a target's length.

    Returns
    -------
    RunPlan

    Examples
    --------
    A tactical-grade gyro (ARW 0.01 deg/sqrt(h), RRW 0.1 deg/h/sqrt(h)) at 200 Hz:

    >>> import engine as eg
    >>> spec = eg.inference.parse_datasheet("arw=0.01 deg/sqrt(h), rrw=0.1 deg/h/sqrt(h)")
    >>> m = spec.model(200.0, "deg/s")
    >>> p = plan_run(m, 200.0, "K within 10 %, N within 1 %", unit="deg/s")
    >>> print(f"{p.required['K'] / 200 / 3600:.2g} h; {p.required['N'] / 200 / 60:.2g} min")
    """
    m = _valued(model)
    fs = float(fs)
    if not (math.isfinite(fs) and fs > 0):
        raise ValueError(f"fs must be a positive number of Hz, got {fs}")
    tg = parse_targets(targets) if isinstance(targets, str) else tuple(targets)
    n_max = int(max_hours * 3600 * fs)
    cache: dict[int, IeeeTable] = {}

    def table(n: int) -> IeeeTable:
        if n not in cache:
            cache[n] = plan_precision(m, fs, n, unit=unit, level=level)
        return cache[n]

    longest = table(max(64, n_max))
    keys = [k for k in _PLANNED if k in longest]
    # the bias instability planned for is the model's own floor (as the longest log sees it):
    # a shorter log whose scales end before it sees another minimum (a GM's bump, or the
    # edge), which is not the quantity asked for
    floor_tau = {k: longest[k].tau_s for k in ("B", "ADEV_min") if k in longest}

    def rel(tb: IeeeTable, key: str) -> float:
        if key in floor_tau and not math.isclose(tb[key].tau_s, floor_tau[key], rel_tol=1e-6):
            return math.nan
        return _rel(tb, key)

    valid_from, valid_why = _valid_from(m, fs)
    # the model's own floor (none when even the longest log's minimum is at the scales' edge)
    at_floor = [k for k in floor_tau if "edge" not in longest[k].note]
    floor_from, floor_why = _floor_from(floor_tau[at_floor[0]] if at_floor else None, fs)
    drift_from, drift_why = 0, ""
    if "R" in keys:  # where the plan's R says at most DRIFT_AT_ZERO of the fits are at 0
        s_max = 1.0 / (2.0 * -NormalDist().inv_cdf(DRIFT_AT_ZERO))
        rel_max = math.expm1(NormalDist().inv_cdf(0.5 + level / 2) * s_max)
        found = _shortest(partial(_rel_at, table, rel, "R"), rel_max, n_max)
        if found is not None:
            drift_from = found
            drift_why = (
                f"the length at which at most {100 * DRIFT_AT_ZERO:g} % of fits put the drift at 0 "
                f"(R within {100 * rel_max:.3g} %)"
            )
    asymptotic: dict[str, int | None] = {}
    required: dict[str, int | None] = {}
    achieved: dict[str, float] = {}
    boundary: dict[str, float] = {}
    for t in tg:
        if t.key not in keys:
            raise ValueError(
                f"target {t}: the model {m.spec()} has no {t.key} "
                f"({IEEE_KEYS[t.key]}); the model's quantities: {', '.join(keys)}"
            )
        lowest = max(
            valid_from,
            floor_from if t.key in _FLOOR_KEYS else 0,
            drift_from if t.key == "R" else 0,
        )
        # to the sample where it sets the length; to 0.5 % where a bound does (said only)
        bound_meets = 64 < lowest <= n_max and _rel_at(table, rel, t.key, lowest) <= t.rel
        prec_of = partial(_rel_at, table, rel, t.key)
        a = _shortest(prec_of, t.rel, n_max, rtol=5e-3 if bound_meets else 0.0)
        if bound_meets and a is not None:
            a = min(a, lowest)
        n = None if a is None or lowest > n_max else max(a, lowest)
        asymptotic[t.key], required[t.key] = a, n
        achieved[t.key] = math.nan if n is None else rel(table(n), t.key)
        if n is not None and t.key in _FLOOR_KEYS:
            boundary[t.key] = no_floor_share(m, fs, n)
        elif n is not None and t.key == "R":
            boundary[t.key] = drift_at_zero(table(n))
    if lengths is None:
        longest_n = max([4 * n for n in required.values() if n is not None], default=0)
        top = min(n_max, max(longest_n, int(3600 * fs)))
        secs = 60.0 * 2.0 ** np.arange(0, 64)
        grid = _sorted_unique(np.round(secs[secs * fs <= top] * fs).astype(np.int64))
        grid = grid[grid >= 64] if grid.size else np.array([min(top, 64)], dtype=np.int64)
    else:
        grid = _sorted_unique(np.asarray(lengths, dtype=np.int64))
    if grid.size == 0 or grid[0] < 16:
        raise ValueError("plan_run needs lengths of at least 16 samples")
    tables = tuple(table(int(n)) for n in grid)
    precision = {k: np.array([rel(tb, k) for tb in tables]) for k in keys}
    return RunPlan(
        m,
        fs,
        unit,
        float(level),
        tg,
        grid,
        precision,
        required,
        tables,
        asymptotic,
        achieved,
        valid_from,
        valid_why,
        floor_from,
        floor_why,
        drift_from,
        drift_why,
        boundary,
    )


def _sorted_unique(a: np.ndarray) -> np.ndarray:
    """The distinct lengths of ``a``, increasing (``np.unique``, whose NumPy 2 version imports
    ``numpy.ma``, a twentieth of a second of the ``gmwm plan`` command)."""
    return np.array(sorted(set(a.tolist())), dtype=np.int64)


def _valid_from(m: Model, fs: float) -> tuple[int, str]:
    """The shortest length (samples) at which the plan's asymptotic covariance holds, and why:
    :data:`SPAN_GM` correlation times of the slowest GM/AR1 term that is not white noise at
    the sampling rate (a correlation time of a sample or more; a faster one is the white
    noise it adds, :func:`engine.fit.ieee.white_share`). Every quantity's estimate shares
    the GM's scales through the efficient fit, so the bound applies to all of them: even N,
    read off the first scales, came out 1.45x wider than planned at 10 correlation times.
    """
    _, folded = white_share(m, fs)
    tcs = []
    for lab, p in zip(m.labels, m.processes, strict=True):
        if p.nonlinear is None or lab in folded or p.linear_coef() <= 0:
            continue
        phi = p.nl_value(fs)
        if phi is not None and 0.0 < phi < 1.0:
            tcs.append((-1.0 / math.log(phi) / fs, lab))
    if not tcs:
        return 0, ""
    tc, lab = max(tcs)
    why = f"{SPAN_GM:g} correlation times of {lab} ({_hours_text(tc)})"
    return int(math.ceil(SPAN_GM * tc * fs - 1e-6)), why


def _floor_from(tau_s: float | None, fs: float) -> tuple[int, str]:
    """The shortest length (samples) at which the plan's interval of the bias instability
    holds, and why: :data:`SPAN_B` times the averaging time ``tau_s`` (s) of the model's Allan
    floor. B is read off the WV levels at and above the floor; a log of ``L`` such times holds
    about ``L / 2`` effective degrees of freedom at the floor's level, too few below
    :data:`SPAN_B` for the fitted GM and random walk to spread as the asymptotics say
    (tests/benchmarks/plan_b_scan.py, docs/planning.md)."""
    if tau_s is None or not (math.isfinite(tau_s) and tau_s > 0):
        return 0, ""
    why = f"{SPAN_B:g} times B's averaging time ({_hours_text(tau_s)})"
    return int(math.ceil(SPAN_B * tau_s * fs - 1e-6)), why


def drift_at_zero(table: IeeeTable) -> float:
    """The share of efficient fits expected to put the drift at 0, from the plan's interval of
    the rate ramp R: ``Phi(-1 / (2 s))`` with ``s`` the sd of ``log R_hat``. The fit is linear
    in ``omega^2`` (the drift's WV is ``omega^2 tau^2 / 16``), whose estimate is about normal
    with sd ``2 s omega^2`` and is held at its boundary 0 when it would be negative
    (tests/benchmarks/plan_drift_scan.py checks it against Monte Carlo). NaN without R."""
    q = table.get("R")
    if q is None or not (q.has_interval and q.value > 0 and q.high > q.value):
        return math.nan
    s = math.log(q.high / q.value) / NormalDist().inv_cdf(0.5 + table.level / 2)
    return NormalDist().cdf(-1.0 / (2.0 * s))


#: Points per octave of the Allan times on which :func:`no_floor_share` looks for each draw's
#: minimum (4: a quarter of :func:`engine.units.allan_floor`'s CPU, the same shares to 0.1 %).
_PER_OCTAVE = 4


def no_floor_share(model: Model | str, fs: float, n: int, *, draws: int = 2000) -> float:
    """The share of efficient fits of an ``n``-sample log whose Allan deviation has no minimum
    inside the scales (the fit reports their B as an upper bound at the edge).

    From the fit's asymptotic normal (``(A' V^-1 A)^-1``, :func:`engine.fit.asymptotic.
    param_cov`), drawn ``draws`` times (a fixed seed: the same plan twice gives the same
    share) in the coordinates where the GMWM is linear: each process's linear coefficient
    (a variance; ``omega^2`` for a drift), held at 0 where the draw is negative as the
    constrained fit holds it, and the non-linear parameters (a GM's beta) in their own
    unconstrained coordinates. Each draw's Allan deviation is evaluated on
    :func:`engine.units.allan_floor`'s grid and counted when its minimum is at an end. (The
    normal in the log coordinates the intervals use gives almost no such fits, and the delta
    method of a linearised edge condition 3-5 times too many: tests/benchmarks/plan_mc.py's
    counts, docs/planning.md.)

    Parameters
    ----------
    model : Model or str
        Every value set.
    fs : float
        Sampling frequency (Hz).
    n : int
        Log length (samples).
    draws : int
        Draws from the asymptotic normal (2,000: a share of 5 % to +-0.5 %).

    Returns
    -------
    float
        In [0, 1]; NaN when the model itself has no floor inside the scales of ``n`` samples.
    """
    m = _valued(model)
    pf = _planned_fit(m, float(fs), int(n), "", None)
    j = pf.wv.n_levels
    if allan_floor(m, pf.fs, j)["at_edge"]:
        return math.nan
    free = free_params(pf)
    cov = param_cov(pf, pf.vmat, free)
    u0 = np.array(
        [
            m.processes[i].params()[nm].to_unconstrained(float(getattr(m.processes[i], nm)))
            for i, nm in free
        ]
    )
    u = np.random.default_rng(0).multivariate_normal(u0, cov, size=draws, method="eigh")
    col = {key: k for k, key in enumerate(free)}
    # the Allan times of allan_floor's grid, as WV scales (tau = 2 m samples)
    tau = 2.0 * 2.0 ** np.linspace(0.0, max(j - 1, 0), max(j - 1, 0) * _PER_OCTAVE + 1)
    wv = np.zeros((draws, tau.size))
    for i, p in enumerate(m.processes):
        h0 = p.linear_coef()
        spec = p.params()
        lin = p.param_names[-1]  # the linear coefficient's parameter (Process.linear_coef)
        h = np.full(draws, h0)
        if (i, lin) in col:  # linear in the coefficient: its first-order change, clipped
            k = col[(i, lin)]
            e = 1e-6 * max(1.0, abs(u0[k]))
            up = p.with_values(**{lin: spec[lin].from_unconstrained(u0[k] + e)}).linear_coef()
            h = np.maximum(h0 + (up - h0) / e * (u[:, k] - u0[k]), 0.0)
        if p.nonlinear is None:
            wv += h[:, None] * p.basis(tau, pf.fs)[None, :]
            continue
        nl = np.full(draws, float(getattr(p, p.nonlinear)))
        if (i, p.nonlinear) in col:
            to_nl = spec[p.nonlinear].from_unconstrained
            nl = np.array([to_nl(v) for v in u[:, col[(i, p.nonlinear)]]])
        phis = np.array([p.phi_from_nl(v, pf.fs) for v in nl])
        wv += h[:, None] * p.basis_many(tau, pf.fs, phis)
    wv = np.where(np.isfinite(wv) & (wv > 0), wv, np.inf)
    at = np.argmin(wv, axis=1)
    return float(np.mean((at == 0) | (at == tau.size - 1)))


def _rel_at(
    table: Callable[[int], IeeeTable],
    rel: Callable[[IeeeTable, str], float],
    key: str,
    n: int,
) -> float:
    """The precision of ``key`` at ``n`` samples."""
    return rel(table(n), key)


def _shortest(
    prec: Callable[[int], float], rel: float, n_max: int, rtol: float = 0.0
) -> int | None:
    """The shortest length (samples) with ``prec(n) <= rel``, to the sample (``rtol`` 0) or
    to ``rtol`` of it.

    The lengths with one number of WV levels form runs ``2^(k-1) < n <= 2^k``. Within a run
    the precision falls with the length; where the log gains a level (``n = 2^k + 1``, a last
    level of two coefficients) it jumps up (K of a WN+RW gyro: 0.118 at ``2^24`` samples,
    0.149 at ``2^24 + 1``), then falls below the previous run's. So the shortest length lies
    in the first run whose end meets the target: a x4 search from 64 samples (ends of runs)
    brackets it, the run ends inside the bracket find the run, and a safeguarded regula
    falsi (Illinois) on ``log prec`` against ``log n``, from the failing end of the run
    before, closes it to one sample. (Interpolating
    across the bracket and stepping up by 2 % overshot the shortest length by up to 9 %, and
    by 45 % where the target fell just before a run's end.)
    """

    def ok(n: int) -> bool:
        p = prec(n)
        return math.isfinite(p) and p <= rel

    lo, hi = 0, 64
    while not ok(hi):
        if hi >= n_max:
            return None
        lo, hi = hi, min(4 * hi, n_max)
    if lo == 0:
        return hi
    # the first run whose end meets the target: (lo, hi] from here on
    for k in range(lo.bit_length(), (hi - 1).bit_length()):
        if lo < 2**k < hi:
            if ok(2**k):
                hi = 2**k
                break
            lo = 2**k
    lo = max(lo, 2 ** (hi - 1).bit_length() // 2)
    # lo fails and hi meets it, with one number of levels in (lo, hi]: regula falsi
    f_lo, f_hi = _log_gap(prec(lo), rel), _log_gap(prec(hi), rel)
    side, check = 0, False
    while hi - lo > max(1.0, rtol * hi):
        n = (lo + hi) // 2
        if check:  # to a tolerance: is the length rtol shorter than a new hi too short?
            n = max(hi - max(1, int(rtol * hi)), lo + 1)
        elif math.isfinite(f_lo) and math.isfinite(f_hi) and f_lo > f_hi:
            x = math.log(lo) + f_lo / (f_lo - f_hi) * (math.log(hi) - math.log(lo))
            n = min(max(int(math.ceil(math.exp(x))), lo + 1), hi - 1)
        f = _log_gap(prec(n), rel)
        check = rtol > 0 and f <= 0 and not check
        if f <= 0:
            hi, f_hi = n, f
            f_lo = f_lo / 2 if side == 1 else f_lo
            side = 1
        else:
            lo, f_lo = n, f
            f_hi = f_hi / 2 if side == -1 else f_hi
            side = -1
    return hi


def _log_gap(p: float, rel: float) -> float:
    """``log(p / rel)``: negative where the precision ``p`` meets the target ``rel``, +inf
    where it has none."""
    if not math.isfinite(p):
        return math.inf
    return math.log(p / rel) if p > 0 else -math.inf
