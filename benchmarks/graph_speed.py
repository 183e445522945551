"""Speed and memory of the graph smoother: one hour of 100 Hz gyro + odometer and 5 Hz GNSS
(simulated one_hour drive), at 1x, 2x and 4x that length.

    .venv/bin/python benchmarks/graph_speed.py              # 1x, 2x, 4x hours
    .venv/bin/python benchmarks/graph_speed.py --hours 1    # one length only

Each length runs in a fresh process (so its peak RSS is its own): the aligned epochs and
the aekf + RTS pass that starts the graph are built first and not timed; the graph solve
alone is timed (wall and CPU), and the process's peak RSS is read from ``resource``.
The compile of the kernels is done once before timing.
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import copy, json, resource, sys, time
import numpy as np
sys.path.insert(0, {root!r})
from gpsdr_cli import config, filters
from gpsdr_cli.align import build_epochs
from gpsdr_cli.filters.graph import smooth_graph
from gpsdr_cli.simulate import simulate_drive

hours = {hours}
p = config.defaults()
p["filter"]["name"] = "aekf"
p["filter"]["smooth"] = True
# compile on a short drive first
s0 = simulate_drive("urban_canyon", seed=1, duration_s=30.0)
e0 = build_epochs(copy.deepcopy(s0.drive), s0.frame, p)
smooth_graph(e0, filters.get("aekf")(e0, p), p)
sim = simulate_drive("one_hour", seed=1, duration_s=3600.0 * hours)
ep = build_epochs(sim.drive, sim.frame, p)
del sim
rts = filters.get("aekf")(ep, p)
c0 = time.process_time()
t0 = time.perf_counter()
out = smooth_graph(ep, rts, p)
wall = time.perf_counter() - t0
cpu = time.process_time() - c0
rss = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
print(json.dumps({{"hours": hours, "epochs": len(ep), "wall_s": wall, "cpu_s": cpu,
                   "peak_rss_mb": rss, "iterations": out.iterations,
                   "converged": out.converged}}))
"""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--hours", default="1,2,4")
    args = ap.parse_args(argv)
    rows = []
    for h in [float(x) for x in args.hours.split(",") if x]:
        res = subprocess.run([sys.executable, "-c", CHILD.format(root=str(ROOT), hours=h)],
                             capture_output=True, text=True, check=True)
        rows.append(json.loads(res.stdout.strip().splitlines()[-1]))
        print(rows[-1], file=sys.stderr)
    print("| hours | epochs | graph wall s | CPU s | s per hour | peak RSS MB | iterations |")
    print("|---|---|---|---|---|---|---|")
    for r in rows:
        print(f"| {r['hours']:g} | {r['epochs']} | {r['wall_s']:.1f} | {r['cpu_s']:.1f} | "
              f"{r['wall_s'] / r['hours']:.1f} | {r['peak_rss_mb']:.0f} | {r['iterations']} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
