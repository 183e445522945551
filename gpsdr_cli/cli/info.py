"""``gpsdr info``: what a log holds (streams, rates, spans, GNSS outages, DOPs, skipped lines)."""

from __future__ import annotations

import json
import math
from typing import Any

import click

from .options import common_options, config_option, reader_options


@click.command()
@click.argument("logs", nargs=-1, required=True, metavar="LOG...")
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object per log instead.")
@config_option
@reader_options
@common_options
def info(logs: tuple[str, ...], as_json: bool, config_path: str | None, date: Any,
         topics: dict[str, str] | None, log_time: bool,
         gyro_units: str | None, gyro_sign: str | None, odo_kind: str | None,
         ticks_per_m: float | None, quiet: bool) -> None:
    """Describe logs: the streams found with record counts, rates and time spans,
    GNSS fix quality, outages (start, length), PDOP/HDOP distribution, and the
    records skipped by reason.  Works on NMEA, MCAP, gyro/odometer/reference CSV
    and track Parquet files.

    \b
    Examples:
      gpsdr info drive.mcap
      gpsdr info gps.nmea gyro.csv odo.csv
      gpsdr info --json gps.nmea | jq .gnss.outages
    """
    from ..pipeline import describe_log
    from .options import make_params

    params = make_params(config_path, gyro_units=gyro_units, gyro_sign=gyro_sign,
                         odo_kind=odo_kind, ticks_per_m=ticks_per_m)
    from ..errors import GpsdrError

    failed = 0
    for i, path in enumerate(logs):
        try:
            desc = describe_log(path, params, topics=topics, date=date, use_log_time=log_time)
        except GpsdrError as err:
            if len(logs) == 1:
                raise
            from .errors import to_click_exception

            to_click_exception(err).show()  # the other files still get described
            failed += 1
            continue
        if as_json:
            click.echo(json.dumps(desc, default=str))
            continue
        if i:
            click.echo("")
        _print(desc)
    if failed:
        raise click.exceptions.Exit(1)


def _f(x: Any, fmt: str = ".2f") -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return format(x, fmt)


def _print(desc: dict[str, Any]) -> None:
    echo = click.echo
    echo(f"{desc['path']}: {desc['kind']}")
    for s in desc.get("streams", []):
        echo(f"  {s['stream']:<10} {s['records']:>9} records  {_f(s['rate_hz'], '8.2f')} Hz  "
             f"{s['start']} .. {s['end']}  ({_f(s['duration_s'], '.1f')} s)")
    g = desc.get("gnss")
    if g:
        q = ", ".join(f"{k}: {v}" for k, v in g["fix_quality"].items())
        echo(f"  GNSS fixes: {g['fixes']} records, {g['valid']} usable; fix quality {q}")
        outs = g["outages"]
        echo(f"  GNSS outages (gap > {g['outage_threshold_s']:.2f} s): {len(outs)}")
        for o in outs[:20]:
            echo(f"    {o['start']}  {o['length_s']:.1f} s")
        if len(outs) > 20:
            echo(f"    ... {len(outs) - 20} more (--json lists all)")
        for key, label in (("pdop", "PDOP"), ("hdop", "HDOP"), ("n_sats", "satellites")):
            d = g.get(key)
            if d:
                echo(f"  {label:<10} min {_f(d['min'])}  median {_f(d['median'])}  "
                     f"p95 {_f(d['p95'])}  max {_f(d['max'])}  ({d['count']} values)")
            else:
                echo(f"  {label:<10} none")
    for key in ("gyro", "odo", "reference"):
        d = desc.get(key)
        if d:
            for name, dist in d.items():
                if isinstance(dist, dict):
                    echo(f"  {key} {name}: min {_f(dist['min'], '.4g')}  median "
                         f"{_f(dist['median'], '.4g')}  max {_f(dist['max'], '.4g')}")
    track = desc.get("track")
    if track:
        for k, v in track.items():
            echo(f"  {k}: {v}")
    for note in desc.get("notes", []):
        echo(f"  note: {note}")
    skipped = desc.get("skipped", {})
    if not skipped and any(n.startswith("nothing usable") for n in desc.get("notes", [])):
        return  # the note counted what was skipped; "0" under it would contradict it
    total = sum(v["count"] for v in skipped.values())
    echo(f"  skipped records: {total}")
    for reason, v in skipped.items():
        first = f" (first: {v['first']})" if v["first"] else ""
        echo(f"    {v['count']:>7}  {reason}{first}")
