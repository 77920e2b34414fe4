"""The calibration report (``gmwm report``, ``eg.report``): its numbers against ``gmwm fit
--json`` and the engine, its pieces against formulas, its size budget, and the real logs.

The browser tests (the page opens offline, every figure painted) are in
``tests/engine/test_report_in_browser.py``.
"""

from __future__ import annotations

import hashlib
import json
import math
import sys
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import engine as eg
from engine.cli import main
from engine.reporting import ReportError, gather_report, render_html
from engine.reporting.data import welch_psd

MODEL = "GM+WN+RW"
DATASHEET = "arw=0.3 deg/sqrt(h), bi=6 deg/h, rrw=1 deg/h/sqrt(h)"


class _Tables(HTMLParser):
    """The report's tables: ``tables[(class, channel)]`` = rows of ``(text, data-value)``
    cells; and the embedded JSON (``<script id="gmwm-report-data">``)."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: dict[tuple[str, str], list[list[tuple[str, str | None]]]] = {}
        self._table: list[list[tuple[str, str | None]]] | None = None
        self._cell: list[Any] | None = None
        self._json = False
        self.data_json = ""
        self.links: list[str] = []  # every src and href attribute

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        self.links += [v or "" for k, v in attrs if k in ("src", "href")]
        if tag == "table":
            self._table = self.tables.setdefault(
                (a.get("class") or "", a.get("data-channel") or ""), []
            )
        elif tag == "tr" and self._table is not None:
            self._table.append([])
        elif tag in ("td", "th") and self._table is not None:
            self._cell = ["", a.get("data-value")]
        elif tag == "script" and a.get("id") == "gmwm-report-data":
            self._json = True

    def handle_endtag(self, tag: str) -> None:
        if tag == "table":
            self._table = None
        elif tag in ("td", "th") and self._cell is not None and self._table is not None:
            self._table[-1].append((self._cell[0].strip(), self._cell[1]))
            self._cell = None
        elif tag == "script":
            self._json = False

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell[0] += data
        if self._json:
            self.data_json += data


def parse(page: str) -> _Tables:
    t = _Tables()
    t.feed(page)
    return t


def _val(cell: tuple[str, str | None]) -> float:
    assert cell[1] is not None, f"cell {cell[0]!r} has no data-value"
    return float(cell[1])


def _same(a: float | None, b: float) -> bool:
    """Equal numbers, a JSON null (None) and NaN being the same missing value."""
    a = math.nan if a is None else float(a)
    return (math.isnan(a) and math.isnan(b)) or a == b


def run(capsys: pytest.CaptureFixture[str], *argv: str) -> tuple[int, str, str]:
    code = main(list(argv))
    out, err = capsys.readouterr()
    return code, out, err


# --------------------------------------------------------------------------- golden test
def test_report_numbers_equal_gmwm_fit_json(capsys, tmp_path):
    """(a) The golden test: every number of the parameter, datasheet and J-test tables (and
    the embedded JSON fit) equals ``gmwm fit --json --ci asymptotic``'s to the last digit."""
    demo = str(eg.demo_path())
    out = tmp_path / "gyro.html"
    code, text, err = run(
        capsys, "report", demo, "--channels", "gyro_x,accel_y", "--model", MODEL, "-o", str(out)
    )
    assert code == 0, err
    assert str(out) in text and out.is_file()
    page = parse(out.read_text(encoding="utf-8"))
    blob = json.loads(page.data_json)
    assert list(blob["channels"]) == ["gyro_x", "accel_y"]
    for ch in ("gyro_x", "accel_y"):
        code, fit_text, err = run(
            capsys, "fit", demo, "--channel", ch, "--model", MODEL, "--json", "--ci", "asymptotic"
        )
        assert code == 0, err
        fit = json.loads(fit_text)
        # the parameter table: value, low, high of every interval, same order
        rows = page.tables[("params", ch)][1:]
        assert [r[0][0] for r in rows] == [iv["name"] for iv in fit["intervals"]]
        for r, iv in zip(rows, fit["intervals"], strict=True):
            for cell, key in zip(r[1:4], ("value", "low", "high"), strict=True):
                assert _same(iv[key], _val(cell)), (ch, iv["name"], key)
        # the datasheet table: every row of gmwm fit --json's datasheet, same order
        rows = page.tables[("datasheet", ch)][1:]
        assert len(rows) == len(fit["datasheet"]) > 0
        for r, d in zip(rows, fit["datasheet"], strict=True):
            assert (r[0][0], r[1][0], r[2][0], r[6][0]) == (
                d["process"],
                d["quantity"],
                d["symbol"],
                d["unit"],
            )
            for cell, key in zip(r[3:6], ("value", "low", "high"), strict=True):
                assert _same(d[key], _val(cell)), (ch, d["quantity"], key)
        # the embedded JSON holds the same fit (objective, parameters, WV, implied)
        mine = blob["channels"][ch]["fit"]
        for key in ("model_values", "objective", "params", "implied", "components", "wv"):
            assert mine[key] == fit[key], (ch, key)
        assert blob["channels"][ch]["intervals"] == fit["intervals"]
        # the J-test table equals the engine's J-test of the same fit
        log = eg.load_log(demo)
        wv = eg.wavelet_variance(log[ch], fs=log.fs, unit=log.units[ch])
        jt = eg.j_test(eg.fit_gmwm(wv, MODEL))
        (stat, df, p, _method) = page.tables[("jtest", ch)][1]
        assert _val(stat) == jt.statistic and int(df[0]) == jt.df and _val(p) == jt.p_value
    # how it was made: the command line as given, the model, the versions
    prov = blob["provenance"]
    assert prov["command_line"].startswith(f"gmwm report {demo} --channels gyro_x,accel_y")
    assert prov["model"] == MODEL and prov["versions"]["gmwm engine"] == eg.__version__


