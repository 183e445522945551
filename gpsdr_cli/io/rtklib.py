"""RTKLIB solution files (``.pos``, from rnx2rtkp / RTKPOST / RTKNAVI) -> :class:`GnssFixes`.

Forms read (RTKLIB's ``out-solformat``; the header's column line tells which):

- ``llh``: ``latitude(deg) longitude(deg) height(m)`` (WGS84, ellipsoidal height), or the
  same in degrees-minutes-seconds (``latitude(d'")``: ``-33 27 00.12345``, three fields
  each), then ``Q ns sdn(m) sde(m) sdu(m) sdne(m) sdeu(m) sdun(m) age(s) ratio``.
- ``xyz``: ``x-ecef(m) y-ecef(m) z-ecef(m) Q ns sdx(m) sdy(m) sdz(m) sdxy(m) sdyz(m)
  sdzx(m) ...``: converted to geodetic with pyproj (EPSG:4978 -> EPSG:4979, one
  Transformer built once); the ECEF covariance (RTKLIB writes the off-diagonal terms as
  signed square roots) is rotated to east/north for the sigmas.
- ``enu``: ``e-baseline(m) n-baseline(m) u-baseline(m) Q ns sde(m) sdn(m) ...``, east,
  north and up from the base whose position the ``% ref pos`` header line gives (geodetic
  or ECEF): rotated back to ECEF at the base, then converted as ``xyz``.  Without that
  line it is refused with what to do.

Time: ``YYYY/MM/DD HH:MM:SS.sss`` or ``WEEK TOW`` (GPS week and seconds of week), in
the time system the column line names: ``GPST`` (the default when there is no column
line), ``UTC`` or ``JST`` (UTC + 9 h).  GPST is converted to UTC by the leap seconds
(GPST - UTC: 18 s since 2017-01-01, :data:`LEAP_SECONDS`).

Fields: ``Q`` -> ``fix_quality`` (GGA codes): 1 fix -> 4 (RTK fixed), 2 float -> 5, 3 SBAS
-> 2, 4 DGPS -> 2, 5 single -> 1, 6 PPP -> 2, 0 (no solution) -> 0.  PPP -> 2: GGA has no
PPP code; PPP is a single-receiver solution corrected by external (precise orbit and
clock) data, which is what code 2 (differential/SBAS) means to users of GGA; 4 and 5
would claim a base station's carrier-phase ambiguities.  ``ns`` -> ``n_sats``; ``sdn``,
``sde`` -> ``sigma_n_m``, ``sigma_e_m`` (1-sigma, metres).  RTKLIB writes no DOPs, speed
or course: NaN.

Why a hand-written line reader: RTKLIB's format is whitespace-separated text whose
column count depends on the form; no maintained Python package reads all of them, and
the files are small (one line per epoch).  Lines starting with ``%`` are header; blank
lines are ignored; any other line that does not parse is skipped and counted in the
:class:`SkipReport` by reason with its ``name:line``.
"""

from __future__ import annotations

import datetime
import functools
import hashlib
import re
from pathlib import Path

import numpy as np

from gpsdr_cli.errors import InputError, NoDataError
from gpsdr_cli.io.drive import Drive, GnssFixes, SkipReport, Source

__all__ = ["LEAP_SECONDS", "Q_TO_GGA", "ecef_to_llh", "gpst_minus_utc_ns", "looks_like_rtklib",
           "parse_rtklib", "read_rtklib"]

#: RTKLIB Q -> NMEA GGA fix quality (see the module docstring for PPP).
Q_TO_GGA = {0: 0, 1: 4, 2: 5, 3: 2, 4: 2, 5: 1, 6: 2}

#: (first UTC day, GPST - UTC in s from that day on), IERS Bulletin C; GPS time began
#: 1980-01-06 with GPST = UTC.  A new leap second needs a row here.
LEAP_SECONDS: tuple[tuple[datetime.date, int], ...] = tuple(
    (datetime.date(*ymd), n) for n, ymd in enumerate([
        (1981, 7, 1), (1982, 7, 1), (1983, 7, 1), (1985, 7, 1), (1988, 1, 1), (1990, 1, 1),
        (1991, 1, 1), (1992, 7, 1), (1993, 7, 1), (1994, 7, 1), (1996, 1, 1), (1997, 7, 1),
        (1999, 1, 1), (2006, 1, 1), (2009, 1, 1), (2012, 7, 1), (2015, 7, 1), (2017, 1, 1),
    ], start=1))

