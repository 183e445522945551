"""fkf (Tang et al. federated Kalman filter): closed-form pieces, the compiled kernel against
the numpy reference, accuracy against known truth, and the never-NaN/never-diverge cases."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gpsdr_cli import config
from gpsdr_cli.align import build_epochs
from gpsdr_cli.errors import ConfigError
from gpsdr_cli.filters import fkf, get
from gpsdr_cli.filters import kernels_fkf as kf
from tests.filters.reference_fkf import (
    Phi_of,
    Q_of,
    kf_update,
    regime_par,
    run_reference,
    tiny_drive,
    two_filter,
)

#: relative agreement of the compiled kernel with the numpy reference (dimensionless)
REF_RTOL = 1e-9
TRACK_KEYS = ("e", "n", "v_e", "v_n", "var_e", "var_n", "cov_en")


def _params(**sections: dict) -> dict:
    base = {"fkf": {"check_spd": True}}
    for name, values in sections.items():
        base.setdefault(name, {}).update(values)
    return config.merge(config.defaults(), base)


def _errors(result, epochs, truth) -> np.ndarray:
    """Horizontal error per epoch (m) against the generator's truth."""
    te = np.interp(epochs.t_ns, truth["t_ns"], truth["e"])
    tn = np.interp(epochs.t_ns, truth["t_ns"], truth["n"])
    return np.hypot(result.e - te, result.n - tn)


def _rmse(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(x ** 2)))


def _assert_sane(result, n: int) -> None:
    """Finite complete track, every P SPD at every epoch (the kernel's Cholesky check)."""
    assert len(result) == n
    for key in TRACK_KEYS:
        assert np.all(np.isfinite(getattr(result, key))), key
    assert np.all(result.var_e > 0) and np.all(result.var_n > 0)
    assert np.all(result.cov_en ** 2 < result.var_e * result.var_n)
    assert result.info["spd_failures"] == 0


def assert_matches_reference(result, ref: dict) -> None:
    for key in TRACK_KEYS:
        a, b = getattr(result, key), ref[key]
        scale = max(float(np.max(np.abs(b))), 1e-12)
        rel = float(np.max(np.abs(a - b))) / scale
        assert rel < REF_RTOL, f"{key}: kernel vs reference differ by {rel:.2e} relative"


# ---- closed-form pieces ---------------------------------------------------------------

def test_predict_is_phi_p_phi_t_plus_q_with_the_erratum() -> None:
    rng = np.random.default_rng(1)
    A = rng.normal(size=(10, 10))
    P = A @ A.T + np.eye(10)
    x = rng.normal(size=10)
    par = fkf.prepare(build_epochs(tiny_drive(5.0)[0], tiny_drive(5.0)[1], _params()),
                      _params()).par
    for T, static in ((0.1, False), (1.3, False), (0.5, True)):
        for d in (np.ones(10), np.full(10, 1 / math.sqrt(0.3))):
            xk, Pk = x.copy(), P.copy()
            kf.predict(xk, Pk, T, static, par, d)
            Phi = Phi_of(T, static, par, x)
            if not static:
                assert Phi[0, 2] == pytest.approx(T * T / 2)   # erratum: T^2/2, not T^2
            expected = Phi @ P @ Phi.T + np.outer(d, d) * Q_of(T, static, par, x)
            assert np.allclose(Pk, expected, rtol=1e-13, atol=1e-13)
            assert np.allclose(xk, Phi @ x, rtol=1e-13, atol=1e-13)


def test_row_update_is_the_joseph_form() -> None:
    rng = np.random.default_rng(2)
    A = rng.normal(size=(10, 10))
    P = A @ A.T + np.eye(10)
    x = rng.normal(size=10)
    h = np.zeros(10)
    h[[1, 4, 8]] = [0.03, -0.07, 1.0]
    xk, Pk = x.copy(), P.copy()
    kf.update_row(xk, Pk, h, 0.2, 0.01, np.zeros(10), np.zeros(10))
    xr, Pr = kf_update(x, P, h, 0.2, 0.01)
    assert np.allclose(Pk, Pr, rtol=1e-12, atol=1e-12)
    assert np.allclose(xk, xr, rtol=1e-12, atol=1e-12)
    assert np.array_equal(Pk, Pk.T)


