"""The heading offset unwrapped across long gaps by its drift rate (gpsdr_cli.angles)."""

from __future__ import annotations

import math

import numpy as np

from gpsdr_cli.angles import unwrap_across_gaps


def _wrapped(a: np.ndarray) -> np.ndarray:
    return np.angle(np.exp(1j * a))


def test_a_gyro_bias_across_a_three_minute_gap_keeps_its_way_round() -> None:
    """1 deg/s of drift, courses for 26 s, none for 175 s, then 60 s more: the offset moves by
    190 deg across the gap, which the shortest way round reads as -170 deg."""
    rate = math.radians(1.0) * 1.09
    t = np.concatenate([np.arange(0.0, 26.0, 0.2), np.arange(201.0, 261.0, 0.2)])
    rng = np.random.default_rng(1)
    true = 0.3 + rate * t
    got = unwrap_across_gaps(t, _wrapped(true + rng.normal(0.0, 0.03, len(t))))
    assert np.max(np.abs(got - true)) < 0.15
    plain = np.unwrap(_wrapped(true))
    assert np.max(np.abs(plain - true)) > 6.0  # numpy's shortest way is a full turn off


def test_without_gaps_it_is_numpys_unwrap() -> None:
    t = np.arange(0.0, 120.0, 0.5)
    a = _wrapped(0.05 * t + np.sin(t))
    assert np.array_equal(unwrap_across_gaps(t, a), np.unwrap(a))


def test_a_gap_with_too_little_on_either_side_keeps_numpys_choice() -> None:
    t = np.array([0.0, 1.0, 100.0, 101.0])
    a = np.array([0.0, 0.1, 3.0, 3.1])
    assert np.array_equal(unwrap_across_gaps(t, a), np.unwrap(a))
    assert unwrap_across_gaps(np.zeros(0), np.zeros(0)).shape == (0,)


def test_rates_that_disagree_across_the_gap_keep_numpys_choice() -> None:
    """A track's course near a stop can turn fast: 0.003 rad/s before a 25-s gap, 0.05 after
    (urban_nlos seed 22's fkf start for the graph) is no rate to choose a branch by."""
    t = np.concatenate([np.arange(0.0, 30.0, 0.2), np.arange(55.0, 85.0, 0.2)])
    a = np.where(t < 40.0, 0.003 * t, 0.5 + 0.05 * (t - 55.0))
    wrapped = _wrapped(a - 2.6 * (t > 40.0))
    assert np.array_equal(unwrap_across_gaps(t, wrapped), np.unwrap(wrapped))


def test_a_rate_seen_on_one_side_only_must_agree_with_the_drive() -> None:
    """0.001 rad/s of drift over the drive; after a 100-s gap, 30 s of courses that ramp at
    0.04 rad/s (reflected, at a crawl) and only 2 s of them before it: that side alone would
    move the branch a whole turn (4 rad over the gap); the drive's rate keeps it."""
    rate = 0.001
    t = np.concatenate([np.arange(0.0, 150.0, 0.2), np.arange(190.0, 192.0, 0.5),
                        np.arange(292.0, 322.0, 1.0)])
    true = 0.4 + rate * t
    true[t >= 292.0] += 0.04 * (t[t >= 292.0] - 292.0)
    got = unwrap_across_gaps(t, _wrapped(true))
    assert np.max(np.abs(got - true)) < 1e-9
