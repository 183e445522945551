"""How long the HTML report of a one-hour drive takes to open in headless Chromium.

    python benchmarks/html_report.py [--runs 3] [--keep report.html] [--duration S]

Simulates the ``one_hour`` scenario (100 Hz gyro: 360 k filter epochs), fuses it with
aekf through the pipeline, writes the HTML report against the truth, then opens it
``--runs`` times in headless Chromium (a fresh profile each time, ``--dump-dom``: the
DOM after the page's script has drawn everything).  Prints the file size, the points
drawn, the wall time of each open (browser start included) and the page's own drawing
time.  Target: open in <= 5 s.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from tempfile import TemporaryDirectory

REPO = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(REPO))

from gpsdr_cli import config
from gpsdr_cli.pipeline import fuse
from gpsdr_cli.report.html import write_html_report
from gpsdr_cli.simulate import simulate_drive
from gpsdr_cli.testing import browser

TARGET_S = 5.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--runs", type=int, default=3)
    ap.add_argument("--keep", type=Path, default=None, help="also keep the report here")
    ap.add_argument("--duration", type=float, default=None,
                    help="simulate this many seconds instead of the hour (a quick check)")
    args = ap.parse_args(argv)
    if browser.find_chromium() is None:
        print("chromium is not installed (Debian: apt-get install chromium)", file=sys.stderr)
        return 2
    t0 = time.perf_counter()
    sim = simulate_drive("one_hour", seed=0, duration_s=args.duration)
    params = config.defaults()
    res = fuse(sim.drive, params, sim.truth[["t_ns", "lat", "lon"]])
    t_fused = time.perf_counter() - t0
    with TemporaryDirectory() as tmp:
        out = Path(args.keep) if args.keep else Path(tmp) / "one_hour.html"
        t1 = time.perf_counter()
        write_html_report(res.track, out, res.reference_en, "aekf, one hour")
        t_write = time.perf_counter() - t1
        walls, draws = [], []
        status: dict[str, str] = {}
        for _ in range(args.runs):
            run = browser.dump_dom(out)
            status = run.status()
            if status.get("data-state") != "done":
                print(f"the page did not finish drawing: {status} "
                      f"{browser.console_errors(run.stderr)}", file=sys.stderr)
                return 1
            walls.append(run.wall_s)
            draws.append(float(status["data-draw-ms"]) / 1000.0)
        size_mb = out.stat().st_size / 1e6
    print(f"one_hour{'' if args.duration is None else f' ({args.duration:g} s)'}: "
          f"{len(res.track)} epochs (simulate + fuse {t_fused:.1f} s); "
          f"report written in {t_write:.2f} s, {size_mb:.1f} MB")
    print(f"drawn: {status['data-line-points']} line points, {status['data-fixes']} fixes, "
          f"panels {status['data-panels']}")
    print("chromium open (wall, browser start included): "
          + ", ".join(f"{w:.2f}" for w in walls) + f" s; median {statistics.median(walls):.2f} s")
    print("page drawing (in the page): " + ", ".join(f"{d:.2f}" for d in draws) + " s")
    ok = statistics.median(walls) <= TARGET_S
    print(f"target <= {TARGET_S:.0f} s: {'met' if ok else 'MISSED'}")
    return 0 if ok else 1


if __name__ == "__main__":
    raise SystemExit(main())
