"""``gpsdr fuse``: one drive in, a track Parquet and a statistics Parquet out."""

from __future__ import annotations

import contextlib
import gc
import json
import math
import sys
from collections.abc import Iterator, Mapping
from pathlib import Path
from typing import Any, Self

import click

from ..errors import UsageError
from .options import (
    STATE,
    SmoothCommand,
    common_options,
    config_option,
    filter_options,
    format_option,
    frame_time_options,
    make_params,
    reader_options,
)

#: Inputs larger than this (bytes, all files together) get a progress line (terminal, not -q).
LONG_LOG_BYTES = 20_000_000


def default_outputs(base: str, fmt: str) -> tuple[Path, Path]:
    """``LOG.mcap`` -> ``LOG.fused.parquet``, ``LOG.stats.parquet`` (next to the log)."""
    p = Path(base)
    stem = p.name
    for suffix in (".gz",):
        stem = stem.removesuffix(suffix)
    stem = Path(stem).stem if Path(stem).suffix else stem
    ext = "parquet" if fmt == "parquet" else "csv"
    return p.with_name(f"{stem}.fused.{ext}"), p.with_name(f"{stem}.stats.{ext}")


def stats_next_to(track: Path, fmt: str) -> Path:
    """``-o run.parquet`` -> ``run.stats.parquet``; ``x.fused.parquet`` -> ``x.stats.parquet``."""
    stem = track.name
    for suffix in (".parquet", ".csv"):
        stem = stem.removesuffix(suffix)
    stem = stem.removesuffix(".fused")
    return track.with_name(f"{stem}.stats.{'parquet' if fmt == 'parquet' else 'csv'}")


#: At most this many sentence types are named in the summary line.
_NOT_USED_NAMED = 4


def skipped_summary(counts: Mapping[str, int]) -> str:
    """``"56 input records skipped (42 sentences not used: GSV, DTM; 3 unknown sentences;
    11 damaged or unusable)"`` from the skip counts by reason (unknown: well-formed sentences
    of a kind the reader does not know, a receiver's proprietary ones mostly); a part with no
    records is left out, and with nothing skipped: ``"0 input records skipped"``."""
    from ..io.drive import NOT_USED, UNKNOWN

    total = int(sum(counts.values()))
    text = f"{total} input records skipped"
    if total == 0:
        return text
    unused: dict[str, int] = {}
    for reason, n in counts.items():
        if reason.startswith(NOT_USED):
            kind = (reason[len(NOT_USED):].split() or ["?"])[0]  # "GSV"
            unused[kind] = unused.get(kind, 0) + int(n)
    n_unused = sum(unused.values())
    n_unknown = sum(int(n) for reason, n in counts.items() if reason.startswith(UNKNOWN))
    parts = []
    if n_unused:
        kinds = sorted(unused, key=lambda k: -unused[k])  # most first; ties in report order
        names = ", ".join(kinds[:_NOT_USED_NAMED]) + (", ..." if len(kinds) > _NOT_USED_NAMED else "")
        parts.append(f"{n_unused} sentence{'s' if n_unused != 1 else ''} not used: {names}")
    if n_unknown:
        parts.append(f"{n_unknown} unknown sentence{'s' if n_unknown != 1 else ''}")
    if total - n_unused - n_unknown:
        parts.append(f"{total - n_unused - n_unknown} damaged or unusable")
    return f"{text} ({'; '.join(parts)})"


@click.command(cls=SmoothCommand)
@click.argument("log", required=False, metavar="[LOG]")
@click.option("--gps", type=str, metavar="G.nmea", help="NMEA 0183 log (or - for stdin).")
@click.option("--gyro", type=str, metavar="Y.csv", help="Gyro CSV: t, yaw_rate.")
@click.option("--odo", type=str, metavar="O.csv", help="Odometer CSV: t and speed|distance|ticks.")
@click.option("--accel", type=str, metavar="ACC.csv",
              help="Forward accelerometer CSV: t, acc_x (m/s^2, positive forward; the gyro's "
                   "time options).  An acc_x column in the gyro CSV is read without it.")
@filter_options
@click.option("--reference", type=str, metavar="TRUTH.csv",
              help="Reference trajectory (CSV t,lat,lon[,alt], NMEA or a track Parquet): "
                   "adds error statistics and prints RMSE, CEP95 and max to stderr.")
@click.option("-o", "--output", type=str, metavar="TRACK.parquet",
              help="Track output (- = stdout).  Default: LOG.fused.parquet next to the log.")
@click.option("--stats", "stats_path", type=str, metavar="STATS.parquet",
              help="Statistics output.  Default: next to the track, .stats.parquet.")
