"""Short city drives with reflected signals and CAN-rate dead reckoning: any track above its fixes?

    python benchmarks/short_city.py [--seeds 1,2,3,4,5,6] [--duration 283] [--rate 5]

The simulated ``urban_nlos`` drive cut to ``--duration`` seconds, with the gyro and the
odometer sampled at ``--rate`` Hz (a CAN bus's yaw rate and wheel speed), run through the
pipeline (``gpsdr fuse``'s run_filter) by every filter, forward and with RTS, and by the graph
smoother from the default filter's RTS track.  A row gives the fixes' RMSE against the truth,
each track's, the graph's, the fixes the NLOS screen left out and the worst track over the
fixes (``WORSE`` above 1.0).  Defaults: the length and the rates of the real
city-centre drive that issue 14 reports (283 s, 5 Hz CAN).  RMSE in metres.
``--no-odometer``: the same drives with the gyro alone, where nothing screens the fixes.
``--nlos-ramp LO,HI``: the reflections ramp in and out over LO-HI seconds instead of the
simulator's 1-4 s (a receiver whose own filter blends a reflection in slowly).
``--nlos-duration LO,HI``: each reflection lasts LO-HI seconds instead of the simulator's
5-60 s (a street where the direct signal stays blocked for minutes).
``--steady-gyro``: the gyro's bias held at its first draw for the whole drive (an automotive
yaw-rate sensor's) instead of the simulator's wandering MEMS bias.
``--gyro-scale-error K``: the gyro reads K more of the true yaw rate than the simulator's own
scale error (0.03: a phone gyro's 3 %).
``--gyro-phase S``: the gyro sampled S seconds after the odometer instead of at the same
instants (two CAN messages; 0.1 at 5 Hz: half a period apart).
``--nlos-wander SD,DIST``: the canyon's reflected-signal errors wander instead of holding
steps: a Gauss-Markov error of SD metres per axis that decorrelates over DIST metres driven
(``simulate.NLOS_SHAPE = "wander"``).
``--nlos-doppler speed``: a reflection's receiver-velocity error proportional to the true
velocity, none at a standstill (``simulate.NLOS_VEL_MODEL``; a wall mirrors the receiver's
velocity) instead of the simulator's bias of 1 m/s per axis held through the step, stops too.
``--set SECTION.KEY=VALUE`` (repeatable, VALUE as in the TOML config) changes a default for
every run, e.g. ``--set gnss.nlos_fkf_velocity_sd_mps=0.2``.  The last lines give the
median, mean and worst of track RMSE over the fixes' RMSE per column.
"""

from __future__ import annotations

import argparse
import copy
import math
import sys
import time
import tomllib
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402
from dr_rate import graph_rmse  # noqa: E402

from gpsdr_cli import config, simulate  # noqa: E402
from gpsdr_cli.simulate import simulate_drive  # noqa: E402
from gpsdr_cli.testing.faults import drop_streams, with_drive  # noqa: E402
from gpsdr_cli.testing.sim import run_filter  # noqa: E402

FILTERS = ("ekf", "aekf", "fkf", "fafkf")


