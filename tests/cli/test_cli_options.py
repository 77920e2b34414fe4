"""One meaning per option name across the ``gmwm`` subcommands.

Before, ``--scale`` was a counts factor in most commands and seconds in ``gmwm virtual``,
``wv``/``virtual`` took ``--alpha`` where ``fit``/``export``/``check`` took ``--level`` for the
same confidence (beside ``--levels``), ``study`` wrote to ``--out`` and the others to ``-o``,
and ``batch --select`` was ``select --max-model``. The table below is the one meaning of every
option; the test walks every subcommand's parser and fails on an option missing from it, on
an option stored under another name, or on a help text that says something else. The old
spellings still work and print one line naming the new option.
"""

from __future__ import annotations

import argparse
import json
import re

import numpy as np
import pytest

import engine as eg
from engine.cli import build_parser, main
from engine.cli.common import DeprecatedAlias

# option -> (destination, what its help must say: the one meaning)
MEANINGS: dict[str, tuple[str, str]] = {
    "--absolute": ("absolute", r"sum the WVs plainly"),
    "--band": ("band", r"minimise the WV over the scales S1:S2 \(s\)"),
    "-B": ("bootstrap", r"^bootstrap replicates"),
    "--bound-data": ("bound_data", r"^filter formats: the bound also covers the empirical WV"),
    "--bound-band": ("bound_band", r"^filter formats: the WV scales S1:S2 \(s\) the bound covers"),
    "--bound-confidence": ("bound_confidence", r"^filter formats: bound the upper limit"),
    "--bootstrap": ("bootstrap", r"^bootstrap replicates"),
    "--channel": ("channel", r"channel"),
    "--channels": ("channels", r"channels"),
    "--ci": ("ci", r"^parameter intervals"),
    "--consumer": ("consumer", r"^JSON report: project each fit onto"),
    "--confidence": ("confidence", r"^confidence level of .*, in \(0, 1\) \(0\.95\)$"),
    "--datasheet": ("datasheet", r"^KEY=VALUE UNIT items"),
    "--datasheet-file": ("datasheet_file", r"Kalibr imu\.yaml"),
    "--dependence-test": ("dependence_test", r"test of dependence"),
    "--eff": ("eff", r"^efficiency of the robust WV, in \(0, 0\.99\)"),
    "--filter-rate": ("filter_rate", r"the rate \(Hz\) the EKF predicts at"),
    "--fit": ("fit", r"^a fitted model: the output of 'gmwm fit --json'"),
    "--export": ("export", r"^with -o DIR: write DIR/fleet\.<suffix>, one filter file"),
    "--format": ("format", r"^export format"),
    "--hours": ("hours", r"^log lengths to tabulate, in hours"),
    "--horizon": ("horizon", r"the longest WV scale the bound covers"),
    "--fs": ("fs", r"^sampling frequency in Hz"),
    "--inflate": ("inflate", r"multiply every noise value by this factor"),
    "--json": ("json", r"^print one JSON object"),
    "--levels": ("levels", r"^number of WV levels J$"),
    "--drop-warmup": ("drop_warmup", r"^drop the warm-up the log check finds"),
    "--temperature": ("temperature", r"^temperature channel whose bias-temperature polynomial"),
    "--max-hours": ("max_hours", r"^longest log considered for a target"),
    "--max-model": ("max_model", r"sub-model of this model"),
    "--methods": ("methods", r"GMWM-efficient"),
    "--model": ("model", r"model"),
    "--model-for": ("model_for", r"^model of one channel"),
    "--models": ("models", r"^candidate models"),
    "-n": ("n", r"^number of samples"),
    "--n": ("n", r"^log lengths in samples"),  # study: several sample counts
    "--name": ("name", r"virtual channel's name"),
    "--no-intervals": ("no_intervals", r"^filter formats: skip the 95 %"),
    "--no-tails": ("no_tails", r"^filter formats: the data bound without its tail factors"),
    "--optimism": ("optimism", r"^optimism term of the WVIC"),
    "-o": ("output", r"output file|^folder for"),
    "--output": ("output", r"output file|^folder for"),
    "--partial": ("partial", r"only gyroscope or only accelerometer"),
    "--projection": ("projection", r"^filter formats: bound \(default\) projects"),
    "--scale-factor-std": ("scale_factor_std", r"kf-gins"),
    "--quiet": ("quiet", r"no progress line"),
    "--reps": ("reps", r"^replicates per log length"),
    "--report": ("report", r"^write the fleet acceptance report"),
    "--robust": ("robust", r"^robust \(Tukey biweight\) WV$"),
    "--rostopic": ("rostopic", r"^rostopic entry"),
    "--scale": ("scale", r"^scale factor for raw counts"),  # counts, everywhere
    "--scheduler": ("scheduler", r"Dask cluster"),
    "--seed": ("seed", r"seed"),
    "--segment": ("segment", r"^time column with gaps"),
    "--params": ("params", r"^flight logs: the EKF noise parameters flown"),
    "--segments": ("segments", r"^analyse only these parts of a flight log: auto"),
    "--window": ("window", r"^still segments: the window"),
    "--threshold": ("threshold", r"^still segments: moving when"),
    "--min-length": ("min_length", r"^still segments: the shortest"),
    "--shared": ("shared", r"^processes shared by"),
    "--static": ("static", r"^PNG figures instead of interactive"),
    "--spec": ("spec", r"^with --report: an acceptance limit"),
    "--stream": ("stream", r"^stream a \.npy/HDF5 log"),
    "--target": ("target", r"^precision targets at --confidence"),
    "--tau": ("tau", r"^minimise the WV at the scale tau = S seconds$"),
    "--top": ("top", r"^show only the best N"),
    "--topic": ("topic", r"^ROS bag: the sensor_msgs/Imu topic; PX4 ULog: the IMU topic "),
    "--unit": ("unit", r"^signal unit stored in the output$"),
    "--units": ("units", r"^signal unit\(?s?\)? overriding the file"),
    "--vehicle-id": ("vehicle_id", r"^px4: the MAVLink system id"),
    "--weights": ("weights", r"^weighting matrix"),
    "--workers": ("workers", r"processes"),
}

