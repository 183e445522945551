"""``gpsdr extract``: tables per stream from the comma2k19 sample, against the logs' own text.

The expected values are decoded here from the files' lines (NMEA ddmm.mmmmmm / 60, the
CSV rows), independently of the readers; tolerance 1e-9 deg for positions, 1e-9 s for
times (exact ns for the NMEA centiseconds).
"""

from __future__ import annotations

import io
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from tests.conftest import one_line_error

TOL_DEG = 1e-9


def first_gga(path: Path) -> tuple[int, float, float]:
    """(number of GGA lines with a fix, lat, lon of the first) decoded by hand."""
    ggas = [ln.split(",") for ln in path.read_text().splitlines() if ln[3:6] == "GGA"]
    fixed = [f for f in ggas if f[6] not in ("", "0")]
    f = fixed[0]
    lat = (int(f[2][:2]) + float(f[2][2:]) / 60) * (1 if f[3] == "N" else -1)
    lon = (int(f[4][:3]) + float(f[4][3:]) / 60) * (1 if f[5] == "E" else -1)
    return len(fixed), lat, lon


def test_one_file_per_stream_with_units(gpsdr, sample_dir: Path, tmp_path: Path) -> None:
    out = tmp_path / "drive.parquet"
    result = gpsdr(["extract", sample_dir / "gps.nmea", sample_dir / "gyro.csv",
                    sample_dir / "odo.csv", "-o", out])
    assert result.exit_code == 0, result.output
    assert not out.exists()
    files = {s: tmp_path / f"drive.{s}.parquet" for s in ("gnss", "gyro", "odo")}
    assert all(p.exists() for p in files.values())
    assert not (tmp_path / "drive.accel.parquet").exists()
    n_fix, lat, lon = first_gga(sample_dir / "gps.nmea")
    gnss = pd.read_parquet(files["gnss"])
    assert list(gnss.columns) == ["time", "lat", "lon", "alt", "fix_quality", "n_sats", "hdop",
                                  "pdop", "vdop", "sigma_e", "sigma_n", "speed", "course_deg",
                                  "geometry"]  # GeoParquet: a WKB point per fix
    assert int((gnss.fix_quality > 0).sum()) == n_fix == 579
    assert abs(gnss.lat.iloc[0] - lat) < TOL_DEG and abs(gnss.lon.iloc[0] - lon) < TOL_DEG
    assert gnss.time.iloc[0] == pd.Timestamp("2018-08-02T16:14:48.30", tz="UTC")
    schema = pq.read_schema(files["gnss"])
    assert str(schema.field("time").type) == "timestamp[ns, tz=UTC]"
    assert schema.field("lat").metadata[b"unit"] == b"deg"
    assert schema.field("speed").metadata[b"unit"] == b"m/s"
    assert schema.field("sigma_e").metadata[b"unit"] == b"m"
    # no GST in this log: sigmas are nulls, never NaN
    assert pq.read_table(files["gnss"]).column("sigma_e").null_count == len(gnss)
    gyro_csv = np.loadtxt(sample_dir / "gyro.csv", delimiter=",", skiprows=1)
    gyro = pd.read_parquet(files["gyro"])
    assert len(gyro) == len(gyro_csv) == 6256
    np.testing.assert_allclose(gyro.yaw_rate.to_numpy(), gyro_csv[:, 1], rtol=0, atol=1e-12)
    t = gyro.time.astype("int64").to_numpy() / 1e9
    np.testing.assert_allclose(t, gyro_csv[:, 0], rtol=0, atol=1e-6)  # s: CSV has microseconds
    assert pq.read_schema(files["gyro"]).field("yaw_rate").metadata[b"unit"] == b"rad/s"
    odo = pd.read_parquet(files["odo"])
    assert len(odo) == 4974
    err = result.stderr
    assert "gnss: 579 records" in err and "gyro: 6256 records" in err
    assert "odo: 4974 records" in err and "skipped records: 0" in err


def test_stream_writes_exactly_out_and_stdout_is_csv(gpsdr, sample_dir: Path,
                                                     tmp_path: Path) -> None:
    out = tmp_path / "g.csv"
    result = gpsdr(["extract", sample_dir / "gps.nmea", sample_dir / "gyro.csv",
                    "--stream", "gyro", "-o", out])
    assert result.exit_code == 0, result.output
    assert sorted(p.name for p in tmp_path.iterdir()) == ["g.csv"]
    assert out.read_text().splitlines()[0] == '"time","yaw_rate"'
    piped = gpsdr(["extract", sample_dir / "gps.nmea", "-o", "-"])
    assert piped.exit_code == 0, piped.output
    df = pd.read_csv(io.StringIO(piped.stdout))
    n_fix, lat, lon = first_gga(sample_dir / "gps.nmea")
    assert len(df) == n_fix and abs(df.lat[0] - lat) < TOL_DEG and abs(df.lon[0] - lon) < TOL_DEG
    several = gpsdr(["extract", sample_dir / "gps.nmea", sample_dir / "gyro.csv", "-o", "-"])
    assert several.exit_code == 2 and "give --stream" in one_line_error(several)


def test_skipped_records_are_printed_by_reason(gpsdr, sample_dir: Path, tmp_path: Path) -> None:
    log = tmp_path / "bad.nmea"
    lines = (sample_dir / "gps.nmea").read_text().splitlines(keepends=True)
    lines[1] = lines[1].replace("*57", "*00")  # bad checksum on line 2
    lines.insert(5, "hello\n")  # line 6
    log.write_text("".join(lines))
    result = gpsdr(["extract", log, "-o", tmp_path / "x.parquet"])
    assert result.exit_code == 0, result.output
    assert "skipped records: 2" in result.stderr
    assert f"bad checksum (first: {log}:2)" in result.stderr
    assert f"not a sentence (no $ on the line) (first: {log}:6)" in result.stderr


@pytest.mark.parametrize(("args", "code", "text"), [
    (["-o", "x.json"], 2, "name the output .parquet or .csv"),
    (["--stream", "accel", "-o", "x.parquet"], 1, "no accel stream"),
])
def test_usage_errors(gpsdr, sample_dir: Path, tmp_path: Path, monkeypatch, args, code,
                      text) -> None:
    monkeypatch.chdir(tmp_path)
    result = gpsdr(["extract", sample_dir / "gps.nmea", *args])
    assert result.exit_code == code
    assert text in one_line_error(result)
    assert list(tmp_path.iterdir()) == []


def test_extract_has_help_with_examples(gpsdr) -> None:
    result = gpsdr(["extract", "--help"])
    assert result.exit_code == 0
    assert "Examples:" in result.output and "OUT.gnss.parquet" in result.output
