"""GNS and GLL position sentences, disagreeing sentences of one epoch, UTF-16 and Latin-1 logs.

Expected coordinates are hand-decoded from the sentences (ddmm.mmmm / 60); tolerance
1e-9 deg unless named otherwise.
"""

from __future__ import annotations

import datetime
from pathlib import Path

import numpy as np
import pytest

from gpsdr_cli.io.nmea import parse_nmea, read_nmea
from tests.io.test_nmea import DAY, ck, log, t_ns

DATA = Path(__file__).resolve().parents[1] / "data" / "nmea"
TOL_DEG = 1e-9
LAT = 48 + 7.038 / 60
LON = 11 + 31.0 / 60


def gns(tod: str, mode: str, talker: str = "GN", lat: str = "4807.038,N",
        lon: str = "01131.000,E", nsat: str = "14", hdop: str = "0.9", alt: str = "545.4",
        sep: str = "46.9") -> str:
    return ck(f"{talker}GNS,{tod},{lat},{lon},{mode},{nsat},{hdop},{alt},{sep},,,V")


def gll(tod: str, status: str = "A", mode: str = "A", lat: str = "4807.038,N",
        lon: str = "01131.000,E", talker: str = "GP") -> str:
    return ck(f"{talker}GLL,{lat},{lon},{tod},{status},{mode}")


def zda(tod: str) -> str:
    return ck(f"GPZDA,{tod},17,05,2024,00,00")


@pytest.mark.parametrize(("mode", "quality"), [
    ("RR", 4), ("FN", 5), ("DA", 2), ("AN", 1), ("EN", 6), ("NN", 0), ("NNNR", 4),
    ("AR", 4), ("AF", 5), ("AD", 2), ("EA", 1), ("N", 0), ("AAAAAA", 1), ("MN", 0),
    ("SS", 0), ("PN", 3),
])
def test_gns_mode_letters_map_to_gga_quality(mode: str, quality: int) -> None:
    fixes, report, _ = parse_nmea(log(zda("120000.00"), gns("120000.00", mode)), date=DAY)
    # manual input (M) and simulator (S) positions are no measurement: counted as skipped
    not_measured = {"M": "manual input", "S": "simulator"}.get(mode[0])
    assert report.total == (not_measured is not None)
    if not_measured:
        assert report.counts[f"GNS in {not_measured} mode (mode {mode[0]}, not a measurement)"] == 1
    assert fixes.fix_quality.tolist() == [quality]
    if quality:
        assert abs(fixes.lat_deg[0] - LAT) < TOL_DEG and abs(fixes.lon_deg[0] - LON) < TOL_DEG
    else:
        assert np.isnan(fixes.lat_deg[0])


@pytest.mark.parametrize("talker", ["GP", "GN", "GL", "GA", "GB", "BD", "GQ"])
def test_gns_any_talker_gives_satellites_hdop_and_ellipsoidal_height(talker: str) -> None:
    fixes, report, meta = parse_nmea(log(zda("120000.00"), gns("120000.00", "AA", talker=talker,
                                                                nsat="17", hdop="0.7")))
    assert report.total == 0 and meta["sentences"]["GNS"] == 1
    assert fixes.t_ns.tolist() == [t_ns(DAY, 12, 0, 0)]
    assert fixes.n_sats.tolist() == [17]
    assert fixes.hdop.tolist() == [0.7]
    assert abs(fixes.alt_m[0] - (545.4 + 46.9)) < 1e-9  # m: MSL + geoid separation


def test_gns_bad_mode_is_skipped_and_counted() -> None:
    fixes, report, _ = parse_nmea(log(zda("120000.00"), gns("120000.00", "AX"),
                                      zda("120001.00"), gns("120001.00", "DD")))
    assert report.counts["malformed mode in GNS"] == 1
    assert fixes.fix_quality.tolist() == [2]  # the skipped GNS leaves its epoch no position row
    assert fixes.t_ns.tolist() == [t_ns(DAY, 12, 0, 1)]


