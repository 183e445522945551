"""UBX reader on real u-blox logs from gpsd's regression suite (``tests/data/ubx/README.md``):
ESF-RAW's sensor time tags, the NAV-SOL / NAV-POSLLH / NAV-POSECEF fixes of receivers
without NAV-PVT, and the errors of logs without a usable fix; plus synthetic cases of the
same (a 24-bit tag wrap with an off-rate sensor clock, a GPS week turning, NAV-VELNED).
Expected values come from pyubx2's reading of the logs, from gpsd's own decoding of them
(its expected output), or from how the synthetic frames are built."""

from __future__ import annotations

import datetime as dt
import io
import math
import re
import struct
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from pyubx2 import UBXMessage, UBXReader

from gpsdr_cli.errors import MissingDateError, NoDataError
from gpsdr_cli.io.ubx import parse_ubx, read_ubx
from gpsdr_cli.testing.ubx_log import nav_pvt

DATA = Path(__file__).resolve().parents[1] / "data" / "ubx"
GPS_EPOCH = dt.datetime(1980, 1, 6, tzinfo=dt.UTC)
LEAP_S = 18  # GPS - UTC from 2017 on; every log whose times are checked here is later
DEG_TOL = 5e-9  # gpsd prints 1e-9 deg; the ECEF -> geodetic conversions agree to 1e-10
ALT_TOL_M = 1e-3  # gpsd prints altHAE to 0.1 mm
M_PER_DEG = 111_320.0


def _messages(data: bytes, identity: str) -> list:
    return [m for _, m in UBXReader(io.BytesIO(data), protfilter=2, quitonerror=0)
            if m is not None and m.identity == identity]


def _utc_ns(week: int, itow_ms: int, ftow_ns: int = 0, leap_s: int = LEAP_S) -> int:
    t = GPS_EPOCH + dt.timedelta(weeks=week, milliseconds=itow_ms, seconds=-leap_s)
    return int(t.timestamp()) * 10**9 + ftow_ns


def _expected(name: str) -> dict[int, tuple[float, float, float, float]]:
    """gpsd's TPV per whole UTC second: (lat, lon, altHAE, speed)."""
    out = {}
    for line in (DATA / f"{name}.expected.tsv").read_text().splitlines()[2:]:
        ts, la, lo, alt, sp = line.split("\t")
        sec = int(dt.datetime.fromisoformat(ts.replace("Z", "+00:00")).timestamp())
        out[sec] = (float(la), float(lo), float(alt), float(sp))
    return out


def _frame(cls: int, mid: int, payload: bytes) -> bytes:
    body = struct.pack("<BBH", cls, mid, len(payload)) + payload
    a = b = 0
    for c in body:
        a = (a + c) & 0xFF
        b = (b + a) & 0xFF
    return b"\xb5\x62" + body + bytes([a, b])


def _frames_of(data: bytes) -> list[bytes]:
    """The checksum-valid UBX frames of a log, in order (its text left out)."""
    return [raw for raw, m in UBXReader(io.BytesIO(data), protfilter=2, quitonerror=0)
            if m is not None]


# --------------------------------------------------------------------------- ESF-RAW

def test_esf_raw_of_a_real_neo_m8u_spans_the_log_not_25_times_it(gpsdr, tmp_path: Path) -> None:
    """sTtag counts 1/25.6 ms: read as milliseconds the 2.9 s of gyro became 74 s, and
    `gpsdr fuse` made a 74-s track of it."""
    data = (DATA / "ublox-neo-m8u.log").read_bytes()
    raws = _messages(data, "ESF-RAW")
    assert len(raws) == 29 and len(_messages(data, "NAV-PVT")) == 3
    d = read_ubx(DATA / "ublox-neo-m8u.log")
    assert len(d.gyro) == len(d.accel) == 290  # 10 samples of each per message
    span_s = (int(d.gyro.t_ns[-1]) - int(d.gyro.t_ns[0])) / 1e9
    assert abs(span_s - 2.9) < 0.3
    # 100 Hz samples: tags step ~256 units = 10 ms
    assert abs(float(np.median(np.diff(d.gyro.t_ns))) - 10e6) < 0.1e6
    # Independent clock: the 4 bytes before the samples hold, on this receiver, the same
    # millisecond count as ESF-MEAS's timeTag (100 ms per message).  Mapped by ESF-MEAS's
    # own offset, each message's first sample lies within one message period (100 ms).
    off_meas = d.meta["ubx"]["esf_offset_ns"]["ESF-MEAS"]
    ref = np.array([m.reserved1 for m in raws], np.int64) * 10**6 + off_meas
    first = d.gyro.t_ns.reshape(29, 10)[:, 0]
    assert np.max(np.abs(first - ref)) < 100_000_000
    # the yaw rates are the type-5 words as pyubx2 reads them (deg/s 2^-12, z down)
    z = []
    for m in raws:
        for k in range(1, 71):
            word = int.from_bytes(getattr(m, f"data_{k:02d}"), "little")
            if word >> 24 == 5:
                f = word & 0xFFFFFF
                z.append(f - (1 << 24) if f >= 1 << 23 else f)
    assert np.allclose(d.gyro.yaw_rate_radps, -np.radians(np.array(z) * 2.0**-12), atol=1e-15)
    r = gpsdr(["info", DATA / "ublox-neo-m8u.log"])
    assert r.exit_code == 0, r.output
    assert re.search(r"gyro\s+290 records .*\(2\.9 s\)", r.output), r.output
    out = tmp_path / "m8u.parquet"
    assert gpsdr(["fuse", DATA / "ublox-neo-m8u.log", "-q", "-o", out]).exit_code == 0
    t = pd.read_parquet(out)["time"]
    assert abs((t.iloc[-1] - t.iloc[0]).total_seconds() - 2.9) < 0.3


