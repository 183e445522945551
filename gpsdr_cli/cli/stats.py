"""``gpsdr stats``: statistics of an existing track, against a reference when given."""

from __future__ import annotations

import math
import sys
from typing import Any

import click

from .options import common_options, format_option


@click.command()
@click.argument("track", metavar="TRACK.parquet")
@click.option("--reference", type=str, metavar="TRUTH.csv",
              help="Reference trajectory: CSV t,lat,lon[,alt], NMEA, or a track Parquet.")
@click.option("-o", "--output", type=str, metavar="STATS.parquet",
              help="Also write the statistics table here (- = stdout).")
@format_option
@common_options
def stats(track: str, reference: str | None, output: str | None, fmt: str, quiet: bool) -> None:
    """Error statistics of a track file: RMSE, mean, CEP50, CEP95 and max per segment
    (all, open, degraded, outage, static, each outage) against a reference, and
    the health figures (NIS share, GNSS separation) without one, and the quality
    checks (forward/backward separation RMS, p95, max; epochs per quality class)
    when the track has them.  TRACK - reads
    the track from stdin.

    \b
    Examples:
      gpsdr stats drive.fused.parquet --reference truth.csv
      gpsdr fuse --gps gps.nmea -o - | gpsdr stats - --reference truth.csv
      gpsdr stats track.parquet --reference truth.csv -o stats.parquet
    """
    from ..io.parquet import read_track, write_table
    from ..pipeline import stats_units, track_statistics

    df, meta = read_track(track)
    ref = None
    if reference:
        from ..io.reference import read_reference

        ref = read_reference(reference)
    table, _ = track_statistics(df, meta, ref, name="<stdin>" if track == "-" else track)
    if output:
        write_table(table, output, metadata={**meta, "stats_of": track,
                                             "reference": reference or ""},
                    units=stats_units(table), fmt=fmt)
    if output != "-":
        _print_table(table, sys.stdout)


def _cell(v: Any) -> str:
    if str(v) in ("<NA>", "nan", "NaT", "None"):
        return "-"
    if isinstance(v, float):
        return "-" if not math.isfinite(v) else f"{v:.3f}"
    return str(v)


def _print_table(table: Any, out: Any) -> None:
    cols = [c for c in ("filter", "segment", "epochs", "rmse_m", "mean_m", "cep50_m", "cep95_m",
                        "max_m", "nis_in_95_share", "gnss_separation_rmse_m", "duration_s",
                        "distance_m", "end_error_m", "end_error_pct_distance",
                        "separation_rms_m", "separation_p95_m", "separation_max_m")
            if c in table.columns]
    rows = [[_cell(v) for v in rec] for rec in table[cols].itertuples(index=False)]
    widths = [max(len(c), *(len(r[i]) for r in rows)) if rows else len(c)
              for i, c in enumerate(cols)]
    click.echo("  ".join(c.rjust(w) for c, w in zip(cols, widths, strict=True)), file=out)
    for r in rows:
        click.echo("  ".join(v.rjust(w) for v, w in zip(r, widths, strict=True)), file=out)
    shares = [f"quality_{k}_share" for k in range(1, 7)]
    if all(c in table.columns for c in shares):
        every = table[table["segment"] == "all"]
        if len(every):
            txt = ", ".join(f"{k}: {100.0 * float(every[c].iloc[0]):.1f} %"
                            for k, c in enumerate(shares, start=1)
                            if str(every[c].iloc[0]) not in ("<NA>", "nan"))
            click.echo(f"epochs per quality class (1 best .. 6 worst): {txt}", file=out)
