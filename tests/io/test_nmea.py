"""NMEA reader on hand-written logs whose every number is known.

Tolerances: positions 1e-9 deg (exact ddmm arithmetic), speeds 1e-9 m/s, times exact (ns).
"""

from __future__ import annotations

import datetime
import io
import sys

import numpy as np
import pytest

from gpsdr_cli.errors import ChecksumError, InputError, MissingDateError, NoDataError, ParseError
from gpsdr_cli.io.nmea import KNOT_MPS, looks_like_nmea, parse_nmea, read_nmea

DAY = datetime.date(2024, 5, 17)
pytestmark = pytest.mark.filterwarnings("error")  # no numpy RuntimeWarning may escape


def ck(body: str, lower: bool = False) -> str:
    """``$body*hh`` with the XOR checksum (upper-case hex unless ``lower``)."""
    x = 0
    for c in body.encode():
        x ^= c
    h = f"{x:02x}" if lower else f"{x:02X}"
    return f"${body}*{h}"


def log(*lines: str, eol: str = "\r\n") -> bytes:
    return (eol.join(lines) + eol).encode()


def t_ns(day: datetime.date, hh: int, mm: int, ss: float) -> int:
    dt = datetime.datetime(day.year, day.month, day.day, tzinfo=datetime.UTC)
    return int(dt.timestamp()) * 1_000_000_000 + round((hh * 3600 + mm * 60 + ss) * 1e9)


GGA = "GPGGA,123519.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,"
RMC = "GPRMC,123519.00,A,4807.038,N,01131.000,E,022.4,084.4,170524,003.1,W,A"
LAT = 48 + 7.038 / 60
LON = 11 + 31.0 / 60


def gga(tod: str, q: int = 1, lat: str = "4807.038,N", lon: str = "01131.000,E",
        talker: str = "GP") -> str:
    return ck(f"{talker}GGA,{tod},{lat},{lon},{q},08,0.9,545.4,M,46.9,M,,")


def rmc(tod: str, date: str = "170524", status: str = "A", talker: str = "GP") -> str:
    return ck(f"{talker}RMC,{tod},{status},4807.038,N,01131.000,E,022.4,084.4,{date},003.1,W,A")


# ------------------------------------------------------------------ basic fields
def test_gga_rmc_gst_merge_into_one_epoch() -> None:
    data = log(ck(RMC), ck(GGA), ck("GPGST,123519.00,1.2,2.1,1.5,35.0,1.8,1.6,3.2"),
               ck("GPVTG,090.0,T,,M,010.0,N,018.5,K,A"))
    fixes, report, meta = parse_nmea(data)
    assert len(fixes) == 1
    assert fixes.t_ns[0] == t_ns(DAY, 12, 35, 19)
    assert fixes.lat_deg[0] == pytest.approx(LAT, abs=1e-9)
    assert fixes.lon_deg[0] == pytest.approx(LON, abs=1e-9)
    assert fixes.alt_m[0] == pytest.approx(545.4 + 46.9, abs=1e-9)  # MSL + geoid separation
    assert fixes.fix_quality[0] == 1 and fixes.n_sats[0] == 8
    assert fixes.hdop[0] == pytest.approx(0.9)
    assert fixes.sigma_n_m[0] == pytest.approx(1.8)  # GST field 6: latitude sd
    assert fixes.sigma_e_m[0] == pytest.approx(1.6)  # GST field 7: longitude sd
    assert fixes.speed_mps[0] == pytest.approx(22.4 * 1852 / 3600, abs=1e-9)  # RMC beats VTG
    assert fixes.course_deg[0] == pytest.approx(84.4)
    assert report.total == 0
    assert meta["sentences"] == {"RMC": 1, "GGA": 1, "GST": 1, "VTG": 1}
    assert meta["talkers"] == {"GP": 4}
    assert meta["dates"] == ["2024-05-17"]


def test_southern_western_hemispheres_and_vtg_speed() -> None:
    data = log(gga("010203.5", lat="3345.1200,S", lon="07036.6000,W"),
               ck("GPVTG,271.5,T,,M,005.0,N,009.3,K,D"))
    fixes, _, _ = parse_nmea(data, date=DAY)
    assert fixes.lat_deg[0] == pytest.approx(-(33 + 45.12 / 60), abs=1e-9)
    assert fixes.lon_deg[0] == pytest.approx(-(70 + 36.6 / 60), abs=1e-9)
    assert fixes.speed_mps[0] == pytest.approx(5 * KNOT_MPS, abs=1e-9)
    assert fixes.course_deg[0] == pytest.approx(271.5)
    assert fixes.t_ns[0] == t_ns(DAY, 1, 2, 3.5)


