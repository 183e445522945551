"""Many drives at once: find them, fuse each in a worker, write one report.

A *drive* is either an MCAP file, or a folder holding an NMEA file and gyro /
odometer CSVs (named ``gps.nmea``, ``gyro.csv``, ``odo.csv``, or found by
sniffing the files' contents); a ``truth.csv`` next to it (``<stem>.truth.csv``
for an MCAP) is used as the reference.  A folder that holds an NMEA + CSV set
is one drive even if it also holds an MCAP of the same recording (as
``gpsdr simulate`` writes); MCAPs are drives of their own elsewhere.

Workers: a ``concurrent.futures.ProcessPoolExecutor`` (the default; processes
because the filters hold the GIL between numba kernels and pandas), or a
dask.distributed cluster (``scheduler="tcp://host:8786"``) with
``client.map`` / ``as_completed``: the same function runs on every worker, so
every worker needs gpsdr installed and the input and output paths visible
(a shared filesystem).  One failing drive never stops the batch: its row in
the report says why.

The local pool forks its workers from a warmed parent (imports done, filter
kernels loaded or compiled once: :func:`warm_parent`) while the parent runs no
other thread, so a worker starts on its first drive at once instead of paying
~1 s of CPU (4+ s with a cold numba cache) to import and load the same things;
with another thread alive (a progress bar already shown, a dask client) it
falls back to forkserver.  Drives go in largest first, at most ``jobs + 1`` at
a time, so a worker that dies loses only those: they are rerun alone (only the
culprit fails) and the rest continues in a new pool.

Resumable: a drive whose outputs exist, are newer than all its inputs and were
made with the same parameters is skipped unless ``force``.
"""

from __future__ import annotations

import glob
import math
import os
import time
import traceback
import warnings
from collections.abc import Callable, Iterable
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

from .config import Params

REPORT_NAME = "batch_report.parquet"
REPORT_UNITS = {
    "drive": "drive name (output file stem)",
    "status": "ok, failed, or up to date (skipped: outputs newer than inputs)",
    "error": "one-line error message of a failed drive",
    "started": "UTC time the worker started the drive (the pool's timeline)",
    "duration_s": "s, wall-clock time to process the drive",
    "cpu_s": "s, CPU time (user + system) of the worker process while it processed the drive",
    "epochs": "count of filter epochs",
    "rmse_m": "m, horizontal RMS error against the reference (null without one)",
    "cep95_m": "m, 95th percentile horizontal error against the reference",
    "max_m": "m, largest horizontal error against the reference",
    "track": "path of the track file",
    "stats": "path of the statistics file",
    "inputs": "input files, ; separated",
}
GPS_NAMES = ("gps.nmea", "gnss.nmea")
GYRO_NAMES = ("gyro.csv", "imu.csv")
ODO_NAMES = ("odo.csv", "odometer.csv", "speed.csv", "wheel.csv")
TRUTH_NAMES = ("truth.csv", "reference.csv")
NMEA_SUFFIXES = (".nmea", ".txt", ".log")


@dataclass
class DriveSpec:
    """One drive to process: its files, and the stem its outputs are named by."""

    name: str
    log: str | None = None
    gps: str | None = None
    gyro: str | None = None
    odo: str | None = None
    reference: str | None = None

    @property
    def inputs(self) -> list[str]:
        return [p for p in (self.log, self.gps, self.gyro, self.odo, self.reference) if p]


@dataclass
class BatchOptions:
    """What every drive of a batch is processed with (picklable: it goes to the workers)."""

    out_dir: str
    params: Params
    fmt: str = "parquet"
    force: bool = False
    extra_meta: dict[str, str] = field(default_factory=dict)
    auto_gnss_offset: bool = False
    topics: dict[str, str] | None = None
    date: Any = None
    use_log_time: bool = False


# --------------------------------------------------------------------------- discovery

