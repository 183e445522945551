"""Reference trajectories (the truth error statistics are computed against).

Three forms, told apart by content (see :func:`gpsdr_cli.io.readers.sniff`):

* CSV with a header: ``t`` (UTC POSIX seconds; ``time`` or ``timestamp`` also
  accepted), ``lat``, ``lon`` (degrees WGS84) and optionally ``alt`` (m);
* an NMEA file (its valid fixes, via :func:`gpsdr_cli.io.nmea.read_nmea`);
* a track Parquet as gpsdr writes it (``time`` timestamp or int64 ns, ``lat``,
  ``lon``, optional ``alt``).

The result is sorted by time with duplicate times dropped (both counted in
``skipped``), so it can be interpolated directly; rows with a non-finite or
out-of-range latitude/longitude are dropped and counted too.
"""

from __future__ import annotations

import hashlib
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..conventions import NS_PER_S
from ..errors import InputError, NoDataError
from .csv import _parse_header, _read_table, read_bytes
from .drive import SkipReport


@dataclass
class Reference:
    """A reference trajectory: int64 ns UTC times, WGS84 degrees, metres (NaN = no altitude)."""

    t_ns: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray
    source: str
    sha256: str = ""
    skipped: SkipReport = field(default_factory=SkipReport)

    def __len__(self) -> int:
        return len(self.t_ns)


_T_NAMES = ("t", "time", "timestamp", "t_s")


def _from_csv(path: str, data: bytes, skipped: SkipReport) -> tuple[np.ndarray, ...]:
    names, _, _ = _parse_header(path, data)
    t_col = next((n for n in _T_NAMES if n in names), "t")
    cols = ["lat", "lon"] + (["alt"] if "alt" in names else [])
    t_ns, vals, _, _ = _read_table(path, data, t_col, cols,
                                   ["the reference's t column", "a lat column", "a lon column",
                                    "an alt column"], skipped)
    alt = vals["alt"] if "alt" in vals else np.full(len(t_ns), np.nan)
    return t_ns, vals["lat"], vals["lon"], alt


def _from_parquet(path: str) -> tuple[np.ndarray, ...]:
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        table = pq.read_table(path)
    except (pa.ArrowException, OSError) as err:
        raise InputError(path, f"unreadable Parquet: {err}") from err
    names = table.column_names
    for col in ("lat", "lon"):
        if col not in names:
            raise InputError(path, f"no column {col!r} in the Parquet (columns: {', '.join(names)}); "
                             "expected a track with time, lat, lon")
    if "time" in names:
        tcol = table.column("time")
        if pa.types.is_timestamp(tcol.type):
            tcol = tcol.cast(pa.timestamp("ns", tz=tcol.type.tz))
            t_ns = tcol.cast(pa.int64()).to_numpy(zero_copy_only=False)
        elif pa.types.is_integer(tcol.type):
            t_ns = tcol.to_numpy(zero_copy_only=False).astype(np.int64)
        else:
            t_s = tcol.to_numpy(zero_copy_only=False).astype(np.float64)
            t_ns = np.round(t_s * NS_PER_S).astype(np.int64)
    elif "t" in names:
        t_s = table.column("t").to_numpy(zero_copy_only=False).astype(np.float64)
        t_ns = np.round(t_s * NS_PER_S).astype(np.int64)
    else:
        raise InputError(path, f"no time column in the Parquet (columns: {', '.join(names)}); "
                         "expected time (timestamp) or t (POSIX s)")
    if table.column("time" if "time" in names else "t").null_count:
        raise InputError(path, "null times in the Parquet's time column")

    def f64(name: str) -> np.ndarray:
        return table.column(name).to_numpy(zero_copy_only=False).astype(np.float64)

    alt = f64("alt") if "alt" in names else np.full(len(t_ns), np.nan)
    return t_ns, f64("lat"), f64("lon"), alt


def read_reference(path: str | Path) -> Reference:
    """Read a reference trajectory (CSV, NMEA or track Parquet), sorted by time."""
    from .readers import sniff

    path_s = str(path)
    kind = sniff(path)
    skipped = SkipReport()
    if kind == "nmea":
        from .nmea import read_nmea

        drive = read_nmea(path)
        g = drive.gnss
        skipped.merge(drive.skipped)
        if g is None:
            raise NoDataError(path_s, "no GNSS fixes in the NMEA reference")
        ok = g.valid
        skipped.add("reference epoch without a fix", path_s, int((~ok).sum()))
        t_ns, lat, lon, alt = g.t_ns[ok], g.lat_deg[ok], g.lon_deg[ok], g.alt_m[ok]
        sha = drive.sources[0].sha256 if drive.sources else ""
    elif kind == "parquet":
        t_ns, lat, lon, alt = _from_parquet(path_s)
        sha = hashlib.sha256(read_bytes(path)).hexdigest()
    elif kind == "csv":
        data = read_bytes(path)
        t_ns, lat, lon, alt = _from_csv(path_s, data, skipped)
        sha = hashlib.sha256(data).hexdigest()
    else:
        raise InputError(path_s, f"a {kind.upper()} file cannot be a reference; expected a CSV "
                         "t,lat,lon[,alt], an NMEA file or a track Parquet")
    ok = np.isfinite(lat) & np.isfinite(lon) & (np.abs(lat) <= 90) & (np.abs(lon) <= 180)
    skipped.add("reference row with missing or out-of-range lat/lon", path_s, int((~ok).sum()))
    t_ns, lat, lon, alt = t_ns[ok], lat[ok], lon[ok], alt[ok]
    order = np.argsort(t_ns, kind="stable")
    if np.any(order != np.arange(len(order))):
        t_ns, lat, lon, alt = t_ns[order], lat[order], lon[order], alt[order]
    dup = np.concatenate([[False], np.diff(t_ns) == 0]) if len(t_ns) else np.zeros(0, bool)
    skipped.add("reference row with a duplicate time (dropped)", path_s, int(dup.sum()))
    keep = ~dup
    if not keep.any():
        raise NoDataError(path_s, "no usable reference rows")
    return Reference(t_ns=t_ns[keep], lat_deg=lat[keep], lon_deg=lon[keep],
                     alt_m=np.where(np.isfinite(alt[keep]), alt[keep], np.nan),
                     source=path_s, sha256=sha, skipped=skipped)
