"""``gpsdr compare``: every filter and smoother on one drive, one table, an overlay plot."""

from __future__ import annotations

import sys
from typing import Any

import click

from ..errors import UsageError
from .options import (
    FILTER_NAMES,
    common_options,
    config_option,
    frame_time_options,
    make_params,
    reader_options,
)


@click.command()
@click.argument("log", required=False, metavar="[LOG]")
@click.option("--gps", type=str, metavar="G.nmea", help="NMEA 0183 log.")
@click.option("--gyro", type=str, metavar="Y.csv", help="Gyro CSV: t, yaw_rate.")
@click.option("--odo", type=str, metavar="O.csv", help="Odometer CSV: t and speed|distance|ticks.")
@click.option("--reference", type=str, metavar="REF",
              help="Reference trajectory (CSV t,lat,lon[,alt], NMEA or a track Parquet): "
                   "the table gets RMSE, CEP95 and max against it.")
@click.option("--filters", "filters_text", default=",".join(FILTER_NAMES), show_default=True,
              metavar="LIST", help="Comma-separated filters to run.")
@click.option("--smooth", "smooth_text", default="none,rts,auto", show_default=True,
              metavar="LIST",
              help="Comma-separated smoothers to run after each filter: none (forward only), "
                   "rts, graph, auto (what `gpsdr fuse` runs by default: graph where a gyro "
                   "or odometer logs the motion; its row is labelled with what ran).")
@click.option("-o", "--output", type=str, metavar="TABLE.csv|.parquet",
              help="Also write the table (format by suffix).")
@click.option("--plot", "plot_path", type=str, metavar="overlay.png",
              help="Overlay of the tracks on one map, with the error against time when a "
                   "reference is given (the filters' sigma otherwise).")
@config_option
@frame_time_options
@reader_options
@common_options
def compare(log: str | None, gps: str | None, gyro: str | None, odo: str | None,
            reference: str | None, filters_text: str, smooth_text: str, output: str | None,
            plot_path: str | None, config_path: str | None, gnss_offset: str | float | None,
            epsg: int | None, date: Any, topics: dict[str, str] | None, log_time: bool,
            gyro_units: str | None, gyro_sign: str | None, odo_kind: str | None,
            ticks_per_m: float | None, quiet: bool) -> None:
    """Run every filter (and smoother) on the same drive and print one table.

    The logs are read once; each run is what `gpsdr fuse --filter F [--smooth]`
    gives with the same parameters.  With --reference: RMSE, CEP95 and max
    horizontal error per run.  Without one: the share of GNSS updates whose NIS
    is inside the 95 % bound, the RMS GNSS-minus-fused separation and, when the
    track has it, the forward/backward separation.

    \b
    Examples:
      gpsdr compare drive.mcap --reference truth.csv
      gpsdr compare --gps gps.nmea --gyro gyro.csv --odo odo.csv --filters ekf,aekf \\
                    --smooth none,rts -o table.csv --plot overlay.png
    """
    from ..compare import parse_list, smoother_names

    if log is None and gps is None and gyro is None and odo is None:
        raise click.UsageError("give a LOG file, or the streams as --gps/--gyro/--odo "
                               "(see gpsdr compare --help)")
    if log is not None and gps is not None:
        raise click.UsageError("give either LOG or --gps, not both")
    if "-" in (log, gps):
        raise UsageError("compare reads its logs from files, not from stdin")
    params = make_params(config_path, gnss_offset=gnss_offset, epsg=epsg, gyro_units=gyro_units,
                         gyro_sign=gyro_sign, odo_kind=odo_kind, ticks_per_m=ticks_per_m)
    filters = parse_list(filters_text, "filters", FILTER_NAMES)
    smoothers = parse_list(smooth_text, "smooth", smoother_names(params))
    fmt = None
    if output:
        fmt = {"csv": "csv", "parquet": "parquet"}.get(output.rsplit(".", 1)[-1].lower())
        if fmt is None:
            raise UsageError(f"-o {output}: give a .csv or .parquet file name")

    from ..compare import COMPARE_COLUMNS
    from ..compare import compare as run_compare
    from ..io.readers import read_drive

    drive = read_drive(log, gps=gps, gyro=gyro, odo=odo, params=params, topics=topics,
                       date=date, use_log_time=log_time)
    ref = None
    if reference:
        from ..io.reference import read_reference

        ref = read_reference(reference)
    progress = None if quiet else (lambda what: click.echo(f"running {what}", err=True))
    cmp = run_compare(drive, params, ref, filters, smoothers,
                      auto_gnss_offset=gnss_offset == "auto", progress=progress)
    _print_table(cmp.table, reference is not None, sys.stdout)
    if output:
        from ..io.parquet import write_table

        write_table(cmp.table, output, metadata={**cmp.metadata, "reference": reference or ""},
                    units=COMPARE_COLUMNS, fmt=fmt or "parquet")
    if plot_path:
        from ..compare import plot_overlay

        plot_overlay(cmp, plot_path)
    if not quiet:
        for path in (output, plot_path):
            if path:
                click.echo(f"wrote {path}", err=True)


def _cell(v: Any, digits: int = 3) -> str:
    if v is None or str(v) in ("<NA>", "nan", "None"):
        return "-"
    if isinstance(v, float):
        return f"{v:.{digits}f}"
    return str(v)


def _print_table(table: Any, with_reference: bool, out: Any) -> None:
    cols = ["filter", "smoother", "epochs"]
    if with_reference:
        cols += ["rmse_m", "cep95_m", "max_m"]
    cols += ["nis_in_95_share", "gnss_separation_rmse_m"]
    if table["separation_rms_m"].notna().any():
        cols += ["separation_rms_m", "separation_p95_m"]
    cols += ["gnss_used", "gnss_rejected", "run_s"]
    rows = [[_cell(v, 2 if c == "run_s" else 3) for c, v in zip(cols, rec, strict=True)]
            for rec in table[cols].itertuples(index=False)]
    widths = [max(len(c), *(len(r[i]) for r in rows)) if rows else len(c)
              for i, c in enumerate(cols)]
    click.echo("  ".join(c.rjust(w) for c, w in zip(cols, widths, strict=True)), file=out)
    for r in rows:
        click.echo("  ".join(v.rjust(w) for v, w in zip(r, widths, strict=True)), file=out)
