"""Non-line-of-sight (NLOS) errors added to a simulated drive's fixes, as real city GNSS
lies: steps of 10-80 m that persist for 5-60 s, consistent among themselves during a step,
while the reported sigma (GST) and HDOP stay small.

Used by the smoother's tests and ``benchmarks/accuracy.py`` (scenario ``urban_nlos``).
Units: metres in the simulation's local frame, seconds.
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np

from ..conventions import NS_PER_S
from ..simulate import SimDrive


@dataclasses.dataclass
class NlosDrive:
    """The drive with NLOS fixes; ``nlos`` marks the affected GNSS records."""

    sim: SimDrive
    drive: object
    nlos: np.ndarray


def add_nlos(sim: SimDrive, seed: int, *, share: float = 0.35, step_m: tuple[float, float] = (10.0, 80.0),
             length_s: tuple[float, float] = (5.0, 60.0), sigma_m: float = 1.5,
             hdop: float = 0.9) -> NlosDrive:
    """A copy of ``sim.drive`` whose fixes carry NLOS steps over about ``share`` of the
    drive's time (step sizes and lengths uniform in the ranges, directions uniform), and
    report ``sigma_m`` (GST) and ``hdop`` at every fix."""
    rng = np.random.default_rng(seed)
    drive = copy.deepcopy(sim.drive)
    g = drive.gnss
    t = (g.t_ns - g.t_ns[0]) / NS_PER_S
    dur = float(t[-1]) if len(t) else 0.0
    de = np.zeros(len(t))
    dn = np.zeros(len(t))
    nlos = np.zeros(len(t), bool)
    t0 = float(rng.uniform(10.0, 40.0))
    while t0 < dur - 5.0:
        length = float(rng.uniform(*length_s))
        size = float(rng.uniform(*step_m))
        ang = float(rng.uniform(0.0, 2 * np.pi))
        m = (t >= t0) & (t < t0 + length)
        # a reflection wanders a little along its step: 1 m of slow noise on top
        wob = np.cumsum(rng.normal(0.0, 0.05, m.sum()))
        de[m] += size * np.sin(ang) + wob
        dn[m] += size * np.cos(ang) + wob[::-1]
        nlos |= m
        # gaps between steps so that about `share` of the time is NLOS
        mean_len = 0.5 * (length_s[0] + length_s[1])
        t0 += length + float(rng.exponential(mean_len * (1.0 - share) / share))
    ok = np.isfinite(g.lat_deg)
    e, n = sim.frame.forward(g.lat_deg[ok], g.lon_deg[ok])
    lat, lon = sim.frame.inverse(e + de[ok], n + dn[ok])
    g.lat_deg = g.lat_deg.copy()
    g.lon_deg = g.lon_deg.copy()
    g.lat_deg[ok] = lat
    g.lon_deg[ok] = lon
    g.sigma_e_m = np.where(ok, sigma_m, np.nan)
    g.sigma_n_m = np.where(ok, sigma_m, np.nan)
    g.hdop = np.where(ok, hdop, np.nan)
    return NlosDrive(sim=sim, drive=drive, nlos=nlos & ok)
