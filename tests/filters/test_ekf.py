"""The non-adaptive ekf: fixed Q and ONE constant GNSS sigma for the whole drive."""

from __future__ import annotations

import numpy as np

from gpsdr_cli.config import defaults
from gpsdr_cli.filters import get
from gpsdr_cli.filters.aekf import gnss_noise

from . import tiny_drive


def test_ekf_uses_one_constant_sigma():
    """Per-fix sigmas 1 m and 4 m: the ekf's R is their median everywhere; the aekf's follows."""
    ep, _ = tiny_drive(60.0, seed=31, dr_hz=10.0)
    sd = np.where(np.arange(len(ep)) % 3 == 0, 4.0, 1.0)
    ep.gnss_sd_e = np.where(ep.has_gnss, sd, np.nan)
    ep.gnss_sd_n = ep.gnss_sd_e.copy()
    r_e, _, ka, sigma = gnss_noise(ep, defaults(), adaptive=False)
    expected = float(np.median(ep.gnss_sd_e[ep.has_gnss]))
    assert sigma == expected
    np.testing.assert_allclose(r_e[ep.has_gnss], expected ** 2)
    assert np.all(ka == 1.0)
    r_e_a, _, _, _ = gnss_noise(ep, defaults(), adaptive=True)
    np.testing.assert_allclose(r_e_a[ep.has_gnss], ep.gnss_sd_e[ep.has_gnss] ** 2)
    res = get("ekf")(ep, defaults())
    assert res.info["ekf_gnss_sigma_m"] == expected


def test_ekf_ignores_pdop_regimes_aekf_does_not():
    """Poor PDOP (8) for 20 s: the aekf inflates R (k = 10), so its NIS there is tiny;
    the ekf's R is unchanged and its NIS stays chi-square-sized."""
    ep, _ = tiny_drive(90.0, seed=32, dr_hz=10.0, bad_pdop=((30.0, 50.0, 8.0),))
    t = (ep.t_ns - ep.t_ns[0]) / 1e9
    poor = ep.has_gnss & (t >= 31.0) & (t < 50.0)
    ekf = get("ekf")(ep, defaults())
    aekf = get("aekf")(ep, defaults())
    assert np.median(aekf.nis[poor]) < 0.1 * np.median(ekf.nis[poor])
    assert 0.3 < np.median(ekf.nis[poor]) < 4.0
