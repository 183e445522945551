"""ROS 1 ``.bag`` and ROS 2 bag (``.db3`` SQLite file or bag folder) reader.

The same topic and schema rules as MCAP (:mod:`gpsdr_cli.io.mcap`): NavSatFix and
``nmea_msgs/Sentence`` as GNSS, Imu ``angular_velocity.z`` as the gyro and its
``linear_acceleration.x`` as the forward accelerometer, Odometry / TwistStamped /
TwistWithCovarianceStamped ``linear.x`` as the odometer, chosen per stream by the
channel with the most usable messages unless a topic override names one.  The
mapping to a :class:`Drive` is the MCAP module's (:func:`mcap.drive_from_channels`).

How the containers are read, and why not all through ``rosbags``: rosbags is the
library for the formats (it reads every bag gpsdr does not read itself, and the
tests write their bags with it), but it takes a Python step per message (its ROS 1
reader also parses the whole index on open: ~70 k messages/s here, ~160 k for ROS 2
SQLite, against a 300 k target), and its deserialiser builds a Python object per
message.  So the two common layouts have a hand-written fast path:

* ROS 1 ``.bag``: the records are framed by a compiled scan
  (:mod:`gpsdr_cli.io.rosbag1_walk`; chunks uncompressed, bz2 or lz4), the
  connections taken from their own records.  A bag cut short (no index, which
  rosbags refuses) is read up to its last whole chunk, with a warning.
* ROS 2 SQLite (a ``.db3`` file or a bag folder of them, uncompressed): the
  ``topics`` table, then the wanted topics' rows of ``messages`` in id (insertion)
  order -- the table's own, so no sort, and not log-time order through the timestamp
  index, which costs a row lookup per message; the times are the header stamps
  anyway -- by one aggregate query per 500 k rows that returns their blobs concatenated
  and their log times, topics and sizes as one fixed-width hex string, so no Python
  object is made per message (a row-per-message fetch costs ~2 us a row).
* Anything else (compressed ROS 2 bags, MCAP storage, other chunk codecs): rosbags.

In every case the raw messages of a wanted topic are decoded in one batch by the
vectorised fixed-layout decoder of :mod:`gpsdr_cli.io.ros2_fast` (CDR for ROS 2,
the ROS 1 serialisation for ``.bag``), the one MCAP uses; a message it declines is
counted as undecodable.  Times are the header stamps (int64 ns UTC;
``use_log_time`` takes the bag's log times; a zero stamp falls back to it).
"""

from __future__ import annotations

import datetime as dt
import hashlib
import struct
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from . import mcap
from .drive import Drive, SkipReport
from .formats import ROSBAG1_MAGIC, SQLITE_MAGIC


def _damage_errors() -> tuple[type[BaseException], ...]:
    import sqlite3
    import struct

    import apsw
    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error

    return (Reader1Error, Reader2Error, sqlite3.Error, apsw.Error, OSError, struct.error,
            ValueError,
            KeyError, IndexError, EOFError)


def _sqlite_files(path: Path) -> list[Path]:
    """The SQLite storage files of a ROS 2 bag (a ``.db3`` file, or those in its folder)."""
    files = sorted(path.glob("*.db3")) if path.is_dir() else [path]
    ok = all(f.is_file() and f.open("rb").read(len(SQLITE_MAGIC)) == SQLITE_MAGIC for f in files)
    return files if ok else []


