"""The batch smoother on a drive without an odometer (gpsdr_cli.filters.graph): the
forward accelerometer carries the speed state through the GNSS outages, against the
simulator's truth."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from gpsdr_cli import config
from gpsdr_cli.filters.graph import smooth_graph
from gpsdr_cli.simulate import simulate_drive
from gpsdr_cli.testing.sim import run_filter


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def _graph(sim, drive):
    rts = run_filter(sim, drive, "aekf", smooth=True, pipeline=True)
    p = config.defaults()
    p["filter"]["name"] = "aekf"
    p["filter"]["smooth"] = True
    out = smooth_graph(rts.epochs, rts.result, p)
    assert out.result is not None, out.message
    tr = sim.truth
    ep = rts.epochs
    err = np.hypot(out.result.e - np.interp(ep.t_ns, tr.t_ns, tr.e),
                   out.result.n - np.interp(ep.t_ns, tr.t_ns, tr.n))
    return rts, out, err


@pytest.fixture(scope="module")
def no_odo():
    sim = simulate_drive("no_odometer", seed=2, duration_s=300.0)
    return sim, _graph(sim, sim.drive)


def test_accelerometer_carries_the_outages(no_odo) -> None:
    """15-s outages while braking to a stop and driving off: with the accelerometer's
    integral as the speed state's motion the graph stays at decimetres inside them, below
    aekf + RTS with its track bridged by the same accelerometer (accel_speed)."""
    sim, (rts, out, err) = no_odo
    ep = rts.epochs
    outage = np.asarray(ep.gnss_outage, bool)
    assert len(sim.noise["brake_outages"]) >= 5
    assert outage.sum() > 3000                        # epochs inside outages
    assert out.result.info["graph_accel"]
    assert _rms(err[outage]) < 0.3                     # m
    assert float(np.max(err)) < 1.0                    # m
    assert _rms(err[outage]) < 0.7 * _rms(rts.err_m[outage])
    # the reported sigma covers the error inside the outages, and is not wildly larger
    sig = np.sqrt(out.result.var_e + out.result.var_n)
    assert 1.0 <= _rms(sig[outage]) / _rms(err[outage]) <= 5.0


def test_without_the_accelerometer_the_speed_walks(no_odo) -> None:
    """The same drive with the accelerometer's log removed: the speed state is a random
    walk again and the outages are metres off (what the accelerometer is for)."""
    sim, (_rts, _out, err) = no_odo
    drive = copy.deepcopy(sim.drive)
    drive.accel = None
    rts2, out2, err2 = _graph(sim, drive)
    assert not out2.result.info["graph_accel"]
    outage = np.asarray(rts2.epochs.gnss_outage, bool)
    assert _rms(err2[outage]) > 5 * _rms(err[outage])
    assert np.all(np.isfinite(err2))


@pytest.fixture(scope="module")
def rtk_park():
    sim = simulate_drive("rtk", seed=1, duration_s=300.0)
    return sim, _graph(sim, sim.drive)


def test_rtk_park_averages_the_fixes(rtk_park) -> None:
    """RTK fixes (1-2.5 cm) and no odometer: at the stops (the receiver's speed) the graph
    holds the car still and averages the fixes there, below their own error, with a sigma
    that stays honest against the truth; elsewhere it is no worse than aekf + RTS."""
    sim, (rts, out, err) = rtk_park
    ep = rts.epochs
    tr = sim.truth
    still = np.interp(ep.t_ns, tr.t_ns, tr.speed) < 0.01
    cm = ep.has_gnss & (np.asarray(ep.gnss_sd_e) < 0.05)
    fix_err = np.hypot(ep.gnss_e - np.interp(ep.t_ns, tr.t_ns, tr.e),
                       ep.gnss_n - np.interp(ep.t_ns, tr.t_ns, tr.n))
    park = cm & still
    assert park.sum() > 150                           # fixes while stopped
    assert out.result.static[park].mean() > 0.9
    assert _rms(fix_err[park]) > 0.015                # m: the fixes' own error there
    assert _rms(err[park]) < 0.6 * _rms(fix_err[park])
    sig = np.sqrt(out.result.var_e + out.result.var_n)
    assert 0.5 <= _rms(sig[park]) / _rms(err[park]) <= 2.0
    assert _rms(err) < rts.rmse_m


def test_positions_only_keeps_the_accelerometer() -> None:
    """A drive without the receiver's speed and course: the stops from the fixes'
    positions are too coarse to hold the speed at zero against the accelerometer, and the
    track stays at centimetres to decimetres everywhere (not metres after each stop)."""
    sim = simulate_drive("no_odometer", seed=1)
    drive = copy.deepcopy(sim.drive)
    drive.gnss.speed_mps[:] = np.nan
    drive.gnss.course_deg[:] = np.nan
    rts2, out2, err2 = _graph(sim, drive)
    assert out2.result.info["graph_accel"]
    assert not out2.result.static.any()
    assert _rms(err2) < 0.15                          # m
    assert float(np.max(err2)) < 1.0                  # m
    assert _rms(err2) < 0.2 * rts2.rmse_m
