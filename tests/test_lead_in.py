"""The lead-in: gyro and odometer logged before the receiver's first fix
(:mod:`gpsdr_cli.lead_in`).  The filters start at the first fix and the epochs before it
are dead-reckoned backwards; before, every filter started at the first fix's position at
the first gyro/odometer epoch (comma2k19 without its first 10 s of fixes: ekf 97.5 m RMSE
forward, fkf 58.8 m, the fixes alone 2.15 m)."""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from gpsdr_cli import config, lead_in, pipeline
from gpsdr_cli.conventions import NS_PER_S
from gpsdr_cli.simulate import simulate_drive

#: s of fixes removed at the start
LEAD_IN_S = 20.0


@pytest.fixture(scope="module")
def late_fix():
    sim = simulate_drive("open_sky", seed=3, duration_s=150.0)
    drive = copy.deepcopy(sim.drive)
    g = drive.gnss
    keep = g.t_ns >= g.t_ns[0] + int(LEAD_IN_S * NS_PER_S)
    drive.gnss = dataclasses.replace(g, **{f.name: getattr(g, f.name)[keep]
                                            for f in dataclasses.fields(g)
                                            if isinstance(getattr(g, f.name), np.ndarray)
                                            and len(getattr(g, f.name)) == len(keep)})
    return sim, drive


def _errors(sim, drive, name: str, smooth: bool, lead_s: float = LEAD_IN_S):
    p = config.defaults()
    p["filter"]["name"] = name
    p["filter"]["smooth"] = smooth
    p["filter"]["smoother"] = "rts" if smooth else "none"
    res = pipeline.fuse(drive, p)
    t = res.epochs.t_ns
    tr = sim.truth
    te, tn = res.frame.forward(tr["lat"].to_numpy(), tr["lon"].to_numpy())  # fuse's own frame
    err = np.hypot(res.track["e"].to_numpy() - np.interp(t, tr.t_ns, te),
                   res.track["n"].to_numpy() - np.interp(t, tr.t_ns, tn))
    lead = (t - t[0]) / NS_PER_S < lead_s
    return err, lead, res


@pytest.mark.parametrize("name", ["ekf", "aekf", "fkf", "fafkf"])
@pytest.mark.parametrize("smooth", [False, True])
def test_a_late_first_fix_is_dead_reckoned_back(late_fix, name: str, smooth: bool) -> None:
    sim, drive = late_fix
    err, lead, res = _errors(sim, drive, name, smooth)
    assert res.result.info["lead_in_epochs"] == int(lead.sum())
    assert abs(res.result.info["lead_in_s"] - LEAD_IN_S) < 0.05
    # m: ~350 m driven backwards from the first fix with the gyro and odometer
    assert float(np.max(err[lead])) < 10.0, f"{name}: lead-in max {np.max(err[lead]):.1f} m"
    # m: after the first fix, open-sky accuracy (the fixes alone: 1.4 m RMS)
    assert float(np.sqrt(np.mean(err[~lead] ** 2))) < 1.0
    # the lead-in's sigma covers its error (2-D, 3 sigma of the larger axis)
    sd = np.maximum(res.track["sigma_e"].to_numpy(), res.track["sigma_n"].to_numpy())
    assert np.all(err[lead] < 3.0 * np.sqrt(2.0) * sd[lead])
    assert not res.track["gnss_used"].to_numpy()[lead].any()


def test_without_the_lead_in_the_filter_starts_wrong(late_fix, monkeypatch) -> None:
    """The old behaviour (no split): the first fix's position at the first DR epoch."""
    sim, drive = late_fix
    monkeypatch.setattr(lead_in, "split", lambda epochs: (0, epochs))
    err, lead, _ = _errors(sim, drive, "ekf", False)
    assert float(np.max(err[lead])) > 100.0


