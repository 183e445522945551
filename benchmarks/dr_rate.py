"""Accuracy against the dead-reckoning rate: a CAN bus's 5-10 Hz against a 100-Hz IMU.

    python benchmarks/dr_rate.py [--scenario open_sky] [--seed 1] [--duration 600]

Simulates ``--scenario`` with the gyro and the odometer both at 100, 20, 10 and 5 Hz (the
same per-sample noise: the worst case, a CAN signal is often averaged) and runs every
filter forward and with RTS through the pipeline (``gpsdr fuse``'s run_filter), and the
graph smoother started from the default filter's RTS track (``--smooth graph``).  RMSE in
metres against the truth, the fixes alone beside them.
"""

from __future__ import annotations

import argparse
import copy
import sys
import warnings
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

import numpy as np  # noqa: E402

from gpsdr_cli import config  # noqa: E402
from gpsdr_cli.filters import NAMES  # noqa: E402
from gpsdr_cli.filters.graph import smooth_graph  # noqa: E402
from gpsdr_cli.simulate import simulate_drive  # noqa: E402
from gpsdr_cli.testing.sim import run_filter  # noqa: E402

RATES_HZ = (100, 20, 10, 5)


def graph_rmse(sim, rts, params) -> str:
    """The graph smoother's RMSE (m) from the RTS run ``rts``, or why it fell back."""
    out = smooth_graph(rts.epochs, rts.result, params)
    if out.result is None:
        return f"failed ({out.message})"
    t = rts.epochs.t_ns
    tr = sim.truth
    err = np.hypot(out.result.e - np.interp(t, tr.t_ns, tr.e), out.result.n - np.interp(t, tr.t_ns, tr.n))
    return f"{float(np.sqrt(np.mean(err ** 2))):.2f}"


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--scenario", default="open_sky")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--duration", type=float, default=600.0, help="s")
    args = ap.parse_args()
    warnings.filterwarnings("ignore")
    print(f"{args.scenario}, seed {args.seed}, {args.duration:g} s: RMSE m, forward / RTS")
    print("| gyro + odometer Hz | fixes | " + " | ".join(NAMES) + " | graph |")
    print("|---|---|" + "---|" * (len(NAMES) + 1))
    params = config.defaults()
    params["filter"]["smooth"] = True
    lead = NAMES.index(params["filter"]["name"])
    for rate in RATES_HZ:
        sim = simulate_drive(args.scenario, args.seed, args.duration, gyro_rate_hz=rate,
                             odo_rate_hz=rate)
        runs = [[run_filter(sim, copy.deepcopy(sim.drive), name, smooth=s, pipeline=True)
                 for s in (False, True)] for name in NAMES]
        cells = " | ".join(f"{fwd.rmse_m:.2f} / {rts.rmse_m:.2f}" for fwd, rts in runs)
        graph = graph_rmse(sim, runs[lead][1], params)
        print(f"| {rate} | {runs[0][0].gnss_rmse_m:.2f} | {cells} | {graph} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
