"""ROS 1 bag (format 2.0) records, walked for the raw bytes of the messages gpsdr reads.

Why hand-written: rosbags' ROS 1 reader parses every message record's header in
Python and merges the chunks through a heap (~70 k messages/s here); the bag is
a flat sequence of records (uint32 header length, ``name=value`` fields each with a
uint32 length, uint32 data length, data), so a compiled scan frames each chunk's
records at once.  rosbags still opens the bag (version, index, connections); this
module only reads the chunks' message-data records (op 0x02: ``conn`` uint32,
``time`` = uint32 sec, uint32 nsec).  Chunks compressed with anything other than
none, bz2 or lz4 raise :class:`Unsupported` and the caller uses rosbags instead.
"""

from __future__ import annotations

import bz2
import struct

import numba
import numpy as np

from .formats import ROSBAG1_MAGIC

_OP_CHUNK, _OP_CONN = 0x05, 0x07


class Unsupported(Exception):
    """A bag this walk does not read (the caller falls back to rosbags)."""


def _fields(header: bytes) -> dict[str, bytes]:
    out: dict[str, bytes] = {}
    pos = 0
    while pos + 4 <= len(header):
        (n,) = struct.unpack_from("<I", header, pos)
        field = header[pos + 4:pos + 4 + n]
        pos += 4 + n
        name, _, value = field.partition(b"=")
        out[name.decode("ascii", "replace")] = value
    return out


@numba.njit(cache=True)
def _scan_chunk(buf: np.ndarray, fill: bool, conn: np.ndarray, t_ns: np.ndarray,
                off: np.ndarray, size: np.ndarray):  # pragma: no cover
    n = len(buf)
    p = 0
    k = 0
    while p + 4 <= n:
        hl = np.int64(buf[p]) | np.int64(buf[p + 1]) << 8 | np.int64(buf[p + 2]) << 16 \
            | np.int64(buf[p + 3]) << 24
        h0 = p + 4
        h1 = h0 + hl
        if h1 + 4 > n:
            return k, 1
        op = -1
        c = 0
        sec = 0
        nsec = 0
        q = h0
        while q + 4 <= h1:
            fl = np.int64(buf[q]) | np.int64(buf[q + 1]) << 8 | np.int64(buf[q + 2]) << 16 \
                | np.int64(buf[q + 3]) << 24
            f0 = q + 4
            f1 = f0 + fl
            if f1 > h1:
                return k, 1
            if fl == 4 and buf[f0] == 111 and buf[f0 + 1] == 112 and buf[f0 + 2] == 61:  # op=
                op = buf[f0 + 3]
            elif fl == 9 and buf[f0] == 99 and buf[f0 + 1] == 111 and buf[f0 + 2] == 110 \
                    and buf[f0 + 3] == 110 and buf[f0 + 4] == 61:  # conn=
                for i in range(4):
                    c |= np.int64(buf[f0 + 5 + i]) << (8 * i)
            elif fl == 13 and buf[f0] == 116 and buf[f0 + 1] == 105 and buf[f0 + 2] == 109 \
                    and buf[f0 + 3] == 101 and buf[f0 + 4] == 61:  # time=
                for i in range(4):
                    sec |= np.int64(buf[f0 + 5 + i]) << (8 * i)
                    nsec |= np.int64(buf[f0 + 9 + i]) << (8 * i)
            q = f1
        dl = np.int64(buf[h1]) | np.int64(buf[h1 + 1]) << 8 | np.int64(buf[h1 + 2]) << 16 \
            | np.int64(buf[h1 + 3]) << 24
        d0 = h1 + 4
        if d0 + dl > n:
            return k, 1
        if op == 2 or op == 7:
            if fill:
                # a connection record (op 7): conn = -1 - id, t_ns = its header's offset
                conn[k] = c if op == 2 else -1 - c
                t_ns[k] = sec * 1_000_000_000 + nsec if op == 2 else h0
                off[k] = d0
                size[k] = dl
            k += 1
        p = d0 + dl
    return k, 0


def chunk_messages(records: bytes) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, bool]:
    """(conn id, log time ns, data offset, data size) of each message record in a chunk's
    records (connection records: conn = -1 - id, time = the header offset), and whether
    the records ended cleanly."""
    buf = np.frombuffer(records, np.uint8)
    z = np.zeros(0, np.int64)
    k, _ = _scan_chunk(buf, False, z, z, z, z)
    conn, t_ns = np.empty(k, np.int64), np.empty(k, np.int64)
    off, size = np.empty(k, np.int64), np.empty(k, np.int64)
    _, status = _scan_chunk(buf, True, conn, t_ns, off, size)
    return conn, t_ns, off, size, status == 0


def connection(records: bytes, header_at: int, data_at: int, size: int) -> tuple[int, str, str]:
    """(id, topic, message type) of a connection record: the header holds conn and
    topic, the data the publisher's connection header (type=...)."""
    (hl,) = struct.unpack_from("<I", records, header_at - 4)
    head = _fields(records[header_at:header_at + hl])
    body = _fields(records[data_at:data_at + size])
    cid = struct.unpack("<I", head["conn"])[0]
    return cid, head.get("topic", b"").decode("utf-8", "replace"), \
        body.get("type", b"").decode("utf-8", "replace")


def walk(data: bytes):
    """Yield ``(records bytes, conn, t_ns, off, size)`` per chunk, then for the
    top-level connection records (the index section) one more batch; raises ValueError
    at damage, after yielding what came before it, and :class:`Unsupported` for an
    unknown compression."""
    import lz4.frame

    pos = len(ROSBAG1_MAGIC)
    n = len(data)
    while pos + 4 <= n:
        (hl,) = struct.unpack_from("<I", data, pos)
        if pos + 8 + hl > n:
            raise ValueError(f"record header at byte {pos} runs past the end")
        fields = _fields(data[pos + 4:pos + 4 + hl])
        (dl,) = struct.unpack_from("<I", data, pos + 4 + hl)
        d0 = pos + 8 + hl
        if d0 + dl > n:
            raise ValueError(f"record at byte {pos} runs past the end (truncated?)")
        op = fields.get("op", b"\xff")[:1]
        if op == bytes([_OP_CONN]) and "conn" in fields:
            cid = struct.unpack("<I", fields["conn"][:4].ljust(4, b"\0"))[0]
            yield data, np.array([-1 - cid]), np.array([pos + 4]), np.array([d0]), np.array([dl])
        elif op == bytes([_OP_CHUNK]):
            comp = fields.get("compression", b"none")
            raw = data[d0:d0 + dl]
            if comp == b"none":
                records = raw
            elif comp == b"bz2":
                records = bz2.decompress(raw)
            elif comp == b"lz4":
                records = lz4.frame.decompress(raw)
            else:
                raise Unsupported(f"chunk compression {comp!r}")
            conn, t_ns, off, size, clean = chunk_messages(records)
            yield records, conn, t_ns, off, size
            if not clean:
                raise ValueError(f"chunk at byte {pos} damaged")
        pos = d0 + dl
