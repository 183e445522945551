"""Warm end-to-end ``gpsdr fuse`` of a one-hour drive: wall time and peak RSS, before/after.

    python benchmarks/warm_fuse.py [--before REV] [--runs 5] [--drive DIR] [--cold]

The drive is the one-hour scenario (``simulate_drive("one_hour", seed=1)``) written
the way other tools write their logs rather than as ``gpsdr simulate`` does:

- ``gyro.csv``: ``t,yaw_rate`` at 100 Hz, times with 6 decimals, rad/s with 7;
- ``odo.csv``: ``t,distance`` at 50 Hz, times with 4 decimals, the metres driven
  since the previous row with 5 decimals (``odo.kind = "distance"``);
- ``gps.nmea``: GGA, GSA and RMC at 5 Hz (no GST).

Each revision runs ``python -m gpsdr_cli.cli.main fuse --gps .. --gyro .. --odo ..``
(the defaults: aekf, then the graph smoother since docs/decisions/0071, before it no
smoother) once to fill the numba cache, then ``--runs`` times under ``/usr/bin/time
-v``, the two revisions interleaved so both see the same load; the table gives the
median, min and max of the wall time, the CPU time (user + system: on a shared machine
it moves less than the wall time) and the peak RSS.
``--before REV`` (default ``main``) is exported with ``git archive`` into a temporary
folder; the "after" is this checkout.  ``--cold`` also times one cold start per
revision (an empty ``NUMBA_CACHE_DIR``).  ``PYTHONDONTWRITEBYTECODE`` is dropped from the
runs' environment, so "warm" includes Python's bytecode cache (written by the first run).
The drive is generated once into ``--drive`` (default: a folder under the system temp
directory) and reused.
"""

from __future__ import annotations

import argparse
import os
import re
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
DEFAULT_DRIVE = Path(tempfile.gettempdir()) / "gpsdr-warm-fuse-drive"


def write_drive(out: Path, seed: int = 1) -> None:
    """The one-hour drive as gyro.csv, odo.csv (distance, 50 Hz) and gps.nmea (GGA+GSA+RMC)."""
    sys.path.insert(0, str(ROOT))
    import numpy as np

    from gpsdr_cli.simulate import nmea_lines, simulate_drive

    out.mkdir(parents=True, exist_ok=True)
    d = simulate_drive("one_hour", seed=seed).drive

    def posix(t_ns: np.ndarray, decimals: int) -> np.ndarray:
        sec, ns = np.divmod(t_ns.astype(np.int64), 10**9)
        frac = ns // 10 ** (9 - decimals)
        return np.char.add(np.char.add(sec.astype(str), "."),
                           np.char.zfill(frac.astype(str), decimals))

    def write(path: Path, header: str, *cols: np.ndarray) -> None:
        rows = cols[0]
        for c in cols[1:]:
            rows = np.char.add(np.char.add(rows, ","), c)
        path.write_text(header + "\n" + "\n".join(rows.tolist()) + "\n", encoding="ascii")

    g = d.gyro
    write(out / "gyro.csv", "t,yaw_rate", posix(g.t_ns, 6),
          np.char.mod("%.7f", g.yaw_rate_radps))
    o = d.odo
    t50 = o.t_ns[::2]
    dist = np.concatenate([[0.0], np.diff(np.interp(
        t50, o.t_ns, np.concatenate([[0.0], np.cumsum(o.speed_mps[1:] * np.diff(o.t_ns) / 1e9)])))])
    write(out / "odo.csv", "t,distance", posix(t50, 4), np.char.mod("%.5f", dist))
    lines = [s for s in nmea_lines(d.gnss) if not s.startswith("$GNGST")]
    (out / "gps.nmea").write_text("".join(lines), encoding="ascii", newline="")


