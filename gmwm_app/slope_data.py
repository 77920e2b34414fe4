"""The slope method (Allan-variance slopes) beside GMWM, without widgets: read each
process off its region of the Allan deviation, the automatic read-off, GMWM on the same WV,
and the table, lines and implied curves the "Slope method" tab draws (tested without a
browser; worker-thread safe).
"""

from __future__ import annotations

import json
import logging
import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import engine as eg
from engine.fit.estimate import MethodEstimate, from_gmwm
from engine.teaching import SLOPES, avsm, avsm_auto, gmwm_spec
from engine.wv.allan import AllanVariance

from .state import AppState, demo_path, format_value

log = logging.getLogger(__name__)

__all__ = [
    "SlopeResult",
    "CODE_ORDER",
    "REGION_COLORS",
    "TABLE_COLUMNS",
    "METHODS",
    "MIN_POINTS",
    "check_regions",
    "compute_slope",
    "comparison_values",
    "comparison_rows",
    "implied_adev_curves",
    "slope_line_data",
    "truth_model",
    "regions_text",
]

#: Rows of the comparison table by Allan-deviation slope: QN, WN, the bias-like terms (the
#: floor BI, then GM and AR1, which have no single slope), RW, DR.
CODE_ORDER = tuple(
    sorted(["BI", *eg.models.PROCESS_TYPES], key=lambda c: SLOPES.get(c, 0.0))  # stable: BI first
)
#: Colour of each slope-method term's region (and of its slope line): the process's own colour,
#: orange for the bias-instability floor.
REGION_COLORS = {c: eg.models.PROCESS_TYPES[c].color if c != "BI" else "#FF7F0E" for c in SLOPES}

#: Methods in the table and on the plot: column name -> (MethodEstimate.method, colour, dash).
METHODS: dict[str, tuple[str, str, str]] = {
    "AVSM": ("AVSM", "#D62728", "dashed"),
    "ROS auto": ("AVSM-auto", "#E69F00", "dotted"),
    "GMWM": ("GMWM", "#1F4E8C", "solid"),
}
TABLE_COLUMNS = ("process", "quantity", "AVSM", "ROS auto", "GMWM", "truth", "unit")

#: Averaging times a region must hold (one point fixes a line, two show whether it fits).
MIN_POINTS = 2
_GRID_PER_OCTAVE = 8


@dataclass
class SlopeResult:
    """Everything the tab shows for one WV and one set of regions.

    Attributes
    ----------
    av : AllanVariance or None
        The octave Allan variance of the (classical) WV.
    estimates : dict
        ``"AVSM"``, ``"ROS auto"``, ``"GMWM"`` -> :class:`~engine.fit.estimate.MethodEstimate`
        (missing when the method could not run; the reason is in ``messages``).
    truth : Model or None
        The true model of simulated data.
    regions : dict
        The regions that were used, ``{code: (tau_lo_s, tau_hi_s)}``.
    gmwm_spec : str
        The model fitted by GMWM (``""`` when no region is set).
    messages : list of str
        What could not be done, in words (bad regions, a fit that failed ...).
    """

    av: AllanVariance | None
    estimates: dict[str, MethodEstimate] = field(default_factory=dict)
    truth: eg.Model | None = None
    regions: dict[str, tuple[float, float]] = field(default_factory=dict)
    gmwm_spec: str = ""
    messages: list[str] = field(default_factory=list)


