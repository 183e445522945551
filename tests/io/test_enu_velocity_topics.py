"""The frame of a twist topic's ``linear`` velocity: ENU (x east, y north, as the GNSS
drivers publish /vel and /fix_velocity) or the body frame (x = forward speed), decided
from the fixes' own motion, else from the twist alone, on logs built as the ROS drivers
publish them.  Speeds m/s; course in degrees clockwise from north."""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pytest

from gpsdr_cli.geodesy import LocalFrame
from gpsdr_cli.io import ros2_fast
from gpsdr_cli.io.mcap import read_mcap
from gpsdr_cli.io.rosbag import read_rosbag

T0 = 1_700_000_000_000_000_000
LAT0, LON0 = 37.40, -122.10


def _drive(heading_deg: float, speed_mps: float, duration_s: float, rate_hz: float,
           fix_sd_m: float, seed: int = 3) -> dict[str, np.ndarray]:
    """A drive at ``speed_mps`` whose heading (clockwise from north) wanders +-4 deg
    about ``heading_deg``: stamps, noisy fix lat/lon, and the true ENU velocity at them."""
    rng = np.random.default_rng(seed)
    fine_hz = 50.0  # positions integrated finely, then sampled at the message rate
    t = np.arange(0.0, duration_s, 1.0 / fine_hz)
    psi = np.radians(heading_deg + 4.0 * np.sin(2 * np.pi * t / 40.0))
    ve, vn = speed_mps * np.sin(psi), speed_mps * np.cos(psi)
    e = np.concatenate([[0.0], np.cumsum((ve[1:] + ve[:-1]) / 2 / fine_hz)])
    n = np.concatenate([[0.0], np.cumsum((vn[1:] + vn[:-1]) / 2 / fine_hz)])
    k = np.arange(0, len(t), int(round(fine_hz / rate_hz)))
    lat, lon = LocalFrame.centred_on(LAT0, LON0).inverse(
        e[k] + rng.normal(0.0, fix_sd_m, len(k)), n[k] + rng.normal(0.0, fix_sd_m, len(k)))
    return {"t_ns": T0 + np.round(t[k] * 1e9).astype(np.int64), "lat": lat, "lon": lon,
            "ve": ve[k], "vn": vn[k]}


def _fix(t: int, lat: float, lon: float, sd_m: float, ros1: bool = False) -> bytes:
    var = sd_m ** 2
    return ros2_fast.encode("navsatfix", t, "gps", ros1=ros1, lat=lat, lon=lon, alt=30.0,
                            status=0, cov=(var, 0, 0, 0, var, 0, 0, 0, 4 * var), cov_type=2)


def _write_mcap(path: Path, channels: list[tuple[str, str, list[tuple[int, bytes]]]]) -> Path:
    """ROS 2 CDR channels ``(topic, ros2_fast layout, [(stamp_ns, data)])``, log time = stamp."""
    from mcap.writer import Writer

    buf = io.BytesIO()
    w = Writer(buf)
    w.start(profile="ros2", library="gpsdr tests")
    events = []
    for topic, layout, msgs in channels:
        name, text = ros2_fast.SCHEMAS[layout]
        cid = w.register_channel(topic, "cdr", w.register_schema(name, "ros2msg", text.encode()))
        events += [(t, cid, data) for t, data in msgs]
    for t, cid, data in sorted(events, key=lambda ev: ev[0]):
        w.add_message(cid, log_time=t, data=data, publish_time=t)
    w.finish()
    path.write_bytes(buf.getvalue())
    return path


def _frame(d, container: str = "mcap") -> dict[str, dict[str, str]]:
    return d.meta[container]["twist_frame"]


