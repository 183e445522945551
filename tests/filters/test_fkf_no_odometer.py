"""fkf/fafkf on a drive without an odometer (GNSS + gyro only: a phone, a GNSS/IMU logger).

Nothing but the receiver then says when the car stopped: :func:`gpsdr_cli.filters.standstill.gnss_standstill`
takes the standstill from the receiver's (Doppler) speed.  Without it the velocity wandered on
GNSS noise at every stop, a gated multipath burst let its variance grow until one of the burst's
fixes passed the gate, and the velocity jumped and ran away (stop_and_go seed 2, 300 s, old code:
fkf forward / RTS 42.94 / 42.66 m RMSE, fafkf 11.74 / 10.93 m; GNSS alone 3.94 m).
"""

from __future__ import annotations

import copy
from types import SimpleNamespace

import numpy as np
import pytest

from gpsdr_cli import config, filters
from gpsdr_cli.align import build_epochs
from gpsdr_cli.filters import fkf, standstill
from gpsdr_cli.filters.gnss_model import gnss_error_model
from gpsdr_cli.simulate import simulate_drive
from gpsdr_cli.testing.faults import gnss_jump, start_ns, window
from gpsdr_cli.testing.sim import run_filter
from tests.filters import test_fkf as fkf_tests
from tests.filters.reference_fkf import run_reference, tiny_drive

#: m: RMSE bound against truth (new code 0.47-0.74 m, GNSS alone 3.94 m, old code 10.9-42.9 m)
RMSE_BOUND_M = 1.5


@pytest.fixture(scope="module")
def stop_and_go_no_odo():
    sim = simulate_drive("stop_and_go", seed=2, duration_s=300.0)
    drive = copy.deepcopy(sim.drive)
    drive.odo = None
    return sim, drive


def _rmse(sim, drive, name: str, smooth: bool, overrides: dict | None = None):
    run = run_filter(sim, drive, name, smooth, overrides)
    return run.rmse_m, run.gnss_rmse_m, run.result, run.true_speed_mps


@pytest.mark.parametrize("name", ["fkf", "fafkf"])
@pytest.mark.parametrize("smooth", [False, True])
def test_no_odometer_stops_do_not_run_away(stop_and_go_no_odo, name, smooth):
    sim, drive = stop_and_go_no_odo
    rmse, gnss, r, true_speed = _rmse(sim, drive, name, smooth)
    assert rmse < RMSE_BOUND_M, f"{name} smooth={smooth}: {rmse:.2f} m RMSE"
    assert rmse < gnss / 2.0                       # and well below the fixes alone (3.94 m)
    assert r.info["zupt_epochs"] > 0
    # every standstill epoch from the receiver's speed is a true stop (m/s)
    assert np.all(true_speed[r.static] < 0.5)


#: m: positions only (no receiver speed either): new code 1.18-1.69 m, old code 10.5-43.2 m
POSITIONS_ONLY_BOUND_M = 2.5


@pytest.mark.parametrize("name", ["fkf", "fafkf"])
@pytest.mark.parametrize("smooth", [False, True])
def test_positions_only_no_odometer_stops(stop_and_go_no_odo, name, smooth):
    """GGA without RMC/VTG and no odometer: the standstill from the fixes' median positions
    (:func:`gpsdr_cli.filters.standstill.fix_speeds`).  Old code: fkf 43.18 / 42.92 m, fafkf
    11.17 / 10.48 m (forward / RTS); GNSS alone 3.94 m."""
    sim, drive = stop_and_go_no_odo
    drive = copy.deepcopy(drive)
    drive.gnss.speed_mps[:] = np.nan
    drive.gnss.course_deg[:] = np.nan
    rmse, gnss, r, true_speed = _rmse(sim, drive, name, smooth)
    assert r.info["course_source"] == "fix_chords"
    assert rmse < POSITIONS_ONLY_BOUND_M, f"{name} smooth={smooth}: {rmse:.2f} m RMSE"
    assert rmse < gnss
    assert r.info["zupt_epochs"] > 0
    assert np.all(true_speed[r.static] < 1.0)          # m/s: the fixes' speed threshold


