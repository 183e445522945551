"""``gpsdr plot``: a PNG report of a track (map, errors, sigmas), with a reference if given."""

from __future__ import annotations

import click

from .options import common_options


@click.command()
@click.argument("track", metavar="TRACK.parquet")
@click.option("--reference", type=str, metavar="REF",
              help="Reference trajectory (CSV t,lat,lon, NMEA or track Parquet).")
@click.option("-o", "--output", required=True, type=str, metavar="report.png",
              help="Image to write (PNG, or any format matplotlib knows by suffix).")
@click.option("--title", default="", help="Title of the report.")
@common_options
def plot(track: str, reference: str | None, output: str, title: str, quiet: bool) -> None:
    """Plot a track: trajectory map with GNSS fixes, and error against the reference
    (or the filter's sigmas) over time.

    \b
    Examples:
      gpsdr plot drive.fused.parquet -o report.png
      gpsdr plot track.parquet --reference truth.csv -o report.png --title "AEKF + RTS"
    """
    from ..io.parquet import read_track
    from ..pipeline import prepare_track
    from ..plot import plot_report

    df, meta = read_track(track)
    ref_en = None
    if reference:
        from ..io.reference import read_reference

        df, _, ref_en = prepare_track(df, meta, read_reference(reference), name=track)
    path = plot_report(df, output, reference_en=ref_en, title=title or default_title(meta))
    if not quiet:
        click.echo(f"wrote {path}", err=True)


def default_title(meta: dict[str, str]) -> str:
    """``aekf``, ``aekf + RTS`` or ``aekf + graph`` for a smoothed track, from the track
    file's metadata (files without ``smoother``: ``smoothed`` = true means RTS)."""
    name = meta.get("filter", "")
    if not name:
        return name
    kind = meta.get("smoother") or ("rts" if meta.get("smoothed") == "true" else "none")
    return name + {"rts": " + RTS", "graph": " + graph"}.get(kind, "")
