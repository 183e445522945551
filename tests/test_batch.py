"""Batch processing: drive discovery, process pool, resumability, failures, dask.distributed."""

from __future__ import annotations

import os
import shutil
import signal
import time
from pathlib import Path

import pandas as pd
import pytest

from gpsdr_cli import config
from gpsdr_cli.batch import BatchOptions, find_drives, run_dask, run_local
from tests.conftest import SHARED_DATA

pytestmark = pytest.mark.filterwarnings("ignore::UserWarning")

MCAP = SHARED_DATA / "mcap_samples" / "ublox_gps_ros2.mcap"


@pytest.fixture
def logs(sample_dir: Path, tmp_path: Path) -> Path:
    """good/ (with truth), plain/ (no truth, sniffed names), broken/ (garbage NMEA)."""
    root = tmp_path / "logs"
    good = root / "2018" / "good"
    good.mkdir(parents=True)
    for name in ("gps.nmea", "gyro.csv", "odo.csv", "truth.csv"):
        shutil.copy(sample_dir / name, good / name)
    plain = root / "plain"
    plain.mkdir()
    shutil.copy(sample_dir / "gps.nmea", plain / "receiver.txt")  # found by content
    shutil.copy(sample_dir / "gyro.csv", plain / "yaw.csv")
    shutil.copy(sample_dir / "odo.csv", plain / "can_speed.csv")
    broken = root / "broken"
    broken.mkdir()
    (broken / "gps.nmea").write_text("$GPGGA,this,is,not,a,fix\n" * 10)
    shutil.copy(sample_dir / "gyro.csv", broken / "gyro.csv")
    (root / "notes").mkdir()
    (root / "notes" / "README.md").write_text("nothing to see\n")
    return root


def test_find_drives_by_name_and_content(logs: Path) -> None:
    specs = {s.name: s for s in find_drives(str(logs))}
    assert sorted(specs) == ["2018__good", "broken", "plain"]
    good = specs["2018__good"]
    assert Path(good.gps).name == "gps.nmea" and Path(good.reference).name == "truth.csv"
    plain = specs["plain"]
    assert Path(plain.gps).name == "receiver.txt"
    assert Path(plain.gyro).name == "yaw.csv" and Path(plain.odo).name == "can_speed.csv"
    assert plain.reference is None


def test_find_drives_mcap_and_glob(logs: Path, tmp_path: Path) -> None:
    if not MCAP.exists():
        pytest.skip("shared MCAP sample not present")
    shutil.copy(MCAP, logs / "run1.mcap")
    shutil.copy(MCAP, logs / "2018" / "good" / "drive.mcap")  # same recording as the NMEA set
    names = sorted(s.name for s in find_drives(str(logs)))
    assert names == ["2018__good", "broken", "plain", "run1"]
    globbed = find_drives(str(logs / "*.mcap"))
    assert [s.name for s in globbed] == ["run1"] and globbed[0].log.endswith("run1.mcap")
    by_dir_glob = sorted(s.name for s in find_drives(str(logs / "*")))
    assert "2018__good" in by_dir_glob and "plain" in by_dir_glob


def test_batch_cli_report_resume_and_force(gpsdr, logs: Path, tmp_path: Path) -> None:
    out = tmp_path / "out"
    result = gpsdr(["batch", logs, "-o", out, "--jobs", "2", "--filter", "ekf"])
    assert result.exit_code == 1, result.output  # the broken drive fails, the others do not
    report = pd.read_parquet(out / "batch_report.parquet")
    status = dict(zip(report["drive"], report["status"], strict=True))
    assert status == {"2018__good": "ok", "broken": "failed", "plain": "ok"}
    row = report.set_index("drive").loc
    assert "broken/gps.nmea" in row["broken", "error"]
    assert 1.0 < row["2018__good", "rmse_m"] < 4.0  # m, comma2k19 without the latency shift
    assert pd.isna(row["plain", "rmse_m"])  # no reference there
    assert row["2018__good", "epochs"] > 10_000
    for name in ("2018__good", "plain"):
        assert (out / f"{name}.fused.parquet").exists() and (out / f"{name}.stats.parquet").exists()
    assert "2018__good" in result.stdout and "failed" in result.stdout
    assert "1 of 3 drives failed" in result.stderr

    again = gpsdr(["batch", logs, "-o", out, "--jobs", "2", "--filter", "ekf"])
    report = pd.read_parquet(out / "batch_report.parquet").set_index("drive")
    assert report.loc["2018__good", "status"] == "up to date"
    assert report.loc["2018__good", "rmse_m"] == pytest.approx(row["2018__good", "rmse_m"])
    assert again.exit_code == 1

    # a newer input, other parameters, or --force: processed again
    future = time.time() + 5
    os.utime(logs / "plain" / "yaw.csv", (future, future))
    # (two drives to redo: a pool, forked after this process read the up-to-date drive's schema)
    t_before = pd.Timestamp.now(tz="UTC")
    third = gpsdr(["batch", logs, "-o", out, "--jobs", "2", "--filter", "ekf"])
    t_after = pd.Timestamp.now(tz="UTC")
    report = pd.read_parquet(out / "batch_report.parquet").set_index("drive")
    assert report.loc["plain", "status"] == "ok"
    assert report.loc["2018__good", "status"] == "up to date"
    assert third.exit_code == 1
    # the pool's timeline: each drive redone ran within the command's own time span
    report = pd.read_parquet(out / "batch_report.parquet")
    assert str(report["started"].dtype) == "datetime64[ns, UTC]"
    ran = report[report["status"] != "up to date"]
    assert sorted(ran["drive"]) == ["broken", "plain"]
    ends = ran["started"] + pd.to_timedelta(ran["duration_s"], unit="s")
    assert (ran["started"] >= t_before).all() and (ends <= t_after).all()
    other = gpsdr(["batch", logs / "2018", "-o", out, "--filter", "aekf", "-q"])
    assert other.exit_code == 0, other.output
    assert pd.read_parquet(out / "batch_report.parquet")["status"].tolist() == ["ok"]
    forced = gpsdr(["batch", logs / "2018", "-o", out, "--filter", "aekf", "--force", "-q"])
    assert pd.read_parquet(out / "batch_report.parquet")["status"].tolist() == ["ok"]
    assert forced.exit_code == 0