def _read_ros1(path: Path, decoder: mcap.Decoder, skipped: SkipReport, meta: dict[str, Any],
               path_s: str) -> list[mcap.Channel] | None:
    """A ROS 1 bag's channels, the wanted ones decoded, by the compiled record scan
    (:mod:`gpsdr_cli.io.rosbag1_walk`); None when the bag needs rosbags' reader."""
    import mmap

    from . import rosbag1_walk

    with open(path, "rb") as f:
        data = mmap.mmap(f.fileno(), 0, access=mmap.ACCESS_READ)
    channels: dict[int, mcap.Channel] = {}
    pending = []
    try:
        for records, conn, t_ns, off, size in rosbag1_walk.walk(data):
            for q in np.flatnonzero(conn < 0).tolist():  # connection records
                cid, topic, msgtype = rosbag1_walk.connection(records, int(t_ns[q]), int(off[q]),
                                                              int(size[q]))
                if cid not in channels:
                    # ROS 1 type names (pkg/Type) map like the ROS 2 spelling
                    channels[cid] = mcap.new_channel(cid, topic, "ros1", msgtype, "", b"")
            msg = conn >= 0
            if msg.any():
                pending.append((records, conn[msg], t_ns[msg], off[msg], size[msg]))
    except rosbag1_walk.Unsupported:
        return None
    except (ValueError, KeyError, OSError, EOFError, RuntimeError, struct.error) as err:
        skipped.add("ROS bag damaged (rest of it unread)", path_s)
        meta.setdefault("damage", []).append(str(err))
    for records, conn, t_ns, off, size in pending:
        npbuf = np.frombuffer(records, np.uint8)
        for cid in np.unique(conn).tolist():
            chan = channels.get(cid)
            sel = conn == cid
            if chan is None:
                skipped.add("ROS bag message on an undeclared connection", f"{path_s}: conn {cid}",
                            int(sel.sum()))
                continue
            decoder.on_messages(chan, records, npbuf, t_ns[sel], off[sel], size[sel])
    meta["storage"] = "ROS 1 chunks (compiled record scan)"
    return list(channels.values())


def _compressed(path: Path) -> bool:
    """A ROS 2 bag folder whose metadata.yaml names a compression mode."""
    import re

    meta = path / "metadata.yaml" if path.is_dir() else None
    if meta is None or not meta.is_file():
        return False
    m = re.search(r"compression_mode:\s*['\"]?(\w*)", meta.read_text("utf-8", "replace"))
    return bool(m and m.group(1) and m.group(1).lower() != "none")


#: Rows per query on ``messages``: keeps the concatenated blob well under SQLite's
#: 1 GB value limit for the small message types gpsdr reads.
_SQL_CHUNK_ROWS = 500_000

# One query per chunk of the wanted topics' messages, in id (= insertion) order: the
# blobs concatenated, and per message its log time, size and topic as fixed-width hex,
# so no Python object is made per message.  The ORDER BY + LIMIT subquery is a
# co-routine the aggregates consume in its order (SQLite does not flatten it).
_SQL_CHUNK = (
    "SELECT CAST(group_concat(data, '') AS BLOB), "
    "group_concat(printf('%016x%016x%08x', timestamp, topic_id, length(data)), ''), "
    "count(*), max(id) FROM (SELECT id, topic_id, timestamp, data FROM messages "
    "WHERE topic_id IN ({ids}) AND id > ? ORDER BY id LIMIT ?)")
_SQL_ROW = np.dtype([("t_ns", ">i8"), ("topic", ">i8"), ("size", ">u4")])


def _message_chunks(con: Any, tids: list[int]) -> Any:
    """(blob, log times ns, topic ids, sizes) per chunk of the messages of ``tids``."""
    import apsw

    sql = _SQL_CHUNK.format(ids=",".join(str(int(t)) for t in tids))
    last = -(1 << 63)
    while True:
        try:
            (blob, rows_hex, n, last_id), = con.execute(sql, (last, _SQL_CHUNK_ROWS))
        except apsw.TooBigError:  # messages too large to concatenate: one row at a time
            yield _rows(con, tids, last)
            return
        if not n:
            return
        rows = np.frombuffer(bytes.fromhex(rows_hex), _SQL_ROW)
        yield (blob or b"", rows["t_ns"].astype(np.int64), rows["topic"].astype(np.int64),
               rows["size"].astype(np.int64))
        if n < _SQL_CHUNK_ROWS:
            return
        last = last_id