def test_gll_status_and_mode() -> None:
    lines = [zda("120000.00"), gll("120000.00", "A", "D"),
             zda("120001.00"), gll("120001.00", "V", "N"),
             zda("120002.00"), ck("GPGLL,4807.038,N,01131.000,E,120002.00,A"),  # pre-2.3: no mode
             zda("120003.00"), gll("120003.00", "A", "N")]
    fixes, report, _ = parse_nmea(log(*lines))
    assert report.total == 0
    assert fixes.fix_quality.tolist() == [2, 0, 1, 0]
    assert np.isfinite(fixes.lat_deg).tolist() == [True, False, True, False]
    assert np.isnan(fixes.alt_m).all()  # GLL has no height


def test_gns_only_log_from_a_multi_constellation_receiver() -> None:
    """An NMEA 4.x receiver giving its position only in GNS: every epoch is a fix."""
    lines = []
    for i in range(71):
        tod = f"12{i // 60:02d}{i % 60:02d}.00"
        lines += [ck(f"GNRMC,{tod},A,4807.038,N,01131.000,E,0.1,,170524,,,A,V")
                  if i == 0 else zda(tod), gns(tod, "AAAN")]
    fixes, report, _ = parse_nmea(log(*lines))
    assert len(fixes) == 71 and (fixes.fix_quality == 1).all()
    assert report.total == 0


def test_disagreeing_sentences_take_gga_over_rmc_over_gll_and_are_counted() -> None:
    # GGA at 4807.038, RMC 0.01' (1.7e-4 deg) north, GLL 0.02' north: three fixes of one second
    lines = [ck("GPRMC,120000.00,A,4807.048,N,01131.000,E,0.1,,170524,,,A"),
             gll("120000.00", lat="4807.058,N"), ck("GPGGA,120000.00,4807.038,N,01131.000,E,"
                                                     "1,08,0.9,545.4,M,46.9,M,,"),
             ck("GPRMC,120001.00,A,4807.048,N,01131.000,E,0.1,,170524,,,A"),
             gll("120001.00", lat="4807.058,N"),
             gll("120002.00", lat="4807.058,N"), zda("120002.00")]
    fixes, report, meta = parse_nmea(log(*lines))
    assert report.total == 0  # a disagreement is not a skipped record
    np.testing.assert_allclose(fixes.lat_deg, [LAT, 48 + 7.048 / 60, 48 + 7.058 / 60],
                               atol=TOL_DEG, rtol=0)
    assert meta["position_disagreements"] == 2
    assert any("2 epochs whose sentences disagree" in n for n in meta["notes"])
    last, _, meta_last = parse_nmea(log(*lines), position_from="last")
    np.testing.assert_allclose(last.lat_deg, [LAT, 48 + 7.058 / 60, 48 + 7.058 / 60],
                               atol=TOL_DEG, rtol=0)
    assert meta_last["position_disagreements"] == 2


def test_coarser_rmc_within_its_last_digit_is_no_disagreement() -> None:
    lines = [ck("GPGGA,120000.00,4807.0381234,N,01131.0004567,E,4,08,0.9,545.4,M,46.9,M,,"),
             ck("GPRMC,120000.00,A,4807.0381,N,01131.0005,E,0.1,,170524,,,R")]
    fixes, _, meta = parse_nmea(log(*lines))
    assert meta["position_disagreements"] == 0 and "notes" not in meta
    assert abs(fixes.lat_deg[0] - (48 + 7.0381234 / 60)) < TOL_DEG  # the finer GGA's digits
    assert fixes.fix_quality.tolist() == [4]


