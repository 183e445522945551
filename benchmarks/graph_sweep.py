"""The graph smoother's kernel and noise settings against truth: urban_canyon (300 s) with
and without NLOS steps (``gpsdr_cli.testing.nlos``), started from aekf + RTS.

    .venv/bin/python benchmarks/graph_sweep.py                       # the default settings
    .venv/bin/python benchmarks/graph_sweep.py --true-scale-sd 0.005  # + the true odometer scale
    .venv/bin/python benchmarks/graph_sweep.py --seeds 1,2 \\
        '{"kernel": "gauss"}' '{"kernel_scale": 1.0}' '{"kernel": "huber", "kernel_scale": 1.0}'

Each positional argument is a JSON object of ``[graph]`` overrides (none: the defaults).
Prints RMSE (m) of the fixes, aekf + RTS and the graph per seed and drive.
"""

from __future__ import annotations

import argparse
import copy
import json
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gpsdr_cli import config, filters
from gpsdr_cli.align import build_epochs
from gpsdr_cli.filters.graph import smooth_graph
from gpsdr_cli.simulate import simulate_drive
from gpsdr_cli.testing.nlos import add_nlos


def _rms(x: np.ndarray) -> float:
    return float(np.sqrt(np.mean(np.square(x))))


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("overrides", nargs="*", default=["{}"])
    ap.add_argument("--seeds", default="1")
    ap.add_argument("--duration", type=float, default=300.0)
    ap.add_argument("--true-scale-sd", type=float, default=0.0,
                    help="also give the graph the true odometer scale as prior with this sigma")
    args = ap.parse_args(argv)
    print("| settings | seed | drive | fixes m | aekf + RTS m | graph m | iterations |")
    print("|---|---|---|---|---|---|---|")
    for seed in [int(s) for s in args.seeds.split(",")]:
        sim = simulate_drive("urban_canyon", seed=seed, duration_s=args.duration)
        for kind, drive in (("clean", sim.drive), ("nlos", add_nlos(sim, seed).drive)):
            p = config.defaults()
            p["filter"]["name"] = "aekf"
            p["filter"]["smooth"] = True
            ep = build_epochs(copy.deepcopy(drive), sim.frame, p)
            rts = filters.get("aekf")(ep, p)
            tr = sim.truth
            te = np.interp(ep.t_ns, tr.t_ns, tr.e)
            tn = np.interp(ep.t_ns, tr.t_ns, tr.n)
            f = ep.has_gnss
            fix = _rms(np.hypot(ep.gnss_e[f] - te[f], ep.gnss_n[f] - tn[f]))
            rts_m = _rms(np.hypot(rts.e - te, rts.n - tn))
            runs = list(args.overrides)
            if args.true_scale_sd > 0:
                true_s = 1.0 / (1.0 + sim.noise["odo_scale_error"])
                runs.append(json.dumps({"odo_scale": round(true_s, 6),
                                        "odo_scale_sd": args.true_scale_sd}))
            for text in runs:
                q = copy.deepcopy(p)
                q["graph"].update(json.loads(text))
                out = smooth_graph(ep, rts, q)
                g = _rms(np.hypot(out.result.e - te, out.result.n - tn)) if out.result else np.nan
                print(f"| `{text}` | {seed} | {kind} | {fix:.2f} | {rts_m:.2f} | {g:.2f} | "
                      f"{out.iterations} |", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
