"""The GNSS lever arm (gpsdr_cli.lever_arm): a simulated drive whose fixes are at an antenna
1.5 m ahead of the reference point, fused with and without the arm."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from gpsdr_cli import config, lever_arm, pipeline, simulate
from gpsdr_cli.align import build_epochs
from gpsdr_cli.errors import UsageError

ARM_FWD_M = 1.5
#: m: without the arm the track follows the antenna, 1.5 m ahead: the error is metres
NO_ARM_RMSE_MIN_M = 1.0
#: m: with the arm the track is the one the same noisy fixes give at the reference point
#: (the simulator's own error floor: 0.62 m RMSE for aekf on this drive) to within this.
#: A difference, not a ratio: the floor is the fixes' noise, which the arm does not change.
WITH_ARM_OVER_FLOOR_MAX_M = 0.10


def test_offset_directions() -> None:
    # heading north: forward is +n, left is -e; heading east: forward +e, left +n
    de, dn = lever_arm.antenna_offset_en(np.array([0.0, np.pi / 2]), 1.0, 0.0)
    np.testing.assert_allclose([de, dn], [[0.0, 1.0], [1.0, 0.0]], atol=1e-12)
    de, dn = lever_arm.antenna_offset_en(np.array([0.0, np.pi / 2]), 0.0, 1.0)
    np.testing.assert_allclose([de, dn], [[-1.0, 0.0], [0.0, 1.0]], atol=1e-12)


def test_held_heading() -> None:
    v_e = np.array([0.0, 5.0, 0.2, 0.0, 0.0])
    v_n = np.array([0.1, 0.0, 0.0, 3.0, 0.0])
    h = lever_arm.held_heading(v_e, v_n, 1.0)
    np.testing.assert_allclose(h, [np.pi / 2, np.pi / 2, np.pi / 2, 0.0, 0.0])
    assert np.isnan(lever_arm.held_heading(np.zeros(3), np.zeros(3), 1.0)).all()


@pytest.mark.parametrize(("text", "arm"), [("1.5,0", [1.5, 0.0, 0.0]), (" 1.5, -0.3 ,1.2", [1.5, -0.3, 1.2])])
def test_parse(text: str, arm: list[float]) -> None:
    assert lever_arm.parse_lever_arm(text) == arm


@pytest.mark.parametrize("text", ["1.5", "a,b", "1,2,3,4", "nan,0"])
def test_parse_rejects(text: str) -> None:
    with pytest.raises(UsageError, match="FWD,LEFT"):
        lever_arm.parse_lever_arm(text)


@pytest.fixture(scope="module")
def antenna_drive() -> tuple[simulate.SimDrive, object]:
    """The open-sky drive (curves up to 0.37 rad/s) with every fix moved to an antenna
    ARM_FWD_M ahead of the reference point, along the true heading at the fix."""
    sim = simulate.simulate_drive("open_sky", seed=1, duration_s=300.0)
    g = sim.drive.gnss
    e, n = sim.frame.forward(g.lat_deg, g.lon_deg)
    h = np.interp(g.t_ns, sim.truth.t_ns, np.unwrap(np.radians(sim.truth.heading_deg)))
    de, dn = lever_arm.antenna_offset_en(h, ARM_FWD_M, 0.0)
    lat, lon = sim.frame.inverse(e + de, n + dn)
    return sim, dataclasses.replace(sim.drive, gnss=dataclasses.replace(g, lat_deg=lat, lon_deg=lon))


def _errors(sim: simulate.SimDrive, track) -> np.ndarray:
    e, n = sim.frame.forward(track["lat"].to_numpy(float), track["lon"].to_numpy(float))
    t = track["time"].astype("int64").to_numpy()
    return np.hypot(e - np.interp(t, sim.truth.t_ns, sim.truth.e),
                    n - np.interp(t, sim.truth.t_ns, sim.truth.n))


def test_lever_arm_brings_the_track_to_the_reference_point(antenna_drive) -> None:
    sim, antenna = antenna_drive
    p = config.defaults()
    p["qc"]["backward_pass"] = False
    p["filter"]["smoother"] = "none"  # the forward filter: the graph's track hides the arm less
    floor = _errors(sim, pipeline.fuse(sim.drive, p).track)       # fixes at the reference point
    plain = pipeline.fuse(antenna, p).track
    err_plain = _errors(sim, plain)
    p_arm = copy.deepcopy(p)
    p_arm["gnss"]["lever_arm_m"] = [ARM_FWD_M, 0.0, 0.0]
    res = pipeline.fuse(antenna, p_arm)
    err_arm = _errors(sim, res.track)
    def rmse(d):
        return float(np.sqrt(np.mean(d ** 2)))
    t = res.track["time"].astype("int64").to_numpy()
    turning = np.abs(np.interp(t, sim.truth.t_ns, sim.truth.yaw_rate)) > 0.2
    assert turning.any()
    assert rmse(err_plain) > NO_ARM_RMSE_MIN_M
    assert err_plain[turning].max() > NO_ARM_RMSE_MIN_M
    assert rmse(err_arm) - rmse(floor) < WITH_ARM_OVER_FLOOR_MAX_M, (rmse(err_arm), rmse(floor))
    assert rmse(err_arm[turning]) - rmse(floor[turning]) < WITH_ARM_OVER_FLOOR_MAX_M
    assert res.metadata["param.gnss.lever_arm_m"] == "[1.5, 0.0, 0.0]"


def test_second_pass_changes_little(antenna_drive) -> None:
    """The shift's error is |arm| x the previous pass's heading error: after one corrected
    pass the fixes move by millimetres."""
    sim, antenna = antenna_drive
    p = config.defaults()
    ep = build_epochs(copy.deepcopy(antenna), sim.frame, p)
    arm = (ARM_FWD_M, 0.0, 0.0)
    first = pipeline.run_filter(ep, p)
    one = lever_arm.corrected_epochs(ep, first, arm, 1.0)
    two = lever_arm.corrected_epochs(ep, pipeline.run_filter(one, p), arm, 1.0)
    f = ep.has_gnss
    step = np.hypot(two.gnss_e[f] - one.gnss_e[f], two.gnss_n[f] - one.gnss_n[f])
    assert float(np.sqrt(np.mean(step ** 2))) < 0.02
    moved = np.hypot(one.gnss_e[f] - ep.gnss_e[f], one.gnss_n[f] - ep.gnss_n[f])
    assert np.median(moved) == pytest.approx(ARM_FWD_M, abs=1e-9)


def test_cli_lever_arm(gpsdr, tmp_path, antenna_drive) -> None:
    sim, antenna = antenna_drive
    simulate_dir = tmp_path / "d"
    simulate.write_drive(dataclasses.replace(sim, drive=antenna), simulate_dir)
    files = {p.suffix: p for p in simulate_dir.iterdir()}
    assert ".nmea" in files
    out = tmp_path / "t.parquet"
    res = gpsdr(["fuse", "--gps", str(files[".nmea"]), "--lever-arm", "1.5,0", "-o", str(out), "-q"])
    assert res.exit_code == 0, res.output
    from gpsdr_cli.io.parquet import read_track

    _, meta = read_track(str(out))
    assert meta["param.gnss.lever_arm_m"] == "[1.5, 0.0, 0.0]"
    bad = gpsdr(["fuse", "--gps", str(files[".nmea"]), "--lever-arm", "1.5", "-o", str(out)])
    assert bad.exit_code == 2 and "FWD,LEFT" in bad.output


def test_an_antenna_ahead_is_not_a_late_odometer(antenna_drive) -> None:
    """In turns, fixes from an antenna 1.5 m ahead read like fixes early by 1.5 m / speed;
    the odometer's lag is read from speed changes alone, which see the simulator's own
    0.05 s, so the odometer stays as logged (decisions/0024)."""
    from gpsdr_cli.latency import estimate_gnss_offset

    _, antenna = antenna_drive
    p = config.defaults()
    p["filter"]["smoother"] = "none"  # the forward track the lag is read on
    res = pipeline.fuse(antenna, p)
    assert res.params["time"]["odo_offset_s"] == 0.0
    assert not any("odometer's speed reads" in w for w in res.drive_warnings)
    vector = estimate_gnss_offset(res.track)
    along = estimate_gnss_offset(res.track, along=True)
    assert vector.offset_s > 0.06                        # 0.071 s: the arm, seen in turns
    assert along.offset_s == pytest.approx(0.05, abs=0.015)  # 0.046 s: the odometer's lag
