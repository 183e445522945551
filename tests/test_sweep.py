"""benchmarks/sweep.py: its sensor models are the simulator's (bit for bit at the simulator's
constants), its perturbations reach the drive and the oracle's noise dict, and every patch
of gpsdr_cli.simulate is undone afterwards."""

from __future__ import annotations

import math

import numpy as np
import pytest

from gpsdr_cli import simulate
from tests.conftest import load_benchmark


@pytest.fixture(scope="module")
def sw():
    return load_benchmark("sweep")


def _sim(sw, name: str, seed: int = 3):
    return sw.simulate_setting(sw.SETTINGS[name], "urban_canyon", seed, 60.0)


def test_models_at_the_simulators_constants_are_the_simulator(sw) -> None:
    ref = simulate.simulate_drive("urban_canyon", seed=3, duration_s=60.0)
    plain = sw.Setting("same", "models at default constants", gyro={}, odo={})
    sim = sw.simulate_setting(plain, "urban_canyon", 3, 60.0)
    np.testing.assert_array_equal(sim.drive.gyro.yaw_rate_radps, ref.drive.gyro.yaw_rate_radps)
    np.testing.assert_array_equal(sim.drive.odo.speed_mps, ref.drive.odo.speed_mps)
    np.testing.assert_array_equal(sim.drive.gnss.lat_deg, ref.drive.gnss.lat_deg)
    assert sim.noise == ref.noise


def test_patches_are_undone(sw) -> None:
    env0, gyro0, odo0 = dict(simulate._ENV), simulate._gyro, simulate._odo
    for name in ("mp_sd_x2", "gst_share_0", "gyro_bias_x5", "odo_coarse"):
        _sim(sw, name)
    with pytest.raises(RuntimeError), sw.patched(sw.SETTINGS["mp_tau_x3"], 1):
        raise RuntimeError("inside")
    assert simulate._ENV == env0
    assert simulate._gyro is gyro0 and simulate._odo is odo0


def test_perturbations_reach_the_drive_and_the_noise(sw) -> None:
    base = _sim(sw, "default")
    mp2 = _sim(sw, "mp_sd_x2")
    assert mp2.noise["gnss_environments"]["urban"]["multipath_sd_m"] == pytest.approx(8.0)  # m
    # the same draws scaled: the multipath series is exactly twice the default's (to 1e-9 m)
    np.testing.assert_allclose(mp2.gnss_errors["multipath_e"], 2 * base.gnss_errors["multipath_e"],
                               atol=1e-9)
    gst0 = _sim(sw, "gst_share_0")
    np.testing.assert_allclose(gst0.gnss_errors["reported_sd_m"], gst0.gnss_errors["white_sd_m"])
    coarse = _sim(sw, "odo_coarse")
    steps = np.unique(np.round(coarse.drive.odo.speed_mps[coarse.drive.odo.speed_mps > 0.5]))
    assert coarse.noise["odo_effective_sd_mps"] > 0.4  # m/s: 1 m/s steps / sqrt(6)
    assert len(steps) > 3
    odo3 = _sim(sw, "odo_scale_3pct", seed=3)
    assert odo3.noise["odo_scale_error"] == 0.03 and odo3.noise["odo_scale_sd"] == 0.03
    assert _sim(sw, "odo_scale_3pct", seed=2).noise["odo_scale_error"] == -0.03
    bias = _sim(sw, "gyro_bias_x5")
    assert bias.noise["gyro_bias_sd_radps"] == pytest.approx(math.radians(1.5))  # rad/s
    p = sw.params_for("ekf", False)
    assert simulate.oracle_params(bias.noise, p)["gyro"]["bias_sd_radps"] == pytest.approx(
        math.radians(1.5))


def test_pool_and_flags(sw) -> None:
    rs = [sw.Result("s", "urban_canyon", seed, "ekf", rmse, 1.0, 5.0, rmse, math.nan, math.nan)
          for seed, rmse in ((1, 1.0), (2, 1.4))]
    df = sw.pool(rs)
    assert df["rmse_m"].iloc[0] == pytest.approx(math.sqrt((1.0 + 1.96) / 2))  # m, RMS over seeds
    assert sw.flags(df.iloc[0]) == ["oracle x1.22"]
    tun = sw.Result("s", "tunnels", 1, "fkf + RTS", 1.0, 1.0, 1.0, 1.2, 1.5, 0.1)
    assert sw.flags(sw.pool([tun]).iloc[0]) == ["fused >= GNSS", "drift > 1 %"]