def test_rmc_only_epochs_use_rmc_position_and_mode() -> None:
    data = log(rmc("000001"), ck("GNRMC,000002,A,4807.038,N,01131.000,E,0.0,,170524,,,D"),
               ck("GNRMC,000003,A,4807.038,N,01131.000,E,0.0,,170524,,,E"), rmc("000004", status="V"))
    fixes, _, _ = parse_nmea(data)
    assert fixes.fix_quality.tolist() == [1, 2, 6, 0]
    assert np.isfinite(fixes.lat_deg[:3]).all() and np.isnan(fixes.lat_deg[3])
    assert np.isnan(fixes.speed_mps[3])  # status V: no speed either


# ------------------------------------------------------------------ no fix / qualities
def test_no_fix_rows_are_nan_never_zero() -> None:
    data = log(rmc("100000"), ck("GPGGA,100000,,,,,0,00,99.99,,,,,,"),
               rmc("100001"), gga("100001", q=1, lat=",", lon=","),  # quality 1 but empty position
               rmc("100002"), gga("100002", q=0),  # quality 0 with a (stale) position
               rmc("100003"), gga("100003", lat="0000.000,N", lon="00000.000,E"),
               rmc("100004"), gga("100004"),
               rmc("100005"), gga("100005", q=0, lat=",N", lon=",E"))  # letters, no numbers
    fixes, report, _ = parse_nmea(bytearray(data))
    assert len(fixes) == 6
    assert fixes.fix_quality.tolist() == [0, 0, 0, 0, 1, 0]
    assert np.isnan(fixes.lat_deg[:4]).all() and np.isnan(fixes.lon_deg[:4]).all()
    assert not (fixes.lat_deg == 0).any()
    assert fixes.valid.tolist() == [False] * 4 + [True, False]
    assert np.isnan(fixes.hdop[0])  # 99.99: the receivers' "no DOP" placeholder
    assert report.total == 0


@pytest.mark.parametrize("q", [2, 4, 5, 6])
def test_dgps_rtk_and_dead_reckoning_qualities_kept(q: int) -> None:
    fixes, _, _ = parse_nmea(log(gga("120000", q=q)), date=DAY)
    assert fixes.fix_quality[0] == q and fixes.valid[0]


@pytest.mark.parametrize(("q", "how"), [(7, "manual input"), (8, "simulator")])
def test_manual_input_and_simulator_gga_are_no_fix_and_counted(q: int, how: str) -> None:
    # quality 7 is a position typed in, 8 one the receiver's simulator made up: neither is
    # measured; dead reckoning (6) stays what it was
    data = log(gga("120000", q=q), gga("120001", q=6), gga("120002"))
    fixes, report, _ = parse_nmea(data, date=DAY)
    assert fixes.fix_quality.tolist() == [0, 6, 1]
    assert fixes.valid.tolist() == [False, True, True] and np.isnan(fixes.lat_deg[0])
    assert dict(report.counts) == {f"GGA in {how} mode (quality {q}, not a measurement)": 1}
    fixes, _, _ = parse_nmea(data, date=DAY, strict=True)  # well formed: not a strict error
    assert fixes.fix_quality.tolist() == [0, 6, 1]


@pytest.mark.parametrize(("mode", "how"), [("M", "manual input"), ("S", "simulator")])
def test_manual_input_and_simulator_rmc_gll_are_no_fix_and_counted(mode: str, how: str) -> None:
    data = log(ck(f"GPRMC,120000,A,4807.038,N,01131.000,E,022.4,084.4,170524,003.1,W,{mode}"),
               ck(f"GPGLL,4807.038,N,01131.000,E,120001,A,{mode}"),
               ck(f"GPRMC,120002,V,4807.038,N,01131.000,E,0.0,0.0,170524,003.1,W,{mode}"),
               rmc("120003"))
    fixes, report, _ = parse_nmea(data)
    assert fixes.fix_quality.tolist() == [0, 0, 0, 1]
    assert np.isnan(fixes.lat_deg[:3]).all()
    assert dict(report.counts) == {f"RMC in {how} mode (mode {mode}, not a measurement)": 2,
                                   f"GLL in {how} mode (mode {mode}, not a measurement)": 1}


def test_gga_with_13_and_15_fields() -> None:
    g13 = ck("GPGGA,120000,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M")
    g15 = ck("GPGGA,120001,4807.038,N,01131.000,E,4,08,0.9,545.4,M,46.9,M,1.0,0000,")
    fixes, report, _ = parse_nmea(log(g13, g15), date=DAY)
    assert fixes.fix_quality.tolist() == [1, 4]
    assert np.allclose(fixes.lat_deg, LAT, atol=1e-9)
    assert report.total == 0


