"""Monte Carlo study of the slope method, ARMAV and GMWM (the GMWM paper, Fig. 1-2, Table I).

For each sensor of Table I (a STIM-300 gyroscope and accelerometer as GMWM estimated them),
each log length T and each replicate: simulate the true model at 250 Hz, compute the Haar WV
(and from it the octave Allan variance, ``AVAR = 2 nu2``), and estimate the model by

* ``GMWM``: :func:`engine.fit_gmwm`, default weights ``diag(1/(ci_high - ci_low)^2)``;
* ``ARMAV``: :func:`engine.fit.gmwfm.fit_armav` (``f = log10``, log-space interval weights);
  optionally ``ARMAV-unweighted`` (``f = log10``, identity weights);
* ``AVSM``: :func:`engine.allan.avsm` on the regions a typical user picks
  (:func:`typical_regions`);
* optionally ``AVSM-auto``: :func:`engine.allan.avsm_auto` (WN and RW only).

Bias, SD and RMSE are reported per parameter and method in Table I's datasheet units. Every
replicate draws from its own seed ``SeedSequence([seed, sensor, T, replicate])``, so the
results do not depend on the number of worker processes.

Table I (true values; parameters converted to the engine's per-sample parameters with
:func:`from_datasheet`):

=============  =========================  ===========================
process        gyroscope (deg/s)          accelerometer (m/s^2)
=============  =========================  ===========================
QN (Q)         --                         1.79e-6 m/s
WN (sigma)     1.57e-1 deg/sqrt(h)        4.70e-2 m/s/sqrt(h)
RW (gamma)     1.34 deg/h/sqrt(h)         4.35e1 m/s/h/sqrt(h)
DR (omega)     --                         4.14e1 m/s/h^2
=============  =========================  ===========================
"""

from __future__ import annotations

import json
import math
import os
import sys
import time
from collections.abc import Iterable, Sequence
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, TextIO

import numpy as np

from .allan import AllanVariance, MethodEstimate, avsm, avsm_auto, from_gmwm
from .fit import fit_gmwm
from .fit.gmwfm import fit_armav
from .models import DR, QN, RW, WN, Model
from .units import DISPLAY, QUANTITIES, si_factor
from .units import from_datasheet as units_from_datasheet
from .units import to_datasheet as units_to_datasheet
from .wv import WaveletVariance, default_levels, wavelet_variance

__all__ = [
    "TABLE_I",
    "STUDY_FS",
    "STUDY_N",
    "METHODS",
    "from_datasheet",
    "to_datasheet",
    "table1_model",
    "typical_regions",
    "estimate_all",
    "run_slope_study",
    "StudyResult",
]

STUDY_FS = 250.0
STUDY_N = (2_500_000, 6_300_000)
METHODS = ("GMWM", "ARMAV", "ARMAV-unweighted", "AVSM", "AVSM-auto")
DEFAULT_METHODS = ("GMWM", "ARMAV", "AVSM")
_SENSOR_ID = {"gyro": 1, "accel": 2}

#: Table I of the GMWM paper: per sensor, the signal unit and (code, symbol, value, unit).
TABLE_I: dict[str, dict[str, Any]] = {
    "gyro": {
        "unit": "deg/s",
        "label": "Gyro",
        "params": (("WN", "sigma", 1.57e-1, "deg/sqrt(h)"), ("RW", "gamma", 1.34, "deg/h/sqrt(h)")),
    },
    "accel": {
        "unit": "m/s^2",
        "label": "Accel",
        "params": (
            ("QN", "Q", 1.79e-6, "m/s"),
            ("WN", "sigma", 4.70e-2, "m/s/sqrt(h)"),
            ("RW", "gamma", 4.35e1, "m/s/h/sqrt(h)"),
            ("DR", "omega", 4.14e1, "m/s/h^2"),
        ),
    },
}
_SHORT = {"ARMAV-unweighted": "ARMAV-unw"}  # plot labels
_PARAM_OF = {"QN": "QN.q2", "WN": "WN.sigma2", "RW": "RW.gamma2", "DR": "DR.omega"}


# -------------------------------------------------------------------------------------------
# units
# -------------------------------------------------------------------------------------------
def _display_symbol(code: str) -> str | None:
    """Symbol of the hour-based display of a process (ARW/RRW/R) in :data:`engine.units.DISPLAY`;
    the same for gyroscopes and accelerometers (only the time unit changes)."""
    sym = QUANTITIES[code][0].symbol
    return sym if ("gyroscope", sym) in DISPLAY else None


