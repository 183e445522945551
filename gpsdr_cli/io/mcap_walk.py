"""The MCAP container, walked record by record (the MCAP spec's framing).

Why not ``mcap.reader``: the library builds a Python object per record (~330 k
records/s before any decoding), and on a truncated or damaged file it raises
without handing over what it already read.  The walk here frames the records
linearly (opcode u8, length u64 LE, body) in a compiled scan, decompresses chunks
(zstd, lz4) with their declared size as the bound, checks their CRC, and on
damage keeps everything before it, with a warning (:attr:`Walker.damage`) and a
:class:`SkipReport` entry.  A CRC-checked summary section lets it skip chunks that
hold only channels nobody reads.  Decoding the messages is the caller's
(:mod:`gpsdr_cli.io.mcap`).
"""

from __future__ import annotations

import struct
import zlib
from collections.abc import Callable
from typing import Any

import numba
import numpy as np

from .drive import SkipReport
from .formats import MCAP_MAGIC as MAGIC

#: Larger declared chunks are taken as damage (writers use ~1-4 MB chunks).
_MAX_CHUNK_BYTES = 1 << 31

_OP_HEADER, _OP_FOOTER, _OP_SCHEMA, _OP_CHANNEL, _OP_MESSAGE, _OP_CHUNK = 1, 2, 3, 4, 5, 6
_OP_DATA_END = 0x0F

_U16 = struct.Struct("<H")
_U32 = struct.Struct("<I")
_U64 = struct.Struct("<Q")


class Damage(Exception):
    """The container is damaged at this point; keep what was read before."""


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


class Walker:
    """Linear walk over the MCAP records, handing messages over chunk by chunk.

    ``make_channel(id, topic, message_encoding, schema_name, schema_encoding,
    schema_data)`` builds the caller's object for a channel record (kept in
    :attr:`channels`); ``wanted(channel)`` says whether its messages are read (a
    chunk holding none is not decompressed); ``on_messages(channel, buf, npbuf,
    log_ns, offsets, sizes)`` receives each batch of one channel's messages: their
    log times and the byte ranges of their data in ``buf`` (``npbuf`` is the same
    bytes as a uint8 array).
    """

    def __init__(self, path: str, data: bytes, *, make_channel: Callable[..., Any],
                 wanted: Callable[[Any], bool],
                 on_messages: Callable[[Any, bytes, np.ndarray, np.ndarray, np.ndarray, np.ndarray],
                                       None]) -> None:
        self.path = path
        self.data = data
        self.make_channel = make_channel
        self.wanted = wanted
        self.on_messages = on_messages
        self.schemas: dict[int, tuple[str, str, bytes]] = {}
        self.channels: dict[int, Any] = {}
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
            raise Damage("string length runs past its record")
        n = _U32.unpack_from(buf, pos)[0]
        if pos + 4 + n > end:
            raise Damage("string runs past its record")
        try:
            return buf[pos + 4:pos + 4 + n].decode("utf-8"), pos + 4 + n
        except UnicodeDecodeError as err:
            raise Damage("string is not UTF-8") from err

    def _schema(self, buf: bytes, pos: int, end: int) -> None:
        if pos + 2 > end:
            raise Damage("schema record too short")
        sid = _U16.unpack_from(buf, pos)[0]
        name, p = self._string(buf, pos + 2, end)
        enc, p = self._string(buf, p, end)
        if p + 4 > end:
            raise Damage("schema record too short")
        n = _U32.unpack_from(buf, p)[0]
        if p + 4 + n > end:
            raise Damage("schema data runs past its record")
        self.schemas.setdefault(sid, (name, enc, bytes(buf[p + 4:p + 4 + n])))

    def _channel(self, buf: bytes, pos: int, end: int) -> None:
        if pos + 4 > end:
            raise Damage("channel record too short")
        cid, sid = struct.unpack_from("<HH", buf, pos)
        topic, p = self._string(buf, pos + 4, end)
        enc, p = self._string(buf, p, end)
        if cid in self.channels:
            return
        name, s_enc, s_data = self.schemas.get(sid, ("", "", b""))
        self.channels[cid] = self.make_channel(cid, topic, enc, name, s_enc, s_data)

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
            raise Damage(_SCAN_PROBLEMS[status].format(n=end - where, at=where))

    def _chunk(self, buf: bytes, pos: int, end: int) -> None:
        self.n_chunks += 1
        if pos + 28 > end:
            raise Damage("chunk record too short")
        usize = _U64.unpack_from(buf, pos + 16)[0]
        crc = _U32.unpack_from(buf, pos + 24)[0]
        compression, p = self._string(buf, pos + 28, end)
        if p + 8 > end:
            raise Damage("chunk record too short")
        n = _U64.unpack_from(buf, p)[0]
        if p + 8 + n > end:
            raise Damage("chunk records run past the chunk")
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
        except Damage as err:
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
            for op, pos, ln in zip(ops.tolist(), body.tolist(), length.tolist(), strict=False):
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
        except (Damage, struct.error):
            return
        self.chunk_channels = chunks
        self.wanted_ids = {cid for cid, c in self.channels.items() if self.wanted(c)}

    def walk(self) -> None:
        data = self.data
        self._read_summary()
        try:
            self._records(data, len(MAGIC), len(data), in_chunk=False)
        except Damage as err:
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
            self.on_messages(chan, buf, npbuf, lt[sel], off[sel], sz[sel])
