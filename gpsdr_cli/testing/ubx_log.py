"""UBX logs written from a :class:`Drive` with pyubx2, as an F9R-like unit would log them.

NAV-PVT for each GNSS fix, ESF-MEAS for each gyro reading (data type 5) and each
odometer reading (type 11 speed, or 8/9 rear wheel ticks), in time order; the ESF time
tags run on a local millisecond clock ``local_offset_ms`` behind UTC, as a receiver's
does.  Used by the tests and benchmarks/read_ubx_rosbag.py.
"""

from __future__ import annotations

import math
import struct

import numpy as np
from pyubx2 import UBXMessage

from ..conventions import NS_PER_S
from ..io.drive import Drive

#: GGA quality -> (fixType, gnssFixOk, diffSoln, carrSoln)
_FIX = {0: (0, 0, 0, 0), 1: (3, 1, 0, 0), 2: (3, 1, 1, 0), 4: (3, 1, 1, 2), 5: (3, 1, 1, 1),
        6: (1, 0, 0, 0)}


def nav_pvt(t_ns: int, *, lat: float, lon: float, height_m: float = 50.0, quality: int = 1,
            h_acc_m: float = 1.0, ve: float = 0.0, vn: float = 0.0, num_sv: int = 12,
            pdop: float = 1.5, valid: bool = True) -> bytes:
    """One NAV-PVT frame at UTC ``t_ns`` (iTOW = GPS time of week, ms, 18 s leap)."""
    sec, ns = divmod(int(t_ns), NS_PER_S)
    d = np.datetime64(sec, "s").astype(object)
    fix_type, fix_ok, diff, carr = _FIX.get(quality, (3, 1, 0, 0))
    gps_s = sec - 315964800 + 18
    itow = (gps_s % (7 * 86400)) * 1000 + ns // 1_000_000
    ok = 1 if valid else 0
    m = UBXMessage("NAV", "NAV-PVT", 0, iTOW=itow, year=d.year, month=d.month, day=d.day,
                   hour=d.hour, min=d.minute, second=d.second, validDate=ok, validTime=ok,
                   fullyResolved=ok, nano=ns, fixType=fix_type, gnssFixOk=fix_ok,
                   diffSoln=diff, carrSoln=carr, numSV=num_sv, lat=lat, lon=lon,
                   height=round(height_m * 1000), hMSL=round((height_m - 30) * 1000),
                   hAcc=round(h_acc_m * 1000), vAcc=round(2 * h_acc_m * 1000),
                   velN=round(vn * 1000), velE=round(ve * 1000), gSpeed=round(math.hypot(ve, vn) * 1000),
                   headMot=math.degrees(math.atan2(ve, vn)) % 360, pDOP=pdop)
    return m.serialize()


def esf_meas(tag_ms: int, words: list[tuple[int, int]]) -> bytes:
    """ESF-MEAS with (data type, 24-bit field) words; the field is masked to 24 bits."""
    payload = struct.pack("<IHH", tag_ms & 0xFFFFFFFF, len(words) << 11, 0)
    payload += b"".join(struct.pack("<I", (t << 24) | (f & 0xFFFFFF)) for t, f in words)
    return UBXMessage("ESF", "ESF-MEAS", 0, payload=payload).serialize()


def ubx_log(drive: Drive, *, local_offset_ms: int = -1_234_567_890_123, ticks_per_m: float = 0.0,
            nmea_lines: list[str] | None = None) -> bytes:
    """The drive as a UBX byte stream (see the module docstring).  ``ticks_per_m`` > 0
    writes the odometer as rear wheel ticks instead of speed; ``nmea_lines`` are
    interleaved after each NAV-PVT in turn."""
    events: list[tuple[int, int, bytes]] = []
    g = drive.gnss
    if g is not None:
        for i in range(len(g)):
            q = int(g.fix_quality[i])
            if not np.isfinite(g.lat_deg[i]):
                q = 0
            sp = float(g.speed_mps[i]) if np.isfinite(g.speed_mps[i]) else 0.0
            co = math.radians(float(g.course_deg[i])) if np.isfinite(g.course_deg[i]) else 0.0
            sig = float(g.sigma_e_m[i]) * math.sqrt(2) if np.isfinite(g.sigma_e_m[i]) else 2.0
            frame = nav_pvt(int(g.t_ns[i]), lat=float(np.nan_to_num(g.lat_deg[i])),
                            lon=float(np.nan_to_num(g.lon_deg[i])),
                            height_m=float(np.nan_to_num(g.alt_m[i], nan=50.0)), quality=q,
                            h_acc_m=sig, ve=sp * math.sin(co), vn=sp * math.cos(co))
            if nmea_lines:
                frame += nmea_lines[i % len(nmea_lines)].encode() + b"\r\n"
            events.append((int(g.t_ns[i]), 0, frame))

    def tag(t: int) -> int:
        return t // 1_000_000 + local_offset_ms

    if drive.gyro is not None:
        for t, w in zip(drive.gyro.t_ns.tolist(), drive.gyro.yaw_rate_radps.tolist(), strict=False):
            # u-blox z is down: a counter-clockwise yaw rate is a negative gyro z
            events.append((t, 1, esf_meas(tag(t), [(5, round(-math.degrees(w) * 4096))])))
    if drive.accel is not None:
        for t, a in zip(drive.accel.t_ns.tolist(), drive.accel.accel_mps2.tolist(), strict=False):
            events.append((t, 1, esf_meas(tag(t), [(16, round(a * 1024))])))
    if drive.odo is not None:
        dist = 0.0
        last = None
        for t, v in zip(drive.odo.t_ns.tolist(), drive.odo.speed_mps.tolist(), strict=False):
            if ticks_per_m > 0:
                if last is not None:
                    dist += abs(v) * (t - last) / NS_PER_S
                last = t
                n = round(dist * ticks_per_m) % (1 << 23) | ((1 << 23) if v < 0 else 0)
                words = [(8, n), (9, n)]
            else:
                words = [(11, round(v * 1000))]
            events.append((t, 2, esf_meas(tag(t), words)))
    events.sort(key=lambda e: (e[0], e[1]))
    return b"".join(e[2] for e in events)
