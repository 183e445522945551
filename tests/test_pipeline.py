"""The pipeline on the real comma2k19 drive: track contract, metadata, accuracy vs GNSS alone."""

from __future__ import annotations

import copy
import hashlib
import importlib.util
import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from gpsdr_cli import config
from gpsdr_cli.conventions import QC_COLUMNS, TRACK_COLUMNS, TRACK_EXTRA_COLUMNS
from gpsdr_cli.errors import NoDataError
from gpsdr_cli.filters import NAMES
from gpsdr_cli.io.drive import Drive
from gpsdr_cli.pipeline import NonFiniteOutputError, check_finite, fuse, summary_of

#: m: the comma2k19 fixes sit ~0.1 s ahead of the reference (data README); with that shift
#: the fixes alone are ~0.5 m RMS from it.
LATENCY_S = 0.1
#: m: the fused track may not be worse than the fixes by more than this on clean open-sky data
OPEN_SKY_TOLERANCE_M = 0.1


@pytest.fixture(scope="module")
def drive(sample_dir: Path) -> Drive:
    from gpsdr_cli.io.readers import read_drive

    return read_drive(gps=sample_dir / "gps.nmea", gyro=sample_dir / "gyro.csv",
                      odo=sample_dir / "odo.csv", params=config.defaults())


@pytest.fixture(scope="module")
def reference(sample_dir: Path):
    from gpsdr_cli.io.reference import read_reference

    return read_reference(sample_dir / "truth.csv")


@pytest.fixture(scope="module")
def result(drive: Drive, reference):
    params = config.defaults()
    params["filter"]["smooth"] = True
    params["filter"]["smoother"] = "rts"
    return fuse(drive, params, reference)


def _available(name: str) -> bool:
    from gpsdr_cli.filters import MODULES

    return importlib.util.find_spec(MODULES[name]) is not None


def test_track_has_the_contract_columns(result) -> None:
    track = result.track
    assert list(track.columns) == list(TRACK_COLUMNS) + list(TRACK_EXTRA_COLUMNS) + list(QC_COLUMNS)
    assert str(track["time"].dtype) == "datetime64[ns, UTC]"
    assert track["gnss_used"].dtype == bool
    assert track["time"].is_monotonic_increasing and track["time"].is_unique
    check_finite(track, result.stats)
    # speed and heading are derived from the velocity (heading clockwise from north)
    np.testing.assert_allclose(track["speed"], np.hypot(track["v_e"], track["v_n"]), atol=1e-12)
    h = track["heading_deg"].to_numpy()
    assert ((h >= 0) & (h < 360)).all()
    moving = track["speed"] > 5.0
    expect = np.degrees(np.arctan2(track["v_e"], track["v_n"])) % 360
    np.testing.assert_allclose(h[moving], expect[moving], atol=1e-9)
    # lat/lon are the local e/n taken back to WGS84: round trip within 1e-6 m
    e, n = result.frame.forward(track["lat"].to_numpy(), track["lon"].to_numpy())
    assert np.max(np.hypot(e - track["e"], n - track["n"])) < 1e-6
    # sigmas from the filter covariance: positive, sub-10 m on open sky
    assert (track["sigma_e"] > 0).all() and (track["sigma_n"] < 10).all()


def test_pdop_is_forward_filled_from_gnss_records(result) -> None:
    track = result.track
    first_fix = int(np.flatnonzero(np.isfinite(result.epochs.pdop))[0])
    assert track["pdop"].iloc[:first_fix].isna().all()
    assert (track["pdop"].iloc[first_fix:] == 1.8).all()  # comma2k19's constant placeholder
    has_fix = np.isfinite(track["gnss_e"].to_numpy())
    assert has_fix.sum() == result.epochs.n_gnss
    assert np.isnan(track["nis"].to_numpy()[~has_fix]).all()


