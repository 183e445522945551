"""Reference trajectories from CSV, NMEA and a track Parquet."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pyarrow as pa
import pyarrow.parquet as pq
import pytest

from gpsdr_cli.errors import InputError, NoDataError
from gpsdr_cli.io.reference import Reference, read_reference

DRIVE = Path(__file__).resolve().parents[3] / "shared" / "data" / "comma2k19"
MCAP = Path(__file__).resolve().parents[1] / "data" / "mcap" / "small_drive.mcap"


def test_comma2k19_truth_csv():
    r = read_reference(DRIVE / "truth.csv")
    assert isinstance(r, Reference) and len(r) == 1200
    assert r.t_ns[0] == 1533226488_397000000 and r.t_ns[-1] == 1533226548_346000000
    assert r.lat_deg[0] == 37.721000009 and r.lon_deg[0] == -122.472299089 and r.alt_m[0] == 31.639
    assert np.all(np.diff(r.t_ns) > 0) and r.skipped.total == 0
    assert r.source == str(DRIVE / "truth.csv") and len(r.sha256) == 64


def test_nmea_reference_takes_valid_fixes():
    r = read_reference(DRIVE / "gps.nmea")
    assert len(r) == 579
    # the u-blox fixes lie on the same road as the truth: within 0.001 deg of its box
    truth = read_reference(DRIVE / "truth.csv")
    assert truth.lat_deg.min() - 1e-3 < r.lat_deg.min() and r.lat_deg.max() < truth.lat_deg.max() + 1e-3


def test_csv_without_alt_unsorted_duplicates_and_bad_rows(tmp_path):
    p = tmp_path / "ref.csv"
    p.write_text("time,lat,lon\n10,1.0,2.0\n5,0.5,1.5\n10,9.0,9.0\n7,95.0,1.0\n8,x,1\n")
    r = read_reference(p)
    np.testing.assert_array_equal(r.t_ns, [5 * 10**9, 10 * 10**9])
    np.testing.assert_array_equal(r.lat_deg, [0.5, 1.0])  # the first of the duplicate times wins
    assert np.isnan(r.alt_m).all()
    assert r.skipped.counts["reference row with a duplicate time (dropped)"] == 1
    assert r.skipped.counts["reference row with missing or out-of-range lat/lon"] == 1
    assert r.skipped.first["missing, non-numeric or non-finite value"] == f"{p}:6"


@pytest.mark.parametrize("time_type", ["timestamp", "int64", "posix_t"])
def test_track_parquet(tmp_path, time_type):
    t_ns = 1_700_000_000_000_000_000 + np.arange(5, dtype=np.int64) * 100_000_000
    cols = {"lat": np.linspace(54, 54.001, 5), "lon": np.linspace(18, 18.002, 5), "alt": np.full(5, 3.0)}
    if time_type == "timestamp":
        cols = {"time": pa.array(t_ns, pa.timestamp("ns", tz="UTC")), **cols}
    elif time_type == "int64":
        cols = {"time": t_ns, **cols}
    else:
        cols = {"t": t_ns / 1e9, **cols}
    p = tmp_path / "track.parquet"
    pq.write_table(pa.table(cols), p)
    r = read_reference(p)
    np.testing.assert_array_equal(r.t_ns, t_ns)
    np.testing.assert_array_equal(r.lon_deg, np.linspace(18, 18.002, 5))
    np.testing.assert_array_equal(r.alt_m, 3.0)


def test_errors(tmp_path):
    p = tmp_path / "ref.csv"
    p.write_text("t,latitude,longitude\n1,2,3\n")
    with pytest.raises(InputError, match=r"no column 'lat' \(columns found: t, latitude, longitude\)"):
        read_reference(p)
    p.write_text("t,lat,lon\n1,nan,3\n")
    with pytest.raises(NoDataError, match="no usable reference rows"):
        read_reference(p)
    q = tmp_path / "t.parquet"
    pq.write_table(pa.table({"x": [1.0]}), q)
    with pytest.raises(InputError, match="no column 'lat'"):
        read_reference(q)
    with pytest.raises(InputError, match="cannot be a reference"):
        read_reference(MCAP)
    e = tmp_path / "empty.csv"
    e.write_bytes(b"")
    with pytest.raises(InputError, match="empty file"):
        read_reference(e)