@pytest.mark.parametrize(("a", "wrapped"), [
    (math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi / 2, -math.pi / 2),
    (0.3, 0.3), (-7.0, -7.0 + 2 * math.pi), (13.0, 13.0 - 4 * math.pi)])
def test_heading_residuals_wrap_to_half_open_pi(a: float, wrapped: float) -> None:
    assert kf.wrap_pi(a) == pytest.approx(wrapped, abs=1e-12)


def test_chi_square_thresholds() -> None:
    assert fkf.gate_threshold(0.95) == pytest.approx(5.991465, abs=1e-5)   # chi2(2) 95 %
    assert fkf.chi2_1(0.95) == pytest.approx(3.841459, abs=1e-5)           # chi2(1) 95 %


# ---- the kernel against the reference ----------------------------------------------------

@pytest.fixture(scope="module")
def busy_drive():
    """60 s: a circle, a 10 s stop and a 10 s GNSS gap."""
    return tiny_drive(60.0, turn_radps=0.05, stop=(20, 30), gnss_gap=(40, 50))


@pytest.mark.parametrize("mode", ["nr", "fr"])
@pytest.mark.parametrize("smooth", [False, True])
def test_fkf_kernel_reproduces_the_reference(busy_drive, mode: str, smooth: bool) -> None:
    """With eps also decorrelating over 100 m driven (the fafkf reference tests: time only)."""
    drive, frame, _ = busy_drive
    params = _params(fkf={"mode": mode, "gnss_err_dist_m": 100.0}, filter={"smooth": smooth})
    epochs = build_epochs(drive, frame, params)
    result = get("fkf")(epochs, params)
    ref = run_reference(fkf.prepare(epochs, params), "fkf", smooth=smooth)
    assert_matches_reference(result, ref)
    assert np.array_equal(result.gnss_used, ref["gnss_used"])
    _assert_sane(result, len(epochs))


@pytest.mark.parametrize("mode", ["nr", "fr"])
def test_stop_without_fixes_corrects_the_velocity_only(mode: str) -> None:
    """A stop inside a GNSS gap: the zero-velocity rows leave the position (and the GNSS
    error states) alone, in the kernel as in the reference."""
    drive, frame, _ = tiny_drive(60.0, turn_radps=0.05, stop=(25, 35), gnss_gap=(20, 40))
    params = _params(fkf={"mode": mode})
    epochs = build_epochs(drive, frame, params)
    prep = fkf.prepare(epochs, params)
    t_s = (epochs.t_ns - epochs.t_ns[0]) / 1e9
    assert prep.static[(t_s > 27) & (t_s < 33)].all() and not epochs.has_gnss[(t_s > 21) & (t_s < 39)].any()
    result = get("fkf")(epochs, params)
    assert_matches_reference(result, run_reference(prep, "fkf"))
    stopped = np.flatnonzero((t_s > 27.5) & (t_s < 33))
    assert np.ptp(result.e[stopped]) < 1e-6 and np.ptp(result.n[stopped]) < 1e-6


@pytest.mark.parametrize("mode", ["nr", "fr"])
def test_a_stop_leaves_the_heading_alignment_alone(mode: str) -> None:
    """Braking into a stop on a bend: the zero-velocity rows say nothing about the gyro
    heading's alignment error q_w, so it holds through the stop (read through the velocity's
    covariance, one simulated city stop moved it 1.3 -> 10.7 deg, decisions/0023)."""
    drive, frame, _ = tiny_drive(60.0, turn_radps=0.05, stop=(25, 35), gnss_gap=(20, 40))
    params = _params(fkf={"mode": mode})
    epochs = build_epochs(drive, frame, params)
    prep = fkf.prepare(epochs, params)
    t_s = (epochs.t_ns - epochs.t_ns[0]) / 1e9
    ref = run_reference(prep, "fkf")
    assert_matches_reference(get("fkf")(epochs, params), ref)
    stopped = np.flatnonzero(prep.static & (t_s > 21) & (t_s < 39))
    assert len(stopped) > 100
    q_w = ref["q_w"][stopped[0] - 1:stopped[-1] + 1]
    assert np.ptp(q_w) < 1e-12, np.ptp(q_w)


