"""Time to export a one-hour 100 Hz track (360 k rows) to each format, decimated to 1 Hz and full.

Usage: python benchmarks/export.py [--rows N] [--gpxpy]

The track is synthesised (a 10 m/s drive round a 500 m circle, every track column filled,
a GNSS fix every 10th row of which one in fifty rejected) and written with gpsdr's own
writer, so its file is a real GeoParquet track.  ``--gpxpy`` also times gpxpy's object
model on the full track (the alternative the GPX writer was measured against).
Targets: <= 2 s decimated, <= 10 s full.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import pandas as pd

from gpsdr_cli.conventions import TRACK_COLUMNS, TRACK_EXTRA_COLUMNS
from gpsdr_cli.geodesy import LocalFrame
from gpsdr_cli.io.export import ExportOptions, export_track
from gpsdr_cli.io.parquet import read_track, write_table

FORMATS = ("gpx", "kml", "geojson", "csv", "mcap")


def synthetic_track(rows: int, rate_hz: float = 100.0) -> tuple[pd.DataFrame, dict[str, str]]:
    rng = np.random.default_rng(1)
    frame = LocalFrame.centred_on(52.52, 13.405)
    t = np.arange(rows) / rate_hz
    ang = 10.0 * t / 500.0
    e, n = 500.0 * np.sin(ang), 500.0 * (1 - np.cos(ang))
    lat, lon = frame.inverse(e, n)
    v_e, v_n = 10.0 * np.cos(ang), 10.0 * np.sin(ang)
    fix = np.arange(rows) % 10 == 0
    used = fix & (rng.random(rows) > 0.02)
    df = pd.DataFrame({
        "time": pd.to_datetime(1_780_000_000 * 10**9 + np.round(t * 1e9).astype(np.int64),
                               unit="ns", utc=True),
        "lat": lat, "lon": lon, "e": e, "n": n, "v_e": v_e, "v_n": v_n,
        "speed": np.hypot(v_e, v_n), "heading_deg": np.degrees(np.arctan2(v_e, v_n)) % 360,
        "sigma_e": rng.uniform(0.3, 2, rows), "sigma_n": rng.uniform(0.3, 2, rows),
        "gnss_used": used, "pdop": np.full(rows, 1.6),
        "gnss_e": np.where(fix, e + rng.normal(0, 1, rows), np.nan),
        "gnss_n": np.where(fix, n + rng.normal(0, 1, rows), np.nan),
        "gnss_rejected": fix & ~used, "gnss_outage": np.zeros(rows, bool),
        "static": np.zeros(rows, bool), "nis": np.where(fix, 1.0, np.nan),
    })
    meta = {"filter": "aekf", **{f"frame.{k}": v for k, v in frame.describe().items()}}
    return df, meta


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rows", type=int, default=360_000)
    ap.add_argument("--gpxpy", action="store_true")
    args = ap.parse_args()
    df, meta = synthetic_track(args.rows)
    with tempfile.TemporaryDirectory() as tmp:
        track_path = Path(tmp) / "hour.parquet"
        t0 = time.perf_counter()
        write_table(df, track_path, metadata=meta, units={**TRACK_COLUMNS, **TRACK_EXTRA_COLUMNS})
        t_write = time.perf_counter() - t0
        print(f"track: {args.rows} rows; GeoParquet write {t_write:.2f} s, "
              f"{track_path.stat().st_size / 1e6:.1f} MB")
        print("wall seconds (CPU seconds of this process in brackets: the machine may be shared)")
        print(f"{'format':8} {'1 Hz s':>14} {'1 Hz MB':>8} {'full s':>14} {'full MB':>8}")
        for fmt in FORMATS:
            cells = []
            for every in (1.0, None):
                out = Path(tmp) / f"hour.{fmt}"
                t0, c0 = time.perf_counter(), time.process_time()
                track, m = read_track(track_path)  # what `gpsdr export` does: read, then write
                export_track(track, m, out, ExportOptions(every_s=every))
                wall, cpu = time.perf_counter() - t0, time.process_time() - c0
                cells += [f"{wall:.2f} ({cpu:.2f})", out.stat().st_size / 1e6]
            print(f"{fmt:8} {cells[0]:>14} {cells[1]:8.1f} {cells[2]:>14} {cells[3]:8.1f}")
        if args.gpxpy:
            print(f"gpxpy object model, full: {_gpxpy_seconds(df):.2f} s")


def _gpxpy_seconds(df: pd.DataFrame) -> float:
    import gpxpy.gpx as g

    t0 = time.perf_counter()
    gpx = g.GPX()
    seg = g.GPXTrackSegment()
    trk = g.GPXTrack()
    trk.segments.append(seg)
    gpx.tracks.append(trk)
    for la, lo, tm in zip(df.lat.tolist(), df.lon.tolist(), df.time.dt.to_pydatetime(),
                          strict=True):
        seg.points.append(g.GPXTrackPoint(la, lo, time=tm))
    gpx.to_xml(version="1.1")
    return time.perf_counter() - t0


if __name__ == "__main__":
    main()
