"""Speed of gpsdr's filters: one command, one table.

    python benchmarks/speed.py [--seconds 3600] [--filterpy-epochs 3000] [--no-cli] [--cli-only N]

Simulates a one-hour drive (``simulate_drive("one_hour")``: 100 Hz gyro and
odometer, 5 Hz GNSS: 360 k epochs), then prints:

- epochs/s of every registered filter, forward only and with RTS smoothing
  (best of 3, wall clock and process CPU time: on a shared machine the CPU
  figure is the one that measures the code);
- the same 8-state model run epoch by epoch through FilterPy's
  ``KalmanFilter`` (same F, Q, H, R per epoch; the nonlinear rows fed as
  linearised pseudo-measurements), on the first few thousand epochs,
  extrapolated, and the speed ratio;
- time and peak RSS of aekf + smoothing for 1x, 2x and 4x the log length (each
  in a fresh subprocess so the peak RSS is its own; the longer logs repeat the
  drive with shifted times);
- end-to-end ``gpsdr fuse`` wall time on the drive's files, warm and cold
  (cold = an empty numba cache: ``NUMBA_CACHE_DIR`` set to a new empty folder,
  so your own cache stays), both as shipped (the kernels compile in a
  background process while the logs are read, :mod:`gpsdr_cli.warmup`) and
  with ``GPSDR_WARM_UP=0`` (compiled in the foreground), or "n/a" when the
  console script is not installed.
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

from gpsdr_cli.align import Epochs, build_epochs
from gpsdr_cli.config import defaults
from gpsdr_cli.errors import UsageError
from gpsdr_cli.filters import NAMES, get


def peak_rss_mb() -> float:
    """Peak resident set size of this process, MB.

    Linux: VmHWM of /proc/self/status, the high-water mark of the current
    address space (``ru_maxrss`` would include the parent's RSS at fork time).
    """
    try:
        for line in Path("/proc/self/status").read_text().splitlines():
            if line.startswith("VmHWM:"):
                return int(line.split()[1]) / 1024.0
    except OSError:
        pass
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0  # Linux: kB


def one_hour_epochs(seconds: float):
    from gpsdr_cli.simulate import simulate_drive

    sim = simulate_drive("one_hour", seed=0, duration_s=seconds)
    return sim, build_epochs(sim.drive, sim.frame, defaults())


def tile(ep: Epochs, times: int) -> Epochs:
    """The drive repeated ``times`` times, each copy shifted to start after the previous."""
    if times == 1:
        return ep
    span = int(ep.t_ns[-1] - ep.t_ns[0]) + 10_000_000
    t = np.concatenate([ep.t_ns + i * span for i in range(times)])
    dt = np.zeros(len(t))
    dt[1:] = np.diff(t) / 1e9
    fields = {}
    for name in ("has_gnss", "gnss_e", "gnss_n", "gnss_sd_e", "gnss_sd_n", "pdop",
                 "gnss_speed_mps", "gnss_course_rad", "has_gyro", "yaw_rate_radps", "has_odo",
                 "odo_speed_mps", "gnss_outage"):
        fields[name] = np.concatenate([getattr(ep, name)] * times)
    return Epochs(t_ns=t, dt_s=dt, gap_s=ep.gap_s, **fields)


def time_filter(name: str, ep: Epochs, smooth: bool, repeats: int = 3) -> tuple[float, float]:
    """Best wall and CPU seconds of ``repeats`` runs (after one warm-up/compile run)."""
    p = defaults()
    p["filter"]["smooth"] = smooth
    get(name)(ep, p)
    walls, cpus = [], []
    for _ in range(repeats):
        w0, c0 = time.perf_counter(), time.process_time()
        get(name)(ep, p)
        walls.append(time.perf_counter() - w0)
        cpus.append(time.process_time() - c0)
    return min(walls), min(cpus)


def filterpy_rate(ep: Epochs, n_epochs: int) -> float:
    """Epochs/s of the same model epoch by epoch through filterpy.kalman.KalmanFilter."""
    from filterpy.kalman import KalmanFilter

    from gpsdr_cli.filters.aekf import gnss_noise, initial_state
    from gpsdr_cli.models.cs_model import (
        cs_sigma_a2,
        newton_matrix,
        odo_row,
        omega_row,
        phi_matrix,
        q_matrix,
    )

    p = defaults()
    a, gy, od, st = p["aekf"], p["gyro"], p["odo"], p["standstill"]
    alpha, tau_eps = 1.0 / a["tau_a_s"], gy["bias_tau_s"]
    q_eps, q_ks = 2 * gy["bias_sd_radps"] ** 2 / tau_eps, od["scale_rw_sd"] ** 2
    r_e, r_n, ka, _ = gnss_noise(ep, p, True)
    x0, P0, _, _ = initial_state(ep, p)
    kf = KalmanFilter(dim_x=8, dim_z=1)
    kf.x = x0.reshape(8, 1).copy()
    kf.P = P0.copy()
    H = np.zeros(8)
    sa2 = cs_sigma_a2.py_func
    n = min(n_epochs, len(ep))
    t0 = time.process_time()
    for k in range(n):
        T = ep.dt_s[k]
        if k > 0 and T > 0:
            x = kf.x[:, 0]
            s2e = sa2(x[2], a["a_max_mps2"], a["a_min_mps2"], ka[k], a["sigma_a_mps2"])
            s2n = sa2(x[5], a["a_max_mps2"], a["a_min_mps2"], ka[k], a["sigma_a_mps2"])
            F = phi_matrix(T, alpha, tau_eps)
            Q = q_matrix(T, alpha, 2 * alpha * s2e, 2 * alpha * s2n, q_eps, q_ks)
            kf.predict(F=F, Q=Q)
            kf.x = newton_matrix(T, tau_eps, drift_decay=False) @ x.reshape(8, 1)  # CS mean
        if ep.has_gnss[k]:
            for idx, z, r in ((0, ep.gnss_e[k], r_e[k]), (3, ep.gnss_n[k], r_n[k])):
                Hg = np.zeros((1, 8))
                Hg[0, idx] = 1.0
                kf.update(np.array([[z]]), R=np.array([[r]]), H=Hg)
        x = kf.x[:, 0]
        v = float(np.hypot(x[1], x[4]))
        if ep.has_odo[k] and v > st["omega_min_speed_mps"]:
            h = odo_row(x, x[1] / v, x[4] / v, H)
            z = ep.odo_speed_mps[k] - h + H @ x  # linearised: y = z - h(x) = z_lin - H x
            kf.update(np.array([[z]]), R=np.array([[od["noise_sd_mps"] ** 2]]),
                      H=H.reshape(1, 8).copy())
        x = kf.x[:, 0]
        if ep.has_gyro[k] and np.hypot(x[1], x[4]) > st["omega_min_speed_mps"]:
            h = omega_row(x, H)
            z = -ep.yaw_rate_radps[k] - h + H @ x
            kf.update(np.array([[z]]), R=np.array([[gy["noise_sd_radps"] ** 2]]),
                      H=H.reshape(1, 8).copy())
    return n / (time.process_time() - t0)


EPOCH_FIELDS = ("t_ns", "dt_s", "has_gnss", "gnss_e", "gnss_n", "gnss_sd_e", "gnss_sd_n", "pdop",
                "gnss_speed_mps", "gnss_course_rad", "has_gyro", "yaw_rate_radps", "has_odo",
                "odo_speed_mps", "gnss_outage")


def child(times: int, npz: str) -> None:
    """Subprocess: aekf + smoothing on the saved drive tiled ``times`` times; print JSON.

    The epochs come from an .npz the parent wrote, so the peak RSS is the
    filter's (plus the interpreter, numpy and numba), not the simulator's.
    """
    with np.load(npz) as d:
        ep = Epochs(gap_s=float(d["gap_s"]), **{k: d[k] for k in EPOCH_FIELDS})
    rss_loaded = peak_rss_mb()
    ep = tile(ep, times)
    p = defaults()
    p["filter"]["smooth"] = True
    small = tile(Epochs(gap_s=ep.gap_s, **{k: getattr(ep, k)[:1000] for k in EPOCH_FIELDS}), 1)
    get("aekf")(small, p)  # compile / load the cache on a small slice
    rss_ready = peak_rss_mb()
    w0 = time.perf_counter()
    res = get("aekf")(ep, p)
    secs = time.perf_counter() - w0
    del res
    print(json.dumps({"epochs": len(ep), "seconds": secs, "peak_rss_mb": peak_rss_mb(),
                      "rss_before_mb": rss_ready, "rss_inputs_mb": rss_loaded}))


def cli_times(sim) -> tuple[str, str, str]:
    """``gpsdr fuse`` wall time: warm, cold, cold with the compile in the foreground."""
    exe = shutil.which("gpsdr") or str(ROOT / ".venv" / "bin" / "gpsdr")
    if not Path(exe).exists():
        return "n/a", "n/a", "n/a"
    from gpsdr_cli.simulate import write_drive

    with tempfile.TemporaryDirectory() as tmp:
        files = write_drive(sim, tmp, mcap=False)
        cmd = [exe, "fuse", "--gps", str(files["gps.nmea"]), "--gyro", str(files["gyro.csv"]),
               "--odo", str(files["odo.csv"]), "-o", str(Path(tmp) / "track.parquet"),
               "--stats", str(Path(tmp) / "stats.parquet")]

        def run(env: dict[str, str] | None = None) -> str:
            w0 = time.perf_counter()
            res = subprocess.run(cmd, capture_output=True, text=True, check=False,
                                 env=None if env is None else {**os.environ, **env})
            if res.returncode != 0:
                return f"failed ({res.stderr.strip().splitlines()[-1] if res.stderr else res.returncode})"
            return f"{time.perf_counter() - w0:.2f} s"

        run()  # make sure the cache is populated
        warm = run()
        cold = run({"NUMBA_CACHE_DIR": str(Path(tmp) / "cold1"), "GPSDR_WARM_UP": "1"})
        fg = run({"NUMBA_CACHE_DIR": str(Path(tmp) / "cold2"), "GPSDR_WARM_UP": "0"})
    return warm, cold, fg


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=3600.0, help="drive length (s)")
    ap.add_argument("--filterpy-epochs", type=int, default=3000)
    ap.add_argument("--no-cli", action="store_true", help="skip the gpsdr fuse timing")
    ap.add_argument("--cli-only", type=int, default=0, metavar="N",
                    help="only the gpsdr fuse timings (warm, cold, cold without the background "
                         "compile), N times")
    ap.add_argument("--child", type=int, default=0, help=argparse.SUPPRESS)
    ap.add_argument("--npz", default="", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child:
        child(args.child, args.npz)
        return

    w0 = time.perf_counter()
    sim, ep = one_hour_epochs(args.seconds)
    n = len(ep)
    if args.cli_only:
        for _ in range(args.cli_only):
            warm, cold, fg = cli_times(sim)
            print(f"gpsdr fuse: warm {warm}, cold {cold}, cold with GPSDR_WARM_UP=0 {fg}",
                  flush=True)
        return
    print(f"drive: one_hour, {args.seconds:.0f} s, {n} epochs "
          f"({int(ep.has_gyro.sum())} gyro, {int(ep.has_odo.sum())} odometer, "
          f"{int(ep.has_gnss.sum())} GNSS); simulated + aligned in {time.perf_counter() - w0:.1f} s")
    print()
    print(f"{'filter':<8} {'smooth':<6} {'wall s':>8} {'cpu s':>8} {'M epochs/s (cpu)':>17}")
    rates: dict[str, float] = {}
    for name in NAMES:
        for smooth in (False, True):
            try:
                wall, cpu = time_filter(name, ep, smooth)
            except (ImportError, UsageError) as err:
                print(f"{name:<8} {smooth!s:<6} {'n/a':>8}  ({err})")
                break
            rates[f"{name}{'+rts' if smooth else ''}"] = n / cpu
            print(f"{name:<8} {smooth!s:<6} {wall:8.3f} {cpu:8.3f} {n / cpu / 1e6:17.2f}")
    print()
    fp = filterpy_rate(ep, args.filterpy_epochs)
    print(f"FilterPy KalmanFilter, same model, {args.filterpy_epochs} epochs: {fp:,.0f} epochs/s (cpu) "
          f"-> {n / fp:.0f} s extrapolated for this drive")
    if "aekf" in rates:
        print(f"aekf kernel / FilterPy: {rates['aekf'] / fp:.0f}x; ekf: {rates['ekf'] / fp:.0f}x")
    print(f"peak RSS of this process (simulator included): {peak_rss_mb():.0f} MB")
    print()
    print(f"{'aekf+rts':<10} {'epochs':>9} {'wall s':>8} {'peak RSS MB':>12} "
          f"{'RSS before run MB':>18}")
    with tempfile.TemporaryDirectory() as tmp:
        npz = str(Path(tmp) / "epochs.npz")
        np.savez(npz, gap_s=ep.gap_s, **{k: getattr(ep, k) for k in EPOCH_FIELDS})
        for times in (0, 1, 2, 4):  # 0: a first child loads/compiles the numba cache, not shown
            if times == 0:
                subprocess.run([sys.executable, __file__, "--child", "1", "--npz", npz],
                               capture_output=True, text=True, check=False)
                continue
            res = subprocess.run([sys.executable, __file__, "--child", str(times), "--npz", npz],
                                 capture_output=True, text=True, check=False)
            if res.returncode != 0:
                print(f"{times}x  failed: {res.stderr.strip().splitlines()[-1:]}")
                continue
            d = json.loads(res.stdout.strip().splitlines()[-1])
            print(f"{str(times) + 'x':<10} {d['epochs']:>9} {d['seconds']:8.2f} "
                  f"{d['peak_rss_mb']:12.0f} {d['rss_before_mb']:18.0f}")
    print()
    if args.no_cli:
        print("gpsdr fuse: skipped (--no-cli)")
        return
    warm, cold, fg = cli_times(sim)
    print(f"gpsdr fuse (aekf, --gps/--gyro/--odo files of this drive): warm {warm}, "
          f"cold (empty numba cache) {cold}; cold with GPSDR_WARM_UP=0 (no background "
          f"compile) {fg}")


if __name__ == "__main__":
    main()