# --------------------------------------------------------------------------- the pieces
@pytest.fixture(scope="module")
def demo_report():
    """The six-channel demo with a datasheet (gyroscopes checked, accelerometers not)."""
    return gather_report(eg.demo_path(), model=MODEL, datasheet=DATASHEET)


def test_log_facts_and_allan(demo_report):
    """The log section (fingerprint, fs, duration, units) and the Allan deviation against an
    independent computation (:func:`engine.allan_variance` on the raw series)."""
    rep = demo_report
    demo = Path(eg.demo_path())
    assert rep.log["sha256"] == hashlib.sha256(demo.read_bytes()).hexdigest()
    assert rep.log["fs"] == 100.0 and rep.log["n"] == 200_000
    assert rep.log["duration_s"] == 2000.0 and rep.log["units"]["accel_x"] == "m/s^2"
    log = eg.load_log(demo)
    for ch in ("gyro_x", "accel_z"):
        av = rep.channels[ch].allan
        ref = eg.allan_variance(log[ch], fs=log.fs)
        np.testing.assert_allclose(av.avar, ref.avar, rtol=1e-9)
        np.testing.assert_allclose(av.ci_low, ref.ci_low, rtol=1e-9)
        np.testing.assert_allclose(av.ci_high, ref.ci_high, rtol=1e-9)


def test_slope_guides_read_the_datasheet_values(demo_report):
    """The IEEE guides pass through N at T = 1 s, K at T = 3 s (N = sqrt(sigma2/fs),
    K = sqrt(gamma2 fs): docs/conventions.md), with slopes -1/2 and +1/2; the floor is flat at
    0.664 B."""
    ch = demo_report.channels["gyro_x"]
    p, fs = ch.fit.params, ch.fit.fs
    g = {x.code: x for x in ch.guides}
    assert g["WN"].slope == -0.5 and g["RW"].slope == 0.5 and g["BI"].slope == 0.0
    assert math.isclose(g["WN"].adev(np.array([1.0]))[0], math.sqrt(p["WN.sigma2"] / fs))
    assert math.isclose(g["RW"].adev(np.array([3.0]))[0], math.sqrt(p["RW.gamma2"] * fs))
    # four times the averaging time: half (WN) and twice (RW) the deviation
    assert math.isclose(g["WN"].adev(np.array([4.0]))[0], g["WN"].value / 2)
    assert math.isclose(g["RW"].adev(np.array([12.0]))[0], 2 * g["RW"].value)
    assert math.isclose(g["BI"].value, eg.units.BI_FACTOR * g["BI"].datasheet_value)


def test_welch_psd_of_white_noise_is_flat_at_2_sigma2_over_fs():
    """White noise of variance s2 at fs has the one-sided PSD 2 s2 / fs. The model PSD is
    that exactly; the Welch estimate averaged over all bins is within 3 % (8 segments x
    ~2^13 bins: a relative SD under 0.5 %)."""
    fs, s2 = 50.0, 4.0
    x = np.random.default_rng(3).normal(0.0, math.sqrt(s2), 2**17)
    res = eg.fit_gmwm(eg.wavelet_variance(x, fs=fs), "WN")
    sp = welch_psd(x, fs, res)
    assert sp.nperseg == 2**14
    np.testing.assert_allclose(sp.model, 2 * res.params["WN.sigma2"] / fs, rtol=1e-12)
    # band means are means over disjoint bins: weight them back by band width
    assert abs(np.median(sp.welch) / (2 * s2 / fs) - 1) < 0.03
    assert np.all(np.diff(sp.f) > 0) and sp.f[0] > 0 and sp.f[-1] <= fs / 2