# ------------------------------------------------------------------ GSA
def test_gsa_per_constellation_merges_last_non_empty() -> None:
    data = log(rmc("120000"), gga("120000"),
               ck("GNGSA,A,3,01,02,03,,,,,,,,,,1.9,0.95,1.6,1"),
               ck("GNGSA,A,3,65,66,,,,,,,,,,,1.8,0.95,1.5,2"),
               ck("GNGSA,A,3,,,,,,,,,,,,,1.7,0.95,1.4,3"),
               ck("GNGSA,A,3,,,,,,,,,,,,,,,,4"),  # empty DOPs: do not erase the others
               rmc("120001"), gga("120001"),
               ck("GNGSA,A,3,01,02,03,,,,,,,,,,2.5,1.1,2.2,1"))
    fixes, report, meta = parse_nmea(data)
    assert fixes.pdop.tolist() == [1.7, 2.5]
    assert fixes.vdop.tolist() == [1.4, 2.2]
    assert fixes.hdop.tolist() == [0.9, 0.9]  # GGA's HDOP wins over GSA's
    assert meta["sentences"]["GSA"] == 5 and report.total == 0


def test_gsa_hdop_used_when_gga_has_none_and_no_fix_gsa_ignored() -> None:
    data = log(rmc("120000"), ck("GPGSA,A,3,01,02,03,04,,,,,,,,,2.0,1.2,1.6"),
               rmc("120001"), ck("GPGSA,A,1,,,,,,,,,,,,,99.99,99.99,99.99"))
    fixes, _, _ = parse_nmea(data)
    assert fixes.hdop[0] == pytest.approx(1.2) and fixes.pdop[0] == pytest.approx(2.0)
    assert np.isnan(fixes.pdop[1]) and np.isnan(fixes.hdop[1])


def test_pqgsa_is_quectel_qzss_gsa_not_proprietary() -> None:
    data = log(rmc("120000"), ck("PQGSA,A,3,193,194,,,,,,,,,,,1.6,0.8,1.3,5"))
    fixes, report, meta = parse_nmea(data)
    assert fixes.pdop[0] == pytest.approx(1.6) and fixes.vdop[0] == pytest.approx(1.3)
    assert report.total == 0 and meta["talkers"]["PQ"] == 1


def test_nmea41_fields_and_gsa_with_29_fields() -> None:
    sats = ",".join(f"{i:02d}" for i in range(1, 23))  # 22 satellite ids
    gsa29 = ck(f"GNGSA,A,3,{sats},1.4,0.7,1.2,1")
    assert gsa29.count(",") + 1 == 29  # 29 fields, the address included
    rmc41 = ck("GNRMC,120000.00,A,4807.038,N,01131.000,E,0.5,,170524,,,R,S")  # mode R, nav status S
    fixes, report, _ = parse_nmea(log(rmc41, gsa29))
    assert fixes.fix_quality[0] == 4
    assert (fixes.pdop[0], fixes.hdop[0], fixes.vdop[0]) == (1.4, 0.7, 1.2)
    assert report.total == 0


def test_gsa_before_first_timed_sentence_attaches_to_first_epoch() -> None:
    data = log(ck("GPGSA,A,3,01,02,03,04,,,,,,,,,2.0,1.2,1.6"), gga("120000"), rmc("120000"))
    fixes, _, _ = parse_nmea(data)
    assert len(fixes) == 1 and fixes.pdop[0] == pytest.approx(2.0)


# ------------------------------------------------------------------ dates
def test_midnight_rollover_without_dates_uses_argument() -> None:
    data = log(gga("235958.0"), gga("235959.0"), gga("000000.0"), gga("000001.0"))
    fixes, _, meta = parse_nmea(data, date=DAY)
    expected = t_ns(DAY, 23, 59, 58) + np.arange(4) * 1_000_000_000
    assert fixes.t_ns.tolist() == expected.tolist()
    assert meta["date_source"] == "argument"
    assert meta["dates"] == ["2024-05-17", "2024-05-18"]
    as_datetime = datetime.datetime(2024, 5, 17, 8, 0, tzinfo=datetime.UTC)
    assert parse_nmea(data, date=as_datetime)[0].t_ns.tolist() == expected.tolist()


def test_forward_gap_stays_on_the_same_day() -> None:
    data = log(gga("010000"), gga("140000"), gga("235959"), gga("000001"))
    fixes, _, _ = parse_nmea(data, date=DAY)
    next_day = DAY + datetime.timedelta(days=1)
    assert fixes.t_ns.tolist() == [t_ns(DAY, 1, 0, 0), t_ns(DAY, 14, 0, 0),
                                   t_ns(DAY, 23, 59, 59), t_ns(next_day, 0, 0, 1)]


