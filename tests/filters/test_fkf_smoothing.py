"""fkf/fafkf fused RTS smoother in O(segment) memory: the checkpointed backward pass (the
forward pass re-run per segment from its checkpoint) must give exactly the smoother over
every epoch's stored x and P, and the model-specific RTS step exactly the generic one."""

from __future__ import annotations

import numpy as np
import pytest

from gpsdr_cli import config
from gpsdr_cli.align import build_epochs
from gpsdr_cli.filters import fkf, get
from gpsdr_cli.filters import kernels_fkf as kf
from gpsdr_cli.filters.core.rts import phi_times, rts_step
from gpsdr_cli.simulate import simulate_drive
from tests.filters.reference_fkf import tiny_drive

#: a segment length (epochs) that divides neither drive's epoch count (checked below)
ODD_SEGMENT = 997
TRACK_KEYS = ("e", "n", "v_e", "v_n", "var_e", "var_n", "cov_en")


@pytest.fixture(scope="module")
def urban():
    """Four minutes of the simulated urban canyon (multipath, dropouts, stops): 24 k epochs."""
    sim = simulate_drive("urban_canyon", seed=4, duration_s=240.0)
    return build_epochs(sim.drive, sim.frame, config.defaults())


def _params(segment: int, **sections: dict) -> dict:
    base: dict = {"filter": {"smooth": True}, "fkf": {"smooth_segment_epochs": segment}}
    for name, values in sections.items():
        base.setdefault(name, {}).update(values)
    return config.merge(config.defaults(), base)


@pytest.mark.parametrize(("name", "sections"), [
    ("fkf", {}),                                          # FR: rows applied centrally
    ("fkf", {"fkf": {"mode": "nr"}}),                     # NR: information fusion, stale rule
    ("fafkf", {}),                                        # fuzzy R and fuzzy shares
    ("fafkf", {"fkf": {"mode": "nr"}, "fafkf": {"weights": "shares"}}),
])
def test_checkpointed_smoother_equals_full_storage(urban, name: str, sections: dict) -> None:
    n = len(urban)
    assert n % ODD_SEGMENT != 0
    full = get(name)(urban, _params(0, **sections))
    assert full.info["smoothing"] == "rts_fused"
    for segment in (ODD_SEGMENT, 1, n + 5):
        ck = get(name)(urban, _params(segment, **sections))
        for key in TRACK_KEYS + ("gnss_used", "gnss_rejected", "nis", "static"):
            # the re-run is the same code on the same state: the same floats, not just 1e-9
            np.testing.assert_array_equal(getattr(ck, key), getattr(full, key),
                                          err_msg=f"{name} {sections} segment {segment}: {key}")
        for key, value in full.extras.items():
            np.testing.assert_array_equal(ck.extras[key], value, err_msg=key)
        assert ck.info == full.info
    # and smoothing moved the track (the comparison is not of two forward passes)
    fwd = get(name)(urban, config.merge(_params(0, **sections), {"filter": {"smooth": False}}))
    assert float(np.max(np.hypot(full.e - fwd.e, full.n - fwd.n))) > 0.1


def test_smoothed_pass_stores_no_per_epoch_covariance(urban) -> None:
    """With checkpoints the pass returns no per-epoch x or P (they live one segment at a
    time inside it), and its gnss_used/nis/weights are those of a pass that stores nothing."""
    params = _params(ODD_SEGMENT)
    prep = fkf.prepare(urban, params)
    n = len(urban)
    smoothed = fkf.forward("fkf", prep, True, ODD_SEGMENT)
    plain = fkf.forward("fkf", prep, False, ODD_SEGMENT)
    assert smoothed[7].shape[0] == 1 and smoothed[8].shape[0] == 1
    assert smoothed[0].shape == plain[0].shape == (kf.N_OUT, n)
    assert not np.array_equal(smoothed[0], plain[0])
    for a, b in zip(smoothed[1:7], plain[1:7], strict=True):
        np.testing.assert_array_equal(a, b)
    full = fkf.forward("fkf", prep, True, 0)
    assert full[7].shape == (n, kf.NXS) and full[8].shape == (n, kf.NPACK)
    np.testing.assert_array_equal(full[0], plain[0])


