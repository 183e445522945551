"""Where a cold ``gpsdr fuse`` spends its compile time: numba compile seconds per function.

    find gpsdr_cli -name '*.nb[ic]' -delete      # clear numba's cache first (a cold start)
    python benchmarks/compile_profile.py DRIVE_DIR [--filter NAME]
    # or, leaving your cache alone:  NUMBA_CACHE_DIR=$(mktemp -d) python benchmarks/compile_profile.py DRIVE_DIR

DRIVE_DIR holds gps.nmea, gyro.csv and odo.csv (``gpsdr simulate -o DIR --scenario
one_hour``).  Times are inclusive: a caller's time includes the callees compiled
inside it.  With a warm cache the table is empty.
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

from numba.core import event


class _CompileTimes(event.Listener):
    def __init__(self) -> None:
        self.start: dict[tuple[int, str], float] = {}
        self.times: dict[str, float] = {}

    def on_start(self, ev: event.Event) -> None:
        self.start[id(ev.data["dispatcher"]), str(ev.data["args"])] = time.perf_counter()

    def on_end(self, ev: event.Event) -> None:
        key = (id(ev.data["dispatcher"]), str(ev.data["args"]))
        name = f"{ev.data['dispatcher'].py_func.__qualname__} #{len(self.times)}"
        self.times[name] = time.perf_counter() - self.start[key]


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

    w0 = time.perf_counter()
    res = CliRunner().invoke(cli, ["fuse", "--gps", str(drive / "gps.nmea"), "--gyro",
                                   str(drive / "gyro.csv"), "--odo", str(drive / "odo.csv"),
                                   "-o", str(drive / "compile_profile.parquet"), "-q",
                                   *sys.argv[2:]])
    total = time.perf_counter() - w0
    if res.exit_code:
        sys.exit(res.output)
    print(f"gpsdr fuse in-process: {total:.2f} s; numba compile seconds (inclusive):")
    for name, sec in sorted(listener.times.items(), key=lambda kv: -kv[1])[:25]:
        print(f"{sec:7.2f}  {name}")


if __name__ == "__main__":
    main()
