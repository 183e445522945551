"""Every receiver log in some directories through ``gpsdr fuse``: a finite track or one clean error.

    python benchmarks/real_logs.py [PATH ...] [--configs default,ekf:none,...] [--jobs N]

Runs the real ``gpsdr`` executable, as a user would, on each log file under the given paths
(default: ``tests/data`` and ``sample_logs``; licences, READMEs and expected-output tables
are passed over) with each configuration: ``default`` (no option: aekf and the automatic
smoother) and ``FILTER:SMOOTHER`` pairs.  A log that has no date (GGA only) stops the
default run with an error asking for ``--date``; the runs are then repeated with
``--date 2020-01-01``, so that its fixes still go through the filters.

Each cell is one of:

- ``ok``: exit 0 and a track that meets the fault suite's contract
  (:func:`gpsdr_cli.testing.faults.track_problems`: the required columns, one row per epoch,
  time increasing), with no NaN or infinity in any float column (empty cells are nulls,
  which are allowed) and every sigma above zero;
- ``err``: exit 1 and one line ``gpsdr: error: ...`` (a log without fixes, without a date,
  of a format the tool does not read);
- ``BUG``: anything else: a traceback, another exit code, a timeout, a NaN, a sigma of zero
  or less.  The script exits 1 when there is one.

The last lines count the cells of each kind and list the distinct error lines.  For more
logs, point it at a directory of public receiver logs, e.g. gpsd's ``test/daemon``
regression logs (``benchmarks/gpsd_compare.py`` compares their positions with gpsd's).
"""

from __future__ import annotations

import argparse
import os
import shutil
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pyarrow as pa
import pyarrow.compute as pc
import pyarrow.parquet as pq

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gpsdr_cli.testing.faults import error_line_problems, run_cli, track_problems  # noqa: E402

CONFIGS = "default,ekf:none,aekf:rts,fkf:rts,fafkf:rts,aekf:graph,fkf:graph,fafkf:graph"
#: files that describe the data next to the logs, not logs
SKIP_NAMES = ("README", "LICENSE", "ATTRIBUTION", "MANIFEST", "COPYING")
SKIP_SUFFIXES = (".md", ".tsv", ".json", ".chk", ".source.txt", ".py", ".csv", ".parquet")
DATE_FALLBACK = "2020-01-01"


def find_logs(paths: list[Path]) -> list[Path]:
    """The log files under ``paths`` (files given by name are taken as they are).  CSV files
    are passed over inside directories: alone they are a gyro or odometer table or a
    reference, not a receiver log."""
    out = []
    for p in paths:
        if p.is_file():
            out.append(p)
            continue
        for f in sorted(p.rglob("*")):
            if (f.is_file() and not f.name.startswith(".")
                    and not any(f.name.upper().startswith(s) for s in SKIP_NAMES)
                    and not f.name.endswith(SKIP_SUFFIXES)):
                out.append(f)
    return out


def nan_columns(path: Path) -> list[str]:
    """The float columns of a track file holding NaN or infinity (nulls are allowed: an empty
    cell, e.g. ``pdop`` at an epoch without a fix)."""
    t = pq.read_table(path)
    return [name for name in t.column_names if pa.types.is_floating(t.column(name).type)
            and (pc.sum(pc.is_nan(t.column(name))).as_py() or pc.sum(pc.is_inf(t.column(name))).as_py())]


