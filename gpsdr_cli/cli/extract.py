"""``gpsdr extract``: the parsed streams of any log as Parquet or CSV tables."""

from __future__ import annotations

from typing import Any

import click

from .options import common_options, config_option, reader_options

STREAM_NAMES = ("gnss", "gyro", "odo", "accel")


@click.command()
@click.argument("logs", nargs=-1, required=True, metavar="LOG...")
@click.option("-o", "--output", required=True, metavar="OUT.parquet|OUT.csv|-",
              help="Output table; its suffix picks Parquet or CSV; - is CSV on stdout "
                   "(one stream).  Several streams: OUT.gnss.parquet, OUT.gyro.parquet, "
                   "OUT.odo.parquet, OUT.accel.parquet (the stream before the suffix).")
@click.option("--stream", type=click.Choice(STREAM_NAMES), default=None,
              help="Write only this stream, exactly to OUT.")
@config_option
@reader_options
@common_options
def extract(logs: tuple[str, ...], output: str, stream: str | None, config_path: str | None,
            date: Any, topics: dict[str, str] | None, log_time: bool, gyro_units: str | None,
            gyro_sign: str | None, odo_kind: str | None, ticks_per_m: float | None,
            quiet: bool) -> None:
    """Write what gpsdr reads from LOG... as tables, one per stream: gnss (time, lat,
    lon, alt, fix_quality, n_sats, hdop, pdop, vdop, sigma_e, sigma_n, speed,
    course_deg), gyro (time, yaw_rate), odo (time, speed), accel (time, accel_mps2).
    Time is timestamp[ns, UTC]; units are in the Parquet field metadata; rows are in
    the order read.  Reads every format the other commands read; several LOGs merge
    as in `gpsdr fuse` (CSV logs by their header; the first file giving a stream
    supplies it).  Prints the records per stream and every skipped record by reason
    on stderr.

    \b
    Examples:
      gpsdr extract gps.nmea -o fixes.csv
      gpsdr extract gps.nmea gyro.csv odo.csv -o drive.parquet
          # -> drive.gnss.parquet, drive.gyro.parquet, drive.odo.parquet
      gpsdr extract drive.mcap --stream gyro -o gyro.parquet
      gpsdr extract rover.pos -o - | head
    """
    from ..io.extract import extract as run
    from .options import STATE, make_params

    params = make_params(config_path, gyro_units=gyro_units, gyro_sign=gyro_sign,
                         odo_kind=odo_kind, ticks_per_m=ticks_per_m)
    result = run(list(logs), output, params, stream=stream, topics=topics, date=date,
                 use_log_time=log_time)
    if STATE["quiet"]:
        return
    def echo(text: str) -> None:
        click.echo(text, err=True)

    for s, n in result.records.items():
        where = "stdout" if result.files[s] == "-" else result.files[s]
        echo(f"{s}: {n} records -> {where}")
    drive = result.drive
    meta = drive.meta if drive is not None else {}
    for note in list(meta.get("notes", [])) + list(meta.get("warnings", [])):
        echo(f"note: {note}")
    skipped = drive.skipped if drive is not None else None
    total = skipped.total if skipped is not None else 0
    echo(f"skipped records: {total}")
    if skipped is not None:
        for reason, n in skipped.counts.most_common():
            first = skipped.first.get(reason, "")
            echo(f"  {n:>7}  {reason}" + (f" (first: {first})" if first else ""))
