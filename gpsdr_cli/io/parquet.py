"""Write and read gpsdr's tables (track, statistics, batch report) as Parquet or CSV.

Parquet via pyarrow: the meaning and unit of every column go into that field's
metadata (``unit``, ``description``), and the run's facts (filter, parameters,
frame, version, inputs with SHA-256) into the file's schema metadata, so a
track file explains itself.  CSV cannot carry metadata; it is for pipes and
spreadsheets.

Writes are atomic: the table goes to a temporary file in the target's
directory, is flushed and fsync'ed, then ``os.replace``d over the target, so a
killed process leaves the old file or none, never half a file.  The path ``-``
means stdout (writing) or stdin (reading).

A table with ``lat`` and ``lon`` columns (a track, the GNSS fixes) is written as
GeoParquet 1.1 (https://geoparquet.org/releases/v1.1.0/): a ``geometry`` column
of WKB points (lon, lat, and ``height_m`` as Z where the table has it; null
where lat/lon are not finite) and the ``geo`` file-metadata key.  ``crs`` is
omitted, which GeoParquet defines as OGC:CRS84 (WGS84, longitude first), the
datum of gpsdr's lat/lon.  No bbox covering column: a track file is one row
group, so the covering would add four columns and filter nothing; the file
``bbox`` is in the metadata.  The WKB is built by hand with numpy (a packed
record array viewed as bytes, one Arrow buffer): it is a 21- or 29-byte
record per point, shapely is not a run-time dependency, and a 360 k-row track
encodes in milliseconds.  Readers here drop the geometry column again, since
it only repeats lat/lon.

Conventions: :mod:`gpsdr_cli.conventions` (``time`` is timestamp[ns, UTC]).
"""

from __future__ import annotations

import contextlib
import io
import json
import os
import sys
import tempfile
from collections.abc import Iterator
from pathlib import Path
from typing import BinaryIO

import numpy as np
import pandas as pd
import pyarrow as pa
import pyarrow.csv as pacsv
import pyarrow.parquet as pq

from ..errors import InputError, UsageError

FORMATS = ("parquet", "csv")
PARQUET_MAGIC = b"PAR1"

#: GeoParquet: the version written, the geometry column, and the optional height column.
GEOPARQUET_VERSION = "1.1.0"
GEOMETRY_COLUMN = "geometry"
HEIGHT_COLUMN = "height_m"

# ISO WKB geometry type codes (OGC 06-103r4 / ISO 13249-3): 1 Point, 1001 Point Z
_WKB_POINT, _WKB_POINT_Z = 1, 1001
_WKB_LITTLE_ENDIAN = 1


def wkb_points(lon_deg: np.ndarray, lat_deg: np.ndarray,
               height_m: np.ndarray | None = None) -> pa.BinaryArray:
    """Little-endian ISO WKB points (x = lon, y = lat [deg], z = height [m]) as an Arrow array.

    Rows whose lon or lat is not finite are null.  Vectorised: one packed record per valid
    row (byte order, uint32 type, float64 x, y[, z]) viewed as a single data buffer.
    """
    lon = np.asarray(lon_deg, float)
    lat = np.asarray(lat_deg, float)
    valid = np.isfinite(lon) & np.isfinite(lat)
    fields = [("order", "u1"), ("kind", "<u4"), ("x", "<f8"), ("y", "<f8")]
    if height_m is not None:
        fields.append(("z", "<f8"))
    rec = np.empty(int(valid.sum()), dtype=np.dtype(fields))  # packed: no alignment padding
    rec["order"] = _WKB_LITTLE_ENDIAN
    rec["kind"] = _WKB_POINT if height_m is None else _WKB_POINT_Z
    rec["x"] = lon[valid]
    rec["y"] = lat[valid]
    if height_m is not None:
        rec["z"] = np.asarray(height_m, float)[valid]
    size = rec.dtype.itemsize
    offsets = np.zeros(len(lon) + 1, np.int32)
    np.cumsum(valid * size, out=offsets[1:])
    bitmap = None if valid.all() else pa.py_buffer(np.packbits(valid, bitorder="little"))
    return pa.Array.from_buffers(pa.binary(), len(lon),
                                 [bitmap, pa.py_buffer(offsets), pa.py_buffer(rec.tobytes())],
                                 null_count=int((~valid).sum()))


