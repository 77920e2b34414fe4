"""ROS 1 and ROS 2 bags with sensor_msgs/Imu, written with the rosbags writer and read back."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags", reason="the 'rosbags' package reads ROS bags (pip install rosbags)")

import engine as eg  # noqa: E402
from engine.cli import main  # noqa: E402
from engine.io import (  # noqa: E402
    IMU_CHANNELS,
    LoadError,
    imu_topics,
    load_log,
    mcap_profile,
    read_imu_bag,
    rosbag,
    write_imu_bag,
)

N = 1500
FS = 200.0


@pytest.fixture(scope="module")
def imu() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    rng = np.random.default_rng(11)
    gyro = rng.normal(0.0, 1e-3, (N, 3)) + np.array([1e-3, -2e-3, 5e-4])
    acc = rng.normal(0.0, 2e-2, (N, 3)) + np.array([0.0, 0.0, 9.81])
    stamps = 1_700_000_000_123_456_789 + np.arange(N, dtype=np.int64) * 5_000_000
    return gyro, acc, stamps


def _kinds() -> list[tuple[int, str, str]]:
    return [
        (1, "", ".bag"),
        (2, "sqlite3", ""),
        (2, "mcap", ""),
        (2, "sqlite3", ".db3"),
        (2, "mcap", ".mcap"),
    ]


@pytest.mark.parametrize(("ros", "storage", "form"), _kinds())
def test_round_trip(tmp_path: Path, imu, ros: int, storage: str, form: str) -> None:
    gyro, acc, stamps = imu
    path = tmp_path / ("imu.bag" if ros == 1 else "imu2")
    write_imu_bag(
        path, gyro, acc, stamps, ros=ros, storage=storage or "sqlite3", frame_id="imu_link"
    )
    if form in (".db3", ".mcap"):  # a bare storage file, without metadata.yaml
        path = next(path.glob(f"*{form}"))
    log = load_log(path)
    assert log.names == list(IMU_CHANNELS) and log.n == N
    assert log.fs == FS and log.fs_source == "time column"
    assert log.units == {
        **dict.fromkeys(IMU_CHANNELS[:3], "rad/s"),
        **dict.fromkeys(IMU_CHANNELS[3:], "m/s^2"),
    }
    for j, name in enumerate(IMU_CHANNELS):
        ref = gyro[:, j] if j < 3 else acc[:, j - 3]
        np.testing.assert_array_equal(log[name], ref)  # exact float64
    assert log.meta["topic"] == "/imu" and log.meta["frame_id"] == "imu_link"
    assert log.meta["time_column"] == "header.stamp" and log.meta["time_report"]["ok"]
    assert log.meta["decoder"] == "numpy"
    assert log.meta["format"].startswith("rosbag1" if ros == 1 else "rosbag2")


def test_reference_decoder_agrees(tmp_path: Path, imu, monkeypatch) -> None:
    gyro, acc, stamps = imu
    for ros in (1, 2):
        path = tmp_path / (f"r{ros}.bag" if ros == 1 else f"r{ros}")
        write_imu_bag(path, gyro, acc, stamps, ros=ros)
        fast = read_imu_bag(path)
        with monkeypatch.context() as m:
            m.setattr(rosbag, "_decode_chunk", lambda *a: None)
            slow = read_imu_bag(path)
        assert slow.meta["decoder"] == "rosbags" and fast.meta["decoder"] == "numpy"
        np.testing.assert_array_equal(fast.stamps_ns, slow.stamps_ns)
        np.testing.assert_array_equal(fast.stamps_ns, stamps)
        for k in IMU_CHANNELS:
            np.testing.assert_array_equal(fast.channels[k], slow.channels[k])


def test_gaps_in_stamps_follow_the_segment_policy(tmp_path: Path, imu) -> None:
    gyro, acc, stamps = imu
    st = stamps.copy()
    st[1000:] += 100_000_000  # 20 lost messages
    path = write_imu_bag(tmp_path / "gap.bag", gyro, acc, st)
    with pytest.raises(LoadError, match=r"gap.*sample 1000.*segment='longest'"):
        load_log(path)
    log = load_log(path, segment="longest")
    assert log.n == 1000 and log.fs == FS and log.meta["segment"] == [0, 1000]
    np.testing.assert_array_equal(log["gyro_y"], gyro[:1000, 1])


def test_zero_header_stamps_fall_back_to_receive_time(tmp_path: Path, imu) -> None:
    gyro, acc, stamps = imu
    path = write_imu_bag(tmp_path / "z.bag", gyro, acc, np.zeros(N, np.int64), receive_ns=stamps)
    log = load_log(path)
    assert log.fs == FS and log.meta["time_column"] == "receive time"
    assert any("receive times" in n for n in log.meta["notes"])


def test_topics(tmp_path: Path, imu) -> None:
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    gyro, acc, stamps = imu
    one = write_imu_bag(tmp_path / "a.bag", gyro, acc, stamps, topic="/imu/data")
    assert imu_topics(one) == {"/imu/data": N}
    with pytest.raises(LoadError, match="no sensor_msgs/Imu topic '/other'.*/imu/data"):
        load_log(one, topic="/other")
    # two IMU topics in one bag: the user must choose
    ts = get_typestore(Stores.ROS1_NOETIC)
    two = tmp_path / "two.bag"
    src = read_imu_bag(one)
    assert src.meta["imu_topics"] == ["/imu/data"]
    with Writer(two) as w:
        conns = [w.add_connection(t, "sensor_msgs/msg/Imu", typestore=ts) for t in ("/a", "/b")]
        strc = w.add_connection("/note", "std_msgs/msg/String", typestore=ts)
        from rosbags.rosbag1 import Reader

        with Reader(one) as r:
            for _, t, raw in r.messages():
                for conn in conns:
                    w.write(conn, t, raw)
        w.write(
            strc,
            int(stamps[0]),
            ts.serialize_ros1(ts.types["std_msgs/msg/String"](data="hello"), "std_msgs/msg/String"),
        )
    with pytest.raises(LoadError, match=r"2 sensor_msgs/Imu topics \(/a, /b\).*topic="):
        load_log(two)
    assert load_log(two, topic="/b").n == N
    # no IMU topic at all
    nothing = tmp_path / "none.bag"
    with Writer(nothing) as w:
        c = w.add_connection("/note", "std_msgs/msg/String", typestore=ts)
        w.write(
            c,
            1,
            ts.serialize_ros1(ts.types["std_msgs/msg/String"](data="x"), "std_msgs/msg/String"),
        )
    with pytest.raises(LoadError, match="no sensor_msgs/Imu topic; its topics: /note"):
        load_log(nothing)


def test_broken_bags(tmp_path: Path, imu) -> None:
    gyro, acc, stamps = imu
    good = write_imu_bag(tmp_path / "g.bag", gyro, acc, stamps)
    data = good.read_bytes()
    (tmp_path / "trunc.bag").write_bytes(data[: len(data) // 2])
    with pytest.raises(LoadError, match="trunc.bag"):
        load_log(tmp_path / "trunc.bag")
    (tmp_path / "renamed.bin").write_bytes(data)
    with pytest.raises(LoadError, match=r"rename it to \*\.bag"):
        load_log(tmp_path / "renamed.bin")
    with pytest.raises(LoadError, match="3 message"):
        load_log(write_imu_bag(tmp_path / "s.bag", gyro[:3], acc[:3], stamps[:3]))
    d2 = write_imu_bag(tmp_path / "ros2", gyro, acc, stamps, ros=2)
    (d2 / "metadata.yaml").write_text("not: [valid")
    with pytest.raises(LoadError, match="ros2"):
        load_log(d2)
    empty = tmp_path / "emptydir"
    empty.mkdir()
    with pytest.raises(LoadError, match="directory"):
        load_log(empty)


def test_fit_and_cli(tmp_path: Path, imu, capsys) -> None:
    gyro, acc, stamps = imu
    path = write_imu_bag(tmp_path / "c", gyro, acc, stamps, ros=2, storage="mcap")
    assert main(["wv", str(path), "--channel", "accel_z", "--json"]) == 0
    d = json.loads(capsys.readouterr().out)
    assert d["channel"] == "accel_z" and d["fs"] == FS and d["n"] == N
    np.testing.assert_allclose(d["variance"], eg.wavelet_variance(acc[:, 2]).variance, rtol=1e-12)
    assert main(["wv", str(path), "--topic", "/nope"]) == 2
    assert "/nope" in capsys.readouterr().err
    shutil.rmtree(path)


def _mcap_with_profile(path: Path, profile: str) -> Path:
    """The start of an MCAP file: magic and a Header record (opcode 1, length, profile, library)."""
    prof, lib = profile.encode(), b"test"
    body = len(prof).to_bytes(4, "little") + prof + len(lib).to_bytes(4, "little") + lib
    path.write_bytes(
        b"\x89MCAP0\r\n" + b"\x01" + len(body).to_bytes(8, "little") + body + b"\0" * 64
    )
    return path


@pytest.mark.parametrize(
    "profile, said", [("ros1", "'ros1' profile (ROS 1 messages in MCAP)"), ("", "empty profile")]
)
def test_mcap_of_another_profile_names_the_real_cause(tmp_path: Path, profile, said) -> None:
    """An MCAP with the ROS 1 profile or none is not called a damaged bag."""
    f = _mcap_with_profile(tmp_path / "x.mcap", profile)
    assert mcap_profile(f) == profile
    with pytest.raises(LoadError, match="MCAP") as e:
        load_log(f)
    assert said in str(e.value) and "damaged" not in str(e.value) and "'ros2'" in str(e.value)


def test_a_ros2_mcap_bag_reports_its_profile(tmp_path: Path, imu) -> None:
    gyro, acc, stamps = imu
    d = write_imu_bag(tmp_path / "m", gyro, acc, stamps, ros=2, storage="mcap")
    (f,) = sorted(Path(d).glob("*.mcap"))
    assert mcap_profile(f) == "ros2"
    assert load_log(d)["gyro_x"].size == gyro.shape[0]


def test_the_app_reads_a_ros2_bag_folder_by_server_path(tmp_path: Path, imu) -> None:
    """A ROS 2 bag (a folder with metadata.yaml) can be chosen as a server path."""
    from gmwm_app import limits
    from gmwm_app.state import AppState

    gyro, acc, stamps = imu
    d = write_imu_bag(tmp_path / "bag2", gyro, acc, stamps, ros=2)
    before = limits.current()
    limits.configure(data_dirs=[tmp_path])
    try:
        st = AppState()
        assert st.load_path(str(d)), st.error
        assert st.channel in IMU_CHANNELS and st.n == gyro.shape[0]
        assert not st.load_path(str(tmp_path))  # a plain folder: a clear message, data kept
        assert "ROS 2 bag folder" in st.error and st.n == gyro.shape[0]
    finally:
        limits.configure(
            max_upload_mb=before.max_upload_mb,
            data_dirs=before.data_dirs,
            allowed_files=before.allowed_files,
        )
