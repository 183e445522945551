"""The compiled ekf/aekf kernels reproduce the plain numpy reference to 1e-9 relative."""

from __future__ import annotations

import numpy as np
import pytest

from gpsdr_cli.config import defaults
from gpsdr_cli.filters import aekf as aekf_module
from gpsdr_cli.filters import get

from . import tiny_drive
from .reference_aekf import reference_filter

#: relative tolerance between kernel and reference on the track (position, its variances,
#: NIS), dimensionless, relative to each array's largest magnitude
RTOL = 1e-9
#: the same for velocity and the hidden states (acceleration, drift, scale): round-off
#: differences of the block/upper-triangle arithmetic are amplified by the 1/v^2 of the
#: heading-rate row when the vehicle restarts from a stop (measured up to 3e-8 for a few epochs)
RTOL_HIDDEN = 1e-7

OPTIONS = {
    "plain": {},
    "no_gate": {"gnss": {"gate": False}},
    "innovation_factor": {"adaptive": {"innovation_factor": True}},
    "fading": {"adaptive": {"fading": True, "fading_lambda": 1.05}},
    "sage_husa": {"adaptive": {"sage_husa": True}},
    "no_standstill": {"standstill": {"enabled": False}},  # also exercises a gate reset
    "continuous_pdop": {"gnss": {"pdop_mode": "continuous"}},
    "drift_always_consider": {"aekf": {"drift_consider": "always"}},
    "heading_consider": {"aekf": {"heading_consider": True}},
    "drift_never_consider_decay": {"aekf": {"drift_consider": "never", "drift_mean_decay": True}},
    "turn_skip": {"aekf": {"turn_propagation": True, "turn_omega_row": "skip"}},
    "turn_lateral": {"aekf": {"turn_propagation": True, "turn_omega_row": "lateral"}},
    "turn_no_standstill": {"aekf": {"turn_propagation": True}, "standstill": {"enabled": False}},
    "gate_inflate": {"gnss": {"gate_mode": "inflate", "gate_warmup_fixes": 0}},
    "odo_along_track": {"aekf": {"odo_along_track": True}},
    "gate_inflate_innovation": {"gnss": {"gate_mode": "inflate"},
                                "adaptive": {"innovation_factor": True}},
    "gate_reject_no_warmup": {"gnss": {"gate_mode": "reject", "gate_warmup_fixes": 0}},
    "no_heading_floor": {"aekf": {"heading_floor": False, "odo_along_track": False,
                                  "lateral_acc_only": "never"}},
    "lateral_acc_always": {"aekf": {"lateral_acc_only": "always"},
                           "standstill": {"zupt_keeps_position": "always"}},
    "no_whitening_no_velocity": {"aekf": {"innovation_whitening": False, "gnss_velocity": False}},
    "whitening_fast": {"aekf": {"whitening_b": 0.9, "whitening_max": 4.0}},
    "whitening_sage_husa": {"aekf": {"innovation_whitening": True},
                            "adaptive": {"sage_husa": True}},
    "whitening_on": {"aekf": {"innovation_whitening": True}},
    "no_gnss_err_states": {"aekf": {"gnss_err_states": False}},
    "no_gnss_err_states_whitening": {"aekf": {"gnss_err_states": False, "innovation_whitening": True}},
    "gnss_err_time_only": {"aekf": {"gnss_err_dist_m": 0.0, "gnss_err_tau_s": 5.0}},
}


@pytest.fixture(scope="module")
def drive():
    return tiny_drive(70.0, seed=3, dr_hz=20.0, gyro_bias_radps=0.02, odo_scale=1.03,
                      outages=((20.0, 32.0),), stops=((45.0, 52.0),),
                      bad_pdop=((5.0, 12.0, 4.0), (55.0, 62.0, 8.0)),
                      outliers=((14.0, 15.0, 40.0),))