def geo_metadata(lon_deg: np.ndarray, lat_deg: np.ndarray,
                 height_m: np.ndarray | None = None) -> dict[str, object]:
    """The GeoParquet 1.1 ``geo`` key for one point column (crs omitted = OGC:CRS84)."""
    lon = np.asarray(lon_deg, float)
    lat = np.asarray(lat_deg, float)
    valid = np.isfinite(lon) & np.isfinite(lat)
    column: dict[str, object] = {"encoding": "WKB",
                                 "geometry_types": ["Point" if height_m is None else "Point Z"]}
    if valid.any():
        lo = [float(lon[valid].min()), float(lat[valid].min())]
        hi = [float(lon[valid].max()), float(lat[valid].max())]
        if height_m is not None:
            z = np.asarray(height_m, float)[valid]
            lo.append(float(z.min()))
            hi.append(float(z.max()))
        column["bbox"] = lo + hi
    return {"version": GEOPARQUET_VERSION, "primary_column": GEOMETRY_COLUMN,
            "columns": {GEOMETRY_COLUMN: column}}


def _height_of(df: pd.DataFrame) -> np.ndarray | None:
    """The Z of the points: ``height_m`` if the table has it, finite wherever lat/lon are."""
    if HEIGHT_COLUMN not in df.columns:
        return None
    h = df[HEIGHT_COLUMN].to_numpy(dtype=float, na_value=np.nan)
    where = np.isfinite(df["lon"].to_numpy(float)) & np.isfinite(df["lat"].to_numpy(float))
    return h if np.isfinite(h[where]).all() else None


def add_geometry(table: pa.Table, df: pd.DataFrame) -> pa.Table:
    """``table`` (made from ``df``) plus the WKB ``geometry`` column and the ``geo`` key."""
    lon = df["lon"].to_numpy(dtype=float, na_value=np.nan)
    lat = df["lat"].to_numpy(dtype=float, na_value=np.nan)
    height = _height_of(df)
    geom = wkb_points(lon, lat, height)
    desc = ("WKB point (lon, lat deg" + (", height_m" if height is not None else "")
            + "), OGC:CRS84; GeoParquet geometry, repeats lat/lon")
    fld = pa.field(GEOMETRY_COLUMN, pa.binary(),
                   metadata={"unit": "WKB", "description": desc})
    out = table.append_column(fld, geom)
    meta = dict(table.schema.metadata or {})
    meta[b"geo"] = json.dumps(geo_metadata(lon, lat, height)).encode()
    return out.replace_schema_metadata(meta)


def is_geo_table(df: pd.DataFrame) -> bool:
    """A table whose rows are positions (it has ``lat`` and ``lon``): written as GeoParquet."""
    return "lat" in df.columns and "lon" in df.columns and GEOMETRY_COLUMN not in df.columns


def _unit_of(text: str) -> str:
    """``"m, east in the local frame"`` -> ``"m"`` (the part before the first comma)."""
    return text.split(",", 1)[0].strip()


def to_arrow(df: pd.DataFrame, *, metadata: dict[str, str] | None = None,
             units: dict[str, str] | None = None) -> pa.Table:
    """The DataFrame as an Arrow table with field and schema metadata.

    Float NaN becomes a Parquet null (``from_pandas`` semantics), as the
    conventions charter asks for "not measured".
    """
    table = pa.Table.from_pandas(df, preserve_index=False)
    units = units or {}
    fields = []
    for fld in table.schema:
        if pa.types.is_timestamp(fld.type) and fld.type.unit != "ns":
            # the contract: timestamp[ns, UTC] whatever resolution pandas chose
            fld = fld.with_type(pa.timestamp("ns", tz=fld.type.tz))
        if fld.name in units:
            fld = fld.with_metadata({"unit": _unit_of(units[fld.name]),
                                     "description": units[fld.name]})
        fields.append(fld)
    schema_meta = dict(table.schema.metadata or {})
    for key, value in (metadata or {}).items():
        schema_meta[str(key).encode()] = str(value).encode()
    schema = pa.schema(fields, metadata=schema_meta)
    return table.cast(schema)