def test_rollover_after_last_dated_epoch_and_before_first() -> None:
    # GGA before the first RMC (date back-filled), then GGAs after the last RMC roll over
    data = log(gga("235957"), rmc("235958", date="170524"), gga("235959"), gga("000000"))
    fixes, _, _ = parse_nmea(data, date=datetime.date(2000, 1, 1))  # log date wins
    expected = t_ns(DAY, 23, 59, 57) + np.arange(4) * 1_000_000_000
    assert fixes.t_ns.tolist() == expected.tolist()


def test_multi_day_log_with_dates() -> None:
    lines = []
    for date in ("170524", "180524", "190524"):
        lines += [rmc("120000", date=date), gga("120000")]
    lines += [rmc("235959", date="190524"), rmc("000000", date="200524")]
    fixes, _, meta = parse_nmea(log(*lines))
    days = [datetime.date(2024, 5, d) for d in (17, 18, 19)]
    expected = [t_ns(d, 12, 0, 0) for d in days] + [t_ns(days[2], 23, 59, 59),
                                                    t_ns(datetime.date(2024, 5, 20), 0, 0, 0)]
    assert fixes.t_ns.tolist() == expected
    assert meta["dates"] == ["2024-05-17", "2024-05-18", "2024-05-19", "2024-05-20"]


def test_gga_before_its_rmc_takes_the_rmc_date_after_a_default_date() -> None:
    # gpsd's rgm3800.log: no-fix RMCs dated 050180 (the receiver's default), then the first
    # fix's GGA and, after it, its RMC with the real date; the GGA belongs to that RMC's
    # epoch, not to an epoch of its own on the default date (1980-01-06 after midnight)
    data = log(rmc("235951.952", date="050180", status="V"), gga("102523.342"),
               rmc("102523.342", date="210808"), gga("102524.342"),
               rmc("102524.342", date="210808"))
    fixes, _, _ = parse_nmea(data)
    day = datetime.date(2008, 8, 21)
    want = [t_ns(datetime.date(1980, 1, 5), 23, 59, 51.952), t_ns(day, 10, 25, 23.342),
            t_ns(day, 10, 25, 24.342)]
    assert fixes.t_ns.tolist() == want
    assert fixes.fix_quality.tolist()[1:] == [1, 1]  # the GGAs' quality, in the RMC's epochs


def test_zda_gives_the_date() -> None:
    data = log(gga("120000"), ck("GPZDA,120000.00,17,05,2024,00,00"))
    fixes, _, _ = parse_nmea(data)
    assert fixes.t_ns[0] == t_ns(DAY, 12, 0, 0)


def test_no_date_source_asks_for_date_option() -> None:
    with pytest.raises(NoDataError, match="--date YYYY-MM-DD"):
        parse_nmea(log(gga("120000")), name="x.nmea")
    with pytest.raises(NoDataError, match="no fix"):
        parse_nmea(log(gga("120000", q=0)), name="x.nmea")


def test_missing_date_names_the_dated_sentences_skipped() -> None:
    # RMC broken over two lines just before its checksum digits: each is truncated, so the
    # GGA fixes are left without a date, and the message says why
    def wrapped(sentence: str) -> str:
        return sentence[:-2] + "\r\n" + sentence[-2:]

    data = log(*[line for tod in ("120000", "120001", "120002")
                 for line in (wrapped(rmc(tod)), gga(tod))])
    with pytest.raises(MissingDateError) as err:
        parse_nmea(data, name="x.nmea")
    message = str(err.value)
    assert "3 RMC skipped: no checksum (truncated sentence)" in message
    assert "--date YYYY-MM-DD" in message and "\n" not in message
    bad = rmc("120000")[:-2] + ("00" if rmc("120000")[-2:] != "00" else "11")
    with pytest.raises(MissingDateError, match="1 RMC skipped: bad checksum"):
        parse_nmea(log(bad, gga("120000")), name="x.nmea")
    with pytest.raises(MissingDateError, match=r"1 malformed time in RMC\)"):
        parse_nmea(log(rmc("1200"), gga("120000")), name="x.nmea")
    # a ZDA with its date fields empty (a marine logger's): its time is used, its date is why
    zda = ck("GPZDA,120000.00,,,,00,")
    with pytest.raises(MissingDateError, match=r"with a date; 1 ZDA with empty date fields\)"):
        parse_nmea(log(zda, gga("120000")), name="x.nmea")
    # no dated sentence skipped: the skip summary
    with pytest.raises(MissingDateError,
                       match=r"with a date; skipped: 1 not used: GSV \(satellites in view\)\)"):
        parse_nmea(log(gga("120000"), ck("GPGSV,1,1,00")), name="x.nmea")


