"""Compare gpsdr's NMEA reader with gpsd's expected output on gpsd's regression logs.

Usage::

    python benchmarks/gpsd_compare.py DIR [--position-from rank|last] [--timeout S] [-v]

``DIR`` holds pairs ``NAME.log`` + ``NAME.log.chk`` in the layout of gpsd's
``test/daemon/`` regression suite (the logs are raw receiver output; the ``.chk`` holds
gpsd's JSON reports, one per line, other lines ignored).  Nothing is downloaded: the
script reads only ``DIR``.

Truth: every gpsd ``TPV`` report with ``mode >= 2``, a ``time`` and ``lat``/``lon``.
gpsd may print several TPVs for one epoch (one per sentence that ends a cycle); the last
one per epoch time is its answer for that epoch, since gpsd reports the position of the
latest position sentence of the cycle.

gpsdr: ``gpsdr_cli.io.nmea.read_nmea`` (what ``gpsdr extract --stream gnss`` runs), rows
with ``fix_quality > 0`` and finite lat/lon.  Many of gpsd's logs carry only GGA (time of
day, no date): gpsdr then needs a date, as ``gpsdr extract --date``.  The script passes
the UTC date of the first gpsd TPV of that log; a date in the log (RMC, ZDA) still wins
inside gpsdr, so the date argument only fills logs that have none.

gpsd's newer ``.chk`` files date an old receiver's fixes whole GPS week rollovers (1024
weeks) later than the receiver does (a 2007 log reported in 2027); where gpsdr's first fix
lies such a number of rollovers from gpsd's, gpsd's times are moved back by them first
(the table says so).

Matching: a gpsd fix is "matched" when gpsdr has a fix at the same epoch time (to the
millisecond), or failing that in the same UTC second; "within 1e-6" when both lat and
lon differ by at most 1e-6 deg.  "extra" counts gpsdr fixes at times gpsd reports no fix.
Each read runs in a child process with a timeout; a crash or timeout counts every gpsd
fix of that log as missed.
"""

from __future__ import annotations

import argparse
import datetime
import json
import multiprocessing as mp
import sys
import traceback
from pathlib import Path

TOL_DEG = 1e-6
#: one GPS week-number rollover, 1024 weeks (ms)
ROLLOVER_MS = 1024 * 7 * 86_400_000


def gpsd_fixes(chk: Path) -> dict[int, tuple[float, float]]:
    """Epoch time (ms since 1970, UTC) -> (lat, lon) deg of gpsd's last TPV of that epoch."""
    out: dict[int, tuple[float, float]] = {}
    for line in chk.read_text(encoding="utf-8", errors="replace").splitlines():
        line = line.strip()
        if not line.startswith("{"):
            continue
        try:
            rep = json.loads(line)
        except ValueError:
            continue
        if (rep.get("class") != "TPV" or rep.get("mode", 0) < 2 or "time" not in rep
                or "lat" not in rep or "lon" not in rep):
            continue
        t = datetime.datetime.fromisoformat(rep["time"].replace("Z", "+00:00"))
        out[round(t.timestamp() * 1000)] = (float(rep["lat"]), float(rep["lon"]))
    return out


def _read(path: str, date: datetime.date | None, position_from: str, q) -> None:
    try:
        import numpy as np

        from gpsdr_cli.io.nmea import read_nmea
        g = read_nmea(path, date=date, position_from=position_from).gnss
        ok = (g.fix_quality > 0) & np.isfinite(g.lat_deg) & np.isfinite(g.lon_deg)
        ms = np.round(g.t_ns[ok] / 1e6).astype(np.int64)
        rows = zip(ms.tolist(), g.lat_deg[ok].tolist(), g.lon_deg[ok].tolist(), strict=True)
        q.put(("ok", list(rows)))
    except BaseException as err:  # noqa: BLE001 - every failure is a result here
        q.put(("error", f"{type(err).__name__}: {err}", traceback.format_exc(limit=3)))


def gpsdr_fixes(log: Path, date: datetime.date | None, position_from: str,
                timeout_s: float) -> tuple[str, list | str]:
    ctx = mp.get_context("fork")
    q = ctx.Queue()
    p = ctx.Process(target=_read, args=(str(log), date, position_from, q))
    p.start()
    try:
        res = q.get(timeout=timeout_s)
    except Exception:  # noqa: BLE001 - queue.Empty: the read hung or died
        p.kill()
        p.join()
        return ("timeout" if p.exitcode in (None, -9) else "crash"), f"exit code {p.exitcode}"
    p.join()
    if res[0] == "ok":
        return "ok", res[1]
    # InputError/NoDataError etc. are refusals of the file, still a miss of every fix
    return "error", res[1]