def check_regions(
    av: AllanVariance, regions: Mapping[str, tuple[float, float]], min_points: int = MIN_POINTS
) -> tuple[dict[str, tuple[float, float]], list[str]]:
    """Split the regions into usable ones and messages about the others.

    Parameters
    ----------
    av : AllanVariance
        The Allan variance the regions are drawn on.
    regions : mapping
        ``{code: (tau_lo_s, tau_hi_s)}``, averaging times in seconds.
    min_points : int
        Averaging times a region must hold.

    Returns
    -------
    good : dict
        The usable regions.
    messages : list of str
        One sentence per unusable region: what is wrong and what to do.
    """
    good: dict[str, tuple[float, float]] = {}
    msgs: list[str] = []
    tau = av.tau_s
    for code, (lo, hi) in regions.items():
        if code not in REGION_COLORS:
            msgs.append(f"unknown process {code!r} (use QN, WN, BI, RW or DR)")
            continue
        if not (math.isfinite(lo) and lo >= 0 and hi >= lo):
            msgs.append(
                f"the {code} region ({lo:g} to {hi:g} s) is not an interval of averaging times"
            )
            continue
        k = int(np.sum((tau >= lo * (1 - 1e-9)) & (tau <= hi * (1 + 1e-9))))
        if k == 0:
            msgs.append(
                f"the {code} region ({lo:.3g} to {hi:.3g} s) holds no averaging time "
                f"of this log (it has {tau[0]:.3g} to {tau[-1]:.3g} s): drag it over "
                "the points"
            )
        elif k < min_points:
            msgs.append(
                f"the {code} region ({lo:.3g} to {hi:.3g} s) holds {k} averaging "
                f"time; drag over at least {min_points} points to see a slope"
            )
        else:
            good[code] = (float(lo), float(hi))
    return good, msgs


def compute_slope(
    wv: eg.WaveletVariance | None,
    regions: Mapping[str, tuple[float, float]],
    truth: eg.Model | None = None,
    *,
    gmwm: Callable[[eg.WaveletVariance, str], MethodEstimate] | None = None,
    min_points: int = MIN_POINTS,
) -> SlopeResult:
    """The slope method, its automatic read-off and GMWM on one WV (pure; worker-thread safe).

    Parameters
    ----------
    wv : WaveletVariance or None
        The session's WV (a robust WV is replaced by its classical one: the Allan variance
        is the classical estimator).
    regions : mapping
        ``{code: (tau_lo_s, tau_hi_s)}`` with codes among QN, WN, BI, RW, DR.
    truth : Model, optional
        The true model (simulated data).
    gmwm : callable, optional
        ``gmwm(wv, spec) -> MethodEstimate`` (a cache); default ``from_gmwm(fit_gmwm(wv, spec))``.
    min_points : int
        Averaging times each region must hold.

    Returns
    -------
    SlopeResult
        Never raises for bad regions or failed fits: they become ``messages``.
    """
    if wv is None:
        return SlopeResult(None, truth=truth, messages=["load a log first"])
    if wv.robust:
        if wv.classical is None:
            return SlopeResult(
                None,
                truth=truth,
                messages=[
                    "this channel has a robust WV only; the Allan variance needs the classical one"
                ],
            )
        wv = wv.classical
    if wv.n_levels < 2:
        return SlopeResult(
            None,
            truth=truth,
            messages=["the log is too short for an Allan deviation plot (fewer than 2 levels)"],
        )
    av = AllanVariance.from_wv(wv)
    out = SlopeResult(av, truth=truth)
    good, msgs = check_regions(av, regions, min_points)
    out.regions = good
    out.messages += msgs
    if good:
        try:
            out.estimates["AVSM"] = avsm(av, good)
        except ValueError as e:
            out.messages.append(f"slope method: {e}")
    elif not regions:
        out.messages.append(
            "choose a process and drag over the points of the plot to set its region"
        )
    try:
        out.estimates["ROS auto"] = avsm_auto(av)
    except ValueError as e:
        out.messages.append(f"automatic read-off: {e}")
    out.gmwm_spec = gmwm_spec(list(good))
    if out.gmwm_spec:
        try:
            fit = gmwm or (lambda w, s: from_gmwm(eg.fit_gmwm(w, s)))
            out.estimates["GMWM"] = fit(wv, out.gmwm_spec)
        except (ValueError, ArithmeticError) as e:  # ModelError / FitError are ValueErrors
            out.messages.append(f"GMWM could not fit {out.gmwm_spec}: {e}")
    return out


def _sort_key(label: str) -> int:
    code = label.split("_")[0]
    return CODE_ORDER.index(code) if code in CODE_ORDER else len(CODE_ORDER)


