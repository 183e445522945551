"""fkf/fafkf at a stop: the constant-acceleration model carries the velocity through zero,
and the odometer's distance row must not let it run on in reverse (docs/decisions/0064)."""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest

from gpsdr_cli.filters import kernels_fkf as kf
from gpsdr_cli.simulate import simulate_drive
from gpsdr_cli.testing.sim import run_filter


def test_a_velocity_reversed_against_the_heading_is_measured_along_the_heading() -> None:
    """|v| cannot tell a reversed velocity: against the gyro's heading the row is the signed
    speed along it, so the odometer's forward distance pulls the velocity forward."""
    x = np.zeros(kf.NX)
    x[kf.IVE], x[kf.IVN] = -0.5, -0.5 * math.sqrt(3.0)    # 1 m/s towards 210 deg
    h = np.zeros(kf.NX)
    psi = math.radians(30.0)                               # the vehicle heads 30 deg
    pred = kf.distance_row(x, h, 0.2, 0.1, psi, True)
    assert pred == pytest.approx(-0.2)                     # 1 m/s backwards over 0.2 s
    assert h[kf.IVE] == pytest.approx(0.2 * math.sin(psi))
    assert h[kf.IVN] == pytest.approx(0.2 * math.cos(psi))
    # without the gyro's heading this epoch: Tang et al.'s |v| row
    pred = kf.distance_row(x, h, 0.2, 0.1, psi, False)
    assert pred == pytest.approx(0.2)
    assert h[kf.IVE] == pytest.approx(0.2 * x[kf.IVE])
    # a forward velocity keeps the |v| row
    x[kf.IVE], x[kf.IVN] = 0.5, 0.5 * math.sqrt(3.0)
    assert kf.distance_row(x, h, 0.2, 0.1, psi, True) == pytest.approx(0.2)


@pytest.mark.parametrize("name", ["fkf", "fafkf"])
def test_a_stop_in_a_long_screened_gap_keeps_the_track(monkeypatch, name: str) -> None:
    """A 283-s city drive (5-Hz CAN, a steady gyro, reflections lasting 20-180 s) whose NLOS
    screen keeps no fix for the last 150 s, with a stop in them: the velocity went through
    zero into reverse, grew backwards, and at the drive-off the heading rows near pi threw
    the track 70 m in 2 s (fkf 45.4 m, fafkf 87.7 m RMS against fixes at 24.6 m)."""
    from gpsdr_cli import simulate

    monkeypatch.setattr(simulate, "NLOS_DURATION_S", (20.0, 180.0))
    monkeypatch.setattr(simulate, "GYRO_BIAS_TAU_S", math.inf)
    sim = simulate_drive("urban_nlos", 14, 283.0, gyro_rate_hz=5.0, odo_rate_hz=5.0)
    r = run_filter(sim, copy.deepcopy(sim.drive), name, pipeline=True)
    assert r.result.info["nlos_screened"] > 1000
    assert r.rmse_m < 0.8 * r.gnss_rmse_m
    assert r.result.info["heading_rejected"] == 0
