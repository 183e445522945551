"""MCAP reader: GNSS fixes, gyro yaw rates and odometer speeds from ROS 2 / Foxglove logs.

Channels are found by schema name (overridable by topic):

=========  ====================================================================
gnss       ``sensor_msgs/msg/NavSatFix``, ``foxglove.LocationFix`` (JSON or
           protobuf), ``nmea_msgs/msg/Sentence`` (fed to :func:`parse_nmea`),
           ``ublox_msgs/msg/NavPVT`` (the UBX reader's NAV-PVT rules; times from
           its UTC fields)
gyro       ``sensor_msgs/msg/Imu``: ``angular_velocity.z``, rad/s, CCW-positive
           (REP-103 z up), the charter's sign
accel      the same Imu's ``linear_acceleration.x`` (m/s^2, x forward), unless its
           covariance[0] is -1 or every value is exactly 0 (the field left unset)
odo        ``nav_msgs/msg/Odometry`` (``twist.twist.linear.x``),
           ``geometry_msgs/msg/TwistStamped`` and ``TwistWithCovarianceStamped``
           (``twist.linear.x``), forward speed in m/s
=========  ====================================================================

Fix quality: NavSatStatus FIX is autonomous (1), SBAS and GBAS are DGPS (2), and a GBAS
fix whose known covariance is at most ``RTK_FIXED_SD_M`` per axis is RTK fixed (4): the
status has no code for RTK (the u-blox and NMEA drivers send it as GBAS), and only a
carrier-phase fixed solution is stated to centimetres.  Not an SBAS one: the ROS 2 NMEA
driver sends DGPS as SBAS with a sigma of HDOP x 0.1 m, 5 cm at an HDOP of 0.5.  Read as DGPS, an
RTK drive got metres of GNSS error states and its track wandered 1-3 m from centimetre
fixes.  An unaugmented fix (FIX, or foxglove.LocationFix, which has no status) stays
autonomous whatever its covariance: RTK needs corrections, and a publisher that fills in a
centimetre covariance for metres of error would otherwise pin the track to its noise
(docs/decisions/0025-rtk-from-a-navsatfix-covariance.md).

Encodings: ROS 2 CDR (a vectorised fixed-layout fast path,
:mod:`gpsdr_cli.io.ros2_fast`, with ``mcap_ros2``'s generic decoder as the fallback
for any message the fast path declines), ROS 1 (the same fast path; no generic
fallback is installed, so a message it declines is counted as undecodable) and
JSON; ``foxglove.LocationFix`` also in protobuf (a small hand-written wire
decoder, since ``protobuf`` is not a dependency: field numbers are read from the
channel's FileDescriptorSet, else the published foxglove schema's).
Times are the message header stamps, int64 ns UTC; ``use_log_time`` takes the
MCAP log times instead (and a zero stamp always falls back to the log time).
When several channels of one kind exist, the one with the most usable messages
is used and the others are listed in ``meta["mcap"]``.

The container walk is :mod:`gpsdr_cli.io.mcap_walk` (damage keeps what was read
before it); protobuf's wire format is :mod:`gpsdr_cli.io.protobuf`.

A twist's ``linear`` is read in one of two frames (:func:`twist_reading`): the body
frame, ``x`` = forward speed (wheel odometry; negative only while reversing), or a
navigation frame, ENU (``x`` = east, ``y`` = north, m/s), as GNSS drivers publish it
(nmea_navsat_driver ``/vel``, u-blox ``/fix_velocity``).  The frame_id says little
(those drivers stamp the receiver's own frame, e.g. "gps") and is not decoded, and the
type not much more (nav_msgs/Odometry's twist is meant to be in its child frame, the
body, but nothing enforces it), so the values decide:

1. beside GNSS fixes, the fixes' own motion: over spans of about :data:`_PAIR_S`
   the fixes' displacement per second (ENU, in the drive's local frame) equals the
   twist's mean (x, y) when it is ENU, and only its length equals the mean x when
   it is a forward speed; a frame wins by a clear majority of the spans that fit
   one reading and miss the other (heading west, north or south; heading east the
   two agree), provided it fits a fair share of all moving spans;
2. else a large lateral share (median ``|y| / |(x, y)|`` above :data:`_LATERAL_SHARE`
   while moving) means ENU;
3. else ``x`` negative for long (below :data:`_BACKWARD_MPS` in more than
   :data:`_BACKWARD_SHARE` of the moving messages, or a negative median, for over
   :data:`_REVERSING_MAX_S` in all) is no forward speed: it is read as
   ``|linear.xy|`` with a warning (the speed of an ENU velocity, or of a sensor
   mounted backwards); a shorter backward stretch stays signed, as reversing;
4. else a stream that moves is a forward speed; one that barely moves (a parked
   log) has no telling frame and is read as ``|linear.xy|``, right in either frame
   but for the sign of reversing, with a warning.

Beside GNSS fixes that carry no speed (NavSatFix never does), an ENU channel is the
receiver's Doppler velocity: it becomes the fixes' speed and course (nearest message
within 0.1 s), which the filters' receiver-velocity update uses, and it is not taken
as the odometer (a warning says so when no other odometer channel exists).
Otherwise, or when a topic override names it, it is read as an odometer speed =
|linear.xy|, with a warning.  ``meta["twist_frame"]`` holds each twist channel's
frame and the evidence.  An Imu whose ``angular_velocity_covariance[0]``
is -1 declares that it has no angular velocity (sensor_msgs convention); such
messages are skipped and counted, not read as zero yaw rate (unless their z
rates vary, which makes the flag sloppy metadata: then they are kept, with a
warning).
"""


from __future__ import annotations

import dataclasses
import datetime as dt
import functools
import hashlib
import json
import math
import mmap
import os
import struct
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from ..conventions import FIX_DGPS, FIX_GPS, FIX_NONE, FIX_RTK, NS_PER_S
from ..errors import InputError, NoDataError, UsageError
from . import protobuf, ros2_fast
from .drive import Drive, ForwardAccel, GnssFixes, Odometry, SkipReport, Source, YawRates
from .formats import MCAP_MAGIC as MAGIC
from .mcap_walk import Walker

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")

