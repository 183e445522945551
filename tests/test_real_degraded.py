"""The degradations of ``benchmarks/real_degraded.py`` do what they say, read back by gpsdr's own readers.

Only the file builders are tested here (fast, no filter run): the benchmark itself runs
``gpsdr fuse`` ~200 times and is not a test.
"""

from __future__ import annotations

import datetime
from pathlib import Path

import numpy as np
import pytest

from gpsdr_cli import config
from gpsdr_cli.io.csv import read_gyro_csv, read_odo_csv
from gpsdr_cli.io.nmea import parse_nmea

from .conftest import load_benchmark

RD = load_benchmark("real_degraded")
DATE = datetime.date(2018, 8, 2)

pytestmark = pytest.mark.skipif(not (RD.DATA / "gps.nmea").exists(), reason="comma2k19 data not present")


@pytest.fixture(scope="module")
def base():
    return RD.Base.load(RD.DATA)


def _fix_times_s(path: Path) -> np.ndarray:
    """Seconds from the first fix of the undamaged log, of every usable fix in ``path``."""
    fixes, _, _ = parse_nmea(path.read_bytes(), name=str(path), date=DATE)
    t0 = parse_nmea((RD.DATA / "gps.nmea").read_bytes(), date=DATE)[0].t_ns[0]
    t = (np.asarray(fixes.t_ns) - t0) / 1e9
    return t[np.isfinite(np.asarray(fixes.lat_deg))]


def _build(base, tmp_path: Path, *steps) -> tuple[list[str], str, int]:
    return RD.build(RD.Case("t", tuple(steps)), base, tmp_path)


def test_epochs_group_every_sentence(base):
    # 579 fix epochs (data README), each RMC + GGA + 2 GSA; nothing lost by the grouping
    assert len(base.epochs) == 579
    assert sum(len(ep.lines) for ep in base.epochs) == 579 * 4
    assert base.duration_s == pytest.approx(59.7, abs=0.05)   # s


def test_outage_removes_exactly_its_window(base, tmp_path):
    _build(base, tmp_path, RD.outage(20.0, 20.0))
    t = _fix_times_s(tmp_path / "gps.nmea")
    assert not ((t >= 20.0 - 1e-6) & (t < 40.0 - 1e-6)).any()
    kept = [ep for ep in base.epochs if not (20.0 <= ep.t_s < 40.0)]
    assert len(t) == len(kept)
    assert t.max() - t.min() == pytest.approx(59.7, abs=0.05)   # s: both ends kept


def test_decimation_keeps_one_epoch_per_second(base, tmp_path):
    _build(base, tmp_path, RD.decimate_1hz)
    t = _fix_times_s(tmp_path / "gps.nmea")
    assert 59 <= len(t) <= 61
    assert np.all(np.diff(t) > 0.5)   # s


def test_no_fix_sentences_parse_as_no_fix(base, tmp_path):
    _build(base, tmp_path, RD.no_fix_sentences(20.0, 20.0))
    _, skipped, _ = parse_nmea((tmp_path / "gps.nmea").read_bytes(), date=DATE)
    assert sum(skipped.counts.values()) == 0   # valid checksums: nothing skipped
    t = _fix_times_s(tmp_path / "gps.nmea")
    assert not ((t >= 20.0 - 1e-6) & (t < 40.0 - 1e-6)).any()
    assert len(t) == len([ep for ep in base.epochs if not (20.0 <= ep.t_s < 40.0)])


def test_csv_edits(base, tmp_path):
    params = config.defaults()
    _, _, damaged = _build(base, tmp_path, RD.odo_scale(1.02), RD.gyro_bias(0.5), RD.odo_rate(10.0))
    assert damaged == 0
    odo = read_odo_csv(tmp_path / "odo.csv", params["odo"]).odo
    gyro = read_gyro_csv(tmp_path / "gyro.csv", params["gyro"]).gyro
    raw_odo = np.loadtxt(RD.DATA / "odo.csv", delimiter=",", skiprows=1)
    raw_gyro = np.loadtxt(RD.DATA / "gyro.csv", delimiter=",", skiprows=1)
    dt = np.diff(np.asarray(odo.t_ns)) / 1e9
    assert dt.min() > 0.05 and np.median(dt) == pytest.approx(0.1, abs=0.015)   # s: 10 Hz
    us = np.round(raw_odo[:, 0] * 1e6).astype(np.int64)          # the files' times have 6 decimals
    i = np.searchsorted(us, np.round(np.asarray(odo.t_ns) / 1e3).astype(np.int64))
    np.testing.assert_allclose(np.asarray(odo.speed_mps), 1.02 * raw_odo[i, 1], rtol=1e-12)
    np.testing.assert_allclose(np.asarray(gyro.yaw_rate_radps), raw_gyro[:, 1] + np.radians(0.5), atol=1e-12)


def test_corruption_counts_damage(base, tmp_path):
    _, note, damaged = _build(base, tmp_path, RD.corrupt(0.05))
    n_lines = 579 * 4
    assert 0.03 * n_lines < damaged - 2 * len(RD.CSV_GARBAGE) < 0.07 * n_lines
    assert "NMEA lines damaged" in note


def test_time_spike_row(base, tmp_path):
    _, _, damaged = _build(base, tmp_path, RD.csv_time_spike(100, 480.0))
    assert damaged == 2
    rows = (tmp_path / "odo.csv").read_text().splitlines()
    t = np.array([float(r.split(",")[0]) for r in rows[1:]])
    assert t[100] - t[99] == pytest.approx(480.0, abs=1e-6)   # s
    assert len(rows) == len(base.odo) + 1
