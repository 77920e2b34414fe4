"""Property-based tests (hypothesis): random and malformed inputs to the loaders and the CLI.

Every input must give a result or a clear error: ``LoadError``/``ModelError``/``FitError``/
``ValueError`` subclasses with a message, or ``gmwm`` exit status 2 with one line on stderr;
never another exception type, a traceback or a hang (per-example deadlines; the module runs in
well under a minute).
"""

from __future__ import annotations

import contextlib
import itertools
import json
import math
import os
import signal
from collections.abc import Iterator
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, event, example, given, settings
from hypothesis import strategies as st
from hypothesis.extra import numpy as hnp

import engine as eg
from engine.cli import main
from engine.fit import FitError
from engine.formats import ExportError, read_kalibr, si_factor
from engine.io import ImuLog, LoadError, check_time, load_log
from engine.models import ModelError, parse_model
from engine.session import SessionError, load_session
from engine.wv import wavelet_variance_stream


def cfg(examples: int, deadline_ms: int = 10_000) -> settings:
    """Bounded runs: ``examples`` cases, each under ``deadline_ms`` (no hang; generous, so that
    a loaded CI machine does not flake: typical examples take a few ms)."""
    return settings(
        max_examples=examples,
        deadline=deadline_ms,
        database=None,
        # the same examples on every run (CI must not depend on luck); set
        # GMWM_HYPOTHESIS_EXPLORE=1 to draw new ones (a local search for bugs)
        derandomize=os.environ.get("GMWM_HYPOTHESIS_EXPLORE") != "1",
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.function_scoped_fixture],
    )


CLEAR = (LoadError, ModelError, FitError, ExportError, SessionError, ValueError)

MAGICS = [
    b"",
    b"\x89HDF\r\n\x1a\n",
    b"\x93NUMPY",
    b"\x93NUMPY\x01\x00v\x00",
    b"PK\x03\x04",
    b"#ROSBAG V2.0\n",
    b"\x89MCAP0\r\n",
    b"SQLite format 3\x00",
    b"time,gyro_x\n",
]
EXTS = ["", ".csv", ".txt", ".tsv", ".dat", ".npy", ".npz", ".h5", ".bag", ".mcap", ".db3", ".bin"]


class Hang(BaseException):
    """Raised by :func:`no_hang`; a BaseException so that no ``except Exception`` (or the CLI's
    ``except OSError``) can swallow it."""


@contextlib.contextmanager
def no_hang(seconds: float = 60.0) -> Iterator[None]:
    """Fail (instead of hanging forever) if the body runs longer than ``seconds``: hypothesis'
    deadline only measures examples that finish."""

    def alarm(signum: int, frame: object) -> None:
        raise Hang(f"hang: no result after {seconds} s")

    old = signal.signal(signal.SIGALRM, alarm)
    signal.setitimer(signal.ITIMER_REAL, seconds)
    try:
        yield
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0)
        signal.signal(signal.SIGALRM, old)


_SCRATCH: list[Path] = []
_COUNT = itertools.count()


@pytest.fixture(scope="module", autouse=True)
def scratch(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Path]:
    """One pytest-managed directory for every generated file (pytest rotates old ones)."""
    d = tmp_path_factory.mktemp("hyp")
    _SCRATCH.append(d)
    yield d
    _SCRATCH.remove(d)


def _new_dir() -> Path:
    d = _SCRATCH[-1] / f"e{next(_COUNT)}"
    d.mkdir()
    return d


def _tmpfile(data: bytes, ext: str) -> Path:
    p = _new_dir() / f"f{ext}"
    p.write_bytes(data)
    return p


def _assert_clear(exc: BaseException) -> None:
    assert isinstance(exc, CLEAR), f"unexpected {type(exc).__name__}: {exc}"
    msg = str(exc)
    assert msg.strip(), f"{type(exc).__name__} without a message"
    assert "Traceback" not in msg


def _check_log(log: ImuLog) -> None:
    assert isinstance(log, ImuLog)
    assert math.isfinite(log.fs) and log.fs > 0
    if log.is_summary:
        return
    sizes = {a.size for a in log.channels.values()}
    assert len(sizes) == 1 and sizes.pop() >= 4
    for a in log.channels.values():
        assert a.dtype.kind == "f" and np.all(np.isfinite(a))


