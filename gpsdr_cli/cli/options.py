"""Shared click option groups, as decorators (the sqlite-utils pattern).

Only click and the standard library are imported here: ``gpsdr --help`` must
answer without loading numpy, pandas or numba.
"""

from __future__ import annotations

import datetime as _dt
from collections.abc import Callable
from typing import Any

import click

#: The registered filter names (gpsdr_cli.filters.NAMES; repeated here because importing the
#: registry loads numpy; tests/test_cli.py checks the two agree).
FILTER_NAMES: tuple[str, ...] = ("ekf", "aekf", "fkf", "fafkf")

#: Process-wide flags set by the options below and read by main.py's error handler.
STATE: dict[str, bool] = {"debug": False, "quiet": False}

F = Callable[..., Any]


def _set_flag(name: str) -> Callable[[click.Context, click.Parameter, bool], bool]:
    def callback(ctx: click.Context, param: click.Parameter, value: bool) -> bool:
        if value:
            STATE[name] = True
            if name == "debug":
                import warnings

                warnings.simplefilter("default")  # main.py silences them otherwise
        return value
    return callback


def common_options(fn: F) -> F:
    """--debug and -q/--quiet, accepted by every command."""
    fn = click.option("--debug", is_flag=True, expose_value=False, is_eager=True,
                      callback=_set_flag("debug"),
                      help="Show the full traceback of an error.")(fn)
    fn = click.option("-q", "--quiet", is_flag=True, callback=_set_flag("quiet"),
                      help="No progress bars or summaries on stderr.")(fn)
    return fn


def config_option(fn: F) -> F:
    return click.option("--config", "config_path", type=click.Path(dir_okay=False),
                        metavar="PARAMS.toml",
                        help="Parameter file overriding the defaults "
                             "(see `gpsdr fuse --print-config`).")(fn)


SMOOTH_CHOICES = ("auto", "rts", "graph", "none")


class SmoothCommand(click.Command):
    """A command whose ``--smooth`` takes an optional value: a bare ``--smooth`` (followed by
    anything that is not rts, graph or none, e.g. the LOG argument) means ``--smooth=rts``,
    as it did when ``--smooth`` was a flag."""

    def parse_args(self, ctx: click.Context, args: list[str]) -> list[str]:
        out: list[str] = []
        for i, a in enumerate(args):
            if a == "--":
                out.extend(args[i:])
                break
            if a == "--smooth" and (i + 1 >= len(args) or args[i + 1] not in SMOOTH_CHOICES):
                a = "--smooth=rts"
            out.append(a)
        return super().parse_args(ctx, out)


def _keep_no_smooth(ctx: click.Context, param: click.Parameter, value: str | None) -> str | None:
    # --no-smooth (handled first when given) must not be overwritten by an absent --smooth
    return ctx.params.get("smooth") if value is None else value


def _no_smooth(ctx: click.Context, param: click.Parameter, value: bool) -> None:
    if value:
        ctx.params["smooth"] = "none"


def filter_options(fn: F) -> F:
    """--filter, --smooth [rts|graph|none], --no-smooth and the calibration priors
    --odo-scale / --gyro-bias / --gyro-scale (default: from the parameters)."""
    fn = click.option("--gyro-scale", "gyro_scale", type=str, default=None, metavar="SCALE[+-SD]",
                      help="Known gyro scale (true yaw rate = SCALE x reading): every filter reads "
                           "the yaw rate times it, the graph's correction starts from it, "
                           "optionally with its sigma (default SD: [graph] gyro_scale_cal_sd), "
                           "e.g. 0.994+-0.002.")(fn)
    fn = click.option("--gyro-bias", "gyro_bias", type=str, default=None, metavar="RADPS[+-SD]",
                      help="Known gyro bias (rad/s, in the yaw rate's sign): the graph's prior and "
                           "ekf/aekf's starting drift, "
                           "optionally with its sigma (default SD: [graph] gyro_bias_sd_radps), "
                           "e.g. 0.002+-0.0005.")(fn)
    fn = click.option("--odo-scale", "odo_scale", type=str, default=None, metavar="SCALE[+-SD]",
                      help="Known odometer scale (true speed = SCALE x reading): the graph's prior "
                           "and ekf/aekf's starting scale, "
                           "optionally with its sigma (default SD: [graph] odo_scale_sd), "
                           "e.g. 1.012+-0.005.")(fn)
    fn = click.option("--no-smooth", is_flag=True, expose_value=False, callback=_no_smooth,
                      help="No smoother: the forward filter's track.")(fn)
    fn = click.option("--smooth", type=click.Choice(SMOOTH_CHOICES), is_flag=False,
                      flag_value="rts", default=None, callback=_keep_no_smooth,
                      help="After the forward filter: rts (the default of a bare --smooth), "
                           "graph (robust batch smoother: down-weights NLOS fixes), none, or "
                           "auto (graph with a gyro or odometer, rts on fixes alone; the "
                           "default, [filter] smoother).")(fn)
    fn = click.option("--filter", "filter_name", type=click.Choice(FILTER_NAMES),
                      default=None, help="Filter to run (default: [filter] name, aekf).")(fn)
    return fn


def format_option(fn: F) -> F:
    return click.option("--format", "fmt", type=click.Choice(("parquet", "csv")),
                        default="parquet", show_default=True,
                        help="Output table format.")(fn)


