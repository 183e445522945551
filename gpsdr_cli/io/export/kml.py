"""KML 2.2 of a fused track: a ``gx:Track`` (a ``when`` per ``gx:coord``) and a ``LineString``.

Google Earth plays the ``gx:Track`` with its time slider; the ``LineString`` placemark
draws the whole path in any KML viewer.  Coordinates are lon, lat (10 decimals) and the
height: ``height_m`` with ``altitudeMode`` absolute where the track has it, else 0 and
``clampToGround``.  Rows without a position are left out.

Written as text column by column, as :mod:`.gpx` is and for the same reason (an object per
point costs seconds on a 360 k-point hour); read back with fastkml in the tests.
"""

from __future__ import annotations

import os

import numpy as np
import pandas as pd

from ..parquet import atomic_output
from .text import DEG_DECIMALS, escape, iso_times, numbers, time_ns


def write_kml(track: pd.DataFrame, path: str | os.PathLike, *, name: str) -> None:
    """Write ``track`` (time, lat, lon[, height_m]) as a KML document, atomically."""
    lat = track["lat"].to_numpy(dtype=float, na_value=np.nan)
    lon = track["lon"].to_numpy(dtype=float, na_value=np.nan)
    keep = np.isfinite(lat) & np.isfinite(lon)
    rows = track[keep]
    lat_s = numbers(lat[keep], DEG_DECIMALS)
    lon_s = numbers(lon[keep], DEG_DECIMALS)
    height = (rows["height_m"].to_numpy(dtype=float, na_value=np.nan)
              if "height_m" in rows.columns else None)
    if height is not None and np.isfinite(height).all():
        alt_s, mode = numbers(height, 3), "absolute"
    else:
        alt_s, mode = ["0"] * len(rows), "clampToGround"
    when = iso_times(time_ns(rows))
    title = escape(name)
    with atomic_output(path) as fh:
        fh.write(('<?xml version="1.0" encoding="UTF-8"?>\n'
                  '<kml xmlns="http://www.opengis.net/kml/2.2"'
                  ' xmlns:gx="http://www.google.com/kml/ext/2.2">\n'
                  f"<Document><name>{title}</name>\n"
                  '<Style id="fused"><LineStyle><color>ff0000ff</color><width>3</width>'
                  "</LineStyle></Style>\n"
                  f"<Placemark><name>{title} (path)</name><styleUrl>#fused</styleUrl>"
                  f"<LineString><tessellate>1</tessellate><altitudeMode>{mode}</altitudeMode>"
                  "<coordinates>\n").encode())
        fh.write("\n".join(f"{lo},{la},{al}" for lo, la, al in zip(lon_s, lat_s, alt_s,
                                                                     strict=True)).encode())
        fh.write(("\n</coordinates></LineString></Placemark>\n"
                  f"<Placemark><name>{title} (timed)</name><styleUrl>#fused</styleUrl>"
                  f"<gx:Track><altitudeMode>{mode}</altitudeMode>\n").encode())
        fh.write("".join(f"<when>{w}</when>\n" for w in when).encode())
        fh.write("".join(f"<gx:coord>{lo} {la} {al}</gx:coord>\n"
                         for lo, la, al in zip(lon_s, lat_s, alt_s, strict=True)).encode())
        fh.write(b"</gx:Track></Placemark>\n</Document>\n</kml>\n")
