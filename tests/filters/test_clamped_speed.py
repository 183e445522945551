"""A receiver that reports a speed of exactly 0 below a threshold while its fixes move.

Found on a real 1-Hz SiRF log (JOSM's regression data): RMC speeds alternated between 1-2
m/s and 0.00 while the fixes moved 1-2 m a second.  Every zero was a standstill and a
zero-velocity measurement, so the track stayed 10-14 m behind the fixes for minutes
with a 1.6-m sigma.  The drive below creeps at 1.2 m/s for a minute between two stops,
under a simulated static-navigation clamp at 1.5 m/s.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd
import pytest
from click.testing import CliRunner

from gpsdr_cli import config
from gpsdr_cli.cli.main import cli
from gpsdr_cli.filters.gnss_model import clamped_speeds
from tests.io.test_nmea import ck

from . import tiny_drive

#: m, the largest |track - truth| east with each smoother (measured 4.5 / 3.0 / 2.0 m;
#: before: 18 / 15 / 61 m, the track parked for the whole creep)
MAX_ERR_M = {"none": 6.0, "rts": 4.5, "graph": 3.5}
CREEP_MPS = 1.2


def _creep_log(path) -> np.ndarray:
    """Parked 30 s, 60 s east at 1.2 m/s, parked 60 s; 1-Hz fixes with 0.3-m noise; the
    RMC speed 0.00 below 1.5 m/s.  Returns the true east offset (m) at each fix."""
    rng = np.random.default_rng(3)
    lat0, lon0 = 53.79, -1.727
    lines, east, e = [], [], 0.0
    for k in range(150):
        v = CREEP_MPS if 30 <= k < 90 else 0.0
        if k:
            e += v
        east.append(e)
        fe, fn = e + 0.3 * rng.standard_normal(), 0.3 * rng.standard_normal()
        lat = lat0 + fn / 111_200.0
        lon = lon0 + fe / (111_200.0 * math.cos(math.radians(lat0)))
        t = f"15{5 + k // 60:02d}{k % 60:02d}.000"
        la = f"{int(lat):02d}{(lat - int(lat)) * 60:07.4f}"
        lo = f"{int(abs(lon)):03d}{(abs(lon) - int(abs(lon))) * 60:07.4f}"
        kn = 0.0 if v < 1.5 else v / 0.514444
        lines.append(ck(f"GPGGA,{t},{la},N,{lo},W,1,08,1.0,100.0,M,47.9,M,,") + "\n")
        lines.append(ck(f"GPRMC,{t},A,{la},N,{lo},W,{kn:.2f},90.00,140808,,,A") + "\n")
    path.write_text("".join(lines))
    return np.asarray(east)


@pytest.mark.parametrize("smooth", ["none", "rts", "graph"])
def test_a_clamped_zero_speed_does_not_park_a_moving_track(tmp_path, smooth: str) -> None:
    log = tmp_path / "creep.nmea"
    east = _creep_log(log)
    out = tmp_path / "t.parquet"
    res = CliRunner().invoke(cli, ["fuse", "--gps", str(log), "--smooth", smooth, "-q",
                                   "-o", str(out)])
    assert res.exit_code == 0, res.output
    track = pd.read_parquet(out)
    assert len(track) == len(east)
    # the frame's origin is the first fix; the truth from there
    err = np.abs(track.e.to_numpy() - track.gnss_e.to_numpy()[0] - (east - east[0]))
    assert err.max() < MAX_ERR_M[smooth], err.max()
    # the parked stretches are still standstills, the creep is not
    static = track.static.to_numpy()
    assert static[5:28].all() and static[100:].all()
    assert not static[40:85].any()


def test_only_an_exact_zero_where_the_fixes_move_is_dropped() -> None:
    """A zero speed where the fixes move goes (with its course); a zero where they stand,
    and a small measured speed where they move (a reflected fix's jump at a stop), stay."""
    ep, _ = tiny_drive(60.0, seed=5, dr_hz=10.0, gnss_hz=5.0, gnss_sd_m=1.0,
                       stops=((20.0, 40.0),))
    p = config.defaults()
    t_s = (ep.t_ns - ep.t_ns[0]) / 1e9
    f = np.flatnonzero(ep.has_gnss)
    spd = ep.gnss_speed_mps.copy()
    moving = f[(t_s[f] > 5.0) & (t_s[f] < 15.0)]
    stopped = f[(t_s[f] > 25.0) & (t_s[f] < 35.0)]
    spd[moving[::2]] = 0.0          # clamped while driving
    spd[moving[1::2]] = 0.02        # a measured near-zero while driving: kept
    spd[stopped] = 0.0              # clamped at a real stop: kept
    ep.gnss_speed_mps[:] = spd
    out = clamped_speeds(ep, p)
    assert np.isnan(out.gnss_speed_mps[moving[::2]]).all()
    assert np.isnan(out.gnss_course_rad[moving[::2]]).all()
    np.testing.assert_array_equal(out.gnss_speed_mps[moving[1::2]], 0.02)
    np.testing.assert_array_equal(out.gnss_speed_mps[stopped], 0.0)
    # nothing else touched
    rest = np.setdiff1d(f, moving[::2])
    np.testing.assert_array_equal(out.gnss_speed_mps[rest], spd[rest])
