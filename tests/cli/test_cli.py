"""The ``gmwm`` command: JSON contract, readable tables, simulate round trips, bad input."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from conftest import WV_KEYS

import engine as eg
from engine.cli import main


def run(capsys, *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


@pytest.fixture(scope="module")
def sim_h5(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("cli") / "sim.h5"
    assert (
        main(
            [
                "simulate",
                "--model",
                "GM(beta=0.5, sigma2_gm=1e-3)+WN(sigma2=1e-2)",
                "-n",
                "60000",
                "--fs",
                "50",
                "--seed",
                "3",
                "-o",
                str(path),
            ]
        )
        == 0
    )
    return path


def test_wv_json_contract(capsys, sim_h5):
    code, out, err = run(capsys, "wv", str(sim_h5), "--json")
    assert code == 0 and err == ""
    d = json.loads(out)
    assert WV_KEYS <= set(d)
    assert d["n"] == 60000 and d["fs"] == 50.0 and d["robust"] is False
    x = eg.load_log(sim_h5)["x"]
    np.testing.assert_allclose(d["variance"], eg.wavelet_variance(x).variance, rtol=1e-12)
    np.testing.assert_allclose(d["tau_s"], np.array(d["tau_samples"]) / 50.0)


def test_wv_options(capsys, sim_h5):
    code, out, _ = run(
        capsys,
        "wv",
        str(sim_h5),
        "--levels",
        "6",
        "--robust",
        "--eff",
        "0.8",
        "--alpha",
        "0.1",
        "--json",
    )
    d = json.loads(out)
    assert code == 0 and len(d["variance"]) == 6 and d["robust"] is True
    assert d["eff"] == 0.8 and d["alpha"] == 0.1


def test_wv_table_has_units(capsys, real_data):
    code, out, _ = run(
        capsys, "wv", str(real_data / "adis16405_imu1.h5"), "--channel", "gyro_y", "--levels", "4"
    )
    assert code == 0
    assert "gyro_y" in out and "(deg/s)^2" in out and "tau [s]" in out and "fs = 100 Hz" in out


def test_fit_json_contract(capsys, sim_h5):
    code, out, err = run(capsys, "fit", str(sim_h5), "--model", "WN+GM", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["model"] == "GM+WN" and d["n"] == 60000 and d["fs"] == 50.0 and d["weights"] == "ci"
    assert [(p["process"], p["index"], p["name"]) for p in d["params"]] == [
        ("GM", 1, "beta"),
        ("GM", 1, "sigma2_gm"),
        ("WN", 1, "sigma2"),
    ]
    assert all({"value", "unit"} <= set(p) for p in d["params"])
    beta = d["params"][0]["value"]
    assert beta == pytest.approx(0.5, rel=0.3)
    assert set(d["components"]) == {"GM", "WN"}
    assert WV_KEYS <= set(d["wv"])
    np.testing.assert_allclose(
        np.sum([d["components"][k] for k in d["components"]], axis=0), d["implied"], rtol=1e-12
    )


def test_fit_table_readable(capsys, sim_h5):
    code, out, _ = run(capsys, "fit", str(sim_h5), "--model", "GM+WN")
    assert code == 0 and "GM.beta" in out and "1/s" in out and "objective" in out


def test_fit_from_wv_summary(capsys, real_data):
    code, out, err = run(
        capsys,
        "fit",
        str(real_data / "derived" / "navchip_wv_av.h5"),
        "--channel",
        "gyro_z",
        "--model",
        "GM+QN+WN+RW",
        "--json",
    )
    assert code == 0, err
    d = json.loads(out)
    assert d["fs"] == 250.0 and d["n"] == 3105250 and len(d["wv"]["variance"]) == 20


@pytest.mark.parametrize("ext", ["h5", "npy", "csv"])
def test_simulate_then_fit_round_trip(capsys, tmp_path, ext):
    out_file = tmp_path / f"s.{ext}"
    code, out, _ = run(
        capsys,
        "simulate",
        "--model",
        "WN(sigma2=4)+RW(gamma2=1e-4)",
        "-n",
        "40000",
        "--fs",
        "20",
        "--seed",
        "1",
        "-o",
        str(out_file),
    )
    assert code == 0 and out_file.exists() and "40000 samples" in out
    fs = ["--fs", "20"] if ext == "npy" else []  # a bare .npy holds no sampling rate
    code, out, err = run(capsys, "fit", str(out_file), "--model", "WN+RW", "--json", *fs)
    assert code == 0, err
    d = json.loads(out)
    vals = {p["name"]: p["value"] for p in d["params"]}
    assert d["fs"] == pytest.approx(20.0)
    assert vals["sigma2"] == pytest.approx(4.0, rel=0.05)
    assert vals["gamma2"] == pytest.approx(1e-4, rel=0.6)


def test_simulate_is_reproducible(tmp_path):
    a, b = tmp_path / "a.npy", tmp_path / "b.npy"
    for p in (a, b):
        assert (
            main(
                [
                    "simulate",
                    "--model",
                    "AR1(phi=0.9, sigma2=1)",
                    "-n",
                    "500",
                    "--seed",
                    "7",
                    "-o",
                    str(p),
                ]
            )
            == 0
        )
    np.testing.assert_array_equal(np.load(a), np.load(b))


def bad_files(tmp_path: Path) -> dict[str, Path]:
    files = {
        "empty": tmp_path / "empty.csv",
        "text": tmp_path / "text.csv",
        "binary": tmp_path / "binary.csv",
        "nan": tmp_path / "nan.csv",
        "short": tmp_path / "short.csv",
        "constant": tmp_path / "constant.csv",
    }
    files["empty"].write_text("")
    files["text"].write_text("gyro_x\n0.1\n0.2\nabc\n0.3\n0.5\n")
    files["binary"].write_bytes(bytes(range(256)) * 8)
    files["nan"].write_text("gyro_x\n" + "\n".join(["0.1", "nan", "0.3"] * 10) + "\n")
    files["short"].write_text("gyro_x\n0.1\n0.2\n")
    files["constant"].write_text("gyro_x\n" + "1.5\n" * 100)
    return files


@pytest.mark.parametrize(
    ("case", "extra", "match"),
    [
        ("missing", [], "no such file"),
        ("empty", [], "empty"),
        ("text", [], "line 4, column 1 of 1 ('gyro_x'): a value that is not a number"),
        ("binary", [], "text"),
        ("nan", [], "NaN"),
        ("short", [], "4"),
        ("constant", [], "constant"),
        ("good", ["--channel", "nope"], "nope"),
        ("good", ["--fs", "0"], "--fs"),
        ("good", ["--fs", "-3"], "--fs"),
        ("good", ["--levels", "40"], "levels"),
        ("good", ["--model", "WN+WN"], "2 WN terms"),
        ("good", ["--model", "BOGUS"], "unknown process"),
        ("good", ["--model", "8*GM+WN"], "17 parameters but the WV has only 15"),
    ],
)
def test_bad_input_exits_nonzero_with_one_line(capsys, tmp_path, sim_h5, case, extra, match):
    files = bad_files(tmp_path)
    path = {"missing": tmp_path / "nope.csv", "good": sim_h5}.get(case) or files[case]
    model = [] if "--model" in extra else ["--model", "WN"]
    code, out, err = run(capsys, "fit", str(path), *model, *extra)
    assert code == 2 and out == ""
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    assert "Traceback" not in err and match.lower() in err.lower(), err


def test_command_line_entry_point_has_no_traceback(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("x\nfoo\nbar\nbaz\nqux\n")
    r = subprocess.run(
        [sys.executable, "-m", "engine.cli", "wv", str(bad)],
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr and r.stderr.startswith("gmwm:")
    r = subprocess.run(
        [sys.executable, "-m", "engine.cli"], capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr


def test_fit_json_keeps_strings_with_nan_in_them(capsys, tmp_path):
    """Non-finite numbers become null; a channel named 'NaNo' stays 'NaNo'."""
    x = eg.parse_model("WN(sigma2=1)+RW(gamma2=1e-4)").simulate(4096, rng=3)
    path = tmp_path / "log.csv"
    np.savetxt(path, x[:, None], header="NaNo", comments="")
    code, out, err = run(capsys, "fit", str(path), "--model", "WN+RW", "--json")
    assert code == 0, err
    d = json.loads(out)
    assert d["channel"] == "NaNo"
    assert d["params"][0]["value"] == pytest.approx(1.0, rel=0.2)


def _raised_texts(path: Path) -> list[tuple[int, str]]:
    """The literal text of every ``raise X(...)`` of a module (f-string parts included)."""
    import ast

    out = []
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Raise) and isinstance(node.exc, ast.Call):
            parts = [
                c.value
                for arg in node.exc.args
                for c in ast.walk(arg)
                if isinstance(c, ast.Constant) and isinstance(c.value, str)
            ]
            out.append((node.lineno, "".join(parts)))
    return out


def test_engine_messages_name_arguments_not_cli_flags():
    # an older tree had 14 engine messages naming --units, --inflate ... (the CLI's words)
    import re

    root = Path(__file__).resolve().parents[2] / "engine"
    found = [
        f"{p.relative_to(root.parent)}:{line}: {text}"
        for p in sorted(root.rglob("*.py"))
        if "cli" not in p.relative_to(root).parts
        for line, text in _raised_texts(p)
        if re.search(r"(?<![\w-])--[a-z]", text)
    ]
    assert found == []


def test_the_cli_words_engine_messages_in_its_flags(capsys, tmp_path):
    from engine.cli.common import cli_text

    assert cli_text("levels=30 is out of range") == "--levels 30 is out of range"
    assert (
        cli_text("allow a partial file (allow_partial=True)") == "allow a partial file (--partial)"
    )
    assert cli_text("give it with units={'gyro_x': 'deg/s'} among") == (
        "give it with --units gyro_x=deg/s among"
    )
    assert cli_text("choose segment='longest' to") == "choose --segment longest to"
    assert cli_text("spec='arw<=0.3 deg/sqrt(h)' is not") == "--spec 'arw<=0.3 deg/sqrt(h)' is not"
    assert (
        cli_text("fs=100 Hz; wv.levels=3; segment=(0, 9)")
        == "fs=100 Hz; wv.levels=3; segment=(0, 9)"
    )
    demo = str(eg.demo_path())
    args = ["export", demo, "--model", "WN+RW", "-o", str(tmp_path / "x.txt")]
    assert main([*args, "--format", "px4"]) == 2
    err = capsys.readouterr().err
    assert "(--filter-rate)" in err and "filter_rate=" not in err
    assert main([*args, "--channels", "gyro_x", "--format", "kalibr"]) == 2
    err = capsys.readouterr().err
    assert "only gyroscope" in err and "(--partial)" in err
    # a format that takes no --partial is not offered it
    assert main([*args, "--channels", "gyro_x", "--format", "openvins"]) == 2
    err = capsys.readouterr().err
    assert "only gyroscope" in err and "partial" in err and "--partial" not in err
    assert main(["fit", demo, "--channel", "gyro_x", "--model", "WN", "--levels", "99"]) == 2
    assert "--levels 99 is out of range" in capsys.readouterr().err