def test_a_lead_in_whose_heading_nothing_tells_holds_the_first_fix() -> None:
    """A 150-s stop-and-go drive whose fixes start at 60 s, when the car has been parked for
    30 s and stays parked: nothing after the first fix says which way the car came.  The
    lead-in went back along heading 0 (north; the car had driven south to its spot): 535 m
    off with a sigma of 9 m.  The first fix is held with the odometer's distance as its sigma."""
    sim = simulate_drive("stop_and_go", seed=2, duration_s=150.0)
    drive = copy.deepcopy(sim.drive)
    g = drive.gnss
    keep = g.t_ns >= g.t_ns[0] + int(60.0 * NS_PER_S)
    drive.gnss = dataclasses.replace(g, **{f.name: getattr(g, f.name)[keep]
                                            for f in dataclasses.fields(g)
                                            if isinstance(getattr(g, f.name), np.ndarray)
                                            and len(getattr(g, f.name)) == len(keep)})
    err, lead, res = _errors(sim, drive, "aekf", False, lead_s=60.0)
    assert float(np.max(err[lead])) < 300.0          # the car's farthest from where it parked
    sd = np.maximum(res.track["sigma_e"].to_numpy(), res.track["sigma_n"].to_numpy())
    assert np.all(err[lead] < 3.0 * np.sqrt(2.0) * sd[lead])


def test_no_split_when_the_fix_comes_first() -> None:
    sim = simulate_drive("open_sky", seed=1, duration_s=30.0)
    p = config.defaults()
    from gpsdr_cli.align import build_epochs

    ep = build_epochs(copy.deepcopy(sim.drive), sim.frame, p)
    k, rest = lead_in.split(ep)
    assert k == 0 and rest is ep


@pytest.mark.parametrize("smooth", [False, True])
def test_a_gnss_only_log_holds_its_first_fix_before_it(smooth: bool) -> None:
    """A GNSS-only log whose first 165 s are no-fix records (a cold start; the car drove
    ~900 m then stopped, and the first fix comes while it stands).  The filter run from the
    first record had carried the velocity it found after the fix back through them: 830 m
    of invented motion forward, 285 m smoothed.  Nothing measured motion there: the first
    fix's position is held, its sigma the filters' 60 m/s bound on an unmeasured step."""
    from gpsdr_cli.testing.faults import drop_streams

    sim = simulate_drive("open_sky", seed=3, duration_s=300.0)  # stopped from 157 to 178 s
    drive = drop_streams(copy.deepcopy(sim.drive), "gyro", "odo")
    g = drive.gnss
    cold = g.t_ns < g.t_ns[0] + int(165.0 * NS_PER_S)
    gone = np.where(cold, np.nan, 1.0)
    drive.gnss = dataclasses.replace(
        g, lat_deg=g.lat_deg * gone, lon_deg=g.lon_deg * gone, alt_m=g.alt_m * gone,
        speed_mps=g.speed_mps * gone, course_deg=g.course_deg * gone,
        fix_quality=np.where(cold, 0, g.fix_quality).astype(g.fix_quality.dtype))
    p = config.defaults()
    p["filter"]["smooth"] = smooth
    p["filter"]["smoother"] = "rts" if smooth else "none"
    res = pipeline.fuse(drive, p)
    k = res.result.info["lead_in_epochs"]
    assert abs(res.result.info["lead_in_s"] - 165.0) < 0.25
    e, n = res.track["e"].to_numpy(), res.track["n"].to_numpy()
    assert np.all(np.isfinite(e)) and np.all(np.isfinite(n))
    assert float(np.max(np.hypot(e[:k] - e[k], n[:k] - n[k]))) < 1e-6
    sd = res.track["sigma_e"].to_numpy()
    assert sd[0] > 60.0 * 164.0 and np.all(np.diff(sd[:k]) <= 1e-9)   # shrinking to the fix
    tr = sim.truth
    te, tn = res.frame.forward(tr["lat"].to_numpy(), tr["lon"].to_numpy())
    t = res.epochs.t_ns
    err = np.hypot(e - np.interp(t, tr.t_ns, te), n - np.interp(t, tr.t_ns, tn))
    assert float(np.max(err[:k])) > 300.0          # the car did move: the hold is a bound
    assert np.all(err[:k] < 3.0 * sd[:k] + 1.0)
