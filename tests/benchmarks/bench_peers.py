"""Accuracy against the tools people use instead, side by side.

Run from the repository root (the peers are in the ``bench`` extra):

    python tests/benchmarks/bench_peers.py [--reps 20] [--seed 1] [--workers 2]
        [--n-table1 2.5e6] [--avar-density 16] [--json FILE]

On simulated logs with known truth, each replicate is estimated by every method below, and the
relative bias ``mean(est / truth - 1)`` and relative RMSE ``sqrt(mean((est / truth - 1)^2))``
of the datasheet coefficients N, K (and Q, R where the truth has them) are reported with the
median time per log (from the raw series to the numbers, the AV/WV included).

The logs (``SCENARIOS``):

* ``stim_gyro``, ``stim_accel``: the GMWM paper's Table I (STIM-300 gyroscope WN+RW in deg/s,
  accelerometer QN+WN+RW+DR in m/s^2) at 250 Hz, ``T = 2.5e6`` samples by default (the
  paper's shorter length), from :func:`engine.teaching.table1.table1_model`.
* ``ros_accel``, ``ros_gyro``: white noise + random walk at 200 Hz, 2.16e6 samples (3 h),
  with the values of allan_variance_ros's simulator configuration
  (``config/simulation/imu_simulator.yaml``): N and K below, simulated as that simulator (and
  Kalibr's noise model) does: white noise of SD ``N / sqrt(dt)``, random-walk steps of SD
  ``K sqrt(dt)``, i.e. ``sigma2 = N^2 fs`` and ``gamma2 = K^2 / fs`` per sample.

The methods, and how each one's output is put in the common units (CONVENTIONS.md: with
``dt = 1/fs``, ``N = sqrt(sigma2 dt)`` [u/sqrt(Hz) = u s^0.5], ``K = sqrt(gamma2 / dt)``
[u/s/sqrt(Hz) = u s^-0.5], ``Q = sqrt(q2) dt`` [u s], ``R = omega / dt`` [u/s]; the Allan
variance shapes ``N^2/T``, ``K^2 T/3``, ``3 Q^2/T^2``, ``R^2 T^2/2``):

* ``GMWM ci``: ``eg.fit_gmwm(eg.wavelet_variance(x, fs), model)`` with the R default weights
  ``diag(1/(ci_high - ci_low)^2)``, the true model's structure; per-sample parameters to N, K,
  Q, R by :func:`engine.units.to_datasheet` (the formulas above).
* ``GMWM efficient``: ``eg.fit_efficient`` (the ci fit, then ``Omega = V^-1`` with V implied by
  that fit's model); same conversion.
* ``allantools + IEEE 952``: ``allantools.oadev(x, rate=fs, data_type="freq",
  taus="octave")`` (overlapping ADEV, taus in s), then the IEEE Std 952 slope read-off of
  :func:`engine.teaching.avsm`: a line of fixed slope (-1/2 for N, +1/2 for K, -1 for Q, +1 for
  R) fitted in log-log over a region, read at tau = 1 s (N), 3 s (K), sqrt(3) s (Q), sqrt(2) s
  (R), where the ADEV line equals the coefficient (already in the common units, since tau is in
  s). Regions: :func:`engine.teaching.table1.typical_regions` (the GMWM study's "typical user":
  WN from the first point to 10 s, RW the last three points; for the accelerometer also QN the
  first two points and DR the last two); the WN+RW logs use the gyroscope rule.
* ``allan-variance (default)``: ``tau, av = allan_variance.compute_avar(x, dt)`` then
  ``params, _ = allan_variance.estimate_parameters(tau, av)`` as its example notebook does
  (all five effects: quantization, white, flicker, walk, ramp; NNLS on the AVAR with relative
  weights). Its documented units are the common ones: ``white`` [u s^0.5] = N, ``walk``
  [u s^-0.5] = K, ``quantization`` [u s] = Q, ``ramp`` [u/s] = R (its AVAR model is
  ``3 Q^2/tau^2 + N^2/tau + (2 ln2/pi) B^2 + K^2 tau/3 + R^2 tau^2/2``, tau in s).
* ``allan-variance (true effects)``: the same with ``effects=`` the truth's processes only (the
  structure GMWM is given); timed together with the default call (one ``compute_avar``).
* ``avar``: ``M = avar.windows(len(x), density=D)``, ``va = avar.variance(x, M)``,
  ``f = avar.fit(M / fs, va, T=1/fs, ks=...)`` with one component per true process, started
  where each component's curve passes through the end of the AV it dominates, then the key "o"
  (the documented optimisation: ``scipy.optimize.leastsq`` on the log10 component variances)
  pressed through ``f.on_key_press`` on a non-interactive (Agg) figure. The components are
  ``[slope, variance]`` with AVAR ``variance/tau`` (white), ``variance tau/3`` (Brownian),
  ``3 variance/tau^2`` (quantization), ``variance tau^2/2`` (ramp), tau in s: N, K, Q, R are
  the square roots. ``D`` defaults to 16 windows per decade (avar's default 64 costs 4x the
  time, 14 s per 2.16e6-sample log; ``--avar-density 64`` runs it).
* ``allan-variance-analyzer``: ``AllanVarianceAnalyzer(config, out).run(data)`` with the
  config ``imu_rate = measure_rate = fs`` and ``data`` the series in all six columns (its
  input is a Tx6 accelerometer + gyroscope array); it writes a Kalibr ``imu.yaml``, whose
  ``accelerometer_noise_density`` (the -1/2 line over 0.1-10 s, read at 1 s) is N and
  ``accelerometer_random_walk`` (a +1/2 line fitted over all periods, 0.1-1000 s, read at 3 s)
  is K, in the input's units (the gyroscope entries go through rad -> deg -> rad and are equal;
  with one series in all three axes the "worst axis" it reports is that series). It is a port of
  allan_variance_ros's ``scripts/analysis.py``, so it also stands for that tool's read-off. Its
  time is for the six-column call.

Q is not reported for methods that cannot estimate it (the analyzer), and B (bias instability)
for none: no log here has a flicker term, so there is no truth to score it against.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import math
import os
import tempfile
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from importlib import metadata
from typing import Any

import matplotlib
import numpy as np

import engine as eg
from engine._parallel import parallel_map
from engine.models import RW, WN, Model
from engine.teaching import avsm
from engine.teaching.table1 import STUDY_FS, table1_model, typical_regions
from engine.units import to_datasheet
from engine.wv.allan import AllanVariance

matplotlib.use("Agg")  # avar.fit draws a figure; no window here

# The peers are optional (the ``bench`` extra): a missing one is reported in the table.
try:
    import allantools
except ImportError:  # pragma: no cover - depends on the environment
    allantools = None
try:
    import allan_variance
except ImportError:  # pragma: no cover
    allan_variance = None
try:
    import avar
    from matplotlib import pyplot as plt
    from matplotlib.backend_bases import KeyEvent
except ImportError:  # pragma: no cover
    avar = None
try:
    import yaml  # the analyzer's output is a YAML file (PyYAML comes with it)
    from allan_variance_analyzer import AllanVarianceAnalyzer
    from loguru import logger as _loguru

    _loguru.disable("allan_variance_analyzer")
except ImportError:  # pragma: no cover
    AllanVarianceAnalyzer = None

#: allan_variance_ros's simulator configuration (config/simulation/imu_simulator.yaml).
ROS_ACCEL = {"N": 0.0025019929573561175, "K": 6.972435158192731e-05}  # m/s^2/sqrt(Hz), m/s^3/..
ROS_GYRO = {"N": 1.888339269965301e-04, "K": 2.5565313322052523e-06}  # rad/s/sqrt(Hz), rad/s^2/..
ROS_FS = 200.0
ROS_N = 2_160_000

#: Datasheet symbol of each process code (CONVENTIONS.md, "Units and datasheet conversions").
SYMBOL = {"QN": "Q", "WN": "N", "RW": "K", "DR": "R"}
SYMBOLS = ("N", "K", "Q", "R")

#: PyPI distribution name of each peer (their versions are printed and pinned in the bench extra).
PEERS = {
    "allantools": "allantools",
    "allan-variance": "allan-variance",
    "avar": "avar",
    "allan-variance-analyzer": "allan-variance-analyzer",
}

METHODS = (
    "GMWM ci",
    "GMWM efficient",
    "allantools + IEEE 952",
    "allan-variance (default)",
    "allan-variance (true effects)",
    "avar",
    "allan-variance-analyzer",
)


# -------------------------------------------------------------------------------------------
# the logs
# -------------------------------------------------------------------------------------------
@dataclass(frozen=True)
class Scenario:
    """A simulated log with known truth.

    Attributes
    ----------
    name, label : str
        Key and table label.
    model : Model
        True model with per-sample parameters at ``fs``.
    fs : float
        Sampling frequency (Hz).
    n : int
        Log length (samples).
    unit : str
        Signal unit.
    region_rule : str
        Which :func:`engine.teaching.table1.typical_regions` rule gives the IEEE regions
        (``"gyro"`` for WN/RW, ``"accel"`` for Table I's accelerometer).
    """

    name: str
    label: str
    model: Model
    fs: float
    n: int
    unit: str
    region_rule: str = "gyro"

    @property
    def codes(self) -> tuple[str, ...]:
        """The true model's process codes."""
        return tuple(p.code for p in self.model.processes)

    @property
    def truth(self) -> dict[str, float]:
        """True N, K, Q, R (those the model has), in the common units."""
        return {
            SYMBOL[p.code]: to_datasheet(p.code, float(p.values[0]), self.fs)
            for p in self.model.processes
        }


def wn_rw_model(n_density: float, k_density: float, fs: float) -> Model:
    """WN + RW with densities N [u/sqrt(Hz)] and K [u/s/sqrt(Hz)]: ``sigma2 = N^2 fs``,
    ``gamma2 = K^2 / fs`` (allan_variance_ros's simulator and Kalibr's noise model)."""
    return Model((WN(n_density**2 * fs), RW(k_density**2 / fs)))


def scenarios(n_table1: int = 2_500_000) -> dict[str, Scenario]:
    """The four logs of the benchmark (Table I at ``n_table1`` samples, the ROS ones at
    2.16e6)."""
    return {
        "stim_gyro": Scenario(
            "stim_gyro",
            "STIM-300 gyro (Table I), WN+RW",
            table1_model("gyro", STUDY_FS),
            STUDY_FS,
            n_table1,
            "deg/s",
            "gyro",
        ),
        "stim_accel": Scenario(
            "stim_accel",
            "STIM-300 accel (Table I), QN+WN+RW+DR",
            table1_model("accel", STUDY_FS),
            STUDY_FS,
            n_table1,
            "m/s^2",
            "accel",
        ),
        "ros_accel": Scenario(
            "ros_accel",
            "ROS sim accel, WN+RW",
            wn_rw_model(ROS_ACCEL["N"], ROS_ACCEL["K"], ROS_FS),
            ROS_FS,
            ROS_N,
            "m/s^2",
        ),
        "ros_gyro": Scenario(
            "ros_gyro",
            "ROS sim gyro, WN+RW",
            wn_rw_model(ROS_GYRO["N"], ROS_GYRO["K"], ROS_FS),
            ROS_FS,
            ROS_N,
            "rad/s",
        ),
    }


def ieee_regions(sc: Scenario) -> dict[str, tuple[float, float]]:
    """The IEEE slope regions (s) for the true processes of ``sc``: Table I's typical-user
    regions (:func:`engine.teaching.table1.typical_regions`, the gyroscope rule for WN/RW)."""
    regions = typical_regions(sc.region_rule, sc.n, sc.fs)
    return {c: regions[c] for c in sc.codes}


# -------------------------------------------------------------------------------------------
# the estimators: each returns {method: {symbol: value in the common units}}
# -------------------------------------------------------------------------------------------
def _from_model(model: Model, fs: float) -> dict[str, float]:
    return {SYMBOL[p.code]: to_datasheet(p.code, float(p.values[0]), fs) for p in model.processes}


def est_gmwm_ci(x: np.ndarray, sc: Scenario) -> dict[str, dict[str, float]]:
    """GMWM with the R default (ci) weights, the true structure."""
    wv = eg.wavelet_variance(x, fs=sc.fs)
    return {"GMWM ci": _from_model(eg.fit_gmwm(wv, sc.model.cleared()).model, sc.fs)}


def est_gmwm_efficient(x: np.ndarray, sc: Scenario) -> dict[str, dict[str, float]]:
    """Two-step efficient GMWM (``Omega = V^-1``), the true structure."""
    wv = eg.wavelet_variance(x, fs=sc.fs)
    return {"GMWM efficient": _from_model(eg.fit_efficient(wv, sc.model.cleared()).model, sc.fs)}


def est_allantools_ieee(x: np.ndarray, sc: Scenario) -> dict[str, dict[str, float]]:
    """allantools' overlapping ADEV at octave taus, read off by IEEE Std 952's slopes."""
    taus, adev, err, ns = allantools.oadev(x, rate=sc.fs, data_type="freq", taus="octave")
    m = np.rint(np.asarray(taus) * sc.fs).astype(np.int64)
    av = AllanVariance(
        tau_samples=m,
        avar=np.asarray(adev) ** 2,
        ci_low=np.clip(adev - err, 0.0, None) ** 2,
        ci_high=(adev + err) ** 2,
        n_terms=np.asarray(ns, dtype=np.int64),
        n=int(x.size),
        fs=sc.fs,
        interval="rel",
        unit=sc.unit,
    )
    est = avsm(av, ieee_regions(sc))
    lines = est.details["lines"]
    # each line's reading is the ADEV line at READ_TAU (1 s, 3 s, sqrt 3 s, sqrt 2 s): N, K, Q, R
    return {
        "allantools + IEEE 952": {SYMBOL[c]: float(lines[c]["reading"]["value"]) for c in sc.codes}
    }


_AV_EFFECT = {"QN": "quantization", "WN": "white", "RW": "walk", "DR": "ramp"}


def est_allan_variance(x: np.ndarray, sc: Scenario) -> dict[str, dict[str, float]]:
    """allan-variance's ``compute_avar`` + ``estimate_parameters`` (all effects, and the true
    ones); its coefficients are in the common units (white = N, walk = K, ...)."""
    tau, av = allan_variance.compute_avar(x, 1.0 / sc.fs)
    out = {}
    for meth, effects in (
        ("allan-variance (default)", None),
        ("allan-variance (true effects)", [_AV_EFFECT[c] for c in sc.codes]),
    ):
        params, _ = allan_variance.estimate_parameters(tau, av, effects)
        out[meth] = {SYMBOL[c]: float(params[_AV_EFFECT[c]]) for c in sc.codes}
    return out


_AVAR_SLOPE = {"QN": -2, "WN": -1, "RW": 1, "DR": 2}


def est_avar(x: np.ndarray, sc: Scenario, density: int = 16) -> dict[str, dict[str, float]]:
    """avar's ``windows`` + ``variance`` + ``fit`` with the "o" (optimise) key pressed."""
    m = avar.windows(x.size, density=density)
    with contextlib.redirect_stdout(io.StringIO()):  # avar.variance prints a progress line
        va = avar.variance(x, m)
    tau = m / sc.fs
    # each component's curve through the end of the AV where it dominates (a user's first guess)
    start = {
        "WN": va[0] * tau[0],
        "QN": va[0] * tau[0] ** 2 / 3.0,
        "RW": 3.0 * va[-1] / tau[-1],
        "DR": 2.0 * va[-1] / tau[-1] ** 2,
    }
    ks = [[_AVAR_SLOPE[c], float(start[c])] for c in sc.codes]
    fig, ax = plt.subplots()
    try:
        f = avar.fit(tau, va, T=1.0 / sc.fs, ks=ks, ax=ax)
        f.on_key_press(KeyEvent("key_press_event", f.canvas, "o"))
        fitted = {k[0]: float(k[1]) for k in f.ks}
    finally:
        plt.close(fig)
    return {"avar": {SYMBOL[c]: math.sqrt(fitted[_AVAR_SLOPE[c]]) for c in sc.codes}}


def est_analyzer(x: np.ndarray, sc: Scenario) -> dict[str, dict[str, float]]:
    """allan-variance-analyzer's ``AllanVarianceAnalyzer.run`` on the series in all six
    columns; N and K from the Kalibr ``imu.yaml`` it writes."""
    data = np.column_stack([x] * 6)
    with tempfile.TemporaryDirectory() as d:
        cfg = os.path.join(d, "imu_config.yaml")
        with open(cfg, "w", encoding="utf-8") as fh:
            fh.write(f"imu_rate: {sc.fs:g}\nmeasure_rate: {sc.fs:g}\n")
        analyzer = AllanVarianceAnalyzer(cfg, d)
        with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
            analyzer.run(data)
        with open(os.path.join(d, "imu.yaml"), encoding="utf-8") as fh:
            kalibr = yaml.safe_load(fh)
    values = {
        "N": float(kalibr["accelerometer_noise_density"]),
        "K": float(kalibr["accelerometer_random_walk"]),
    }
    return {"allan-variance-analyzer": {s: v for s, v in values.items() if s in sc.truth}}


#: (methods produced, estimator, the peer it needs or None).
ESTIMATORS: list[tuple[tuple[str, ...], Callable[..., dict[str, dict[str, float]]], str | None]] = [
    (("GMWM ci",), est_gmwm_ci, None),
    (("GMWM efficient",), est_gmwm_efficient, None),
    (("allantools + IEEE 952",), est_allantools_ieee, "allantools"),
    (
        ("allan-variance (default)", "allan-variance (true effects)"),
        est_allan_variance,
        "allan-variance",
    ),
    (("avar",), est_avar, "avar"),
    (("allan-variance-analyzer",), est_analyzer, "allan-variance-analyzer"),
]

_AVAILABLE = {
    "allantools": allantools is not None,
    "allan-variance": allan_variance is not None,
    "avar": avar is not None,
    "allan-variance-analyzer": AllanVarianceAnalyzer is not None,
}


def peer_versions() -> dict[str, str]:
    """Installed version of each peer (``"not installed"`` if missing)."""
    out = {}
    for name, dist in PEERS.items():
        try:
            out[name] = metadata.version(dist)
        except metadata.PackageNotFoundError:
            out[name] = "not installed"
    return out


# -------------------------------------------------------------------------------------------
# one replicate, the run, the summary
# -------------------------------------------------------------------------------------------
def run_replicate(
    task: tuple[Scenario, int, int, int],
) -> dict[str, dict[str, Any]]:
    """Simulate replicate ``rep`` of a scenario and estimate it by every method.

    Parameters
    ----------
    task : (Scenario, seed, rep, avar_density)
        The log, the base seed, the replicate index (the log draws from
        ``SeedSequence([seed, crc(name), n, rep])``) and avar's windows per decade.

    Returns
    -------
    dict
        Per method: ``{"values": {symbol: value}, "seconds": float, "error": str | None}``.
    """
    sc, seed, rep, density = task
    key = sum(ord(ch) * 31**i for i, ch in enumerate(sc.name)) % (2**32)
    rng = np.random.default_rng(np.random.SeedSequence([seed, key, sc.n, rep]))
    x = sc.model.simulate(sc.n, fs=sc.fs, rng=rng)
    out: dict[str, dict[str, Any]] = {}
    for methods, fn, peer in ESTIMATORS:
        if peer is not None and not _AVAILABLE[peer]:
            for meth in methods:
                out[meth] = {"values": {}, "seconds": math.nan, "error": f"{peer} not installed"}
            continue
        kwargs = {"density": density} if fn is est_avar else {}
        t0 = time.perf_counter()
        try:
            res = fn(x, sc, **kwargs)
            err = None
        except Exception as e:  # noqa: BLE001 - a failed estimate is a result of the benchmark
            res, err = {}, f"{type(e).__name__}: {e}"
        dt = time.perf_counter() - t0
        for meth in methods:
            out[meth] = {"values": res.get(meth, {}), "seconds": dt, "error": err}
    return out


def summarise(sc: Scenario, reps: Sequence[dict[str, dict[str, Any]]]) -> dict[str, Any]:
    """Relative bias, RMSE and their Monte Carlo SEs per method and symbol, median time."""
    truth = sc.truth
    out: dict[str, Any] = {}
    for meth in METHODS:
        rows = [r[meth] for r in reps]
        errors = sorted({r["error"] for r in rows if r["error"]})
        entry: dict[str, Any] = {
            "seconds_median": float(np.nanmedian([r["seconds"] for r in rows]))
            if any(np.isfinite(r["seconds"]) for r in rows)
            else math.nan,
            "errors": errors,
            "params": {},
        }
        for sym, true in truth.items():
            est = np.array([r["values"].get(sym, math.nan) for r in rows], dtype=float)
            ok = np.isfinite(est)
            if not ok.any():
                continue
            e = est[ok] / true - 1.0
            k = int(ok.sum())
            entry["params"][sym] = {
                "bias": float(e.mean()),
                "rmse": float(np.sqrt(np.mean(e**2))),
                "bias_se": float(e.std(ddof=1) / math.sqrt(k)) if k > 1 else math.nan,
                "n_ok": k,
                "n_zero": int(np.sum(est[ok] == 0.0)),
            }
        out[meth] = entry
    return out


def run(
    reps: int = 20,
    *,
    seed: int = 1,
    names: Sequence[str] | None = None,
    n_table1: int = 2_500_000,
    avar_density: int = 16,
    workers: int = 2,
    progress: bool = True,
) -> dict[str, Any]:
    """Run the benchmark and return its summary (JSON-ready).

    Parameters
    ----------
    reps : int
        Replicates per log.
    seed : int
        Base seed.
    names : sequence of str, optional
        Scenario keys (default all four).
    n_table1 : int
        Length of the Table I logs (samples).
    avar_density : int
        avar's windows per decade.
    workers : int
        Worker processes (:func:`engine.parallel_map`; 1 runs in process).
    progress : bool
        Print one line per finished scenario.
    """
    scs = scenarios(n_table1)
    names = list(names or scs)
    summary: dict[str, Any] = {
        "reps": reps,
        "seed": seed,
        "avar_density": avar_density,
        "versions": peer_versions(),
        "scenarios": {},
    }
    for name in names:
        sc = scs[name]
        t0 = time.perf_counter()
        results = parallel_map(
            run_replicate, [(sc, seed, r, avar_density) for r in range(reps)], workers
        )
        summary["scenarios"][name] = {
            "label": sc.label,
            "fs": sc.fs,
            "n": sc.n,
            "unit": sc.unit,
            "truth": sc.truth,
            "wall_s": time.perf_counter() - t0,
            "methods": summarise(sc, results),
        }
        if progress:
            print(f"# {name}: {reps} replicates in {time.perf_counter() - t0:.0f} s", flush=True)
    return summary


def _pct(v: float) -> str:
    """A relative error in percent, two significant digits (three from 100 %)."""
    pct = 100.0 * v
    if abs(pct) < 1e-4:
        return "+0 %"
    return f"{pct:+.0f} %" if abs(pct) >= 99.5 else f"{pct:+.2g} %"


def table(summary: dict[str, Any]) -> str:
    """The markdown table: per log and method, relative bias / RMSE of N, K, Q, R and the
    median time per log (lowest RMSE of each column and log in bold)."""
    head = "| log | method | " + " | ".join(f"{s} bias / RMSE" for s in SYMBOLS) + " | s/log |"
    lines = [head, "|" + "---|" * 7]
    for s in summary["scenarios"].values():
        best = {}
        for sym in SYMBOLS:
            vals = [m["params"][sym]["rmse"] for m in s["methods"].values() if sym in m["params"]]
            best[sym] = min(vals) if vals else None
        for meth, m in s["methods"].items():
            cells = []
            for sym in SYMBOLS:
                if sym not in s["truth"]:
                    cells.append("")
                elif sym not in m["params"]:
                    cells.append("-")
                else:
                    p = m["params"][sym]
                    rm = _pct(p["rmse"]).lstrip("+")
                    if p["rmse"] == best[sym]:
                        rm = f"**{rm}**"
                    cell = f"{_pct(p['bias'])} / {rm}"
                    if p["n_zero"]:
                        cell += f" ({p['n_zero']} at 0)"
                    cells.append(cell)
            if m["errors"] and not m["params"]:
                cells = [f"failed: {m['errors'][0][:60]}"] + [""] * 3
            sec = m["seconds_median"]
            lines.append(
                f"| {s['label']} | {meth} | {' | '.join(cells)} | "
                f"{'' if not np.isfinite(sec) else f'{sec:.2f}'} |"
            )
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--reps", type=int, default=20, help="replicates per log (default 20)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--n-table1", type=float, default=2.5e6, help="Table I log length")
    ap.add_argument("--avar-density", type=int, default=16, help="avar windows per decade")
    ap.add_argument("--logs", default="", help="subset: " + ",".join(scenarios()))
    ap.add_argument("--json", default="", help="also write the summary to this file")
    args = ap.parse_args()
    names = [s for s in args.logs.split(",") if s] or None
    if names:
        bad = sorted(set(names) - set(scenarios()))
        if bad:
            ap.error(f"--logs: unknown log(s) {', '.join(bad)}; use {', '.join(scenarios())}")
    t0 = time.perf_counter()
    summary = run(
        args.reps,
        seed=args.seed,
        names=names,
        n_table1=int(args.n_table1),
        avar_density=args.avar_density,
        workers=args.workers,
    )
    summary["wall_s"] = time.perf_counter() - t0
    print(
        "versions: "
        + ", ".join(f"{k} {v}" for k, v in summary["versions"].items())
        + f"; {args.reps} replicates per log, seed {args.seed}, {summary['wall_s']:.0f} s wall"
    )
    print(table(summary))
    for s in summary["scenarios"].values():
        for meth, m in s["methods"].items():
            if m["errors"]:
                print(f"{s['label']}, {meth}: {len(m['errors'])} error(s): {m['errors'][0]}")
    if args.json:
        with open(args.json, "w", encoding="utf-8") as fh:
            json.dump(summary, fh, indent=1)


if __name__ == "__main__":
    main()
