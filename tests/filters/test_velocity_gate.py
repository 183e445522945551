"""The receiver velocity's own innovation gate (docs/decisions/0031-receiver-velocity-gate.md).

A run of wrong receiver velocities that agree among themselves (the readers' spike check
cannot see them) was taken at its 0.2-2 m/s sigma: four 3-s runs with the course 45 deg
off carried a 120-s open-sky drive 14-19 m off with ekf/aekf and 36-97 m with fkf/fafkf,
against fixes at 1.5 m.  Gated, and left out of fkf's course correction (more than 20 deg
off the corrected gyro heading), every filter stays within 0.7 m.  The gate judges the
velocity with at least ``[gnss] velocity_gate_floor_mps``: at the drive-off the state is
still at rest, and without the floor aekf gated the first 2 s of good velocities
(0.69 -> 0.75 m RMSE on the clean drive).  Without an odometer fkf's gates reset after 3 s;
the velocity's keeps ``[gnss] velocity_gate_reset_s`` (10 s), or the run's last wrong
velocity got in and fkf/fafkf ended 12-18 m off.
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from gpsdr_cli.conventions import NS_PER_S
from gpsdr_cli.simulate import simulate_drive
from gpsdr_cli.testing.faults import copy_drive, drop_streams, with_drive
from gpsdr_cli.testing.sim import run_filter

FILTERS = ("ekf", "aekf", "fkf", "fafkf")
#: m: RMSE with the wrong runs, forward and RTS (new code 0.32-0.68 m; before the gate
#: 14-97 m; gated but with fkf's course correction averaging the wrong courses, fkf 0.93 m
#: forward and 0.78 m RTS; without an odometer, gated with a 3-s reset, fkf/fafkf 12-18 m)
WRONG_RUNS_RMSE_M = 0.75


@pytest.fixture(scope="module")
def drives():
    """{odometer: (sim, the drive with the wrong runs)}, with and without an odometer."""
    out = {}
    for odometer in (True, False):
        sim = simulate_drive("open_sky", 1, 120.0)
        if not odometer:
            sim = with_drive(sim, drop_streams(sim.drive, "odo"))
        bad = copy_drive(sim.drive)
        g = bad.gnss
        t = (g.t_ns - g.t_ns[0]) / NS_PER_S
        runs = np.zeros(len(t), bool)
        for start in (20.0, 50.0, 80.0, 100.0):
            runs |= (t >= start) & (t < start + 3.0)
        g.course_deg[runs] = (g.course_deg[runs] + 45.0) % 360.0
        out[odometer] = (sim, bad)
    return out


@pytest.mark.parametrize("name", FILTERS)
@pytest.mark.parametrize("smooth", [False, True])
@pytest.mark.parametrize("odometer", [True, False])
def test_a_run_of_wrong_velocities_is_gated(drives, name: str, smooth: bool,
                                            odometer: bool) -> None:
    sim, bad = drives[odometer]
    run = run_filter(sim, copy.deepcopy(bad), name, smooth=smooth, pipeline=True)
    assert run.rmse_m < WRONG_RUNS_RMSE_M, f"{run.rmse_m:.2f} m (fixes {run.gnss_rmse_m:.2f} m)"
    assert run.result.info["gnss_velocity_gated"] >= 20      # of 75 wrong: 30-45 gated


@pytest.mark.parametrize("name", ["aekf", "fkf"])
def test_good_velocities_pass_at_the_drive_off(drives, name: str) -> None:
    sim, _ = drives[True]
    run = run_filter(sim, copy.deepcopy(sim.drive), name, pipeline=True)
    assert run.result.info["gnss_velocity_gated"] == 0
