"""Merging streams into epochs: ordering, dropped records, offsets, sigmas, outage marking."""

from __future__ import annotations

import numpy as np
import pytest

from gpsdr_cli import config
from gpsdr_cli.align import REASON_SPIKE, build_epochs, outage_mask
from gpsdr_cli.conventions import NS_PER_S
from gpsdr_cli.geodesy import LocalFrame
from gpsdr_cli.io.drive import Drive, GnssFixes, Odometry, YawRates

T0 = 1_600_000_000 * NS_PER_S


def _gnss(times_s: list[float], quality: list[int] | None = None) -> GnssFixes:
    g = GnssFixes.empty(len(times_s))
    g.t_ns[:] = T0 + np.round(np.asarray(times_s) * NS_PER_S).astype(np.int64)
    g.fix_quality[:] = 1 if quality is None else quality
    g.lat_deg[:] = 48.0 + 1e-5 * np.arange(len(times_s))
    g.lon_deg[:] = 11.0
    g.lat_deg[g.fix_quality == 0] = np.nan
    g.lon_deg[g.fix_quality == 0] = np.nan
    g.hdop[:] = 1.0
    return g


def test_union_of_times_and_values_in_place() -> None:
    params = config.defaults()
    gyro_t = T0 + np.arange(0, 10) * NS_PER_S // 10
    drive = Drive(gnss=_gnss([0.0, 0.5]),
                  gyro=YawRates(gyro_t, np.linspace(0, 0.9, 10)),
                  odo=Odometry(gyro_t[::2] + 5_000_000, np.full(5, 3.0)))
    frame = LocalFrame.centred_on(48.0, 11.0)
    ep = build_epochs(drive, frame, params)
    assert len(ep) == 15  # 10 gyro stamps (two shared with GNSS) + 5 odometer stamps
    assert np.all(np.diff(ep.t_ns) > 0)
    assert ep.has_gnss.sum() == 2 and ep.has_gyro.sum() == 10 and ep.has_odo.sum() == 5
    assert ep.gnss_e[0] == pytest.approx(0.0, abs=1e-9)
    assert ep.gnss_n[ep.has_gnss][1] == pytest.approx(1.112, abs=0.01)  # 1e-5 deg north
    assert np.isnan(ep.yaw_rate_radps[~ep.has_gyro]).all()
    assert ep.dt_s[0] == 0.0 and ep.dt_s[1:].min() > 0


def test_duplicates_and_backward_steps_are_dropped_and_counted() -> None:
    params = config.defaults()
    t = T0 + np.array([0, 10, 10, 20, 5, 30]) * 10_000_000
    drive = Drive(gyro=YawRates(t, np.array([0.1, 0.2, 0.3, 0.4, 0.5, np.nan])))
    ep = build_epochs(drive, None, params)
    assert list(ep.yaw_rate_radps) == [0.1, 0.2, 0.4]
    counts = drive.skipped.counts
    assert counts["gyro: duplicate timestamp"] == 1
    assert counts[f"gyro: {REASON_SPIKE}"] == 1  # the lone step back
    assert counts["gyro: non-finite value"] == 1


def test_time_offset_shifts_the_stream() -> None:
    params = config.set_value(config.defaults(), "time.gnss_offset_s", 0.1)
    drive = Drive(gnss=_gnss([0.0, 1.0]))
    ep = build_epochs(drive, LocalFrame.centred_on(48.0, 11.0), params)
    assert ep.t_ns[0] == T0 + NS_PER_S // 10


def test_base_sigma_prefers_receiver_then_hdop_then_default() -> None:
    params = config.defaults()
    g = _gnss([0.0, 1.0, 2.0])
    g.sigma_e_m[0] = 0.7
    g.sigma_n_m[0] = 0.9
    g.hdop[2] = np.nan
    ep = build_epochs(Drive(gnss=g), LocalFrame.centred_on(48.0, 11.0), params)
    uere = params["gnss"]["uere_m"]
    assert ep.gnss_sd_e[0] == 0.7 and ep.gnss_sd_n[0] == 0.9
    assert ep.gnss_sd_e[1] == pytest.approx(uere / np.sqrt(2))
    assert ep.gnss_sd_e[2] == pytest.approx(params["gnss"]["sigma_default_m"] / np.sqrt(2))


def test_no_fix_rows_are_epochs_without_gnss_and_dr_fixes_are_not_used() -> None:
    params = config.defaults()
    g = _gnss([0.0, 1.0, 2.0, 3.0], quality=[1, 0, 6, 1])
    ep = build_epochs(Drive(gnss=g), LocalFrame.centred_on(48.0, 11.0), params)
    assert list(ep.has_gnss) == [True, False, False, True]
    assert np.isnan(ep.gnss_e[1]) and np.isnan(ep.gnss_e[2])


def test_outage_mask_marks_only_long_gaps() -> None:
    t = np.arange(0, 40) * NS_PER_S // 2  # 0 .. 19.5 s every 0.5 s
    fixes = t[(t < 5 * NS_PER_S) | (t >= 15 * NS_PER_S)]
    out = outage_mask(t, fixes, gap_s=1.5)
    inside = (t > 4.5 * NS_PER_S) & (t < 15 * NS_PER_S)
    assert np.array_equal(out, inside)
    assert outage_mask(t, fixes[:0], 1.5).all()
    # a 1 s hole is not an outage
    assert not outage_mask(t, t[t != 5 * NS_PER_S], 1.5).any()
