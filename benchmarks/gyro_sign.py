"""The gyro's sign and units against the receiver's course: is a misread gyro caught, a right one left?

    python benchmarks/gyro_sign.py

Every simulated drive below, as logged and with its yaw rates negated (a logger that writes
them clockwise-positive), then in deg/s read as rad/s and in rad/s read as deg/s, through
:func:`gpsdr_cli.gyro_sign.course_slope` and :func:`gpsdr_cli.gyro_sign.check`: the 40 283-s
city drives of ``benchmarks/short_city.py`` (5-Hz CAN rates), 10 of them with a 3 % gyro
scale error, and seeds 1-3 of the other scenarios at 300 s.  A row, as logged and mirrored:
slope of the course change on the gyro's heading change, its standard error, robust cost as
read over read as the nearest misreading, windows, and whether it was called misread.  The
last lines count false calls and misread drives caught.
"""

from __future__ import annotations

import copy
import dataclasses
import math
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gpsdr_cli import config, simulate  # noqa: E402
from gpsdr_cli.align import build_epochs  # noqa: E402
from gpsdr_cli.gyro_sign import check, course_slope  # noqa: E402


def _row(ep) -> tuple[str, bool]:
    """The table cells of ``ep`` and whether its gyro was called misread."""
    fit = course_slope(ep)
    called = check(ep)[1] is not None
    if fit is None:
        return "- | - | - | - | no", called
    slope, se, ratio, n = fit
    return f"{slope:+.3f} | {se:.3f} | {ratio:.3f} | {n} | {'yes' if called else 'no'}", called


def main() -> int:
    warnings.filterwarnings("ignore")
    params = config.defaults()
    drives = [(f"city {s}", 0.0, "urban_nlos", s, 283.0) for s in range(1, 41)]
    drives += [(f"city {s}, gyro 3 % off", 0.03, "urban_nlos", s, 283.0) for s in range(1, 11)]
    drives += [(f"{sc} {s}", 0.0, sc, s, 300.0)
               for sc in ("open_sky", "urban_canyon", "tunnels", "stop_and_go", "urban_nlos",
                          "rtk", "no_odometer") for s in (1, 2, 3)]
    print("| drive | as logged: slope | se | cost ratio | windows | called wrong "
          "| mirrored: slope | se | cost ratio | windows | called wrong |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    false_calls = 0
    caught = {"mirrored": 0, "deg/s as rad/s": 0, "rad/s as deg/s": 0}
    for label, extra, scenario, seed, dur in drives:
        simulate.GYRO_EXTRA_SCALE = extra
        rates = {"gyro_rate_hz": 5.0, "odo_rate_hz": 5.0} if label.startswith("city") else {}
        sim = simulate.simulate_drive(scenario, seed, dur, **rates)
        ep = build_epochs(copy.deepcopy(sim.drive), sim.frame, params)
        mirrored = dataclasses.replace(ep, yaw_rate_radps=-ep.yaw_rate_radps)
        cells, called = _row(ep)
        cells_m, called_m = _row(mirrored)
        false_calls += called
        caught["mirrored"] += called_m
        for name, f in (("deg/s as rad/s", 180.0 / math.pi), ("rad/s as deg/s", math.pi / 180.0)):
            misread = dataclasses.replace(ep, yaw_rate_radps=f * ep.yaw_rate_radps)
            caught[name] += check(misread)[1] is not None
        print(f"| {label} | {cells} | {cells_m} |", flush=True)
    simulate.GYRO_EXTRA_SCALE = 0.0
    print(f"\n{false_calls} of {len(drives)} drives as logged called misread; caught: "
          + ", ".join(f"{k} {v} of {len(drives)}" for k, v in caught.items()))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