#: Which stream each layout feeds.
KIND_OF_LAYOUT = {"navsatfix": "gnss", "locationfix": "gnss", "sentence": "gnss",
                  "navpvt": "gnss", "imu": "gyro", "twist": "odo", "twistcov": "odo",
                  "odometry": "odo"}
_LAYOUTS = dict(ros2_fast.LAYOUTS)
_LAYOUTS["foxglove.LocationFix"] = "locationfix"
_LAYOUTS["foxglove_msgs/msg/LocationFix"] = "locationfix"
# ublox_msgs/NavPVT (the ROS u-blox driver): the UBX NAV-PVT fields in UBX order, each
# naturally aligned, so its CDR body (and ROS 1 body) is the UBX payload byte for byte.
_LAYOUTS["ublox_msgs/msg/NavPVT"] = "navpvt"
_LAYOUTS["ublox_msgs/NavPVT"] = "navpvt"

#: Twist frame (:func:`twist_reading`): a message or span moves faster than this, m/s.
_MOVING_MPS = 0.5
#: ENU when the median |linear.y| / |linear.xy| while moving is above this share.
_LATERAL_SHARE = 0.3
#: A forward speed is negative only while reversing, which is slow and short: linear.x
#: below this (m/s) in more than _BACKWARD_SHARE of the moving messages (or a negative
#: median), for more than _REVERSING_MAX_S of backward motion in all, is none.
_BACKWARD_MPS = -1.0
_BACKWARD_SHARE = 0.2
_REVERSING_MAX_S = 30.0
#: The fixes' motion test: fixes paired about this far apart (s), long enough that
#: metre-level fix noise stays a fraction of a m/s, short enough that a turn's chord
#: is still close to its arc (3 s at 0.3 rad/s: 3 % short).
_PAIR_S = 3.0
#: a reading fits a span within max(_FIT_MPS, _FIT_SHARE x its speed), m/s ...
_FIT_MPS = 0.3
_FIT_SHARE = 0.1
#: ... or this many times the fixes' stated noise on the span's displacement per second
_FIT_SD = 1.5
#: ... votes for a frame when it fits and the other misses by twice that, and wins
#: with at least _MIN_VOTES votes and _VOTE_MAJORITY times the other's.
_MIN_VOTES = 5
_VOTE_MAJORITY = 4
#: ... provided it fits at least this share of all the moving spans (urban fixes with
#: metres of multipath fit under half of them)
_FIT_MIN_SHARE = 1 / 3
#: an ENU velocity message belongs to the fix stamped within this (u-blox: the same stamp)
_VELOCITY_MATCH_NS = 100_000_000


@dataclass
class Channel:
    id: int
    topic: str
    encoding: str
    schema_name: str
    schema_encoding: str
    schema_data: bytes
    layout: str | None
    n_msgs: int = 0
    #: Decoded columns by field: arrays from the fast path, scalars from the generic route.
    cols: dict[str, list] = field(default_factory=dict)
    scalars: dict[str, list] = field(default_factory=dict)
    texts: list[bytes] = field(default_factory=list)
    n_undecodable: int = 0
    first_undecodable: str = ""
    generic: Any = None  # cached generic decoder, False when unavailable
    pb_numbers: dict[str, int] | None = None  # protobuf field numbers by name
    #: ublox_msgs/NavPVT: fixes decoded per batch by the UBX reader, and what it skipped
    fixes: list[GnssFixes] = field(default_factory=list)
    fix_skips: SkipReport = field(default_factory=SkipReport)

    def add(self, name: str, values: Any) -> None:
        self.cols.setdefault(name, []).append(values)


def new_channel(cid: int, topic: str, encoding: str, schema_name: str, schema_encoding: str,
                 schema_data: bytes) -> Channel:
    return Channel(cid, topic, encoding, schema_name, schema_encoding, schema_data,
                    _LAYOUTS.get(schema_name))


# --------------------------------------------------------------------------- decoding