def test_batch_nothing_found(gpsdr, tmp_path: Path) -> None:
    (tmp_path / "empty").mkdir()
    result = gpsdr(["batch", tmp_path / "empty", "-o", tmp_path / "out"])
    assert result.exit_code == 1 and "no drive found" in result.stderr
    result = gpsdr(["batch", str(tmp_path / "nothing*"), "-o", tmp_path / "out"])
    assert result.exit_code == 1 and "no file matches" in result.stderr


def test_batch_on_dask(logs: Path, tmp_path: Path, gpsdr) -> None:
    """The same batch on a dask.distributed LocalCluster, through the API and the CLI."""
    from dask.distributed import Client, LocalCluster

    params = config.defaults()
    params["filter"]["name"] = "ekf"
    specs = find_drives(str(logs))
    with LocalCluster(n_workers=1, threads_per_worker=2, processes=False,
                      dashboard_address=None) as cluster, Client(cluster) as client:
        rows = run_dask(specs, BatchOptions(out_dir=str(tmp_path / "api"), params=params), client)
        (tmp_path / "cli").mkdir()
        result = gpsdr(["batch", logs, "-o", tmp_path / "cli", "--filter", "ekf",
                        "--scheduler", cluster.scheduler_address])
    by = {r["drive"]: r for r in rows}
    assert {k: v["status"] for k, v in by.items()} == {"2018__good": "ok", "broken": "failed",
                                                       "plain": "ok"}
    local = {r["drive"]: r for r in run_local(specs, BatchOptions(
        out_dir=str(tmp_path / "local"), params=params), jobs=1)}
    # same code, same numbers, wherever it ran
    assert by["2018__good"]["rmse_m"] == pytest.approx(local["2018__good"]["rmse_m"], abs=1e-9)
    assert result.exit_code == 1
    report = pd.read_parquet(tmp_path / "cli" / "batch_report.parquet")
    assert sorted(report["status"]) == ["failed", "ok", "ok"]


def test_unreachable_scheduler_is_a_usage_error(logs: Path, tmp_path: Path) -> None:
    from gpsdr_cli.errors import UsageError

    opts = BatchOptions(out_dir=str(tmp_path / "o"), params=config.defaults())
    with pytest.raises(UsageError, match="cannot connect to the dask scheduler tcp://127.0.0.1:9"):
        run_dask(find_drives(str(logs / "2018")), opts, "tcp://127.0.0.1:9", connect_timeout_s=1)


def crash_on_broken(spec, opts):  # a module-level worker the process pool can import
    from gpsdr_cli.batch import _row

    time.sleep(0.5)  # the other drives are in flight when the crash takes the pool down
    if spec.name == "broken":
        os.kill(os.getpid(), signal.SIGKILL)  # killed mid-drive (as the OOM killer would)
    return _row(spec, "ok")


def available(*methods: str) -> list[str]:
    import multiprocessing as mp

    return [m for m in methods if m in mp.get_all_start_methods()]


