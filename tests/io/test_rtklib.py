"""RTKLIB ``.pos`` reader: every form, time systems and leap seconds, Q mapping, sigmas,
skipped lines, dispatch and ``gpsdr fuse --gps FILE.pos``.

Tolerances: 1e-9 deg (0.1 mm) for positions, 1e-4 m for heights and sigmas printed with
4 decimals, exact for times.
"""

from __future__ import annotations

import datetime
from pathlib import Path

import numpy as np
import pytest
from pyproj import Transformer

from gpsdr_cli.errors import InputError, NoDataError
from gpsdr_cli.io.readers import read_drive, sniff
from gpsdr_cli.io.rtklib import Q_TO_GGA, parse_rtklib, read_rtklib

DATA = Path(__file__).resolve().parents[1] / "data" / "rtklib"
TOL_DEG = 1e-9
S = 1_000_000_000
LLH_HEAD = ("% program   : RTKPOST ver.2.4.3\n"
            "% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,"
            "6:ppp,ns=# of satellites)\n"
            "%  {ts}                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)"
            "   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio\n")


def utc_ns(*args: int, sec: float = 0.0) -> int:
    d = datetime.datetime(*args, tzinfo=datetime.UTC)
    return int(d.timestamp()) * S + round(sec * S)


def llh_line(t: str, lat: float, lon: float, h: float, q: int, ns: int = 9,
             sdn: float = 0.0123, sde: float = 0.0234) -> str:
    return (f"{t}   {lat:12.9f}  {lon:13.9f} {h:10.4f} {q:3d} {ns:3d} {sdn:8.4f} {sde:8.4f}"
            "   0.0300   0.0010  -0.0020   0.0030   1.00    3.2\n")


def test_real_enu_baseline_solution_against_pyproj_topocentric() -> None:
    """RTKLIB's demo kinematic solution (ENU baselines from the base in ``% ref pos``):
    positions agree with pyproj's topocentric inverse to 1e-9 deg."""
    d = read_rtklib(DATA / "demo1-out-excerpt.pos")
    g = d.gnss
    assert len(g) == 16 and d.skipped.total == 0
    assert d.meta["rtklib_form"] == "enu"
    lat0, lon0, h0 = 40.086179918, -105.206044414, 1575.6355
    topo = Transformer.from_pipeline(  # ECEF -> ENU at the base; inverse: ENU -> ECEF
        f"+proj=topocentric +ellps=WGS84 +lat_0={lat0} +lon_0={lon0} +h_0={h0}")
    x, y, z = topo.transform(-0.6970, 0.1185, -2.5211, direction="INVERSE")
    lon, lat, h = Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True).transform(x, y, z)
    assert abs(g.lat_deg[0] - lat) < TOL_DEG and abs(g.lon_deg[0] - lon) < TOL_DEG
    assert abs(g.alt_m[0] - h) < 1e-4
    # GPST 17:24:57 - 17 leap seconds (2015-07-01 .. 2016-12-31) = 17:24:40 UTC
    assert g.t_ns[0] == utc_ns(2015, 12, 14, 17, 24, 40)
    assert (g.fix_quality == 5).all()  # Q 2 float -> GGA 5
    assert g.sigma_e_m[0] == pytest.approx(1.3662, abs=1e-12)  # sde comes first in this form
    assert g.sigma_n_m[0] == pytest.approx(1.5742, abs=1e-12)
    assert g.n_sats.tolist()[-3:] == [14, 15, 15]


def test_enu_without_ref_pos_is_refused(tmp_path: Path) -> None:
    text = (DATA / "demo1-out-excerpt.pos").read_text().replace("% ref pos", "% xxx pos")
    with pytest.raises(InputError, match=r"x\.pos:25: RTKLIB ENU-baseline .* out-solformat=llh"):
        parse_rtklib(text.encode(), name="x.pos")


@pytest.mark.parametrize("q", range(7))
def test_q_maps_to_gga_quality(q: int) -> None:
    data = LLH_HEAD.format(ts="GPST") + llh_line("2020/06/01 12:00:00.000", 35.5, 139.5, 40.0, q)
    g = parse_rtklib(data.encode())[0]
    assert g.fix_quality.tolist() == [{0: 0, 1: 4, 2: 5, 3: 2, 4: 2, 5: 1, 6: 2}[q]]
    assert Q_TO_GGA[q] == g.fix_quality[0]
    if q:
        assert abs(g.lat_deg[0] - 35.5) < TOL_DEG and abs(g.alt_m[0] - 40.0) < 1e-9
        assert g.sigma_n_m[0] == pytest.approx(0.0123) and g.sigma_e_m[0] == pytest.approx(0.0234)
        assert g.n_sats[0] == 9
    else:
        assert np.isnan(g.lat_deg[0]) and np.isnan(g.sigma_e_m[0])