def test_esf_raw_24_bit_tag_wrap_and_an_off_rate_sensor_clock() -> None:
    """800 s of 100 Hz ESF-RAW gyro whose 24-bit count wraps twice (every 655.36 s) on a
    sensor clock 0.3 % fast: continuous 10 ms steps, and the fitted rate keeps the error
    flat over the log (at the nominal rate it would drift by 2.4 s)."""
    t0 = int(dt.datetime(2026, 5, 4, 10, tzinfo=dt.UTC).timestamp()) * 10**9
    fast = 1.003
    tag0 = (1 << 24) - 20_000  # 0.78 s before the first wrap
    events = [(t0 + i * 10**9, nav_pvt(t0 + i * 10**9, lat=54.0, lon=18.0)) for i in range(801)]
    n_frames = 8000
    true_t = []
    for j in range(n_frames):  # one message per 0.1 s, output after its last sample
        samples = [t0 + 5_000_000 + (10 * j + k) * 10_000_000 for k in range(10)]
        true_t += samples
        payload = b"\0" * 4 + b"".join(
            struct.pack("<II", (5 << 24) | ((-4096) & 0xFFFFFF),
                        (tag0 + round((t - t0) / 39_062.5 * fast)) % (1 << 24))
            for t in samples)
        events.append((samples[-1], _frame(0x10, 0x03, payload)))
    events.sort(key=lambda e: e[0])
    d = parse_ubx(b"".join(e[1] for e in events), name="wrap.ubx")
    assert len(d.gyro) == 10 * n_frames
    err = d.gyro.t_ns - np.array(true_t)
    assert np.max(np.abs(np.diff(d.gyro.t_ns) - 10_000_000)) < 50_000  # no 655 s jump
    assert d.meta["ubx"]["esf_raw_clock_rate"] == pytest.approx(1 / fast, abs=1e-5)
    assert np.ptp(err) < 5_000_000
    # a frame stands at the middle of its stretch between NAV-PVTs, not at its last
    # sample: up to half a frame period (45 ms here) of constant offset
    assert np.max(np.abs(err)) < 60_000_000
    assert np.allclose(d.gyro.yaw_rate_radps, math.radians(1.0), atol=1e-12)


# --------------------------------------------------------------------------- NAV-SOL

