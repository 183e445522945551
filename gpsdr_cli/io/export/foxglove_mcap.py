"""MCAP for Foxglove: the fused track as ``foxglove.LocationFix``, its path as ``foxglove.GeoJSON``.

Channels (JSON message encoding, JSON Schema schemas named as Foxglove's own, so its Map
panel shows them):

- :data:`FUSED_TOPIC`: one ``foxglove.LocationFix`` per (kept) track row, log and publish
  time = the row's ``time`` (the input's timeline: gpsdr's track time is the time base it
  read the input on).  ``position_covariance`` is ENU, m^2, row-major: diag(sigma_e^2,
  sigma_n^2, 0) with ``position_covariance_type`` 2 (diagonal known); the track estimates
  no height, so altitude is ``height_m`` where the track has it, else 0, and the up
  variance 0.  ``heading`` is radians clockwise from north (Foxglove's convention and
  gpsdr's).
- :data:`TRACK_TOPIC`: one ``foxglove.GeoJSON`` at the first row's time holding the whole
  (kept) track as one LineString.
- :data:`REJECTED_TOPIC`: one ``foxglove.LocationFix`` per GNSS fix the filter did not use
  (a fix at the epoch, ``gnss_used`` false), placed from ``gnss_e``/``gnss_n`` through the
  track's local frame (its file metadata), covariance unknown (type 0).  Always the full
  track's fixes, whatever the decimation.

``with_input``: every schema, channel, message (data, log/publish time, sequence),
metadata and attachment record of an input MCAP is copied unchanged, merged with the
fused messages in log-time order, so raw and fused play together.  Written with the
``mcap`` package's :class:`~mcap.writer.Writer` (zstd chunks, full index).
"""

from __future__ import annotations

import heapq
import json
import os
from collections.abc import Iterator
from typing import Any

import numpy as np
import pandas as pd

from ... import __version__
from ...errors import InputError
from ..parquet import atomic_output
from .geojson import track_geojson
from .text import time_ns

FUSED_TOPIC = "/gpsdr/fused"
TRACK_TOPIC = "/gpsdr/fused_track"
REJECTED_TOPIC = "/gpsdr/gnss_rejected"
FRAME_ID = "gpsdr_fused"

_TIME = {"type": "object", "properties": {"sec": {"type": "integer", "minimum": 0},
                                          "nsec": {"type": "integer", "minimum": 0,
                                                   "maximum": 999_999_999}}}
LOCATION_FIX_SCHEMA: dict[str, Any] = {
    "title": "foxglove.LocationFix",
    "description": "A GNSS position (lat/lon deg WGS84, altitude m; covariance ENU m^2)",
    "type": "object",
    "properties": {
        "timestamp": _TIME,
        "frame_id": {"type": "string"},
        "latitude": {"type": "number"},
        "longitude": {"type": "number"},
        "altitude": {"type": "number"},
        "position_covariance": {"type": "array", "items": {"type": "number"},
                                "minItems": 9, "maxItems": 9},
        "position_covariance_type": {"type": "integer", "enum": [0, 1, 2, 3]},
        "heading": {"type": "number"},
    },
    "required": ["timestamp", "frame_id", "latitude", "longitude", "altitude",
                 "position_covariance", "position_covariance_type"],
}
GEOJSON_SCHEMA: dict[str, Any] = {
    "title": "foxglove.GeoJSON",
    "description": "GeoJSON for annotating maps",
    "type": "object",
    "properties": {"geojson": {"type": "string"}},
    "required": ["geojson"],
}

# A message: (log_time_ns, key, data, publish_time_ns, sequence); key names the channel.
_Msg = tuple[int, Any, bytes, int, int]


