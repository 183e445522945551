"""ROS 1 ``.bag`` and ROS 2 bag (``.db3`` SQLite file or bag folder) reader, through ``rosbags``.

The same topic and schema rules as MCAP (:mod:`gpsdr_cli.io.mcap`): NavSatFix and
``nmea_msgs/Sentence`` as GNSS, Imu ``angular_velocity.z`` as the gyro and its
``linear_acceleration.x`` as the forward accelerometer, Odometry / TwistStamped /
TwistWithCovarianceStamped ``linear.x`` as the odometer, chosen per stream by the
channel with the most usable messages unless a topic override names one.  The
mapping to a :class:`Drive` is the MCAP module's (:func:`mcap.drive_from_channels`).

``rosbags`` (its rosbag1 / rosbag2 readers, chosen by the file's magic) opens the container: ROS 1 bag records and index, ROS 2
SQLite (or MCAP-storage) bags, and hands over each message's raw bytes with its
log time.  Its deserialiser builds a Python object per message, so it is not used:
the raw bytes of each wanted connection are concatenated and decoded in one batch
by the vectorised fixed-layout decoder of :mod:`gpsdr_cli.io.ros2_fast` (CDR for
ROS 2, the ROS 1 serialisation for ``.bag``), the one MCAP uses.  A message that
decoder declines is counted as undecodable.  Times are the header stamps (int64 ns
UTC; ``use_log_time`` takes the bag's log times; a zero stamp falls back to it).
"""

from __future__ import annotations

import datetime as dt
import hashlib
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

    from rosbags.rosbag1 import ReaderError as Reader1Error
    from rosbags.rosbag2 import ReaderError as Reader2Error

    return (Reader1Error, Reader2Error, sqlite3.Error, OSError, struct.error, ValueError,
            KeyError, IndexError, EOFError)


def _sqlite_files(path: Path) -> list[Path]:
    """The SQLite storage files of a ROS 2 bag (a ``.db3`` file, or those in its folder)."""
    files = sorted(path.glob("*.db3")) if path.is_dir() else [path]
    ok = all(f.is_file() and f.open("rb").read(len(SQLITE_MAGIC)) == SQLITE_MAGIC for f in files)
    return files if ok else []


def _query_sqlite(files: list[Path], ids: dict[str, int], raw: dict[int, list[bytes]],
                  log: dict[int, list[int]]) -> None:
    """The wanted topics' (log time, data) rows straight from rosbag2's ``messages`` table:
    one query per file instead of a Python step per message through rosbags."""
    import sqlite3

    for f in files:
        con = sqlite3.connect(f"file:{f}?mode=ro", uri=True)
        try:
            tid = {i: ids[name] for i, name in con.execute("SELECT id, name FROM topics")
                   if name in ids}
            if not tid:
                continue
            marks = ",".join("?" * len(tid))
            rows = con.execute(f"SELECT topic_id, timestamp, data FROM messages "
                               f"WHERE topic_id IN ({marks})", tuple(tid)).fetchall()
            for db_id, t, data in rows:
                cid = tid[db_id]
                log[cid].append(t)
                raw[cid].append(data)
        finally:
            con.close()


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
    decoder = mcap._Decoder(path_s, wanted)
    _DAMAGE = _damage_errors()
    skipped = SkipReport()
    meta: dict[str, Any] = {}
    ros1 = p.is_file() and p.open("rb").read(len(ROSBAG1_MAGIC)) == ROSBAG1_MAGIC
    try:
        if ros1:
            from rosbags.rosbag1 import Reader
        else:
            from rosbags.rosbag2 import Reader
        reader = Reader(p)
        reader.open()
    except _DAMAGE as err:
        raise InputError(path_s, f"cannot open as a ROS bag: {type(err).__name__}: {err} "
                         "(a ROS 1 bag cut short needs `rosbag reindex`)") from err
    try:
        channels: list[mcap._Channel] = []
        for conn in reader.connections:
            enc = "ros1" if ros1 else "cdr"
            chan = mcap._new_channel(conn.id, conn.topic, enc, conn.msgtype, "", b"")
            channels.append(chan)
        want = [c for c in channels if decoder.is_wanted(c)]
        by_id = {c.id: c for c in want}
        conns = [conn for conn in reader.connections if conn.id in by_id]
        raw: dict[int, list[bytes]] = {c.id: [] for c in want}
        log: dict[int, list[int]] = {c.id: [] for c in want}
        dbs = [] if ros1 or reader.compression_mode else _sqlite_files(p)
        try:
            if dbs:
                meta["storage"] = "sqlite3 (queried directly)"
                _query_sqlite(dbs, {c.topic: c.id for c in want}, raw, log)
            else:
                for conn, t, data in reader.messages(connections=conns):
                    raw[conn.id].append(bytes(data))
                    log[conn.id].append(t)
        except _DAMAGE as err:  # damage past the index: keep what was read
            skipped.add("ROS bag damaged (rest of it unread)", path_s)
            meta.setdefault("damage", []).append(f"{type(err).__name__}: {err}")
        for chan in channels:
            conn_count = next(c.msgcount for c in reader.connections if c.id == chan.id)
            if chan.id not in by_id:
                chan.n_msgs = int(conn_count)
                continue
            msgs = raw[chan.id]
            if not msgs:
                continue
            sizes = np.fromiter((len(m) for m in msgs), np.int64, len(msgs))
            buf = b"".join(msgs)
            off = np.concatenate([[0], np.cumsum(sizes)[:-1]]).astype(np.int64)
            npbuf = np.frombuffer(buf, np.uint8) if buf else np.zeros(1, np.uint8)
            decoder.on_messages(chan, buf, npbuf, np.asarray(log[chan.id], np.int64), off, sizes)
        meta["channels"] = [{"topic": c.topic, "schema": c.schema_name, "encoding": c.encoding,
                             "messages": c.n_msgs} for c in channels]
        meta["format"] = "ROS 1 bag" if ros1 else "ROS 2 bag"
        meta["messages"] = int(sum(c.n_msgs for c in channels))
    finally:
        reader.close()
    warnings = [f"{path_s}: {d}; read up to there" for d in meta.get("damage", [])]
    drive = mcap.drive_from_channels(path_s, _sha256(p), channels, topics=topics, wanted=wanted,
                                     use_log_time=use_log_time, date=date, skipped=skipped,
                                     warnings=warnings, meta=meta)
    drive.meta["rosbag"] = meta
    return drive
