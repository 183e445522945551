"""The shared GNSS error model (gpsdr_cli.filters.gnss_model and align.base_sigma):
fix quality decides the noise, and fixes whose chords disagree with the dead reckoning
(NLOS) are down-weighted.  Errors against the simulator's truth, in metres."""

from __future__ import annotations

import numpy as np
import pytest

from gpsdr_cli import config, simulate
from gpsdr_cli.align import base_sigma, build_epochs
from gpsdr_cli.filters.gnss_model import chord_mismatch_m, gnss_error_model
from gpsdr_cli.testing.sim import run_filter


def test_base_sigma_follows_fix_quality():
    p = config.defaults()
    hdop = np.array([0.8, 0.8, 0.8, 0.8])
    nan = np.full(4, np.nan)
    q = np.array([4, 5, 1, 4])
    gst = np.array([np.nan, np.nan, np.nan, 0.015])
    sd_e, _ = base_sigma(gst, gst, hdop, p, q)
    assert sd_e[0] == pytest.approx(0.8 * 0.03 / np.sqrt(2.0), rel=1e-12)   # RTK fixed
    assert sd_e[1] == pytest.approx(0.8 * 0.4 / np.sqrt(2.0), rel=1e-12)    # RTK float
    assert sd_e[2] == pytest.approx(0.8 * 2.5 / np.sqrt(2.0), rel=1e-12)    # autonomous
    assert sd_e[3] == pytest.approx(0.015, rel=1e-12)                       # GST honoured
    # without HDOP an RTK-fixed fix is still centimetres, an autonomous one the default
    sd_e, _ = base_sigma(nan, nan, nan, p, np.array([4, 4, 1, 1]))
    assert sd_e[0] == pytest.approx(0.03 / np.sqrt(2.0))
    assert sd_e[2] == pytest.approx(5.0 / np.sqrt(2.0))


def _rms_from_fixed(run, sim) -> float:
    ep = run.epochs
    f = np.flatnonzero(ep.has_gnss & (ep.gnss_sd_e < 0.05))  # the RTK-fixed fixes
    return float(np.sqrt(np.mean((run.result.e[f] - ep.gnss_e[f]) ** 2
                                 + (run.result.n[f] - ep.gnss_n[f]) ** 2)))


@pytest.mark.parametrize("name", ["aekf", "fkf"])
def test_rtk_drive_follows_centimetre_fixes(name):
    """On the rtk scenario (GGA 4 at 1-2.5 cm, float stretches, false fixes) the track
    follows the fixes reported at centimetres (false fixes included) to about a decimetre,
    against 0.3 m with the metre GNSS error states of an autonomous receiver."""
    sim = simulate.simulate_drive("rtk", seed=1)
    ep = build_epochs(sim.drive, sim.frame, config.defaults())
    assert ep.rtk_fixed_share > 0.5
    run = run_filter(sim, sim.drive, name)
    off = run_filter(sim, sim.drive, name, overrides={"gnss": {"rtk_share": 2.0}})
    assert _rms_from_fixed(run, sim) < 0.15  # the false fixes (0.2-1 m) included
    assert _rms_from_fixed(run, sim) < 0.5 * _rms_from_fixed(off, sim)
    assert np.sqrt(np.mean(run.err_m ** 2)) < np.sqrt(np.mean(run.gnss_err_m ** 2))


def test_nlos_steps_are_down_weighted_for_ekf():
    """urban_nlos (steps of 10-80 m for 5-60 s under a good HDOP): the chords betray the
    steps, and ekf ends well below the fixes' error; without the check it is at or above
    the fixes'."""
    sim = simulate.simulate_drive("urban_nlos", seed=2)
    run = run_filter(sim, sim.drive, "ekf")
    off = run_filter(sim, sim.drive, "ekf", overrides={"gnss": {"nlos_mismatch_m": 0.0}})
    rms = lambda a: float(np.sqrt(np.mean(a ** 2)))  # noqa: E731
    gnss = rms(run.gnss_err_m)
    assert rms(run.err_m) < 0.75 * gnss
    assert rms(off.err_m) > 0.95 * gnss


@pytest.mark.parametrize("scenario", ["open_sky", "tunnels"])
def test_clean_drives_untouched(scenario):
    """Open-sky fixes agree with the odometer: no fix is re-weighted, the parameters stay."""
    sim = simulate.simulate_drive(scenario, seed=1)
    p = config.defaults()
    ep = build_epochs(sim.drive, sim.frame, p)
    mis = chord_mismatch_m(ep, 2.0)
    assert np.nanmax(mis) < 8.0
    ep2, p2 = gnss_error_model(ep, p)
    assert ep2 is ep and p2 is p


@pytest.mark.parametrize("name", ["ekf", "aekf", "fkf"])
def test_outlier_burst_is_down_weighted(name):
    """Fixes 40 m off for 2 s: the chord check scales their sigma up, and the track stays
    within 3.5 m of the truth without a gate (4.5 m with neither the gate nor the check)."""
    from tests.filters import horizontal_error, tiny_drive

    ep, tr = tiny_drive(120.0, seed=11, dr_hz=20.0, outliers=((60.0, 62.0, 40.0),))
    p = config.defaults()
    p["gnss"]["gate"] = False
    ep2, _ = gnss_error_model(ep, p)
    window = (tr.t_s >= 60.0) & (tr.t_s < 62.0) & ep.has_gnss
    assert (ep2.gnss_sd_e[window] > 2.0 * ep.gnss_sd_e[window]).all()
    from gpsdr_cli.filters import get

    res = get(name)(ep, p)
    assert horizontal_error(res, tr)[tr.t_s > 10.0].max() < 3.5
