"""Projection round trips (lat/lon <-> e/n) within 1e-6 m, including the antimeridian."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from gpsdr_cli.errors import InputError, UsageError
from gpsdr_cli.geodesy import LocalFrame

ROUND_TRIP_TOL_M = 1e-6


def _round_trip_m(frame: LocalFrame, lat: np.ndarray, lon: np.ndarray) -> float:
    e, n = frame.forward(lat, lon)
    lat2, lon2 = frame.inverse(e, n)
    e2, n2 = frame.forward(lat2, lon2)
    return float(np.max(np.hypot(e2 - e, n2 - n)))


@pytest.mark.parametrize(
    ("lat0", "lon0"),
    [(0.0, 0.0), (0.0, 100.0), (78.2, 15.6), (-77.8, 166.7),
     (-45.0, 179.9999), (10.0, -179.9999), (64.0, 180.0)],
    ids=["equator", "equator-east", "svalbard", "mcmurdo", "antimeridian-w", "antimeridian-e",
         "antimeridian-exact"],
)
def test_round_trip_within_a_micrometre(lat0: float, lon0: float) -> None:
    frame = LocalFrame.centred_on(lat0, lon0)
    # a 20 km box around the origin, crossing the antimeridian where the origin is near it
    d = np.linspace(-0.1, 0.1, 41)
    lat = np.clip(lat0 + d, -89.9, 89.9)
    lon = lon0 + 2 * d[::-1]
    assert _round_trip_m(frame, lat, lon) < ROUND_TRIP_TOL_M


def test_origin_is_zero_and_axes_point_east_and_north() -> None:
    frame = LocalFrame.centred_on(48.0, 11.0)
    e, n = frame.forward(np.array([48.0, 48.0, 48.001]), np.array([11.0, 11.001, 11.0]))
    assert abs(e[0]) < 1e-9 and abs(n[0]) < 1e-9
    # 0.001 deg of longitude at 48 N is about 74.6 m east; of latitude about 111.2 m north
    assert e[1] == pytest.approx(74.6, abs=0.2) and abs(n[1]) < 0.01
    assert n[2] == pytest.approx(111.2, abs=0.2) and abs(e[2]) < 1e-6


def test_antimeridian_is_continuous() -> None:
    frame = LocalFrame.centred_on(-16.0, 180.0)
    e, _ = frame.forward(np.array([-16.0, -16.0]), np.array([179.999, -179.999]))
    spacing_m = 0.002 * 111_320 * np.cos(np.radians(16.0))
    assert e[1] - e[0] == pytest.approx(spacing_m, rel=1e-3)


def test_epsg_utm_matches_known_easting() -> None:
    frame = LocalFrame.from_epsg(32633)  # UTM 33N, central meridian 15 E
    e, n = frame.forward(np.array([0.0]), np.array([15.0]))
    assert e[0] == pytest.approx(500_000.0, abs=1e-6)
    assert n[0] == pytest.approx(0.0, abs=1e-6)


def test_epsg_must_be_projected() -> None:
    with pytest.raises(UsageError, match="not a projected CRS"):
        LocalFrame.from_epsg(4326)


def test_no_fix_to_centre_on_is_an_input_error() -> None:
    with pytest.raises(InputError, match="no valid GNSS fix"):
        LocalFrame.for_fixes(np.array([np.nan]), np.array([np.nan]))


@settings(max_examples=200, deadline=None)
@given(lat0=st.floats(-85, 85), lon0=st.floats(-180, 180),
       dlat=st.floats(-0.2, 0.2), dlon=st.floats(-0.2, 0.2))
def test_round_trip_property(lat0: float, lon0: float, dlat: float, dlon: float) -> None:
    frame = LocalFrame.centred_on(lat0, lon0)
    lat = np.array([lat0, np.clip(lat0 + dlat, -89.0, 89.0)])
    lon = np.array([lon0, lon0 + dlon])
    assert _round_trip_m(frame, lat, lon) < ROUND_TRIP_TOL_M
