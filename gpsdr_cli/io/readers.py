"""Which reader a file needs, and one call that reads a whole drive.

:func:`sniff` decides by content, not by file name: the MCAP magic, the Parquet
magic, the ROS 1 bag and SQLite magics (or a ROS 2 bag folder), checksum-valid UBX
frames (alone or among NMEA lines), an RTKLIB .pos header, NMEA sentences with valid
checksums, else a delimited text table with a header row.  Empty and binary files,
UTF-16 files other than NMEA and NovAtel ASCII logs are an :class:`InputError` naming
the file.
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import hashlib
import re
from collections.abc import Callable
from pathlib import Path

import numpy as np

from ..config import Params
from ..conventions import NS_PER_S
from ..errors import InputError, MissingDateError, NoDataError, UsageError
from .csv import (
    MAX_SPEED_MPS,
    _parse_header,
    read_accel_csv,
    read_gyro_csv,
    read_odo_csv,
    text_problem,
)
from .drive import Drive, stream_source
from .formats import (  # magics only: a reader is imported per format
    MCAP_MAGIC,
    PARQUET_MAGIC,
    ROSBAG1_MAGIC,
    SQLITE_MAGIC,
    UBX_SYNC,
)
from .spikes import accel_spikes, gyro_spikes, odometer_spikes, receiver_velocity_spikes

_HEAD_BYTES = 65536
#: A NovAtel ASCII message at a line start: '#' (or '%' for the short header) + the upper
#: case message name ending in A (BESTPOSA, INSPVASA), header fields, ';' before the data.
_NOVATEL_ASCII = re.compile(rb"(?m)^[#%]([A-Z][A-Z0-9_]*A),[^;\r\n]*;")


#: A line that starts as an NMEA sentence does: '$', an address of 2-6 upper-case letters or
#: digits, a comma.
_NMEA_LINE = re.compile(rb"(?m)^\$[A-Z][A-Z0-9]{1,5},")


def _head(path: str | Path) -> bytes:
    from .csv import read_bytes

    return read_bytes(path, _HEAD_BYTES)


def sniff(path: str | Path) -> str:
    """``"mcap"``, ``"ubx"``, ``"rosbag"``, ``"nmea"``, ``"rtklib"``, ``"csv"`` or
    ``"parquet"``, by the file's first bytes (a ROS 2 bag may be a folder; a ``.pos`` name
    for an RTKLIB solution without a header)."""
    from .nmea import looks_like_nmea

    if Path(path).is_dir() and _is_rosbag2_dir(Path(path)):
        return "rosbag"
    head = _head(path)
    if not head:
        raise InputError(path, "empty file")
    if head.startswith(MCAP_MAGIC):
        return "mcap"
    if head.startswith(PARQUET_MAGIC):
        return "parquet"
    if head.startswith((ROSBAG1_MAGIC, SQLITE_MAGIC)):
        return "rosbag"
    if _looks_like_ubx(path, head):
        return "ubx"
    from .rtklib import looks_like_rtklib

    if looks_like_rtklib(head) or (Path(path).suffix.lower() == ".pos" and b"$" not in head[:4096]):
        return "rtklib"  # an RTKLIB .pos solution (a .pos of NMEA sentences is NMEA)
    problem = text_problem(head)
    if problem and problem.startswith("UTF-16") and not looks_like_nmea(head):
        raise InputError(path, problem)  # UTF-16 NMEA is decoded by the NMEA reader
    if looks_like_nmea(head) or _nmea_after_noise(head, looks_like_nmea):
        return "nmea"
    if problem:
        raise InputError(path, f"{problem}; expected MCAP, a ROS bag, u-blox UBX, NMEA, "
                               "an RTKLIB .pos, CSV or Parquet")
    if b"$GP" in head[:4096] or b"$GN" in head[:4096] or _NMEA_LINE.search(head[:4096]):
        # NMEA whose first sentences are damaged or lack checksums: the NMEA reader counts
        # them and says what it found
        return "nmea"
    novatel = _NOVATEL_ASCII.search(head[:4096])
    if novatel:  # its comma-separated lines would pass for a CSV table
        raise InputError(path, f"NovAtel ASCII log ({novatel.group(1).decode()} messages) is not "
                         "supported; have the receiver log NMEA instead (e.g. LOG COM1 GPGGA "
                         "ONTIME 1 and LOG COM1 GPRMC ONTIME 1) and give that file")
    first = head.split(b"\n", 1)[0].decode("utf-8", "replace").strip()
    if any(d in first for d in (",", ";", "\t")):
        _parse_header(path, head)  # raises when the first line is not a header
        return "csv"
    raise InputError(path, f"unrecognised format (first line {first[:60]!r}); "
                     "expected MCAP, NMEA, CSV with a header row, or Parquet", line=1)


def _looks_like_ubx(path: str | Path, head: bytes) -> bool:
    """UBX frames with valid checksums (two, or one in a ``.ubx`` file or a short head),
    alone or among NMEA lines."""
    if UBX_SYNC not in head:
        return False  # before the import: the UBX reader loads numba
    from .ubx import count_frames

    n = count_frames(head)
    return n >= 2 or (n == 1 and (str(path).lower().endswith(".ubx") or len(head) < 4096))


def _is_rosbag2_dir(path: Path) -> bool:
    return (path / "metadata.yaml").is_file() or any(path.glob("*.db3"))


def _nmea_after_noise(head: bytes, looks_like_nmea) -> bool:
    """NMEA interleaved with binary (e.g. u-blox UBX) may start past the first KB:
    try the first few ``$`` positions in the head."""
    pos = head.find(b"$")
    for _ in range(64):
        if pos < 0:
            return False
        if looks_like_nmea(head[pos:pos + 1024]):
            return True
        pos = head.find(b"$", pos + 1)
    return False


def sha256_file(path: str | Path) -> str:
    """Hex SHA-256 of a file's bytes, read in 1 MB blocks."""
    h = hashlib.sha256()
    try:
        with open(path, "rb") as f:
            for block in iter(lambda: f.read(1 << 20), b""):
                h.update(block)
    except OSError as err:
        raise InputError(path, f"cannot read: {err.strerror or err}") from err
    return h.hexdigest()


