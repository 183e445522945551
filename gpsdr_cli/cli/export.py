"""``gpsdr export``: a track file to GPX, KML, GeoJSON, CSV or an MCAP for Foxglove."""

from __future__ import annotations

from pathlib import Path

import click

from ..errors import UsageError
from .options import STATE, common_options

SUFFIX_HELP = ".gpx, .kml, .geojson, .csv or .mcap"


def decimation_options(fn: click.decorators.FC) -> click.decorators.FC:
    """--every and --min-distance (shared with nothing yet; kept as one decorator)."""
    fn = click.option("--min-distance", "min_distance_m", type=float, metavar="METRES",
                      help="Keep a row only every METRES along the track.")(fn)
    fn = click.option("--every", "every_s", type=float, metavar="SECONDS",
                      help="Keep a row only every SECONDS (e.g. 1 for 1 Hz).")(fn)
    return fn


@click.command()
@click.argument("track", metavar="TRACK.parquet")
@click.option("-o", "--output", required=True, type=str, metavar="OUT",
              help=f"Output file; its suffix picks the format: {SUFFIX_HELP}.")
@decimation_options
@click.option("--points", is_flag=True,
              help="GeoJSON: add a Point feature per kept row (time, speed, sigma, quality).")
@click.option("--kepler", is_flag=True,
              help="GeoJSON: Kepler.gl trip coordinates [lon, lat, alt, unix_ts].")
@click.option("--with-input", "with_input", type=click.Path(dir_okay=False), metavar="LOG.mcap",
              help="MCAP: copy every channel and message of this input MCAP beside the "
                   "fused ones, so raw and fused play together in Foxglove.")
@common_options
def export(track: str, output: str, every_s: float | None, min_distance_m: float | None,
           points: bool, kepler: bool, with_input: str | None, quiet: bool) -> None:
    """Export a track (a Parquet or CSV from gpsdr fuse) for map and robotics tools.

    The format follows OUT's suffix: .gpx (GPX 1.1 track with time, sigma and
    quality extensions), .kml (gx:Track with timestamps plus a LineString),
    .geojson (a LineString; --points adds decimated points, --kepler the
    Kepler.gl trip form), .csv (every column), .mcap (foxglove.LocationFix
    messages, the track as foxglove.GeoJSON and the rejected GNSS fixes, for
    Foxglove).  A 100 Hz hour is 360 k points: --every and --min-distance thin
    it (a row is kept when both have passed since the last kept row).  TRACK -
    reads the track from stdin.

    \b
    Examples:
      gpsdr export drive.fused.parquet -o drive.gpx --every 1
      gpsdr export drive.fused.parquet -o drive.kml --min-distance 5
      gpsdr export drive.fused.parquet -o drive.geojson --every 1 --points
      gpsdr export drive.fused.parquet -o trips.geojson --every 1 --kepler
      gpsdr export drive.fused.parquet -o drive.csv
      gpsdr export drive.fused.parquet -o fused.mcap --with-input drive.mcap
    """
    from ..io.export import ExportOptions, export_track, format_of
    from ..io.parquet import read_track

    format_of(output)  # an unknown suffix fails before reading anything
    for other in (track, with_input):
        if other and other != "-" and _same(output, other):
            raise UsageError(f"{output}: refusing to overwrite an input file; give another -o")
    df, meta = read_track(track)
    name = f"gpsdr {meta.get('filter', 'fused')} track"
    if track != "-":
        name += f" ({Path(track).name})"
    opts = ExportOptions(every_s=every_s, min_distance_m=min_distance_m, points=points,
                         kepler=kepler, with_input=with_input, name=name)
    rows = export_track(df, meta, output, opts, source=track if track != "-" else "<stdin>")
    if not (quiet or STATE["quiet"]):
        click.echo(f"exported {rows} of {len(df)} rows -> {output}", err=True)


def _same(a: str, b: str) -> bool:
    try:
        return Path(a).resolve() == Path(b).resolve()
    except OSError:
        return False
