"""``gpsdr extract``: the streams gpsdr reads from logs, as plain tables.

One table per stream, rows in the order the readers returned them (not sorted or
de-duplicated: that is what the other commands' alignment step does, and counts):

- ``gnss``: time, lat, lon, alt, fix_quality, n_sats, hdop, pdop, vdop, sigma_e, sigma_n,
  speed, course_deg
- ``gyro``: time, yaw_rate
- ``odo``: time, speed
- ``accel``: time, accel_mps2

``time`` is timestamp[ns, UTC]; units and meanings are in :data:`COLUMNS` and go into
the Parquet field metadata.  Unknown values (NaN in a :class:`Drive`, ``n_sats`` -1)
are nulls.  Inputs are read by :func:`gpsdr_cli.io.readers.read_drive`, so every
format it reads works here; several logs merge as in ``gpsdr fuse`` (the first file
giving a stream supplies it).

Output names: with one stream (``--stream``, or a drive holding one) the table is
written exactly to ``OUT``; with several, ``OUT.parquet`` becomes ``OUT.gnss.parquet``,
``OUT.gyro.parquet``, ... (the stream name before the suffix), CSV alike.  ``-`` is CSV
on stdout and takes one stream.  Every file is written atomically.
"""

from __future__ import annotations

import datetime as dt
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd

from ..config import Params
from ..errors import NoDataError, UsageError
from .drive import Drive

STREAMS = ("gnss", "gyro", "odo", "accel")

#: stream -> column -> "unit, meaning" (Parquet field metadata: unit before the comma).
COLUMNS: dict[str, dict[str, str]] = {
    "gnss": {
        "time": "UTC timestamp, ns, the receiver's fix time",
        "lat": "deg, WGS84 latitude",
        "lon": "deg, WGS84 longitude",
        "alt": "m, height above the WGS84 ellipsoid (MSL where the log has no geoid separation)",
        "fix_quality": "code, NMEA GGA fix quality: 0 no fix, 1 autonomous, 2 DGPS/SBAS, "
                       "4 RTK fixed, 5 RTK float, 6 dead reckoning",
        "n_sats": "count, satellites used",
        "hdop": "1, horizontal dilution of precision",
        "pdop": "1, position dilution of precision",
        "vdop": "1, vertical dilution of precision",
        "sigma_e": "m, 1-sigma east error reported by the receiver",
        "sigma_n": "m, 1-sigma north error reported by the receiver",
        "speed": "m/s, ground speed",
        "course_deg": "deg, course over ground clockwise from true north",
    },
    "gyro": {"time": "UTC timestamp, ns",
             "yaw_rate": "rad/s, yaw rate about the vehicle's up axis, counter-clockwise positive"},
    "odo": {"time": "UTC timestamp, ns", "speed": "m/s, vehicle speed along its forward axis"},
    "accel": {"time": "UTC timestamp, ns",
              "accel_mps2": "m/s^2, specific force along the vehicle's forward axis"},
}


@dataclass
class Extracted:
    """What :func:`extract` wrote: files per stream, record counts, the drive's report."""

    files: dict[str, str] = field(default_factory=dict)
    records: dict[str, int] = field(default_factory=dict)
    drive: Drive | None = None


def _time(t_ns: np.ndarray) -> pd.Series:
    return pd.Series(pd.to_datetime(np.asarray(t_ns, np.int64), unit="ns", utc=True))


def stream_table(drive: Drive, stream: str) -> pd.DataFrame | None:
    """The table of one stream of ``drive`` (None when the drive lacks it)."""
    s = getattr(drive, stream)
    if s is None:
        return None
    if stream == "gnss":
        n_sats = pd.array(np.asarray(s.n_sats, np.int16), dtype="Int16")
        n_sats[np.asarray(s.n_sats) < 0] = pd.NA
        return pd.DataFrame({
            "time": _time(s.t_ns), "lat": s.lat_deg, "lon": s.lon_deg, "alt": s.alt_m,
            "fix_quality": np.asarray(s.fix_quality, np.int8), "n_sats": n_sats,
            "hdop": s.hdop, "pdop": s.pdop, "vdop": s.vdop, "sigma_e": s.sigma_e_m,
            "sigma_n": s.sigma_n_m, "speed": s.speed_mps, "course_deg": s.course_deg})
    if stream == "gyro":
        return pd.DataFrame({"time": _time(s.t_ns), "yaw_rate": s.yaw_rate_radps})
    if stream == "odo":
        return pd.DataFrame({"time": _time(s.t_ns), "speed": s.speed_mps})
    return pd.DataFrame({"time": _time(s.t_ns), "accel_mps2": s.accel_mps2})