_NS = 1_000_000_000
_GPS_EPOCH_NS = int(datetime.datetime(1980, 1, 6, tzinfo=datetime.UTC).timestamp()) * _NS
_UNIX_DAY0 = datetime.date(1970, 1, 1).toordinal()
_JST_NS = 9 * 3600 * _NS
_SECONDS_PER_WEEK = 604800
_DATE = re.compile(r"(\d{4})/(\d{1,2})/(\d{1,2})$")
_TIME = re.compile(r"(\d{1,2}):(\d{1,2}):(\d{1,2}(?:\.\d*)?)$")
#: The column line's marker of each form.
_FORMS = (("latitude(deg)", "llh"), ("latitude(d'\")", "dms"), ("x-ecef", "xyz"),
          ("e-baseline", "enu"))


@functools.cache
def ecef_to_llh():
    """The one ECEF -> geodetic Transformer (lon, lat, h out, ``always_xy``)."""
    from pyproj import Transformer

    return Transformer.from_crs("EPSG:4978", "EPSG:4979", always_xy=True)


def gpst_minus_utc_ns(t_gpst_ns: np.ndarray) -> np.ndarray:
    """GPST - UTC (ns) at GPS times ``t_gpst_ns`` (ns since the Unix epoch, GPS scale)."""
    edges = np.array([(int(datetime.datetime(d.year, d.month, d.day,
                                             tzinfo=datetime.UTC).timestamp()) + n) * _NS
                      for d, n in LEAP_SECONDS], np.int64)
    return np.searchsorted(edges, t_gpst_ns, side="right").astype(np.int64) * _NS


def looks_like_rtklib(head: bytes) -> bool:
    """True when ``head`` (a file's first bytes) is an RTKLIB solution: '%' header lines
    naming RTKLIB's columns or program."""
    lines = [ln.strip() for ln in head[:8192].splitlines()[:80]]
    pct = [ln for ln in lines if ln.startswith(b"%")]
    if not pct:
        return False
    text = b"\n".join(pct)
    return (b"Q=1:fix" in text or b"program   : RTK" in text or b"program   : rnx2rtkp" in text
            or any(re.match(rb"%\s+(GPST|UTC|JST)\s", ln) is not None for ln in pct))


def _column_line(header: list[tuple[int, str]]) -> tuple[str | None, str, int | None]:
    """(form or None, time system, line number) from the header's column line."""
    for lineno, ln in header:
        body = ln.lstrip("%").split()
        if body and body[0] in ("GPST", "UTC", "JST"):
            for marker, form in _FORMS:
                if marker in ln:
                    return form, body[0], lineno
            return None, body[0], lineno
    return None, "GPST", None