def test_nmea_navsat_driver_vel_driving_west_is_enu(tmp_path: Path) -> None:
    """nmea_navsat_driver in a ROS 1 bag: /fix NavSatFix and /vel TwistStamped (ENU,
    from RMC) at 1 Hz, driving west at 15 m/s: x = east = -15 m/s.  Read as a forward
    speed it was an odometer of -15 m/s; it is the fixes' velocity, course ~270 deg."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    dr = _drive(270.0, 15.0, 120.0, 1.0, fix_sd_m=0.5)
    ts = get_typestore(Stores.ROS1_NOETIC)
    path = tmp_path / "nmea_navsat_west.bag"
    w = Writer(path)
    w.open()
    c_fix = w.add_connection("/fix", "sensor_msgs/msg/NavSatFix", typestore=ts)
    c_vel = w.add_connection("/vel", "geometry_msgs/msg/TwistStamped", typestore=ts)
    for i, t in enumerate(dr["t_ns"].tolist()):
        w.write(c_fix, t, _fix(t, dr["lat"][i], dr["lon"][i], 0.5, ros1=True))
        w.write(c_vel, t, ros2_fast.encode("twist", t, "gps", ros1=True, vx=dr["ve"][i],
                                           vy=dr["vn"][i]))
    w.close()

    d = read_rosbag(path)
    assert _frame(d, "rosbag")["/vel"]["frame"] == "enu"
    assert d.odo is None  # no odometer of -15 m/s
    assert d.meta["rosbag"]["gnss_velocity"] == {"topic": "/vel", "fixes": 120}
    np.testing.assert_allclose(d.gnss.speed_mps, np.hypot(dr["ve"], dr["vn"]), rtol=1e-12)
    np.testing.assert_allclose(d.gnss.speed_mps, 15.0, rtol=1e-12)
    course = np.degrees(np.arctan2(dr["ve"], dr["vn"])) % 360.0  # clockwise from north
    np.testing.assert_allclose(d.gnss.course_deg, course, rtol=1e-12)
    assert np.all(np.abs(d.gnss.course_deg - 270.0) < 4.01)
    assert any("/vel" in w and "not as an odometer" in w for w in d.meta["warnings"])

    # named as the odometer, it is a speed: |(x, y)| = 15 m/s, never -15
    o = read_rosbag(path, topics={"odo": "/vel"})
    np.testing.assert_allclose(o.odo.speed_mps, 15.0, rtol=1e-12)
    assert any("navigation-frame (ENU)" in w for w in o.meta["warnings"])


@pytest.mark.parametrize(("heading_deg", "speed_mps", "fix_sd_m"), [
    (0.0, 12.0, 0.8),     # north: the lateral y carries the speed
    (270.0, 0.8, 0.02),   # a slow robot heading west, RTK fixes: x = -0.8 m/s
])
def test_ublox_fix_velocity_is_enu(tmp_path: Path, heading_deg: float, speed_mps: float,
                                   fix_sd_m: float) -> None:
    """The u-blox driver: /fix and /fix_velocity (TwistWithCovarianceStamped, ENU) with
    the same stamps at 5 Hz: the velocity becomes the fixes' speed and course."""
    dr = _drive(heading_deg, speed_mps, 90.0, 5.0, fix_sd_m)
    rng = np.random.default_rng(5)
    vx = dr["ve"] + rng.normal(0.0, 0.02, len(dr["ve"]))  # Doppler noise, m/s
    vy = dr["vn"] + rng.normal(0.0, 0.02, len(dr["vn"]))
    t = dr["t_ns"].tolist()
    fixes = [(s, _fix(s, dr["lat"][i], dr["lon"][i], fix_sd_m)) for i, s in enumerate(t)]
    vel = [(s, ros2_fast.encode("twistcov", s, "gps", vx=vx[i], vy=vy[i])) for i, s in enumerate(t)]
    d = read_mcap(_write_mcap(tmp_path / "ublox.mcap", [("/fix", "navsatfix", fixes),
                                                         ("/fix_velocity", "twistcov", vel)]))
    reading = _frame(d)["/fix_velocity"]
    assert reading["frame"] == "enu" and "fixes' displacement" in reading["evidence"]
    assert d.odo is None
    np.testing.assert_allclose(d.gnss.speed_mps, np.hypot(vx, vy), rtol=1e-12)
    assert abs(np.median(d.gnss.speed_mps) - speed_mps) < 0.01 * speed_mps + 0.01
    np.testing.assert_allclose(d.gnss.course_deg, np.degrees(np.arctan2(vx, vy)) % 360.0,
                               rtol=1e-12)
    off = (d.gnss.course_deg - heading_deg + 180.0) % 360.0 - 180.0  # the +-4 deg wander
    assert abs(np.median(off)) < 1.0 and np.all(np.abs(off) < 8.0)


def test_body_twist_driving_west_stays_a_forward_speed(tmp_path: Path) -> None:
    """A wheel odometer (nav_msgs/Odometry, twist in child frame base_link) on a car
    heading west: x = +14 m/s forward, then 8 s reversing at -1.5 m/s.  The fixes move
    west at the same speed: it is a forward speed, sign kept, and not the fixes' velocity."""
    dr = _drive(270.0, 14.0, 100.0, 1.0, fix_sd_m=0.5)
    t_odo = T0 + np.arange(0, 108_000, 20, dtype=np.int64) * 1_000_000  # 50 Hz, 108 s
    speed = np.where(t_odo < T0 + 100 * 10**9, 14.0, -1.5)
    fixes = [(s, _fix(s, dr["lat"][i], dr["lon"][i], 0.5)) for i, s in enumerate(dr["t_ns"].tolist())]
    odo = [(s, ros2_fast.encode("odometry", s, "odom", vx=speed[i], vy=0.0,
                                child_frame_id="base_link")) for i, s in enumerate(t_odo.tolist())]
    d = read_mcap(_write_mcap(tmp_path / "wheel.mcap", [("/fix", "navsatfix", fixes),
                                                        ("/odom", "odometry", odo)]))
    reading = _frame(d)["/odom"]
    assert reading["frame"] == "body" and reading["speed"] == "x"
    assert "fixes' displacement" in reading["evidence"]
    np.testing.assert_array_equal(d.odo.speed_mps, speed)
    assert np.median(d.odo.speed_mps) == 14.0 and d.odo.speed_mps.min() == -1.5
    assert np.isnan(d.gnss.speed_mps).all()  # not taken as the receiver's velocity
    assert "gnss_velocity" not in d.meta["mcap"]
    assert not any("/odom" in w for w in d.meta.get("warnings", []))


