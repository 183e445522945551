"""Parquet write options for a one-hour track: time, file size and memory, one table.

    python benchmarks/write_parquet.py [--seconds 3600]

Fuses the simulated one-hour drive (aekf, forward) once, then writes the track
with each codec, with and without pyarrow's default dictionary encoding, and
without it but with the float columns BYTE_STREAM_SPLIT-encoded ("split")
(best of 3 wall-clock seconds; the growth of this process's RSS across the
writes is printed too).  gpsdr_cli/io/parquet.py picked its options from this table.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

import pyarrow as pa
import pyarrow.parquet as pq

from gpsdr_cli.config import defaults
from gpsdr_cli.io.parquet import to_arrow
from gpsdr_cli.pipeline import TRACK_UNITS, fuse


def rss_mb() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024.0
    return float("nan")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=3600.0, help="drive length (s)")
    args = ap.parse_args()
    from gpsdr_cli.simulate import simulate_drive

    sim = simulate_drive("one_hour", seed=0, duration_s=args.seconds)
    track = fuse(sim.drive, defaults()).track
    table = to_arrow(track, units=TRACK_UNITS)
    print(f"track: {len(track)} rows x {track.shape[1]} columns")
    floats = [f.name for f in table.schema if pa.types.is_floating(f.type)]
    print(f"{'codec':8s} {'encoding':>10s} {'write s':>8s} {'size MB':>8s} {'RSS +MB':>8s}")
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "track.parquet"
        for codec in ("snappy", "zstd", "lz4"):
            for encoding in ("dictionary", "plain", "split"):
                r0 = rss_mb()
                best = float("inf")
                for _ in range(3):
                    w0 = time.perf_counter()
                    pq.write_table(table, out, compression=codec,
                                   use_dictionary=encoding == "dictionary",
                                   use_byte_stream_split=floats if encoding == "split" else False)
                    best = min(best, time.perf_counter() - w0)
                print(f"{codec:8s} {encoding:>10s} {best:8.3f} "
                      f"{out.stat().st_size / 1e6:8.1f} {rss_mb() - r0:8.1f}")


if __name__ == "__main__":
    main()
