"""The gyro's sign and units against the receiver's course (gpsdr_cli/gyro_sign.py)."""

from __future__ import annotations

import copy
import dataclasses
import json
import math

import numpy as np
import pytest

from gpsdr_cli import config
from gpsdr_cli.align import build_epochs
from gpsdr_cli.gyro_sign import check, course_slope
from gpsdr_cli.io.drive import YawRates
from gpsdr_cli.pipeline import fuse
from gpsdr_cli.simulate import simulate_drive


@pytest.fixture(scope="module")
def canyon():
    return simulate_drive("urban_canyon", 1, 300.0)


def _epochs(sim, drive=None):
    p = config.defaults()
    return build_epochs(copy.deepcopy(drive or sim.drive), sim.frame, p)


def test_the_course_follows_the_gyro_with_slope_one(canyon) -> None:
    """A simulated 300-s canyon drive: the course change over 6-s windows is the gyro's heading
    change with slope 0.99; mirrored, -0.99, and the gyro as read explains the course changes
    20 times worse than the mirrored one."""
    ep = _epochs(canyon)
    slope, se, ratio, n = course_slope(ep)
    assert slope == pytest.approx(1.0, abs=0.03) and se < 0.01 and ratio < 0.1 and n > 500
    mirrored = dataclasses.replace(ep, yaw_rate_radps=-ep.yaw_rate_radps)
    slope_m, _, ratio_m, _ = course_slope(mirrored)
    assert slope_m == pytest.approx(-slope) and ratio_m > 10.0
    assert check(ep)[1] is None
    out, note = check(mirrored)
    assert "turns -0.992 times as the receiver's course" in note and "other sign" in note
    np.testing.assert_array_equal(out.yaw_rate_radps, ep.yaw_rate_radps)



@pytest.mark.parametrize("factor,config", [(180.0 / math.pi, 'units = "deg/s"'),
                                           (math.pi / 180.0, 'units = "rad/s"'),
                                           (-180.0 / math.pi, "sign to the other value")])
def test_yaw_rates_in_the_other_units_are_read_right(canyon, factor: float, config: str) -> None:
    """deg/s read as rad/s turn 57 times too far, rad/s read as deg/s 57 times too little: the
    slope says which, the rates are scaled back (to 1e-9 of the rad/s readings) and the note
    names the setting."""
    ep = _epochs(canyon)
    misread = dataclasses.replace(ep, yaw_rate_radps=factor * ep.yaw_rate_radps)
    out, note = check(misread)
    assert note is not None and config in note
    np.testing.assert_allclose(out.yaw_rate_radps, ep.yaw_rate_radps, rtol=1e-9, atol=1e-12)

def test_a_drive_that_cannot_tell_is_left_alone(canyon) -> None:
    """Without the receiver's course (GGA only), or without turns at speed, nothing is said."""
    ep = _epochs(canyon)
    no_course = dataclasses.replace(ep, gnss_course_rad=np.full(len(ep), np.nan),
                                    yaw_rate_radps=-ep.yaw_rate_radps)
    assert course_slope(no_course) is None and check(no_course)[1] is None
    straight = dataclasses.replace(ep, gnss_course_rad=np.where(ep.has_gnss, 0.3, np.nan),
                                   yaw_rate_radps=np.zeros(len(ep)))
    assert course_slope(straight) is None


def test_fuse_reads_a_mirrored_gyro_the_right_way(canyon) -> None:
    """The same drive with its yaw rates logged clockwise-positive: read as they are, the graph
    smoother ended 444 m RMS from the truth (fixes 7.6 m).  Now the track is the one of the
    gyro logged the right way, and the summary says what was done."""
    flipped = copy.deepcopy(canyon.drive)
    flipped.gyro = YawRates(t_ns=flipped.gyro.t_ns, yaw_rate_radps=-flipped.gyro.yaw_rate_radps)
    right = fuse(copy.deepcopy(canyon.drive), config.defaults())
    mirrored = fuse(flipped, config.defaults())
    assert not any("the gyro turns" in w for w in right.drive_warnings)
    assert any("the gyro turns" in w for w in mirrored.drive_warnings)
    np.testing.assert_allclose(mirrored.track["e"], right.track["e"], atol=1e-9)
    np.testing.assert_allclose(mirrored.track["n"], right.track["n"], atol=1e-9)


def test_a_gyro_scale_far_from_one_is_reported() -> None:
    """A gyro reading 30 % more turn than there is is no sensor's scale error but a
    configuration's: the graph smoother's scale correction reads it, and the summary says so."""
    sim = simulate_drive("open_sky", 1, 300.0)
    drive = copy.deepcopy(sim.drive)
    drive.gyro = YawRates(t_ns=drive.gyro.t_ns, yaw_rate_radps=1.3 * drive.gyro.yaw_rate_radps)
    res = fuse(drive, config.defaults())
    note = [w for w in res.drive_warnings if w.startswith("the gyro reads")]
    assert len(note) == 1 and "+1.3" in note[0], res.drive_warnings
    g = json.loads(res.metadata["filter_info"])["graph_gyro_scale"]
    assert g == pytest.approx(1.0 / 1.3 - 1.0, abs=0.01)