def test_metadata_names_filter_parameters_frame_and_inputs(result, sample_dir: Path) -> None:
    meta = result.metadata
    assert meta["filter"] == "aekf" and meta["smoothed"] == "true"
    for key, value in config.flat(result.params).items():
        assert meta[f"param.{key}"] == value
    reloaded = config.merge(config.defaults(), __import__("tomllib").loads(meta["params_toml"]))
    assert config.to_toml(reloaded) == config.to_toml(result.params)  # (NaN != NaN in dicts)
    assert "tmerc" in meta["frame.crs_proj4"] and float(meta["frame.origin_lat_deg"]) == \
        pytest.approx(37.72, abs=0.01)
    import json

    inputs = {Path(i["path"]).name: i["sha256"] for i in json.loads(meta["inputs"])}
    for name in ("gps.nmea", "gyro.csv", "odo.csv"):
        assert inputs[name] == hashlib.sha256((sample_dir / name).read_bytes()).hexdigest()
    assert meta["gpsdr.version"] == __import__("gpsdr_cli").__version__
    assert json.loads(meta["skipped"]) == {}


def test_fuse_does_not_change_its_input(drive: Drive, reference) -> None:
    before = copy.deepcopy(drive.skipped.counts)
    meta = copy.deepcopy(drive.meta)
    first = fuse(drive, config.defaults(), reference)
    assert drive.skipped.counts == before
    assert drive.meta == meta  # the run's warnings are the run's
    # a second run says what the first said, once (the odometer's lag, comma2k19 as logged)
    assert fuse(drive, config.defaults(), reference).drive_warnings == first.drive_warnings
    assert sum("odometer's speed reads" in w for w in first.drive_warnings) == 1


def test_reference_is_projected_in_the_same_frame(result, reference) -> None:
    ref = result.reference_en
    e, n = result.frame.forward(reference.lat_deg, reference.lon_deg)
    np.testing.assert_allclose(ref["e"].to_numpy(), e, atol=1e-9)
    np.testing.assert_allclose(ref["n"].to_numpy(), n, atol=1e-9)


def test_fused_error_on_the_real_drive(drive: Drive, reference) -> None:
    """With the 0.1 s GNSS latency applied the fixes alone are ~0.5 m RMS from the reference;
    the smoothed fusion must be sub-metre everywhere and at least as good as the fixes."""
    params = config.defaults()
    params["filter"]["smooth"] = True
    params["filter"]["smoother"] = "rts"
    params["time"]["gnss_offset_s"] = LATENCY_S
    res = fuse(drive, params, reference)
    fused = res.summary()
    gnss = res.gnss_only_summary()
    assert fused["rmse_m"] < 1.0 and fused["max_m"] < 1.5
    assert fused["rmse_m"] <= gnss["rmse_m"] + OPEN_SKY_TOLERANCE_M


@pytest.mark.parametrize("name", NAMES)
def test_fusion_beats_noisy_gnss(drive: Drive, reference, name: str) -> None:
    """The same drive with 3 m (1-sigma per axis) white noise added to every fix: the fused
    track must be clearly closer to the reference than the noisy fixes themselves."""
    if not _available(name):
        pytest.skip(f"filter {name} not in this tree yet")
    from gpsdr_cli.pipeline import choose_frame

    noisy = copy.deepcopy(drive)
    frame = choose_frame(noisy, config.defaults())
    rng = np.random.default_rng(7)
    g = noisy.gnss
    e, n = frame.forward(g.lat_deg, g.lon_deg)
    g.lat_deg, g.lon_deg = frame.inverse(e + rng.normal(0, 3.0, len(e)),
                                         n + rng.normal(0, 3.0, len(n)))
    g.hdop[:] = 3.0 * math.sqrt(2) / config.defaults()["gnss"]["uere_m"] * math.sqrt(2)
    params = config.defaults()
    params["filter"]["name"] = name
    params["filter"]["smooth"] = True
    params["filter"]["smoother"] = "rts"
    params["time"]["gnss_offset_s"] = LATENCY_S
    res = fuse(noisy, params, reference)
    fused, alone = res.summary()["rmse_m"], res.gnss_only_summary()["rmse_m"]
    assert alone == pytest.approx(3.0 * math.sqrt(2), rel=0.15)  # the noise we added
    assert fused < 0.6 * alone, f"{name}: fused {fused:.2f} m vs GNSS alone {alone:.2f} m"