def _read_log(path: str | Path, *, role: str, topics: dict[str, str] | None,
              date: dt.date | None, use_log_time: bool, params: Params | None = None) -> Drive:
    kind = sniff(path)
    if kind == "mcap":
        from .mcap import read_mcap

        return read_mcap(path, topics=topics, use_log_time=use_log_time, date=date)
    if kind == "ubx":
        from .ubx import read_ubx

        return read_ubx(path, date=date, ticks_per_m=_ticks_per_m(params))
    if kind == "rosbag":
        from .rosbag import read_rosbag

        return read_rosbag(path, topics=topics, use_log_time=use_log_time, date=date)
    if kind == "nmea":
        from .nmea import read_nmea

        return read_nmea(path, date=date)
    if kind == "rtklib":
        from .rtklib import read_rtklib

        return read_rtklib(path)
    raise UsageError(f"{path}: a {kind.upper()} file cannot be the {role}; "
                     "expected an MCAP, UBX, ROS bag, NMEA or RTKLIB .pos log")


def read_log(path: str | Path, *, params: Params | None = None,
             topics: dict[str, str] | None = None, date: dt.date | None = None,
             use_log_time: bool = False) -> Drive:
    """One log of any kind that holds a drive's streams (MCAP, UBX, ROS bag, NMEA)."""
    return _read_log(path, role="LOG", topics=topics, date=date, use_log_time=use_log_time,
                     params=params)