# (subcommand, old spelling) -> (new option as the message names it, value given, value stored)
DEPRECATED: dict[tuple[str, str], tuple[str, str, object]] = {
    ("wv", "--alpha"): ("--confidence", "0.1", 0.9),
    ("virtual", "--alpha"): ("--confidence", "0.01", 0.99),
    ("fit", "--level"): ("--confidence", "0.9", 0.9),
    ("export", "--level"): ("--confidence", "0.8", 0.8),
    ("check", "--level"): ("--confidence", "0.99", 0.99),
    ("virtual", "--scale"): ("--tau", "80", 80.0),
    ("study", "--out"): ("-o/--output", "results", "results"),
    ("batch", "--select"): ("--max-model", "2*GM+WN+RW", "2*GM+WN+RW"),
}


def _subparsers() -> dict[str, argparse.ArgumentParser]:
    p = build_parser()
    (sub,) = [a for a in p._actions if isinstance(a, argparse._SubParsersAction)]
    return dict(sub.choices)


def test_every_option_has_one_meaning() -> None:
    seen: dict[str, set[str]] = {}
    aliases = set()
    for cmd, sp in _subparsers().items():
        for a in sp._actions:
            if isinstance(a, argparse._HelpAction) or not a.option_strings:
                continue
            if isinstance(a, DeprecatedAlias):
                (opt,) = a.option_strings
                assert (cmd, opt) in DEPRECATED, f"gmwm {cmd} {opt}: an alias not in the table"
                assert a.help == argparse.SUPPRESS and a.new == DEPRECATED[(cmd, opt)][0]
                aliases.add((cmd, opt))
                continue
            for opt in a.option_strings:
                assert opt in MEANINGS, f"gmwm {cmd} {opt}: give it a meaning in MEANINGS"
                dest, meaning = MEANINGS[opt]
                assert a.dest == dest, f"gmwm {cmd} {opt} is stored as {a.dest}, not {dest}"
                assert re.search(meaning, a.help or ""), f"gmwm {cmd} {opt}: {a.help!r}"
                seen.setdefault(opt, set()).add(cmd)
    assert aliases == set(DEPRECATED)
    assert set(seen) == set(MEANINGS)  # no stale row
    # the old clashes are gone: a counts factor wherever --scale is an option
    assert "virtual" not in seen["--scale"] and "--level" not in seen and "--alpha" not in seen
    assert seen["-o"] == {"simulate", "export", "virtual", "batch", "study", "report"}