def test_gnss_standstill_off_reproduces_runaway(stop_and_go_no_odo):
    """gnss_standstill_speed_mps = coast_acc_psd = no_odo_gate_reset_s = 0 is the old
    behaviour: the bound above fails there."""
    sim, drive = stop_and_go_no_odo
    old = {"gnss_standstill_speed_mps": 0.0, "coast_acc_psd": 0.0, "no_odo_gate_reset_s": 0.0}
    rmse, _, r, _ = _rmse(sim, drive, "fkf", False, {"fkf": old})
    assert r.info["zupt_epochs"] == 0
    assert rmse > 10.0 * RMSE_BOUND_M                # 42.94 m


def test_gnss_standstill_intervals():
    """Static between two fixes when both, and every fix in the window before the later one,
    are below the speed; a fix without a speed or a gap > 2 s breaks it."""
    t = np.arange(0.0, 6.0, 0.1)                      # s, epochs at 10 Hz
    n = len(t)
    has = np.zeros(n, bool)
    has[::5] = True                                   # fixes at 2 Hz: 0.0, 0.5, ..., 5.5 s
    speed = np.full(n, np.nan)
    #               0.0  0.5  1.0  1.5  2.0  2.5  3.0  3.5  4.0  4.5  5.0  5.5 s
    speed[has] = [2.0, 0.1, 0.1, 0.2, 0.1, 0.9, 0.1, 0.1, 0.1, np.nan, 0.1, 0.1]
    ep = SimpleNamespace(has_gnss=has, gnss_speed_mps=speed)
    p = config.defaults()
    p["fkf"]["gnss_standstill_window_s"] = 1.25
    st = standstill.gnss_standstill(ep, t, p)
    expected = np.zeros(n, bool)
    # the interval ending at 1.0 s sees 2.0 m/s at 0.0 s in its window [-0.25, 1.0]; those
    # ending at 1.5 and 2.0 s are still; 2.5 s (0.9 m/s) breaks it, and stays in the window
    # [2.25, 3.5]; 4.0 s closes a still window; 4.5 s has no speed and is in [4.25, 5.5]
    for a, b in ((1.0, 1.5), (1.5, 2.0), (3.5, 4.0)):
        expected[(t > a + 1e-9) & (t <= b + 1e-9)] = True
    np.testing.assert_array_equal(st, expected)
    p["fkf"]["gnss_standstill_speed_mps"] = 0.0       # off
    assert not standstill.gnss_standstill(ep, t, p).any()


def test_odometer_drive_ignores_gnss_standstill():
    """With an odometer the standstill stays the odometer's: the new keys change nothing."""
    sim = simulate_drive("stop_and_go", seed=2, duration_s=120.0)
    out = []
    for thr in (0.5, 5.0):
        p = config.defaults()
        p["filter"]["name"] = "fkf"
        p["fkf"]["gnss_standstill_speed_mps"] = thr
        ep = build_epochs(sim.drive, sim.frame, p)
        out.append(filters.get("fkf")(ep, p))
    np.testing.assert_array_equal(out[0].e, out[1].e)
    np.testing.assert_array_equal(out[0].static, out[1].static)


@pytest.mark.parametrize("kind", ["fkf", "fafkf"])
@pytest.mark.parametrize("mode", ["nr", "fr"])
@pytest.mark.parametrize("smooth", [False, True])
def test_kernel_reproduces_the_reference_without_odometer(kind: str, mode: str, smooth: bool):
    """60 s on a circle, a 10-s stop (standstill from the receiver's speed) and a 10-s GNSS
    gap (no speed measured: the zero-acceleration rows, [fkf] coast_acc_psd): kernel and plain
    reference agree to the reference tolerance."""
    drive, frame, _ = tiny_drive(60.0, turn_radps=0.05, stop=(20, 30), gnss_gap=(40, 50))
    drive.odo = None
    params = config.merge(config.defaults(), {"fkf": {"check_spd": True, "mode": mode},
                                              "filter": {"smooth": smooth}})
    if kind == "fafkf" and smooth:
        params["fafkf"]["weights"] = "shares"         # the fused RTS (the reference's)
    epochs = build_epochs(drive, frame, params)
    result = filters.get(kind)(epochs, params)
    assert result.info["zupt_epochs"] > 0 and result.info["coast_updates"] > 0
    assert result.info["spd_failures"] == 0
    # the reference on what the filter registry gives the kernel, the GNSS model's epochs and
    # parameters: build_epochs dropped the simulated receiver's exact-zero speeds at the
    # stop's hard edges (0.2 s each side: gnss_model.clamped_speeds), and without them the
    # chord check calls the drive NLOS
    model_epochs, model_params = gnss_error_model(epochs, params)
    ref = run_reference(fkf.prepare(model_epochs, model_params), kind, smooth=smooth)
    fkf_tests.assert_matches_reference(result, ref)


