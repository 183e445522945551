"""NMEA 0183 reader: GGA, GNS, RMC, GLL, GSA, VTG, GST and ZDA from any talker, and the
proprietary Trimble ``$PTNL,GGK`` and u-blox ``$PUBX,00`` positions and ``$PUBX,04``
dates -> :class:`GnssFixes`.

Why hand-written instead of pynmea2 / pynmeagps: those parse one sentence at a
time into Python objects (tens of microseconds per sentence), and they raise or
silently drop on the oddities real logs carry.  This reader works on whole
4 MiB chunks of lines at once with numpy (about a microsecond or two per
sentence, see ``benchmarks/read_nmea.py``):

1. Find every sentence start (``$``, or ``!`` before a letter) anywhere in a
   line, so logger prefixes, binary bytes before the ``$``, ``$$`` doubled
   starts and two sentences spliced on one line all work.  A sentence ends at
   the next start or line end; its checksum is the first ``*hh`` in it.
2. Verify every checksum at once (``np.bitwise_xor.reduceat``); hex digits
   upper or lower case.  A sentence without ``*hh`` is read when it is whole
   (see :func:`_complete_without_checksum`; gpsd reads them too) and counted in
   ``meta['sentences_without_checksum']``.
3. Classify sentences by their first bytes (``np.unique`` over the addresses; for
   ``$PTNL``/``$PUBX`` the message id after the address too), locate the fields of
   each known type by comma offsets, gather each wanted field of all sentences into
   one fixed-width bytes array and convert it with one numpy cast; only a column
   holding a non-number falls back to a per-value loop, which marks that field bad.
4. Group sentences into receiver epochs: a sentence with a time of day
   (GGA, GNS, RMC, GLL, GST, ZDA, PTNL,GGK, PUBX,00) whose time (or date) differs from the
   previous timed sentence's opens a new epoch; sentences without a time (GSA, VTG) belong
   to the epoch of the timed sentence before them (the first epoch if none precedes).  One
   row per epoch that has a position sentence (GGA, GNS, PTNL,GGK, PUBX,00, RMC or GLL);
   within an epoch the last non-empty value of each field wins (so one GSA per
   constellation merges into one row).

Conventions (see :mod:`gpsdr_cli.conventions`): ``t_ns`` int64 ns UTC (time
of day rounded to the microsecond); lat/lon degrees WGS84 (``ddmm.mmmm`` +
hemisphere converted); speeds m/s.  Field numbers below follow NMEA 0183 4.11
with field 0 = the address (``GPGGA``; ``PTNL`` or ``PUBX``, whose field 1 is the
message id ``GGK`` or ``00``).

Field choices, documented here once:

- Position, fix quality, satellites, HDOP: from the epoch's most informative
  position sentence: GGA, else GNS, else PTNL,GGK, else PUBX,00, else RMC, else GLL
  (GGA and GNS carry quality, satellites, HDOP and altitude, GGK and PUBX,00 a quality
  and the ellipsoidal height, RMC a mode letter, GLL a status).  The kind
  chosen decides even without a fix (a GGA with quality 0 is not overridden
  by an RMC with status ``A``).  RMC and GLL (status ``A``): the NMEA 2.3 mode
  letter gives the quality: A/blank -> 1, D -> 2, P -> 3, R -> 4, F -> 5,
  E -> 6, N/M/S -> 0.  GNS (NMEA 4.x multi-constellation receivers): its mode
  field has one letter per system (GPS, GLONASS, Galileo, BeiDou, QZSS,
  NavIC); the best letter gives the quality (R 4 > F 5 > D 2 > P 3 > A 1 > E
  6; only N/M/S: no fix), so a fix exists when any system has one.  GNS
  satellites, HDOP, altitude and geoid separation read as GGA's (GGA's win; a
  GGA fix claiming 0 satellites leaves the count to GNS, else unknown).  One GGA
  per constellation in an epoch (``$GPGGA`` + ``$GLGGA``, SiRFstar V): their
  satellites add up; a ``$GN`` GGA of the epoch is the total.
- Trimble ``$PTNL,GGK`` (field 2 time, 3 date ``mmddyy``, month first, 4-7 position, 8
  quality 0-15, 9 satellites, 10 PDOP, 11 height ``EHT-5.923``, 12 ``M``), as Trimble's
  own GGA reports the same solutions (receiver manuals' GGA table): RTK fixed 3, 7 (3D
  network), 9 (2D network) and xFill 15 -> 4; RTK float 2, 6, 8, Location RTK 12 (RTK
  degraded to decimetres), OmniSTAR HP/XP 10 and CenterPoint RTX 14 -> 5 (converging
  precise point solutions are decimetre-level, a float's accuracy, not a fix's); DGPS 4,
  SBAS 5, OmniSTAR VBS 11 and beacon DGPS 13 -> 2; autonomous 1 -> 1; 0 -> no fix
  (other values are malformed: the sentence is skipped and counted).  The height is
  above the ellipsoid: ``alt_m`` as given; a height without the ``EHT`` prefix is not
  read (counted).  GGK's date dates its epoch like RMC's (RMC and ZDA win where present).
- u-blox ``$PUBX,00`` (field 2 time, 3-6 position, 7 altRef height above the ellipsoid,
  8 navStat, 9 hAcc m, 10 vAcc, 11 SOG km/h, 12 COG deg, 13 vVel, 14 diffAge, 15-17
  HDOP/VDOP/TDOP, 18 satellites): navStat NF/TT -> no fix, DR (dead reckoning only) -> 6,
  G2/G3/RK (RK: GNSS with dead reckoning) -> 1, D2/D3 -> 2.  hAcc is one radial
  1-sigma number: ``sigma_n_m = sigma_e_m = hAcc / sqrt(2)`` (as :mod:`gpsdr_cli.io.ubx`
  reads NAV-PVT's hAcc; GST's per-axis sigmas win in an epoch that has both).  It has no
  date: its epochs are dated as GGA's are.
- u-blox ``$PUBX,04`` (field 2 time, 3 date ``ddmmyy``; the clock fields after them not
  read): its date dates its epoch like RMC's (GGK, RMC and ZDA win where present), so a
  log of PUBX,00 or GGA positions with PUBX,04 times needs no ``--date``.  Other
  ``$PTNL`` and ``$PUBX`` messages are counted as unknown proprietary sentences.
- Sentences of one epoch that disagree on the position (by more than 1e-7 deg
  and more than one unit of the last digit either prints) are counted in
  ``meta['position_disagreements']`` and a note, not as skipped records;
  ``position_from="last"`` takes the epoch's last position sentence instead, as
  gpsd does (the ranked choice is the default: it keeps GGA's quality fields).
  Positions that agree that closely are one fix printed twice: the last of
  them printed as finely as the chosen one gives the coordinates (a receiver
  that rounds GGA and truncates GLL; gpsd reports the last, too).
- No fix (GGA quality 0, RMC status ``V``, empty or ``0,0`` coordinates) gives a
  row with NaN lat/lon/alt and ``fix_quality`` 0, never zero coordinates.  So do the
  positions no receiver measured: GGA quality 7 (manual input) and 8 (simulator), mode
  ``M`` or ``S`` in RMC, GLL and GNS; those sentences are also counted in the skip report
  ("... in simulator mode ...", not fatal in strict mode), so that a log of them says why
  it has no fix.  GGA quality 6 (dead reckoning) stays a row of quality 6.
- ``alt_m``: ellipsoidal height = GGA altitude above mean sea level + geoid
  separation (GGA field 11).  When a receiver leaves the separation empty the
  MSL altitude is kept and ``meta['alt_without_geoid_sep']`` counts those rows.
- ``pdop``/``vdop`` (and ``hdop`` when GGA has none): GSA, last non-empty of the
  epoch (else GGK's PDOP, PUBX,00's HDOP and VDOP); the DOPs are the last three
  fields, before the NMEA 4.1 system id.
  A GSA reporting fix type 1 (no fix) contributes no DOPs; a DOP of 99.99 (the
  receivers' "no DOP" placeholder) is NaN.
- ``sigma_n_m``/``sigma_e_m``: GST fields 6 and 7 (1-sigma latitude and
  longitude error, metres).
- ``speed_mps``/``course_deg``: RMC (status ``A``), else VTG (mode not ``N``), else
  PUBX,00 (with a fix); knots * 1852/3600, km/h / 3.6.
- Date: RMC (``ddmmyy``; years 80-99 read as 19xx), ZDA, PTNL,GGK or PUBX,04, per epoch; epochs
  between dated ones take the previous date plus midnight rollovers (time of
  day decreasing by more than 12 h is the next day; an increase, however
  large, is a gap within the day).  The ``date`` argument is
  only used when the log has no RMC/ZDA/GGK/PUBX,04 date at all: a date in the log always
  wins.  Dates before 1980 (GPS time began 1980-01-06) are malformed; before 2000
  or in the future (GPS week-rollover bugs) are kept
  as given, counted in ``meta['warning_counts']`` and explained in
  ``meta['warnings']`` (a list of one-line messages).

Encoding: UTF-16 (LE/BE, with a byte-order mark or told by its NUL bytes) is
decoded; Latin-1 bytes need no decoding (NMEA is ASCII); both are named in
``meta['encoding']`` and a note.  Binary noise is skipped and counted.

Everything that is skipped is counted by reason in the :class:`SkipReport`
with the first ``name:line`` where it occurred; ``strict=True`` raises
:class:`ParseError` (or :class:`ChecksumError`) for the first such line
instead.  Well-formed sentences this reader does not read are counted and never fatal:
standard NMEA 0183 types it does not use (GSV, DTM, TXT, ... listed in ``_NOT_USED``) as
``"not used: GSV (satellites in view)"``, and so are Unicore's secondary-antenna variants of
them (``$GNGGAH``, ``$GNRMCH`` ...: a dual-antenna receiver's heading antenna, not the
position); unknown ones (other types, proprietary ``$P...`` other than the two above, AIS
``!AIVDM``, numeric talkers, other six-letter addresses) as ``"unknown sentence ..."``.
Lines that begin with ``#`` are comments (``"comment line (starts with #)"``, never fatal),
even when they quote a sentence.
"""

from __future__ import annotations

import datetime
import hashlib
import re
import sys
from collections import Counter
from pathlib import Path

import numpy as np

from gpsdr_cli.conventions import (
    FIX_DGPS,
    FIX_DR,
    FIX_FLOAT_RTK,
    FIX_GPS,
    FIX_NONE,
    FIX_PPS,
    FIX_RTK,
)
from gpsdr_cli.errors import ChecksumError, InputError, MissingDateError, NoDataError, ParseError
from gpsdr_cli.io.drive import NOT_USED, UNKNOWN, Drive, GnssFixes, SkipReport, Source

__all__ = ["looks_like_nmea", "parse_nmea", "read_nmea"]

