"""A GNSS-only receiver log with cold-start junk: no-fix epochs stamped with the receiver's
default date (1980-01-06), then a jump of 44 years to the first real fix, 3-5 satellites and
HDOP 1.7-4.  Every filter, forward and smoothed, must give a complete finite track near the
truth; the junk records are dropped and counted.  The filters themselves must also stay
finite when handed the 44-year span (the initial and gap variances are bounded)."""

from __future__ import annotations

import math

import numpy as np
import pytest
from click.testing import CliRunner

from gpsdr_cli import config, filters, pipeline
from gpsdr_cli.align import build_epochs
from gpsdr_cli.cli.main import cli
from gpsdr_cli.io.parquet import read_track
from gpsdr_cli.io.readers import read_drive

LAT0, LON0 = 48.1, 11.5
SPEED_MPS = 5.0           # due north
M_PER_DEG = 111_195.0
#: the fixes' noise is 3 m per axis; a filter may not end up far from the straight path
BOUND_M = 6.0


def _cks(body: str) -> str:
    c = 0
    for ch in body:
        c ^= ord(ch)
    return f"${body}*{c:02X}"


def _dm(value: float, width: int) -> str:
    a = abs(value)
    return f"{int(a):0{width}d}{(a - int(a)) * 60:07.4f}"


def junk_log(n_fix: int, seed: int = 0) -> str:
    rng = np.random.default_rng(seed)
    out = []
    for i in range(40):
        t = f"0000{i:02d}.00"
        out += [_cks(f"GPRMC,{t},V,,,,,,,060180,,,N"), _cks(f"GPGGA,{t},,,,,0,00,99.99,,,,,,"),
                _cks("GPGSA,A,1,,,,,,,,,,,,,99.99,99.99,99.99")]
    for i in range(n_fix):
        s = 12 * 3600 + i
        t = f"{s // 3600:02d}{(s // 60) % 60:02d}{s % 60:02d}.00"
        lat = LAT0 + (i * SPEED_MPS + rng.normal(0, 3)) / M_PER_DEG
        lon = LON0 + rng.normal(0, 3) / (M_PER_DEG * math.cos(math.radians(LAT0)))
        pos = f"{_dm(lat, 2)},N,{_dm(lon, 3)},E"
        ns, hdop = int(rng.integers(3, 6)), float(rng.uniform(1.7, 4.0))
        out += [_cks(f"GPRMC,{t},A,{pos},{SPEED_MPS / 0.514444:.1f},0.0,010524,,,A"),
                _cks(f"GPGGA,{t},{pos},1,{ns:02d},{hdop:.2f},500.0,M,47.0,M,,"),
                _cks(f"GPGSA,A,3,01,02,03,,,,,,,,,,{hdop * 1.5:.2f},{hdop:.2f},{hdop * 1.2:.2f}")]
    return "\n".join(out) + "\n"


def _cross_track_m(lon_deg: np.ndarray) -> np.ndarray:
    return (np.asarray(lon_deg) - LON0) * M_PER_DEG * math.cos(math.radians(LAT0))


@pytest.mark.parametrize("name", ["ekf", "aekf", "fkf", "fafkf"])
@pytest.mark.parametrize("smooth", [False, True])
@pytest.mark.parametrize("n_fix", [2, 5, 40])
def test_fuse_cold_start_junk(tmp_path, name, smooth, n_fix):
    log = tmp_path / "cold.nmea"
    log.write_text(junk_log(n_fix, seed=n_fix))
    out = tmp_path / "cold.parquet"
    args = ["fuse", "--gps", str(log), "--filter", name, "-o", str(out)]
    res = CliRunner().invoke(cli, args + (["--smooth"] if smooth else []))
    assert res.exit_code == 0, res.output
    assert "40 input records skipped" in res.output
    track, _ = read_track(str(out))
    assert len(track) == n_fix
    for col in ("lat", "lon", "e", "n", "sigma_e", "sigma_n"):
        assert np.isfinite(track[col].to_numpy(float)).all(), col
    assert np.abs(_cross_track_m(track["lon"])).max() < BOUND_M
    assert track["time"].min().year == 2024


@pytest.mark.parametrize("name", ["ekf", "aekf", "fkf", "fafkf"])
@pytest.mark.parametrize("smooth", [False, True])
def test_filters_finite_across_44_years(tmp_path, name, smooth):
    """The filters given the junk epochs themselves (no cleaning): finite, non-negative
    variances, and the track after the first fix near the straight path."""
    log = tmp_path / "cold.nmea"
    log.write_text(junk_log(12, seed=1))
    params = config.defaults()
    params["filter"]["smooth"] = smooth
    params["filter"]["smoother"] = "rts" if smooth else "none"
    drive = read_drive(gps=str(log), params=params)
    epochs = build_epochs(drive, pipeline.choose_frame(drive, params), params)
    assert (np.diff(epochs.t_ns) > 40 * 365 * 86400 * 10**9).any()
    result = filters.get(name)(epochs, params)
    for arr in (result.e, result.n, result.var_e, result.var_n):
        assert np.isfinite(arr).all()
    assert (result.var_e >= 0).all() and (result.var_n >= 0).all()
    after = epochs.has_gnss.cumsum() > 0
    assert np.abs(result.e[after]).max() < BOUND_M
