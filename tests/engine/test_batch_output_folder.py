"""The output folder of ``gmwm batch`` (engine.batch.BatchFolder).

Before: the reports and summaries were written at the very end (a killed batch left
nothing), files of the same names were overwritten whoever wrote them (an input named
``summary.csv`` in the output folder was lost), nothing said when the summary was written,
and a second run fitted everything again.
"""

from __future__ import annotations

import datetime as dt
import json
from pathlib import Path

import numpy as np
import pytest

from engine.batch import BATCH_RECORD, fit_batch
from engine.cli import main
from engine.io import save_log

MODEL = "WN+RW"


@pytest.fixture
def logs(tmp_path: Path) -> list[str]:
    rng = np.random.default_rng(11)
    out = []
    for k in range(4):
        x = rng.normal(size=20_000) + np.cumsum(rng.normal(scale=1e-3 * (k + 1), size=20_000))
        out.append(str(save_log(tmp_path / f"unit{k}.h5", {"gyro_x": x}, 100.0)))
    return out


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


def test_files_it_did_not_write_are_never_overwritten(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, logs: list[str]
) -> None:
    """An input log named summary.csv in the output folder, or a foreign unit0.json: exit 2
    before any fit, naming the file, which is unchanged (before: overwritten)."""
    out = tmp_path / "out"
    out.mkdir()
    own = out / "summary.csv"
    own.write_text("time,gyro_x\n" + "".join(f"{i / 100},{i % 7}\n" for i in range(200)))
    before = own.read_bytes()
    code, _, err = run(capsys, "batch", *logs, str(own), "--model", MODEL, "-o", str(out))
    assert code == 2 and f"'{own}' exists and was not written by gmwm batch" in err
    assert own.read_bytes() == before and not (out / "unit0.json").exists()
    own.unlink()
    foreign = out / "unit0.json"
    foreign.write_text('{"mine": true}\n')
    code, _, err = run(capsys, "batch", *logs, "--model", MODEL, "-o", str(out))
    assert code == 2 and f"'{foreign}' exists and was not written" in err
    assert foreign.read_text() == '{"mine": true}\n' and not (out / "summary.json").exists()


def test_resume_refits_only_what_changed(
    capsys: pytest.CaptureFixture[str], tmp_path: Path, logs: list[str]
) -> None:
    """Second run: every log resumed from its recorded report and the same summary bytes;
    a changed log (content) or other options are fitted again."""
    out = tmp_path / "out"
    assert run(capsys, "batch", *logs, "--model", MODEL, "--quiet", "-o", str(out))[0] == 0
    first = (out / "summary.csv").read_bytes()
    d1 = json.loads((out / "summary.json").read_text())
    assert d1["n_resumed"] == 0 and (out / BATCH_RECORD).exists()
    written = dt.datetime.fromisoformat(d1["written_utc"])
    assert abs((dt.datetime.now(dt.timezone.utc) - written).total_seconds()) < 120
    code, text, _ = run(capsys, "batch", *logs, "--model", MODEL, "--quiet", "-o", str(out))
    assert code == 0 and "(4 resumed from an earlier run)" in text
    assert (out / "summary.csv").read_bytes() == first
    assert json.loads((out / "summary.json").read_text())["n_resumed"] == 4
    x = np.random.default_rng(99).normal(size=20_000)
    save_log(logs[2], {"gyro_x": x}, 100.0)  # new content, same name
    res = fit_batch(logs, workers=1, model=MODEL, output=out)
    assert [lf.resumed for lf in res.logs] == [True, True, False, True]
    res = fit_batch(logs, workers=1, model="WN", output=out)  # other options
    assert not any(lf.resumed for lf in res.logs)


def test_each_report_is_written_as_its_log_completes(tmp_path: Path, logs: list[str]) -> None:
    """A batch stopped after two logs (here: its progress callback raises) has already
    written their two reports; the next run resumes them and fits the other two."""
    out = tmp_path / "out"

    def stop_after_two(done: int, total: int) -> None:
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        fit_batch(logs, workers=1, model=MODEL, output=out, progress=stop_after_two)
    assert sorted(p.name for p in out.glob("unit*.json")) == ["unit0.json", "unit1.json"]
    res = fit_batch(logs, workers=1, model=MODEL, output=out)
    assert [lf.resumed for lf in res.logs] == [True, True, False, False]
    files = res.save(out)
    assert len(files["reports"]) == 4 and (out / "summary.csv").exists()


def test_an_edited_report_is_not_overwritten(tmp_path: Path, logs: list[str]) -> None:
    out = tmp_path / "out"
    fit_batch(logs, workers=1, model=MODEL, output=out).save(out)
    (out / "unit1.json").write_text("edited by hand\n")
    with pytest.raises(ValueError, match=r"unit1.json' exists and was not written by gmwm batch"):
        fit_batch(logs, workers=1, model=MODEL, output=out)
    assert (out / "unit1.json").read_text() == "edited by hand\n"


def test_the_fleet_report_writes_each_report_as_it_completes(
    tmp_path: Path, logs: list[str]
) -> None:
    """``gmwm batch --report R.html -o DIR``: the same folder, written unit by unit."""
    from engine.reporting import gather_fleet

    out = tmp_path / "out"

    def stop_after_two(done: int, total: int) -> None:
        if done == 2:
            raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        gather_fleet(logs, workers=1, model=MODEL, output=out, progress=stop_after_two)
    assert sorted(p.name for p in out.glob("unit*.json")) == ["unit0.json", "unit1.json"]
    (out / "summary.json").write_text("{}\n")  # not the batch's: refused before any fit
    with pytest.raises(ValueError, match="summary.json' exists and was not written"):
        gather_fleet(logs, workers=1, model=MODEL, output=out)
