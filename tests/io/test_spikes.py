"""Readings that jump off their neighbours beyond what a vehicle does (gpsdr_cli.io.spikes)."""

from __future__ import annotations

import numpy as np

from gpsdr_cli.conventions import NS_PER_S
from gpsdr_cli.io.spikes import (
    accel_spikes,
    gyro_spikes,
    odometer_spikes,
    receiver_velocity_spikes,
    step_noise,
)


def _drive_velocities(rate_hz: float = 5.0, seconds: float = 60.0) -> tuple[np.ndarray, ...]:
    """A hard drive: 9 m/s^2 braking to a stop, a 0.9-g turn at 15 m/s, Doppler noise 0.3 m/s."""
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    speed = np.where(t < 25, np.clip(25.0 - np.clip(t - 17.0, 0, None) * 9.0, 0, None),
                     np.clip((t - 25.0) * 3.0, 0, 15.0))     # stopped from 19.8 to 25 s
    course = np.where(t < 30, 0.0, (t - 30.0) * np.rad2deg(0.9 * 9.81 / 15.0)) % 360.0
    rng = np.random.default_rng(1)
    ve = speed * np.sin(np.deg2rad(course)) + rng.normal(0, 0.3, len(t))
    vn = speed * np.cos(np.deg2rad(course)) + rng.normal(0, 0.3, len(t))
    t_ns = (t * NS_PER_S).astype(np.int64)
    return t_ns, np.hypot(ve, vn), np.rad2deg(np.arctan2(ve, vn)) % 360.0


def test_hard_braking_and_cornering_are_not_spikes() -> None:
    for rate in (1.0, 5.0, 10.0):
        t_ns, speed, course = _drive_velocities(rate)
        assert not receiver_velocity_spikes(t_ns, speed, course).any(), rate


def test_lone_and_paired_spikes_are_found_and_nothing_else() -> None:
    t_ns, speed, course = _drive_velocities()
    bad = np.zeros(len(t_ns), bool)
    bad[[40, 41, 120, 200, 260]] = True           # a pair, and lone ones (at rest: index 110-124)
    speed[bad] = [3.0, 3.0, 8.0, 30.0, 15.0]
    course[bad] = [180.0, 180.0, 90.0, 200.0, 90.0]
    course[40] = 180.0
    found = receiver_velocity_spikes(t_ns, speed, course)
    np.testing.assert_array_equal(np.flatnonzero(found), np.flatnonzero(bad))


def test_unsorted_and_missing_velocities() -> None:
    """Judged in time order whatever the record order; NaN neither judged nor a neighbour."""
    t_ns, speed, course = _drive_velocities()
    speed[[10, 11, 13]] = np.nan                  # 12 keeps two neighbours on one side only
    speed[12] = 40.0
    order = np.random.default_rng(2).permutation(len(t_ns))
    found = receiver_velocity_spikes(t_ns[order], speed[order], course[order])
    assert set(order[found]) == {12}
    assert not receiver_velocity_spikes(t_ns[:2], speed[:2], course[:2]).any()


def _odometer(rate_hz: float, seconds: float = 60.0) -> tuple[np.ndarray, np.ndarray]:
    """A CAN wheel speed: 25 m/s, braking at 9 m/s^2 to a stop, 3 m/s^2 away; 0.02 m/s noise."""
    t = np.arange(0.0, seconds, 1.0 / rate_hz)
    v = np.where(t < 25, np.clip(25.0 - np.clip(t - 17.0, 0, None) * 9.0, 0, None),
                 np.clip((t - 25.0) * 3.0, 0, 25.0))
    v = np.abs(v + np.random.default_rng(3).normal(0, 0.02, len(t)) * (v > 0))
    return (t * NS_PER_S).astype(np.int64), v


def test_odometer_glitches_are_found_and_braking_is_not() -> None:
    for rate in (5.0, 10.0, 100.0):
        t_ns, v = _odometer(rate)
        assert not odometer_spikes(t_ns, v).any(), rate
        bad = np.zeros(len(v), bool)
        k = np.searchsorted(t_ns, np.array([5.0, 10.0, 22.0, 40.0]) * NS_PER_S)
        bad[k] = True
        bad[k[1] + 1] = True                      # a pair
        v[bad] = np.where(v[bad] > 10, v[bad] - 12.0, v[bad] + 7.0)   # 22 s: a blip at the stop
        np.testing.assert_array_equal(np.flatnonzero(odometer_spikes(t_ns, v)),
                                      np.flatnonzero(bad))


def test_a_wheel_speed_from_coarse_ticks_keeps_its_steps() -> None:
    """0.05-m ticks read at 100 Hz step by 5 m/s between readings: not glitches."""
    t_ns, v = _odometer(100.0)
    dist = np.concatenate(([0.0], np.cumsum(v[1:] * 0.01)))
    ticks_v = np.concatenate(([0.0], np.diff(np.floor(dist / 0.05)) * 0.05 / 0.01))
    assert np.unique(np.round(ticks_v, 6)).size <= 8
    assert step_noise(t_ns, ticks_v) > 5.0
    assert not odometer_spikes(t_ns, ticks_v).any()


def test_gyro_glitches() -> None:
    t = np.arange(0.0, 30.0, 0.01)
    w = 0.5 * np.sin(2 * np.pi * t / 8.0)        # slaloms: 0.4 rad/s^2 at most
    t_ns = (t * NS_PER_S).astype(np.int64)
    assert not gyro_spikes(t_ns, w).any()
    w[[500, 1500, 1501]] = [5.0, -3.0, -3.0]
    assert np.flatnonzero(gyro_spikes(t_ns, w)).tolist() == [500, 1500, 1501]


def test_accelerometer_glitches_and_road_vibration() -> None:
    """Vibration of 1 m/s^2 and an emergency stop's onset are motion; +-40 m/s^2 is not."""
    t = np.arange(0.0, 30.0, 0.01)
    a = np.where((t > 10) & (t < 13), -8.0 * np.clip((t - 10) / 0.4, 0, 1), 0.5)
    a = a + np.random.default_rng(4).normal(0, 1.0, len(t))
    t_ns = (t * NS_PER_S).astype(np.int64)
    assert not accel_spikes(t_ns, a).any()
    a[[300, 1050, 2000]] = [40.0, 30.0, -35.0]
    assert np.flatnonzero(accel_spikes(t_ns, a)).tolist() == [300, 1050, 2000]