@pytest.mark.parametrize(("ts", "when", "want"), [
    ("GPST", "2016/12/31 12:00:00.000", utc_ns(2016, 12, 31, 11, 59, 43)),  # 17 s
    ("GPST", "2017/01/02 12:00:00.000", utc_ns(2017, 1, 2, 11, 59, 42)),  # 18 s
    ("GPST", "2024/05/17 12:00:00.250", utc_ns(2024, 5, 17, 11, 59, 42, sec=0.25)),
    ("UTC", "2024/05/17 12:00:00.250", utc_ns(2024, 5, 17, 12, 0, 0, sec=0.25)),
    ("JST", "2024/05/17 21:00:00.000", utc_ns(2024, 5, 17, 12, 0, 0)),
    ("GPST", "2314 475218.000", utc_ns(2024, 5, 17, 12, 0, 0)),  # week 2314, Fri 12:00:18 GPST
])
def test_time_systems_and_leap_seconds(ts: str, when: str, want: int) -> None:
    data = LLH_HEAD.format(ts=ts) + llh_line(when, 35.5, 139.5, 40.0, 1)
    g, _, meta = parse_rtklib(data.encode())
    assert int(g.t_ns[0]) == want
    assert meta["time_system"] == ts


def test_dms_form() -> None:
    head = LLH_HEAD.format(ts="UTC").replace("latitude(deg) longitude(deg)",
                                             "latitude(d'\")   longitude(d'\")")
    line = ("2024/05/17 12:00:00.000  -33 27 00.12345  -70 39 36.00000   520.0000   1  12"
            "   0.0100   0.0200   0.0300   0.0000   0.0000   0.0000   0.00    9.9\n"
            "2024/05/17 12:00:01.000   -0 30 00.00000    0 15 00.00000   520.0000   1  12"
            "   0.0100   0.0200   0.0300   0.0000   0.0000   0.0000   0.00    9.9\n")
    g, report, meta = parse_rtklib((head + line).encode())
    assert meta["rtklib_form"] == "dms" and report.total == 0
    np.testing.assert_allclose(g.lat_deg, [-(33 + 27 / 60 + 0.12345 / 3600), -0.5], atol=TOL_DEG,
                               rtol=0)
    np.testing.assert_allclose(g.lon_deg, [-(70 + 39 / 60 + 36 / 3600), 0.25], atol=TOL_DEG, rtol=0)


def test_xyz_form_converts_position_and_rotates_the_covariance() -> None:
    lat, lon, h = 48.1173, 11.5167, 520.0
    x, y, z = Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True).transform(lon, lat, h)
    # a covariance diagonal in ENU (sigma_e 0.3 m, sigma_n 0.5 m, sigma_u 1.0 m) in ECEF
    p, l_ = np.radians(lat), np.radians(lon)
    r = np.array([[-np.sin(l_), np.cos(l_), 0],
                  [-np.sin(p) * np.cos(l_), -np.sin(p) * np.sin(l_), np.cos(p)],
                  [np.cos(p) * np.cos(l_), np.cos(p) * np.sin(l_), np.sin(p)]])
    cov = r.T @ np.diag([0.3**2, 0.5**2, 1.0**2]) @ r
    sq = [np.sign(c) * np.sqrt(abs(c)) for c in (cov[0, 0], cov[1, 1], cov[2, 2], cov[0, 1],
                                                 cov[1, 2], cov[2, 0])]
    head = ("% (x/y/z-ecef=WGS84,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,ns=# of satellites)\n"
            "%  GPST                      x-ecef(m)      y-ecef(m)      z-ecef(m)   Q  ns   sdx(m)"
            "   sdy(m)   sdz(m)  sdxy(m)  sdyz(m)  sdzx(m) age(s)  ratio\n")
    line = (f"2024/05/17 12:00:18.000 {x:14.4f} {y:14.4f} {z:14.4f}   1  14 "
            + " ".join(f"{v:8.6f}" for v in sq) + "   0.00    5.0\n")
    g, _, meta = parse_rtklib((head + line).encode())
    assert meta["rtklib_form"] == "xyz"
    assert abs(g.lat_deg[0] - lat) < 1e-8 and abs(g.lon_deg[0] - lon) < 1e-8  # 0.1 mm printed
    assert abs(g.alt_m[0] - h) < 1e-3
    assert g.sigma_e_m[0] == pytest.approx(0.3, abs=1e-4)
    assert g.sigma_n_m[0] == pytest.approx(0.5, abs=1e-4)
    assert g.t_ns[0] == utc_ns(2024, 5, 17, 12, 0, 0)