def _write_to(table: pa.Table, fh: BinaryIO, fmt: str) -> None:
    if fmt == "parquet":
        # zstd; no dictionary on numbers (on floats pyarrow's builds a hash table, gives up
        # past 1 MB and writes plain anyway); floats BYTE_STREAM_SPLIT, which zstd compresses
        # faster and smaller (benchmarks/write_parquet.py).  Text keeps its dictionaries.
        text = [f.name for f in table.schema
                if pa.types.is_string(f.type) or pa.types.is_large_string(f.type)
                or pa.types.is_dictionary(f.type)]
        floats = [f.name for f in table.schema if pa.types.is_floating(f.type)]
        pq.write_table(table, fh, compression="zstd", use_dictionary=text,
                       use_byte_stream_split=floats)
    else:
        pacsv.write_csv(table, fh)


def write_table(df: pd.DataFrame, path: str | os.PathLike, *, metadata: dict[str, str] | None = None,
                units: dict[str, str] | None = None, fmt: str = "parquet") -> None:
    """Write ``df`` to ``path`` (``-`` = stdout) atomically, as Parquet or CSV.

    ``units``: column -> "unit, meaning" (Parquet field metadata);
    ``metadata``: file-level key -> value strings (Parquet schema metadata).
    """
    if fmt not in FORMATS:
        raise UsageError(f"unknown output format {fmt!r}; choose parquet or csv")
    table = to_arrow(df, metadata=metadata, units=units)
    if fmt == "parquet" and is_geo_table(df):
        table = add_geometry(table, df)
    if str(path) == "-":
        buf = io.BytesIO()
        _write_to(table, buf, fmt)
        out = sys.stdout.buffer
        out.write(buf.getvalue())
        out.flush()
        return
    with atomic_output(path) as fh:
        _write_to(table, fh, fmt)


@contextlib.contextmanager
def atomic_output(path: str | os.PathLike) -> Iterator[BinaryIO]:
    """A binary file that replaces ``path`` only once it is completely written and synced
    (a temporary file in the target's directory, fsync'ed, renamed): a killed process
    leaves the old file or none."""
    target = Path(path)
    directory = target.parent if str(target.parent) else Path(".")
    if not directory.is_dir():
        raise InputError(target, f"cannot write: directory {directory} does not exist")
    fd, tmp_name = tempfile.mkstemp(prefix=f".{target.name}.", suffix=".tmp", dir=directory)
    try:
        os.chmod(tmp_name, 0o666 & ~_umask())  # mkstemp makes 0600; give the usual mode
        with os.fdopen(fd, "wb") as fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp_name, target)
    except OSError as err:
        _unlink_quietly(tmp_name)
        raise InputError(target, f"cannot write: {err.strerror or err}") from err
    except BaseException:
        _unlink_quietly(tmp_name)
        raise
    _fsync_dir(directory)


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


def _unlink_quietly(name: str) -> None:
    try:
        os.unlink(name)
    except FileNotFoundError:
        pass


