"""``gmwm`` limits and late checks.

* Every subcommand that writes (simulate, export, virtual, batch, study) refuses an output it
  cannot write before any computation: one line, in a fraction of a second, where the
  computation behind it takes seconds to minutes (before: batch and study computed everything
  first).
* ``simulate -n`` is checked as a sample count: ``1e14`` and ``3e9`` are one-line errors, not
  a traceback or a minute of allocation.
* Engine warnings (PX4/ArduPilot range) print as ``gmwm export: warning: ...``, one line, not
  as a Python ``UserWarning`` with a source path.
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from engine import _limits
from engine.cli import main
from engine.demo import demo_path

DEMO = str(demo_path())
ENV = {**os.environ, "PYTHONPATH": str(Path(__file__).resolve().parents[2])}
#: CPU seconds of a refusal (the modules a command imports are loaded once before it is timed);
#: each command below computes for several seconds to minutes of CPU. CPU time, not wall time:
#: a loaded machine stretches the wall clock of even a refusal past any fixed bound.
FAST = 0.5


def _gmwm(*argv: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-m", "engine.cli", *argv],
        capture_output=True,
        text=True,
        env=ENV,
        timeout=120,
    )


def _bad_outputs(tmp_path: Path) -> dict[str, tuple[str, str]]:
    """A bad file output and a bad folder output, with the words the refusal must contain."""
    afile = tmp_path / "a_file.txt"
    afile.write_text("x")
    return {
        "missing folder": (str(tmp_path / "no_such_dir" / "out.h5"), "does not exist"),
        "unwritable folder": ("/proc/gmwm_out.h5", "not writable"),  # even root cannot
        "folder given as file": (str(tmp_path), "is a folder"),
        "folder inside a file": (str(afile / "sub.h5"), "is a file"),
        "unwritable dir output": ("/proc/gmwm_dir/sub", "not writable"),
    }


# Heavy work behind each command: minutes if the output were checked last.
COMMANDS = {
    "simulate": ["simulate", "--model", "WN(sigma2=1)+RW(gamma2=1e-6)", "-n", "2e8", "-o"],
    "export": [
        "export",
        DEMO,
        "--model",
        "3*GM+WN+RW",
        "--ci",
        "bootstrap",
        "-B",
        "500",
        "--format",
        "json",
        "-o",
    ],
    "virtual": [
        "virtual",
        DEMO,
        "--channels",
        "gyro_x,gyro_y,gyro_z",
        "--model",
        "2*GM+WN+RW",
        "--shared",
        "WN,RW",
        "--format",
        "kalibr",
        "-o",
    ],
    "batch": ["batch", DEMO, DEMO, "--max-model", "3*GM+WN+QN+RW+DR", "--quiet", "-o"],
    "study": ["study", "slope", "--reps", "200", "-o"],
    "report": ["report", DEMO, "--max-model", "3*GM+WN+QN+RW+DR", "-o"],
}
FILE_CASES = ("missing folder", "unwritable folder", "folder given as file", "folder inside a file")
DIR_CASES = ("folder inside a file", "unwritable dir output")


@pytest.mark.parametrize("cmd", list(COMMANDS))
def test_unwritable_output_fails_before_any_computation(cmd, tmp_path, capsys) -> None:
    cases = DIR_CASES if cmd in ("batch", "study") else FILE_CASES
    bad = _bad_outputs(tmp_path)
    main([*COMMANDS[cmd], "/proc/gmwm_warm/out.html"])  # load the command's modules, untimed
    capsys.readouterr()
    for case in cases:
        path, words = bad[case]
        if cmd == "simulate" and case == "folder given as file":
            words = "is a folder"
        if cmd == "report":  # an HTML file (its suffix is checked too)
            path = path[: -len(".h5")] + ".html" if path.endswith(".h5") else path
        t0 = time.process_time()
        code = main([*COMMANDS[cmd], path])
        took = time.process_time() - t0
        out, err = capsys.readouterr()
        assert code == 2, (cmd, case, err)
        assert took < FAST, (cmd, case, took)
        assert out == "" and err.count("\n") == 1, (cmd, case, err)
        assert err.startswith(f"gmwm: error: -o {path}") and words in err, (cmd, case, err)
    assert not list((tmp_path).glob("no_such_dir"))  # nothing was created


def test_dir_outputs_may_be_created(tmp_path, capsys) -> None:
    """A missing folder for batch/study is created (with its parents): not an error."""
    out = tmp_path / "new" / "fleet"
    code = main(
        ["batch", DEMO, "--model", "WN+RW", "--channels", "gyro_x", "--quiet", "-o", str(out)]
    )
    _, err = capsys.readouterr()
    assert code == 0, err
    assert (out / "summary.json").is_file()


def test_simulate_counts_are_one_line_errors() -> None:
    for n, words in (
        ("1e14", "-n = 1e+14 samples is beyond any simulation"),
        ("2.5", "-n must be a whole number of samples"),
        ("0", "-n must be at least 1 sample"),
    ):
        t0 = time.perf_counter()
        r = _gmwm("simulate", "--model", "WN(sigma2=1)", "-n", n, "-o", "x.h5")
        assert r.returncode == 2 and r.stdout == "", r.stderr
        assert r.stderr.count("\n") == 1 and words in r.stderr, r.stderr
        assert "Traceback" not in r.stderr and time.perf_counter() - t0 < 30


def test_simulate_3e9_refused_by_memory() -> None:
    mem = _limits.available_memory()
    if mem is not None and 3e9 * _limits.BYTES_PER_SAMPLE <= _limits.MEMORY_FRACTION * mem:
        pytest.skip("this machine has the memory for 3e9 samples")
    r = _gmwm("simulate", "--model", "WN(sigma2=1)", "-n", "3e9", "-o", "x.h5")
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "-n = 3000000000 samples would need about 96 GB" in r.stderr
    assert f"use -n <= {_limits.max_samples()}"[:12] in r.stderr


def test_simulate_limit_follows_memory(monkeypatch, capsys) -> None:
    """On a 23 GB machine -n 3e9 (which reached 17 GB in 60 s) is refused."""
    monkeypatch.setattr(_limits, "available_memory", lambda: 23 * 10**9)
    assert main(["simulate", "--model", "WN(sigma2=1)", "-n", "3e9", "-o", "x.h5"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "use -n <= 359375000" in err, err


def test_study_n_is_checked_first(monkeypatch, capsys, tmp_path) -> None:
    monkeypatch.setattr(_limits, "available_memory", lambda: 23 * 10**9)
    main(["study", "slope", "-o", "/proc/gmwm_warm/sub"])  # load the command's modules, untimed
    capsys.readouterr()
    t0 = time.process_time()
    code = main(["study", "slope", "--reps", "1", "--n", "1e6,2e8", "--workers", "2"])
    assert code == 2 and time.process_time() - t0 < FAST
    err = capsys.readouterr().err
    assert (
        "--n = 200000000 samples" in err and "x 2 at once" in err and "use --n <= 179687500" in err
    )


def test_engine_warnings_are_one_line_cli_warnings(tmp_path) -> None:
    out = tmp_path / "ekf.params"
    r = _gmwm(
        "export",
        DEMO,
        "--model",
        "GM+WN+RW",
        "--format",
        "px4",
        "--filter-rate",
        "100",
        "--inflate",
        "200",
        "-o",
        str(out),
    )
    assert r.returncode == 0, r.stderr
    lines = r.stderr.splitlines()
    warn = [ln for ln in lines if ln.startswith("gmwm export: warning: EKF2_GYR_NOISE = ")]
    assert len(warn) == 1 and "outside its documented range [0.0001, 0.1]" in warn[0], r.stderr
    assert all(ln.startswith("gmwm export: warning: ") for ln in lines), r.stderr
    assert "UserWarning" not in r.stderr and ".py" not in r.stderr
    first, *misfits = r.stdout.strip().splitlines()
    assert first == f"wrote px4 export of 6 channel(s) ({', '.join(_chans())}) to {out}"
    # then one line per channel whose fit the data reject
    assert all(": model and data disagree: " in ln for ln in misfits), r.stdout
    assert "# warning: EKF2_GYR_NOISE" in out.read_text()  # and in the file, as before


def _chans() -> list[str]:
    return ["gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z"]