def test_datasheet_check_per_channel_kind(demo_report):
    """A gyroscope datasheet is checked on the gyroscopes (the engine's own check) and not
    on the accelerometers, which say why."""
    rep = demo_report
    for ch in ("gyro_x", "gyro_y", "gyro_z"):
        c = rep.channels[ch]
        ref = eg.check_datasheet(c.fit.wv, DATASHEET, fit=c.fit)
        assert c.check.verdict == ref.verdict
        np.testing.assert_array_equal(c.check.datasheet_wv, ref.datasheet_wv)
    for ch in ("accel_x", "accel_y", "accel_z"):
        assert rep.channels[ch].check is None
        assert "gyroscope" in rep.channels[ch].notes["datasheet_check"]


def test_size_budget_of_the_six_channel_demo(demo_report, tmp_path):
    """(c) The six-channel demo report: under 5 MB interactive, under 2 MB static."""
    inter = render_html(demo_report).encode("utf-8")
    static = render_html(demo_report, static=True).encode("utf-8")
    mb = len(inter) / 1e6, len(static) / 1e6
    print(f"six-channel demo: interactive {mb[0]:.2f} MB, static {mb[1]:.2f} MB")
    assert len(inter) < 5e6
    assert len(static) < 2e6
    assert b"<canvas" not in static and b"BokehJS" not in static  # no JavaScript plots
    assert b"data:image/png;base64," in static
    # nothing loaded from outside the file: every src/href is inline data or an anchor
    for page in (inter, static):
        links = parse(page.decode("utf-8")).links
        assert links and all(v.startswith(("data:", "#")) for v in links), links


# --------------------------------------------------------------------------- errors
def test_static_without_matplotlib_says_what_to_install(demo_report, monkeypatch):
    monkeypatch.setitem(sys.modules, "matplotlib.figure", None)  # import fails
    with pytest.raises(ReportError, match=r"pip install 'gmwm-app\[study\]'"):
        render_html(demo_report, static=True)


def test_cli_refuses_bad_output_before_fitting(capsys, tmp_path):
    demo = str(eg.demo_path())
    code, _, err = run(capsys, "report", demo, "--model", "WN", "-o", str(tmp_path / "r.pdf"))
    assert code == 2 and "use a .html or .htm file name" in err and "Traceback" not in err
    code, _, err = run(capsys, "report", demo, "--model", "WN", "-o", str(tmp_path / "no/r.html"))
    assert code == 2 and "does not exist" in err
    code, _, err = run(capsys, "report", demo, "--model", "WN", "-o", "r.html", "--format", "xyz")
    assert code == 2 and "--format 'xyz'" in err and "kalibr" in err


def test_failed_channel_is_listed_not_dropped(tmp_path):
    """A constant channel has no fit: the report lists it with the reason."""
    x = np.random.default_rng(1).normal(size=4096)
    path = tmp_path / "two.h5"
    eg.io.save_log(path, {"gyro_x": x, "gyro_y": np.zeros(4096)}, 100.0, units={"gyro_x": "deg/s"})
    page = eg.report(path, tmp_path / "two.html", model="WN", export_format=None)
    rep = json.loads(parse(page).data_json)
    assert rep["channels"]["gyro_x"]["fit"]["model"] == "WN"
    assert "constant" in rep["channels"]["gyro_y"]["error"]
    assert "not fitted" in page and "constant" in page


# --------------------------------------------------------------------------- real data
def test_report_of_a_real_adis_log(real_data, tmp_path):
    """(d) A real ADIS16405 log (10^6 samples at 100 Hz, deg/s and g): the report's fingerprint
    and numbers are the file's and the engine's."""
    path = real_data / "adis16405_imu1.h5"
    out = tmp_path / "adis.html"
    page = eg.report(path, out, model=MODEL, channels=["gyro_x", "accel_z"])
    rep = json.loads(parse(page).data_json)
    assert rep["log"]["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert rep["log"]["n"] == 1_000_000 and rep["log"]["fs"] == 100.0
    assert rep["log"]["units"]["accel_z"] == "g"
    log = eg.load_log(path)
    for ch in ("gyro_x", "accel_z"):
        res = eg.fit_gmwm(eg.wavelet_variance(log[ch], fs=log.fs, unit=log.units[ch]), MODEL)
        mine = rep["channels"][ch]
        assert mine["fit"]["objective"] == res.objective
        assert [p["value"] for p in mine["fit"]["params"]] == list(res.params.values())
        assert len(mine["psd"]["f"]) > 50 and min(mine["psd"]["welch"]) > 0
    assert "kalibr" in page and out.stat().st_size == len(page.encode("utf-8"))
