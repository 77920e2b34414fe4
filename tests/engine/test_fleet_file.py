"""The fleet file: one filter file for several units of one sensor model.

``engine.export(..., fleet=)`` and ``engine.batch.export_fleet`` write, per axis, the largest
white-noise density N and random walk K of the units' own default exports. A WN+RW file's WV
grows with each of them, so the fleet file's WV is at least every unit's bound target (its
fitted WV and its empirical WV's lower 95 % limit times its tail factors) over the band: no
unit is exported overconfident. Checked on simulated units (exact invariants: a fleet of one
unit repeated is that unit's file; the noisier unit sets each value) and on two ADIS16405 units
whose accelerometer random walks differ by x1.9 (the file read back, its WV against each unit's
data). The slow test runs the filter on the six units' recorded accelerometers with fixes every
100 s (``tests/benchmarks/filter_fleet_spread.py``, docs/filters.md "One file for a fleet").
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest
import yaml

import engine as eg
from engine.batch import export_fleet, fit_log
from engine.formats import FORMATS
from engine.formats.tails import log_tail_factors
from engine.units import ExportError, si_factor

FS = 100.0
CHANNELS = ("gyro_x", "accel_x")
UNITS = {"gyro_x": "rad/s", "accel_x": "m/s^2"}


def _sim_fits(seed: int, k_scale: float) -> dict[str, eg.GMWMResult]:
    """WN+RW fits of a simulated gyro_x and accel_x (random walk variance x ``k_scale**2``)."""
    rng = np.random.default_rng(seed)
    out = {}
    for ch, (s2, g2) in {"gyro_x": (1e-6, 1e-12), "accel_x": (1e-4, 1e-9)}.items():
        m = eg.parse_model(f"WN({s2}) + RW({g2 * k_scale**2})")
        x = m.simulate(2**15, rng=rng)
        out[ch] = eg.fit_gmwm(eg.wavelet_variance(x, fs=FS, unit=UNITS[ch]), "WN + RW")
    return out


def _kalibr_values(text: str) -> dict[str, float]:
    """The four Kalibr keys of a written file, read back."""
    d = yaml.safe_load(text)
    keys = ("gyroscope", "accelerometer")
    return {
        f"{k}_{q}": float(d[f"{k}_{q}"]) for k in keys for q in ("noise_density", "random_walk")
    }


@pytest.fixture(scope="module")
def sim_units():
    return _sim_fits(1, 1.0), _sim_fits(2, 2.0)


def test_fleet_of_one_unit_repeated_is_that_units_file(sim_units):
    a, _ = sim_units
    own = _kalibr_values(eg.export(None, a, "kalibr", ci=None))
    fleet = _kalibr_values(eg.export(None, a, "kalibr", ci=None, fleet=[("again", a, None)]))
    assert fleet == own


def test_fleet_file_takes_the_largest_value_of_each_unit(sim_units):
    a, b = sim_units
    own_a = _kalibr_values(eg.export(None, a, "kalibr", ci=None))
    own_b = _kalibr_values(eg.export(None, b, "kalibr", ci=None))
    text = eg.export(None, a, "kalibr", ci=None, source="a.h5", fleet=[("b.h5", b, None)])
    fleet = _kalibr_values(text)
    for key, v in fleet.items():
        assert v == max(own_a[key], own_b[key]), key
    # unit b's random walk is simulated x2 unit a's: it sets K, and the header says so
    assert fleet["accelerometer_random_walk"] == own_b["accelerometer_random_walk"]
    assert own_b["accelerometer_random_walk"] > 1.5 * own_a["accelerometer_random_walk"]
    assert "# fleet accelerometer K x:" in text and "from b.h5" in text
    # the same in a per-step format: PX4's values at the filter rate are the fleet's
    px4 = eg.export(None, a, "px4", ci=None, filter_rate=FS, fleet=[("b.h5", b, None)])
    px4_b = eg.export(None, b, "px4", ci=None, filter_rate=FS)
    acc = [line for line in px4.splitlines() if "EKF2_ACC_B_NOISE" in line]
    assert acc and acc == [line for line in px4_b.splitlines() if "EKF2_ACC_B_NOISE" in line]


@pytest.mark.parametrize(
    ("fmt", "kw", "match"),
    [
        ("kf-gins", {}, "Gauss-Markov bias has a correlation time per unit"),
        ("gazebo", {}, "Gauss-Markov bias has a correlation time per unit"),
        ("json", {}, "a fleet file is a filter format's"),
        ("kalibr", {"projection": "fit"}, "a fleet file is a filter format's"),
    ],
)
def test_fleet_file_refuses_what_it_cannot_bound(sim_units, fmt, kw, match):
    a, b = sim_units
    with pytest.raises(ExportError, match=match):
        eg.export(None, a, fmt, ci=None, fleet=[("b.h5", b, None)], **kw)


def test_the_format_record_says_which_formats_take_a_fleet(sim_units, monkeypatch):
    # the record's capability (Format.fleet_file) is what export does: a fleet file is written
    # for exactly the filter formats that declare it, and the others are refused by export
    # from the record, before their writer runs
    a, b = sim_units
    filters = {n: f for n, f in FORMATS.items() if f.is_filter}
    declared = {n for n, f in filters.items() if f.fleet_file}
    assert declared == {n for n, f in filters.items() if f.consumer in ("WN+RW", "WN")}
    assert {"kalibr", "openvins", "px4", "ros-imu"} <= declared
    assert not declared & {"gazebo", "gz-sim", "kf-gins"}
    for name, f in filters.items():
        kw = {"filter_rate": FS} if f.needs_filter_rate else {}
        if name in declared:
            assert eg.export(None, a, name, ci=None, fleet=[("b.h5", b, None)], **kw)
    ran: list[str] = []
    for name, f in filters.items():
        kw = {"filter_rate": FS} if f.needs_filter_rate else {}
        if name in declared:
            continue
        spy = dataclasses.replace(f, write=lambda fits, o, name=name: ran.append(name) or "")
        monkeypatch.setitem(FORMATS, name, spy)
        with pytest.raises(ExportError, match="correlation time per unit"):
            eg.export(None, a, name, ci=None, fleet=[("b.h5", b, None)], **kw)
    assert ran == []  # refused by the record, not inside the writers


def test_fleet_unit_without_a_channel_is_named(sim_units):
    a, b = sim_units
    with pytest.raises(ExportError, match=r"fleet unit b\.h5: no accelerometer axis x"):
        eg.export(
            None, a, "kalibr", ci=None, allow_partial=True,
            fleet=[("b.h5", {"gyro_x": b["gyro_x"]}, None)],
        )  # fmt: skip


# ------------------------------------------------------------------------------------------
# the signal the fits were made on: warm-up cut, temperature compensated
# ------------------------------------------------------------------------------------------
N_SIM = 2**17
#: planted gyro_x noise (rad/s): white noise 1e-6 per sample (N = 1e-4 rad/s/sqrt(Hz) at
#: 100 Hz) and random walk 1e-12 per sample (K = 1e-5 rad/s^2/sqrt(Hz))
SIM_SPEC = "WN(1e-6) + RW(1e-12)"
N_TRUE = 1e-4


def _gyro_density(text: str) -> float:
    return float(yaml.safe_load(text)["gyroscope_noise_density"])


def _write_units(tmp_path, make) -> list[str]:
    """Two simulated gyro_x logs (seeds 1, 2) of ``SIM_SPEC`` plus ``make(t, rng)``'s
    channels, as HDF5 files."""
    paths = []
    for seed in (1, 2):
        rng = np.random.default_rng(seed)
        t = np.arange(N_SIM) / FS
        x = eg.parse_model(SIM_SPEC).simulate(N_SIM, rng=rng)
        chans = make(t, x)
        path = tmp_path / f"unit{seed}.h5"
        eg.io.save_log(path, chans, FS, units={"gyro_x": "rad/s", "imu_temp": "degC"})
        paths.append(str(path))
    return paths


def _fleet_text(units: list) -> str:
    """``eg.export`` of a Kalibr fleet file (gyro only) from ``(source, fits, log)`` units: the
    first unit's fits and log, the others as ``fleet=``; the logs' tail factors."""
    (src, fits, log), rest = units[0], units[1:]
    return eg.export(
        None, fits, "kalibr", allow_partial=True, ci=None, log=log, source=src, fleet=rest
    )


def test_fleet_file_reads_the_log_without_the_warmup_the_fit_dropped(tmp_path):
    """A warm-up transient of 10 white-noise SDs (1e-2 rad/s, time constant 60 s) in both
    units: ``fit_batch(drop_warmup=True)`` fits the log after it, and the fleet file's tail
    factors must read that signal too. In the raw log the transient gives tail factors of
    1.3-2.1 at 5-20 s, which raise the file's white-noise density to x1.2-1.4 the planted 1e-4
    (1.36e-4 in the fleet file); without it the file is the two units' own exports of the cut
    logs (``gmwm export`` of each), and its density is the planted one within 3 %."""
    from engine.io import drop_warmup, qualify_log

    paths = _write_units(tmp_path, lambda t, x: {"gyro_x": x + 1e-2 * np.exp(-t / 60.0)})
    batch = eg.fit_batch(paths, workers=1, model="WN+RW", channels=["gyro_x"], drop_warmup=True)
    lfs = batch.logs
    assert all(lf.ok for lf in lfs), [lf.error for lf in lfs]
    text = export_fleet(None, lfs, "kalibr", allow_partial=True, ci=None)
    cut, raw, starts = [], [], []
    for lf in lfs:
        log = eg.load_log(lf.source)
        starts.append(qualify_log(log, ["gyro_x"]).suggested_start)
        cut.append((lf.source, lf.fits, drop_warmup(log, starts[-1])))
        raw.append((lf.source, lf.fits, log))
    assert starts == [26_112, 28_160]  # 4.4 and 4.7 time constants
    assert text == _fleet_text(cut)
    assert _gyro_density(text) == pytest.approx(N_TRUE, rel=0.03)
    assert (
        _gyro_density(_fleet_text(raw)) > 1.2 * N_TRUE
    )  # the premise: the raw log's tails inflate it
    assert [lf.warmup_dropped for lf in lfs] == starts  # what LogFit.prepared cuts


def test_fleet_file_reads_the_temperature_compensated_signal(tmp_path):
    """A bias of 2e-4 rad/s per degC (41 deg/h/degC) and a temperature that warms up by 10 degC
    and steps by 4 degC every 5 min (a heater cycling): ``fit_log`` compensates it (its
    ``temperature="auto"``), and the fleet file's tail factors must read the compensated
    signal. The raw signal's steps give tail factors 1.8-3.0 at 5-20 s (a density x1.6-1.7
    the planted one); compensated, the file is the two units' own exports of the compensated
    logs, and its density is the planted one within 3 %, as is the WN+RW projection of each
    log's own JSON report (``LogFit.report``, which read the raw signal's tails as well)."""

    def make(t, x):
        temp = 25 + 10 * (1 - np.exp(-t / 300)) + 2 * np.sign(np.sin(2 * np.pi * t / 600))
        return {"gyro_x": x + 2e-4 * (temp - 25), "imu_temp": temp}

    paths = _write_units(tmp_path, make)
    lfs = [fit_log(p, model="WN+RW", channels=["gyro_x"]) for p in paths]
    assert all(lf.temperature["gyro_x"].applied for lf in lfs)
    text = export_fleet(None, lfs, "kalibr", allow_partial=True, ci=None)
    comp, raw = [], []
    for lf in lfs:
        log = eg.load_log(lf.source)
        comp.append((lf.source, lf.fits, lf.temperature["gyro_x"].compensated_log(log)))
        raw.append((lf.source, lf.fits, log))
    assert text == _fleet_text(comp)
    assert _gyro_density(text) == pytest.approx(N_TRUE, rel=0.03)
    assert (
        _gyro_density(_fleet_text(raw)) > 1.3 * N_TRUE
    )  # the premise: the raw signal's tails inflate it
    # the log's own JSON report: its WN+RW projection reads the compensated signal too
    for lf in lfs:
        proj = json.loads(lf.report)["channels"]["gyro_x"]["projections"]["WN+RW"]
        assert proj["params"]["N"]["value"] == pytest.approx(N_TRUE, rel=0.03)
    # LogFit.prepared (what both read) is the signal the fit was made on
    prepared = lfs[0].prepared(eg.load_log(paths[0]))
    np.testing.assert_allclose(
        prepared.wavelet_variance("gyro_x").variance, lfs[0].fits["gyro_x"].wv.variance,
        rtol=1e-10,
    )  # fmt: skip


def test_prepared_log_refuses_a_changed_file(tmp_path):
    """A log whose length differs from the fitted one (the file was replaced since the batch
    fitted it) is refused by name in one line, not read as the fitted signal."""
    paths = _write_units(tmp_path, lambda t, x: {"gyro_x": x})
    lf = fit_log(paths[0], model="WN+RW", channels=["gyro_x"])
    eg.io.save_log(paths[0], {"gyro_x": np.zeros(1000) + 1.0}, FS)
    with pytest.raises(ExportError, match=r"unit1\.h5: 1,000 samples now, 131,072 when it"):
        export_fleet(None, [lf], "kalibr", allow_partial=True, ci=None)


# ------------------------------------------------------------------------------------------
# two ADIS16405 units
# ------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def adis_units(real_data):
    return [
        fit_log(real_data / f"adis16405_imu{i}.h5", model="WN+RW", channels=list(CHANNELS))
        for i in (1, 4)
    ]


def _file_wv(n_si: float, k_si: float, tau_s: np.ndarray) -> np.ndarray:
    """Haar WV (SI units^2) of a WN+RW file at scales ``tau_s`` (s): docs/conventions.md with
    ``sigma2 = N^2 fs`` and ``gamma2 = K^2 / fs``."""
    tau = tau_s * FS
    return n_si**2 * FS / tau + k_si**2 / FS * (tau**2 + 2) / (12 * tau)


@pytest.mark.real_data
def test_fleet_file_bounds_every_units_data_on_the_adis_logs(adis_units):
    """Units 1 and 4 (accel_x K of their own exports 1.25e-4 and 2.31e-4 g/s/sqrt(Hz)): the
    fleet Kalibr file, read back, has a WV at least each unit's fitted WV and each unit's
    empirical lower 95 % limit times its tail factors at every dyadic scale from two filter
    steps (0.02 s) to the log length; unit 1's own file is below unit 4's data there."""
    text = export_fleet(None, adis_units, "kalibr", ci=None)
    fleet = _kalibr_values(text)
    own1 = _kalibr_values(
        eg.export(
            None, adis_units[0].fits, "kalibr", ci=None, log=eg.load_log(adis_units[0].source)
        )
    )
    below_own1 = 0
    for lf in adis_units:
        tails = log_tail_factors(eg.load_log(lf.source), lf.fits)
        for ch, fit in lf.fits.items():
            kind, f_si = si_factor(fit.wv.unit, ch)
            t = np.asarray(fit.wv.tau_samples, float)
            inb = (t / FS >= 0.02) & (t / FS <= lf.n / FS)
            tau_s = t[inb] / FS
            low = np.asarray(fit.wv.ci_low)[inb] * tails[ch].at(t[inb])
            target = np.maximum(fit.model.wv(t[inb], FS), low) * f_si**2
            wv = _file_wv(fleet[f"{kind}_noise_density"], fleet[f"{kind}_random_walk"], tau_s)
            assert np.all(wv >= target * (1 - 1e-6)), (lf.source, ch, np.min(wv / target))
            wv1 = _file_wv(own1[f"{kind}_noise_density"], own1[f"{kind}_random_walk"], tau_s)
            below_own1 += int(np.sum(wv1 < target * (1 - 1e-6)))
    assert below_own1 > 0  # unit 1's own file does not bound unit 4: the fleet file is needed
    k1 = own1["accelerometer_random_walk"]
    assert fleet["accelerometer_random_walk"] / k1 == pytest.approx(2.314 / 1.247, rel=0.02)


def _six_units_at_100_s(real_data, kind: str):
    """The six ADIS16405 units' recorded ``kind`` errors (each axis minus its log mean, the
    whole 167 min log: 100 fix intervals of 100 s), the filter's bias prior, each unit's
    default WN+RW export per axis, and ``run(u, {ch: FilterNoise})``: unit u's mean NEES
    (its three axes pooled) and fraction of epochs above the 95 % band, as
    ``bench_filter.py --recorded`` and ``filter_fleet_spread.py`` run them (seed 1 + u)."""
    import sys
    from pathlib import Path

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_filter import CHANNELS, KINDS, bias_prior
    from filter_fleet_spread import unit_exports
    from filtersim import block_fraction, nees_band, run_recorded

    logs = [eg.load_log(real_data / f"adis16405_imu{i}.h5") for i in range(1, 7)]
    chans, fix_sigma = KINDS[kind], CHANNELS[f"{kind}_x"][0]
    n = min(log.n for log in logs)
    errs = {}
    for u, log in enumerate(logs):
        for ch in chans:
            x = np.asarray(log[ch], float)[:n]
            errs[(u, ch)] = (x - x.mean())[None, :]
    pb0 = bias_prior(list(errs.values()), int(1200 * FS), FS)
    hi = nees_band(1, len(chans))[1]

    def run(u: int, noise: dict) -> tuple[float, float]:
        v = np.mean(
            [
                run_recorded(
                    errs[(u, ch)], noise[ch], fs=FS, hold=1, t_fix_s=100.0,
                    fix_sigma=fix_sigma, pb0=pb0, seed=1 + u,
                ).nees
                for ch in chans
            ],
            axis=0,
        )  # fmt: skip
        return float(v.mean()), block_fraction(v > hi, int(100 * FS))[0]

    return chans, unit_exports(logs, chans, "WN+RW"), run


def _fleet(chans, ex, s_k: float = 1.0) -> dict:
    """Per axis the largest N and ``s_k`` x the largest K of the six units' exports."""
    from filtersim import FilterNoise

    return {
        ch: FilterNoise(
            max(ex[(u, ch)].N for u in range(6)), s_k * max(ex[(u, ch)].K for u in range(6))
        )
        for ch in chans
    }


