"""Proprietary sentences: Trimble ``$PTNL,GGK`` and u-blox ``$PUBX,00`` positions, and
u-blox ``$PUBX,04`` dates.

Logs are built here with their checksums computed (XOR of the bytes between ``$`` and
``*``); expected coordinates are hand-decoded (ddmm.mmmm / 60), tolerance 1e-9 deg.
The real Trimble line is ``tests/data/nmea/trimble-ggk.log`` (see ATTRIBUTION.tsv there).
"""

from __future__ import annotations

import datetime
import math
from pathlib import Path

import numpy as np
import pyarrow.parquet as pq
import pytest

from gpsdr_cli.errors import MissingDateError, ParseError
from gpsdr_cli.io.nmea import looks_like_nmea, parse_nmea, read_nmea

pytestmark = pytest.mark.filterwarnings("error")  # no numpy RuntimeWarning may escape

DATA = Path(__file__).resolve().parents[1] / "data" / "nmea"
DEG = 1e-9  # deg
LAT = 48 + 7.03812345 / 60
LON = -(11 + 31.00098765 / 60)  # W


def ck(body: str) -> str:
    """``$body*hh``: hh the XOR of the body's bytes, two upper-case hex digits."""
    x = 0
    for c in body.encode("ascii"):
        x ^= c
    return f"${body}*{x:02X}"


def log(*lines: str) -> bytes:
    return ("\r\n".join(lines) + "\r\n").encode("ascii")


def ns(y: int, mo: int, d: int, hh: int, mm: int, ss: int, us: int = 0) -> int:
    dt = datetime.datetime(y, mo, d, hh, mm, ss, tzinfo=datetime.UTC)
    return int(dt.timestamp()) * 1_000_000_000 + us * 1000


def ggk(tod: str = "102939.25", date: str = "120524", q: str = "3",
        pos: str = "4807.03812345,N,01131.00098765,W", nsat: str = "14", dop: str = "1.7",
        height: str = "EHT-5.923") -> str:
    return ck(f"PTNL,GGK,{tod},{date},{pos},{q},{nsat},{dop},{height},M")


def pubx(tod: str = "081350.50", nav: str = "D3", pos: str = "4807.03812,N,01131.00099,W",
         alt: str = "546.589", hacc: str = "2.8", sog: str = "36.0", cog: str = "77.52",
         nsat: str = "9") -> str:
    return ck(f"PUBX,00,{tod},{pos},{alt},{nav},{hacc},3.9,{sog},{cog},-0.007,,0.92,1.19,"
              f"0.77,{nsat},0,0")


# ---------------------------------------------------------------- Trimble PTNL,GGK
def test_ggk_fields_time_date_month_first_position_height() -> None:
    fixes, report, meta = parse_nmea(log(ggk()), name="g.log")
    assert report.total == 0 and meta["sentences"] == {"PTNL,GGK": 1}
    assert meta["talkers"] == {"PTNL": 1}
    # 120524 is mmddyy: 5 December 2024 (read as ddmmyy it would be 12 May)
    assert fixes.t_ns.tolist() == [ns(2024, 12, 5, 10, 29, 39, 250_000)]
    assert fixes.lat_deg[0] == pytest.approx(LAT, abs=DEG)
    assert fixes.lon_deg[0] == pytest.approx(LON, abs=DEG)
    assert fixes.alt_m[0] == pytest.approx(-5.923, abs=1e-12)  # m, ellipsoidal, as given
    assert fixes.fix_quality[0] == 4  # RTK fixed
    assert fixes.n_sats[0] == 14
    assert fixes.pdop[0] == pytest.approx(1.7) and np.isnan(fixes.hdop[0])
    assert np.isnan(fixes.sigma_n_m[0]) and np.isnan(fixes.speed_mps[0])
    assert meta["alt_without_geoid_sep"] == 0


@pytest.mark.parametrize(("code", "quality"), [
    (0, 0), (1, 1), (2, 5), (3, 4), (4, 2), (5, 2), (6, 5), (7, 4), (8, 5), (9, 4),
    (10, 5), (11, 2), (12, 5), (13, 2), (14, 5), (15, 4)])
def test_ggk_quality_codes(code: int, quality: int) -> None:
    fixes, report, _ = parse_nmea(log(ggk(q=str(code))))
    assert report.total == 0
    assert fixes.fix_quality.tolist() == [quality]
    assert np.isfinite(fixes.lat_deg[0]) == (quality > 0)
    assert np.isfinite(fixes.alt_m[0]) == (quality > 0)