def parse_date(ctx: click.Context, param: click.Parameter, value: str | None) -> _dt.date | None:
    if value is None:
        return None
    try:
        return _dt.date.fromisoformat(value)
    except ValueError as err:
        raise click.BadParameter(f"{value!r} is not a date YYYY-MM-DD") from err


def parse_offset(ctx: click.Context, param: click.Parameter, value: str | None) -> str | float | None:
    if value is None or value == "auto":
        return value
    try:
        return float(value)
    except ValueError as err:
        raise click.BadParameter(f"{value!r}: expected seconds (e.g. 0.1) or auto") from err


def parse_topics(ctx: click.Context, param: click.Parameter,
                 value: tuple[str, ...]) -> dict[str, str] | None:
    topics: dict[str, str] = {}
    for item in value:
        kind, sep, name = item.partition("=")
        if not sep or not kind or not name:
            raise click.BadParameter(f"{item!r}: expected KIND=TOPIC, e.g. gnss=/ublox/fix")
        topics[kind.strip()] = name.strip()
    return topics or None


def reader_options(fn: F) -> F:
    """How to read the inputs: NMEA date, MCAP topics and time, CSV conventions."""
    opts = [
        click.option("--date", type=str, callback=parse_date, metavar="YYYY-MM-DD",
                     help="UTC date for NMEA logs without RMC/ZDA dates."),
        click.option("--topic", "topics", multiple=True, callback=parse_topics,
                     metavar="KIND=NAME",
                     help="MCAP: take stream KIND (gnss, gyro, odo) from topic NAME; repeatable."),
        click.option("--log-time", is_flag=True,
                     help="MCAP: use the log time instead of the message header stamp."),
        click.option("--gyro-units", type=click.Choice(("rad/s", "deg/s")), default=None,
                     help="Units of the gyro column (default rad/s)."),
        click.option("--gyro-sign", type=click.Choice(("ccw", "cw")), default=None,
                     help="ccw: positive counter-clockwise seen from above (default); cw: the "
                          "opposite."),
        click.option("--odo-kind", type=click.Choice(("auto", "speed", "distance", "ticks")),
                     default=None, help="What the odometer CSV holds (default: by column name)."),
        click.option("--ticks-per-m", type=float, default=None, metavar="TICKS",
                     help="Wheel ticks per metre, for --odo-kind ticks."),
    ]
    for opt in reversed(opts):
        fn = opt(fn)
    return fn


def frame_time_options(fn: F) -> F:
    """The GNSS time offset and the local frame."""
    fn = click.option("--epsg", type=int, default=None, metavar="CODE",
                      help="Local frame = this projected CRS (e.g. 32610 for UTM 10N) "
                           "instead of a transverse Mercator on the first fix.")(fn)
    fn = click.option("--gnss-offset", type=str, callback=parse_offset, metavar="SECONDS|auto",
                      help="Add SECONDS to every GNSS time stamp (receiver latency), or "
                           "estimate it: auto runs twice and reports the value.")(fn)
    return fn


def make_params(config_path: str | None = None, *, filter_name: str | None = None,
                smooth: str | bool | None = None, gnss_offset: str | float | None = None,
                epsg: int | None = None, gyro_units: str | None = None,
                gyro_sign: str | None = None, odo_kind: str | None = None,
                ticks_per_m: float | None = None, odo_scale: str | None = None,
                gyro_bias: str | None = None, gyro_scale: str | None = None) -> Any:
    """Defaults, then the --config file, then the command-line options (last wins)."""
    from .. import config

    params = config.load(config_path)
    overrides: dict[str, dict[str, Any]] = {}

    def put(section: str, key: str, value: Any) -> None:
        if value is not None:
            overrides.setdefault(section, {})[key] = value

    put("filter", "name", filter_name)
    if isinstance(smooth, bool):
        smooth = "rts" if smooth else "none"
    if smooth is not None:
        put("filter", "smoother", smooth)
        put("filter", "smooth", smooth != "none")
    if odo_scale is not None or gyro_bias is not None or gyro_scale is not None:
        from ..filters.graph import parse_prior

        base = params["graph"]
        if odo_scale is not None:
            v, sd = parse_prior(odo_scale, base["odo_scale_sd"], "--odo-scale")
            put("graph", "odo_scale", v)
            put("graph", "odo_scale_sd", sd)
        if gyro_bias is not None:
            v, sd = parse_prior(gyro_bias, base["gyro_bias_sd_radps"], "--gyro-bias")
            put("graph", "gyro_bias_radps", v)
            put("graph", "gyro_bias_sd_radps", sd)
        if gyro_scale is not None:
            v, sd = parse_prior(gyro_scale, base["gyro_scale_cal_sd"], "--gyro-scale")
            if v <= 0:
                from ..errors import UsageError

                raise UsageError(f"--gyro-scale {gyro_scale!r}: a scale is positive (yaw rates "
                                 "of the other sign are [gyro] sign = \"cw\")")
            put("graph", "gyro_scale", v)
            put("graph", "gyro_scale_cal_sd", sd)
    if isinstance(gnss_offset, float):
        put("time", "gnss_offset_s", gnss_offset)
    put("frame", "epsg", epsg)
    put("gyro", "units", gyro_units)
    put("gyro", "sign", gyro_sign)
    put("odo", "kind", odo_kind)
    put("odo", "ticks_per_m", ticks_per_m)
    return config.merge(params, overrides, "command line")
