"""Export a fused track to the formats map and robotics tools open: GPX, KML, GeoJSON, CSV, MCAP.

``export_track(track, meta, path, options)`` picks the writer by the output's
suffix (``.gpx``, ``.kml``, ``.geojson``/``.json``, ``.csv``, ``.mcap``).  Every
writer writes atomically (a temporary file in the target's directory, fsync'ed,
then renamed over the target), so a failed or killed export leaves the old file
or none.  Decimation (:func:`decimate`) thins a 100 Hz track for map tools: a
row is kept when at least ``every_s`` seconds *and* ``min_distance_m`` metres
along the track have passed since the last kept row; the first and last rows
are always kept.

Conventions: :mod:`gpsdr_cli.conventions` (time int64 ns UTC, lat/lon degrees
WGS84, sigma_e/sigma_n metres 1-sigma, heading clockwise from north).
"""

from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pandas as pd

from ...errors import InputError, UsageError
from .text import time_ns

#: Output suffix -> format name.
SUFFIXES: dict[str, str] = {".gpx": "gpx", ".kml": "kml", ".geojson": "geojson",
                            ".json": "geojson", ".csv": "csv", ".mcap": "mcap"}

#: Columns a table must have to be exported as a track.
REQUIRED_COLUMNS = ("time", "lat", "lon")


@dataclass(frozen=True)
class ExportOptions:
    """What to write besides the track's positions.

    ``every_s``: keep a row only every this many seconds (None: no time decimation);
    ``min_distance_m``: only every this many metres along the track (None: none);
    ``points``: GeoJSON, add one Point feature per kept row with its properties;
    ``kepler``: GeoJSON, the Kepler.gl trip form (coordinates [lon, lat, alt, unix_s]);
    ``with_input``: MCAP, an input MCAP whose every channel and message is copied beside
    the fused ones; ``name``: the track's name in GPX/KML/GeoJSON.
    """

    every_s: float | None = None
    min_distance_m: float | None = None
    points: bool = False
    kepler: bool = False
    with_input: str | None = None
    name: str = "gpsdr fused track"


def format_of(path: str | os.PathLike) -> str:
    """The export format named by ``path``'s suffix, or a :class:`UsageError` naming them."""
    suffix = Path(path).suffix.lower()
    if suffix not in SUFFIXES:
        known = ", ".join(sorted(set(SUFFIXES)))
        raise UsageError(f"{path}: unknown export format {suffix or '(no suffix)'!r}; "
                         f"give a file ending in one of {known}")
    return SUFFIXES[suffix]


def check_track(track: pd.DataFrame, source: str | os.PathLike | None) -> None:
    """Raise a one-line :class:`InputError` unless ``track`` looks like a gpsdr track."""
    missing = [c for c in REQUIRED_COLUMNS if c not in track.columns]
    if missing:
        raise InputError(source, f"not a gpsdr track: no column {', '.join(missing)} "
                                 "(expected a track Parquet or CSV written by gpsdr fuse)")
    if not isinstance(track["time"].dtype, pd.DatetimeTZDtype):
        raise InputError(source, "not a gpsdr track: column time is not a UTC timestamp")
    if len(track) == 0:
        raise InputError(source, "the track has no rows; nothing to export")
    t = track["time"].to_numpy("datetime64[ns]").view(np.int64)
    back = np.flatnonzero(np.diff(t) < 0)
    if len(back):
        raise InputError(source, f"row {int(back[0]) + 1}: time goes backwards "
                                 f"({track['time'].iloc[back[0] + 1]}); a gpsdr track is "
                                 "time-ordered")