def parse_rtklib(data: bytes, *, name: str = "<pos>") -> tuple[GnssFixes, SkipReport, dict]:
    """Parse an RTKLIB ``.pos`` file's bytes: (fixes in file order, skipped lines, meta).

    Raises :class:`InputError` for an empty file or a form this reader does not take
    (ENU baseline, NMEA) and :class:`NoDataError` when no line parses.
    """
    if not data.strip():
        raise InputError(name, "empty file (expected an RTKLIB solution: '%' header lines, "
                               "then one line per epoch)")
    if b"\x00" in data[:4096]:
        raise InputError(name, "binary data (NUL bytes); expected an RTKLIB .pos text file")
    text = data.decode("utf-8", errors="replace")
    lines = text.splitlines()
    header = [(i + 1, ln) for i, ln in enumerate(lines[:400]) if ln.startswith("%")]
    form, tsys, col_line = _column_line(header)
    ref_ecef = _ref_pos(header) if form == "enu" else None
    if form == "enu" and ref_ecef is None:
        raise InputError(name, "RTKLIB ENU-baseline solution (e/n/u-baseline columns) without "
                               "a '% ref pos' header line: the base position is needed; re-run "
                               "RTKLIB with out-solformat=llh (or xyz)", line=col_line)
    report = SkipReport()
    n = len(lines)
    t_ns = np.zeros(n, np.int64)
    pos = np.full((n, 3), np.nan)
    q = np.zeros(n, np.int64)
    ns = np.full(n, -1, np.int64)
    sd = np.full((n, 6), np.nan)
    keep = np.zeros(n, bool)
    forms_seen: set[str] = set()
    week_form = False

    def skip(reason: str, lineno: int) -> None:
        report.add(reason, f"{name}:{lineno}")

    for i, ln in enumerate(lines):
        if not ln.strip() or ln.startswith("%"):
            continue
        tok = ln.split()
        lineno = i + 1
        if len(tok) < 7:
            skip("too few columns (expected time, position, Q, ns)", lineno)
            continue
        # time: calendar (two fields) or GPS week + seconds of week
        m_d, m_t = _DATE.match(tok[0]), _TIME.match(tok[1])
        if m_d and m_t:
            try:
                day = datetime.date(int(m_d[1]), int(m_d[2]), int(m_d[3]))
                hh, mm, ss = int(m_t[1]), int(m_t[2]), float(m_t[3])
                if hh > 23 or mm > 59 or ss >= 61.0:
                    raise ValueError
            except ValueError:
                skip("malformed time (expected YYYY/MM/DD HH:MM:SS.sss)", lineno)
                continue
            if not 1980 <= day.year <= 2099:
                skip("malformed time (expected YYYY/MM/DD HH:MM:SS.sss)", lineno)
                continue
            t = ((day.toordinal() - _UNIX_DAY0) * 86400 + hh * 3600 + mm * 60) * _NS \
                + round(ss * 1e9)
        else:
            try:
                week, tow = int(tok[0]), float(tok[1])
            except ValueError:
                skip("malformed time (expected YYYY/MM/DD HH:MM:SS.sss or GPS week and "
                     "seconds)", lineno)
                continue
            if not (0 <= week <= 9999 and 0.0 <= tow < _SECONDS_PER_WEEK):
                skip("malformed time (expected YYYY/MM/DD HH:MM:SS.sss or GPS week and "
                     "seconds)", lineno)
                continue
            week_form = True
            t = _GPS_EPOCH_NS + week * _SECONDS_PER_WEEK * _NS + round(tow * 1e9)
        rest = tok[2:]
        line_form = form or ("dms" if len(rest) >= 11 and _is_dms(rest) else None)
        try:
            vals = [float(x) for x in rest]
        except ValueError:
            skip("malformed number", lineno)
            continue
        if not all(np.isfinite(vals)):
            skip("malformed number", lineno)
            continue
        if line_form == "dms":
            if len(vals) < 9:
                skip("too few columns (expected time, position, Q, ns)", lineno)
                continue
            lat = _dms(vals[0:3])
            lon = _dms(vals[3:6])
            if lat is None or lon is None:
                skip("malformed position (expected deg min sec)", lineno)
                continue
            xyz = (lat, lon, vals[6])
            after = vals[7:]
        else:
            xyz = tuple(vals[0:3])
            after = vals[3:]
            if line_form is None:  # no column line: geodetic if it reads as degrees
                line_form = "llh" if abs(xyz[0]) <= 90 and abs(xyz[1]) <= 360 else "xyz"
        forms_seen.add(line_form)
        qv, nsv = after[0], after[1]
        if qv != int(qv) or int(qv) not in Q_TO_GGA:
            skip("malformed quality Q (expected 0..6)", lineno)
            continue
        if nsv != int(nsv) or not 0 <= nsv < 32767:
            skip("malformed number of satellites", lineno)
            continue
        if line_form in ("llh", "dms"):
            if not (-90 <= xyz[0] <= 90 and -180 <= xyz[1] <= 360 and abs(xyz[2]) < 1e5):
                skip("malformed position (latitude/longitude out of range)", lineno)
                continue
        elif line_form == "enu":
            if not max(abs(v) for v in xyz) < 1e6:
                skip("malformed position (baseline longer than 1000 km)", lineno)
                continue
        elif not 6.0e6 < float(np.linalg.norm(xyz)) < 6.5e6 + 1e5:
            skip("malformed position (ECEF point not near the Earth's surface)", lineno)
            continue
        t_ns[i] = t
        pos[i] = xyz
        q[i] = int(qv)
        ns[i] = int(nsv)
        s = after[2:8]
        sd[i, :len(s)] = s
        keep[i] = True
    if not keep.any():
        raise NoDataError(name, "no RTKLIB solution line parsed ("
                          + (", ".join(f"{v} {r}" for r, v in report.counts.most_common(3))
                             or "no data lines") + ")")
    if len(forms_seen) > 1:
        raise InputError(name, f"lines of several forms ({', '.join(sorted(forms_seen))}); "
                               "expected one RTKLIB solution per file")
    (the_form,) = forms_seen
    t_ns, pos, q, ns, sd = t_ns[keep], pos[keep], q[keep], ns[keep], sd[keep]
    if the_form == "xyz":
        lon, lat, h = ecef_to_llh().transform(pos[:, 0], pos[:, 1], pos[:, 2])
        sig_e, sig_n = _enu_sigmas(sd, np.radians(lat), np.radians(lon))
    elif the_form == "enu":
        lat, lon, h = _enu_to_llh(pos, ref_ecef)
        sig_e, sig_n = sd[:, 0], sd[:, 1]  # sde(m) sdn(m) in this form
    else:
        lat, lon, h = pos[:, 0], pos[:, 1], pos[:, 2]
        lon = np.where(lon > 180.0, lon - 360.0, lon)
        sig_n, sig_e = sd[:, 0], sd[:, 1]
    leap_ns = gpst_minus_utc_ns(t_ns) if tsys == "GPST" else np.zeros(len(t_ns), np.int64)
    if tsys == "GPST":
        t_ns = t_ns - leap_ns
    elif tsys == "JST":
        t_ns = t_ns - _JST_NS
    gga = np.array([Q_TO_GGA[int(v)] for v in range(7)], np.int8)[q]
    fix = gga > 0
    nan = np.full(len(t_ns), np.nan)
    fixes = GnssFixes(
        t_ns=t_ns, lat_deg=np.where(fix, lat, np.nan), lon_deg=np.where(fix, lon, np.nan),
        alt_m=np.where(fix, h, np.nan), fix_quality=gga, n_sats=ns.astype(np.int16),
        hdop=nan, pdop=nan.copy(), vdop=nan.copy(),
        sigma_e_m=np.where(fix & (sig_e >= 0), sig_e, np.nan),
        sigma_n_m=np.where(fix & (sig_n >= 0), sig_n, np.nan),
        speed_mps=nan.copy(), course_deg=nan.copy())
    meta = {"rtklib_form": the_form, "time_system": tsys,
            "time_format": "gps week + seconds" if week_form else "calendar",
            "lines": n, "solutions": len(t_ns),
            "q_counts": {int(k): int(v) for k, v in zip(*np.unique(q, return_counts=True),
                                                        strict=True)}}
    if tsys == "GPST":
        meta["notes"] = [("times are GPST in the file: converted to UTC by the leap seconds "
                         f"({int(leap_ns[0] // _NS)} s at the first solution)")]
    return fixes, report, meta


