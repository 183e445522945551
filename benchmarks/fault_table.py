"""Fault x outcome table: every fault of the catalogue through ``gpsdr fuse``, for every filter.

    .venv/bin/python benchmarks/fault_table.py [--filters ekf,aekf,...] [--cases a,b,...]
                                               [--subprocess] [--markdown]
                                               [--smooth rts|graph|none]

For each fault (:data:`gpsdr_cli.testing.faults.CATALOGUE`: outages 10 s to
10 min, a 30 min standstill, clock steps, duplicates, NaN and empty fields,
100 m jumps, gyro saturation, odometer dropouts, no GNSS, no DR, midnight and
date changes, truncated/corrupt MCAP, binary garbage in NMEA) and filter, one
cell: ``ok`` (complete finite track, one row per epoch) with the fault's figure,
``err1``/``err2`` (a clean one-line error), ``BUG`` (an escape, a NaN, a
missing row, a traceback, an error where a track was due) or ``BAD`` (a track
that breaks the accuracy bounds of ``faults.accuracy_problems``).  Figures: RMSE
against the truth (m) for most faults; for outages the largest error inside
the outage (m), the growth of the horizontal sigma across it and the end error
in sigmas (consistency); for the jump
the largest error while the fixes are 100 m off and the fixes rejected; for
standstills the drift over the stop (m).  File faults run through click's
CliRunner (``--subprocess``: the real ``gpsdr`` executable); the long faults
(10 min outage, 30 min standstill) run ``pipeline.fuse`` in memory.  ``--smooth graph``
runs every case through the robust batch smoother (a smoothed sigma peaks inside an outage,
so the outage rows' sigma-growth bound does not apply to it).
"""

from __future__ import annotations

import argparse
import math
import shutil
import sys
import tempfile
import time
from pathlib import Path

from gpsdr_cli.filters import NAMES
from gpsdr_cli.testing import faults as F


def _fmt(x: float, spec: str = ".1f") -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def cell(case: F.FaultCase, inputs: F.CaseInputs, out: F.Outcome) -> tuple[str, list[str]]:
    """The table cell for one run, and the contract problems found."""
    problems = F.outcome_problems(out, case.expect)
    if out.status != 0:
        text = f"err{out.status}"
    else:
        m = F.case_metrics(inputs, out)
        if case.name.startswith("standstill"):
            text = f"drift {_fmt(m['drift_m'], '.2f')}"
        elif case.name.startswith("outage"):
            text = (f"max {_fmt(m['focus_max_m'])} sx{_fmt(m['sigma_growth'])} "
                    f"e/s {_fmt(m['end_error_sigmas'])}")
        elif case.name.startswith("jump"):
            text = f"max {_fmt(m['focus_max_m'])} rej {_fmt(m['rejected'], '.0f')}"
        else:
            text = f"rmse {_fmt(m['rmse_m'])}"
    accuracy = F.accuracy_problems(case, inputs, out)
    if problems:
        text = "BUG " + text
    elif accuracy:
        text = "BAD " + text
    return text, problems + [f"accuracy: {a}" for a in accuracy]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--filters", default=",".join(NAMES), help="comma-separated filter names")
    ap.add_argument("--cases", default="", help="comma-separated fault names (default: all)")
    ap.add_argument("--subprocess", action="store_true", help="run the real gpsdr executable")
    ap.add_argument("--markdown", action="store_true", help="print a Markdown table")
    ap.add_argument("--keep", default="", help="keep the inputs of each run under this directory")
    ap.add_argument("--smooth", default="", choices=("", "none", "rts", "graph"),
                    help="the stage after the filter (default: gpsdr fuse's)")
    a = ap.parse_args(argv)

    filters = [f for f in a.filters.split(",") if f]
    cases = [F.CASES[c] for c in a.cases.split(",") if c] or list(F.CATALOGUE)
    exe = None
    if a.subprocess:
        exe = shutil.which("gpsdr") or str(Path(sys.executable).with_name("gpsdr"))
    root = Path(a.keep) if a.keep else Path(tempfile.mkdtemp(prefix="gpsdr-faults-"))
    sim = F.base_sim()
    t0 = time.perf_counter()
    rows: list[list[str]] = []
    bugs: list[str] = []
    for case in cases:
        row = [case.name, case.expect]
        for f in filters:
            d = root / case.name / f
            inputs, out = F.run_case(case, f, d, sim, subprocess_exe=exe, smoother=a.smooth)
            text, problems = cell(case, inputs, out)
            row.append(text)
            for p in problems:
                bugs.append(f"{case.name} / {f}: {p}")
        rows.append(row)
        print(f"  {case.name}: " + " | ".join(row[2:]), file=sys.stderr, flush=True)
    elapsed = time.perf_counter() - t0

    head = ["fault", "expect", *filters]
    widths = [max(len(r[i]) for r in [head, *rows]) for i in range(len(head))]
    if a.markdown:
        print("| " + " | ".join(head) + " |")
        print("|" + "|".join("---" for _ in head) + "|")
        for r in rows:
            print("| " + " | ".join(r) + " |")
    else:
        print("  ".join(h.ljust(w) for h, w in zip(head, widths, strict=True)))
        for r in rows:
            print("  ".join(c.ljust(w) for c, w in zip(r, widths, strict=True)))
    n_contract = sum(1 for b in bugs if ": accuracy: " not in b)
    print(f"\n{len(cases)} faults x {len(filters)} filters in {elapsed:.0f} s; "
          f"{n_contract} contract violations, {len(bugs) - n_contract} accuracy violations")
    print("legend: rmse/max/drift in m against the truth; sx = sigma growth across the outage; "
          "e/s = end error / sigma; rej = fixes rejected; errN = clean one-line error, exit N")
    for b in bugs:
        print(("BAD " if ": accuracy: " in b else "BUG ") + b.replace(": accuracy: ", ": "))
    if not a.keep:
        shutil.rmtree(root, ignore_errors=True)
    return 1 if bugs else 0


if __name__ == "__main__":
    sys.exit(main())