def comparison_values(
    estimates: Mapping[str, MethodEstimate | None],
    truth: eg.Model | None,
    fs: float,
    unit: str = "",
) -> list[dict[str, Any]]:
    """Datasheet quantities of each method and of the truth, side by side (numbers).

    Parameters
    ----------
    estimates : mapping
        Column name (``"AVSM"``, ``"ROS auto"``, ``"GMWM"``) -> estimate or None.
    truth : Model or None
        The true model (every value set).
    fs : float
        Sampling frequency (Hz), for the datasheet conversions.
    unit : str
        Signal unit.

    Returns
    -------
    list of dict
        ``{"process", "quantity", "unit", <column>: float or None ...}``, one row per
        datasheet quantity (``engine.units.datasheet``: N, Q, K, R, GM correlation time ...;
        the slope method's bias instability B), in the order QN, WN, BI, GM, RW, DR.
    """
    rows: dict[tuple[str, str, str], dict[str, Any]] = {}
    sources: list[tuple[str, list[dict[str, Any]]]] = []
    for col in METHODS:
        e = estimates.get(col)
        if e is not None:
            sources.append((col, e.datasheet()))
    if truth is not None and len(truth) and truth.is_set:
        sources.append(("truth", eg.units.datasheet(truth, fs, unit)))
    for col, ds in sources:
        for r in ds:
            key = (r["label"], r["quantity"], r["unit"])  # native and display rows share names
            row = rows.setdefault(
                key,
                {
                    "process": r["label"],
                    "quantity": r["quantity"],
                    "unit": r["unit"],
                    **{c: None for c in METHODS},
                    "truth": None,
                },
            )
            row[col] = float(r["value"])
    order = sorted(rows, key=lambda k: _sort_key(k[0]))  # stable: datasheet order within
    return [rows[k] for k in order]


def comparison_rows(values: list[dict[str, Any]]) -> dict[str, list[str]]:
    """The table's columns (strings) from :func:`comparison_values`."""

    def fmt(v: Any) -> str:
        return "" if v is None else format_value(float(v))

    out: dict[str, list[str]] = {c: [] for c in TABLE_COLUMNS}
    for r in values:
        out["process"].append(r["process"])
        out["quantity"].append(r["quantity"])
        out["unit"].append(str(r["unit"]).replace("^2", "²"))
        for c in (*METHODS, "truth"):
            out[c].append(fmt(r[c]))
    return out


def _grid(av: AllanVariance) -> np.ndarray:
    """Averaging times (samples) of the smooth curves: the measured span, 8 per octave."""
    lo, hi = math.log2(float(av.tau_samples[0])), math.log2(float(av.tau_samples[-1]))
    k = max(int(round((hi - lo) * _GRID_PER_OCTAVE)) + 1, 2)
    return 2.0 ** np.linspace(lo, hi, k)


def implied_adev_curves(result: SlopeResult) -> dict[str, dict[str, np.ndarray]]:
    """Model-implied Allan deviation of each method (and the truth) over the measured span.

    ``ADEV(m) = sqrt(2 nu2(2m))`` with ``nu2`` the implied Haar WV at scale ``2m`` samples
    (``docs/conventions.md``); the slope method's bias-instability floor adds ``(0.664 B)^2``
    to the AVAR.

    Returns
    -------
    dict
        Column name (``"AVSM"``, ``"ROS auto"``, ``"GMWM"``, ``"truth"``) -> ``{"tau_s",
        "adev"}`` (empty arrays when that method has no estimate).
    """
    empty = {"tau_s": np.zeros(0), "adev": np.zeros(0)}
    names = (*METHODS, "truth")
    if result.av is None:
        return {c: dict(empty) for c in names}
    av = result.av
    m = _grid(av)
    tau_s = m / av.fs
    out: dict[str, dict[str, np.ndarray]] = {}
    for col in METHODS:
        e = result.estimates.get(col)
        if e is None:
            out[col] = dict(empty)
            continue
        nu = np.asarray(e.implied_at(2.0 * m), float)
        out[col] = {"tau_s": tau_s, "adev": _pos_sqrt(2.0 * nu)}
    t = result.truth
    if t is not None and len(t) and t.is_set:
        out["truth"] = {"tau_s": tau_s, "adev": _pos_sqrt(2.0 * t.wv(2.0 * m, av.fs))}
    else:
        out["truth"] = dict(empty)
    return out