def _location_fixes(t_ns: np.ndarray, lat: np.ndarray, lon: np.ndarray, alt: np.ndarray,
                    var_e: np.ndarray, var_n: np.ndarray, heading_rad: np.ndarray | None,
                    cov_type: int, key: str) -> Iterator[_Msg]:
    """JSON LocationFix messages, one per row (floats as Python repr: valid JSON, exact)."""
    head = heading_rad.tolist() if heading_rad is not None else [None] * len(t_ns)
    for seq, (t, la, lo, al, ve, vn, hd) in enumerate(zip(
            t_ns.tolist(), lat.tolist(), lon.tolist(), alt.tolist(), var_e.tolist(),
            var_n.tolist(), head, strict=True)):
        sec, nsec = divmod(t, 1_000_000_000)
        text = (f'{{"timestamp":{{"sec":{sec},"nsec":{nsec}}},"frame_id":"{FRAME_ID}",'
                f'"latitude":{la!r},"longitude":{lo!r},"altitude":{al!r},'
                f'"position_covariance":[{ve!r},0.0,0.0,0.0,{vn!r},0.0,0.0,0.0,0.0],'
                f'"position_covariance_type":{cov_type}'
                + (f',"heading":{hd!r}}}' if hd is not None else "}"))
        yield t, key, text.encode(), t, seq


def _column(track: pd.DataFrame, name: str, fill: float = np.nan) -> np.ndarray:
    if name not in track.columns:
        return np.full(len(track), fill)
    return track[name].to_numpy(dtype=float, na_value=fill)


def fused_messages(rows: pd.DataFrame) -> Iterator[_Msg]:
    """The fused track's LocationFix messages (rows with a position)."""
    lat, lon = _column(rows, "lat"), _column(rows, "lon")
    ok = np.isfinite(lat) & np.isfinite(lon)
    alt = np.nan_to_num(_column(rows, "height_m", 0.0)[ok], nan=0.0)
    var_e = np.nan_to_num(_column(rows, "sigma_e", 0.0)[ok] ** 2, nan=0.0)
    var_n = np.nan_to_num(_column(rows, "sigma_n", 0.0)[ok] ** 2, nan=0.0)
    heading = (np.radians(np.nan_to_num(_column(rows, "heading_deg")[ok], nan=0.0))
               if "heading_deg" in rows.columns else None)
    return _location_fixes(time_ns(rows)[ok], lat[ok], lon[ok], alt, var_e, var_n, heading,
                           2, FUSED_TOPIC)


def rejected_fixes(track: pd.DataFrame, meta: dict[str, str]) -> tuple[int, Iterator[_Msg]]:
    """GNSS fixes present but not used, as LocationFix messages; (count, messages).

    (0, empty) when the track cannot say: no ``gnss_e``/``gnss_n``/``gnss_used`` columns, or
    no local frame in its metadata (a CSV track).
    """
    need = {"gnss_e", "gnss_n", "gnss_used"}
    if not need <= set(track.columns):
        return 0, iter(())
    from ...geodesy import frame_from_metadata

    frame = frame_from_metadata(meta)
    if frame is None:
        return 0, iter(())
    e, n = _column(track, "gnss_e"), _column(track, "gnss_n")
    pick = np.isfinite(e) & np.isfinite(n) & ~track["gnss_used"].to_numpy(bool)
    if not pick.any():
        return 0, iter(())
    lat, lon = frame.inverse(e[pick], n[pick])
    zeros = np.zeros(int(pick.sum()))
    return int(pick.sum()), _location_fixes(time_ns(track)[pick], lat, lon, zeros, zeros, zeros,
                                            None, 0, REJECTED_TOPIC)


def _input_records(reader: Any) -> Iterator[_Msg]:
    for _schema, channel, message in reader.iter_messages(log_time_order=True):
        yield (message.log_time, ("in", channel.id), message.data, message.publish_time,
               message.sequence)


