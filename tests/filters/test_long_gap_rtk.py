"""A GNSS-only log whose fixes stop for ten minutes and come back RTK fixed.

gpsd's ``nmea-rtk.log`` (a Trimble receiver, ``tests/data/nmea/gpsd-nmea-rtk-excerpt.log``):
DGPS fixes, a gap of 630 s, then fixes at GST-class centimetres.  Over the gap fkf's white-jerk
prediction grew the position variance to 5e12 m^2, the RTK fix's update cancelled it to
rounding noise larger than the fix's own 2e-4 m^2, the fused covariance came out indefinite,
and fkf / fafkf + RTS wrote negative variances (``gpsdr fuse`` stopped on a NaN sigma).  The
position's sigma ceiling is now 1e5 m, applied so that the gain a fix gives the other states
is kept (:func:`gpsdr_cli.filters.kernels_fkf.cap_variance`).
"""

from __future__ import annotations

import copy

import numpy as np
import pytest

from gpsdr_cli import config, filters
from gpsdr_cli.filters import kernels_fkf as kf
from gpsdr_cli.io.nmea import read_nmea
from gpsdr_cli.pipeline import fuse
from gpsdr_cli.testing.faults import nmea_checksum
from tests.conftest import REPO

LOG = REPO / "tests" / "data" / "nmea" / "gpsd-nmea-rtk-excerpt.log"


def _finite_track(track) -> None:
    for col in ("lat", "lon", "e", "n", "v_e", "v_n", "sigma_e", "sigma_n"):
        assert np.isfinite(track[col].to_numpy(float)).all(), col
    assert (track["sigma_e"] > 0).all() and (track["sigma_n"] > 0).all()


@pytest.mark.parametrize("smoother", ["rts", "graph", "none"])
@pytest.mark.parametrize("name", filters.NAMES)
def test_every_filter_follows_the_rtk_fixes_after_the_gap(name, smoother):
    p = config.defaults()
    p["filter"]["name"] = name
    p["filter"]["smooth"] = smoother != "none"
    p["filter"]["smoother"] = smoother
    res = fuse(read_nmea(LOG), p)
    tr = res.track
    _finite_track(tr)
    rtk = tr["time"] >= tr["time"].iloc[-1] - np.timedelta64(2, "s")
    d = np.hypot(tr["e"][rtk] - tr["gnss_e"][rtk], tr["n"][rtk] - tr["gnss_n"][rtk])
    assert np.nanmedian(d) < 0.03, (name, smoother, np.round(d.to_numpy(), 3))


def _restamped(lines: list[str], shift_s: float) -> list[str]:
    """``lines`` (GGA) with their UTC field moved by ``shift_s``, checksums remade."""
    out = []
    for line in lines:
        body = line[1:line.index("*")].split(",")
        t = int(body[1][:2]) * 3600 + int(body[1][2:4]) * 60 + float(body[1][4:]) + shift_s
        body[1] = f"{int(t // 3600):02d}{int(t % 3600 // 60):02d}{t % 60:05.2f}"
        text = ",".join(body)
        out.append(f"${text}*{nmea_checksum(text.encode()).decode()}")
    return out


@pytest.mark.parametrize("gap_s", [621.9, 629.9, 651.1, 811.7, 1000.0, 3600.0])
@pytest.mark.parametrize("name", ["fkf", "fafkf"])
def test_smoothed_variances_stay_positive_whatever_the_gap(name, gap_s, tmp_path):
    """Two DGPS fixes, the gap, two RTK fixes: before, 30 of 60 gaps of 600-1030 s gave
    fkf + RTS a negative variance (these four among them, the log's own 629.9 s too)."""
    lines = [ln for ln in LOG.read_text().splitlines() if ln.startswith("$")]
    dgps = [ln for ln in lines if ln.startswith("$GPRMC,13282")][-2:]
    rtk = [ln for ln in lines if ",4,19," in ln][:2]
    rtk = _restamped(rtk, gap_s - 629.9)
    path = tmp_path / "gap.nmea"
    path.write_text("\n".join(dgps + rtk) + "\n")
    drive = read_nmea(path)
    p = config.defaults()
    p["filter"]["name"] = name
    p["filter"]["smooth"] = True
    p["filter"]["smoother"] = "rts"
    res = fuse(copy.deepcopy(drive), p)
    _finite_track(res.track)
    last = res.track.iloc[-1]
    assert np.hypot(last.e - last.gnss_e, last.n - last.gnss_n) < 0.02


def test_the_variance_cap_keeps_the_regressions_and_stays_positive():
    """A prior after a long gap (position sigma 2.2e6 m, velocity 9e3 m/s, strongly
    correlated): capped, the position sigma is the ceiling, every other state's regression
    on the position (the gain a fix gives it) is unchanged, and P stays positive
    semi-definite.  The congruence D P D kept the correlations instead and multiplied those
    regressions by 22."""
    rng = np.random.default_rng(7)
    A = rng.normal(size=(kf.NX, kf.NX)) * np.array([2.2e6, 9e3, 25.0, 2.2e6, 9e3, 25.0,
                                                     1.0, 1.0, 0.16, 0.26])[:, None]
    P = A @ A.T / kf.NX
    before = P.copy()
    assert kf.cap_variance(P)
    for i in (kf.IE, kf.IN):
        assert np.sqrt(P[i, i]) == pytest.approx(kf.SD_CEILING[i])
    others = [j for j in range(kf.NX) if j not in (kf.IE, kf.IN)]
    np.testing.assert_allclose(P[others, kf.IE] / P[kf.IE, kf.IE],
                               before[others, kf.IE] / before[kf.IE, kf.IE], rtol=1e-9)
    ev = np.linalg.eigvalsh(P / np.sqrt(np.outer(np.diag(P), np.diag(P))))
    assert ev.min() > 0.0
