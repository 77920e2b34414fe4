"""Shared pytest fixtures and the real-data switch.

Real data: the static IMU logs of ``../shared/data`` (next to the repository; the environment
variable ``GMWM_REAL_DATA`` names another folder). Every test that reads them takes the
``real_data`` fixture (or carries the ``real_data`` marker): when the folder is absent such
tests are skipped with one reason, and they fail instead when ``GMWM_REQUIRE_REAL_DATA=1``
(set by ``.ci/run``, so CI never passes without the real logs).

App fixtures: a demo log for the app tests (the bundled ``engine/demo/demo_imu.h5`` when it exists,
else a small simulated one in the same layout) and ``app_demo``, which points the app at it.
"""

from __future__ import annotations

import contextlib
import os
import socket
import subprocess
import sys
import time
from collections.abc import Callable, Iterator
from pathlib import Path
from typing import Any

import h5py
import pytest
from _browser import chromium, require_chromium

import engine as eg

# The test modules live in concept folders (engine/, app/, cli/, project/) and a few import
# helpers from another module by its name (``from test_server_load import _wait``): every folder
# is on the path, whichever module pytest imports first.
for _folder in ("engine", "app", "cli", "project"):
    sys.path.insert(0, str(Path(__file__).resolve().parent / _folder))

REAL_DATA_ENV = "GMWM_REAL_DATA"
REQUIRE_REAL_DATA_ENV = "GMWM_REQUIRE_REAL_DATA"

#: The keys of a WV's JSON form (``WaveletVariance.to_dict``, ``gmwm wv --json``).
WV_KEYS = {
    "n",
    "fs",
    "levels",
    "tau_samples",
    "tau_s",
    "variance",
    "ci_low",
    "ci_high",
    "n_coef",
    "robust",
    "eff",
    "alpha",
}


def real_data_dir() -> Path:
    """The folder of the real IMU logs: ``$GMWM_REAL_DATA`` or ``<repo>/../shared/data``."""
    env = os.environ.get(REAL_DATA_ENV)
    return Path(env) if env else Path(__file__).resolve().parents[2] / "shared" / "data"


def _real_data_missing() -> str | None:
    """None when the real logs are there, else the one reason every real-data test gives."""
    d = real_data_dir()
    if d.is_dir():
        return None
    shown = os.environ.get(REAL_DATA_ENV) or "../shared/data"
    return f"real IMU logs not found at {shown}: optional for users; see README (Data)"


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark every test that uses the ``real_data`` fixture with the ``real_data`` marker."""
    for item in items:
        if "real_data" in getattr(item, "fixturenames", ()):
            item.add_marker(pytest.mark.real_data)


@pytest.hookimpl(tryfirst=True)
def pytest_runtest_setup(item: pytest.Item) -> None:
    """Skip (or, with ``GMWM_REQUIRE_REAL_DATA=1``, fail) real-data tests without the data."""
    if item.get_closest_marker("real_data") is None:
        return
    reason = _real_data_missing()
    if reason is None:
        return
    if os.environ.get(REQUIRE_REAL_DATA_ENV, "") not in ("", "0"):
        pytest.fail(f"{REQUIRE_REAL_DATA_ENV}=1 but the {reason}", pytrace=False)
    pytest.skip(reason)


@pytest.fixture(scope="session")
def real_data() -> Path:
    """The folder of the real IMU logs (tests using it are skipped or failed without it)."""
    reason = _real_data_missing()
    if reason is not None:  # reached only when the hook above was bypassed
        pytest.skip(reason)
    return real_data_dir()


APP_DEMO_CHANNELS = ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")
APP_DEMO_MODEL = "GM(beta=0.5, sigma2_gm=1e-4)+WN(sigma2=1e-3)+RW(gamma2=1e-9)"


def run_capped(code: str, address_space: int, timeout: float) -> subprocess.CompletedProcess:
    """Run ``python -c code`` in a child whose address space is capped at ``address_space``
    bytes (one BLAS thread), so that a regression that allocates without bound ends in a
    MemoryError there, not in the kernel killing processes on this machine."""

    def cap() -> None:
        import resource

        resource.setrlimit(resource.RLIMIT_AS, (address_space, address_space))

    env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
    return subprocess.run(
        [sys.executable, "-c", code],
        capture_output=True,
        text=True,
        timeout=timeout,
        preexec_fn=cap,
        env=env,
    )


def write_small_demo(path: Path, n: int = 20_000, fs: float = 100.0) -> Path:
    """A six-channel demo log in the bundled layout (root 1-D datasets, ``fs_hz``, ``units``)."""
    model = eg.parse_model(APP_DEMO_MODEL)
    with h5py.File(path, "w") as f:
        for i, name in enumerate(APP_DEMO_CHANNELS):
            ds = f.create_dataset(name, data=model.simulate(n, fs=fs, rng=i + 1))
            ds.attrs["units"] = "deg/s" if name.startswith("gyro") else "m/s^2"
        f.attrs["fs_hz"] = fs
    return path


@pytest.fixture(scope="session")
def app_demo_file(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The demo log the app tests use."""
    from gmwm_app.state import demo_path

    real = demo_path()
    if real.exists():
        return real
    return write_small_demo(tmp_path_factory.mktemp("app_demo") / "demo_imu.h5")