def test_gnss_standstill_bridges_an_outage_at_a_stop():
    """A 5-s outage between still fixes at the same place with the gyro heading unchanged is
    a stop; the same outage across a 30-deg turn, or with the fixes 20 m apart, is not."""
    t = np.arange(0.0, 12.0, 0.1)                     # s
    n = len(t)
    has = np.zeros(n, bool)
    has[::2] = True
    has[(t > 4.0 + 1e-9) & (t < 9.0 - 1e-9)] = False   # outage: fixes at 4.0 and 9.0 s
    zeros = np.zeros(n)
    ep = SimpleNamespace(has_gnss=has, gnss_speed_mps=np.where(has, 0.1, np.nan),
                         gnss_e=zeros.copy(), gnss_n=zeros.copy(),
                         gnss_sd_e=np.full(n, 2.0), gnss_sd_n=np.full(n, 2.0))
    p = config.defaults()
    gap = (t > 4.0 + 1e-9) & (t <= 9.0 + 1e-9)
    straight = (t, np.zeros(n))
    assert standstill.gnss_standstill(ep, t, p, heading=straight)[gap].all()
    assert not standstill.gnss_standstill(ep, t, p)[gap].any()          # no gyro: no bridge
    turned = (t, np.where(t > 6.0, np.radians(30.0), 0.0))
    assert not standstill.gnss_standstill(ep, t, p, heading=turned)[gap].any()
    ep.gnss_e[t >= 9.0 - 1e-9] = 20.0                  # m: beyond 3 sigma of the two fixes (12 m)
    assert not standstill.gnss_standstill(ep, t, p, heading=straight)[gap].any()


#: s: a 6-s reflection 75 m away while the car stands (the stop lasts from 29 to 221 s), the
#: receiver's speed missing from 2 s before it to 2 s after, so nothing says the car stands
REFLECTION_AT_S, REFLECTION_S = 32.0, 6.0


@pytest.mark.parametrize("name", ["fkf", "fafkf"])
def test_a_gate_reset_moves_the_position_not_the_velocity(stop_and_go_no_odo, name):
    """The gate resets after 3 s of rejected fixes (``[fkf] no_odo_gate_reset_s``).  As a
    plain row, the first fix taken then read the 75-m offset the model had predicted 3 s of
    velocity variance for as velocity: fkf 47 m/s, fafkf 33 m/s on a car standing still,
    tracks 12.79 and 16.48 m RMSE against the fixes' 10.87 m (decisions/0080).  The reset's
    fix no longer corrects the velocity and acceleration: 12 and 13 m/s, 7.72 and 9.95 m."""
    sim, drive = stop_and_go_no_odo
    jumped = gnss_jump(drive, REFLECTION_AT_S, distance_m=75.0, bearing_deg=50.0,
                       duration_s=REFLECTION_S)
    quiet = window(jumped.gnss.t_ns, start_ns(drive), REFLECTION_AT_S - 2.0, REFLECTION_S + 4.0)
    jumped.gnss.speed_mps[quiet] = np.nan
    jumped.gnss.course_deg[quiet] = np.nan
    r = run_filter(sim, jumped, name, pipeline=True)
    t_s = (r.epochs.t_ns - r.epochs.t_ns[0]) / 1e9
    near = (t_s >= REFLECTION_AT_S) & (t_s <= REFLECTION_AT_S + REFLECTION_S + 10.0)
    assert np.all(r.true_speed_mps[near] < 0.01)
    assert r.result.info["gate_resets"] > 0
    speed = np.hypot(r.result.v_e, r.result.v_n)[near]
    assert speed.max() < 20.0, f"{name}: {speed.max():.1f} m/s while standing"
    assert r.rmse_m < r.gnss_rmse_m, f"{name}: {r.rmse_m:.2f} m, fixes {r.gnss_rmse_m:.2f} m"
