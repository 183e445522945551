"""Unhealthy dead reckoning on simulated drives: is any filter's track worse than its fixes?

    python benchmarks/dr_faults.py [--scenarios urban_canyon,urban_nlos,open_sky] [--seeds 1,2]

Each fault of :data:`FAULTS` is injected into each drive (gpsdr_cli.testing.faults), and every
filter runs forward and with RTS through the pipeline (``gpsdr fuse``'s run_filter).  A row
gives the fixes' RMSE and each track's RMSE against the truth, both outside the GNSS outages
(the fixes do not exist there), and the worst track over the fixes; ``WORSE`` marks a row
where some track is above 1.0.
"""

from __future__ import annotations

import argparse
import copy
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gpsdr_cli.simulate import simulate_drive  # noqa: E402
from gpsdr_cli.testing import faults as F  # noqa: E402
from gpsdr_cli.testing.sim import run_filter  # noqa: E402

FAULTS = {
    "clean": lambda d: d,
    "gyro clips at 0.1 rad/s": lambda d: F.gyro_saturation(d, 0.1),
    "gyro clips at 0.2 rad/s": lambda d: F.gyro_saturation(d, 0.2),
    "odometer 0 m/s for 60 s": lambda d: F.odo_dropout(d, 100.0, 60.0, mode="zero"),
    "odometer silent 120 s": lambda d: F.odo_dropout(d, 100.0, 120.0, mode="missing"),
    "GNSS outage 30 s": lambda d: F.gnss_outage(d, 200.0, 30.0),
    "gyro and odometer at 5 Hz": lambda d: F.decimate(F.decimate(d, "gyro", 5.0), "odo", 5.0),
    "no odometer": lambda d: F.drop_streams(d, "odo"),
    "no gyro": lambda d: F.drop_streams(d, "gyro"),
}
FILTERS = ("ekf", "aekf", "fkf", "fafkf")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="urban_canyon,urban_nlos,open_sky")
    ap.add_argument("--seeds", default="1,2")
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    t0 = time.perf_counter()
    head = " | ".join(f"{f} / +RTS" for f in FILTERS)
    print(f"| drive | fault | fixes | {head} | worst / fixes |")
    print("|---|---|---|" + "---|" * len(FILTERS) + "---|")
    n_worse = 0
    for sc in args.scenarios.split(","):
        for seed in (int(s) for s in args.seeds.split(",")):
            sim = simulate_drive(sc, seed)
            for fname, fault in FAULTS.items():
                drive = fault(copy.deepcopy(sim.drive))
                cells, worst, fixes = [], 0.0, float("nan")
                for name in FILTERS:
                    pair = []
                    for smooth in (False, True):
                        r = run_filter(sim, copy.deepcopy(drive), name, smooth=smooth,
                                       pipeline=True)
                        out = ~r.epochs.gnss_outage
                        rmse = float(np.sqrt(np.mean(r.err_m[out] ** 2)))
                        fixes = r.gnss_rmse_m
                        worst = max(worst, rmse)
                        pair.append(rmse)
                    cells.append(f"{pair[0]:.2f} / {pair[1]:.2f}")
                ratio = worst / fixes
                n_worse += ratio > 1.0
                mark = " WORSE" if ratio > 1.0 else ""
                print(f"| {sc} s{seed} | {fname} | {fixes:.2f} | " + " | ".join(cells)
                      + f" | {ratio:.2f}{mark} |", flush=True)
    print(f"\n{n_worse} rows with a track worse than its fixes; {time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
