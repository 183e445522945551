"""MCAP reader: GNSS fixes, gyro yaw rates and odometer speeds from ROS 2 / Foxglove logs.

Channels are found by schema name (overridable by topic):

=========  ====================================================================
gnss       ``sensor_msgs/msg/NavSatFix``, ``foxglove.LocationFix`` (JSON or
           protobuf), ``nmea_msgs/msg/Sentence`` (fed to :func:`parse_nmea`)
gyro       ``sensor_msgs/msg/Imu``: ``angular_velocity.z``, rad/s, CCW-positive
           (REP-103 z up), the charter's sign
odo        ``nav_msgs/msg/Odometry`` (``twist.twist.linear.x``),
           ``geometry_msgs/msg/TwistStamped`` and ``TwistWithCovarianceStamped``
           (``twist.linear.x``), forward speed in m/s
=========  ====================================================================

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

Why the container is walked here instead of with ``mcap.reader``: the library
builds a Python object per record (~330 k records/s before any decoding, short
of the 300 k msg/s target once decoding is added), and on a truncated or
damaged file it raises without handing over what it already read.  The walk
below reads the records linearly (the MCAP spec's record framing: opcode u8,
length u64), decompresses chunks (zstd, lz4), checks their CRC, and on damage
keeps everything before it, with a warning and a :class:`SkipReport` entry.

Speed from ``twist.linear.x`` assumes a body-frame twist.  Some GNSS drivers
(u-blox ``/fix_velocity``) publish the velocity in a navigation frame (ENU),
recognised by a large lateral component while moving.  Beside GNSS fixes that
carry no speed (NavSatFix never does), such a channel is the receiver's Doppler
velocity: it becomes the fixes' speed and course (nearest message within
0.1 s), which the filters' receiver-velocity update uses, and it is not taken
as the odometer (a warning says so when no other odometer channel exists).
Without GNSS fixes, or when a topic override names it, it is read as an
odometer speed = |linear.xy|, with a warning.  An Imu whose ``angular_velocity_covariance[0]``
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
import zlib
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numba
import numpy as np

from ..conventions import FIX_DGPS, FIX_GPS, FIX_NONE, NS_PER_S
from ..errors import InputError, NoDataError, UsageError
from . import ros2_fast
from .drive import Drive, GnssFixes, Odometry, SkipReport, Source, YawRates
from .readers import MCAP_MAGIC as MAGIC  # there: sniffing must not import this module

#: Larger declared chunks are taken as damage (writers use ~1-4 MB chunks).
_MAX_CHUNK_BYTES = 1 << 31

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 1, 2, 3, 4, 5, 6
_OP_DATA_END = 0x0F

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")

#: Which stream each layout feeds.
KIND_OF_LAYOUT = {"navsatfix": "gnss", "locationfix": "gnss", "sentence": "gnss",
                  "imu": "gyro", "twist": "odo", "twistcov": "odo", "odometry": "odo"}
_LAYOUTS = dict(ros2_fast.LAYOUTS)
_LAYOUTS["foxglove.LocationFix"] = "locationfix"
_LAYOUTS["foxglove_msgs/msg/LocationFix"] = "locationfix"

#: Navigation-frame twist detection: moving faster than this, m/s ...
_MOVING_MPS = 0.5
#: ... with a median |linear.y| / |linear.xy| above this share.
_LATERAL_SHARE = 0.3
#: an ENU velocity message belongs to the fix stamped within this (u-blox: the same stamp)
_VELOCITY_MATCH_NS = 100_000_000


class _Damage(Exception):
    """The container is damaged at this point; keep what was read before."""


@dataclass
class _Channel:
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

    def add(self, name: str, values: Any) -> None:
        self.cols.setdefault(name, []).append(values)


# --------------------------------------------------------------------------- container walk

_SCAN_PROBLEMS = {
    1: "{n} stray bytes at offset {at}, too few for a record header",
    2: "record at offset {at} runs past the end (truncated?)",
    3: "message record at offset {at} shorter than its header",
    4: "opcode 0x00 (zeroed bytes) at offset {at}",
}


@numba.njit(cache=True)
def _scan_pass(buf: np.ndarray, start: int, end: int, stop_at_data_end: bool, fill: bool,
               ops: np.ndarray, body: np.ndarray, length: np.ndarray, ch: np.ndarray,
               lt: np.ndarray):  # pragma: no cover
    k = 0
    p = start
    status = 0
    while p < end:
        if p + 9 > end:
            status = 1
            break
        op = buf[p]
        ln = np.uint64(0)
        for i in range(8):
            ln |= np.uint64(buf[p + 1 + i]) << np.uint64(8 * i)
        if ln > np.uint64(end - p - 9):
            status = 2
            break
        if op == 0:
            status = 4
            break
        n = np.int64(ln)
        if op == 5 and n < 22:
            status = 3
            break
        if fill:
            if op == 5:
                q = p + 9
                ch[k] = np.int64(buf[q]) | (np.int64(buf[q + 1]) << 8)
                t = np.uint64(0)
                for i in range(8):
                    t |= np.uint64(buf[q + 6 + i]) << np.uint64(8 * i)
                lt[k] = np.int64(t)
            ops[k] = op
            body[k] = p + 9
            length[k] = n
        k += 1
        p += 9 + n
        if stop_at_data_end and (op == 0x0F or op == 0x02):
            break
    return k, status, p


def _scan_records(buf: np.ndarray, start: int, end: int, stop_at_data_end: bool):
    """Frame the records of buf[start:end] (MCAP: opcode u8, length u64 LE, body).

    Returns per record: opcode, body offset, body length, and for messages the
    channel id and log time; then a status (0 ok, else a key of _SCAN_PROBLEMS)
    and the offset where the scan stopped.  Compiled, in two passes (count, then
    fill exactly sized arrays): this is the one loop that touches every record,
    and Python spends ~0.6 us per record on it.
    """
    none = np.zeros(0, np.int64)
    k, _, _ = _scan_pass(buf, start, end, stop_at_data_end, False, np.zeros(0, np.uint8),
                         none, none, none, none)
    ops = np.empty(k, np.uint8)
    body = np.empty(k, np.int64)
    length = np.empty(k, np.int64)
    ch = np.zeros(k, np.int64)
    lt = np.zeros(k, np.int64)
    k, status, p = _scan_pass(buf, start, end, stop_at_data_end, True, ops, body, length, ch, lt)
    return ops, body, length, ch, lt, status, p


class _Walker:
    """Linear walk over the MCAP records; decodes wanted channels chunk by chunk."""

    def __init__(self, path: str, data: bytes, wanted: dict[str, str | None],
                 use_log_time: bool) -> None:
        self.path = path
        self.data = data
        self.wanted = wanted
        self.use_log_time = use_log_time
        self.schemas: dict[int, tuple[str, str, bytes]] = {}
        self.channels: dict[int, _Channel] = {}
        self.damage: list[str] = []
        self.skipped = SkipReport()
        self.n_chunks = 0
        self.n_messages = 0
        self.reached_data_end = False
        self.has_summary = False
        #: From a CRC-checked summary: chunk record offset -> channel ids in it; per-channel counts.
        self.chunk_channels: dict[int, frozenset[int]] = {}
        self.stat_counts: dict[int, int] = {}
        self.wanted_ids: set[int] = set()
        self.n_chunks_skipped = 0

    # records --------------------------------------------------------------
    def _string(self, buf: bytes, pos: int, end: int) -> tuple[str, int]:
        if pos + 4 > end:
            raise _Damage("string length runs past its record")
        n = _U32.unpack_from(buf, pos)[0]
        if pos + 4 + n > end:
            raise _Damage("string runs past its record")
        try:
            return buf[pos + 4:pos + 4 + n].decode("utf-8"), pos + 4 + n
        except UnicodeDecodeError as err:
            raise _Damage("string is not UTF-8") from err

    def _schema(self, buf: bytes, pos: int, end: int) -> None:
        if pos + 2 > end:
            raise _Damage("schema record too short")
        sid = _U16.unpack_from(buf, pos)[0]
        name, p = self._string(buf, pos + 2, end)
        enc, p = self._string(buf, p, end)
        if p + 4 > end:
            raise _Damage("schema record too short")
        n = _U32.unpack_from(buf, p)[0]
        if p + 4 + n > end:
            raise _Damage("schema data runs past its record")
        self.schemas.setdefault(sid, (name, enc, bytes(buf[p + 4:p + 4 + n])))

    def _channel(self, buf: bytes, pos: int, end: int) -> None:
        if pos + 4 > end:
            raise _Damage("channel record too short")
        cid, sid = struct.unpack_from("<HH", buf, pos)
        topic, p = self._string(buf, pos + 4, end)
        enc, p = self._string(buf, p, end)
        if cid in self.channels:
            return
        name, s_enc, s_data = self.schemas.get(sid, ("", "", b""))
        self.channels[cid] = _Channel(cid, topic, enc, name, s_enc, s_data, _LAYOUTS.get(name))

    def _records(self, buf: bytes, start: int, end: int, in_chunk: bool) -> None:
        """Walk the records of buf[start:end]: the compiled scan frames them, Python
        handles the few non-message records in order, messages are decoded in batches."""
        arr = np.frombuffer(buf, np.uint8)
        ops, body, length, ch, lt, status, where = _scan_records(arr, start, end, not in_chunk)
        special = np.flatnonzero(ops != _OP_MESSAGE).tolist()
        seg = 0
        for k in [*special, len(ops)]:
            if k > seg:
                self._flush(buf, arr, ch[seg:k], lt[seg:k], body[seg:k] + 22, length[seg:k] - 22)
            if k == len(ops):
                break
            op, pos = int(ops[k]), int(body[k])
            nxt = pos + int(length[k])
            if op == _OP_SCHEMA:
                self._schema(buf, pos, nxt)
            elif op == _OP_CHANNEL:
                self._channel(buf, pos, nxt)
            elif op == _OP_CHUNK and not in_chunk:
                inside = self.chunk_channels.get(pos - 9)
                if inside and not inside & self.wanted_ids:
                    self.n_chunks += 1
                    self.n_chunks_skipped += 1  # the index says: nothing gpsdr reads in there
                else:
                    self._chunk(buf, pos, nxt)
            elif op == _OP_DATA_END and not in_chunk:
                self.reached_data_end = True
            seg = k + 1
        if status:
            raise _Damage(_SCAN_PROBLEMS[status].format(n=end - where, at=where))

    def _chunk(self, buf: bytes, pos: int, end: int) -> None:
        self.n_chunks += 1
        if pos + 28 > end:
            raise _Damage("chunk record too short")
        usize = _U64.unpack_from(buf, pos + 16)[0]
        crc = _U32.unpack_from(buf, pos + 24)[0]
        compression, p = self._string(buf, pos + 28, end)
        if p + 8 > end:
            raise _Damage("chunk record too short")
        n = _U64.unpack_from(buf, p)[0]
        if p + 8 + n > end:
            raise _Damage("chunk records run past the chunk")
        raw = buf[p + 8:p + 8 + n]
        where = f"{self.path}: chunk {self.n_chunks}"
        import lz4.frame
        import zstandard

        if usize > _MAX_CHUNK_BYTES:
            self._bad_chunk(where, f"claims {usize} uncompressed bytes")
            return
        try:
            # Output bounded by the chunk's declared size: a damaged header cannot make
            # the decompressor allocate more.
            if compression == "":
                records = bytes(raw)
            elif compression == "zstd":
                declared = zstandard.frame_content_size(raw)
                if declared not in (-1, usize):
                    raise ValueError(f"zstd frame says {declared} bytes, chunk says {usize}")
                records = zstandard.ZstdDecompressor().decompress(raw, max_output_size=usize)
            elif compression == "lz4":
                records = lz4.frame.LZ4FrameDecompressor().decompress(raw, max_length=usize + 1)
            else:
                self.skipped.add(f"MCAP chunk with unsupported compression {compression!r}", where)
                return
        except (zstandard.ZstdError, RuntimeError, ValueError, OSError, MemoryError,
                OverflowError) as err:
            self._bad_chunk(where, f"cannot decompress ({compression}): {err}")
            return
        if len(records) != usize:
            self._bad_chunk(where, f"decompressed to {len(records)} bytes, header says {usize}")
            return
        if crc and zlib.crc32(records) != crc:
            self._bad_chunk(where, "CRC mismatch (corrupt chunk)")
            return
        try:
            self._records(records, 0, len(records), in_chunk=True)
        except _Damage as err:
            self._bad_chunk(where, str(err))

    def _bad_chunk(self, where: str, why: str) -> None:
        self.skipped.add("MCAP chunk damaged (its messages lost)", where)
        self.damage.append(f"{where}: {why}; skipped")

    def _read_summary(self) -> None:
        """Channels and the chunk index from the summary section, if its CRC checks.

        Lets the walk skip chunks holding only channels gpsdr does not read (camera,
        lidar): no decompression for them.  Any doubt (no summary, no CRC, a bad
        CRC, an index without message indexes) leaves every chunk to be read."""
        data = self.data
        n = len(data)
        if n < 8 + 37 + 8 or data[-8:] != MAGIC or data[n - 37] != _OP_FOOTER:
            return
        start = _U64.unpack_from(data, n - 28)[0]
        crc = _U32.unpack_from(data, n - 12)[0]
        if not (crc and 8 <= start <= n - 37) or zlib.crc32(data[start:n - 12]) != crc:
            return
        arr = np.frombuffer(data, np.uint8)
        ops, body, length, _, _, status, _ = _scan_records(arr, start, n - 37, False)
        if status:
            return
        chunks: dict[int, frozenset[int]] = {}
        try:
            for op, pos, ln in zip(ops.tolist(), body.tolist(), length.tolist()):
                end = pos + ln
                if op == _OP_SCHEMA:
                    self._schema(data, pos, end)
                elif op == _OP_CHANNEL:
                    self._channel(data, pos, end)
                elif op == 0x08:  # ChunkIndex: start, end times; chunk offset, length; map
                    offset = _U64.unpack_from(data, pos + 16)[0]
                    nbytes = _U32.unpack_from(data, pos + 32)[0]
                    ids = [_U16.unpack_from(data, pos + 36 + 10 * i)[0] for i in range(nbytes // 10)]
                    chunks[offset] = frozenset(ids)
                elif op == 0x0B:  # Statistics: ... channel_message_counts map at +42
                    nbytes = _U32.unpack_from(data, pos + 42)[0]
                    for i in range(nbytes // 10):
                        cid, cnt = struct.unpack_from("<HQ", data, pos + 46 + 10 * i)
                        self.stat_counts[cid] = cnt
        except (_Damage, struct.error):
            return
        self.chunk_channels = chunks
        self.wanted_ids = {cid for cid, c in self.channels.items() if self._wanted(c)}

    def walk(self) -> None:
        data = self.data
        self._read_summary()
        try:
            self._records(data, len(MAGIC), len(data), in_chunk=False)
        except _Damage as err:
            self.damage.append(f"{self.path}: {err}; read up to there")
            self.skipped.add("MCAP truncated or damaged (rest of file unread)", self.path)
            return
        if not self.reached_data_end:
            self.damage.append(f"{self.path}: ends without a data-end record (truncated?); "
                               "read up to the end")
            self.skipped.add("MCAP truncated or damaged (rest of file unread)", self.path)
        elif len(data) >= 8 + 29 + 8 and data[-8:] == MAGIC and data[-37] == _OP_FOOTER:
            # Footer: opcode, length, summary_start u64, summary_offset_start u64, crc u32; magic.
            self.has_summary = _U64.unpack_from(data, len(data) - 28)[0] != 0
        else:
            self.damage.append(f"{self.path}: summary or footer truncated (no closing magic); "
                               "every data record was read")

    # decoding --------------------------------------------------------------
    def _flush(self, buf: bytes, npbuf: np.ndarray, ch: np.ndarray, lt: np.ndarray,
               off: np.ndarray, sz: np.ndarray) -> None:
        self.n_messages += len(ch)
        for cid in np.unique(ch):
            chan = self.channels.get(int(cid))
            sel = ch == cid
            if chan is None:
                self.skipped.add("MCAP message on an undeclared channel", f"{self.path}: channel {cid}",
                                 int(sel.sum()))
                continue
            chan.n_msgs += int(sel.sum())
            if not self._wanted(chan):
                continue
            self._decode(chan, buf, npbuf, lt[sel], off[sel], sz[sel])

    def _wanted(self, chan: _Channel) -> bool:
        if chan.layout is None:
            return False
        topic = self.wanted.get(KIND_OF_LAYOUT[chan.layout])
        return topic is None or topic == chan.topic

    def _decode(self, chan: _Channel, buf: bytes, npbuf: np.ndarray, lt: np.ndarray,
                off: np.ndarray, sz: np.ndarray) -> None:
        layout = chan.layout
        assert layout is not None
        enc = chan.encoding.lower()
        rest = np.arange(len(off))
        if enc in ("cdr", "ros1") and layout != "locationfix":
            fields, ok = ros2_fast.decode(layout, npbuf, off, sz, ros1=enc == "ros1")
            if ok.any():
                chan.add("log_ns", lt[ok])
                if layout == "sentence":
                    chan.add("stamp_ns", fields["stamp_ns"][ok])
                    for o, n in zip(fields["text_off"][ok].tolist(), fields["text_len"][ok].tolist()):
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

    def _extract_one(self, chan: _Channel, msg: Any) -> dict[str, Any] | None:
        try:
            return _extract(chan.layout, msg)
        except (KeyError, TypeError, ValueError, AttributeError, OverflowError) as err:
            chan.first_undecodable = chan.first_undecodable or (
                f"{self.path}: {chan.topic} message {chan.n_msgs}: {type(err).__name__}: {err}")
        return None

    def _decode_one(self, chan: _Channel, raw: bytes) -> dict[str, Any] | None:
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
                    chan.pb_numbers = _pb_numbers(chan.schema_data)
                return _extract("locationfix", _pb_location_fix(raw, chan.pb_numbers))
        except (struct.error, IndexError, KeyError, TypeError, ValueError, AttributeError,
                OverflowError, UnicodeDecodeError, RecursionError) as err:
            chan.first_undecodable = chan.first_undecodable or (
                f"{self.path}: {chan.topic} message {chan.n_msgs}: {type(err).__name__}: {err}")
        return None


def _generic_decoder(chan: _Channel) -> Any:
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


def _varint(buf: bytes, pos: int) -> tuple[int, int]:
    value = shift = 0
    while True:
        b = buf[pos]
        pos += 1
        value |= (b & 0x7F) << shift
        if not b & 0x80:
            return value, pos
        shift += 7
        if shift > 63:
            raise ValueError("varint longer than 10 bytes")


def _pb_fields(buf: bytes) -> list[tuple[int, int, Any]]:
    """Protobuf wire format: (field number, wire type, value) with value an int
    (varint), bytes (length-delimited, fixed64, fixed32)."""
    out: list[tuple[int, int, Any]] = []
    pos, end = 0, len(buf)
    while pos < end:
        key, pos = _varint(buf, pos)
        num, wt = key >> 3, key & 7
        if wt == 0:
            value, pos = _varint(buf, pos)
        elif wt in (1, 5):
            n = 8 if wt == 1 else 4
            if pos + n > end:
                raise ValueError("truncated fixed-width field")
            value, pos = buf[pos:pos + n], pos + n
        elif wt == 2:
            n, pos = _varint(buf, pos)
            if pos + n > end:
                raise ValueError("truncated length-delimited field")
            value, pos = buf[pos:pos + n], pos + n
        else:
            raise ValueError(f"unsupported wire type {wt}")
        out.append((num, wt, value))
    return out


#: foxglove.LocationFix field numbers (foxglove schemas), used when the channel's
#: schema carries no readable FileDescriptorSet.
_LOCFIX_NUMBERS = {"latitude": 1, "longitude": 2, "altitude": 3, "position_covariance": 4,
                   "position_covariance_type": 5, "timestamp": 6}


def _pb_numbers(descriptor_set: bytes, message: str = "LocationFix") -> dict[str, int]:
    """Field numbers by name of ``message`` in a FileDescriptorSet (schema data of a
    protobuf MCAP channel): FileDescriptorSet.file = 1, FileDescriptorProto.message_type
    = 4, DescriptorProto.name = 1 / field = 2, FieldDescriptorProto.name = 1 / number = 3.
    Falls back to the published foxglove numbers when the descriptor is unreadable."""
    try:
        for num, wt, file in _pb_fields(descriptor_set):
            if num != 1 or wt != 2:
                continue
            for n2, w2, msg in _pb_fields(file):
                if n2 != 4 or w2 != 2:
                    continue
                fields = _pb_fields(msg)
                if not any(n == 1 and v == message.encode() for n, _, v in fields):
                    continue
                numbers = {}
                for n3, w3, fdesc in fields:
                    if n3 == 2 and w3 == 2:
                        f = {n: v for n, _, v in _pb_fields(fdesc)}
                        if 1 in f and 3 in f:
                            numbers[bytes(f[1]).decode("utf-8", "replace")] = int(f[3])
                if {"latitude", "longitude"} <= numbers.keys():
                    return numbers
    except (ValueError, IndexError, TypeError):
        pass
    return dict(_LOCFIX_NUMBERS)


def _pb_location_fix(buf: bytes, numbers: dict[str, int] | None = None) -> dict[str, Any]:
    """foxglove.LocationFix in protobuf wire format; ``numbers`` maps field names to
    numbers (from the channel's descriptor, default the published schema).
    Timestamp is google.protobuf.Timestamp (seconds = 1, nanos = 2)."""
    by_num = {v: k for k, v in (numbers or _LOCFIX_NUMBERS).items()}
    out: dict[str, Any] = {"latitude": None, "longitude": None, "altitude": 0.0,
                           "position_covariance": [], "position_covariance_type": 0,
                           "timestamp": {"sec": 0, "nsec": 0}}
    for num, wt, value in _pb_fields(buf):
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
            for k, w, v in _pb_fields(value):
                if w == 0 and k in (1, 2):
                    v = v - (1 << 64) if v >= 1 << 63 else v  # int64/int32 two's complement
                    ts["sec" if k == 1 else "nsec"] = v
            out["timestamp"] = ts
    return out


# --------------------------------------------------------------------------- streams

def _cat(chan: _Channel, name: str, dtype: Any) -> np.ndarray:
    """A field's values: fast-path arrays, then generic-route scalars (the same order for
    every field of a channel, so rows stay aligned)."""
    parts = list(chan.cols.get(name, []))
    if chan.scalars.get(name):
        parts.append(np.array(chan.scalars[name], dtype=dtype))
    if not parts:
        return np.zeros(0, dtype)
    return np.concatenate(parts).astype(dtype, copy=False)


def _times(chan: _Channel, use_log_time: bool) -> tuple[np.ndarray, int]:
    """Header stamps (or log times); a zero stamp falls back to the log time."""
    log = _cat(chan, "log_ns", np.int64)
    if use_log_time:
        return log, 0
    stamp = _cat(chan, "stamp_ns", np.int64)
    zero = stamp == 0
    return np.where(zero, log, stamp), int(zero.sum())


def _gnss_from_fixes(chan: _Channel, t_ns: np.ndarray, skipped: SkipReport, where: str) -> GnssFixes:
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
    return g


def _gnss_from_sentences(chan: _Channel, t_ns: np.ndarray, date: dt.date | None, path: str,
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


def _build(kind: str, chan: _Channel, *, path: str, use_log_time: bool, date: dt.date | None,
           skipped: SkipReport, meta: dict, warnings: list[str]) -> Any:
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
    speed = vx
    if _navigation_frame(chan):
        speed = np.hypot(vx, vy)
        warnings.append(f"{where}: twist.linear has a large lateral (y) component while moving: "
                        "read as a navigation-frame (ENU) velocity, speed = |linear.xy|")
        meta.setdefault("twist_frame", {})[chan.topic] = "navigation (ENU): speed = hypot(x, y)"
    bad = ~np.isfinite(speed)
    skipped.add("non-finite speed", where, int(bad.sum()))
    return Odometry(t_ns=t_ns[~bad], speed_mps=speed[~bad])


def _navigation_frame(chan: _Channel) -> bool:
    """A twist channel whose linear velocity is in a navigation frame (ENU, as u-blox
    ``/fix_velocity``) rather than the body frame: a large lateral (y) share while moving."""
    if chan.layout is None or KIND_OF_LAYOUT[chan.layout] != "odo":
        return False
    vx = _cat(chan, "vx", np.float64)
    vy = _cat(chan, "vy", np.float64)
    norm = np.hypot(vx, vy)
    moving = np.isfinite(norm) & (norm > _MOVING_MPS)
    return bool(moving.sum() >= 10
                and np.median(np.abs(vy[moving]) / norm[moving]) > _LATERAL_SHARE)


def _attach_velocity(gnss: GnssFixes, chan: _Channel, use_log_time: bool) -> tuple[GnssFixes, int]:
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


def _imu_absent(chan: _Channel) -> np.ndarray:
    """Imu messages without angular velocity: covariance[0] = -1 (sensor_msgs/Imu: "no
    data"), unless the channel's z rates do vary under that flag (then it is sloppy
    driver metadata, not missing data, and the rates are kept)."""
    wz = _cat(chan, "wz", np.float64)
    declared = _cat(chan, "wz_cov0", np.float64) == -1.0
    if declared.any() and np.any(wz[declared] != 0.0):
        return np.zeros(len(wz), bool)
    return declared


def _usable(kind: str, chan: _Channel) -> int:
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
    topics = {k: v for k, v in (topics or {}).items() if v}
    for kind in topics:
        if kind not in ("gnss", "gyro", "odo"):
            raise UsageError(f"topic override for {kind!r}: expected gnss, gyro or odo")
    wanted = {k: topics.get(k) for k in ("gnss", "gyro", "odo")}
    walker = _Walker(path_s, data, wanted, use_log_time)
    walker.walk()
    skipped = walker.skipped
    warnings = list(walker.damage)
    meta: dict[str, Any] = {}
    channels = {c.topic: c for c in walker.channels.values()}
    for kind, topic in topics.items():
        chan = channels.get(topic)
        if chan is None:
            raise UsageError(f"{path_s}: no topic {topic!r} for {kind}; topics in the file: "
                             f"{', '.join(sorted(channels)) or '(none)'}")
        if chan.layout is None or KIND_OF_LAYOUT[chan.layout] != kind:
            raise UsageError(f"{path_s}: topic {topic!r} has schema {chan.schema_name!r}, "
                             f"which gpsdr cannot read as {kind}")
    drive = Drive(skipped=skipped, sources=[Source(path_s, hashlib.sha256(data).hexdigest())])
    chosen: dict[str, str] = {}
    alternatives: dict[str, list[str]] = {}
    for kind in ("gnss", "gyro", "odo"):
        cands = [c for c in walker.channels.values()
                 if c.layout is not None and KIND_OF_LAYOUT[c.layout] == kind
                 and (wanted[kind] is None or c.topic == wanted[kind])]
        if kind == "odo" and wanted["odo"] is None and drive.gnss is not None:
            # A navigation-frame (ENU) twist beside GNSS fixes is the receiver's own Doppler
            # velocity (u-blox /fix_velocity), not a wheel odometer: it becomes the fixes'
            # speed and course, which every filter's receiver-velocity update uses.
            nav = [c for c in cands if _navigation_frame(c)]
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
                        skipped=skipped, meta=meta, warnings=warnings)
        if len(stream):
            setattr(drive, kind, stream)
            chosen[kind] = best.topic
    drive.sources[0].streams = tuple(chosen)
    def count(c: _Channel) -> int:  # channels in skipped chunks: the summary's statistics
        if walker.n_chunks_skipped and c.id not in walker.wanted_ids:
            return walker.stat_counts.get(c.id, c.n_msgs)
        return c.n_msgs

    meta["channels"] = [{"topic": c.topic, "schema": c.schema_name, "encoding": c.encoding,
                         "messages": count(c)} for c in walker.channels.values()]
    meta["chosen"] = chosen
    if alternatives:
        meta["alternatives"] = alternatives
    meta["messages"] = walker.n_messages
    meta["chunks"] = walker.n_chunks
    if walker.n_chunks_skipped:
        meta["chunks_skipped"] = walker.n_chunks_skipped  # held only channels not read
    meta["indexed"] = walker.has_summary
    drive.meta["mcap"] = meta
    if warnings:
        drive.meta["warnings"] = warnings
    if not chosen:
        chans = list(walker.channels.values())
        found = ", ".join(f"{c.topic} ({c.schema_name or 'no schema'})" for c in chans[:8])
        found = (found + (f" and {len(chans) - 8} more" if len(chans) > 8 else "")) or "no channels"
        damage = f"; {warnings[0]}" if warnings else ""
        raise NoDataError(path_s, f"no readable GNSS, gyro or odometer messages (found: {found}){damage}")
    return drive
