"""u-blox UBX reader: GNSS fixes, gyro, odometer and forward accelerometer from a UBX log.

What is read (u-blox interface descriptions, protocol 27+ / M8 and F9):

============  ===============================================================
NAV-PVT       UTC time (only when validDate, validTime and fullyResolved are
              set; others are skipped and counted), lat/lon, height above the
              ellipsoid (``alt_m``), fix quality (below), hAcc as the sigmas,
              numSV, pDOP, velN/velE as speed and course
NAV-DOP       hDOP, vDOP (and pDOP) of the NAV-PVT with the same iTOW
NAV-HPPOSLLH  lat/lon/height with the 0.1 mm parts and its hAcc, overriding
              the NAV-PVT of the same iTOW
ESF-MEAS      data type 5 gyro z -> yaw rate; 11 speed -> odometer; 8/9 rear
ESF-RAW       wheel ticks (averaged), else 6/7 front ones, else 10 single tick
              -> odometer through ``[odo] ticks_per_m``; 16 accelerometer x ->
              forward accel; the other types (12 gyro temperature, 13/14 gyro
              y/x, 17/18 accelerometer y/z) are counted in ``meta`` only
NAV-POSLLH    without NAV-PVT in the log (u-blox 6/7, timing firmware): lat/lon,
              height above the ellipsoid, hAcc as the sigmas (as NAV-PVT's)
NAV-SOL       without NAV-PVT and NAV-POSLLH: the ECEF position (cm) as
              lat/lon/height, pAcc (cm, 3-D) as the horizontal estimate (a
              cautious one), the ECEF velocity, numSV, pDOP; the fix status
              and GPS week of the other position messages of its iTOW
NAV-POSECEF   without any of the above: the ECEF position and pAcc
NAV-STATUS    gpsFix, gpsFixOk, diffSoln, carrSoln of the same iTOW: the fix
              quality of the three above (over NAV-SOL's own)
NAV-TIMEGPS   the GPS week (and leapS) that dates the three above
NAV-VELNED    velN/velE (cm/s) as speed and course for the three above, else
              the ECEF velocity of NAV-SOL or NAV-VELECEF
NMEA          lines between the UBX frames, through :func:`parse_nmea`, when
              they hold a fix, time or DOP sentence; used for the fixes only
              when the UBX messages give none
============  ===============================================================

NAV-PVT is preferred when a log has it: the older messages of the same epochs are
then not read, so no epoch is doubled.  Without NAV-PVT the first of NAV-POSLLH,
NAV-SOL, NAV-POSECEF that the log holds gives the positions; their validity comes
from NAV-STATUS, else NAV-SOL, of the same iTOW (gpsFix 2-D, 3-D, GNSS + dead
reckoning with gpsFixOk is a fix; 0 and 5, time only, are not).  When the log has
neither NAV-STATUS nor NAV-SOL at all, every position not all zeros is taken
as a 3-D fix (a receiver set to send NAV-POSLLH alone) and a note says so.  Time:
GPS week (of the NAV-SOL or NAV-TIMEGPS nearest in the stream, or of ``--date``)
and iTOW, minus GPS - UTC (NAV-TIMEGPS's leapS, else the IERS table); without a
week the fixes are skipped and counted, as NAV-PVT without a date is.  A log whose
every fix message is time only (fixType / gpsFix 5: a timing receiver at a fixed,
surveyed position) and which has no gyro or odometer is an error that says so.

Fix quality (NMEA GGA codes): fixType 1 (dead reckoning only) -> 6; no
gnssFixOK, fixType 0 or 5 (time only), or invalidLlh -> 0; else carrSoln 2
(fixed) -> 4, carrSoln 1 (float) -> 5, diffSoln -> 2, otherwise 1.  The same for
NAV-STATUS / NAV-SOL's gpsFix, gpsFixOk, diffSoln and (NAV-STATUS, when
carrSolnValid) carrSoln.

Sigmas: hAcc is u-blox's "horizontal accuracy estimate", one number for the
horizontal plane.  It is read as the radial (2-D) 1-sigma error, so that
``sigma_e_m**2 + sigma_n_m**2 = hAcc**2``: ``sigma_e_m = sigma_n_m = hAcc / sqrt(2)``.
(ROS's ublox driver puts hAcc**2 on each axis, a factor sqrt(2) more cautious.)
vAcc has no place in :class:`GnssFixes` and is not read.

Sensor signs: u-blox's vehicle (installation) frame is x forward, y right, z
down, so a positive gyro z is a turn to the right; the charter's yaw rate is
counter-clockwise (about up), hence ``yaw_rate = -gyro_z``.  Accelerometer x is
forward, as the charter's.  Wheel ticks are 23-bit absolute counters with the
direction in bit 23 (1 = backward); speed = the counter's step (mod 2**23) /
ticks_per_m / dt, negative when backward.

Time of ESF messages: ESF-MEAS's ``timeTag`` is the receiver's local millisecond
counter (32 bits), not GPS time.  ESF-RAW's per-sample ``sTtag`` is the sensor's own
24-bit count of 1/25.6 ms (39.0625 us; wraps every 655.36 s).  u-blox's published
protocol description gives no unit for it; Swift Navigation's gnss-converters, which
also reads ESF-RAW, notes as much and takes 39.0625 us, the Bosch BMI160's sensor
time step; a real NEO-M8U log (gpsd's ublox-neo-m8u.log) agrees: ~256 units per
10-ms sample, 2.9 s of samples over its 2.9 s of messages.  Each counter is mapped to
UTC from the log itself: each ESF message is given the UTC of its place in the
stream, interpolated between the fix messages (NAV-PVT, else the NAV-POSLLH/SOL/
POSECEF ones) before and after it (messages are output in time order, one epoch
apart at most), and the offset is the median of (that UTC - its time tag) over the
log; the tag plus the offset is its time.  The median over thousands of messages
makes the per-message spread (up to one epoch) cancel to milliseconds.  An ESF-RAW
message stands by the tag of its last sample (it is output after it).  The sensor's
clock is not the receiver's (0.2-0.3 % slow on that M8U against the millisecond
count), so over ESF-RAW logs of a minute or more its rate is fitted too (least
squares of UTC on tag), else a 10-minute log would drift by a second or more.
Without fix UTC times the ESF messages are skipped and counted.

What pyubx2 does and what is hand-written, and why: pyubx2 (the maintained
UBX library) parses about 2 k messages/s here, a Python object per message,
two orders of magnitude short of the 200 k messages/s an hour-long F9R log at
100 Hz needs.  So the frames are found and checksummed by a compiled scan
(:func:`_scan`: sync bytes, length, the 8-bit Fletcher checksum from running
sums, resynchronising two bytes on after a bad frame), and the NAV payloads
are decoded as numpy structured arrays whose field names, types and offsets are
built from pyubx2's own message definitions (``UBX_PAYLOADS_GET``), so no
offset is typed by hand; the ESF data words (24-bit field, 6-bit type) are
unpacked with numpy.  The tests generate every case with pyubx2's
``UBXMessage`` and check the values against it.
"""

from __future__ import annotations

import datetime as dt
import functools
import hashlib
import math
import re
from pathlib import Path
from typing import Any

import numba
import numpy as np

from ..conventions import FIX_DGPS, FIX_DR, FIX_FLOAT_RTK, FIX_GPS, FIX_NONE, FIX_RTK, NS_PER_S
from ..errors import InputError, MissingDateError, NoDataError
from .drive import Drive, ForwardAccel, GnssFixes, Odometry, SkipReport, Source, YawRates
from .formats import UBX_SYNC
from .rtklib import ecef_to_llh, gpst_minus_utc_ns

