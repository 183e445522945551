"""Reading speed of the UBX and ROS bag readers, in messages per second, as one table.

    python benchmarks/read_ubx_rosbag.py [--repeat 3]

UBX: an F9R-like log of a simulated drive (NAV-PVT 5 Hz, ESF-MEAS gyro and speed
100 Hz each) written with pyubx2, tiled to ~250 k messages; also pyubx2's own
UBXReader over the first 5 k messages for comparison.  ROS bags: a ROS 1 ``.bag``
and a ROS 2 ``.db3`` with NavSatFix 5 Hz, Imu and Odometry 100 Hz each (~300 k
messages), written with rosbags.  Times are the best of ``--repeat`` warm runs,
wall clock and the process CPU time of the same run (CPU counts every thread; it
moves less than wall time when other jobs share the machine).
"""

from __future__ import annotations

import argparse
import io
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))

from gpsdr_cli.io import ros2_fast
from gpsdr_cli.io.rosbag import read_rosbag
from gpsdr_cli.io.ubx import parse_ubx
from gpsdr_cli.simulate import simulate_drive
from gpsdr_cli.testing.ubx_log import ubx_log

T0 = 1_777_000_000 * 10**9


def _best(fn, repeat: int) -> tuple[float, float]:
    """(wall s, CPU s) of the fastest of ``repeat`` warm runs."""
    fn()  # warm (numba cache load)
    best = (float("inf"), float("inf"))
    for _ in range(repeat):
        t, c = time.perf_counter(), time.process_time()
        fn()
        best = min(best, (time.perf_counter() - t, time.process_time() - c))
    return best


def write_bag(path: Path, ros1: bool, seconds: int) -> int:
    """A bag of ``seconds`` s: NavSatFix 5 Hz, Imu and Odometry 100 Hz; returns its messages."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    w = Writer1(path) if ros1 else Writer2(path, version=9)
    w.open()
    c_fix = w.add_connection("/fix", "sensor_msgs/msg/NavSatFix", typestore=ts)
    c_imu = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
    c_odo = w.add_connection("/odom", "nav_msgs/msg/Odometry", typestore=ts)
    imu = ros2_fast.encode("imu", T0, "imu", ros1=ros1, wz=0.01, ax=0.2)
    odo = ros2_fast.encode("odometry", T0, "odom", ros1=ros1, vx=5.0)
    fix = ros2_fast.encode("navsatfix", T0, "gps", ros1=ros1, lat=54.0, lon=18.0)
    n = 0
    for i in range(seconds * 100):
        t = T0 + i * 10_000_000
        w.write(c_imu, t, imu)
        w.write(c_odo, t, odo)
        n += 2
        if i % 20 == 0:
            w.write(c_fix, t, fix)
            n += 1
    w.close()
    return n


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    rows = []
    sim = simulate_drive("open_sky", seed=1, duration_s=120.0)
    one = ubx_log(sim.drive)
    data = one * 10
    n_ubx = parse_ubx(data, name="bench.ubx").meta["ubx"]["frames"]
    rows.append(("UBX (gpsdr)", n_ubx, _best(lambda: parse_ubx(data, name="bench.ubx"), args.repeat)))
    from pyubx2 import UBXReader

    def pyubx2_read() -> int:
        k = 0
        for _raw, _msg in UBXReader(io.BytesIO(one), protfilter=2):
            k += 1
            if k >= 5000:
                break
        return k

    rows.append(("UBX (pyubx2 UBXReader)", 5000, _best(pyubx2_read, 1)))
    with tempfile.TemporaryDirectory() as tmp:
        for ros1, name in ((True, "ROS 1 .bag"), (False, "ROS 2 .db3")):
            path = Path(tmp) / ("b.bag" if ros1 else "b2")
            n = write_bag(path, ros1, 1000)
            rows.append((name, n, _best(lambda p=path: read_rosbag(p), args.repeat)))
    print(f"{'reader':<24} {'messages':>9} {'seconds':>8} {'k msg/s':>8} {'CPU s':>7}")
    for name, n, (s, cpu) in rows:
        print(f"{name:<24} {n:>9} {s:>8.3f} {n / s / 1000:>8.0f} {cpu:>7.3f}")


if __name__ == "__main__":
    main()
