"""ROS 1 .bag and ROS 2 .db3 bags, written by rosbags' own writers and serialisers."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from rosbags.typesys import Stores, get_typestore

from gpsdr_cli.errors import InputError, NoDataError
from gpsdr_cli.io.readers import read_drive, sniff
from gpsdr_cli.io.rosbag import read_rosbag

T0 = 1_777_000_000 * 10**9
N = 200
VALUE_TOL = 1e-12


def _msgs(ts, ros1: bool, i: int) -> dict[str, object]:
    t = T0 + i * 10_000_000
    Time = ts.types["builtin_interfaces/msg/Time"]
    Header = ts.types["std_msgs/msg/Header"]
    V3 = ts.types["geometry_msgs/msg/Vector3"]
    Q = ts.types["geometry_msgs/msg/Quaternion"]
    sec, nsec = divmod(t, 10**9)
    hdr = (Header(seq=i, stamp=Time(sec=sec, nanosec=nsec), frame_id="base")
           if ros1 else Header(stamp=Time(sec=sec, nanosec=nsec), frame_id="base"))
    z9 = np.zeros(9)
    imu = ts.types["sensor_msgs/msg/Imu"](
        header=hdr, orientation=Q(x=0.0, y=0.0, z=0.0, w=1.0), orientation_covariance=z9,
        angular_velocity=V3(x=0.0, y=0.0, z=0.001 * i), angular_velocity_covariance=z9,
        linear_acceleration=V3(x=0.01 * i - 1.0, y=0.0, z=9.81), linear_acceleration_covariance=z9)
    Twist = ts.types["geometry_msgs/msg/Twist"]
    TwistS = ts.types["geometry_msgs/msg/TwistStamped"]
    tw = TwistS(header=hdr, twist=Twist(linear=V3(x=3.0 + 0.01 * i, y=0.0, z=0.0),
                                        angular=V3(x=0.0, y=0.0, z=0.0)))
    Status = ts.types["sensor_msgs/msg/NavSatStatus"]
    fix = ts.types["sensor_msgs/msg/NavSatFix"](
        header=hdr, status=Status(status=2 if i % 2 else 0, service=1), latitude=54.0 + 1e-6 * i,
        longitude=18.0, altitude=12.5, position_covariance=np.array([0.25, 0, 0, 0, 0.36, 0, 0, 0, 1.0]),
        position_covariance_type=2)
    return {"/imu": imu, "/vel": tw, "/fix": fix}


def write_bag(path: Path, ros1: bool) -> Path:
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    w = Writer1(path) if ros1 else Writer2(path, version=9)
    w.open()
    types = {"/imu": "sensor_msgs/msg/Imu", "/vel": "geometry_msgs/msg/TwistStamped",
             "/fix": "sensor_msgs/msg/NavSatFix"}
    conns = {k: w.add_connection(k, v, typestore=ts) for k, v in types.items()}
    for i in range(N):
        for topic, msg in _msgs(ts, ros1, i).items():
            if topic == "/fix" and i % 10:
                continue
            raw = (ts.serialize_ros1(msg, types[topic]) if ros1
                   else ts.serialize_cdr(msg, types[topic]))
            w.write(conns[topic], T0 + i * 10_000_000 + 5_000, raw)
    w.close()
    return path


@pytest.fixture(params=["ros1", "ros2_dir", "ros2_db3"])
def bag(request, tmp_path: Path) -> Path:
    if request.param == "ros1":
        return write_bag(tmp_path / "drive.bag", True)
    d = write_bag(tmp_path / "drive2", False)
    return d if request.param == "ros2_dir" else next(d.glob("*.db3"))


def test_streams_and_values(bag: Path) -> None:
    assert sniff(bag) == "rosbag"
    d = read_rosbag(bag)
    t = T0 + np.arange(N) * 10_000_000
    assert np.array_equal(d.gyro.t_ns, t)  # header stamps, not the log times (+5 us)
    assert np.max(np.abs(d.gyro.yaw_rate_radps - 0.001 * np.arange(N))) < VALUE_TOL
    assert np.max(np.abs(d.accel.accel_mps2 - (0.01 * np.arange(N) - 1.0))) < VALUE_TOL
    assert np.max(np.abs(d.odo.speed_mps - (3.0 + 0.01 * np.arange(N)))) < VALUE_TOL
    g = d.gnss
    assert len(g) == N // 10
    assert np.max(np.abs(g.lat_deg - (54.0 + 1e-6 * np.arange(0, N, 10)))) < VALUE_TOL
    assert np.allclose(g.sigma_e_m, 0.5) and np.allclose(g.sigma_n_m, 0.6)
    assert set(g.fix_quality.tolist()) == {1}  # every 10th message: i even -> STATUS_FIX
    assert d.skipped.total == 0
    assert {c["topic"]: c["messages"] for c in d.meta["rosbag"]["channels"]} == {
        "/imu": N, "/vel": N, "/fix": N // 10}


def test_log_time_and_topic_override(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "b.bag", True)
    d = read_rosbag(bag, use_log_time=True)
    assert d.gyro.t_ns[0] == T0 + 5_000
    with pytest.raises(Exception, match="no topic '/nope'"):
        read_rosbag(bag, topics={"gnss": "/nope"})


def test_read_drive_and_info(tmp_path: Path, gpsdr) -> None:
    from gpsdr_cli import config

    bag = write_bag(tmp_path / "b2", False)
    d = read_drive(bag, params=config.defaults())
    assert d.gyro is not None and d.accel is not None
    r = gpsdr(["info", bag])
    assert r.exit_code == 0, r.output
    assert "gyro" in r.output and "accel" in r.output and "100.00 Hz" in r.output


def test_corrupt_and_truncated_bags_are_clear_errors(tmp_path: Path) -> None:
    bag = write_bag(tmp_path / "b.bag", True)
    data = bag.read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) // 2])
    with pytest.raises(InputError, match="cut.bag"):
        read_rosbag(cut)
    d2 = write_bag(tmp_path / "c2", False)
    db = next(d2.glob("*.db3"))
    raw = bytearray(db.read_bytes())
    raw[100:4000] = b"\xff" * 3900
    db.write_bytes(bytes(raw))
    with pytest.raises((InputError, NoDataError), match="c2"):
        read_rosbag(d2)


def test_no_readable_topic(tmp_path: Path) -> None:
    from rosbags.rosbag2 import Writer

    ts = get_typestore(Stores.ROS2_HUMBLE)
    p = tmp_path / "s"
    w = Writer(p, version=9)
    w.open()
    c = w.add_connection("/chatter", "std_msgs/msg/String", typestore=ts)
    w.write(c, T0, ts.serialize_cdr(ts.types["std_msgs/msg/String"](data="hi"), "std_msgs/msg/String"))
    w.close()
    with pytest.raises(NoDataError, match="/chatter"):
        read_rosbag(p)
    shutil.rmtree(p)


def test_ros1_bag_cut_short_keeps_the_whole_chunks_before_the_cut(tmp_path: Path) -> None:
    from gpsdr_cli.simulate import simulate_drive
    from gpsdr_cli.testing.bags import write_rosbag

    sim = simulate_drive("open_sky", seed=2, duration_s=60.0)
    bag = write_rosbag(sim.drive, tmp_path / "full.bag", ros1=True)
    full = read_rosbag(bag)
    assert len(full.gyro) == len(sim.drive.gyro)
    assert np.max(np.abs(full.gyro.yaw_rate_radps - sim.drive.gyro.yaw_rate_radps)) < VALUE_TOL
    cut = tmp_path / "cut.bag"
    data = bag.read_bytes()
    cut.write_bytes(data[: int(len(data) * 0.6)])
    d = read_rosbag(cut)  # no index: rosbags refuses it; the record walk keeps what is whole
    assert d.skipped.counts["ROS bag damaged (rest of it unread)"] == 1
    n = len(d.gyro)
    assert 0.2 * len(full.gyro) < n < 0.7 * len(full.gyro)
    assert np.array_equal(d.gyro.t_ns, full.gyro.t_ns[:n])


def test_ublox_msgs_navpvt_topic_as_gnss(tmp_path: Path) -> None:
    """ublox_msgs/NavPVT (ROS u-blox driver): the CDR body is the UBX NAV-PVT payload."""
    from rosbags.rosbag2 import Writer

    from gpsdr_cli.testing.ubx_log import nav_pvt

    msgdef = ("uint32 i_tow\nuint16 year\nuint8 month\nuint8 day\nuint8 hour\nuint8 min\n"
              "uint8 sec\nuint8 valid\nuint32 t_acc\nint32 nano\nuint8 fix_type\nuint8 flags\n"
              "uint8 flags2\nuint8 num_sv\nint32 lon\nint32 lat\nint32 height\nint32 h_msl\n"
              "uint32 h_acc\nuint32 v_acc\nint32 vel_n\nint32 vel_e\nint32 vel_d\nint32 g_speed\n"
              "int32 heading\nuint32 s_acc\nuint32 head_acc\nuint16 p_dop\nuint8[6] reserved1\n"
              "int32 head_veh\nint16 mag_dec\nuint16 mag_acc\n")
    from rosbags.typesys import get_types_from_msg

    ts = get_typestore(Stores.ROS2_HUMBLE)
    ts.register(get_types_from_msg(msgdef, "ublox_msgs/msg/NavPVT"))
    p = tmp_path / "pvt"
    w = Writer(p, version=9)
    w.open()
    c = w.add_connection("/ublox/navpvt", "ublox_msgs/msg/NavPVT", typestore=ts)
    for i in range(5):
        t = T0 + i * 200_000_000
        payload = nav_pvt(t, lat=54.3 + i * 1e-6, lon=18.6, quality=4 if i else 5, h_acc_m=0.014)[6:-2]
        raw = b"\x00\x01\x00\x00" + payload
        msg = ts.deserialize_cdr(raw, "ublox_msgs/msg/NavPVT")  # rosbags agrees on the layout
        assert (msg.lat, msg.year, msg.h_acc) == (round((54.3 + i * 1e-6) * 1e7), 2026, 14)
        w.write(c, t + 3_000_000, raw)
    w.close()
    d = read_rosbag(p)
    g = d.gnss
    assert np.array_equal(g.t_ns, T0 + np.arange(5) * 200_000_000)  # UTC fields, not log time
    assert np.max(np.abs(g.lat_deg - (54.3 + np.arange(5) * 1e-6))) < 1e-9
    assert g.fix_quality.tolist() == [5, 4, 4, 4, 4]
    assert np.allclose(g.sigma_e_m, 0.014 / np.sqrt(2), atol=1e-9)


def _extra_topic(bag: Path, n: int) -> None:
    """Append ``n`` std_msgs/String messages on /chatter (a topic gpsdr does not read)."""
    import apsw

    con = apsw.Connection(str(next(bag.glob("*.db3"))))
    con.execute("INSERT INTO topics (name, type, serialization_format, offered_qos_profiles, "
                "type_description_hash) VALUES ('/chatter', 'std_msgs/msg/String', 'cdr', '', '')")
    tid = con.last_insert_rowid()
    for i in range(n):
        con.execute("INSERT INTO messages (topic_id, timestamp, data) VALUES (?, ?, ?)",
                    (tid, T0 + i, b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00"))
    con.close()


def _streams(d) -> dict[str, np.ndarray]:
    return {"gyro_t": d.gyro.t_ns, "wz": d.gyro.yaw_rate_radps, "ax": d.accel.accel_mps2,
            "odo_t": d.odo.t_ns, "v": d.odo.speed_mps, "gnss_t": d.gnss.t_ns,
            "lat": d.gnss.lat_deg, "sig": d.gnss.sigma_e_m}


def test_sqlite_chunked_and_row_by_row_reads_agree(tmp_path: Path, monkeypatch) -> None:
    """The aggregate queries split into chunks, and the row-by-row fallback for values
    past SQLite's length limit, read the same streams as one query."""
    import apsw

    from gpsdr_cli.io import rosbag

    bag = write_bag(tmp_path / "b2", False)
    _extra_topic(bag, 37)
    whole = read_rosbag(bag)
    counts = {c["topic"]: c["messages"] for c in whole.meta["rosbag"]["channels"]}
    assert counts == {"/imu": N, "/vel": N, "/fix": N // 10, "/chatter": 37}
    assert whole.skipped.total == 0
    assert np.max(np.abs(whole.gyro.yaw_rate_radps - 0.001 * np.arange(N))) < VALUE_TOL

    monkeypatch.setattr(rosbag, "_SQL_CHUNK_ROWS", 7)
    chunked = read_rosbag(bag)
    monkeypatch.undo()

    class Limited(apsw.Connection):  # an SQLite built with a 4 kB value limit
        def __init__(self, *args, **kwargs) -> None:
            super().__init__(*args, **kwargs)
            self.limit(apsw.SQLITE_LIMIT_LENGTH, 4096)

    monkeypatch.setattr(apsw, "Connection", Limited)
    rows = read_rosbag(bag)
    for d in (chunked, rows):
        assert {c["topic"]: c["messages"] for c in d.meta["rosbag"]["channels"]} == counts
        for name, values in _streams(whole).items():
            assert np.array_equal(_streams(d)[name], values), name


@pytest.mark.parametrize("ros1", [False, True])
def test_fast_decoder_large_batches_match_small_ones(ros1: bool) -> None:
    """Batches past the decoder's strided-gather threshold give the values encoded, and the
    same as one message at a time (frame ids of varying length shift every field)."""
    from gpsdr_cli.io import ros2_fast

    n = 6000
    msgs = [ros2_fast.encode("imu", T0 + i * 10_000_000, "f" * (i % 7), ros1=ros1,
                             wz=0.001 * i - 2.0, ax=0.5 - 1e-4 * i) for i in range(n)]
    sizes = np.array([len(m) for m in msgs], np.int64)
    off = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    buf = np.frombuffer(b"".join(msgs), np.uint8)
    fields, ok = ros2_fast.decode("imu", buf, off, sizes, ros1=ros1)
    assert ok.all()
    assert np.array_equal(fields["stamp_ns"], T0 + np.arange(n) * 10_000_000)
    assert np.array_equal(fields["wz"], 0.001 * np.arange(n) - 2.0)
    assert np.array_equal(fields["ax"], 0.5 - 1e-4 * np.arange(n))
    for i in (0, 1, 4097, n - 1):
        one, ok1 = ros2_fast.decode("imu", np.frombuffer(msgs[i], np.uint8), np.zeros(1, np.int64),
                                    sizes[i:i + 1], ros1=ros1)
        assert ok1[0] and one["wz"][0] == fields["wz"][i] and one["ax"][0] == fields["ax"][i]
