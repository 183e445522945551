"""Outage rows whose outage outlasts the reference, or begins before it.

Why: ``gpsdr fuse`` on a drive whose GNSS stops before the log does (real_degraded
"out20@40 (to end)") wrote ``end_error_m`` null, because the error was read at the
track's last epoch, after the reference had ended.
"""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from gpsdr_cli.config import defaults
from gpsdr_cli.conventions import NS_PER_S
from gpsdr_cli.evaluation import error_statistics
from tests.test_evaluation import SPEED, T0, row, straight_track

RATE_HZ = 10.0
GROWTH_MPS = 0.1  # the fused track drifts east at 0.1 m/s during the outage


def _drifting(out_from_s: float, out_to_s: float) -> pd.DataFrame:
    """100 s north at 10 m/s; an outage over [out_from_s, out_to_s] s in which the track
    drifts east by GROWTH_MPS x (time since the outage began)."""
    track, _ = straight_track(n_ep=1001, rate_hz=RATE_HZ)
    t_s = np.arange(1001) / RATE_HZ
    out = (t_s >= out_from_s - 1e-9) & (t_s <= out_to_s + 1e-9)
    track["gnss_outage"] = out
    track.loc[out, ["gnss_e", "gnss_n", "nis"]] = np.nan
    track["e"] = np.where(out, GROWTH_MPS * (t_s - out_from_s + 1.0 / RATE_HZ), 0.0)
    return track


def _reference(from_s: float, to_s: float) -> pd.DataFrame:
    t = T0 + (np.arange(round(from_s * RATE_HZ), round(to_s * RATE_HZ) + 1)
              * (NS_PER_S / RATE_HZ)).astype(np.int64)
    return pd.DataFrame({"t_ns": t, "e": 0.0, "n": SPEED * (t - T0) / NS_PER_S})


def test_outage_to_the_end_past_the_reference_has_an_end_error() -> None:
    track = _drifting(70.0, 100.0)              # GNSS gone from 70 s to the end (100 s)
    st = error_statistics(track, _reference(0.0, 90.0), "ekf", defaults())  # truth ends at 90 s
    o = row(st, "outage_1")
    assert o["end_utc"] == pd.Timestamp(T0 + 100 * NS_PER_S, unit="ns", tz="UTC").isoformat()
    assert o["end_error_utc"] == pd.Timestamp(T0 + 90 * NS_PER_S, unit="ns", tz="UTC").isoformat()
    assert o["end_error_m"] == pytest.approx(GROWTH_MPS * 20.1, abs=1e-9)   # m, at 90 s
    # 20.1 s from the last fix (69.9 s) to 90 s at 10 m/s along the reference: 201 m
    assert o["end_error_pct_distance"] == pytest.approx(100 * 2.01 / 201.0, rel=1e-6)
    # the whole outage: 201 m on the reference, then 10 s (100 m) along the fused track
    assert o["distance_m"] == pytest.approx(301.0, abs=0.01)                 # m


def test_outage_before_the_reference_begins_is_measured_to_its_end() -> None:
    track = _drifting(0.0, 30.0)                # no fix from the first epoch to 30 s
    st = error_statistics(track, _reference(10.0, 100.0), "ekf", defaults())
    o = row(st, "outage_1")
    assert o["end_error_m"] == pytest.approx(GROWTH_MPS * 30.1, abs=1e-9)   # m, at 30 s
    assert o["end_error_utc"] == o["end_utc"]
    # 0 .. 10 s along the fused track (drifting 1 cm per 1 m step), 10 .. 30 s on the reference
    track_part = 100 * np.hypot(1.0, GROWTH_MPS / RATE_HZ)
    assert o["distance_m"] == pytest.approx(track_part + 200.0, abs=1e-6)   # m
    assert o["end_error_pct_distance"] == pytest.approx(100 * 3.01 / (track_part + 200.0), rel=1e-9)


def test_outage_the_reference_never_covers_has_null_end_figures() -> None:
    track = _drifting(80.0, 100.0)
    st = error_statistics(track, _reference(0.0, 50.0), "ekf", defaults())
    o = row(st, "outage_1")
    assert pd.isna(o["end_error_m"]) and pd.isna(o["end_error_pct_distance"])
    assert pd.isna(o["end_error_utc"])
    assert o["distance_m"] == pytest.approx(20.1 * SPEED, abs=0.05)         # m, fused track
