"""engine.io.load_log of a file's content (bytes or a binary file object, as an upload gives):
the same log as from the file's path, for every format; messages name the upload."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from engine.io import ImuLog, LoadError, load_log, save_log


def same_log(a: ImuLog, b: ImuLog) -> None:
    """Equal channels (values and dtypes), fs, its source, units, WVs and metadata."""
    assert a.names == b.names and a.fs == b.fs and a.fs_source == b.fs_source
    assert a.units == b.units
    for ch in a.channels:
        assert a[ch].dtype == b[ch].dtype
        np.testing.assert_array_equal(a[ch], b[ch])
    for ch, wv in a.wv.items():
        assert wv.to_dict() == b.wv[ch].to_dict()
    assert a.meta == b.meta


def files(tmp_path: Path) -> list[Path]:
    rng = np.random.default_rng(5)
    ch = {"gyro_x": rng.normal(size=3000), "accel_z": rng.normal(size=3000)}
    ch32 = {**ch, "f32": ch["gyro_x"].astype(np.float32)}
    t = np.arange(3000) / 200.0
    csv = tmp_path / "run.csv"
    lines = ["time_s,gyro_x[deg/s],accel_z[g]"]
    lines += [
        f"{float(t[i])!r},{float(ch['gyro_x'][i])!r},{float(ch['accel_z'][i])!r}"
        for i in range(3000)
    ]
    csv.write_text("\n".join(lines) + "\n", encoding="utf-8")
    npy = tmp_path / "run.npy"
    np.save(npy, np.column_stack([ch["gyro_x"], ch["accel_z"]]))
    npz = tmp_path / "run.npz"
    np.savez(npz, gyro_x=ch["gyro_x"], accel_z=ch["accel_z"], fs=200.0)
    h5 = save_log(tmp_path / "run.h5", ch32, 200.0, {"gyro_x": "deg/s"}, attrs={"sensor": "s"})
    return [csv, npy, npz, Path(h5)]


def test_each_format_from_bytes_equals_from_path(tmp_path: Path) -> None:
    for path in files(tmp_path):
        want = load_log(path)
        assert want.n == 3000 and want.names  # a real log, read from the path
        data = path.read_bytes()
        for content in (data, bytearray(data), io.BytesIO(data)):
            got = load_log(content, name=path.name)
            same_log(got, want)
            assert got.source == path.name
        if path.suffix == ".csv":
            assert want.fs == 200.0 and want.fs_source == "time column"


def test_summary_hdf5_from_bytes(real_data: Path) -> None:
    path = real_data / "derived" / "navchip_wv_av.h5"
    want = load_log(path)
    got = load_log(path.read_bytes(), name=path.name)
    assert got.is_summary and got.n == want.n == 3_105_250
    same_log(got, want)


def test_content_options_and_hints(tmp_path: Path) -> None:
    """fs= and segment= apply to content too; the magic bytes win over a wrong name; a text
    upload without a name is read as text."""
    csv, npy, _, h5 = files(tmp_path)
    a = load_log(npy.read_bytes(), name="x.npy", fs=50.0)
    assert a.fs == 50.0 and a.fs_source == "user"
    same_log(load_log(h5.read_bytes(), name="wrong.csv"), load_log(h5))
    same_log(load_log(csv.read_bytes()), load_log(csv))
    seg = load_log(csv.read_bytes(), name="run.csv", segment=(100, 1100))
    assert seg.n == 1000
    np.testing.assert_array_equal(seg["gyro_x"], load_log(csv)["gyro_x"][100:1100])


def test_content_errors_name_the_upload(tmp_path: Path) -> None:
    with pytest.raises(LoadError, match=r"'my log\.csv' is empty"):
        load_log(b"", name="my log.csv")
    with pytest.raises(LoadError, match=r"'bad\.csv'.*line 3"):
        load_log(b"a,b\n1,2\n3,x\n", name="bad.csv")
    with pytest.raises(LoadError, match=r"'broken\.h5'") as exc:
        load_log(b"\x89HDF\r\n\x1a\n" + b"\x00" * 100, name="broken.h5")
    assert "tmp" not in str(exc.value)
    with pytest.raises(LoadError, match=r"'<upload>'.*not a text file"):
        load_log(b"\x00\x01\x02binary")


@pytest.mark.parametrize(("ros", "storage", "suffix"), [(1, "", ".bag"), (2, "mcap", ".mcap")])
def test_one_file_bag_from_bytes(tmp_path: Path, ros: int, storage: str, suffix: str) -> None:
    """A one-file ROS bag as content (through a temporary file the loader removes)."""
    pytest.importorskip("rosbags")
    from engine.io import write_imu_bag

    rng = np.random.default_rng(2)
    gyro, acc = rng.normal(size=(800, 3)), rng.normal(size=(800, 3))
    stamps = 1_700_000_000_000_000_000 + np.arange(800, dtype=np.int64) * 5_000_000
    path = tmp_path / ("imu.bag" if ros == 1 else "imu2")
    write_imu_bag(path, gyro, acc, stamps, ros=ros, storage=storage or "sqlite3")
    if ros == 2:
        path = next(path.glob(f"*{suffix}"))
    want = load_log(path)
    got = load_log(path.read_bytes(), name=f"upload{suffix}")
    assert got.n == 800 and got.fs == 200.0
    np.testing.assert_array_equal(got[0], gyro[:, 0])
    same_log(got, want)