def _close(a: np.ndarray, b: np.ndarray, what: str, rtol: float = RTOL) -> None:
    scale = max(float(np.max(np.abs(b))), 1e-300)
    np.testing.assert_allclose(a, b, rtol=rtol, atol=rtol * scale, err_msg=what)


@pytest.mark.parametrize("name", ["ekf", "aekf"])
@pytest.mark.parametrize("option", list(OPTIONS))
@pytest.mark.parametrize("smooth", [False, True])
def test_kernel_matches_reference(drive, name, option, smooth, monkeypatch):
    epochs, _ = drive
    # several checkpoint segments (one ends on a GNSS epoch, none divides the drive evenly)
    monkeypatch.setattr(aekf_module, "SEGMENT_EPOCHS", 257)
    params = defaults()
    for sec, vals in OPTIONS[option].items():
        params[sec].update(vals)
    params["filter"]["smooth"] = smooth
    res = get(name)(epochs, params)
    ref = reference_filter(epochs, params, adaptive=(name == "aekf"))
    x, P = ref["x"], ref["P"]
    _close(res.e, x[:, 0], "e")
    _close(res.n, x[:, 3], "n")
    _close(res.v_e, x[:, 1], "v_e", RTOL_HIDDEN)
    _close(res.v_n, x[:, 4], "v_n", RTOL_HIDDEN)
    _close(res.extras["a_e"], x[:, 2], "a_e", RTOL_HIDDEN)
    _close(res.extras["a_n"], x[:, 5], "a_n", RTOL_HIDDEN)
    _close(-res.extras["gyro_bias_radps"], x[:, 6], "eps", RTOL_HIDDEN)
    _close(res.extras["odo_scale"], x[:, 7], "k_s", RTOL_HIDDEN)
    _close(res.var_e, P[:, 0, 0], "var_e")
    _close(res.var_n, P[:, 3, 3], "var_n")
    _close(res.cov_en, P[:, 0, 3], "cov_en")
    np.testing.assert_array_equal(res.gnss_used, ref["gnss_used"])
    np.testing.assert_array_equal(res.gnss_rejected, ref["gnss_rejected"])
    np.testing.assert_array_equal(res.static, ref["static"])
    m = np.isfinite(ref["nis"])
    np.testing.assert_array_equal(np.isfinite(res.nis), m)
    _close(res.nis[m], ref["nis"][m], "nis")


@pytest.mark.parametrize("name", ["ekf", "aekf"])
@pytest.mark.parametrize("smooth", [False, True])
@pytest.mark.parametrize("gnss_vel", [True, False])
def test_kernel_matches_reference_without_an_odometer(name, smooth, gnss_vel, monkeypatch):
    """GNSS and gyro only: the standstill from the GNSS (aekf.odometer_inputs) and, with
    positions only, no GNSS error states -- kernel and reference alike."""
    epochs, _ = tiny_drive(70.0, seed=5, dr_hz=20.0, gyro_bias_radps=0.02, odo=False,
                           outages=((20.0, 26.0),), stops=((40.0, 50.0),), gnss_vel=gnss_vel)
    monkeypatch.setattr(aekf_module, "SEGMENT_EPOCHS", 257)
    params = defaults()
    params["filter"]["smooth"] = smooth
    res = get(name)(epochs, params)
    assert res.info["gnss_standstill_epochs"] > 100  # the 10-s stop at 20 Hz, about
    assert res.info["gnss_err_states"] is gnss_vel
    ref = reference_filter(epochs, params, adaptive=(name == "aekf"))
    x, P = ref["x"], ref["P"]
    _close(res.e, x[:, 0], "e")
    _close(res.n, x[:, 3], "n")
    _close(res.v_e, x[:, 1], "v_e", RTOL_HIDDEN)
    _close(res.var_e, P[:, 0, 0], "var_e")
    np.testing.assert_array_equal(res.static, ref["static"])
    np.testing.assert_array_equal(res.gnss_used, ref["gnss_used"])
