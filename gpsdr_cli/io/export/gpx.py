"""GPX 1.1 track (``trk/trkseg/trkpt``) of a fused track, with gpsdr's figures as extensions.

Each ``trkpt`` has lat/lon (10 decimals), ``ele`` (from ``height_m``, where the track has
it), ``time`` (UTC, microseconds), ``pdop`` (where known) and, in the namespace
:data:`NAMESPACE` (prefix ``gpsdr``): ``sigma`` (m, horizontal 1-sigma,
sqrt(sigma_e^2 + sigma_n^2)), ``speed`` (m/s), ``course`` (deg clockwise from north),
``quality`` (1 best .. 6 worst, where the track has a ``quality`` column) and
``gnss_used`` (1 where a GNSS fix was applied at this epoch).  Rows without a position
are left out.

Written as text column by column rather than with gpxpy's object model, although gpxpy
is a dependency: building and serialising one ``GPXTrackPoint`` per row does not fit a
100 Hz hour (360 k points) into the 10 s an export may take, this writer does
(docs/decisions/0006-export-writers.md).  The output is read back with ``gpxpy.parse``
in the tests.
"""

from __future__ import annotations

import os

import numpy as np
import pandas as pd

from ... import __version__
from ..parquet import atomic_output
from .text import DEG_DECIMALS, elements, escape, integers, iso_times, numbers, quoteattr, time_ns

#: XML namespace of gpsdr's GPX extensions (a URN: it names, it is not fetched).
NAMESPACE = "urn:gpsdr:gpx:1"


def _column(track: pd.DataFrame, name: str) -> np.ndarray:
    if name not in track.columns:
        return np.full(len(track), np.nan)
    return track[name].to_numpy(dtype=float, na_value=np.nan)


def write_gpx(track: pd.DataFrame, path: str | os.PathLike, *, name: str) -> None:
    """Write ``track`` (time, lat, lon, ...) as one GPX 1.1 track segment, atomically."""
    lat = _column(track, "lat")
    lon = _column(track, "lon")
    keep = np.isfinite(lat) & np.isfinite(lon)
    rows = track[keep]
    n = len(rows)
    lat_s = numbers(lat[keep], DEG_DECIMALS)
    lon_s = numbers(lon[keep], DEG_DECIMALS)
    ele = elements("ele", _column(rows, "height_m"), 3)
    when = iso_times(time_ns(rows))
    pdop = elements("pdop", _column(rows, "pdop"), 2)
    sigma = np.hypot(_column(rows, "sigma_e"), _column(rows, "sigma_n"))
    ext = [elements("gpsdr:sigma", sigma, 3),
           elements("gpsdr:speed", _column(rows, "speed"), 3),
           elements("gpsdr:course", _column(rows, "heading_deg"), 2)]
    if "quality" in rows.columns:
        ext.append(integers("gpsdr:quality", rows["quality"].to_numpy()))
    if "gnss_used" in rows.columns:
        ext.append(integers("gpsdr:gnss_used", rows["gnss_used"].to_numpy(bool)))
    ext_rows = ["".join(parts) for parts in zip(*ext, strict=True)] if ext else [""] * n
    head = ('<?xml version="1.0" encoding="UTF-8"?>\n'
            '<gpx version="1.1" creator=' + quoteattr(f"gpsdr {__version__}")
            + ' xmlns="http://www.topografix.com/GPX/1/1"'
            f' xmlns:gpsdr="{NAMESPACE}"'
            ' xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"'
            ' xsi:schemaLocation="http://www.topografix.com/GPX/1/1'
            ' http://www.topografix.com/GPX/1/1/gpx.xsd">\n'
            f"<metadata><name>{escape(name)}</name></metadata>\n"
            f"<trk><name>{escape(name)}</name><trkseg>\n")
    with atomic_output(path) as fh:
        fh.write(head.encode())
        chunk: list[str] = []
        for la, lo, el, tm, pd_, ex in zip(lat_s, lon_s, ele, when, pdop, ext_rows, strict=True):
            chunk.append(f'<trkpt lat="{la}" lon="{lo}">{el}<time>{tm}</time>{pd_}'
                         + (f"<extensions>{ex}</extensions>" if ex else "") + "</trkpt>\n")
            if len(chunk) >= 50_000:
                fh.write("".join(chunk).encode())
                chunk.clear()
        fh.write("".join(chunk).encode())
        fh.write(b"</trkseg></trk>\n</gpx>\n")
