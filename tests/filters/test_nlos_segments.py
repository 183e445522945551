"""Runs of fixes that share one reflected-signal bias: cut where the offset from the
track jumps or drifts, and one vote each in the batch fit behind the NLOS screen and the
graph smoother."""

from __future__ import annotations

import copy

import numpy as np
import pytest

from gpsdr_cli import config
from gpsdr_cli.filters.graph import smooth_graph
from gpsdr_cli.filters.nlos_segments import segment_trust, segments
from gpsdr_cli.simulate import simulate_drive
from gpsdr_cli.testing.sim import run_filter


def test_cut_where_the_offset_jumps_drifts_or_the_fixes_pause() -> None:
    rng = np.random.default_rng(3)
    t = np.arange(0.0, 80.0, 0.2)
    off_e = rng.normal(0.0, 1.0, t.size)
    off_n = rng.normal(0.0, 1.0, t.size)
    step = (t >= 20.0) & (t < 30.0)        # a 30-m reflection for 10 s
    off_e[step] += 30.0
    ramp = t >= 40.0                       # a reflection growing at 0.5 m/s
    off_n[ramp] += 0.5 * (t[ramp] - 40.0)
    keep = (t < 60.0) | (t >= 64.0)        # 4 s without fixes
    t, off_e, off_n = t[keep], off_e[keep], off_n[keep]
    seg, run = segments(t, off_e, off_n, jump_m=5.0, gap_s=3.0)
    assert np.all(np.diff(seg) >= 0) and np.all(np.diff(run) >= 0)
    # the step's fixes are one segment, its own, and the clean fixes either side others
    inside = (t >= 20.0) & (t < 30.0)
    assert len(np.unique(seg[inside])) == 1
    assert seg[inside][0] not in seg[~inside]
    assert seg[t < 20.0].max() == 0
    # the ramp is cut before its segments span much more than the threshold, but stays one
    # run (one vote): nothing jumped
    ramp = (t >= 40.0) & (t < 60.0)
    assert len(np.unique(seg[ramp])) >= 2
    assert len(np.unique(run[ramp])) == 1
    for s in np.unique(seg[t >= 40.0]):
        m = seg == s
        assert np.ptp(off_n[m]) < 5.0 + 2 * 2.0 * 1.0 + 0.5 * 1.0
    # the step is a run of its own; the pause starts a segment and a run
    assert len(np.unique(run[inside])) == 1 and run[inside][0] not in run[~inside]
    k = np.searchsorted(t, 64.0)
    assert seg[k] > seg[k - 1] and run[k] > run[k - 1]


@pytest.fixture(scope="module")
def long_run():
    """urban_nlos seed 2 (600 s, 100-Hz gyro and odometer, fixes 40 m RMS): a 40-s run of
    fixes 20 m off follows 14 s of clean fixes after two minutes of reflections."""
    return simulate_drive("urban_nlos", 2)


def test_a_long_reflected_run_does_not_outvote_the_clean_fixes_around_it(long_run) -> None:
    """Fix by fix, the run's 200 reflected fixes outvoted the 70 clean ones before it: the
    screen kept the reflected run and left out the clean fixes, and ekf + RTS ended 12.4 m
    from the truth.  A run votes once: 1.4 m.  (Fix by fix with the gyro's scale estimated,
    decisions/0074, the run pulls less: 7.2 m; held at 0 here.)"""
    sim = long_run
    off = run_filter(sim, copy.deepcopy(sim.drive), "ekf", smooth=True, pipeline=True,
                     overrides={"graph": {"nlos_segments": False, "gyro_scale_prior_sd": 1e-6}})
    on = run_filter(sim, copy.deepcopy(sim.drive), "ekf", smooth=True, pipeline=True)
    assert off.rmse_m > 0.25 * off.gnss_rmse_m
    assert on.rmse_m < 0.08 * on.gnss_rmse_m
    # what the filter was given: the fixes within 5 m of the truth, the others left out
    ep = on.epochs
    tr = sim.truth
    f = ep.has_gnss
    err = np.hypot(ep.gnss_e[f] - np.interp(ep.t_ns[f], tr.t_ns, tr.e),
                   ep.gnss_n[f] - np.interp(ep.t_ns[f], tr.t_ns, tr.n))
    used = on.result.gnss_used[f]
    assert used[err < 5.0].mean() > 0.95
    assert used[err > 10.0].mean() < 0.01