def _with_pdop(epochs, t_s: np.ndarray):
    """PDOP 1.5 (clear sky) except 4.0 (obstructed) from 15 to 35 s and NaN from 50 s."""
    pdop = np.where((t_s >= 15.0) & (t_s < 35.0), 4.0, 1.5)
    epochs.pdop = np.where(t_s >= 50.0, np.nan, pdop)
    return epochs


@pytest.mark.parametrize("mode", ["nr", "fr"])
@pytest.mark.parametrize("smooth", [False, True])
def test_fkf_kernel_reproduces_the_reference_across_multipath_regimes(busy_drive, mode: str,
                                                                     smooth: bool) -> None:
    """eps's regime moving between clear and obstructed sky (10-s window: shares between 0
    and 1, blended models) in the forward pass and the smoother."""
    drive, frame, _ = busy_drive
    params = _params(fkf={"mode": mode, "gnss_err_window_s": 10.0}, filter={"smooth": smooth})
    epochs = build_epochs(drive, frame, params)
    _with_pdop(epochs, (epochs.t_ns - epochs.t_ns[0]) / 1e9)
    prep = fkf.prepare(epochs, params)
    w = prep.eps_w
    assert w.min() == 0.0 and w.max() == 1.0 and np.any((w > 0.0) & (w < 1.0))
    result = get("fkf")(epochs, params)
    ref = run_reference(prep, "fkf", smooth=smooth)
    assert_matches_reference(result, ref)
    _assert_sane(result, len(epochs))


@pytest.mark.parametrize("w", [0.0, 0.25, 0.5, 1.0])
def test_select_eps_blends_rates_and_variances(w: float) -> None:
    """The kernel's per-step eps model equals the reference's (1/tau, 1/D, sd^2 linear in
    the regime; a distance <= 0 adds no rate) to 1e-12 relative."""
    params = _params(fkf={"gnss_err_tau_s": 60.0, "gnss_err_sd_m": 1.0, "gnss_err_dist_m": 0.0,
                          "gnss_err_obstructed_tau_s": 180.0, "gnss_err_obstructed_sd_m": 3.0,
                          "gnss_err_obstructed_dist_m": 50.0})
    drive, frame, _ = tiny_drive(10.0)
    par = fkf.prepare(build_epochs(drive, frame, params), params).par
    got = par.copy()
    kf.select_eps(got, w)
    want = regime_par(par, w)
    for k in (kf.PAR_TAU_EPS, kf.PAR_EPS_SD, kf.PAR_EPS_DIST):
        assert got[k] == pytest.approx(want[k], rel=1e-12)
    # the rate at 10 m/s: 1/60 + 0 at w = 0, 1/180 + 10/50 at w = 1
    x = np.zeros(kf.NX)
    x[kf.IVE] = 10.0
    rate = -math.log(kf.eps_decay(x, 1.0, got))
    assert rate == pytest.approx((1 - w) / 60.0 + w * (1 / 180.0 + 10.0 / 50.0), rel=1e-12)
    assert got[kf.PAR_EPS_SD] ** 2 == pytest.approx((1 - w) * 1.0 + w * 9.0, rel=1e-12)


def test_multipath_regime_is_the_share_of_high_pdop_fixes() -> None:
    """Share of fixes with PDOP >= gnss_err_pdop (without PDOP: base sigma >= gnss_err_sigma_m)
    in a centred window, held from the latest fix (GNSS gaps, the epochs before the first fix:
    the first fix's)."""
    drive, frame, _ = tiny_drive(60.0, gnss_gap=(40, 50))
    params = _params(fkf={"gnss_err_window_s": 0.0})
    epochs = build_epochs(drive, frame, params)
    t_s = (epochs.t_ns - epochs.t_ns[0]) / 1e9
    _with_pdop(epochs, t_s)
    w = fkf.multipath_regime(epochs, params)
    f = np.flatnonzero(epochs.has_gnss)
    assert np.array_equal(w[f], ((t_s[f] >= 15.0) & (t_s[f] < 35.0)).astype(float))
    gap = (t_s > 41.0) & (t_s < 49.0)
    assert np.all(w[gap] == w[f[t_s[f] < 40.0][-1]])        # held across the gap
    params = _params(fkf={"gnss_err_window_s": 10.0})
    w = fkf.multipath_regime(epochs, params)
    k = f[np.argmin(np.abs(t_s[f] - 15.0))]                 # half the window obstructed
    assert w[k] == pytest.approx(0.5, abs=0.05)
    assert w[f[np.argmin(np.abs(t_s[f] - 25.0))]] == 1.0
    assert w[f[np.argmin(np.abs(t_s[f] - 5.0))]] == 0.0
    assert np.all(w[t_s >= 56.0] == 0.0)        # no PDOP: by the base sigma, 1 m < 2.2 m: clear
    params = _params(fkf={"gnss_err_window_s": 0.0, "gnss_err_sigma_m": 1.0})
    w = fkf.multipath_regime(epochs, params)
    assert np.all(w[t_s >= 50.0] == 1.0) and np.all(w[t_s < 15.0] == 0.0)  # 1 m >= 1 m
    params = _params(fkf={"gnss_err_pdop": math.inf, "gnss_err_sigma_m": 1.0})
    assert not fkf.multipath_regime(epochs, params).any()  # one regime: the clear-sky keys


