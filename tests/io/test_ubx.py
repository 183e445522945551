"""UBX reader: pyubx2-generated messages for each field case, mixed UBX + NMEA, damage,
the ESF time mapping, fuzzing, and `gpsdr fuse` on an F9R-like log of a simulated drive."""

from __future__ import annotations

import datetime as dt
import math
import struct
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st
from pyubx2 import UBXMessage, UBXReader

from gpsdr_cli.errors import GpsdrError, NoDataError
from gpsdr_cli.io.readers import read_drive, sniff
from gpsdr_cli.io.ubx import esf_offset_ns, parse_ubx, read_ubx
from gpsdr_cli.testing.faults import horizontal_error_m
from gpsdr_cli.testing.ubx_log import esf_meas, nav_pvt, ubx_log

T0 = int(dt.datetime(2026, 5, 4, 10, 20, 30, tzinfo=dt.UTC).timestamp()) * 10**9
LAT_TOL_DEG = 1e-9       # NAV-PVT carries 1e-7 deg; HPPOSLLH 1e-9 deg
SIGMA_TOL_M = 1e-9


def _one(frames: bytes, **kw) -> object:
    return parse_ubx(frames, name="t.ubx", **kw)


@pytest.mark.parametrize(("quality", "expect"), [(4, 4), (5, 5), (2, 2), (1, 1), (6, 6), (0, 0)])
def test_nav_pvt_fix_quality_from_fix_type_and_carrier_solution(quality: int, expect: int) -> None:
    frames = b"".join(nav_pvt(T0 + i * 200_000_000, lat=54.1 + i * 1e-5, lon=18.6, quality=quality,
                              h_acc_m=0.02, ve=3.0, vn=4.0) for i in range(3))
    g = _one(frames).gnss
    assert g is not None and len(g) == 3
    assert (g.fix_quality == expect).all()
    if expect == 0:
        assert np.isnan(g.lat_deg).all()
        return
    assert np.array_equal(g.t_ns, T0 + np.arange(3) * 200_000_000)
    assert np.max(np.abs(g.lat_deg - (54.1 + np.arange(3) * 1e-5))) < LAT_TOL_DEG
    assert abs(g.sigma_e_m[0] - 0.02 / math.sqrt(2)) < SIGMA_TOL_M
    assert g.speed_mps[0] == pytest.approx(5.0, abs=1e-9)
    # course clockwise from north: east 3, north 4 -> atan2(3, 4)
    assert g.course_deg[0] == pytest.approx(math.degrees(math.atan2(3.0, 4.0)), abs=1e-9)
    assert g.n_sats[0] == 12 and g.pdop[0] == pytest.approx(1.5)
    assert g.alt_m[0] == pytest.approx(50.0, abs=1e-9)  # height above the ellipsoid


def test_nav_pvt_without_valid_utc_is_skipped_and_counted() -> None:
    frames = nav_pvt(T0, lat=54.0, lon=18.0) + nav_pvt(T0 + 10**9, lat=54.0, lon=18.0, valid=False)
    d = _one(frames)
    assert len(d.gnss) == 1 and d.gnss.t_ns[0] == T0
    assert d.skipped.counts["UBX NAV-PVT without a valid, fully resolved UTC time (skipped)"] == 1


def test_values_agree_with_pyubx2_parse() -> None:
    frame = nav_pvt(T0 + 123_000_000, lat=-33.8688197, lon=151.2092955, quality=5, h_acc_m=0.35,
                    ve=-1.25, vn=0.5)
    ref = UBXReader.parse(frame)
    g = _one(frame).gnss
    assert g.lat_deg[0] == pytest.approx(ref.lat, abs=LAT_TOL_DEG)
    assert g.lon_deg[0] == pytest.approx(ref.lon, abs=LAT_TOL_DEG)
    assert g.sigma_e_m[0] == pytest.approx(ref.hAcc / 1000 / math.sqrt(2), abs=SIGMA_TOL_M)
    assert g.speed_mps[0] == pytest.approx(math.hypot(ref.velN, ref.velE) / 1000, abs=1e-9)
    assert g.t_ns[0] == T0 + 123_000_000


