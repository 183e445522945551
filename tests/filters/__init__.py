"""Filter tests, and a small drive fixture with known truth that builds Epochs directly.

:func:`tiny_drive` is a test fixture, not a second simulator: a smooth speed
and yaw-rate profile integrated on the epoch grid, sensors sampled from it with
seeded noise and the faults a test asks for (gyro bias, odometer scale error,
GNSS outages, stops, bad PDOP, multipath outliers).  The project's simulator is
:mod:`gpsdr_cli.simulate`.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from gpsdr_cli.align import Epochs, outage_mask


@dataclass
class Truth:
    t_s: np.ndarray
    e: np.ndarray
    n: np.ndarray
    v_e: np.ndarray
    v_n: np.ndarray
    speed: np.ndarray
    meta: dict = field(default_factory=dict)


def tiny_drive(duration_s: float = 120.0, *, seed: int = 0, dr_hz: float = 50.0,
               gnss_hz: float = 5.0, gnss_sd_m: float = 2.0, gyro_bias_radps: float = 0.0,
               gyro_sd_radps: float = 0.0017, odo_scale: float = 1.0, odo_sd_mps: float = 0.05,
               outages: tuple[tuple[float, float], ...] = (),
               stops: tuple[tuple[float, float], ...] = (), pdop: float = 1.5,
               bad_pdop: tuple[tuple[float, float, float], ...] = (),
               outliers: tuple[tuple[float, float, float], ...] = (), gyro: bool = True,
               odo: bool = True, gnss: bool = True, cruise_mps: float = 12.0,
               gnss_vel: bool = True) -> tuple[Epochs, Truth]:
    """Epochs and truth for a drive of ``duration_s`` s on a common grid of ``dr_hz``.

    ``stops``: (start_s, end_s) windows at zero speed (smooth ramps of 3 s around);
    ``outages``: (start_s, end_s) without GNSS; ``bad_pdop``: (start_s, end_s, pdop);
    ``outliers``: (start_s, end_s, metres) added east to every fix in the window.
    """
    rng = np.random.default_rng(seed)
    dt = 1.0 / dr_hz
    t = np.arange(0.0, duration_s + 1e-9, dt)
    n = len(t)
    # speed: cruise with gentle variation, ramps into and out of stops
    speed = cruise_mps + 2.0 * np.sin(2 * np.pi * t / 47.0)
    for a, b in stops:
        ramp = np.clip(np.minimum(t - (a - 3.0), (b + 3.0) - t) / 3.0, 0.0, 1.0)
        fac = np.where((t >= a) & (t <= b), 0.0, 1.0 - ramp)
        speed = speed * np.clip(fac, 0.0, 1.0)
    # heading rate (clockwise+, rad/s): a sequence of smooth turns, none while stopped
    psi_rate = 0.12 * np.sin(2 * np.pi * t / 31.0) * np.sin(2 * np.pi * t / 13.0) ** 2
    psi_rate = psi_rate * np.clip(speed / cruise_mps, 0.0, 1.0) ** 2  # no turning on the spot
    psi = 0.3 + np.concatenate(([0.0], np.cumsum(0.5 * (psi_rate[1:] + psi_rate[:-1]) * dt)))
    v_e = speed * np.sin(psi)
    v_n = speed * np.cos(psi)
    e = np.concatenate(([0.0], np.cumsum(0.5 * (v_e[1:] + v_e[:-1]) * dt))) + 100.0
    nn = np.concatenate(([0.0], np.cumsum(0.5 * (v_n[1:] + v_n[:-1]) * dt))) - 50.0

    step = max(1, round(dr_hz / gnss_hz))
    has_gnss = np.zeros(n, bool)
    if gnss:
        has_gnss[::step] = True
        for a, b in outages:
            has_gnss[(t >= a) & (t < b)] = False
    pd = np.full(n, np.nan)
    pd[::step] = pdop
    for a, b, p in bad_pdop:
        pd[::step][(t[::step] >= a) & (t[::step] < b)] = p
    g_e = np.where(has_gnss, e + rng.normal(0, gnss_sd_m, n), np.nan)
    g_n = np.where(has_gnss, nn + rng.normal(0, gnss_sd_m, n), np.nan)
    for a, b, m in outliers:
        g_e = np.where(has_gnss & (t >= a) & (t < b), g_e + m, g_e)
    sd = np.where(has_gnss, gnss_sd_m, np.nan)
    g_speed = np.where(has_gnss & gnss_vel, speed + rng.normal(0, 0.1, n), np.nan)
    g_course = np.where(has_gnss & gnss_vel, psi + rng.normal(0, 0.02, n), np.nan)
    has_gyro = np.full(n, gyro)
    has_odo = np.full(n, odo)
    yaw = np.where(has_gyro, -psi_rate + gyro_bias_radps + rng.normal(0, gyro_sd_radps, n), np.nan)
    odo_v = np.where(has_odo, np.maximum(speed * odo_scale + rng.normal(0, odo_sd_mps, n)
                                         * (speed > 0), 0.0), np.nan)
    if not (gyro or odo):  # GNSS-only: keep only GNSS epochs
        keep = has_gnss
    else:
        keep = np.ones(n, bool)
    t_ns = (np.round(t * 1e9).astype(np.int64) + 1_700_000_000 * 10**9)[keep]
    dts = np.zeros(keep.sum())
    dts[1:] = np.diff(t_ns) / 1e9
    fix_t = t_ns[has_gnss[keep]]
    gap_s = max(1.5, 2.5 / gnss_hz)
    ep = Epochs(t_ns=t_ns, dt_s=dts, has_gnss=has_gnss[keep], gnss_e=g_e[keep], gnss_n=g_n[keep],
                gnss_sd_e=sd[keep], gnss_sd_n=sd[keep], pdop=pd[keep],
                gnss_speed_mps=g_speed[keep], gnss_course_rad=g_course[keep],
                has_gyro=has_gyro[keep], yaw_rate_radps=yaw[keep], has_odo=has_odo[keep],
                odo_speed_mps=odo_v[keep], gnss_outage=outage_mask(t_ns, fix_t, gap_s),
                gap_s=gap_s)
    truth = Truth(t_s=t[keep], e=e[keep], n=nn[keep], v_e=v_e[keep], v_n=v_n[keep],
                  speed=speed[keep], meta={"gyro_bias_radps": gyro_bias_radps,
                                           "odo_scale": odo_scale})
    return ep, truth


def horizontal_error(result, truth: Truth) -> np.ndarray:
    """Per-epoch horizontal error (m) of a FilterResult against the fixture's truth."""
    return np.hypot(result.e - truth.e, result.n - truth.n)
