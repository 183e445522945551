"""fafkf (Tang et al. fuzzy adaptive federated filter): kernel against the numpy reference,
adaptation to a GNSS noise jump, fusion weights, never-NaN/never-diverge drives."""

from __future__ import annotations

import numpy as np
import pytest

from gpsdr_cli import config
from gpsdr_cli.align import build_epochs
from gpsdr_cli.errors import ConfigError
from gpsdr_cli.filters import fkf, get
from tests.filters.reference_fkf import run_reference, tiny_drive, two_filter
from tests.filters.test_fkf import (
    CASES,
    TRACK_KEYS,
    _assert_sane,
    _errors,
    _params,
    _rmse,
    _with_pdop,
    assert_matches_reference,
    survival_case,
)

#: fafkf's bounds on the horizontal RMS error (m) for the drives of test_fkf.CASES; measured
#: worst over modes/weights/smoothing: 2.3, 47, 0.9, 3.5, 2.8, 1.2 (gyro bias: 5.2 in NR with
#: block weights since the q_w random walk went from 0.01 to 0.005 rad/sqrt(s))
FAFKF_BOUNDS = {"standstill_4_min": 3.5, "gnss_gone_10_min": 60.0, "no_dr_stream": 1.5,
                "no_gnss_stream": 10.0, "gyro_bias_4_deg_s": 6.0, "odometer_5_pct_off": 2.0}


@pytest.fixture(scope="module")
def busy_drive():
    """60 s: a circle, a 10 s stop, a 10 s GNSS gap and GNSS noise x4 from 35 s."""
    return tiny_drive(60.0, turn_radps=0.05, stop=(20, 30), gnss_gap=(40, 50),
                      gnss_sd_jump=(35.0, 4.0))


@pytest.mark.parametrize("mode", ["nr", "fr"])
@pytest.mark.parametrize("weights", ["shares", "scalar", "block"])
@pytest.mark.parametrize("normalisation", ["share", "log"])
def test_fafkf_kernel_reproduces_the_reference(busy_drive, mode: str, weights: str,
                                               normalisation: str) -> None:
    drive, frame, _ = busy_drive
    params = _params(fkf={"mode": mode}, fafkf={"weights": weights,
                                                "normalisation": normalisation})
    epochs = build_epochs(drive, frame, params)
    result = get("fafkf")(epochs, params)
    ref = run_reference(fkf.prepare(epochs, params), "fafkf")
    assert_matches_reference(result, ref)
    assert np.array_equal(result.gnss_used, ref["gnss_used"])
    b = result.extras["beta_gnss"]
    assert np.allclose(b, ref["beta"][:, 0], rtol=1e-9, atol=1e-12, equal_nan=True)
    assert result.info["r_adaptations"] > 0
    _assert_sane(result, len(epochs))


def test_fafkf_papers_covariance_matching_reproduces_the_reference(busy_drive) -> None:
    """``[fafkf] remove_residual_mean = false``: Tang et al.'s mean of r r^T."""
    drive, frame, _ = busy_drive
    params = _params(fafkf={"remove_residual_mean": False})
    epochs = build_epochs(drive, frame, params)
    result = get("fafkf")(epochs, params)
    ref = run_reference(fkf.prepare(epochs, params), "fafkf")
    assert_matches_reference(result, ref)
    assert result.info["r_adaptations"] > 0


@pytest.mark.parametrize("mode", ["nr", "fr"])
def test_fafkf_rts_smoothing_reproduces_the_reference(busy_drive, mode: str) -> None:
    """Weights "shares": the fusion is covariance-weighted, so the fused RTS of fkf applies."""
    drive, frame, _ = busy_drive
    params = _params(fkf={"mode": mode}, fafkf={"weights": "shares"}, filter={"smooth": True})
    epochs = build_epochs(drive, frame, params)
    result = get("fafkf")(epochs, params)
    assert result.info["smoothing"] == "rts_fused"
    assert_matches_reference(result, run_reference(fkf.prepare(epochs, params), "fafkf",
                                                   smooth=True))
    _assert_sane(result, len(epochs))


@pytest.mark.parametrize("weights", ["shares", "block"])
def test_fafkf_kernel_reproduces_the_reference_across_multipath_regimes(busy_drive,
                                                                       weights: str) -> None:
    """eps's regime moving between clear and obstructed sky (blended in a 10-s window)."""
    drive, frame, _ = busy_drive
    params = _params(fkf={"gnss_err_window_s": 10.0}, fafkf={"weights": weights},
                     filter={"smooth": weights == "shares"})
    epochs = build_epochs(drive, frame, params)
    _with_pdop(epochs, (epochs.t_ns - epochs.t_ns[0]) / 1e9)
    prep = fkf.prepare(epochs, params)
    assert prep.eps_w.max() == 1.0
    result = get("fafkf")(epochs, params)
    assert_matches_reference(result, run_reference(prep, "fafkf", smooth=weights == "shares"))
    _assert_sane(result, len(epochs))


@pytest.mark.parametrize("mode", ["nr", "fr"])
def test_fafkf_smoothing_reproduces_the_reference(busy_drive, mode: str) -> None:
    """The paper's convex weights: not a Kalman posterior, smoothed forward + backward."""
    drive, frame, _ = busy_drive
    params = _params(fkf={"mode": mode}, fafkf={"weights": "scalar"}, filter={"smooth": True})
    epochs = build_epochs(drive, frame, params)
    result = get("fafkf")(epochs, params)
    assert result.info["smoothing"] == "forward_backward"
    f = run_reference(fkf.prepare(epochs, params), "fafkf")
    b = run_reference(fkf.prepare(fkf.reverse_epochs(epochs), params), "fafkf")
    b = {k: v[::-1] * (-1.0 if k in ("v_e", "v_n") else 1.0) for k, v in b.items()
         if k in TRACK_KEYS}
    assert_matches_reference(result, two_filter(f, b))
    _assert_sane(result, len(epochs))