def test_parked_log_reads_speed_magnitude_and_says_so(tmp_path: Path) -> None:
    """Parked: fixes scattered by 1 m about one point, /fix_velocity Doppler noise of
    0.05 m/s.  Neither frame can be told: speed = |(x, y)| (>= 0, right in either frame),
    not attached to the fixes as a course, and a warning names the topic."""
    rng = np.random.default_rng(11)
    t = (T0 + np.arange(300, dtype=np.int64) * 10**9).tolist()
    lat, lon = LocalFrame.centred_on(LAT0, LON0).inverse(rng.normal(0, 1.0, 300),
                                                         rng.normal(0, 1.0, 300))
    vx, vy = rng.normal(0, 0.05, 300), rng.normal(0, 0.05, 300)
    fixes = [(s, _fix(s, lat[i], lon[i], 1.0)) for i, s in enumerate(t)]
    vel = [(s, ros2_fast.encode("twistcov", s, "gps", vx=vx[i], vy=vy[i])) for i, s in enumerate(t)]
    d = read_mcap(_write_mcap(tmp_path / "parked.mcap", [("/fix", "navsatfix", fixes),
                                                         ("/fix_velocity", "twistcov", vel)]))
    reading = _frame(d)["/fix_velocity"]
    assert reading["frame"] == "unknown" and reading["speed"] == "hypot(x, y)"
    np.testing.assert_allclose(d.odo.speed_mps, np.hypot(vx, vy), rtol=1e-15)
    assert d.odo.speed_mps.min() >= 0.0 and d.odo.speed_mps.max() < 0.3
    assert np.isnan(d.gnss.course_deg).all()
    assert any("/fix_velocity" in w and "too little motion" in w for w in d.meta["warnings"])


@pytest.mark.parametrize("vx", [
    -12.0,   # strongly negative for 120 s: an ENU velocity heading west
    -0.8,    # slowly backwards for 120 s (median < 0): no reversing lasts that long
])
def test_long_negative_forward_speed_without_fixes_is_flipped(tmp_path: Path, vx: float) -> None:
    """No fixes to compare with: a "forward speed" negative for two minutes is not one;
    it is read as |(x, y)| with a warning naming the topic."""
    rng = np.random.default_rng(2)
    t = (T0 + np.arange(1200, dtype=np.int64) * 10**8).tolist()  # 10 Hz, 120 s
    x = vx + rng.normal(0, 0.05, 1200)
    tw = [(s, ros2_fast.encode("twist", s, "base", vx=x[i], vy=0.0)) for i, s in enumerate(t)]
    d = read_mcap(_write_mcap(tmp_path / "neg.mcap", [("/vel", "twist", tw)]))
    assert _frame(d)["/vel"]["frame"] == "unknown"
    np.testing.assert_allclose(d.odo.speed_mps, np.abs(x), rtol=1e-15)
    assert np.median(d.odo.speed_mps) == pytest.approx(-vx, abs=0.01)
    assert any("/vel" in w and "not a forward speed" in w for w in d.meta["warnings"])


def test_short_reversing_without_fixes_keeps_its_sign(tmp_path: Path) -> None:
    """Only 6 s of motion, all backwards at -1.5 m/s: a reversing manoeuvre, kept signed
    (with a warning); 60 s forward with 8 s of it stays signed and silent."""
    t = T0 + np.arange(680, dtype=np.int64) * 10**8
    rev = np.where(t < T0 + 6 * 10**9, -1.5, 0.0)
    fwd = np.where(t < T0 + 60 * 10**9, 9.0, -1.5)
    for name, x, warned in (("rev", rev, True), ("fwd", fwd, False)):
        tw = [(s, ros2_fast.encode("twist", s, "base_link", vx=x[i])) for i, s in enumerate(t.tolist())]
        d = read_mcap(_write_mcap(tmp_path / f"{name}.mcap", [("/vel", "twist", tw)]))
        assert _frame(d)["/vel"]["frame"] == "body"
        np.testing.assert_array_equal(d.odo.speed_mps, x)
        assert any("kept as reversing" in w for w in d.meta.get("warnings", [])) == warned