def _csv_kind(path: Path) -> str | None:
    """gyro | odo | truth by the CSV header, None when it is none of them."""
    try:
        with open(path, "rb") as fh:
            head = fh.readline(4096).decode("utf-8", "replace").lstrip("\ufeff").lower()
    except OSError:
        return None
    cols = {c.strip() for c in head.split(",")}
    if "yaw_rate" in cols:
        return "gyro"
    if cols & {"speed", "distance", "ticks"}:
        return "odo"
    if {"lat", "lon"} <= cols:
        return "truth"
    return None


def _is_nmea(path: Path) -> bool:
    try:
        from .io.nmea import looks_like_nmea

        with open(path, "rb") as fh:
            return bool(looks_like_nmea(fh.read(4096)))
    except (OSError, ImportError):
        return path.suffix.lower() == ".nmea"


def _folder_drive(folder: Path, root: Path) -> DriveSpec | None:
    """The NMEA + CSV drive in ``folder``, or None if it holds none."""
    files = sorted(p for p in folder.iterdir() if p.is_file())
    by_name = {p.name.lower(): p for p in files}
    gps = next((by_name[n] for n in GPS_NAMES if n in by_name), None)
    if gps is None:
        gps = next((p for p in files if p.suffix.lower() in NMEA_SUFFIXES and _is_nmea(p)), None)
    if gps is None:
        return None
    found: dict[str, Path] = {}
    for kind, names in (("gyro", GYRO_NAMES), ("odo", ODO_NAMES), ("truth", TRUTH_NAMES)):
        hit = next((by_name[n] for n in names if n in by_name), None)
        if hit is not None:
            found[kind] = hit
    for p in files:
        if p.suffix.lower() == ".csv" and p not in found.values():
            kind = _csv_kind(p)
            if kind and kind not in found and "uncalibrated" not in p.name:
                found[kind] = p
    return DriveSpec(name=_name_for(folder, root), gps=str(gps),
                     gyro=str(found["gyro"]) if "gyro" in found else None,
                     odo=str(found["odo"]) if "odo" in found else None,
                     reference=str(found["truth"]) if "truth" in found else None)


def _mcap_drive(path: Path, root: Path) -> DriveSpec:
    ref: str | None = None
    own = path.with_name(f"{path.stem}.truth.csv")
    plain = path.with_name("truth.csv")
    if own.exists():
        ref = str(own)
    elif plain.exists() and not [p for p in path.parent.glob("*.mcap") if p != path]:
        ref = str(plain)
    rel = _name_for(path.parent, root)
    name = path.stem if path.parent.resolve() == root.resolve() else f"{rel}__{path.stem}"
    return DriveSpec(name=name, log=str(path), reference=ref)


def _name_for(folder: Path, root: Path) -> str:
    try:
        rel = folder.resolve().relative_to(root.resolve())
    except ValueError:
        rel = Path(folder.name)
    parts = [p for p in rel.parts if p not in ("", ".")]
    return "__".join(parts) if parts else folder.resolve().name


def _scan_dir(root: Path, base: Path) -> list[DriveSpec]:
    out: list[DriveSpec] = []
    for folder, dirs, _files in os.walk(root):
        dirs[:] = sorted(d for d in dirs if not d.startswith("."))
        f = Path(folder)
        spec = _folder_drive(f, base)
        if spec is not None:
            out.append(spec)
            continue
        for mcap in sorted(f.glob("*.mcap")):
            out.append(_mcap_drive(mcap, base))
    return out


def find_drives(target: str) -> list[DriveSpec]:
    """Drives under a directory (recursively) or matching a glob pattern."""
    from .errors import InputError

    p = Path(target)
    if p.is_dir():
        specs = _scan_dir(p, p)
    else:
        matches = sorted(glob.glob(target, recursive=True))
        if not matches:
            raise InputError(target, "no such file or directory, and no file matches the pattern")
        base = Path(os.path.commonpath([os.path.abspath(m) for m in matches]))
        if base.is_file():
            base = base.parent
        specs = []
        seen: set[str] = set()
        for m in map(Path, matches):
            if m.is_dir():
                new = _scan_dir(m, base)
            elif m.suffix.lower() == ".mcap":
                new = [_mcap_drive(m, base)]
            else:
                spec = _folder_drive(m.parent, base)
                new = [spec] if spec is not None and spec.gps == str(m) else []
            for s in new:
                if s.name not in seen:
                    seen.add(s.name)
                    specs.append(s)
    names: dict[str, int] = {}
    for s in specs:  # unique output stems
        k = names.get(s.name, 0)
        names[s.name] = k + 1
        if k:
            s.name = f"{s.name}_{k}"
    return specs


