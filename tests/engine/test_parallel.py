"""Every parallel path gives the same numbers in process, on the local process pool, on a
thread pool and on a real Dask ``LocalCluster`` (processes); a worker killed mid-run loses no
task. Each task carries its own seed, so the results do not depend on the
executor, the number of workers, the chunking or the order in which tasks finish.

Identical to the last bit for one BLAS thread per process, as the workers of the local pool
and of Dask run (and the ``gmwm`` command and the app): the WV's sums of squares are one BLAS
dot product then, and chunked under a multi-threaded BLAS (``engine.wv._kernel``), which can
change the last bit. So this module runs its in-process references with one BLAS thread."""

from __future__ import annotations

import json
import os
import signal
import sys
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
import pytest

import engine as eg
from engine._blas import blas_threads, set_blas_threads
from engine._parallel import ProgressLine, executor_workers, parallel_map
from engine.multivariate import MultiModel
from engine.teaching.study import _replicate

distributed = pytest.importorskip("distributed")


@pytest.fixture(scope="module", autouse=True)
def one_blas_thread():
    before = blas_threads()
    set_blas_threads(1)
    yield
    if before is not None:
        set_blas_threads(before)


@pytest.fixture(scope="module")
def dask_client():
    """One 2-process LocalCluster for the module (start-up 2-5 s), with the workers'
    environment of ``gmwm --scheduler local`` (no MALLOC_TRIM_THRESHOLD_: engine._parallel)."""
    import dask

    with dask.config.set({"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None}):
        cluster = distributed.LocalCluster(
            n_workers=2, threads_per_worker=1, processes=True, dashboard_address=None
        )
    client = distributed.Client(cluster)
    yield client
    client.close()
    cluster.close()


@pytest.fixture(scope="module")
def dask_ex(dask_client):
    return dask_client.get_executor(pure=False)


@pytest.fixture(scope="module")
def wn_rw_fit():
    m = eg.parse_model("WN(sigma2=1e-2)+RW(gamma2=1e-6)")
    wv = eg.wavelet_variance(m.simulate(2**13, fs=10.0, rng=2), fs=10.0)
    return eg.fit_gmwm(wv, "WN+RW")


# -------------------------------------------------------------------------------------------
# the mapping helper
# -------------------------------------------------------------------------------------------
def _slow_square(k: int) -> int:
    time.sleep(0.002 * (8 - k % 8))  # later tasks finish first on a pool
    return k * k


def test_parallel_map_keeps_order_counts_progress_and_cancels():
    items = list(range(24))
    calls = []
    with ThreadPoolExecutor(4) as ex:
        got = parallel_map(
            _slow_square, items, executor=ex, progress=lambda d, t: calls.append((d, t))
        )
        assert got == [k * k for k in items]
        assert calls == [(d, 24) for d in range(1, 25)]
        # chunks: counted when the chunk returns, the results still in order
        calls.clear()
        got = parallel_map(
            _slow_square, items, executor=ex, chunksize=5, progress=lambda d, t: calls.append(d)
        )
        assert got == [k * k for k in items] and len(calls) == 5 and calls[-1] == 24
        assert {b - a for a, b in zip([0, *calls[:-1]], calls, strict=True)} <= {4, 5}

        class Cancelled(Exception):
            pass

        def cancel(done: int, total: int) -> None:
            if done == 3:
                raise Cancelled

        with pytest.raises(Cancelled):
            parallel_map(_slow_square, list(range(400)), executor=ex, progress=cancel)
        assert executor_workers(ex, 1) == 4
    assert parallel_map(_slow_square, [3, 1], workers=8) == [9, 1]  # too few: in process
    assert executor_workers(None, 3) == 3


def test_dask_is_imported_only_when_a_cluster_is_asked_for():
    import subprocess
    from pathlib import Path

    code = (
        "import sys, engine as eg, engine.cli.batch, engine.cli.core; eg.fit_batch; "
        "eg.param_intervals; eg.run_slope_study; eg.multivariate.dependence_test; "
        "print('dask' in sys.modules, 'distributed' in sys.modules)"
    )
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=root
    )
    assert out.stdout.split() == ["False", "False"]


def test_progress_line_prints_every_tenth_with_its_noun():
    import io

    s = io.StringIO()
    bar = ProgressLine(0, s, "gmwm batch", "logs")
    for d in range(1, 5):
        bar(d, 4)
    lines = s.getvalue().splitlines()
    assert [ln.split(" (")[0] for ln in lines] == [f"gmwm batch: {d}/4 logs" for d in range(1, 5)]
    assert lines[-1].startswith("gmwm batch: 4/4 logs (100 %)")


# -------------------------------------------------------------------------------------------
# same numbers on every executor
# -------------------------------------------------------------------------------------------
def test_bootstrap_intervals_are_identical_on_every_executor(wn_rw_fit, dask_ex):
    kw = {"method": "bootstrap", "B": 16, "seed": 5}
    ref = eg.param_intervals(wn_rw_fit, **kw)
    assert eg.param_intervals(wn_rw_fit, workers=2, **kw) == ref  # local spawned pool
    with ThreadPoolExecutor(3) as ex:
        assert eg.param_intervals(wn_rw_fit, executor=ex, **kw) == ref
    calls = []
    on_dask = eg.param_intervals(
        wn_rw_fit, executor=dask_ex, progress=lambda d, t: calls.append(d), **kw
    )
    assert on_dask == ref and sorted(calls) == list(range(1, 17))
    # the comparison can fail: another seed gives other intervals
    assert eg.param_intervals(wn_rw_fit, method="bootstrap", B=16, seed=6) != ref
    # and the bootstrap V of the asymptotic intervals too
    v_ref = eg.fit.wv_cov_bootstrap(wn_rw_fit.model, wn_rw_fit.wv, B=8, seed=1)
    v_dask = eg.fit.wv_cov_bootstrap(wn_rw_fit.model, wn_rw_fit.wv, B=8, seed=1, executor=dask_ex)
    np.testing.assert_array_equal(v_dask, v_ref)


def test_bootstrap_optimism_is_identical_on_dask(wn_rw_fit, dask_ex):
    kw = {"max_model": "WN+RW+DR", "optimism": "bootstrap", "B": 10, "seed": 2}
    ref = eg.rank_models(wn_rw_fit.wv, **kw)
    got = eg.rank_models(wn_rw_fit.wv, executor=dask_ex, **kw)
    assert [(c.model, c.optimism, c.criterion) for c in got.candidates] == [
        (c.model, c.optimism, c.criterion) for c in ref.candidates
    ]
    assert all(np.isfinite(c.optimism) and c.optimism != 0 for c in ref.candidates)


def test_bootstrap_j_test_is_identical_on_every_executor(wn_rw_fit, dask_ex):
    """The bootstrap J-test's replicates are tasks too (they ran in a serial loop before)."""
    from engine.inference import j_test

    kw = {"method": "bootstrap", "B": 19, "seed": 3}
    ref = j_test(wn_rw_fit, **kw)
    assert j_test(wn_rw_fit, workers=2, **kw) == ref
    with ThreadPoolExecutor(2) as ex:
        assert j_test(wn_rw_fit, executor=ex, **kw) == ref
    assert j_test(wn_rw_fit, executor=dask_ex, **kw) == ref
    # p = (1 + #{T_b >= T}) / (1 + B): a multiple of 1/20, and T is the asymptotic test's T
    assert round(ref.p_value * 20, 9) == round(ref.p_value * 20) and 0 < ref.p_value <= 1
    assert ref.statistic == j_test(wn_rw_fit).statistic and ref.method == "bootstrap"


def _dep_data():
    dep = MultiModel(
        ["a", "b"],
        "WN(sigma2=1)+RW",
        shared=["RW"],
        cov={"RW": np.array([[1e-2, 5e-3], [5e-3, 1e-2]])},
    )
    return dep.simulate(2**11, rng=4), dep.cleared()


def test_dependence_test_is_identical_on_dask_and_seeded_per_replicate(dask_ex):
    x, model = _dep_data()
    ref = eg.multivariate.dependence_test(x, model, B=6, seed=3)
    calls = []
    got = eg.multivariate.dependence_test(
        x, model, B=6, seed=3, executor=dask_ex, progress=lambda d, t: calls.append((d, t))
    )
    assert got == ref and sorted(calls) == [(d, 6) for d in range(1, 7)]
    # seeded per replicate, not per worker: replicate b is the same whatever B
    more = eg.multivariate.dependence_test(x, model, B=9, seed=3, workers=2)
    assert more.bootstrap[:6] == ref.bootstrap and len(set(more.bootstrap)) == 9


STUDY = {
    "seed": 2,
    "n_values": (2**14,),
    "sensors": ("gyro",),
    "methods": ("GMWM", "AVSM"),
    "progress": False,
}


def test_study_is_identical_on_dask(dask_ex):
    ref = eg.run_slope_study(4, workers=1, **STUDY)
    got = eg.run_slope_study(4, executor=dask_ex, **STUDY)
    for m in STUDY["methods"]:
        for c, v in ref.estimates[2**14]["gyro"][m].items():
            np.testing.assert_array_equal(got.estimates[2**14]["gyro"][m][c], v)
            assert np.all(np.isfinite(v))
        assert len(set(ref.estimates[2**14]["gyro"][m]["WN"].tolist())) == 4  # 4 replicates
    assert got.settings["workers"] == 2 and got.settings["executor"] == "ClientExecutor"
    assert ref.settings["executor"] == "in process"


def test_cli_study_scheduler_local_gives_the_numbers_of_the_local_run(tmp_path, capsys):
    from engine.cli import main

    argv = ["study", "slope", "--reps", "2", "--seed", "5", "--n", "3e4", "--methods", "GMWM"]
    assert main([*argv, "--workers", "1", "--json"]) == 0
    local = json.loads(capsys.readouterr().out)
    assert main([*argv, "--scheduler", "local", "--json"]) == 0
    cap = capsys.readouterr()
    on_dask = json.loads(cap.out)
    assert on_dask["settings"]["executor"] == "ClientExecutor"
    # this process's BLAS has one thread here (the module's fixture), as the workers'
    assert on_dask["summary"] == local["summary"] and len(local["summary"]) == 6
    assert "gmwm study slope" not in cap.err  # its progress bar: on a terminal only


# -------------------------------------------------------------------------------------------
# a worker killed mid-run (keep this test last: the nanny restarts the worker)
# -------------------------------------------------------------------------------------------
def _slow_replicate(task: tuple) -> tuple:
    time.sleep(0.3)
    return _replicate(task)


def test_a_worker_killed_mid_run_loses_no_task(dask_client, dask_ex):
    import cloudpickle

    cloudpickle.register_pickle_by_value(sys.modules[__name__])  # workers need not import us
    tasks = [("gyro", 2**13, 9, r, ("GMWM",), 250.0, None) for r in range(12)]
    ref = [_replicate(t) for t in tasks]
    pids = dask_client.run(os.getpid)
    assert len(pids) == 2
    killed = []

    def kill_one(done: int, total: int) -> None:
        if done == 2 and not killed:  # mid-run: 2 of 12 done, both workers busy
            pid = sorted(pids.values())[0]
            os.kill(pid, signal.SIGKILL)
            killed.append((pid, done))

    got = parallel_map(_slow_replicate, tasks, executor=dask_ex, progress=kill_one)
    assert killed and killed[0][1] < len(tasks)
    assert got == ref  # every replicate arrived, with its own numbers
    # the worker died (the nanny started a new process in its place)
    deadline = time.time() + 20
    while time.time() < deadline:
        now = dask_client.run(os.getpid)
        if killed[0][0] not in now.values():
            break
        time.sleep(0.2)
    assert killed[0][0] not in dask_client.run(os.getpid).values()


def _blas_threads_in_task(_: int) -> int | None:
    return blas_threads()


def test_tasks_run_in_process_with_one_blas_thread_and_the_count_is_restored():
    """In process, the tasks see one BLAS thread as in a worker (the WV kernel sums in chunks
    on a multi-threaded BLAS, so the last bit would depend on where a task ran); the caller's
    setting is back afterwards. The study with workers=1 then equals the pooled study to the
    bit (tests/engine/test_slope_study.py)."""
    if blas_threads() is None:
        pytest.skip("no OpenBLAS thread control in this process")
    prev = blas_threads()
    try:
        set_blas_threads(2)
        assert blas_threads() == 2
        assert parallel_map(_blas_threads_in_task, range(5), workers=1) == [1] * 5
        assert blas_threads() == 2
    finally:
        set_blas_threads(prev or 1)
