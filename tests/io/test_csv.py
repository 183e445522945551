"""Gyro and odometer CSV readers: real comma2k19 files, units/signs/kinds, exact
times, corrupt rows counted with line numbers, and clear errors."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from gpsdr_cli import config
from gpsdr_cli.errors import ConfigError, InputError, NoDataError, UsageError
from gpsdr_cli.io.csv import read_gyro_csv, read_odo_csv

DRIVE = Path(__file__).resolve().parents[2] / "sample_logs" / "comma2k19"
P = config.defaults()


def _csv(tmp_path: Path, text: str | bytes, name: str = "x.csv") -> Path:
    p = tmp_path / name
    p.write_bytes(text.encode() if isinstance(text, str) else text)
    return p


def _opts(section: str, **kw) -> dict:
    return {**P[section], **kw}


def test_real_gyro_and_odo_files():
    g = read_gyro_csv(DRIVE / "gyro.csv", P["gyro"])
    assert len(g.gyro) == 6256 and g.skipped.total == 0
    # exact decimal -> ns, no float quantisation: "1533226488.429536"
    assert g.gyro.t_ns[0] == 1533226488_429536000
    assert g.gyro.yaw_rate_radps[0] == -0.0037231
    assert g.meta["gyro_csv"]["parser"] == "pyarrow"
    assert g.sources[0].streams == ("gyro",) and len(g.sources[0].sha256) == 64
    o = read_odo_csv(DRIVE / "odo.csv", P["odo"])
    assert len(o.odo) == 4974 and o.odo.t_ns[0] == 1533226488_439005000
    assert o.odo.speed_mps[0] == 7.97431 and o.meta["odo_csv"]["kind"] == "speed"
    # 60 s drive at 1012 m: mean speed about 16.9 m/s
    dur = (o.odo.t_ns[-1] - o.odo.t_ns[0]) / 1e9
    assert np.mean(o.odo.speed_mps) * dur == pytest.approx(1012, rel=0.05)


def test_units_and_sign_options(tmp_path):
    p = _csv(tmp_path, "time,rate_dps\n1700000000.0,90\n1700000000.01,-45\n")
    d = read_gyro_csv(p, _opts("gyro", t_column="time", column="rate_dps", units="deg/s", sign="cw"))
    np.testing.assert_allclose(d.gyro.yaw_rate_radps, [-math.pi / 2, math.pi / 4], rtol=1e-15)
    d = read_gyro_csv(p, _opts("gyro", t_column="time", column="rate_dps"))
    np.testing.assert_array_equal(d.gyro.yaw_rate_radps, [90.0, -45.0])
    with pytest.raises(ConfigError, match=r"gyro.units = 'rpm'"):
        read_gyro_csv(p, _opts("gyro", t_column="time", column="rate_dps", units="rpm"))


def test_relative_time_and_rounding(tmp_path):
    # 1.5 ns rounds half-to-even to 2 ns, 2.5 ns to 2 ns; > 9 decimals takes the slow path.
    p = _csv(tmp_path, "t,yaw_rate\n0.0000000015,1\n0.0000000025,2\n10.25,3\n")
    d = read_gyro_csv(p, _opts("gyro", time="relative", start_posix_s=1533226488.4))
    np.testing.assert_array_equal(d.gyro.t_ns - 1533226488_400000000, [2, 2, 10_250_000_000])
    assert d.meta["gyro_csv"]["parser"] == "line-by-line"
    # Relative seconds read as POSIX: a warning, not silence.
    d = read_gyro_csv(p, P["gyro"])
    assert "relative" in d.meta["warnings"][0]


def test_exact_ns_beats_float(tmp_path):
    # float64(1700000000.123456789) * 1e9 is off by ~100 ns; the decimal path is exact.
    p = _csv(tmp_path, "t,yaw_rate\n1700000000.123456789,0\n1700000000.000000001,0\n")
    d = read_gyro_csv(p, P["gyro"])
    np.testing.assert_array_equal(d.gyro.t_ns, [1700000000_123456789, 1700000000_000000001])


@pytest.mark.parametrize("kind, header, rows, expected", [
    ("speed", "t,speed", [(0.0, 1.0), (0.1, 2.0), (0.3, 3.0)], [1.0, 2.0, 3.0]),
    ("distance", "t,distance", [(0.0, 5.0), (0.1, 1.0), (0.3, 3.0)], [10.0, 15.0]),
    ("ticks", "t,ticks", [(0.0, 100), (0.5, 150), (1.0, 250)], [2.0, 4.0]),
])
def test_odometer_kinds_and_auto(tmp_path, kind, header, rows, expected):
    t0 = 1_700_000_000
    text = header + "\n" + "".join(f"{t0 + t},{v}\n" for t, v in rows)
    p = _csv(tmp_path, text)
    for k in ("auto", kind):
        d = read_odo_csv(p, _opts("odo", kind=k, ticks_per_m=50.0))
        np.testing.assert_allclose(d.odo.speed_mps, expected, rtol=1e-12)
        assert d.meta["odo_csv"]["kind"] == kind
        if kind != "speed":
            assert d.skipped.counts[f"first row of a {kind} odometer (no previous row)"] == 1
            assert d.odo.t_ns[0] == (t0 + rows[1][0]) * 10**9


def test_ticks_need_ticks_per_m(tmp_path):
    p = _csv(tmp_path, "t,ticks\n1700000000,1\n1700000001,2\n")
    with pytest.raises(UsageError, match="ticks_per_m"):
        read_odo_csv(p, P["odo"])


def test_odo_column_option_and_missing_kind(tmp_path):
    p = _csv(tmp_path, "t,v_wheel\n1700000000,1\n1700000001,2\n")
    with pytest.raises(InputError, match=r"no speed, distance or ticks column \(columns found: t, v_wheel\)"):
        read_odo_csv(p, P["odo"])
    d = read_odo_csv(p, _opts("odo", kind="speed", column="v_wheel"))
    np.testing.assert_array_equal(d.odo.speed_mps, [1.0, 2.0])


def test_corrupt_rows_skipped_and_counted_with_first_line(tmp_path):
    rows = ["t,yaw_rate"] + [f"{1700000000 + i / 10:.1f},{i}" for i in range(10)]
    rows[3] = "1700000000.2,abc"       # line 4: non-numeric
    rows[5] = "1700000000.4,1,2"       # line 6: wrong field count
    rows[6] = ""                       # line 7: empty
    rows[8] = "1700000000.7,"          # line 9: missing value
    rows[9] = "1700000000.8,nan"       # line 10: non-finite
    p = _csv(tmp_path, "\n".join(rows) + "\n")
    d = read_gyro_csv(p, P["gyro"])
    np.testing.assert_array_equal(d.gyro.yaw_rate_radps, [0, 1, 3, 6, 9])
    c, first = d.skipped.counts, d.skipped.first
    assert c["missing, non-numeric or non-finite value"] == 3
    assert first["missing, non-numeric or non-finite value"] == f"{p}:4"
    assert c["wrong field count (expected 2)"] == 1 and first["wrong field count (expected 2)"] == f"{p}:6"
    assert c["empty line"] == 1 and first["empty line"] == f"{p}:7"
    assert d.meta["gyro_csv"]["parser"] == "line-by-line"


def test_fast_path_skips_blank_values_with_line_numbers(tmp_path):
    # Empty values and blank lines do not stop pyarrow: still counted, same line numbers.
    p = _csv(tmp_path, "t,yaw_rate\n1700000000,1\n\n1700000001,\n1700000002,3\n")
    d = read_gyro_csv(p, P["gyro"])
    assert d.meta["gyro_csv"]["parser"] == "pyarrow"
    np.testing.assert_array_equal(d.gyro.yaw_rate_radps, [1, 3])
    assert d.skipped.first == {"empty line": f"{p}:3",
                               "missing, non-numeric or non-finite value": f"{p}:4"}


def test_fast_and_slow_paths_agree(tmp_path):
    rng = np.random.default_rng(0)
    t = 1_700_000_000 + np.cumsum(rng.uniform(0.005, 0.015, 2000))
    v = rng.normal(0, 0.1, 2000)
    lines = ["t,yaw_rate"] + [f"{a:.6f},{float(b)!r}" for a, b in zip(t, v, strict=True)]
    clean = _csv(tmp_path, "\n".join(lines) + "\n", "clean.csv")
    dirty = _csv(tmp_path, "\n".join(lines[:500] + ["garbage"] + lines[500:]) + "\n", "dirty.csv")
    a = read_gyro_csv(clean, P["gyro"])
    b = read_gyro_csv(dirty, P["gyro"])
    assert (a.meta["gyro_csv"]["parser"], b.meta["gyro_csv"]["parser"]) == ("pyarrow", "line-by-line")
    np.testing.assert_array_equal(a.gyro.t_ns, b.gyro.t_ns)
    np.testing.assert_array_equal(a.gyro.yaw_rate_radps, b.gyro.yaw_rate_radps)
    np.testing.assert_array_equal(a.gyro.yaw_rate_radps, v)
    assert b.skipped.first == {"wrong field count (expected 2)": f"{dirty}:501"}


def test_header_variants(tmp_path):
    p = _csv(tmp_path, b"\xef\xbb\xbf \"t\" ; yaw_rate \r\n1700000000;0.5\r\n1700000001;0.25\r\n")
    d = read_gyro_csv(p, P["gyro"])
    np.testing.assert_array_equal(d.gyro.yaw_rate_radps, [0.5, 0.25])
    assert d.meta["gyro_csv"]["delimiter"] == ";"


def test_missing_column_names_file_columns_and_option(tmp_path):
    p = _csv(tmp_path, "time,yaw\n1,2\n")
    with pytest.raises(InputError) as err:
        read_gyro_csv(p, P["gyro"])
    msg = str(err.value)
    assert str(p) in msg and "columns found: time, yaw" in msg and "gyro.t_column" in msg
    with pytest.raises(InputError, match="gyro.column"):
        read_gyro_csv(p, _opts("gyro", t_column="time"))


@pytest.mark.parametrize("content, match", [
    (b"", "empty file"),
    ("t,yaw_rate\n1,2\n".encode("utf-16"), "UTF-16"),
    ("t,yaw_rate\n1,2\n".encode("utf-16-le"), "UTF-16"),
    (b"\x00\x01\x02\x03binary\xff\xfe\x00", "binary"),
    (b"1700000000,0.1\n1700000001,0.2\n", "no header row"),
    (b"t,yaw_rate\n", "no usable gyro rows"),
    (b"t,yaw_rate\nx,y\n", "no usable gyro rows"),
    (b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n", "looks like an NMEA log"),
    (b"\x89MCAP0\r\n\x01", "is an MCAP log"),
    (b"PAR1\x00\x00", "is a Parquet file"),
])
def test_bad_files_are_one_clear_input_error(tmp_path, content, match):
    p = _csv(tmp_path, content)
    with pytest.raises(InputError, match=match) as err:
        read_gyro_csv(p, P["gyro"])
    assert str(err.value).startswith(str(p))
    assert "\n" not in str(err.value)


def test_no_data_is_no_data_error(tmp_path):
    p = _csv(tmp_path, "t,distance\n1700000000,1\n")
    with pytest.raises(NoDataError, match="first row of a distance odometer"):
        read_odo_csv(p, P["odo"])


def test_unreadable_paths(tmp_path):
    with pytest.raises(InputError, match="no such file"):
        read_gyro_csv(tmp_path / "missing.csv", P["gyro"])
    with pytest.raises(InputError, match="is a directory"):
        read_gyro_csv(tmp_path, P["gyro"])


def test_lone_cr_newlines_both_paths(tmp_path):
    p = _csv(tmp_path, "t,yaw_rate\r1700000000,1\r1700000001,2\r")
    np.testing.assert_array_equal(read_gyro_csv(p, P["gyro"]).gyro.yaw_rate_radps, [1, 2])
    p = _csv(tmp_path, "t,yaw_rate\r1700000000,1\rbad\r1700000001,2\r")
    d = read_gyro_csv(p, P["gyro"])
    np.testing.assert_array_equal(d.gyro.yaw_rate_radps, [1, 2])
    assert d.skipped.first == {"wrong field count (expected 2)": f"{p}:3"}


@pytest.mark.parametrize("t_text", ["1533226488429", "1533226488429536000", "1533226488429536000000"])
def test_millisecond_or_nanosecond_stamps_are_named(tmp_path, t_text):
    p = _csv(tmp_path, f"t,yaw_rate\n{t_text},0.1\n")
    expected = r"time beyond year 2262 \(expected seconds, not ms/us/ns\) at .*:2"
    with pytest.raises(NoDataError, match=expected):
        read_gyro_csv(p, P["gyro"])


def test_distance_after_a_skipped_line_is_dropped_ticks_are_not(tmp_path):
    t0 = 1_700_000_000
    d = read_odo_csv(_csv(tmp_path, f"t,distance\n{t0},0\n{t0 + 1},2\n{t0 + 2},x\n{t0 + 3},2\n{t0 + 4},4\n"),
                     P["odo"])
    np.testing.assert_array_equal(d.odo.speed_mps, [2.0, 4.0])  # the row after line 4 is dropped
    assert d.skipped.first["distance row after a skipped line (interval unknown)"].endswith(":5")
    k = read_odo_csv(_csv(tmp_path, f"t,ticks\n{t0},0\n{t0 + 1},20\n{t0 + 2},x\n{t0 + 3},60\n",
                          "k.csv"), _opts("odo", ticks_per_m=10.0))
    np.testing.assert_array_equal(k.odo.speed_mps, [2.0, 2.0])  # 40 ticks over 2 s


def test_cumulative_distance_column_is_read_as_the_running_total(tmp_path):
    """A distance column that is the odometer's total (50 Hz, 4-decimal times, 12.5 m/s with
    a 2 s stop, 30 km on the clock): speed = its step / dt, with a warning; per-row
    distances of the same drive read as before."""
    t0 = 1_700_000_000
    t = t0 + np.arange(500) * 0.02
    v_true = np.where((np.arange(499) >= 200) & (np.arange(499) < 300), 0.0, 12.5)
    total = 30_000.0 + np.concatenate([[0.0], np.cumsum(v_true * 0.02)])
    rows = "".join(f"{a:.4f},{b:.5f}\n" for a, b in zip(t, total, strict=True))
    d = read_odo_csv(_csv(tmp_path, "t,distance\n" + rows), P["odo"])
    np.testing.assert_allclose(d.odo.speed_mps, v_true, atol=1e-6)
    assert d.meta["odo_csv"]["kind"] == "distance (cumulative)"
    assert any("odometer's total" in w for w in d.meta["warnings"])
    steps = np.diff(total)
    rows = f"{t[0]:.4f},0.00000\n" + "".join(
        f"{a:.4f},{b:.5f}\n" for a, b in zip(t[1:], steps, strict=True))
    d = read_odo_csv(_csv(tmp_path, "t,distance\n" + rows, "steps.csv"), P["odo"])
    np.testing.assert_allclose(d.odo.speed_mps, v_true, atol=1e-6)
    assert d.meta["odo_csv"]["kind"] == "distance" and "warnings" not in d.meta


def test_exponents_still_checked_when_the_file_has_an_e(tmp_path):
    t0 = 1_700_000_000
    plain = _csv(tmp_path, f"t,yaw_rate\n{t0},0.5\n{t0 + 1},2.5E-1\n{t0 + 2},1e-2\n")
    d = read_gyro_csv(plain, P["gyro"])
    np.testing.assert_allclose(d.gyro.yaw_rate_radps, [0.5, 0.25, 0.01], rtol=1e-15)
    assert d.meta["gyro_csv"]["parser"] == "pyarrow"
    huge = _csv(tmp_path, f"t,yaw_rate\n{t0},0.5\n{t0 + 1},1e-3201000\n", "huge.csv")
    d = read_gyro_csv(huge, P["gyro"])
    assert d.meta["gyro_csv"]["parser"] == "line-by-line" and len(d.gyro) == 2