@pytest.fixture(autouse=True)
def _fresh_shared_demo() -> None:
    """Each test reads the demo log itself (the app shares it across sessions of a process,
    :func:`gmwm_app.data.read_demo`): a test's WV count must not depend on earlier tests."""
    data = sys.modules.get("gmwm_app.data")
    if data is not None:
        data.clear_shared()


@pytest.fixture
def app_demo(app_demo_file: Path, monkeypatch: pytest.MonkeyPatch) -> Path:
    """Point ``gmwm_app.state.demo_path()`` at the test demo log; returns its path."""
    monkeypatch.setenv("GMWM_APP_DEMO", str(app_demo_file))
    return app_demo_file


@pytest.fixture
def app(app_demo: Path) -> Any:
    """A fresh app (``create_app().gmwm_app``) with the demo log loaded and its WV computed."""
    from gmwm_app.app import create_app

    a = create_app().gmwm_app
    assert a.state.error == "" and a.state.log is not None and a.state.wv is not None
    return a


@pytest.fixture
def datasheet_checks(monkeypatch: pytest.MonkeyPatch) -> list[Any]:
    """The datasheet specs the app's Datasheet check tab checks, in order (the engine's
    ``check_datasheet`` counted where the tab calls it)."""
    from gmwm_app import check_view

    checks: list[Any] = []
    real = eg.check_datasheet

    def counted(*args: Any, **kw: Any) -> Any:
        checks.append(args[1])
        return real(*args, **kw)

    monkeypatch.setattr(check_view.eg, "check_datasheet", counted)
    return checks


@pytest.fixture
def app_state(app_demo: Path):
    """A fresh session state with the demo log loaded."""
    from gmwm_app.state import AppState

    s = AppState()
    assert s.load_demo(), s.error
    return s


def stop_server(thread: Any, scheduled_before: set[str]) -> None:
    """Stop a server started by ``pn.serve(..., threaded=True)`` and drop the Panel tasks
    scheduled on its loop meanwhile (``scheduled_before``: the keys of
    ``pn.state._scheduled`` before it started).

    Panel schedules one ``gc.collect`` 5 s after a session ends, on the server's loop, under
    a name that makes any later scheduling of it a no-op while it is pending. A server
    stopped within those 5 s leaves it pending forever: no later server of the process gets
    its collections after a session ends (the page pool tests failed after test_app_load.py
    this way). The collection it would have run is run here.
    """
    import gc

    import panel as pn

    thread.stop()
    thread.join(timeout=10)
    stale = [key for key in list(pn.state._scheduled) if key not in scheduled_before]
    for key in stale:
        pn.state._scheduled.pop(key, None)
    if stale:
        gc.collect()


@contextlib.contextmanager
def served_app(
    demo_file: Path, make_app: Callable[[int], Any] | None = None, **serve_kw: Any
) -> Iterator[tuple[int, Any]]:
    """Serve the app on a free 127.0.0.1 port in a background thread with ``demo_file`` as
    the demo; yields (port, server thread) once the port accepts connections; always stops
    (:func:`stop_server`). ``make_app(port)`` makes the application (default: the app's
    :func:`gmwm_app.server.create_application`)."""
    import panel as pn

    from gmwm_app.server import create_application

    old = os.environ.get("GMWM_APP_DEMO")
    os.environ["GMWM_APP_DEMO"] = str(demo_file)
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    scheduled = set(pn.state._scheduled)
    thread = pn.serve(
        {"/": make_app(port) if make_app is not None else create_application()},
        port=port,
        address="127.0.0.1",
        show=False,
        threaded=True,
        start=True,
        verbose=False,
        websocket_origin=[f"127.0.0.1:{port}"],
        **serve_kw,
    )
    try:
        deadline = time.time() + 20
        while time.time() < deadline:
            try:
                with socket.create_connection(("127.0.0.1", port), timeout=0.5):
                    break
            except OSError:
                time.sleep(0.05)
        yield port, thread
    finally:
        stop_server(thread, scheduled)
        if old is None:
            os.environ.pop("GMWM_APP_DEMO", None)
        else:
            os.environ["GMWM_APP_DEMO"] = old


@pytest.fixture(scope="module")
def server(app_demo_file: Path) -> Iterator[str]:
    """The app served on the demo log in a background thread for a browser test module;
    yields its URL; always shut down."""
    require_chromium()
    with served_app(app_demo_file) as (port, _thread):
        yield f"http://127.0.0.1:{port}/"


@pytest.fixture(scope="module")
def browser(server: str) -> Iterator[Any]:
    """A headless Chromium for the module's pages of :func:`server`."""
    with chromium() as b:
        yield b