def _ticks_per_m(params: Params | None) -> float:
    """``[odo] ticks_per_m``: UBX wheel ticks are read with the CSV odometer's option."""
    try:
        return float(params["odo"].get("ticks_per_m", 0.0)) if params is not None else 0.0
    except (KeyError, TypeError, ValueError):
        return 0.0


def _only(drive: Drive, stream: str) -> Drive:
    """Keep one stream of a drive read from an MCAP given for that stream only."""
    for name in ("gnss", "gyro", "odo"):
        if name != stream:
            setattr(drive, name, None)
    for src in drive.sources:
        src.streams = tuple(s for s in src.streams if s == stream)
    return drive


def share_heap_with_arrow() -> None:
    """Make pyarrow allocate from the C heap that numpy uses.

    pyarrow's default pool (mimalloc) keeps the pages of freed CSV tables for
    itself, where numpy cannot reuse them: on a one-hour drive that held ~30 MB
    of peak RSS for nothing (benchmarks/speed.py, peak RSS of ``gpsdr fuse``).
    Arrow's own switch (``ARROW_DEFAULT_MEMORY_POOL=system``) does the same from
    the environment; a user's explicit choice there is kept.
    """
    import os

    if os.environ.get("ARROW_DEFAULT_MEMORY_POOL"):
        return
    import pyarrow as pa

    if pa.default_memory_pool().backend_name != "system":
        pa.set_memory_pool(pa.system_memory_pool())


def _gps_dated_by(read_gps: Callable[[dt.date | None], Drive], dr_parts: list[Drive]) -> Drive | None:
    """The NMEA log read with the UTC date taken from the gyro/odometer records (the day of
    their first stamp, or the day before or after when the fixes' time of day then falls
    more than 12 h from it: a drive across midnight); None without DR records."""
    starts = [int(getattr(p, s).t_ns[0]) for p in dr_parts for s in ("gyro", "odo")
              if getattr(p, s) is not None and len(getattr(p, s).t_ns)]
    if not starts:
        return None
    t0 = min(starts)
    day = dt.datetime.fromtimestamp(t0 / 1e9, dt.UTC).date()
    part = read_gps(day)
    if part.gnss is not None and len(part.gnss.t_ns):
        off_days = round((int(part.gnss.t_ns[0]) - t0) / (86400 * 1e9))
        if off_days:  # the same as reading with the other day: every stamp moves by whole days
            day = day - dt.timedelta(days=off_days)
            part.gnss = dataclasses.replace(
                part.gnss, t_ns=part.gnss.t_ns - off_days * 86400 * NS_PER_S)
    part.meta["date_from_dr"] = day.isoformat()
    return part


