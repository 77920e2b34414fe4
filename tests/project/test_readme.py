"""README and the documentation pages cannot rot: their code runs as written.

The pages are README.md (the front page) and the docs/ pages of :data:`PAGES`, in the order a
reader meets them.

* Every ```python block of a page runs, in order, in ONE interpreter session per page
  (cumulative, as the page reads: later blocks use names of earlier ones), from the repository
  root, in a fresh subprocess; every block must print something.
* Every ```sh block whose commands are all ``gmwm ...`` runs in bash, as written, in one empty
  folder (``gmwm`` is this checkout's command, ``python`` this interpreter).
* Every option named in a ```text synopsis of the ``gmwm`` command exists.
* The key lists of the ``--json`` description (docs/cli.md) are the keys the commands print.
* README's first two blocks are the app and the test command, and ``.ci/run`` runs the latter.
"""

from __future__ import annotations

import json
import os
import re
import shlex
import subprocess
import sys
from pathlib import Path

import pytest

from engine.cli import build_parser, main

REPO = Path(__file__).resolve().parents[2]
#: The pages whose code runs, in reading order: the front page, then the documentation.
PAGES = (
    "README.md",
    "docs/getting-started.md",
    "docs/inference.md",
    "docs/multichannel.md",
    "docs/cli.md",
    "docs/datasheet-check.md",
    "docs/reports.md",
)
TEXT = {page: (REPO / page).read_text(encoding="utf-8") for page in PAGES}
README = TEXT["README.md"]
CLI_PAGE = TEXT["docs/cli.md"]  # the `gmwm` command: synopsis and --json description
FENCE = re.compile(r"^```(\w*)\n(.*?)^```", re.S | re.M)
PAGE_BLOCKS = {
    page: [(m.group(1), m.group(2)) for m in FENCE.finditer(t)] for page, t in TEXT.items()
}
BLOCKS = PAGE_BLOCKS["README.md"]


def blocks(lang: str, page: str | None = None) -> list[str]:
    """The code of the ``lang`` blocks of one page, or of every page in reading order."""
    pages = PAGES if page is None else (page,)
    return [code for p in pages for tag, code in PAGE_BLOCKS[p] if tag == lang]


def _env() -> dict[str, str]:
    env = {k: v for k, v in os.environ.items() if k != "GMWM_APP_DEMO"}
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def test_the_first_two_commands_install_and_run_the_app_and_the_tests():
    app, tests = BLOCKS[0][1].strip(), BLOCKS[1][1].strip()
    assert app == "python -m pip install -q -e . && gmwm-app"
    assert tests == 'python -m pip install -q -e ".[test,bench]" && python -m pytest'
    ci = (REPO / ".ci" / "run").read_text()
    assert f"TEST_CMD='{tests}'" in ci and 'eval "$TEST_CMD"' in ci
    # CI runs the tests with the real logs required (a skip would be a failure)
    assert ci.index("export GMWM_REQUIRE_REAL_DATA=1") < ci.index('eval "$TEST_CMD"')