def test_malformed_lines_are_skipped_and_counted_with_line_numbers() -> None:
    good = llh_line("2024/05/17 12:00:00.000", 35.5, 139.5, 40.0, 1)
    lines = [LLH_HEAD.format(ts="GPST"), good,
             "2024/13/17 12:00:01.000   35.5 139.5 40.0 1 9\n",  # line 5: month 13
             "2024/05/17 12:00:02.000   35.5 139.5 40.0 9 9\n",  # line 6: Q 9
             "2024/05/17 12:00:03.000   95.5 139.5 40.0 1 9\n",  # line 7: latitude 95
             "2024/05/17 12:00:04.000   35.5 abc 40.0 1 9\n",  # line 8
             "2024/05/17 12:00:05.000   35.5\n",  # line 9: truncated
             "\n", good.replace(":00.000", ":06.000")]
    g, report, _ = parse_rtklib("".join(lines).encode(), name="c.pos")
    assert len(g) == 2
    assert report.total == 5
    assert report.first["malformed time (expected YYYY/MM/DD HH:MM:SS.sss)"] == "c.pos:5"
    assert report.first["malformed quality Q (expected 0..6)"] == "c.pos:6"
    assert report.first["malformed position (latitude/longitude out of range)"] == "c.pos:7"
    assert report.first["malformed number"] == "c.pos:8"
    assert report.first["too few columns (expected time, position, Q, ns)"] == "c.pos:9"


def test_no_solution_line_and_empty_file() -> None:
    with pytest.raises(NoDataError, match=r"^n\.pos: no RTKLIB solution line parsed \(1 "):
        parse_rtklib((LLH_HEAD.format(ts="GPST") + "x y z 1 2 3 4\n").encode(), name="n.pos")
    with pytest.raises(InputError, match=r"^e\.pos: empty file"):
        parse_rtklib(b"  \n", name="e.pos")


def test_dispatch_and_fuse_with_gps_pos(tmp_path: Path, sample_dir: Path, gpsdr) -> None:
    """A .pos made from the sample drive's NMEA fixes (UTC) fuses with its gyro and odometer."""
    from gpsdr_cli.config import defaults
    from gpsdr_cli.io.nmea import read_nmea

    nm = read_nmea(sample_dir / "gps.nmea").gnss
    lines = [LLH_HEAD.format(ts="UTC")]
    for t, la, lo, h, q in zip(nm.t_ns, nm.lat_deg, nm.lon_deg, nm.alt_m, nm.fix_quality,
                               strict=True):
        if q > 0:
            stamp = datetime.datetime.fromtimestamp(int(t) // 1000 / 1e6, datetime.UTC)
            lines.append(llh_line(stamp.strftime("%Y/%m/%d %H:%M:%S.%f")[:-3], la, lo, h, 5))
    pos = tmp_path / "rover.pos"
    pos.write_text("".join(lines))
    assert sniff(pos) == "rtklib"
    d = read_drive(gps=pos, gyro=sample_dir / "gyro.csv", odo=sample_dir / "odo.csv",
                   params=defaults())
    assert len(d.gnss) == int((nm.fix_quality > 0).sum())
    ok = nm.fix_quality > 0
    np.testing.assert_allclose(d.gnss.lat_deg, nm.lat_deg[ok], atol=1e-9, rtol=0)
    np.testing.assert_array_equal(d.gnss.t_ns, nm.t_ns[ok])
    out = tmp_path / "track.parquet"
    result = gpsdr(["fuse", "--gps", pos, "--gyro", sample_dir / "gyro.csv",
                    "--odo", sample_dir / "odo.csv", "-o", out])
    assert result.exit_code == 0, result.output
    assert out.exists()
    info = gpsdr(["info", pos])
    assert info.exit_code == 0 and "rtklib" in info.output
    assert "converted to UTC" not in info.output  # a UTC file


def test_an_infinite_field_where_dms_minutes_would_be_is_skipped_not_raised() -> None:
    """A damaged line with "inf" in the second field (a d m s line's minutes) was an
    OverflowError out of the form test; it is one skipped line, the others read."""
    head = LLH_HEAD.format(ts="UTC")
    good = ("2024/05/17 12:00:00.000   48.117300000   11.516700000   520.0000   1  14"
            "   0.0100   0.0200   0.0300   0.0000   0.0000   0.0000   0.00    9.9\n")
    bad = ("2024/05/17 12:00:01.000   48.117300000   inf   11.516700000   520.   1  14"
           "   0.0100   0.0200   0.0300   0.0000   0.0000   0.0000   0.00    9.9\n")
    g, report, _ = parse_rtklib((head + good + bad + good.replace(":00.000", ":02.000")).encode())
    assert len(g) == 2 and report.total == 1