def _random_spd(rng: np.random.Generator, scale: np.ndarray) -> np.ndarray:
    A = rng.normal(size=(kf.NX, kf.NX))
    return (A @ A.T + np.eye(kf.NX)) * np.outer(scale, scale)


@pytest.mark.parametrize(("T", "static"), [(0.01, False), (0.2, False), (1.3, False),
                                           (0.1, True), (0.0, False)])
def test_fused_rts_step_is_the_generic_step_bit_for_bit(T: float, static: bool) -> None:
    rng = np.random.default_rng(7)
    # eps also decorrelating with distance: its factor depends on the state (at x_post)
    params = _params(0, fkf={"gnss_err_dist_m": 100.0})
    drive, frame, _ = tiny_drive(5.0)
    par = fkf.prepare(build_epochs(drive, frame, params), params).par
    scale = np.array([3.0, 1.0, 0.3, 3.0, 1.0, 0.3, 1.0, 1.0, 0.02, 0.05])
    for _ in range(20):
        P_post = _random_spd(rng, scale)
        x_post = rng.normal(size=kf.NX) * scale * 5.0
        x_prior, P_prior = x_post.copy(), P_post.copy()
        kf.predict(x_prior, P_prior, T, static, par, np.ones(kf.NX))
        x_sn = x_prior + rng.normal(size=kf.NX) * scale
        P_sn = 0.5 * P_prior + 0.1 * _random_spd(rng, scale)
        Phi = np.zeros((kf.NX, kf.NX))
        kf.phi_matrix(T, static, par, Phi, x_post)
        x_g, P_g = np.zeros(kf.NX), np.zeros((kf.NX, kf.NX))
        B = np.zeros((kf.NX, kf.NX))
        phi_times(kf.NX, Phi, P_post, B)
        rts_step(kf.NX, x_post, P_post, B, x_prior, P_prior, x_sn, P_sn, x_g, P_g,
                 np.zeros((kf.NX, kf.NX)), np.zeros(kf.NX))
        x_f, P_f = np.zeros(kf.NX), np.zeros((kf.NX, kf.NX))
        kf.rts_step_fused(x_post, P_post, x_prior, P_prior, T, static,
                          kf.eps_decay(x_post, T, par), x_sn, P_sn, x_f, P_f,
                          np.zeros((kf.NX, kf.NX)), np.zeros((kf.NX, kf.NX)), np.zeros(kf.NX))
        np.testing.assert_array_equal(x_f, x_g)
        np.testing.assert_array_equal(P_f, P_g)
        # and it is the RTS step: C = P Phi^T P_prior^-1 (to rounding, 1e-9 relative)
        C = np.linalg.solve(P_prior, Phi @ P_post).T
        np.testing.assert_allclose(x_f, x_post + C @ (x_sn - x_prior), rtol=1e-9, atol=1e-9)


def test_two_filter_combination_is_blockwise_exact(monkeypatch) -> None:
    """combine_two_filter in blocks (bounded temporaries) = in one piece, float for float,
    with a block length that does not divide the drive."""
    rng = np.random.default_rng(3)
    n = 1000

    def track() -> np.ndarray:
        t = rng.normal(size=(kf.N_OUT, n))
        t[kf.O_VAR_E] = 1.0 + rng.random(n)
        t[kf.O_VAR_N] = 1.0 + rng.random(n)
        t[kf.O_COV_EN] = 0.5 * rng.uniform(-1.0, 1.0, n)
        return t

    fwd, bwd = track(), track()[:, ::-1]             # the backward pass arrives reversed
    whole = fkf.combine_two_filter(fwd, np.ascontiguousarray(bwd))
    monkeypatch.setattr(fkf, "COMBINE_BLOCK", 37)
    np.testing.assert_array_equal(fkf.combine_two_filter(fwd, bwd), whole)