def _display_factor(code: str, unit: str) -> float:
    """Factor from the native datasheet value (N, K, Q, R) of a ``unit`` signal to Table I's."""
    sym = _display_symbol(code)
    if sym is None:
        return 1.0  # Q is quoted in integrated units (u s)
    kind, f_si = si_factor(unit)
    return f_si * DISPLAY[(kind, sym)].factor


def to_datasheet(code: str, value: float, fs: float, unit: str = "deg/s") -> float:
    """Table I datasheet value of a per-sample parameter (signal in deg/s or m/s^2).

    The native value of :func:`engine.units.to_datasheet` (``N = sqrt(sigma2 dt)``,
    ``K = sqrt(gamma2 / dt)``, ``Q = sqrt(q2) dt``, ``R = omega / dt``) in the display unit of
    :data:`engine.units.DISPLAY` (``60 N`` per sqrt(h), ``216000 K`` per h per sqrt(h),
    ``3600^2 R`` per h^2; Q in u s). deg/s and m/s^2 give the same factors (only hours enter).

    Parameters
    ----------
    code : {"WN", "RW", "QN", "DR"}
    value : float
        ``sigma2``, ``gamma2``, ``q2`` or ``omega`` (per sample).
    fs : float
        Sampling frequency (Hz).
    unit : str
        Signal unit (``"deg/s"`` or ``"m/s^2"``).
    """
    return units_to_datasheet(code, value, fs) * _display_factor(code, unit)


def from_datasheet(code: str, value: float, fs: float, unit: str = "deg/s") -> float:
    """Per-sample parameter from a Table I datasheet value (inverse of :func:`to_datasheet`)."""
    return units_from_datasheet(code, value / _display_factor(code, unit), fs)


def table1_model(sensor: str, fs: float = STUDY_FS) -> Model:
    """The true model of Table I for ``"gyro"`` (WN + RW, deg/s) or ``"accel"``
    (QN + WN + RW + DR, m/s^2), with per-sample parameters at ``fs``."""
    if sensor not in TABLE_I:
        raise ValueError(f"unknown sensor {sensor!r}: use 'gyro' or 'accel'")
    cls = {"WN": WN, "RW": RW, "QN": QN, "DR": DR}
    return Model(
        tuple(
            cls[c](from_datasheet(c, v, fs, TABLE_I[sensor]["unit"]))
            for c, _, v, _ in TABLE_I[sensor]["params"]
        )
    )


# -------------------------------------------------------------------------------------------
# the slope method's regions
# -------------------------------------------------------------------------------------------
def typical_regions(sensor: str, n: int, fs: float = STUDY_FS) -> dict[str, tuple[float, float]]:
    """Averaging-time regions (s) that a typical user picks on the octave ADEV plot.

    Chosen by looking at the Allan deviation of one simulated log, as a user does, without
    knowledge of where the processes overlap:

    * gyroscope: WN over the straight -1/2 part, from the first point up to 10 s (well before
      the minimum, near 700 s; for short logs at most up to the sixth point from the end);
      RW over the last three points, where the curve turns up.
    * accelerometer (the model says QN, WN, RW and DR): QN (slope -1) over the first two
      points (4 and 8 ms; on the plot the curve has slope -1/2 there: the QN is hidden under
      the WN); WN over 15 ms to 1.1 s; RW over 30 to 300 s, the straight +1/2 part after the
      minimum (near 7 s); DR (slope +1) over the last two points, where the curve steepens.
      For short logs the RW region stops before the DR points (at least one point kept).

    Parameters
    ----------
    sensor : {"gyro", "accel"}
    n : int
        Log length (samples); the octave averaging times are ``2^k``, ``k < floor(log2(n-1))``.
    fs : float
        Sampling frequency (Hz).
    """
    tau = 2.0 ** np.arange(default_levels(n)) / fs
    if tau.size < 6:
        raise ValueError(f"a log of {n} samples is too short for the slope method's regions")
    if sensor == "gyro":
        wn_hi = min(10.0, float(tau[-6]))
        return {"WN": (float(tau[0]), wn_hi), "RW": (float(tau[-3]), float(tau[-1]))}
    if sensor == "accel":
        dr = (float(tau[-2]), float(tau[-1]))
        rw_pts = tau[(tau >= 30.0) & (tau <= 300.0) & (tau < dr[0])]
        if rw_pts.size == 0:
            rw_pts = tau[-3:-2]
        return {
            "QN": (float(tau[0]), float(tau[1])),
            "WN": (0.015, 1.1),
            "RW": (float(rw_pts[0]), float(rw_pts[-1])),
            "DR": dr,
        }
    raise ValueError(f"unknown sensor {sensor!r}: use 'gyro' or 'accel'")


