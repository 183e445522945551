"""MCAP reader: the real u-blox recording, generated logs with known values, the CDR
fast path against mcap_ros2's generic decoder, JSON/protobuf, damage and overrides."""

from __future__ import annotations

import io
import json
import struct
from pathlib import Path

import numpy as np
import pytest

from gpsdr_cli.conventions import FIX_DGPS, FIX_GPS, FIX_NONE, FIX_RTK
from gpsdr_cli.errors import InputError, NoDataError, UsageError
from gpsdr_cli.io import ros2_fast
from gpsdr_cli.io.mcap import read_mcap

REAL = Path(__file__).resolve().parents[3] / "shared" / "data" / "mcap_samples" / "ublox_gps_ros2.mcap"
DATA = Path(__file__).resolve().parents[1] / "data" / "mcap"
T0 = 1_700_000_000_000_000_000


def write_mcap(path: Path | io.BytesIO, channels: list[tuple[str, str, list[tuple[int, int, bytes]]]],
               *, compression: str = "zstd", chunk_size: int = 1024 * 1024, index: bool = True,
               schemas: dict[str, tuple[str, str, bytes]] | None = None, chunked: bool = True) -> bytes:
    """Write channels ``(topic, layout_or_schema_key, [(log_time_ns, publish_ns, data)])``.

    ``layout`` keys are ros2_fast layouts (ROS 2 CDR); other keys are looked up in
    ``schemas`` as ``(schema_name, schema_encoding, schema_data)`` with the message
    encoding given after a colon in the key, e.g. ``"locfix:json"``.
    Messages are written in time order across channels.
    """
    from mcap.writer import CompressionType, IndexType, Writer

    buf = io.BytesIO()
    comp = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "": CompressionType.NONE}[compression]
    w = Writer(buf, compression=comp, chunk_size=chunk_size,
               index_types=IndexType.ALL if index else IndexType.NONE,
               use_summary_offsets=index, use_statistics=index, repeat_channels=index,
               repeat_schemas=index, use_chunking=chunked)
    w.start(profile="ros2", library="gpsdr tests")
    events = []
    for topic, key, msgs in channels:
        if key in ros2_fast.SCHEMAS:
            name, text = ros2_fast.SCHEMAS[key]
            sid = w.register_schema(name, "ros2msg", text.encode())
            cid = w.register_channel(topic, "cdr", sid)
        else:
            assert schemas is not None
            name, s_enc, s_data = schemas[key]
            sid = w.register_schema(name, s_enc, s_data)
            cid = w.register_channel(topic, key.split(":")[1], sid)
        events += [(lt, cid, pt, data) for lt, pt, data in msgs]
    events.sort(key=lambda e: e[0])
    for lt, cid, pt, data in events:
        w.add_message(cid, log_time=lt, data=data, publish_time=pt)
    w.finish()
    raw = buf.getvalue()
    if isinstance(path, Path):
        path.write_bytes(raw)
    return raw


def _drive_channels(n_gnss: int = 50, n_imu: int = 500, frame: str = "gps_link"):
    """A 10 s drive: 5 Hz NavSatFix, 50 Hz Imu and TwistStamped, known values."""
    rng = np.random.default_rng(7)
    tg = T0 + np.arange(n_gnss, dtype=np.int64) * 200_000_000
    ti = T0 + np.arange(n_imu, dtype=np.int64) * 20_000_000
    lat = 54.4 + rng.uniform(-0.01, 0.01, n_gnss)
    lon = 18.6 + rng.uniform(-0.01, 0.01, n_gnss)
    sig = rng.uniform(0.5, 3.0, n_gnss)
    wz = rng.normal(0, 0.1, n_imu)
    v = rng.uniform(0, 30, n_imu)
    gnss = [(int(t) + 5_000_000, int(t), ros2_fast.encode(
        "navsatfix", int(t), frame[:i % 9], lat=lat[i], lon=lon[i], alt=30.0 + i,
        cov=(sig[i] ** 2, 0, 0, 0, (2 * sig[i]) ** 2, 0, 0, 0, 9.0), cov_type=2, status=i % 3))
        for i, t in enumerate(tg)]
    imu = [(int(t) + 3_000_000, int(t), ros2_fast.encode("imu", int(t), frame[:i % 7], wz=wz[i]))
           for i, t in enumerate(ti)]
    twist = [(int(t) + 4_000_000, int(t), ros2_fast.encode("twist", int(t), "base", vx=v[i]))
             for i, t in enumerate(ti)]
    truth = {"tg": tg, "lat": lat, "lon": lon, "sig": sig, "ti": ti, "wz": wz, "v": v}
    return [("/fix", "navsatfix", gnss), ("/imu", "imu", imu), ("/vel", "twist", twist)], truth


@pytest.fixture(scope="module")
def generated(tmp_path_factory):
    path = tmp_path_factory.mktemp("mcap") / "drive.mcap"
    channels, truth = _drive_channels()
    write_mcap(path, channels, chunk_size=4096)
    return path, truth