def test_multipath_regimes_on_the_simulated_urban_canyon() -> None:
    """Issue #4: the simulator's urban multipath (4 m per axis, 1/tau = 1/60 s + speed/50 m)
    seen by eps as a 1-m, 60-s time-only error made fkf trust the fixes' slow multipath:
    on this 5-min drive (seed 3) 3.41 m forward, 2.39 m RTS with one regime
    (gnss_err_pdop = inf); with the obstructed-sky model (PDOP >= 2: 3 m, 60 s, 50 m) 2.90 m
    and 1.35 m.  Bounds: forward 10 %, RTS 30 % below the one-regime model."""
    from gpsdr_cli.simulate import simulate_drive

    sim = simulate_drive("urban_canyon", seed=3, duration_s=300.0)
    tr = sim.truth
    truth = {"t_ns": tr.t_ns.to_numpy(), "e": tr.e.to_numpy(), "n": tr.n.to_numpy()}
    rmse = {}
    for label, over in (("two", {}), ("one", {"gnss_err_pdop": math.inf})):
        for smooth in (False, True):
            params = _params(fkf=over, filter={"smooth": smooth})
            epochs = build_epochs(sim.drive, sim.frame, params)
            result = get("fkf")(epochs, params)
            _assert_sane(result, len(epochs))
            rmse[label, smooth] = _rmse(_errors(result, epochs, truth))
    assert rmse["two", False] < 0.9 * rmse["one", False]
    assert rmse["two", True] < 0.7 * rmse["one", True]


def test_two_filter_combination_matches_reference(busy_drive) -> None:
    drive, frame, _ = busy_drive
    params = _params()
    epochs = build_epochs(drive, frame, params)
    f = run_reference(fkf.prepare(epochs, params), "fafkf")
    b = run_reference(fkf.prepare(fkf.reverse_epochs(epochs), params), "fafkf")
    b = {k: (v[::-1] * (-1.0 if k in ("v_e", "v_n") else 1.0)) for k, v in b.items()
         if k in TRACK_KEYS}
    ref = two_filter(f, b)
    def pack(d: dict) -> np.ndarray:
        return np.vstack([d[k] for k in TRACK_KEYS])       # the kernels' layout: rows O_*
    got = fkf.combine_two_filter(pack(f), pack(b))
    assert np.allclose(got, pack(ref), rtol=1e-12, atol=1e-12)


# ---- accuracy against truth ------------------------------------------------------------

@pytest.mark.parametrize("turn", [0.0, 0.1])
def test_fkf_beats_the_raw_fixes(turn: float) -> None:
    drive, frame, truth = tiny_drive(120.0, turn_radps=turn, gnss_sd_m=1.0)
    params = _params()
    epochs = build_epochs(drive, frame, params)
    result = get("fkf")(epochs, params)
    _assert_sane(result, len(epochs))
    err = _errors(result, epochs, truth)
    g = epochs.has_gnss
    raw = np.hypot(epochs.gnss_e[g] - np.interp(epochs.t_ns[g], truth["t_ns"], truth["e"]),
                   epochs.gnss_n[g] - np.interp(epochs.t_ns[g], truth["t_ns"], truth["n"]))
    # measured: 0.49 m against 1.38 m raw (1 m per axis); bound 0.8 m and half the raw error
    assert _rmse(err[epochs.t_ns > epochs.t_ns[0] + 5e9]) < min(0.8, 0.5 * _rmse(raw))
    # the fused velocity follows the truth to 0.3 m/s RMS
    ve = np.interp(epochs.t_ns, truth["t_ns"], truth["v_e"])
    assert _rmse(result.v_e[100:] - ve[100:]) < 0.3


