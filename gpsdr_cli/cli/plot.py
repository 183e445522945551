"""``gpsdr plot``: a PNG report of a track (map, errors, sigmas), with a reference if given,
and/or an interactive HTML report (``--html``)."""

from __future__ import annotations

import click

from .options import common_options


@click.command()
@click.argument("track", metavar="TRACK.parquet")
@click.option("--reference", type=str, metavar="REF",
              help="Reference trajectory (CSV t,lat,lon, NMEA or track Parquet).")
@click.option("-o", "--output", type=str, metavar="report.png",
              help="Image to write (PNG, or any format matplotlib knows by suffix).")
@click.option("--html", "html_out", type=str, metavar="report.html",
              help="Interactive report to write: one self-contained HTML file (map with "
                   "pan, zoom and hover; the same time panels) that opens offline.")
@click.option("--title", default="", help="Title of the report.")
@common_options
def plot(track: str, reference: str | None, output: str | None, html_out: str | None,
         title: str, quiet: bool) -> None:
    """Plot a track: trajectory map with GNSS fixes, and error against the reference
    (or the filter's sigmas) over time, as a PNG (-o) and/or an interactive HTML page
    (--html): fused track coloured by sigma (or quality), outages, rejected and
    down-weighted fixes, hover details; an OpenStreetMap base map is off until ticked.

    \b
    Examples:
      gpsdr plot drive.fused.parquet -o report.png
      gpsdr plot track.parquet --reference truth.csv -o report.png --title "AEKF + RTS"
      gpsdr plot drive.fused.parquet --reference truth.csv --html report.html
    """
    if not output and not html_out:
        raise click.UsageError("give -o report.png and/or --html report.html")
    from ..io.parquet import read_track
    from ..pipeline import params_from_metadata, prepare_track
    from ..plot import plot_report

    df, meta = read_track(track)
    ref = None
    if reference:
        from ..io.reference import read_reference

        ref = read_reference(reference)
    # the track in its own frame (e/n from lat/lon when it has none), the reference in it
    df, _, ref_en = prepare_track(df, meta, ref, name=track)
    pdop_good = float(params_from_metadata(meta)["gnss"]["pdop_good"])
    paths = []
    if output:
        paths.append(plot_report(df, output, reference_en=ref_en,
                                 title=title or default_title(meta), pdop_good=pdop_good))
    if html_out:
        from ..report.html import write_html_report

        paths.append(write_html_report(df, html_out, ref_en, title or default_title(meta),
                                       pdop_good=pdop_good))
    if not quiet:
        for path in paths:
            click.echo(f"wrote {path}", err=True)


def default_title(meta: dict[str, str]) -> str:
    """``aekf``, ``aekf + RTS`` or ``aekf + graph`` for a smoothed track, from the track
    file's metadata (files without ``smoother``: ``smoothed`` = true means RTS)."""
    name = meta.get("filter", "")
    if not name:
        return name
    kind = meta.get("smoother") or ("rts" if meta.get("smoothed") == "true" else "none")
    return name + {"rts": " + RTS", "graph": " + graph"}.get(kind, "")
