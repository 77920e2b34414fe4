"""The fleet acceptance report (``gmwm batch --report``, ``eg.fleet_report``): its numbers
against the engine's batch, the robust z-score against its formula and a planted outlier,
the verdicts against limits, a damaged log listed with its reason, the anchors, the CLI.

The browser test (the page opens offline, every figure painted, size) is in
``tests/engine/test_fleet_report_in_browser.py``.
"""

from __future__ import annotations

import math
from concurrent.futures import ThreadPoolExecutor
from html.parser import HTMLParser
from pathlib import Path
from typing import Any

import numpy as np
import pytest

import engine as eg
from engine.cli import main
from engine.inference import DatasheetError
from engine.io import save_log
from engine.reporting import gather_fleet, render_fleet_html
from engine.reporting.fleet import (
    MIN_UNITS_Z,
    OUTLIER_Z,
    ieee_terms,
    noise_terms,
    parse_limits,
    robust_z,
)

FS = 100.0
N = 2**15
SIGMA2 = 1e-3  # (deg/s)^2: ARW = sqrt(sigma2 / fs) * 60 = 0.1897 deg/sqrt(h)
GAMMA2 = 1e-7
OUTLIER = 3  # the unit whose white noise has 3x the standard deviation (ARW 0.569)
SPEC = "arw<=0.3 deg/sqrt(h)"
ARW_COL = ("WN", "ARW", "deg/sqrt(h)")


class _Page(HTMLParser):
    """Fleet tables ``tables[(class, channel)][unit] = [(text, attrs)]``, ids and hrefs."""

    def __init__(self) -> None:
        super().__init__()
        self.tables: dict[tuple[str, str], dict[str, list[tuple[str, dict[str, Any]]]]] = {}
        self.columns: dict[str, list[str]] = {}
        self.ids: set[str] = set()
        self.hrefs: list[str] = []
        self._t: tuple[str, str] | None = None
        self._row: list[tuple[str, dict[str, Any]]] | None = None
        self._cell: list[Any] | None = None

    def handle_starttag(self, tag: str, attrs: list[tuple[str, str | None]]) -> None:
        a = dict(attrs)
        if "id" in a:
            self.ids.add(a["id"] or "")
        if tag == "a" and a.get("href"):
            self.hrefs.append(a["href"] or "")
        if tag == "table":
            self._t = (a.get("class") or "", a.get("data-channel") or "")
            self.tables.setdefault(self._t, {})
        elif tag == "tr" and self._t is not None:
            self._row = None
            if a.get("data-unit"):
                self._row = self.tables[self._t].setdefault(a["data-unit"] or "", [])
        elif tag == "th" and self._t is not None and a.get("data-column"):
            self.columns.setdefault(self._t[1], []).append(a["data-column"] or "")
        elif tag == "td" and self._row is not None:
            self._cell = ["", a]

    def handle_endtag(self, tag: str) -> None:
        if tag == "table":
            self._t = None
        elif tag == "td" and self._cell is not None and self._row is not None:
            self._row.append((" ".join(self._cell[0].split()), self._cell[1]))
            self._cell = None

    def handle_data(self, data: str) -> None:
        if self._cell is not None:
            self._cell[0] += data


def _parse(html: str) -> _Page:
    p = _Page()
    p.feed(html)
    return p


# ----------------------------------------------------------------------------- pure pieces
def test_robust_z_is_the_median_mad_formula():
    x = np.array([1.0, 2.0, 3.0, 4.0, 100.0])  # median 3, |x - 3| = 2 1 0 1 97: MAD 1
    assert np.allclose(robust_z(x), (x - 3.0) / 1.4826, rtol=0, atol=1e-15)
    # MAD 0 (four equal values): 1.253314 x the mean absolute deviation (0.8)
    z = robust_z([1.0, 1.0, 1.0, 1.0, 5.0])
    assert z[:4].tolist() == [0.0] * 4 and z[4] == pytest.approx(4.0 / (1.253314 * 0.8), 1e-12)
    assert robust_z([2.0] * 6).tolist() == [0.0] * 6
    # NaN stays NaN and does not count; fewer than MIN_UNITS_Z values: no z at all
    z = robust_z([1.0, 2.0, np.nan, 3.0, 4.0, 100.0])
    assert np.isnan(z[2]) and z[5] == pytest.approx(97 / 1.4826)
    assert np.isnan(robust_z([1.0, 2.0, 50.0, 3.0][: MIN_UNITS_Z - 1])).all()