def _ref_pos(header: list[tuple[int, str]]) -> np.ndarray | None:
    """The base's ECEF position (m) from a ``% ref pos : lat lon h`` (deg, deg, m) or
    ``x y z`` (m) header line; None without one.  RTKLIB prints the geodetic values with
    no space before a negative longitude (``40.086179918-105.206044414 1575.6355``)."""
    for _lineno, ln in header:
        if ln.lstrip("% ").startswith("ref pos"):
            v = [float(x) for x in re.findall(r"[-+]?\d+(?:\.\d*)?", ln.split(":", 1)[-1])]
            if len(v) != 3 or not all(np.isfinite(v)):
                return None
            if abs(v[0]) <= 90 and abs(v[1]) <= 360 and abs(v[2]) < 1e5:
                x, y, z = _llh_to_ecef().transform(v[1], v[0], v[2])
                return np.array([x, y, z])
            return np.array(v) if 6.0e6 < np.linalg.norm(v) < 6.6e6 else None
    return None


@functools.cache
def _llh_to_ecef():
    """The one geodetic -> ECEF Transformer (lon, lat, h in, ``always_xy``)."""
    from pyproj import Transformer

    return Transformer.from_crs("EPSG:4979", "EPSG:4978", always_xy=True)


def _enu_rotation(lat_rad: float, lon_rad: float) -> np.ndarray:
    """ECEF -> local east/north/up rotation at a point (rows: e, n, u unit vectors)."""
    sl, cl, sp, cp = np.sin(lon_rad), np.cos(lon_rad), np.sin(lat_rad), np.cos(lat_rad)
    return np.array([[-sl, cl, 0.0], [-sp * cl, -sp * sl, cp], [cp * cl, cp * sl, sp]])