KNOT_MPS = 1852.0 / 3600.0  # 1 international knot in m/s
_US_PER_DAY = 86_400_000_000
_HALF_DAY_US = _US_PER_DAY // 2

# kind codes of the sentences this reader uses
_GGA, _RMC, _GSA, _VTG, _GST, _ZDA, _GNS, _GLL, _GGK, _PUBX, _PUBX4 = range(11)
_KNOWN = {b"GGA": _GGA, b"RMC": _RMC, b"GSA": _GSA, b"VTG": _VTG, b"GST": _GST, b"ZDA": _ZDA,
          b"GNS": _GNS, b"GLL": _GLL}
#: Proprietary sentences read: (address, message id in field 1) -> kind.
_PROPRIETARY = {(b"PTNL", b"GGK"): _GGK, (b"PUBX", b"00"): _PUBX, (b"PUBX", b"04"): _PUBX4}
_TYPE_NAME = {v: k.decode() for k, v in _KNOWN.items()} | {
    v: f"{a.decode()},{m.decode()}" for (a, m), v in _PROPRIETARY.items()}
#: Standard NMEA 0183 sentence types (any talker) this reader does not use, with a short
#: plain name: counted as ``"not used: GSV (satellites in view)"``, not as unknown, so a
#: log full of them does not read as damaged.  Never fatal, like unknown sentences.
_NOT_USED = {
    b"GSV": "satellites in view",
    b"DTM": "datum reference",
    b"TXT": "text message",
    b"GBS": "satellite fault detection",
    b"GRS": "range residuals",
    b"GPQ": "poll request",
    b"GNQ": "poll request",
    b"GLQ": "poll request",
    b"GBQ": "poll request",
    b"VLW": "distance travelled",
    b"HDT": "true heading",
    b"HDG": "magnetic heading, deviation and variation",
    b"HDM": "magnetic heading",
    b"THS": "true heading and status",
    b"ROT": "rate of turn",
    b"RMB": "navigation to a waypoint",
    b"RMA": "Loran-C fix",
    b"BOD": "bearing origin to destination",
    b"BWC": "bearing and distance to a waypoint",
    b"XTE": "cross-track error",
    b"RTE": "route",
    b"WPL": "waypoint location",
    b"APB": "autopilot sentence B",
    b"MSS": "beacon receiver status",
    b"ALM": "GPS almanac",
    b"AAM": "waypoint arrival alarm",
    b"GLC": "Loran-C geographic position",
    b"XDR": "transducer measurements",
    b"DPT": "water depth",
    b"DBT": "water depth below transducer",
    b"DBS": "water depth below surface",
    b"MTW": "water temperature",
    b"VHW": "water speed and heading",
    b"VBW": "dual ground and water speed",
    b"VDR": "set and drift",
    b"MWV": "wind speed and angle",
    b"MWD": "wind direction and speed",
    b"RSA": "rudder sensor angle",
}
#: Bytes of a sentence's start that tell its kind: '$' + address + ','; for the
#: proprietary addresses read, the message id and its comma too.
_HEAD = 7
_HEAD_PROPRIETARY = {b"$PTNL,": 10, b"$PUBX,": 9}
_TIMED = (_GGA, _RMC, _GST, _ZDA, _GNS, _GLL, _GGK, _PUBX, _PUBX4)
#: Sentences that carry a date: a log whose every one of them is damaged has no date.
_DATED = (_RMC, _ZDA, _GGK, _PUBX4)
#: field number of the time of day; 1 for the other timed sentences
_TIME_FIELD = {_GLL: 5, _GGK: 2, _PUBX: 2, _PUBX4: 2}
#: Position sentences, most informative first: the epoch's position comes from the first
#: of these it has (GGA and GNS carry quality, satellites, HDOP and altitude; PTNL,GGK and
#: PUBX,00 quality and ellipsoidal height; RMC a mode; GLL only a status).
_POSITION_RANK = (_GGA, _GNS, _GGK, _PUBX, _RMC, _GLL)
#: Sentences of one epoch whose positions differ by more than this (deg; 1.1 cm in
#: latitude) disagree, unless one of them is printed more coarsely.
_DISAGREE_DEG = 1e-7
#: ... and unless they differ by at most this many units of the coarser one's last printed
#: digit: a receiver that rounds GGA and truncates GLL, or computes them a few ms apart,
#: prints one fix 1-2 units apart (0.0001' of arc: 0.19 m), which is no disagreement
_SAME_FIX_DIGITS = 2.5

# hex digit value of each byte, -1 if not a hex digit (upper or lower case)
_HEX = np.full(256, -1, np.int16)
for _c in b"0123456789":
    _HEX[_c] = _c - 48
for _c in b"ABCDEF":
    _HEX[_c] = _c - 55
    _HEX[_c + 32] = _c - 55

#: RMC/GNS mode indicator (NMEA 2.3+) -> GGA-style fix quality.  M (manual input) and S
#: (simulator) are positions no receiver measured: no fix.
_MODE_QUALITY = {b"": FIX_GPS, b"A": FIX_GPS, b"D": FIX_DGPS, b"P": FIX_PPS, b"R": FIX_RTK,
                 b"F": FIX_FLOAT_RTK, b"E": FIX_DR, b"N": FIX_NONE, b"M": FIX_NONE,
                 b"S": FIX_NONE}
#: GGA qualities of positions no receiver measured: typed in (7) or made up by the
#: receiver's simulator mode (8).  No fix; they never reach ``fix_quality``.
_GGA_MANUAL = 7
_GGA_SIMULATOR = 8
#: Skip reasons of sentences whose position is not a measurement, by the mode letter.
_NOT_MEASURED = {b"M": "manual input mode", b"S": "simulator mode"}
#: GNS mode letters from best to worst: the epoch's quality is the best any constellation
#: reports (a fix exists if one system has one).
_GNS_RANK = b"RFDPAE"
#: Trimble PTNL,GGK quality (index 0-15) -> GGA-style quality, as Trimble's GGA reports
#: the same solution: RTK fixed (3, 7, 9) and xFill (15) 4; RTK float (2, 6, 8), Location
#: RTK (12), OmniSTAR HP/XP (10) and CenterPoint RTX (14) 5; DGPS, SBAS, OmniSTAR VBS and
#: beacon (4, 5, 11, 13) 2; autonomous 1; 0 no fix.
_GGK_QUALITY = np.array([0, 1, 5, 4, 2, 2, 5, 4, 5, 4, 5, 2, 5, 2, 5, 4])
#: u-blox PUBX,00 navStat -> GGA-style quality: DR (the receiver's dead reckoning alone) is
#: 6 like GGA's "estimated"; RK (GNSS combined with dead reckoning) is a fix.
_NAVSTAT_QUALITY = {b"NF": FIX_NONE, b"TT": FIX_NONE, b"DR": FIX_DR, b"G2": FIX_GPS,
                    b"G3": FIX_GPS, b"RK": FIX_GPS, b"D2": FIX_DGPS, b"D3": FIX_DGPS}
KMH_MPS = 1.0 / 3.6  # 1 km/h in m/s

_CHUNK_BYTES = 1 << 22  # 4 MiB of whole lines scanned at a time
_DOP_NONE = 99.99  # receivers' placeholder for "no DOP" (u-blox, Quectel, ...): read as NaN
_MAX_FIELD = 40  # bytes; longer fields are never valid numbers or letters here


class _Problems:
    """Skipped things by reason: count, first byte offset, and whether strict mode raises."""

    def __init__(self) -> None:
        self.items: dict[str, list] = {}

    def add(self, reason: str, pos: np.ndarray | int, *, fatal: bool = True,
            exc: type[ParseError] = ParseError, n: int | None = None,
            detail: np.ndarray | None = None) -> None:
        """Count ``n`` (default: one per offset in ``pos``) skips of ``reason``.

        ``detail`` (aligned with ``pos``): text for the strict-mode message of the first.
        """
        pos = np.atleast_1d(np.asarray(pos, dtype=np.int64))
        if len(pos) == 0:
            return
        count = len(pos) if n is None else n
        i = int(pos.argmin())
        first = int(pos[i])
        note = "" if detail is None else str(detail[i])
        item = self.items.get(reason)
        if item is None:
            self.items[reason] = [count, first, fatal, exc, note]
        else:
            item[0] += count
            if first < item[1]:
                item[1], item[4] = first, note


def _line_breaks(arr: np.ndarray) -> np.ndarray:
    """Offsets of the line ends in ``arr``: LF, and CR not followed by LF."""
    lf = arr == 10
    ends = arr == 13
    ends[:-1] &= ~lf[1:]
    ends |= lf
    return np.flatnonzero(ends)


class _Lines:
    """Byte offset -> 1-based line number (LF, CRLF or lone CR line ends)."""

    def __init__(self, breaks: np.ndarray, arr: np.ndarray) -> None:
        self.breaks = breaks
        self.count = len(breaks) + int(len(arr) > 0 and arr[-1] not in (10, 13))

    def __call__(self, pos: np.ndarray | int) -> np.ndarray:
        return np.searchsorted(self.breaks, pos, side="right") + 1


# ------------------------------------------------------------------ sniffing and encoding
_SNIFF = re.compile(rb"[$!]([A-Za-z0-9]{2,12}[^*$!\r\n]*)\*([0-9A-Fa-f]{2})")
_SNIFF_NO_CK = re.compile(rb"(?m)^\$[A-Z]{2}(?:GGA|RMC|GNS|ZDA),\d{6}(?:\.\d*)?,[0-9A-Z.,+-]*\r?$")


def _utf16_kind(head: bytes) -> str | None:
    """'le'/'be' when ``head`` is UTF-16 text (BOM, or NULs interleaved with ASCII)."""
    if head[:2] == b"\xff\xfe":
        return "le"
    if head[:2] == b"\xfe\xff":
        return "be"
    sample = np.frombuffer(head[:4096], np.uint8)
    if len(sample) < 16:
        return None
    even, odd = sample[0::2], sample[1::2]
    n = min(len(even), len(odd))
    even, odd = even[:n], odd[:n]
    if np.mean(odd == 0) > 0.4 and np.mean(even == 0) < 0.05:
        return "le"
    if np.mean(even == 0) > 0.4 and np.mean(odd == 0) < 0.05:
        return "be"
    return None


def looks_like_nmea(head: bytes) -> bool:
    """True when ``head`` (the first bytes of a file) holds NMEA sentences with valid checksums.

    Needs two checksum-valid sentences in the first KB (one if the head holds at most
    three sentence starts).  UTF-16 NMEA also answers True, so that :func:`read_nmea` can say
    how to convert it.
    """
    kind = _utf16_kind(head)
    if kind is not None:
        head = head[2:] if head[:2] in (b"\xff\xfe", b"\xfe\xff") else head
        head = head.decode("utf-16-le" if kind == "le" else "utf-16-be",
                            errors="replace").encode("ascii", errors="replace")
    head = head[:1024].replace(b"\x00", b"")
    found = 0
    for m in _SNIFF.finditer(head):
        body = m.group(1)
        ck = 0
        for b in body:
            ck ^= b
        if ck == int(m.group(2), 16):
            found += 1
            if found >= 2:
                return True
    if found == 1 and head.count(b"$") + head.count(b"!") <= 3:
        return True
    # receivers that send no checksums: three lines that are plainly timed sentences
    return found == 0 and len(_SNIFF_NO_CK.findall(head)) >= 3


