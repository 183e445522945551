"""gpsdr export: each format read back by its own reader (gpxpy, fastkml, shapely + json, mcap)."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from gpsdr_cli.io.export import decimate, path_length_m
from gpsdr_cli.io.parquet import read_track
from tests.conftest import REPO, one_line_error

DEG_TOL = 1e-9  # deg: text formats carry 10 decimals
SAMPLE = REPO / "sample_logs" / "comma2k19"


@pytest.fixture(scope="module")
def fused(tmp_path_factory: pytest.TempPathFactory) -> Path:
    from click.testing import CliRunner

    from gpsdr_cli.cli.main import cli

    out = tmp_path_factory.mktemp("export") / "track.parquet"
    res = CliRunner().invoke(cli, ["fuse", "--gps", SAMPLE / "gps.nmea", "--gyro",
                                   SAMPLE / "gyro.csv", "--odo", SAMPLE / "odo.csv", "-o", out,
                                   "-q"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    return out


@pytest.fixture(scope="module")
def track(fused: Path) -> pd.DataFrame:
    return read_track(fused)[0]


def _export(gpsdr, fused: Path, out: Path, *extra: object) -> None:
    res = gpsdr(["export", fused, "-o", out, *extra])
    assert res.exit_code == 0, res.stderr
    assert not list(out.parent.glob(".*.tmp"))  # atomic: no temporary file left


def test_gpx_read_by_gpxpy(gpsdr, fused: Path, track: pd.DataFrame, tmp_path: Path) -> None:
    import gpxpy

    out = tmp_path / "t.gpx"
    _export(gpsdr, fused, out)
    gpx = gpxpy.parse(out.read_text())
    pts = gpx.tracks[0].segments[0].points
    assert len(pts) == len(track)
    np.testing.assert_allclose([p.latitude for p in pts], track.lat, rtol=0, atol=DEG_TOL)
    np.testing.assert_allclose([p.longitude for p in pts], track.lon, rtol=0, atol=DEG_TOL)
    t_us = np.array([p.time.timestamp() for p in pts])
    want = track.time.astype("int64").to_numpy() / 1e9
    assert np.abs(t_us - want).max() < 1.01e-6  # s: microsecond time stamps
    sigma = {e.tag.split("}")[1]: float(e.text) for e in pts[100].extensions}["sigma"]
    assert sigma == pytest.approx(np.hypot(track.sigma_e[100], track.sigma_n[100]), abs=5e-4)
    assert pts[100].position_dilution == pytest.approx(track.pdop[100], abs=5e-3)


def test_gpx_quality_extension_when_the_track_has_it(tmp_path: Path, track: pd.DataFrame) -> None:
    import gpxpy

    from gpsdr_cli.io.export.gpx import write_gpx

    df = track.head(50).copy()
    df["quality"] = np.arange(50) % 6 + 1
    write_gpx(df, tmp_path / "q.gpx", name="q")
    pts = gpxpy.parse((tmp_path / "q.gpx").read_text()).tracks[0].segments[0].points
    q = [int({e.tag.split("}")[1]: e.text for e in p.extensions}["quality"]) for p in pts]
    assert q == df["quality"].tolist()


def test_kml_read_by_fastkml(gpsdr, fused: Path, track: pd.DataFrame, tmp_path: Path) -> None:
    from fastkml import kml

    out = tmp_path / "t.kml"
    _export(gpsdr, fused, out, "--every", "1")
    rows = decimate(track, every_s=1.0)
    doc = kml.KML.parse(out)
    placemarks = list(doc.features[0].features)
    line = placemarks[0].geometry
    xy = np.array(line.coords)
    np.testing.assert_allclose(xy[:, 0], rows.lon, rtol=0, atol=DEG_TOL)
    np.testing.assert_allclose(xy[:, 1], rows.lat, rtol=0, atol=DEG_TOL)
    gx_track = placemarks[1].kml_geometry
    whens = [item.when for item in gx_track.track_items]
    coords = np.array([item.coord.coords[0][:2] for item in gx_track.track_items])
    assert len(whens) == len(rows)
    np.testing.assert_allclose(coords[:, 1], rows.lat, rtol=0, atol=DEG_TOL)
    got = np.array([w.dt.timestamp() for w in whens])
    np.testing.assert_allclose(got, rows.time.astype("int64") / 1e9, rtol=0, atol=1.01e-6)


def test_geojson_read_by_shapely(gpsdr, fused: Path, track: pd.DataFrame, tmp_path: Path) -> None:
    import shapely.geometry

    out = tmp_path / "t.geojson"
    _export(gpsdr, fused, out, "--every", "2", "--points")
    doc = json.loads(out.read_text())
    rows = decimate(track, every_s=2.0)
    line = shapely.geometry.shape(doc["features"][0]["geometry"])
    assert line.geom_type == "LineString" and len(line.coords) == len(rows)
    xy = np.array(line.coords)
    np.testing.assert_allclose(xy[:, 1], rows.lat, rtol=0, atol=DEG_TOL)
    pts = doc["features"][1:]
    assert len(pts) == len(rows)
    p = shapely.geometry.shape(pts[3]["geometry"])
    assert abs(p.x - rows.lon[3]) < DEG_TOL
    assert pts[3]["properties"]["speed_mps"] == pytest.approx(rows.speed[3], abs=5e-4)
    assert pd.Timestamp(pts[3]["properties"]["time"]) == rows.time[3]


def test_geojson_kepler_trip_form(gpsdr, fused: Path, track: pd.DataFrame, tmp_path: Path) -> None:
    out = tmp_path / "k.geojson"
    _export(gpsdr, fused, out, "--every", "1", "--kepler")
    coords = np.array(json.loads(out.read_text())["features"][0]["geometry"]["coordinates"])
    rows = decimate(track, every_s=1.0)
    assert coords.shape == (len(rows), 4)
    np.testing.assert_allclose(coords[:, 3], rows.time.astype("int64") / 1e9, atol=5e-4)
    assert (np.diff(coords[:, 3]) >= 1.0 - 1e-3).sum() == len(rows) - 2  # s apart, but the end


def test_csv_has_every_column(gpsdr, fused: Path, track: pd.DataFrame, tmp_path: Path) -> None:
    out = tmp_path / "t.csv"
    _export(gpsdr, fused, out)
    back = pd.read_csv(out)
    assert list(back.columns) == list(track.columns)
    np.testing.assert_allclose(back.lat, track.lat, rtol=0, atol=1e-12)


def test_mcap_read_by_mcap_reader(gpsdr, fused: Path, track: pd.DataFrame, tmp_path: Path) -> None:
    from mcap.reader import make_reader

    out = tmp_path / "t.mcap"
    _export(gpsdr, fused, out)
    by_topic: dict[str, list] = {}
    with open(out, "rb") as fh:
        for schema, channel, msg in make_reader(fh).iter_messages():
            by_topic.setdefault(channel.topic, []).append((schema.name, msg, json.loads(msg.data)))
    fixes = by_topic["/gpsdr/fused"]
    assert len(fixes) == len(track) and fixes[0][0] == "foxglove.LocationFix"
    k = 500
    _, msg, fix = fixes[k]
    assert msg.log_time == track.time.astype("int64")[k]
    assert fix["timestamp"]["sec"] * 10**9 + fix["timestamp"]["nsec"] == msg.log_time
    assert fix["latitude"] == track.lat[k] and fix["longitude"] == track.lon[k]
    assert fix["position_covariance"][0] == pytest.approx(track.sigma_e[k] ** 2, rel=1e-12)
    assert fix["position_covariance"][4] == pytest.approx(track.sigma_n[k] ** 2, rel=1e-12)
    assert fix["position_covariance_type"] == 2
    (name, _, geo), = by_topic["/gpsdr/fused_track"]
    assert name == "foxglove.GeoJSON"
    coords = json.loads(geo["geojson"])["features"][0]["geometry"]["coordinates"]
    assert len(coords) == len(track)
    fix_epoch = track.gnss_e.notna() & ~track.gnss_used
    assert len(by_topic.get("/gpsdr/gnss_rejected", [])) == int(fix_epoch.sum())


def test_mcap_with_input_copies_every_message(gpsdr, track: pd.DataFrame, tmp_path: Path) -> None:
    from mcap.reader import make_reader

    log = REPO / "tests" / "data" / "mcap" / "small_drive.mcap"
    res = gpsdr(["fuse", log, "-o", tmp_path / "f.parquet", "-q"])
    assert res.exit_code == 0, res.stderr
    out = tmp_path / "both.mcap"
    res = gpsdr(["export", tmp_path / "f.parquet", "-o", out, "--with-input", log])
    assert res.exit_code == 0, res.stderr
    with open(log, "rb") as fh:
        want = [(c.topic, m.log_time, m.publish_time, m.sequence, bytes(m.data))
                for _, c, m in make_reader(fh).iter_messages(log_time_order=True)]
    with open(out, "rb") as fh:
        got = [(c.topic, m.log_time, m.publish_time, m.sequence, bytes(m.data))
               for _, c, m in make_reader(fh).iter_messages(log_time_order=True)]
    ours = [g for g in got if g[0].startswith("/gpsdr/")]
    assert sorted(g for g in got if not g[0].startswith("/gpsdr/")) == sorted(want)
    for g in ours:
        json.loads(g[4])
    assert len(ours) >= 2


def test_decimation_by_time_and_distance(track: pd.DataFrame) -> None:
    rows = decimate(track, every_s=1.0, min_distance_m=5.0)
    t = rows.time.astype("int64").to_numpy() / 1e9
    d = path_length_m(track)[np.searchsorted(track.time.astype("int64"),
                                             rows.time.astype("int64"))]
    assert (np.diff(t)[:-1] >= 1.0 - 1e-9).all()  # s; the last row is kept whatever
    assert (np.diff(d)[:-1] >= 5.0 - 1e-9).all()  # m along the track
    assert rows.time.iloc[-1] == track.time.iloc[-1]
    # greedy: a kept row is the first past both thresholds (none earlier would do)
    t_all = track.time.astype("int64").to_numpy() / 1e9
    k1 = np.searchsorted(t_all, t[1])
    assert t_all[k1 - 1] - t[0] < 1.0 or path_length_m(track)[k1 - 1] < 5.0


def test_unknown_suffix_and_non_track_are_one_line_errors(gpsdr, fused: Path,
                                                          tmp_path: Path) -> None:
    res = gpsdr(["export", fused, "-o", tmp_path / "x.shp"])
    assert res.exit_code == 2 and "unknown export format '.shp'" in one_line_error(res)
    (tmp_path / "n.csv").write_text("a,b\n1,2\n")
    res = gpsdr(["export", tmp_path / "n.csv", "-o", tmp_path / "x.gpx"])
    assert res.exit_code == 1
    assert "not a gpsdr track" in one_line_error(res) and "n.csv" in one_line_error(res)
    assert not (tmp_path / "x.gpx").exists()


def test_fuse_export_writes_the_same_file(gpsdr, fused: Path, tmp_path: Path) -> None:
    import gpxpy

    res = gpsdr(["fuse", "--gps", SAMPLE / "gps.nmea", "--gyro", SAMPLE / "gyro.csv", "--odo",
                 SAMPLE / "odo.csv", "-o", tmp_path / "f.parquet", "--export", tmp_path / "f.gpx",
                 "-q"])
    assert res.exit_code == 0, res.stderr
    _export(gpsdr, tmp_path / "f.parquet", tmp_path / "e.gpx")
    a = gpxpy.parse((tmp_path / "f.gpx").read_text()).tracks[0].segments[0].points
    b = gpxpy.parse((tmp_path / "e.gpx").read_text()).tracks[0].segments[0].points
    assert [(p.latitude, p.longitude, p.time) for p in a] == \
        [(p.latitude, p.longitude, p.time) for p in b]


def test_export_has_help_with_examples(gpsdr) -> None:
    res = gpsdr(["export", "--help"])
    assert res.exit_code == 0
    assert "Examples:" in res.stdout and "gpsdr export" in res.stdout and "--with-input" in res.stdout