def test_fkf_on_the_simulator_open_sky() -> None:
    from gpsdr_cli.simulate import simulate_drive
    sim = simulate_drive("open_sky", seed=1, duration_s=300.0)
    params = _params()
    epochs = build_epochs(sim.drive, sim.frame, params)
    result = get("fkf")(epochs, params)
    _assert_sane(result, len(epochs))
    tr = sim.truth
    truth = {"t_ns": tr.t_ns.to_numpy(), "e": tr.e.to_numpy(), "n": tr.n.to_numpy()}
    err = _errors(result, epochs, truth)
    g = epochs.has_gnss
    raw = np.hypot(epochs.gnss_e[g] - np.interp(epochs.t_ns[g], truth["t_ns"], truth["e"]),
                   epochs.gnss_n[g] - np.interp(epochs.t_ns[g], truth["t_ns"], truth["n"]))
    # measured 0.34 m with the receiver velocity rows (0.64 m without; raw fixes 1.46 m):
    # bound 0.6 m and raw
    assert _rmse(err) < min(0.6, _rmse(raw))
    smoothed = get("fkf")(epochs, _params(filter={"smooth": True}))
    _assert_sane(smoothed, len(epochs))
    # RTS: measured 0.38 m here (seeds 2, 3: 0.46 and 0.23 m against forward 0.48 and
    # 0.37 m; 10-min drives, seeds 1-3 pooled: 0.32 vs 0.49 m): within 20 % of forward
    assert _rmse(_errors(smoothed, epochs, truth)) < min(0.6, 1.2 * _rmse(err))


# ---- never NaN, never diverge ---------------------------------------------------------

CASES = {
    # name: (tiny_drive kwargs, stream to drop, bound on the horizontal RMS error in m)
    "standstill_4_min": ({"duration_s": 300, "stop": (30, 270), "turn_radps": 0.02}, None, 2.0),
    "gnss_gone_10_min": ({"duration_s": 780, "gnss_gap": (60, 660), "turn_radps": 0.01, "dr_hz": 20},
                         None, 25.0),
    "no_dr_stream": ({"duration_s": 120, "turn_radps": 0.05}, "dr", 1.5),
    "no_gnss_stream": ({"duration_s": 120, "turn_radps": 0.05}, "gnss", 10.0),
    "gyro_bias_4_deg_s": ({"duration_s": 300, "gyro_bias_radps": math.radians(4.0),
                               "turn_radps": 0.05}, None, 3.0),
    "odometer_5_pct_off": ({"duration_s": 300, "odo_scale": 1.05, "turn_radps": 0.05}, None, 1.5),
}


def survival_case(name: str, mode: str, **extra: dict) -> tuple:
    """Epochs, truth and parameters of the CASES drive ``name`` (streams dropped as it says)."""
    kwargs, drop, _ = CASES[name]
    drive, frame, truth = tiny_drive(**kwargs)
    if drop == "dr":
        drive.gyro = drive.odo = None
    if drop == "gnss":
        drive.gnss = None
        extra["frame"] = {"initial_heading_deg": math.degrees(0.7)}
    params = _params(fkf={"mode": mode}, **extra)
    return build_epochs(drive, frame, params), truth, params


@pytest.mark.parametrize("name", list(CASES))
@pytest.mark.parametrize("mode", ["nr", "fr"])
def test_fkf_survives(name: str, mode: str) -> None:
    bound = CASES[name][2]
    epochs, truth, params = survival_case(name, mode)
    for smooth in (False, True):
        result = get("fkf")(epochs, config.merge(params, {"filter": {"smooth": smooth}}))
        _assert_sane(result, len(epochs))
        assert _rmse(_errors(result, epochs, truth)) < bound, (name, mode, smooth)
    if name == "standstill_4_min":
        assert result.static.sum() > 0.9 * 240 * 50       # 240 s at 50 Hz held
    if name == "no_dr_stream":
        assert result.info["local_filters"] == "gnss"
    if name == "no_gnss_stream":
        assert result.info["local_filters"] == "dr"