def path_length_m(track: pd.DataFrame) -> np.ndarray:
    """Cumulative horizontal distance along the track, metres (0 at the first row).

    From the local ``e``/``n`` where the track has them; else from lat/lon on a sphere of
    the WGS84 mean radius (equirectangular per step: sub-millimetre error at 100 Hz steps).
    """
    if "e" in track.columns and "n" in track.columns:
        e = track["e"].to_numpy(float)
        n = track["n"].to_numpy(float)
        step = np.hypot(np.diff(e), np.diff(n))
    else:
        lat = np.radians(track["lat"].to_numpy(float))
        lon = np.radians(track["lon"].to_numpy(float))
        mean_lat = 0.5 * (lat[1:] + lat[:-1])
        step = 6_371_008.8 * np.hypot(np.diff(lon) * np.cos(mean_lat), np.diff(lat))
    step = np.where(np.isfinite(step), step, 0.0)  # a row without a position adds nothing
    return np.concatenate([[0.0], np.cumsum(step)])


def decimate(track: pd.DataFrame, every_s: float | None = None,
             min_distance_m: float | None = None) -> pd.DataFrame:
    """Rows at least ``every_s`` s and ``min_distance_m`` m (along the track) apart.

    Greedy from the first row: the next kept row is the first one past both thresholds
    (a binary search per kept row, so the cost is the number of rows kept); the last row
    is kept too, so the track ends where it ended.
    """
    for name, value in (("--every", every_s), ("--min-distance", min_distance_m)):
        if value is not None and not (np.isfinite(value) and value > 0):
            raise UsageError(f"{name} {value}: give a positive number")
    if (every_s is None and min_distance_m is None) or len(track) < 3:
        return track
    t = time_ns(track)
    dist = path_length_m(track) if min_distance_m is not None else None
    step_ns = round(every_s * 1e9) if every_s is not None else 0
    kept = [0]
    k, n = 0, len(track)
    while True:
        nxt = k + 1
        if step_ns:
            nxt = max(nxt, int(np.searchsorted(t, t[k] + step_ns, side="left")))
        if dist is not None:
            nxt = max(nxt, int(np.searchsorted(dist, dist[k] + min_distance_m, side="left")))
        if nxt >= n:
            break
        kept.append(nxt)
        k = nxt
    if kept[-1] != n - 1:
        kept.append(n - 1)
    return track.iloc[np.asarray(kept)].reset_index(drop=True)


def export_track(track: pd.DataFrame, meta: dict[str, str], path: str | os.PathLike,
                 options: ExportOptions | None = None,
                 source: str | os.PathLike | None = None) -> int:
    """Write ``track`` to ``path`` in the format its suffix names; return the rows written.

    ``meta``: the track file's metadata (the local frame places the rejected GNSS fixes in
    the MCAP); ``source``: the track's file name, for error messages.
    """
    opts = options or ExportOptions()
    fmt = format_of(path)
    check_track(track, source)
    if opts.with_input is not None and fmt != "mcap":
        raise UsageError("--with-input copies an input MCAP: the output must end in .mcap")
    if (opts.points or opts.kepler) and fmt != "geojson":
        raise UsageError("--points and --kepler shape a GeoJSON: the output must end in .geojson")
    rows = decimate(track, opts.every_s, opts.min_distance_m)
    if fmt == "gpx":
        from .gpx import write_gpx

        write_gpx(rows, path, name=opts.name)
    elif fmt == "kml":
        from .kml import write_kml

        write_kml(rows, path, name=opts.name)
    elif fmt == "geojson":
        from .geojson import write_geojson

        write_geojson(rows, path, name=opts.name, points=opts.points, kepler=opts.kepler)
    elif fmt == "csv":
        from ...conventions import TRACK_COLUMNS, TRACK_EXTRA_COLUMNS
        from ..parquet import write_table

        units = {**TRACK_COLUMNS, **TRACK_EXTRA_COLUMNS}
        write_table(rows, path, units={k: v for k, v in units.items() if k in rows}, fmt="csv")
    else:
        from .foxglove_mcap import write_mcap

        write_mcap(track, rows, meta, path, with_input=opts.with_input)
    return len(rows)