# -------------------------------------------------------------------------------------------
# one replicate
# -------------------------------------------------------------------------------------------
def estimate_all(
    x: np.ndarray,
    sensor: str,
    *,
    fs: float = STUDY_FS,
    methods: Sequence[str] = DEFAULT_METHODS,
    regions: dict[str, tuple[float, float]] | None = None,
) -> dict[str, MethodEstimate]:
    """Estimate Table I's model of ``sensor`` from one series by each method.

    Parameters
    ----------
    x : ndarray, shape (N,)
        The series (deg/s for the gyroscope, m/s^2 for the accelerometer).
    sensor : {"gyro", "accel"}
    fs : float
        Sampling frequency (Hz).
    methods : sequence of str
        Among ``GMWM``, ``ARMAV``, ``ARMAV-unweighted``, ``AVSM``, ``AVSM-auto``.
    regions : dict, optional
        AVSM regions (s); default :func:`typical_regions`.

    Returns
    -------
    dict of str to MethodEstimate
    """
    bad = [m for m in methods if m not in METHODS]
    if bad:
        raise ValueError(f"unknown method(s) {', '.join(bad)}: use {', '.join(METHODS)}")
    wv = wavelet_variance(x, fs=fs, unit=TABLE_I[sensor]["unit"])
    return {m: _estimate_one(m, wv, sensor, regions) for m in methods}


def _estimate_one(
    meth: str, wv: WaveletVariance, sensor: str, regions: dict[str, tuple[float, float]] | None
) -> MethodEstimate:
    model = table1_model(sensor, wv.fs).cleared()
    if meth == "GMWM":
        return from_gmwm(fit_gmwm(wv, model))
    if meth == "ARMAV":
        return fit_armav(wv, model).as_estimate()
    if meth == "ARMAV-unweighted":
        est = fit_armav(wv, model, weights="identity").as_estimate()
        return replace(est, method=meth)
    av = AllanVariance.from_wv(wv)
    if meth == "AVSM":
        return avsm(av, regions or typical_regions(sensor, wv.n, wv.fs))
    return avsm_auto(av)


def _replicate(
    task: tuple,
) -> tuple[tuple[int, str, int], dict[str, dict[str, float]], dict[str, str]]:
    """Worker: simulate one replicate and return datasheet values per method and parameter."""
    sensor, n, seed, rep, methods, fs, regions = task
    rng = np.random.default_rng(np.random.SeedSequence([seed, _SENSOR_ID[sensor], n, rep]))
    x = table1_model(sensor, fs).simulate(n, fs=fs, rng=rng)
    wv = wavelet_variance(x, fs=fs, unit=TABLE_I[sensor]["unit"])
    del x
    errors: dict[str, str] = {}
    vals: dict[str, dict[str, float]] = {}
    codes = [c for c, *_ in TABLE_I[sensor]["params"]]
    for meth in methods:
        try:
            est = _estimate_one(meth, wv, sensor, regions)
            vals[meth] = {
                c: (
                    to_datasheet(c, est.params[_PARAM_OF[c]], fs, TABLE_I[sensor]["unit"])
                    if _PARAM_OF[c] in est.params
                    else math.nan
                )
                for c in codes
            }
        except Exception as e:  # noqa: BLE001 - a failed estimate is a result of the study
            errors[meth] = f"{type(e).__name__}: {e}"
            vals[meth] = {c: math.nan for c in codes}
    return (n, sensor, rep), vals, errors


# -------------------------------------------------------------------------------------------
# progress
# -------------------------------------------------------------------------------------------
class _Progress:
    """A text progress bar on a stream (a bar on a terminal, a line per 10 % otherwise)."""

    def __init__(self, total: int, stream: TextIO | None, label: str = "study") -> None:
        self.total, self.stream, self.label = total, stream, label
        self.done = 0
        self.t0 = time.perf_counter()
        self.tty = bool(stream is not None and hasattr(stream, "isatty") and stream.isatty())
        self._next_pct = 10

    def update(self, k: int = 1) -> None:
        self.done += k
        if self.stream is None:
            return
        el = time.perf_counter() - self.t0
        eta = el / self.done * (self.total - self.done) if self.done else math.nan
        pct = 100.0 * self.done / self.total
        if self.tty:
            w = 30
            fill = int(w * self.done / self.total)
            self.stream.write(
                f"\r{self.label} [{'#' * fill}{'.' * (w - fill)}] "
                f"{self.done}/{self.total} {el:6.0f} s, ETA {eta:5.0f} s"
            )
            if self.done == self.total:
                self.stream.write("\n")
            self.stream.flush()
        elif pct >= self._next_pct or self.done == self.total:
            while self._next_pct <= pct:
                self._next_pct += 10
            self.stream.write(
                f"{self.label}: {self.done}/{self.total} ({pct:.0f} %), "
                f"{el:.0f} s, ETA {eta:.0f} s\n"
            )
            self.stream.flush()