CLASS_NAV, CLASS_ESF = 0x01, 0x10
ID_PVT, _DOP, _HPPOSLLH = 0x07, 0x04, 0x14
#: NAV messages of receivers without NAV-PVT (u-blox 6/7, timing firmware) and their
#: payload lengths, bytes
_POSECEF, _POSLLH, _NAV_STATUS, _SOL, _VELECEF, _VELNED, _TIMEGPS = (
    0x01, 0x02, 0x03, 0x06, 0x11, 0x12, 0x20)
_LEN = {"NAV-POSECEF": 20, "NAV-POSLLH": 28, "NAV-STATUS": 16, "NAV-SOL": 52,
        "NAV-VELECEF": 20, "NAV-VELNED": 36, "NAV-TIMEGPS": 16}
_MEAS, _RAW = 0x02, 0x03
#: NAV-PVT up to pDOP (the u-blox 7 length); M8/F9 send 92 bytes.
PVT_MIN = 84

#: ESF data types (interface description, "ESF data types"; the same numbers as
#: ublox_msgs/EsfMEAS): 5 gyro z, 6-9 wheel ticks FL/FR/RL/RR, 10 single tick, 11 speed,
#: 12 gyro temperature, 13/14 gyro y/x, 16-18 accelerometer x/y/z.
T_GYRO_Z, T_WHEEL_FL, T_WHEEL_FR, T_WHEEL_RL, T_WHEEL_RR = 5, 6, 7, 8, 9
T_SINGLE_TICK, T_SPEED, T_ACCEL_X = 10, 11, 16
_GYRO_SCALE_DPS = 2.0 ** -12
_ACCEL_SCALE = 2.0 ** -10
_SPEED_SCALE = 1e-3
_TICK_MODULUS = 1 << 23
_MS = 1_000_000  # ns per ms
#: ESF-RAW sTtag: a 24-bit counter of 1/25.6 ms = 39.0625 us (78125 / 2 ns) per unit
_RAW_TAG_MODULUS = 1 << 24
_RAW_TAG_NS_NUM, _RAW_TAG_NS_DEN = 78125, 2
#: ESF-RAW's sensor clock (0.2-0.3 % off nominal on an M8U) has its rate fitted only over
#: logs this long (ns): frames placed between fixes by rank scatter by up to half a fix
#: interval, and in simulation (1 Hz fixes, 10 Hz frames) the slope fitted over 20 s was
#: still up to 0.3 % off, over 45 s within 0.06 %
_RATE_FIT_MIN_SPAN_NS = 60 * NS_PER_S
#: a fitted sensor clock rate further than this from nominal is not believed
_RATE_MAX_ERROR = 0.05
#: GPS time: 1980-01-06 00:00:00 UTC in ns since 1970; a week in ms
_GPS_EPOCH_NS = 315_964_800 * NS_PER_S
_WEEK_MS = 604_800_000

_STATUS = {1: "UBX frame with a bad checksum (skipped)",
           2: "UBX frame truncated at the end of the file (skipped)"}


# --------------------------------------------------------------------------- frames

#: UBX message classes (NAV RXM INF ACK CFG UPD MON AID TIM ESF MGA LOG SEC HNR NAV2 and
#: the NMEA/PUBX classes F0/F1): a sync pair followed by another class byte is not a frame.
_CLASSES = np.zeros(256, np.bool_)
_CLASSES[[0x01, 0x02, 0x04, 0x05, 0x06, 0x09, 0x0A, 0x0B, 0x0D, 0x10, 0x13, 0x21, 0x27, 0x28,
          0x29, 0xF0, 0xF1]] = True
#: Longer declared payloads are not frames (the longest u-blox outputs, RXM-RAWX / NAV-SAT /
#: MON-SPAN, stay below this); bounds the checksum work a false sync pair can cost.
_MAX_PAYLOAD = 8192


@numba.njit(cache=True)
def _prefix_sums(buf: np.ndarray) -> tuple[np.ndarray, np.ndarray]:  # pragma: no cover
    """Running sums mod 256 of the bytes (c1) and of c1 (c2), so that the Fletcher checksum
    of any byte range is O(1): a false sync pair with a long declared length costs nothing."""
    n = len(buf)
    c1 = np.zeros(n + 1, np.uint8)
    c2 = np.zeros(n + 1, np.uint8)
    a = np.uint8(0)
    b = np.uint8(0)
    for i in range(n):
        a = np.uint8(a + buf[i])
        b = np.uint8(b + a)
        c1[i + 1] = a
        c2[i + 1] = b
    return c1, c2


@numba.njit(cache=True)
def _scan_pass(buf: np.ndarray, fill: bool, start: np.ndarray, cls: np.ndarray,
               mid: np.ndarray, length: np.ndarray, bad_at: np.ndarray, bad_kind: np.ndarray,
               text: np.ndarray, classes: np.ndarray, max_payload: int, c1: np.ndarray,
               c2: np.ndarray):  # pragma: no cover
    n = len(buf)
    k = 0
    nb = 0
    p = 0
    while p + 1 < n:
        if buf[p] != 0xB5 or buf[p + 1] != 0x62:
            p += 1
            continue
        if p + 6 > n:
            if fill:
                bad_at[nb] = p
                bad_kind[nb] = 2
                for i in range(p, n):
                    text[i] = 0
            nb += 1
            break
        ln = np.int64(buf[p + 4]) | (np.int64(buf[p + 5]) << 8)
        if not classes[buf[p + 2]] or ln > max_payload:
            p += 1  # not a frame: two bytes that happen to equal the sync pair
            continue
        end = p + 8 + ln
        if end > n:
            kind = 2
        else:
            # Fletcher over bytes [s, e): A = c1[e] - c1[s], B = c2[e] - c2[s] - (e - s) c1[s]
            s0 = p + 2
            e0 = p + 6 + ln
            a = (np.int64(c1[e0]) - np.int64(c1[s0])) & 0xFF
            b = (np.int64(c2[e0]) - np.int64(c2[s0]) - (e0 - s0) * np.int64(c1[s0])) & 0xFF
            kind = 0 if (a == buf[end - 2] and b == buf[end - 1]) else 1
        if kind == 0:
            if fill:
                start[k] = p
                cls[k] = buf[p + 2]
                mid[k] = buf[p + 3]
                length[k] = ln
                for i in range(p, end):
                    text[i] = 0
            k += 1
            p = end
            continue
        # A damaged frame: its bytes up to the next '$' (an NMEA line) or the next sync
        # byte (where the scan goes on; this bounds the work to one pass) are not text.
        if fill:
            bad_at[nb] = p
            bad_kind[nb] = kind
            stop = min(end, n)
            for i in range(p, stop):
                if i > p + 1 and (buf[i] == 0x24 or buf[i] == 0xB5):
                    break
                text[i] = 0
        nb += 1
        p += 2
    return k, nb