def read_drive(log: str | Path | None = None, *, gps: str | Path | None = None,
               gyro: str | Path | None = None, odo: str | Path | None = None, params: Params,
               topics: dict[str, str] | None = None, date: dt.date | None = None,
               use_log_time: bool = False, accel: str | Path | None = None) -> Drive:
    """Read a drive from a LOG (MCAP, UBX, ROS bag or NMEA) and/or separate GNSS, gyro,
    odometer and accelerometer files.

    Streams from ``gps``/``gyro``/``odo`` take precedence over the same stream in
    ``log``; the rest of ``log`` merges in (:meth:`Drive.merge`).  ``gps = '-'``
    reads NMEA from standard input.  A gyro or odometer file may be a CSV
    (options from ``params["gyro"]``/``params["odo"]``) or an MCAP.  ``accel``: a forward
    accelerometer CSV (``t,acc_x``, m/s^2; the gyro's time options), taking precedence over
    an ``acc_x`` column of the gyro CSV.
    """
    if log is None and gps is None and gyro is None and odo is None:
        raise UsageError("no input: give a LOG (MCAP, UBX, ROS bag or NMEA) or --gps/--gyro/--odo files")
    share_heap_with_arrow()
    drive = Drive()
    warnings: list[str] = []

    def add(part: Drive) -> None:
        """Merge ``part``; its sources list only the streams actually taken from it."""
        taken = tuple(s for s in ("gnss", "gyro", "odo", "accel")
                      if getattr(drive, s) is None and getattr(part, s) is not None)
        for src in part.sources:
            src.streams = tuple(s for s in src.streams if s in taken) if src.streams else taken
        warnings.extend(part.meta.get("warnings", []))
        drive.merge(part)

    dr_parts: list[Drive] = []
    for path, stream, reader, section in ((gyro, "gyro", read_gyro_csv, "gyro"),
                                          (odo, "odo", read_odo_csv, "odo")):
        if path is None:
            continue
        if sniff(path) == "mcap":
            from .mcap import read_mcap

            part = _only(read_mcap(path, topics=topics, use_log_time=use_log_time, date=date), stream)
            if getattr(part, stream) is None:
                raise NoDataError(str(path), f"no {stream} messages in the MCAP")
        else:
            part = reader(path, params[section])
        dr_parts.append(part)
    if accel is not None:
        part = read_accel_csv(accel, params["gyro"])
        drive.accel = part.accel
        warnings.extend(part.meta.get("warnings", []))
        drive.skipped.merge(part.skipped)
        drive.sources.extend(part.sources)
    if gps is not None:
        def read_gps(day: dt.date | None) -> Drive:
            if str(gps) == "-":
                from .nmea import read_nmea

                return read_nmea("-", date=day)
            return _only(_read_log(gps, role="GNSS input (--gps)", topics=topics, date=day,
                                   use_log_time=use_log_time, params=params), "gnss")

        try:
            part = read_gps(date)
        except MissingDateError:
            # GGA without RMC/ZDA: the gyro/odometer files carry full UTC stamps
            part = None if str(gps) == "-" else _gps_dated_by(read_gps, dr_parts)  # stdin: read once
            if part is None:
                raise
            warnings.append(f"{gps}: no date in the log; took {part.meta['date_from_dr']} "
                            "from the gyro/odometer time stamps (give --date to override)")
        if part.gnss is None:
            raise NoDataError(str(gps), "no GNSS fixes")
        add(part)
    for part in dr_parts:
        add(part)
    if log is not None:
        add(_read_log(log, role="LOG", topics=topics, date=date, use_log_time=use_log_time,
                      params=params))
    if drive.gnss is None and drive.gyro is None and drive.odo is None:
        names = ", ".join(str(p) for p in (log, gps, gyro, odo) if p is not None)
        raise NoDataError(names, "no GNSS, gyro or odometer data")
    drop_impossible(drive, warnings)
    if warnings:
        drive.meta["warnings"] = warnings
    return drive


#: dead-reckoning readings beyond these are corrupt records, not motion: no road vehicle's
#: wheels turn at 150 m/s, MEMS gyros end at +-2000 deg/s (35 rad/s) and accelerometers at
#: +-16 g.  Read as motion, one odometer speed of 1e308 m/s made every later position
#: infinite.  (stream, its array, limit, unit)
DR_LIMITS = (("gyro", "yaw_rate_radps", 50.0, "rad/s"),
             ("odo", "speed_mps", MAX_SPEED_MPS, "m/s"),
             ("accel", "accel_mps2", 160.0, "m/s^2"))
#: ... and readings that jump off their neighbours further than a vehicle moves (one
#: odometer reading in two hundred at a random 0-40 m/s took ekf/aekf 8-86 m off)
DR_SPIKES = {"gyro": gyro_spikes, "odo": odometer_spikes, "accel": accel_spikes}