def _pos_sqrt(a: np.ndarray) -> np.ndarray:
    a = np.asarray(a, float)
    return np.where(a > 0, np.sqrt(np.where(a > 0, a, 1.0)), np.nan)


def slope_line_data(result: SlopeResult) -> dict[str, list[Any]]:
    """The slope method's fixed-slope lines (for a ``multi_line``) and where they are read.

    Each line ``log10 ADEV = intercept + slope log10 tau`` is drawn over its region, extended
    to the averaging time where the datasheet value is read (1 s for N, 3 s for K, ...).

    Returns
    -------
    dict
        ``xs``, ``ys`` (lists of 2-point lists), ``color``, ``code``, and ``read_tau``,
        ``read_adev`` (the reading point; NaN for the bias-instability floor).
    """
    out: dict[str, list[Any]] = {
        "xs": [],
        "ys": [],
        "color": [],
        "code": [],
        "read_tau": [],
        "read_adev": [],
    }
    e = result.estimates.get("AVSM")
    if e is None:
        return out
    for code, ln in e.details.get("lines", {}).items():
        lo, hi = float(ln["tau_lo"]), float(ln["tau_hi"])
        rt = ln.get("read_tau_s")
        if rt is not None:
            lo, hi = min(lo, rt), max(hi, rt)
        lo, hi = lo / 1.25, hi * 1.25
        xs = [lo, hi]
        ys = [10.0 ** (ln["intercept"] + ln["slope"] * math.log10(x)) for x in xs]
        out["xs"].append(xs)
        out["ys"].append(ys)
        out["color"].append(REGION_COLORS.get(code, "#555555"))
        out["code"].append(code)
        out["read_tau"].append(float(rt) if rt is not None else math.nan)
        out["read_adev"].append(
            10.0 ** (ln["intercept"] + ln["slope"] * math.log10(rt)) if rt is not None else math.nan
        )
    return out


def _demo_truth_path() -> Any:
    p = demo_path()
    return p.with_name(f"{p.stem}_truth.json")


def truth_model(state: AppState) -> eg.Model | None:
    """The true model of the session's channel when the data are simulated, else None.

    Teaching scenarios carry it in the log's ``meta["truth"]``; the demo log's is in
    ``<demo>_truth.json`` beside it. None when the sampling frequency was changed by the user
    (per-sample values would no longer be the truth) or the channel has no known truth.
    """
    lg = state.log
    if lg is None or not state.channel:
        return None
    if state.fs and lg.fs and abs(float(state.fs) - float(lg.fs)) > 1e-9 * float(lg.fs):
        return None
    spec = (lg.meta or {}).get("truth", {}).get(state.channel)
    if spec is None and state.source == "demo":
        p = _demo_truth_path()
        try:
            with open(p, encoding="utf-8") as f:
                spec = json.load(f).get("models", {}).get(state.channel)
        except FileNotFoundError:  # a demo log without its truth (a simulated stand-in)
            spec = None
        except (OSError, ValueError) as e:  # no truth then; say why in the log
            log.warning("could not read the demo's truth from %s: %s", p, e)
            spec = None
    if not spec:
        return None
    try:
        m = eg.parse_model(spec)
    except ValueError as e:
        log.warning("the truth %r of channel %s is no model: %s", spec, state.channel, e)
        return None
    return m if m.is_set else None


def regions_text(result: SlopeResult) -> str:
    if result.av is None or not result.regions:
        return ""
    tau = result.av.tau_s
    parts = []
    for code, (lo, hi) in result.regions.items():
        k = int(np.sum((tau >= lo * (1 - 1e-9)) & (tau <= hi * (1 + 1e-9))))
        parts.append(f"**{code}** {lo:.3g}–{hi:.3g} s ({k} points)")
    return "Regions: " + " · ".join(parts)
