"""A receiver that states centimetres (GGA 4, a 1-cm sigma) for fixes with metres of error.

Taken at its word the drive was an RTK drive and the track followed the metre noise: a
simulated 300-s urban-canyon drive so stated went from 1.05 m (aekf + RTS, the same fixes
stated honestly) to 6.22 m.  The fixes' own steps tell (decision 0028).
"""

from __future__ import annotations

import copy
import dataclasses

import numpy as np
import pytest

from gpsdr_cli import config
from gpsdr_cli.align import build_epochs
from gpsdr_cli.io.mcap import read_mcap
from gpsdr_cli.pipeline import choose_frame, fuse
from gpsdr_cli.rtk_false_fix import centimetre_fixes
from gpsdr_cli.simulate import simulate_drive

from .conftest import SHARED_DATA


def _stated_to_a_centimetre(sim):
    g = sim.drive.gnss
    q = np.where(g.valid, 4, g.fix_quality).astype(np.int8)
    one_cm = np.full(len(g), 0.01)
    return dataclasses.replace(sim.drive, gnss=dataclasses.replace(
        g, fix_quality=q, sigma_e_m=one_cm, sigma_n_m=one_cm.copy()))


@pytest.fixture(scope="module")
def canyon():
    return simulate_drive("urban_canyon", seed=1, duration_s=300.0)


def test_metre_fixes_stated_to_a_centimetre_are_no_rtk_fixes(canyon):
    drive = _stated_to_a_centimetre(canyon)
    p = config.defaults()
    ep = build_epochs(drive, canyon.frame, p)
    assert ep.rtk_fixed_share == 0.0
    assert not centimetre_fixes(ep, p).any()
    sd = np.hypot(ep.gnss_sd_e, ep.gnss_sd_n)[ep.has_gnss] / np.sqrt(2.0)
    assert 0.5 < np.median(sd) < 5.0                         # m: the steps' scatter, not 1 cm
    assert any("not RTK" in w for w in drive.meta["warnings"])


def test_honest_centimetre_fixes_keep_their_word():
    p = config.defaults()
    sim = simulate_drive("rtk", seed=1, duration_s=300.0)
    ep = build_epochs(copy.deepcopy(sim.drive), sim.frame, p)
    assert ep.rtk_fixed_share > 0.6 and centimetre_fixes(ep, p).sum() > 700
    assert not any("not RTK" in w for w in sim.drive.meta.get("warnings", []))
    drive = read_mcap(SHARED_DATA / "mcap_samples" / "ublox_gps_ros2.mcap")  # a real F9P
    ep = build_epochs(drive, choose_frame(drive, p), p)
    assert ep.rtk_fixed_share > 0.9 and centimetre_fixes(ep, p).sum() > 2000
    assert not any("not RTK" in w for w in drive.meta.get("warnings", []))


def test_the_track_is_as_good_as_with_the_fixes_stated_honestly(canyon):
    p = config.defaults()
    p["filter"]["smoother"] = "rts"
    out = []
    for drive in (copy.deepcopy(canyon.drive), _stated_to_a_centimetre(canyon)):
        res = fuse(drive, copy.deepcopy(p), reference=canyon.reference())
        out.append(res.summary()["rmse_m"])
    honest, stated = out
    assert stated < 1.1 * honest, (stated, honest)          # m; 6.22 against 1.05 before