def _pair(text: str) -> tuple[float, float]:
    """"LO,HI" as two floats."""
    lo, hi = (float(v) for v in text.split(","))
    return lo, hi


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1,2,3,4,5,6")
    ap.add_argument("--duration", type=float, default=283.0, help="s")
    ap.add_argument("--rate", type=float, default=5.0, help="gyro and odometer rate, Hz")
    ap.add_argument("--no-odometer", action="store_true",
                    help="drop the odometer (gyro only: nothing screens the fixes)")
    ap.add_argument("--nlos-ramp", default="", metavar="LO,HI",
                    help="the reflections' on and off ramps, s (default: the simulator's)")
    ap.add_argument("--nlos-duration", default="", metavar="LO,HI",
                    help="how long each reflection lasts, s (default: the simulator's)")
    ap.add_argument("--steady-gyro", action="store_true",
                    help="the gyro's bias constant over the drive (default: it wanders)")
    ap.add_argument("--gyro-scale-error", type=float, default=0.0, metavar="K",
                    help="extra gyro scale error, e.g. 0.03 (default: the simulator's own)")
    ap.add_argument("--gyro-phase", type=float, default=0.0, metavar="S",
                    help="the gyro sampled S s after the odometer (default: the same instants)")
    ap.add_argument("--nlos-wander", default="", metavar="SD,DIST",
                    help="wandering reflection errors, m per axis and m driven (default: steps)")
    ap.add_argument("--nlos-doppler", choices=("bias", "speed"), default="bias",
                    help="the reflections' receiver-velocity error model (default: bias)")
    ap.add_argument("--set", action="append", default=[], metavar="SECTION.KEY=VALUE",
                    help="change a default for every run (repeatable)")
    args = ap.parse_args()
    overrides: dict[str, dict] = {}
    for item in args.set:
        key, _, value = item.partition("=")
        section, _, name = key.partition(".")
        overrides.setdefault(section, {})[name] = tomllib.loads(f"v = {value}")["v"]
    # read by simulate_drive at each call
    if args.nlos_ramp:
        simulate.NLOS_RAMP_S = _pair(args.nlos_ramp)
    if args.nlos_duration:
        simulate.NLOS_DURATION_S = _pair(args.nlos_duration)
    if args.steady_gyro:
        simulate.GYRO_BIAS_TAU_S = math.inf
    simulate.GYRO_EXTRA_SCALE = args.gyro_scale_error
    simulate.GYRO_PHASE_S = args.gyro_phase
    simulate.NLOS_VEL_MODEL = args.nlos_doppler
    if args.nlos_wander:
        simulate.NLOS_SHAPE = "wander"
        simulate.NLOS_WANDER_SD_M, simulate.NLOS_WANDER_DIST_M = _pair(args.nlos_wander)
    warnings.filterwarnings("ignore")
    t0 = time.perf_counter()
    head = " | ".join(f"{f} / +RTS" for f in FILTERS)
    print(f"| seed | fixes | {head} | graph | screened fixes | worst / fixes |")
    print("|---|---|" + "---|" * len(FILTERS) + "---|---|---|")
    params = config.defaults()
    params["filter"]["smooth"] = True
    for section, values in overrides.items():
        params[section].update(values)
    n_worse = 0
    ratios: dict[str, list[float]] = {}
    for seed in (int(s) for s in args.seeds.split(",")):
        sim = simulate_drive("urban_nlos", seed, args.duration, gyro_rate_hz=args.rate,
                             odo_rate_hz=args.rate)
        if args.no_odometer:
            sim = with_drive(sim, drop_streams(sim.drive, "odo"))
        cells, worst, fixes, screened = [], 0.0, float("nan"), 0
        for name in FILTERS:
            pair = []
            for smooth in (False, True):
                r = run_filter(sim, copy.deepcopy(sim.drive), name, smooth=smooth,
                               overrides=overrides, pipeline=True)
                fixes = r.gnss_rmse_m
                ratios.setdefault(name + (" + RTS" if smooth else ""), []).append(
                    r.rmse_m / r.gnss_rmse_m)
                worst = max(worst, r.rmse_m)
                screened = int(r.result.info.get("nlos_screened", 0))
                pair.append(r.rmse_m)
                if smooth and name == params["filter"]["name"]:
                    graph = graph_rmse(sim, r, params)
            cells.append(f"{pair[0]:.1f} / {pair[1]:.1f}")
        ratio = worst / fixes
        n_worse += ratio > 1.0
        mark = " WORSE" if ratio > 1.0 else ""
        print(f"| {seed} | {fixes:.1f} | " + " | ".join(cells)
              + f" | {graph} | {screened} | {ratio:.2f}{mark} |", flush=True)
    print(f"\n{n_worse} drives with a track worse than its fixes; {time.perf_counter() - t0:.0f} s")
    print("\n| track / fixes | " + " | ".join(ratios) + " |")
    print("|---|" + "---|" * len(ratios))
    for label, fn in (("median", np.median), ("mean", np.mean), ("worst", np.max)):
        print(f"| {label} | " + " | ".join(f"{fn(v):.3f}" for v in ratios.values()) + " |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