def test_stats_without_reference_have_health_rows(drive: Drive) -> None:
    res = fuse(drive, config.defaults())
    s = summary_of(res.stats)
    assert math.isnan(s["rmse_m"])
    assert 0.5 < s["nis_in_95_share"] <= 1.0
    assert s["gnss_separation_rmse_m"] < 3.0  # m: fused track stays near the fixes
    assert set(res.stats["segment"]) >= {"all", "open", "degraded", "outage", "static"}


def test_dead_reckoning_needs_an_origin(drive: Drive, reference) -> None:
    dr = Drive(gyro=drive.gyro, odo=drive.odo, sources=drive.sources)
    with pytest.raises(NoDataError, match="origin_lat_deg"):
        fuse(dr, config.defaults())
    params = config.defaults()
    lat0, lon0 = float(reference.lat_deg[0]), float(reference.lon_deg[0])
    params["frame"].update(origin_lat_deg=lat0, origin_lon_deg=lon0,
                           initial_heading_deg=1.4)  # the truth's heading at the start
    res = fuse(dr, params, reference)
    assert res.track["lat"].iloc[0] == pytest.approx(lat0, abs=1e-7)
    assert res.track["lon"].iloc[0] == pytest.approx(lon0, abs=1e-7)
    assert res.track["e"].iloc[0] == pytest.approx(0.0, abs=1e-6)
    assert not res.track["gnss_used"].any()
    assert res.track["gnss_outage"].all()
    # 60 s / 1012 m of gyro + CAN speed alone from the true start: plain integration of
    # heading = 1.4 deg - integral(yaw_rate) with the CAN speed ends 37 m from the reference
    # at worst, and so does the filter (37.4 m); before aekf.odo_consider the speed rows
    # walked the odometer scale and the position off: 75-153 m
    assert res.summary()["max_m"] < 0.05 * 1012



def test_dead_reckoning_alone_is_not_smoothed_even_when_asked(drive: Drive, reference) -> None:
    """Nothing observes the position without a fix: an RTS pass over this dead reckoning moved
    the origin the user gave 4.9 m north (the forward pass's odometer rows are consider
    updates).  Asked for, the smoother is not run, and a warning says why."""
    dr = Drive(gyro=drive.gyro, odo=drive.odo, sources=drive.sources)
    params = config.defaults()
    params["frame"].update(origin_lat_deg=float(reference.lat_deg[0]),
                           origin_lon_deg=float(reference.lon_deg[0]), initial_heading_deg=1.4)
    forward = fuse(dr, params, reference)
    for smoother in ("rts", "graph"):
        asked = copy.deepcopy(params)
        asked["filter"].update(smooth=True, smoother=smoother)
        res = fuse(dr, asked, reference)
        assert res.track["e"].iloc[0] == pytest.approx(0.0, abs=1e-6)
        assert res.track["n"].iloc[0] == pytest.approx(0.0, abs=1e-6)
        np.testing.assert_allclose(res.track["n"], forward.track["n"], atol=1e-9)
        assert res.metadata["smoother"] == "none" and res.metadata["smoothed"] == "false"
        assert any(w.startswith(f"{smoother} smoother not run: no GNSS fix")
                   for w in res.drive_warnings), res.drive_warnings

def test_epsg_frame(drive: Drive) -> None:
    params = config.defaults()
    params["frame"]["epsg"] = 32610  # UTM 10N: San Francisco
    res = fuse(drive, params)
    assert res.metadata["frame.crs_wkt"].startswith("PROJCRS[\"WGS 84 / UTM zone 10N\"")
    assert 540_000 < res.track["e"].iloc[0] < 560_000  # UTM easting of -122.47 deg


def test_non_finite_output_is_refused(result) -> None:
    bad = result.track.copy()
    bad.loc[5, "e"] = np.nan
    with pytest.raises(NonFiniteOutputError, match="column e .* epoch 5"):
        check_finite(bad)
    bad = result.track.copy()
    bad.loc[3, "pdop"] = np.inf
    with pytest.raises(NonFiniteOutputError, match="pdop"):
        check_finite(bad)