def _run_page(page: str) -> str:
    """Run one page's python blocks in one fresh session; return what they print."""
    code = blocks("python", page)
    mark = "@@README-BLOCK-{}@@"
    script = "\n".join(f"print({mark.format(k)!r})\n{c}" for k, c in enumerate(code))
    p = subprocess.run(
        [sys.executable, "-c", script],
        cwd=REPO,
        env=_env(),
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert p.returncode == 0, (page, p.stderr[-3000:])
    out = p.stdout
    pos = [out.index(mark.format(k)) for k in range(len(code))] + [len(out)]
    for k in range(len(code)):
        printed = out[pos[k] + len(mark.format(k)) : pos[k + 1]].strip()
        assert printed, f"{page}: python block {k + 1} prints nothing:\n{code[k]}"
        assert "\\n" not in printed, f"{page}: block {k + 1} shows an escaped string, not text"
    return out


def test_python_blocks_run_as_written_in_order():
    code = blocks("python")
    assert len(code) >= 3
    assert blocks("python", "README.md"), "the front page has no Python example"
    out = "".join(_run_page(page) for page in PAGES if blocks("python", page))
    # what the tour prints is what it says: the demo, a ranked table, the replicate fit
    assert "demo_imu.h5" in out and "6 channel(s)" in out
    assert "WVIC ranking (63 candidates" in out
    assert "replicate fit of GM+WN+RW to 3 recordings" in out


def test_shell_examples_run_as_written(tmp_path):
    sh = [c for c in blocks("sh") if c.strip()]
    assert sh, "the README has no runnable gmwm example"
    assert any(c.strip() for c in blocks("sh", "README.md")), "the front page has no gmwm example"
    assert any("--filter-rate" in c for c in blocks("sh", "README.md"))
    outs = []
    for code in sh:
        lines = [ln for ln in code.splitlines() if ln.strip() and not ln.startswith("#")]
        assert all(ln.startswith("gmwm ") for ln in lines), code
        prelude = (
            f'gmwm() {{ {shlex.quote(sys.executable)} -m engine.cli "$@"; }}\n'
            f'python() {{ {shlex.quote(sys.executable)} "$@"; }}\n'
        )
        p = subprocess.run(
            ["bash", "-euo", "pipefail", "-c", prelude + code],
            cwd=tmp_path,
            env=_env(),
            capture_output=True,
            text=True,
            timeout=600,
        )
        assert p.returncode == 0 and p.stderr == "", p.stderr[-3000:]
        assert "Traceback" not in p.stdout
        outs.append(p.stdout)
    out = "".join(outs)  # every block's output (the checks below are of the first blocks)
    assert "sim.npy.json" in out and "fs = 100 Hz" in out and "(deg/s)^2" in out
    assert "candidates ranked, best 3 shown" in out
    assert "wrote report.html (interactive" in out and (tmp_path / "report.html").is_file()


def test_synopsis_names_only_options_that_exist():
    parser = build_parser()
    subs = next(a for a in parser._actions if hasattr(a, "choices") and a.choices).choices
    lines = [ln for c in blocks("text") for ln in c.splitlines() if ln.startswith("gmwm ")]
    assert {ln.split()[1] for ln in lines} >= {"wv", "fit", "simulate", "select", "export"}
    for ln in lines:
        sub = subs[ln.split()[1]]
        known = {o for a in sub._actions for o in a.option_strings}
        named = set(re.findall(r"(?<![\w-])(--?[a-zA-Z][\w-]*)", ln))
        assert named <= known, (ln, named - known)


def _described_keys(command: str) -> set[str]:
    m = re.search(rf"^\* `gmwm {command} --json`:[^`]*`([^`]+)`", CLI_PAGE, re.M)
    assert m, f"docs/cli.md does not describe gmwm {command} --json"
    return {k.strip() for k in m.group(1).split(",")}


def test_json_description_lists_the_keys_the_commands_print(tmp_path, capsys):
    log = tmp_path / "s.h5"
    spec = "GM(beta=0.5, sigma2_gm=1e-4)+WN(sigma2=1e-3)"
    assert main(["simulate", "--model", spec, "-n", "20000", "--fs", "100", "-o", str(log)]) == 0
    capsys.readouterr()

    def keys(*argv: str) -> dict:
        assert main([*argv, "--json"]) == 0
        return json.loads(capsys.readouterr().out)

    wv = keys("wv", str(log))
    fit = keys("fit", str(log), "--model", "GM+WN")
    sel = keys("select", str(log), "--max-model", "GM+WN")
    assert _described_keys("wv") == set(wv)
    assert _described_keys("fit") == set(fit)
    assert _described_keys("select") == set(sel)
    # "the object of gmwm wv --json without channel"
    assert set(fit["wv"]) == set(wv) - {"channel"}
    assert set(fit["params"][0]) == {"process", "index", "label", "name", "value", "unit"}
    with pytest.raises(AssertionError):  # the check can fail: a made-up command
        _described_keys("nonsense")
