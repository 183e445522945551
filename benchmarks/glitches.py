"""In-range glitches: wrong but plausible readings, and what each filter makes of them.

    python benchmarks/glitches.py [--seeds 1,2] [--duration 300] [--no-check]

Simulated drives with truth (open sky; the ``no_odometer`` scenario for the accelerometer),
their streams damaged in memory as a dirty log would be, then the readers' check
(:func:`gpsdr_cli.io.readers.drop_impossible`: readings beyond physics or off their
neighbours, :mod:`gpsdr_cli.io.spikes`) and the pipeline's filters, forward and with RTS.
A row gives, per filter, the RMSE (m) against the truth clean -> damaged, the worst over
the seeds, and the fixes' own RMSE.  ``--no-check`` leaves the readers' check out (the
filters' own gates alone).  Faults:

* ``velocity``: 5 % of the receiver's velocities a random speed (0-40 m/s) and course;
* ``velocity, no odometer``: the same on the drive without its odometer;
* ``odometer``: 5 % of 100-Hz odometer readings a random 0-40 m/s;
* ``gyro``: 1 % of gyro readings a random -8..8 rad/s;
* ``accelerometer``: 1 % of forward accelerations a random -40..40 m/s^2 (no odometer:
  the accelerometer bridges the 15-s outages).
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gpsdr_cli.io.readers import drop_impossible  # noqa: E402
from gpsdr_cli.simulate import simulate_drive  # noqa: E402
from gpsdr_cli.testing.faults import (  # noqa: E402
    drop_streams,
    random_values,
    with_drive,
    wrong_velocities,
)
from gpsdr_cli.testing.sim import run_filter  # noqa: E402

FILTERS = ("ekf", "aekf", "fkf", "fafkf")
#: name -> (scenario, drop the odometer, damage(drive, seed))
FAULTS = {
    "velocity": ("open_sky", False, lambda d, s: wrong_velocities(d, 0.05, seed=s)),
    "velocity, no odometer": ("open_sky", True, lambda d, s: wrong_velocities(d, 0.05, seed=s)),
    "odometer": ("open_sky", False, lambda d, s: random_values(d, "odo", 0.05, 0.0, 40.0, seed=s)),
    "gyro": ("open_sky", False, lambda d, s: random_values(d, "gyro", 0.01, -8.0, 8.0, seed=s)),
    "accelerometer": ("no_odometer", False,
                      lambda d, s: random_values(d, "accel", 0.01, -40.0, 40.0, seed=s)),
}


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", default="1,2")
    ap.add_argument("--duration", type=float, default=300.0, help="s")
    ap.add_argument("--no-check", action="store_true", help="leave the readers' check out")
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    seeds = [int(s) for s in args.seeds.split(",")]
    t0 = time.perf_counter()
    head = " | ".join(f"{f} / + RTS" for f in FILTERS)
    print(f"Worst RMSE over seeds {args.seeds} (m), clean -> damaged"
          f"{'' if not args.no_check else ', without the readers check'}\n")
    print(f"| fault | fixes | {head} |")
    print("|---|---|" + "---|" * len(FILTERS))
    for name, (scenario, no_odo, damage) in FAULTS.items():
        worst: dict[tuple[str, bool], list[float]] = {}
        fixes = 0.0
        for seed in seeds:
            sim = simulate_drive(scenario, seed, args.duration, odo_rate_hz=100.0)
            if no_odo:
                sim = with_drive(sim, drop_streams(sim.drive, "odo"))
            bad = damage(sim.drive, seed)
            if not args.no_check:
                drop_impossible(bad, [])
            for f in FILTERS:
                for smooth in (False, True):
                    pair = [run_filter(sim, copy.deepcopy(d), f, smooth=smooth, pipeline=True)
                            for d in (sim.drive, bad)]
                    fixes = max(fixes, pair[1].gnss_rmse_m)
                    w = worst.setdefault((f, smooth), [0.0, 0.0])
                    w[0] = max(w[0], pair[0].rmse_m)
                    w[1] = max(w[1], pair[1].rmse_m)
        cells = [f"{worst[f, False][0]:.2f} -> {worst[f, False][1]:.2f} / "
                 f"{worst[f, True][0]:.2f} -> {worst[f, True][1]:.2f}" for f in FILTERS]
        print(f"| {name} | {fixes:.2f} | " + " | ".join(cells) + " |", flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
