"""GeoJSON (RFC 7946) of a fused track: one LineString feature, optionally Point features.

The LineString holds the kept rows' [lon, lat] (or [lon, lat, height_m] where the track
has heights); with ``kepler`` its coordinates are Kepler.gl's trip form
[lon, lat, alt_m, unix_s] (alt 0 where unknown, unix seconds to the millisecond), which
Kepler.gl's Trip layer animates.  ``points`` adds one Point feature per kept row with its
properties: ``time`` (ISO 8601 UTC), ``unix_s``, ``speed_mps``, ``heading_deg``,
``sigma_m`` (horizontal 1-sigma, sqrt(sigma_e^2 + sigma_n^2)), ``sigma_e_m``,
``sigma_n_m``, ``gnss_used``, ``pdop`` and ``quality`` where the track has them (null where
not measured).  Coordinates are rounded to 1e-10 deg (RFC 7946 allows any precision).

The standard library's :mod:`json` writes it: GeoJSON is plain JSON, and the coordinate
arrays go through numpy's ``tolist`` in one call.
"""

from __future__ import annotations

import json
import os
from typing import Any

import numpy as np
import pandas as pd

from ..parquet import atomic_output
from .text import DEG_DECIMALS, iso_times, nullable, time_ns


def _floats(track: pd.DataFrame, name: str, decimals: int) -> list[float | None]:
    if name not in track.columns:
        return [None] * len(track)
    return nullable(track[name].to_numpy(dtype=float, na_value=np.nan), decimals)


def line_coordinates(track: pd.DataFrame, kepler: bool = False) -> list[list[float]]:
    """[lon, lat(, height)] per row with a position; Kepler: [lon, lat, alt, unix_s]."""
    lon = np.round(track["lon"].to_numpy(dtype=float, na_value=np.nan), DEG_DECIMALS)
    lat = np.round(track["lat"].to_numpy(dtype=float, na_value=np.nan), DEG_DECIMALS)
    keep = np.isfinite(lon) & np.isfinite(lat)
    cols = [lon[keep], lat[keep]]
    height = (track["height_m"].to_numpy(dtype=float, na_value=np.nan)[keep]
              if "height_m" in track.columns else None)
    has_height = height is not None and bool(np.isfinite(height).all())
    if kepler:
        cols.append(np.round(height, 3) if has_height else np.zeros(int(keep.sum())))
        cols.append(np.round(time_ns(track)[keep] / 1e9, 3))
    elif has_height:
        cols.append(np.round(height, 3))
    return np.column_stack(cols).tolist()


def track_geojson(track: pd.DataFrame, *, name: str, points: bool = False,
                  kepler: bool = False) -> dict[str, Any]:
    """The FeatureCollection as a dict (also the payload of the MCAP's foxglove.GeoJSON)."""
    t = time_ns(track)
    when = iso_times(t)
    line = {"type": "Feature",
            "geometry": {"type": "LineString", "coordinates": line_coordinates(track, kepler)},
            "properties": {"name": name, "start_time": when[0], "end_time": when[-1],
                           "rows": len(track)}}
    features: list[dict[str, Any]] = [line]
    if points:
        features.extend(_point_features(track, t, when))
    return {"type": "FeatureCollection", "features": features}


def _point_features(track: pd.DataFrame, t: np.ndarray, when: list[str]) -> list[dict[str, Any]]:
    lon = _floats(track, "lon", DEG_DECIMALS)
    lat = _floats(track, "lat", DEG_DECIMALS)
    sigma = np.hypot(track["sigma_e"].to_numpy(float), track["sigma_n"].to_numpy(float)) \
        if {"sigma_e", "sigma_n"} <= set(track.columns) else np.full(len(track), np.nan)
    props: dict[str, list[Any]] = {
        "time": when,
        "unix_s": np.round(t / 1e9, 3).tolist(),
        "speed_mps": _floats(track, "speed", 3),
        "heading_deg": _floats(track, "heading_deg", 2),
        "sigma_m": nullable(sigma, 3),
        "sigma_e_m": _floats(track, "sigma_e", 3),
        "sigma_n_m": _floats(track, "sigma_n", 3),
    }
    if "gnss_used" in track.columns:
        props["gnss_used"] = track["gnss_used"].to_numpy(bool).tolist()
    if "pdop" in track.columns:
        props["pdop"] = _floats(track, "pdop", 2)
    if "quality" in track.columns:
        q = nullable(track["quality"].to_numpy(dtype=float, na_value=np.nan), 0)
        props["quality"] = [None if x is None else int(x) for x in q]
    keys = list(props)
    out = []
    for k, (x, y) in enumerate(zip(lon, lat, strict=True)):
        if x is None or y is None:
            continue
        out.append({"type": "Feature", "geometry": {"type": "Point", "coordinates": [x, y]},
                    "properties": {key: props[key][k] for key in keys}})
    return out


def write_geojson(track: pd.DataFrame, path: str | os.PathLike, *, name: str,
                  points: bool = False, kepler: bool = False) -> None:
    """Write the FeatureCollection of ``track`` to ``path``, atomically (UTF-8, no NaN)."""
    doc = track_geojson(track, name=name, points=points, kepler=kepler)
    with atomic_output(path) as fh:
        fh.write(json.dumps(doc, allow_nan=False, separators=(",", ":")).encode())
        fh.write(b"\n")