def test_week_rollover_date_kept_and_warned() -> None:
    fixes, _, meta = parse_nmea(log(rmc("120000", date="021099")))
    assert fixes.t_ns[0] == t_ns(datetime.date(1999, 10, 2), 12, 0, 0)
    assert meta["warning_counts"] == {"suspicious date": 1}
    assert len(meta["warnings"]) == 1
    assert meta["warnings"][0].startswith("<nmea>: suspicious date 1999-10-02 kept as given")
    assert meta["suspicious_dates"] == ["1999-10-02"]


def test_malformed_date_and_trailing_dot_time() -> None:
    data = log(rmc("222508", date="2208-1"), rmc("222509."), gga("22251"))
    fixes, report, _ = parse_nmea(data, name="m.nmea")
    assert fixes.t_ns.tolist() == [t_ns(DAY, 22, 25, 8), t_ns(DAY, 22, 25, 9)]  # date back-filled
    assert report.counts["malformed date in RMC (field ignored)"] == 1
    assert report.first["malformed date in RMC (field ignored)"] == "m.nmea:1"
    assert report.counts["malformed time in GGA"] == 1
    assert report.first["malformed time in GGA"] == "m.nmea:3"


# ------------------------------------------------------------------ framing oddities
def test_doubled_dollar_binary_prefix_logger_prefix_and_nul_padding() -> None:
    data = (b"$" + log(rmc("120000"))
            + b"\xb5b\x01\x07\x5c\x00\xff\xfe" + log(gga("120000"))
            + b"2024-05-17T12:00:01.003Z " + log(rmc("120001"))
            + log(gga("120001")).replace(b"\r\n", b"\x00\x00\x00\r\n"))
    fixes, report, meta = parse_nmea(data)
    assert len(fixes) == 2 and fixes.valid.all()
    assert report.total == 0
    assert meta["doubled_starts"] == 1


def test_spliced_lines() -> None:
    truncated = gga("120000")[:30]
    data = log(rmc("120000") + gga("120000"),  # two full sentences on one line
               truncated + rmc("120001"),  # a cut-off sentence then a full one
               gga("120001"))
    fixes, report, meta = parse_nmea(data, name="s.nmea")
    assert len(fixes) == 2 and fixes.valid.all()
    assert meta["sentences"] == {"RMC": 2, "GGA": 2}
    assert report.counts == {"no checksum (truncated sentence)": 1}
    assert report.first["no checksum (truncated sentence)"] == "s.nmea:2"


def test_lower_case_checksum_hex() -> None:
    body = "GPRMC,120000,A,4807.038,N,01131.000,E,0.0,,170524,,,A"  # checksum has letters
    assert any(c in "abcdef" for c in ck(body, lower=True)[-2:])
    fixes, report, _ = parse_nmea(log(ck(body, lower=True)))
    assert len(fixes) == 1 and report.total == 0


def test_crlf_lf_and_cr_mixed_with_comments_json_text() -> None:
    data = (rmc("120000").encode() + b"\r\n" + gga("120000").encode() + b"\n"
            + b"# comment line\n" + b'{"event": "start", "t": 1}\r\n'
            + b"free text from the logger\n" + b"\n   \n"
            + rmc("120001").encode() + b"\r" + gga("120001").encode() + b"\n")
    fixes, report, meta = parse_nmea(data, name="c.nmea")
    assert len(fixes) == 2
    assert report.counts == {"comment line (starts with #)": 1,
                             "not a sentence (no $ on the line)": 2}
    assert report.first["comment line (starts with #)"] == "c.nmea:3"
    assert report.first["not a sentence (no $ on the line)"] == "c.nmea:4"
    assert meta["lines"] == 9


def test_skip_counts_by_reason_with_first_line() -> None:
    bad = rmc("120001")[:-2] + ("00" if not rmc("120001").endswith("00") else "11")
    data = log(rmc("120000"), gga("120000"),
               ck("GPGSV,3,1,11,01,06,014,08,12,43,207,28,14,06,049,,15,44,171,23"),  # 3
               ck("PGRME,15.0,M,45.0,M,25.0,M"),  # 4
               "!" + ck("AIVDM,1,1,,B,13aENmgP1CPH`N`NJ2L0Mwwb2@Nj,0")[1:],  # 5
               ck("02MWV,327.6,R,1.89,N"),  # 6
               ck("GNGGAH,073346.00,4004.73874301,N,11614.19077585,E,1,28,0.6,64.2,M,8.4,M,,"),
               bad,  # 8
               "$GPGGA,120002,4807.038,N,01131.000,E,1,08",  # 9: truncated, no checksum
               ck("GPGSV,3,2,11,01,06,014,08,12,43,207,28,14,06,049,,15,44,171,23"))
    fixes, report, _ = parse_nmea(data, name="r.nmea")
    assert len(fixes) == 1
    assert report.counts["not used: GSV (satellites in view)"] == 2
    assert report.first["not used: GSV (satellites in view)"] == "r.nmea:3"
    assert report.counts["unknown sentence (proprietary $P...)"] == 1
    assert report.counts["unknown sentence (numeric talker)"] == 1
    # Unicore's secondary antenna: a known type, not the vehicle's position
    assert report.counts["not used: GGAH (the secondary antenna of a dual-antenna receiver)"] == 1
    assert report.counts["bad checksum"] == 1 and report.first["bad checksum"] == "r.nmea:8"
    assert report.counts["no checksum (truncated sentence)"] == 1
    assert report.first["no checksum (truncated sentence)"] == "r.nmea:9"
    assert report.counts["unknown sentence (encapsulated !AIVDM, e.g. AIS)"] == 1
    assert report.total == 8


