"""Track digest: one SHA-256 per output array of every filter, to prove a refactor
changes nothing.

    python benchmarks/track_digest.py                         # print the digests
    python benchmarks/track_digest.py --save /tmp/base.npz    # ... and keep the arrays
    python benchmarks/track_digest.py --compare /tmp/base.npz # max |diff| against them
    python benchmarks/track_digest.py --quick                 # seed 1 only, 3 scenarios

Runs ekf, aekf, fkf and fafkf, forward and with RTS smoothing, on simulated drives
(seeds 1 and 2 of urban_canyon, urban_nlos, rtk, no_odometer, tunnels and
stop_and_go, 180-s drives except tunnels at full length) and on the seeds' plain
configurations and a positions-only drive (the branches the defaults do not take).
Every array of the ``FilterResult`` (``e, n, v_e, ..., nis``, every ``extras``
entry) is hashed from its raw bytes, so "identical" means bit for bit.  With
``--compare``, each array's max absolute difference against the saved one is
printed next to its digest and the exit status is 1 when any exceeds ``--tol``
(default 0: bit-identical) or an array is missing.
"""

from __future__ import annotations

import argparse
import copy
import hashlib
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gpsdr_cli.simulate import simulate_drive  # noqa: E402
from gpsdr_cli.testing.sim import run_filter  # noqa: E402

FILTERS = ("ekf", "aekf", "fkf", "fafkf")
SCENARIOS = ("urban_canyon", "urban_nlos", "rtk", "no_odometer", "tunnels", "stop_and_go")
#: the drive length (s); None: the scenario's own (tunnels needs its full length for a tunnel)
DURATION_S = {"tunnels": None}
SHORT_S = 180.0
AEKF_PLAIN = {"aekf": {"gnss_err_states": False, "gnss_velocity": False}}
FKF_PLAIN = {"fkf": {"gnss_velocity": False, "gnss_err_pdop": float("inf"),
                     "gnss_err_dist_m": 0.0, "gnss_err_sd_m": 1.0, "gnss_err_tau_s": 60.0},
             "fafkf": {"remove_residual_mean": False}}
#: (label, filter, overrides) run besides the defaults on urban_canyon
VARIANTS = (("ekf_plain", "ekf", AEKF_PLAIN), ("aekf_plain", "aekf", AEKF_PLAIN),
            ("fkf_plain", "fkf", FKF_PLAIN), ("fafkf_plain", "fafkf", FKF_PLAIN))


def result_arrays(res) -> dict[str, np.ndarray]:
    """Every per-epoch array of a FilterResult, by name."""
    out = {}
    for name in ("t_ns", "e", "n", "v_e", "v_n", "var_e", "var_n", "cov_en", "gnss_used",
                 "gnss_rejected", "nis", "static"):
        out[name] = np.asarray(getattr(res, name))
    for name, arr in sorted(res.extras.items()):
        a = np.asarray(arr)
        if a.dtype != object:
            out["x_" + name] = a
    return out


def runs(quick: bool):
    """Yield (key prefix, sim, drive, filter, overrides, smooth)."""
    seeds = (1,) if quick else (1, 2)
    scenarios = ("urban_canyon", "rtk", "no_odometer") if quick else SCENARIOS
    for scenario in scenarios:
        for seed in seeds:
            sim = simulate_drive(scenario, seed=seed,
                                 duration_s=DURATION_S.get(scenario, SHORT_S))
            drives = [("", sim.drive)]
            if scenario == "urban_canyon" and seed == 1:
                pos = copy.deepcopy(sim.drive)
                pos.gnss.speed_mps[:] = np.nan
                pos.gnss.course_deg[:] = np.nan
                drives.append(("posonly_", pos))
            for tag, drive in drives:
                for name in FILTERS:
                    for smooth in (False, True):
                        yield (f"{scenario}_s{seed}_{tag}{name}_{'rts' if smooth else 'fwd'}",
                               sim, drive, name, None, smooth)
            if scenario == "urban_canyon" and seed == 1:
                for label, name, ov in VARIANTS:
                    for smooth in (False, True):
                        yield (f"{scenario}_s{seed}_{label}_{'rts' if smooth else 'fwd'}",
                               sim, sim.drive, name, ov, smooth)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--save", type=Path, help="write every array to this .npz")
    ap.add_argument("--compare", type=Path, help="max |diff| against this saved .npz")
    ap.add_argument("--tol", type=float, default=0.0, help="allowed max |diff| (default 0)")
    ap.add_argument("--quick", action="store_true", help="seed 1 of three scenarios only")
    args = ap.parse_args()
    ref = dict(np.load(args.compare)) if args.compare else None
    arrays: dict[str, np.ndarray] = {}
    worst = 0.0
    bad = 0
    for prefix, sim, drive, name, ov, smooth in runs(args.quick):
        r = run_filter(sim, drive, name, smooth=smooth, overrides=ov).result
        for key, a in result_arrays(r).items():
            full = f"{prefix}.{key}"
            arrays[full] = a
            h = hashlib.sha256(np.ascontiguousarray(a).tobytes()).hexdigest()[:16]
            line = f"{full:60s} {h}"
            if ref is not None:
                if full not in ref or ref[full].shape != a.shape:
                    line += "  MISSING/SHAPE"
                    bad += 1
                else:
                    b = ref[full]
                    if a.dtype.kind in "fc":
                        same_nan = np.array_equal(np.isnan(a), np.isnan(b))
                        d = float(np.nanmax(np.abs(a - b))) if a.size and not np.all(np.isnan(a)) else 0.0
                        d = d if same_nan else float("inf")
                    else:
                        d = float(np.max(np.abs(a.astype(np.float64) - b.astype(np.float64)))) \
                            if a.size else 0.0
                    identical = np.ascontiguousarray(a).tobytes() == np.ascontiguousarray(b).tobytes()
                    worst = max(worst, d)
                    line += "  identical" if identical else f"  max|diff| {d:.3g}"
                    if d > args.tol or (args.tol == 0.0 and not identical):
                        bad += 1
            print(line)
    if ref is not None:
        missing = sorted(set(ref) - set(arrays))
        for k in missing:
            print(f"{k:60s} not produced")
        bad += len(missing)
        print(f"\n{len(arrays)} arrays, worst max|diff| {worst:.3g}, "
              f"{bad} over tolerance {args.tol:g}")
    if args.save:
        np.savez_compressed(args.save, **arrays)
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main())
