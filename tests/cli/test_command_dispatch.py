"""The ``gmwm`` command's table of sub-commands and its dispatch (``engine.cli.commands``).

* ``gmwm --help`` lists every sub-command with its one-line help, the same listing as the
  full parser's, without importing any sub-command's module;
* ``gmwm X --help`` works for every sub-command and shows X's own options;
* ``gmwm X ...`` imports X's module only: ``gmwm plan`` loads neither the export formats, the
  reports nor the app, nor the fit's search, the bootstrap's process pool, the loaders,
  PyYAML or ``numpy.ma`` (checked in ``sys.modules`` of a fresh interpreter, not by a timing:
  tests/benchmarks/bench_plan.py times the command).
"""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from engine.cli import build_parser, main
from engine.cli.commands import COMMANDS

REPO = Path(__file__).resolve().parents[2]
#: The sub-commands of the ``gmwm`` command (what its users type; README and docs/cli.md).
NAMES = (
    "wv",
    "fit",
    "select",
    "simulate",
    "study",
    "export",
    "check",
    "virtual",
    "batch",
    "report",
    "segments",
    "plan",
)


def _fresh(code: str) -> str:
    """stdout of ``code`` run in a fresh interpreter on this tree."""
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=REPO
    )
    return out.stdout


def _modules_after(argv: list[str]) -> set[str]:
    """The modules loaded by ``gmwm ARGV`` in a fresh interpreter (all of them: the engine's,
    the app's, the standard library's and the third parties')."""
    code = (
        "import contextlib, io, sys\n"
        "from engine.cli import main\n"
        "with contextlib.redirect_stdout(io.StringIO()):\n"
        "    try:\n"
        f"        status = main({argv!r})\n"
        "    except SystemExit as e:\n"
        "        status = e.code\n"
        "print(status)\n"
        "print(' '.join(sys.modules))\n"
    )
    status, mods = _fresh(code).splitlines()[-2:]
    assert status == "0", f"gmwm {' '.join(argv)} exited with {status}"
    return set(mods.split())


def test_the_table_names_every_sub_command():
    assert tuple(COMMANDS) == NAMES
    parser = build_parser()  # every sub-command's full parser
    sub = next(a for a in parser._actions if a.dest == "command")
    assert tuple(sub.choices) == NAMES
    helps = {a.dest: a.help for a in sub._choices_actions}
    assert helps == {c.name: c.help for c in COMMANDS.values()}
    assert all(h and "\n" not in h for h in helps.values())


def test_top_level_help_lists_every_sub_command(capsys):
    with pytest.raises(SystemExit) as e:
        main(["--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    for c in COMMANDS.values():
        assert c.name in text
        # argparse wraps the help; its words appear in order
        assert " ".join(c.help.split()) in " ".join(text.split())
    # the same text as the full parser's, which imports every sub-command's module
    assert text == build_parser().format_help()


@pytest.mark.parametrize("name", NAMES)
def test_each_sub_command_help_works(name, capsys):
    with pytest.raises(SystemExit) as e:
        main([name, "--help"])
    assert e.value.code == 0
    text = capsys.readouterr().out
    assert text.startswith(f"usage: gmwm {name} ")
    full = build_parser()
    sub = next(a for a in full._actions if a.dest == "command")
    assert text == sub.choices[name].format_help()  # the full parser of that sub-command


def test_top_level_help_imports_no_sub_command_module():
    mods = _modules_after(["--help"])
    assert "engine.cli.commands" in mods
    modules = {f"engine.cli.{c.module}" for c in COMMANDS.values()}
    assert not mods & modules, sorted(mods & modules)


def test_a_sub_command_imports_its_own_module_only():
    mods = _modules_after(["segments", "--help"])
    assert "engine.cli.segments" in mods
    others = {f"engine.cli.{c.module}" for c in COMMANDS.values()} - {"engine.cli.segments"}
    assert not mods & others, sorted(mods & others)


def test_an_unknown_sub_command_is_a_one_line_error(capsys):
    assert main(["plot", "x.csv"]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "invalid choice: 'plot'" in err and "plan" in err


def test_plan_loads_neither_the_formats_nor_the_reports_nor_the_app():
    mods = _modules_after(
        [
            "plan",
            "--model",
            "GM(beta=0.05, sigma2_gm=4e-6)+WN(sigma2=2.5e-5)+RW(gamma2=1e-10)",
            "--fs",
            "100",
            "--target",
            "N within 1 %, K within 30 %",
        ]
    )
    assert "engine.inference.planning" in mods
    # engine.formats.common (text helpers) is all of the formats the shared CLI code uses
    heavy = {m for m in mods if m.startswith(("engine.formats.", "engine.reporting", "gmwm_app"))}
    assert heavy <= {"engine.formats.common"}, sorted(heavy)
    assert not {"engine.multivariate", "engine.teaching", "engine.batch"} & mods


#: What ``gmwm plan`` does not need, for any of its inputs but a pilot log (which it fits): the
#: fit's search and starting values, the bootstrap's process pool (multiprocessing and
#: concurrent.futures, 0.04-0.1 s of imports), the loaders and PyYAML (read_datasheet's Kalibr
#: files, 0.05-0.2 s), numpy.ma (np.unique's, 0.04 s) and the hmac of the secrets module.
NOT_FOR_PLAN = {
    "engine.fit.gmwm",
    "engine.fit.start",
    "engine.fit.covariance",
    "engine._parallel",
    "engine.io.log",
    "engine.io.kalibr",
    "engine.inference.datasheet_check",
    "multiprocessing",
    "concurrent.futures",
    "yaml",
    "numpy.ma",
    "secrets",
    "scipy",
    "h5py",
}


@pytest.mark.parametrize(
    "source",
    [
        ["--model", "GM(beta=0.05, sigma2_gm=4e-6)+WN(sigma2=2.5e-5)+RW(gamma2=1e-10)"],
        ["--datasheet", "arw=0.15 deg/sqrt(h), rrw=2 deg/h/sqrt(h)", "--units", "deg/s"],
    ],
    ids=["model", "datasheet"],
)
def test_plan_loads_only_what_the_plan_computes(source):
    mods = _modules_after(
        ["plan", *source, "--fs", "100", "--target", "K within 10 %, N within 1 %"]
        + ["--hours", "0.5,1,2,10"]
    )
    assert {"engine.inference.planning", "engine.fit.asymptotic", "engine.fit.ieee"} <= mods
    assert not NOT_FOR_PLAN & mods, sorted(NOT_FOR_PLAN & mods)