def compare(log: Path, position_from: str, timeout_s: float) -> dict:
    truth = gpsd_fixes(Path(str(log) + ".chk"))
    date = None
    if truth:
        date = datetime.datetime.fromtimestamp(min(truth) / 1000, datetime.timezone.utc).date()
    status, res = gpsdr_fixes(log, date, position_from, timeout_s)
    row = {"log": log.name, "gpsd": len(truth), "matched": 0, "within": 0, "extra": 0,
           "status": status, "misses": [], "far": []}
    if status != "ok":
        row["error"] = res
        return row
    ours = {ms: (lat, lon) for ms, lat, lon in res}
    if truth and ours:
        # gpsd's newer .chk files move an old receiver's dates on by whole GPS week rollovers
        # (1024 weeks: a 2007 log reported in 2027); the receiver's own date is gpsdr's
        k = round((min(ours) - min(truth)) / ROLLOVER_MS)
        if k:
            truth = {ms + k * ROLLOVER_MS: pos for ms, pos in truth.items()}
            row["rollovers"] = k
    by_sec: dict[int, list[int]] = {}
    for ms in ours:
        by_sec.setdefault(ms // 1000, []).append(ms)
    used: set[int] = set()
    for ms, (lat, lon) in sorted(truth.items()):
        key = ms if ms in ours else None
        if key is None:
            cands = [m for m in by_sec.get(ms // 1000, []) if m not in truth and m not in used]
            key = min(cands, key=lambda m: abs(m - ms)) if cands else None
        if key is None:
            row["misses"].append(ms)
            continue
        used.add(key)
        row["matched"] += 1
        dlat, dlon = abs(ours[key][0] - lat), abs(ours[key][1] - lon)
        if dlat <= TOL_DEG and dlon <= TOL_DEG:
            row["within"] += 1
        else:
            row["far"].append((ms, dlat, dlon))
    row["extra"] = sum(1 for ms in ours if ms not in truth and ms not in used)
    return row


def _iso(ms: int) -> str:
    return datetime.datetime.fromtimestamp(ms / 1000, datetime.timezone.utc).strftime(
        "%Y-%m-%dT%H:%M:%S.%f")[:-3]


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", type=Path)
    ap.add_argument("--position-from", default="rank", choices=("rank", "last"))
    ap.add_argument("--timeout", type=float, default=60.0, help="seconds per log")
    ap.add_argument("-v", "--verbose", action="store_true", help="list missed/far fixes")
    a = ap.parse_args(argv)
    logs = sorted(p for p in a.dir.glob("*.log") if Path(str(p) + ".chk").exists())
    if not logs:
        print(f"no .log + .log.chk pairs in {a.dir}", file=sys.stderr)
        return 2
    rows = [compare(p, a.position_from, a.timeout) for p in logs]
    w = max(len(r["log"]) for r in rows)
    print(f"{'log':<{w}}  {'gpsd':>5} {'same s':>6} {'<=1e-6':>6} {'extra':>5}  status")
    tot = {"gpsd": 0, "matched": 0, "within": 0, "extra": 0}
    bad = 0
    for r in rows:
        for k in tot:
            tot[k] += r[k]
        bad += r["status"] != "ok"
        note = f" ({r['error']})" if "error" in r else ""
        if r.get("rollovers"):
            note += f" (gpsd's dates {-r['rollovers']:+d} x 1024 weeks)"
        print(f"{r['log']:<{w}}  {r['gpsd']:>5} {r['matched']:>6} {r['within']:>6} "
              f"{r['extra']:>5}  {r['status']}{note}")
        if a.verbose:
            for ms in r["misses"][:5]:
                print(f"    missed {_iso(ms)}")
            for ms, dlat, dlon in r["far"][:5]:
                print(f"    far    {_iso(ms)}  dlat {dlat:.2e} dlon {dlon:.2e}")
    n = max(tot["gpsd"], 1)
    print(f"{'total':<{w}}  {tot['gpsd']:>5} {tot['matched']:>6} {tot['within']:>6} "
          f"{tot['extra']:>5}  {bad} crash/timeout/refused")
    print(f"matched at the same second: {100 * tot['matched'] / n:.2f} %; "
          f"within {TOL_DEG:g} deg: {100 * tot['within'] / n:.2f} % "
          f"({len(rows)} logs, position_from={a.position_from})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
