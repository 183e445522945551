"""ROS bags written from a :class:`Drive` with rosbags' writers (fault suite, tests).

NavSatFix for the fixes, Imu (angular_velocity.z) for the gyro and TwistStamped
(linear.x) for the odometer, serialised by :func:`gpsdr_cli.io.ros2_fast.encode`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..io import ros2_fast
from ..io.drive import Drive


def write_rosbag(drive: Drive, path: str | Path, *, ros1: bool = False) -> Path:
    """The drive as a ROS 1 ``.bag`` (``ros1``) or a ROS 2 SQLite bag folder at ``path``."""
    from rosbags.rosbag1 import Writer as Writer1
    from rosbags.rosbag2 import Writer as Writer2
    from rosbags.typesys import Stores, get_typestore

    path = Path(path)
    ts = get_typestore(Stores.ROS1_NOETIC if ros1 else Stores.ROS2_HUMBLE)
    w = Writer1(path) if ros1 else Writer2(path, version=9)
    w.open()
    events: list[tuple[int, object, bytes]] = []
    g = drive.gnss
    if g is not None:
        c = w.add_connection("/fix", "sensor_msgs/msg/NavSatFix", typestore=ts)
        for i in range(len(g)):
            ok = bool(g.fix_quality[i] > 0 and np.isfinite(g.lat_deg[i]))
            var = float(g.sigma_e_m[i]) ** 2 if np.isfinite(g.sigma_e_m[i]) else 4.0
            events.append((int(g.t_ns[i]), c, ros2_fast.encode(
                "navsatfix", int(g.t_ns[i]), "gps", ros1=ros1, status=0 if ok else -1,
                lat=float(np.nan_to_num(g.lat_deg[i])), lon=float(np.nan_to_num(g.lon_deg[i])),
                alt=float(np.nan_to_num(g.alt_m[i])), cov=(var, 0, 0, 0, var, 0, 0, 0, 4 * var),
                cov_type=2)))
    if drive.gyro is not None:
        c = w.add_connection("/imu", "sensor_msgs/msg/Imu", typestore=ts)
        for t, wz in zip(drive.gyro.t_ns.tolist(), drive.gyro.yaw_rate_radps.tolist(), strict=False):
            events.append((t, c, ros2_fast.encode("imu", t, "imu", ros1=ros1, wz=wz)))
    if drive.odo is not None:
        c = w.add_connection("/vel", "geometry_msgs/msg/TwistStamped", typestore=ts)
        for t, v in zip(drive.odo.t_ns.tolist(), drive.odo.speed_mps.tolist(), strict=False):
            events.append((t, c, ros2_fast.encode("twist", t, "base", ros1=ros1, vx=v)))
    events.sort(key=lambda e: e[0])
    for t, c, raw in events:
        w.write(c, t, raw)
    w.close()
    return path