# --------------------------------------------------------------------------- one drive

def output_paths(spec: DriveSpec, out_dir: str, fmt: str) -> tuple[Path, Path]:
    ext = "parquet" if fmt == "parquet" else "csv"
    d = Path(out_dir)
    return d / f"{spec.name}.fused.{ext}", d / f"{spec.name}.stats.{ext}"


def request_key(opts: BatchOptions) -> str:
    """What a drive's outputs were asked for with (stored in the track; resume compares it)."""
    from . import config

    return (config.to_toml(opts.params) + f"# auto_gnss_offset = {opts.auto_gnss_offset}\n"
            f"# topics = {opts.topics}\n# date = {opts.date}\n# log_time = {opts.use_log_time}\n")


def _up_to_date(spec: DriveSpec, track: Path, stats: Path, opts: BatchOptions) -> bool:
    try:
        newest_in = max(Path(p).stat().st_mtime for p in spec.inputs)
        oldest_out = min(track.stat().st_mtime, stats.stat().st_mtime)
    except (OSError, ValueError):
        return False
    if oldest_out < newest_in:
        return False
    if opts.fmt != "parquet":
        return True
    import pyarrow.parquet as pq

    try:
        meta = pq.read_schema(track).metadata or {}
    except (OSError, ValueError):
        return False
    return meta.get(b"batch.request", b"").decode() == request_key(opts)


def _row(spec: DriveSpec, status: str, error: str = "", duration_s: float = 0.0,
         summary: dict[str, float] | None = None, track: str = "", stats: str = "",
         cpu_s: float = 0.0) -> dict[str, Any]:
    s = summary or {}
    nan = float("nan")
    started_ns = time.time_ns() - round(duration_s * 1e9)  # the row is made when the drive ends
    return {"drive": spec.name, "status": status, "error": error, "started": started_ns,
            "duration_s": duration_s,
            "cpu_s": cpu_s,
            "epochs": int(s["epochs"]) if s.get("epochs", nan) == s.get("epochs", nan) else -1,
            "rmse_m": s.get("rmse_m", nan), "cep95_m": s.get("cep95_m", nan),
            "max_m": s.get("max_m", nan), "track": track, "stats": stats,
            "inputs": ";".join(spec.inputs)}


