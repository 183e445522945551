"""The odometer read earlier when the fixes sit clearly ahead of it (``[time] odo_lag_auto``)."""

from __future__ import annotations

import dataclasses
import warnings

import pytest

from gpsdr_cli import config
from gpsdr_cli.pipeline import fuse
from gpsdr_cli.simulate import simulate_drive

#: the simulated odometer already describes the speed 0.05 s before its stamp (decisions/0022)
SIM_ODO_LAG_S = 0.05


def _fuse(sim, name: str, smoother: str = "none", **time):
    """The forward filter by default: the lag is read on its track (the graph smoother, the
    default since decisions/0071, fits the odometer's lag itself)."""
    params = config.defaults()
    params["filter"]["name"] = name
    params["filter"]["smoother"] = smoother
    params["time"].update(time)
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        out = fuse(sim.drive, params, sim.reference())
    stats = out.stats
    return out, float(stats[stats.segment == "all"].rmse_m.iloc[0])


def _late_odometer(seed: int, late_s: float):
    sim = simulate_drive("open_sky", seed, 200.0)
    odo = sim.drive.odo
    sim.drive.odo = dataclasses.replace(odo, t_ns=odo.t_ns + round(late_s * 1e9))
    return sim


def test_a_late_odometer_is_read_earlier() -> None:
    """Odometer stamps 0.2 s late (a CAN speed stamped on arrival): the lag is found from the
    fixes to 0.05 s (0.21 s; the along-track reading's zero is at 0.23 s), and aekf's error
    falls to a fifth (2.42 -> 0.49 m on 200 s)."""
    sim = _late_odometer(1, 0.2)
    found, rmse = _fuse(sim, "aekf")
    _, as_logged = _fuse(sim, "aekf", odo_lag_auto=False)
    assert found.params["time"]["odo_offset_s"] == pytest.approx(-(0.2 + SIM_ODO_LAG_S), abs=0.05)
    assert any("odometer's speed reads" in w for w in found.drive_warnings)
    assert rmse < 0.3 * as_logged, (rmse, as_logged)
    # the default, aekf + graph, fits the lag itself: 0.23 m
    _, graph = _fuse(sim, "aekf", smoother="auto")
    assert graph < 0.3 * as_logged, (graph, as_logged)


def test_fkf_keeps_its_odometer() -> None:
    """fkf takes the fixes' speed and course into its heading and odometer scale: its track
    hides the lag, and moved by what an ekf pass finds it got worse (decisions/0024)."""
    found, _ = _fuse(_late_odometer(1, 0.2), "fkf")
    assert found.params["time"]["odo_offset_s"] == 0.0


def test_late_fixes_do_not_move_the_odometer() -> None:
    """Fixes stamped 0.15 s late sit behind the dead reckoning: a wheel speed cannot be early,
    so the odometer stays as logged (the summary suggests --gnss-offset auto instead)."""
    sim = simulate_drive("open_sky", 1, 200.0, gnss_stamp_offset_s=-0.15)
    out, _ = _fuse(sim, "aekf")
    assert out.params["time"]["odo_offset_s"] == 0.0
    assert not any("odometer's speed reads" in w for w in out.drive_warnings)


def test_an_odometer_on_time_is_left_alone() -> None:
    """The drive as simulated (only the odometer's own 0.05 s) and an offset the user gave."""
    sim = simulate_drive("open_sky", 2, 200.0)
    out, _ = _fuse(sim, "aekf")
    assert out.params["time"]["odo_offset_s"] == 0.0
    late = _late_odometer(1, 0.2)
    given, _ = _fuse(late, "aekf", odo_offset_s=-0.1)
    assert given.params["time"]["odo_offset_s"] == -0.1