class Decoder:
    """Decodes the messages of the channels gpsdr reads into their :class:`Channel`."""

    def __init__(self, path: str, wanted: dict[str, str | None]) -> None:
        self.path = path
        self.wanted = wanted

    def on_messages(self, chan: Channel, buf: bytes, npbuf: np.ndarray, lt: np.ndarray,
                    off: np.ndarray, sz: np.ndarray) -> None:
        """One batch of one channel's messages: log times and data byte ranges in buf."""
        chan.n_msgs += len(off)
        if self.is_wanted(chan):
            self._decode(chan, buf, npbuf, lt, off, sz)

    def is_wanted(self, chan: Channel) -> bool:
        if chan.layout is None:
            return False
        topic = self.wanted.get(KIND_OF_LAYOUT[chan.layout])
        return topic is None or topic == chan.topic

    def _decode(self, chan: Channel, buf: bytes, npbuf: np.ndarray, lt: np.ndarray,
                off: np.ndarray, sz: np.ndarray) -> None:
        layout = chan.layout
        assert layout is not None
        enc = chan.encoding.lower()
        rest = np.arange(len(off))
        if layout == "navpvt":
            self._decode_navpvt(chan, npbuf, lt, off, sz, enc)
            return
        if enc in ("cdr", "ros1") and layout != "locationfix":
            fields, ok = ros2_fast.decode(layout, npbuf, off, sz, ros1=enc == "ros1")
            if ok.any():
                chan.add("log_ns", lt[ok])
                if layout == "sentence":
                    chan.add("stamp_ns", fields["stamp_ns"][ok])
                    offs = fields["text_off"][ok].tolist()
                    for o, n in zip(offs, fields["text_len"][ok].tolist(), strict=False):
                        chan.texts.append(bytes(buf[o:o + n]))
                else:
                    for name, values in fields.items():
                        chan.add(name, values[ok])
            rest = np.flatnonzero(~ok)
        batch: list[Any] | None = None
        if enc == "json" and len(rest):
            # One json.loads for the batch (the C parser's per-call overhead dominates);
            # any bad message sends the batch back to one-by-one decoding.
            joined = b",".join(buf[int(off[i]):int(off[i]) + int(sz[i])] for i in rest.tolist())
            try:
                batch = json.loads(b"[" + joined + b"]")
            except (ValueError, RecursionError):
                batch = None
            if batch is not None and len(batch) != len(rest):
                batch = None
        for j, i in enumerate(rest.tolist()):
            if batch is not None:
                rec = self._extract_one(chan, batch[j])
            else:
                o, n = int(off[i]), int(sz[i])
                rec = self._decode_one(chan, bytes(buf[o:o + n]))
            if rec is None:
                chan.n_undecodable += 1
                if not chan.first_undecodable:
                    chan.first_undecodable = f"{self.path}: {chan.topic} message {chan.n_msgs}"
                continue
            rec["log_ns"] = int(lt[i])
            if layout == "sentence":
                chan.texts.append(rec.pop("text"))
            for name, value in rec.items():
                chan.scalars.setdefault(name, []).append(value)

    def _decode_navpvt(self, chan: Channel, npbuf: np.ndarray, lt: np.ndarray, off: np.ndarray,
                       sz: np.ndarray, enc: str) -> None:
        """ublox_msgs/NavPVT through the UBX reader's NAV-PVT table: the body (after CDR's
        4-byte encapsulation header) is the UBX payload; times are its UTC fields."""
        from . import ubx

        base = 4 if enc == "cdr" else 0
        ok = sz >= base + ubx.PVT_MIN
        if enc == "cdr":
            head = npbuf[np.where(ok, off, 0)[:, None] + np.arange(2)]
            ok &= (head[:, 0] == 0) & (head[:, 1] == 1)
        elif enc != "ros1":
            ok[:] = False
        bad = int((~ok).sum())
        if bad:
            chan.n_undecodable += bad
            chan.first_undecodable = chan.first_undecodable or (
                f"{self.path}: {chan.topic}: NavPVT message too short or not little-endian CDR")
        if not ok.any():
            return
        n = int(ok.sum())
        frames = {"cls": np.full(n, ubx.CLASS_NAV, np.uint8), "id": np.full(n, ubx.ID_PVT, np.uint8),
                  "length": sz[ok] - base, "start": off[ok] + base - 6}
        fixes = ubx.nav_fixes(npbuf, frames, f"{self.path}: {chan.topic}", chan.fix_skips)[0]
        chan.fixes.append(fixes)
        chan.add("log_ns", lt[ok])

    def _extract_one(self, chan: Channel, msg: Any) -> dict[str, Any] | None:
        try:
            return _extract(chan.layout, msg)
        except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as err:
            chan.first_undecodable = chan.first_undecodable or (
                f"{self.path}: {chan.topic} message {chan.n_msgs}: {type(err).__name__}: {err}")
        return None

    def _decode_one(self, chan: Channel, raw: bytes) -> dict[str, Any] | None:
        """One message by the generic route (CDR generic decoder, JSON, protobuf), or None."""
        enc = chan.encoding.lower()
        try:
            if enc == "cdr":
                if chan.generic is None:
                    chan.generic = _generic_decoder(chan)
                if chan.generic is False:
                    return None
                return _extract(chan.layout, chan.generic(raw))
            if enc == "json":
                return _extract(chan.layout, json.loads(raw))
            if enc == "protobuf" and chan.layout == "locationfix":
                if chan.pb_numbers is None:
                    chan.pb_numbers = protobuf.field_numbers(
                        chan.schema_data, "LocationFix", ("latitude", "longitude")
                    ) or dict(_LOCFIX_NUMBERS)
                return _extract("locationfix", _pb_location_fix(raw, chan.pb_numbers))
        except (struct.error, IndexError, KeyError, TypeError, ValueError, AttributeError,
                OverflowError, UnicodeDecodeError, RecursionError) as err:
            chan.first_undecodable = chan.first_undecodable or (
                f"{self.path}: {chan.topic} message {chan.n_msgs}: {type(err).__name__}: {err}")
        return None


def _generic_decoder(chan: Channel) -> Any:
    """mcap_ros2's dynamic decoder for the channel's schema, or False if there is none."""
    if chan.schema_encoding != "ros2msg":
        return False
    from mcap_ros2._dynamic import generate_dynamic

    try:
        decoders = generate_dynamic(chan.schema_name, chan.schema_data.decode("utf-8"))
    except (ValueError, KeyError, IndexError, TypeError, UnicodeDecodeError, AttributeError) as err:
        chan.first_undecodable = f"schema {chan.schema_name!r} does not parse: {err}"
        return False
    return decoders.get(chan.schema_name, False)


# --------------------------------------------------------------------------- generic extraction

@functools.lru_cache(maxsize=256)
def _parts(dotted: str) -> tuple[str, ...]:
    return tuple(dotted.split("."))


def _get(obj: Any, *names: str, default: Any = None) -> Any:
    """``obj.a.b`` for decoded objects or ``obj["a"]["b"]`` for JSON; first name path found."""
    for dotted in names:
        cur = obj
        for part in _parts(dotted):
            cur = cur.get(part) if isinstance(cur, dict) else getattr(cur, part, None)
            if cur is None:
                break
        if cur is not None:
            return cur
    return default


def _int(x: Any, lo: int, hi: int, what: str) -> int:
    """An integer field within [lo, hi]; TypeError/ValueError otherwise (undecodable message)."""
    if isinstance(x, bool) or not isinstance(x, (int, float, np.integer, np.floating)):
        raise TypeError(f"{what} = {x!r} is not a number")
    if not (math.isfinite(x) and lo <= x <= hi):
        raise ValueError(f"{what} = {x!r} outside [{lo}, {hi}]")
    return int(x)


_I64 = 2**63 - 1


def _stamp_ns(stamp: Any) -> int:
    if stamp is None:
        return 0
    if isinstance(stamp, (int, float)) and not isinstance(stamp, bool):  # JSON: seconds
        return _int(round(float(stamp) * NS_PER_S) if math.isfinite(stamp) else stamp,
                    -_I64, _I64, "stamp")
    sec = _int(_get(stamp, "sec", "secs", "seconds", default=0), -2**40, 2**40, "stamp seconds")
    nsec = _int(_get(stamp, "nanosec", "nsec", "nsecs", "nanos", default=0), -2**40, 2**40,
                "stamp nanoseconds")
    return _int(sec * NS_PER_S + nsec, -_I64, _I64, "stamp")