def _is_binary(data: bytes) -> bool:
    """More than 10 % of the first 64 KB are neither printable ASCII nor whitespace."""
    sample = np.frombuffer(data[:65536], np.uint8)
    if len(sample) == 0:
        return False
    text = ((sample >= 32) & (sample < 127)) | (sample == 9) | (sample == 10) | (sample == 13)
    return float(np.mean(~text)) > 0.10


# ------------------------------------------------------------------ field conversion
def _num(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Bytes field array -> (float64 values, NaN where empty or bad; mask of bad non-empty).

    Bad: not a number, or beyond +-1e9 (inf, nan, 1e300 ...).
    """
    empty = a == b""
    try:
        with np.errstate(over="ignore"):  # "1E999" casts to inf: bad below, no warning
            v = np.where(empty, b"nan", a).astype(np.float64)
    except ValueError:
        v = np.full(len(a), np.nan)
        for i, s in enumerate(a.tolist()):
            if s:
                try:
                    v[i] = float(s)
                except ValueError:
                    v[i] = np.inf  # marks bad below
    # no field read here exceeds 1e9 in magnitude; the bound keeps arithmetic finite
    with np.errstate(invalid="ignore"):
        bad = ~empty & ~(np.abs(v) <= 1e9)
    v[bad] = np.nan
    return v, bad


def _int_part_len(a: np.ndarray) -> np.ndarray:
    dot = np.strings.find(a, b".")
    return np.where(dot >= 0, dot, np.strings.str_len(a))


def _time_of_day_us(a: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``hhmmss[.sss]`` -> (microseconds of day, -1 where missing/bad; empty mask; bad mask).

    A trailing dot (``222509.``) is accepted; the integer part must have six digits.
    """
    v, bad = _num(a)
    empty = a == b""
    hh = np.floor(v / 10000.0)
    mm = np.floor(v / 100.0) - hh * 100.0
    ss = v - hh * 10000.0 - mm * 100.0
    ok = (np.isfinite(v) & (_int_part_len(a) == 6) & (v >= 0) & (hh < 24) & (mm < 60)
          & (ss < 61))
    bad = bad | (~empty & ~ok)
    with np.errstate(invalid="ignore"):
        us = np.where(ok, np.rint((hh * 3600.0 + mm * 60.0) * 1e6 + ss * 1e6), -1.0)
    return us.astype(np.int64), empty, bad


def _days_from_civil(y: np.ndarray, m: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Days since 1970-01-01 of proleptic Gregorian dates (H. Hinnant's algorithm)."""
    y = y - (m <= 2)
    era = y // 400
    yoe = y - era * 400
    mp = (m + 9) % 12
    doy = (153 * mp + 2) // 5 + d - 1
    doe = yoe * 365 + yoe // 4 - yoe // 100 + doy
    return era * 146097 + doe - 719468


def _valid_ymd(y: np.ndarray, m: np.ndarray, d: np.ndarray) -> np.ndarray:
    leap = (y % 4 == 0) & ((y % 100 != 0) | (y % 400 == 0))
    dim = np.array([0, 31, 28, 31, 30, 31, 30, 31, 31, 30, 31, 30, 31])[np.clip(m, 0, 12)]
    dim = dim + ((m == 2) & leap)
    # GNSS dates start with GPS time (1980-01-06); RMC's two-digit years map into 1980-2079
    return (m >= 1) & (m <= 12) & (d >= 1) & (d <= dim) & (y >= 1980) & (y <= 2099)


def _ymd_days(y: np.ndarray, m: np.ndarray, d: np.ndarray, ok: np.ndarray
              ) -> tuple[np.ndarray, np.ndarray]:
    """(days since epoch as float, NaN where invalid; mask of invalid among ``ok``)."""
    yi = np.where(ok, np.clip(y, 0, 9999), 2000).astype(np.int64)
    mi = np.where(ok, np.clip(m, 0, 99), 1).astype(np.int64)
    di = np.where(ok, np.clip(d, 0, 99), 1).astype(np.int64)
    valid = ok & _valid_ymd(yi, mi, di)
    days = np.where(valid, _days_from_civil(yi, mi, di), 0).astype(np.float64)
    days[~valid] = np.nan
    return days, ok & ~valid


def _rmc_date(a: np.ndarray, month_first: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``ddmmyy`` (``mmddyy`` if ``month_first``, PTNL,GGK) -> (days since epoch, NaN where
    missing/bad; bad mask)."""
    v, bad = _num(a)
    empty = a == b""
    digits = (np.strings.str_len(a) == 6) & np.strings.isdigit(a)
    ok = digits & np.isfinite(v)
    vi = np.where(ok, v, 0).astype(np.int64)
    yy = vi % 100
    hi, mid = vi // 10000, (vi // 100) % 100
    days, invalid = _ymd_days(np.where(yy < 80, 2000 + yy, 1900 + yy),
                              hi if month_first else mid, mid if month_first else hi, ok)
    return days, bad | (~empty & ~ok) | invalid


def _lat_lon(val: np.ndarray, hemi: np.ndarray, pos_letter: bytes, neg_letter: bytes,
             max_deg: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(d)ddmm.mmmm`` + hemisphere -> (degrees, NaN where empty/bad; empty mask; bad mask)."""
    v, bad = _num(val)
    empty = val == b""  # an empty value is no position, whatever the hemisphere says
    deg = np.floor(v / 100.0)
    minutes = v - deg * 100.0
    out = deg + minutes / 60.0
    sign = np.where(hemi == neg_letter, -1.0, 1.0)
    ok = (np.isfinite(v) & (v >= 0) & (minutes < 60.0) & (out <= max_deg)
          & ((hemi == pos_letter) | (hemi == neg_letter)))
    bad = bad | (~empty & ~ok)
    return np.where(ok, sign * out, np.nan), empty, bad


def _resolution_deg(val: np.ndarray) -> np.ndarray:
    """One unit of the last printed digit of ``(d)ddmm.mmmm`` values, in degrees."""
    dot = np.strings.find(val, b".")
    decimals = np.where(dot >= 0, np.strings.str_len(val) - dot - 1, 0)
    return 10.0 ** -np.clip(decimals, 0, 12) / 60.0


def _mode_quality(mode: np.ndarray, table: dict[bytes, int] = _MODE_QUALITY) -> np.ndarray:
    """RMC/GLL mode letters (PUBX,00 navStat with ``table``) -> GGA-style quality (-1 where
    not in ``table``), looked up once per distinct value."""
    uniq, inv = np.unique(mode, return_inverse=True)
    q = np.array([table.get(m, -1) for m in uniq.tolist()], np.int64)
    return q[inv.ravel()] if len(uniq) else np.zeros(0, np.int64)


def _gns_one(mode: bytes) -> int:
    """GGA-style quality of one GNS mode field (one letter per constellation); -1 if bad.

    The best letter wins (R 4 > F 5 > D 2 > P 3 > A 1 > E 6); only N/M/S letters: 0.
    """
    if not mode or any(c not in b"NAEDFMPRS" for c in mode):
        return -1
    for c in _GNS_RANK:
        if c in mode:
            return _MODE_QUALITY[bytes([c])]
    return 0


def _gns_quality(mode: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """GNS mode fields -> (GGA-style quality, 0 where bad; bad mask), once per distinct value."""
    uniq, inv = np.unique(mode, return_inverse=True)
    q = np.array([_gns_one(m) for m in uniq.tolist()], np.int64)
    q = q[inv.ravel()] if len(uniq) else np.zeros(0, np.int64)
    bad = q < 0
    return np.where(bad, 0, q), bad


def _position(s: _Sentences, k: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Fields ``k..k+3`` (lat, N/S, lon, E/W) -> (lat, lon deg, resolution deg, bad mask)."""
    la, lo = s.f(k), s.f(k + 2)
    lat, _, b1 = _lat_lon(la, s.f(k + 1), b"N", b"S", 90.0)
    lon, _, b2 = _lat_lon(lo, s.f(k + 3), b"E", b"W", 180.0)
    return lat, lon, np.maximum(_resolution_deg(la), _resolution_deg(lo)), b1 | b2


def _has_fix(q: np.ndarray, lat: np.ndarray, lon: np.ndarray) -> np.ndarray:
    """A fix: a measured quality (above 0, not GGA's manual input 7 or simulator 8) and a
    position, not the ``0,0`` some receivers print."""
    measured = (q > FIX_NONE) & (q != _GGA_MANUAL) & (q != _GGA_SIMULATOR)
    return measured & np.isfinite(lat) & np.isfinite(lon) & ~((lat == 0) & (lon == 0))


def _count_not_measured(probs: _Problems, tname: str, pos: np.ndarray, mode: np.ndarray) -> None:
    """Count the sentences whose mode (one letter, or GNS's one per system) says manual
    input or simulator: the user sees why a log of them gives no fix."""
    left = np.ones(len(pos), bool)
    for letter, how in _NOT_MEASURED.items():
        hit = left & (np.strings.find(mode, letter) >= 0)
        left &= ~hit
        probs.add(f"{tname} in {how} (mode {letter.decode()}, not a measurement)", pos[hit],
                  fatal=False)


def _dop(v: np.ndarray) -> np.ndarray:
    """A DOP field, NaN where absent, not positive or the receivers' 99.99 placeholder."""
    return np.where((v > 0) & (v < _DOP_NONE), v, np.nan)


def _satellites(n: np.ndarray) -> np.ndarray:
    """A satellite count, NaN where absent or out of range."""
    return np.where((n >= 0) & (n < 32767), np.floor(n), np.nan)


# ------------------------------------------------------------------ the parser
def _classify(head: bytes, bang: bool) -> int | str:
    """Kind code of a sentence from the first bytes of its body, or the skip reason."""
    parts = head.split(b",", 2)
    addr = parts[0]
    if len(parts) == 3 and (addr, parts[1]) in _PROPRIETARY and not bang:
        return _PROPRIETARY[(addr, parts[1])]  # a whole message id: a comma follows it
    if bang:
        return f"{UNKNOWN} (encapsulated !" + addr[:5].decode("ascii", "replace") + ", e.g. AIS)"
    if len(addr) == 5 and addr.isalpha() and addr.isupper():
        talker, typ = addr[:2], addr[2:]
        kind = _KNOWN.get(typ)
        if kind is not None and (talker[:1] != b"P" or (talker == b"PQ" and kind == _GSA)):
            return kind
        if talker[:1] == b"P":
            return f"{UNKNOWN} (proprietary $P...)"
        if typ in _NOT_USED:
            return f"{NOT_USED} {typ.decode()} ({_NOT_USED[typ]})"
        return f"{UNKNOWN} {typ.decode()}"
    if addr[:1] == b"P" and addr.isalnum():
        return f"{UNKNOWN} (proprietary $P...)"
    if addr[:2].isdigit():
        return f"{UNKNOWN} (numeric talker)"
    if len(addr) == 6 and addr.isalpha() and addr.isupper():
        if addr[5:] == b"H" and (addr[2:5] in _KNOWN or addr[2:5] in _NOT_USED):
            # Unicore's dual-antenna receivers: GGAH, RMCH, GSTH ... describe the secondary
            # (heading) antenna, a baseline away from the position the plain sentences give
            return f"{NOT_USED} {addr[2:].decode()} (the secondary antenna of a dual-antenna receiver)"
        return f"{UNKNOWN} (six-letter address)"
    label = "".join(chr(c) if 32 < c < 127 else "?" for c in addr[:6])
    return f"{UNKNOWN} {label!r}"


class _Sentences:
    """The valid sentences of one kind, their fields located by comma offsets (no splitting).

    ``f(k)`` gathers field ``k`` (0 = address) of every sentence into a fixed-width
    bytes array in one numpy operation; fields longer than ``_MAX_FIELD`` bytes
    become ``b"?"`` (never a valid value).
    """

    def __init__(self, win: np.ndarray, commas: np.ndarray, pos: np.ndarray, s1: np.ndarray,
                 st: np.ndarray) -> None:
        self.win, self.commas, self.pos, self.s1, self.st = win, commas, pos, s1, st
        self.n = len(pos)
        self.c0 = np.searchsorted(commas, s1)
        self.nf = np.searchsorted(commas, st) - self.c0 + 1  # fields including the address

    def f(self, k: int | np.ndarray) -> np.ndarray:
        k = np.broadcast_to(np.asarray(k, np.int64), (self.n,))
        has = (k < self.nf) & (k >= 0)
        nc = len(self.commas)
        ci = np.clip(self.c0 + k - 1, 0, max(nc - 1, 0))
        ce = np.clip(self.c0 + k, 0, max(nc - 1, 0))
        if nc:
            a = np.where(k == 0, self.s1, self.commas[ci] + 1)
            b = np.where(k == self.nf - 1, self.st, self.commas[ce])
        else:
            a, b = self.s1, self.st
        length = np.where(has, b - a, 0)
        w = int(min(length.max(initial=0), _MAX_FIELD))
        if w == 0:
            return np.zeros(self.n, dtype="S1")
        # rows of a sliding window over the bytes: one contiguous copy per field
        g = self.win[:, :w][np.where(has, a, 0)]
        g *= np.arange(w)[None, :] < length[:, None]
        out = g.view(f"S{w}").ravel()
        long = length > _MAX_FIELD
        if long.any():
            out = out.astype(f"S{max(w, 1)}")
            out[long] = b"?"
        return out


def _last_per_epoch(out: np.ndarray, epoch: np.ndarray, values: np.ndarray,
                    use: np.ndarray | None = None) -> None:
    """out[e] = the last (in file order) value with ``use`` of each epoch ``e``."""
    m = np.isfinite(values) if use is None else use
    e, v = epoch[m], values[m]
    if len(e) == 0:
        return
    last = np.r_[e[1:] != e[:-1], True]
    out[e[last]] = v[last]


#: Fewest fields (address included) a sentence without a checksum must have to be read:
#: every field up to the last one this reader uses is then complete, so a line cut short
#: by a logger is not mistaken for a sentence that merely omits its checksum.
_ADDRESS = re.compile(rb"[A-Z][A-Z0-9]{2,6},")
_MIN_FIELDS_NO_CK = {b"GGA": 14, b"GNS": 12, b"RMC": 12, b"GLL": 7, b"GSA": 18, b"VTG": 9,
                     b"GST": 9, b"ZDA": 6}


def _heads(arr: np.ndarray, at: np.ndarray, width: int) -> np.ndarray:
    """The ``width`` bytes from each offset in ``at`` (clipped at the end of ``arr``), one
    ``S{width}`` value each: a sentence's address, classified once per distinct one."""
    idx = np.minimum(np.asarray(at, np.int64)[:, None] + np.arange(width), len(arr) - 1)
    return np.ascontiguousarray(arr[idx]).view(f"S{width}").ravel()


def _without_checksum_reasons(arr: np.ndarray, starts: np.ndarray) -> list[tuple[str, np.ndarray]]:
    """The whole lines without ``*hh`` that are not read, grouped by skip reason: a standard
    type the reader does not use is counted as that type (``not used: GSV ...``), as it is
    with a checksum; any other line as an unknown sentence without checksum."""
    if len(starts) == 0:
        return []
    uniq, inverse = np.unique(_heads(arr, starts + 1, 5), return_inverse=True)
    why = []
    for h in uniq.tolist():  # once per distinct address
        reason = _classify(h, False)
        why.append(reason if isinstance(reason, str) and reason.startswith(NOT_USED)
                   else f"{UNKNOWN} without checksum")
    by_reason = np.asarray(why)[inverse.ravel()]
    return [(r, starts[by_reason == r]) for r in sorted(set(why))]


def _complete_without_checksum(arr: np.ndarray, starts: np.ndarray, end: np.ndarray,
                               star: np.ndarray, eol: np.ndarray,
                               commas: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Of the sentences without ``*hh``, those read anyway: (starts, body ends), and the
    starts of whole lines of a type this reader does not use (:func:`_without_checksum_reasons`).

    NMEA 0183 made the checksum optional for most sentences before 2.0 and some
    receivers (old Garmin and Magellan handhelds, loggers that strip it) never send one;
    gpsd reads such lines.  Taken: a known type from any talker, ended by a line end (not
    by the next ``$``, not the unterminated last line of the file), no ``*`` at all,
    printable ASCII only, and at least ``_MIN_FIELDS_NO_CK`` fields.
    """
    if len(starts) == 0:
        return starts, starts, starts
    at_eol = np.isin(end, eol) & (star >= end)
    st = end.copy()
    for _ in range(2):  # trailing blanks before the line end ("\r\r\n", "... \r\n")
        blank = (st > starts + 1) & ((arr[np.maximum(st - 1, 0)] == 32)
                                     | (arr[np.maximum(st - 1, 0)] == 13))
        st = np.where(blank, st - 1, st)
    ok = at_eol & (st - starts >= 7)
    if not ok.any():
        return starts[:0], starts[:0], starts[:0]
    printable = np.r_[0, np.cumsum((arr < 32) | (arr > 126))]
    ok &= printable[st] - printable[starts + 1] == 0
    nf = np.searchsorted(commas, st) - np.searchsorted(commas, starts) + 1
    idx = np.flatnonzero(ok)
    uniq, inverse = np.unique(_heads(arr, starts[idx] + 1, 8), return_inverse=True)
    never = np.iinfo(np.int64).max
    need = np.full(len(uniq), never)
    address = np.zeros(len(uniq), bool)
    for u, h in enumerate(uniq.tolist()):  # once per distinct address
        address[u] = _ADDRESS.match(h) is not None
        k = _MIN_FIELDS_NO_CK.get(h[2:5]) if h[5:6] == b"," else None
        if k is not None and isinstance(_classify(h[:5], False), int):
            need[u] = k
    take = np.zeros(len(starts), bool)
    need_i = need[inverse.ravel()]
    take[idx] = nf[idx] >= need_i
    other = np.zeros(len(starts), bool)  # e.g. $GPRMB, $PGRME: not "$" inside free text
    other[idx] = (need_i == never) & address[inverse.ravel()]
    return starts[take], st[take], starts[other]


def _count_damaged_dated(arr: np.ndarray, starts: np.ndarray, reason: str, stats: dict) -> None:
    """Count in ``stats['damaged_dated']`` by (type, "skipped: ``reason``") the skipped
    sentences at ``starts`` whose address is a dated kind (RMC, ZDA, PTNL,GGK, PUBX,04): they tell
    why a log has no date."""
    if len(starts) == 0:
        return
    uniq, counts = np.unique(_heads(arr, starts, max(_HEAD_PROPRIETARY.values())),
                             return_counts=True)
    for head, count in zip(uniq.tolist(), counts.tolist(), strict=True):
        kind = _classify(head[1:], head[:1] == b"!")
        if kind in _DATED:
            stats["damaged_dated"][(_TYPE_NAME[kind], f"skipped: {reason}")] += count


def _scan_chunk(arr: np.ndarray, base: int, breaks: np.ndarray, probs: _Problems,
                acc: dict[int, list[dict[str, np.ndarray]]], stats: dict) -> int:
    """Steps 1-4 on one chunk of whole lines (``arr``, starting at byte ``base`` of the file).

    Appends the parsed fields of each kind to ``acc``, problems (with file offsets) to
    ``probs`` and counts to ``stats``; returns the number of checksum-valid sentences.
    ``breaks``: offsets of the line ends inside the chunk.
    """
    n = len(arr)
    # ---- 1. sentence candidates: from a start to the next start or line end
    is_start = arr == 36  # '$'
    bang = arr == 33  # '!' followed by an upper-case letter (AIS and other encapsulation)
    if n > 1:
        nxt = arr[1:]
        bang[:-1] &= (nxt >= 65) & (nxt <= 90)
    bang[-1:] = False
    starts = np.flatnonzero(is_start | bang)
    # a '$' on a line that begins with '#' is a comment's text (gpsd's regression logs quote
    # sentences in their headers), not a sentence cut short
    line_first = np.r_[0, breaks + 1]
    line_first = line_first[line_first < n]
    if len(starts) and len(line_first):
        on_line = line_first[np.searchsorted(line_first, starts, side="right") - 1]
        starts = starts[arr[on_line] != 35]  # '#'
    eol = np.flatnonzero((arr == 10) | (arr == 13))
    stars = np.flatnonzero(arr == 42)
    next_start = np.r_[starts[1:], n]
    i_eol = np.searchsorted(eol, starts)
    next_eol = np.r_[eol, n][i_eol]
    end = np.minimum(next_start, next_eol)
    i_star = np.searchsorted(stars, starts)
    star = np.r_[stars, n][i_star]
    has_ck = star + 3 <= end
    star_c = np.minimum(star, n - 1)
    h1 = _HEX[arr[np.minimum(star_c + 1, n - 1)]]
    h2 = _HEX[arr[np.minimum(star_c + 2, n - 1)]]
    has_ck &= (h1 >= 0) & (h2 >= 0) & (star > starts + 1)

    doubled = (next_start == starts + 1) & (next_start < n)  # "$$": ignore the first
    stats["doubled_starts"] += int(doubled.sum())
    no_ck = ~has_ck & ~doubled
    commas = np.flatnonzero(arr == 44)
    nock_start, nock_st, nock_other = _complete_without_checksum(
        arr, starts[no_ck], end[no_ck], star[no_ck], eol, commas)
    stats["no_checksum"] += len(nock_start)
    for reason, at in _without_checksum_reasons(arr, nock_other):
        probs.add(reason, at + base, fatal=False)
    truncated = np.setdiff1d(starts[no_ck], np.r_[nock_start, nock_other])
    probs.add("no checksum (truncated sentence)", truncated + base)
    _count_damaged_dated(arr, truncated, "no checksum (truncated sentence)", stats)

    # ---- 2. checksums, all at once
    s1 = starts[has_ck] + 1
    st = star[has_ck]
    if len(s1):
        idx = np.empty(2 * len(s1), np.int64)
        idx[0::2] = s1
        idx[1::2] = st
        xor = np.bitwise_xor.reduceat(arr, idx)[0::2]
        given = h1[has_ck] * 16 + h2[has_ck]
        good = xor == given
    else:
        good = np.zeros(0, bool)
    if not good.all():
        computed = np.char.mod("computed *%02X", xor[~good])
        probs.add("bad checksum", starts[has_ck][~good] + base, exc=ChecksumError,
                  detail=computed)
        _count_damaged_dated(arr, starts[has_ck][~good], "bad checksum", stats)
    ok_start = starts[has_ck][good]
    ok_st_a = st[good]
    if len(nock_start):
        ok_start = np.r_[ok_start, nock_start]
        ok_st_a = np.r_[ok_st_a, nock_st]
        order = np.argsort(ok_start, kind="stable")
        ok_start, ok_st_a = ok_start[order], ok_st_a[order]
    ok_s1_a = ok_start + 1

    # lines that hold no sentence start at all but are not blank: free text, JSON, comments
    if len(line_first):
        nonblank = np.logical_or.reduceat(
            ~((arr == 32) | (arr == 9) | (arr == 10) | (arr == 13)), line_first)
        with_start = np.zeros(len(line_first), bool)
        with_start[np.searchsorted(line_first, starts, side="right") - 1] = True
        text_lines = line_first[nonblank & ~with_start]
        comment = arr[text_lines] == 35  # '#'
        probs.add("comment line (starts with #)", text_lines[comment] + base, fatal=False)
        probs.add("not a sentence (no $ on the line)", text_lines[~comment] + base)


    # ---- 3. classify by the first 7 bytes ('$'/'!' + address + ','), once per distinct head;
    # $PTNL/$PUBX by their message id too ('$PTNL,GGK,', '$PUBX,00,')
    # window view over the chunk padded with NULs: row i = the _MAX_FIELD bytes from i
    win = np.lib.stride_tricks.sliding_window_view(
        np.concatenate([arr, np.zeros(_MAX_FIELD, np.uint8)]), _MAX_FIELD)
    wide = max(_HEAD_PROPRIETARY.values())
    heads = win[:, :wide][ok_start]
    keep_len = np.full(len(ok_start), _HEAD)
    for prefix, width in _HEAD_PROPRIETARY.items():
        keep_len[(heads[:, :len(prefix)] == np.frombuffer(prefix, np.uint8)).all(axis=1)] = width
    keep_len = np.minimum(keep_len, ok_st_a - ok_start)
    heads *= np.arange(wide)[None, :] < keep_len[:, None]  # past the head or the body: NUL
    heads = heads.view(f"S{wide}").ravel()
    uniq, first_i, inverse, counts = np.unique(heads, return_index=True, return_inverse=True,
                                               return_counts=True)
    kind_of_uniq = np.empty(len(uniq), np.int64)
    for u, head in enumerate(uniq.tolist()):
        k = _classify(head[1:], head[:1] == b"!")
        if isinstance(k, int):
            kind_of_uniq[u] = k
            talker = head[1:5] if k in (_GGK, _PUBX, _PUBX4) else head[1:3]  # PTNL, PUBX
            stats["talkers"][talker.decode("ascii", "replace")] += int(counts[u])
        else:
            kind_of_uniq[u] = -1
            probs.add(k, int(ok_start[first_i[u]]) + base, fatal=False, n=int(counts[u]))
    kind_arr = kind_of_uniq[inverse.ravel()] if len(uniq) else np.zeros(0, np.int64)

    sent: dict[int, _Sentences] = {}
    for kind in _TYPE_NAME:
        sel = np.flatnonzero(kind_arr == kind)
        if len(sel) == 0:
            continue
        sent[kind] = _Sentences(win, commas, ok_start[sel] + base, ok_s1_a[sel], ok_st_a[sel])
        stats["sentences"][_TYPE_NAME[kind]] += len(sel)

    # ---- 4. fields per kind; each returns (keep mask, sod_us) and its arrays
    for kind, s in sent.items():
        tname = _TYPE_NAME[kind]
        p: dict[str, np.ndarray] = {}
        keep = np.ones(s.n, bool)
        if kind in _TIMED:
            sod, empty_t, bad_t = _time_of_day_us(s.f(_TIME_FIELD.get(kind, 1)))
            probs.add(f"malformed time in {tname}", s.pos[bad_t])
            probs.add(f"{tname} without time (receiver not synchronised)", s.pos[empty_t],
                      fatal=False)
            keep &= sod >= 0
            p["sod"] = sod
        if kind == _GGA:
            lat, lon, res, badpos = _position(s, 2)
            q, bq = _num(s.f(6))
            bq |= np.isfinite(q) & ((q != np.floor(q)) | (q < 0) | (q > 9))
            probs.add("malformed position in GGA", s.pos[badpos & keep])
            probs.add("malformed fix quality in GGA", s.pos[bq & keep & ~badpos])
            keep &= ~badpos & ~bq
            qi = np.where(np.isfinite(q) & ~bq, q, 0).astype(np.int64)
            for code, how in ((_GGA_MANUAL, "manual input mode"),
                              (_GGA_SIMULATOR, "simulator mode")):
                probs.add(f"GGA in {how} (quality {code}, not a measurement)",
                          s.pos[(qi == code) & keep], fatal=False)
            fix = _has_fix(qi, lat, lon)
            nsat, bs = _num(s.f(7))
            hdop, bh = _num(s.f(8))
            alt, ba = _num(s.f(9))
            sep, bsep = _num(s.f(11))
            for bad, fld in ((bs, "satellites"), (bh, "HDOP"), (ba, "altitude"),
                             (bsep, "geoid separation")):
                probs.add(f"malformed {fld} in GGA (field ignored)", s.pos[bad & keep])
            stats["alt_without_geoid_sep"] += int((fix & keep & np.isfinite(alt) & np.isnan(sep)).sum())
            # a fix from 0 satellites is a receiver's placeholder (Furuno GT-88): unknown
            nsat[fix & (nsat == 0)] = np.nan
            p.update(lat=np.where(fix, lat, np.nan), lon=np.where(fix, lon, np.nan), res=res,
                     alt=np.where(fix, alt + np.nan_to_num(sep), np.nan),
                     q=np.where(fix, qi, 0).astype(np.float64),
                     nsat=_satellites(nsat), hdop=_dop(hdop), talker=_talker_code(s.f(0)))
        elif kind == _GNS:
            lat, lon, res, badpos = _position(s, 2)
            probs.add("malformed position in GNS", s.pos[badpos & keep])
            keep &= ~badpos
            mode = s.f(6)
            qi, bm = _gns_quality(mode)
            # a per-system GNS beside the combined GN one (NMEA 4.1: Trimble, u-blox) carries
            # its satellite count only: empty mode, no position; not a damaged sentence
            bm &= ~((mode == b"") & np.isnan(lat) & np.isnan(lon))
            probs.add("malformed mode in GNS", s.pos[bm & keep & ~badpos])
            keep &= ~bm
            none = keep & (qi == FIX_NONE)  # a letter of a fix in any system wins
            _count_not_measured(probs, "GNS", s.pos[none], mode[none])
            fix = _has_fix(qi, lat, lon)
            nsat, bs = _num(s.f(7))
            hdop, bh = _num(s.f(8))
            alt, ba = _num(s.f(9))
            sep, bsep = _num(s.f(10))
            for bad, fld in ((bs, "satellites"), (bh, "HDOP"), (ba, "altitude"),
                             (bsep, "geoid separation")):
                probs.add(f"malformed {fld} in GNS (field ignored)", s.pos[bad & keep])
            stats["alt_without_geoid_sep"] += int((fix & keep & np.isfinite(alt) & np.isnan(sep)).sum())
            p.update(lat=np.where(fix, lat, np.nan), lon=np.where(fix, lon, np.nan), res=res,
                     alt=np.where(fix, alt + np.nan_to_num(sep), np.nan),
                     q=np.where(fix, qi, 0).astype(np.float64),
                     nsat=_satellites(nsat), hdop=_dop(hdop))
        elif kind == _GGK:
            lat, lon, res, badpos = _position(s, 4)
            q, bq = _num(s.f(8))
            bq |= np.isfinite(q) & ((q != np.floor(q)) | (q < 0) | (q >= len(_GGK_QUALITY)))
            probs.add(f"malformed position in {tname}", s.pos[badpos & keep])
            probs.add(f"malformed fix quality in {tname}", s.pos[bq & keep & ~badpos])
            keep &= ~badpos & ~bq
            qi = _GGK_QUALITY[np.where(np.isfinite(q) & ~bq, q, 0).astype(np.int64)]
            fix = _has_fix(qi, lat, lon)
            days, bd = _rmc_date(s.f(3), month_first=True)
            probs.add(f"malformed date in {tname} (field ignored)", s.pos[bd & keep])
            nsat, bs = _num(s.f(9))
            pdop, bp = _num(s.f(10))
            # the height is ellipsoidal and says so: "EHT-5.923"; a bare number is not read
            ht = s.f(11)
            eht = np.strings.startswith(ht, b"EHT")
            alt, ba = _num(np.where(eht, np.strings.replace(ht, b"EHT", b"", 1), b""))
            ba |= (ht != b"") & ~eht
            for bad, fld in ((bs, "satellites"), (bp, "DOP"), (ba, "height")):
                probs.add(f"malformed {fld} in {tname} (field ignored)", s.pos[bad & keep])
            p.update(lat=np.where(fix, lat, np.nan), lon=np.where(fix, lon, np.nan), res=res,
                     alt=np.where(fix, alt, np.nan), q=np.where(fix, qi, 0).astype(np.float64),
                     nsat=_satellites(nsat), pdop=_dop(pdop), days=days)
        elif kind == _PUBX4:
            # u-blox's time of day and date (ddmmyy), beside PUBX,00 positions without one
            days, bd = _rmc_date(s.f(3))
            probs.add(f"malformed date in {tname} (field ignored)", s.pos[bd & keep])
            p["days"] = days
        elif kind == _PUBX:
            lat, lon, res, badpos = _position(s, 3)
            qi = _mode_quality(s.f(8), _NAVSTAT_QUALITY)
            bq = qi < 0
            badpos &= ~bq & (qi > 0)  # "NF" prints zeros or blanks: no position to check
            probs.add(f"malformed position in {tname}", s.pos[badpos & keep])
            probs.add(f"malformed navigation status in {tname}", s.pos[bq & keep & ~badpos])
            keep &= ~badpos & ~bq
            fix = _has_fix(qi, lat, lon)
            alt, ba = _num(s.f(7))
            hacc, bha = _num(s.f(9))
            spd, bsp = _num(s.f(11))
            crs, bc = _num(s.f(12))
            hdop, bh = _num(s.f(15))
            vdop, bv = _num(s.f(16))
            nsat, bs = _num(s.f(18))
            for bad, fld in ((ba, "altitude"), (bha, "horizontal accuracy"), (bsp, "speed"),
                             (bc, "course"), (bh, "HDOP"), (bv, "VDOP"), (bs, "satellites")):
                probs.add(f"malformed {fld} in {tname} (field ignored)", s.pos[bad & keep])
            # hAcc is one radial 1-sigma: hAcc**2 = sigma_n**2 + sigma_e**2, as io/ubx.py
            # reads NAV-PVT's hAcc, so both u-blox outputs give the same sigmas
            sig = np.where(fix & (hacc > 0), hacc / np.sqrt(2.0), np.nan)
            p.update(lat=np.where(fix, lat, np.nan), lon=np.where(fix, lon, np.nan), res=res,
                     alt=np.where(fix, alt, np.nan), q=np.where(fix, qi, 0).astype(np.float64),
                     sig_n=sig, sig_e=sig,
                     speed=np.where(fix & (spd >= 0), spd * KMH_MPS, np.nan),
                     course=np.where(fix & (crs >= 0) & (crs <= 360), crs % 360.0, np.nan),
                     hdop=_dop(hdop), vdop=_dop(vdop), nsat=_satellites(nsat))
        elif kind == _GLL:
            status = s.f(6)
            lat, lon, res, badpos = _position(s, 1)
            badpos &= status == b"A"
            probs.add("malformed position in GLL", s.pos[badpos & keep])
            keep &= ~badpos
            mode = s.f(7)
            mq = _mode_quality(mode)
            probs.add("malformed mode in GLL (field ignored)", s.pos[(mq < 0) & keep])
            ok = keep & (mq >= 0)
            _count_not_measured(probs, "GLL", s.pos[ok], mode[ok])
            mq[mq < 0] = 1
            fix = (status == b"A") & _has_fix(mq, lat, lon)
            p.update(lat=np.where(fix, lat, np.nan), lon=np.where(fix, lon, np.nan), res=res,
                     q=np.where(fix, mq, 0).astype(np.float64))
        elif kind == _RMC:
            status = s.f(2)
            lat, lon, res, badpos = _position(s, 3)
            badpos &= status == b"A"
            probs.add("malformed position in RMC", s.pos[badpos & keep])
            keep &= ~badpos
            mode = s.f(12)
            mq = _mode_quality(mode)
            probs.add("malformed mode in RMC (field ignored)", s.pos[(mq < 0) & keep])
            ok = keep & (mq >= 0)
            _count_not_measured(probs, "RMC", s.pos[ok], mode[ok])
            mq[mq < 0] = 1
            valid = status == b"A"
            fix = valid & _has_fix(mq, lat, lon)
            spd, bsp = _num(s.f(7))
            crs, bc = _num(s.f(8))
            probs.add("malformed speed in RMC (field ignored)", s.pos[bsp & keep])
            probs.add("malformed course in RMC (field ignored)", s.pos[bc & keep])
            days, bd = _rmc_date(s.f(9))
            probs.add("malformed date in RMC (field ignored)", s.pos[bd & keep])
            p.update(lat=np.where(fix, lat, np.nan), lon=np.where(fix, lon, np.nan), res=res,
                     q=np.where(fix, mq, 0).astype(np.float64),
                     speed=np.where(valid & (spd >= 0), spd * KNOT_MPS, np.nan),
                     course=np.where(valid & (crs >= 0) & (crs <= 360), crs % 360.0, np.nan),
                     days=days)
        elif kind == _GSA:
            nf = s.nf
            last = s.f(nf - 1)
            sysid = (nf >= 19) & (np.strings.find(last, b".") < 0) & (np.strings.str_len(last) <= 2)
            k0 = np.where(sysid, nf - 4, nf - 3)
            short = k0 < 3
            probs.add("GSA with too few fields", s.pos[short])
            keep &= ~short
            k0 = np.maximum(k0, 3)
            dops = []
            for j in range(3):
                kk = k0 + j
                v, b = _num(s.f(kk))
                probs.add("malformed DOP in GSA (field ignored)", s.pos[b & keep])
                dops.append(_dop(v))
            nofix = s.f(2) == b"1"
            p.update(pdop=np.where(nofix, np.nan, dops[0]), hdop=np.where(nofix, np.nan, dops[1]),
                     vdop=np.where(nofix, np.nan, dops[2]))
        elif kind == _VTG:
            crs, bc = _num(s.f(1))
            spd, bsp = _num(s.f(5))
            probs.add("malformed speed in VTG (field ignored)", s.pos[bsp])
            probs.add("malformed course in VTG (field ignored)", s.pos[bc])
            valid = s.f(9) != b"N"
            p.update(speed=np.where(valid & (spd >= 0), spd * KNOT_MPS, np.nan),
                     course=np.where(valid & (crs >= 0) & (crs <= 360), crs % 360.0, np.nan))
        elif kind == _GST:
            sn, b1 = _num(s.f(6))
            se, b2 = _num(s.f(7))
            probs.add("malformed sigma in GST (field ignored)", s.pos[(b1 | b2) & keep])
            p.update(sig_n=np.where(sn >= 0, sn, np.nan), sig_e=np.where(se >= 0, se, np.nan))
        elif kind == _ZDA:
            d, bd = _num(s.f(2))
            mo, bm = _num(s.f(3))
            y, by = _num(s.f(4))
            have = np.isfinite(d) & np.isfinite(mo) & np.isfinite(y)
            ok = have & (_int_part_len(s.f(4)) == 4)
            days, invalid = _ymd_days(y, mo, d, ok)
            bad_date = bd | bm | by | (have & ~ok) | invalid
            probs.add("malformed date in ZDA (field ignored)", s.pos[bad_date & keep])
            # a ZDA whose date fields are empty (a receiver before its almanac, some marine
            # loggers) still gives the time; it is why a log has no date, if it has none
            empty = int(np.count_nonzero(~have & ~(bd | bm | by) & keep))
            if empty:
                stats["damaged_dated"][("ZDA", "with empty date fields")] += empty
            p["days"] = days
        p["pos"] = s.pos
        acc.setdefault(kind, []).append({k: v[keep] for k, v in p.items()})
    return len(ok_start)


def _assign_epochs(parsed: dict[int, dict[str, np.ndarray]]) -> np.ndarray | None:
    """Give every sentence its epoch (``parsed[kind]['ep']``); return each epoch's time of day.

    A timed sentence (GGA, GNS, RMC, GLL, GST, ZDA, PTNL,GGK, PUBX,00) opens a new epoch
    when its time of day differs from the previous timed sentence's, or when its date
    differs from a date already seen among the sentences of that time of day in a row (a
    multi-day log sampled at the same time of day).
    Untimed sentences (GSA, VTG) join the epoch of the timed sentence before them; before
    the first one, the first epoch.
    Returns the epochs' times of day (us), or None when no sentence has a time.
    """
    kinds = list(parsed)
    if not kinds:
        return None
    pos_all = np.concatenate([parsed[k]["pos"] for k in kinds])
    sod_all = np.concatenate([parsed[k]["sod"] if k in _TIMED else
                              np.full(len(parsed[k]["pos"]), -1, np.int64) for k in kinds])
    days_all = np.concatenate([parsed[k]["days"] if "days" in parsed[k] else
                               np.full(len(parsed[k]["pos"]), np.nan) for k in kinds])
    order = np.argsort(pos_all, kind="stable")
    s_sorted = sod_all[order]
    t_mask = s_sorted >= 0
    if not t_mask.any():
        return None
    ts = s_sorted[t_mask]
    td = days_all[order][t_mask]
    # the date seen so far among the sentences of the same time of day in a row: a GGA
    # that comes before its epoch's RMC keeps that RMC even when the date it brings is not
    # the last one seen (a receiver's first fix after its cold-start default date)
    same = np.r_[False, ts[1:] == ts[:-1]]
    run_start = np.maximum.accumulate(np.where(~same, np.arange(len(ts)), 0))
    last_d = np.maximum.accumulate(np.where(np.isfinite(td), np.arange(len(td)), -1))
    d_run = np.where(last_d >= run_start, td[np.maximum(last_d, 0)], np.nan)
    date_change = np.isfinite(td[1:]) & np.isfinite(d_run[:-1]) & (td[1:] != d_run[:-1])
    new = np.r_[True, (ts[1:] != ts[:-1]) | date_change]
    ep_timed = np.cumsum(new) - 1
    last_timed = np.maximum.accumulate(np.where(t_mask, np.arange(len(s_sorted)), -1))
    rank = np.cumsum(t_mask) - 1
    ep_sorted = np.where(last_timed >= 0, ep_timed[rank[np.maximum(last_timed, 0)]], 0)
    ep_all = np.empty_like(ep_sorted)
    ep_all[order] = ep_sorted
    off = 0
    for k in kinds:
        m = len(parsed[k]["pos"])
        parsed[k]["ep"] = ep_all[off:off + m]
        off += m
    return ts[new]


def _merge_epochs(parsed: dict[int, dict[str, np.ndarray]], n_ep: int,
                  position_from: str = "rank") -> dict[str, np.ndarray]:
    """One value per epoch and field: the last non-empty in file order, by the module's rules.

    ``row``: the epoch has a position sentence (:data:`_POSITION_RANK`: the epochs that become
    fixes).  ``disagree``: its position sentences disagree (:func:`_disagreements`).
    ``position_from``: ``"rank"`` (the position of the most informative kind) or ``"last"``
    (of the last position sentence with a fix, in file order: what gpsd reports).
    """
    def field(kinds_fields: list[tuple[int, str]]) -> np.ndarray:
        out = np.full(n_ep, np.nan)
        for kind, fld in kinds_fields:  # later kinds win
            if kind in parsed:
                _last_per_epoch(out, parsed[kind]["ep"], parsed[kind][fld])
        return out

    # position and quality: from the most informative position sentence kind the epoch has
    # (even without a fix: a GGA's quality 0 is not overridden by an RMC's 'A')
    row = np.zeros(n_ep, bool)
    taken = np.zeros(n_ep, bool)
    e = {f: np.full(n_ep, np.nan) for f in ("lat", "lon", "alt", "res")}
    e["q"] = np.zeros(n_ep)
    for kind in _POSITION_RANK:
        if kind not in parsed:
            continue
        g = parsed[kind]
        has = np.zeros(n_ep, bool)
        has[g["ep"]] = True
        use = np.isfinite(g["lat"]) & ~taken[g["ep"]]
        for f in ("lat", "lon", "q", "res") + (("alt",) if "alt" in g else ()):
            _last_per_epoch(e[f], g["ep"], g[f], use)
        taken |= has
    row = taken
    if position_from == "last":
        kinds = [k for k in _POSITION_RANK if k in parsed]
        cat = {f: np.concatenate([parsed[k][f] for k in kinds])
               for f in ("ep", "pos", "lat", "lon", "q", "res")}
        o = np.argsort(cat["pos"], kind="stable")
        fix = np.isfinite(cat["lat"][o])
        for f in ("lat", "lon", "q", "res"):
            _last_per_epoch(e[f], cat["ep"][o], cat[f][o], fix)
    elif position_from != "rank":
        raise ValueError(f"position_from must be 'rank' or 'last', not {position_from!r}")
    e["disagree"] = _disagreements(parsed, e, n_ep)
    # later kinds win: of two position sentences, the one ranked higher in _POSITION_RANK
    e["nsat"] = field([(_PUBX, "nsat"), (_GGK, "nsat"), (_GNS, "nsat")])
    if _GGA in parsed:
        _gga_satellites(e["nsat"], parsed[_GGA])  # GGA wins
    e["hdop"] = field([(_PUBX, "hdop"), (_GSA, "hdop"), (_GNS, "hdop"),
                       (_GGA, "hdop")])  # GGA's HDOP wins
    e["pdop"] = field([(_GGK, "pdop"), (_GSA, "pdop")])
    e["vdop"] = field([(_PUBX, "vdop"), (_GSA, "vdop")])
    e["sig_n"] = field([(_PUBX, "sig_n"), (_GST, "sig_n")])  # GST's per-axis sigmas win
    e["sig_e"] = field([(_PUBX, "sig_e"), (_GST, "sig_e")])
    e["speed"] = field([(_PUBX, "speed"), (_VTG, "speed"), (_RMC, "speed")])  # RMC wins
    e["course"] = field([(_PUBX, "course"), (_VTG, "course"), (_RMC, "course")])
    e["row"] = row
    return e


def _talker_code(addr: np.ndarray) -> np.ndarray:
    """The two talker letters of each address (``GP``, ``GL``, ``GN``...) as one number."""
    t = np.frombuffer(np.ascontiguousarray(addr.astype("S2")).tobytes(), np.uint8)
    t = t.reshape(-1, 2).astype(np.float64) if len(addr) else np.zeros((0, 2))
    return t[:, 0] * 256 + t[:, 1]


_GN_CODE = float(ord("G") * 256 + ord("N"))


def _gga_satellites(out: np.ndarray, g: dict[str, np.ndarray]) -> None:
    """out[e] = the satellites of epoch ``e``'s GGA fix.

    Receivers that print one GGA per constellation (SiRFstar V: ``$GPGGA`` with the GPS
    satellites, ``$GLGGA`` with the GLONASS ones, same position) count the fix's
    satellites in their sum; a ``$GN`` (combined) GGA of the epoch gives the total itself.
    One talker per epoch (the usual case) is its last GGA's count.
    """
    m = np.isfinite(g["nsat"])
    ep, tk, ns = g["ep"][m], g["talker"][m], g["nsat"][m]
    if len(ep) == 0:
        return
    o = np.lexsort((tk, ep))  # stable: file order kept within (epoch, talker)
    ep, tk, ns = ep[o], tk[o], ns[o]
    last = np.r_[(ep[1:] != ep[:-1]) | (tk[1:] != tk[:-1]), True]
    ep, tk, ns = ep[last], tk[last], ns[last]
    gn = tk == _GN_CODE
    total = np.zeros(len(out))
    np.add.at(total, ep[~gn], ns[~gn])
    has = np.zeros(len(out), bool)
    has[ep] = True
    out[has] = total[has]
    out[ep[gn]] = ns[gn]


def _disagreements(parsed: dict[int, dict[str, np.ndarray]], e: dict[str, np.ndarray],
                   n_ep: int) -> np.ndarray:
    """Mask of epochs where a position sentence's fix differs from the one taken; refines it.

    Differs: by more than :data:`_DISAGREE_DEG` in latitude or longitude, and by more than
    :data:`_SAME_FIX_DIGITS` units of the last digit printed by either (an RMC with 4
    decimals of minutes beside a GGA with 7 is the same fix, rounded).  Among the sentences that agree with
    the one taken and are printed as finely, the last in file order gives ``e['lat']`` /
    ``e['lon']`` (what gpsd reports for such an epoch: receivers that round GGA and
    truncate GLL differ by one digit).
    """
    kinds = [k for k in _POSITION_RANK if k in parsed]
    out = np.zeros(n_ep, bool)
    if not kinds:
        return out
    cat = {f: np.concatenate([parsed[k][f] for k in kinds]) for f in ("ep", "pos", "lat", "lon",
                                                                       "res")}
    m = np.isfinite(cat["lat"])
    order = np.argsort(cat["pos"][m], kind="stable")
    ep, lat, lon, res = (cat[f][m][order] for f in ("ep", "lat", "lon", "res"))
    ref_ok = np.isfinite(e["lat"][ep])
    tol = np.maximum(_DISAGREE_DEG, np.fmax(res, e["res"][ep]) * _SAME_FIX_DIGITS)
    with np.errstate(invalid="ignore"):
        d = ((np.abs(lat - e["lat"][ep]) > tol) | (np.abs(lon - e["lon"][ep]) > tol)) & ref_ok
    out[ep[d]] = True
    same = ref_ok & ~d & (res <= e["res"][ep] * 1.0001)
    _last_per_epoch(e["lat"], ep, lat, same)
    _last_per_epoch(e["lon"], ep, lon, same)
    return out


def _epoch_days(parsed: dict[int, dict[str, np.ndarray]], epoch_sod: np.ndarray,
                date: datetime.date | None) -> tuple[np.ndarray | None, str]:
    """Day (since 1970-01-01) of every epoch and where it came from; None if no date source.

    PTNL,GGK, RMC and ZDA dates (ZDA wins within an epoch, then RMC) are carried to the
    epochs around them with midnight rollovers counted in between: time of day decreasing
    by more than 12 h is the next day; an increase, however large, is a gap within the
    same day.
    Only without any such date is ``date`` (the first epoch's day) used.
    """
    n_ep = len(epoch_sod)
    day_of_epoch = np.full(n_ep, np.nan)
    for kind in (_PUBX4, _GGK, _RMC, _ZDA):
        if kind in parsed:
            g = parsed[kind]
            k_days = np.full(n_ep, np.nan)
            _last_per_epoch(k_days, g["ep"], g["days"])
            fill = np.isfinite(k_days)
            day_of_epoch[fill] = k_days[fill]
    roll = np.r_[0, np.cumsum(np.diff(epoch_sod) < -_HALF_DAY_US)].astype(np.int64)
    dated = np.isfinite(day_of_epoch)
    if dated.any():
        offset = np.where(dated, day_of_epoch - roll, 0).astype(np.int64)
        src = np.maximum.accumulate(np.where(dated, np.arange(n_ep), -1))
        src[src < 0] = int(np.flatnonzero(dated)[0])  # before the first date: back-fill
        return offset[src] + roll, "log (RMC/ZDA/GGK/PUBX,04)"
    if date is not None:
        return (date - datetime.date(1970, 1, 1)).days + roll, "argument"
    return None, "none"


def parse_nmea(data: bytes, *, name: str = "<nmea>", date: datetime.date | None = None,
               strict: bool = False, position_from: str = "rank") -> tuple[GnssFixes, SkipReport, dict]:
    """Parse NMEA text (whole file content as bytes).

    Returns fixes (one row per receiver epoch, in file order), the skipped-line
    report (reasons counted, first ``name:line`` of each) and a meta dict
    (``sentences``, ``talkers``, ``lines``, ``epochs``, ``dates``, ``date_source``,
    ``warnings``, ...).  ``date`` is used only when the log holds no RMC/ZDA/PTNL,GGK date.
    ``strict`` raises :class:`ParseError` at the first bad line instead of skipping it.
    ``position_from``: which position an epoch whose sentences disagree takes:
    ``"rank"``, the default (GGA, then GNS, PTNL,GGK, PUBX,00, RMC, GLL: the sentence that
    also carries the
    quality, satellites, HDOP and height), or ``"last"`` (the last in file order, as
    gpsd does; docs/decisions/0005-nmea-epoch-position-and-text-readers.md has a log
    where the two differ by 1.7e-6 deg).  Either way the disagreeing epochs are counted
    in ``meta['position_disagreements']`` and a note (``gpsdr info`` prints it).
    UTF-16 and Latin-1 input is decoded (``meta['encoding']`` and a note).
    Raises :class:`InputError` for empty or binary input,
    :class:`NoDataError` when no epoch with a time (and a date) can be built and
    :class:`MissingDateError` for fixes without a date (its message names the RMC, ZDA or
    PTNL,GGK sentences skipped, else the skip summary).
    """
    data = bytes(data)  # bytearray / memoryview welcome
    if isinstance(date, datetime.datetime):
        date = date.date()
    if len(data) == 0:
        raise InputError(name, "empty file (expected NMEA 0183 text lines like $GPGGA,...*hh)")
    data, encoding = _decode(data)
    # NUL padding: drop it (line numbers count line ends only, so they do not move)
    buf = data.replace(b"\x00", b"") if b"\x00" in data else data
    if not buf.strip():
        raise InputError(name, "file holds only NUL bytes or whitespace (expected NMEA 0183 text)")
    arr = np.frombuffer(buf, np.uint8)
    n = len(arr)
    probs = _Problems()
    acc: dict[int, list[dict[str, np.ndarray]]] = {}
    stats: dict = {"doubled_starts": 0, "sentences": Counter(), "talkers": Counter(),
                   "alt_without_geoid_sep": 0, "no_checksum": 0, "damaged_dated": Counter()}
    # whole lines per chunk bound the temporaries' memory (about 10 bytes per input byte)
    all_breaks = []
    n_valid = 0
    cs = 0
    while cs < n:
        nl = buf.find(b"\n", min(cs + _CHUNK_BYTES, n) - 1)
        ce = n if nl < 0 else nl + 1
        chunk = arr[cs:ce]
        breaks = _line_breaks(chunk)
        all_breaks.append(breaks + cs)
        n_valid += _scan_chunk(chunk, cs, breaks, probs, acc, stats)
        cs = ce
    lines = _Lines(np.concatenate(all_breaks), arr)
    if n_valid == 0 and _is_binary(buf):
        raise InputError(name, "binary file with no NMEA sentence (expected text lines like "
                               "$GPGGA,...*hh; is this a UBX/RTCM/SBF log?)")
    meta: dict = {"lines": lines.count, "doubled_starts": stats["doubled_starts"],
                  "sentences": dict(stats["sentences"]), "talkers": dict(stats["talkers"]),
                  "alt_without_geoid_sep": stats["alt_without_geoid_sep"],
                  "sentences_without_checksum": stats["no_checksum"]}
    parsed = {k: {f: np.concatenate([d[f] for d in parts]) for f in parts[0]}
              for k, parts in sorted(acc.items())}

    # ---- 5.-7. epochs, merged fields, dates
    report = _report(probs, name, lines, strict, buf)
    epoch_sod = _assign_epochs(parsed)
    if epoch_sod is None:
        checksums = " with a valid checksum" if report.counts.get("bad checksum", 0) else ""
        what = (f"GGA/GNS/RMC/GLL/GSA/VTG/GST/ZDA/PTNL,GGK/PUBX,00 sentence{checksums}"
                if not parsed else "GGA, GNS, RMC or GLL sentence with a time of day (nor "
                "PTNL,GGK or PUBX,00)")
        hint = ""
        if not parsed and report.counts.get("bad checksum", 0) >= 0.9 * sum(report.counts.values()):
            # a writer that computes every checksum wrongly, or a file edited by hand
            hint = ("; every checksum is wrong: the program that wrote the log computes them "
                    "wrongly, or the file was edited; recompute each *hh as the XOR of the "
                    "bytes between $ and *")
        raise NoDataError(name, f"no {what} ({_summary(report)}){hint}")
    e = _merge_epochs(parsed, len(epoch_sod), position_from)
    row = e.pop("row")
    disagree = e.pop("disagree")
    day, meta["date_source"] = _epoch_days(parsed, epoch_sod, date)
    if day is None:
        why = _why_undated(report, stats["damaged_dated"])
        if (e["q"][row] > 0).any():
            raise MissingDateError(name, "no date in the log (no RMC, ZDA, PTNL,GGK or PUBX,04 "
                                         f"sentence with a date; {why}); "
                                         "pass --date YYYY-MM-DD (the UTC date of the first fix)")
        raise NoDataError(name, "no fix and no date in the log (only no-fix epochs without "
                                f"RMC/ZDA/PTNL,GGK dates; {why})")
    if not row.any():
        raise NoDataError(name, "no GGA, GNS, RMC or GLL sentence with a time of day (nor "
                                f"PTNL,GGK or PUBX,00) ({_summary(report)})")
    r = {f: v[row] for f, v in e.items()}
    t_us = day[row].astype(np.int64) * _US_PER_DAY + epoch_sod[row]
    fixes = GnssFixes(
        t_ns=t_us * 1000, lat_deg=r["lat"], lon_deg=r["lon"], alt_m=r["alt"],
        fix_quality=r["q"].astype(np.int8),
        n_sats=np.where(np.isfinite(r["nsat"]), r["nsat"], -1).astype(np.int16),
        hdop=r["hdop"], pdop=r["pdop"], vdop=r["vdop"], sigma_e_m=r["sig_e"],
        sigma_n_m=r["sig_n"], speed_mps=r["speed"], course_deg=r["course"])
    meta["epochs"] = len(fixes)
    meta["epochs_without_gga_rmc"] = int((~row).sum())
    meta["position_disagreements"] = int(disagree[row].sum())
    udays = np.unique(day[row])
    dates = [datetime.date(1970, 1, 1) + datetime.timedelta(days=int(d)) for d in udays]
    meta["dates"] = [d.isoformat() for d in dates]
    today = datetime.datetime.now(datetime.UTC).date()
    # only dates the log gave: a receiver's rollover bug, not a caller's --date
    suspicious = [d.isoformat() for d in dates
                  if d.year < 2000 or d > today + datetime.timedelta(days=1)
                  ] if meta["date_source"].startswith("log") else []
    meta["warnings"] = []
    meta["warning_counts"] = {}
    if suspicious:
        meta["warning_counts"]["suspicious date"] = len(suspicious)
        meta["suspicious_dates"] = suspicious
        meta["warnings"].append(
            f"{name}: suspicious date {', '.join(suspicious[:3])} kept as given (expected "
            f"2000-01-01 .. today; a GPS week-rollover bug in the receiver?)")
    if meta["alt_without_geoid_sep"]:
        meta["warning_counts"]["altitude without geoid separation"] = meta["alt_without_geoid_sep"]
        meta["warnings"].append(
            f"{name}: {meta['alt_without_geoid_sep']} GGA fixes have no geoid separation: "
            "their alt_m is above mean sea level, not the ellipsoid")
    notes = []
    if encoding is not None:
        meta["encoding"] = encoding
        notes.append(f"text encoding {encoding}: decoded (NMEA is ASCII; save as UTF-8 to skip this)")
    if meta["sentences_without_checksum"]:
        notes.append(f"{meta['sentences_without_checksum']} complete sentences without a "
                     "checksum read as they are (not verified)")
    if meta["position_disagreements"]:
        notes.append(
            f"{meta['position_disagreements']} epochs whose sentences disagree on the position "
            f"(> {_DISAGREE_DEG:g} deg): took "
            + ("GGA, then GNS, PTNL,GGK, PUBX,00, RMC, GLL" if position_from == "rank"
               else "the last sentence of each epoch"))
    if notes:
        meta["notes"] = notes
    return fixes, report, meta


def _decode(data: bytes) -> tuple[bytes, str | None]:
    """Bytes as ASCII-compatible text, and the encoding decoded (None: ASCII/UTF-8).

    UTF-16 (BOM, or NULs in every other byte) is decoded to ASCII with ``?`` for what is
    not ASCII, so line numbers stay; Latin-1 needs no decoding (every byte is one
    character and NMEA uses only ASCII), it is only named.  Binary noise (control bytes,
    0x80-0x9F) is neither: the parser skips and counts it.
    """
    kind = _utf16_kind(data[:4096])
    if kind is not None:
        bom = data[:2] in (b"\xff\xfe", b"\xfe\xff")
        text = data[2:] if bom else data
        text = text.decode("utf-16-le" if kind == "le" else "utf-16-be", errors="replace")
        how = "byte-order mark" if bom else "no byte-order mark, told by its NUL bytes"
        return text.encode("ascii", errors="replace"), f"UTF-16-{kind.upper()} ({how})"
    arr = np.frombuffer(data, np.uint8)
    if len(arr) == 0 or int(arr.max()) < 128:
        return data, None
    try:
        data.decode("utf-8")
        return data, None
    except UnicodeDecodeError:
        pass
    high = arr[arr >= 128]
    c1 = int(np.count_nonzero(high < 0xA0))
    ctrl = int(np.count_nonzero((arr < 32) & (arr != 9) & (arr != 10) & (arr != 13)))
    # Latin-1 text uses the letters 0xA0-0xFF; binary bytes spread over C0/C1 controls too
    if c1 + ctrl <= 0.05 * len(high):
        return data, "Latin-1 (ISO 8859-1)"
    return data, None


#: What strict mode says was expected, by the start of a skip reason.
_EXPECTED = (
    ("no checksum", "expected $ADDRESS,fields...*hh before the line end"),
    ("bad checksum", "expected the XOR of the bytes between $ and * as *hh"),
    ("not a sentence", "expected an NMEA sentence starting with $"),
    ("malformed time", "expected hhmmss[.sss]"),
    ("malformed date in RMC", "expected ddmmyy"),
    ("malformed date in ZDA", "expected dd,mm,yyyy"),
    ("malformed date in PTNL,GGK", "expected mmddyy"),
    ("malformed fix quality in PTNL,GGK", "expected 0 to 15"),
    ("malformed height in PTNL,GGK", "expected EHT and a number of metres"),
    ("malformed navigation status", "expected one of NF DR G2 G3 D2 D3 RK TT"),
    ("malformed position", "expected ddmm.mmmm,N|S,dddmm.mmmm,E|W"),
    ("malformed mode", "expected one of A D P R F E N M S"),
    ("GSA with too few fields", "expected mode,fix type,satellites...,PDOP,HDOP,VDOP"),
    ("malformed", "expected a number"),
)


def _report(probs: _Problems, name: str, lines: _Lines, strict: bool,
            buf: bytes = b"") -> SkipReport:
    """Turn the problems into a SkipReport, or raise the first fatal one when strict."""
    if strict:
        fatal = [(v[1], r, v[3], v[4]) for r, v in probs.items.items() if v[2]]
        if fatal:
            pos, reason, exc, note = min(fatal, key=lambda t: t[0])
            text = re.split(rb"[\r\n]", buf[pos:pos + 82], maxsplit=1)[0]
            text = text.decode("ascii", "backslashreplace")
            expected = next(e for p, e in _EXPECTED + (("", "expected NMEA 0183"),)
                            if reason.startswith(p))
            note = f", {note}" if note else ""
            raise exc(name, f"{reason}: {text!r}{note}; {expected} (strict mode)",
                      line=int(lines(pos)))
    report = SkipReport()
    for reason, (count, first, *_rest) in sorted(probs.items.items(), key=lambda kv: kv[1][1]):
        report.add(reason, f"{name}:{int(lines(first))}", count)
    return report


def _summary(report: SkipReport) -> str:
    if not report.counts:
        return "nothing skipped"
    parts = [f"{n} {r}" for r, n in report.counts.most_common(4)]
    return "skipped: " + "; ".join(parts)


def _why_undated(report: SkipReport, damaged: Counter) -> str:
    """What was skipped of the dated sentences (RMC, ZDA, PTNL,GGK), for a log left without a
    date: "3 RMC skipped: bad checksum", "21 ZDA with empty date fields"; else the skip
    summary."""
    parts = [f"{n} {t} {r}" for (t, r), n in damaged.most_common(3)]
    for reason, n in report.counts.most_common():
        for t in (_TYPE_NAME[k] for k in _DATED):
            # reasons that drop the sentence (or its date) name the type like this
            if (reason.endswith(f" in {t}") or reason.startswith(f"{t} without time")
                    or reason == f"malformed date in {t} (field ignored)"):
                parts.append(f"{n} {reason}")
    return "; ".join(parts[:3]) if parts else _summary(report)


def read_nmea(path: str | Path, *, date: datetime.date | None = None,
              position_from: str = "rank") -> Drive:
    """Read an NMEA file (``'-'`` = standard input bytes) into a :class:`Drive`.

    The drive has ``gnss``, ``skipped``, ``sources=[Source(path, sha256, ('gnss',))]``
    and ``meta`` (see :func:`parse_nmea`).
    """
    name = str(path)
    try:
        if name == "-":
            data = sys.stdin.buffer.read()
        else:
            data = Path(path).read_bytes()
    except OSError as err:
        raise InputError(name, f"cannot read: {err.strerror or err}") from err
    fixes, report, meta = parse_nmea(data, name=name, date=date, position_from=position_from)
    sha = hashlib.sha256(data).hexdigest()
    return Drive(gnss=fixes, skipped=report, sources=[Source(name, sha, ("gnss",))],
                 meta=meta)