@pytest.mark.parametrize("code", ["16", "-1", "2.5", "X"])
def test_ggk_bad_quality_skips_the_sentence(code: str) -> None:
    fixes, report, _ = parse_nmea(log(ggk(q=code), ggk(tod="102940.25")))
    assert report.counts["malformed fix quality in PTNL,GGK"] == 1
    assert fixes.t_ns.tolist() == [ns(2024, 12, 5, 10, 29, 40, 250_000)]


def test_ggk_malformed_fields_are_counted() -> None:
    data = log(ggk(tod="102939.00", height="150.790"),  # no EHT: not known to be ellipsoidal
               ggk(tod="102940.00", height="EHTx"),
               ggk(tod="102941.00", date="131324"),  # month 13
               ggk(tod="102942.00", pos="4807.0381,N,01131.0009,Q"),
               ggk(tod="102943.00", nsat="?", dop="1.7x"))
    fixes, report, _ = parse_nmea(data, name="bad.log")
    assert report.counts["malformed height in PTNL,GGK (field ignored)"] == 2
    assert report.first["malformed height in PTNL,GGK (field ignored)"] == "bad.log:1"
    assert report.counts["malformed date in PTNL,GGK (field ignored)"] == 1
    assert report.first["malformed date in PTNL,GGK (field ignored)"] == "bad.log:3"
    assert report.counts["malformed position in PTNL,GGK"] == 1
    assert report.counts["malformed satellites in PTNL,GGK (field ignored)"] == 1
    assert report.counts["malformed DOP in PTNL,GGK (field ignored)"] == 1
    # the bad-position sentence is gone; the others keep their fix, without the bad field
    assert len(fixes) == 4 and (fixes.fix_quality == 4).all()
    assert np.isnan(fixes.alt_m[:2]).all() and fixes.alt_m[2] == pytest.approx(-5.923)
    # the third epoch has no date of its own: the others' date, 5 December 2024
    assert fixes.t_ns[2] == ns(2024, 12, 5, 10, 29, 41)
    assert fixes.n_sats[3] == -1 and np.isnan(fixes.pdop[3])
    with pytest.raises(ParseError, match="expected EHT"):
        parse_nmea(data, name="bad.log", strict=True)


def test_gga_and_ggk_of_one_epoch_keep_gga() -> None:
    gga = ck("GPGGA,102939.25,4807.038,N,01131.000,W,1,08,0.9,545.4,M,46.9,M,,")
    fixes, report, meta = parse_nmea(log(gga, ggk(pos="4807.03812345,N,01131.01000000,W")))
    assert report.total == 0 and len(fixes) == 1
    assert fixes.lat_deg[0] == pytest.approx(48 + 7.038 / 60, abs=DEG)
    assert fixes.lon_deg[0] == pytest.approx(-(11 + 31.0 / 60), abs=DEG)
    assert fixes.fix_quality[0] == 1 and fixes.n_sats[0] == 8  # GGA's, not GGK's 4 and 14
    assert fixes.alt_m[0] == pytest.approx(545.4 + 46.9)
    assert fixes.pdop[0] == pytest.approx(1.7)  # only GGK has a PDOP
    # GGK is 0.01' (12 m) off GGA in longitude: a disagreement, counted and noted
    assert meta["position_disagreements"] == 1
    assert "PTNL,GGK" in meta["notes"][0]


def test_real_trimble_ggk_line() -> None:
    path = DATA / "trimble-ggk.log"
    assert path.read_bytes().count(b"$") == 1  # the one sentence, nothing else
    assert looks_like_nmea(path.read_bytes())
    drive = read_nmea(path)  # date from GGK itself: 051910 is 19 May 2010
    g = drive.gnss
    assert drive.skipped.total == 0
    assert g.t_ns.tolist() == [ns(2010, 5, 19, 10, 29, 39)]
    assert g.lat_deg[0] == pytest.approx(50 + 0.97323841 / 60, abs=DEG)
    assert g.lon_deg[0] == pytest.approx(8 + 27.62010742 / 60, abs=DEG)
    assert g.alt_m[0] == pytest.approx(150.790, abs=1e-12)
    assert g.fix_quality[0] == 2  # GGK 5, SBAS
    assert g.n_sats[0] == 9 and g.pdop[0] == pytest.approx(1.9)
    assert drive.meta["dates"] == ["2010-05-19"]


