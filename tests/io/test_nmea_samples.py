"""NMEA reader on real receiver logs.

Small copies live in tests/data/nmea (attribution in ATTRIBUTION.tsv there); the full
collection and the comma2k19 drive are read from ../shared/data when present.
Expected values are hand-decoded from the sentences (ddmm.mmmm / 60); tolerance 1e-9 deg.
"""

from __future__ import annotations

import datetime
from pathlib import Path

import numpy as np
import pytest

from gpsdr_cli.errors import InputError, NoDataError
from gpsdr_cli.io.nmea import looks_like_nmea, parse_nmea, read_nmea

DATA = Path(__file__).parents[1] / "data" / "nmea"
SHARED = Path(__file__).parents[2].parent / "shared" / "data"
SAMPLES = SHARED / "nmea_samples"
SAMPLE_FILES = sorted(p for p in SAMPLES.rglob("*") if p.is_file()
                      and p.suffix in (".log", ".nmea", ".txt")) if SAMPLES.is_dir() else []
LOCAL_FILES = sorted(p for p in DATA.glob("*") if p.suffix in (".log", ".nmea"))

pytestmark = pytest.mark.filterwarnings("error")  # no numpy RuntimeWarning may escape
DEG = 1e-9  # deg, tolerance on decoded positions


def ns(y: int, mo: int, d: int, hh: int, mm: int, ss: float) -> int:
    dt = datetime.datetime(y, mo, d, hh, mm, tzinfo=datetime.UTC)
    return int(dt.timestamp()) * 1_000_000_000 + round(ss * 1e9)


@pytest.mark.parametrize("path", SAMPLE_FILES + LOCAL_FILES, ids=lambda p: p.name)
def test_every_real_file_reads_or_raises_input_error(path: Path) -> None:
    try:
        drive = read_nmea(path, date=None)
    except InputError:
        return
    g = drive.gnss
    assert len(g) > 0
    assert (g.t_ns > 0).all()
    lat = g.lat_deg[g.valid]
    assert ((lat >= -90) & (lat <= 90)).all()
    assert not ((g.lat_deg == 0) & (g.lon_deg == 0)).any()


@pytest.mark.parametrize("path", SAMPLE_FILES + LOCAL_FILES, ids=lambda p: p.name)
def test_every_real_file_with_a_date_reads_or_raises_no_data(path: Path) -> None:
    try:
        read_nmea(path, date=datetime.date(2021, 3, 6))
    except NoDataError:
        pass


def test_comma2k19_579_fixes_10hz_gn() -> None:
    path = SHARED / "comma2k19" / "gps.nmea"
    if not path.exists():
        pytest.skip("../shared/data/comma2k19 not present")
    drive = read_nmea(path)
    g = drive.gnss
    assert len(g) == 579 and g.valid.all()
    assert drive.meta["talkers"] == {"GN": 2316}
    dt = np.diff(g.t_ns)
    assert np.median(dt) == 100_000_000 and dt.min() == 100_000_000  # 10 Hz, holes of 0.2 s
    assert g.t_ns[0] == ns(2018, 8, 2, 16, 14, 48.3)
    assert g.lat_deg[0] == pytest.approx(37 + 43.259862 / 60, abs=DEG)
    assert g.lon_deg[0] == pytest.approx(-(122 + 28.338318 / 60), abs=DEG)
    assert g.alt_m[0] == pytest.approx(33.370, abs=1e-9)
    assert g.speed_mps[0] == pytest.approx(15.207 * 1852 / 3600, abs=1e-9)
    assert (g.pdop == 1.8).all() and (g.vdop == 1.5).all() and (g.hdop == 1.0).all()
    assert drive.skipped.total == 0


def test_comma2k19_fixes_match_the_independent_reference() -> None:
    """Decoded positions against comma2k19's post-processed pose, interpolated to the fix times.

    Bound 3 m: the fixes lead the reference by ~0.1 s at up to 20 m/s (2 m) plus receiver
    error; a wrong hemisphere, ddmm conversion or time base would be off by kilometres.
    """
    import pandas as pd

    path = SHARED / "comma2k19" / "gps.nmea"
    if not path.exists():
        pytest.skip("../shared/data/comma2k19 not present")
    g = read_nmea(path).gnss
    truth = pd.read_csv(SHARED / "comma2k19" / "truth.csv")
    t = g.t_ns / 1e9
    inside = (t >= truth.t.min()) & (t <= truth.t.max())
    lat = np.interp(t, truth.t, truth.lat)
    lon = np.interp(t, truth.t, truth.lon)
    dn = (g.lat_deg - lat) * 111_320.0  # m per deg of latitude (approx.)
    de = (g.lon_deg - lon) * 111_320.0 * np.cos(np.radians(lat))
    err_m = np.hypot(dn, de)[inside]
    assert inside.sum() >= 570
    assert err_m.max() < 3.0  # m