def _scan(buf: np.ndarray) -> dict[str, np.ndarray]:
    """Frames of a UBX byte stream: start offset, class, id, payload length of each
    checksum-valid frame; offset and kind (1 bad checksum, 2 truncated) of each damaged
    one; and the mask of bytes outside every frame (the NMEA text).  Two compiled passes
    (count, then fill exactly sized arrays)."""
    z = np.zeros(0, np.int64)
    c1, c2 = _prefix_sums(buf)
    k, nb = _scan_pass(buf, False, z, np.zeros(0, np.uint8), np.zeros(0, np.uint8), z, z,
                       np.zeros(0, np.uint8), np.zeros(0, np.uint8), _CLASSES, _MAX_PAYLOAD,
                       c1, c2)
    out = {"start": np.empty(k, np.int64), "cls": np.empty(k, np.uint8),
           "id": np.empty(k, np.uint8), "length": np.empty(k, np.int64),
           "bad_at": np.empty(nb, np.int64), "bad_kind": np.empty(nb, np.uint8),
           "text": np.ones(len(buf), np.uint8)}
    _scan_pass(buf, True, out["start"], out["cls"], out["id"], out["length"], out["bad_at"],
               out["bad_kind"], out["text"], _CLASSES, _MAX_PAYLOAD, c1, c2)
    return out


def count_frames(head: bytes, limit: int = 64) -> int:
    """Checksum-valid UBX frames among the first ``limit`` sync positions of ``head``
    (for sniffing; pure Python, no numba compile)."""
    found = 0
    pos = head.find(UBX_SYNC)
    for _ in range(limit):
        if pos < 0 or pos + 8 > len(head):
            break
        ln = head[pos + 4] | head[pos + 5] << 8
        end = pos + 8 + ln
        if end <= len(head):
            a = b = 0
            for c in head[pos + 2:end - 2]:
                a = (a + c) & 0xFF
                b = (b + a) & 0xFF
            if head[end - 2] == a and head[end - 1] == b:
                found += 1
                pos = head.find(UBX_SYNC, end)
                continue
        pos = head.find(UBX_SYNC, pos + 2)
    return found


# --------------------------------------------------------------------------- payload tables

_TYPES = {"U001": "u1", "U002": "<u2", "U004": "<u4", "I001": "i1", "I002": "<i2",
          "I004": "<i4", "X001": "u1", "X002": "<u2", "X004": "<u4"}


@functools.lru_cache(maxsize=8)
def _layout(name: str) -> tuple[np.dtype, dict[str, float], dict[str, tuple[str, int, int]]]:
    """A numpy dtype for a fixed-length UBX payload from pyubx2's definition: the
    fields, their scale factors, and the bit fields (container, shift, width)."""
    from pyubx2.ubxtypes_get import UBX_PAYLOADS_GET

    names, formats, offsets = [], [], []
    scales: dict[str, float] = {}
    bits: dict[str, tuple[str, int, int]] = {}
    off = 0
    for key, spec in UBX_PAYLOADS_GET[name].items():
        if isinstance(spec, tuple) and isinstance(spec[1], dict):  # bit field group
            kind, sub = spec
            shift = 0
            for bname, bspec in sub.items():
                width = int(bspec[1:])
                bits[bname] = (key, shift, width)
                shift += width
        else:
            kind = spec[0] if isinstance(spec, tuple) else spec
            if isinstance(spec, tuple):
                scales[key] = float(spec[1])
        names.append(key)
        formats.append(_TYPES[kind])
        offsets.append(off)
        off += int(kind[1:])
    return np.dtype({"names": names, "formats": formats, "offsets": offsets}), scales, bits


def _table(buf: np.ndarray, starts: np.ndarray, name: str, size: int) -> np.ndarray:
    """The payloads at ``starts`` (frame offsets) as a structured array of ``name``'s
    fields that fit in ``size`` bytes."""
    full, _, _ = _layout(name)
    keep = [f for f in full.names if full.fields[f][1] + full.fields[f][0].itemsize <= size]
    dtype = np.dtype({"names": keep, "formats": [full.fields[f][0] for f in keep],
                      "offsets": [full.fields[f][1] for f in keep], "itemsize": size})
    rows = buf[(starts + 6)[:, None] + np.arange(size)]
    return np.ascontiguousarray(rows).view(dtype)[:, 0]


def _bit(tab: np.ndarray, name: str, field: str) -> np.ndarray:
    container, shift, width = _layout(name)[2][field]
    return (tab[container].astype(np.int64) >> shift) & ((1 << width) - 1)