@pytest.mark.parametrize(("cmd", "old"), list(DEPRECATED))
def test_deprecated_spelling_works_and_names_the_new_option(cmd: str, old: str) -> None:
    new, given, stored = DEPRECATED[(cmd, old)]
    base = {
        "wv": ["wv", "x.h5"],
        "fit": ["fit", "x.h5", "--model", "WN"],
        "export": ["export", "x.h5", "--model", "WN", "-o", "-"],
        "check": ["check", "x.h5", "--datasheet", "arw=0.3 deg/sqrt(h)"],
        "virtual": ["virtual", "a.h5", "b.h5", "--model", "WN"],
        "study": ["study", "slope"],
        "batch": ["batch", "x.h5", "-o", "out"],
    }[cmd]
    args = build_parser().parse_args([*base, old, given])
    dest = MEANINGS[new.split("/")[-1]][0]
    want = pytest.approx(stored) if isinstance(stored, float) else stored
    assert getattr(args, dest) == want
    shown = f"{stored:g}" if isinstance(stored, float) else stored
    assert args.warnings == [f"{old} is deprecated: use {new} {shown}"] or args.warnings == [
        f"{old} is deprecated: use {new} {shown} (= 1 - alpha)"
    ]
    advised = build_parser().parse_args([*base, new.split("/")[-1], shown])  # as the message says
    assert getattr(advised, dest) == want
    assert getattr(advised, "warnings", None) is None  # the new spelling warns of nothing


def test_old_and_new_spellings_give_the_same_result(tmp_path, capsys) -> None:
    rng = np.random.default_rng(5)
    x = np.cumsum(rng.normal(0, 1e-3, 20000)) + rng.normal(0, 0.1, 20000)
    f = tmp_path / "x.h5"
    eg.io.save_log(f, {"gyro_x": x}, 100.0, units={"gyro_x": "deg/s"})
    assert main(["wv", str(f), "--json", "--alpha", "0.1"]) == 0
    out, err = capsys.readouterr()
    assert err == "gmwm wv: warning: --alpha is deprecated: use --confidence 0.9 (= 1 - alpha)\n"
    assert main(["wv", str(f), "--json", "--confidence", "0.9"]) == 0
    out2, err2 = capsys.readouterr()
    assert err2 == "" and json.loads(out) == json.loads(out2)
    d = json.loads(out)
    assert d["alpha"] == 0.1  # the engine's alpha, exactly as typed
    argv = ["fit", str(f), "--model", "WN+RW", "--ci", "asymptotic"]
    assert main([*argv, "--level", "0.8", "--json"]) == 0
    a, err = capsys.readouterr()
    assert err == "gmwm fit: warning: --level is deprecated: use --confidence 0.8\n"
    assert main([*argv, "--confidence", "0.8", "--json"]) == 0
    b, _ = capsys.readouterr()
    assert json.loads(a)["intervals"] == json.loads(b)["intervals"]


def test_virtual_tau_and_its_old_spelling(tmp_path, capsys) -> None:
    rng = np.random.default_rng(2)
    files = []
    for k in range(2):
        f = tmp_path / f"s{k}.h5"
        x = rng.normal(0, 0.1 * (k + 1), 8192) + np.cumsum(rng.normal(0, 1e-3, 8192))
        eg.io.save_log(f, {"gyro_x": x}, 100.0, units={"gyro_x": "deg/s"})
        files.append(str(f))
    argv = ["virtual", *files, "--model", "WN+RW", "--shared", "WN,RW", "--json"]
    assert main([*argv, "--scale", "1.28"]) == 0
    old, err = capsys.readouterr()
    assert err == "gmwm virtual: warning: --scale is deprecated: use --tau 1.28\n"
    assert main([*argv, "--tau", "1.28"]) == 0
    new, err = capsys.readouterr()
    assert err == "" and json.loads(old)["weights"] == json.loads(new)["weights"]
    assert main([*argv, "--tau", "1.28", "--band", "1:2"]) == 2  # still exclusive
    assert "not allowed with" in capsys.readouterr().err
