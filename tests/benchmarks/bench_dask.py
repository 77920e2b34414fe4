"""Local process pool against a Dask LocalCluster, for the Monte Carlo study and a batch of logs,
and the scaling to N workers on paper.

Run: ``python tests/benchmarks/bench_dask.py [--reps 8] [--n 1e6] [--logs 8] [--samples 2e5]
[--workers 2]``. The LocalCluster's workers are warmed (their imports) before each timing;
the local pool's time includes its start-up (spawned at every call), printed apart.

Measured in one run, on this machine: the study and a batch of simulated logs (written to a
temporary folder, deleted after), in process, on the local pool of ``--workers`` processes and
on a LocalCluster of as many worker processes (its start-up timed apart); the results are
checked equal. Then the per-task cost on the cluster (an empty task's round trip) and the
estimate for N workers: the tasks are independent, so with ``t`` the mean time of one task in
one worker, ``o`` the client/scheduler time per task (which does not shrink with N) and ``T``
tasks, ``wall(N) ~ T * max(t / N, o) + start-up``; the speed-up is ``T t / wall(N)``.
"""

from __future__ import annotations

import argparse
import contextlib
import math
import os
import tempfile
import time
from pathlib import Path

import numpy as np

import engine as eg
from engine._blas import set_blas_threads
from engine._parallel import dask_executor, parallel_map


def _noop(k: int) -> int:
    return k


def _timed(fn, *a, **kw):
    t0 = time.perf_counter()
    out = fn(*a, **kw)
    return out, time.perf_counter() - t0


