"""Gyro and odometer clocks off the receiver's: the fused error with and without the check.

    python benchmarks/dr_clock.py [--scenarios urban_canyon,stop_and_go,urban_nlos] [--seed 1]

Each simulated drive is fused (``pipeline.fuse``, default aekf, forward) with both dead-reckoning
streams stamped late by each offset of ``--offsets``, once with ``[time] dr_clock_check``
off and once on (gpsdr_cli.clock_check).  A cell is the RMSE (m) against the truth, off / on;
the last columns give the offsets the check set for the odometer and the gyro at the
largest offset.
"""

from __future__ import annotations

import argparse
import copy
import dataclasses
import sys
import time
import warnings
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gpsdr_cli import clock_check, config  # noqa: E402
from gpsdr_cli.pipeline import fuse  # noqa: E402
from gpsdr_cli.simulate import simulate_drive  # noqa: E402


def shifted(drive, shift_s: float):
    d = copy.deepcopy(drive)
    ns = np.int64(round(shift_s * 1e9))
    for name in ("gyro", "odo"):
        s = getattr(d, name)
        if s is not None:
            setattr(d, name, dataclasses.replace(s, t_ns=s.t_ns + ns))
    return d


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenarios", default="urban_canyon,stop_and_go,urban_nlos")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--offsets", default="0,18,-18,1", help="s, comma-separated")
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    offsets = [float(x) for x in args.offsets.split(",")]
    t0 = time.perf_counter()
    print("| drive | fixes | " + " | ".join(f"{o:+g} s" for o in offsets)
          + f" | set at {offsets[-1]:+g} s: odometer / gyro |")
    print("|---|---|" + "---|" * len(offsets) + "---|")
    for sc in args.scenarios.split(","):
        sim = simulate_drive(sc, args.seed)
        truth = sim.truth[["t_ns", "lat", "lon"]]
        cells, fixes = [], float("nan")
        for off in offsets:
            pair = []
            for on in (False, True):
                p = config.defaults()
                p["time"]["dr_clock_check"] = on
                res = fuse(shifted(sim.drive, off), p, truth)
                pair.append(res.summary()["rmse_m"])
                fixes = res.gnss_only_summary()["rmse_m"]
            cells.append(f"{pair[0]:.2f} / {pair[1]:.2f}")
        q, _ = clock_check.check(shifted(sim.drive, offsets[-1]), config.defaults())
        print(f"| {sc} s{args.seed} | {fixes:.2f} | " + " | ".join(cells)
              + f" | {q['time']['odo_offset_s']:+.2f} / {q['time']['gyro_offset_s']:+.2f} |",
              flush=True)
    print(f"\n{time.perf_counter() - t0:.0f} s")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
