"""Monte Carlo study of the slope method, ARMAV and GMWM (the GMWM paper, Fig. 1-2, Table I).

For each sensor of Table I (a STIM-300 gyroscope and accelerometer), each log length and each
replicate: simulate the true model at 250 Hz, compute the Haar WV and estimate the model by
GMWM (ci and efficient weights), ARMAV and the slope method (hand-picked regions, optionally
the ROS tools' automatic read-off); report bias, SD and RMSE per parameter and method in
Table I's datasheet units. Every replicate draws from its own seed, so the results do not
depend on the number of workers. The methods and Table I's values: docs/methods.md, "The slope
method study"; the 500-replicate results: docs/benchmarks.md.
"""

from __future__ import annotations

import math
import os
import sys
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import Executor
from dataclasses import replace
from typing import Any, TextIO

import numpy as np

from .._parallel import ProgressLine, executor_workers, parallel_map
from ..fit import fit_gmwm
from ..fit.estimate import MethodEstimate, from_gmwm
from ..fit.gmwfm import fit_armav
from ..wv import WaveletVariance, wavelet_variance
from ..wv.allan import AllanVariance
from .slope import avsm, avsm_auto
from .study_result import StudyResult
from .table1 import (
    DEFAULT_METHODS,
    METHODS,
    PARAM_OF,
    SENSOR_ID,
    STUDY_FS,
    STUDY_N,
    TABLE_I,
    table1_model,
    to_datasheet,
    typical_regions,
)

__all__ = ["estimate_all", "run_slope_study"]


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
        Among ``GMWM``, ``GMWM-efficient``, ``ARMAV``, ``ARMAV-unweighted``, ``AVSM``,
        ``AVSM-auto``.
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
    if meth == "GMWM-efficient":
        return from_gmwm(fit_gmwm(wv, model, weights="efficient"), method=meth)
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
    rng = np.random.default_rng(np.random.SeedSequence([seed, SENSOR_ID[sensor], n, rep]))
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
                    to_datasheet(c, est.params[PARAM_OF[c]], fs, TABLE_I[sensor]["unit"])
                    if PARAM_OF[c] in est.params
                    else math.nan
                )
                for c in codes
            }
        except Exception as e:  # noqa: BLE001 - a failed estimate is a result of the study
            errors[meth] = f"{type(e).__name__}: {e}"
            vals[meth] = {c: math.nan for c in codes}
    return (n, sensor, rep), vals, errors


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
    progress: bool | TextIO | Callable[[int, int], None] = True,
    executor: Executor | None = None,
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
        Among ``GMWM``, ``GMWM-efficient``, ``ARMAV``, ``ARMAV-unweighted``, ``AVSM``,
        ``AVSM-auto``.
    fs : float
        Sampling frequency (Hz).
    workers : int or None
        Local worker processes (:func:`engine._parallel.parallel_map`); 1 runs in process;
        None uses every CPU.
    regions : dict, optional
        AVSM regions per sensor (``{"gyro": {"WN": (lo, hi), ...}}``, seconds); default
        :func:`typical_regions` for each log length.
    progress : bool, stream or callable (done, total)
        Progress line on stderr (True), on a given stream, none (False), or a callback
        called after each replicate.
    executor : concurrent.futures.Executor, optional
        Runs the replicates instead of the local processes, e.g. a Dask cluster's
        ``Client.get_executor()`` (``gmwm study --scheduler``); the estimates do not depend
        on it.

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
    bar: Callable[[int, int], None]
    if callable(progress):  # the caller's callback (the command line's bar)
        bar = progress
    else:
        stream = sys.stderr if progress is True else (progress or None)
        bar = ProgressLine(len(tasks), stream, label="gmwm study slope")
    est: dict[int, dict[str, dict[str, dict[str, np.ndarray]]]] = {
        n: {
            s: {m: {c: np.full(reps, np.nan) for c, *_ in TABLE_I[s]["params"]} for m in methods}
            for s in sensors
        }
        for n in ns
    }
    errors: list[dict[str, Any]] = []
    t0 = time.perf_counter()
    # one replicate per job (each takes 0.1-1 s): the finest progress, and a lost worker
    # loses one replicate
    results = parallel_map(_replicate, tasks, workers, executor=executor, progress=bar, chunksize=1)
    for (n, s, r), vals, errs in results:
        for m, by_c in vals.items():
            for c, v in by_c.items():
                est[n][s][m][c][r] = v
        for m, e in errs.items():
            errors.append({"n": n, "sensor": s, "rep": r, "method": m, "error": e})
    wall = time.perf_counter() - t0
    errors.sort(key=lambda e: (e["n"], e["sensor"], e["rep"], e["method"]))
    settings = {
        "reps": reps,
        "seed": int(seed),
        "n_values": ns,
        "fs": float(fs),
        "methods": list(methods),
        "sensors": list(sensors),
        "workers": executor_workers(executor, workers),
        "executor": "in process"
        if executor is None and workers == 1
        else ("local processes" if executor is None else type(executor).__name__),
        "regions": {
            n: {s: {c: list(t) for c, t in r.items()} for s, r in by.items()}
            for n, by in used_regions.items()
        },
    }
    return StudyResult(estimates=est, errors=errors, settings=settings, wall_time_s=wall)
