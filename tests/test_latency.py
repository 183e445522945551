"""GNSS time offset estimation on simulated drives with a known injected offset."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from gpsdr_cli.latency import estimate_gnss_offset, estimate_gnss_offset_s, huber_fit
from gpsdr_cli.simulate import simulate_drive


def truth_track(sim, vel_noise_mps: float = 0.0, seed: int = 0) -> pd.DataFrame:
    """A track that follows the truth (velocity optionally noisy), with the simulated fixes."""
    tr = sim.truth
    g = sim.drive.gnss
    ge, gn = sim.frame.forward(g.lat_deg, g.lon_deg)
    idx = np.searchsorted(tr["t_ns"].to_numpy(), g.t_ns)
    rng = np.random.default_rng(seed)
    track = pd.DataFrame({
        "time": pd.to_datetime(tr["t_ns"], unit="ns", utc=True),
        "e": tr["e"], "n": tr["n"],
        "v_e": tr["v_e"] + vel_noise_mps * rng.standard_normal(len(tr)),
        "v_n": tr["v_n"] + vel_noise_mps * rng.standard_normal(len(tr)),
        "gnss_e": np.nan, "gnss_n": np.nan, "gnss_outage": False,
    })
    track.loc[idx, "gnss_e"] = ge
    track.loc[idx, "gnss_n"] = gn
    return track


@pytest.fixture(scope="module")
def drive_offset():
    return simulate_drive("open_sky", seed=0, gnss_stamp_offset_s=0.1)


def test_recovers_injected_offset_without_reference(drive_offset):
    est = estimate_gnss_offset(truth_track(drive_offset, vel_noise_mps=0.05))
    assert est.method == "differenced"
    assert est.offset_s == pytest.approx(0.1, abs=0.02)  # s
    assert est.stderr_s < 0.02


def test_along_the_track_alone_recovers_it_too(drive_offset):
    """From speed changes alone (the fixes against the odometer), the same 0.1 s; a drive
    standing still has no along-track direction to read it on."""
    est = estimate_gnss_offset(truth_track(drive_offset, vel_noise_mps=0.05), along=True)
    assert est.method == "differenced along track"
    assert est.offset_s == pytest.approx(0.1, abs=0.02)  # s
    standing = truth_track(drive_offset)
    standing[["v_e", "v_n"]] = 0.0
    assert not estimate_gnss_offset(standing, along=True).identified


def test_recovers_injected_offset_against_reference(drive_offset):
    ref = drive_offset.truth[["t_ns", "e", "n"]]
    est = estimate_gnss_offset(truth_track(drive_offset), ref)
    assert est.method == "reference"
    assert est.offset_s == pytest.approx(0.1, abs=0.02)  # s


def test_negative_offset_and_zero_offset():
    sim = simulate_drive("stop_and_go", seed=1, gnss_stamp_offset_s=-0.2)
    assert estimate_gnss_offset_s(truth_track(sim)) == pytest.approx(-0.2, abs=0.03)  # s
    sim0 = simulate_drive("open_sky", seed=3, duration_s=300.0)
    assert estimate_gnss_offset_s(truth_track(sim0)) == pytest.approx(0.0, abs=0.02)  # s


def test_not_identifiable_returns_zero_with_reason():
    sim = simulate_drive("open_sky", seed=2, duration_s=60.0, gnss_stamp_offset_s=0.1)
    tk = truth_track(sim)
    standing = tk.copy()
    standing[["v_e", "v_n"]] = 0.0
    standing["gnss_e"] = np.where(np.isfinite(tk["gnss_e"]), 0.0, np.nan)
    standing["gnss_n"] = np.where(np.isfinite(tk["gnss_n"]), 0.0, np.nan)
    est = estimate_gnss_offset(standing)
    assert est.offset_s == 0.0 and not est.identified
    assert "not identifiable" in est.reason
    few = tk.copy()
    keep = np.flatnonzero(np.isfinite(tk["gnss_e"]))[:10]
    few["gnss_e"] = np.nan
    few.loc[keep, "gnss_e"] = tk.loc[keep, "gnss_e"]
    est = estimate_gnss_offset(few)
    assert est.offset_s == 0.0 and "too few" in est.reason
    est = estimate_gnss_offset(tk.drop(columns=["v_e"]))
    assert est.offset_s == 0.0 and "v_e" in est.reason


def test_huber_fit_ignores_gross_outliers():
    rng = np.random.default_rng(0)
    x = rng.uniform(0, 20, 500)
    y = 0.1 * x + 0.3 + 0.05 * rng.standard_normal(500)
    y[::25] += 30.0  # 4 % gross outliers
    beta, cov = huber_fit(np.column_stack([x, np.ones_like(x)]), y)
    assert beta[0] == pytest.approx(0.1, abs=0.005)
    assert beta[1] == pytest.approx(0.3, abs=0.05)
    assert np.all(np.isfinite(cov))


def test_offset_hint_only_for_a_large_significant_offset():
    """A track on the truth: fixes stamped 0.15 s early give the hint (ahead), 0.15 s late
    the mirror one; on time, none."""
    from gpsdr_cli.latency import offset_hint

    for stamp_s, word in ((0.15, "ahead of"), (-0.15, "behind"), (0.0, None)):
        sim = simulate_drive("open_sky", seed=0, gnss_stamp_offset_s=stamp_s)  # +-0.007 s
        hint = offset_hint(truth_track(sim))
        if word is None:
            assert hint is None
        else:
            assert hint is not None and word in hint and "--gnss-offset auto" in hint
            # fixes ahead could as well be a late wheel speed (decisions/0022); behind not
            assert ("odo_offset_s" in hint) == (stamp_s > 0)
            assert "odo_offset_s" not in offset_hint(truth_track(sim), odometer=False)
