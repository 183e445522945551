"""Fuzz gpsdr's readers and ``fuse`` end to end with mutated files; print the outcome counts.

    .venv/bin/python benchmarks/fuzz.py --cases 100000 [--jobs 2] [--seed 0] [--save DIR]
                                        [--max-seconds S]
    .venv/bin/python benchmarks/fuzz.py --one INDEX [--seed 0] [--save DIR]   # replay one case

Seeds: a 12 s simulated urban drive written as gps.nmea, gyro.csv, odo.csv and
drive.mcap, plus the MCAP rewritten uncompressed in small chunks
(:func:`gpsdr_cli.testing.faults.fuzz_seed_files`).  Case ``i`` draws from a
generator seeded with ``seed * 1_000_000_007 + i``: a target, a filter, and 1-8
mutations of one to three of those files (bit flips, random bytes, inserted
tokens such as ``nan``/``1e308``/``$GPGGA``, deletions, duplicated ranges,
swapped lines, rare truncation; NMEA checksums recomputed half of the time so
mutated fields reach the field parsers).  Targets:

- ``nmea``: ``parse_nmea``; ``gyro_csv``/``odo_csv``: the CSV readers;
  ``mcap``: ``read_mcap``;
- ``e2e_files``/``e2e_mcap``: ``read_drive`` + ``pipeline.fuse`` with a filter
  drawn from ``gpsdr_cli.filters.NAMES``, then the track checked (one row per
  epoch, finite required columns).

Contract: only GpsdrError subclasses escape, no successful run yields a NaN in
a required column, and nothing crashes the process.  Anything else is a bug:
its first input is saved under ``--save``; a case that kills its worker (a
segfault in a compiled library) is replayed alone with ``--one`` to confirm it
and counted as ``crash:SIG<NAME>``.  Why not atheris: it needs a clang-built
CPython extension and guides by C coverage; the readers' hot paths are numpy
and pyarrow, so structured random mutation finds the same classes of bugs.
"""

from __future__ import annotations

import argparse
import collections
import hashlib
import multiprocessing as mp
import os
import signal
import subprocess
import sys
import tempfile
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from pathlib import Path

import numpy as np

from gpsdr_cli.filters import NAMES
from gpsdr_cli.testing import faults as F

#: Cases per worker task (progress is reported per finished task).
CHUNK = 500
#: Share of cases per target (the e2e targets are ~20x slower than a reader).
WEIGHTS = {"nmea": 0.3, "gyro_csv": 0.15, "odo_csv": 0.15, "mcap": 0.2, "e2e_files": 0.12,
           "e2e_mcap": 0.08}


def draw(seed: int, index: int) -> tuple[np.random.Generator, str, str | None, int]:
    """Case ``index``'s generator, target and filter (deterministic)."""
    case_seed = seed * 1_000_000_007 + index
    rng = np.random.default_rng(case_seed)
    targets = list(WEIGHTS)
    p = np.array([WEIGHTS[t] for t in targets])
    target = targets[int(rng.choice(len(targets), p=p / p.sum()))]
    filt = NAMES[int(rng.integers(len(NAMES)))] if target.startswith("e2e") else None
    return rng, target, filt, case_seed


def _save(save_dir: str, full: str, files: dict[str, bytes], filt: str | None, index: int) -> str:
    h = hashlib.sha1(full.encode()).hexdigest()[:10]
    d = Path(save_dir) / f"{full.split(':', 1)[0]}-{h}"
    d.mkdir(parents=True, exist_ok=True)
    for name, data in files.items():
        (d / name).write_bytes(data)
    (d / "outcome.txt").write_text(f"{full}\nfilter={filt}\nindex={index}\n")
    return str(d)


def _worker(args: tuple[int, int, int, int, str, str | None, str, float, frozenset[int]]
            ) -> tuple[int, collections.Counter, dict]:
    """Run cases ``start .. start+n-1`` (minus ``skip``); counts and one example per bug key.

    Before each case its index goes into the task's breadcrumb file, so the
    parent can tell which case was running when a worker died.
    """
    task_id, start, n, seed, seed_dir, save_dir, crumb_dir, deadline, skip = args
    seeds = {name: (Path(seed_dir) / name).read_bytes() for name in F.FUZZ_FILES}
    counts: collections.Counter = collections.Counter()
    examples: dict[str, str] = {}
    base = Path(tempfile.mkdtemp(prefix=f"gpsdr-fuzz-{task_id}-",
                                 dir="/dev/shm" if os.path.isdir("/dev/shm") else None))
    crumb = Path(crumb_dir) / f"task-{task_id}"
    for index in range(start, start + n):
        if index in skip:
            continue
        if time.time() > deadline:
            break
        crumb.write_text(str(index))
        rng, target, filt, _ = draw(seed, index)
        key, files = F.fuzz_case(target, seeds, rng, base, filter_name=filt)
        full = f"{target}:{key}"
        counts[full] += 1
        if F.is_bug(key) and full not in examples:
            examples[full] = (_save(save_dir, full, files, filt, index) if save_dir
                              else f"--one {index} --seed {seed}")
    crumb.unlink(missing_ok=True)
    for p in base.iterdir():
        p.unlink()
    base.rmdir()
    return task_id, counts, examples