def test_limits_parse_with_the_datasheet_keys_and_units():
    lims = parse_limits(["arw<=0.3 deg/sqrt(h)", "bi <= 5 deg/h, vrw<=0.05 m/s/sqrt(h)"])
    assert [(lim.key, lim.symbol, lim.kind) for lim in lims] == [
        ("arw", "N", "gyroscope"),
        ("bi", "B", "gyroscope"),
        ("vrw", "N", "accelerometer"),
    ]
    # 0.3 deg/sqrt(h) = 0.3 / 60 deg/s/sqrt(Hz) in rad
    assert lims[0].si == pytest.approx(0.3 / 60 * math.pi / 180, rel=1e-14)
    assert lims[0].in_unit("deg/s") == pytest.approx(0.005, rel=1e-14)
    for bad, what in [
        ("arw<0.3 deg/sqrt(h)", "KEY<=VALUE UNIT"),
        ("arw<=0.3 m/s", "not a unit of N"),
        ("foo<=1 deg/h", "unknown datasheet key"),
        ("arw<=0.3 deg/sqrt(h), n<=1 deg/sqrt(h)", "has a limit already"),
    ]:
        with pytest.raises(DatasheetError, match=what):
            parse_limits([bad])


# ----------------------------------------------------------------------------- simulated fleet
@pytest.fixture(scope="module")
def sim_fleet(tmp_path_factory) -> Path:
    """Six gyroscope units of WN+RW (unit 3: 3x the white noise) and one damaged HDF5."""
    d = tmp_path_factory.mktemp("fleet")
    for k in range(6):
        s2 = SIGMA2 * (9.0 if k == OUTLIER else 1.0)
        m = eg.parse_model(f"WN(sigma2={s2})+RW(gamma2={GAMMA2})")
        chans = {c: m.simulate(N, fs=FS, rng=100 + 10 * k + i) for i, c in enumerate(("gx", "gy"))}
        save_log(d / f"unit{k}.h5", chans, FS, units=dict.fromkeys(chans, "deg/s"))
    good = (d / "unit0.h5").read_bytes()
    (d / "damaged.h5").write_bytes(good[: len(good) // 3])  # truncated mid-file
    return d


@pytest.fixture(scope="module")
def sim_report(sim_fleet):
    paths = [str(sim_fleet / "unit*.h5"), str(sim_fleet / "damaged.h5")]
    with ThreadPoolExecutor(2) as ex:  # any Executor, as fit_batch takes
        fleet = gather_fleet(paths, model="WN+RW", spec=[SPEC], executor=ex)
    return fleet, render_fleet_html(fleet), paths


def test_the_table_equals_the_engines_batch_numbers(sim_report):
    fleet, html, paths = sim_report
    batch = eg.fit_batch(paths, model="WN+RW", workers=1)
    # the batch inside the report is the engine's batch, number for number
    assert fleet.batch.summary_csv() == batch.summary_csv()
    page = _parse(html)
    for ch in ("gx", "gy"):
        table = page.tables[("fleet", ch)]
        cols = page.columns[ch]
        assert cols[:3] == ["WN|ARW|deg/sqrt(h)", "RW|RRW|deg/h/sqrt(h)", "model|B|deg/h"]
        # the fit's IEEE quantities follow (engine/fit/ieee.py)
        assert cols[3:] == [
            "IEEE|ARW|deg/sqrt(h)",
            "IEEE|ADEV min|deg/h",
            "IEEE|ADEV min (data)|deg/h",
        ]
        for lf in batch.fitted:
            name = Path(lf.source).name
            fit = lf.fits[ch]
            rows = eg.units.datasheet_rows(
                fit.model, fit.fs, fit.wv.unit, channel=ch, n_levels=fit.wv.n_levels
            )
            want = {
                (t.column[0], t.column[1], t.column[2]): t.value
                for t in noise_terms(rows, "deg/s", ch) + ieee_terms(fit)
            }
            cells = table[name][1:]
            for col, (_, attrs) in zip(cols, cells, strict=True):
                got = float(attrs["data-value"])
                # equal to the last bits: the report ran on a thread pool, the batch in this
                # thread (BLAS sums in another order: 1 ulp apart, seen)
                assert got == pytest.approx(want[tuple(col.split("|"))], rel=1e-12, abs=0)
                lo, hi = float(attrs["data-low"]), float(attrs["data-high"])
                if col != "model|B|deg/h":  # the Allan floor has no interval
                    assert lo < got < hi
        # ARW analytic: sqrt(sigma2 / fs) * 60, within 3 % (sigma2 to ~1 % at N = 2^15)
        arw = {u: float(c[1][1]["data-value"]) for u, c in table.items() if len(c) > 2}
        for k in range(6):
            truth = math.sqrt(SIGMA2 * (9.0 if k == OUTLIER else 1.0) / FS) * 60.0
            assert arw[f"unit{k}.h5"] == pytest.approx(truth, rel=0.03)


def test_the_planted_outlier_is_flagged_and_fails_the_limit(sim_report):
    fleet, html, _ = sim_report
    units = {u.name: u for u in fleet.units}
    for ch in ("gx", "gy"):
        z = {
            n: next(t.z for t in u.terms[ch] if t.column == ARW_COL)
            for n, u in units.items()
            if u.terms
        }
        flagged = sorted(n for n, v in z.items() if abs(v) > OUTLIER_Z)
        assert flagged == [f"unit{OUTLIER}.h5"], z
        assert z[f"unit{OUTLIER}.h5"] > 50  # 3x the SD: far beyond the threshold
    # the limit: ARW 0.19 (interval within 0.3) passes, the outlier's 0.57 fails
    assert {n: u.verdict for n, u in units.items()} == {
        **{f"unit{k}.h5": "pass" for k in range(6) if k != OUTLIER},
        f"unit{OUTLIER}.h5": "fail",
        "damaged.h5": "error",
    }
    why = " ".join(units[f"unit{OUTLIER}.h5"].reasons)
    assert "gx ARW 0.5" in why and "> limit 0.3 deg/sqrt(h)" in why and "robust z" in why
    page = _parse(html)
    cell = page.tables[("fleet", "gx")][f"unit{OUTLIER}.h5"][1]
    assert "outlier" in cell[1]["class"] and float(cell[1]["data-z"]) > OUTLIER_Z


def test_the_damaged_log_is_listed_with_its_reason(sim_report):
    fleet, html, _ = sim_report
    assert [u.name for u in fleet.units] == [*(f"unit{k}.h5" for k in range(6)), "damaged.h5"]
    bad = fleet.units[-1]
    assert bad.report is None and "not a readable HDF5 file" in bad.error
    page = _parse(html)
    row = page.tables[("acceptance", "")]["damaged.h5"]
    assert row[2][0] == "error" and "not a readable HDF5 file" in row[3][0]
    assert "not fitted: LoadError" in page.tables[("fleet", "gx")]["damaged.h5"][1][0]
    assert "unit-7" in page.ids  # its section says why it has no report


def test_every_anchor_leads_to_a_section_and_each_unit_has_its_own(sim_report):
    fleet, html, _ = sim_report
    page = _parse(html)
    local = [h[1:] for h in page.hrefs if h.startswith("#")]
    assert local and not [h for h in local if h not in page.ids]
    for k in range(1, 7):
        assert f"#unit-{k}" in page.hrefs and f"unit-{k}-ch-gx" in page.ids
        # the unit's section is the calibration report's: its figures and tables
        for key in ("adev", "wv", "resid", "psd"):
            assert f"fig-unit-{k}-gx-{key}" in page.ids
    assert html.count('class="params"') == 12  # 6 units x 2 channels


def test_gather_report_takes_existing_fits_without_refitting(sim_fleet):
    log = eg.load_log(str(sim_fleet / "unit0.h5"))
    lf = eg.fit_log(log, model="WN+RW")
    given = eg.reporting.gather_report(log, fits=lf.fits, export_format=None)
    fresh = eg.reporting.gather_report(log, model="WN+RW", export_format=None)
    for ch in ("gx", "gy"):
        assert given.channels[ch].fit is lf.fits[ch]  # the very object: nothing refitted
        a, b = given.channels[ch], fresh.channels[ch]
        assert [r.value for r in a.rows] == [r.value for r in b.rows]
        assert [(i.low, i.high) for i in a.intervals] == [(i.low, i.high) for i in b.intervals]
    assert given.provenance["fits_given"] and not fresh.provenance["fits_given"]
    with pytest.raises(TypeError, match="model cannot be given with fits="):
        eg.reporting.gather_report(log, fits=lf.fits, model="WN")
    with pytest.raises(TypeError, match="does not have"):
        eg.reporting.gather_report(log, fits={"nope": lf.fits["gx"]})


@pytest.mark.slow  # a second fleet fitted and rendered through the CLI: 36 s of CPU
def test_cli_batch_report(sim_fleet, tmp_path, capsys):
    out = tmp_path / "fleet.html"
    argv = ["batch", str(sim_fleet / "unit*.h5"), str(sim_fleet / "damaged.h5")]
    argv += ["--model", "WN+RW", "--report", str(out), "--spec", SPEC, "--workers", "1"]
    assert main([*argv, "--quiet", "-o", str(tmp_path / "dir")]) == 0
    cap = capsys.readouterr()
    assert "damaged.h5: LoadError" in cap.err and f"wrote {out}" in cap.err
    assert "the fleet report" in cap.out and (tmp_path / "dir" / "summary.csv").is_file()
    page = _parse(out.read_text(encoding="utf-8"))
    verdicts = {u: r[2][0] for u, r in page.tables[("acceptance", "")].items()}
    assert verdicts[f"unit{OUTLIER}.h5"] == "fail" and verdicts["damaged.h5"] == "error"
    # refusals before any fit: a bad limit, a limit without --report, a bad report name
    for extra, msg in [
        (["--report", str(out), "--spec", "arw<0.3 deg/sqrt(h)"], "KEY<=VALUE UNIT"),
        (["-o", str(tmp_path / "d2"), "--spec", SPEC], "apply to --report"),
        (["--report", str(tmp_path / "fleet.txt")], ".html"),
        ([], "give -o DIR"),
    ]:
        assert main([*argv[:5], *extra, "--quiet"]) == 2
        assert msg in capsys.readouterr().err


# ----------------------------------------------------------------------------- real fleet
@pytest.mark.slow  # six real logs fitted in worker processes: 27 s of CPU
def test_real_fleet_numbers_equal_the_batch(real_data, tmp_path):
    files = [str(real_data / f"adis16405_imu{k}.h5") for k in range(1, 7)]
    fleet = gather_fleet(files, model="GM+WN+RW", channels=["gyro_x"], workers=2)
    batch = eg.fit_batch(files, model="GM+WN+RW", channels=["gyro_x"], workers=1)
    assert fleet.batch.summary_csv() == batch.summary_csv()
    assert [u.verdict for u in fleet.units] == ["not checked"] * 6
    page = _parse(render_fleet_html(fleet))
    table = page.tables[("fleet", "gyro_x")]
    cols = page.columns["gyro_x"]
    for lf in batch.logs:
        fit = lf.fits["gyro_x"]
        rows = eg.units.datasheet_rows(fit.model, fit.fs, fit.wv.unit, n_levels=fit.wv.n_levels)
        terms = noise_terms(rows, fit.wv.unit, "gyro_x") + ieee_terms(fit)
        want = {"|".join(t.column): t.value for t in terms}
        got = {
            c: float(a["data-value"])
            for c, (_, a) in zip(cols, table[Path(lf.source).name][1:], strict=True)
        }
        assert got == pytest.approx(want, rel=1e-12, abs=0)  # worker processes vs here


# ----------------------------------------------------------------------------- temperature
THERMAL_C = 2e-3  # deg/s per degC = 7.2 deg/h per degC
THERMAL_N = 2**16
THERMAL_SPEC = "WN(sigma2=1e-4)+RW(gamma2=1e-10)"  # (deg/s)^2, as the report temperature tests
TEMP_COL = "temperature|S_T|deg/h/degC"


@pytest.fixture(scope="module")
def thermal_fleet(tmp_path_factory):
    """Three gyro units with a temperature column (the planted 7.2 deg/h/degC) and a fourth
    without one; the fleet report of the four, its page and the compensated fits' own
    sensitivities."""
    d = tmp_path_factory.mktemp("thermal_fleet")
    t = np.arange(THERMAL_N) / FS
    temp = 25 + 5 * (1 - np.exp(-t / 120)) + 2 * np.sin(2 * np.pi * t / 90)
    m = eg.parse_model(THERMAL_SPEC)
    for k in range(4):
        x = m.simulate(THERMAL_N, fs=FS, rng=500 + k) + THERMAL_C * temp
        chans = {"gx": x, "temperature": temp} if k < 3 else {"gx": x}
        units = {"gx": "deg/s", "temperature": "degC"}
        save_log(d / f"unit{k}.csv", chans, FS, units={c: units[c] for c in chans})
    fleet = gather_fleet([str(d / "unit*.csv")], model="WN+RW", channels=["gx"], workers=1)
    return fleet, _parse(render_fleet_html(fleet))


def test_the_fleet_table_has_each_units_temperature_sensitivity(thermal_fleet):
    """The gx table has a column ``temperature S_T [deg/h/degC]``: for each unit with a
    temperature channel, its fit's sensitivity and 95 % interval (which covers the planted
    7.2 deg/h/degC on each of the three seeds: 98 % coverage over 200 logs, docs/qualify.md),
    and a dash for the unit without one."""
    fleet, page = thermal_fleet
    cols = page.columns["gx"]
    assert cols.count(TEMP_COL) == 1
    table = page.tables[("fleet", "gx")]
    i = cols.index(TEMP_COL) + 1
    units = {u.name: u for u in fleet.units}
    for k in range(3):
        name = f"unit{k}.csv"
        tf = units[name].report.channels["gx"].temperature
        assert tf is not None and tf.sensitivity_unit == "deg/h/degC"
        text, attrs = table[name][i]
        got, lo, hi = (float(attrs[a]) for a in ("data-value", "data-low", "data-high"))
        assert (got, (lo, hi)) == (tf.sensitivity, tf.sensitivity_interval)
        assert lo < 7.2 < hi and hi - lo < 7.2, (name, lo, hi)
        assert f"{got:.4g}" in text
    assert table["unit3.csv"][i] == ("—", {"class": "n", "data-value": "nan"})
    assert units["unit3.csv"].report.channels["gx"].temperature is None
    # the batch's summary has the same figure (one declaration: TemperatureFit.SYMBOL)
    rows = [r for r in fleet.batch.rows if r.symbol == "S_T"]
    assert [(r.channel, r.unit, r.n_units) for r in rows] == [("gx", "deg/h/degC", 3)]


@pytest.fixture(scope="module")
def marked_fleet(tmp_path_factory):
    """Two gyro units with a temperature column under the same profile: one with the planted
    7.2 deg/h/degC (compensated), one with none (seed 503: p = 0.45, so ``auto`` leaves its
    signal raw and its sensitivity, 0.30 [-0.48, 1.07] deg/h/degC, is information only)."""
    d = tmp_path_factory.mktemp("marked_fleet")
    t = np.arange(THERMAL_N) / FS
    temp = 25 + 5 * (1 - np.exp(-t / 120)) + 2 * np.sin(2 * np.pi * t / 90)
    m = eg.parse_model(THERMAL_SPEC)
    for k, c in ((500, THERMAL_C), (503, 0.0)):
        x = m.simulate(THERMAL_N, fs=FS, rng=k) + c * temp
        units = {"gx": "deg/s", "temperature": "degC"}
        save_log(d / f"unit{k}.csv", {"gx": x, "temperature": temp}, FS, units=units)
    fleet = gather_fleet([str(d / "unit*.csv")], model="WN+RW", channels=["gx"], workers=1)
    return fleet, _parse(render_fleet_html(fleet))


def test_a_sensitivity_not_compensated_is_marked(marked_fleet):
    """The ``temperature S_T`` column marks the unit whose channel was not compensated, with
    the test's p-value ("not compensated (p = 0.45)"), in the page's cell, in the fleet's JSON
    (the term's ``note``) and in the batch's summary (CSV and JSON: its own quantity, ``bias
    temperature sensitivity, not compensated``, pooled apart from the compensated units');
    the compensated unit is not marked. Before, both showed a bare number."""
    from engine.inference.temperature import TemperatureFit

    fleet, page = marked_fleet
    units = {u.name: u for u in fleet.units}
    comp = units["unit500.csv"].report.channels["gx"].temperature
    raw = units["unit503.csv"].report.channels["gx"].temperature
    assert comp.applied and not raw.applied and raw.p_value == pytest.approx(0.45, abs=0.005)
    lo, hi = raw.sensitivity_interval
    assert lo < 0 < hi
    cols = page.columns["gx"]
    i = cols.index(TEMP_COL) + 1
    table = page.tables[("fleet", "gx")]
    text, attrs = table["unit503.csv"][i]
    assert attrs["data-note"] == "not compensated (p = 0.45)"
    assert text.endswith("not compensated (p = 0.45)") and float(attrs["data-value"]) == (
        raw.sensitivity
    )
    text, attrs = table["unit500.csv"][i]
    assert "data-note" not in attrs and "not compensated" not in text
    d = fleet.to_dict()
    notes = {
        u["name"]: [t["note"] for t in u["terms"]["gx"] if t["symbol"] == "S_T"] for u in d["units"]
    }
    assert notes == {"unit500.csv": [""], "unit503.csv": ["not compensated (p = 0.45)"]}
    rows = {r.quantity: r for r in fleet.batch.rows if r.symbol == "S_T"}
    assert set(rows) == {TemperatureFit.QUANTITY, TemperatureFit.QUANTITY_NOT_APPLIED}
    assert rows[TemperatureFit.QUANTITY].mean == comp.sensitivity
    assert rows[TemperatureFit.QUANTITY_NOT_APPLIED].mean == raw.sensitivity
    csv = fleet.batch.summary_csv()
    assert "bias temperature sensitivity, not compensated" in csv
    status = {Path(s["source"]).name: s for s in fleet.batch.to_dict()["logs"]}
    t = status["unit503.csv"]["temperature"]["gx"]
    assert t["compensated"] is False and t["p_value"] == raw.p_value


@pytest.fixture(scope="module")
def mixed_fleet(tmp_path_factory):
    """Five gyro units with the planted 7.2 deg/h/degC (compensated) and the unit of seed 503
    with none (p = 0.45: left raw, its sensitivity 0.30 deg/h/degC information only), under
    the same temperature profile."""
    d = tmp_path_factory.mktemp("mixed_fleet")
    t = np.arange(THERMAL_N) / FS
    temp = 25 + 5 * (1 - np.exp(-t / 120)) + 2 * np.sin(2 * np.pi * t / 90)
    m = eg.parse_model(THERMAL_SPEC)
    for k, c in ((500, THERMAL_C), (501, THERMAL_C), (502, THERMAL_C), (504, THERMAL_C),
                 (505, THERMAL_C), (503, 0.0)):  # fmt: skip
        x = m.simulate(THERMAL_N, fs=FS, rng=k) + c * temp
        units = {"gx": "deg/s", "temperature": "degC"}
        save_log(d / f"unit{k}.csv", {"gx": x, "temperature": temp}, FS, units=units)
    return gather_fleet([str(d / "unit*.csv")], model="WN+RW", channels=["gx"], workers=1)


def test_outlier_scores_compare_a_sensitivity_only_with_comparable_units(mixed_fleet):
    """A sensitivity not compensated is its own quantity: its robust z-score is computed among
    the units that share it (here none besides itself: fewer than MIN_UNITS_Z, so no score
    and no outlier), and the five compensated units are scored among themselves (the robust z
    of their five sensitivities). Before, the six were pooled and the unit left raw (0.30
    against a median of 7.2 deg/h/degC) was reported as an outlier."""
    from engine.reporting.fleet import robust_z

    units = {u.name: u for u in mixed_fleet.units}

    def s_t(name):
        (v,) = [v for v in units[name].terms["gx"] if v.column[1] == "S_T"]
        return v

    raw = s_t("unit503.csv")
    assert raw.note.startswith("not compensated") and math.isnan(raw.z) and not raw.outlier
    assert not any("S_T" in r for r in units["unit503.csv"].reasons)
    comp = ["unit500.csv", "unit501.csv", "unit502.csv", "unit504.csv", "unit505.csv"]
    vals = [s_t(n) for n in comp]
    assert all(v.note == "" for v in vals)
    want = robust_z([v.value for v in vals])
    np.testing.assert_allclose([v.z for v in vals], want, rtol=1e-12)
    med = float(np.median([v.value for v in vals]))
    np.testing.assert_allclose([v.rel for v in vals], [(v.value - med) / med for v in vals])