def _csv_stream(path: str, params: Params) -> str:
    """'gyro' or 'odo': which stream a CSV log holds, told by its header (as ``gpsdr info``)."""
    from ..errors import InputError

    with open(path, "rb") as fh:
        header = fh.readline().decode("utf-8", "replace").lstrip("\ufeff")
    cols = {c.strip().lower() for c in header.replace(";", ",").replace("\t", ",").split(",")}
    if params["gyro"]["column"].lower() in cols:
        return "gyro"
    if cols & ({"speed", "distance", "ticks", params["odo"]["column"].lower()} - {""}):
        return "odo"
    raise InputError(path, f"line 1: CSV header {header.strip()!r} is neither a gyro log "
                           f"({params['gyro']['column']}) nor an odometer log (speed, distance, "
                           "ticks); extract reads logs, not reference tracks", line=1)


def read_logs(paths: list[str], params: Params, *, topics: dict[str, str] | None = None,
              date: dt.date | None = None, use_log_time: bool = False) -> Drive:
    """Read and merge the logs like ``gpsdr fuse``: CSVs by header as the gyro/odometer
    files, the first NMEA/RTKLIB log as the GNSS file, the first other log as LOG; further
    logs add only the streams still missing (the first giving a stream wins)."""
    from .readers import read_drive, sniff

    if not paths:
        raise UsageError("no input: give one or more LOG files")
    csv: dict[str, str] = {}
    gps: str | None = None
    others: list[str] = []
    for p in paths:
        kind = sniff(p)
        if kind == "parquet":
            raise UsageError(f"{p}: a Parquet file is an output of gpsdr, not a log to extract")
        if kind == "csv":
            stream = _csv_stream(p, params)
            if stream in csv:
                raise UsageError(f"{p}: a second {stream} CSV (the first: {csv[stream]}); "
                                 "give one per stream")
            csv[stream] = p
        elif kind in ("nmea", "rtklib") and gps is None:
            gps = p
        else:
            others.append(p)
    kw = {"params": params, "topics": topics, "date": date, "use_log_time": use_log_time}
    drive = read_drive(others[0] if others else None, gps=gps, gyro=csv.get("gyro"),
                       odo=csv.get("odo"), **kw)
    for p in others[1:]:
        part = read_drive(p, **kw)
        unused = [s for s in STREAMS if getattr(part, s) is not None
                  and getattr(drive, s) is not None]
        if unused:
            drive.meta.setdefault("warnings", []).append(
                f"{p}: its {', '.join(unused)} not used (an earlier input gives them)")
        drive.merge(part)
    return drive


def output_paths(out: str, streams: list[str], one: bool) -> dict[str, str]:
    """Where each stream goes: ``out`` itself for one stream, else ``stem.STREAM.suffix``."""
    if one or len(streams) == 1:
        return {streams[0]: out}
    if out == "-":
        raise UsageError(f"-o - writes one table, and the inputs hold {len(streams)} streams "
                         f"({', '.join(streams)}): give --stream")
    p = Path(out)
    return {s: str(p.with_name(f"{p.stem}.{s}{p.suffix}")) for s in streams}


def output_format(out: str) -> str:
    """'parquet' or 'csv' by the output's suffix (``-``: csv)."""
    if out == "-":
        return "csv"
    suffix = Path(out).suffix.lower()
    if suffix in (".parquet", ".pq"):
        return "parquet"
    if suffix in (".csv", ".txt"):
        return "csv"
    raise UsageError(f"{out}: cannot tell the format from the suffix {suffix or '(none)'!r}; "
                     "name the output .parquet or .csv (or - for CSV on stdout)")


def extract(paths: list[str], out: str, params: Params, *, stream: str | None = None,
            topics: dict[str, str] | None = None, date: dt.date | None = None,
            use_log_time: bool = False) -> Extracted:
    """Read ``paths`` and write one table per stream (see the module docstring)."""
    from .parquet import write_table

    if stream is not None and stream not in STREAMS:
        raise UsageError(f"unknown stream {stream!r}; choose one of {', '.join(STREAMS)}")
    fmt = output_format(out)
    drive = read_logs(list(paths), params, topics=topics, date=date, use_log_time=use_log_time)
    present = [s for s in STREAMS if getattr(drive, s) is not None]
    wanted = [stream] if stream is not None else present
    if stream is not None and stream not in present:
        raise NoDataError(", ".join(paths), f"no {stream} stream in the input (it holds "
                                            f"{', '.join(present) or 'nothing'})")
    targets = output_paths(out, wanted, stream is not None)
    ins = {str(Path(p).resolve()) for p in paths}
    for target in targets.values():
        if target != "-" and str(Path(target).resolve()) in ins:
            raise UsageError(f"{target}: refusing to overwrite an input file; give another -o")
    result = Extracted(drive=drive)
    sources = "; ".join(f"{s.path} sha256={s.sha256}" for s in drive.sources)
    for s in wanted:
        df = stream_table(drive, s)
        if df is None:  # not present: only an explicit --stream can ask, refused above
            continue
        write_table(df, targets[s], units=COLUMNS[s], fmt=fmt,
                    metadata={"gpsdr.stream": s, "gpsdr.inputs": sources})
        result.files[s] = targets[s]
        result.records[s] = len(df)
    return result
