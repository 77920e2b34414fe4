"""What one session may take of a shared server: a cap on ranking candidates, a fair share of
the shared worker threads, jobs abandoned when their session ends (the session's job runner
driven on an asyncio loop of the test, no server), and unfinished uploads bounded (one per
session, dropped when stalled or when the session ends, all sessions' together under a
budget).
"""

from __future__ import annotations

import asyncio
import threading
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from conftest import served_app

from gmwm_app import limits
from gmwm_app.jobs import Jobs


@pytest.fixture
def default_limits() -> Iterator[None]:
    yield
    limits.configure()


def test_ranking_refuses_too_many_candidates(app_state: Any, default_limits: None) -> None:
    limits.configure(max_candidates=10)
    t0 = time.perf_counter()
    assert not app_state.rank("3*GM+WN+QN+RW+DR")  # 63 sub-models
    assert time.perf_counter() - t0 < 2.0  # refused before fitting anything
    err = app_state.error
    assert "has 63 candidate models" in err and "at most 10" in err and "--max-candidates" in err
    assert app_state.selection is None
    assert not app_state.rank("WN, RW, QN, DR, WN+RW, WN+QN, WN+DR, RW+QN, RW+DR, QN+DR, GM")
    assert "has 11 candidate models" in app_state.error
    # within the cap the ranking runs
    assert app_state.rank("WN+RW+QN"), app_state.error
    assert len(app_state.selection.candidates) == 7
    # the default cap admits the tab's own example and refuses a 335-candidate ranking
    limits.configure()
    assert limits.current().max_candidates == limits.DEFAULT_MAX_CANDIDATES == 128
    assert not app_state.rank("20*GM+WN+QN+RW+DR")
    assert "has 335 candidate models" in app_state.error


def _jobs() -> Jobs:
    j = Jobs(doc=None)  # not served: results are applied at once, in the loop's thread
    assert not j.served
    return j


def test_a_session_occupies_at_most_its_share_of_the_worker_threads(default_limits: None) -> None:
    limits.configure(session_jobs=2)
    j = _jobs()
    running, peak, applied = [0], [0], []
    lock = threading.Lock()

    def work(i: int) -> int:
        with lock:
            running[0] += 1
            peak[0] = max(peak[0], running[0])
        time.sleep(0.15)
        with lock:
            running[0] -= 1
        return i

    async def main() -> None:
        await asyncio.gather(
            *(
                j._background(None, i, lambda i=i: work(i), applied.append, None, None)
                for i in range(6)
            )
        )

    t0 = time.perf_counter()
    asyncio.run(main())
    elapsed = time.perf_counter() - t0
    assert sorted(applied) == list(range(6))
    assert peak[0] == 2  # 6 jobs, 2 at a time (the pool has 4 threads)
    assert elapsed >= 3 * 0.15 * 0.9  # three rounds of two


def test_superseded_and_orphaned_jobs_do_not_run(default_limits: None) -> None:
    limits.configure(session_jobs=1)
    j = _jobs()
    ran: list[str] = []
    done: list[str] = []

    def work(name: str) -> str:
        ran.append(name)
        time.sleep(0.1)
        return name

    async def main() -> None:
        futures = []
        for name in ("a", "b", "c"):  # three loads of one key: only the newest matters
            j._count += 1
            j._latest["page-load"] = j._count
            coro = j._background(
                "page-load",
                j._count,
                lambda n=name: work(n),
                lambda _o: None,
                None,
                lambda n=name: done.append(n),
            )
            futures.append(asyncio.ensure_future(coro))
            await asyncio.sleep(0.02)  # "a" starts before "b" and "c" are asked for
        await asyncio.gather(*futures)

    asyncio.run(main())
    # "a" had started when "b" and "c" came; "b" was superseded before its turn: not run
    assert ran == ["a", "c"] and j.skipped == 1
    assert sorted(done) == ["a", "b", "c"]  # every job's done still ran (the indicator)

    # the session ends: what waits is not started, and cancel events are set
    j2 = _jobs()
    cancel = j2.abandon_on_close(threading.Event())
    ran.clear()

    async def main2() -> None:
        first = asyncio.ensure_future(
            j2._background(None, 1, lambda: work("x"), lambda _o: None, None, None)
        )
        queued = asyncio.ensure_future(
            j2._background(None, 2, lambda: work("y"), lambda _o: None, None, None)
        )
        await asyncio.sleep(0.02)
        j2._session_ended(None)
        await asyncio.gather(first, queued)

    asyncio.run(main2())
    assert ran == ["x"] and j2.skipped == 1 and cancel.is_set()
    late = j2.abandon_on_close(threading.Event())
    assert late.is_set()  # registered after the end: set at once


def test_the_ranking_stops_when_its_session_ends(app: Any) -> None:
    """The Model selection view's cancel event is one the session's end sets."""
    view = app.open_view("Model selection")
    assert not view._cancel.is_set()
    app.jobs._session_ended(None)
    assert view._cancel.is_set()


def test_gmwm_app_flags(tmp_path: Path) -> None:
    from gmwm_app.__main__ import build_parser, main

    args = build_parser().parse_args(["--max-candidates", "40", "--session-jobs", "3"])
    assert args.max_candidates == 40 and args.session_jobs == 3
    assert main(["--max-candidates", "0", "--no-show"]) == 2