def write_mcap(track: pd.DataFrame, rows: pd.DataFrame, meta: dict[str, str],
               path: str | os.PathLike, *, with_input: str | None = None) -> dict[str, int]:
    """Write the MCAP (see the module docstring) atomically; return messages per topic
    (and ``input messages copied``)."""
    from mcap.writer import Writer

    t = time_ns(rows)
    n_rejected, rejected = rejected_fixes(track, meta)
    doc = track_geojson(rows, name="gpsdr fused track")
    geo_msg = json.dumps({"geojson": json.dumps(doc, allow_nan=False,
                                                separators=(",", ":"))}).encode()
    ours: list[Iterator[_Msg]] = [fused_messages(rows), iter([(int(t[0]), TRACK_TOPIC, geo_msg,
                                                               int(t[0]), 0)]), rejected]
    counts = {FUSED_TOPIC: int((np.isfinite(_column(rows, "lat"))
                                & np.isfinite(_column(rows, "lon"))).sum()),
              TRACK_TOPIC: 1, REJECTED_TOPIC: n_rejected}
    with atomic_output(path) as fh, _open_input(with_input) as reader:
        writer = Writer(fh)
        profile = reader.get_header().profile if reader is not None else ""
        writer.start(profile=profile, library=f"gpsdr {__version__}")
        channel_ids: dict[Any, int] = {}
        streams = list(ours)
        if reader is not None:
            channel_ids.update(_copy_definitions(reader, writer))
            streams.insert(0, _input_records(reader))
        fix_schema = writer.register_schema("foxglove.LocationFix", "jsonschema",
                                            json.dumps(LOCATION_FIX_SCHEMA).encode())
        geo_schema = writer.register_schema("foxglove.GeoJSON", "jsonschema",
                                            json.dumps(GEOJSON_SCHEMA).encode())
        meta_ch = {"gpsdr.version": __version__, "filter": meta.get("filter", "")}
        channel_ids[FUSED_TOPIC] = writer.register_channel(FUSED_TOPIC, "json", fix_schema, meta_ch)
        channel_ids[TRACK_TOPIC] = writer.register_channel(TRACK_TOPIC, "json", geo_schema, meta_ch)
        if n_rejected:
            channel_ids[REJECTED_TOPIC] = writer.register_channel(REJECTED_TOPIC, "json",
                                                                  fix_schema, meta_ch)
        copied = 0
        for log_time, key, data, publish_time, seq in heapq.merge(*streams, key=lambda m: m[0]):
            copied += isinstance(key, tuple)
            cid = channel_ids.get(key)
            if cid is None:  # a channel the input's summary did not list
                cid = channel_ids[key] = _late_channel(reader, writer, key[1], channel_ids)
            writer.add_message(cid, log_time, data, publish_time, seq)
        if reader is not None:
            _copy_extras(reader, writer)
        writer.finish()
    if with_input is not None:
        counts["input messages copied"] = copied
    return counts


class _open_input:
    """The input MCAP's reader (or None), closing the file afterwards."""

    def __init__(self, path: str | None) -> None:
        self.path = path
        self._fh: Any = None

    def __enter__(self) -> Any:
        if self.path is None:
            return None
        from mcap.reader import make_reader

        try:
            self._fh = open(self.path, "rb")
            head = self._fh.read(8)
            self._fh.seek(0)
        except OSError as err:
            raise InputError(self.path, f"cannot read: {err.strerror or err}") from err
        if head != b"\x89MCAP0\r\n":
            self._fh.close()
            raise InputError(self.path, "not an MCAP file (no MCAP magic); --with-input "
                                        "takes the .mcap the track was fused from")
        return make_reader(self._fh)

    def __exit__(self, *exc: object) -> None:
        if self._fh is not None:
            self._fh.close()


def _copy_definitions(reader: Any, writer: Any) -> dict[Any, int]:
    """Register the input's schemas and channels (from its summary); input channel -> ours."""
    summary = reader.get_summary()
    ids: dict[Any, int] = {}
    if summary is None:
        return ids
    schema_ids = {0: 0}
    for sid, schema in sorted(summary.schemas.items()):
        schema_ids[sid] = writer.register_schema(schema.name, schema.encoding, schema.data)
    for cid, ch in sorted(summary.channels.items()):
        ids[("in", cid)] = writer.register_channel(ch.topic, ch.message_encoding,
                                                   schema_ids.get(ch.schema_id, 0),
                                                   dict(ch.metadata))
    return ids


def _late_channel(reader: Any, writer: Any, in_cid: int, ids: dict[Any, int]) -> int:
    """Register an input channel met in the data but missing from the summary."""
    for schema, channel, _message in reader.iter_messages():
        if channel.id == in_cid:
            sid = 0 if schema is None else writer.register_schema(schema.name, schema.encoding,
                                                                  schema.data)
            return writer.register_channel(channel.topic, channel.message_encoding, sid,
                                           dict(channel.metadata))
    raise InputError(None, f"input MCAP: channel {in_cid} vanished while copying")


def _copy_extras(reader: Any, writer: Any) -> None:
    """The input's metadata and attachment records, unchanged."""
    for record in reader.iter_metadata():
        writer.add_metadata(record.name, dict(record.metadata))
    for att in reader.iter_attachments():
        writer.add_attachment(att.create_time, att.log_time, att.name, att.media_type, att.data)

