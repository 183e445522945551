"""Format sniffing, read_drive dispatch and merging, sha256_file."""

from __future__ import annotations

import hashlib
import io
import sys
from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from gpsdr_cli import config
from gpsdr_cli.errors import InputError, NoDataError, UsageError
from gpsdr_cli.io.readers import read_drive, sha256_file, sniff

DRIVE = Path(__file__).resolve().parents[3] / "shared" / "data" / "comma2k19"
REAL_MCAP = DRIVE.parent / "mcap_samples" / "ublox_gps_ros2.mcap"
SMALL_MCAP = Path(__file__).resolve().parents[1] / "data" / "mcap" / "small_drive.mcap"
P = config.defaults()


@pytest.mark.parametrize("path, kind", [
    (DRIVE / "gps.nmea", "nmea"), (DRIVE / "gyro.csv", "csv"), (DRIVE / "truth.csv", "csv"),
    (REAL_MCAP, "mcap"), (SMALL_MCAP, "mcap"),
])
def test_sniff_real_files(path, kind):
    assert sniff(path) == kind


def test_sniff_by_content_not_name(tmp_path):
    p = tmp_path / "track.csv"
    pq.write_table(pa.table({"time": [1]}), p)
    assert sniff(p) == "parquet"
    noisy = tmp_path / "ubx_and_nmea.log"  # 3 KB of binary (UBX-like) before the sentences
    noisy.write_bytes(bytes(range(256)) * 12 + (DRIVE / "gps.nmea").read_bytes()[:3000])
    assert sniff(noisy) == "nmea"
    q = tmp_path / "log.txt"
    q.write_bytes(b"12:00:01 " + (DRIVE / "gps.nmea").read_bytes()[:2000])  # logger prefix
    assert sniff(q) == "nmea"


def test_sentences_without_checksums_are_read_as_nmea_and_named(tmp_path):
    # gpsd's skytraq-err.log: a '#' header, then a receiver's firmware-loader messages in
    # sentence form without checksums: the NMEA reader's error says what it found there,
    # not "unrecognised format"
    p = tmp_path / "skytraq.log"
    p.write_bytes(b"# Name: skytraq\n#\n" + b"$STI,IC,error=4\n" * 3 + b"$STI,IC,error=6\n")
    assert sniff(p) == "nmea"
    with pytest.raises(NoDataError, match="4 unknown sentence without checksum"):
        read_drive(p, params=P)


@pytest.mark.parametrize("content, match", [
    (b"", "empty file"),
    ("$GPGGA,1\n".encode("utf-16"), "UTF-16"),
    (bytes(range(256)) * 4, "binary"),
    (b"just some words\nand more\n", "unrecognised format"),
])
def test_sniff_rejects(tmp_path, content, match):
    p = tmp_path / "f.log"
    p.write_bytes(content)
    with pytest.raises(InputError, match=match) as err:
        sniff(p)
    assert str(p) in str(err.value)
    with pytest.raises(InputError):
        read_drive(p, params=P)


def _novatel_ascii(start: str, message: str, header: str, data: str) -> bytes:
    """One NovAtel ASCII message with its CRC-32 (reflected 0xEDB88320, initial 0)."""
    body = f"{message},{header};{data}".encode()
    crc = 0
    for byte in body:
        crc ^= byte
        for _ in range(8):
            crc = (crc >> 1) ^ 0xEDB88320 if crc & 1 else crc >> 1
    return start.encode() + body + b"*%08x\r\n" % crc


@pytest.mark.parametrize("line", [
    _novatel_ascii("#", "BESTPOSA", "COM1,0,80.0,FINESTEERING,2300,345600.000,02000000,b1f6,16809",
                   'SOL_COMPUTED,SINGLE,51.11678928,-114.03886216,1064.3,-16.2,WGS84,1.5,1.2,'
                   '2.9,"",0.000,0.000,20,18,18,18,00,06,39,33'),
    _novatel_ascii("%", "INSPVASA", "2300,345600.000",
                   "2300,345600.000,51.11678928,-114.03886216,1064.3,0.1,0.2,0.0,1.5,-0.4,"
                   "90.2,INS_SOLUTION_GOOD"),
])
def test_novatel_ascii_log_is_named_not_taken_for_csv(tmp_path, line):
    p = tmp_path / "novatel.asc"
    p.write_bytes(line * 3)
    name = line[1:].split(b",", 1)[0].decode()
    with pytest.raises(InputError, match=rf"NovAtel ASCII log \({name} messages\) is not "
                                         "supported") as err:
        read_drive(gps=p, params=P)
    assert str(p) in str(err.value) and "CSV" not in str(err.value)
    assert "\n" not in str(err.value)