@pytest.mark.parametrize(("name", "n_epochs", "n_fixes", "quality"), [
    ("ublox-neo-m8t", 12, 12, 1),   # 3-D
    ("ublox-8-time", 15, 15, 2),    # 2-D with diffSoln
    ("navisys-gr701w", 60, 31, 1),  # 29 without gpsFixOK: 26 gpsFix 0, 3 2-D/3-D
])
def test_nav_sol_fixes_of_real_logs_match_gpsd_and_pyubx2(name: str, n_epochs: int,
                                                          n_fixes: int, quality: int) -> None:
    path = DATA / f"{name}-excerpt.log"
    data = path.read_bytes()
    sols = _messages(data, "NAV-SOL")
    assert len(sols) == n_epochs
    g = read_ubx(path).gnss
    assert len(g) == n_epochs
    assert np.array_equal(g.t_ns, [_utc_ns(m.week, m.iTOW, m.fTOW) for m in sols])
    fix = np.array([m.gpsFix in (2, 3, 4) and m.gpsfixOK == 1 for m in sols])
    assert int(fix.sum()) == n_fixes
    assert np.array_equal(g.valid, fix)
    assert (g.fix_quality[fix] == quality).all() and (g.fix_quality[~fix] == 0).all()
    assert np.isnan(g.lat_deg[~fix]).all()
    assert np.allclose(g.sigma_e_m[fix], [m.pAcc / 100 / math.sqrt(2) for m in np.array(sols)[fix]],
                       atol=1e-12)
    assert np.array_equal(g.n_sats, [m.numSV for m in sols])
    gpsd = _expected(name)
    seconds = np.round(g.t_ns / 1e9).astype(np.int64)
    for i in np.flatnonzero(fix):
        lat, lon, alt, speed = gpsd[int(seconds[i])]
        assert abs(g.lat_deg[i] - lat) < DEG_TOL and abs(g.lon_deg[i] - lon) < DEG_TOL
        assert abs(g.alt_m[i] - alt) < ALT_TOL_M
        assert abs(g.speed_mps[i] - speed) < 2e-3  # gpsd prints 1 mm/s
    # gpsd's other mode >= 2 epochs are exactly the solutions without gpsFixOK
    no_ok = {int(s) for s, m in zip(seconds, sols, strict=True) if m.gpsfixOK == 0}
    assert set(gpsd) - set(seconds[fix].tolist()) == no_ok & set(gpsd)


def test_fuse_on_a_real_nav_sol_log_gives_its_fixes(gpsdr, tmp_path: Path) -> None:
    """`gpsdr fuse` on a NEO-M8T log with only NAV-SOL fixes: a finite track through them
    (a static antenna; pAcc 1.6-1.7 m)."""
    out = tmp_path / "m8t.parquet"
    r = gpsdr(["fuse", DATA / "ublox-neo-m8t-excerpt.log", "-q", "-o", out])
    assert r.exit_code == 0, r.output
    track = pd.read_parquet(out)
    assert len(track) == 12
    assert np.isfinite(track[["lat", "lon"]].to_numpy()).all()
    gpsd = _expected("ublox-neo-m8t")
    secs = np.round(track["time"].astype("int64").to_numpy() / 1e9).astype(np.int64)
    ref = np.array([gpsd[int(s)][:2] for s in secs])
    dn = (track["lat"].to_numpy() - ref[:, 0]) * M_PER_DEG
    de = (track["lon"].to_numpy() - ref[:, 1]) * M_PER_DEG * math.cos(math.radians(ref[0, 0]))
    assert float(np.max(np.hypot(de, dn))) < 3.0


def test_nav_pvt_is_preferred_over_nav_sol_of_the_same_epochs() -> None:
    path = DATA / "ublox8-uniqid-monhw.log"
    data = path.read_bytes()
    pvts = _messages(data, "NAV-PVT")
    assert len(pvts) == len(_messages(data, "NAV-SOL")) == 7
    d = read_ubx(path)
    assert len(d.gnss) == 7  # not 14
    assert np.allclose(d.gnss.lat_deg, [m.lat for m in pvts], atol=1e-9)
    assert np.allclose(d.gnss.sigma_e_m, [m.hAcc / 1000 / math.sqrt(2) for m in pvts], atol=1e-12)
    assert "NAV-SOL" in d.meta["ubx"]["legacy_ignored"]
    assert d.meta["ubx"]["nmea"]["sentences"]["RMC"] == 6  # its NMEA lines are still read


# --------------------------------------------------------------------------- NAV-POSLLH

def _with_status(data: bytes, gps_fix: int | None) -> bytes:
    """The log's frames with every NAV-STATUS's gpsFix set to ``gps_fix`` (its checksum
    recomputed), or without NAV-STATUS at all (None)."""
    out = []
    for raw in _frames_of(data):
        if raw[2:4] == b"\x01\x03":
            if gps_fix is None:
                continue
            payload = bytearray(raw[6:-2])
            payload[4] = gps_fix
            raw = _frame(0x01, 0x03, bytes(payload))
        out.append(raw)
    return b"".join(out)


