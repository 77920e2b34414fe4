"""The installed wheel, not the checkout: build it, install it into a fresh virtual environment,
then (from a folder outside the repository) open the bundled demo and fit it.

The venv sees the packages of the interpreter that runs the tests (numpy, panel ... come from
there, nothing is downloaded): a ``.pth`` file in the venv lists that interpreter's
site-packages folders. ``--system-site-packages`` would not do: when the tests run in a virtual
environment (as README's test command does on a fresh machine), it exposes the *base*
interpreter's packages, which lack the project's dependencies. The wheel is installed with
``--no-deps``. The running interpreter may hold an editable install of this project pointing at
some checkout; a folder named in a ``.pth`` file has its own ``.pth`` files ignored, so that
install's finder never runs, and the test asserts that ``engine`` and ``gmwm_app`` are imported
from the venv's copy.
"""

from __future__ import annotations

import json
import os
import shutil
import site
import subprocess
import sys
import venv
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.slow

CHECK = r"""
import json, sys
from pathlib import Path
import engine as eg
import gmwm_app
from engine.demo import demo_path, demo_truth
from gmwm_app.state import AppState, demo_path as app_demo_path

log = eg.load_log(demo_path())
wv = eg.wavelet_variance(log["gyro_x"], fs=log.fs, unit=log.units["gyro_x"])
res = eg.fit_gmwm(wv, "2*GM+WN+RW")
s = AppState()
ok = s.load_demo()
print(json.dumps({
    "engine": eg.__file__, "gmwm_app": gmwm_app.__file__, "demo": str(demo_path()),
    "app_demo": str(app_demo_path()), "app_loaded": ok, "app_error": s.error,
    "fs": log.fs, "n": log.n, "names": log.names, "truth_models": demo_truth()["models"],
    "wn": res.params["WN.sigma2"], "objective": res.objective,
}))
"""


def _run(cmd: list[str], cwd: Path, env: dict[str, str], timeout: float = 600) -> str:
    p = subprocess.run(cmd, cwd=cwd, env=env, capture_output=True, text=True, timeout=timeout)
    assert p.returncode == 0, f"{cmd} failed ({p.returncode}):\n{p.stdout}\n{p.stderr}"
    return p.stdout


def _build_wheel(tmp: Path, env: dict[str, str]) -> Path:
    # build from a copy of the sources so the checkout gets no build/ or egg-info folders
    src = tmp / "src"
    ignore = shutil.ignore_patterns("__pycache__", "*.pyc", "*.egg-info", "build")
    for name in ("pyproject.toml", "README.md"):
        shutil.copy2(REPO / name, src / name if src.is_dir() else _mk(src) / name)
    for pkg in ("engine", "gmwm_app"):
        shutil.copytree(REPO / pkg, src / pkg, ignore=ignore)
    out = tmp / "dist"
    _run(
        [sys.executable, "-m", "pip", "wheel", str(src), "--no-deps", "--no-build-isolation"]
        + ["-q", "-w", str(out)],
        cwd=tmp,
        env=env,
    )
    (wheel,) = out.glob("gmwm_app-*.whl")
    return wheel


def _mk(p: Path) -> Path:
    p.mkdir(parents=True)
    return p


def test_installed_wheel_opens_and_fits_the_bundled_demo(tmp_path: Path) -> None:
    pytest.importorskip("wheel", reason="building the wheel offline needs the 'wheel' package")
    env = {k: v for k, v in os.environ.items() if k not in ("PYTHONPATH", "GMWM_APP_DEMO")}
    env["PIP_DISABLE_PIP_VERSION_CHECK"] = "1"
    wheel = _build_wheel(tmp_path, env)

    # the demo log and its truth are in the wheel, as package data of engine.demo
    names = set(zipfile.ZipFile(wheel).namelist())
    assert {"engine/demo/demo_imu.h5", "engine/demo/demo_imu_truth.json"} <= names
    assert not any(n.startswith(("data/", "tests/")) for n in names)

    vdir = tmp_path / "venv"
    venv.EnvBuilder(system_site_packages=False, with_pip=False, symlinks=True).create(vdir)
    py, bindir = vdir / "bin" / "python", vdir / "bin"
    # the base interpreter's pip installs into the venv (pip --python: no pip inside the venv);
    # --force-reinstall: an editable install of this project in the base must not satisfy it
    _run(
        [sys.executable, "-m", "pip", "--python", str(py), "install", "-q", "--no-deps"]
        + ["--force-reinstall", str(wheel)],
        cwd=tmp_path,
        env=env,
    )
    venv_site = _run(
        [str(py), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
        tmp_path,
        env,
    ).strip()
    assert (bindir / "gmwm").is_file() and (bindir / "gmwm-app").is_file()  # entry points
    # the running interpreter's packages, after the venv's own (the wheel's copy wins)
    outer = [p for p in site.getsitepackages() if Path(p).is_dir()]
    (Path(venv_site) / "_gmwm_test_outer_site.pth").write_text("\n".join(outer) + "\n")

    work = _mk(tmp_path / "elsewhere")  # a folder outside the repository
    d = json.loads(_run([str(py), "-c", CHECK], cwd=work, env=env).strip().splitlines()[-1])
    site_dir = Path(venv_site).resolve()
    for key in ("engine", "gmwm_app", "demo", "app_demo"):
        assert Path(d[key]).resolve().is_relative_to(site_dir), (key, d[key], site_dir)
    assert d["app_loaded"] and d["app_error"] == "", d["app_error"]
    assert d["fs"] == 100.0 and d["n"] == 200_000 and len(d["names"]) == 6
    # the fit recovers the demo's white noise (truth 2.5e-3 per sample) within 5 %
    assert "WN(sigma2=2.5e-3)" in d["truth_models"]["gyro_x"]
    assert d["wn"] == pytest.approx(2.5e-3, rel=0.05) and d["objective"] >= 0

    # the venv's gmwm command fits its own demo
    demo = d["demo"]
    out = _run(
        [str(bindir / "gmwm"), "fit", demo, "--channel", "gyro_x", "--model", "2*GM+WN+RW"]
        + ["--json"],
        cwd=work,
        env=env,
    )
    fit = json.loads(out)
    assert fit["fs"] == 100.0 and fit["n"] == 200_000 and fit["model"] == "2*GM+WN+RW"
    wn = {(p["process"], p["name"]): p["value"] for p in fit["params"]}[("WN", "sigma2")]
    assert wn == pytest.approx(d["wn"], rel=1e-9)
    # gmwm-app parses its arguments from the venv's copy (serving is the browser tests' job)
    out = _run([str(bindir / "gmwm-app"), "--help"], cwd=work, env=env)
    assert "bundled demo log" in out