def process_drive(spec: DriveSpec, opts: BatchOptions) -> dict[str, Any]:
    """Fuse one drive and write its outputs; never raises (errors become the row)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")  # a worker's warnings would garble the progress bar
        return _process_drive(spec, opts)


def _process_drive(spec: DriveSpec, opts: BatchOptions) -> dict[str, Any]:
    from .errors import GpsdrError

    t0 = time.perf_counter()
    c0 = time.process_time()
    track_p, stats_p = output_paths(spec, opts.out_dir, opts.fmt)
    try:
        if not opts.force and _up_to_date(spec, track_p, stats_p, opts):
            summary = _existing_summary(stats_p, opts.fmt)
            return _row(spec, "up to date", "", time.perf_counter() - t0, summary,
                        str(track_p), str(stats_p), time.process_time() - c0)
        from .io.parquet import write_table
        from .io.readers import read_drive
        from .pipeline import WRITTEN_TRACK_UNITS, fuse, stats_units

        drive = read_drive(spec.log, gps=spec.gps, gyro=spec.gyro, odo=spec.odo,
                           params=opts.params, topics=opts.topics, date=opts.date,
                           use_log_time=opts.use_log_time)
        ref = None
        if spec.reference:
            from .io.reference import read_reference

            ref = read_reference(spec.reference)
        res = fuse(drive, opts.params, ref, auto_gnss_offset=opts.auto_gnss_offset)
        del drive  # as gpsdr fuse: only the outputs are wanted now (each worker's peak)
        res.release_arrays()
        stats_p.parent.mkdir(parents=True, exist_ok=True)  # a worker on another machine
        meta = {**res.metadata, **opts.extra_meta, "drive": spec.name,
                "batch.request": request_key(opts)}
        write_table(res.track, track_p, metadata=meta, units=WRITTEN_TRACK_UNITS, fmt=opts.fmt)
        write_table(res.stats, stats_p, metadata=meta, units=stats_units(res.stats), fmt=opts.fmt)
        return _row(spec, "ok", "", time.perf_counter() - t0, res.summary(),
                    str(track_p), str(stats_p), time.process_time() - c0)
    except GpsdrError as err:
        return _row(spec, "failed", str(err), time.perf_counter() - t0,
                    cpu_s=time.process_time() - c0)
    except Exception as err:  # noqa: BLE001 - one bad drive never stops the batch: a report row
        tb = traceback.extract_tb(err.__traceback__)
        where = f" at {Path(tb[-1].filename).name}:{tb[-1].lineno}" if tb else ""
        msg = " ".join(str(err).split())
        return _row(spec, "failed", f"internal error: {type(err).__name__}: {msg}{where}",
                    time.perf_counter() - t0, cpu_s=time.process_time() - c0)


def _existing_summary(stats_p: Path, fmt: str) -> dict[str, float]:
    from .errors import GpsdrError
    from .io.parquet import read_track
    from .pipeline import summary_of

    try:
        df, _ = read_track(stats_p)
    except (GpsdrError, OSError):  # a stale stats file only costs the RMSE column of the report
        return {}
    return summary_of(df)


# --------------------------------------------------------------------------- many drives

OnDone = Callable[[dict[str, Any]], None]


def plan(specs: Iterable[DriveSpec], opts: BatchOptions,
         done: OnDone) -> list[DriveSpec]:
    """Report the drives that are up to date (cheap, here) and return the ones to process."""
    Path(opts.out_dir).mkdir(parents=True, exist_ok=True)
    todo: list[DriveSpec] = []
    for spec in specs:
        track_p, stats_p = output_paths(spec, opts.out_dir, opts.fmt)
        if not opts.force and _up_to_date(spec, track_p, stats_p, opts):
            done(_row(spec, "up to date", "", 0.0, _existing_summary(stats_p, opts.fmt),
                      str(track_p), str(stats_p)))
        else:
            todo.append(spec)
    return todo


Worker = Callable[[DriveSpec, BatchOptions], dict[str, Any]]

#: What a drive needs beyond this module: imported once in the parent before forking.
DRIVE_MODULES = ("pyarrow.parquet", "gpsdr_cli.io.readers", "gpsdr_cli.io.nmea",
                 "gpsdr_cli.io.csv", "gpsdr_cli.io.mcap", "gpsdr_cli.io.reference",
                 "gpsdr_cli.io.parquet", "gpsdr_cli.pipeline", "gpsdr_cli.evaluation")


def start_method() -> str:
    """How the pool starts its workers: ``fork`` when it is safe, else forkserver / spawn.

    ``fork`` lets every worker inherit the parent's imports and loaded kernels
    (:func:`warm_parent`) instead of paying ~1 s of CPU each to import pandas /
    pyarrow / numba and load the kernels again (4+ s each to compile them with a
    cold numba cache).  It is safe only while this process runs no other thread:
    fork copies the calling thread alone, so a lock another thread holds (rich's
    refresh thread, a dask client) would stay locked in the child forever.
    """
    import multiprocessing as mp

    from .warmup import fork_is_safe

    if fork_is_safe():
        return "fork"
    return "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"


def warm_parent(opts: BatchOptions) -> None:
    """Import what a drive needs and load (or compile) its kernels, in this process.

    Forked workers then start with all of it.  A failure here only costs time:
    every drive meets the same error again and reports it in its row.
    """
    import importlib

    from .warmup import warm_up

    for name in DRIVE_MODULES:
        importlib.import_module(name)
    try:
        warm_up(opts.params, auto_gnss_offset=opts.auto_gnss_offset)
    except Exception:  # noqa: BLE001, S110 - an optimisation: each drive reports this error itself
        pass


def input_bytes(spec: DriveSpec) -> int:
    """Total size of a drive's input files (bytes; 0 for one that cannot be read)."""
    total = 0
    for p in spec.inputs:
        try:
            total += os.stat(p).st_size
        except OSError:
            pass  # the worker reports the missing file
    return total