def test_time_only_nav_posllh_log_says_so(gpsdr, tmp_path: Path) -> None:
    """A timing receiver in surveyed-in mode: every NAV-STATUS says gpsFix 5 (time only),
    so its NAV-POSLLH are no fixes; the error says why (not an NMEA complaint)."""
    path = DATA / "u-blox-m8t-time-excerpt.log"
    data = path.read_bytes()
    stats = _messages(data, "NAV-STATUS")
    assert len(stats) == len(_messages(data, "NAV-POSLLH")) == 8
    assert {m.gpsFix for m in stats} == {5}
    with pytest.raises(NoDataError) as err:
        read_ubx(path)
    msg = str(err.value)
    assert "every one of its 8 NAV-POSLLH epochs is time-only (NAV-STATUS gpsFix 5)" in msg
    assert "NAV-POSLLH x8" in msg and "NMEA" not in msg
    r = gpsdr(["fuse", path, "-q", "-o", tmp_path / "x.parquet"])
    assert r.exit_code == 1
    assert "NAV-POSLLH epochs is time-only" in r.stderr


@pytest.mark.parametrize("status", ["3-D fix", "no NAV-STATUS", "no fix"])
def test_nav_posllh_fixes_by_nav_status(status: str) -> None:
    """The same real frames with NAV-STATUS saying 3-D fix, or absent (taken as fixes, with
    a note), or gpsFix 0: positions, heights and hAcc as pyubx2 reads them, dated by
    NAV-TIMEGPS's week."""
    raw = (DATA / "u-blox-m8t-time-excerpt.log").read_bytes()
    data = _with_status(raw, {"3-D fix": 3, "no NAV-STATUS": None, "no fix": 0}[status])
    llh = _messages(data, "NAV-POSLLH")
    tg = {m.iTOW: m for m in _messages(data, "NAV-TIMEGPS")}
    d = parse_ubx(data, name="m8t.ubx")
    g = d.gnss
    assert len(g) == 8
    assert np.array_equal(g.t_ns, [_utc_ns(tg[m.iTOW].week, m.iTOW, tg[m.iTOW].fTOW,
                                           tg[m.iTOW].leapS) for m in llh])
    if status == "no fix":
        assert not g.valid.any() and (g.fix_quality == 0).all()
        return
    assert g.valid.all() and (g.fix_quality == 1).all()
    assert np.allclose(g.lat_deg, [m.lat for m in llh], atol=1e-12)
    assert np.allclose(g.lon_deg, [m.lon for m in llh], atol=1e-12)
    assert np.allclose(g.alt_m, [m.height / 1000 for m in llh], atol=1e-9)
    assert np.allclose(g.sigma_e_m, [m.hAcc / 1000 / math.sqrt(2) for m in llh], atol=1e-12)
    assert g.sigma_e_m[0] == pytest.approx(20.619 / math.sqrt(2))  # hAcc 20 619 mm
    notes = d.meta.get("notes", [])
    assert any("taken as a 3-D fix" in n for n in notes) == (status == "no NAV-STATUS")


def test_nav_posecef_alone_agrees_with_the_receivers_own_nav_posllh() -> None:
    """Without NAV-POSLLH the NAV-POSECEF (cm) positions are converted to latitude,
    longitude and height; they agree with the receiver's NAV-POSLLH within its cm."""
    raw = _with_status((DATA / "u-blox-m8t-time-excerpt.log").read_bytes(), 3)
    llh = _messages(raw, "NAV-POSLLH")
    ecef = _messages(raw, "NAV-POSECEF")
    data = b"".join(f for f in _frames_of(raw) if f[2:4] != b"\x01\x02")
    g = parse_ubx(data, name="m8t-ecef.ubx").gnss
    assert len(g) == 8 and g.valid.all()
    assert np.max(np.abs(g.lat_deg - [m.lat for m in llh])) * M_PER_DEG < 0.02
    assert np.max(np.abs(g.lon_deg - [m.lon for m in llh])) * M_PER_DEG < 0.02
    assert np.max(np.abs(g.alt_m - [m.height / 1000 for m in llh])) < 0.02
    assert np.allclose(g.sigma_e_m, [m.pAcc / 100 / math.sqrt(2) for m in ecef], atol=1e-12)


W = 2400  # a GPS week number (2026)


def _legacy_epoch(week_ms: int, *, lat: float, with_week: bool, vn_cm: int = 300,
                  ve_cm: int = 400) -> bytes:
    frames = [UBXMessage("NAV", "NAV-POSLLH", 0, iTOW=week_ms, lat=lat, lon=18.5,
                         height=40_000, hMSL=10_000, hAcc=1500, vAcc=3000).serialize(),
              UBXMessage("NAV", "NAV-STATUS", 0, iTOW=week_ms, gpsFix=3, gpsFixOk=1,
                         wknSet=1, towSet=1).serialize(),
              UBXMessage("NAV", "NAV-VELNED", 0, iTOW=week_ms, velN=vn_cm, velE=ve_cm,
                         speed=500, gSpeed=500).serialize()]
    if with_week:
        frames.append(UBXMessage("NAV", "NAV-TIMEGPS", 0, iTOW=week_ms, week=W, leapS=18,
                                 towValid=1, weekValid=1, leapSValid=1).serialize())
    return b"".join(frames)