def _load(path: Path, **kw) -> ImuLog | None:
    try:
        with no_hang():
            log = load_log(path, **kw)
    except Exception as exc:  # noqa: BLE001 - the property is about the exception type
        _assert_clear(exc)
        event(f"error: {type(exc).__name__}")
        return None
    _check_log(log)
    event(f"loaded ({log.meta.get('format')})")
    return log


# ----------------------------------------------------------------------------- loaders
@cfg(120)
@given(magic=st.sampled_from(MAGICS), body=st.binary(max_size=600), ext=st.sampled_from(EXTS))
def test_random_bytes(magic: bytes, body: bytes, ext: str) -> None:
    _load(_tmpfile(magic + body, ext))


_FIELD = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True, width=64).map(repr),
    st.integers(-(10**20), 10**20).map(str),
    st.sampled_from(
        [
            "",
            "nan",
            "NaN",
            "inf",
            "-inf",
            "1e308",
            "-1e308",
            "1e-320",
            "abc",
            "0x1F",
            "1,5",
            '"3"',
            " 7 ",
            "1e400",
            "--1",
            "+.5",
        ]
    ),
    st.from_regex(r"[-+]?[0-9]{1,4}(\.[0-9]{0,6})?([eE][-+]?[0-9]{1,3})?", fullmatch=True),
)
_HEADER = st.lists(
    st.sampled_from(
        [
            "time",
            "t",
            "timestamp",
            "time_ms",
            "gyro_x [deg/s]",
            "accel_z (g)",
            "x",
            "x",
            "",
            "a b",
            "#c",
            "seconds",
            "time [ns]",
            "temp [°C]",
        ]
    ),
    min_size=1,
    max_size=5,
)


_GOOD = st.floats(-1e6, 1e6, allow_nan=False, allow_subnormal=False).map(repr)


@st.composite
def csv_text(draw: st.DrawFn) -> str:
    """CSV-ish text: mostly well formed (so that the loader's later stages run), with random
    corruptions: bad fields, NaN/Inf, huge/tiny numbers, ragged rows, stray lines, and time
    columns with gaps, duplicates and reversals."""
    delim = draw(st.sampled_from([",", ";", "\t", " ", "  ", ", "]))
    ncol = draw(st.integers(1, 5))
    nrow = draw(st.integers(0, 40))
    bad_rate = draw(st.sampled_from([0, 0, 0.02, 0.1, 0.5]))
    lines = []
    if draw(st.booleans()):
        lines.append(delim.join(draw(_HEADER)))
    ragged = draw(st.integers(0, 4)) == 0
    time_kind = draw(st.sampled_from(["none", "clean", "gaps", "messy"]))
    t = 0.0
    for _ in range(nrow):
        k = draw(st.integers(max(ncol - 1, 0), ncol + 1)) if ragged else ncol
        row = [draw(_FIELD) if draw(st.floats(0, 1)) < bad_rate else draw(_GOOD) for _ in range(k)]
        if time_kind != "none" and row:
            step = 0.01
            if time_kind == "gaps":
                step = draw(st.sampled_from([0.01] * 8 + [0.05, 0.3]))
            elif time_kind == "messy":
                step = draw(st.sampled_from([0.01] * 5 + [0.0, -0.02, 0.04, 0.0101]))
            t += step
            row[0] = repr(round(t, 6))
        lines.append(delim.join(row))
        if draw(st.integers(0, 30)) == 0:
            lines.append(draw(st.sampled_from(["# comment", "", "\x00", "garbage;;;", "1e999"])))
    return draw(st.sampled_from(["\n", "\r\n"])).join(lines)


@cfg(150)
@pytest.mark.slow  # 11 s of CPU
@given(
    text=csv_text(),
    ext=st.sampled_from([".csv", ".txt", ""]),
    segment=st.sampled_from([None, "stop", "longest", "report"]),
    fs=st.sampled_from([None, None, 100.0]),
)
def test_random_csv_text(text: str, ext: str, segment: str | None, fs: float | None) -> None:
    log = _load(_tmpfile(text.encode("utf-8", "surrogatepass"), ext), segment=segment, fs=fs)
    if log is not None and log.meta.get("time_report") and not log.meta["time_report"]["ok"]:
        # never spliced silently: a cut is recorded, or the joins are in the notes
        assert "segment" in log.meta or any("joined" in n for n in log.meta.get("notes", []))