def _estimates(res) -> list:
    return [
        v.tolist()
        for by_s in res.estimates.values()
        for by_m in by_s.values()
        for by_c in by_m.values()
        for v in by_c.values()
    ]


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--reps", type=int, default=8, help="study replicates per sensor (8)")
    ap.add_argument("--n", type=float, default=1e6, help="study log length in samples (1e6)")
    ap.add_argument("--logs", type=int, default=8, help="logs in the batch (8)")
    ap.add_argument("--samples", type=float, default=2e5, help="samples per channel (2e5)")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument(
        "--trim-check",
        action="store_true",
        help="also time the study on a LocalCluster with Dask's default MALLOC_TRIM_THRESHOLD_",
    )
    args = ap.parse_args()
    set_blas_threads(1)  # as the workers: the in-process reference has one BLAS thread too
    w = args.workers
    print(f"machine: {os.cpu_count()} CPUs, load average {os.getloadavg()[0]:.2f}")
    stack = contextlib.ExitStack()
    t0 = time.perf_counter()
    ex = stack.enter_context(dask_executor("local", w))  # what --scheduler local starts
    startup = time.perf_counter() - t0
    print(f"LocalCluster of {w} worker processes: start-up {startup:.2f} s")

    _, t_spawn = _timed(parallel_map, _noop, list(range(4 * w)), workers=w)
    print(f"local pool of {w} spawned processes: start-up {t_spawn:.2f} s (paid at every call)")
    # ---- per-task overhead of the cluster (an empty task, one per job) ----------------------
    parallel_map(_noop, list(range(20)), executor=ex)  # warm
    k = 400
    _, t_noop = _timed(parallel_map, _noop, list(range(k)), executor=ex)
    o = t_noop / k
    print(f"empty task round trip on the cluster: {1e3 * o:.2f} ms per task ({k} tasks)")

    # ---- the study ---------------------------------------------------------------------------
    kw = {
        "seed": 1,
        "n_values": (args.n,),
        "methods": ("GMWM", "GMWM-efficient", "ARMAV", "AVSM"),
        "progress": False,
    }
    n_tasks = 2 * args.reps
    eg.run_slope_study(2, **{**kw, "n_values": (2**14,)}, executor=ex)  # the workers' imports
    ref, t_one = _timed(eg.run_slope_study, args.reps, workers=1, **kw)
    pool, t_pool = _timed(eg.run_slope_study, args.reps, workers=w, **kw)
    dask, t_dask = _timed(eg.run_slope_study, args.reps, executor=ex, **kw)
    same = _estimates(ref) == _estimates(pool) == _estimates(dask)
    t_task = t_one / n_tasks
    print(
        f"\nstudy, {n_tasks} replicates at T = {args.n:.3g} (GMWM, GMWM-efficient, ARMAV, AVSM): "
        f"{t_task:.3f} s per replicate in process; identical estimates: {same}"
    )
    print(f"  in process            {t_one:7.2f} s")
    print(f"  local pool, {w} procs   {t_pool:7.2f} s  ({t_one / t_pool:.2f}x in process)")
    print(
        f"  LocalCluster, {w} procs {t_dask:7.2f} s  ({t_one / t_dask:.2f}x in process, "
        f"{t_pool / t_dask:.2f}x the local pool; + {startup:.1f} s start-up once)"
    )

    if args.trim_check:
        from distributed import Client, LocalCluster

        with (
            LocalCluster(
                n_workers=w, threads_per_worker=1, processes=True, dashboard_address=None
            ) as cl,
            Client(cl) as cli,
        ):
            dex = cli.get_executor(pure=False)
            eg.run_slope_study(2, **{**kw, "n_values": (2**14,)}, executor=dex)
            trim, t_trim = _timed(eg.run_slope_study, args.reps, executor=dex, **kw)
        print(
            f"  Dask's default worker env (MALLOC_TRIM_THRESHOLD_=65536) {t_trim:7.2f} s "
            f"({t_dask / t_trim:.2f}x ours; identical: {_estimates(trim) == _estimates(ref)})"
        )

    # ---- a batch of logs ----------------------------------------------------------------------
    with tempfile.TemporaryDirectory() as d:
        truth = eg.parse_model("GM(beta=0.5, sigma2_gm=1e-4)+WN(sigma2=1e-3)+RW(gamma2=1e-9)")
        n = int(args.samples)
        chans = [f"gyro_{a}" for a in "xyz"]
        for u in range(args.logs):
            rng = np.random.default_rng(u)
            data = {c: truth.simulate(n, fs=100.0, rng=rng) for c in chans}
            eg.io.save_log(
                Path(d) / f"unit{u:02d}.h5", data, 100.0, units=dict.fromkeys(chans, "deg/s")
            )
        paths = [str(Path(d) / "unit*.h5")]
        bkw = {"model": "GM+WN+RW"}
        warm = [str(Path(d) / "unit00.h5")]
        eg.fit_batch(warm, executor=ex, channels=["gyro_x"], **bkw)  # the workers' imports
        b1, tb1 = _timed(eg.fit_batch, paths, workers=1, **bkw)
        bp, tbp = _timed(eg.fit_batch, paths, workers=w, **bkw)
        bd, tbd = _timed(eg.fit_batch, paths, executor=ex, **bkw)
    same = (
        [lf.report for lf in b1.logs]
        == [lf.report for lf in bp.logs]
        == [lf.report for lf in bd.logs]
    )
    tb_task = tb1 / args.logs
    print(
        f"\nbatch of {args.logs} logs x 3 channels x {n:.3g} samples (GM+WN+RW): "
        f"{tb_task:.3f} s per log in process; identical reports: {same}"
    )
    print(f"  in process            {tb1:7.2f} s")
    print(f"  local pool, {w} procs   {tbp:7.2f} s  ({tb1 / tbp:.2f}x in process)")
    print(
        f"  LocalCluster, {w} procs {tbd:7.2f} s  ({tb1 / tbd:.2f}x in process, "
        f"{tbp / tbd:.2f}x the local pool)"
    )
    stack.close()

    # ---- on paper: N workers -----------------------------------------------------------------
    print(
        f"\nscaling on paper: wall(N) = max(ceil(T / N) t, T o) + start-up, o = {1e3 * o:.2f} ms "
        "(the scheduler hands out one task at a time)"
    )
    paper_t = 0.9  # s per replicate at T = 6.3e6 with five methods (docs/benchmarks.md)
    paper_tasks = 3000 * 2 * 2  # the GMWM paper: 3000 replicates, 2 sensors, 2 lengths
    print(f"  {'N':>5} {'study here':>11} {'batch here':>11} {'paper study':>12} {'speed-up':>9}")
    for nw in (1, 2, 4, 8, 16, 32, 64, 128, 256):
        s_here = n_tasks * t_task / wall(n_tasks, t_task, o, nw)
        b_here = args.logs * tb_task / wall(args.logs, tb_task, o, nw)
        paper = wall(paper_tasks, paper_t, o, nw)
        print(
            f"  {nw:>5} {s_here:>10.1f}x {b_here:>10.1f}x {paper / 3600:>10.2f} h "
            f"{paper_tasks * paper_t / paper:>8.0f}x"
        )
    print("  (speed-ups over one worker, start-up excluded)")


def wall(tasks: int, t: float, o: float, n: int) -> float:
    """Wall time of ``tasks`` independent tasks of ``t`` s on ``n`` workers, ``o`` s of
    scheduler time per task."""
    return max(math.ceil(tasks / n) * t, tasks * o)


if __name__ == "__main__":
    main()
