"""Parquet/CSV writer: round trips, metadata, stdout, and atomicity under a real SIGKILL."""

from __future__ import annotations

import io
import os
import signal
import subprocess
import sys
import textwrap
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpsdr_cli.conventions import TRACK_COLUMNS
from gpsdr_cli.errors import InputError, UsageError
from gpsdr_cli.io.parquet import field_units, read_table_bytes, read_track, write_table

finite = st.floats(allow_nan=False, allow_infinity=False, width=64)


@st.composite
def frames(draw: st.DrawFn) -> pd.DataFrame:
    n = draw(st.integers(0, 40))
    t0 = draw(st.integers(0, 2**62 // 2))
    steps = draw(st.lists(st.integers(1, 10**10), min_size=n, max_size=n))
    t = t0 + np.cumsum(np.array(steps, dtype=np.int64)) if n else np.zeros(0, np.int64)
    cols = {"time": pd.to_datetime(t, unit="ns", utc=True)}
    for name in draw(st.lists(st.sampled_from(["e", "n", "v_e", "sigma_e", "x"]),
                              unique=True, max_size=5)):
        cols[name] = draw(st.lists(finite, min_size=n, max_size=n))
    cols["gnss_used"] = draw(st.lists(st.booleans(), min_size=n, max_size=n))
    cols["count"] = draw(st.lists(st.integers(-2**63, 2**63 - 1), min_size=n, max_size=n))
    df = pd.DataFrame(cols)
    df["time"] = df["time"].astype("datetime64[ns, UTC]")
    df["gnss_used"] = df["gnss_used"].astype(bool)
    df["count"] = df["count"].astype("int64")
    for c in df.columns:
        if c not in ("time", "gnss_used", "count"):
            df[c] = df[c].astype("float64")
    return df


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(df=frames())
def test_parquet_round_trip_is_exact(tmp_path: Path, df: pd.DataFrame) -> None:
    path = tmp_path / "t.parquet"
    write_table(df, path, metadata={"filter": "aekf"}, units={"e": "m, east"})
    back, meta = read_track(path)
    pd.testing.assert_frame_equal(back, df, check_exact=True)
    assert meta == {"filter": "aekf"}


@settings(max_examples=30, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(df=frames())
def test_csv_round_trip_keeps_values(tmp_path: Path, df: pd.DataFrame) -> None:
    path = tmp_path / "t.csv"
    write_table(df, path, fmt="csv")
    back, meta = read_track(path)
    assert meta == {}
    assert list(back.columns) == list(df.columns)
    assert len(back) == len(df)
    if len(df):
        assert (back["time"].astype("int64").to_numpy() == df["time"].astype("int64").to_numpy()).all()
        for c in df.columns:
            if df[c].dtype == "float64":
                # CSV prints the shortest repr that round-trips a double
                np.testing.assert_array_equal(back[c].to_numpy(float), df[c].to_numpy())


def test_units_and_metadata_are_stored(tmp_path: Path) -> None:
    df = pd.DataFrame({"time": pd.to_datetime([1, 2], unit="s", utc=True),
                       "e": [1.0, 2.0], "pdop": [np.nan, 1.8]})
    path = tmp_path / "x.parquet"
    write_table(df, path, metadata={"param.filter.name": "fkf", "frame.origin_lat_deg": "37.7"},
                units={"e": TRACK_COLUMNS["e"], "pdop": TRACK_COLUMNS["pdop"],
                       "time": TRACK_COLUMNS["time"]})
    schema = pq.read_schema(path)
    assert schema.field("e").metadata[b"description"] == TRACK_COLUMNS["e"].encode()
    assert field_units(path) == {"time": "UTC timestamp", "e": "m", "pdop": "dimensionless"}
    assert schema.metadata[b"param.filter.name"] == b"fkf"
    assert str(schema.field("time").type) == "timestamp[ns, tz=UTC]"
    table = pq.read_table(path)
    assert table.column("pdop").null_count == 1  # NaN is written as a Parquet null
    back, meta = read_track(path)
    assert meta["frame.origin_lat_deg"] == "37.7"
    assert np.isnan(back["pdop"].iloc[0])


def test_write_to_stdout_and_read_from_bytes(capfdbinary: pytest.CaptureFixture[bytes]) -> None:
    df = pd.DataFrame({"time": pd.to_datetime([10, 20], unit="s", utc=True), "lat": [1.5, 2.5]})
    write_table(df, "-", metadata={"k": "v"})
    out = capfdbinary.readouterr().out
    assert out[:4] == b"PAR1"
    back, meta = read_table_bytes(out)
    pd.testing.assert_frame_equal(back, df.astype({"time": "datetime64[ns, UTC]"}))
    assert meta == {"k": "v"}
    write_table(df, "-", fmt="csv")
    text = capfdbinary.readouterr().out.decode()
    assert text.splitlines()[0] == '"time","lat"'
    back, _ = read_table_bytes(text.encode())
    assert back["lat"].tolist() == [1.5, 2.5]


def test_errors_are_input_errors(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="no such file"):
        read_track(tmp_path / "missing.parquet")
    empty = tmp_path / "empty.parquet"
    empty.write_bytes(b"")
    with pytest.raises(InputError, match="empty"):
        read_track(empty)
    broken = tmp_path / "broken.parquet"
    broken.write_bytes(b"PAR1" + os.urandom(100))
    with pytest.raises(InputError, match="not a readable Parquet"):
        read_track(broken)
    with pytest.raises(InputError, match="does not exist"):
        write_table(pd.DataFrame({"a": [1]}), tmp_path / "nodir" / "x.parquet")
    with pytest.raises(UsageError):
        write_table(pd.DataFrame({"a": [1]}), tmp_path / "x.xlsx", fmt="xlsx")


def test_failed_write_leaves_old_file_and_no_temp(tmp_path: Path) -> None:
    path = tmp_path / "t.parquet"
    write_table(pd.DataFrame({"a": [1.0]}), path)
    before = path.read_bytes()

    class Boom:
        pass

    bad = pd.DataFrame({"a": [Boom()]})  # pyarrow cannot convert: fails before the rename
    with pytest.raises(Exception):  # noqa: B017 - any pyarrow error will do
        write_table(bad, path)
    assert path.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["t.parquet"]


WRITER = textwrap.dedent("""
    import sys
    import numpy as np, pandas as pd
    from gpsdr_cli.io.parquet import write_table
    n = int(sys.argv[2])
    rng = np.random.default_rng(1)
    df = pd.DataFrame({c: rng.standard_normal(n) for c in "abcdefgh"})
    df["gen"] = 2.0
    print("ready", flush=True)
    while True:
        write_table(df, sys.argv[1], metadata={"gen": "2"})
""")


def test_sigkill_mid_write_leaves_old_or_complete_file(tmp_path: Path) -> None:
    """A REAL kill: a subprocess rewriting a large table is SIGKILLed while its temp file
    is being written; the target must be the old table or a complete new one, never half."""
    target = tmp_path / "track.parquet"
    n_rows = 1_500_000
    old = pd.DataFrame({c: np.zeros(10) for c in "abcdefgh"})
    old["gen"] = 1.0
    write_table(old, target, metadata={"gen": "1"})
    script = tmp_path / "writer.py"
    script.write_text(WRITER)
    proc = subprocess.Popen([sys.executable, str(script), str(target), str(n_rows)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE)
    try:
        assert proc.stdout is not None
        assert proc.stdout.readline().strip() == b"ready"
        deadline = time.monotonic() + 60
        killed_mid_write = False
        while time.monotonic() < deadline:
            temps = [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
            if temps and any(_size(p) > 0 for p in temps):
                os.kill(proc.pid, signal.SIGKILL)
                killed_mid_write = True
                break
            time.sleep(0.001)
        assert killed_mid_write, "the writer never started a temp file"
        proc.wait(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    assert proc.returncode == -signal.SIGKILL
    leftovers = [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]
    assert leftovers, "the kill should have hit a write in progress"
    back, meta = read_track(target)  # must be a whole, readable file
    if meta["gen"] == "1":
        pd.testing.assert_frame_equal(back, old)
    else:
        assert len(back) == n_rows and (back["gen"] == 2.0).all()


def _size(p: Path) -> int:
    try:
        return p.stat().st_size
    except FileNotFoundError:
        return 0


def test_csv_read_from_stdin_like_buffer() -> None:
    buf = io.BytesIO()
    pd.DataFrame({"time": ["2018-08-02T16:14:48Z"], "lat": [37.7]}).to_csv(buf, index=False)
    back, _ = read_table_bytes(buf.getvalue())
    assert str(back["time"].dtype) == "datetime64[ns, UTC]"
    assert back["time"].iloc[0] == pd.Timestamp("2018-08-02T16:14:48Z")