@pytest.fixture(scope="module")
def valid_files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    """Small valid logs of every format, as bytes (to be truncated or corrupted)."""
    from engine.io import write_imu_bag

    d = tmp_path_factory.mktemp("hyp_valid")
    rng = np.random.default_rng(2)
    ch = {"gyro_x": rng.normal(size=64), "accel_z": rng.normal(size=64)}
    out = {}
    for ext in (".h5", ".csv", ".npy"):
        out[ext] = eg.io.save_log(d / f"v{ext}", ch, 100.0, units={"gyro_x": "rad/s"}).read_bytes()
    np.savez(d / "v.npz", gyro_x=ch["gyro_x"], fs=100.0)
    out[".npz"] = (d / "v.npz").read_bytes()
    stamps = (np.arange(64) * 5_000_000 + 10**9).astype(np.int64)
    g, a = rng.normal(size=(64, 3)), rng.normal(size=(64, 3))
    out[".bag"] = write_imu_bag(d / "v.bag", g, a, stamps, ros=1).read_bytes()
    for storage, ext in (("mcap", ".mcap"), ("sqlite3", ".db3")):
        bag = write_imu_bag(d / f"r2{storage}", g, a, stamps, ros=2, storage=storage)
        out[ext] = next(bag.glob(f"*{ext}")).read_bytes()
    return out


@cfg(100, 20_000)
@example(fmt=".h5", cut=1.0, flips=[(0.6328125, 0)], tail=b"")  # h5py RuntimeError, fixed
@given(
    fmt=st.sampled_from([".h5", ".csv", ".npy", ".npz", ".bag", ".mcap", ".db3"]),
    cut=st.one_of(st.just(1.0), st.floats(0, 1)),
    flips=st.lists(st.tuples(st.floats(0, 1), st.integers(0, 255)), max_size=6),
    tail=st.binary(max_size=40),
)
def test_corrupted_valid_files(
    valid_files: dict[str, bytes], fmt: str, cut: float, flips, tail: bytes
) -> None:
    data = bytearray(valid_files[fmt])
    for pos, val in flips:
        data[min(int(pos * len(data)), len(data) - 1)] = val
    data = bytes(data[: max(1, int(cut * len(data)))]) + tail
    _load(_tmpfile(data, fmt))


@cfg(60)
@given(
    arr=hnp.arrays(
        dtype=st.sampled_from(
            [
                np.float64,
                np.float32,
                np.int16,
                np.int64,
                np.uint8,
                np.float16,
                np.complex64,
                np.bool_,
            ]
        ),
        shape=hnp.array_shapes(min_dims=1, max_dims=3, max_side=12),
    ),
    scale=st.sampled_from([None, 0.05, 1e300, 0.0, float("nan"), {"x": 2.0}, {"nope": 1.0}]),
    fmt=st.sampled_from([".npy", ".npz", ".h5"]),
)
def test_random_arrays(arr: np.ndarray, scale, fmt: str) -> None:
    p = _new_dir() / f"a{fmt}"
    if fmt == ".npy":
        np.save(p, arr)
    elif fmt == ".npz":
        np.savez(p, x=arr, fs=np.array(100.0))
    else:
        import h5py

        with h5py.File(p, "w") as f:
            f["x"] = arr
            f.attrs["fs_hz"] = 50.0
    log = _load(p, scale=scale)
    if log is not None and isinstance(scale, float) and arr.dtype.kind in "iu" and arr.ndim == 1:
        np.testing.assert_array_equal(log["x"], arr.astype(np.float64) * scale)