def test_heading_realignment_without_course_steering() -> None:
    """The paper's one-time alignment (window 0) with a 4 deg/s gyro bias: the drifting
    heading must not drag the track away from the fixes (finite, bounded).  In FR mode the
    fused heading fights the gyro: the GNSS gate then sees most fixes fail and its majority
    rule re-admits them (108 m before that rule, when the gate locked the fixes out)."""
    drive, frame, truth = tiny_drive(300, gyro_bias_radps=math.radians(4.0), turn_radps=0.05)
    for mode, bound in (("fr", 20.0), ("nr", 10.0)):       # measured 10.2 m and 3.1 m
        # the paper's configuration: no course steering, so q_w's random walk must carry
        # the whole bias (0.01 rad/sqrt(s); the steered default 0.005 lets it run away)
        params = _params(fkf={"mode": mode, "heading_course_window_s": 0.0,
                              "heading_err_rw_sd": 0.01, "gnss_velocity": False})
        epochs = build_epochs(drive, frame, params)
        result = get("fkf")(epochs, params)
        _assert_sane(result, len(epochs))
        if mode == "fr":                                   # fused heading fights the gyro
            assert result.info["gate_resets"] > 0
        assert _rmse(_errors(result, epochs, truth)) < bound


def test_course_correction_removes_a_gyro_bias() -> None:
    drive, frame, _ = tiny_drive(120, gyro_bias_radps=math.radians(4.0), turn_radps=0.05)
    params = _params()
    epochs = build_epochs(drive, frame, params)
    prep = fkf.prepare(epochs, params)
    m = np.isfinite(prep.theta)
    true_psi = 0.7 + 0.05 * (epochs.t_ns[m] - epochs.t_ns[0]) / 1e9
    resid = np.angle(np.exp(1j * (prep.theta[m] - true_psi)))
    # without the correction the integrated bias reaches 480 deg; with it: < 3 deg RMS
    assert np.degrees(np.sqrt(np.mean(resid[20:-20] ** 2))) < 3.0


def test_gnss_outlier_is_gated() -> None:
    drive, frame, truth = tiny_drive(60.0)
    k = 150
    drive.gnss.lat_deg[k] += 100.0 / 111_000.0                    # 100 m north jump
    params = _params()
    epochs = build_epochs(drive, frame, params)
    result = get("fkf")(epochs, params)
    i = np.searchsorted(epochs.t_ns, drive.gnss.t_ns[k])
    assert result.gnss_rejected[i] and not result.gnss_used[i]
    assert result.nis[i] > fkf.gate_threshold(params["gnss"]["gate_prob"])
    assert result.info["gnss_rejected"] == 1
    assert np.max(_errors(result, epochs, truth)[epochs.t_ns > epochs.t_ns[0] + 5e9]) < 3.0


def _every_7th_fix_off(drive, offset_m: float, start: int = 0) -> np.ndarray:
    """Fixes start, start+7, ... moved ``offset_m`` north (a second receiver merged in, the
    fault suite's duplicates); returns the moved indices."""
    k = np.arange(start, len(drive.gnss.t_ns), 7)
    drive.gnss.lat_deg[k] += offset_m / 111_000.0
    return k


@pytest.mark.parametrize(("name", "bound"), [("fkf", 1.0), ("fafkf", 3.5)])
def test_first_fix_off_does_not_lock_the_gate(name: str, bound: float) -> None:
    """Every 7th fix 11 m off, the first one included, at a standstill: the filter starts on
    a bad fix.  The gate waits for gnss.gate_warmup_fixes accepted fixes, so the state settles
    on the majority and the copies are rejected.  fkf before the warm-up and the majority
    rule: 10.8 m RMSE, every good fix rejected and only the copies taken; now 0.50 m.  fafkf
    2.4 m: its adaptive R grows with the copies' residuals until they pass.  Bound (m) on the
    RMSE after 5 s."""
    drive, frame, truth = tiny_drive(120.0, gnss_sd_m=0.5, stop=(0.0, 20.0))
    bad = _every_7th_fix_off(drive, 11.0)
    params = _params()
    epochs = build_epochs(drive, frame, params)
    result = get(name)(epochs, params)
    _assert_sane(result, len(epochs))
    err = _errors(result, epochs, truth)
    assert _rmse(err[epochs.t_ns > epochs.t_ns[0] + 5e9]) < bound
    i = np.searchsorted(epochs.t_ns, drive.gnss.t_ns[bad])
    good = np.setdiff1d(np.flatnonzero(epochs.has_gnss), i)
    assert result.gnss_used[good].mean() > 0.99
    if name == "fkf":
        assert result.gnss_rejected[i[1:]].all()