def test_signalk_gps_log_gga_gsa_rmc_vtg_cycle() -> None:
    path = SAMPLES / "signalk" / "text" / "gps.log"
    if not path.exists():
        pytest.skip("../shared/data/nmea_samples not present")
    drive = read_nmea(path)
    g = drive.gnss
    assert len(g) == 1202  # one row per GGA time; the last GGA has no RMC/GSA after it
    assert g.t_ns[0] == ns(2014, 4, 3, 8, 54, 11.0)
    assert g.lat_deg[0] == pytest.approx(52 + 22.3215 / 60, abs=DEG)
    assert g.pdop[0] == pytest.approx(3.11)  # GSA after the GGA joins its epoch
    assert g.speed_mps[0] == pytest.approx(0.58 * 1852 / 3600, abs=1e-9)
    assert np.isfinite(g.pdop[:-1]).all()
    assert dict(drive.skipped.counts) == {"not used: GSV (satellites in view)": 943}


def test_mixed_ubx_binary_and_nmea() -> None:
    drive = read_nmea(DATA / "pygpsdata-mixed.log", date=datetime.date(2021, 3, 6))
    g = drive.gnss
    assert g.t_ns.tolist() == [ns(2021, 3, 6, 10, 41, 13), ns(2021, 3, 6, 10, 41, 14)]
    assert g.lat_deg[0] == pytest.approx(53 + 27.03557 / 60, abs=DEG)
    assert g.lon_deg[0] == pytest.approx(-(2 + 14.42234 / 60), abs=DEG)
    assert g.alt_m[0] == pytest.approx(65.4 + 48.5)
    assert g.pdop.tolist() == [12.55, 12.55] and g.vdop.tolist() == [9.07, 9.06]  # 4 GSAs merged
    assert drive.skipped.counts["not used: GSV (satellites in view)"] == 5
    assert drive.meta["date_source"] == "argument"
    with pytest.raises(NoDataError, match="--date"):
        read_nmea(DATA / "pygpsdata-mixed.log")


def test_lower_case_checksums_nmea41_rmc_and_zda() -> None:
    drive = read_nmea(DATA / "pygpsdata-nmea4lc.log")
    g = drive.gnss
    assert g.t_ns.tolist() == [ns(2021, 3, 6, 10, 36, 7)]
    assert g.lon_deg[0] == pytest.approx(-(102 + 14.42462 / 60), abs=DEG)
    assert "bad checksum" not in drive.skipped.counts


def test_bad_checksums_counted() -> None:
    drive = read_nmea(DATA / "pygpsdata-nmeabadck.log")
    assert drive.skipped.counts["bad checksum"] == 2
    assert drive.skipped.first["bad checksum"].endswith("pygpsdata-nmeabadck.log:1")
    assert len(drive.gnss) == 1


def test_a_log_whose_every_checksum_is_wrong_says_so(tmp_path: Path) -> None:
    """A program that writes every checksum wrongly: one error line that says what to do."""
    good = (DATA / "pygpsdata-nmea4lc.log").read_text().splitlines()
    bad = [ln[:-2] + ("00" if ln[-2:].upper() != "00" else "11") for ln in good if "*" in ln]
    f = tmp_path / "wrong.nmea"
    f.write_text("\n".join(bad) + "\n")
    with pytest.raises(NoDataError) as err:
        read_nmea(f)
    msg = str(err.value)
    assert f"{len(bad)} bad checksum" in msg and "every checksum is wrong" in msg
    assert "recompute each *hh as the XOR" in msg


def test_malformed_checksum_hex_is_no_checksum() -> None:
    drive = read_nmea(DATA / "pygpsdata-nmeabadck2.log")  # "*3)" on line 2
    assert drive.skipped.first["no checksum (truncated sentence)"].endswith(":2")
    assert drive.gnss.valid.all() and len(drive.gnss) == 1


def test_truncated_at_eof() -> None:
    drive = read_nmea(DATA / "pygpsdata-badeof.log")  # ends with a lone "$"
    assert drive.skipped.counts["no checksum (truncated sentence)"] == 1
    assert drive.gnss.lat_deg[0] == pytest.approx(53 + 27.03942 / 60, abs=DEG)