def largest_first(specs: list[DriveSpec]) -> list[DriveSpec]:
    """The drives in the order a pool should start them: the longest (largest inputs) first.

    Longest-processing-time-first scheduling: a long drive started last would
    keep one worker busy while the others idle at the end of the batch.
    """
    return sorted(specs, key=input_bytes, reverse=True)


def run_local(specs: Iterable[DriveSpec], opts: BatchOptions, jobs: int,
              on_done: OnDone | None = None, worker: Worker | None = None,
              on_ready: Callable[[], None] | None = None,
              method: str | None = None) -> list[dict[str, Any]]:
    """Process drives in a process pool (``jobs`` workers; 1 = in this process).

    ``worker`` (default :func:`process_drive`) must be a module-level function.
    ``on_ready`` is called once the workers exist and before the first
    ``on_done``: a caller that starts threads (a progress display) starts them
    there, so that forked workers do not inherit them.  ``method`` forces the
    start method (default :func:`start_method`).
    """
    work = worker or process_drive
    rows: list[dict[str, Any]] = []
    pending: list[dict[str, Any]] = []

    def done(row: dict[str, Any]) -> None:
        rows.append(row)
        if on_done:
            on_done(row)

    specs = plan(specs, opts, pending.append)

    def ready() -> None:
        if on_ready:
            on_ready()
        for row in pending:
            done(row)

    if jobs <= 1 or len(specs) <= 1:
        ready()
        for spec in specs:
            done(work(spec, opts))
        return rows
    method = method or start_method()
    if method == "fork":
        warm_parent(opts)
    queue = largest_first(specs)
    first = True
    while queue:
        suspects = _run_pool(work, queue, opts, jobs, method, ready if first else None, done)
        first = False
        # A worker that dies (segfault, out-of-memory kill) takes the whole pool down with
        # every drive in flight: rerun each of those alone, so that only the culprit fails,
        # then go on with a new pool.  (fork again only if no thread has started meanwhile,
        # e.g. the caller's progress display; else a cold forkserver pool)
        for spec in suspects:
            done(_run_alone(work, spec, opts, start_method()))
        method = start_method()
    return rows


def _run_pool(work: Worker, queue: list[DriveSpec], opts: BatchOptions, jobs: int, method: str,
              ready: Callable[[], None] | None, done: OnDone) -> list[DriveSpec]:
    """Run drives from the front of ``queue`` in one pool until it is empty or the pool breaks.

    At most ``jobs + 1`` drives are handed to the pool at a time (one waiting, so that
    no worker idles between two drives): when a worker dies, only those are lost.
    Returns the drives that were in the pool when it broke (none if it did not).
    """
    import multiprocessing as mp
    from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
    from concurrent.futures.process import BrokenProcessPool

    if method == "fork":
        from .warmup import flush_std_streams

        flush_std_streams()
    lost: list[DriveSpec] = []
    with ProcessPoolExecutor(max_workers=min(jobs, len(queue)),
                             mp_context=mp.get_context(method)) as pool:
        running: dict[Any, DriveSpec] = {}

        def fill() -> None:
            while queue and len(running) <= jobs:
                spec = queue.pop(0)
                running[pool.submit(work, spec, opts)] = spec

        fill()  # with fork, the first submit forks every worker (before the pool's thread starts)
        if ready:
            ready()
        while running:
            finished, _ = wait(running, return_when=FIRST_COMPLETED)
            for fut in finished:
                spec = running.pop(fut)
                try:
                    done(fut.result())
                except BrokenProcessPool:
                    lost.append(spec)
            if not lost:
                fill()
    return lost


