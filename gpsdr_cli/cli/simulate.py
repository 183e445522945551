"""``gpsdr simulate``: write a drive with known truth (NMEA, CSVs, MCAP, truth.csv)."""

from __future__ import annotations

import click

from ..errors import UsageError
from .options import common_options


@click.command()
@click.option("-o", "--output", "out_dir", required=True, type=click.Path(file_okay=False),
              metavar="DIR", help="Directory to write the drive into (created).")
@click.option("--scenario", default="urban_canyon", show_default=True, metavar="NAME",
              help="open_sky, urban_canyon, tunnels, stop_and_go, one_hour, urban_nlos, rtk, no_odometer.")
@click.option("--seed", default=0, show_default=True, type=int, help="Random seed.")
@click.option("--duration", "duration_s", type=float, default=None, metavar="SECONDS",
              help="Override the scenario's length.")
@common_options
def simulate(out_dir: str, scenario: str, seed: int, duration_s: float | None,
             quiet: bool) -> None:
    """Simulate a drive with known truth: gps.nmea, gyro.csv, odo.csv, drive.mcap,
    truth.csv and noise.json in DIR, ready for `gpsdr fuse` and `gpsdr stats`.

    \b
    Examples:
      gpsdr simulate -o sim/ --scenario tunnels --seed 3
      gpsdr fuse --gps sim/gps.nmea --gyro sim/gyro.csv --odo sim/odo.csv \\
                 --reference sim/truth.csv
    """
    from pathlib import Path

    from ..simulate import SCENARIOS, simulate_drive, write_drive

    if scenario not in SCENARIOS:
        raise UsageError(f"unknown scenario {scenario!r}; choose one of {', '.join(SCENARIOS)}")
    if duration_s is not None and not duration_s > 0:
        raise UsageError(f"--duration {duration_s}: expected a positive number of seconds")
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    sim = simulate_drive(scenario, seed=seed, duration_s=duration_s)
    files = write_drive(sim, out)
    if not quiet:
        for kind, path in files.items():
            click.echo(f"{kind}: {path}")