def test_the_graph_smoother_votes_by_segment_too(long_run) -> None:
    """The graph smoother from the screened filter's RTS track: fix by fix it followed the
    same run (8.4 m); by runs 0.6 m, every reflected run's fixes down-weighted."""
    sim = long_run
    rts = run_filter(sim, copy.deepcopy(sim.drive), "ekf", smooth=True, pipeline=True)
    p = config.defaults()
    out = smooth_graph(rts.epochs, rts.result, p)
    assert out.result is not None
    tr = sim.truth
    t = rts.epochs.t_ns
    err = np.hypot(out.result.e - np.interp(t, tr.t_ns, tr.e),
                   out.result.n - np.interp(t, tr.t_ns, tr.n))
    assert float(np.sqrt(np.mean(err ** 2))) < 0.05 * rts.gnss_rmse_m
    f = rts.epochs.has_gnss
    ferr = np.hypot(rts.epochs.gnss_e[f] - np.interp(t[f], tr.t_ns, tr.e),
                    rts.epochs.gnss_n[f] - np.interp(t[f], tr.t_ns, tr.n))
    w = out.gnss_weight[f]
    assert np.all(np.isfinite(w))
    assert np.median(w[ferr > 10.0]) < 0.1 and np.median(w[ferr < 3.0]) > 0.5


def test_far_segments_do_not_add_up_to_a_pull() -> None:
    """urban_nlos seed 6 (283 s, 5-Hz gyro and odometer): under a Cauchy vote every
    reflected segment 20-70 m off still pulls (its pull falls only as 1 / distance), and
    together they moved the fit's first minute 15 m off its clean fixes, which the screen
    then left out: ekf ran 138 m from the truth against fixes at 40 m (16 m since the epochs
    before the first fix kept are dead-reckoned back from it, decisions/0057).  Under the
    bounded Geman-McClure vote a far segment does not pull: 1.7 m.  (Judged once: the
    screen's second judgement, against the ekf's track, rescues even the Cauchy vote, to
    4.0 m; and so do the reflected runs' Doppler speeds, which weigh them less: both runs
    here without them.  So does the gyro's scale estimated, decisions/0074, 1.5 m, and the
    course bias per segment, decisions/0079, 1.7 m: the Cauchy run holds both off.)"""
    sim = simulate_drive("urban_nlos", 6, 283.0, gyro_rate_hz=5.0, odo_rate_hz=5.0)
    r = run_filter(sim, copy.deepcopy(sim.drive), "ekf", pipeline=True,
                   overrides={"gnss": {"nlos_doppler_trust_mps": 0.0}})
    assert r.rmse_m < 0.1 * r.gnss_rmse_m
    cauchy = run_filter(sim, copy.deepcopy(sim.drive), "ekf", pipeline=True,
                        overrides={"graph": {"nlos_segment_kernel": "cauchy",
                                             "gyro_scale_prior_sd": 1e-6,
                                             "nlos_segment_course_sd_rad": 0.0},
                                   "gnss": {"nlos_screen_passes": 1,
                                            "nlos_doppler_trust_mps": 0.0}})
    assert cauchy.rmse_m > 5.0 * r.rmse_m and cauchy.result.info["lead_in_s"] > 30.0


def test_a_run_whose_doppler_disagrees_votes_less() -> None:
    """Each run's trust is 1 / (1 + (r / scale)^2), r its RMS Doppler-minus-odometer speed:
    a clean run (0.1 m/s) keeps nearly all of its vote, a reflected one (1 m/s) a fifth at a
    scale of 0.5 m/s; a run with too few measured speeds, or a fix in no run, keeps all of it."""
    rng = np.random.default_rng(7)
    runs = np.repeat([0, 1, 2, -1], [50, 40, 30, 5])
    mis = np.concatenate([rng.choice([-0.1, 0.1], 50), rng.choice([-1.0, 1.0], 40),
                          np.full(30, np.nan), np.full(5, 3.0)])
    mis[50:55] = np.nan            # a few unmeasured fixes do not change the run's RMS
    mis[90] = 2.0                  # the unmeasured run: 1 of 30 measured, below the minimum
    trust = segment_trust(runs, mis, 0.5)
    np.testing.assert_allclose(trust[:50], 1.0 / 1.04)
    np.testing.assert_allclose(trust[50:90], 0.2)
    np.testing.assert_array_equal(trust[90:], 1.0)
    np.testing.assert_array_equal(segment_trust(runs, mis, 0.0), 1.0)