def _f(x: Any) -> float:
    return math.nan if x is None else float(x)


def _extract(layout: str | None, msg: Any) -> dict[str, Any]:
    """The fast path's fields from a generically decoded message (object or JSON dict)."""
    if layout == "locationfix":
        stamp = _stamp_ns(_get(msg, "timestamp"))
    else:
        stamp = _stamp_ns(_get(msg, "header.stamp"))
    out: dict[str, Any] = {"stamp_ns": stamp}
    if layout in ("navsatfix", "locationfix"):
        cov = _get(msg, "position_covariance", default=[]) or []
        cov = list(cov)
        out["status"] = (_int(_get(msg, "status.status", default=0), -128, 127, "status")
                         if layout == "navsatfix" else 0)
        out["lat"] = _f(_get(msg, "latitude"))
        out["lon"] = _f(_get(msg, "longitude"))
        out["alt"] = _f(_get(msg, "altitude"))
        out["cov_e"] = _f(cov[0]) if len(cov) >= 9 else math.nan
        out["cov_n"] = _f(cov[4]) if len(cov) >= 9 else math.nan
        out["cov_type"] = _int(_get(msg, "position_covariance_type", default=0), 0, 255,
                               "position_covariance_type")
    elif layout == "imu":
        out["wz"] = _f(_get(msg, "angular_velocity.z"))
        cov = list(_get(msg, "angular_velocity_covariance", default=[]) or [])
        out["wz_cov0"] = _f(cov[0]) if cov else 0.0
        out["ax"] = _f(_get(msg, "linear_acceleration.x", default=0.0))
        acov = list(_get(msg, "linear_acceleration_covariance", default=[]) or [])
        out["ax_cov0"] = _f(acov[0]) if acov else 0.0
    elif layout in ("twist", "twistcov", "odometry"):
        path = "twist.linear" if layout == "twist" else "twist.twist.linear"
        out["vx"] = _f(_get(msg, f"{path}.x"))
        out["vy"] = _f(_get(msg, f"{path}.y", default=0.0))
    elif layout == "sentence":
        text = _get(msg, "sentence", default="")
        out["text"] = text.encode("utf-8", "replace") if isinstance(text, str) else bytes(text)
    else:
        raise ValueError(f"no extraction for layout {layout!r}")
    return out


#: schema carries no readable FileDescriptorSet.
_LOCFIX_NUMBERS = {"latitude": 1, "longitude": 2, "altitude": 3, "position_covariance": 4,
                   "position_covariance_type": 5, "timestamp": 6}


def _pb_location_fix(buf: bytes, numbers: dict[str, int] | None = None) -> dict[str, Any]:
    """foxglove.LocationFix in protobuf wire format; ``numbers`` maps field names to
    numbers (from the channel's descriptor, default the published schema).
    Timestamp is google.protobuf.Timestamp (seconds = 1, nanos = 2)."""
    by_num = {v: k for k, v in (numbers or _LOCFIX_NUMBERS).items()}
    out: dict[str, Any] = {"latitude": None, "longitude": None, "altitude": 0.0,
                           "position_covariance": [], "position_covariance_type": 0,
                           "timestamp": {"sec": 0, "nsec": 0}}
    for num, wt, value in protobuf.fields(buf):
        name = by_num.get(num)
        if name in ("latitude", "longitude", "altitude") and wt == 1:
            out[name] = struct.unpack("<d", value)[0]
        elif name == "position_covariance" and wt == 1:
            out[name].append(struct.unpack("<d", value)[0])
        elif name == "position_covariance" and wt == 2:
            n = len(value) // 8
            out[name] = list(struct.unpack(f"<{n}d", value[:8 * n]))
        elif name == "position_covariance_type" and wt == 0:
            out[name] = value
        elif name == "timestamp" and wt == 2:
            ts = {"sec": 0, "nsec": 0}
            for k, w, v in protobuf.fields(value):
                if w == 0 and k in (1, 2):
                    v = v - (1 << 64) if v >= 1 << 63 else v  # int64/int32 two's complement
                    ts["sec" if k == 1 else "nsec"] = v
            out["timestamp"] = ts
    return out


# --------------------------------------------------------------------------- streams

def _cat(chan: Channel, name: str, dtype: Any) -> np.ndarray:
    """A field's values: fast-path arrays, then generic-route scalars (the same order for
    every field of a channel, so rows stay aligned)."""
    parts = list(chan.cols.get(name, []))
    if chan.scalars.get(name):
        parts.append(np.array(chan.scalars[name], dtype=dtype))
    if not parts:
        return np.zeros(0, dtype)
    return np.concatenate(parts).astype(dtype, copy=False)


def _times(chan: Channel, use_log_time: bool) -> tuple[np.ndarray, int]:
    """Header stamps (or log times); a zero stamp falls back to the log time."""
    log = _cat(chan, "log_ns", np.int64)
    if use_log_time:
        return log, 0
    stamp = _cat(chan, "stamp_ns", np.int64)
    zero = stamp == 0
    return np.where(zero, log, stamp), int(zero.sum())


#: a fix whose known covariance is at most this per axis (m) is taken as RTK fixed
#: (the ``[gnss] rtk_cm_sd_m`` default: the centimetres no other solution reaches)
RTK_FIXED_SD_M = 0.05
#: NavSatStatus.STATUS_GBAS_FIX (ground-based augmentation: the drivers' RTK)
GBAS_FIX = 2


