"""Edges of the ``gmwm`` command a newcomer meets first.

* ``gmwm simulate -o x.npy`` keeps fs, channel name and unit (sidecar ``x.npy.json``) and
  ``gmwm fit x.npy`` reads them back; a log without fs gets a loud warning on stderr.
* ``gmwm ... | head`` ends quietly (no BrokenPipeError traceback).
* Every option of every sub-command has a help text.
* The streamed and the in-memory WV name a channel alike.
* ``select --top N`` says how many candidates were ranked and how many are shown.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import h5py
import numpy as np
import pytest

import engine as eg
from engine.cli import build_parser, main

REPO = Path(__file__).resolve().parents[2]
SIM = "GM(beta=0.5, sigma2_gm=1e-4)+WN(sigma2=1e-3)"


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


# ----------------------------------------------------------------------------- fs and unit
def test_simulate_npy_keeps_fs_channel_and_unit(capsys, tmp_path):
    out = tmp_path / "x.npy"
    code, text, err = run(
        capsys,
        "simulate",
        "--model",
        SIM,
        "-n",
        "20000",
        "--fs",
        "200",
        "--unit",
        "deg/s",
        "--channel",
        "gyro",
        "--seed",
        "3",
        "-o",
        str(out),
    )
    assert code == 0 and err == "" and "x.npy.json" in text
    side = json.loads((tmp_path / "x.npy.json").read_text())
    assert side["fs_hz"] == 200.0 and side["channels"] == ["gyro"]
    assert side["units"] == {"gyro": "deg/s"} and side["seed"] == "3"
    assert eg.parse_model(side["model"]).values() == eg.parse_model(SIM).values()

    log = eg.load_log(out)
    assert log.fs == 200.0 and log.fs_source == "file" and log.names == ["gyro"]
    assert log.units == {"gyro": "deg/s"} and log.meta["model"] == side["model"]
    np.testing.assert_array_equal(log["gyro"], np.load(out))

    code, text, err = run(capsys, "fit", str(out), "--model", "GM+WN", "--json")
    d = json.loads(text)
    assert code == 0 and err == ""  # no warning: fs is known
    assert d["fs"] == 200.0 and d["channel"] == "gyro" and d["wv"]["unit"] == "deg/s"
    # tau in seconds follows fs: level 1 is 2 samples = 0.01 s at 200 Hz
    assert d["wv"]["tau_s"][0] == pytest.approx(2 / 200, rel=1e-12)
    # the GM correlation time is in seconds at 200 Hz (truth beta = 0.5 /s)
    beta = next(p["value"] for p in d["params"] if p["name"] == "beta")
    assert beta == pytest.approx(0.5, rel=0.5)
    # a user's --fs still wins over the sidecar
    code, text, _ = run(capsys, "wv", str(out), "--fs", "50", "--json")
    assert json.loads(text)["fs"] == 50.0


def test_unknown_fs_is_a_loud_warning_on_stderr(capsys, tmp_path):
    x = np.random.default_rng(1).standard_normal(5000)
    plain = tmp_path / "plain.npy"
    np.save(plain, x)
    for extra in ([], ["--stream"]):
        code, text, err = run(capsys, "wv", str(plain), "--json", *extra)
        assert code == 0 and json.loads(text)["fs"] == 1.0
        assert "warning" in err and "1 Hz ASSUMED" in err and "--fs" in err and "plain.npy" in err
    code, _, err = run(capsys, "fit", str(plain), "--model", "WN")
    assert code == 0 and "1 Hz ASSUMED" in err
    code, _, err = run(capsys, "export", str(plain), "--model", "WN", "--format", "json", "-o", "-")
    assert code == 0 and "1 Hz ASSUMED" in err
    two = tmp_path / "two.npy"  # several channels (MGMWM) and several recordings
    np.save(two, np.random.default_rng(2).standard_normal((5000, 2)))
    code, _, err = run(capsys, "fit", str(two), "--model", "WN", "--channels", "col0,col1")
    assert code == 0 and "1 Hz ASSUMED" in err and "two.npy" in err
    code, _, err = run(capsys, "fit", str(plain), str(plain), "--model", "WN")
    assert code == 0 and "1 Hz ASSUMED" in err
    # an error stays one line (the warning is printed only with a result)
    code, out, err = run(capsys, "fit", str(plain), "--model", "WN+WN")
    assert code == 2 and out == "" and len(err.strip().splitlines()) == 1 and "WN" in err
    # with --fs: silent
    code, _, err = run(capsys, "fit", str(plain), "--model", "WN", "--fs", "100")
    assert code == 0 and err == ""


def test_a_broken_sidecar_is_a_clear_error(capsys, tmp_path):
    p = tmp_path / "x.npy"
    np.save(p, np.arange(100.0))
    (tmp_path / "x.npy.json").write_text("[1, 2]")
    code, _, err = run(capsys, "wv", str(p))
    assert code == 2 and "x.npy.json" in err and "not a JSON object" in err


# ----------------------------------------------------------------------------- naming
def _names(capsys, path: Path, *extra: str) -> list[tuple[str, str, np.ndarray]]:
    """(header line, JSON channel, WV) of the in-memory and the streamed WV of one channel."""
    out = []
    for stream in ([], ["--stream"]):
        code, text, err = run(capsys, "wv", str(path), "--levels", "5", *extra, *stream)
        assert code == 0, err
        head = text.splitlines()[0]
        code, text, err = run(capsys, "wv", str(path), "--levels", "5", "--json", *extra, *stream)
        d = json.loads(text)
        out.append((head, d["channel"], np.array(d["variance"])))
    return out


@pytest.mark.parametrize("kind", ["npy-1d", "npy-2d", "npy-sidecar", "h5"])
def test_streamed_and_in_memory_wv_name_the_channel_alike(capsys, tmp_path, kind):
    x = np.random.default_rng(2).standard_normal((4000, 3))
    extra: tuple[str, ...] = ("--fs", "10")
    if kind == "npy-1d":
        path, want = tmp_path / "a.npy", "x"
        np.save(path, x[:, 0])
    elif kind == "npy-2d":
        path, want, extra = tmp_path / "b.npy", "col1", ("--fs", "10", "--channel", "1")
        np.save(path, x)
    elif kind == "npy-sidecar":
        path, want, extra = tmp_path / "c.npy", "gyro_z", ()
        argv = ["simulate", "--model", SIM, "-n", "4000", "--fs", "10", "--channel", "gyro_z"]
        assert main([*argv, "-o", str(path)]) == 0
        capsys.readouterr()
    else:
        path, want, extra = tmp_path / "d.h5", "gyro_y", ("--channel", "gyro_y")
        with h5py.File(path, "w") as f:
            f.create_dataset("gyro_x", data=x[:, 0])
            f.create_dataset("gyro_y", data=x[:, 1])
            f.attrs["fs_hz"] = 10.0
    (mem_head, mem_ch, mem_wv), (st_head, st_ch, st_wv) = _names(capsys, path, *extra)
    assert mem_ch == st_ch == want
    assert mem_head == st_head == f"{path} [{want}]"
    np.testing.assert_allclose(st_wv, mem_wv, rtol=1e-12)


# ----------------------------------------------------------------------------- select --top
@pytest.mark.slow  # four rankings of 11 candidates: 12 s of CPU
def test_select_top_says_how_many_were_ranked(capsys, tmp_path):
    path = tmp_path / "s.h5"
    assert main(["simulate", "--model", SIM, "-n", "20000", "--fs", "100", "-o", str(path)]) == 0
    capsys.readouterr()
    # sub-models of 2*GM+WN+RW: 0..2 GM terms times the 4 subsets of {WN, RW}, less the empty
    n_ranked = 3 * 4 - 1
    code, text, err = run(capsys, "select", str(path), "--max-model", "2*GM+WN+RW", "--top", "3")
    assert code == 0, err
    lines = text.splitlines()
    assert f"({n_ranked} candidates ranked, best 3 shown," in lines[1]
    # file line, title, the selection, column header, 3 rows, the 3-line note saying which
    # J-test it is
    assert lines[2].startswith("selected: ")
    assert len(lines) == 3 + 1 + 3 + 3 and lines[7].startswith("J-test p: efficient J-test")
    assert [ln.split()[0] for ln in lines[4:7]] == ["1", "2", "3"]
    code, text, _ = run(capsys, "select", str(path), "--max-model", "2*GM+WN+RW", "--json")
    full = json.loads(text)
    assert full["n_ranked"] == full["n_shown"] == len(full["candidates"]) == n_ranked
    code, text, _ = run(
        capsys, "select", str(path), "--max-model", "2*GM+WN+RW", "--top", "3", "--json"
    )
    top = json.loads(text)
    assert top["n_ranked"] == n_ranked and top["n_shown"] == 3
    assert top["candidates"] == full["candidates"][:3]
    # without --top (or --top >= the count) the title counts what it shows
    code, text, _ = run(capsys, "select", str(path), "--max-model", "2*GM+WN+RW", "--top", "50")
    assert f"({n_ranked} candidates," in text.splitlines()[1] and "shown" not in text


# ----------------------------------------------------------------------------- help texts
def _actions(p: argparse.ArgumentParser, prefix: str):
    for a in p._actions:
        if isinstance(a, argparse._SubParsersAction):
            for name, sp in a.choices.items():
                yield from _actions(sp, f"{prefix} {name}")
        elif not isinstance(a, argparse._HelpAction):
            yield prefix, "/".join(a.option_strings) or a.dest, a.help


def test_every_option_of_every_command_has_help():
    from gmwm_app.__main__ import build_parser as app_parser

    found = list(_actions(build_parser(), "gmwm")) + list(_actions(app_parser(), "gmwm-app"))
    commands = {c for c, _, _ in found}
    assert {"gmwm wv", "gmwm fit", "gmwm select", "gmwm simulate", "gmwm export"} <= commands
    missing = [f"{c} {opt}" for c, opt, h in found if not (h and h.strip())]
    assert missing == []
    assert len(found) > 60  # the walk really visited the sub-commands


# ----------------------------------------------------------------------------- broken pipe
def test_a_reader_that_leaves_early_gets_no_traceback(tmp_path):
    path = tmp_path / "big.npy"
    np.save(path, np.random.default_rng(0).standard_normal(200_000))
    env = {**os.environ, "PYTHONPATH": str(REPO)}
    cmds = [
        ["wv", str(path), "--fs", "100"],
        ["select", str(path), "--fs", "100", "--models", "WN,GM+WN", "--json"],
    ]
    for i in range(12):
        cmd = [sys.executable, "-m", "engine.cli", *cmds[i % 2]]
        p = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
        if i % 3 == 0:
            p.stdout.read(1)  # `head -c 1`: read a little, then leave
        p.stdout.close()  # the reader is gone (before or after the first write)
        err = p.stderr.read().decode()
        p.stderr.close()
        code = p.wait(timeout=120)
        assert "Traceback" not in err and "BrokenPipeError" not in err, err
        assert err == "" and code in (0, 141), (code, err)
