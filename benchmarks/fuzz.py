"""Fuzz gpsdr's readers and ``fuse`` end to end with mutated files; print the outcome counts.

    .venv/bin/python benchmarks/fuzz.py --cases 100000 [--jobs 2] [--seed 0] [--save DIR]

Seeds: a 12 s simulated urban drive written as gps.nmea, gyro.csv, odo.csv and
drive.mcap (:func:`gpsdr_cli.testing.faults.fuzz_seed_files`).  Each case
mutates one to three of those files (bit flips, random bytes, inserted tokens
such as ``nan``/``1e308``/``$GPGGA``, deletions, duplicated ranges, swapped
lines, rare truncation; NMEA checksums recomputed half of the time so mutated
fields reach the field parsers) and runs one target:

- ``nmea``: ``parse_nmea``; ``gyro_csv``/``odo_csv``: the CSV readers;
  ``mcap``: ``read_mcap``;
- ``e2e_files``/``e2e_mcap``: ``read_drive`` + ``pipeline.fuse`` with a filter
  drawn from ``gpsdr_cli.filters.NAMES``, then the track checked (one row per
  epoch, finite required columns).

Contract: only GpsdrError subclasses escape, and no successful run yields a
NaN in a required column.  Anything else is counted as an escape; the first
input of each distinct escape is saved under ``--save`` for reproduction.
Why not atheris: it needs a clang-built CPython extension and gives coverage
guidance mostly for C code; the readers' hot paths are numpy, so random
structured mutation finds the same classes of bugs here.
"""

from __future__ import annotations

import argparse
import collections
import hashlib
import multiprocessing as mp
import os
import signal
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

from gpsdr_cli.filters import NAMES
from gpsdr_cli.testing import faults as F

#: Cases per worker task (progress is reported per finished task).
CHUNK = 1000
#: Share of cases per target (the e2e targets are ~20x slower than a reader).
WEIGHTS = {"nmea": 0.3, "gyro_csv": 0.15, "odo_csv": 0.15, "mcap": 0.2, "e2e_files": 0.12,
           "e2e_mcap": 0.08}


def _worker(args: tuple[int, int, int, str, str | None]) -> tuple[collections.Counter, dict]:
    """Run ``n`` cases from ``seed``; return outcome counts and one example per bug key."""
    worker_id, n, seed, seed_dir, save_dir = args
    seeds = {name: (Path(seed_dir) / name).read_bytes() for name in F.FUZZ_FILES}
    targets = list(WEIGHTS)
    p = np.array([WEIGHTS[t] for t in targets])
    p /= p.sum()
    counts: collections.Counter = collections.Counter()
    examples: dict[str, str] = {}
    base = Path(tempfile.mkdtemp(prefix=f"gpsdr-fuzz-{worker_id}-",
                                 dir="/dev/shm" if os.path.isdir("/dev/shm") else None))
    for i in range(n):
        case_seed = seed * 1_000_000_007 + worker_id * 100_003 + i
        rng = np.random.default_rng(case_seed)
        target = targets[int(rng.choice(len(targets), p=p))]
        filt = NAMES[int(rng.integers(len(NAMES)))] if target.startswith("e2e") else None
        key, files = F.fuzz_case(target, seeds, rng, base, filter_name=filt)
        full = f"{target}:{key}"
        counts[full] += 1
        if F.is_bug(key) and full not in examples:
            where = ""
            if save_dir:
                h = hashlib.sha1(full.encode()).hexdigest()[:10]
                d = Path(save_dir) / f"{target}-{h}"
                d.mkdir(parents=True, exist_ok=True)
                for name, data in files.items():
                    (d / name).write_bytes(data)
                (d / "outcome.txt").write_text(f"{full}\nfilter={filt}\ncase_seed={case_seed}\n")
                where = str(d)
            examples[full] = where or f"case_seed={case_seed} filter={filt}"
    for name in F.FUZZ_FILES:
        (base / name).unlink(missing_ok=True)
    base.rmdir()
    return counts, examples


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=10_000, help="number of cases (default 10000)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes")
    ap.add_argument("--seed", type=int, default=0, help="seed of the case generator")
    ap.add_argument("--save", default="fuzz_escapes", help="where to save escaping inputs")
    a = ap.parse_args(argv)

    # SIGTERM -> SystemExit, so the pool's context manager terminates the workers too
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    seed_dir = Path(tempfile.mkdtemp(prefix="gpsdr-fuzz-seed-"))
    F.fuzz_seed_files(seed_dir)
    jobs = max(1, min(a.jobs, a.cases))
    n_tasks = max(jobs, -(-a.cases // CHUNK))
    sizes = [a.cases // n_tasks + (1 if k < a.cases % n_tasks else 0) for k in range(n_tasks)]
    tasks = [(k, sizes[k], a.seed, str(seed_dir), a.save) for k in range(n_tasks)]
    t0 = time.perf_counter()
    results = []
    done = 0
    with mp.get_context("spawn").Pool(jobs) as pool:
        for res in pool.imap_unordered(_worker, tasks):
            results.append(res)
            done += sum(res[0].values())
            print(f"\r{done}/{a.cases} cases, {time.perf_counter() - t0:.0f} s", end="",
                  file=sys.stderr, flush=True)
    print(file=sys.stderr)
    elapsed = time.perf_counter() - t0
    counts: collections.Counter = collections.Counter()
    examples: dict[str, str] = {}
    for c, ex in results:
        counts.update(c)
        for k, v in ex.items():
            examples.setdefault(k, v)

    per_target: collections.Counter = collections.Counter()
    for key, c in counts.items():
        per_target[key.split(":", 1)[0]] += c
    bugs = {k: c for k, c in counts.items() if F.is_bug(k.split(":", 1)[1])}
    print(f"cases {sum(counts.values())} in {elapsed:.0f} s ({jobs} jobs), "
          f"distinct outcomes {len(counts)}, escapes {sum(bugs.values())} "
          f"({len(bugs)} distinct)")
    print("cases per target: " + ", ".join(f"{t} {per_target[t]}" for t in WEIGHTS))
    print(f"{'count':>7}  outcome")
    for key, c in sorted(counts.items(), key=lambda kv: (-kv[1], kv[0])):
        mark = "  <-- BUG" if key in bugs else ""
        print(f"{c:>7}  {key}{mark}")
    for key, where in sorted(examples.items()):
        print(f"example {key}: {where}")
    for name in F.FUZZ_FILES:
        (seed_dir / name).unlink(missing_ok=True)
    return 1 if bugs else 0


if __name__ == "__main__":
    sys.exit(main())