def _gnss_from_fixes(chan: Channel, t_ns: np.ndarray, skipped: SkipReport, where: str) -> GnssFixes:
    lat = _cat(chan, "lat", np.float64)
    lon = _cat(chan, "lon", np.float64)
    status = _cat(chan, "status", np.int64)
    g = GnssFixes.empty(len(t_ns))
    g.t_ns = t_ns
    valid_ll = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
    bad_ll = ~valid_ll & np.isfinite(lat) & np.isfinite(lon)
    skipped.add("GNSS fix with latitude/longitude out of range (kept as no fix)", where, int(bad_ll.sum()))
    fix = valid_ll & (status >= 0)
    # NavSatStatus: 0 FIX -> GPS, 1 SBAS / 2 GBAS (augmented) -> DGPS; < 0 NO_FIX.
    g.fix_quality = np.where(fix, np.where(status > 0, FIX_DGPS, FIX_GPS), FIX_NONE).astype(np.int8)
    g.lat_deg = np.where(fix, lat, np.nan)
    g.lon_deg = np.where(fix, lon, np.nan)
    alt = _cat(chan, "alt", np.float64)
    g.alt_m = np.where(fix & np.isfinite(alt), alt, np.nan)
    cov_type = _cat(chan, "cov_type", np.int64)
    for name, out in (("cov_e", "sigma_e_m"), ("cov_n", "sigma_n_m")):
        var = _cat(chan, name, np.float64)
        good = fix & (cov_type > 0) & np.isfinite(var) & (var > 0)
        setattr(g, out, np.where(good, np.sqrt(np.where(good, var, 1.0)), np.nan))
    rtk = fix & (status == GBAS_FIX) & (np.maximum(g.sigma_e_m, g.sigma_n_m) <= RTK_FIXED_SD_M)
    g.fix_quality[rtk] = FIX_RTK
    return g