def test_malformed_field_blanks_only_that_field() -> None:
    data = log(ck("GPRMC,120000,A,4807.038,N,01131.000,E,X.138,12.0,170524,,,A"))
    fixes, report, _ = parse_nmea(data, name="f.nmea")
    assert np.isnan(fixes.speed_mps[0]) and fixes.course_deg[0] == pytest.approx(12.0)
    assert fixes.valid[0]
    assert report.counts == {"malformed speed in RMC (field ignored)": 1}


def test_bad_latitude_drops_the_sentence() -> None:
    data = log(rmc("120000"), gga("120000", lat="4867.000,N"))  # 67 minutes
    fixes, report, _ = parse_nmea(data)
    assert fixes.valid[0] and fixes.lat_deg[0] == pytest.approx(LAT)  # from RMC
    assert report.counts == {"malformed position in GGA": 1}


def test_instrument_sentences_of_a_boat_or_car_bus_are_not_used_not_unknown() -> None:
    # pypilot's and Humminbird's logs (gpsd's regression suite) mix these standard NMEA 0183
    # sentences with the fixes: they are named as not used, not counted as unknown or damaged
    data = log(rmc("120000"), ck("IIXDR,C,19.5,C,AIRTEMP"), ck("SDDPT,4.5,0.3"),
               ck("YXMTW,15.2,C"), ck("IIVHW,,T,,M,5.1,N,9.4,K"), ck("WIMWV,327.6,R,1.89,N,A"),
               gga("120000"))
    fixes, report, _ = parse_nmea(data, name="b.nmea")
    assert len(fixes) == 1
    assert report.counts == {"not used: XDR (transducer measurements)": 1,
                             "not used: DPT (water depth)": 1,
                             "not used: MTW (water temperature)": 1,
                             "not used: VHW (water speed and heading)": 1,
                             "not used: MWV (wind speed and angle)": 1}


# ------------------------------------------------------------------ strict mode
def test_strict_raises_at_first_bad_line() -> None:
    data = log(rmc("120000"), ck("GPGSV,1,1,00"), "# a comment quoting $GPGGA", "note",
               gga("120000"))
    with pytest.raises(ParseError, match=r"^s\.nmea:4: not a sentence"):
        parse_nmea(data, name="s.nmea", strict=True)
    body = rmc("120001")
    data = log(rmc("120000"), body[:-2] + ("00" if body[-2:] != "00" else "11"))
    with pytest.raises(ChecksumError, match=r"^s\.nmea:2: bad checksum") as err:
        parse_nmea(data, name="s.nmea", strict=True)
    assert f"computed *{body[-2:]}" in str(err.value)  # the right checksum is named
    with pytest.raises(ParseError, match=r"^s\.nmea:1: malformed time in GGA: '\$GPGGA,1200,.*"
                                         r"expected hhmmss\[\.sss\]"):
        parse_nmea(log(gga("1200")), name="s.nmea", strict=True, date=DAY)
    fixes, _, _ = parse_nmea(log(rmc("120000"), ck("GPGSV,1,1,00")), strict=True)  # not used: fine
    assert len(fixes) == 1


# ------------------------------------------------------------------ input errors
def test_input_errors_name_the_file(tmp_path) -> None:
    with pytest.raises(InputError, match=r"^e\.nmea: empty file"):
        parse_nmea(b"", name="e.nmea")
    text = log(rmc("120000"), gga("120000")).decode()
    for enc in ("utf-16", "utf-16-le", "utf-16-be"):  # decoded, not refused
        assert len(parse_nmea(text.encode(enc), name="u.nmea")[0]) == 1
    rng = np.random.default_rng(1)
    binary = rng.integers(0, 256, 4000, dtype=np.uint8).tobytes().replace(b"$", b"")
    with pytest.raises(InputError, match=r"^b\.bin: binary file with no NMEA"):
        parse_nmea(binary, name="b.bin")
    with pytest.raises(NoDataError, match="no GGA/GNS/RMC"):
        parse_nmea(log(ck("GPGSV,1,1,00"), "hello"), name="g.nmea")
    with pytest.raises(InputError, match="cannot read"):
        read_nmea(tmp_path / "missing.nmea")
    with pytest.raises(InputError, match="cannot read"):
        read_nmea(tmp_path)  # a directory


