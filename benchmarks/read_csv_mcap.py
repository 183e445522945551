"""Reader throughput: gyro/odometer CSV, MCAP (ROS 2 CDR) and NMEA.

Generates a one-hour drive in a temporary directory -- MCAP with 5 Hz
NavSatFix, 100 Hz Imu and 100 Hz TwistStamped; 100 Hz gyro and odometer CSVs;
5 Hz NMEA (GGA + RMC + GSA + GST) -- then times each reader (best of
``--repeat`` runs) and prints a table.  Targets: CSV >= 2 M rows/s, MCAP >= 300 k
msg/s.  Also times mcap_ros2's generic decoder on the same MCAP for comparison.

    .venv/bin/python benchmarks/read_csv_mcap.py [--hours 1] [--repeat 3]
"""

from __future__ import annotations

import argparse
import math
import tempfile
import time
from pathlib import Path

import numpy as np

from gpsdr_cli import config
from gpsdr_cli.io import ros2_fast
from gpsdr_cli.io.csv import read_gyro_csv, read_odo_csv
from gpsdr_cli.io.mcap import read_mcap

T0_NS = 1_700_000_000_000_000_000


def _nmea_checksum(body: str) -> str:
    c = 0
    for ch in body.encode():
        c ^= ch
    return f"${body}*{c:02X}"


def _dm(value: float, deg_digits: int) -> str:
    a = abs(value)
    d = int(a)
    return f"{d:0{deg_digits}d}{(a - d) * 60:08.5f}"