@pytest.mark.parametrize("method", available("fork", "forkserver"))
def test_a_crashing_worker_fails_only_its_drive(logs: Path, tmp_path: Path, method: str) -> None:
    params = config.defaults()
    params["filter"]["name"] = "ekf"
    order: list[str] = []
    rows = run_local(find_drives(str(logs)), BatchOptions(out_dir=str(tmp_path / "o"),
                                                          params=params),
                     jobs=3, worker=crash_on_broken, method=method,
                     on_ready=lambda: order.append("ready"),
                     on_done=lambda row: order.append(row["drive"]))
    by = {r["drive"]: r for r in rows}
    assert {k: v["status"] for k, v in by.items()} == {"2018__good": "ok", "broken": "failed",
                                                       "plain": "ok"}
    assert "worker process died" in by["broken"]["error"]
    assert order[0] == "ready" and sorted(order[1:]) == ["2018__good", "broken", "plain"]


def crash_on_first(spec, opts):  # module-level: the pool imports it
    from gpsdr_cli.batch import _row

    time.sleep(0.3)
    if spec.name == "d0":
        os.kill(os.getpid(), signal.SIGKILL)
    return _row(spec, "ok", f"pid={os.getpid()}")


@pytest.mark.parametrize("method", available("fork", "forkserver"))
def test_after_a_crash_the_rest_of_the_batch_runs_in_a_new_pool(tmp_path: Path,
                                                                method: str) -> None:
    """Only the drives in flight are rerun alone; the others go on sharing worker processes."""
    from gpsdr_cli.batch import DriveSpec

    specs = []
    for i in range(10):  # d0 is the largest: the pool starts it first
        (tmp_path / f"d{i}.nmea").write_bytes(b"x" * (1000 - 10 * i))
        specs.append(DriveSpec(name=f"d{i}", gps=str(tmp_path / f"d{i}.nmea")))
    rows = run_local(specs, BatchOptions(out_dir=str(tmp_path / "o"), params=config.defaults()),
                     jobs=2, worker=crash_on_first, method=method)
    by = {r["drive"]: r for r in rows}
    assert sorted(by) == [f"d{i}" for i in range(10)]
    assert by["d0"]["status"] == "failed" and "worker process died" in by["d0"]["error"]
    ok = [r for r in rows if r["status"] == "ok"]
    assert len(ok) == 9
    # the broken pool held at most jobs + 1 = 3 drives besides those it finished (one worker
    # survived until the crash): those are rerun alone, one process each; the others share
    # the 2 workers of the next pool.  Rerunning every unfinished drive alone would give 9.
    pids = {r["error"] for r in ok}
    assert len(pids) <= 1 + 2 + 2, [(r["drive"], r["error"][:9]) for r in rows]


def inherited_state(spec, opts):  # what a worker holds before it touches its drive
    import sys

    from gpsdr_cli.batch import _row

    kernels = sys.modules.get("gpsdr_cli.filters.kernels_aekf")
    loaded = kernels is not None and len(kernels.cs_filter_kernel.signatures) > 0
    return _row(spec, "ok", f"pipeline={'gpsdr_cli.pipeline' in sys.modules} kernels={loaded}")


@pytest.mark.parametrize("method", available("fork", "forkserver"))
def test_forked_workers_start_warm(logs: Path, tmp_path: Path, method: str) -> None:
    """fork: every worker inherits the parent's imports and loaded kernels; forkserver: none."""
    params = config.defaults()
    params["filter"]["name"] = "ekf"
    rows = run_local(find_drives(str(logs)), BatchOptions(out_dir=str(tmp_path / "o"),
                                                          params=params),
                     jobs=2, worker=inherited_state, method=method)
    want = "pipeline=True kernels=True" if method == "fork" else "pipeline=False kernels=False"
    assert [r["error"] for r in rows] == [want] * 3


def test_fork_only_while_no_other_thread_runs(monkeypatch: pytest.MonkeyPatch) -> None:
    import multiprocessing as mp
    import threading

    from gpsdr_cli.batch import start_method

    if "fork" not in mp.get_all_start_methods():
        pytest.skip("no fork on this platform")
    stop = threading.Event()
    t = threading.Thread(target=stop.wait)  # as rich's refresh thread would be
    t.start()
    try:
        assert start_method() in ("forkserver", "spawn")
    finally:
        stop.set()
        t.join()
    # (earlier tests may leave threads behind, e.g. dask's: pretend this one is alone)
    monkeypatch.setattr(threading, "active_count", lambda: 1)
    assert start_method() == "fork"


def test_pool_starts_the_largest_drives_first(tmp_path: Path) -> None:
    from gpsdr_cli.batch import DriveSpec, largest_first

    sizes = {"small": 10, "big": 3000, "middle": 500}
    specs = []
    for name, size in sizes.items():
        (tmp_path / f"{name}.nmea").write_bytes(b"x" * size)
        (tmp_path / f"{name}.csv").write_bytes(b"y" * size)
        specs.append(DriveSpec(name=name, gps=str(tmp_path / f"{name}.nmea"),
                               gyro=str(tmp_path / f"{name}.csv")))
    specs.append(DriveSpec(name="missing", gps=str(tmp_path / "nope.nmea")))
    assert [s.name for s in largest_first(specs)] == ["big", "middle", "small", "missing"]
