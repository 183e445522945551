"""Where a cold ``gpsdr fuse`` spends its compile time: numba compile seconds per function.

    find gpsdr_cli -name '*.nb[ic]' -delete      # clear numba's cache first (a cold start)
    python benchmarks/compile_profile.py DRIVE_DIR [--filter NAME]
    # or, leaving your cache alone:
    NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/compile_profile.py DRIVE_DIR

DRIVE_DIR holds gps.nmea, gyro.csv and odo.csv (``gpsdr simulate -o DIR --scenario
one_hour``).  Two columns per compiled specialisation, in CPU seconds of this process
(numba compiles in the calling thread; CPU time, unlike wall time, does not count what
other processes on a shared machine take): inclusive (a caller's
time includes the callees compiled inside it) and body seconds (inclusive minus the
callees compiled inside it: the function's own type inference, rewrites and
lowering).  With a warm cache the table is empty.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from numba.core import event


class _CompileTimes(event.Listener):
    """Inclusive and body (exclusive) seconds per compiled specialisation."""

    def __init__(self) -> None:
        self.stack: list[tuple[tuple[int, str], float, list[float]]] = []
        self.times: dict[str, tuple[float, float]] = {}

    def on_start(self, ev: event.Event) -> None:
        key = (id(ev.data["dispatcher"]), str(ev.data["args"]))
        self.stack.append((key, time.process_time(), [0.0]))

    def on_end(self, ev: event.Event) -> None:
        key = (id(ev.data["dispatcher"]), str(ev.data["args"]))
        while self.stack:  # the matching start (nested compiles close in order)
            k, t0, child = self.stack.pop()
            if k == key:
                break
        else:
            return
        incl = time.process_time() - t0
        if self.stack:
            self.stack[-1][2][0] += incl
        name = f"{ev.data['dispatcher'].py_func.__qualname__} #{len(self.times)}"
        self.times[name] = (incl, incl - child[0])


def main() -> None:
    if len(sys.argv) < 2:
        sys.exit(__doc__)
    drive = Path(sys.argv[1])
    # compile here, in this process, where the listener sees it (not in gpsdr fuse's
    # background warm-up process, gpsdr_cli.warmup)
    os.environ["GPSDR_WARM_UP"] = "0"
    listener = _CompileTimes()
    event.register("numba:compile", listener)
    from click.testing import CliRunner

    from gpsdr_cli.cli.main import cli

    w0, c0 = time.perf_counter(), time.process_time()
    res = CliRunner().invoke(cli, ["fuse", "--gps", str(drive / "gps.nmea"), "--gyro",
                                   str(drive / "gyro.csv"), "--odo", str(drive / "odo.csv"),
                                   "-o", str(drive / "compile_profile.parquet"), "-q",
                                   *sys.argv[2:]])
    total, cpu = time.perf_counter() - w0, time.process_time() - c0
    if res.exit_code:
        sys.exit(res.output)
    top = sum(body for _, body in listener.times.values())  # every compile counted once
    print(f"gpsdr fuse in-process: {total:.2f} s wall, {cpu:.2f} s CPU; numba compile "
          f"{top:.2f} s CPU in {len(listener.times)} specialisations (inclusive, body):")
    for name, (incl, body) in sorted(listener.times.items(), key=lambda kv: -kv[1][0])[:25]:
        print(f"{incl:7.2f} {body:7.2f}  {name}")


if __name__ == "__main__":
    main()