def test_auto_gnss_offset(drive: Drive, reference) -> None:
    if importlib.util.find_spec("gpsdr_cli.latency") is None:
        pytest.skip("gpsdr_cli.latency not in this tree yet")
    params = config.defaults()
    params["filter"]["smooth"] = True
    params["filter"]["smoother"] = "rts"
    res = fuse(drive, params, reference, auto_gnss_offset=True)
    assert res.gnss_offset_s == pytest.approx(LATENCY_S, abs=0.04)  # s
    assert float(res.metadata["gnss_offset_auto_s"]) == res.gnss_offset_s
    assert float(res.metadata["param.time.gnss_offset_s"]) == res.gnss_offset_s
    assert res.gnss_offset_note.startswith("differenced")  # not from the reference
    assert res.summary()["rmse_m"] < 1.0


def test_track_is_written_with_units(result, tmp_path: Path) -> None:
    from gpsdr_cli.io.parquet import field_units, read_track, write_table
    from gpsdr_cli.pipeline import TRACK_UNITS

    path = tmp_path / "t.parquet"
    write_table(result.track, path, metadata=result.metadata, units=TRACK_UNITS)
    back, meta = read_track(path)
    pd.testing.assert_frame_equal(back, result.track)
    assert meta == result.metadata
    assert field_units(path)["speed"] == "m/s" and field_units(path)["heading_deg"] == "deg"


def test_a_stray_time_stamp_is_dropped_and_counted(drive: Drive, reference) -> None:
    """One gyro stamp 23 days late (a corrupt digit): dropped and reported, not integrated."""
    from gpsdr_cli.pipeline import stray_mask

    bad = copy.deepcopy(drive)
    bad.gyro.t_ns[-1] += 2_000_000 * 1_000_000_000
    res = fuse(bad, config.defaults(), reference)
    span_s = (res.track["time"].iloc[-1] - res.track["time"].iloc[0]).total_seconds()
    assert span_s < 61.0  # s: the drive, not 23 days
    import json

    skipped = json.loads(res.metadata["skipped"])
    (reason,) = skipped
    assert reason.startswith("gyro: time stamp more than 3600 s away")
    assert skipped[reason]["count"] == 1 and "record 6256" in skipped[reason]["first"]
    assert res.summary()["rmse_m"] < 4.0
    # two long sessions an hour and a half apart are both kept
    t = np.concatenate([np.arange(1000), 5400 + np.arange(800)]) * 1_000_000_000
    assert stray_mask(t).all()


def test_pdop_is_null_after_a_gnss_record_without_one(drive: Drive) -> None:
    d = copy.deepcopy(drive)
    d.gnss.pdop[100:200] = np.nan  # receiver stopped sending GSA for 10 s
    res = fuse(d, config.defaults())
    t = res.track["time"].astype("int64").to_numpy()
    rec = d.gnss.t_ns
    inside = (t >= rec[100]) & (t < rec[200])
    after = t >= rec[200]
    assert inside.sum() > 1000
    assert np.isnan(res.track["pdop"].to_numpy()[inside]).all()
    assert (res.track["pdop"].to_numpy()[after] == 1.8).all()


def test_one_far_stamp_in_a_short_stream_is_stray_against_the_whole_drive() -> None:
    """60 GNSS fixes and one dated 22 years later: 1.6 % of its stream, but a speck of the
    drive's 1261 records; it must be dropped, not predicted across."""
    from gpsdr_cli.pipeline import stray_mask

    ns = 1_000_000_000
    gnss = np.concatenate((1_700_000_000 * ns + np.arange(60) * ns, [2_400_000_000 * ns]))
    dr = 1_700_000_000 * ns + np.arange(1200) * ns // 20
    keep = stray_mask(gnss, np.concatenate((gnss, dr)))
    assert keep[:60].all() and not keep[60]
    assert stray_mask(dr, np.concatenate((gnss, dr))).all()