@click.option("--lever-arm", "lever_arm", type=str, metavar="FWD,LEFT[,UP]",
              help="Vehicle reference point to GNSS antenna, metres (forward, left, up); the "
                   "track is reported at the reference point.  Default: [gnss] lever_arm_m.")
@click.option("--export", "export_path", type=str, metavar="OUT",
              help="Also export the fused track (.gpx, .kml, .geojson, .csv, .mcap; "
                   "see gpsdr export) after writing it.")
@config_option
@click.option("--print-config", is_flag=True,
              help="Print the effective parameters as TOML (a --config file) and exit.")
@format_option
@frame_time_options
@reader_options
@common_options
def fuse(log: str | None, gps: str | None, gyro: str | None, odo: str | None, accel: str | None,
         filter_name: str | None, smooth: str | None, odo_scale: str | None,
         gyro_bias: str | None, gyro_scale: str | None, reference: str | None,
         output: str | None, stats_path: str | None, export_path: str | None,
         config_path: str | None,
         print_config: bool, fmt: str, date: Any, gnss_offset: str | float | None,
         epsg: int | None, topics: dict[str, str] | None, log_time: bool,
         gyro_units: str | None, gyro_sign: str | None, odo_kind: str | None,
         ticks_per_m: float | None, lever_arm: str | None, quiet: bool) -> None:
    """Fuse one drive's GNSS, gyro and odometer logs into a track.

    LOG is an MCAP file (or an NMEA file; - reads NMEA from stdin).  Or give the
    streams as --gps/--gyro/--odo.  Writes the track (one row per filter epoch:
    time, lat, lon, e, n, v_e, v_n, speed, heading_deg, sigma_e, sigma_n,
    gnss_used, pdop, ...) and the statistics table.  By default the filter's track is
    finished by the robust graph smoother where a gyro or odometer logs the motion (RTS
    on fixes alone); --smooth is RTS, --no-smooth the forward filter alone.

    \b
    Examples:
      gpsdr fuse drive.mcap                          # aekf + graph
      gpsdr fuse --gps gps.nmea --gyro gyro.csv --odo odo.csv --filter fafkf --smooth \\
                 --reference truth.csv -o track.parquet
      gpsdr fuse --gps gps.nmea --gyro gyro.csv --odo odo.csv \\
                 --odo-scale 1.012+-0.005 --gyro-scale 0.994+-0.002
      cat gps.nmea | gpsdr fuse - -o - --format csv > track.csv
      gpsdr fuse drive.mcap --lever-arm 1.5,0.3     # antenna 1.5 m ahead, 0.3 m left
      gpsdr fuse drive.mcap --export drive.gpx
      gpsdr fuse --print-config > params.toml
    """
    params = make_params(config_path, filter_name=filter_name, smooth=smooth,
                         gnss_offset=gnss_offset, epsg=epsg, gyro_units=gyro_units,
                         gyro_sign=gyro_sign, odo_kind=odo_kind, ticks_per_m=ticks_per_m,
                         odo_scale=odo_scale, gyro_bias=gyro_bias, gyro_scale=gyro_scale)
    if lever_arm is not None:
        from ..lever_arm import parse_lever_arm

        params["gnss"]["lever_arm_m"] = parse_lever_arm(lever_arm)
    if print_config:
        from .. import config

        click.echo(config.to_toml(params), nl=False)
        return
    if log is None and gps is None and gyro is None and odo is None:
        raise click.UsageError("give a LOG file, or the streams as --gps/--gyro/--odo "
                               "(see gpsdr fuse --help)")
    if log is not None and gps is not None:
        raise click.UsageError("give either LOG or --gps, not both")
    if export_path is not None:
        from ..io.export import format_of

        format_of(export_path)  # an unknown suffix fails before the work
    stdin_input = "-" in (log, gps)
    track_path, stats_out = _outputs(log or gps or gyro or odo or "-", output, stats_path, fmt,
                                     stdin_input)
    inputs = [p for p in (log, gps, gyro, odo, accel, reference) if p and p != "-"]
    for out in (track_path, stats_out, export_path):
        if out is not None and out != "-" and any(_same(out, p) for p in inputs):
            raise UsageError(f"{out}: refusing to overwrite an input file; give another -o/--stats")
    for out in (track_path, stats_out, export_path):  # fail before the work, and before writing anything
        if out is not None and out != "-" and not Path(out).resolve().parent.is_dir():
            from ..errors import InputError

            raise InputError(out, f"cannot write: directory {Path(out).parent} does not exist")
    if track_path == "-" and fmt == "parquet" and sys.stdout.isatty():
        raise UsageError("refusing to write binary Parquet to a terminal; "
                         "redirect stdout, give -o FILE or --format csv")

    # compile the filter kernels on the other core while this process reads (cold start only;
    # before the status line starts its thread, since this forks)
    from ..warmup import start_background

    ahead = start_background(params, auto_gnss_offset=gnss_offset == "auto")
    if ahead is None:  # a warm cache: numba's start-up in a thread while this one reads
        from ..warmup import start_preload

        ahead = start_preload(params)
    try:
        show = _progress_wanted(quiet, [log, gps, gyro, odo])
        with _cyclic_gc_paused(), _Stages(show) as stages:
            stages("reading inputs")
            drive = _read(log, gps, gyro, odo, params, topics, date, log_time, accel)
            ref = None
            if reference:
                from ..io.reference import read_reference

                ref = read_reference(reference)
            from ..pipeline import WRITTEN_TRACK_UNITS, stats_units
            from ..pipeline import fuse as run_fuse

            res = run_fuse(drive, params, ref, auto_gnss_offset=gnss_offset == "auto",
                           progress=stages, ready=ahead.wait if ahead else _ready(params))
            del drive  # the raw streams, and below the epochs and filter arrays: the outputs
            res.release_arrays()  # hold what is needed, and the write's peak memory is lower
            stages("writing outputs")
            from ..io.parquet import write_table

            # the track first: if it cannot be written, an existing statistics file stays as is
            write_table(res.track, track_path, metadata=res.metadata, units=WRITTEN_TRACK_UNITS, fmt=fmt)
            if stats_out is not None:
                write_table(res.stats, stats_out, metadata=res.metadata,
                            units=stats_units(res.stats), fmt=fmt)
            if export_path is not None:
                from ..io.export import ExportOptions, export_track

                export_track(res.track, res.metadata, export_path,
                             ExportOptions(name=f"gpsdr {res.metadata.get('filter')} track"))
    finally:
        if ahead is not None:
            ahead.cancel()  # failed before the filter: no orphan compiler

    if not quiet:
        _report(res, track_path, stats_out, reference, gnss_offset == "auto")


