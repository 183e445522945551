"""Drives without an odometer (GNSS and gyro only: a phone, a ROS bag without wheel odometry).

    .venv/bin/python benchmarks/no_odometer.py                       # ~2 min, the README table
    .venv/bin/python benchmarks/no_odometer.py --scenarios tunnels --filters aekf --seeds 1

Every simulated scenario (``simulate_drive(name, seed)``) with ``drive.odo = None``, each
filter forward and smoothed through ``build_epochs`` + :func:`gpsdr_cli.pipeline.run_filter`
(the registered filter, and forward the accelerometer's speed through the outages,
:mod:`gpsdr_cli.filters.accel_speed`, as ``gpsdr fuse`` runs them); prints per scenario the range
over the seeds of the RMSE (m, horizontal, every epoch, against the simulator's truth),
next to the fixes alone, and for the scenarios with 15-s braking / drive-off outages
(no_odometer) the median over the seeds' outages of the error at their end, and of the
smoothed track's largest error inside each (and the worst).
``--positions-only`` also strips the receiver's speed and course; ``--no-accel`` the
forward accelerometer (gyro only).

    .venv/bin/python benchmarks/no_odometer.py --scenarios no_odometer --filters ekf,aekf,fkf,fafkf
    .venv/bin/python benchmarks/no_odometer.py --scenarios no_odometer --no-accel
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

from gpsdr_cli import config
from gpsdr_cli.align import build_epochs
from gpsdr_cli.pipeline import run_filter
from gpsdr_cli.simulate import SCENARIOS, simulate_drive


def run(sim, drive, name: str, smooth: bool
        ) -> tuple[float, float, list[float], list[float]]:
    """RMSE (m) of ``name`` over ``drive`` against the truth, the fixes' RMSE (m), the
    error (m) at the end of each of the scenario's 15-s outages (the last epoch before the
    next fix) and the largest error (m) inside each."""
    p = config.defaults()
    p["filter"]["name"] = name
    p["filter"]["smooth"] = smooth
    ep = build_epochs(copy.deepcopy(drive), sim.frame, p)
    r = run_filter(ep, p)
    tr = sim.truth
    te, tn = np.interp(ep.t_ns, tr.t_ns, tr.e), np.interp(ep.t_ns, tr.t_ns, tr.n)
    err = np.hypot(r.e - te, r.n - tn)
    f = ep.has_gnss
    gnss = float(np.sqrt(np.mean((ep.gnss_e[f] - te[f]) ** 2 + (ep.gnss_n[f] - tn[f]) ** 2)))
    g = sim.drive.gnss
    tf = g.t_ns[g.valid]
    ends, worst = [], []
    for o in sim.noise.get("brake_outages", []):
        k = int(np.searchsorted(tf, int(tr.t_ns.iloc[0]) + int(o["start_s"] * 1e9))) - 1
        if 0 <= k < len(tf) - 1:
            ends.append(float(err[int(np.searchsorted(ep.t_ns, tf[k + 1])) - 1]))
            inside = (ep.t_ns > tf[k]) & (ep.t_ns < tf[k + 1])
            worst.append(float(err[inside].max()))
    return float(np.sqrt(np.mean(err ** 2))), gnss, ends, worst


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
    ap.add_argument("--no-accel", action="store_true", help="strip the forward accelerometer")
    args = ap.parse_args()
    names = args.filters.split(",")
    seeds = [int(s) for s in args.seeds.split(",")]
    t0 = time.perf_counter()
    rows = []
    for scen in args.scenarios.split(","):
        gnss: list[float] = []
        res: dict[tuple[str, bool], list[float]] = {}
        ends: dict[tuple[str, bool], list[float]] = {}
        worst: dict[tuple[str, bool], list[float]] = {}
        for seed in seeds:
            sim = simulate_drive(scen, seed=seed)
            drive = copy.deepcopy(sim.drive)
            drive.odo = None
            if args.no_accel:
                drive.accel = None
            if args.positions_only:
                drive.gnss.speed_mps[:] = np.nan
                drive.gnss.course_deg[:] = np.nan
            for name in names:
                for smooth in (False, True):
                    rmse, g, e, w = run(sim, drive, name, smooth)
                    res.setdefault((name, smooth), []).append(rmse)
                    ends.setdefault((name, smooth), []).extend(e)
                    worst.setdefault((name, smooth), []).extend(w)
            gnss.append(g)
        cells = [f"{span(res[(n, False)])} / {span(res[(n, True)])}" for n in names]
        if ends[(names[0], False)]:
            cells = [c + f" (15-s outage ends {np.median(ends[(n, False)]):.2f} / "
                         f"{np.median(ends[(n, True)]):.2f}; inside, smoothed: "
                         f"{np.median(worst[(n, True)]):.2f}, worst {max(worst[(n, True)]):.2f})"
                     for c, n in zip(cells, names, strict=True)]
        rows.append(f"| {scen} | {span(gnss)} | " + " | ".join(cells) + " |")
    what = "positions only, no odometer" if args.positions_only else "no odometer"
    if args.no_accel:
        what += ", no accelerometer"
    print(f"{what}: RMSE m, forward / smoothed, range over seeds {args.seeds} "
          f"({time.perf_counter() - t0:.0f} s); (15-s outage ends: median end error m, "
          "forward / smoothed; inside: the smoothed track's largest error in each outage, "
          "median and worst, m)\n")
    print("| scenario | GNSS alone | " + " | ".join(names) + " |")
    print("|---" * (len(names) + 2) + "|")
    print("\n".join(rows))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
