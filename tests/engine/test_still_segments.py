"""Still segments of a flight log and the pooled WV of several segments, against simulated
still-move-still flights whose motion is known (tests/fixtures/make_flight_logs.py)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from flightlogs import make

import engine as eg
from engine.cli import main
from engine.io.segments import still_segments, with_segments
from engine.wv.pooled import pooled_wavelet_variance

FS = 250.0


def _log(fl: make.Flight) -> eg.ImuLog:
    ch = {f"gyro_{a}": fl.gyro[:, i] for i, a in enumerate("xyz")}
    ch |= {f"accel_{a}": fl.accel[:, i] for i, a in enumerate("xyz")}
    return eg.ImuLog(ch, fs=FS, units=dict.fromkeys(ch, ""), source="sim")


def test_one_piece_is_the_plain_wv() -> None:
    x = np.random.default_rng(0).normal(size=5000)
    a, b = pooled_wavelet_variance([x], fs=10.0), eg.wavelet_variance(x, fs=10.0)
    np.testing.assert_array_equal(a.variance, b.variance)
    np.testing.assert_array_equal(a.ci_low, b.ci_low)
    np.testing.assert_array_equal(a.n_coef, b.n_coef)


def test_pooled_is_the_coefficient_weighted_mean() -> None:
    """nu2_j = sum_s M_js nu2_js / sum_s M_js; a piece shorter than 2^j adds nothing."""
    rng = np.random.default_rng(1)
    pieces = [rng.normal(size=n) for n in (3000, 700, 40)]
    wv = pooled_wavelet_variance(pieces, levels=8)
    per = [eg.wavelet_variance(p, levels=min(8, eg.wv.default_levels(p.size))) for p in pieces]
    for j in range(8):
        m = [w.n_coef[j] for w in per if w.n_levels > j]
        v = [w.variance[j] for w in per if w.n_levels > j]
        assert wv.n_coef[j] == sum(m) == sum(max(p.size - 2 ** (j + 1) + 1, 0) for p in pieces)
        assert wv.variance[j] == pytest.approx(np.dot(m, v) / sum(m), rel=1e-12)
    assert wv.n == 3740


def test_segments_find_the_still_parts() -> None:
    """On 3 simulated flights (still 20 s, move 10 s, still 20 s, still 15 s): no moving
    sample is in a segment and at least 90 % of the still samples are."""
    for seed in range(3):
        fl = make.simulate_flight(FS, still_s=(20.0, 20.0, 15.0), move_s=10.0, seed=seed)
        segs = still_segments(_log(fl))
        inside = np.zeros(fl.moving.size, bool)
        for a, b in segs:
            inside[a:b] = True
        assert len(segs) == 3
        assert not np.any(inside & fl.moving)
        assert inside[~fl.moving].mean() >= 0.9


def test_pooled_still_wv_equals_the_still_only_wv() -> None:
    """The pooled WV of the auto segments of a still-move-still flight lies within the 95 %
    interval of the still-only WV (the same noise without the motion) at every level with
    at least 64 coefficients, in 20 replicates: at most 20 x 11 x 5 % = 11 misses are
    expected by chance if they were independent; we allow 10 % of the level checks (binomial
    p of exceeding ~0.02 at 5 % per check). The WV of the whole flight is far off (> 100 x at
    level 4). The truth sigma^2 / 2 at level 1 is inside the pooled 95 % interval in at least
    16 of the 20 replicates."""
    checks = misses = truth_misses = 0
    for seed in range(20):
        fl = make.simulate_flight(FS, still_s=(20.0, 20.0), move_s=10.0, seed=seed)
        noise = make.simulate_flight(FS, still_s=(20.0, 20.0), move_s=10.0, seed=seed, motion=0.0)
        log = with_segments(_log(fl), "auto")
        pooled = log.wavelet_variance("gyro_x")
        ref = eg.wavelet_variance(noise.gyro[~fl.moving, 0], fs=FS, levels=pooled.n_levels)
        ok = pooled.n_coef >= 64
        inside = (pooled.variance >= ref.ci_low) & (pooled.variance <= ref.ci_high)
        checks += int(ok.sum())
        misses += int((ok & ~inside).sum())
        whole = _log(fl).wavelet_variance("gyro_x", levels=pooled.n_levels)
        assert whole.variance[3] > 100 * pooled.variance[3]
        # and the truth: white noise sigma^2 / tau at level 1 within the pooled interval
        truth_misses += not pooled.ci_low[0] <= fl.gyro_sigma**2 / 2 <= pooled.ci_high[0]
    assert misses <= 0.1 * checks
    assert truth_misses <= 4  # binomial(20, 0.05): P(>= 5) = 0.003


def test_fit_on_segments_recovers_the_noise(tmp_path: Path, capsys) -> None:
    """`gmwm fit flight.ulg --segments auto --model WN`: sigma2 = 1.6e-5 (rad/s)^2 within 5
    sampling sigmas (sqrt(2/n), n = 9750 still samples); the whole flight gives > 10 x."""
    pytest.importorskip("pyulog")
    fl = make.simulate_flight(FS, still_s=(20.0, 20.0), move_s=10.0, seed=7)
    ulg = make.write_ulog(tmp_path / "flight.ulg", fl)
    assert main(["fit", str(ulg), "--model", "WN", "--segments", "auto", "--json"]) == 0
    out = json.loads(capsys.readouterr().out)
    n = int((~fl.moving).sum())
    assert out["params"][0]["value"] == pytest.approx(fl.gyro_sigma**2, rel=5 * np.sqrt(2 / n))
    assert main(["fit", str(ulg), "--model", "WN", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["params"][0]["value"] > 10 * fl.gyro_sigma**2
    assert main(["segments", str(ulg), "--json"]) == 0
    segs = json.loads(capsys.readouterr().out)["segments"]
    assert [(s["start"], s["stop"]) for s in segs] == still_segments(eg.load_log(ulg))


def test_segment_errors() -> None:
    fl = make.simulate_flight(FS, still_s=(20.0, 20.0), move_s=10.0, seed=1)
    log = _log(fl)
    with pytest.raises(eg.LoadError, match="START:STOP"):
        with_segments(log, "0-100")
    with pytest.raises(eg.LoadError, match="inside the log"):
        with_segments(log, "0:99999999")
    with pytest.raises(eg.LoadError, match="no still segment"):
        with_segments(log, "auto", min_s=1000.0)
    two = with_segments(log, "0:5000,7500:12500")
    assert two.segments == ((0, 5000), (7500, 12500))
    assert two.wavelet_variance("gyro_x").n == 10000


@pytest.mark.real_data
def test_a_real_still_log_is_one_segment(real_data: Path) -> None:
    """A real static log (ADIS16405 replicate 2, the first 100 000 samples) is still
    throughout: one segment covering at least 99 % of it, whose pooled WV is the plain WV."""
    log = eg.load_log(real_data / "adis16405_imu2.h5", segment=(0, 100_000))
    segs = still_segments(log)
    assert len(segs) == 1 and (segs[0][1] - segs[0][0]) >= 0.99 * log.n
    seg = with_segments(log, "auto")
    a = seg.wavelet_variance("gyro_x", levels=10)
    b = eg.wavelet_variance(log["gyro_x"][segs[0][0] : segs[0][1]], fs=log.fs, levels=10)
    np.testing.assert_allclose(a.variance, b.variance, rtol=1e-12)


def test_report_shows_the_segments_in_time() -> None:
    """The report of a flight analysed on its segments: a time plot per channel whose shaded
    bands are the segments in seconds, the log's segments in its info, the PSD of the longest
    segment (its note), and the WV the pooled one."""
    from engine.reporting import gather_report
    from engine.reporting.render import figure_specs

    fl = make.simulate_flight(FS, still_s=(20.0, 20.0), move_s=10.0, seed=2)
    log = with_segments(_log(fl), "auto")
    rep = gather_report(log, model="WN", channels=["gyro_x"])
    ch = rep.channels["gyro_x"]
    assert ch.timeline is not None
    assert ch.timeline.segments == [(a / FS, b / FS) for a, b in log.segments]
    assert rep.log["segments"] == [list(p) for p in log.segments]
    assert "longest still segment" in ch.notes["psd"]
    assert ch.fit is not None
    np.testing.assert_array_equal(ch.fit.wv.variance, log.wavelet_variance("gyro_x").variance)
    spec = figure_specs(rep)["gyro_x-segments"]
    assert not spec.log_x and len(spec.layers) == 1 + len(log.segments)
    # the envelope holds every sample, the last partial block too (12500 = 1785 x 7 + 5)
    x = fl.gyro[:, 0]
    assert ch.timeline.t.size == 1786 and ch.timeline.high[-1] == x[-5:].max()
    assert ch.timeline.low.min() == x.min() and ch.timeline.high.max() == x.max()
