"""Fault injection: damaged drives through the real ``gpsdr fuse``, for every filter.

Each fault of :data:`gpsdr_cli.testing.faults.CATALOGUE` must give a complete
track (one row per epoch, finite e/n/v/sigma; nulls only in ``pdop``) or one
clear error line with exit status 1/2, as INTERFACE.md demands.  Faults with a
known effect are checked against the simulator's truth: sigmas grow in an
outage, a 100 m jump is rejected and the track stays near the truth, a 30
minute stop holds position.  The first block checks the injectors themselves.
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from gpsdr_cli.conventions import NS_PER_S
from gpsdr_cli.io.drive import Drive, GnssFixes, Odometry, YawRates
from gpsdr_cli.testing import faults as F

T0 = 1_700_000_000 * NS_PER_S


# ---------------------------------------------------------------------------- the injectors

def _toy_drive() -> Drive:
    """60 s north at 10 m/s: GNSS 1 Hz, gyro and odometer 10 Hz."""
    g = GnssFixes.empty(60)
    g.t_ns[:] = T0 + np.arange(60) * NS_PER_S
    g.fix_quality[:] = 1
    g.lat_deg[:] = 48.0 + np.arange(60) * 10.0 / F.M_PER_DEG_LAT
    g.lon_deg[:] = 11.0
    g.hdop[:] = 1.0
    t = T0 + np.arange(600) * NS_PER_S // 10
    return Drive(gnss=g, gyro=YawRates(t.copy(), np.full(600, 0.01)),
                 odo=Odometry(t.copy(), np.full(600, 10.0)))


def test_outage_and_jump_touch_only_their_window() -> None:
    d = _toy_drive()
    o = F.gnss_outage(d, 10.0, 5.0)
    assert o.gnss.valid.sum() == 55 and d.gnss.valid.sum() == 60  # argument untouched
    assert not o.gnss.valid[10:15].any()
    assert len(F.gnss_outage(d, 10.0, 5.0, mode="drop").gnss) == 55
    j = F.gnss_jump(d, 20.0, distance_m=100.0, bearing_deg=90.0)
    de_m = (j.gnss.lon_deg - d.gnss.lon_deg) * F.M_PER_DEG_LAT * np.cos(np.deg2rad(d.gnss.lat_deg))
    assert de_m[20] == pytest.approx(100.0, abs=0.01)  # metres
    assert np.count_nonzero(de_m) == 1


def test_clock_steps_duplicates_and_nan() -> None:
    d = _toy_drive()
    b = F.time_step_backwards(d, "gyro", 10.0, 1.0, count=3)
    steps = np.diff(b.gyro.t_ns)
    assert (steps < 0).sum() == 1 and steps.min() == -NS_PER_S + NS_PER_S // 10
    dup = F.duplicate_records(d, "odo", 10, value_offset=5.0)
    assert len(dup.odo) == 660
    assert (np.diff(dup.odo.t_ns) == 0).sum() == 60
    assert np.isclose(dup.odo.speed_mps, 15.0).sum() == 60
    n = F.nan_values(d, "gyro", 0.5, seed=1)
    assert 240 < np.isnan(n.gyro.yaw_rate_radps).sum() < 360


def test_decimate_keeps_the_integral() -> None:
    d = _toy_drive()
    d.gyro.yaw_rate_radps[:] = np.sin(np.arange(600) / 30.0)
    dd = F.decimate(d, "gyro", 1.0)
    assert len(dd.gyro) == 60
    assert dd.gyro.yaw_rate_radps.sum() * 1.0 == pytest.approx(d.gyro.yaw_rate_radps.sum() * 0.1)


def test_midnight_shift() -> None:
    delta = F.midnight_delta_ns(T0, 30.0, day="2024-12-31")
    start = pd.Timestamp(T0 + delta, unit="ns", tz="UTC")
    assert start == pd.Timestamp("2024-12-31T23:59:30", tz="UTC")


def test_standstill_insertion_moves_everything_after_it() -> None:
    sim = F.base_sim(duration_s=60.0)
    moved, t_stop = F.insert_standstill(sim, 30.0, 100.0, dr_rate_hz=10.0)
    d_ns = 100 * NS_PER_S
    tr = moved.truth
    stop = (tr["t_ns"] >= t_stop) & (tr["t_ns"] < t_stop + d_ns)
    assert (tr.loc[stop, "speed"] == 0).all()
    assert np.ptp(tr.loc[stop, "e"]) == 0.0
    assert np.all(np.diff(tr["t_ns"]) > 0)
    assert len(tr) == len(sim.truth) + 100 * 100  # 100 Hz truth
    assert F.end_ns(moved.drive) == F.end_ns(sim.drive) + d_ns
    o = moved.drive.odo
    in_stop = (o.t_ns >= t_stop) & (o.t_ns < t_stop + d_ns)
    assert in_stop.sum() == 1000 and (o.speed_mps[in_stop] == 0).all()
    g = moved.drive.gnss
    assert ((g.t_ns >= t_stop) & (g.t_ns < t_stop + d_ns)).sum() == 500  # 5 Hz


def test_nmea_faults_keep_checksums_valid() -> None:
    from gpsdr_cli.io.nmea import parse_nmea

    line = b"$GPGGA,123519,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,*47\r\n"
    blanked = F.nmea_empty_fields(line * 20, 0.3, seed=1)
    assert blanked.count(b",,") > line.count(b",,") * 20
    _, skipped, _ = parse_nmea(blanked, date=pd.Timestamp("2024-01-01").date())
    assert not any("checksum" in r for r in skipped.counts)
    assert F.nmea_drop_sentences(line, ["GGA"]) == b""


def test_mutate_is_deterministic_and_changes_bytes() -> None:
    data = b"t,speed\n1.0,2.0\n" * 10
    a = F.mutate(data, np.random.default_rng(3))
    b = F.mutate(data, np.random.default_rng(3))
    assert a == b and a != data


def test_track_problems_finds_nan_and_gaps() -> None:
    tr = pd.DataFrame({c: [1.0, 2.0] for c in F.REQUIRED_FINITE})
    tr["time"] = pd.to_datetime([T0, T0 + 1], unit="ns", utc=True)
    tr["gnss_used"] = [True, False]
    tr["pdop"] = [np.nan, 1.0]
    assert F.track_problems(tr, n_epochs=2) == []
    tr.loc[1, "sigma_e"] = np.nan
    assert F.track_problems(tr, n_epochs=3) == ["2 rows for 3 epochs", "sigma_e: 1 non-finite of 2"]
    assert F.error_line_problems("gpsdr: error: x.nmea:3: bad\n") == []
    assert F.error_line_problems("Traceback (most recent call last):\n  File\n")


# ---------------------------------------------------------------------------- end to end

FILTERS = ("ekf", "aekf", "fkf", "fafkf")

#: RMSE bound against the truth (m) where the fault itself forbids the default 5 m:
#: GNSS stamps 2 s late for good (~15 m/s x 2 s along track), no GNSS at all (120 s of DR),
#: half the drive in a 60 s outage (its own test bounds the error inside it).
RMSE_BOUND_M = {"gnss_clock_back": 40.0, "no_gnss_origin": 250.0, "outage_60s": 40.0}


@pytest.fixture(scope="module")
def sim() -> object:
    return F.base_sim()


def _run(case: str, filter_name: str, sim: object, tmp_path: Path) -> tuple[F.CaseInputs, F.Outcome]:
    return F.run_case(F.CASES[case], filter_name, tmp_path / case, sim)


@pytest.mark.parametrize("filter_name", FILTERS)
@pytest.mark.parametrize("case", [c.name for c in F.CATALOGUE if c.base == "short"])
def test_fault_gives_a_track_or_one_clear_error(case: str, filter_name: str, sim: object,
                                                tmp_path: Path) -> None:
    fc = F.CASES[case]
    inputs, out = _run(case, filter_name, sim, tmp_path)
    assert F.outcome_problems(out, fc.expect) == []
    if out.status == 0 and fc.expect == "track":
        # the damaged drive still follows the truth: open sky, 120 s, GNSS almost throughout
        assert F.case_metrics(inputs, out)["rmse_m"] < RMSE_BOUND_M.get(case, 5.0)


def _dr_bound_m(inputs: F.CaseInputs) -> float:
    """5 m + 10 % of the distance driven in the fault window (a common dead-reckoning spec)."""
    tr = inputs.sim.truth
    t = tr["t_ns"].to_numpy()
    lo, hi = inputs.focus_ns
    w = (t >= lo) & (t < hi)
    dist_m = float(np.sum(tr["speed"].to_numpy()[w]) * np.median(np.diff(t)) / NS_PER_S)
    return 5.0 + 0.1 * dist_m


@pytest.mark.parametrize("filter_name", FILTERS)
def test_outage_sigma_grows_and_error_stays_bounded(filter_name: str, sim: object,
                                                     tmp_path: Path) -> None:
    inputs, out = _run("outage_60s", filter_name, sim, tmp_path)
    assert F.outcome_problems(out, "track") == []
    tr = out.track
    t = F.track_t_ns(tr)
    lo, hi = inputs.focus_ns
    w = (t >= lo) & (t < hi)
    sig = np.hypot(tr["sigma_e"], tr["sigma_n"]).to_numpy()[w]
    assert sig[-1] > 2.0 * sig[0]  # 60 s of dead reckoning at ~15 m/s
    # no position update in an outage; odometer updates may trim it slightly via P_pv
    assert np.all(sig >= 0.95 * np.maximum.accumulate(sig))
    assert not tr["gnss_used"].to_numpy()[w].any()
    m = F.case_metrics(inputs, out)
    assert m["focus_max_m"] < _dr_bound_m(inputs)
    # the covariance tells the truth: 99.9 % chi-square(2) radius is 3.7 sigma
    assert m["end_error_sigmas"] < 3.7


@pytest.mark.parametrize("filter_name", FILTERS)
def test_jump_of_100m_is_rejected(filter_name: str, sim: object, tmp_path: Path) -> None:
    inputs, out = _run("jump_100m", filter_name, sim, tmp_path)
    assert F.outcome_problems(out, "track") == []
    m = F.case_metrics(inputs, out)
    assert m["rejected"] >= 5  # all five 5 Hz fixes of the jump
    assert m["focus_max_m"] < 5.0  # m from the truth while the fixes are 100 m off


@pytest.mark.parametrize("filter_name", FILTERS)
@pytest.mark.parametrize("case", [c.name for c in F.CATALOGUE if c.base == "long"])
def test_long_faults_in_memory(case: str, filter_name: str, tmp_path: Path) -> None:
    inputs, out = _run(case, filter_name, None, tmp_path)
    assert F.outcome_problems(out, "track") == []
    m = F.case_metrics(inputs, out)
    if case.startswith("standstill"):
        assert m["drift_m"] < 1.0  # m over 30 minutes at rest
    else:  # 10 minutes without GNSS
        tr = out.track
        t = F.track_t_ns(tr)
        lo, hi = inputs.focus_ns
        w = (t >= lo) & (t < hi)
        sig = np.hypot(tr["sigma_e"], tr["sigma_n"]).to_numpy()[w]
        assert sig[-1] > 5.0 * sig[0]
        assert np.all(sig >= 0.95 * np.maximum.accumulate(sig))
        assert m["focus_max_m"] < _dr_bound_m(inputs)


def test_failed_run_keeps_an_existing_output(sim: object, tmp_path: Path) -> None:
    """A failing run must not clobber (or half-write) the file -o names, nor leave temp files."""
    inputs = F.CASES["no_gnss"].make(sim, tmp_path)
    track = tmp_path / "track.parquet"
    stats = tmp_path / "track.parquet.stats.parquet"
    track.write_bytes(b"precious track")
    stats.write_bytes(b"precious stats")
    before = sorted(p.name for p in tmp_path.iterdir())
    out = F.run_cli(inputs.args, tmp_path)
    assert out.status == 1 and F.error_line_problems(out.stderr) == []
    assert track.read_bytes() == b"precious track"
    assert stats.read_bytes() == b"precious stats"
    assert sorted(p.name for p in tmp_path.iterdir()) == before


def test_real_process_gives_one_line_and_exit_status(sim: object, tmp_path: Path) -> None:
    exe = shutil.which("gpsdr") or str(Path(__file__).resolve().parents[1] / ".venv/bin/gpsdr")
    _, bad = F.run_case(F.CASES["nmea_all_garbage"], "aekf", tmp_path / "bad", sim,
                        subprocess_exe=exe)
    assert bad.status == 1
    assert F.error_line_problems(bad.stderr) == []
    assert "gps.nmea" in bad.stderr
    _, good = F.run_case(F.CASES["jump_100m"], "aekf", tmp_path / "good", sim, subprocess_exe=exe)
    assert good.status == 0 and F.track_problems(good.track, n_epochs=good.epochs) == []
