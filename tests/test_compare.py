"""``gpsdr compare``: one row per filter x smoother, each equal to what ``gpsdr fuse`` gives."""

from __future__ import annotations

from pathlib import Path

import pandas as pd
import pytest

from gpsdr_cli import config
from gpsdr_cli.cli.options import FILTER_NAMES
from gpsdr_cli.compare import smoother_names, with_smoother
from gpsdr_cli.errors import UsageError
from tests.conftest import one_line_error

#: Same pipeline, same parameters: the figures agree to rounding (m).
SAME_M = 1e-9


@pytest.fixture(scope="module")
def drive_dir(tmp_path_factory) -> Path:
    """A 120 s simulated highway drive with a tunnel, and its truth."""
    from click.testing import CliRunner

    from gpsdr_cli.cli.main import cli

    out = tmp_path_factory.mktemp("sim")
    res = CliRunner().invoke(cli, ["simulate", "-q", "-o", str(out), "--scenario", "tunnels",
                                   "--seed", "2", "--duration", "120"], catch_exceptions=False)
    assert res.exit_code == 0, res.output
    return out


def _streams(d: Path) -> list[str]:
    return ["--gps", str(d / "gps.nmea"), "--gyro", str(d / "gyro.csv"), "--odo", str(d / "odo.csv")]


def _fuse_all_row(gpsdr, d: Path, tmp: Path, name: str, smooth: bool, reference: bool) -> pd.Series:
    track, stats = tmp / f"{name}{smooth}.parquet", tmp / f"{name}{smooth}.stats.parquet"
    args = ["fuse", *_streams(d), "--filter", name, "--smooth" if smooth else "--no-smooth",
            "-o", track, "--stats", stats, "-q"]
    if reference:
        args += ["--reference", d / "truth.csv"]
    res = gpsdr(args)
    assert res.exit_code == 0, res.stderr
    s = pd.read_parquet(stats)
    return s[s["segment"] == "all"].iloc[0]


def test_table_has_one_row_per_run_equal_to_fuse(gpsdr, drive_dir, tmp_path) -> None:
    table_path = tmp_path / "table.csv"
    plot_path = tmp_path / "overlay.png"
    res = gpsdr(["compare", *_streams(drive_dir), "--reference", drive_dir / "truth.csv",
                 "--filters", ",".join(FILTER_NAMES), "--smooth", "none,rts",
                 "-o", table_path, "--plot", plot_path, "-q"])
    assert res.exit_code == 0, res.stderr
    table = pd.read_csv(table_path)
    assert len(table) == len(FILTER_NAMES) * 2
    assert list(zip(table["filter"], table["smoother"], strict=True)) == [
        (f, s) for f in FILTER_NAMES for s in ("none", "rts")]
    for rec in table.itertuples(index=False):
        ref = _fuse_all_row(gpsdr, drive_dir, tmp_path, rec.filter, rec.smoother == "rts", True)
        for col in ("rmse_m", "cep95_m", "max_m", "nis_in_95_share", "gnss_separation_rmse_m"):
            assert abs(getattr(rec, col) - float(ref[col])) <= SAME_M, (rec.filter, rec.smoother, col)
        assert rec.epochs == int(ref["epochs"])
    # against the truth every run stays within metres on an open highway with one tunnel
    assert table["rmse_m"].max() < 5.0  # m
    # the printed table names every run with its RMSE
    lines = res.stdout.strip().splitlines()
    assert len(lines) == 1 + len(table) and "rmse_m" in lines[0]
    first = table.iloc[0]
    assert f"{first['rmse_m']:.3f}" in lines[1]
    assert plot_path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and plot_path.stat().st_size > 30_000


def test_without_a_reference_the_health_figures(gpsdr, drive_dir, tmp_path) -> None:
    out = tmp_path / "table.parquet"
    res = gpsdr(["compare", *_streams(drive_dir), "--filters", "aekf,ekf", "--smooth", "rts",
                 "-o", out, "--plot", tmp_path / "o.png", "-q"])
    assert res.exit_code == 0, res.stderr
    table = pd.read_parquet(out)
    assert list(table["filter"]) == ["aekf", "ekf"] and set(table["smoother"]) == {"rts"}
    assert table["rmse_m"].isna().all()  # no reference: a null, not a number
    assert "rmse_m" not in res.stdout.splitlines()[0].split()
    for rec in table.itertuples(index=False):
        ref = _fuse_all_row(gpsdr, drive_dir, tmp_path, rec.filter, True, False)
        assert abs(rec.nis_in_95_share - float(ref["nis_in_95_share"])) <= SAME_M
        assert abs(rec.gnss_separation_rmse_m - float(ref["gnss_separation_rmse_m"])) <= SAME_M
    import pyarrow.parquet as pq

    schema = pq.read_schema(out)
    assert schema.field("rmse_m").metadata[b"unit"] == b"m"
    assert schema.metadata[b"compare.filters"] == b"aekf,ekf"


def test_the_default_adds_what_fuse_runs_by_default(gpsdr, drive_dir, tmp_path) -> None:
    """``--smooth`` defaults to none,rts,auto; auto's row is named by what ran (the graph on a
    drive with a gyro and an odometer) and equals ``gpsdr fuse``'s default; on fixes alone
    auto is RTS, already a row, and is not repeated."""
    out = tmp_path / "table.csv"
    res = gpsdr(["compare", *_streams(drive_dir), "--reference", drive_dir / "truth.csv",
                 "--filters", "aekf", "-o", out, "-q"])
    assert res.exit_code == 0, res.stderr
    table = pd.read_csv(out)
    assert list(table["smoother"]) == ["none", "rts", "graph"]
    track, stats = tmp_path / "d.parquet", tmp_path / "d.stats.parquet"
    fused = gpsdr(["fuse", *_streams(drive_dir), "--filter", "aekf", "-o", track, "--stats",
                   stats, "--reference", drive_dir / "truth.csv", "-q"])
    assert fused.exit_code == 0, fused.stderr
    s = pd.read_parquet(stats)
    ref = s[s["segment"] == "all"].iloc[0]
    assert abs(table["rmse_m"].iloc[2] - float(ref["rmse_m"])) <= SAME_M
    assert table["rmse_m"].iloc[2] < table["rmse_m"].iloc[0]      # below the forward filter
    res = gpsdr(["compare", "--gps", drive_dir / "gps.nmea", "--filters", "ekf", "-o", out, "-q"])
    assert res.exit_code == 0, res.stderr
    assert list(pd.read_csv(out)["smoother"]) == ["none", "rts"]


@pytest.mark.parametrize(("args", "needle"), [
    (["--filters", "ekf,kalman"], "--filters kalman: unknown"),
    (["--smooth", "none,spline"], "--smooth spline: unknown"),
    (["-o", "table.xlsx"], ".csv or .parquet"),
])
def test_bad_lists_are_usage_errors(gpsdr, drive_dir, args, needle) -> None:
    res = gpsdr(["compare", *_streams(drive_dir), *args])
    assert res.exit_code == 2
    assert needle in one_line_error(res)


def test_smoothers_follow_the_parameter_type() -> None:
    p = config.defaults()
    assert set(smoother_names(p)) == {"auto", "none", "rts", "graph"}
    assert with_smoother(p, "rts")["filter"]["smooth"] is True
    assert with_smoother(p, "none")["filter"]["smooth"] is False
    assert with_smoother(p, "graph")["filter"]["smoother"] == "graph"
    with pytest.raises(UsageError):
        with_smoother(p, "kalman")
    assert p["filter"]["smooth"] is False  # the caller's parameters are not changed
