"""``gpsdr batch``: fuse many drives in parallel (process pool or dask.distributed)."""

from __future__ import annotations

import math
import sys
from typing import Any, Self

import click

from .options import (
    SmoothCommand,
    common_options,
    config_option,
    filter_options,
    format_option,
    frame_time_options,
    make_params,
    reader_options,
)


@click.command(cls=SmoothCommand)
@click.argument("target", metavar="DIR_OR_GLOB")
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False),
              metavar="OUT_DIR", help="Where each drive's track and stats go (created).")
@click.option("-j", "--jobs", type=click.IntRange(min=1), default=None, metavar="N",
              help="Worker processes (default: the number of CPUs).")
@filter_options
@config_option
@format_option
@click.option("--force", is_flag=True,
              help="Process every drive, also those whose outputs are up to date.")
@click.option("--scheduler", metavar="tcp://HOST:PORT",
              help="Run on a dask.distributed cluster instead of local processes.")
@click.option("--calibrate-per-vehicle", "calibrate", is_flag=False, flag_value="folder",
              default=None, metavar="folder|COLUMN",
              help="First estimate each vehicle's odometer scale, gyro bias and gyro scale over "
                   "all its drives (graph smoother, pooled by inverse variance), then fuse every "
                   "drive with the graph smoother and that calibration as its prior.  Vehicles "
                   "are told apart by folder (default) or by COLUMN of --manifest.")
@click.option("--manifest", type=click.Path(dir_okay=False, exists=True), default=None,
              metavar="DRIVES.csv", help="CSV with a drive column (the drive names of the "
                                          "report) and the vehicle column of "
                                          "--calibrate-per-vehicle COLUMN.")
@frame_time_options
@reader_options
@common_options
def batch(target: str, out_dir: str, jobs: int | None, filter_name: str | None,
          smooth: str | None, odo_scale: str | None, gyro_bias: str | None,
          gyro_scale: str | None, config_path: str | None, fmt: str, force: bool,
          scheduler: str | None, calibrate: str | None, manifest: str | None,
          gnss_offset: str | float | None, epsg: int | None,
          date: Any, topics: dict[str, str] | None, log_time: bool, gyro_units: str | None,
          gyro_sign: str | None, odo_kind: str | None, ticks_per_m: float | None,
          quiet: bool) -> None:
    """Fuse every drive under a directory or matching a glob.

    A drive is an MCAP file, or a folder with an NMEA file and gyro/odometer CSVs
    (gps.nmea, gyro.csv, odo.csv or found by content); a truth.csv beside it is
    used as the reference.  Writes DRIVE.fused.parquet and DRIVE.stats.parquet
    per drive and batch_report.parquet (drive, status, error, duration, RMSE) in
    OUT_DIR, and prints the report.  Drives whose outputs are newer than their
    inputs are skipped unless --force.  Exit status 1 if any drive failed.

    \b
    Examples:
      gpsdr batch logs/ -o out/ --jobs 8 --filter fafkf --smooth
      gpsdr batch logs/ -o out/ --smooth graph --odo-scale 1.012+-0.005
      gpsdr batch fleet/ -o out/ --calibrate-per-vehicle          # fleet/<vehicle>/<drive>
      gpsdr batch logs/ -o out/ --calibrate-per-vehicle car --manifest drives.csv
      gpsdr batch 'logs/**/*.mcap' -o out/
      gpsdr batch logs/ -o out/ --scheduler tcp://10.0.0.5:8786
      gpsdr batch 'drives/*/' -o out/ --gnss-offset auto --smooth
    """
    import os
    from pathlib import Path

    from ..batch import (
        REPORT_NAME,
        REPORT_UNITS,
        BatchOptions,
        find_drives,
        report_frame,
        run_dask,
        run_local,
    )
    from ..io.parquet import write_table

    params = make_params(config_path, filter_name=filter_name, smooth=smooth,
                         gnss_offset=gnss_offset, epsg=epsg, gyro_units=gyro_units,
                         gyro_sign=gyro_sign, odo_kind=odo_kind, ticks_per_m=ticks_per_m,
                         odo_scale=odo_scale, gyro_bias=gyro_bias, gyro_scale=gyro_scale)
    specs = find_drives(target)
    if not specs:
        from ..errors import InputError

        raise InputError(target, "no drive found (MCAP files, or folders with an NMEA file "
                                 "and gyro/odometer CSVs)")
    Path(out_dir).mkdir(parents=True, exist_ok=True)
    opts = BatchOptions(out_dir=out_dir, params=params, fmt=fmt, force=force,
                        auto_gnss_offset=gnss_offset == "auto", topics=topics, date=date,
                        use_log_time=log_time)
    n_jobs = jobs or os.cpu_count() or 1
    groups = [(opts, specs)]
    if calibrate is not None:
        import dataclasses

        from ..batch import calibrate_vehicles, read_manifest, vehicle_key, with_calibration

        table = None
        if calibrate != "folder":
            if manifest is None:
                raise click.UsageError(f"--calibrate-per-vehicle {calibrate}: give --manifest "
                                       "DRIVES.csv with that column")
            table = read_manifest(manifest, calibrate)
        opts.params["filter"]["smoother"] = "graph"
        opts.params["filter"]["smooth"] = True
        cals = calibrate_vehicles(specs, opts, table)
        by_vehicle: dict[str, list[Any]] = {}
        for spec in specs:
            by_vehicle.setdefault(vehicle_key(spec, table), []).append(spec)
        groups = []
        for vehicle, members in by_vehicle.items():
            cal = cals.get(vehicle)
            p = with_calibration(opts.params, cal) if cal is not None else opts.params
            groups.append((dataclasses.replace(opts, params=p, extra_meta={
                **opts.extra_meta, "vehicle": vehicle,
                "vehicle_calibration": repr(cal) if cal is not None else "none"}), members))
            if not quiet:
                click.echo(f"vehicle {vehicle}: " + (
                    f"{cal.drives} drives, odometer scale {cal.odo_scale:.5f} +- "
                    f"{cal.odo_scale_sd:.5f}, gyro bias {cal.gyro_bias_radps:+.6f} +- "
                    f"{cal.gyro_bias_sd_radps:.6f} rad/s, gyro scale {cal.gyro_scale:.5f} +- "
                    f"{cal.gyro_scale_sd:.5f}" if cal is not None
                    else "no calibration (no drive solved)"), err=True)

    rows = []
    with _Bar(len(specs), quiet) as bar:
        for g_opts, g_specs in groups:
            if scheduler:
                bar.start()
                rows += run_dask(g_specs, g_opts, scheduler, on_done=bar.advance)
            else:  # the bar's refresh thread starts once the workers are forked (run_local)
                rows += run_local(g_specs, g_opts, n_jobs, on_done=bar.advance,
                                  on_ready=bar.start)
    report = report_frame(rows)
    write_table(report, Path(out_dir) / REPORT_NAME,
                metadata={"target": target, "filter": str(params["filter"]["name"])},
                units=REPORT_UNITS)
    _print_report(report, quiet)
    failed = int((report["status"] == "failed").sum())
    if failed:
        click.echo(f"gpsdr: {failed} of {len(report)} drives failed "
                   f"(see {Path(out_dir) / REPORT_NAME})", err=True)
        sys.exit(1)