# --------------------------------------------------------------------------- real file

def test_real_ublox_recording_counts_and_ranges():
    d = read_mcap(REAL)
    g = d.gnss
    assert len(g) == 3364
    assert d.meta["mcap"]["messages"] == 3 * 3364
    assert {c["topic"]: c["messages"] for c in d.meta["mcap"]["channels"]} == {
        "/gps/fix": 3364, "/gps/fix_velocity": 3364, "/gps/navheading": 3364}
    # Gdansk: 54.37 N 18.61 E; the antenna barely moves (spread < 100 m = 0.001 deg).
    assert np.all(g.valid)
    assert 54.370 < np.min(g.lat_deg) and np.max(g.lat_deg) < 54.372
    assert 18.613 < np.min(g.lon_deg) and np.max(g.lon_deg) < 18.615
    # First fix from the generic decoder: lat 54.3709248, cov diag 0.012321 -> sigma 0.111 m.
    assert g.lat_deg[0] == 54.3709248 and g.lon_deg[0] == 18.6138034
    assert g.sigma_e_m[0] == pytest.approx(0.111, abs=1e-12)
    assert g.t_ns[0] == 1616425418_800331612  # the header stamp, not the log time
    # An F9P with RTK corrections: NavSatStatus says GBAS (no code says RTK), hAcc 1.4-2.6 cm.
    # Those fixes are RTK fixed; the first 15.6 s (FIX, 0.10-0.11 m) and 41 FIX ones stated
    # to 1.7-2.3 cm later (no corrections: not RTK) are not.
    assert g.fix_quality[0] == FIX_GPS
    rtk = g.fix_quality == FIX_RTK
    assert np.count_nonzero(rtk) == 3166 and np.count_nonzero(g.fix_quality == FIX_GPS) == 198
    assert np.fmax(g.sigma_e_m, g.sigma_n_m)[rtk].max() <= 0.05
    assert np.fmax(g.sigma_e_m, g.sigma_n_m)[g.fix_quality == FIX_GPS].max() > 0.05
    # 339 s of 10 Hz stamps, strictly increasing
    assert np.all(np.diff(g.t_ns) > 0)
    assert (g.t_ns[-1] - g.t_ns[0]) / 1e9 == pytest.approx(339.3, abs=0.5)
    # The Imu is /gps/navheading: angular velocity covariance[0] = -1 (not provided).
    assert d.gyro is None
    assert d.skipped.counts["Imu without angular velocity (angular_velocity_covariance[0] = -1)"] == 3364
    # ENU fix velocity beside NavSatFix: the receiver's Doppler velocity, attached to the
    # fixes (same stamps), not an odometer.  A walking-pace antenna: < 2 m/s.
    assert d.odo is None
    assert np.isfinite(g.speed_mps).all() and np.max(g.speed_mps) < 2.0
    assert np.all((g.course_deg >= 0) & (g.course_deg < 360))
    assert d.meta["mcap"]["gnss_velocity"] == {"topic": "/gps/fix_velocity", "fixes": 3364}
    assert any("not as an odometer" in w for w in d.meta["warnings"])
    assert d.sources[0].streams == ("gnss",)
    # with the topic named as the odometer, it is read as one (speed = |linear.xy|)
    d2 = read_mcap(REAL, topics={"odo": "/gps/fix_velocity"})
    np.testing.assert_allclose(d2.odo.speed_mps, g.speed_mps, rtol=1e-12)
    assert not np.isfinite(d2.gnss.speed_mps).any()


