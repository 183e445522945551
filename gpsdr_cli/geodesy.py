"""Projection between WGS84 latitude/longitude (degrees) and the local east/north frame (metres).

Default frame: a transverse Mercator on the WGS84 ellipsoid centred on the first
valid fix (scale 1, no false easting/northing), so the frame has no zone breaks
and ``e = n = 0`` at the origin.  On request, any projected CRS by EPSG code
(``e``/``n`` are then that CRS's easting/northing, unshifted).

One pyproj ``Transformer`` per direction is built once and reused, with
``always_xy=True`` (longitude first), as pyproj recommends.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from pyproj import CRS, Transformer

from .errors import InputError, UsageError

WGS84 = CRS.from_epsg(4326)


@dataclass
class LocalFrame:
    """A local east/north frame.  ``e, n = frame.forward(lat_deg, lon_deg)`` in metres."""

    crs: CRS
    origin_lat_deg: float
    origin_lon_deg: float
    _fwd: Transformer = field(init=False, repr=False)
    _inv: Transformer = field(init=False, repr=False)

    def __post_init__(self) -> None:
        self._fwd = Transformer.from_crs(WGS84, self.crs, always_xy=True)
        self._inv = Transformer.from_crs(self.crs, WGS84, always_xy=True)

    @classmethod
    def centred_on(cls, lat_deg: float, lon_deg: float) -> LocalFrame:
        """Transverse Mercator centred on (lat_deg, lon_deg), degrees."""
        if not (np.isfinite(lat_deg) and np.isfinite(lon_deg)) or abs(lat_deg) > 90:
            raise InputError(None, f"cannot centre a local frame on lat={lat_deg}, lon={lon_deg}")
        lon0 = ((lon_deg + 180.0) % 360.0) - 180.0
        crs = CRS.from_proj4(
            f"+proj=tmerc +lat_0={lat_deg:.12f} +lon_0={lon0:.12f} +k=1 +x_0=0 +y_0=0 "
            "+ellps=WGS84 +units=m +no_defs"
        )
        return cls(crs, float(lat_deg), float(lon0))

    @classmethod
    def from_epsg(cls, code: int, lat_deg: float = np.nan, lon_deg: float = np.nan) -> LocalFrame:
        """A projected CRS by EPSG code (e.g. 32633 for UTM 33N)."""
        try:
            crs = CRS.from_epsg(int(code))
        except Exception as err:  # pyproj raises CRSError; the message names the code
            raise UsageError(f"EPSG:{code} is not a CRS pyproj knows: {err}") from err
        if not crs.is_projected:
            raise UsageError(f"EPSG:{code} ({crs.name}) is not a projected CRS; "
                             "give one in metres, e.g. a UTM zone")
        return cls(crs, float(lat_deg), float(lon_deg))

    @classmethod
    def for_fixes(cls, lat_deg: np.ndarray, lon_deg: np.ndarray, epsg: int | None = None) -> LocalFrame:
        """The default frame for a drive: centred on its first finite fix (or an EPSG CRS)."""
        ok = np.flatnonzero(np.isfinite(lat_deg) & np.isfinite(lon_deg))
        lat0 = float(lat_deg[ok[0]]) if len(ok) else np.nan
        lon0 = float(lon_deg[ok[0]]) if len(ok) else np.nan
        if epsg is not None:
            return cls.from_epsg(epsg, lat0, lon0)
        if not len(ok):
            raise InputError(None, "no valid GNSS fix to centre the local frame on; "
                                   "give --origin LAT,LON or --epsg CODE")
        return cls.centred_on(lat0, lon0)

    def forward(self, lat_deg: np.ndarray, lon_deg: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """WGS84 lat/lon (deg) -> local (e, n) metres.  NaN in, NaN out."""
        e, n = self._fwd.transform(np.asarray(lon_deg, float), np.asarray(lat_deg, float))
        return np.asarray(e, float), np.asarray(n, float)

    def inverse(self, e: np.ndarray, n: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Local (e, n) metres -> WGS84 (lat, lon) degrees, longitude in [-180, 180)."""
        lon, lat = self._inv.transform(np.asarray(e, float), np.asarray(n, float))
        lon = ((np.asarray(lon, float) + 180.0) % 360.0) - 180.0
        return np.asarray(lat, float), lon

    def describe(self) -> dict[str, str]:
        """The frame's definition, for file metadata."""
        return {
            "crs_wkt": self.crs.to_wkt(),
            "crs_proj4": self.crs.to_proj4() or "",
            "origin_lat_deg": repr(self.origin_lat_deg),
            "origin_lon_deg": repr(self.origin_lon_deg),
        }


def frame_from_metadata(meta: dict[str, str]) -> LocalFrame | None:
    """Rebuild the local frame a track file was written in, from its ``frame.crs_wkt`` and
    ``frame.origin_lat_deg`` / ``frame.origin_lon_deg`` metadata (None if it does not say)."""
    wkt = meta.get("frame.crs_wkt")
    if not wkt:
        return None
    return LocalFrame(CRS.from_wkt(wkt), float(meta.get("frame.origin_lat_deg", "nan")),
                      float(meta.get("frame.origin_lon_deg", "nan")))