def test_bad_field_with_valid_checksum_blanks_the_field() -> None:
    drive = read_nmea(DATA / "pygpsdata-nmeafoo2.log")  # RMC speed "X.138"
    assert drive.skipped.counts["malformed speed in RMC (field ignored)"] == 1
    assert drive.skipped.counts["unknown sentence FOO"] == 1
    g = drive.gnss
    assert g.valid.all() and g.speed_mps[0] == pytest.approx(0.138 * 1852 / 3600, abs=1e-9)  # VTG


def test_startup_empty_fields_no_time() -> None:
    with pytest.raises(NoDataError, match="no GGA, GNS, RMC or GLL sentence with a time"):
        read_nmea(DATA / "pygpsdata-nmeastartup.log")


def test_um981_nmea41_rmc_with_nav_status() -> None:
    g = read_nmea(DATA / "pygpsdata-um981.log").gnss
    assert g.t_ns.tolist() == [ns(2026, 2, 24, 13, 0, 58), ns(2026, 2, 24, 13, 0, 59)]
    assert g.lat_deg[0] == pytest.approx(53 + 27.03598945 / 60, abs=DEG)
    assert g.alt_m[0] == pytest.approx(36.3017 + 51.6775, abs=1e-9)


def test_six_letter_addresses_are_unknown() -> None:
    """Unicore's GGAH, RMCH ... (a dual-antenna receiver's secondary antenna) are not the
    vehicle's position: a log of nothing else is an error that says so, and not one about
    checksums (every checksum in it is right); other six-letter addresses are unknown."""
    data = (DATA / "unicore_nmea.log").read_bytes()
    with pytest.raises(NoDataError) as err:
        parse_nmea(data, name="unicore_nmea.log")
    assert "secondary antenna" in str(err.value)
    assert "checksum" not in str(err.value)
    from tests.io.test_nmea import ck

    extra = (ck("GPABCDE,1,2") + "\r\n").encode()
    with pytest.raises(NoDataError) as err:
        parse_nmea(extra, name="x.nmea")
    assert "six-letter address" in str(err.value)


def test_pynmea2_example_log_needs_date() -> None:
    drive = read_nmea(DATA / "data.log", date=datetime.date(2020, 1, 2))
    g = drive.gnss
    assert g.t_ns.tolist() == [ns(2020, 1, 2, 18, 43, 53.07)]
    assert g.lat_deg[0] == pytest.approx(-(19 + 29.045 / 60), abs=DEG)
    assert g.alt_m[0] == pytest.approx(100.0 - 33.9)
    assert drive.skipped.counts["not a sentence (no $ on the line)"] == 1  # "foobar"


def test_numeric_talkers_and_ais_only_logs() -> None:
    n2k = SAMPLES / "signalk" / "text" / "n2kd-183-merrimac.log"
    ais = SAMPLES / "signalk" / "text" / "nais300-merrimac.log"
    if not n2k.exists():
        pytest.skip("../shared/data/nmea_samples not present")
    with pytest.raises(NoDataError, match="numeric talker"):
        read_nmea(n2k)
    drive = read_nmea(ais)
    assert drive.skipped.counts["unknown sentence (encapsulated !AIVDM, e.g. AIS)"] == 417
    assert len(drive.gnss) == 10


def test_pynmea2_sentence_literals() -> None:
    path = SAMPLES / "pynmea2" / "text" / "test_sentences.nmea"
    if not path.exists():
        pytest.skip("../shared/data/nmea_samples not present")
    drive = read_nmea(path)
    assert drive.skipped.counts["unknown sentence (proprietary $P...)"] >= 40
    assert drive.meta["warning_counts"] == {"suspicious date": 2}  # 1994 dates of the NMEA textbook
    assert (drive.gnss.fix_quality >= 0).all()


def test_sniffer_on_real_files() -> None:
    assert looks_like_nmea((DATA / "pygpsdata-um981.log").read_bytes()[:1024])
    assert looks_like_nmea((DATA / "pygpsdata-mixed.log").read_bytes()[:2048][-1024:])
    assert not looks_like_nmea((DATA / "ATTRIBUTION.tsv").read_bytes()[:1024])
    assert looks_like_nmea((DATA / "pygpsdata-nmeabadck.log").read_bytes())  # 1 of 3 valid