class _Bar:
    """A rich progress bar with ETA on stderr (only on a terminal and without -q).

    Shown from :meth:`start` on, not from ``__enter__``: rich refreshes it from a
    thread, and the batch's workers must be forked before any thread exists.
    """

    def __init__(self, total: int, quiet: bool) -> None:
        self.total = total
        self.quiet = quiet
        self._progress: Any = None
        self._task: Any = None

    def __enter__(self) -> Self:
        return self

    def start(self) -> None:
        if not self.quiet and self._progress is None:
            from rich.console import Console
            from rich.progress import (
                BarColumn,
                MofNCompleteColumn,
                Progress,
                TextColumn,
                TimeElapsedColumn,
                TimeRemainingColumn,
            )

            console = Console(stderr=True)
            if console.is_terminal:
                self._progress = Progress(
                    TextColumn("[bold]batch"), BarColumn(), MofNCompleteColumn(),
                    TimeElapsedColumn(), TextColumn("ETA"), TimeRemainingColumn(),
                    TextColumn("{task.description}"), console=console,
                    refresh_per_second=2)  # seconds-resolution ETA; the parent shares the CPUs
                self._progress.__enter__()
                self._task = self._progress.add_task("", total=self.total)

    def advance(self, row: dict[str, Any]) -> None:
        if self._progress is not None:
            self._progress.update(self._task, advance=1,
                                  description=f"{row['drive']}: {row['status']}")

    def __exit__(self, *exc: object) -> None:
        if self._progress is not None:
            self._progress.__exit__(*exc)


def _fmt(v: Any, spec: str) -> str:
    if isinstance(v, float) and not math.isfinite(v):
        return "-"
    return format(v, spec)


def _print_report(report: Any, quiet: bool) -> None:
    from rich.console import Console
    from rich.table import Table

    table = Table(title="gpsdr batch", show_lines=False)
    for col, justify in (("drive", "left"), ("status", "left"), ("duration s", "right"),
                         ("RMSE m", "right"), ("CEP95 m", "right"), ("error", "left")):
        table.add_column(col, justify=justify, overflow="fold")
    for r in report.itertuples(index=False):
        style = {"ok": "green", "failed": "red"}.get(r.status, "dim")
        table.add_row(r.drive, f"[{style}]{r.status}[/]", _fmt(r.duration_s, ".1f"),
                      _fmt(r.rmse_m, ".2f"), _fmt(r.cep95_m, ".2f"), r.error)
    ok = int((report["status"] == "ok").sum())
    skipped = int((report["status"] == "up to date").sum())
    failed = int((report["status"] == "failed").sum())
    console = Console(width=160) if not sys.stdout.isatty() else Console()
    if not quiet:
        console.print(table)
    console.print(f"{len(report)} drives: {ok} ok, {skipped} up to date, {failed} failed")