def test_gate_majority_rule_ends_a_lock_out() -> None:
    """From 40 s on all fixes but every 7th sit 15 m north (the majority moved): the
    remaining old ones keep passing the gate, so 'every fix rejected for gate_reset_s'
    never happens; the majority rule (most recent fixes gated) re-admits the majority.
    Bound: within 3.5 m of the majority 25 s after the step (locked: 15 m; with 0.05-s
    odometer distance rows the GNSS error states eps_e, eps_n take up to 3.3 m of the
    unphysical 15-m step and release it with tau_eps = 60 s: 3.26 m; 1.13 m with the
    1-mm rows at every 50-Hz record)."""
    drive, frame, truth = tiny_drive(120.0)
    t_s = (drive.gnss.t_ns - drive.gnss.t_ns[0]) / 1e9
    late = np.flatnonzero(t_s >= 40.0)
    moved = late[(late - late[0]) % 7 != 0]
    drive.gnss.lat_deg[moved] += 15.0 / 111_000.0
    params = _params(fkf={"gnss_velocity": False})          # the position gate alone
    epochs = build_epochs(drive, frame, params)
    result = get("fkf")(epochs, params)
    _assert_sane(result, len(epochs))
    err = _errors(result, epochs, truth)
    t = (epochs.t_ns - epochs.t_ns[0]) / 1e9
    assert np.max(np.abs(err[t > 65.0] - 15.0)) < 3.5
    assert result.info["gate_resets"] > 0


def test_despike_is_the_median_of_five_rule() -> None:
    """The compiled despiker equals the numpy statement of the rule: a sample further than
    the threshold from the median of its 5-sample window (ends padded) becomes that median;
    a window with a NaN leaves the sample alone.  Exact equality (same values selected)."""
    rng = np.random.default_rng(3)
    for n in (5, 6, 17, 5000):
        v = rng.normal(size=n)
        v[rng.random(n) < 0.05] += 10.0
        if n > 100:
            v[rng.random(n) < 0.01] = np.nan
        padded = np.concatenate((v[:1].repeat(2), v, v[-1:].repeat(2)))
        med = np.median(np.lib.stride_tricks.sliding_window_view(padded, 5), axis=1)
        bad = np.abs(v - med) > 1.0
        out, count = fkf.despike(v, 1.0)
        np.testing.assert_array_equal(out, np.where(bad, med, v))
        assert count == int(bad.sum())


def test_bad_mode_is_a_config_error() -> None:
    drive, frame, _ = tiny_drive(5.0)
    params = _params(fkf={"mode": "zr"})
    with pytest.raises(ConfigError, match="fkf.mode"):
        get("fkf")(build_epochs(drive, frame, params), params)


def test_odometer_scale_taken_from_the_gnss_speed() -> None:
    """An odometer reading 5 % high is scaled back to the GNSS speed (0.5 % tolerance), and the
    fused track then keeps within 1.0 m RMS (measured 0.5 m) instead of riding the scale."""
    drive, frame, truth = tiny_drive(300, odo_scale=1.05, turn_radps=0.05)
    params = _params()
    epochs = build_epochs(drive, frame, params)
    prep = fkf.prepare(epochs, params)
    assert prep.info["odo_scale"] == pytest.approx(1.0 / 1.05, rel=0.005)
    o = np.flatnonzero(np.isfinite(prep.dist))
    speed = prep.dist[o] / prep.t_m[o]
    assert np.median(speed) == pytest.approx(10.0, rel=0.005)        # tiny_drive: 10 m/s
    off = fkf.prepare(epochs, config.merge(params, {"fkf": {"odo_scale_window_s": 0.0}}))
    assert off.info["odo_scale"] == 1.0
    assert _rmse(_errors(get("fkf")(epochs, params), epochs, truth)) < 1.0