# ---------------------------------------------------------------------------------------------
# unfinished uploads
# ---------------------------------------------------------------------------------------------
def _chunk(name: str, chunk: int, total: int, data: bytes) -> Any:
    from types import SimpleNamespace

    return SimpleNamespace(
        event_name="upload_event",
        data={"name": name, "chunk": chunk, "total_chunks": total, "type": "", "data": data},
    )


def test_unfinished_uploads_are_bounded(monkeypatch: pytest.MonkeyPatch) -> None:
    from gmwm_app import upload
    from gmwm_app.upload import BoundedFileDropper

    a, b = BoundedFileDropper(chunk_size=1000), BoundedFileDropper(chunk_size=1000)
    part = bytes(1000)
    # one upload in progress per session: a new one drops the partial one
    a._process_event(_chunk("one.csv", 1, 5, part))
    assert a.held_bytes() == 1000
    a._process_event(_chunk("two.csv", 1, 5, part))
    assert a.held_bytes() == 1000 and list(a._received) == ["two.csv"]
    # the session ends: its partial upload goes
    a.drop_partial()
    assert a.held_bytes() == 0
    # stalled: no chunk for STALLED_S s -> dropped at any dropper's next chunk
    clock = [1000.0]
    monkeypatch.setattr(upload.time, "monotonic", lambda: clock[0])
    a._process_event(_chunk("slow.csv", 1, 5, part))
    clock[0] += upload.STALLED_S + 1
    b._process_event(_chunk("other.csv", 1, 5, part))
    assert a.held_bytes() == 0 and b.held_bytes() == 1000
    # every session's unfinished uploads together stay under the budget
    monkeypatch.setattr(upload, "uploads_budget", lambda: 5500)
    a._process_event(_chunk("x.csv", 1, 5, part))  # 1000 held + 4000 announced: within
    assert upload.held_by_all() == 2000
    c = BoundedFileDropper(chunk_size=1000)
    c._process_event(_chunk("y.csv", 1, 5, part))  # 2000 held + 4000 announced: over
    assert c.held_bytes() == 0 and "too many uploads at once" in c.refused
    b._process_event(_chunk("other.csv", 2, 5, bytes(4000)))  # crosses it while arriving
    assert b.held_bytes() == 0 and "try again" in b.refused
    assert upload.held_by_all() == 1000


def test_app_drops_its_partial_upload_when_the_session_ends(app: Any) -> None:
    app.upload._process_event(_chunk("big.csv", 1, 3, bytes(5000)))
    assert app.upload.held_bytes() == 5000
    app.jobs._session_ended(None)
    assert app.upload.held_bytes() == 0


# ---------------------------------------------------------------------------------------------
# served: two sessions ranking, a third one clicking; then the rankings abandoned
# ---------------------------------------------------------------------------------------------
#: The maximal model the two heavy sessions rank (63 candidates, under the default cap).
HEAVY = "3*GM+WN+QN+RW+DR"
#: How long the click session is measured while the rankings run (s).
MEASURE_S = 8.0


@pytest.fixture(scope="module")
def served(app_demo_file: Path) -> Iterator[dict[str, Any]]:
    """The app on 127.0.0.1 in a background thread (as ``tests/app/test_server_load.py``
    serves it)."""
    import panel as pn
    from test_server_load import _wait

    with served_app(app_demo_file, unused_session_lifetime_milliseconds=120_000) as (port, _t):

        def find() -> Any:
            return next((s for s, *_ in list(pn.state._servers.values()) if s.port == port), None)

        _wait(lambda: find() is not None, "the server to register", 20)
        yield {"url": f"http://127.0.0.1:{port}/", "server": find()}


@pytest.mark.load  # a latency bound (1 s) under two concurrent rankings
def test_rankings_leave_other_sessions_responsive_and_stop_with_their_session(
    served: dict[str, Any],
) -> None:
    from test_server_load import _close_sessions, _in_session, _open, _Probe, _refit, _wait

    apps, _ = _open(served, [{"model": "WN"}, {"model": "WN"}, {"model": "WN"}])
    heavy, clicker = apps[:2], apps[2]
    views = []
    for a in heavy:
        _in_session(a, lambda a=a: views.append(a.open_view("Model selection")))
    _wait(lambda: len(views) == 2, "the selection views")
    for v, a in zip(views, heavy, strict=True):
        _in_session(a, lambda v=v: v.start_ranking(HEAVY))
    _wait(lambda: all(v.running for v in views), "the rankings to start")
    lags: list[float] = []
    t_end = time.perf_counter() + MEASURE_S
    with _Probe(served["url"]) as probe:
        specs = ["GM+WN", "WN"]
        while time.perf_counter() < t_end:
            lags.append(_refit(clicker, specs[len(lags) % 2], 10))
    still = [v.running for v in views]
    print(
        f"\nwhile 2 sessions ranked {HEAVY}: {len(lags)} refits of a third session, slowest "
        f"{max(lags) * 1000:.0f} ms; server loop probe max {probe.worst * 1000:.0f} ms; "
        f"rankings still running: {still}"
    )
    assert all(still), "the rankings ended before the measurement did: use a larger model"
    assert max(lags) < 1.0 and probe.worst < 1.0
    # the tabs close: their rankings stop at their next candidate, not after all 63
    t0 = time.perf_counter()
    _close_sessions(served["server"])
    _wait(lambda: not any(v.running for v in views), "the rankings to stop", 20)
    assert time.perf_counter() - t0 < 20
    assert all(a.jobs.closed for a in apps)