def test_nav_posllh_across_a_week_turn_with_one_week_number_and_velned_speed() -> None:
    """Four epochs around the end of GPS week W, only the first with NAV-TIMEGPS: the
    later ones take its week, the two after iTOW wraps take W + 1.  NAV-VELNED's cm/s
    velocity gives the speed and course."""
    itows = [604_798_000, 604_799_000, 0, 1000]
    data = b"".join(_legacy_epoch(it, lat=54.0 + k * 1e-5, with_week=k == 0)
                    for k, it in enumerate(itows))
    g = parse_ubx(data, name="week.ubx").gnss
    assert np.array_equal(g.t_ns, [_utc_ns(W, 604_798_000 + k * 1000) for k in range(4)])
    assert np.allclose(g.lat_deg, 54.0 + np.arange(4) * 1e-5, atol=1e-9)
    assert np.allclose(g.speed_mps, 5.0, atol=1e-12)  # north 3 m/s, east 4 m/s
    assert np.allclose(g.course_deg, math.degrees(math.atan2(4.0, 3.0)), atol=1e-9)
    assert np.allclose(g.sigma_e_m, 1.5 / math.sqrt(2), atol=1e-12)


def test_nav_posllh_without_any_week_needs_a_date() -> None:
    data = b"".join(_legacy_epoch(300_000_000 + k * 1000, lat=54.0, with_week=False)
                    for k in range(3))
    with pytest.raises(MissingDateError, match="3 NAV-POSLLH fixes but no GPS week"):
        parse_ubx(data, name="noweek.ubx")
    # iTOW 300 000 s = Thursday 11:20:00 GPS; dated by a day of week W it lands in week W
    day = (GPS_EPOCH + dt.timedelta(weeks=W, days=2)).date()
    g = parse_ubx(data, name="noweek.ubx", date=day).gnss
    assert np.array_equal(g.t_ns, [_utc_ns(W, 300_000_000 + k * 1000) for k in range(3)])


# --------------------------------------------------------------------------- errors

def test_a_ubx_log_without_usable_messages_gets_the_ubx_error_not_an_nmea_one() -> None:
    """0x24 ('$') bytes inside RXM-SFRBX frames once sent the gaps between the frames to
    the NMEA reader, whose 'no NMEA sentence' error hid what the log holds."""
    path = DATA / "ublox-ned-m8t-sbfrx3-excerpt.log"
    assert b"$" in path.read_bytes()
    with pytest.raises(NoDataError) as err:
        read_ubx(path)
    msg = str(err.value)
    assert "no usable UBX message" in msg and "messages: RXM-SFRBX x24" in msg
    assert "NAV-PVT" in msg and "ESF-MEAS" in msg  # what gpsdr reads
    assert "(NMEA lines)" not in msg and "binary file" not in msg


def test_binary_bytes_between_frames_are_not_taken_for_nmea_lines() -> None:
    t0 = int(dt.datetime(2026, 5, 4, 10, tzinfo=dt.UTC).timestamp()) * 10**9
    junk = b"\x00$\x17\xff$GP\x01" * 5
    data = b"".join(nav_pvt(t0 + i * 10**9, lat=54.0, lon=18.0) + junk for i in range(3))
    d = parse_ubx(data, name="junk.ubx")
    assert len(d.gnss) == 3
    assert "warnings" not in d.meta and "nmea" not in d.meta["ubx"]
    assert d.meta["ubx"]["bytes_outside_frames"] == 3 * len(junk)


def test_time_only_nav_pvt_log_error_reaches_the_user(gpsdr, tmp_path: Path) -> None:
    """A LEA-M8F timing receiver: all 28 NAV-PVT fixType 5 (pyubx2); `gpsdr fuse` says so
    instead of 'no valid GNSS fix in the drive'."""
    path = DATA / "ublox-lea-m8f.log"
    pvts = _messages(path.read_bytes(), "NAV-PVT")
    assert len(pvts) == 28 and {m.fixType for m in pvts} == {5}
    r = gpsdr(["fuse", path, "-q", "-o", tmp_path / "x.parquet"])
    assert r.exit_code == 1
    assert "every one of its 28 NAV-PVT messages is time-only (fixType 5)" in r.stderr