def _fsync_dir(directory: Path) -> None:
    """Make the rename durable (POSIX); a no-op where directories cannot be opened."""
    try:
        fd = os.open(directory, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


def _decode_meta(schema: pa.Schema) -> dict[str, str]:
    out: dict[str, str] = {}
    for key, value in (schema.metadata or {}).items():
        k = key.decode("utf-8", "replace")
        if k in ("pandas", "geo"):  # describe this file's columns, not the data's provenance
            continue
        out[k] = value.decode("utf-8", "replace")
    return out


def _geo_columns(schema: pa.Schema) -> set[str]:
    """The geometry (and covering) columns a GeoParquet ``geo`` key names."""
    raw = (schema.metadata or {}).get(b"geo")
    if raw is None:
        return set()
    try:
        geo = json.loads(raw)
        names = set(geo.get("columns", {}))
        for col in geo.get("columns", {}).values():
            for path in (col.get("covering", {}).get("bbox", {}) or {}).values():
                names.add(path[0])
    except (ValueError, AttributeError, TypeError, IndexError):
        return set()  # a malformed geo key: read every column, as a plain Parquet
    return names


def _plain_columns(schema: pa.Schema) -> list[str]:
    """Every column but the geometry ones (they repeat lat/lon, as WKB)."""
    geo = _geo_columns(schema)
    return [name for name in schema.names if name not in geo]


def _without_geometry(table: pa.Table) -> pa.Table:
    geo = _geo_columns(table.schema)
    return table.drop_columns([c for c in table.column_names if c in geo]) if geo else table


def field_units(path_or_table: str | os.PathLike | pa.Table) -> dict[str, str]:
    """Column -> unit string from a Parquet file's field metadata."""
    schema = (path_or_table.schema if isinstance(path_or_table, pa.Table)
              else pq.read_schema(path_or_table))
    return {f.name: f.metadata[b"unit"].decode() for f in schema
            if f.metadata and b"unit" in f.metadata}


def read_table_bytes(data: bytes, name: str = "<stdin>") -> tuple[pd.DataFrame, dict[str, str]]:
    """A Parquet or CSV table held in memory (sniffed by the Parquet magic)."""
    if not data.strip():
        raise InputError(name, "empty input; expected a track Parquet or CSV")
    if data[:4] == PARQUET_MAGIC:
        try:
            table = _without_geometry(pq.read_table(io.BytesIO(data)))
        except (pa.ArrowException, OSError) as err:
            raise InputError(name, f"not a readable Parquet file: {err}") from err
        return _track_df(table.to_pandas(), name), _decode_meta(table.schema)
    try:
        df = pd.read_csv(io.BytesIO(data))
    except (ValueError, UnicodeDecodeError) as err:
        raise InputError(name, f"neither Parquet nor CSV: {err}") from err
    return _track_df(df, name), {}


def read_track(path: str | os.PathLike) -> tuple[pd.DataFrame, dict[str, str]]:
    """A track (or any gpsdr table) and its file metadata; ``-`` reads stdin."""
    if str(path) == "-":
        return read_table_bytes(sys.stdin.buffer.read(), "<stdin>")
    p = Path(path)
    try:
        with open(p, "rb") as fh:
            head = fh.read(4)
    except FileNotFoundError as err:
        raise InputError(p, "no such file") from err
    except IsADirectoryError as err:
        raise InputError(p, "is a directory, expected a track Parquet or CSV") from err
    except OSError as err:
        raise InputError(p, f"cannot read: {err.strerror}") from err
    if head == PARQUET_MAGIC:
        try:
            table = pq.read_table(p, columns=_plain_columns(pq.read_schema(p)))
        except (pa.ArrowException, OSError) as err:
            raise InputError(p, f"not a readable Parquet file: {err}") from err
        return _track_df(table.to_pandas(), str(p)), _decode_meta(table.schema)
    return read_table_bytes(p.read_bytes(), str(p))


def _track_df(df: pd.DataFrame, name: str) -> pd.DataFrame:
    """Normalise the ``time`` column to datetime64[ns, UTC] (CSV reads it as text)."""
    if "time" in df.columns and not isinstance(df["time"].dtype, pd.DatetimeTZDtype):
        try:
            df["time"] = pd.to_datetime(df["time"], utc=True).astype("datetime64[ns, UTC]")
        except (ValueError, TypeError) as err:
            raise InputError(name, f"column time: not timestamps: {err}") from err
    elif "time" in df.columns:
        df["time"] = df["time"].astype("datetime64[ns, UTC]")
    return df
