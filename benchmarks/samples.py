"""Accuracy of every filter on the bundled sample logs: one command, one table.

    python benchmarks/samples.py

Runs each registered filter, forward and with the RTS smoother, through the same
pipeline as ``gpsdr fuse`` on ``sample_logs/urban_drive.mcap`` (simulated urban
canyon, against its truth) and ``sample_logs/comma2k19`` (real highway drive,
against comma's post-processed pose; GNSS latency estimated with
``--gnss-offset auto``), and prints RMSE, CEP95 and max horizontal error in
metres next to the GNSS fixes alone.  The README's per-sample table is this
output.
"""

from __future__ import annotations

import sys
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gpsdr_cli import config, filters
from gpsdr_cli.io.readers import read_drive
from gpsdr_cli.io.reference import read_reference
from gpsdr_cli.pipeline import fuse

SAMPLES = REPO / "sample_logs"


def _drives() -> list[tuple[str, dict, Path, bool]]:
    c = SAMPLES / "comma2k19"
    return [
        ("urban_drive.mcap (simulated urban canyon, 5 min)",
         {"log": SAMPLES / "urban_drive.mcap"}, SAMPLES / "urban_drive.truth.csv", False),
        ("comma2k19 (real highway, 60 s; GNSS offset auto)",
         {"gps": c / "gps.nmea", "gyro": c / "gyro.csv", "odo": c / "odo.csv"},
         c / "truth.csv", True),
    ]


def main() -> int:
    rows = []
    for label, files, truth, auto_offset in _drives():
        reference = read_reference(truth)
        for name in filters.NAMES:
            for smooth in (False, True):
                params = config.defaults()
                params["filter"]["name"] = name
                params["filter"]["smooth"] = smooth
                params["filter"]["smoother"] = "rts" if smooth else "none"
                drive = read_drive(params=params, **files)
                t0 = time.perf_counter()
                result = fuse(drive, params, reference, auto_gnss_offset=auto_offset)
                dt = time.perf_counter() - t0
                fused = result.summary()
                gnss = result.gnss_only_summary()
                rows.append((label, name + (" + RTS" if smooth else ""), fused, gnss, dt,
                             result.gnss_offset_s))
    print("| drive | filter | RMSE m | CEP95 m | max m | GNSS-only RMSE m | GNSS offset s | s |")
    print("|---|---|---|---|---|---|---|---|")
    for label, name, fused, gnss, dt, offset in rows:
        print(f"| {label} | {name} | {fused['rmse_m']:.2f} | {fused['cep95_m']:.2f} | "
              f"{fused['max_m']:.2f} | {gnss['rmse_m']:.2f} | {offset:+.3f} | {dt:.1f} |")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