def test_distance_rows_keep_the_distance_and_follow_the_heading_epochs() -> None:
    """100-Hz odometer records at the epochs 0, 2, 4, ... (gyro-only epochs in between),
    0.05-s slots, heading epochs every 0.1 s on odometer epochs and one on a gyro-only
    epoch: the rows are the slots' first odometer records plus every heading epoch after
    the first record, each the distance since the previous row (the cumulative distance
    interpolated to the gyro-only epoch; tolerance 1e-9 m), summing to the records' total;
    0 s gives every record (Tang et al.)."""
    t_s = np.arange(2001) * 0.005 + 0.003                  # epochs every 5 ms, off the grid
    o = np.arange(0, 2001, 2)                               # odometer at every second epoch
    t_odo = t_s[o]
    speed = 10.0 + np.sin(t_odo)
    heading = np.zeros(len(t_s), bool)
    heading[::20] = True                                    # 0.1 s, on odometer epochs
    heading[1075] = True                                    # a gyro-only epoch
    rows, dist, t_m = fkf.distance_rows(t_s, o, speed, 0.05, heading)
    slot_first = o[np.flatnonzero(np.diff(np.floor(t_odo / 0.05)) != 0) + 1]
    expected = np.union1d(slot_first, np.flatnonzero(heading)[1:])
    np.testing.assert_array_equal(rows, expected)
    cum = np.concatenate(([0.0], np.cumsum(speed[1:] * np.diff(t_odo))))
    c_rows = np.interp(t_s[rows], t_odo, cum)
    assert abs(dist.sum() - c_rows[-1]) < 1e-9
    k = int(np.searchsorted(rows, 1075))                   # the gyro-only epoch's row
    j = int(np.searchsorted(t_odo, t_s[1075])) - 1         # the last record before it
    jp = int(np.searchsorted(o, rows[k - 1]))              # the previous row's record
    # whole records since the previous row, then the part of the next record's interval
    part = speed[j + 1] * (t_s[1075] - t_odo[j])
    assert abs(dist[k] - (cum[j] - cum[jp] + part)) < 1e-9
    np.testing.assert_allclose(t_m, np.diff(np.concatenate(([t_odo[0]], t_s[rows]))), atol=1e-12)
    assert np.all(t_m < 0.05 + 1e-9)                       # no row spans more than a slot
    rows0, dist0, tm0 = fkf.distance_rows(t_s, o, speed, 0.0, heading)
    np.testing.assert_array_equal(rows0, o[1:])
    np.testing.assert_allclose(tm0, np.diff(t_odo), atol=1e-12)
    np.testing.assert_allclose(dist0, speed[1:] * np.diff(t_odo), rtol=1e-12)


@pytest.mark.parametrize("seed", [1, 3])
def test_sixty_second_outage_ends_within_two_percent(seed: int) -> None:
    """Issue #4: the simulator's one-hour drive cut at 1700 s has one 60-s GNSS outage on
    a road with turns.  With 1-mm distance rows at every 100-Hz odometer record and heading
    rows at epochs without one, the rows moved the position metres each in the outage:
    30.6 m (7.9 %) and 20.7 m (5.0 %) at its end for seeds 1 and 3; now 1.7 m (0.45 %) and
    2.6 m (0.62 %).  Bound: the end error within 2 % of the distance driven in it (the
    project's 60-s drift target)."""
    from gpsdr_cli.evaluation import error_statistics, reference_en
    from gpsdr_cli.pipeline import fuse
    from gpsdr_cli.simulate import simulate_drive

    sim = simulate_drive("one_hour", seed=seed, duration_s=1700.0)
    params = config.defaults()
    params["filter"]["name"] = "fkf"
    res = fuse(sim.drive, params)
    ref = reference_en(sim.truth[["t_ns", "lat", "lon"]], res.frame)
    st = error_statistics(res.track, ref, "fkf", params)
    rows = st[st["segment"].str.startswith("outage_") & (st["duration_s"] >= 50.0)]
    assert len(rows) == 1
    assert float(rows["end_error_pct_distance"].iloc[0]) < 2.0