def test_read_nmea_file_and_stdin(tmp_path, monkeypatch) -> None:
    import hashlib

    data = log(rmc("120000"), gga("120000"))
    p = tmp_path / "a.nmea"
    p.write_bytes(data)
    drive = read_nmea(p)
    assert len(drive.gnss) == 1
    assert drive.sources[0].path == str(p)
    assert drive.sources[0].sha256 == hashlib.sha256(data).hexdigest()
    assert drive.sources[0].streams == ("gnss",)
    assert drive.meta["sentences"] == {"RMC": 1, "GGA": 1}

    class FakeStdin:
        buffer = io.BytesIO(data)

    monkeypatch.setattr(sys, "stdin", FakeStdin())
    d2 = read_nmea("-")
    assert d2.gnss.t_ns.tolist() == drive.gnss.t_ns.tolist()
    assert d2.sources[0].path == "-"


def test_looks_like_nmea() -> None:
    text = log(rmc("120000"), gga("120000"), rmc("120001"))
    assert looks_like_nmea(text)
    assert looks_like_nmea(b"\xb5b\x01\x07junk" + text)
    assert looks_like_nmea(text.decode().encode("utf-16"))
    assert not looks_like_nmea(b"t,yaw_rate\n1.0,0.01\n2.0,0.02\n")
    assert not looks_like_nmea(b"$GPGGA,no checksum here\n$GPRMC,nor here\n")
    assert not looks_like_nmea(bytes(range(256)) * 4)


def test_round_trip_with_the_simulator_writer_across_midnight() -> None:
    """gpsdr's own NMEA writer (simulate.nmea_lines) -> parse_nmea recovers every field."""
    simulate = pytest.importorskip("gpsdr_cli.simulate")
    from gpsdr_cli.io.drive import GnssFixes

    n = 60
    rng = np.random.default_rng(7)
    g = GnssFixes.empty(n)
    g.t_ns = t_ns(DAY, 23, 59, 57) + np.arange(n, dtype=np.int64) * 100_000_000  # 10 Hz
    g.lat_deg = -33.9 + rng.normal(0, 0.01, n)
    g.lon_deg = 151.2 + rng.normal(0, 0.01, n)
    g.alt_m = 40 + rng.normal(0, 1, n)
    g.fix_quality[:] = 1
    g.fix_quality[20:25] = 0  # an outage
    g.lat_deg[20:25] = np.nan
    g.lon_deg[20:25] = np.nan
    g.n_sats[:] = 9
    g.hdop[:], g.pdop[:], g.vdop[:] = 0.9, 1.7, 1.4
    g.sigma_e_m[:], g.sigma_n_m[:] = 1.5, 2.5
    g.speed_mps = rng.uniform(0, 30, n)
    g.course_deg = rng.uniform(0, 359, n)
    data = "".join(simulate.nmea_lines(g)).encode()
    fixes, report, meta = parse_nmea(data)
    assert report.total == 0
    assert fixes.t_ns.tolist() == g.t_ns.tolist()  # midnight crossed via the RMC dates
    assert meta["dates"] == ["2024-05-17", "2024-05-18"]
    assert fixes.fix_quality.tolist() == g.fix_quality.tolist()
    ok = g.fix_quality > 0
    assert np.allclose(fixes.lat_deg[ok], g.lat_deg[ok], atol=2e-8)  # deg: 1e-6 min printed
    assert np.allclose(fixes.lon_deg[ok], g.lon_deg[ok], atol=2e-8)
    assert np.isnan(fixes.lat_deg[~ok]).all()
    assert np.allclose(fixes.alt_m[ok], g.alt_m[ok], atol=1e-3)  # m: 3 decimals printed
    assert np.allclose(fixes.speed_mps[ok], g.speed_mps[ok], atol=1e-3)  # m/s
    assert np.allclose(fixes.pdop[ok], 1.7) and np.allclose(fixes.vdop[ok], 1.4)
    assert np.allclose(fixes.sigma_e_m[ok], 1.5) and np.allclose(fixes.sigma_n_m[ok], 2.5)
    assert (fixes.n_sats[ok] == 9).all()