def _gnss_from_sentences(chan: Channel, t_ns: np.ndarray, date: dt.date | None, path: str,
                         skipped: SkipReport, meta: dict) -> GnssFixes:
    from .nmea import parse_nmea

    if date is None and len(t_ns):
        date = dt.datetime.fromtimestamp(int(t_ns[0]) // NS_PER_S, dt.UTC).date()
    lines = [t.strip().replace(b"\r", b"").replace(b"\n", b"") for t in chan.texts]
    fixes, nmea_skipped, nmea_meta = parse_nmea(b"\r\n".join(lines) + b"\r\n",
                                                name=f"{path}:{chan.topic}", date=date)
    skipped.merge(nmea_skipped)
    meta["nmea"] = nmea_meta
    return fixes


class _NoStream(Exception):
    pass


def _build(kind: str, chan: Channel, *, path: str, use_log_time: bool, date: dt.date | None,
           skipped: SkipReport, meta: dict, warnings: list[str],
           twist: TwistReading | None = None) -> Any:
    if chan.layout == "navpvt":  # no header: its times are its own UTC fields
        skipped.merge(chan.fix_skips)
        if chan.n_undecodable:
            skipped.add(f"undecodable {chan.schema_name} message", chan.first_undecodable,
                        chan.n_undecodable)
        return _concat_fixes(chan.fixes)
    t_ns, n_zero = _times(chan, use_log_time)
    where = f"{path}: {chan.topic}"
    if n_zero:
        meta.setdefault("zero_stamps", {})[chan.topic] = n_zero
    if chan.n_undecodable:
        skipped.add(f"undecodable {chan.schema_name} message", chan.first_undecodable or where,
                    chan.n_undecodable)
    if kind == "gnss":
        if chan.layout == "sentence":
            return _gnss_from_sentences(chan, t_ns, date, path, skipped, meta)

        return _gnss_from_fixes(chan, t_ns, skipped, where)
    if kind == "gyro":
        wz = _cat(chan, "wz", np.float64)
        absent = _imu_absent(chan)
        skipped.add("Imu without angular velocity (angular_velocity_covariance[0] = -1)", where,
                    int(absent.sum()))
        declared = _cat(chan, "wz_cov0", np.float64) == -1.0
        if (declared & ~absent).any():
            warnings.append(f"{where}: angular_velocity_covariance[0] = -1 (not provided) but "
                            "angular_velocity.z varies: read anyway")
        bad = ~absent & ~np.isfinite(wz)
        skipped.add("non-finite yaw rate", where, int(bad.sum()))
        keep = ~absent & ~bad
        if absent.all() and len(wz):
            warnings.append(f"{where}: every Imu message declares no angular velocity "
                            "(covariance[0] = -1): no gyro stream from it")
        return YawRates(t_ns=t_ns[keep], yaw_rate_radps=wz[keep])
    vx = _cat(chan, "vx", np.float64)
    vy = _cat(chan, "vy", np.float64)
    if twist is None:
        raise ValueError(f"{where}: a twist channel needs its reading (twist_reading)")
    reading = twist
    speed = np.hypot(vx, vy) if reading.hypot else vx
    if reading.frame == "enu":
        warnings.append(f"{where}: twist.linear read as a navigation-frame (ENU) velocity "
                        f"({reading.why}): speed = |linear.xy|")
    elif reading.warning:
        warnings.append(f"{where}: {reading.warning}")
    bad = ~np.isfinite(speed)
    skipped.add("non-finite speed", where, int(bad.sum()))
    return Odometry(t_ns=t_ns[~bad], speed_mps=speed[~bad])


@dataclass(frozen=True)
class TwistReading:
    """How a twist channel's ``linear`` is read (module docstring)."""

    #: "enu" (x east, y north), "body" (x forward) or "unknown"
    frame: str
    #: speed = |linear.xy| (True) or linear.x (False), m/s
    hypot: bool
    #: the evidence, for ``meta["twist_frame"]`` and warnings
    why: str
    #: a line for the drive's warnings when read as an odometer ("" for a plain reading)
    warning: str = ""

    def describe(self) -> dict[str, str]:
        return {"frame": self.frame, "speed": "hypot(x, y)" if self.hypot else "x",
                "evidence": self.why}


def twist_reading(chan: Channel, gnss: GnssFixes | None, use_log_time: bool) -> TwistReading:
    """The frame of a twist channel's linear velocity, from the GNSS fixes' motion when
    they tell, else from the twist alone (the rules in the module docstring)."""
    t_ns, _ = _times(chan, use_log_time)
    vx = _cat(chan, "vx", np.float64)
    vy = _cat(chan, "vy", np.float64)
    if not np.isfinite(vx).any():  # nothing to read (undecodable): no verdict to warn about
        return TwistReading("body", False, "no finite linear.x")
    pre = ""  # the fixes' verdict when they did not decide, kept as evidence
    if gnss is not None and len(gnss):
        frame, why = _frame_from_fixes(t_ns, vx, vy, gnss)
        if frame:
            return TwistReading(frame, frame == "enu", why)
        pre = f"fixes undecided: {why}; "
    norm = np.hypot(vx, vy)
    moving = np.isfinite(norm) & (norm > _MOVING_MPS)
    n_moving = int(moving.sum())
    if n_moving >= 10:
        share = float(np.median(np.abs(vy[moving]) / norm[moving]))
        if share > _LATERAL_SHARE:
            return TwistReading("enu", True, f"{pre}a large lateral (y) component while "
                                f"moving: median |y|/|xy| {share:.2f}")
    x_moving = vx[moving]
    dt_s = float(np.median(np.diff(np.sort(t_ns)))) / NS_PER_S if len(t_ns) > 1 else 0.0
    backward_s = int((x_moving < 0).sum()) * dt_s
    strong = float(np.mean(x_moving < _BACKWARD_MPS)) if n_moving else 0.0
    negative = n_moving > 0 and float(np.median(x_moving)) < 0
    if strong > _BACKWARD_SHARE or negative:
        why = (f"{pre}linear.x below {_BACKWARD_MPS:g} m/s in {strong:.0%} of the {n_moving} "
               f"moving messages, median {float(np.median(x_moving)):.2f} m/s, "
               f"{backward_s:.0f} s backwards")
        if backward_s > _REVERSING_MAX_S:
            # wheels turn backwards only to reverse, briefly: this is an ENU velocity
            # (or a sensor mounted backwards), whose speed either way is |linear.xy|
            return TwistReading("unknown", True, why, f"not a forward speed ({why}; reversing "
                                f"lasts under {_REVERSING_MAX_S:g} s): read as speed = "
                                "|linear.xy|, the speed of an ENU velocity or of a backward "
                                "mounted sensor")
        if negative:
            return TwistReading("body", False, why, f"moving backwards for most of the log "
                                f"({why}): kept as reversing, speed = linear.x < 0")
    if n_moving < 10:
        why = f"{pre}{n_moving} messages faster than {_MOVING_MPS:g} m/s"
        return TwistReading("unknown", True, why, f"too little motion to tell an ENU velocity "
                            f"from a forward speed ({why}): read as speed = |linear.xy|, right in "
                            "either frame but for the sign of reversing")
    return TwistReading("body", False, f"{pre}x forward while moving ({n_moving} messages)")


def _frame_from_fixes(t_v: np.ndarray, vx: np.ndarray, vy: np.ndarray,
                      gnss: GnssFixes) -> tuple[str, str]:
    """("enu", why), ("body", why) or ("", why) from spans of about :data:`_PAIR_S` between
    fixes: their displacement per second (east, north m/s) against the twist's mean over
    the same span, read as ENU (x, y) or as a forward speed x (the displacement's length)."""
    ok = np.isfinite(vx) & np.isfinite(vy)
    t_v, vx, vy = t_v[ok], vx[ok], vy[ok]
    valid = gnss.valid
    t_g, lat, lon = gnss.t_ns[valid], gnss.lat_deg[valid], gnss.lon_deg[valid]
    sd = np.fmax(gnss.sigma_e_m[valid], gnss.sigma_n_m[valid])
    if len(t_v) < 2 or len(t_g) < 2:
        return "", "too few fixes or twist messages to compare"
    order = np.argsort(t_g, kind="stable")
    t_g, lat, lon, sd = t_g[order], lat[order], lon[order], np.nan_to_num(sd[order])
    step = int(_PAIR_S * NS_PER_S)
    # the first fix of each step-long bin: spans that do not overlap, whatever the fix rate
    _, first = np.unique((t_g - t_g[0]) // step, return_index=True)
    a, b = first[:-1], first[1:]
    dt = (t_g[b] - t_g[a]) / NS_PER_S
    from ..geodesy import LocalFrame

    e, n = LocalFrame.for_fixes(lat, lon).forward(lat, lon)
    with np.errstate(divide="ignore", invalid="ignore"):
        ve = (e[b] - e[a]) / dt
        vn = (n[b] - n[a]) / dt
    order = np.argsort(t_v, kind="stable")
    t_v, vx, vy = t_v[order], vx[order], vy[order]
    # the twist's mean over a span is its integral (trapezoids) between the span's ends
    s = (t_v - t_v[0]) / NS_PER_S
    h = np.diff(s) / 2
    cx = np.concatenate([[0.0], np.cumsum(h * (vx[1:] + vx[:-1]))])
    cy = np.concatenate([[0.0], np.cumsum(h * (vy[1:] + vy[:-1]))])
    sa, sb = (t_g[a] - t_v[0]) / NS_PER_S, (t_g[b] - t_v[0]) / NS_PER_S
    # a span needs the twist on both ends and no hole in it longer than a span
    holes = np.concatenate([[0], np.cumsum(np.diff(t_v) > step)])
    ia = np.clip(np.searchsorted(t_v, t_g[a], "right") - 1, 0, len(t_v) - 1)
    ib = np.clip(np.searchsorted(t_v, t_g[b], "left"), 0, len(t_v) - 1)
    use = ((dt > 0) & (dt <= 2 * _PAIR_S) & (t_g[a] >= t_v[0]) & (t_g[b] <= t_v[-1])
           & (holes[ib] == holes[ia]) & np.isfinite(ve) & np.isfinite(vn))
    with np.errstate(divide="ignore", invalid="ignore"):
        mx = (np.interp(sb, s, cx) - np.interp(sa, s, cx)) / (sb - sa)
        my = (np.interp(sb, s, cy) - np.interp(sa, s, cy)) / (sb - sa)
    v_fix = np.hypot(ve, vn)
    v_tw = np.hypot(mx, my)
    moving = use & (np.maximum(v_fix, v_tw) > _MOVING_MPS)
    # the fixes' stated noise widens it: a displacement over dt is off by ~hypot(sd_a, sd_b)
    # / dt (less when, as usual, the fixes' errors are correlated in time)
    tol = np.maximum.reduce([np.full(len(a), _FIT_MPS), _FIT_SHARE * np.maximum(v_fix, v_tw),
                             _FIT_SD * np.hypot(sd[a], sd[b]) / np.where(dt > 0, dt, np.inf)])
    e_enu = np.hypot(mx - ve, my - vn)
    e_body = np.abs(mx - v_fix)
    fit_enu, fit_body = moving & (e_enu < tol), moving & (e_body < tol)
    n_enu = int((fit_enu & (e_body > 2 * tol)).sum())
    n_body = int((fit_body & (e_enu > 2 * tol)).sum())
    n_moving = int(moving.sum())
    why = (f"{n_moving} moving {_PAIR_S:g} s spans between fixes: {n_enu} fit the fixes' "
           f"displacement as ENU (x east, y north) and not as a forward speed, {n_body} the "
           "reverse")
    for frame, n_win, n_lose, fits in (("enu", n_enu, n_body, fit_enu),
                                       ("body", n_body, n_enu, fit_body)):
        # a frame wins only where the two differ, by a clear majority, and must also fit
        # a good share of all moving spans: a stream that fits neither decides nothing
        if (n_win >= _MIN_VOTES and n_win >= _VOTE_MAJORITY * n_lose
                and int(fits.sum()) >= _FIT_MIN_SHARE * n_moving):
            return frame, why
    return "", why


def _attach_velocity(gnss: GnssFixes, chan: Channel, use_log_time: bool) -> tuple[GnssFixes, int]:
    """The fixes with speed (m/s) and course (deg clockwise from north) from an ENU twist
    channel (x east, y north), matched to the nearest message within
    :data:`_VELOCITY_MATCH_NS`; fixes that already carry a speed keep it.  Returns the
    new fixes and how many were given a velocity."""
    t_v, _ = _times(chan, use_log_time)
    ve = _cat(chan, "vx", np.float64)
    vn = _cat(chan, "vy", np.float64)
    ok = np.isfinite(ve) & np.isfinite(vn)
    t_v, ve, vn = t_v[ok], ve[ok], vn[ok]
    if not len(t_v) or not len(gnss):
        return gnss, 0
    order = np.argsort(t_v, kind="stable")
    t_v, ve, vn = t_v[order], ve[order], vn[order]
    after = np.searchsorted(t_v, gnss.t_ns)  # the nearest message: the one before or after
    lo = np.clip(after - 1, 0, len(t_v) - 1)
    hi = np.minimum(after, len(t_v) - 1)
    j = np.where(np.abs(t_v[lo] - gnss.t_ns) <= np.abs(t_v[hi] - gnss.t_ns), lo, hi)
    near = np.abs(t_v[j] - gnss.t_ns) <= _VELOCITY_MATCH_NS
    take = near & ~np.isfinite(gnss.speed_mps)
    speed = gnss.speed_mps.copy()
    course = gnss.course_deg.copy()
    speed[take] = np.hypot(ve[j[take]], vn[j[take]])
    # heading clockwise from north (conventions charter): atan2(east, north)
    course[take] = np.degrees(np.arctan2(ve[j[take]], vn[j[take]])) % 360.0
    return dataclasses.replace(gnss, speed_mps=speed, course_deg=course), int(take.sum())


def _imu_absent(chan: Channel) -> np.ndarray:
    """Imu messages without angular velocity: covariance[0] = -1 (sensor_msgs/Imu: "no
    data"), unless the channel's z rates do vary under that flag (then it is sloppy
    driver metadata, not missing data, and the rates are kept)."""
    wz = _cat(chan, "wz", np.float64)
    declared = _cat(chan, "wz_cov0", np.float64) == -1.0
    if declared.any() and np.any(wz[declared] != 0.0):
        return np.zeros(len(wz), bool)
    return declared


def _concat_fixes(parts: list[GnssFixes]) -> GnssFixes:
    if not parts:
        return GnssFixes.empty(0)
    names = [f.name for f in dataclasses.fields(GnssFixes)]
    return GnssFixes(**{k: np.concatenate([getattr(p, k) for p in parts]) for k in names})


def _usable(kind: str, chan: Channel) -> int:
    if chan.layout == "navpvt":
        return sum(len(f) for f in chan.fixes)
    if kind == "gyro":
        return int((~_imu_absent(chan)).sum())
    if chan.layout == "sentence":
        return len(chan.texts)
    return len(_cat(chan, "log_ns", np.int64))


def _map_file(path: str | Path) -> mmap.mmap | bytes:
    """The file's bytes, memory-mapped: logs with camera topics run to gigabytes and
    only the few messages gpsdr reads (plus one chunk at a time) need to be in memory."""
    try:
        with open(path, "rb") as f:
            if os.fstat(f.fileno()).st_size == 0:
                return b""
            return mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
    except IsADirectoryError as err:
        raise InputError(path, "is a directory, expected a file") from err
    except FileNotFoundError as err:
        raise InputError(path, "no such file") from err
    except (OSError, ValueError) as err:
        raise InputError(path, f"cannot read: {getattr(err, 'strerror', None) or err}") from err


def check_topics(path: str, topics: dict[str, str] | None) -> tuple[dict[str, str], dict[str, str | None]]:
    """The non-empty topic overrides, validated, and the wanted topic per stream."""
    topics = {k: v for k, v in (topics or {}).items() if v}
    for kind in topics:
        if kind not in ("gnss", "gyro", "odo"):
            raise UsageError(f"topic override for {kind!r}: expected gnss, gyro or odo")
    return topics, {k: topics.get(k) for k in ("gnss", "gyro", "odo")}


def drive_from_channels(path_s: str, sha256: str, channels: list[Channel], *,
                        topics: dict[str, str], wanted: dict[str, str | None],
                        use_log_time: bool, date: dt.date | None, skipped: SkipReport,
                        warnings: list[str], meta: dict[str, Any]) -> Drive:
    """The schema/topic rules over decoded channels (an MCAP's or a ROS bag's): pick one
    channel per stream, build the streams, fill ``meta`` (``channels`` not included)."""
    by_topic = {c.topic: c for c in channels}
    for kind, topic in topics.items():
        chan = by_topic.get(topic)
        if chan is None:
            raise UsageError(f"{path_s}: no topic {topic!r} for {kind}; topics in the file: "
                             f"{', '.join(sorted(by_topic)) or '(none)'}")
        if chan.layout is None or KIND_OF_LAYOUT[chan.layout] != kind:
            raise UsageError(f"{path_s}: topic {topic!r} has schema {chan.schema_name!r}, "
                             f"which gpsdr cannot read as {kind}")
    drive = Drive(skipped=skipped, sources=[Source(path_s, sha256)])
    chosen: dict[str, str] = {}
    alternatives: dict[str, list[str]] = {}
    readings: dict[int, TwistReading] = {}
    for kind in ("gnss", "gyro", "odo"):
        cands = [c for c in channels
                 if c.layout is not None and KIND_OF_LAYOUT[c.layout] == kind
                 and (wanted[kind] is None or c.topic == wanted[kind])]
        if kind == "odo":
            readings = {c.id: twist_reading(c, drive.gnss, use_log_time) for c in cands}
            for c in cands:
                meta.setdefault("twist_frame", {})[c.topic] = readings[c.id].describe()
        if kind == "odo" and wanted["odo"] is None and drive.gnss is not None:
            # A navigation-frame (ENU) twist beside GNSS fixes is the receiver's own Doppler
            # velocity (u-blox /fix_velocity), not a wheel odometer: it becomes the fixes'
            # speed and course, which every filter's receiver-velocity update uses.
            nav = [c for c in cands if readings[c.id].frame == "enu"]
            if nav and not np.isfinite(drive.gnss.speed_mps).any():
                nav.sort(key=lambda c: c.n_msgs, reverse=True)
                drive.gnss, n_vel = _attach_velocity(drive.gnss, nav[0], use_log_time)
                if n_vel:
                    cands = [c for c in cands if c not in nav]
                    meta["gnss_velocity"] = {"topic": nav[0].topic, "fixes": n_vel}
                    if not cands:  # it would have been the odometer: say why there is none
                        warnings.append(f"{path_s}: {nav[0].topic}: navigation-frame (ENU) "
                                        f"velocity read as the GNSS fixes' speed and course "
                                        f"({n_vel} of {len(drive.gnss)} fixes), not as an "
                                        "odometer")
        if not cands:
            continue
        cands.sort(key=lambda c: (_usable(kind, c), c.n_msgs), reverse=True)
        best = cands[0]
        if len(cands) > 1:
            alternatives[kind] = [c.topic for c in cands[1:]]
            warnings.append(f"{path_s}: {len(cands)} {kind} channels; using {best.topic} "
                            f"({best.n_msgs} messages), not {', '.join(alternatives[kind])}")
        stream = _build(kind, best, path=path_s, use_log_time=use_log_time, date=date,
                        skipped=skipped, meta=meta, warnings=warnings,
                        twist=readings[best.id] if kind == "odo" else None)
        if len(stream):
            setattr(drive, kind, stream)
            chosen[kind] = best.topic
            if kind == "gyro":
                drive.accel = _accel(best, use_log_time)
    drive.sources[0].streams = tuple(chosen) + (("accel",) if drive.accel is not None else ())
    meta["chosen"] = chosen
    if alternatives:
        meta["alternatives"] = alternatives
    if warnings:
        drive.meta["warnings"] = warnings
    if not chosen:
        found = ", ".join(f"{c.topic} ({c.schema_name or 'no schema'})" for c in channels[:8])
        found = (found + (f" and {len(channels) - 8} more" if len(channels) > 8 else "")
                 ) or "no channels"
        damage = f"; {warnings[0]}" if warnings else ""
        raise NoDataError(path_s, f"no readable GNSS, gyro or odometer messages (found: "
                          f"{found}){damage}")
    return drive


def _accel(chan: Channel, use_log_time: bool) -> ForwardAccel | None:
    """``linear_acceleration.x`` of the Imu channel chosen for the gyro (REP-103: x
    forward), unless its covariance[0] is -1 (no data) or every value is exactly zero
    (a driver that leaves the field unset)."""
    ax = _cat(chan, "ax", np.float64)
    if not len(ax):
        return None
    t_ns, _ = _times(chan, use_log_time)
    keep = (_cat(chan, "ax_cov0", np.float64) != -1.0) & np.isfinite(ax)
    if not keep.any() or not np.any(ax[keep] != 0.0):
        return None
    return ForwardAccel(t_ns=t_ns[keep], accel_mps2=ax[keep])


def read_mcap(path: str | Path, *, topics: dict[str, str] | None = None, use_log_time: bool = False,
              date: dt.date | None = None) -> Drive:
    """Read GNSS, gyro and odometer streams from an MCAP file (see the module docstring).

    ``topics`` maps a stream (``gnss``, ``gyro``, ``odo``) to the topic to use for
    it instead of the schema-based choice.  ``date`` is the UTC date for NMEA
    sentences without one (default: the date of the first message stamp).
    """
    path_s = str(path)
    data = _map_file(path)
    if not len(data):
        raise InputError(path_s, "empty file, expected an MCAP log")
    if data[:8] != MAGIC:
        raise InputError(path_s, f"not an MCAP file (starts with {data[:8]!r}, expected the "
                         "MCAP magic \\x89MCAP0\\r\\n)")
    topics, wanted = check_topics(path_s, topics)
    decoder = Decoder(path_s, wanted)
    walker = Walker(path_s, data, make_channel=new_channel, wanted=decoder.is_wanted,
                    on_messages=decoder.on_messages)
    walker.walk()
    meta: dict[str, Any] = {}

    def count(c: Channel) -> int:  # channels in skipped chunks: the summary's statistics
        if walker.n_chunks_skipped and c.id not in walker.wanted_ids:
            return walker.stat_counts.get(c.id, c.n_msgs)
        return c.n_msgs

    chans = list(walker.channels.values())
    meta["channels"] = [{"topic": c.topic, "schema": c.schema_name, "encoding": c.encoding,
                         "messages": count(c)} for c in chans]
    meta["messages"] = walker.n_messages
    meta["chunks"] = walker.n_chunks
    if walker.n_chunks_skipped:
        meta["chunks_skipped"] = walker.n_chunks_skipped  # held only channels not read
    meta["indexed"] = walker.has_summary
    drive = drive_from_channels(path_s, hashlib.sha256(data).hexdigest(), chans,
                                topics=topics, wanted=wanted, use_log_time=use_log_time,
                                date=date, skipped=walker.skipped, warnings=list(walker.damage),
                                meta=meta)
    drive.meta["mcap"] = meta
    return drive