@pytest.mark.slow
@pytest.mark.real_data
def test_no_accelerometer_file_at_100_s_serves_every_unit(real_data):
    """The filter of ``tests/filtersim.py`` (fixes every 100 s, sigma 1e-3 g s) on the six
    units' recorded accelerometers (:func:`_six_units_at_100_s`).

    * The fleet file (per axis the largest N and K of the six default WN+RW exports) is not
      overconfident on any unit: mean NEES <= 1.3 and <= 5 % of epochs above the 95 % band
      (measured 0.17-0.39, at most 1.9 % above), and too cautious on unit 1 (< 0.5).
    * No file of the family N = N_fleet, K = s_K K_fleet (s_K from 0.3 to 1, eight steps)
      serves every unit: where none is overconfident, unit 1's mean NEES is below 0.5
      (``filter_fleet_spread.py``: 0 of 169 files of a 13 x 13 grid of N and K); unit 4's
      mean NEES is always more than 2 times unit 1's (2.2-3.0 on the grid)."""
    chans, ex, run = _six_units_at_100_s(real_data, "accel")
    fleet = [run(u, _fleet(chans, ex)) for u in range(6)]
    for u, (m, above) in enumerate(fleet, 1):
        assert m <= 1.3 and above <= 0.05, (u, m, above)
    assert fleet[0][0] < 0.5
    safe_unit1 = []
    for s_k in np.geomspace(0.3, 1.0, 8):
        units = [run(u, _fleet(chans, ex, float(s_k))) for u in range(6)]
        assert units[3][0] > 2.0 * units[0][0], (s_k, units)
        if all(m <= 1.3 and above <= 0.05 for m, above in units):
            safe_unit1.append(units[0][0])
    assert safe_unit1 and max(safe_unit1) < 0.5, safe_unit1