@cfg(80)
@given(
    t=hnp.arrays(
        np.float64,
        st.integers(0, 60),
        elements=st.one_of(st.floats(-1e3, 1e3), st.just(np.nan), st.just(np.inf)),
    ),
    sort=st.booleans(),
)
def test_time_check_invariants(t: np.ndarray, sort: bool) -> None:
    if sort:
        t = np.sort(t)
    rep = check_time(t)
    n = t.size
    segs = rep.segments
    assert sum(rep.counts.values()) >= len(rep.events)
    prev = 0
    for a, b in segs:
        assert prev <= a < b <= n
        prev = b
        inner = np.diff(t[a:b])
        assert np.all(inner > 0) and np.all(np.isfinite(t[a:b]))
        if inner.size:
            assert np.all(inner <= 1.5 * rep.median_step)
    if segs.size:
        la, lb = rep.longest
        assert lb - la == max(b - a for a, b in segs)
    assert rep.ok == (not rep.counts)
    json.dumps(rep.to_dict(), allow_nan=False)
    assert rep.summary()
    if not rep.ok:
        assert rep.message()


# ----------------------------------------------------------------------------- models
_TOKENS = [
    "WN",
    "RW",
    "QN",
    "DR",
    "GM",
    "AR1",
    "AR",
    "2*",
    "*2",
    "0*",
    "+",
    "(",
    ")",
    "=",
    "beta",
    "sigma2",
    "1e-3",
    "-1",
    "nan",
    "inf",
    ",",
    " ",
    "gm",
    "foo",
    "3*GM",
    "GM(0.1,1e-4)",
    "WN(sigma2=1)",
    "AR1(phi=1.5)",
    "WN(x=1)",
    "1e999",
    "999*",
]
# Multipliers of 1e10 and more are left to test_huge_multiplier (a known defect, see there).


@cfg(200)
@given(
    spec=st.one_of(
        st.lists(st.sampled_from(_TOKENS), max_size=8).map("".join), st.text(max_size=30)
    )
)
def test_random_model_strings(spec: str) -> None:
    try:
        m = parse_model(spec)
        m.validate(20)
    except Exception as exc:  # noqa: BLE001
        _assert_clear(exc)
        return
    assert isinstance(m, eg.Model) and len(m) >= 1
    assert parse_model(m.spec(values=True)).spec() == m.spec()


def test_huge_multiplier_is_a_clear_error() -> None:
    with pytest.raises(ModelError, match="99999999999"):
        parse_model("99999999999*WN")


@cfg(100)
@given(unit=st.text(max_size=12), text=st.text(max_size=200))
def test_random_units_and_kalibr_text(unit: str, text: str) -> None:
    try:
        kind, f = si_factor(unit, "c")
        assert kind in ("gyroscope", "accelerometer") and f > 0
    except ExportError as exc:
        assert str(exc)
    try:
        assert isinstance(read_kalibr(text + "\n"), dict)
    except ExportError as exc:
        assert str(exc)


@cfg(60)
@given(
    doc=st.recursive(
        st.one_of(st.none(), st.booleans(), st.floats(allow_nan=False), st.text(max_size=8)),
        lambda c: st.one_of(
            st.lists(c, max_size=3),
            st.dictionaries(
                st.sampled_from(
                    [
                        "schema",
                        "data",
                        "channels",
                        "fit",
                        "wv",
                        "model",
                        "load",
                        "path",
                        "intervals",
                        "app",
                    ]
                ),
                c,
                max_size=4,
            ),
        ),
        max_leaves=12,
    ),
    schema=st.booleans(),
)
def test_random_session_files(doc, schema: bool) -> None:
    if schema and isinstance(doc, dict):
        doc["schema"] = "gmwm-session/1"
    p = _tmpfile(json.dumps(doc).encode(), ".json")
    try:
        load_session(p)
    except SessionError as exc:
        assert str(exc)


# ----------------------------------------------------------------------------- streaming
@cfg(40)
@given(
    x=hnp.arrays(
        np.float64, st.integers(4, 3000), elements=st.floats(-1e6, 1e6, allow_subnormal=False)
    ),
    block=st.sampled_from([1024, 2048]),
    f32=st.booleans(),
)
def test_stream_matches_memory(x: np.ndarray, block: int, f32: bool) -> None:
    if f32:
        x = x.astype(np.float32)
    ref = eg.wavelet_variance(x)
    got = wavelet_variance_stream(x, block=block)
    scale = max(float(np.max(ref.variance)), 1e-300)
    np.testing.assert_allclose(got.variance, ref.variance, rtol=1e-9, atol=1e-12 * scale)


