"""Drives without an odometer (GNSS and gyro only: a phone, a ROS bag without wheel odometry).

    .venv/bin/python benchmarks/no_odometer.py                       # ~2 min, the README table
    .venv/bin/python benchmarks/no_odometer.py --scenarios tunnels --filters aekf --seeds 1

Every simulated scenario (``simulate_drive(name, seed)``) with ``drive.odo = None``, each
filter forward and smoothed through ``build_epochs`` + the registered filter
(:func:`gpsdr_cli.testing.sim.run_filter`, as ``benchmarks/accuracy.py`` runs them);
prints per scenario the range over the seeds of the RMSE (m, horizontal, every epoch,
against the simulator's truth), next to the fixes alone.
``--positions-only`` also strips the receiver's speed and course.
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gpsdr_cli.simulate import SCENARIOS, simulate_drive
from gpsdr_cli.testing.sim import run_filter


def span(values: list[float]) -> str:
    lo, hi = min(values), max(values)
    fmt = "{:.2f}" if hi < 10 else "{:.1f}" if hi < 100 else "{:.0f}"
    return fmt.format(lo) if fmt.format(lo) == fmt.format(hi) else f"{fmt.format(lo)}-{fmt.format(hi)}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default=",".join(SCENARIOS))
    ap.add_argument("--filters", default="aekf,fkf")
    ap.add_argument("--seeds", default="1,2,3")
    ap.add_argument("--positions-only", action="store_true")
    args = ap.parse_args()
    names = args.filters.split(",")
    seeds = [int(s) for s in args.seeds.split(",")]
    t0 = time.perf_counter()
    rows = []
    for scen in args.scenarios.split(","):
        gnss: list[float] = []
        res: dict[tuple[str, bool], list[float]] = {}
        for seed in seeds:
            sim = simulate_drive(scen, seed=seed)
            drive = copy.deepcopy(sim.drive)
            drive.odo = None
            if args.positions_only:
                drive.gnss.speed_mps[:] = np.nan
                drive.gnss.course_deg[:] = np.nan
            for name in names:
                for smooth in (False, True):
                    run = run_filter(sim, drive, name, smooth)
                    res.setdefault((name, smooth), []).append(run.rmse_m)
                    g = run.gnss_rmse_m
            gnss.append(g)
        cells = [f"{span(res[(n, False)])} / {span(res[(n, True)])}" for n in names]
        rows.append(f"| {scen} | {span(gnss)} | " + " | ".join(cells) + " |")
    what = "positions only, no odometer" if args.positions_only else "no odometer"
    print(f"{what}: RMSE m, forward / smoothed, range over seeds {args.seeds} "
          f"({time.perf_counter() - t0:.0f} s)\n")
    print("| scenario | GNSS alone | " + " | ".join(names) + " |")
    print("|---" * (len(names) + 2) + "|")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