def _itow(t_ns: int) -> int:
    return ((t_ns // 10**9 - 315964800 + 18) % 604800) * 1000 + (t_ns % 10**9) // 10**6


def test_nav_dop_and_hpposllh_matched_by_itow() -> None:
    pvt = nav_pvt(T0, lat=54.1, lon=18.6, quality=4)
    dop = UBXMessage("NAV", "NAV-DOP", 0, iTOW=_itow(T0), pDOP=1.8, hDOP=0.9, vDOP=1.4).serialize()
    # lat 54.100001234 = 54.1000012 (1e-7 deg) + 34e-9 (the 1e-9 deg part); height + 0.4 mm
    hp = UBXMessage("NAV", "NAV-HPPOSLLH", 0, iTOW=_itow(T0), lat=54.1000012, lon=18.6000006,
                    height=50123, hAcc=141.4,
                    _HPlat=34e-9, _HPlon=25e-9, _HPheight=0.4).serialize()
    ref = UBXReader.parse(hp)
    other = nav_pvt(T0 + 10**9, lat=54.2, lon=18.7, quality=4)  # no DOP/HP at this iTOW
    g = _one(pvt + dop + hp + other).gnss
    assert g.hdop[0] == pytest.approx(0.9) and g.vdop[0] == pytest.approx(1.4)
    assert np.isnan(g.hdop[1])
    assert g.lat_deg[0] == pytest.approx(ref.lat, abs=1e-10)
    # the frame's integers (pyubx2 truncates when it scales): deg = 1e-7 x + 1e-9 x_hp
    lon_i, lat_i = struct.unpack_from("<ii", hp, 6 + 8)
    hp_lon, hp_lat = struct.unpack_from("<bb", hp, 6 + 24)
    assert (lat_i, hp_lat) == (541000012, 34)
    assert abs(g.lat_deg[0] - (lat_i * 1e-7 + hp_lat * 1e-9)) < 1e-12
    assert abs(g.lon_deg[0] - (lon_i * 1e-7 + hp_lon * 1e-9)) < 1e-12
    assert g.alt_m[0] == pytest.approx(50.1234, abs=1e-9)
    assert g.sigma_e_m[0] == pytest.approx(0.1414 / math.sqrt(2), abs=1e-9)  # hAcc 141.4 mm
    assert g.lat_deg[1] == pytest.approx(54.2, abs=LAT_TOL_DEG)


def _pvts(n: int, step_ns: int = 200_000_000) -> list[tuple[int, bytes]]:
    return [(T0 + i * step_ns, nav_pvt(T0 + i * step_ns, lat=54.0, lon=18.0)) for i in range(n)]


def test_esf_meas_gyro_speed_accel_scaled_signed_and_dated() -> None:
    offset_ms = -987_654_321
    events = _pvts(11)
    for k in range(100):  # 50 Hz for 2 s
        t = T0 + k * 20_000_000 + 1_000_000
        tag = t // 10**6 + offset_ms
        # gyro z +2 deg/s is a right turn (z down): yaw rate -2 deg/s counter-clockwise
        events.append((t, esf_meas(tag, [(5, 2 * 4096), (11, -1500), (16, 512)])))
    events.sort(key=lambda e: e[0])
    d = _one(b"".join(e[1] for e in events))
    assert len(d.gyro) == 100
    assert np.allclose(d.gyro.yaw_rate_radps, -math.radians(2.0), atol=1e-12)
    assert np.allclose(d.odo.speed_mps, -1.5, atol=1e-12)   # reversing
    assert np.allclose(d.accel.accel_mps2, 0.5, atol=1e-12)
    true_t = T0 + np.arange(100) * 20_000_000 + 1_000_000
    # the fitted offset puts each message within half a sample period (10 ms) of its time
    assert np.max(np.abs(d.gyro.t_ns - true_t)) <= 10_000_000


def test_esf_offset_exact_for_evenly_spread_messages() -> None:
    pvt_start = np.array([0, 100, 200, 300])
    pvt_t = T0 + np.arange(4) * 10**9
    # four ESF frames per second placed at 1/8, 3/8, 5/8, 7/8 of each interval
    fstart = np.concatenate([np.arange(4) * 20 + 10 + 100 * s for s in range(3)])
    true = np.concatenate([T0 + s * 10**9 + np.array([125, 375, 625, 875]) * 10**6 for s in range(3)])
    tag = true // 10**6 - 5_000_000
    off = esf_offset_ns(fstart, tag, pvt_start, pvt_t)
    assert off == T0 - (T0 // 10**6 - 5_000_000) * 10**6


def test_wheel_ticks_need_ticks_per_m_and_give_speed_with_it() -> None:
    events = _pvts(11)
    ticks_per_m = 40.0
    for k in range(41):  # 20 Hz, 8 m/s forward, counter starting near the 23-bit wrap
        t = T0 + k * 50_000_000
        n = (8_388_000 + round(k * 0.05 * 8.0 * ticks_per_m)) % (1 << 23)
        events.append((t, esf_meas(t // 10**6 + 1000, [(8, n), (9, n)])))
    events.sort(key=lambda e: e[0])
    data = b"".join(e[1] for e in events)
    d = _one(data)
    assert d.odo is None and any("ticks_per_m" in w for w in d.meta["warnings"])
    d = _one(data, ticks_per_m=ticks_per_m)
    assert len(d.odo) == 40
    assert np.allclose(d.odo.speed_mps, 8.0, atol=1e-9)


def test_bad_checksum_and_truncation_skipped_and_counted() -> None:
    good = [nav_pvt(T0 + i * 10**9, lat=54.0, lon=18.0) for i in range(4)]
    bad = bytearray(good[1])
    bad[20] ^= 0xFF
    data = good[0] + bytes(bad) + good[2] + good[3][:50]
    d = _one(data)
    assert len(d.gnss) == 2
    assert d.skipped.counts["UBX frame with a bad checksum (skipped)"] == 1
    assert d.skipped.counts["UBX frame truncated at the end of the file (skipped)"] == 1


def _nmea(body: str) -> str:
    ck = 0
    for c in body.encode():
        ck ^= c
    return f"${body}*{ck:02X}"


def test_mixed_ubx_and_nmea_stream(tmp_path: Path) -> None:
    gga = _nmea("GPGGA,102030.00,5406.000,N,01836.000,E,1,08,0.9,10.0,M,30.0,M,,")
    rmc = _nmea("GPRMC,102030.00,A,5406.000,N,01836.000,E,0.0,0.0,040526,,,A")
    data = (gga + "\r\n").encode() + nav_pvt(T0, lat=54.1, lon=18.6) + (rmc + "\r\n").encode()
    data += nav_pvt(T0 + 10**9, lat=54.1, lon=18.6)
    path = tmp_path / "mixed.log"
    path.write_bytes(data)
    assert sniff(path) == "ubx"
    d = read_ubx(path)
    assert len(d.gnss) == 2  # NAV-PVT preferred
    assert d.meta["ubx"]["nmea"]["sentences"] == {"GGA": 1, "RMC": 1}
    # without NAV-PVT UTC times the NMEA fixes are the GNSS stream
    only_nmea = (gga + "\r\n").encode() + esf_meas(5, [(5, 1)]) + (rmc + "\r\n").encode()
    path.write_bytes(only_nmea + esf_meas(6, [(5, 1)]))
    d = read_ubx(path)
    assert len(d.gnss) == 1 and d.gnss.lat_deg[0] == pytest.approx(54.1)
    assert d.skipped.counts["UBX ESF-MEAS without NAV-PVT UTC times to date it (skipped)"] == 2


def test_no_usable_message_is_a_clear_error(tmp_path: Path) -> None:
    path = tmp_path / "mon.ubx"
    path.write_bytes(UBXMessage("MON", "MON-VER", 0, payload=b"x" * 40).serialize())
    with pytest.raises(NoDataError, match="mon.ubx"):
        read_ubx(path)


@settings(max_examples=150, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.binary(max_size=400), st.lists(st.tuples(st.integers(0, 10_000), st.integers(0, 255)),
                                         max_size=12), st.integers(0, 2000))
def test_fuzz_random_and_mutated_frames(noise: bytes, flips: list[tuple[int, int]],
                                        cut: int) -> None:
    base = bytearray(_SEED)
    for pos, val in flips:
        base[pos % len(base)] = val
    data = bytes(base[: len(base) - cut]) + noise
    try:
        d = parse_ubx(data, name="fuzz.ubx")
    except GpsdrError:
        return
    for s in (d.gnss, d.gyro, d.odo, d.accel):
        if s is not None:
            assert s.t_ns.dtype == np.int64


_SEED = b"".join([nav_pvt(T0 + i * 10**9, lat=54.0, lon=18.0, quality=4) for i in range(3)]
                 + [esf_meas(1000 + 10 * i, [(5, 100), (11, 2000), (16, 30)]) for i in range(5)]
                 + [b"$GPGGA,1,2*00\r\n"])


def test_fuse_on_an_f9r_like_ubx_log_alone(gpsdr, tmp_path: Path) -> None:
    from gpsdr_cli.simulate import simulate_drive
    from gpsdr_cli.testing.faults import gnss_outage

    sim = simulate_drive("open_sky", seed=3, duration_s=150.0)
    drive = gnss_outage(sim.drive, 80.0, 15.0, mode="nofix")  # the gyro and odometer bridge it
    log = tmp_path / "f9r.ubx"
    log.write_bytes(ubx_log(drive, ticks_per_m=50.0))
    cfg = tmp_path / "c.toml"
    cfg.write_text("[odo]\nticks_per_m = 50.0\n")
    out = tmp_path / "f9r.parquet"
    r = gpsdr(["fuse", log, "-o", out, "--config", cfg])
    assert r.exit_code == 0, r.output
    track = pd.read_parquet(out)
    truth = sim.truth.rename(columns={"lat_deg": "lat", "lon_deg": "lon"})
    err = horizontal_error_m(track, truth)
    assert float(np.sqrt(np.mean(err ** 2))) < 3.0      # m, open sky with a 15 s outage
    assert float(np.max(err)) < 10.0                    # m


def test_read_drive_takes_ticks_per_m_from_config(tmp_path: Path) -> None:
    from gpsdr_cli import config

    events = _pvts(6, 10**9)
    for k in range(11):
        t = T0 + k * 500_000_000
        events.append((t, esf_meas(t // 10**6, [(10, k * 100)])))
    events.sort(key=lambda e: e[0])
    path = tmp_path / "single.ubx"
    path.write_bytes(b"".join(e[1] for e in events))
    p = config.defaults()
    p["odo"]["ticks_per_m"] = 20.0
    d = read_drive(path, params=p)
    assert np.allclose(d.odo.speed_mps, 100 / 20.0 / 0.5, atol=1e-9)  # 10 m/s


def test_struct_layout_matches_interface_description() -> None:
    # ESF-MEAS word: 24-bit field, data type in bits 24..29
    frame = esf_meas(7, [(16, -1)])
    (word,) = struct.unpack_from("<I", frame, 6 + 8)
    assert word >> 24 == 16 and word & 0xFFFFFF == 0xFFFFFF


REAL_MIXED = Path(__file__).resolve().parents[1] / "data" / "nmea" / "pygpsdata-mixed.log"
GGA_RESOLUTION_DEG = 1e-6  # GGA's 1e-5 minutes is 1.7e-7 deg


def test_real_mixed_ubx_nmea_log_from_pynmeagps() -> None:
    """A u-blox receiver's log (pynmeagps tests, BSD-3-Clause; tests/data/nmea/ATTRIBUTION.tsv):
    NAV-PVT and NAV-SAT frames among GGA/GSA/GSV lines."""
    assert sniff(REAL_MIXED) == "ubx"
    d = read_ubx(REAL_MIXED)  # no --date needed: NAV-PVT carries it (read_nmea alone refuses)
    with open(REAL_MIXED, "rb") as f:
        ref = [m for _, m in UBXReader(f, protfilter=7) if getattr(m, "identity", "") == "NAV-PVT"]
    assert len(ref) == 2 and len(d.gnss) == 2
    for i, m in enumerate(ref):
        t = int(dt.datetime(m.year, m.month, m.day, m.hour, m.min, m.second,
                            tzinfo=dt.UTC).timestamp()) * 10**9 + m.nano
        assert d.gnss.t_ns[i] == t
        assert d.gnss.lat_deg[i] == pytest.approx(m.lat, abs=LAT_TOL_DEG)
        assert d.gnss.lon_deg[i] == pytest.approx(m.lon, abs=LAT_TOL_DEG)
        assert d.gnss.sigma_e_m[i] == pytest.approx(m.hAcc / 1000 / math.sqrt(2), abs=SIGMA_TOL_M)
        assert d.gnss.n_sats[i] == m.numSV and d.gnss.fix_quality[i] == 1
    # the same epochs from the NMEA lines, dated by the UBX: positions agree
    from gpsdr_cli import config

    nmea = read_drive(REAL_MIXED, params=config.defaults())
    assert d.meta["ubx"]["nmea"]["sentences"]["GGA"] == 2
    from gpsdr_cli.io.nmea import read_nmea

    g = read_nmea(REAL_MIXED, date=dt.date(2021, 3, 7)).gnss
    assert np.max(np.abs(g.lat_deg - d.gnss.lat_deg)) < GGA_RESOLUTION_DEG
    assert np.max(np.abs(g.lon_deg - d.gnss.lon_deg)) < GGA_RESOLUTION_DEG
    assert np.max(np.abs(g.t_ns - d.gnss.t_ns)) < 1_000_000  # NAV-PVT is 0.13 ms before the second
    assert nmea.gnss is not None


def test_esf_raw_gyro_and_accel() -> None:
    events = _pvts(11)
    for k in range(50):  # ESF-RAW: 4 reserved bytes, then (data word, sTtag) pairs
        t = T0 + k * 40_000_000
        # the sensor time tag: 24-bit counts of 39.0625 us (wraps every 655.36 s)
        tag = (round((t - T0) / 39_062.5) + 77) & 0xFFFFFF
        words = [((14 << 24) | 5, tag), ((5 << 24) | ((-4096) & 0xFFFFFF), tag),
                 ((16 << 24) | 2048, tag)]
        payload = b"\0" * 4 + b"".join(struct.pack("<II", w, s) for w, s in words)
        events.append((t, UBXMessage("ESF", "ESF-RAW", 0, payload=payload).serialize()))
    events.sort(key=lambda e: e[0])
    d = _one(b"".join(e[1] for e in events))
    assert len(d.gyro) == 50 and len(d.accel) == 50
    assert np.allclose(d.gyro.yaw_rate_radps, math.radians(1.0), atol=1e-12)  # -1 deg/s z down
    assert np.allclose(d.accel.accel_mps2, 2.0, atol=1e-12)
    assert np.max(np.abs(d.gyro.t_ns - (T0 + np.arange(50) * 40_000_000))) <= 20_000_000


# Every ESF data type of the interface description, with a value that would show if it
# were read as another: (type, signed 24-bit field).
ALL_ESF_TYPES = [(5, -3 * 4096), (6, 11), (7, 12), (8, 13), (9, 14), (10, 15), (11, 2750),
                 (12, 2500), (13, 7 * 4096), (14, -9 * 4096), (16, -256), (17, 5000),
                 (18, -10040)]


def test_esf_meas_data_types_as_pyubx2_reads_them() -> None:
    """Each word's type and 24-bit field as pyubx2 parses the frame; only type 5 is the yaw
    rate (deg/s * 2^-12, z down), 11 the speed (m/s * 1e-3) and 16 the forward accel
    (m/s^2 * 2^-10); the temperature, x/y gyros and y/z accelerometers are not."""
    frame = esf_meas(4321, ALL_ESF_TYPES)
    m = UBXReader.parse(frame)
    assert m.numMeas == len(ALL_ESF_TYPES)
    for k, (typ, field) in enumerate(ALL_ESF_TYPES, start=1):
        assert getattr(m, f"dataType_{k:02d}") == typ
        assert getattr(m, f"dataField_{k:02d}") == field & 0xFFFFFF
    events = _pvts(11)
    for k in range(20):
        t = T0 + k * 100_000_000 + 5_000_000
        events.append((t, esf_meas(t // 10**6 - 4_000, ALL_ESF_TYPES)))
    events.sort(key=lambda e: e[0])
    d = _one(b"".join(e[1] for e in events))
    assert len(d.gyro) == len(d.odo) == len(d.accel) == 20
    assert np.allclose(d.gyro.yaw_rate_radps, math.radians(3.0), atol=1e-12)  # -3 deg/s z down
    assert np.allclose(d.odo.speed_mps, 2.75, atol=1e-12)
    assert np.allclose(d.accel.accel_mps2, -0.25, atol=1e-12)
    assert d.meta["ubx"]["esf_words"] == {typ: 20 for typ, _ in ALL_ESF_TYPES}


@pytest.mark.parametrize("counting", ["down", "up"])
def test_wheel_ticks_direction_bit_gives_a_negative_speed(counting: str) -> None:
    """Bit 23 set = backward: the speed is negative whether the 23-bit count runs down
    (through the wrap at 0) or keeps counting up."""
    events = _pvts(11)
    ticks_per_m = 50.0
    for k in range(21):  # 10 Hz, 2 m/s backward
        t = T0 + k * 100_000_000
        step = round(k * 0.1 * 2.0 * ticks_per_m)
        n = ((40 - step) if counting == "down" else (8_388_600 + step)) % (1 << 23)
        events.append((t, esf_meas(t // 10**6 + 1000, [(8, (1 << 23) | n), (9, (1 << 23) | n)])))
    events.sort(key=lambda e: e[0])
    d = _one(b"".join(e[1] for e in events), ticks_per_m=ticks_per_m)
    assert len(d.odo) == 20
    assert np.allclose(d.odo.speed_mps, -2.0, atol=1e-9)


def test_front_wheel_ticks_when_the_rear_ones_are_absent() -> None:
    events = _pvts(11)
    for k in range(21):  # front wheels 20 and 22 ticks per 0.1 s (a left turn): 10.5 m/s
        t = T0 + k * 100_000_000
        words = [(6, 1000 + 20 * k), (7, 1000 + 22 * k), (10, 5 * k)]
        events.append((t, esf_meas(t // 10**6 + 1000, words)))
    events.sort(key=lambda e: e[0])
    d = _one(b"".join(e[1] for e in events), ticks_per_m=20.0)
    assert np.allclose(d.odo.speed_mps, 10.5, atol=1e-9)  # the front pair, not the single tick


def test_nmea_fixes_of_a_ubx_log_keep_the_disagreement_note(tmp_path: Path, gpsdr) -> None:
    """A UBX log whose fixes come from its NMEA lines: an RMC 0.01' north of its GGA is a
    disagreement, counted in the note ``gpsdr info`` prints; GGA's position is taken."""
    gga = _nmea("GPGGA,102030.00,5406.000,N,01836.000,E,1,08,0.9,10.0,M,30.0,M,,")
    rmc = _nmea("GPRMC,102030.00,A,5406.010,N,01836.000,E,0.0,0.0,040526,,,A")
    path = tmp_path / "esf_nmea.ubx"
    path.write_bytes((gga + "\r\n").encode() + esf_meas(5, [(5, 1)]) + (rmc + "\r\n").encode())
    d = read_ubx(path)
    assert d.gnss.lat_deg[0] == pytest.approx(54.1, abs=1e-9)
    assert d.meta["ubx"]["nmea"]["position_disagreements"] == 1
    r = gpsdr(["info", str(path)])
    assert r.exit_code == 0, r.output
    assert "1 epochs whose sentences disagree on the position" in r.output
