"""RTS smoothing of the ekf/aekf forward pass (gpsdr_cli/filters/smoothing.py)."""

from __future__ import annotations

import numpy as np
import pytest

from gpsdr_cli.config import defaults
from gpsdr_cli.filters import get

from . import horizontal_error, tiny_drive


@pytest.fixture(scope="module")
def outage_drive():
    return tiny_drive(200.0, seed=21, dr_hz=20.0, outages=((80.0, 120.0),),
                      stops=((150.0, 165.0),))


@pytest.mark.parametrize("name", ["ekf", "aekf"])
def test_smoother_bridges_outage(name, outage_drive):
    """Across a 40 s outage the smoothed error is much lower than the forward one.

    Measured (seed 21): forward max 1.1 m (5-10 m before the heading floor and the
    along-track odometer), smoothed 0.5 m; bounds: smoothed max inside the outage
    < 2 m and < 60 % of the forward max; overall RMSE lower.
    """
    ep, tr = outage_drive
    p = defaults()
    p["aekf"]["check_spd"] = True
    fwd = get(name)(ep, p)
    p["filter"]["smooth"] = True
    sm = get(name)(ep, p)
    assert sm.info["smoothed"] and not fwd.info["smoothed"]
    e_f, e_s = horizontal_error(fwd, tr), horizontal_error(sm, tr)
    out = (tr.t_s > 80.0) & (tr.t_s < 120.0)
    assert e_s[out].max() < 2.0
    assert e_s[out].max() < 0.6 * e_f[out].max()
    assert np.sqrt(np.mean(e_s ** 2)) < np.sqrt(np.mean(e_f ** 2))


@pytest.mark.parametrize("name", ["ekf", "aekf"])
def test_smoothed_covariance_never_larger(name, outage_drive):
    """P_s <= P_f (position variances), equal at the last epoch; smoothed sigmas honest.

    RTS is optimal only over an optimal forward pass: with consider states in outages
    (the default: drift, the lateral row's velocity and position, the odometer's
    cross-track gains) the forward gains are deliberately suboptimal and P_s may
    exceed P_f slightly (measured 16 % in the second before an outage, where the
    receiver velocity made P_f small), so the strict check runs without them and
    the default gets 25 %.
    """
    ep, tr = outage_drive
    p = defaults()
    fwd_d = get(name)(ep, p)
    p["filter"]["smooth"] = True
    sm_d = get(name)(ep, p)
    assert np.all(sm_d.var_e <= 1.25 * fwd_d.var_e) and np.all(sm_d.var_n <= 1.25 * fwd_d.var_n)
    p = defaults()
    p["aekf"].update(drift_consider="never", lateral_acc_only="never", odo_along_track=False)
    p["standstill"]["zupt_keeps_position"] = "never"
    fwd = get(name)(ep, p)
    p["filter"]["smooth"] = True
    sm = get(name)(ep, p)
    tol = 1e-9 * np.maximum(fwd.var_e, 1.0)
    assert np.all(sm.var_e <= fwd.var_e + tol)
    assert np.all(sm.var_n <= fwd.var_n + tol)
    assert np.all(sm.var_e > 0) and np.all(sm.var_n > 0)
    assert np.all(sm.cov_en ** 2 < sm.var_e * sm.var_n)
    assert sm.e[-1] == fwd.e[-1] and sm.var_e[-1] == fwd.var_e[-1]
    # normalised smoothed error: RMS of err/sigma within a factor 3 of 1 (consistency)
    err = horizontal_error(sm, tr)[tr.t_s > 5.0]
    sig = np.sqrt(sm.var_e + sm.var_n)[tr.t_s > 5.0]
    z = np.sqrt(np.mean((err / sig) ** 2))
    assert 0.2 < z < 3.0


def test_smoothing_keeps_static_hold(outage_drive):
    """During the stop the smoothed speed stays ~0 (the static hold is in the prior rebuild)."""
    ep, tr = outage_drive
    p = defaults()
    p["filter"]["smooth"] = True
    sm = get("aekf")(ep, p)
    stop = (tr.t_s > 152.0) & (tr.t_s < 163.0)
    assert np.hypot(sm.v_e[stop], sm.v_n[stop]).max() < 0.02