def test_gpsd_expected_positions_on_a_real_log() -> None:
    """gpsd's TPV for each second of a real B&G chartplotter log (GGA, GLL, RMC stamped one
    second late): ``position_from='last'`` matches gpsd within 1e-6 deg."""
    rows = [r.split("\t") for r in (DATA / "gpsd-bundg_zeus_9-expected.tsv").read_text()
            .splitlines() if r and not r.startswith(("#", "time"))]
    want = {np.datetime64(t.rstrip("Z"), "ns").astype(np.int64): (float(a), float(b))
            for t, a, b in rows}
    d = read_nmea(DATA / "gpsd-bundg_zeus_9-excerpt.log", position_from="last")
    got = dict(zip(d.gnss.t_ns.tolist(), zip(d.gnss.lat_deg, d.gnss.lon_deg, strict=True),
                   strict=True))
    for t, (lat, lon) in want.items():
        assert abs(got[t][0] - lat) < 1e-6 and abs(got[t][1] - lon) < 1e-6, t
    assert d.meta["position_disagreements"] == 5  # the late RMC of the seconds it moved (> 2.5 digits)
    ranked = read_nmea(DATA / "gpsd-bundg_zeus_9-excerpt.log")
    t0 = np.datetime64("2018-08-20T09:47:37", "ns").astype(np.int64)
    i = ranked.gnss.t_ns.tolist().index(t0)
    # its GGA (51.0085') and GLL (51.0084') are one fix printed 1 digit apart: the last, as gpsd
    assert abs(ranked.gnss.lat_deg[i] - want[t0][0]) < 1e-6
    assert abs(ranked.gnss.lat_deg[i] - (52 + 51.0085 / 60)) > 1e-6


def test_real_nmea4_log_reads_gns_and_gll() -> None:
    """pynmeagps' NMEA 4.x sample: RMC, GNS, GGA, GLL, a second GGA (INGGA) of one second;
    its RMC longitude was edited (10214 vs 00214): one disagreement, GGA taken."""
    path = DATA.parents[1].parent.parent / "shared" / "data" / "nmea_samples" / "pynmeagps" \
        / "text" / "pygpsdata-nmea4.log"
    if not path.exists():
        pytest.skip("shared data not present")
    d = read_nmea(path)
    assert d.meta["sentences"]["GNS"] == 1 and d.meta["sentences"]["GLL"] == 1
    assert d.meta["position_disagreements"] == 1
    assert abs(d.gnss.lon_deg[0] - -(2 + 14.42462 / 60)) < TOL_DEG


# ------------------------------------------------------------------ encodings
TEXT = log(zda("120000.00"), gns("120000.00", "AA"), zda("120001.00"),
           gns("120001.00", "RR")).decode()


@pytest.mark.parametrize(("enc", "bom", "name"), [
    ("utf-16-le", b"\xff\xfe", "UTF-16-LE (byte-order mark)"),
    ("utf-16-be", b"\xfe\xff", "UTF-16-BE (byte-order mark)"),
    ("utf-16-le", b"", "UTF-16-LE (no byte-order mark, told by its NUL bytes)"),
    ("utf-16-be", b"", "UTF-16-BE (no byte-order mark, told by its NUL bytes)"),
])
def test_utf16_logs_are_decoded(enc: str, bom: bytes, name: str) -> None:
    want, _, _ = parse_nmea(TEXT.encode())
    fixes, report, meta = parse_nmea(bom + TEXT.encode(enc))
    assert report.total == 0
    np.testing.assert_array_equal(fixes.t_ns, want.t_ns)
    np.testing.assert_array_equal(fixes.lat_deg, want.lat_deg)
    assert fixes.fix_quality.tolist() == [1, 4]
    assert meta["encoding"] == name
    assert any(name in n for n in meta["notes"])


def test_latin1_comment_is_named_and_binary_noise_still_counted() -> None:
    latin = ("# Fahrt München–Köln, Empfänger im Wagen\r\n".replace("–", "-").encode("latin-1")
             + TEXT.encode())
    fixes, report, meta = parse_nmea(latin)
    assert len(fixes) == 2 and meta["encoding"] == "Latin-1 (ISO 8859-1)"
    assert report.counts["comment line (starts with #)"] == 1
    noisy = bytes(range(1, 9)) + b"\x81\x90\xb5\x62\x01\x07" + b"\r\n" + TEXT.encode()
    fixes2, report2, meta2 = parse_nmea(noisy)
    assert len(fixes2) == 2 and "encoding" not in meta2
    assert report2.total == 1