# -------------------------------------------------------------------------------------------
# results
# -------------------------------------------------------------------------------------------
def _sci(n: float) -> str:
    """2500000 -> '2.5e6'."""
    e = int(math.floor(math.log10(n)))
    return f"{n / 10**e:g}e{e}"


def _json_num(v: Any) -> Any:
    """NaN/inf as None (JSON has no NaN)."""
    if isinstance(v, float) and not math.isfinite(v):
        return None
    return v


def _fmt(v: float, sig: int = 3) -> str:
    if v is None or not math.isfinite(v):
        return "n/a"
    return f"{v:.{sig}g}" if 1e-3 <= abs(v) < 1e4 or v == 0 else f"{v:.{sig - 1}e}"


@dataclass(frozen=True, eq=False)
class StudyResult:
    """Estimates of every replicate and their summary.

    Attributes
    ----------
    estimates : dict
        ``estimates[n][sensor][method][code]``: ndarray (reps,) of datasheet values (Table I
        units; NaN where the method failed or does not estimate the process).
    errors : list of dict
        ``{"n", "sensor", "rep", "method", "error"}`` for every failed estimate.
    settings : dict
        reps, seed, n_values, fs, methods, sensors, workers, regions (per n and sensor).
    wall_time_s : float
        Wall time of the run.
    """

    estimates: dict[int, dict[str, dict[str, dict[str, np.ndarray]]]]
    errors: list[dict[str, Any]]
    settings: dict[str, Any]
    wall_time_s: float
    rows: list[dict[str, Any]] = field(default_factory=list)

    def __post_init__(self) -> None:
        if not self.rows:
            object.__setattr__(self, "rows", self._summarise())

    def _summarise(self) -> list[dict[str, Any]]:
        rows = []
        for n, by_sensor in self.estimates.items():
            for sensor, by_method in by_sensor.items():
                for code, sym, truth, unit in TABLE_I[sensor]["params"]:
                    for meth, by_code in by_method.items():
                        v = np.asarray(by_code[code], float)
                        ok = v[np.isfinite(v)]
                        if ok.size == 0:
                            continue  # the method does not estimate this process
                        mean = float(np.mean(ok))
                        sd = float(np.std(ok, ddof=1)) if ok.size > 1 else math.nan
                        rmse = float(np.sqrt(np.mean((ok - truth) ** 2)))
                        rows.append(
                            {
                                "n": int(n),
                                "sensor": sensor,
                                "process": code,
                                "symbol": sym,
                                "unit": unit,
                                "truth": truth,
                                "method": meth,
                                "mean": mean,
                                "bias": mean - truth,
                                "rel_bias": (mean - truth) / truth,
                                "sd": sd,
                                "rmse": rmse,
                                "rel_rmse": rmse / truth,
                                "n_ok": int(ok.size),
                                "n_failed": int(v.size - ok.size),
                                "zero_frac": float(np.mean(ok == 0.0)),
                            }
                        )
        return rows

    @classmethod
    def from_json(cls, path: str | os.PathLike) -> StudyResult:
        """Reload a saved study (``study.json`` with its raw estimates), e.g. to redraw it."""
        d = json.loads(Path(path).read_text())
        if "estimates" not in d:
            raise ValueError(f"{path} has no raw estimates (it is a summary)")
        est = {
            int(n): {
                s: {
                    m: {
                        c: np.array([math.nan if x is None else x for x in v], float)
                        for c, v in bm.items()
                    }
                    for m, bm in bs.items()
                }
                for s, bs in bn.items()
            }
            for n, bn in d["estimates"].items()
        }
        return cls(
            estimates=est,
            errors=d.get("errors", []),
            settings=d["settings"],
            wall_time_s=float(d["wall_time_s"]),
        )

    # ---- ranking -----------------------------------------------------------------------
    def _paired_z(self, n: int, sensor: str, code: str, method: str) -> float:
        """z of the mean paired difference of squared errors, GMWM minus ``method``
        (positive: GMWM worse), over the replicates where both have an estimate."""
        truth = {c: v for c, _, v, _ in TABLE_I[sensor]["params"]}[code]
        g = np.asarray(self.estimates[n][sensor]["GMWM"][code], float)
        m = np.asarray(self.estimates[n][sensor][method][code], float)
        ok = np.isfinite(g) & np.isfinite(m)
        d = (g[ok] - truth) ** 2 - (m[ok] - truth) ** 2
        if d.size < 2:
            return math.nan
        se = float(np.std(d, ddof=1)) / math.sqrt(d.size)
        return float(np.mean(d)) / se if se > 0 else (0.0 if np.mean(d) == 0 else math.inf)

    def ranking(self) -> dict[str, Any]:
        """Lowest-RMSE method per (n, sensor, process) and whether GMWM wins everywhere.

        An exception (a method with a lower RMSE than GMWM) is a *tie* when the paired
        difference of squared errors is within 2 Monte Carlo standard errors (``z < 2``, the
        same replicates feed every method) or the RMSEs differ by less than 1 %.
        """
        best: dict[str, str] = {}
        losses = []
        groups: dict[tuple, list[dict[str, Any]]] = {}
        for r in self.rows:
            groups.setdefault((r["n"], r["sensor"], r["process"]), []).append(r)
        for (n, sensor, code), rs in groups.items():
            win = min(rs, key=lambda r: r["rmse"])
            best[f"{n}/{sensor}/{code}"] = win["method"]
            g = [r for r in rs if r["method"] == "GMWM"]
            if g and win["method"] != "GMWM":
                z = self._paired_z(n, sensor, code, win["method"])
                tie = bool(not z >= 2.0 or g[0]["rmse"] <= 1.01 * win["rmse"])
                losses.append(
                    {
                        "n": n,
                        "sensor": sensor,
                        "process": code,
                        "best": win["method"],
                        "best_rmse": win["rmse"],
                        "best_zero_frac": win.get("zero_frac", 0.0),
                        "gmwm_rmse": g[0]["rmse"],
                        "gmwm_zero_frac": g[0].get("zero_frac", 0.0),
                        "z": z,
                        "tie": tie,
                    }
                )
        return {
            "best": best,
            "gmwm_lowest_everywhere": not losses,
            "gmwm_lowest_or_tied_everywhere": all(e["tie"] for e in losses),
            "exceptions": losses,
        }

    def ranking_text(self) -> str:
        """A paragraph on the paper's ranking (GMWM lowest RMSE on every parameter)."""
        rk = self.ranking()
        if rk["gmwm_lowest_everywhere"]:
            return (
                "The paper's ranking holds: GMWM has the lowest RMSE on every parameter, "
                "for every sensor and log length."
            )

        def item(e: dict[str, Any]) -> str:
            t = (
                f"{e['sensor']} {e['process']} at T = {_sci(e['n'])} ({e['best']} "
                f"{_fmt(e['best_rmse'])} vs GMWM {_fmt(e['gmwm_rmse'])}, z = {e['z']:.1f}"
            )
            if e.get("gmwm_zero_frac", 0.0) >= 0.05:
                t += f"; GMWM estimates 0 in {100 * e['gmwm_zero_frac']:.0f} % of the replicates"
            if e.get("best_zero_frac", 0.0) >= 0.05:
                t += f"; {e['best']} in {100 * e['best_zero_frac']:.0f} %"
            return t + ")"

        ties = [item(e) for e in rk["exceptions"] if e["tie"]]
        losses = [item(e) for e in rk["exceptions"] if not e["tie"]]
        out = []
        if losses:
            out.append(
                "The paper's ranking does not hold everywhere: another method has a "
                "clearly lower RMSE than GMWM for " + "; ".join(losses) + "."
            )
        else:
            out.append(
                "The paper's ranking holds within Monte Carlo error: GMWM has the "
                "lowest RMSE or is tied with the best on every parameter."
            )
        if ties:
            out.append(
                "Ties (within 2 Monte Carlo standard errors of the paired difference, or "
                "within 1 %): " + "; ".join(ties) + "."
            )
        return " ".join(out)

    # ---- tables ------------------------------------------------------------------------
    def table(self) -> str:
        """Plain-text table of bias, SD and RMSE per parameter and method."""
        s = self.settings
        lines = [
            f"Slope-method study: {s['reps']} replicates, seed {s['seed']}, fs = "
            f"{s['fs']:g} Hz, wall time {self.wall_time_s:.0f} s"
        ]
        head = (
            f"{'T':>9} {'sensor':<6} {'param':<22} {'truth':>10} {'method':<16} "
            f"{'mean':>10} {'bias':>10} {'bias %':>8} {'SD':>10} {'RMSE':>10} "
            f"{'RMSE/truth':>10}"
        )
        lines += [head, "-" * len(head)]
        for r in self.rows:
            p = f"{r['process']} {r['symbol']} [{r['unit']}]"
            lines.append(
                f"{r['n']:>9.3g} {r['sensor']:<6} {p:<22} {_fmt(r['truth']):>10} "
                f"{r['method']:<16} {_fmt(r['mean']):>10} {_fmt(r['bias']):>10} "
                f"{100 * r['rel_bias']:>8.1f} {_fmt(r['sd']):>10} {_fmt(r['rmse']):>10} "
                f"{_fmt(r['rel_rmse']):>10}"
            )
        lines += ["", self.ranking_text()]
        if self.errors:
            lines.append(f"{len(self.errors)} estimate(s) failed (NaN), see the JSON")
        return "\n".join(lines)

    def markdown(self) -> str:
        """Markdown tables (one per log length), lowest RMSE per parameter in bold."""
        s = self.settings
        out = [
            f"Monte Carlo with Table I's true values: {s['reps']} replicates per log length, "
            f"seed {s['seed']}, fs = {s['fs']:g} Hz, methods {', '.join(s['methods'])}; "
            f"wall time {self.wall_time_s:.0f} s on {s['workers']} worker(s). Bias and RMSE "
            "in Table I's units (and relative to the truth)."
        ]
        for n in self.estimates:
            hours = n / s["fs"] / 3600.0
            out += [
                "",
                f"**T = {_sci(n)} samples ({hours:.1f} h at {s['fs']:g} Hz)**",
                "",
                "| Sensor | Parameter | Truth | Method | Bias (%) | SD | RMSE | RMSE / truth |",
                "|---|---|---|---|---|---|---|---|",
            ]
            rows = [r for r in self.rows if r["n"] == n]
            groups: dict[tuple, list[dict[str, Any]]] = {}
            for r in rows:
                groups.setdefault((r["sensor"], r["process"]), []).append(r)
            for (sensor, _), rs in groups.items():
                win = min(r["rmse"] for r in rs)
                for r in rs:
                    b = "**" if r["rmse"] == win else ""
                    out.append(
                        f"| {TABLE_I[sensor]['label']} | {r['process']} {r['symbol']} "
                        f"[{r['unit']}] | {_fmt(r['truth'])} | {r['method']} | "
                        f"{_fmt(r['bias'])} ({100 * r['rel_bias']:+.1f} %) | {_fmt(r['sd'])} | "
                        f"{b}{_fmt(r['rmse'])}{b} | {b}{_fmt(r['rel_rmse'])}{b} |"
                    )
        regs = self.settings.get("regions") or {}
        if regs and "AVSM" in self.settings["methods"]:
            out += ["", "AVSM regions (averaging time, s), as a typical user picks them:"]
            for n, by_s in regs.items():
                parts = [
                    f"{TABLE_I[s]['label'].lower()} "
                    + ", ".join(f"{c} {_fmt(lo)}-{_fmt(hi)}" for c, (lo, hi) in r.items())
                    for s, r in by_s.items()
                ]
                out.append(f"- T = {_sci(float(n))}: " + "; ".join(parts))
        out += ["", self.ranking_text()]
        return "\n".join(out)

    def to_dict(self, raw: bool = True) -> dict[str, Any]:
        """JSON-ready dictionary: settings, summary rows, ranking, and the raw estimates."""
        d: dict[str, Any] = {
            "study": "slope",
            "settings": self.settings,
            "truth": {
                sensor: {
                    c: {"symbol": sym, "value": v, "unit": u}
                    for c, sym, v, u in TABLE_I[sensor]["params"]
                }
                for sensor in self.settings["sensors"]
            },
            "summary": [{k: _json_num(v) for k, v in r.items()} for r in self.rows],
            "ranking": {
                k: (
                    [{kk: _json_num(vv) for kk, vv in e.items()} for e in v]
                    if k == "exceptions"
                    else v
                )
                for k, v in self.ranking().items()
            },
            "wall_time_s": float(self.wall_time_s),
            "errors": self.errors,
        }
        if raw:
            d["estimates"] = {
                str(n): {
                    sensor: {
                        m: {
                            c: [None if not math.isfinite(x) else float(x) for x in v]
                            for c, v in bm.items()
                        }
                        for m, bm in bs.items()
                    }
                    for sensor, bs in bn.items()
                }
                for n, bn in self.estimates.items()
            }
        return d

    # ---- figures -----------------------------------------------------------------------
    def _panels(self) -> list[tuple[str, str, str, float, str]]:
        return [
            (sensor, c, sym, v, u)
            for sensor in self.settings["sensors"]
            for c, sym, v, u in TABLE_I[sensor]["params"]
        ]

    def boxplot(self, path: str | os.PathLike) -> Path:
        """Box plots of estimate / truth per parameter and method (Fig. 1 of the paper)."""
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        panels = self._panels()
        ns = list(self.estimates)
        fig, axes = plt.subplots(
            len(ns), len(panels), figsize=(3.0 * len(panels), 3.2 * len(ns)), squeeze=False
        )
        for i, n in enumerate(ns):
            for j, (sensor, code, sym, truth, _unit) in enumerate(panels):
                ax = axes[i][j]
                by_m = self.estimates[n][sensor]
                meths = [m for m in by_m if np.any(np.isfinite(by_m[m][code]))]
                data = [
                    np.asarray(by_m[m][code])[np.isfinite(by_m[m][code])] / truth for m in meths
                ]
                ax.boxplot(data, showfliers=True, flierprops={"markersize": 2})
                ax.set_xticks(
                    range(1, len(meths) + 1),
                    [_SHORT.get(m, m) for m in meths],
                    rotation=30,
                    fontsize=8,
                )
                ax.axhline(1.0, color="k", ls="--", lw=0.8)
                allv = np.concatenate(data) if data else np.ones(1)
                if allv.size and (allv.min() < 0.5 or allv.max() > 2.0):
                    # wide spread: log scale, linear near 0 so that estimates at 0 show
                    ax.set_yscale("symlog", linthresh=0.1)
                    ax.set_ylim(bottom=0.0)
                ax.set_title(
                    f"{TABLE_I[sensor]['label']} {code} ({sym})\nT = {_sci(n)}", fontsize=9
                )
                if j == 0:
                    ax.set_ylabel("estimate / truth")
        fig.suptitle(f"Estimates over {self.settings['reps']} replicates (truth = 1)")
        fig.tight_layout()
        p = Path(path)
        fig.savefig(p, dpi=110)
        plt.close(fig)
        return p

    def rmse_plot(self, path: str | os.PathLike) -> Path:
        """RMSE / truth per parameter and method (Fig. 2 of the paper)."""
        import matplotlib

        matplotlib.use("Agg", force=False)
        import matplotlib.pyplot as plt

        panels = self._panels()
        ns = list(self.estimates)
        meths = list(self.settings["methods"])
        fig, axes = plt.subplots(1, len(ns), figsize=(6.0 * len(ns), 4.0), squeeze=False)
        width = 0.8 / len(meths)
        for i, n in enumerate(ns):
            ax = axes[0][i]
            for k, m in enumerate(meths):
                vals = []
                for sensor, code, *_ in panels:
                    r = [
                        r
                        for r in self.rows
                        if r["n"] == n
                        and r["sensor"] == sensor
                        and r["process"] == code
                        and r["method"] == m
                    ]
                    vals.append(r[0]["rel_rmse"] if r else np.nan)
                ax.bar(
                    np.arange(len(panels)) + (k - (len(meths) - 1) / 2) * width,
                    vals,
                    width,
                    label=_SHORT.get(m, m),
                )
            ax.set_xticks(
                range(len(panels)),
                [f"{TABLE_I[s]['label']} {c}" for s, c, *_ in panels],
                fontsize=8,
            )
            ax.set_yscale("log")
            ax.set_ylabel("RMSE / truth")
            ax.set_title(f"T = {_sci(n)} samples")
            ax.legend(fontsize=8)
        fig.tight_layout()
        p = Path(path)
        fig.savefig(p, dpi=110)
        plt.close(fig)
        return p

    def save(self, out_dir: str | os.PathLike) -> dict[str, str]:
        """Write ``study.json``, ``study.md``, ``study.txt`` and, with matplotlib,
        ``boxplot.png`` and ``rmse.png`` to ``out_dir``; return the paths by kind."""
        d = Path(out_dir)
        d.mkdir(parents=True, exist_ok=True)
        paths = {"json": d / "study.json", "markdown": d / "study.md", "text": d / "study.txt"}
        paths["json"].write_text(json.dumps(self.to_dict(), allow_nan=False, indent=1))
        paths["markdown"].write_text(self.markdown() + "\n")
        paths["text"].write_text(self.table() + "\n")
        try:
            import matplotlib  # noqa: F401
        except ImportError:  # pragma: no cover - matplotlib is optional
            pass
        else:
            paths["boxplot"] = self.boxplot(d / "boxplot.png")
            paths["rmse"] = self.rmse_plot(d / "rmse.png")
        return {k: str(v) for k, v in paths.items()}