def run_one(exe: str, log: Path, config: str, date: str, out_dir: Path,
            timeout_s: float) -> tuple[str, str]:
    """(cell, detail) of one run, judged by the fault suite's contract
    (:func:`~gpsdr_cli.testing.faults.track_problems`, ``error_line_problems``) and with no
    NaN in any float column and every sigma above zero."""
    args: list[str] = [str(log)]
    name = f"{config.replace(':', '-')}.parquet"
    flt = None
    if config != "default":
        flt, smoother = config.split(":")
        args += ["--smooth", smoother]
    if date:
        args += ["--date", date]
    try:
        res = run_cli(args, out_dir, filter_name=flt, subprocess_exe=exe,
                      track_name=name, timeout_s=timeout_s)
    except subprocess.TimeoutExpired:
        return "BUG", f"timeout after {timeout_s:.0f} s"
    err = [ln for ln in res.stderr.splitlines() if ln.strip()]
    if res.escape:
        return "BUG", f"escape {res.escape}: " + " | ".join(err[-3:])
    if res.status == 0:
        problems = track_problems(res.track, n_epochs=res.epochs)
        problems += [f"{c}: NaN/inf" for c in nan_columns(out_dir / name)
                     if not any(p.startswith(f"{c}:") for p in problems)]
        problems += [f"{c}: zero" for c in ("sigma_e", "sigma_n")
                     if c in res.track and (res.track[c] == 0.0).any()]
        return ("BUG", "; ".join(problems)) if problems else ("ok", "")
    if res.status == 1 and not error_line_problems(res.stderr) and err[-1].startswith("gpsdr: error:"):
        return "err", err[-1]
    return "BUG", f"exit {res.status}: " + (" | ".join(err[-3:]) if err else "no message")


def run_log(exe: str, log: Path, configs: list[str], out_dir: Path,
            timeout_s: float) -> tuple[str, list[tuple[str, str]]]:
    """(date used, cells) of one log: the default run first; a request for --date repeats
    every run with the fallback date."""
    out_dir = Path(tempfile.mkdtemp(dir=out_dir))  # one folder per log: the runs' tracks
    date = ""
    first = run_one(exe, log, configs[0], date, out_dir, timeout_s)
    if first[0] == "err" and "--date" in first[1]:
        date = DATE_FALLBACK
        first = run_one(exe, log, configs[0], date, out_dir, timeout_s)
    cells = [first] + [run_one(exe, log, c, date, out_dir, timeout_s) for c in configs[1:]]
    return date, cells


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("paths", nargs="*", type=Path,
                    default=[REPO / "tests" / "data", REPO / "sample_logs"])
    ap.add_argument("--configs", default=CONFIGS,
                    help="comma-separated: default and FILTER:SMOOTHER (smoother rts|graph|none)")
    ap.add_argument("--jobs", type=int, default=os.cpu_count() or 1, help="logs run at once")
    ap.add_argument("--timeout", type=float, default=600.0, help="per run, s")
    args = ap.parse_args(argv)
    exe = shutil.which("gpsdr")
    if exe is None:
        print("gpsdr is not on PATH: install the project first (README)", file=sys.stderr)
        return 2
    logs = find_logs(args.paths)
    configs = args.configs.split(",")
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp, ThreadPoolExecutor(args.jobs) as pool:
        results = list(pool.map(lambda lg: run_log(exe, lg, configs, Path(tmp), args.timeout),
                                logs))
    print("| log | " + " | ".join(configs) + " |")
    print("|---|" + "---|" * len(configs))
    counts = {"ok": 0, "err": 0, "BUG": 0}
    errors: dict[str, int] = {}
    bugs = []
    for log, (date, cells) in zip(logs, results, strict=True):
        try:
            name = str(log.relative_to(REPO))
        except ValueError:
            name = str(log)
        if date:
            name += f" (--date {date})"
        print(f"| {name} | " + " | ".join(c for c, _ in cells) + " |")
        for config, (cell, detail) in zip(configs, cells, strict=True):
            counts[cell] += 1
            if cell == "err":
                msg = detail.replace(str(log), "LOG")
                errors[msg] = errors.get(msg, 0) + 1
            elif cell == "BUG":
                bugs.append(f"{name} {config}: {detail}")
    print(f"\n{len(logs)} logs x {len(configs)} configurations: {counts['ok']} tracks, "
          f"{counts['err']} clean errors, {counts['BUG']} bugs; "
          f"{time.perf_counter() - t0:.0f} s")
    for msg, n in sorted(errors.items(), key=lambda kv: -kv[1]):
        print(f"  {n:4d} x {msg[:160]}")
    for b in bugs:
        print("  BUG " + b[:300])
    return 1 if bugs else 0


if __name__ == "__main__":
    raise SystemExit(main())