def test_real_file_fast_path_matches_generic_decoder():
    """Every message of the real file: fast path == mcap_ros2's generic decoder, bit for bit."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    by_topic: dict[str, list] = {}
    with open(REAL, "rb") as f:
        for schema, channel, message, decoded in make_reader(
                f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            by_topic.setdefault(channel.topic, []).append((schema.name, message.data, decoded))
    for topic, msgs in by_topic.items():
        layout = ros2_fast.LAYOUTS[msgs[0][0]]
        blob = b"".join(m[1] for m in msgs)
        sizes = np.array([len(m[1]) for m in msgs])
        offs = np.concatenate([[0], np.cumsum(sizes)[:-1]])
        fields, ok = ros2_fast.decode(layout, np.frombuffer(blob, np.uint8), offs, sizes)
        assert ok.all(), topic
        for i, (_, _, m) in enumerate(msgs):
            assert fields["stamp_ns"][i] == m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
            if layout == "navsatfix":
                assert (fields["lat"][i], fields["lon"][i], fields["alt"][i]) == (
                    m.latitude, m.longitude, m.altitude)
                assert fields["cov_e"][i] == m.position_covariance[0]
                assert fields["cov_n"][i] == m.position_covariance[4]
                assert fields["status"][i] == m.status.status
                assert fields["cov_type"][i] == m.position_covariance_type
            elif layout == "imu":
                assert fields["wz"][i] == m.angular_velocity.z
                assert fields["wz_cov0"][i] == m.angular_velocity_covariance[0]
            else:
                assert (fields["vx"][i], fields["vy"][i]) == (m.twist.twist.linear.x,
                                                             m.twist.twist.linear.y)


# --------------------------------------------------------------------------- generated

@pytest.mark.parametrize("layout", sorted(ros2_fast.SCHEMAS))
def test_encode_decode_matches_generic_for_every_frame_id_length(layout):
    """Alignment after frame_id lengths 0..9 (all residues mod 8), fast vs generic."""
    from mcap_ros2._dynamic import generate_dynamic

    name, text = ros2_fast.SCHEMAS[layout]
    generic = generate_dynamic(name, text)[name]
    rng = np.random.default_rng(3)
    msgs, kws = [], []
    for k in range(10):
        kw = {"navsatfix": {"lat": rng.uniform(-90, 90), "lon": rng.uniform(-180, 180), "alt": rng.normal(),
                                "cov": tuple(rng.uniform(0, 9, 9)), "cov_type": k % 4, "status": k % 4 - 2},
              "imu": {"wz": rng.normal(), "wz_cov0": rng.uniform()},
              "twist": {"vx": rng.normal(), "vy": rng.normal()},
              "twistcov": {"vx": rng.normal(), "vy": rng.normal()},
              "odometry": {"vx": rng.normal(), "vy": rng.normal(), "child_frame_id": "c" * (9 - k)},
              "sentence": {"text": "$GPGGA," + "1" * k + "*00"}}[layout]
        stamp = T0 + int(rng.integers(0, 10**9))
        msgs.append(ros2_fast.encode(layout, stamp, "f" * k, **kw))
        kws.append((stamp, kw))
    blob = b"".join(msgs)
    sizes = np.array([len(m) for m in msgs])
    offs = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    fields, ok = ros2_fast.decode(layout, np.frombuffer(blob, np.uint8), offs, sizes)
    assert ok.all()
    for i, raw in enumerate(msgs):
        m = generic(raw)
        stamp, kw = kws[i]
        assert fields["stamp_ns"][i] == stamp == m.header.stamp.sec * 10**9 + m.header.stamp.nanosec
        assert m.header.frame_id == "f" * i
        if layout == "navsatfix":
            assert fields["lat"][i] == m.latitude == kw["lat"]
            assert fields["cov_n"][i] == m.position_covariance[4] == kw["cov"][4]
            assert fields["status"][i] == m.status.status == kw["status"]
        elif layout == "imu":
            assert fields["wz"][i] == m.angular_velocity.z == kw["wz"]
        elif layout == "twist":
            assert fields["vx"][i] == m.twist.linear.x == kw["vx"]
        elif layout in ("twistcov", "odometry"):
            assert fields["vx"][i] == m.twist.twist.linear.x == kw["vx"]
            assert fields["vy"][i] == m.twist.twist.linear.y == kw["vy"]
        else:
            o, n = fields["text_off"][i], fields["text_len"][i]
            assert blob[o:o + n].decode() == m.sentence == kw["text"]


def test_generated_drive_values(generated):
    path, truth = generated
    d = read_mcap(path)
    g = d.gnss
    np.testing.assert_array_equal(g.t_ns, truth["tg"])
    status = np.arange(len(truth["tg"])) % 3
    np.testing.assert_array_equal(g.fix_quality, np.where(status == 0, FIX_GPS, FIX_DGPS))
    np.testing.assert_array_equal(g.lat_deg, truth["lat"])
    np.testing.assert_array_equal(g.lon_deg, truth["lon"])
    np.testing.assert_allclose(g.sigma_e_m, truth["sig"], rtol=1e-15)
    np.testing.assert_allclose(g.sigma_n_m, 2 * truth["sig"], rtol=1e-15)
    np.testing.assert_array_equal(d.gyro.t_ns, truth["ti"])
    np.testing.assert_array_equal(d.gyro.yaw_rate_radps, truth["wz"])
    np.testing.assert_array_equal(d.odo.speed_mps, truth["v"])
    assert d.meta["mcap"]["chunks"] > 10 and d.meta["mcap"]["indexed"]
    assert "warnings" not in d.meta and d.skipped.total == 0


def test_use_log_time(generated):
    path, truth = generated
    d = read_mcap(path, use_log_time=True)
    np.testing.assert_array_equal(d.gnss.t_ns, truth["tg"] + 5_000_000)
    np.testing.assert_array_equal(d.gyro.t_ns, truth["ti"] + 3_000_000)


@pytest.mark.parametrize("compression", ["", "lz4", "zstd"])
def test_compressions_and_unindexed(tmp_path, compression):
    channels, truth = _drive_channels(20, 100)
    path = tmp_path / "x.mcap"
    write_mcap(path, channels, compression=compression, chunk_size=2048, index=False)
    d = read_mcap(path)
    np.testing.assert_array_equal(d.gyro.yaw_rate_radps, truth["wz"])
    assert len(d.gnss) == 20 and "warnings" not in d.meta


def test_unchunked_file_and_its_truncation(tmp_path):
    channels, truth = _drive_channels(20, 100)
    path = tmp_path / "flat.mcap"
    raw = write_mcap(path, channels, chunked=False)
    d = read_mcap(path)
    assert d.meta["mcap"]["chunks"] == 0 and "warnings" not in d.meta
    np.testing.assert_array_equal(d.gyro.yaw_rate_radps, truth["wz"])
    np.testing.assert_array_equal(d.odo.speed_mps, truth["v"])
    path.write_bytes(raw[:len(raw) // 2])  # cut mid-record: everything before the cut is kept
    d = read_mcap(path)
    n = len(d.gyro)
    assert 40 < n < 100 and d.meta["warnings"]
    np.testing.assert_array_equal(d.gyro.yaw_rate_radps, truth["wz"][:n])


def test_no_fix_status_nan_and_covariance_type(tmp_path):
    msgs = []
    for i, (status, lat, cov_type) in enumerate([(0, 54.0, 2), (-1, 54.0, 2), (0, float("nan"), 2),
                                                 (0, 54.0, 0), (2, 54.0, 1), (0, 95.0, 2)]):
        t = T0 + i * 10**8
        msgs.append((t, t, ros2_fast.encode("navsatfix", t, "gps", lat=lat, lon=18.0, status=status,
                                            cov=(4.0, 0, 0, 0, 9.0, 0, 0, 0, 1.0), cov_type=cov_type)))
    path = tmp_path / "s.mcap"
    write_mcap(path, [("/fix", "navsatfix", msgs)])
    g = read_mcap(path).gnss
    np.testing.assert_array_equal(g.fix_quality, [FIX_GPS, FIX_NONE, FIX_NONE, FIX_GPS, FIX_DGPS, FIX_NONE])
    assert np.isnan(g.lat_deg[[1, 2, 5]]).all() and g.lat_deg[0] == 54.0
    np.testing.assert_array_equal(g.sigma_e_m[[0, 4]], [2.0, 2.0])
    np.testing.assert_array_equal(g.sigma_n_m[[0, 4]], [3.0, 3.0])
    assert np.isnan(g.sigma_e_m[3])  # covariance type 0: unknown


def test_a_centimetre_covariance_is_an_rtk_fixed_fix(tmp_path):
    """NavSatStatus has no RTK code: a known covariance of <= 5 cm per axis makes a GBAS fix
    RTK fixed (quality 4); an unaugmented one, an SBAS one (the ROS 2 NMEA driver's DGPS at
    HDOP x 0.1 m), an unknown covariance (type 0) or 6 cm does not."""
    cases = [(2, 0.02, 0.03, 2), (0, 0.02, 0.02, 1), (2, 0.06, 0.02, 2), (1, 0.5, 0.5, 2),
             (2, 0.01, 0.01, 0), (-1, 0.01, 0.01, 2), (1, 0.05, 0.05, 2)]
    msgs = []
    for i, (status, sd_e, sd_n, cov_type) in enumerate(cases):
        t = T0 + i * 10**8
        msgs.append((t, t, ros2_fast.encode("navsatfix", t, "gps", lat=54.0, lon=18.0,
                                            status=status, cov_type=cov_type,
                                            cov=(sd_e**2, 0, 0, 0, sd_n**2, 0, 0, 0, 1.0))))
    path = tmp_path / "rtk.mcap"
    write_mcap(path, [("/fix", "navsatfix", msgs)])
    g = read_mcap(path).gnss
    np.testing.assert_array_equal(g.fix_quality,
                                  [FIX_RTK, FIX_GPS, FIX_DGPS, FIX_DGPS, FIX_DGPS, FIX_NONE,
                                   FIX_DGPS])


def test_most_messages_wins_and_topic_override(tmp_path):
    ch1, _ = _drive_channels(10, 40)
    ch2, _truth2 = _drive_channels(10, 80)
    channels = ch1 + [("/imu2", "imu", ch2[1][2])]
    path = tmp_path / "m.mcap"
    write_mcap(path, channels)
    d = read_mcap(path)
    assert d.meta["mcap"]["chosen"]["gyro"] == "/imu2" and len(d.gyro) == 80
    assert d.meta["mcap"]["alternatives"]["gyro"] == ["/imu"]
    assert any("2 gyro channels" in w for w in d.meta["warnings"])
    d = read_mcap(path, topics={"gyro": "/imu"})
    assert len(d.gyro) == 40 and d.meta["mcap"]["chosen"]["gyro"] == "/imu"
    with pytest.raises(UsageError, match="no topic '/nope'.*/imu2"):
        read_mcap(path, topics={"gyro": "/nope"})
    with pytest.raises(UsageError, match="cannot read as gyro"):
        read_mcap(path, topics={"gyro": "/fix"})


def test_odometry_twistcov_and_zero_stamp_fallback(tmp_path):
    odo, tw = [], []
    for i in range(20):
        t = T0 + i * 10**8
        stamp = 0 if i == 3 else t
        odo.append((t, t, ros2_fast.encode("odometry", stamp, "odom", vx=float(i), vy=0.01,
                                           child_frame_id="base_link")))
        tw.append((t, t, ros2_fast.encode("twistcov", t, "b", vx=-float(i))))
    path = tmp_path / "o.mcap"
    write_mcap(path, [("/odom", "odometry", odo)])
    d = read_mcap(path)
    np.testing.assert_array_equal(d.odo.speed_mps, np.arange(20.0))
    np.testing.assert_array_equal(d.odo.t_ns, T0 + np.arange(20) * 10**8)  # stamp 0 -> log time
    assert d.meta["mcap"]["zero_stamps"] == {"/odom": 1}
    write_mcap(path, [("/tw", "twistcov", tw)])
    np.testing.assert_array_equal(read_mcap(path).odo.speed_mps, -np.arange(20.0))  # reversing


def test_fast_path_declines_and_generic_fallback_decodes(tmp_path):
    """Nanoseconds >= 1e9 and big-endian encapsulation: fast path says no, generic decodes."""
    good = ros2_fast.encode("imu", T0, "imu", wz=0.5)
    odd_ns = bytearray(good)
    odd_ns[8:12] = struct.pack("<I", 1_500_000_000)  # nanosec field
    sec = T0 // 10**9
    path = tmp_path / "f.mcap"
    write_mcap(path, [("/imu", "imu", [(T0, T0, good), (T0 + 1, T0 + 1, bytes(odd_ns))])])
    buf = np.frombuffer(bytes(odd_ns), np.uint8)
    _, ok = ros2_fast.decode("imu", buf, np.array([0]), np.array([len(odd_ns)]))
    assert not ok[0]
    d = read_mcap(path)
    np.testing.assert_array_equal(d.gyro.yaw_rate_radps, [0.5, 0.5])
    assert d.gyro.t_ns[1] == sec * 10**9 + 1_500_000_000


LOCFIX_JSON = ("foxglove.LocationFix", "jsonschema", b'{"type":"object"}')
LOCFIX_PB = ("foxglove.LocationFix", "protobuf", b"")  # no descriptor: the published numbers
NAVSAT_JSON = ("sensor_msgs/msg/NavSatFix", "jsonschema", b'{"type":"object"}')


def _pb_varint(v: int) -> bytes:
    out = bytearray()
    v &= (1 << 64) - 1
    while True:
        b = v & 0x7F
        v >>= 7
        out.append(b | (0x80 if v else 0))
        if not v:
            return bytes(out)


def _ld(num: int, payload: bytes) -> bytes:
    return _pb_varint(num << 3 | 2) + _pb_varint(len(payload)) + payload


def _vi(num: int, value: int) -> bytes:
    return _pb_varint(num << 3) + _pb_varint(value)


def _d(num: int, value: float) -> bytes:
    return _pb_varint(num << 3 | 1) + struct.pack("<d", value)


LOCFIX_NUMS = {"latitude": 1, "longitude": 2, "altitude": 3, "position_covariance": 4,
               "position_covariance_type": 5, "timestamp": 6, "frame_id": 7}


def _pb_location_fix(sec: int, nsec: int, lat: float, lon: float, cov: list[float], cov_type: int,
                     nums: dict[str, int] = LOCFIX_NUMS) -> bytes:
    ts = _vi(1, sec) + _vi(2, nsec)
    packed = struct.pack(f"<{len(cov)}d", *cov)
    return (_ld(nums["timestamp"], ts) + _ld(nums["frame_id"], b"gps") + _d(nums["latitude"], lat)
            + _d(nums["longitude"], lon) + _d(nums["altitude"], 12.5)
            + _ld(nums["position_covariance"], packed) + _vi(nums["position_covariance_type"], cov_type))


def _descriptor_set(nums: dict[str, int]) -> bytes:
    """A FileDescriptorSet for foxglove.LocationFix with the given field numbers."""
    fields = b"".join(_ld(2, _ld(1, name.encode()) + _vi(3, num)) for name, num in nums.items())
    message = _ld(1, b"LocationFix") + fields
    file = _ld(1, b"foxglove/LocationFix.proto") + _ld(2, b"foxglove") + _ld(4, message)
    return _ld(1, file)


def test_protobuf_field_numbers_come_from_the_descriptor(tmp_path):
    nums = {k: v + 20 for k, v in LOCFIX_NUMS.items()}  # renumbered: only the descriptor says so
    msgs = [(T0 + i, T0 + i, _pb_location_fix(T0 // 10**9, i, 54.0 + i, 18.0, [1.0] * 9, 1, nums))
            for i in range(3)]
    schemas = {"loc:protobuf": ("foxglove.LocationFix", "protobuf", _descriptor_set(nums))}
    p = tmp_path / "pb.mcap"
    write_mcap(p, [("/loc", "loc:protobuf", msgs)], schemas=schemas)
    g = read_mcap(p).gnss
    np.testing.assert_array_equal(g.lat_deg, [54.0, 55.0, 56.0])
    np.testing.assert_array_equal(g.t_ns, T0 + np.arange(3))
    np.testing.assert_array_equal(g.sigma_n_m, 1.0)


@pytest.mark.parametrize("encoding", ["json", "protobuf", "ros-json"])
def test_location_fix_json_protobuf_and_json_navsatfix(tmp_path, encoding):
    msgs = []
    for i in range(5):
        t = T0 + i * 10**9
        sec, nsec = divmod(t, 10**9)
        lat, lon = 54.4 + i * 1e-4, 18.6 - i * 1e-4
        cov = [4.0, 0, 0, 0, 1.0, 0, 0, 0, 9.0]
        if encoding == "json":
            data = json.dumps({"timestamp": {"sec": sec, "nsec": nsec + 7}, "frame_id": "gps",
                               "latitude": lat, "longitude": lon, "altitude": 12.5,
                               "position_covariance": cov, "position_covariance_type": 2}).encode()
        elif encoding == "protobuf":
            data = _pb_location_fix(sec, nsec + 7, lat, lon, cov, 2)
        else:
            data = json.dumps({"header": {"stamp": {"sec": sec, "nanosec": nsec + 7}, "frame_id": "g"},
                               "status": {"status": 0, "service": 1}, "latitude": lat,
                               "longitude": lon, "altitude": 12.5, "position_covariance": cov,
                               "position_covariance_type": 2}).encode()
        msgs.append((t, t, data))
    key = {"json": "loc:json", "protobuf": "loc:protobuf", "ros-json": "nav:json"}[encoding]
    schemas = {"loc:json": LOCFIX_JSON, "loc:protobuf": LOCFIX_PB, "nav:json": NAVSAT_JSON}
    path = tmp_path / "l.mcap"
    write_mcap(path, [("/loc", key, msgs)], schemas=schemas)
    g = read_mcap(path).gnss
    np.testing.assert_array_equal(g.t_ns, T0 + np.arange(5) * 10**9 + 7)
    np.testing.assert_allclose(g.lat_deg, 54.4 + np.arange(5) * 1e-4, rtol=0, atol=1e-12)
    np.testing.assert_allclose(g.lon_deg, 18.6 - np.arange(5) * 1e-4, rtol=0, atol=1e-12)
    np.testing.assert_array_equal(g.sigma_e_m, 2.0)
    np.testing.assert_array_equal(g.alt_m, 12.5)


def test_nmea_sentences_in_mcap(tmp_path):
    from gpsdr_cli.io.nmea import parse_nmea

    def ck(body: str) -> str:
        c = 0
        for ch in body.encode():
            c ^= ch
        return f"${body}*{c:02X}"

    # 2023-11-14 22:13:20 UTC = T0; GGA has no date: it must come from the stamps.
    lines = [ck(f"GPGGA,2213{20 + i:02d}.00,5424.0000,N,01836.0000,E,1,08,0.9,30.0,M,32.0,M,,")
             for i in range(10)]
    msgs = [(T0 + i * 10**9, T0 + i * 10**9,
             ros2_fast.encode("sentence", T0 + i * 10**9, "gps", text=s)) for i, s in enumerate(lines)]
    path = tmp_path / "n.mcap"
    write_mcap(path, [("/nmea", "sentence", msgs)])
    d = read_mcap(path)
    np.testing.assert_array_equal(d.gnss.t_ns, T0 + np.arange(10) * 10**9)
    np.testing.assert_allclose(d.gnss.lat_deg, 54.4, atol=1e-12)
    np.testing.assert_allclose(d.gnss.lon_deg, 18.6, atol=1e-12)
    ref, _, _ = parse_nmea("\r\n".join(lines).encode(), date=__import__("datetime").date(2023, 11, 14))
    np.testing.assert_array_equal(ref.t_ns, d.gnss.t_ns)


# --------------------------------------------------------------------------- damage

def test_truncated_file_reads_up_to_the_damage(generated, tmp_path):
    path, truth = generated
    raw = path.read_bytes()
    full = read_mcap(path)
    for cut in (len(raw) // 3, len(raw) // 2, len(raw) - 100):
        p = tmp_path / f"cut{cut}.mcap"
        p.write_bytes(raw[:cut])
        d = read_mcap(p)
        assert d.meta["warnings"], cut
        assert cut == len(raw) - 100 or any("MCAP" in r for r in d.skipped.counts)
        n = len(d.gyro)
        assert 0 < n <= len(full.gyro)
        # What was read is exactly the prefix of the full file.
        np.testing.assert_array_equal(d.gyro.yaw_rate_radps, truth["wz"][:n])
    assert len(read_mcap(tmp_path / f"cut{len(raw) - 100}.mcap").gyro) == len(truth["wz"])


def test_corrupt_chunk_is_skipped_not_fatal(generated, tmp_path):
    path, truth = generated
    raw = bytearray(path.read_bytes())
    raw[len(raw) // 2] ^= 0xFF
    p = tmp_path / "flip.mcap"
    p.write_bytes(bytes(raw))
    d = read_mcap(p)
    assert d.meta["warnings"]
    assert len(d.gyro) < len(truth["wz"])
    assert set(d.gyro.yaw_rate_radps) <= set(truth["wz"])


@pytest.mark.parametrize("content, match", [
    (b"", "empty file"),
    (b"hello world, not an mcap", "not an MCAP file"),
    (b"\x89MCAP0\r\n", "no readable GNSS"),
])
def test_garbage_is_an_input_error_naming_the_file(tmp_path, content, match):
    p = tmp_path / "bad.mcap"
    p.write_bytes(content)
    with pytest.raises(InputError, match=match) as err:
        read_mcap(p)
    assert str(p) in str(err.value)


def test_no_known_channels_is_no_data_error(tmp_path):
    schemas = {"x:json": ("my/Thing", "jsonschema", b"{}")}
    p = tmp_path / "other.mcap"
    write_mcap(p, [("/thing", "x:json", [(T0, T0, b"{}")])], schemas=schemas)
    with pytest.raises(NoDataError, match=r"/thing \(my/Thing\)"):
        read_mcap(p)


def test_committed_sample_files_read():
    """tests/data/mcap: a small drive (zstd, indexed) and its truncated copy."""
    d = read_mcap(DATA / "small_drive.mcap")
    assert (len(d.gnss), len(d.gyro), len(d.odo)) == (20, 100, 100)
    assert np.all(d.gnss.valid) and 54.3 < d.gnss.lat_deg.mean() < 54.5
    t = read_mcap(DATA / "small_drive_truncated.mcap")
    assert t.meta["warnings"] and len(t.gyro) < 100


def test_ros1_encoding(tmp_path):
    """ROS 1 serialisation (converted bags): no CDR header, no padding, seq before the stamp."""
    cov = (4.0, 0, 0, 0, 9.0, 0, 0, 0, 1.0)
    msgs, imus = [], []
    for i in range(6):
        t = T0 + i * 10**8
        sec, nsec = divmod(t, 10**9)
        # sensor_msgs/NavSatFix by the ROS 1 rules, packed by hand
        hand = (struct.pack("<III", i, sec, nsec) + struct.pack("<I", 3) + b"gps"
                + struct.pack("<bH", 0, 1) + struct.pack("<3d", 54.0 + i * 1e-5, 18.0, 5.0)
                + struct.pack("<9d", *cov) + struct.pack("<B", 2))
        enc = ros2_fast.encode("navsatfix", t, "gps", ros1=True, lat=54.0 + i * 1e-5, lon=18.0, alt=5.0,
                               cov=cov, cov_type=2)
        assert enc[4:] == hand[4:]  # identical but for seq
        msgs.append((t, t, hand))
        imus.append((t, t, ros2_fast.encode("imu", t, "imu" * i, ros1=True, wz=0.1 * i)))
    schemas = {"nav:ros1": ("sensor_msgs/NavSatFix", "ros1msg", b"Header header\n..."),
               "imu:ros1": ("sensor_msgs/Imu", "ros1msg", b"Header header\n...")}
    p = tmp_path / "r1.mcap"
    write_mcap(p, [("/fix", "nav:ros1", msgs), ("/imu", "imu:ros1", imus)], schemas=schemas)
    d = read_mcap(p)
    np.testing.assert_array_equal(d.gnss.t_ns, T0 + np.arange(6) * 10**8)
    np.testing.assert_array_equal(d.gnss.lat_deg, 54.0 + np.arange(6) * 1e-5)
    np.testing.assert_array_equal(d.gnss.sigma_n_m, 3.0)
    np.testing.assert_array_equal(d.gyro.yaw_rate_radps, 0.1 * np.arange(6))


def test_enu_twist_and_partial_imu(tmp_path):
    """A navigation-frame twist (driving north: linear.y carries the speed) is read as
    |linear.xy|; Imu messages with covariance[0] = -1 are skipped one by one."""
    tw, imu = [], []
    for i in range(30):
        t = T0 + i * 10**8
        tw.append((t, t, ros2_fast.encode("twistcov", t, "gps", vx=0.3, vy=10.0)))
        flagged = i % 3 == 0  # flagged "no angular velocity" and all-zero, as drivers write it
        imu.append((t, t, ros2_fast.encode("imu", t, "imu", wz=0.0 if flagged else 0.2,
                                           wz_cov0=-1.0 if flagged else 0.01)))
    p = tmp_path / "enu.mcap"
    write_mcap(p, [("/gps/fix_velocity", "twistcov", tw), ("/imu", "imu", imu)])
    d = read_mcap(p)
    np.testing.assert_allclose(d.odo.speed_mps, np.hypot(0.3, 10.0), rtol=1e-15)
    assert any("navigation-frame" in w for w in d.meta["warnings"])
    assert len(d.gyro) == 20
    assert d.skipped.counts["Imu without angular velocity (angular_velocity_covariance[0] = -1)"] == 10


def test_imu_flagged_without_angular_velocity_but_varying_is_kept(tmp_path):
    imu = [(T0 + i, T0 + i, ros2_fast.encode("imu", T0 + i, "imu", wz=0.01 * i, wz_cov0=-1.0))
           for i in range(10)]
    p = tmp_path / "sloppy.mcap"
    write_mcap(p, [("/imu", "imu", imu)])
    d = read_mcap(p)
    np.testing.assert_array_equal(d.gyro.yaw_rate_radps, 0.01 * np.arange(10))
    assert any("read anyway" in w for w in d.meta["warnings"])


def test_index_lets_camera_only_chunks_be_skipped(tmp_path):
    """A log with a big image topic: chunks holding only images are not decompressed
    (the CRC-checked summary says so); the result equals a full, unindexed read."""
    channels, truth = _drive_channels(20, 100)
    big = [(T0 + 2_000_000_000 + i * 10**7, T0, b'{"data": "' + b"x" * 20000 + b'"}')
           for i in range(60)]
    schemas = {"img:json": ("foxglove.CompressedImage", "jsonschema", b"{}")}
    indexed, flat = tmp_path / "cam.mcap", tmp_path / "cam_flat.mcap"
    write_mcap(indexed, [*channels, ("/camera", "img:json", big)], schemas=schemas, chunk_size=30000)
    write_mcap(flat, [*channels, ("/camera", "img:json", big)], schemas=schemas, chunk_size=30000,
               index=False)
    a, b = read_mcap(indexed), read_mcap(flat)
    assert a.meta["mcap"]["chunks_skipped"] > 10 and "chunks_skipped" not in b.meta["mcap"]
    for s in ("gnss", "gyro", "odo"):
        np.testing.assert_array_equal(getattr(a, s).t_ns, getattr(b, s).t_ns)
    np.testing.assert_array_equal(a.gyro.yaw_rate_radps, truth["wz"])
    counts = {c["topic"]: c["messages"] for c in a.meta["mcap"]["channels"]}
    assert counts == {"/fix": 20, "/imu": 100, "/vel": 100, "/camera": 60}


def test_enu_velocity_becomes_the_fixes_speed_and_course(tmp_path):
    """Beside NavSatFix, an ENU twist (x east, y north) gives each fix its speed and course
    (clockwise from north); a body-frame twist stays the odometer."""
    fixes, vel, odo = [], [], []
    for i in range(30):
        t = T0 + i * 2 * 10**8
        fixes.append((t, t, ros2_fast.encode("navsatfix", t, "gps", lat=37.0 + 1e-6 * i,
                                             lon=-122.0, alt=10.0, status=0, cov_type=2,
                                             cov=[1.0, 0, 0, 0, 1.0, 0, 0, 0, 4.0])))
        # heading 150 deg (south-south-east) at 8 m/s; the message 20 ms after the fix
        vel.append((t + 2 * 10**7, t + 2 * 10**7,
                    ros2_fast.encode("twistcov", t + 2 * 10**7, "gps", vx=4.0,
                                     vy=-8.0 * np.cos(np.radians(30)))))
        odo.append((t, t, ros2_fast.encode("twist", t, "base_link", vx=7.9, vy=0.0)))
    p = tmp_path / "vel.mcap"
    write_mcap(p, [("/fix", "navsatfix", fixes), ("/fix_velocity", "twistcov", vel),
                   ("/wheel", "twist", odo)])
    d = read_mcap(p)
    np.testing.assert_allclose(d.gnss.speed_mps, np.hypot(4.0, 8.0 * np.cos(np.radians(30))), rtol=1e-12)
    course_deg = np.degrees(np.arctan2(4.0, -8.0 * np.cos(np.radians(30)))) % 360
    np.testing.assert_allclose(d.gnss.course_deg, course_deg, rtol=1e-12)
    assert d.gnss.course_deg[0] == pytest.approx(150.0, abs=1e-9)  # clockwise from north
    np.testing.assert_allclose(d.odo.speed_mps, 7.9)
    assert d.meta["mcap"]["chosen"]["odo"] == "/wheel"
    assert not any("not as an odometer" in w for w in d.meta.get("warnings", []))