def _enu_to_llh(enu: np.ndarray, ref_ecef: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Baselines east/north/up (m) from the base at ``ref_ecef`` -> lat, lon (deg), h (m)."""
    lon0, lat0, _h0 = ecef_to_llh().transform(*ref_ecef)
    ecef = ref_ecef[None, :] + enu @ _enu_rotation(np.radians(lat0), np.radians(lon0))
    lon, lat, h = ecef_to_llh().transform(ecef[:, 0], ecef[:, 1], ecef[:, 2])
    return lat, lon, h


def _is_dms(rest: list[str]) -> bool:
    """Whether the fields after the time read as ``d m s d m s h Q ns``: integral minutes
    (below 60) in the 2nd and 5th."""
    try:
        m1, m2 = float(rest[1]), float(rest[4])
    except ValueError:
        return False
    # range first: int() of an "inf" or "nan" field raises
    return 0 <= m1 < 60 and 0 <= m2 < 60 and m1 == int(m1) and m2 == int(m2) \
        and "." not in rest[1] and "." not in rest[4]


def _dms(v: list[float]) -> float | None:
    """RTKLIB's ``deg min sec`` (sign on the degrees, or ``-0`` written as ``-0``) -> deg."""
    d, m, s = v
    if not (0 <= m < 60 and 0 <= s < 60 and m == int(m)):
        return None
    sign = -1.0 if np.signbit(d) else 1.0
    return sign * (abs(d) + m / 60.0 + s / 3600.0)


def _enu_sigmas(sd: np.ndarray, lat_rad: np.ndarray, lon_rad: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray]:
    """1-sigma east and north (m) from RTKLIB's ECEF ``sdx sdy sdz sdxy sdyz sdzx``.

    RTKLIB writes each covariance term c as ``sign(c) sqrt(|c|)``; Sigma_enu = R Sigma R^T
    with R the ECEF -> ENU rotation at the point.  NaN where a term is missing.
    """
    sx, sy, sz, sxy, syz, szx = (sd[:, k] for k in range(6))
    sxy, syz, szx = (np.nan_to_num(np.sign(c) * c * c) for c in (sxy, syz, szx))
    cov = np.empty((len(sd), 3, 3))
    cov[:, 0, 0], cov[:, 1, 1], cov[:, 2, 2] = sx * sx, sy * sy, sz * sz
    cov[:, 0, 1] = cov[:, 1, 0] = sxy
    cov[:, 1, 2] = cov[:, 2, 1] = syz
    cov[:, 0, 2] = cov[:, 2, 0] = szx
    sl, cl, sp, cp = np.sin(lon_rad), np.cos(lon_rad), np.sin(lat_rad), np.cos(lat_rad)
    r_e = np.stack([-sl, cl, np.zeros_like(sl)], axis=1)
    r_n = np.stack([-sp * cl, -sp * sl, cp], axis=1)
    var_e = np.einsum("ki,kij,kj->k", r_e, cov, r_e)
    var_n = np.einsum("ki,kij,kj->k", r_n, cov, r_n)
    with np.errstate(invalid="ignore"):
        return np.sqrt(np.where(var_e >= 0, var_e, np.nan)), \
            np.sqrt(np.where(var_n >= 0, var_n, np.nan))


def read_rtklib(path: str | Path) -> Drive:
    """Read an RTKLIB ``.pos`` file into a :class:`Drive` (``gnss`` only)."""
    name = str(path)
    try:
        data = Path(path).read_bytes()
    except OSError as err:
        raise InputError(name, f"cannot read: {err.strerror or err}") from err
    fixes, report, meta = parse_rtklib(data, name=name)
    return Drive(gnss=fixes, skipped=report,
                 sources=[Source(name, hashlib.sha256(data).hexdigest(), ("gnss",))], meta=meta)
