"""Batch throughput on this machine: ``gpsdr batch`` with 1 and N workers, one table.

    python benchmarks/batch.py [--drives 12] [--jobs 2] [--seconds 3600] [--keep DIR]

Simulates one drive (``one_hour`` scenario, NMEA + CSV + truth), links it into
``--drives`` folders, then times, each on an idle machine:

- ``gpsdr batch DIR -o OUT --jobs 1 --force`` and ``--jobs N``: wall time,
  drives per minute and the speed-up;
- the machine's own ceiling for N processes: N independent ``gpsdr fuse``
  runs of the same drive started together, against N run one after the other;
- a pure-CPU Python loop run the same two ways, which no memory traffic limits.

The last two rows tell whether a speed-up short of N is the pool's fault or
the hardware's (shared memory bandwidth, vCPUs that are hyperthreads).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

LOOP = "s = 0\nfor i in range(12_000_000):\n    s += i * i % 7\n"


def gpsdr_exe() -> str:
    exe = shutil.which("gpsdr") or str(ROOT / ".venv" / "bin" / "gpsdr")
    if not Path(exe).exists():
        sys.exit("gpsdr is not installed: pip install -e . first")
    return exe


def make_fleet(root: Path, drives: int, seconds: float) -> Path:
    from gpsdr_cli.simulate import simulate_drive, write_drive

    one = root / "drive"
    sim = simulate_drive("one_hour", seed=1, duration_s=seconds)
    write_drive(sim, one, mcap=False)
    fleet = root / "fleet"
    for i in range(drives):
        d = fleet / f"d{i + 1:02d}"
        d.mkdir(parents=True)
        for name in ("gps.nmea", "gyro.csv", "odo.csv", "truth.csv"):
            (d / name).symlink_to(one / name)
    return fleet


def timed(cmds: list[list[str]], parallel: bool) -> float:
    """Wall seconds to run ``cmds`` one after the other, or all started together."""
    w0 = time.perf_counter()
    if parallel:
        procs = [subprocess.Popen(c, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE) for c in cmds]
        for p in procs:
            _, err = p.communicate()
            if p.returncode:
                sys.exit(f"{' '.join(procs[0].args)} failed: {err.decode()[-400:]}")
    else:
        for c in cmds:
            res = subprocess.run(c, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, check=False)
            if res.returncode:
                sys.exit(f"{' '.join(c)} failed: {res.stderr.decode()[-400:]}")
    return time.perf_counter() - w0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--drives", type=int, default=12)
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 2)
    ap.add_argument("--seconds", type=float, default=3600.0, help="length of each drive (s)")
    ap.add_argument("--keep", help="use (or create) the fleet in this folder instead of a temp one")
    args = ap.parse_args()
    exe = gpsdr_exe()
    n = args.jobs
    with tempfile.TemporaryDirectory() as tmp:
        root = Path(args.keep) if args.keep else Path(tmp)
        fleet = root / "fleet"
        if not fleet.is_dir():
            print(f"simulating {args.seconds:.0f} s drive, {args.drives} copies ...", flush=True)
            make_fleet(root, args.drives, args.seconds)
        out = Path(tmp) / "out"
        batch = [exe, "batch", str(fleet), "-o", str(out), "--force", "-q"]
        timed([batch + ["--jobs", "1"]], False)  # warm the numba cache and the page cache
        t1 = timed([batch + ["--jobs", "1"]], False)
        tn = timed([batch + ["--jobs", str(n)]], False)
        drive = fleet / "d01"
        fuse = [exe, "fuse", "--gps", str(drive / "gps.nmea"), "--gyro", str(drive / "gyro.csv"),
                "--odo", str(drive / "odo.csv"), "-q"]
        fuses = [fuse + ["-o", str(Path(tmp) / f"f{i}.parquet")] for i in range(n)]
        f1 = timed(fuses, False)
        fn = timed(fuses, True)
        loops = [[sys.executable, "-c", LOOP]] * n
        l1 = timed(loops, False)
        ln = timed(loops, True)
    rate = 60.0 * args.drives
    print(f"\n{args.drives} drives of {args.seconds:.0f} s, {n} workers, {os.cpu_count()} CPUs\n")
    print(f"| run | 1 at a time, s | {n} at once, s | speed-up |")
    print("|---|---|---|---|")
    print(f"| gpsdr batch --jobs 1 vs --jobs {n} ({rate / t1:.1f} vs {rate / tn:.1f} drives/min) "
          f"| {t1:.2f} | {tn:.2f} | {t1 / tn:.2f}x |")
    print(f"| {n} x gpsdr fuse, independent processes | {f1:.2f} | {fn:.2f} | {f1 / fn:.2f}x |")
    print(f"| {n} x pure-CPU Python loop (machine ceiling) | {l1:.2f} | {ln:.2f} | {l1 / ln:.2f}x |")


if __name__ == "__main__":
    main()