@pytest.mark.parametrize("chunk", [1, 37, 200, 1 << 22])
def test_chunked_scan_gives_identical_results(monkeypatch, chunk: int) -> None:
    """Chunk boundaries (whole lines) change nothing: rows, counts, first lines."""
    from gpsdr_cli.io import nmea

    lines = [b"# header", b"\xb5b\x01\x07" * 40 + rmc("235958").encode()]
    for k in range(30):
        sec = (23 * 3600 + 59 * 60 + 58 + k) % 86400
        tod = f"{sec // 3600:02d}{sec // 60 % 60:02d}{sec % 60:02d}"
        date = "170524" if sec >= 12 * 3600 else "180524"
        lines += [rmc(tod, date=date).encode(), gga(tod).encode(),
                  ck("GNGSA,A,3,01,02,03,,,,,,,,,,1.9,0.95,1.6,1").encode()]
        if k % 7 == 0:
            lines.append(gga(tod).encode()[:25])  # truncated
        if k % 11 == 0:
            lines.append(ck("GPGSV,1,1,00").encode() + b"\r")  # CR CR LF
    data = b"\r\n".join(lines) + b"\n"
    ref = parse_nmea(data, name="c.nmea")
    monkeypatch.setattr(nmea, "_CHUNK_BYTES", chunk)
    fixes, report, meta = parse_nmea(data, name="c.nmea")
    assert len(fixes) == 30
    assert fixes.t_ns.tolist() == ref[0].t_ns.tolist()
    assert np.array_equal(fixes.lat_deg, ref[0].lat_deg, equal_nan=True)
    assert np.array_equal(fixes.pdop, ref[0].pdop, equal_nan=True)
    assert dict(report.counts) == dict(ref[1].counts)
    assert report.first == ref[1].first
    assert meta == ref[2]
    assert report.counts["no checksum (truncated sentence)"] == 5


def test_altitude_without_geoid_separation_is_msl_and_warned() -> None:
    data = log(ck("GPGGA,120000,4807.038,N,01131.000,E,1,08,0.9,545.4,M,,M,,"), rmc("120000"))
    fixes, _, meta = parse_nmea(data, name="g.nmea")
    assert fixes.alt_m[0] == pytest.approx(545.4, abs=1e-9)  # m, MSL as given
    assert meta["warning_counts"] == {"altitude without geoid separation": 1}
    assert meta["warnings"][0].startswith("g.nmea: 1 GGA fixes have no geoid separation")


def test_odd_fields_counted_by_reason() -> None:
    long_alt = "1" * 60  # longer than any field the reader gathers
    data = log(ck(f"GPGGA,120000,4807.038,N,01131.000,E,1,08,0.9,{long_alt},M,46.9,M,,"),
               ck("GPRMC,120000,A,4807.038,N,01131.000,E,1.0,,170524,,,Q"),  # unknown mode Q
               ck("GPGSA,A,3"),
               ck("GPVTG,045.0,T,,M,003.0,N,005.6,K,N"),  # mode N: not valid
               ck("GPZDA,120000,32,05,2024,,"),  # 32 May
               ck("GPZDA,120000,17,05,24,,"))  # two-digit year
    fixes, report, _ = parse_nmea(data, name="o.nmea")
    assert dict(report.counts) == {
        "malformed altitude in GGA (field ignored)": 1,
        "malformed mode in RMC (field ignored)": 1,
        "GSA with too few fields": 1,
        "malformed date in ZDA (field ignored)": 2,
    }
    assert report.first["malformed date in ZDA (field ignored)"] == "o.nmea:5"
    assert len(fixes) == 1 and fixes.valid[0] and np.isnan(fixes.alt_m[0])
    assert fixes.fix_quality[0] == 1 and np.isnan(fixes.pdop[0])
    assert fixes.speed_mps[0] == pytest.approx(KNOT_MPS)  # RMC; the VTG was not valid anyway
    assert fixes.t_ns[0] == t_ns(DAY, 12, 0, 0)  # the RMC date


def test_benchmark_log_parses_exactly() -> None:
    """The benchmark's generated log (GGA+RMC+GSA+GST at 5 Hz) reads to one valid row per epoch."""
    import importlib.util
    from pathlib import Path

    path = Path(__file__).parents[2] / "benchmarks" / "read_nmea.py"
    spec = importlib.util.spec_from_file_location("bench_read_nmea", path)
    bench = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(bench)
    data = bench.generate_log(hours=0.02, rate_hz=5.0)  # 72 s, 360 epochs
    fixes, report, meta = parse_nmea(data)
    assert len(fixes) == 360 and fixes.valid.all() and report.total == 0
    assert meta["sentences"] == {"GGA": 360, "RMC": 360, "GSA": 360, "GST": 360}
    assert np.diff(fixes.t_ns).tolist() == [200_000_000] * 359  # 5 Hz exactly
    assert fixes.t_ns[0] == t_ns(DAY, 12, 0, 0)
    assert np.allclose(fixes.pdop, 1.5) and np.allclose(fixes.sigma_n_m, 1.8)
    assert np.all(np.abs(fixes.lat_deg - 48.1173) < 0.0021)  # deg: the generated circle