def _rows(con: Any, tids: list[int], after: int) -> tuple[bytes, np.ndarray, np.ndarray,
                                                            np.ndarray]:
    rows = con.execute(f"SELECT timestamp, topic_id, data FROM messages WHERE topic_id IN "
                       f"({','.join(str(int(t)) for t in tids)}) AND id > ? ORDER BY id",
                       (after,)).fetchall()
    t_ns, topic, blobs = zip(*rows, strict=True) if rows else ((), (), ())
    return (b"".join(blobs), np.array(t_ns, np.int64), np.array(topic, np.int64),
            np.fromiter(map(len, blobs), np.int64, len(blobs)))


def _read_sqlite(files: list[Path], decoder: mcap.Decoder) -> list[mcap.Channel]:
    """A ROS 2 SQLite bag's channels from its ``topics`` table, the wanted ones decoded
    from their rows of ``messages`` fetched by a few aggregate queries (rosbags would
    take a Python step per message)."""
    # apsw (SQLite's own Python binding, which rosbags uses) bundles a recent SQLite
    import apsw

    channels: dict[str, mcap.Channel] = {}
    for f in files:
        con = apsw.Connection(str(f), flags=apsw.SQLITE_OPEN_READONLY)
        try:
            # map the file rather than copy each page through SQLite's page cache
            con.execute(f"PRAGMA mmap_size = {1 << 40}")
            topics = list(con.execute(
                "SELECT id, name, type, serialization_format FROM topics ORDER BY id"))
            wanted: dict[int, mcap.Channel] = {}
            unwanted: dict[int, mcap.Channel] = {}
            for tid, name, msgtype, fmt in topics:
                chan = channels.get(name)
                if chan is None:
                    enc = "cdr" if fmt in ("cdr", "") else str(fmt)
                    chan = channels[name] = mcap.new_channel(len(channels) + 1, name, enc,
                                                              msgtype, "", b"")
                (wanted if decoder.is_wanted(chan) else unwanted)[int(tid)] = chan
            for buf, t_ns, topic, sizes in _message_chunks(con, sorted(wanted)) if wanted else ():
                off = np.zeros(len(sizes), np.int64)
                np.cumsum(sizes[:-1], out=off[1:])
                npbuf = np.frombuffer(buf, np.uint8) if buf else np.zeros(1, np.uint8)
                for tid in np.unique(topic).tolist():
                    sel = topic == tid
                    decoder.on_messages(wanted[tid], buf, npbuf, t_ns[sel], off[sel], sizes[sel])
            if unwanted:
                counts = dict(con.execute(
                    "SELECT topic_id, COUNT(*) FROM messages GROUP BY topic_id"))
                for tid, chan in unwanted.items():
                    chan.n_msgs += int(counts.get(tid, 0))
        finally:
            con.close()
    return list(channels.values())


def _read_rosbags(path: Path, ros1: bool, decoder: mcap.Decoder, skipped: SkipReport,
                  meta: dict[str, Any], path_s: str, errors: tuple) -> list[mcap.Channel]:
    """Any bag rosbags opens (compressed ROS 2 bags, MCAP storage, other chunk codecs)."""
    if ros1:
        from rosbags.rosbag1 import Reader
    else:
        from rosbags.rosbag2 import Reader
    try:
        reader = Reader(path)
        reader.open()
    except errors as err:
        raise InputError(path_s, f"cannot open as a ROS bag: {type(err).__name__}: {err} "
                         "(a ROS 1 bag cut short needs `rosbag reindex`)") from err
    try:
        enc = "ros1" if ros1 else "cdr"
        channels = [mcap.new_channel(c.id, c.topic, enc, c.msgtype, "", b"")
                    for c in reader.connections]
        by_id = {c.id: c for c in channels}
        want = {c.id for c in channels if decoder.is_wanted(c)}
        for conn in reader.connections:
            if conn.id not in want:
                by_id[conn.id].n_msgs = int(conn.msgcount)
        raw: dict[int, list[bytes]] = {cid: [] for cid in want}
        log: dict[int, list[int]] = {cid: [] for cid in want}
        try:
            for conn, t, data in reader.messages(
                    connections=[c for c in reader.connections if c.id in want]):
                raw[conn.id].append(bytes(data))
                log[conn.id].append(t)
        except errors as err:  # damage past the index: keep what was read
            skipped.add("ROS bag damaged (rest of it unread)", path_s)
            meta.setdefault("damage", []).append(f"{type(err).__name__}: {err}")
    finally:
        reader.close()
    for cid in want:
        msgs = raw[cid]
        if not msgs:
            continue
        sizes = np.fromiter(map(len, msgs), np.int64, len(msgs))
        buf = b"".join(msgs)
        off = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
        decoder.on_messages(by_id[cid], buf, np.frombuffer(buf, np.uint8), np.asarray(
            log[cid], np.int64), off, sizes)
    meta["storage"] = "rosbags reader"
    return channels