def _run_alone(work: Worker, spec: DriveSpec, opts: BatchOptions, method: str) -> dict[str, Any]:
    import multiprocessing as mp
    from concurrent.futures import ProcessPoolExecutor
    from concurrent.futures.process import BrokenProcessPool

    t0 = time.perf_counter()
    if method == "fork":
        from .warmup import flush_std_streams

        flush_std_streams()
    with ProcessPoolExecutor(max_workers=1, mp_context=mp.get_context(method)) as pool:
        try:
            return pool.submit(work, spec, opts).result()
        except BrokenProcessPool:
            return _row(spec, "failed", "worker process died while processing this drive "
                        "(crashed or killed, e.g. out of memory)", time.perf_counter() - t0)


def run_dask(specs: Iterable[DriveSpec], opts: BatchOptions, scheduler: Any,
             on_done: OnDone | None = None, connect_timeout_s: float = 10.0) -> list[dict[str, Any]]:
    """Process drives on a dask.distributed cluster (address ``tcp://host:port`` or a Client)."""
    from dask.distributed import Client, as_completed

    from .errors import UsageError

    rows: list[dict[str, Any]] = []

    def done(row: dict[str, Any]) -> None:
        rows.append(row)
        if on_done:
            on_done(row)

    specs = plan(specs, opts, done)
    if not specs:
        return rows
    own = not isinstance(scheduler, Client)
    try:
        client = Client(scheduler, timeout=f"{connect_timeout_s}s") if own else scheduler
    except (OSError, TimeoutError, ValueError) as err:
        raise UsageError(f"cannot connect to the dask scheduler {scheduler}: {err}") from err
    try:
        futures = client.map(process_drive, specs, opts=opts, pure=False)
        by_key = {f.key: s for f, s in zip(futures, specs, strict=True)}
        for fut in as_completed(futures):
            spec = by_key[fut.key]
            try:
                row = fut.result()
            except Exception as err:  # noqa: BLE001 - worker died / task lost: that drive failed
                row = _row(spec, "failed", f"dask task failed: {type(err).__name__}: {err}")
            done(row)
    finally:
        if own:
            client.close()
    return rows


def report_frame(rows: list[dict[str, Any]]) -> Any:
    import pandas as pd

    cols = list(REPORT_UNITS)
    df = pd.DataFrame(rows, columns=cols)
    if len(df):
        df = df.sort_values("drive", kind="stable").reset_index(drop=True)
    df["epochs"] = df["epochs"].astype("int64")
    df["started"] = pd.to_datetime(df["started"].astype("int64"), unit="ns", utc=True)
    for c in ("duration_s", "cpu_s", "rmse_m", "cep95_m", "max_m"):
        df[c] = df[c].astype("float64")
    return df


def spec_dict(spec: DriveSpec) -> dict[str, Any]:
    return asdict(spec)


# --------------------------------------------------------------------------- vehicle calibration

@dataclass
class VehicleCalibration:
    """One vehicle's odometer scale, gyro bias and gyro scale (true rate / reading) pooled over
    its drives (inverse-variance means of each drive's graph estimate); NaN where no drive had
    the sensor."""

    vehicle: str
    drives: int
    odo_scale: float = math.nan
    odo_scale_sd: float = math.nan
    gyro_bias_radps: float = math.nan
    gyro_bias_sd_radps: float = math.nan
    gyro_scale: float = math.nan
    gyro_scale_sd: float = math.nan


def vehicle_key(spec: DriveSpec, manifest: dict[str, str] | None = None) -> str:
    """The vehicle a drive belongs to: its row in ``manifest`` (drive name -> vehicle), else
    the folder its inputs are in (an MCAP's folder; a drive folder's parent)."""
    if manifest is not None and spec.name in manifest:
        return manifest[spec.name]
    first = Path(spec.inputs[0]) if spec.inputs else Path(spec.name)
    folder = first.parent
    if spec.log is None:  # a folder drive: the vehicle is the folder holding drive folders
        folder = folder.parent
    return str(folder)


def read_manifest(path: str, column: str) -> dict[str, str]:
    """``drive -> vehicle`` from a CSV with a ``drive`` column (the drive's name in the report)
    and the vehicle ``column``."""
    import csv

    from .errors import InputError

    try:
        with open(path, newline="", encoding="utf-8") as fh:
            rows = list(csv.DictReader(fh))
    except OSError as err:
        raise InputError(path, f"cannot read the manifest: {err.strerror}") from err
    if not rows or "drive" not in rows[0] or column not in rows[0]:
        raise InputError(path, f"line 1: the manifest needs columns drive and {column}")
    return {r["drive"]: r[column] for r in rows if r.get("drive")}


