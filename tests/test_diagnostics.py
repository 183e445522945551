"""benchmarks/diagnostics.py's figure-computing functions on short simulated drives and on
synthetic numbers with known answers: the GNSS time-offset sweep recovers a simulated
offset and the speed it moves the fixes with, the NIS bands reproduce chi-square means,
the slow/fast split and drift of a known signal, and the simulated study's errors agree
with the pipeline's own statistics."""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest

from tests.conftest import load_benchmark


@pytest.fixture(scope="module")
def diag():
    return load_benchmark("diagnostics")


def test_offset_sweep_finds_a_simulated_gnss_offset(diag):
    """Fixes 0.1 s ahead of their stamps (as comma2k19's): the GNSS-only RMSE minimum and
    the zero of the mean along-track error sit at 0.1 s (+-0.02 s), the along-track mean
    moves by minus the mean speed per second of offset (+-2 %), the cross-track mean not
    at all (+-0.05 m)."""
    from gpsdr_cli.simulate import simulate_drive

    sim = simulate_drive("open_sky", seed=1, duration_s=120.0, gnss_stamp_offset_s=0.1)
    ref = sim.truth[["t_ns", "lat", "lon"]]
    sweep = diag.offset_sweep(sim.drive, ref, (0.0, 0.05, 0.1, 0.15, 0.2), ("ekf",), (False,))
    assert set(sweep["method"]) == {"GNSS only", "ekf"}
    assert len(sweep) == 10
    best, rmse = diag.best_offset(sweep, "GNSS only")
    assert abs(best - 0.1) < 0.02
    assert abs(diag.along_zero(sweep, "GNSS only") - 0.1) < 0.02
    g = sweep[sweep["method"] == "GNSS only"]
    assert rmse <= g["rmse_m"].min() + 1e-9
    speed = float(sim.truth["speed"].mean())
    assert abs(diag.along_slope(sweep, "GNSS only") / -speed - 1.0) < 0.02
    assert np.ptp(g["cross_mean_m"].to_numpy()) < 0.05
    # the fused track at the true offset beats the fixes (open sky, 5-Hz GNSS, 100-Hz DR)
    at = sweep[np.isclose(sweep["offset_s"], 0.1)].set_index("method")["rmse_m"]
    assert at["ekf"] < at["GNSS only"]


def test_nis_bands_reproduce_chi_square_means(diag):
    """chi-square(2) NIS has mean 2; scaled by 3 above PDOP 6 and cut at the gate 18.42 its
    mean is 3 (2 - c e^(-c/2)/(1 - e^(-c/2))) with c = 18.42/3 (5.10: an exponential of mean 2
    cut at c), and a share e^(-c/2) (4.6 %) lies above the gate.  Tolerances: 0.1 for the
    means, 1 point for the share (20 000 samples)."""
    rng = np.random.default_rng(7)
    n = 20000
    pdop = rng.uniform(1.0, 8.0, n)
    nis = rng.chisquare(2, n) * np.where(pdop >= 6.0, 3.0, 1.0)
    gate = 18.420680743952587
    tab = diag.nis_by_pdop(pdop, nis, gate, (1.0, 3.0, 6.0, math.inf), min_count=1)
    assert list(tab["pdop_lo"]) == [1.0, 3.0, 6.0]
    assert tab["mean_nis_gated"].iloc[0] == pytest.approx(2.0, abs=0.1)
    assert tab["mean_nis_gated"].iloc[1] == pytest.approx(2.0, abs=0.1)
    c = gate / 3.0
    tail = math.exp(-c / 2)
    assert tab["mean_nis_gated"].iloc[2] == pytest.approx(3 * (2 - c * tail / (1 - tail)), abs=0.1)
    assert tab["above_gate"].iloc[2] == pytest.approx(tail, abs=0.01)
    assert tab["mean_nis"].iloc[2] == pytest.approx(6.0, abs=0.3)
    r = diag.pdop_regime_nis(pdop, nis, 3.0, 6.0, gate)
    assert r["good"] == pytest.approx(2.0, abs=0.1)
    assert r["poor"] == pytest.approx(tab["mean_nis_gated"].iloc[2])


def test_slow_fast_split_of_a_known_signal(diag):
    """0.5 m + 0.01 m/s drift + white 0.1 m at 10 Hz over 60 s: the fast part's RMS is the
    white noise's less what the 3-s (31-sample) mean keeps, 0.1 sqrt(30/31) (+-0.01 m); the
    drift is 0.01 m/s (+-0.001)."""
    rng = np.random.default_rng(3)
    t_ns = (np.arange(601) * 100_000_000).astype(np.int64)
    ts = t_ns / 1e9
    ac = pd.DataFrame({"t_ns": t_ns, "along_m": 0.5 + 0.01 * ts + 0.1 * rng.standard_normal(601),
                       "cross_m": np.full(601, -0.4)})
    q = diag.slow_fast(ac)
    assert q["along_fast_rms_m"] == pytest.approx(0.1 * math.sqrt(30 / 31), abs=0.01)
    assert q["along_drift_mps"] == pytest.approx(0.01, abs=0.001)
    assert q["cross_fast_rms_m"] < 1e-9
    assert q["cross_slow_rms_m"] == pytest.approx(0.4, abs=1e-9)


def test_sim_study_matches_the_pipeline_statistics(diag):
    """120 s of the urban canyon, ekf and fafkf forward with oracles: each run's RMSE is the
    pipeline's own ``all``-segment RMSE (to 1e-9 m); the oracle rows exist; the fafkf R
    factors lie within [r_min_factor, r_max_factor]; the NIS series pair with PDOPs."""
    from gpsdr_cli import config
    from gpsdr_cli.evaluation import reference_en
    from gpsdr_cli.pipeline import fuse
    from gpsdr_cli.simulate import simulate_drive

    methods = {"ekf": ("ekf", None), "fafkf": ("fafkf", None)}
    study = diag.sim_study([1], duration_s=120.0, methods=methods, smooth_modes=(False,),
                           log=lambda _m: None)
    runs = study.runs.set_index(["method", "oracle"])
    assert len(runs) == 4
    sim = simulate_drive("urban_canyon", seed=1, duration_s=120.0)
    for m in methods:
        res = fuse(sim.drive, diag.params_for(m, False), sim.truth[["t_ns", "lat", "lon"]])
        assert runs.loc[(m, False), "rmse_m"] == pytest.approx(res.summary()["rmse_m"], abs=1e-9)
        ref = reference_en(sim.truth[["t_ns", "lat", "lon"]], res.frame)
        assert len(ref) == len(sim.truth)
    assert runs.loc[("ekf", True), "rmse_m"] > 0
    p = config.defaults()["fafkf"]
    r = study.r_factors["fafkf"]
    assert len(r) > 500
    assert r.min() >= p["r_min_factor"] - 1e-12
    assert r.max() <= p["r_max_factor"] + 1e-9
    pd_, nis = study.nis["ekf"]
    assert len(pd_) == len(nis) > 500
    assert np.all(nis >= 0)
    pool = diag.pooled(study.runs)
    assert diag.pooled_value(pool, "ekf", False) == pytest.approx(runs.loc[("ekf", False), "rmse_m"])