@contextlib.contextmanager
def _cyclic_gc_paused() -> Iterator[None]:
    """No automatic cyclic garbage collection while one drive is fused.

    Importing numba and pandas creates about a million long-lived objects, and every
    young-generation overflow meanwhile makes the collector walk them: ~350 collections,
    0.2-0.3 s of a warm one-hour fuse, that free a few hundred small objects.  The
    arrays are freed by reference counting as before; the collector runs again after.
    """
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()


def _ready(params: Any) -> Any:
    """Without a background compile: load the filter and numba's target the lean way
    (:func:`gpsdr_cli.warmup.prepare_loading`) just before the first pass."""
    name = str(params["filter"]["name"])

    def ready() -> None:
        from ..warmup import prepare_loading

        prepare_loading(name)
    return ready


def _same(a: str | Path, b: str | Path) -> bool:
    try:
        return Path(a).resolve() == Path(b).resolve()
    except OSError:
        return False


def _outputs(base: str, output: str | None, stats_path: str | None, fmt: str,
             stdin_input: bool) -> tuple[str, str | None]:
    """Track and stats destinations (stats None: not written)."""
    if output is None:
        if stdin_input:
            return "-", stats_path  # reading a pipe: the track goes down the pipe
        track, stats = default_outputs(base, fmt)
        return str(track), stats_path or str(stats)
    if output == "-":
        return "-", stats_path
    return output, stats_path or str(stats_next_to(Path(output), fmt))


def _read(log: str | None, gps: str | None, gyro: str | None, odo: str | None, params: Any,
          topics: dict[str, str] | None, date: Any, log_time: bool,
          accel: str | None = None) -> Any:
    from ..io.readers import read_drive

    if log == "-":
        gps, log = "-", None
    return read_drive(log, gps=gps, gyro=gyro, odo=odo, params=params, topics=topics,
                      date=date, use_log_time=log_time, accel=accel)


def _progress_wanted(quiet: bool, paths: list[str | None]) -> bool:
    if quiet or STATE["quiet"] or not sys.stderr.isatty():
        return False
    size = 0
    for p in paths:
        if p and p != "-":
            try:
                size += Path(p).stat().st_size
            except OSError:
                pass
    return size >= LONG_LOG_BYTES


class _Stages:
    """A rich status line on stderr naming the current stage (long logs on a terminal)."""

    def __init__(self, show: bool) -> None:
        self.show = show
        self._status: Any = None

    def __enter__(self) -> Self:
        if self.show:
            from rich.console import Console

            self._status = Console(stderr=True).status("gpsdr fuse: starting")
            self._status.__enter__()
        return self

    def __call__(self, stage: str) -> None:
        if self._status is not None:
            self._status.update(f"gpsdr fuse: {stage}")

    def __exit__(self, *exc: object) -> None:
        if self._status is not None:
            self._status.__exit__(*exc)