def replay(index: int, seed: int, save_dir: str | None) -> str:
    """Run case ``index`` alone in this process (its files kept under ``save_dir``)."""
    seed_dir = Path(tempfile.mkdtemp(prefix="gpsdr-fuzz-seed-"))
    seeds = F.fuzz_seed_files(seed_dir)
    work = Path(save_dir or tempfile.mkdtemp(prefix="gpsdr-fuzz-one-")) / f"case-{index}"
    work.mkdir(parents=True, exist_ok=True)
    rng, target, filt, _ = draw(seed, index)
    (work / "outcome.txt").write_text(f"{target}: running\nfilter={filt}\nindex={index}\n")
    key, _ = F.fuzz_case(target, seeds, rng, work, filter_name=filt)
    (work / "outcome.txt").write_text(f"{target}:{key}\nfilter={filt}\nindex={index}\n")
    return f"{target}:{key} filter={filt} files={work}"


def _confirm_crash(index: int, seed: int, save_dir: str | None) -> tuple[bool, str]:
    """Replay a suspect case in a fresh process: (crashed?, outcome key)."""
    cmd = [sys.executable, __file__, "--one", str(index), "--seed", str(seed)]
    if save_dir:
        cmd += ["--save", str(Path(save_dir) / "crashes")]
    proc = subprocess.run(cmd, capture_output=True, text=True, timeout=600, check=False)
    if proc.returncode < 0:
        _, target, _, _ = draw(seed, index)
        return True, f"{target}:crash:{signal.Signals(-proc.returncode).name}"
    return False, ""


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--cases", type=int, default=10_000, help="number of cases (default 10000)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="worker processes")
    ap.add_argument("--seed", type=int, default=0, help="seed of the case generator")
    ap.add_argument("--save", default="fuzz_escapes", help="where to save escaping inputs")
    ap.add_argument("--max-seconds", type=float, default=float("inf"),
                    help="stop starting cases after this long (the report says how many ran)")
    ap.add_argument("--one", type=int, default=None, metavar="INDEX", help="replay one case")
    a = ap.parse_args(argv)
    if a.one is not None:
        print(replay(a.one, a.seed, a.save))
        return 0

    # SIGTERM -> SystemExit, so the executor's context manager stops the workers too
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    seed_dir = Path(tempfile.mkdtemp(prefix="gpsdr-fuzz-seed-"))
    crumb_dir = Path(tempfile.mkdtemp(prefix="gpsdr-fuzz-crumbs-"))
    F.fuzz_seed_files(seed_dir)
    jobs = max(1, min(a.jobs, a.cases))
    t0 = time.perf_counter()
    deadline = time.time() + a.max_seconds
    tasks: dict[int, tuple] = {}
    for task_id, start in enumerate(range(0, a.cases, CHUNK)):
        tasks[task_id] = (task_id, start, min(CHUNK, a.cases - start), a.seed, str(seed_dir),
                          a.save, str(crumb_dir), deadline, frozenset())
    counts: collections.Counter = collections.Counter()
    examples: dict[str, str] = {}
    done = 0
    while tasks:
        try:
            with ProcessPoolExecutor(jobs, mp_context=mp.get_context("spawn")) as ex:
                futs = {ex.submit(_worker, t): tid for tid, t in tasks.items()}
                while futs:
                    finished, _ = wait(futs, return_when=FIRST_COMPLETED)
                    for fut in finished:
                        tid, c, ex_ = fut.result()
                        del futs[fut]
                        del tasks[tid]
                        counts.update(c)
                        for k, v in ex_.items():
                            examples.setdefault(k, v)
                        done += sum(c.values())
                        print(f"\r{done}/{a.cases} cases, {time.perf_counter() - t0:.0f} s",
                              end="", file=sys.stderr, flush=True)
        except BrokenProcessPool:
            # a worker died: replay the case each unfinished task was on, alone
            for tid in list(tasks):
                crumb = crumb_dir / f"task-{tid}"
                if not crumb.exists():
                    continue
                text = crumb.read_text().strip()
                crumb.unlink()
                if not text:  # the worker died while writing it: nothing to replay
                    continue
                index = int(text)
                crashed, key = _confirm_crash(index, a.seed, a.save)
                if crashed:
                    counts[key] += 1
                    examples.setdefault(key, f"--one {index} --seed {a.seed}")
                    t = tasks[tid]
                    tasks[tid] = (*t[:-1], t[-1] | {index})
            print(f"\nworker died; crashes so far: "
                  f"{sum(c for k, c in counts.items() if ':crash:' in k)}", file=sys.stderr)
    print(file=sys.stderr)
    elapsed = time.perf_counter() - t0

    per_target: collections.Counter = collections.Counter()
    for key, c in counts.items():
        per_target[key.split(":", 1)[0]] += c
    bugs = {k: c for k, c in counts.items()
            if F.is_bug(k.split(":", 1)[1]) or ":crash:" in k}
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
    for d in (seed_dir, crumb_dir):
        for p in d.iterdir():
            p.unlink()
        d.rmdir()
    return 1 if bugs else 0


if __name__ == "__main__":
    sys.exit(main())
