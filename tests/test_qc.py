"""Forward/backward quality checks (gpsdr_cli.qc): the time reversal, the separation column,
the quality class and their statistics; on simulated drives with known truth."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pandas as pd
import pytest

from gpsdr_cli import config, pipeline, qc, simulate
from gpsdr_cli.align import build_epochs

#: m: an open-sky backward pass, reversed back, lies within this of the truth (RMSE);
#: forward aekf 0.62 m, backward 0.75 m on seed 1
BACKWARD_RMSE_MAX_M = 1.0
#: the backward pass may be worse than the forward one by at most this factor (it starts
#: at the drive's end, whose first fixes have no history either)
BACKWARD_OVER_FORWARD_MAX = 1.5


@pytest.fixture(scope="module")
def open_sky() -> simulate.SimDrive:
    return simulate.simulate_drive("open_sky", seed=1, duration_s=300.0)


def _truth_en(sim: simulate.SimDrive, t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return (np.interp(t_ns, sim.truth.t_ns, sim.truth.e), np.interp(t_ns, sim.truth.t_ns, sim.truth.n))


def _rmse(e: np.ndarray, n: np.ndarray, te: np.ndarray, tn: np.ndarray) -> float:
    return float(np.sqrt(np.mean((e - te) ** 2 + (n - tn) ** 2)))


def test_reverse_twice_is_the_drive(open_sky: simulate.SimDrive) -> None:
    p = config.defaults()
    ep = build_epochs(copy.deepcopy(open_sky.drive), open_sky.frame, p)
    back = qc.reverse_epochs(qc.reverse_epochs(ep))
    np.testing.assert_array_equal(back.t_ns, ep.t_ns)
    np.testing.assert_allclose(back.dt_s, ep.dt_s, atol=1e-12)
    np.testing.assert_array_equal(back.yaw_rate_radps, ep.yaw_rate_radps)
    np.testing.assert_array_equal(back.gnss_e, ep.gnss_e)
    np.testing.assert_array_equal(back.gnss_outage, ep.gnss_outage)
    ok = np.isfinite(ep.gnss_course_rad)
    d = np.angle(np.exp(1j * (back.gnss_course_rad[ok] - ep.gnss_course_rad[ok])))
    assert np.max(np.abs(d)) < 1e-12
    rev = qc.reverse_epochs(ep)
    assert np.all(np.diff(rev.t_ns) > 0)
    assert rev.t_ns[0] == ep.t_ns[0] and rev.t_ns[-1] == ep.t_ns[-1]
    # the reversed course is the forward one turned by pi (the car drives backwards)
    k = np.flatnonzero(ok)[10]
    turned = np.angle(np.exp(1j * (rev.gnss_course_rad[len(ep) - 1 - k] - ep.gnss_course_rad[k])))
    assert abs(abs(turned) - np.pi) < 1e-12


@pytest.mark.parametrize("name", ["aekf", "fkf"])
def test_backward_pass_tracks_the_truth(open_sky: simulate.SimDrive, name: str) -> None:
    p = config.defaults()
    p["filter"]["name"] = name
    ep = build_epochs(copy.deepcopy(open_sky.drive), open_sky.frame, p)
    te, tn = _truth_en(open_sky, ep.t_ns)
    fwd = pipeline.run_filter(ep, p)
    e_b, n_b, var_e, var_n = qc.reverse_result_positions(pipeline.run_filter(qc.reverse_epochs(ep), p))
    rf, rb = _rmse(fwd.e, fwd.n, te, tn), _rmse(e_b, n_b, te, tn)
    assert rb < BACKWARD_RMSE_MAX_M, (rf, rb)
    assert rb < BACKWARD_OVER_FORWARD_MAX * rf + 0.1, (rf, rb)
    assert np.all(np.isfinite(var_e)) and np.all(var_n >= 0)
    # the mapping matters: a reversed drive whose yaw rate keeps its sign turns the wrong way
    # (the gyro's scale held at 0: estimated, the NLOS screen's fit reads the sign flipped,
    # g = -1.95, and the filter corrects it)
    wrong = dataclasses.replace(qc.reverse_epochs(ep), yaw_rate_radps=ep.yaw_rate_radps[::-1].copy())
    held = copy.deepcopy(p)
    held["graph"]["gyro_scale_prior_sd"] = 1e-6
    e_w, n_w, _, _ = qc.reverse_result_positions(pipeline.run_filter(wrong, held))
    assert _rmse(e_w, n_w, te, tn) > rb


def test_fuse_writes_separation_and_quality(open_sky: simulate.SimDrive, tmp_path) -> None:
    from gpsdr_cli.io.parquet import field_units, read_track, write_table

    p = config.defaults()
    res = pipeline.fuse(open_sky.drive, p)
    tr = res.track
    sep = tr["separation_m"].to_numpy(float)
    assert np.all(np.isfinite(sep)) and np.all(sep >= 0)
    # open sky: the two passes agree to metres; not identically (independent passes)
    assert 0.05 < np.sqrt(np.mean(sep ** 2)) < 2.0
    assert tr["quality"].dtype == np.int8
    assert set(np.unique(tr["quality"])) <= set(qc.QUALITY_CLASSES)
    # the earlier columns are those of a run without the checks, value for value
    p_off = config.defaults()
    p_off["qc"]["backward_pass"] = False
    off = pipeline.fuse(open_sky.drive, p_off).track
    assert "separation_m" not in off
    pd.testing.assert_frame_equal(tr[list(pipeline.BASE_TRACK_UNITS)], off[list(pipeline.BASE_TRACK_UNITS)])
    # without the separation the class is graded on sigma alone: never worse
    assert np.all(off["quality"].to_numpy() <= tr["quality"].to_numpy())
    path = tmp_path / "t.parquet"
    write_table(tr, path, metadata=res.metadata, units=pipeline.TRACK_UNITS)
    units = field_units(str(path))
    assert units["separation_m"].startswith("m")
    back, _ = read_track(str(path))
    np.testing.assert_array_equal(back["quality"].to_numpy(), tr["quality"].to_numpy())
    # statistics: separation figures and shares per class, from the same column
    row = res.stats[res.stats["segment"] == "all"].iloc[0]
    assert row["separation_rms_m"] == pytest.approx(np.sqrt(np.mean(sep ** 2)), rel=1e-12)
    assert row["separation_p95_m"] == pytest.approx(np.percentile(sep, 95), rel=1e-12)
    assert row["separation_max_m"] == pytest.approx(sep.max(), rel=1e-12)
    shares = [float(row[f"quality_{k}_share"]) for k in qc.QUALITY_CLASSES]
    assert sum(shares) == pytest.approx(1.0, abs=1e-12)
    assert shares[2] == pytest.approx(float(np.mean(tr["quality"] == 3)), abs=1e-12)


def test_separation_grows_in_an_outage() -> None:
    sim = simulate.simulate_drive("tunnels", seed=1, duration_s=600.0)
    res = pipeline.fuse(sim.drive, config.defaults())
    tr = res.track
    out = tr["gnss_outage"].to_numpy(bool)
    assert out.any()
    sep = tr["separation_m"].to_numpy(float)
    # each pass dead-reckons into the tunnel from its own end: they part inside it
    assert np.median(sep[out]) > 3.0 * np.median(sep[~out])
    assert np.all(tr["quality"].to_numpy()[out] >= config.defaults()["qc"]["outage_min_class"])


QC = config.defaults()["qc"]


@pytest.mark.parametrize(("sigma_h", "sep", "expected"), [
    (0.05, 0.08, 1), (0.05, 0.1, 1), (0.05, 0.11, 2), (0.4, 0.2, 2), (1.0, 0.2, 3),
    (0.2, 4.9, 4), (12.0, 0.3, 5), (15.01, 0.1, 6), (np.nan, 0.1, 6), (0.1, np.nan, 6),
])
def test_quality_thresholds(sigma_h: float, sep: float, expected: int) -> None:
    f = np.zeros(1, bool)
    got = qc.quality_class(np.array([sigma_h]), np.array([sep]), ~f, f, f, np.zeros(1, np.int64), QC)
    assert got.tolist() == [expected]


def test_quality_gnss_state() -> None:
    ns = 1_000_000_000
    t = np.arange(0, 100, dtype=np.int64) * ns            # 1 Hz, 100 s
    sig = np.full(100, 0.05)
    used = np.ones(100, bool)
    rejected = np.zeros(100, bool)
    outage = np.zeros(100, bool)
    outage[10:15] = True                                   # 6 s from the last fix to the next
    outage[40:80] = True                                   # 41 s > outage_long_s
    used[outage] = False
    used[90] = False
    rejected[90] = True                                    # a rejected fix; used again at 91
    q = qc.quality_class(sig, None, used, rejected, outage, t, QC)
    assert q[:10].tolist() == [1] * 10
    assert q[10:15].tolist() == [QC["outage_min_class"]] * 5
    assert q[40:80].tolist() == [6] * 40
    assert q[90] == QC["rejected_min_class"] and q[91] == 1


def test_plot_and_stats_command_show_the_checks(open_sky: simulate.SimDrive, tmp_path, gpsdr) -> None:
    from PIL import Image

    from gpsdr_cli.io.parquet import write_table
    from gpsdr_cli.plot import plot_report

    res = pipeline.fuse(open_sky.drive, config.defaults())
    path = tmp_path / "t.parquet"
    write_table(res.track, path, metadata=res.metadata, units=pipeline.TRACK_UNITS)
    png = plot_report(res.track, tmp_path / "r.png")
    png_plain = plot_report(res.track.drop(columns=["separation_m"]), tmp_path / "p.png")
    assert Image.open(png).size == Image.open(png_plain).size
    assert png.stat().st_size > png_plain.stat().st_size  # one more panel drawn
    out = gpsdr(["stats", str(path)])
    assert out.exit_code == 0, out.output
    assert "separation_rms_m" in out.output
    q3 = 100.0 * float(np.mean(res.track["quality"] == 3))
    assert f"3: {q3:.1f} %" in out.output


@pytest.mark.parametrize("smooth", [False, True])
@pytest.mark.parametrize("name", ["ekf", "aekf", "fkf", "fafkf"])
def test_every_filter_with_a_lead_in_and_a_tail(name: str, smooth: bool) -> None:
    """Fixes start 20 s after the gyro and odometer and stop 20 s before them: the forward
    pass dead-reckons the lead-in, the backward pass the tail (its own lead-in)."""
    sim = simulate.simulate_drive("open_sky", seed=2, duration_s=180.0)
    g = sim.drive.gnss
    t0, t1 = int(sim.truth.t_ns.iloc[0]), int(sim.truth.t_ns.iloc[-1])
    keep = (g.t_ns > t0 + 20 * 10**9) & (g.t_ns < t1 - 20 * 10**9)
    gnss = dataclasses.replace(g, **{f.name: getattr(g, f.name)[keep] for f in dataclasses.fields(g)})
    drive = dataclasses.replace(sim.drive, gnss=gnss)
    p = config.defaults()
    p["filter"]["name"] = name
    p["filter"]["smooth"] = smooth
    p["filter"]["smoother"] = "rts" if smooth else "none"
    tr = pipeline.fuse(drive, p).track
    sep = tr["separation_m"].to_numpy(float)
    assert np.all(np.isfinite(sep))
    inside = (tr["time"].astype("int64").to_numpy() > t0 + 25 * 10**9) & \
             (tr["time"].astype("int64").to_numpy() < t1 - 25 * 10**9)
    # open sky with fixes: the passes agree to within a few metres away from the ends
    assert float(np.sqrt(np.mean(sep[inside] ** 2))) < 3.0
    t = tr["time"].astype("int64").to_numpy()
    ends = (t < gnss.t_ns[0]) | (t > gnss.t_ns[-1])      # dead reckoning before/after the fixes
    assert ends.sum() > 1000
    assert np.all(tr["quality"].to_numpy()[ends] >= config.defaults()["qc"]["outage_min_class"])


@pytest.mark.parametrize("smooth", [False, True])
def test_fused_separation_is_that_of_independent_passes(open_sky: simulate.SimDrive,
                                                        smooth: bool) -> None:
    # fuse runs the QC passes before the main one: the column must be the distance between
    # a plain forward pass and the reversed pass, whatever the main pass is
    p = config.defaults()
    p["filter"]["smooth"] = smooth
    p["filter"]["smoother"] = "rts" if smooth else "none"
    res = pipeline.fuse(open_sky.drive, p)
    raw = copy.deepcopy(res.params)
    raw["filter"]["smooth"] = False
    fwd = pipeline.run_filter(res.epochs, raw)
    bwd = pipeline.run_filter(qc.reverse_epochs(res.epochs), raw)
    e_b, n_b, _, _ = qc.reverse_result_positions(bwd)
    expected = np.hypot(fwd.e - e_b, fwd.n - n_b)
    np.testing.assert_array_equal(res.track["separation_m"].to_numpy(float), expected)
    # the smoothed main pass is another track: the separation is not measured against it
    if smooth:
        assert not np.array_equal(res.track["e"].to_numpy(float), fwd.e)


def test_release_arrays_keeps_the_summaries(open_sky: simulate.SimDrive) -> None:
    res = pipeline.fuse(open_sky.drive, config.defaults(), open_sky.reference())
    fixes, track = res.gnss_only_summary(), res.summary()
    assert 0.5 < fixes["rmse_m"] < 5.0 and track["rmse_m"] < fixes["rmse_m"]
    res.release_arrays()
    assert res.epochs is None and res.result is None
    assert res.gnss_only_summary() == fixes and res.summary() == track


@pytest.mark.parametrize("name", ["aekf", "fkf"])
def test_backward_pass_with_a_forward_accelerometer(name: str) -> None:
    """Without an odometer the accelerometer carries the speed through the GNSS outages; the
    reversed drive's car drives backwards, so its reading must change sign too (kept as
    it was, the backward pass of the simulated no_odometer drive, seed 2, ended 28 km
    off)."""
    sim = simulate.simulate_drive("no_odometer", 2, 600.0)
    p = config.defaults()
    p["filter"]["name"] = name
    ep = build_epochs(copy.deepcopy(sim.drive), sim.frame, p)
    assert ep.has_accel.any() and not ep.has_odo.any()
    te, tn = _truth_en(sim, ep.t_ns)
    rev = qc.reverse_epochs(ep)
    back = qc.reverse_epochs(rev)
    np.testing.assert_array_equal(back.accel_mps2, ep.accel_mps2)
    e_b, n_b, _, _ = qc.reverse_result_positions(pipeline.run_filter(rev, p))
    rb = _rmse(e_b, n_b, te, tn)
    assert rb < 8.0, rb
    same_sign = dataclasses.replace(rev, accel_mps2=ep.accel_mps2[::-1].copy())
    e_w, n_w, _, _ = qc.reverse_result_positions(pipeline.run_filter(same_sign, p))
    assert _rmse(e_w, n_w, te, tn) > 5.0 * rb
