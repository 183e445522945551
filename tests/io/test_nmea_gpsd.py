"""The NMEA reader against gpsd's expected output on excerpts of gpsd's regression logs.

``tests/data/gpsd/NAME.log`` are excerpts of gpsd's ``test/daemon/NAME.log`` and
``NAME.expected.tsv`` the positions of gpsd's TPV reports for them (from its
``.log.chk``); see ``tests/data/gpsd/README.md``.
"""

from __future__ import annotations

import datetime
import importlib.util
import json
import re
from pathlib import Path

import numpy as np
import pytest

from gpsdr_cli.io.nmea import parse_nmea

DATA = Path(__file__).resolve().parents[1] / "data" / "gpsd"
REPO = Path(__file__).resolve().parents[2]
LOGS = ["humminbird-M37", "ac12", "polarx2", "beidou-bd", "garmin48", "saab-r4", "sirfstarv-nmea"]
TOL_DEG = 1e-6


def _expected(name: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """gpsd's epochs: times (ms since 1970 UTC), lat, lon (deg)."""
    t, lat, lon = [], [], []
    for line in (DATA / f"{name}.expected.tsv").read_text().splitlines():
        if line.startswith(("#", "time")):
            continue
        ts, la, lo = line.split("\t")
        dt = datetime.datetime.fromisoformat(ts.replace("Z", "+00:00"))
        t.append(round(dt.timestamp() * 1000))
        lat.append(float(la))
        lon.append(float(lo))
    return np.array(t), np.array(lat), np.array(lon)


def _ours(data: bytes, first_ms: int):
    date = datetime.datetime.fromtimestamp(first_ms / 1000, datetime.UTC).date()
    return parse_nmea(data, name="x.log", date=date)


@pytest.mark.parametrize("name", LOGS)
def test_every_gpsd_fix_read_at_its_time_within_1e6_deg(name):
    t, lat, lon = _expected(name)
    fixes, _, _ = _ours((DATA / f"{name}.log").read_bytes(), int(t[0]))
    ok = fixes.fix_quality > 0
    ours_ms = np.round(fixes.t_ns[ok] / 1e6).astype(np.int64)
    idx = {int(m): i for i, m in enumerate(ours_ms)}
    missing = [int(m) for m in t if int(m) not in idx]
    assert not missing, f"gpsd fixes not read: {missing}"
    j = np.array([idx[int(m)] for m in t])
    assert np.abs(fixes.lat_deg[ok][j] - lat).max() <= TOL_DEG
    assert np.abs(fixes.lon_deg[ok][j] - lon).max() <= TOL_DEG


def test_humminbird_each_kind_alone_in_its_second():
    # RMC at odd seconds, GLL and GGA alternating at even ones: every second is a fix,
    # e.g. 19:41:06 from the GLL alone (gpsd: 44.435243333, -71.675831667)
    t, lat, lon = _expected("humminbird-M37")
    fixes, _, meta = _ours((DATA / "humminbird-M37.log").read_bytes(), int(t[0]))
    assert meta["talkers"] == {"IN": 36}
    i = int(np.flatnonzero(fixes.t_ns == np.datetime64("2006-09-16T19:41:06", "ns").astype(np.int64))[0])
    assert fixes.lat_deg[i] == pytest.approx(44.435243333, abs=TOL_DEG)
    assert fixes.lon_deg[i] == pytest.approx(-71.675831667, abs=TOL_DEG)
    # the GGA seconds have quality 2 (DGPS) and the MSL altitude (no geoid separation)
    j = int(np.flatnonzero(fixes.t_ns == np.datetime64("2006-09-16T19:41:08", "ns").astype(np.int64))[0])
    assert fixes.fix_quality[j] == 2 and fixes.alt_m[j] == pytest.approx(268.0)
    assert meta["alt_without_geoid_sep"] == 6


def test_one_gga_per_constellation_sums_the_satellites():
    # SiRFstar V: $GPGGA counts the GPS satellites (8), $GLGGA the GLONASS ones (2) of the
    # same fix; the epoch's fix used both, as its two GSA sentences list (8 + 2 = 10)
    t, _, _ = _expected("sirfstarv-nmea")
    fixes, _, _ = _ours((DATA / "sirfstarv-nmea.log").read_bytes(), int(t[0]))
    assert fixes.n_sats.tolist() == [10, 10, 15, 15, 14]
    # a combined $GN GGA of the epoch is the total itself, whatever per-system ones say
    gga = b"$%sGGA,020935.000,4404.1351,N,12118.8556,W,1,%02d,0.9,1123.9,M,-19.6,M,,0000"
    def s(body):
        ck = 0
        for c in body[1:]:
            ck ^= c
        return body + b"*%02X\r\n" % ck
    data = s(gga % (b"GP", 8)) + s(gga % (b"GL", 2)) + s(gga % (b"GN", 11))
    fixes, _, _ = parse_nmea(data, date=datetime.date(2019, 2, 5))
    assert fixes.n_sats.tolist() == [11]


def test_simulator_mode_gives_no_fix_and_says_why():
    # a Garmin GPSmap 76S in simulator mode: GGA quality 8, RMC status V and mode S, GLL
    # mode S; the positions are made up, so no epoch is a fix and the skip report says why
    fixes, report, _ = parse_nmea((DATA / "GPSmap-76S.log").read_bytes(), name="x.log")
    assert len(fixes) == 3 and not fixes.valid.any()
    assert fixes.fix_quality.tolist() == [0, 0, 0]
    for what in ("GGA in simulator mode (quality 8", "RMC in simulator mode (mode S",
                 "GLL in simulator mode (mode S"):
        assert report.counts[f"{what}, not a measurement)"] == 3


def test_simulator_mode_log_as_gps_input_has_no_usable_fix():
    from gpsdr_cli import config
    from gpsdr_cli.io.readers import read_drive

    drive = read_drive(gps=DATA / "GPSmap-76S.log", params=config.defaults())
    assert len(drive.gnss) == 3 and not drive.gnss.valid.any()
    assert drive.skipped.counts["GGA in simulator mode (quality 8, not a measurement)"] == 3


def _strip_checksums(data: bytes) -> bytes:
    return re.sub(rb"\*[0-9A-F]{2}(?=\r?\n)", b"", data)


def test_sentences_without_checksum_read_like_the_originals():
    # Garmin 48 sentences with every "*hh" removed, as old handhelds and some loggers write
    # them: the same fixes, at gpsd's positions, and counted
    orig = (DATA / "garmin48.log").read_bytes()
    bare = _strip_checksums(orig)
    assert b"*" in bare  # the GSV cut inside its checksum ("*7") stays cut
    t, lat, lon = _expected("garmin48")
    a, ra, ma = _ours(orig, int(t[0]))
    b, rb, mb = _ours(bare, int(t[0]))
    assert ma["sentences_without_checksum"] == 0
    known = len(re.findall(rb"^\$GP(RMC|GGA|GSA|GLL),", bare, re.M))
    assert mb["sentences_without_checksum"] == known == 20
    np.testing.assert_array_equal(a.t_ns, b.t_ns)
    np.testing.assert_array_equal(a.fix_quality, b.fix_quality)
    np.testing.assert_array_equal(a.lat_deg, b.lat_deg)
    np.testing.assert_array_equal(a.lon_deg, b.lon_deg)
    np.testing.assert_array_equal(a.hdop, b.hdop)
    assert "without a checksum" in " ".join(mb["notes"])
    # whole lines of other types: the standard ones the reader does not use (RMB, BOD, RTE,
    # GSV) counted as with their checksums, the proprietary $PGRM... as unknown sentences,
    # and the GSV cut in its checksum is still the one truncated sentence
    n_other = len(re.findall(rb"^\$(?!GP(RMC|GGA|GSA|GLL),)[^*\r\n]*\r?$", bare, re.M))
    not_used = {k: v for k, v in rb.counts.items() if k.startswith("not used:")}
    assert not_used == {k: v for k, v in ra.counts.items() if k.startswith("not used:")}
    assert sum(not_used.values()) == 12
    assert rb.counts["unknown sentence without checksum"] == n_other - 12 == 13
    assert rb.counts["no checksum (truncated sentence)"] == 1
    assert ra.counts["no checksum (truncated sentence)"] == 1


def test_line_cut_short_without_checksum_is_not_a_sentence():
    # a GGA cut after its altitude (logger stopped mid-line): fewer fields than GGA has,
    # so it is a truncated sentence, not one without a checksum
    good = b"$GPGGA,225310,4527.458,S,16709.165,E,1,05,2.1,14.6,M,1.1,M,,\r\n"
    cut = b"$GPGGA,225312,4527.458,S,16709.1\r\n"
    last = b"$GPGGA,225314,4527.458,S,16709.165,E,1,05,2.2,14.6,M,1.1,M,,"  # no line end
    fixes, report, meta = parse_nmea(good + cut + last, date=datetime.date(2001, 6, 6))
    assert meta["sentences_without_checksum"] == 1
    assert report.counts["no checksum (truncated sentence)"] == 2
    assert len(fixes) == 1
    assert fixes.lat_deg[0] == pytest.approx(-45.457633333, abs=TOL_DEG)
    assert fixes.lon_deg[0] == pytest.approx(167.152750000, abs=TOL_DEG)
    assert fixes.alt_m[0] == pytest.approx(14.6 + 1.1)


def test_gpsd_compare_benchmark_on_the_excerpts(tmp_path):
    # the comparison script reads gpsd's .chk format: write one from each expected table
    for name in LOGS:
        (tmp_path / f"{name}.log").write_bytes((DATA / f"{name}.log").read_bytes())
        t, lat, lon = _expected(name)
        rows = [json.dumps({"class": "TPV", "mode": 3,
                            "time": datetime.datetime.fromtimestamp(m / 1000, datetime.UTC)
                            .strftime("%Y-%m-%dT%H:%M:%S.%f")[:-3] + "Z",
                            "lat": la, "lon": lo}) for m, la, lo in zip(t, lat, lon, strict=True)]
        (tmp_path / f"{name}.log.chk").write_text("{\"class\":\"VERSION\"}\n" + "\n".join(rows) + "\n")
    spec = importlib.util.spec_from_file_location("gpsd_compare", REPO / "benchmarks" / "gpsd_compare.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    for name in LOGS:
        row = mod.compare(tmp_path / f"{name}.log", "rank", 60.0)
        assert row["status"] == "ok"
        assert row["matched"] == row["within"] == row["gpsd"] == len(_expected(name)[0])


def test_checksum_less_log_is_recognised_as_nmea(tmp_path):
    # the Humminbird's $IN sentences without their checksums: sniffed as NMEA (its talker
    # is neither $GP nor $GN, so only complete timed sentences can tell)
    from gpsdr_cli.io.nmea import looks_like_nmea
    from gpsdr_cli.io.readers import sniff

    bare = _strip_checksums((DATA / "humminbird-M37.log").read_bytes())
    assert looks_like_nmea(bare[:4096])
    assert not looks_like_nmea(b"$GPGGA,no checksum here\n$GPRMC,nor here\n$GPGGA,x\n")
    p = tmp_path / "m37.log"
    p.write_bytes(bare)
    assert sniff(p) == "nmea"