def _calibration_line(info: dict, meta: dict) -> str | None:
    """What the graph smoother found of the sensors over the whole drive (the values
    ``--odo-scale``, ``--gyro-bias`` and ``--gyro-scale`` take for the next drive of the same
    vehicle), or None where it did not run.  A value whose sigma is still half its prior's or
    more is one the drive did not tell, and is left out."""
    if info.get("smoothing") != "graph":
        return None

    def num(key: str) -> float:
        v = info.get(key)
        return float(v) if isinstance(v, int | float) and math.isfinite(v) else math.nan

    def param(key: str) -> float:
        try:
            return float(meta.get(f"param.{key}", "nan"))
        except ValueError:
            return math.nan

    def told(sd_key: str, prior_key: str) -> bool:
        return not num(sd_key) >= 0.5 * param(prior_key)  # also where the prior is unknown

    parts = []
    if math.isfinite(num("graph_odo_scale")) and told("graph_odo_scale_sd",
                                                      "odo.scale_init_sd"):
        parts.append(f"odometer scale {num('graph_odo_scale'):.4f} +- {num('graph_odo_scale_sd'):.4f}")
    if math.isfinite(num("graph_gyro_bias_radps")) and told("graph_gyro_bias_sd_radps",
                                                            "gyro.bias_init_sd_radps"):
        parts.append(f"gyro bias {num('graph_gyro_bias_radps'):+.5f} +- "
                     f"{num('graph_gyro_bias_sd_radps'):.5f} rad/s")
    if math.isfinite(num("graph_gyro_scale")) and told("graph_gyro_scale_sd",
                                                       "graph.gyro_scale_prior_sd"):
        # the graph's g corrects the readings as the filters read them: times a known scale
        known = param("graph.gyro_scale")
        base = known if math.isfinite(known) and known > 0 else 1.0
        parts.append(f"gyro scale {base * (1.0 + num('graph_gyro_scale')):.4f} +- "
                     f"{base * num('graph_gyro_scale_sd'):.4f}")
    return "calibration (graph smoother): " + ", ".join(parts) if parts else None


def _report(res: Any, track_path: str, stats_out: str | None, reference: str | None,
            auto: bool) -> None:
    """Summary on stderr (stdout stays clean for -o -)."""
    info = res.metadata
    err = sys.stderr
    where = "stdout" if track_path == "-" else track_path
    tag = {"rts": " + RTS", "graph": " + graph"}.get(info.get("smoother", ""), "")
    if "smoother" not in info and info.get("smoothed") == "true":
        tag = " + RTS"
    skipped = {r: v["count"] for r, v in json.loads(info["skipped"]).items()}
    click.echo(f"{info['filter']}{tag}: "
               f"{len(res.track)} epochs, {info['gnss_used']} GNSS fixes used, "
               f"{skipped_summary(skipped)} -> {where}"
               + (f", {stats_out}" if stats_out else ""), file=err)
    if auto:
        click.echo(f"GNSS time offset (auto): {res.gnss_offset_s:+.3f} s ({res.gnss_offset_note})",
                   file=err)
    cal = _calibration_line(json.loads(info.get("filter_info", "{}")), info)
    if cal:
        click.echo(cal, file=err)
    for note in res.drive_warnings:
        click.echo(f"warning: {note}", file=err)
    every = res.stats[res.stats["segment"] == "all"]
    if "separation_rms_m" in every and len(every) and str(every["separation_rms_m"].iloc[0]) != "<NA>":
        row = every.iloc[0]
        click.echo(f"forward/backward separation: RMS {float(row['separation_rms_m']):.2f} m, p95 "
                   f"{float(row['separation_p95_m']):.2f} m, max {float(row['separation_max_m']):.2f} m",
                   file=err)
    if reference:
        s = res.summary()
        if math.isnan(s["rmse_m"]):  # NaN: no epoch inside the reference's time span
            click.echo(f"warning: {reference} does not overlap the track in time; "
                       "no error statistics", file=err)
            return
        click.echo(f"error vs {reference}: RMSE {s['rmse_m']:.2f} m, CEP95 {s['cep95_m']:.2f} m, "
                   f"max {s['max_m']:.2f} m over {s['epochs']:.0f} epochs", file=err)
        g = res.gnss_only_summary()
        if g.get("count"):
            click.echo(f"GNSS fixes alone: RMSE {g['rmse_m']:.2f} m, CEP95 {g['cep95_m']:.2f} m, "
                       f"max {g['max_m']:.2f} m over {g['count']} fixes", file=err)