def test_ggk_only_log_through_fuse(gpsdr, tmp_path: Path) -> None:
    lines = []
    for k in range(60):  # 60 s heading north at 0.0033' of latitude a second (6.1 m/s)
        lat = f"4807.{3812345 + 330_000 * k:08d}"
        lines.append(ggk(tod=f"1029{k:02d}.00", q="3", pos=f"{lat},N,01131.00098765,W"))
    gps = tmp_path / "ggk.log"
    gps.write_bytes(log(*lines))
    out = tmp_path / "ggk.fused.parquet"
    result = gpsdr(["fuse", "--gps", gps, "-o", out])
    assert result.exit_code == 0, result.output
    track = pq.read_table(out).to_pandas()
    assert len(track) >= 60
    assert np.isfinite(track["lat"]).all() and np.isfinite(track["lon"]).all()
    assert track["lat"].iloc[0] == pytest.approx(LAT, abs=1e-5)
    assert track["lat"].iloc[-1] == pytest.approx(48 + (7.03812345 + 0.0033 * 59) / 60, abs=1e-5)


# ---------------------------------------------------------------- u-blox PUBX,00
def test_pubx00_fields_with_date_argument() -> None:
    fixes, report, meta = parse_nmea(log(pubx()), date=datetime.date(2024, 5, 17))
    assert report.total == 0 and meta["sentences"] == {"PUBX,00": 1}
    assert meta["date_source"] == "argument"
    assert fixes.t_ns.tolist() == [ns(2024, 5, 17, 8, 13, 50, 500_000)]
    assert fixes.lat_deg[0] == pytest.approx(48 + 7.03812 / 60, abs=DEG)
    assert fixes.lon_deg[0] == pytest.approx(-(11 + 31.00099 / 60), abs=DEG)
    assert fixes.alt_m[0] == pytest.approx(546.589, abs=1e-12)  # m above the ellipsoid
    assert fixes.fix_quality[0] == 2  # D3
    # hAcc 2.8 m is the radial 1-sigma: 2.8 / sqrt(2) per axis, as io/ubx.py reads NAV-PVT
    assert fixes.sigma_n_m[0] == pytest.approx(2.8 / math.sqrt(2), abs=1e-12)
    assert fixes.sigma_e_m[0] == pytest.approx(2.8 / math.sqrt(2), abs=1e-12)
    assert fixes.speed_mps[0] == pytest.approx(10.0, abs=1e-12)  # 36 km/h
    assert fixes.course_deg[0] == pytest.approx(77.52)
    assert fixes.hdop[0] == pytest.approx(0.92) and fixes.vdop[0] == pytest.approx(1.19)
    assert np.isnan(fixes.pdop[0]) and fixes.n_sats[0] == 9


@pytest.mark.parametrize(("nav", "quality"), [
    ("NF", 0), ("TT", 0), ("DR", 6), ("G2", 1), ("G3", 1), ("RK", 1), ("D2", 2), ("D3", 2)])
def test_pubx00_navstat(nav: str, quality: int) -> None:
    fixes, report, _ = parse_nmea(log(pubx(nav=nav)), date=datetime.date(2024, 5, 17))
    assert report.total == 0
    assert fixes.fix_quality.tolist() == [quality]
    assert np.isfinite(fixes.lat_deg[0]) == (quality > 0)
    assert np.isfinite(fixes.sigma_e_m[0]) == (quality > 0)
    assert np.isfinite(fixes.speed_mps[0]) == (quality > 0)


def test_pubx00_no_fix_as_u_blox_prints_it() -> None:
    # a receiver without a fix: zero coordinates, huge hAcc, 99.99 DOPs
    line = ck("PUBX,00,193416.00,0000.00000,N,00000.00000,E,0.000,NF,5303302,3750001,0.000,"
              "0.00,0.000,,99.99,99.99,99.99,0,0,0")
    fixes, report, _ = parse_nmea(log(line), date=datetime.date(2024, 5, 17))
    assert report.total == 0 and fixes.fix_quality.tolist() == [0]
    assert np.isnan([fixes.lat_deg[0], fixes.lon_deg[0], fixes.alt_m[0], fixes.sigma_n_m[0],
                     fixes.hdop[0], fixes.speed_mps[0]]).all()


