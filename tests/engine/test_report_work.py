"""What a report computes once: the Bokeh model graph of its figures, and a fleet unit's log
check (the numbers of these steps are tested in test_report.py and test_fleet_report.py; here,
that they are not recomputed, with the same page and the same check as a result)."""

from __future__ import annotations

import numpy as np
import pytest
from bokeh.document.models import DocumentModelManager

import engine as eg
import engine.formats
import engine.io
from engine.reporting import gather_fleet, gather_report, render_fleet_html, render_html


@pytest.fixture(scope="module")
def small_report():
    x = eg.parse_model("WN(1e-6) + RW(1e-12)").simulate(2**13, rng=np.random.default_rng(3))
    y = eg.parse_model("WN(4e-6) + RW(1e-12)").simulate(2**13, rng=np.random.default_rng(4))
    log = eg.ImuLog(
        {"gyro_x": x, "gyro_y": y},
        fs=100.0,
        units={"gyro_x": "rad/s", "gyro_y": "rad/s"},
        source="sim.h5",
    )
    return gather_report(log, model="WN+RW")


def test_figures_model_graph_is_computed_once(small_report, monkeypatch):
    """Bokeh recomputes a document's model graph after each root it adds outside a freeze;
    the report adds every figure under one freeze: one recompute whatever the figure count
    (the figures of one loose ``components()`` call cost one recompute each: quadratic)."""
    calls = []
    real = DocumentModelManager.recompute

    def counted(self):
        calls.append(1)
        return real(self)

    monkeypatch.setattr(DocumentModelManager, "recompute", counted)
    page = render_html(small_report)
    n_figures = page.count('id="fig-')
    assert n_figures >= 8  # two channels, four figures each at least
    assert len(calls) == 1, f"{len(calls)} recomputes for {n_figures} figures"


def test_fleet_unit_log_check_is_made_once_and_reported(tmp_path, monkeypatch):
    """A fleet unit's log is checked by its fit (``fit_log``), and its report shows that
    check: one check per unit, not a second one by the report."""
    paths = []
    for k in range(2):
        x = eg.parse_model("WN(1e-6) + RW(1e-12)").simulate(2**13, rng=np.random.default_rng(k))
        p = tmp_path / f"unit{k}.h5"
        eg.io.save_log(p, {"gyro_x": x}, 100.0, units={"gyro_x": "rad/s"})
        paths.append(str(p))
    checked = []
    real = engine.io.qualify_log

    def counted(log, channels=None):
        checked.append(tuple(channels or ()))
        return real(log, channels)

    monkeypatch.setattr(engine.io, "qualify_log", counted)
    fleet = gather_fleet(paths, model="WN+RW", workers=1)
    assert len(checked) == 2, checked  # one per unit (each was checked twice before)
    for u in fleet.units:
        assert u.report is not None
        assert u.report.log["qualification"] == u.log.qualification
        assert u.report.log["qualification"]["n"] == 2**13
    # the page is made from it as before
    assert render_fleet_html(fleet).count("unit-2") > 0


def test_qualification_goes_with_fits_only(small_report):
    with pytest.raises(TypeError, match="qualification= goes with fits="):
        gather_report(eg.demo_path(), model="WN", qualification={"n": 1})


def test_report_exports_only_its_own_format(monkeypatch):
    """A report fits through ``fit_log`` without its JSON report (the report computes its own
    numbers): the only export made is the format the report includes."""
    made = []
    real = engine.formats.export

    def counted(output, fits, fmt, **kw):
        made.append(fmt)
        return real(output, fits, fmt, **kw)

    monkeypatch.setattr(engine.formats, "export", counted)
    x = eg.parse_model("WN(1e-6) + RW(1e-12)").simulate(2**13, rng=np.random.default_rng(5))
    sim = eg.ImuLog({"gyro_x": x}, fs=100.0, units={"gyro_x": "rad/s"}, source="sim.h5")
    rep = gather_report(sim, model="WN+RW", export_format="kalibr")
    assert made == ["kalibr"] and "gyroscope_noise_density" in rep.export["text"]