def _sha256(path: Path) -> str:
    h = hashlib.sha256()
    files = sorted(p for p in path.iterdir() if p.is_file()) if path.is_dir() else [path]
    for f in files:
        with open(f, "rb") as fh:
            for block in iter(lambda fh=fh: fh.read(1 << 20), b""):
                h.update(block)
    return h.hexdigest()


def read_rosbag(path: str | Path, *, topics: dict[str, str] | None = None,
                use_log_time: bool = False, date: dt.date | None = None) -> Drive:
    """Read GNSS, gyro, odometer and accelerometer streams from a ROS 1 or ROS 2 bag."""
    path_s = str(path)
    p = Path(path)
    if not p.exists():
        raise InputError(path_s, "no such file or folder")
    topics, wanted = mcap.check_topics(path_s, topics)
    # hashlib drops the GIL on big blocks: the checksum runs beside the reading
    from concurrent.futures import ThreadPoolExecutor

    with ThreadPoolExecutor(1) as pool:
        sha = pool.submit(_sha256, p)
        return _read_bag(p, path_s, topics, wanted, use_log_time, date, sha)


def _read_bag(p: Path, path_s: str, topics: dict[str, str], wanted: dict[str, str | None],
              use_log_time: bool, date: dt.date | None, sha: Any) -> Drive:
    """:func:`read_rosbag` once the checksum (the future ``sha``) is under way."""
    decoder = mcap.Decoder(path_s, wanted)
    errors = _damage_errors()
    skipped = SkipReport()
    meta: dict[str, Any] = {}
    ros1 = p.is_file() and p.open("rb").read(len(ROSBAG1_MAGIC)) == ROSBAG1_MAGIC
    channels = None
    if ros1:
        channels = _read_ros1(p, decoder, skipped, meta, path_s)
    else:
        dbs = [] if _compressed(p) else _sqlite_files(p)
        if dbs:
            try:
                channels = _read_sqlite(dbs, decoder)
                meta["storage"] = "SQLite (queried directly)"
            except errors as err:
                raise InputError(path_s, f"cannot read as a ROS 2 SQLite bag: "
                                 f"{type(err).__name__}: {err}") from err
    if channels is None:
        decoder = mcap.Decoder(path_s, wanted)
        channels = _read_rosbags(p, ros1, decoder, skipped, meta, path_s, errors)
    meta["channels"] = [{"topic": c.topic, "schema": c.schema_name, "encoding": c.encoding,
                         "messages": c.n_msgs} for c in channels]
    meta["format"] = "ROS 1 bag" if ros1 else "ROS 2 bag"
    meta["messages"] = int(sum(c.n_msgs for c in channels))
    warnings = [f"{path_s}: {d}; read up to there" for d in meta.get("damage", [])]
    drive = mcap.drive_from_channels(path_s, sha.result(), channels, topics=topics, wanted=wanted,
                                     use_log_time=use_log_time, date=date, skipped=skipped,
                                     warnings=warnings, meta=meta)
    drive.meta["rosbag"] = meta
    return drive
