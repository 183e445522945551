"""Hypothesis property tests of the NMEA reader.

Random and mutated logs (bit flips, truncation, random-byte insertions, random field
values with valid checksums): only gpsdr's own InputError subclasses may escape;
every kept row has a real time; latitudes stay in [-90, 90] deg.
"""

from __future__ import annotations

import datetime

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpsdr_cli.errors import InputError
from gpsdr_cli.io.nmea import looks_like_nmea, parse_nmea

DAY = datetime.date(2024, 5, 17)
pytestmark = pytest.mark.filterwarnings("error")  # no numpy RuntimeWarning may escape
SETTINGS = settings(max_examples=150, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow])


def ck(body: bytes, lower: bool = False) -> bytes:
    x = 0
    for c in body:
        x ^= c
    return b"$" + body + b"*" + (f"{x:02x}" if lower else f"{x:02X}").encode()


BASE = b"\r\n".join(ck(b) for b in [
    b"GNRMC,235958.00,A,4807.038,N,01131.000,E,022.4,084.4,170524,,,A,V",
    b"GNGGA,235958.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
    b"GNGSA,A,3,01,02,03,,,,,,,,,,1.9,0.95,1.6,1",
    b"GNGST,235958.00,1.2,2.1,1.5,35.0,1.8,1.6,3.2",
    b"GNVTG,084.4,T,,M,022.4,N,041.5,K,A",
    b"GNZDA,235958.00,17,05,2024,00,00",
    b"GNRMC,000001.00,A,4807.038,N,01131.000,E,022.4,084.4,180524,,,A,V",
    b"GNGGA,000001.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,",
]) + b"\r\n"


def check(data: bytes) -> None:
    """Parse; only InputError subclasses may escape; kept rows are sane."""
    try:
        fixes, report, meta = parse_nmea(data, name="h.nmea", date=DAY)
    except InputError:
        return
    assert len(fixes) > 0
    assert fixes.t_ns.dtype == np.int64
    assert (fixes.t_ns > 0).all()  # every kept row has a time
    v = fixes.valid
    assert ((fixes.lat_deg[v] >= -90) & (fixes.lat_deg[v] <= 90)).all()
    assert ((fixes.lon_deg[v] >= -180) & (fixes.lon_deg[v] <= 180)).all()
    assert np.isnan(fixes.lat_deg[fixes.fix_quality == 0]).all()
    for arr in (fixes.hdop, fixes.pdop, fixes.vdop, fixes.sigma_e_m, fixes.sigma_n_m,
                fixes.speed_mps, fixes.course_deg, fixes.alt_m):
        assert not np.isinf(arr).any()
    assert report.total >= 0 and isinstance(meta, dict)


@SETTINGS
@given(st.binary(max_size=600))
def test_random_bytes(data: bytes) -> None:
    check(data)
    looks_like_nmea(data)


@SETTINGS
@given(st.lists(st.tuples(st.integers(0, len(BASE) * 8 - 1)), min_size=1, max_size=12))
def test_bit_flips(flips: list[tuple[int]]) -> None:
    buf = bytearray(BASE)
    for (bit,) in flips:
        buf[bit // 8] ^= 1 << (bit % 8)
    check(bytes(buf))


@SETTINGS
@given(st.integers(0, len(BASE)), st.integers(0, len(BASE)))
def test_truncation_and_cut(a: int, b: int) -> None:
    check(BASE[:a])
    check(BASE[:min(a, b)] + BASE[max(a, b):])


@SETTINGS
@given(st.lists(st.tuples(st.integers(0, len(BASE)), st.binary(min_size=1, max_size=8)),
                min_size=1, max_size=6))
def test_random_insertions(ins: list[tuple[int, bytes]]) -> None:
    buf = BASE
    for at, junk in sorted(ins, reverse=True):
        buf = buf[:at] + junk + buf[at:]
    check(buf)


FIELD = st.one_of(
    st.text(alphabet="0123456789.-+NSEWAVMDTKeE", max_size=12),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-10**7, 10**7).map(str),
    st.just(""),
)
TYPE = st.sampled_from(["GGA", "RMC", "GSA", "VTG", "GST", "ZDA"])
TALKER = st.sampled_from(["GP", "GN", "GL", "GA", "GB", "BD", "GQ", "QZ", "PQ"])


@SETTINGS
@given(st.lists(st.tuples(TALKER, TYPE, st.lists(FIELD, max_size=30), st.booleans()),
                min_size=1, max_size=12))
def test_checksum_valid_random_fields(sentences: list) -> None:
    lines = []
    for talker, typ, fields, lower in sentences:
        body = ",".join([talker + typ, *fields]).encode("ascii", "replace")
        lines.append(ck(body, lower))
    check(b"\n".join(lines) + b"\n")


@SETTINGS
@given(st.lists(st.tuples(st.integers(0, 23), st.integers(0, 59), st.integers(0, 59),
                          st.integers(0, 9000), st.floats(-89.99, 89.99),
                          st.floats(-179.99, 179.99), st.sampled_from([0, 1, 2, 4, 5, 6])),
                min_size=1, max_size=20))
def test_valid_random_fixes_round_trip(fixes_in: list) -> None:
    """Well-formed GGAs at distinct times: every one becomes a row with its exact values."""
    seen = set()
    lines = []
    expect = []
    for hh, mm, ss, frac, lat, lon, q in fixes_in:
        tod = f"{hh:02d}{mm:02d}{ss:02d}.{frac:04d}"
        if tod in seen:
            continue
        seen.add(tod)
        la, lo = abs(lat), abs(lon)
        lat_s = f"{int(la):02d}{(la - int(la)) * 60:09.6f},{'N' if lat >= 0 else 'S'}"
        lon_s = f"{int(lo):03d}{(lo - int(lo)) * 60:09.6f},{'E' if lon >= 0 else 'W'}"
        lines.append(ck(f"GPGGA,{tod},{lat_s},{lon_s},{q},07,1.1,10.0,M,2.0,M,,".encode()))
        sod_ns = (hh * 3600 + mm * 60 + ss) * 10**9 + frac * 10**5
        dec_lat = float(lat_s[:2]) + float(lat_s[2:11]) / 60
        dec_lon = float(lon_s[:3]) + float(lon_s[3:12]) / 60
        no_fix = q == 0 or (dec_lat == 0 and dec_lon == 0)  # 0,0 is never a position
        expect.append((sod_ns, dec_lat if lat >= 0 else -dec_lat, 0 if no_fix else q))
    fixes, report, _ = parse_nmea(b"\r\n".join(lines), date=DAY)
    assert report.total == 0
    day0 = int(datetime.datetime(2024, 5, 17, tzinfo=datetime.UTC).timestamp()) * 10**9
    sod = (fixes.t_ns - day0) % (86400 * 10**9)
    assert sod.tolist() == [e[0] for e in expect]
    assert fixes.fix_quality.tolist() == [e[2] for e in expect]
    for (_, lat, q), got in zip(expect, fixes.lat_deg, strict=True):
        if q == 0:
            assert np.isnan(got)
        else:
            assert abs(got - lat) < 1e-9  # deg