def _days_from_civil(y: np.ndarray, m: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Days since 1970-01-01 of a proleptic Gregorian date (Hinnant's algorithm)."""
    y = y - (m <= 2)
    era = np.floor_divide(y, 400)
    yoe = y - era * 400
    doy = (153 * (m + np.where(m > 2, -3, 9)) + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468


# --------------------------------------------------------------------------- NAV

def nav_fixes(buf: np.ndarray, fr: dict[str, np.ndarray], path: str, skipped: SkipReport
               ) -> tuple[GnssFixes, np.ndarray, np.ndarray, np.ndarray, dict]:
    """Fixes from NAV-PVT (+ NAV-DOP, NAV-HPPOSLLH); also every NAV-PVT's frame start,
    UTC (ns, 0 when not valid) and iTOW, for the ESF time mapping."""
    cls, mid, length, start = fr["cls"], fr["id"], fr["length"], fr["start"]
    sel = (cls == CLASS_NAV) & (mid == ID_PVT)
    short = sel & (length < PVT_MIN)
    skipped.add(f"UBX NAV-PVT shorter than {PVT_MIN} bytes", path, int(short.sum()))
    sel &= ~short
    pvt = _table(buf, start[sel], "NAV-PVT", PVT_MIN)
    n = len(pvt)
    y, mo, d = (pvt[f].astype(np.int64) for f in ("year", "month", "day"))
    h, mi, s = (pvt[f].astype(np.int64) for f in ("hour", "min", "second"))
    nano = pvt["nano"].astype(np.int64)
    valid = ((_bit(pvt, "NAV-PVT", "validDate") == 1) & (_bit(pvt, "NAV-PVT", "validTime") == 1)
             & (_bit(pvt, "NAV-PVT", "fullyResolved") == 1))
    in_range = ((mo >= 1) & (mo <= 12) & (d >= 1) & (d <= 31) & (h < 24) & (mi < 60) & (s <= 60)
                & (np.abs(nano) < NS_PER_S) & (y >= 1980))
    skipped.add("UBX NAV-PVT without a valid, fully resolved UTC time (skipped)", path,
                int((~valid).sum()))
    skipped.add("UBX NAV-PVT with an out-of-range date or time (skipped)", path,
                int((valid & ~in_range).sum()))
    ok = valid & in_range
    t_ns = np.where(ok, (_days_from_civil(y, mo, d) * 86400 + h * 3600 + mi * 60 + s) * NS_PER_S
                    + nano, 0)
    itow = pvt["iTOW"].astype(np.int64)
    pvt_start = start[sel]

    fix_type = pvt["fixType"].astype(np.int64)
    # invalidLlh: flags3 bit 0 (F9, within the first 84 bytes; reserved and zero on u-blox 7)
    q = _quality(fix_type, _bit(pvt, "NAV-PVT", "gnssFixOk") == 1,
                 _bit(pvt, "NAV-PVT", "diffSoln") == 1, _bit(pvt, "NAV-PVT", "carrSoln"),
                 _bit(pvt, "NAV-PVT", "invalidLlh") == 1)
    lat = pvt["lat"] * 1e-7
    lon = pvt["lon"] * 1e-7
    bad_ll = (np.abs(lat) > 90) | (np.abs(lon) > 180)
    skipped.add("UBX NAV-PVT with latitude/longitude out of range (kept as no fix)", path,
                int((ok & bad_ll & (q > 0)).sum()))
    q[bad_ll] = FIX_NONE
    has = q > 0
    g = GnssFixes.empty(int(ok.sum()))
    g.t_ns = t_ns[ok]
    g.fix_quality = q[ok]
    g.lat_deg = np.where(has, lat, np.nan)[ok]
    g.lon_deg = np.where(has, lon, np.nan)[ok]
    g.alt_m = np.where(has, pvt["height"] * 1e-3, np.nan)[ok]
    sig = pvt["hAcc"] * 1e-3 / math.sqrt(2.0)
    g.sigma_e_m = np.where(has, sig, np.nan)[ok]
    g.sigma_n_m = g.sigma_e_m.copy()
    g.n_sats = pvt["numSV"].astype(np.int16)[ok]
    g.pdop = np.where(pvt["pDOP"] > 0, pvt["pDOP"] * 0.01, np.nan)[ok]
    ve = pvt["velE"] * 1e-3
    vn = pvt["velN"] * 1e-3
    g.speed_mps = np.where(has, np.hypot(ve, vn), np.nan)[ok]
    # course over ground clockwise from north (charter): atan2(east, north)
    g.course_deg = np.where(has, np.degrees(np.arctan2(ve, vn)) % 360.0, np.nan)[ok]
    itow_ok = itow[ok]
    counts = {"nav_pvt": n, "nav_dop": 0, "nav_hpposllh": 0,
              "pvt_time_only": int((fix_type == 5).sum())}
    _add_dop(buf, fr, g, itow_ok, counts)
    hsel = (cls == CLASS_NAV) & (mid == _HPPOSLLH) & (length >= 36)
    if hsel.any() and len(g):
        hp = _table(buf, start[hsel], "NAV-HPPOSLLH", 36)
        counts["nav_hpposllh"] = len(hp)
        j, found = _match(itow_ok, hp["iTOW"].astype(np.int64))
        found &= (_bit(hp, "NAV-HPPOSLLH", "invalidLlh")[j] == 0) & (g.fix_quality > 0)
        hlat = hp["lat"][j] * 1e-7 + hp["_HPlat"][j] * 1e-9
        hlon = hp["lon"][j] * 1e-7 + hp["_HPlon"][j] * 1e-9
        hh = (hp["height"][j] + hp["_HPheight"][j] * 0.1) * 1e-3
        g.lat_deg = np.where(found, hlat, g.lat_deg)
        g.lon_deg = np.where(found, hlon, g.lon_deg)
        g.alt_m = np.where(found, hh, g.alt_m)
        hsig = hp["hAcc"][j] * 1e-4 / math.sqrt(2.0)
        g.sigma_e_m = np.where(found, hsig, g.sigma_e_m)
        g.sigma_n_m = g.sigma_e_m.copy()
        counts["hpposllh_used"] = int(found.sum())
    return g, pvt_start, t_ns, itow, counts


def _quality(fix_type: np.ndarray, fix_ok: np.ndarray, diff: np.ndarray, carr: np.ndarray,
             invalid: np.ndarray) -> np.ndarray:
    """NMEA GGA fix quality from u-blox's fix type (0 none, 1 dead reckoning only, 2 2-D,
    3 3-D, 4 GNSS + dead reckoning, 5 time only), gnssFixOK, diffSoln, carrSoln (1 float,
    2 fixed) and an invalid-position flag."""
    q = np.full(len(fix_type), FIX_GPS, np.int8)
    q[diff] = FIX_DGPS
    q[carr == 1] = FIX_FLOAT_RTK
    q[carr == 2] = FIX_RTK
    q[~fix_ok | (fix_type == 0) | (fix_type == 5) | invalid] = FIX_NONE
    q[fix_type == 1] = FIX_DR
    return q


def _add_dop(buf: np.ndarray, fr: dict[str, np.ndarray], g: GnssFixes, itow: np.ndarray,
             counts: dict) -> None:
    """hDOP, vDOP (and pDOP where ``g`` has none) from the NAV-DOP of each fix's iTOW."""
    dsel = (fr["cls"] == CLASS_NAV) & (fr["id"] == _DOP) & (fr["length"] >= 18)
    if not (dsel.any() and len(g)):
        return
    dop = _table(buf, fr["start"][dsel], "NAV-DOP", 18)
    counts["nav_dop"] = len(dop)
    j, found = _match(itow, dop["iTOW"].astype(np.int64))
    g.hdop = np.where(found, dop["hDOP"][j] * 0.01, np.nan)
    g.vdop = np.where(found, dop["vDOP"][j] * 0.01, np.nan)
    g.pdop = np.where(np.isnan(g.pdop) & found, dop["pDOP"][j] * 0.01, g.pdop)


def _match(itow: np.ndarray, other: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each iTOW, the index of the (last) ``other`` message with the same iTOW."""
    if not len(other):
        return np.zeros(len(itow), np.int64), np.zeros(len(itow), bool)
    order = np.argsort(other, kind="stable")
    srt = other[order]
    k = np.searchsorted(srt, itow, side="right") - 1
    kc = np.clip(k, 0, len(srt) - 1)
    found = (k >= 0) & (srt[kc] == itow)
    return order[kc], found


# --------------------------------------------------------------------------- NAV without NAV-PVT

#: position messages in the order they are preferred when a log has no NAV-PVT
LEGACY_SOURCES = ("NAV-POSLLH", "NAV-SOL", "NAV-POSECEF")
_LEGACY_IDS = {"NAV-POSLLH": _POSLLH, "NAV-SOL": _SOL, "NAV-POSECEF": _POSECEF,
               "NAV-STATUS": _NAV_STATUS, "NAV-TIMEGPS": _TIMEGPS, "NAV-VELNED": _VELNED,
               "NAV-VELECEF": _VELECEF}


def _nav_table(buf: np.ndarray, fr: dict[str, np.ndarray], name: str, path: str,
               skipped: SkipReport) -> tuple[np.ndarray, np.ndarray]:
    """Frame starts and payload table of every NAV message ``name``; shorter payloads than
    its length are skipped and counted."""
    sel = (fr["cls"] == CLASS_NAV) & (fr["id"] == _LEGACY_IDS[name])
    size = _LEN[name]
    short = sel & (fr["length"] < size)
    skipped.add(f"UBX {name} shorter than {size} bytes (skipped)", path, int(short.sum()))
    st = fr["start"][sel & ~short]
    return st, _table(buf, st, name, size)


def _nearest(ref_start: np.ndarray, at: np.ndarray) -> np.ndarray:
    """Index of the reference frame (starts sorted) nearest in the stream to each ``at``."""
    k = np.searchsorted(ref_start, at)
    lo = np.clip(k - 1, 0, len(ref_start) - 1)
    hi = np.clip(k, 0, len(ref_start) - 1)
    return np.where(np.abs(at - ref_start[lo]) <= np.abs(ref_start[hi] - at), lo, hi)


def _gps_utc_ns(start: np.ndarray, itow: np.ndarray, tabs: dict, date: dt.date | None
                ) -> tuple[np.ndarray, str]:
    """UTC (ns; 0 where no week is known) of the epochs at frame ``start`` with GPS time of
    week ``itow`` (ms), and where the week came from.

    The week is that of the NAV-SOL (wknSet) or NAV-TIMEGPS (weekValid) message nearest in
    the stream, moved by one where the two times of week lie more than half a week apart
    (the week turned between them); with neither in the log, that of ``date`` (noon UTC).
    GPS - UTC is NAV-TIMEGPS's leapS where valid, else the IERS table."""
    refs = []
    sol_st, sol = tabs["NAV-SOL"]
    if len(sol_st):
        m = (_bit(sol, "NAV-SOL", "wknSet") == 1) & (_bit(sol, "NAV-SOL", "towSet") == 1)
        refs.append((sol_st[m], sol["week"][m], sol["iTOW"][m], sol["fTOW"][m]))
    tg_st, tg = tabs["NAV-TIMEGPS"]
    if len(tg_st):
        m = (_bit(tg, "NAV-TIMEGPS", "weekValid") == 1) & (_bit(tg, "NAV-TIMEGPS", "towValid") == 1)
        refs.append((tg_st[m], tg["week"][m], tg["iTOW"][m], tg["fTOW"][m]))
    r_st, r_week, r_itow, r_ftow = (np.concatenate([np.asarray(r[i], np.int64) for r in refs])
                                    if refs else np.zeros(0, np.int64) for i in range(4))
    source = "NAV-SOL/NAV-TIMEGPS week"
    if not len(r_st):
        if date is None:
            return np.zeros(len(itow), np.int64), "none"
        noon_ns = (date.toordinal() - dt.date(1970, 1, 1).toordinal()) * 86400 * NS_PER_S \
            + 12 * 3600 * NS_PER_S
        gps_ms = (noon_ns - _GPS_EPOCH_NS
                  + int(gpst_minus_utc_ns(np.array([noon_ns], np.int64))[0])) // _MS
        r_st, r_week, r_itow = (np.zeros(1, np.int64), np.array([gps_ms // _WEEK_MS]),
                                np.array([gps_ms % _WEEK_MS]))
        r_ftow = np.zeros(1, np.int64)
        source = f"the week of --date {date.isoformat()}"
    order = np.argsort(r_st, kind="stable")
    r_st, r_week, r_itow, r_ftow = (a[order] for a in (r_st, r_week, r_itow, r_ftow))
    k = _nearest(r_st, start)
    week = r_week[k] + np.rint((r_itow[k] - itow) / _WEEK_MS).astype(np.int64)
    # fTOW (ns, +-0.5 ms) refines iTOW when the reference is of the same epoch
    ftow = np.where(r_itow[k] == itow, r_ftow[k], 0)
    t_gps = _GPS_EPOCH_NS + (week * _WEEK_MS + itow) * _MS + ftow
    leap = gpst_minus_utc_ns(t_gps) // NS_PER_S
    if len(tg_st):
        m = _bit(tg, "NAV-TIMEGPS", "leapSValid") == 1
        if m.any():
            j = _nearest(tg_st[m], start)
            leap = tg["leapS"][m][j].astype(np.int64)
    return t_gps - leap * NS_PER_S, source


def _ecef_vel_to_en(v: tuple[np.ndarray, np.ndarray, np.ndarray], lat_deg: np.ndarray,
                    lon_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """East and north components (m/s) of an ECEF velocity (m/s) at lat/lon."""
    la, lo = np.radians(lat_deg), np.radians(lon_deg)
    vx, vy, vz = v
    east = -np.sin(lo) * vx + np.cos(lo) * vy
    north = -np.sin(la) * np.cos(lo) * vx - np.sin(la) * np.sin(lo) * vy + np.cos(la) * vz
    return east, north


def legacy_fixes(buf: np.ndarray, fr: dict[str, np.ndarray], path: str, skipped: SkipReport,
                 date: dt.date | None = None) -> tuple[GnssFixes, np.ndarray, np.ndarray, dict]:
    """Fixes of a log without NAV-PVT: positions from NAV-POSLLH, else NAV-SOL, else
    NAV-POSECEF (see the module docstring); also each position message's frame start and
    UTC (ns, 0 when undated) for the ESF time mapping, and counts for ``meta``."""
    tabs = {name: _nav_table(buf, fr, name, path, skipped) for name in _LEGACY_IDS}
    counts: dict[str, Any] = {"nav_" + name[4:].lower(): len(tabs[name][0])
                              for name in _LEGACY_IDS if len(tabs[name][0])}
    source = next((name for name in LEGACY_SOURCES if len(tabs[name][0])), None)
    if source is None:
        e = np.zeros(0, np.int64)
        return GnssFixes.empty(0), e, e, counts
    st, pos = tabs[source]
    n = len(st)
    itow = pos["iTOW"].astype(np.int64)
    if source == "NAV-POSLLH":
        lat, lon = pos["lat"] * 1e-7, pos["lon"] * 1e-7
        alt = pos["height"] * 1e-3
        # hAcc (mm) is the horizontal accuracy estimate, read as NAV-PVT's is
        sig = pos["hAcc"] * 1e-3 / math.sqrt(2.0)
        unset = (pos["lat"] == 0) & (pos["lon"] == 0)  # what a receiver sends before a fix
    else:
        xyz = [pos[f"ecef{c}"] * 1e-2 for c in "XYZ"]  # cm
        lon, lat, alt = (np.asarray(a, float) for a in ecef_to_llh().transform(*xyz))
        # pAcc (cm) is 3-D: as the horizontal estimate it errs on the cautious side
        sig = pos["pAcc"] * 1e-2 / math.sqrt(2.0)
        unset = (pos["ecefX"] == 0) & (pos["ecefY"] == 0) & (pos["ecefZ"] == 0)

    # fix validity from the NAV-SOL and NAV-STATUS of the same epoch (NAV-STATUS wins)
    fix_type = np.full(n, -1, np.int64)
    fix_ok = np.zeros(n, bool)
    diff = np.zeros(n, bool)
    carr = np.zeros(n, np.int64)
    have = np.zeros(n, bool)
    for name, ok_bit in (("NAV-SOL", "gpsfixOK"), ("NAV-STATUS", "gpsFixOk")):
        tab = tabs[name][1]
        if not len(tab):
            continue
        j, found = _match(itow, tab["iTOW"].astype(np.int64))
        fix_type = np.where(found, tab["gpsFix"][j], fix_type)
        fix_ok = np.where(found, _bit(tab, name, ok_bit)[j] == 1, fix_ok)
        diff = np.where(found, _bit(tab, name, "diffSoln")[j] == 1, diff)
        if name == "NAV-STATUS":
            valid_carr = _bit(tab, name, "carrSolnValid")[j] == 1
            carr = np.where(found & valid_carr, _bit(tab, name, "carrSoln")[j], carr)
        have |= found
    if not (len(tabs["NAV-SOL"][0]) or len(tabs["NAV-STATUS"][0])):
        # Assumption: with no fix status in the log at all, a set position is a 3-D fix (a
        # receiver configured to send only NAV-POSLLH); its hAcc still weighs it.
        fix_type[:], fix_ok[:], have[:] = 3, True, True
        counts["fix_assumed"] = n
    skipped.add(f"UBX {source} without NAV-STATUS or NAV-SOL in its epoch (kept as no fix)",
                path, int((~have).sum()))
    q = _quality(fix_type, fix_ok, diff, carr, unset | ~have)
    bad_ll = ~(np.isfinite(lat) & np.isfinite(lon)) | (np.abs(lat) > 90) | (np.abs(lon) > 180)
    skipped.add(f"UBX {source} with latitude/longitude out of range (kept as no fix)", path,
                int((bad_ll & (q > 0)).sum()))
    q[bad_ll] = FIX_NONE
    has = q > 0

    t_utc, week_from = _gps_utc_ns(st, itow, tabs, date)
    dated = t_utc != 0
    skipped.add(f"UBX {source} without a GPS week (no NAV-SOL or NAV-TIMEGPS in the log, and "
                "no --date) (skipped)", path, int((~dated).sum()))
    counts.update(fix_source=source, week_from=week_from, legacy_undated=int((~dated).sum()),
                  legacy_time_only=int((fix_type == 5).sum()), legacy_epochs=n)

    # velocity: NAV-VELNED (cm/s), else the ECEF velocity of NAV-SOL or NAV-VELECEF (cm/s)
    ve = np.full(n, np.nan)
    vn = np.full(n, np.nan)
    vel = tabs["NAV-VELNED"][1]
    if len(vel):
        j, found = _match(itow, vel["iTOW"].astype(np.int64))
        ve = np.where(found, vel["velE"][j] * 1e-2, ve)
        vn = np.where(found, vel["velN"][j] * 1e-2, vn)
    for name in ("NAV-SOL", "NAV-VELECEF"):
        tab = tabs[name][1]
        if not len(tab):
            continue
        j, found = _match(itow, tab["iTOW"].astype(np.int64))
        found &= np.isnan(ve)
        e, nn = _ecef_vel_to_en(tuple(tab[f"ecefV{c}"][j] * 1e-2 for c in "XYZ"), lat, lon)
        ve = np.where(found, e, ve)
        vn = np.where(found, nn, vn)

    g = GnssFixes.empty(int(dated.sum()))
    g.t_ns = t_utc[dated]
    g.fix_quality = q[dated]
    g.lat_deg = np.where(has, lat, np.nan)[dated]
    g.lon_deg = np.where(has, lon, np.nan)[dated]
    g.alt_m = np.where(has, alt, np.nan)[dated]
    g.sigma_e_m = np.where(has, sig, np.nan)[dated]
    g.sigma_n_m = g.sigma_e_m.copy()
    g.speed_mps = np.where(has, np.hypot(ve, vn), np.nan)[dated]
    # course over ground clockwise from north, as NAV-PVT's
    g.course_deg = np.where(has, np.degrees(np.arctan2(ve, vn)) % 360.0, np.nan)[dated]
    sol = tabs["NAV-SOL"][1]
    if len(sol):
        j, found = _match(itow, sol["iTOW"].astype(np.int64))
        g.n_sats = np.where(found, sol["numSV"][j], -1).astype(np.int16)[dated]
        g.pdop = np.where(found & (sol["pDOP"][j] > 0), sol["pDOP"][j] * 0.01, np.nan)[dated]
    _add_dop(buf, fr, g, itow[dated], counts)
    return g, st, t_utc, counts


# --------------------------------------------------------------------------- ESF

def _esf_words(buf: np.ndarray, fr: dict[str, np.ndarray], path: str, skipped: SkipReport
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every ESF-MEAS and ESF-RAW data word: (frame start, time tag, data type, 24-bit
    field, source 0 MEAS / 1 RAW).  The tag is ESF-MEAS's 32-bit millisecond count or
    ESF-RAW's 24-bit sensor count (1/25.6 ms units)."""
    cls, mid, length, start = fr["cls"], fr["id"], fr["length"], fr["start"]
    parts = []
    meas = (cls == CLASS_ESF) & (mid == _MEAS) & (length >= 8)
    if meas.any():
        st, ln = start[meas], length[meas]
        p = st + 6
        tag = _u32(buf, p)
        flags = _u16(buf, p + 4)
        n_meas = (flags >> 11) & 0x1F
        need = 8 + 4 * n_meas
        bad = ln < need
        skipped.add("UBX ESF-MEAS shorter than its numMeas says (skipped)", path, int(bad.sum()))
        keep = ~bad & (n_meas > 0)
        rep = np.repeat(np.flatnonzero(keep), n_meas[keep])
        first = np.cumsum(n_meas[keep]) - n_meas[keep]
        k = np.arange(len(rep)) - np.repeat(first, n_meas[keep])
        word = _u32(buf, p[rep] + 8 + 4 * k)
        parts.append((st[rep], tag[rep], (word >> 24) & 0x3F, word & 0xFFFFFF,
                      np.zeros(len(rep), np.int8)))
    raw = (cls == CLASS_ESF) & (mid == _RAW) & (length >= 12)
    if raw.any():
        st, ln = start[raw], length[raw]
        p = st + 6
        n_w = (ln - 4) // 8
        rep = np.repeat(np.arange(len(st)), n_w)
        first = np.cumsum(n_w) - n_w
        k = np.arange(len(rep)) - np.repeat(first, n_w)
        q = p[rep] + 4 + 8 * k
        word = _u32(buf, q)
        parts.append((st[rep], _u32(buf, q + 4) & (_RAW_TAG_MODULUS - 1), (word >> 24) & 0xFF,
                      word & 0xFFFFFF, np.ones(len(rep), np.int8)))
    if not parts:
        e = np.zeros(0, np.int64)
        return e, e, e, e, np.zeros(0, np.int8)
    return tuple(np.concatenate(c) for c in zip(*parts, strict=False))  # type: ignore[return-value]


def _u32(buf: np.ndarray, pos: np.ndarray) -> np.ndarray:
    return buf[pos[:, None] + np.arange(4)].copy().view("<u4")[:, 0].astype(np.int64)


def _u16(buf: np.ndarray, pos: np.ndarray) -> np.ndarray:
    return buf[pos[:, None] + np.arange(2)].copy().view("<u2")[:, 0].astype(np.int64)


def _signed24(v: np.ndarray) -> np.ndarray:
    return np.where(v >= 1 << 23, v - (1 << 24), v)


def _unwrap(tag: np.ndarray, modulus: int) -> np.ndarray:
    """A wrapping counter made monotonic (steps taken mod ``modulus``; a gap of half the
    modulus or more between two readings cannot be told from a step back)."""
    if len(tag) < 2:
        return tag.astype(np.int64)
    step = np.diff(tag) % modulus
    step = np.where(step >= modulus // 2, step - modulus, step)
    return np.concatenate([[0], np.cumsum(step)]) + int(tag[0])


def _frame_utc(frame_start: np.ndarray, tag_ns: np.ndarray, pvt_start: np.ndarray,
               pvt_t_ns: np.ndarray) -> tuple[np.ndarray, np.ndarray, int] | None:
    """(tag, UTC - base, base) in ns of the distinct ESF frames lying between two fixes with
    a UTC time: each frame's UTC is interpolated between the fix messages before and after
    it in the stream by its rank among the frames between them.  The tag is the first of
    the frame's.  None when fewer than two fixes have a UTC time or no frame lies between."""
    good = pvt_t_ns != 0
    ps, pt = pvt_start[good], pvt_t_ns[good]
    if len(ps) < 2 or not len(frame_start):
        return None
    fs, first = np.unique(frame_start, return_index=True)
    tags = tag_ns[first]
    k = np.searchsorted(ps, fs)
    inside = (k > 0) & (k < len(ps))
    if not inside.any():
        return None
    k = k[inside]
    fs, tags = fs[inside], tags[inside]
    seg = k - 1
    idx = np.arange(len(fs))
    seg_first = np.searchsorted(seg, seg, side="left")
    seg_count = np.searchsorted(seg, seg, side="right") - seg_first
    frac = (idx - seg_first + 0.5) / seg_count
    base = int(pt[0])  # int64 differences first: float64 ns since 1970 would lose 0.25 us
    rel = (pt[seg] - base) + frac * (pt[seg + 1] - pt[seg])
    return tags, rel, base


def esf_offset_ns(frame_start: np.ndarray, tag: np.ndarray, pvt_start: np.ndarray,
                  pvt_t_ns: np.ndarray, *, unit_ns: int = _MS) -> int | None:
    """UTC minus sensor time (ns): the median of (interpolated UTC - tag) over the ESF
    frames with a fix of known UTC on both sides (:func:`_frame_utc`); ``tag`` in units of
    ``unit_ns``.  None when the log has fewer than two fix UTC times."""
    got = _frame_utc(frame_start, np.asarray(tag, np.int64) * unit_ns, pvt_start, pvt_t_ns)
    if got is None:
        return None
    tags, rel, base = got
    return base + round(float(np.median(rel - tags)))


def esf_clock_fit(frame_start: np.ndarray, tag_ns: np.ndarray, pvt_start: np.ndarray,
                  pvt_t_ns: np.ndarray) -> tuple[int, int, float] | None:
    """A sensor clock mapped onto UTC with its rate fitted: (tag0, UTC at tag0, rate), so
    that UTC = UTC at tag0 + rate (tag - tag0), all ns.  The rate is the least-squares
    slope of interpolated UTC on tag when the frames span at least
    :data:`_RATE_FIT_MIN_SPAN_NS`, else 1; the UTC at tag0 is the median of the residuals
    (robust to frames output late).  None as :func:`esf_offset_ns`."""
    got = _frame_utc(frame_start, tag_ns, pvt_start, pvt_t_ns)
    if got is None:
        return None
    tags, rel, base = got
    tag0 = int(tags[0])
    x = (tags - tag0).astype(float)
    rate = 1.0
    if x[-1] - x[0] >= _RATE_FIT_MIN_SPAN_NS and len(x) >= 3:
        xc = x - x.mean()
        rate = float(np.dot(xc, rel - rel.mean()) / np.dot(xc, xc))
    return tag0, base + round(float(np.median(rel - rate * x))), rate


def _esf_streams(buf: np.ndarray, fr: dict[str, np.ndarray], pvt_start: np.ndarray,
                 pvt_t_ns: np.ndarray, ticks_per_m: float, path: str, skipped: SkipReport,
                 warnings: list[str], meta: dict) -> tuple[YawRates | None, Odometry | None,
                                                           ForwardAccel | None]:
    fstart, tag, dtype, field, src = _esf_words(buf, fr, path, skipped)
    if not len(fstart):
        return None, None, None
    order = np.argsort(fstart, kind="stable")
    fstart, tag, dtype, field, src = (a[order] for a in (fstart, tag, dtype, field, src))
    meta["esf_words"] = {int(t): int(c) for t, c in zip(*np.unique(dtype, return_counts=True), strict=False)}
    streams: dict[str, Any] = {"gyro": None, "odo": None, "accel": None}
    for s in (0, 1):
        m = src == s
        if not m.any():
            continue
        name = "ESF-MEAS" if s == 0 else "ESF-RAW"
        if s == 0:
            # the receiver's 32-bit millisecond counter: one offset, no rate
            tag_ns = _unwrap(tag[m], 1 << 32) * _MS
            fs_m, tag_fit = fstart[m], tag_ns
        else:
            # the sensor's 24-bit count; a frame holds up to ten samples and is output after
            # its last, so the last one's tag stands for the frame
            tag_ns = _unwrap(tag[m], _RAW_TAG_MODULUS) * _RAW_TAG_NS_NUM // _RAW_TAG_NS_DEN
            last = np.flatnonzero(np.r_[fstart[m][1:] != fstart[m][:-1], True])
            fs_m, tag_fit = fstart[m][last], tag_ns[last]
        fit = esf_clock_fit(fs_m, tag_fit, pvt_start, pvt_t_ns) if s == 1 else None
        if fit is not None and abs(fit[2] - 1.0) > _RATE_MAX_ERROR:
            warnings.append(f"{path}: {name} sensor clock fitted {100 * (fit[2] - 1):+.1f} % off "
                            "its nominal rate, beyond belief; the nominal rate is used")
            fit = None
        if fit is None:
            off = esf_offset_ns(fs_m, tag_fit, pvt_start, pvt_t_ns, unit_ns=1)
            fit = None if off is None else (0, off, 1.0)
        if fit is None:
            skipped.add(f"UBX {name} without NAV-PVT UTC times to date it (skipped)", path,
                        int(m.sum()))
            continue
        tag0, utc0, rate = fit
        meta.setdefault("esf_offset_ns", {})[name] = utc0 - tag0
        if s == 1:
            meta["esf_raw_clock_rate"] = rate
        if rate == 1.0:
            t = tag_ns - tag0 + utc0
        else:
            t = utc0 + np.rint((tag_ns - tag0) * rate).astype(np.int64)
        d, f = dtype[m], field[m]
        got = {}
        gz = d == T_GYRO_Z
        if gz.any():
            got["gyro"] = YawRates(
                t_ns=t[gz], yaw_rate_radps=-np.radians(_signed24(f[gz]) * _GYRO_SCALE_DPS))
        ax = d == T_ACCEL_X
        if ax.any():
            got["accel"] = ForwardAccel(t_ns=t[ax], accel_mps2=_signed24(f[ax]) * _ACCEL_SCALE)
        sp = d == T_SPEED
        if sp.any():
            got["odo"] = Odometry(t_ns=t[sp], speed_mps=_signed24(f[sp]) * _SPEED_SCALE)
            meta["odometer"] = f"{name} speed"
        else:
            odo = _ticks_odometer(t, d, f, ticks_per_m, path, warnings, name)
            if odo is not None:
                got["odo"] = odo
                meta["odometer"] = f"{name} wheel ticks / {ticks_per_m} ticks per m"
        for k, v in got.items():
            if streams[k] is None or len(v) > len(streams[k]):
                streams[k] = v
    return streams["gyro"], streams["odo"], streams["accel"]


def _ticks_odometer(t: np.ndarray, d: np.ndarray, f: np.ndarray, ticks_per_m: float, path: str,
                    warnings: list[str], name: str) -> Odometry | None:
    """Speed from rear wheel ticks (RL/RR averaged), else the front ones, else the
    single tick counter (the rear axle's are preferred: unsteered wheels)."""
    series: list[tuple[np.ndarray, np.ndarray]] = []
    for wheels in ((T_WHEEL_RL, T_WHEEL_RR), (T_WHEEL_FL, T_WHEEL_FR), (T_SINGLE_TICK,)):
        series = series or [(t[d == w], f[d == w]) for w in wheels if (d == w).sum() >= 2]
    if not series:
        return None
    if not (math.isfinite(ticks_per_m) and ticks_per_m > 0):
        warnings.append(f"{path}: {name} has wheel ticks but no speed; set odo.ticks_per_m "
                        "(ticks per metre) to read them as the odometer")
        return None
    speeds = []
    for ts, fs in series:
        count = fs & (_TICK_MODULUS - 1)
        backward = (fs >> 23) & 1
        step = np.diff(count) % _TICK_MODULUS
        step = np.where(step >= _TICK_MODULUS // 2, _TICK_MODULUS - step, step)
        dt_s = np.diff(ts) / NS_PER_S
        good = dt_s > 0
        v = np.where(good, step / ticks_per_m / np.where(good, dt_s, 1.0), np.nan)
        v = np.where(backward[1:] == 1, -v, v)
        speeds.append((ts[1:][good], v[good]))
    if len(speeds) == 2 and len(speeds[0][0]) == len(speeds[1][0]) \
            and np.array_equal(speeds[0][0], speeds[1][0]):
        return Odometry(t_ns=speeds[0][0], speed_mps=0.5 * (speeds[0][1] + speeds[1][1]))
    return Odometry(t_ns=speeds[0][0], speed_mps=speeds[0][1])


# --------------------------------------------------------------------------- reader

#: the start of an NMEA sentence of a kind :func:`parse_nmea` reads (fix, time, DOP,
#: velocity or error sentences); other bytes between the frames (binary junk, text
#: headers, TXT/GSV sentences) hold nothing to read
_NMEA_START = re.compile(rb"\$(?:[A-Z]{2}(?:GGA|GNS|RMC|GLL|GSA|VTG|GST|ZDA)|PTNL,GGK|PUBX,00),")


def _message_names(messages: dict[str, int]) -> str:
    """'NAV-SAT x151, NAV-STATUS x151, ...': the log's messages by count, named as u-blox
    names them (unknown ones as class-id hex)."""
    from pyubx2.ubxtypes_core import UBX_MSGIDS

    named = []
    for key, c in sorted(messages.items(), key=lambda kv: -kv[1]):
        name = UBX_MSGIDS.get(bytes.fromhex(key.replace("-", "")), key)
        named.append(f"{name} x{c}")
    return ", ".join(named) or "none"


def parse_ubx(data: bytes, *, name: str = "<ubx>", date: dt.date | None = None,
              ticks_per_m: float = 0.0) -> Drive:
    """Read a UBX (or mixed UBX + NMEA) byte stream; see the module docstring.  ``date``
    dates NMEA lines without one, and NAV-POSLLH/NAV-SOL/NAV-POSECEF fixes when the log has
    no GPS week."""
    buf = np.frombuffer(data, np.uint8)
    fr = _scan(buf)
    skipped = SkipReport()
    for kind, reason in _STATUS.items():
        at = fr["bad_at"][fr["bad_kind"] == kind]
        if len(at):
            skipped.add(reason, f"{name}: byte {int(at[0])}", len(at))
    warnings: list[str] = []
    notes: list[str] = []
    meta: dict[str, Any] = {"frames": len(fr["start"]), "bad_frames": len(fr["bad_at"])}
    ids, counts = np.unique(fr["cls"].astype(np.int64) * 256 + fr["id"], return_counts=True)
    meta["messages"] = {f"{i >> 8:02X}-{i & 0xFF:02X}": int(c) for i, c in zip(ids, counts, strict=False)}
    gnss, anchor_start, anchor_t, _, nav_counts = nav_fixes(buf, fr, name, skipped)
    meta.update(nav_counts)
    time_only = None
    legacy_ids = np.array(sorted(_LEGACY_IDS[k] for k in LEGACY_SOURCES))
    has_legacy = bool(((fr["cls"] == CLASS_NAV) & np.isin(fr["id"], legacy_ids)).any())
    if nav_counts["nav_pvt"]:
        if has_legacy:
            meta["legacy_ignored"] = "NAV-PVT preferred over NAV-POSLLH/NAV-SOL/NAV-POSECEF"
        if nav_counts["pvt_time_only"] == nav_counts["nav_pvt"]:
            time_only = (f"every one of its {nav_counts['nav_pvt']} NAV-PVT messages is "
                         "time-only (fixType 5)")
    elif has_legacy:
        gnss, anchor_start, anchor_t, leg = legacy_fixes(buf, fr, name, skipped, date)
        meta.update(leg)
        src = leg["fix_source"]
        if leg.get("fix_assumed"):
            notes.append(f"{name}: no NAV-STATUS or NAV-SOL in the log: every set {src} "
                         "position taken as a 3-D fix")
        if leg["legacy_time_only"] == leg["legacy_epochs"]:
            status = "NAV-STATUS" if leg.get("nav_status") else "NAV-SOL"
            time_only = (f"every one of its {leg['legacy_epochs']} {src} epochs is time-only "
                         f"({status} gpsFix 5)")
    gyro, odo, accel = _esf_streams(buf, fr, anchor_start, anchor_t, ticks_per_m, name,
                                    skipped, warnings, meta)
    text = np.flatnonzero(fr["text"])
    nmea_bytes = buf[text].tobytes()
    meta["bytes_outside_frames"] = len(nmea_bytes)
    nmea_error: InputError | None = None
    if _NMEA_START.search(nmea_bytes):
        day = date
        if day is None and len(gnss):
            day = dt.datetime.fromtimestamp(int(gnss.t_ns[0]) // NS_PER_S, dt.UTC).date()
        try:
            from .nmea import parse_nmea

            fixes, rep, nmea_meta = parse_nmea(nmea_bytes, name=f"{name} (NMEA lines)", date=day)
        except MissingDateError:
            raise
        except (InputError, NoDataError) as err:
            # a file of UBX frames without a usable message gets the UBX error below
            if not len(fr["start"]) and not len(gnss) and gyro is None and odo is None:
                raise
            nmea_error = err
            warnings.append(f"{name}: NMEA lines between the UBX frames not read: {err}")
        else:
            meta["nmea"] = nmea_meta
            if len(gnss):
                meta["nmea_ignored"] = "UBX fixes preferred over the NMEA epochs"
            else:
                gnss = fixes
                skipped.merge(rep)
                notes.extend(nmea_meta.get("notes", []))  # e.g. sentences that disagree
    drive = Drive(skipped=skipped, sources=[Source(name, hashlib.sha256(data).hexdigest())])
    drive.gnss = gnss if len(gnss) else None
    drive.gyro, drive.odo, drive.accel = gyro, odo, accel
    streams = tuple(s for s in ("gnss", "gyro", "odo", "accel") if getattr(drive, s) is not None)
    drive.sources[0].streams = streams
    drive.meta["ubx"] = meta
    if warnings:
        drive.meta["warnings"] = warnings
    if notes:
        drive.meta["notes"] = list(notes)
    if not streams and meta.get("legacy_undated"):
        raise MissingDateError(name, f"{meta['legacy_undated']} {meta['fix_source']} fixes but "
                               "no GPS week to date them (no NAV-SOL or NAV-TIMEGPS in the log); "
                               "give --date")
    found = (f"{meta['frames']} valid frames, {meta['bad_frames']} damaged; messages: "
             f"{_message_names(meta['messages'])}") if not streams or time_only else ""
    if not streams:
        why = f"; NMEA lines: {nmea_error.reason}" if nmea_error is not None else ""
        raise NoDataError(name, "no usable UBX message: gpsdr reads fixes from NAV-PVT (else "
                          "NAV-POSLLH, NAV-SOL or NAV-POSECEF), gyro, odometer and accelerometer "
                          "from ESF-MEAS or ESF-RAW, and NMEA fix sentences between the frames "
                          f"({found}){why}")
    if time_only and streams == ("gnss",) and not drive.gnss.valid.any():
        raise NoDataError(name, f"no position fix: {time_only}, as a timing receiver reports "
                          "while it holds its antenna at a fixed, surveyed position; there is "
                          f"no navigation fix to make a track from ({found})")
    return drive


def read_ubx(path: str | Path, *, date: dt.date | None = None, ticks_per_m: float = 0.0) -> Drive:
    """Read a UBX log file (see :func:`parse_ubx`)."""
    try:
        data = Path(path).read_bytes()
    except IsADirectoryError as err:
        raise InputError(path, "is a directory, expected a UBX file") from err
    except OSError as err:
        raise InputError(path, f"cannot read: {err.strerror or err}") from err
    if not data:
        raise InputError(path, "empty file, expected a UBX log")
    return parse_ubx(data, name=str(path), date=date, ticks_per_m=ticks_per_m)