def generate(out: Path, hours: float, seed: int = 1) -> dict[str, int]:
    """Write drive.mcap, gyro.csv, odo.csv and gps.nmea; return the record counts."""
    from mcap.writer import CompressionType, Writer

    rng = np.random.default_rng(seed)
    n100 = int(hours * 3600 * 100)
    n5 = int(hours * 3600 * 5)
    t100 = T0_NS + np.arange(n100, dtype=np.int64) * 10_000_000
    t5 = T0_NS + np.arange(n5, dtype=np.int64) * 200_000_000
    wz = 0.05 * np.sin(np.arange(n100) / 3000.0) + rng.normal(0, 0.002, n100)
    v = 12.0 + 3.0 * np.sin(np.arange(n100) / 5000.0)
    lat = 54.4 + np.cumsum(np.full(n5, 2e-6))
    lon = 18.6 + np.cumsum(np.full(n5, 1e-6))

    with open(out / "drive.mcap", "wb") as f:
        w = Writer(f, compression=CompressionType.ZSTD)
        w.start(profile="ros2", library="gpsdr benchmark")
        ids = {}
        for layout, topic in (("navsatfix", "/fix"), ("imu", "/imu"), ("twist", "/vel")):
            name, text = ros2_fast.SCHEMAS[layout]
            sid = w.register_schema(name, "ros2msg", text.encode())
            ids[layout] = w.register_channel(topic, "cdr", sid)
        events = [(int(t), "navsatfix", i) for i, t in enumerate(t5)]
        events += [(int(t), "imu", i) for i, t in enumerate(t100)]
        events += [(int(t) + 1, "twist", i) for i, t in enumerate(t100)]
        events.sort()
        cov = (1.0, 0, 0, 0, 1.0, 0, 0, 0, 4.0)
        for t, layout, i in events:
            if layout == "navsatfix":
                msg = ros2_fast.encode(layout, t, "gps", lat=lat[i], lon=lon[i], alt=30.0, cov=cov,
                                       cov_type=2)
            elif layout == "imu":
                msg = ros2_fast.encode(layout, t, "imu_link", wz=wz[i])
            else:
                msg = ros2_fast.encode(layout, t - 1, "base_link", vx=v[i])
            w.add_message(ids[layout], log_time=t, data=msg, publish_time=t)
        w.finish()

    np.savetxt(out / "gyro.csv", np.column_stack([t100 / 1e9, wz]), fmt=["%.6f", "%.7f"],
               delimiter=",", header="t,yaw_rate", comments="")
    np.savetxt(out / "odo.csv", np.column_stack([t100 / 1e9, v]), fmt=["%.6f", "%.5f"],
               delimiter=",", header="t,speed", comments="")

    lines = []
    for i, t in enumerate(t5):
        sod = (t // 1_000_000) % 86_400_000_000 / 1e6
        hh, mm, ss = int(sod // 3600), int(sod % 3600 // 60), sod % 60
        hms = f"{hh:02d}{mm:02d}{ss:05.2f}"
        la, lo = _dm(lat[i], 2), _dm(lon[i], 3)
        lines.append(_nmea_checksum(f"GPGGA,{hms},{la},N,{lo},E,1,09,0.9,30.0,M,32.0,M,,"))
        lines.append(_nmea_checksum(f"GPRMC,{hms},A,{la},N,{lo},E,23.3,26.6,141123,,,A"))
        lines.append(_nmea_checksum("GPGSA,A,3,04,05,09,12,24,25,29,31,,,,,1.8,0.9,1.5"))
        lines.append(_nmea_checksum(f"GPGST,{hms},1.2,0.9,0.7,45.0,0.8,0.9,1.6"))
    (out / "gps.nmea").write_text("\r\n".join(lines) + "\r\n")
    return {"gyro_rows": n100, "odo_rows": n100, "mcap_msgs": n5 + 2 * n100, "nmea_lines": 4 * n5}


def best_time(fn, repeat: int) -> float:
    best = math.inf
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return best


def generic_decoder_rate(path: Path, limit: int) -> float:
    """mcap_ros2's generic decoder on the first ``limit`` messages, msg/s."""
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    with open(path, "rb") as f:
        r = make_reader(f, decoder_factories=[DecoderFactory()])
        n = 0
        t0 = time.perf_counter()
        for _ in r.iter_decoded_messages():
            n += 1
            if n >= limit:
                break
        return n / (time.perf_counter() - t0)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=1.0)
    ap.add_argument("--repeat", type=int, default=3)
    args = ap.parse_args()
    params = config.defaults()
    with tempfile.TemporaryDirectory() as tmp:
        d = Path(tmp)
        t0 = time.perf_counter()
        counts = generate(d, args.hours)
        print(f"generated {args.hours:g} h drive in {time.perf_counter() - t0:.1f} s "
              f"(MCAP {(d / 'drive.mcap').stat().st_size / 1e6:.1f} MB)")
        rows = [
            ("gyro CSV", counts["gyro_rows"], "rows",
             lambda: read_gyro_csv(d / "gyro.csv", params["gyro"])),
            ("odo CSV", counts["odo_rows"], "rows",
             lambda: read_odo_csv(d / "odo.csv", params["odo"])),
            ("MCAP (CDR fast path)", counts["mcap_msgs"], "msgs",
             lambda: read_mcap(d / "drive.mcap")),
        ]
        try:
            from gpsdr_cli.io.nmea import read_nmea
        except ImportError:
            read_nmea = None
        if read_nmea is not None:
            rows.append(("NMEA (GGA+RMC+GSA+GST)", counts["nmea_lines"], "lines",
                         lambda: read_nmea(d / "gps.nmea")))
        print(f"{'reader':<26}{'records':>10}{'seconds':>10}{'rate':>16}")
        for name, n, unit, fn in rows:
            s = best_time(fn, args.repeat)
            print(f"{name:<26}{n:>10}{s:>10.3f}{n / s / 1e6:>11.2f} M {unit}/s")
        g = generic_decoder_rate(d / "drive.mcap", 50_000)
        print(f"{'MCAP (mcap_ros2 generic)':<26}{50_000:>10}{50_000 / g:>10.3f}{g / 1e6:>11.3f} M msgs/s")


if __name__ == "__main__":
    main()