def test_utf16_log_reads_through_read_drive_and_info(tmp_path: Path) -> None:
    from click.testing import CliRunner

    from gpsdr_cli.cli.main import cli

    p = tmp_path / "utf16.nmea"
    lines = [ck("GPRMC,120000.00,A,4807.048,N,01131.000,E,0.1,,170524,,,A"),
             ck("GPGGA,120000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,")]
    p.write_bytes(log(*lines).decode().encode("utf-16"))
    result = CliRunner().invoke(cli, ["info", str(p)])
    assert result.exit_code == 0, result.output
    assert "text encoding UTF-16-LE (byte-order mark)" in result.output
    assert "1 epochs whose sentences disagree on the position" in result.output
    assert datetime.date(2024, 5, 17).isoformat() in result.output


def test_real_furuno_gns_agrees_with_its_gga_and_reads_alone() -> None:
    """A Furuno GT-88 (gpsd's regression log): its GNS mode ``NDD`` (GPS none, GLONASS and
    Galileo differential) gives the quality its GGA states (2); with the GGA lines removed
    the GNS gives the same fixes, with its own satellite count (the GGA says 00)."""
    path = DATA / "gpsd-furuno_gl_ga-excerpt.log"
    d = read_nmea(path)
    assert d.gnss.fix_quality.tolist() == [2, 2, 2]
    assert d.meta["position_disagreements"] == 0
    assert d.gnss.n_sats.tolist() == [11, 11, 10]  # the GGA's 00 is no count
    lat, lon = 59 + 57.0062 / 60, 11 + 0.6429 / 60
    no_gga = b"".join(ln for ln in path.read_bytes().splitlines(keepends=True)
                      if b"GGA," not in ln)
    g, report, meta = parse_nmea(no_gga)
    # the "#" header: 8 comment lines, one naming "$PERD messages" (not a sentence cut short)
    assert report.counts["comment line (starts with #)"] == 8
    assert "no checksum (truncated sentence)" not in report.counts
    assert "GGA" not in meta["sentences"] and meta["sentences"]["GNS"] == 3
    assert g.fix_quality.tolist() == [2, 2, 2]
    np.testing.assert_allclose(g.lat_deg, lat, atol=TOL_DEG, rtol=0)
    np.testing.assert_allclose(g.lon_deg, lon, atol=TOL_DEG, rtol=0)
    np.testing.assert_allclose(g.alt_m, 168.9 + 39.5, atol=1e-9, rtol=0)  # m
    assert g.n_sats.tolist() == [11, 11, 10]
    np.testing.assert_array_equal(g.t_ns, d.gnss.t_ns)
    rows = [r.split("\t") for r in (DATA / "gpsd-furuno_gl_ga-expected.tsv").read_text()
            .splitlines() if r and not r.startswith(("#", "time"))]
    for fixes in (d.gnss, g):  # with and without the GGA lines: gpsd's TPV, 1e-6 deg
        for (t, la, lo, h), tn, a, b, alt in zip(rows, fixes.t_ns, fixes.lat_deg, fixes.lon_deg,
                                                 fixes.alt_m, strict=True):
            assert np.datetime64(t.rstrip("Z"), "ns").astype(np.int64) == tn
            assert abs(a - float(la)) < 1e-6 and abs(b - float(lo)) < 1e-6
            assert abs(alt - float(h)) < 1e-6  # m, ellipsoidal (gpsd's altHAE)


def test_per_system_gns_with_counts_only_is_not_damage() -> None:
    """NMEA 4.1 receivers (a Trimble R2 log) write a combined GNGNS and, per system, a GNS
    with its satellite count only: empty position and mode.  Those are not counted as
    malformed; the combined one is the fix (float RTK: 'FFNNN')."""
    lines = []
    for s in range(3):
        hms = f"2356{47 + s:02d}.00"
        lines += [ck(f"GNGNS,{hms},3403.47162394,N,11711.80927093,W,FFNNN,10,1.2,403.600,"
                     "-32.133,,"),
                  ck(f"GPGNS,{hms},,,,,,6,,,,1.0,0"), ck(f"GLGNS,{hms},,,,,,4,,,,1.0,0")]
    g, report, _ = parse_nmea(log(*lines), date=DAY)
    assert "malformed mode in GNS" not in report.counts
    assert len(g) == 3 and np.all(g.fix_quality == 5)
    assert g.lat_deg[0] == pytest.approx(34 + 3.47162394 / 60, abs=1e-9)
    assert g.t_ns[0] == t_ns(DAY, 23, 56, 47.0)