@pytest.mark.slow
@pytest.mark.real_data
def test_gyro_fleet_file_at_100_s_is_consistent_on_every_unit(real_data):
    """The same on the gyros (fix sigma 0.01 deg): their random walks differ less (x1.49-1.74
    per axis), and the fleet file meets the full criterion on each of the six units: mean NEES
    in [0.5, 1.3], at most 5 % above (measured 0.71-1.14, at most 5.0 %), where unit 1's own
    file is overconfident on unit 2 and unit 4 (1.43 and 1.56, above 1.3)."""
    chans, ex, run = _six_units_at_100_s(real_data, "gyro")
    for u in range(6):
        m, above = run(u, _fleet(chans, ex))
        assert 0.5 <= m <= 1.3 and above <= 0.05, (u + 1, m, above)
    own1 = {ch: ex[(0, ch)] for ch in chans}
    assert run(1, own1)[0] > 1.3 and run(3, own1)[0] > 1.3


@pytest.mark.slow
@pytest.mark.real_data
def test_own_gyro_files_at_100_s_miss_the_band_only_in_the_first_1000_s(real_data):
    """docs/filters.md, "Each unit's own gyro file at 100 s": units 2-6's own default WN+RW
    gyro files on their own recorded signal, the 15 axes pooled, fixes every 100 s. Over the
    whole log 8.2 % of the epochs are above the 95 % band (the criterion is 5 %); with the
    filter started at 1000 s and the same files, 3.6 % and a mean NEES of 1.00. The gyros'
    bias wanders more in the first 1000 s after turn-on: the variance of the differences of
    consecutive 100 s means is x2.2 the rest's (F test p ~ 1e-12), so what misses is that
    warm-up, not the files (deterministic: the recorded signal and seeded fix noise)."""
    import sys
    from pathlib import Path

    from scipy.stats import f as f_dist

    sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
    from bench_filter import CHANNELS, KINDS, bias_prior
    from filter_fleet_spread import unit_exports
    from filtersim import block_fraction, nees_band, run_recorded

    logs = [eg.load_log(real_data / f"adis16405_imu{i}.h5") for i in range(1, 7)]
    chans, fix_sigma = KINDS["gyro"], CHANNELS["gyro_x"][0]
    n = min(log.n for log in logs)
    raw = {(u, ch): np.asarray(log[ch], float)[:n] for u, log in enumerate(logs) for ch in chans}
    pb0 = bias_prior([(x - x.mean())[None, :] for x in raw.values()], int(1200 * FS), FS)
    files = unit_exports(logs, chans, "WN+RW")
    others = [(u, ch) for u in range(1, 6) for ch in chans]
    hi = nees_band(1, len(others))[1]

    def pooled(start: int) -> tuple[float, float]:
        v = np.mean(
            [
                run_recorded(
                    (raw[k][start:] - raw[k][start:].mean())[None, :], files[k], fs=FS, hold=1,
                    t_fix_s=100.0, fix_sigma=fix_sigma, pb0=pb0, seed=1 + k[0],
                ).nees
                for k in others
            ],
            axis=0,
        )  # fmt: skip
        return float(v.mean()), block_fraction(v > hi, int(100 * FS))[0]

    mean, above = pooled(0)
    assert above == pytest.approx(0.082, abs=0.002) and mean == pytest.approx(1.093, abs=0.002)
    mean, above = pooled(int(1000 * FS))
    assert above <= 0.05 and 0.5 <= mean <= 1.3, (mean, above)  # 3.6 %, 1.003
    b = int(100 * FS)
    d = [np.diff(raw[k][: n // b * b].reshape(-1, b).mean(axis=1)) for k in others]
    first = np.concatenate([x[:9] for x in d])  # the 9 differences within the first 1000 s
    rest = np.concatenate([x[9:] for x in d])
    ratio = float(np.mean(first**2) / np.mean(rest**2))
    assert ratio > 1.8 and f_dist.sf(ratio, first.size, rest.size) < 1e-9, ratio