def _time_v(cmd: list[str], env: dict[str, str], cwd: Path) -> tuple[float, float, float]:
    """(wall s, peak RSS MB, user + system CPU s) of one run under /usr/bin/time -v."""
    r = subprocess.run(["/usr/bin/time", "-v", *cmd], env=env, cwd=cwd, capture_output=True,
                       text=True)
    if r.returncode != 0:
        raise SystemExit(f"{' '.join(cmd)} failed:\n{r.stderr[-2000:]}")
    wall = re.search(r"Elapsed \(wall clock\) time.*: (?:(\d+):)?(\d+):([\d.]+)", r.stderr)
    rss = re.search(r"Maximum resident set size \(kbytes\): (\d+)", r.stderr)
    cpu = [re.search(rf"{k} time \(seconds\): ([\d.]+)", r.stderr) for k in ("User", "System")]
    assert wall and rss and all(cpu), r.stderr[-2000:]
    h = int(wall.group(1) or 0)
    s = h * 3600 + int(wall.group(2)) * 60 + float(wall.group(3))
    return s, int(rss.group(1)) / 1024, sum(float(c.group(1)) for c in cpu)  # type: ignore[union-attr]


def _cmd(drive: Path, out: Path) -> list[str]:
    return [sys.executable, "-m", "gpsdr_cli.cli.main", "fuse", "--gps", str(drive / "gps.nmea"),
            "--gyro", str(drive / "gyro.csv"), "--odo", str(drive / "odo.csv"),
            "-o", str(out / "track.parquet"), "-q"]


def _env(src: Path, cache: str | None = None) -> dict[str, str]:
    env = dict(os.environ, PYTHONPATH=str(src))
    # warm means the bytecode too: an installed gpsdr has its .pyc files, and compiling
    # the package's sources on every run (~0.1 s) is not what a user's second run pays
    env.pop("PYTHONDONTWRITEBYTECODE", None)
    if cache is not None:
        env["NUMBA_CACHE_DIR"] = cache
    return env


def _summary(xs: list[float], fmt: str) -> str:
    return (f"{format(statistics.median(xs), fmt)} ({format(min(xs), fmt)}-"
            f"{format(max(xs), fmt)})")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--before", default="main", help="git revision to compare against")
    ap.add_argument("--runs", type=int, default=5)
    ap.add_argument("--drive", type=Path, default=DEFAULT_DRIVE)
    ap.add_argument("--cold", action="store_true", help="also one cold start per revision")
    args = ap.parse_args()
    if not (args.drive / "gps.nmea").exists():
        print(f"writing the drive into {args.drive} ...", file=sys.stderr)
        write_drive(args.drive)
    with tempfile.TemporaryDirectory() as tmp:
        tmpd = Path(tmp)
        before = tmpd / "before"
        before.mkdir()
        archive = subprocess.run(["git", "-C", str(ROOT), "archive", args.before, "gpsdr_cli"],
                                 check=True, capture_output=True).stdout
        subprocess.run(["tar", "-x", "-C", str(before)], input=archive, check=True)
        revs = {f"before ({args.before})": before, "after (this checkout)": ROOT}
        results: dict[str, dict[str, list[float]]] = {
            k: {"wall": [], "rss": [], "cpu": []} for k in revs}
        cold: dict[str, tuple[float, float, float]] = {}
        for name, src in revs.items():
            _time_v(_cmd(args.drive, tmpd), _env(src), tmpd)  # fill the numba cache
            if args.cold:
                cold[name] = _time_v(_cmd(args.drive, tmpd),
                                     _env(src, tempfile.mkdtemp(dir=tmpd)), tmpd)
        for _ in range(args.runs):
            for name, src in revs.items():
                wall, rss, cpu = _time_v(_cmd(args.drive, tmpd), _env(src), tmpd)
                results[name]["wall"].append(wall)
                results[name]["rss"].append(rss)
                results[name]["cpu"].append(cpu)
    load = os.getloadavg()[0]
    print(f"warm gpsdr fuse, one-hour drive ({args.drive}), {args.runs} runs each, "
          f"median (min-max); load average {load:.1f} on {os.cpu_count()} cores")
    print(f"{'revision':<26} {'wall s':>18} {'CPU s':>18} {'peak RSS MB':>16}"
          + ("  cold wall s / MB" if cold else ""))
    for name, r in results.items():
        extra = f"  {cold[name][0]:.2f} / {cold[name][1]:.0f}" if name in cold else ""
        print(f"{name:<26} {_summary(r['wall'], '.2f'):>18} {_summary(r['cpu'], '.2f'):>18} "
              f"{_summary(r['rss'], '.0f'):>16}{extra}")


if __name__ == "__main__":
    main()
