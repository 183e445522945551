"""Property tests of the GNS/GLL parsing and the RTKLIB .pos reader: random bytes and
mutated real lines never let anything but gpsdr's own errors escape, never take long
(a hang would show as an example over :data:`MAX_S`), and what is read is consistent
(lat/lon finite exactly where there is a fix, within their ranges)."""

from __future__ import annotations

import os
import time

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gpsdr_cli.errors import GpsdrError
from gpsdr_cli.io.nmea import parse_nmea
from gpsdr_cli.io.rtklib import parse_rtklib
from gpsdr_cli.testing.faults import mutate, nmea_fix_checksums
from tests.io.test_nmea import DAY

SETTINGS = settings(max_examples=int(os.environ.get("GPSDR_FUZZ_EXAMPLES", "150")), deadline=None)
MAX_S = 5.0  # s per example: the readers take milliseconds on these few lines

GNS_GLL = nmea_fix_checksums(b"$GNZDA,120000.00,17,05,2024,00,00*7B\r\n"
           b"$GNGNS,120000.00,4807.03800,N,01131.00000,E,RRAN,14,0.9,545.4,46.9,1.0,0000,V*7C\r\n"
           b"$GPGLL,4807.038,N,01131.000,E,120000.00,A,D*7C\r\n"
           b"$GNGNS,120001.00,,,,,NNNN,00,99.99,,,,,V*79\r\n"
           b"$GPGLL,,,,,120001.00,V,N*76\r\n"
           b"$GNRMC,120002.00,A,4807.03900,N,01131.00100,E,0.1,,170524,,,F,V*2E\r\n"
           b"$GNGNS,120002.00,4807.03800,N,01131.00000,E,FF,14,0.9,545.4,46.9,,,V*6E\r\n")
ZDA = GNS_GLL.split(b"\n", 1)[0] + b"\n"
POS = (b"% program   : RTKPOST ver.2.4.3\n"
       b"% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,6:ppp,"
       b"ns=# of satellites)\n"
       b"%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)"
       b"   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio\n"
       b"2024/05/17 12:00:00.000   48.117300000   11.516700000   520.0000   1  14   0.0100"
       b"   0.0120   0.0300   0.0010  -0.0020   0.0030   1.00    5.2\n"
       b"2024/05/17 12:00:01.000   48.117310000   11.516710000   520.1000   2  13   0.2100"
       b"   0.2200   0.4000   0.0100  -0.0200   0.0300   1.00    1.2\n"
       b"2314 475220.000   48.117320000   11.516720000   520.2000   5   9   2.1000"
       b"   2.2000   4.0000   0.1000  -0.2000   0.3000   0.00    0.0\n")


def _check_fixes(g) -> None:
    n = len(g.t_ns)
    assert g.t_ns.dtype == np.int64
    for a in (g.lat_deg, g.lon_deg, g.alt_m, g.sigma_e_m, g.sigma_n_m, g.hdop):
        assert len(a) == n and not np.isinf(a).any()
    has = np.isfinite(g.lat_deg)
    assert (np.isfinite(g.lon_deg) == has).all()
    assert (g.fix_quality[has] > 0).all()
    assert (np.abs(g.lat_deg[has]) <= 90).all() and (np.abs(g.lon_deg[has]) <= 180).all()
    assert ((g.sigma_e_m[np.isfinite(g.sigma_e_m)]) >= 0).all()


def _run(read, data: bytes) -> None:
    t0 = time.perf_counter()
    try:
        g = read(data)[0]
    except GpsdrError:
        pass
    else:
        _check_fixes(g)
    assert time.perf_counter() - t0 < MAX_S


def _nmea(data: bytes) -> tuple:
    return parse_nmea(data, name="f.nmea", date=DAY)


def _pos(data: bytes) -> tuple:
    return parse_rtklib(data, name="f.pos")


@SETTINGS
@given(st.binary(max_size=2000))
def test_random_bytes_nmea(data: bytes) -> None:
    _run(_nmea, data)


@SETTINGS
@given(st.binary(max_size=2000))
def test_random_bytes_pos(data: bytes) -> None:
    _run(_pos, data)
    _run(_pos, POS[:200] + data)  # after a real header


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1), fix=st.booleans(),
       utf16=st.sampled_from([None, "utf-16", "utf-16-le", "utf-16-be"]))
def test_mutated_gns_gll_lines(seed: int, fix: bool, utf16: str | None) -> None:
    """Mutations (bit flips, tokens, deletions, duplicated or swapped lines), with the
    checksums recomputed half of the time so the damage reaches the field parsers."""
    data = mutate(GNS_GLL, np.random.default_rng(seed))
    if fix:
        data = nmea_fix_checksums(data)
    if utf16 is not None:
        data = data.decode("latin-1").encode(utf16)
    _run(_nmea, data)


@SETTINGS
@given(seed=st.integers(0, 2**32 - 1))
def test_mutated_pos_lines(seed: int) -> None:
    _run(_pos, mutate(POS, np.random.default_rng(seed)))


@SETTINGS
@given(fields=st.lists(st.one_of(
    st.sampled_from(["", "N", "S", "E", "W", "A", "V", "RR", "NNNNNN", "ZZ", "-1", "99.99",
                     "4807.038", "01131.000", "9999.999", "1e400", "nan", "120000.00", "250000"]),
    st.text(alphabet="0123456789.-+ENSWAVRFDPMeX", max_size=12)), min_size=0, max_size=16),
    kind=st.sampled_from(["GNGNS", "GPGLL", "BDGNS", "GQGLL"]))
def test_random_gns_gll_fields_with_valid_checksums(fields: list[str], kind: str) -> None:
    body = ",".join([kind, *fields]).encode()
    ck = 0
    for b in body:
        ck ^= b
    line = b"$" + body + b"*%02X\r\n" % ck
    _run(_nmea, ZDA + line)