def test_pubx00_dated_by_rmc_and_bad_fields_counted() -> None:
    rmc = ck("GPRMC,081350.50,A,4807.03812,N,01131.00099,W,19.4,077.5,170524,,,D")
    data = log(rmc, pubx(), pubx(tod="081351.50", nav="XX"), pubx(tod="081352.50", hacc="2.8.1"),
               pubx(tod="081353.50", pos="4807.03812,N,01131.00099,X"))
    fixes, report, meta = parse_nmea(data, name="u.log")
    assert meta["date_source"] == "log (RMC/ZDA/GGK/PUBX,04)"
    assert report.counts["malformed navigation status in PUBX,00"] == 1
    assert report.first["malformed navigation status in PUBX,00"] == "u.log:3"
    assert report.counts["malformed horizontal accuracy in PUBX,00 (field ignored)"] == 1
    assert report.counts["malformed position in PUBX,00"] == 1
    assert fixes.t_ns.tolist() == [ns(2024, 5, 17, 8, 13, 50, 500_000),
                                   ns(2024, 5, 17, 8, 13, 52, 500_000)]
    assert fixes.fix_quality.tolist() == [2, 2]  # PUBX ranks before RMC: its D3
    assert fixes.speed_mps[0] == pytest.approx(19.4 * 1852 / 3600)  # RMC's speed wins
    assert fixes.speed_mps[1] == pytest.approx(10.0)
    assert np.isnan(fixes.sigma_n_m[1]) and fixes.alt_m[1] == pytest.approx(546.589)
    with pytest.raises(MissingDateError):
        parse_nmea(log(pubx()))


def test_gst_sigmas_win_over_pubx_hacc() -> None:
    gst = ck("GPGST,081350.50,1.2,0.9,0.5,30.0,0.6,0.8,1.5")
    fixes, _, _ = parse_nmea(log(pubx(), gst), date=datetime.date(2024, 5, 17))
    assert fixes.sigma_n_m[0] == pytest.approx(0.6) and fixes.sigma_e_m[0] == pytest.approx(0.8)


def test_other_proprietary_messages_stay_unknown() -> None:
    data = log(ggk(),
               ck("PTNL,AVR,212405.20,+52.1531,Yaw,-0.0806,Tilt,,,12.575,3,1.4,16"),
               ck("PTNL,GGKX,102939.25,120524,4807.0,N,01131.0,W,3,14,1.7,EHT1.0,M"),
               ck("PUBX,03,23,1,-,014,06,08,000"),  # satellites, not read
               ck("PUBX,00"),  # a poll request, not a position
               ck("PUBX,000,081350.50,4807.0,N,01131.0,W,1.0,G3,2.8,3.9,0,0,0,,1,1,1,9,0,0"))
    fixes, report, meta = parse_nmea(data)
    assert report.counts["unknown sentence (proprietary $P...)"] == 5
    assert meta["sentences"] == {"PTNL,GGK": 1} and len(fixes) == 1


# ---------------------------------------------------------------- u-blox PUBX,04
def pubx04(tod: str = "081350.50", date: str = "170524") -> str:
    """u-blox's time sentence: time, date ddmmyy, UTC TOW, week, leap seconds (``D``: the
    receiver's default), clock bias and drift, time-pulse granularity."""
    return ck(f"PUBX,04,{tod},{date},202430.50,2315,18D,-384839,-53.623,16")


def test_pubx04_dates_pubx00_positions() -> None:
    """A u-blox log of PUBX,00 positions and PUBX,04 times needs no --date; a day-first
    date (170524: 17 May 2024), and the next day after midnight."""
    data = log(pubx04(), pubx(), pubx04("235959.50", "170524"), pubx("235959.50"),
               pubx04("000000.50", "180524"), pubx("000000.50"))
    fixes, report, meta = parse_nmea(data, name="u.log")
    assert report.total == 0
    assert meta["sentences"] == {"PUBX,04": 3, "PUBX,00": 3}
    assert meta["date_source"] == "log (RMC/ZDA/GGK/PUBX,04)"
    assert fixes.t_ns.tolist() == [ns(2024, 5, 17, 8, 13, 50, 500_000),
                                   ns(2024, 5, 17, 23, 59, 59, 500_000),
                                   ns(2024, 5, 18, 0, 0, 0, 500_000)]


def test_pubx04_date_loses_to_rmc_and_a_bad_one_is_counted() -> None:
    rmc = ck("GPRMC,081350.50,A,4807.03812,N,01131.00099,W,19.4,077.5,170524,,,D")
    data = log(pubx04(date="010199"), rmc, pubx04("081351.50", "32xx24"), pubx("081351.50"))
    fixes, report, _ = parse_nmea(data, name="u.log")
    assert report.counts["malformed date in PUBX,04 (field ignored)"] == 1
    assert report.first["malformed date in PUBX,04 (field ignored)"] == "u.log:3"
    assert fixes.t_ns.tolist() == [ns(2024, 5, 17, 8, 13, 50, 500_000),
                                   ns(2024, 5, 17, 8, 13, 51, 500_000)]
