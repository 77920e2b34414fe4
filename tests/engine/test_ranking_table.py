"""The full ranking of the default maximal model's 47 sub-models is the one the code before the
ranking's speed-up computed: the same order, the same selection, every candidate's objective,
WVIC and J statistic to a relative 1e-6 (the searches stop at a relative 1e-10 of the
objective). The reference tables were computed by that code (main at eb52a4d, extracted from
git), not by the code under test: ``tests/fixtures/make_ranking_tables.py`` says how.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest

import engine as eg
from engine.demo import demo_path
from engine.inference import rank_models
from engine.inference.selection import DEFAULT_SELECT

TABLES = Path(__file__).resolve().parents[1] / "fixtures" / "ranking_tables.json"
RTOL = 1e-6


def _stored(label: str) -> dict:
    data = json.loads(TABLES.read_text(encoding="utf-8"))
    assert data["max_model"] == DEFAULT_SELECT
    return data["tables"][label]


def _assert_same(path: Path, channel: str, label: str) -> None:
    ref = _stored(label)
    sel = rank_models(eg.load_log(path).wavelet_variance(channel), max_model=DEFAULT_SELECT)
    assert [c.model for c in sel.candidates] == [r["model"] for r in ref["candidates"]]
    for c, r in zip(sel.candidates, ref["candidates"], strict=True):
        for key in ("objective", "criterion", "j_stat"):
            got, want = getattr(c, key), r[key]
            if want is None:
                assert not math.isfinite(got), (c.model, key, got)
            else:
                assert got == pytest.approx(want, rel=RTOL, abs=0), (c.model, key)
    assert sel.best.model == ref["selected"]
    assert sel.best.objective == pytest.approx(ref["selected_objective"], rel=RTOL, abs=0)


def test_demo_ranking_table_is_unchanged() -> None:
    _assert_same(demo_path(), "gyro_z", "demo gyro_z")


@pytest.mark.real_data
def test_adis_ranking_table_is_unchanged(real_data: Path) -> None:
    _assert_same(real_data / "adis16405_imu1.h5", "accel_x", "adis16405_imu1 accel_x")