def test_sniff_missing_file(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        sniff(tmp_path / "nope.mcap")


def test_read_drive_separate_files():
    d = read_drive(gps=DRIVE / "gps.nmea", gyro=DRIVE / "gyro.csv", odo=DRIVE / "odo.csv", params=P)
    assert (len(d.gnss), len(d.gyro), len(d.odo)) == (579, 6256, 4974)
    assert [s.streams for s in d.sources] == [("gnss",), ("gyro",), ("odo",)]
    assert d.sources[1].sha256 == sha256_file(DRIVE / "gyro.csv")


def test_read_drive_mcap_log_and_override_precedence():
    d = read_drive(SMALL_MCAP, params=P)
    assert (len(d.gnss), len(d.gyro), len(d.odo)) == (20, 100, 100)
    # an explicit --gyro replaces the LOG's gyro; the LOG's GNSS and odometer stay
    d = read_drive(SMALL_MCAP, gyro=DRIVE / "gyro.csv", params=P)
    assert len(d.gyro) == 6256 and len(d.gnss) == 20 and len(d.odo) == 100
    assert [Path(s.path).name for s in d.sources] == ["gyro.csv", "small_drive.mcap"]
    assert [s.streams for s in d.sources] == [("gyro",), ("gnss", "odo")]


def test_read_drive_real_mcap_keeps_warnings():
    d = read_drive(REAL_MCAP, params=P)
    assert len(d.gnss) == 3364 and d.gyro is None
    assert any("navheading" in w for w in d.meta["warnings"])


def test_read_drive_mcap_for_one_stream():
    d = read_drive(gps=DRIVE / "gps.nmea", odo=SMALL_MCAP, params=P)
    assert len(d.gnss) == 579 and len(d.odo) == 100 and d.gyro is None
    d = read_drive(gps=SMALL_MCAP, gyro=DRIVE / "gyro.csv", params=P)
    assert len(d.gnss) == 20 and len(d.gyro) == 6256 and d.odo is None
    assert d.sources[0].streams == ("gnss",)
    with pytest.raises(NoDataError, match="no gyro messages"):
        read_drive(gyro=REAL_MCAP, params=P)


def test_gps_from_stdin(monkeypatch):
    data = (DRIVE / "gps.nmea").read_bytes()
    monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data)))
    d = read_drive(gps="-", params=P)
    assert len(d.gnss) == 579 and d.sources[0].sha256 == hashlib.sha256(data).hexdigest()


def test_read_drive_usage_errors(tmp_path):
    with pytest.raises(UsageError, match="no input"):
        read_drive(params=P)
    with pytest.raises(UsageError, match="cannot be the LOG"):
        read_drive(DRIVE / "gyro.csv", params=P)


def test_sha256_file(tmp_path):
    p = tmp_path / "b.bin"
    data = np.random.default_rng(1).bytes(3 << 20)
    p.write_bytes(data)
    assert sha256_file(p) == hashlib.sha256(data).hexdigest()
    with pytest.raises(InputError):
        sha256_file(tmp_path / "missing")


def test_sniffing_text_logs_does_not_load_numba(tmp_path: Path) -> None:
    """The UBX check imports its compiled reader only for a head with UBX sync bytes, so
    ``gpsdr info`` on CSV or NMEA files does not pay numba's start-up."""
    import os
    import subprocess

    csv = tmp_path / "gyro.csv"
    csv.write_text("t,yaw_rate\n1700000000.0,0.1\n1700000000.01,0.2\n")
    nmea = tmp_path / "gps.nmea"
    nmea.write_text("$GPGGA,120000.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*5C\r\n" * 3)
    code = ("import sys; from gpsdr_cli.io.readers import sniff; "
            f"kinds = [sniff({str(csv)!r}), sniff({str(nmea)!r})]; "
            "print(kinds, 'numba' in sys.modules)")
    root = Path(__file__).resolve().parents[2]
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True,
                         env={**os.environ, "PYTHONPATH": str(root)}).stdout
    assert out.strip() == "['csv', 'nmea'] False"


def test_impossible_dead_reckoning_readings_are_skipped_and_counted(tmp_path):
    """A corrupt number is no motion: an odometer speed of 1e308 m/s once made every later
    position infinite (found by the fuzzer).  Readings beyond the physical limits are left
    out and counted, with the file and record."""
    odo = tmp_path / "odo.csv"
    odo.write_text("t,speed\n" + "".join(
        f"{1715673600 + 0.1 * i:.1f},{v}\n"
        for i, v in enumerate([0.0, 1.0, 1e308, 2.0, -253409.0, 3.0, float("nan"), 4.0])))
    gyro = tmp_path / "gyro.csv"
    gyro.write_text("t,yaw_rate\n" + "".join(
        f"{1715673600 + 0.1 * i:.1f},{v}\n" for i, v in enumerate([0.01, 60.0, -0.02, 0.03])))
    d = read_drive(gyro=gyro, odo=odo, params=config.defaults())
    assert d.odo.speed_mps.tolist() == [0.0, 1.0, 2.0, 3.0, 4.0]   # the NaN row: the CSV reader's
    assert np.array_equal(d.gyro.yaw_rate_radps, [0.01, -0.02, 0.03])
    assert d.skipped.counts["odo: reading beyond 150 m/s"] == 2
    assert d.skipped.first["odo: reading beyond 150 m/s"].endswith("odo record 3")
    assert d.skipped.counts["gyro: reading beyond 50 rad/s"] == 1
    assert any("2 of 7 odo readings beyond 150 m/s" in w for w in d.meta["warnings"])