def _pool(values: list[tuple[float, float]]) -> tuple[float, float]:
    """Inverse-variance mean and its sigma of (value, sd) pairs (finite ones only)."""
    ok = [(v, s) for v, s in values if math.isfinite(v) and math.isfinite(s) and s > 0]
    if not ok:
        return math.nan, math.nan
    w = [1.0 / (s * s) for _, s in ok]
    mean = sum(wi * v for wi, (v, _) in zip(w, ok, strict=True)) / sum(w)
    return mean, math.sqrt(1.0 / sum(w))


def calibrate_vehicles(specs: list[DriveSpec], opts: BatchOptions,
                       manifest: dict[str, str] | None = None) -> dict[str, VehicleCalibration]:
    """Each drive through the graph smoother without calibration priors; its odometer scale,
    gyro bias and gyro scale estimates pooled per vehicle.  A drive that fails is left out."""
    import copy

    from .errors import GpsdrError
    from .io.readers import read_drive
    from .pipeline import fuse

    params = copy.deepcopy(opts.params)
    params["filter"]["smoother"] = "graph"
    params["filter"]["smooth"] = True
    params["graph"]["odo_scale"] = math.nan
    params["graph"]["gyro_bias_radps"] = math.nan
    params["graph"]["gyro_scale"] = math.nan
    per: dict[str, list[tuple[tuple[float, float], ...]]] = {}
    for spec in specs:
        try:
            drive = read_drive(spec.log, gps=spec.gps, gyro=spec.gyro, odo=spec.odo,
                               params=params, topics=opts.topics, date=opts.date,
                               use_log_time=opts.use_log_time)
            res = fuse(drive, params, None)
        except GpsdrError:
            continue
        info = res.result.info
        if info.get("smoothing") != "graph":
            continue
        per.setdefault(vehicle_key(spec, manifest), []).append((
            (float(info.get("graph_odo_scale", math.nan)),
             float(info.get("graph_odo_scale_sd", math.nan))),
            (float(info.get("graph_gyro_bias_radps", math.nan)),
             float(info.get("graph_gyro_bias_sd_radps", math.nan))),
            (1.0 + float(info.get("graph_gyro_scale", math.nan)),
             float(info.get("graph_gyro_scale_sd", math.nan)))))
    out: dict[str, VehicleCalibration] = {}
    for vehicle, rows in per.items():
        s, s_sd = _pool([r[0] for r in rows])
        b, b_sd = _pool([r[1] for r in rows])
        k, k_sd = _pool([r[2] for r in rows])
        out[vehicle] = VehicleCalibration(vehicle, len(rows), s, s_sd, b, b_sd, k, k_sd)
    return out


def with_calibration(params: Params, cal: VehicleCalibration, min_sd_scale: float = 0.002,
                     min_sd_bias: float = 0.0002, min_sd_gyro_scale: float = 0.001) -> Params:
    """``params`` with the vehicle's calibration as the graph's priors (sigmas floored: the
    pooled sigma of many drives is optimistic about what varies between them)."""
    import copy

    p = copy.deepcopy(params)
    if math.isfinite(cal.odo_scale):
        p["graph"]["odo_scale"] = cal.odo_scale
        p["graph"]["odo_scale_sd"] = max(cal.odo_scale_sd, min_sd_scale)
    if math.isfinite(cal.gyro_bias_radps):
        p["graph"]["gyro_bias_radps"] = cal.gyro_bias_radps
        p["graph"]["gyro_bias_sd_radps"] = max(cal.gyro_bias_sd_radps, min_sd_bias)
    if math.isfinite(cal.gyro_scale):
        p["graph"]["gyro_scale"] = cal.gyro_scale
        p["graph"]["gyro_scale_cal_sd"] = max(cal.gyro_scale_sd, min_sd_gyro_scale)
    return p