@pytest.mark.parametrize("seed", [0, 1])
@pytest.mark.parametrize("mode", ["nr", "fr"])
def test_fafkf_adapts_to_a_gnss_noise_jump(seed: int, mode: str) -> None:
    """True GNSS noise x5 from 150 s while the receiver keeps reporting 1 m (Tang et al.'s case:
    an error model that changes).  FAFKF's R follows (x25 in variance), FKF's cannot."""
    drive, frame, truth = tiny_drive(300.0, turn_radps=0.02, gnss_sd_jump=(150.0, 5.0),
                                     seed=seed)
    params = _params(fkf={"mode": mode})
    epochs = build_epochs(drive, frame, params)
    t = (epochs.t_ns - epochs.t_ns[0]) / 1e9
    plain = get("fkf")(epochs, params)
    adaptive = get("fafkf")(epochs, params)
    _assert_sane(adaptive, len(epochs))
    after = t > 170.0
    var_fkf = np.mean(_errors(plain, epochs, truth)[after] ** 2)
    var_fafkf = np.mean(_errors(adaptive, epochs, truth)[after] ** 2)
    ratio = var_fafkf / var_fkf
    # measured FR 0.20 .. 0.33, NR 0.33 .. 0.51 (seeds 0-2): fafkf's variance is the same
    # as with the q_w random walk 0.01 (NR 10 m^2), fkf's dropped (seed 0: 22 -> 20 m^2).
    # The paper's 55 % reduction is required of the default FR mode; NR: 40 %.
    bound = 0.5 if mode == "fr" else 0.6
    assert ratio < bound, f"fafkf/fkf error variance after the jump = {ratio:.3f}"
    rf = adaptive.extras["r_factor_gnss_e"]
    early = rf[(t > 20) & (t < 145)]                          # near nominal while consistent
    assert np.median(early) < 1.2 and np.percentile(early, 95) < 3.0
    assert 10.0 < np.median(rf[after]) < 60.0                 # true factor 25 (variance)
    assert np.all(rf >= 1.0) and np.all(rf <= 100.0)          # clamped


def test_gnss_weight_drops_when_gnss_noise_jumps() -> None:
    drive, frame, _ = tiny_drive(300.0, turn_radps=0.02, gnss_sd_jump=(150.0, 5.0))
    params = _params()
    epochs = build_epochs(drive, frame, params)
    t = (epochs.t_ns - epochs.t_ns[0]) / 1e9
    before = (t > 30) & (t < 150)
    jump = (t >= 150) & (t < 155)
    beta = get("fafkf")(epochs, params).extras["beta_gnss"]
    # measured 0.726 before, 0.55 in the 5 s until R has caught up
    assert np.mean(beta[jump]) < np.mean(beta[before]) - 0.1
    # with R capped at 4x it cannot absorb the 25x: the GNSS weight stays down (0.48)
    capped = _params(fafkf={"r_max_factor": 4.0})
    beta_c = get("fafkf")(epochs, capped).extras["beta_gnss"]
    assert np.mean(beta_c[t > 160]) < np.mean(beta_c[before]) - 0.15
    assert np.all((beta_c > 0.0) & (beta_c < 1.0))


def test_fafkf_on_the_simulator_open_sky() -> None:
    from gpsdr_cli.simulate import simulate_drive
    sim = simulate_drive("open_sky", seed=1, duration_s=300.0)
    params = _params()
    epochs = build_epochs(sim.drive, sim.frame, params)
    tr = sim.truth
    truth = {"t_ns": tr.t_ns.to_numpy(), "e": tr.e.to_numpy(), "n": tr.n.to_numpy()}
    g = epochs.has_gnss
    raw = np.hypot(epochs.gnss_e[g] - np.interp(epochs.t_ns[g], truth["t_ns"], truth["e"]),
                   epochs.gnss_n[g] - np.interp(epochs.t_ns[g], truth["t_ns"], truth["n"]))
    for smooth in (False, True):
        result = get("fafkf")(epochs, config.merge(params, {"filter": {"smooth": smooth}}))
        _assert_sane(result, len(epochs))
        # 10-minute drive measured 0.92 m forward (raw fixes 1.46 m)
        assert _rmse(_errors(result, epochs, truth)) < min(1.3, _rmse(raw))


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.parametrize(("mode", "weights"), [("fr", "shares"), ("fr", "block"),
                                               ("fr", "scalar"), ("nr", "block")])
def test_fafkf_survives(name: str, mode: str, weights: str) -> None:
    epochs, truth, params = survival_case(name, mode, fafkf={"weights": weights})
    for smooth in (False, True):
        result = get("fafkf")(epochs, config.merge(params, {"filter": {"smooth": smooth}}))
        _assert_sane(result, len(epochs))
        err = _rmse(_errors(result, epochs, truth))
        assert err < FAFKF_BOUNDS[name], (name, mode, weights, smooth, err)


def test_bad_weights_option_is_a_config_error() -> None:
    drive, frame, _ = tiny_drive(5.0)
    params = _params(fafkf={"weights": "matrix"})
    with pytest.raises(ConfigError, match="fafkf.weights"):
        get("fafkf")(build_epochs(drive, frame, params), params)