# -------------------------------------------------------------------------------------------
# the run
# -------------------------------------------------------------------------------------------
def run_slope_study(
    reps: int = 100,
    *,
    seed: int = 1,
    n_values: Iterable[float] = STUDY_N,
    sensors: Sequence[str] = ("gyro", "accel"),
    methods: Sequence[str] = DEFAULT_METHODS,
    fs: float = STUDY_FS,
    workers: int | None = 2,
    regions: dict[str, dict[str, tuple[float, float]]] | None = None,
    progress: bool | TextIO = True,
) -> StudyResult:
    """Run the Monte Carlo of the GMWM paper's Fig. 1-2 with Table I's true values.

    Parameters
    ----------
    reps : int
        Replicates per log length and sensor (the paper used 3000).
    seed : int
        Base seed; replicate ``r`` of sensor ``s`` at length ``T`` uses
        ``SeedSequence([seed, s, T, r])``, so results do not depend on ``workers``.
    n_values : iterable of float
        Log lengths T in samples (default 2.5e6 and 6.3e6, i.e. 2.8 h and 7 h at 250 Hz).
    sensors : sequence of {"gyro", "accel"}
    methods : sequence of str
        Among ``GMWM``, ``ARMAV``, ``ARMAV-unweighted``, ``AVSM``, ``AVSM-auto``.
    fs : float
        Sampling frequency (Hz).
    workers : int or None
        Worker processes (``concurrent.futures.ProcessPoolExecutor``); 1 runs in process;
        None uses every CPU.
    regions : dict, optional
        AVSM regions per sensor (``{"gyro": {"WN": (lo, hi), ...}}``, seconds); default
        :func:`typical_regions` for each log length.
    progress : bool or stream
        Progress bar on stderr (True), on a given stream, or none (False).

    Returns
    -------
    StudyResult
    """
    if int(reps) < 2:
        raise ValueError(f"reps must be at least 2 (an SD needs two replicates), got {reps}")
    reps = int(reps)
    ns = [int(round(float(v))) for v in n_values]
    if not ns or any(v < 1024 for v in ns):
        raise ValueError(f"log lengths must be at least 1024 samples, got {ns}")
    for sensor in sensors:
        if sensor not in TABLE_I:
            raise ValueError(f"unknown sensor {sensor!r}: use 'gyro' or 'accel'")
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise ValueError(
            f"unknown method(s) {', '.join(bad) or '(none)'}: use {', '.join(METHODS)}"
        )
    if workers is None:
        workers = os.cpu_count() or 1
    workers = max(1, int(workers))
    used_regions = {
        str(n): {s: (regions or {}).get(s) or typical_regions(s, n, fs) for s in sensors}
        for n in ns
    }
    tasks = [
        (s, n, int(seed), r, tuple(methods), float(fs), used_regions[str(n)][s])
        for n in ns
        for s in sensors
        for r in range(reps)
    ]
    stream = sys.stderr if progress is True else (progress or None)
    bar = _Progress(len(tasks), stream, label="gmwm study slope")  # type: ignore[arg-type]
    est: dict[int, dict[str, dict[str, dict[str, np.ndarray]]]] = {
        n: {
            s: {m: {c: np.full(reps, np.nan) for c, *_ in TABLE_I[s]["params"]} for m in methods}
            for s in sensors
        }
        for n in ns
    }
    errors: list[dict[str, Any]] = []

    def store(result: tuple) -> None:
        (n, s, r), vals, errs = result
        for m, by_c in vals.items():
            for c, v in by_c.items():
                est[n][s][m][c][r] = v
        for m, e in errs.items():
            errors.append({"n": n, "sensor": s, "rep": r, "method": m, "error": e})
        bar.update()

    t0 = time.perf_counter()
    if workers == 1:
        for t in tasks:
            store(_replicate(t))
    else:
        ex = ProcessPoolExecutor(max_workers=workers)
        try:
            futs = [ex.submit(_replicate, t) for t in tasks]
            for f in as_completed(futs):
                store(f.result())
        except BaseException:  # Ctrl-C or a worker crash: drop the queued replicates
            ex.shutdown(wait=False, cancel_futures=True)
            raise
        ex.shutdown(wait=True)
    wall = time.perf_counter() - t0
    errors.sort(key=lambda e: (e["n"], e["sensor"], e["rep"], e["method"]))
    settings = {
        "reps": reps,
        "seed": int(seed),
        "n_values": ns,
        "fs": float(fs),
        "methods": list(methods),
        "sensors": list(sensors),
        "workers": workers,
        "regions": {
            n: {s: {c: list(t) for c, t in r.items()} for s, r in by.items()}
            for n, by in used_regions.items()
        },
    }
    return StudyResult(estimates=est, errors=errors, settings=settings, wall_time_s=wall)
