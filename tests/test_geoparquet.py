"""Track files are GeoParquet 1.1: read by GeoPandas, `geo` key valid against the vendored schema."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest

from gpsdr_cli.io.parquet import GEOMETRY_COLUMN, field_units, read_track, wkb_points, write_table
from tests.conftest import REPO

gpd = pytest.importorskip("geopandas")
shapely = pytest.importorskip("shapely")
jsonschema = pytest.importorskip("jsonschema")

SCHEMA = REPO / "tests" / "data" / "geoparquet" / "schema.json"
DEG_TOL = 1e-9  # deg: the WKB doubles must be the lat/lon doubles (no rounding in between)


def _track(n: int = 500) -> pd.DataFrame:
    rng = np.random.default_rng(7)
    t = pd.to_datetime(1_700_000_000 * 10**9 + np.arange(n) * 10**7, utc=True)
    lat = 48.1 + np.cumsum(rng.normal(0, 1e-6, n))
    lon = 11.5 + np.cumsum(rng.normal(0, 1e-6, n))
    return pd.DataFrame({"time": t.astype("datetime64[ns, UTC]"), "lat": lat, "lon": lon,
                         "sigma_e": rng.uniform(0.1, 3, n), "gnss_used": rng.random(n) > 0.3})


@pytest.fixture(scope="module")
def fused_track(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The bundled sample drive, fused by gpsdr itself: a real track file."""
    from click.testing import CliRunner

    from gpsdr_cli.cli.main import cli

    out = tmp_path_factory.mktemp("geo") / "track.parquet"
    sample = REPO / "sample_logs" / "comma2k19"
    res = CliRunner().invoke(cli, ["fuse", "--gps", sample / "gps.nmea", "--gyro",
                                   sample / "gyro.csv", "--odo", sample / "odo.csv",
                                   "-o", out, "-q"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    return out


def _validator() -> jsonschema.Draft7Validator:
    from referencing import Registry

    def refuse(uri: str) -> object:  # nothing is fetched: the test fails instead
        raise AssertionError(f"schema tried to fetch {uri}")

    schema = json.loads(SCHEMA.read_text())
    return jsonschema.Draft7Validator(schema, registry=Registry(retrieve=refuse))


def test_fused_track_reads_as_geodataframe_in_crs84(fused_track: Path) -> None:
    gdf = gpd.read_parquet(fused_track)
    assert isinstance(gdf, gpd.GeoDataFrame)
    assert gdf.crs is not None and gdf.crs.equals("OGC:CRS84")
    assert gdf.crs.to_epsg() == 4326 or gdf.crs.to_string() == "OGC:CRS84"
    assert len(gdf) > 10_000
    np.testing.assert_allclose(gdf.geometry.x.to_numpy(), gdf["lon"].to_numpy(), rtol=0, atol=DEG_TOL)
    np.testing.assert_allclose(gdf.geometry.y.to_numpy(), gdf["lat"].to_numpy(), rtol=0, atol=DEG_TOL)
    assert not gdf.geometry.has_z.any()


def test_geo_metadata_is_valid_geoparquet_1_1(fused_track: Path) -> None:
    geo = json.loads(pq.read_schema(fused_track).metadata[b"geo"])
    _validator().validate(geo)
    assert geo["version"] == "1.1.0" and geo["primary_column"] == GEOMETRY_COLUMN
    col = geo["columns"][GEOMETRY_COLUMN]
    assert col["encoding"] == "WKB" and col["geometry_types"] == ["Point"]
    df = pq.read_table(fused_track).to_pandas()
    assert col["bbox"] == [df.lon.min(), df.lat.min(), df.lon.max(), df.lat.max()]


def test_schema_rejects_what_it_should() -> None:
    """The vendored schema is live: a wrong version or encoding fails validation."""
    good = {"version": "1.1.0", "primary_column": "geometry",
            "columns": {"geometry": {"encoding": "WKB", "geometry_types": ["Point"]}}}
    v = _validator()
    v.validate(good)
    for bad in ({**good, "version": "1.0.0"},
                {**good, "columns": {"geometry": {"encoding": "WKT", "geometry_types": []}}},
                {**good, "columns": {"geometry": {"encoding": "WKB",
                                                  "geometry_types": ["Point"], "bbox": [1, 2]}}}):
        assert not v.is_valid(bad)


def test_existing_columns_and_field_metadata_stay(fused_track: Path) -> None:
    units = field_units(fused_track)
    assert units["sigma_e"] == "m" and units["lat"] == "deg" and units["speed"] == "m/s"
    names = pq.read_schema(fused_track).names
    assert names[-1] == GEOMETRY_COLUMN
    back, meta = read_track(fused_track)  # what gpsdr stats / plot read
    assert GEOMETRY_COLUMN not in back.columns
    assert set(names) - {GEOMETRY_COLUMN} == set(back.columns)
    assert "geo" not in meta and meta["filter"] == "aekf"


def test_stats_and_plot_still_read_a_geoparquet_track(gpsdr, fused_track: Path,
                                                        tmp_path: Path) -> None:
    ref = REPO / "sample_logs" / "comma2k19" / "truth.csv"
    res = gpsdr(["stats", fused_track, "--reference", ref, "-o", tmp_path / "s.parquet"])
    assert res.exit_code == 0, res.output
    assert b"geo" not in (pq.read_schema(tmp_path / "s.parquet").metadata or {})
    res = gpsdr(["plot", fused_track, "-o", tmp_path / "p.png"])
    assert res.exit_code == 0, res.output
    assert (tmp_path / "p.png").stat().st_size > 10_000


def test_wkb_matches_shapely_for_2d_3d_and_null_rows() -> None:
    lon = np.array([13.4, -179.999999999, np.nan, 0.0])
    lat = np.array([52.5, -89.5, 10.0, 0.0])
    h = np.array([40.25, -12.0, 3.0, 0.0])
    for height in (None, h):
        arr = wkb_points(lon, lat, height).to_numpy(zero_copy_only=False)
        geoms = shapely.from_wkb(arr)
        assert geoms[2] is None
        for k in (0, 1, 3):
            want = (shapely.Point(lon[k], lat[k]) if height is None
                    else shapely.Point(lon[k], lat[k], h[k]))
            assert shapely.to_wkb(want, byte_order=1, flavor="iso") == arr[k]


def test_height_column_gives_point_z(tmp_path: Path) -> None:
    df = _track()
    df["height_m"] = np.linspace(30.0, 45.0, len(df))
    write_table(df, tmp_path / "z.parquet")
    geo = json.loads(pq.read_schema(tmp_path / "z.parquet").metadata[b"geo"])
    _validator().validate(geo)
    assert geo["columns"]["geometry"]["geometry_types"] == ["Point Z"]
    assert geo["columns"]["geometry"]["bbox"][2] == 30.0
    gdf = gpd.read_parquet(tmp_path / "z.parquet")
    np.testing.assert_allclose(gdf.geometry.z.to_numpy(), df["height_m"].to_numpy(), atol=1e-12)


def test_rows_without_a_position_have_null_geometry(tmp_path: Path) -> None:
    df = _track(50)
    df.loc[[3, 17], ["lat", "lon"]] = np.nan
    write_table(df, tmp_path / "gap.parquet")
    gdf = gpd.read_parquet(tmp_path / "gap.parquet")
    assert gdf.geometry.isna().sum() == 2 and gdf.geometry.iloc[3] is None
    ok = gdf.geometry.notna()
    np.testing.assert_allclose(gdf.geometry[ok].x, df.lon[ok], rtol=0, atol=DEG_TOL)


def test_tables_without_positions_are_plain_parquet(tmp_path: Path) -> None:
    write_table(pd.DataFrame({"filter": ["ekf"], "rmse_m": [1.5]}), tmp_path / "s.parquet")
    assert b"geo" not in (pq.read_schema(tmp_path / "s.parquet").metadata or {})


def test_wkb_of_a_one_hour_track_is_fast() -> None:
    import time

    n = 360_000
    lon, lat = np.full(n, 13.4), np.full(n, 52.5)
    t0 = time.perf_counter()
    wkb_points(lon, lat)
    assert time.perf_counter() - t0 < 0.5  # s, for 360 k rows (the 100 Hz hour)
