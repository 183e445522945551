"""A known gyro scale (``--gyro-scale``, ``[graph] gyro_scale``; ``gpsdr batch
--calibrate-per-vehicle``'s in tests/test_graph_smoother.py): every filter reads the yaw rates
times it, and the graph smoother's scale correction g starts from it (true yaw rate = scale x
reading)."""

from __future__ import annotations

import copy
import json

import numpy as np
import pytest

from gpsdr_cli import config, simulate
from gpsdr_cli.io.drive import YawRates
from gpsdr_cli.pipeline import fuse
from gpsdr_cli.simulate import simulate_drive


def _params(filter_name: str, smoother: str, gyro_scale: float | None = None) -> dict:
    p = config.defaults()
    p["filter"]["name"] = filter_name
    p["filter"]["smoother"] = smoother
    p["filter"]["smooth"] = smoother != "none"
    if gyro_scale is not None:
        p["graph"]["gyro_scale"] = gyro_scale
    return p


def _rmse(sim, res) -> float:
    """Horizontal RMSE (m) of a fused track against the simulator's truth."""
    tr = res.track
    t = tr["time"].astype("int64").to_numpy()
    e, n = sim.frame.forward(tr["lat"].to_numpy(), tr["lon"].to_numpy())
    err = np.hypot(e - np.interp(t, sim.truth.t_ns, sim.truth.e),
                   n - np.interp(t, sim.truth.t_ns, sim.truth.n))
    return float(np.sqrt(np.mean(err ** 2)))


@pytest.mark.parametrize("filter_name", ["aekf", "fkf"])
def test_every_filter_reads_the_yaw_rates_times_the_known_scale(filter_name: str) -> None:
    """Given a scale k, the forward filter's track is the one of the readings multiplied by
    k and no scale given (urban_canyon seed 3, 120 s; k = 0.97)."""
    sim = simulate_drive("urban_canyon", 3, 120.0)
    scaled = copy.deepcopy(sim.drive)
    scaled.gyro = YawRates(t_ns=scaled.gyro.t_ns, yaw_rate_radps=0.97 * scaled.gyro.yaw_rate_radps)
    given = fuse(copy.deepcopy(sim.drive), _params(filter_name, "none", 0.97))
    multiplied = fuse(scaled, _params(filter_name, "none"))
    as_read = fuse(copy.deepcopy(sim.drive), _params(filter_name, "none"))
    np.testing.assert_allclose(given.track["e"], multiplied.track["e"], atol=1e-9)
    np.testing.assert_allclose(given.track["n"], multiplied.track["n"], atol=1e-9)
    assert float(np.max(np.abs(given.track["e"] - as_read.track["e"]))) > 0.05


def test_a_known_gyro_scale_helps_and_the_graph_reports_the_whole_scale(monkeypatch) -> None:
    """A gyro reading 3.6 % more turn than there is, no odometer (no_odometer seed 6, 300 s):
    the forward aekf 0.89 m RMS as read, 0.57 m given the true scale; the graph smoother's
    scale, the known one times 1 + g, within 0.002 of the truth either way, with a sigma
    under the one it has without the prior (0.0058 -> 0.0019)."""
    monkeypatch.setattr(simulate, "GYRO_EXTRA_SCALE", 0.03)
    sim = simulate_drive("no_odometer", 6, 300.0, gyro_rate_hz=5.0, odo_rate_hz=5.0)
    truth = 1.0 / (1.0 + sim.noise["gyro_scale_error"])
    fwd = {k: _rmse(sim, fuse(copy.deepcopy(sim.drive), _params("aekf", "none", k)))
           for k in (None, truth)}
    assert fwd[truth] < 0.75 * fwd[None], fwd
    scale, sd = {}, {}
    for k in (None, truth):
        info = json.loads(fuse(copy.deepcopy(sim.drive),
                               _params("aekf", "graph", k)).metadata["filter_info"])
        scale[k] = (k or 1.0) * (1.0 + info["graph_gyro_scale"])
        sd[k] = (k or 1.0) * info["graph_gyro_scale_sd"]
    assert scale[None] == pytest.approx(truth, abs=0.002)
    assert scale[truth] == pytest.approx(truth, abs=0.002)
    assert sd[truth] < 0.5 * sd[None] and sd[truth] <= 0.002


def test_the_option_and_the_calibration_line(gpsdr, tmp_path) -> None:
    """``--gyro-scale`` reaches the parameters (its sigma defaults to [graph]
    gyro_scale_cal_sd), the calibration line reports the whole scale, and a scale that is not
    positive is refused with a word on the sign."""
    from gpsdr_cli.simulate import write_drive

    sim = simulate_drive("urban_canyon", 3, 120.0)
    truth = 1.0 / (1.0 + sim.noise["gyro_scale_error"])
    write_drive(sim, tmp_path / "d", mcap=False)
    streams = ["--gps", str(tmp_path / "d" / "gps.nmea"), "--gyro", str(tmp_path / "d" / "gyro.csv"),
               "--odo", str(tmp_path / "d" / "odo.csv")]
    res = gpsdr(["fuse", *streams, "--gyro-scale", f"{truth:.4f}", "--print-config"])
    assert res.exit_code == 0, res.output
    cal_sd = config.defaults()["graph"]["gyro_scale_cal_sd"]
    assert f"gyro_scale = {float(f'{truth:.4f}')!r}" in res.output
    assert f"gyro_scale_cal_sd = {cal_sd!r}" in res.output
    res = gpsdr(["fuse", *streams, "--gyro-scale", f"{truth:.4f}+-0.001",
                 "-o", str(tmp_path / "t.parquet")])
    assert res.exit_code == 0, res.output
    line = [ln for ln in res.stderr.splitlines() if ln.startswith("calibration (graph")]
    assert len(line) == 1, res.stderr
    assert float(line[0].split("gyro scale ")[1].split()[0]) == pytest.approx(truth, abs=0.002)
    bad = gpsdr(["fuse", *streams, "--gyro-scale", "-1", "-o", str(tmp_path / "x.parquet")])
    assert bad.exit_code != 0 and "--gyro-scale" in bad.output and "sign" in bad.output