# ----------------------------------------------------------------------------- CLI
@pytest.fixture(scope="module")
def small_log(tmp_path_factory: pytest.TempPathFactory) -> Path:
    rng = np.random.default_rng(5)
    p = tmp_path_factory.mktemp("hyp_cli") / "six.h5"
    chans = {
        c: rng.normal(0, 0.01, 3000) + np.cumsum(rng.normal(0, 1e-4, 3000))
        for c in ("gyro_x", "gyro_y", "gyro_z", "accel_x", "accel_y", "accel_z")
    }
    units = {c: "deg/s" if c.startswith("gyro") else "g" for c in chans}
    return eg.io.save_log(p, chans, 100.0, units=units)


def _run(capsys: pytest.CaptureFixture[str], argv: list[str]) -> None:
    try:
        with no_hang():
            code = main(argv)
    except SystemExit as e:  # argparse --help exits 0
        assert e.code == 0, argv
        capsys.readouterr()
        return
    out, err = capsys.readouterr()
    event(f"exit {code}")
    assert code in (0, 2), (argv, code, err)
    assert "Traceback" not in out + err
    if code == 2:
        lines = err.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("gmwm"), (argv, err)
    else:
        assert out


_VALUES = [
    "0",
    "-1",
    "2",
    "5",
    "1e3",
    "nan",
    "inf",
    "abc",
    "",
    "0.5",
    "99",
    "WN+RW",
    "GM+WN",
    "2*GM+WN+RW",
    "WN(",
    "gyro_x",
    "accel_z",
    "7",
    "longest",
    "stop",
    "report",
    "gyro_x=0.1",
    "deg/s",
    "x=deg/s",
    "kalibr",
    "json",
    "csv",
    "datasheet",
    "-",
]
_OPTS = [
    "--channel",
    "--fs",
    "--levels",
    "--eff",
    "--alpha",
    "--model",
    "--segment",
    "--scale",
    "--units",
    "--topic",
    "--channels",
    "--format",
    "-o",
    "--weights",
    "--level",
    "--model-for",
    "-n",
    "--seed",
    "--ci",
]
_FLAGS = ["--json", "--robust", "--stream", "--partial"]


@cfg(120, 30_000)
@given(
    cmd=st.sampled_from(["wv", "fit", "export", "simulate", "nope", ""]),
    opts=st.lists(st.tuples(st.sampled_from(_OPTS), st.sampled_from(_VALUES)), max_size=4),
    flags=st.lists(st.sampled_from(_FLAGS), max_size=2, unique=True),
    which=st.sampled_from(["log", "missing", "garbage"]),
)
def test_cli_random_arguments(capsys, small_log: Path, cmd: str, opts, flags, which: str) -> None:
    # no simulate with huge -n: the vocabulary keeps every number small
    target = {
        "log": str(small_log),
        "missing": str(small_log) + ".nope",
        "garbage": str(_tmpfile(b"\x00\x01garbage", ".csv")),
    }[which]
    argv = [cmd, target] if cmd not in ("simulate", "") else ([cmd] if cmd else [])
    for o, v in opts:
        if o == "-o" and v not in ("-", ""):
            v = str(_tmpfile(b"", ".csv").with_suffix(".out"))
        argv += [o, v]
    if cmd == "simulate":
        argv += ["-o", str(_tmpfile(b"", ".h5").with_name("sim.h5"))]
    argv += flags
    assume("-B" not in argv)
    _run(capsys, argv)


@cfg(40, 30_000)
@given(
    spec=st.lists(st.sampled_from(_TOKENS), min_size=1, max_size=6).map("".join),
    fmt=st.sampled_from(["kalibr", "json", "csv", "datasheet"]),
)
def test_cli_fit_and_export_random_models(capsys, small_log: Path, spec: str, fmt: str) -> None:
    _run(capsys, ["fit", str(small_log), "--model", spec, "--channel", "gyro_y"])
    _run(
        capsys,
        [
            "export",
            str(small_log),
            "--model",
            spec,
            "--format",
            fmt,
            "-o",
            "-",
            "--channels",
            "gyro_x,accel_x",
            "--partial",
        ],
    )