def _report_beyond(drive: Drive, warnings: list[str], name: str, bad: np.ndarray, what: str,
                   record: str, left_out: str) -> None:
    """Count the records ``bad`` of stream ``name`` in ``drive.skipped`` as ``what`` (the
    first with its file and ``record`` number: "gyro record 7"), and a warning line when
    they are more than 1 % of the stream (``left_out``: what the line says of them)."""
    source = stream_source(drive, name)
    where = f"{record} {int(np.flatnonzero(bad)[0]) + 1}"
    drive.skipped.add(what, f"{source}: {where}" if source else where, int(bad.sum()))
    if bad.mean() > 0.01:
        warnings.append(f"{source or name}: {int(bad.sum())} of {len(bad)} {left_out} "
                        "(corrupt, or in other units?)")


def drop_impossible(drive: Drive, warnings: list[str]) -> None:
    """Leave out the dead-reckoning records beyond :data:`DR_LIMITS` or off their neighbours
    (:data:`DR_SPIKES`, :mod:`.spikes`), counted in
    ``drive.skipped`` (the first with its file and record number); a warning line when a
    stream loses more than 1 % of its records, and the stream dropped when none is left."""
    for name, field, limit, unit in DR_LIMITS:
        stream = getattr(drive, name)
        if stream is None or not len(stream):
            continue
        v = np.asarray(getattr(stream, field), float)
        bad = np.abs(v) > limit              # NaN stays: the aligner counts non-finite values
        if bad.any():
            _report_beyond(drive, warnings, name, bad, f"{name}: reading beyond {limit:g} {unit}",
                           f"{name} record", f"{name} readings beyond {limit:g} {unit} left out")
        spiky = DR_SPIKES.get(name)
        if spiky is not None:
            jump = spiky(stream.t_ns, np.where(bad, np.nan, v))
            if jump.any():
                _report_beyond(drive, warnings, name, jump,
                               f"{name}: reading off its neighbours beyond what a vehicle does",
                               f"{name} record", f"{name} readings off their neighbours beyond "
                               "what a vehicle does left out")
                bad |= jump
        if not bad.any():
            continue
        keep = ~bad
        if not keep.any():
            setattr(drive, name, None)
            continue
        setattr(drive, name, dataclasses.replace(
            stream, **{f.name: np.asarray(getattr(stream, f.name))[keep]
                       for f in dataclasses.fields(stream)}))
    _drop_impossible_gnss_speed(drive, warnings)


def _drop_impossible_gnss_speed(drive: Drive, warnings: list[str]) -> None:
    """The receiver's speed and course left out (NaN) where the speed is beyond a
    vehicle's, :data:`MAX_SPEED_MPS` (a corrupt RMC/VTG field read 1.6e7 m/s and fkf's
    velocity row, ungated, sent the track to infinity), and where the velocity jumps off
    its neighbours' (:func:`receiver_velocity_spikes`: one fix in twenty with a random speed
    and course took every filter from 0.5 m to 8-180 m); the fix's position stays.
    Counted like :func:`drop_impossible`."""
    g = drive.gnss
    if g is None or not len(g):
        return
    bad = np.abs(np.asarray(g.speed_mps, float)) > MAX_SPEED_MPS
    if bad.any():
        _report_beyond(drive, warnings, "gnss", bad,
                       f"gnss: receiver speed beyond {MAX_SPEED_MPS:g} m/s (speed and course left "
                       "out)", "gnss fix", f"receiver speeds beyond {MAX_SPEED_MPS:g} m/s left out "
                       "with their course")
    speed = np.where(bad, np.nan, g.speed_mps)
    spikes = receiver_velocity_spikes(g.t_ns, speed, g.course_deg)
    if spikes.any():
        _report_beyond(drive, warnings, "gnss", spikes,
                       "gnss: receiver velocity off its neighbours beyond 1 g (speed and course "
                       "left out)", "gnss fix", "receiver velocities off their neighbours "
                       "beyond 1 g left out")
        bad |= spikes
    if bad.any():
        drive.gnss = dataclasses.replace(g, speed_mps=np.where(bad, np.nan, g.speed_mps),
                                         course_deg=np.where(bad, np.nan, g.course_deg))
