"""The one structure every reader returns: a :class:`Drive`.

Per stream: int64 nanosecond UTC times (see :mod:`gpsdr_cli.conventions`) and
SI values in numpy arrays of equal length, in the order the records were read
(not yet sorted or de-duplicated: :mod:`gpsdr_cli.align` does that and counts
what it drops).  Plus a :class:`SkipReport` of every record a reader skipped.
"""

from __future__ import annotations

from collections import Counter
from dataclasses import dataclass, field

import numpy as np


def _f64(n: int) -> np.ndarray:
    return np.full(n, np.nan)


@dataclass
class GnssFixes:
    """GNSS position fixes, one row per receiver epoch.

    ``fix_quality`` 0 marks an epoch without a fix (an outage): its lat/lon are NaN,
    never zero.  Codes are NMEA GGA's for every reader: 1 autonomous, 2 DGPS/SBAS,
    3 PPS, 4 RTK fixed, 5 RTK float, 6 the receiver's own dead reckoning (not a fix),
    7 manual, 8 simulator.  Other formats map onto them (UBX carrSoln, NavSatFix
    status, RTKLIB Q).  Unknown values are NaN (floats) or -1 (``n_sats``).
    ``sigma_e_m``/``sigma_n_m``: 1-sigma horizontal errors reported by the
    receiver (NMEA GST, or a NavSatFix covariance), metres.
    ``speed_mps``/``course_deg``: RMC/VTG ground speed and course over ground
    (deg clockwise from true north).
    """

    t_ns: np.ndarray
    lat_deg: np.ndarray
    lon_deg: np.ndarray
    alt_m: np.ndarray
    fix_quality: np.ndarray  # int8
    n_sats: np.ndarray  # int16, -1 unknown
    hdop: np.ndarray
    pdop: np.ndarray
    vdop: np.ndarray
    sigma_e_m: np.ndarray
    sigma_n_m: np.ndarray
    speed_mps: np.ndarray
    course_deg: np.ndarray

    @classmethod
    def empty(cls, n: int = 0) -> GnssFixes:
        return cls(
            t_ns=np.zeros(n, np.int64), lat_deg=_f64(n), lon_deg=_f64(n), alt_m=_f64(n),
            fix_quality=np.zeros(n, np.int8), n_sats=np.full(n, -1, np.int16),
            hdop=_f64(n), pdop=_f64(n), vdop=_f64(n), sigma_e_m=_f64(n), sigma_n_m=_f64(n),
            speed_mps=_f64(n), course_deg=_f64(n),
        )

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def valid(self) -> np.ndarray:
        """Boolean mask of epochs with a usable fix."""
        return (self.fix_quality > 0) & np.isfinite(self.lat_deg) & np.isfinite(self.lon_deg)


@dataclass
class YawRates:
    """Gyro yaw rate about the vehicle's up axis, rad/s, positive counter-clockwise."""

    t_ns: np.ndarray
    yaw_rate_radps: np.ndarray

    def __len__(self) -> int:
        return len(self.t_ns)


@dataclass
class Odometry:
    """Vehicle speed along its forward axis, m/s (distance and ticks are converted on read)."""

    t_ns: np.ndarray
    speed_mps: np.ndarray

    def __len__(self) -> int:
        return len(self.t_ns)


@dataclass
class ForwardAccel:
    """Specific force along the vehicle's forward axis, m/s^2, positive forward.

    What an accelerometer measures: on a slope it includes ``g sin(pitch)`` (the car
    climbing reads positive while at constant speed), and a constant bias.
    """

    t_ns: np.ndarray
    accel_mps2: np.ndarray

    def __len__(self) -> int:
        return len(self.t_ns)


#: The reason prefix of records a reader left out on purpose (standard sentences it does not
#: use: "not used: GSV (satellites in view)"), not because they were damaged.
NOT_USED = "not used:"
#: The reason prefix of well-formed records of a kind the reader does not know (a receiver's
#: proprietary sentences mostly: "unknown sentence (proprietary $P...)"): neither damaged nor
#: left out on purpose.
UNKNOWN = "unknown sentence"


@dataclass
class SkipReport:
    """Records a reader skipped, counted by reason, with the first place each occurred."""

    counts: Counter = field(default_factory=Counter)
    first: dict[str, str] = field(default_factory=dict)

    def add(self, reason: str, where: str = "", n: int = 1) -> None:
        if n <= 0:
            return
        self.counts[reason] += n
        self.first.setdefault(reason, where)

    def merge(self, other: SkipReport) -> None:
        for reason, n in other.counts.items():
            self.add(reason, other.first.get(reason, ""), n)

    @property
    def total(self) -> int:
        return int(sum(self.counts.values()))


@dataclass
class Source:
    """An input file: its path, SHA-256 and which streams it supplied."""

    path: str
    sha256: str
    streams: tuple[str, ...] = ()


@dataclass
class Drive:
    """Everything read from one drive's logs."""

    gnss: GnssFixes | None = None
    gyro: YawRates | None = None
    odo: Odometry | None = None
    #: Forward accelerometer (optional: UBX ESF-MEAS, sensor_msgs/Imu linear_acceleration.x,
    #: or an ``acc_x`` CSV column).
    accel: ForwardAccel | None = None
    skipped: SkipReport = field(default_factory=SkipReport)
    sources: list[Source] = field(default_factory=list)
    #: Free-form facts a reader found (e.g. NMEA sentence counts, MCAP channels).
    meta: dict = field(default_factory=dict)

    def merge(self, other: Drive) -> None:
        """Take the streams ``other`` has and this drive lacks; add its report and sources."""
        for name in ("gnss", "gyro", "odo", "accel"):
            if getattr(self, name) is None and getattr(other, name) is not None:
                setattr(self, name, getattr(other, name))
        self.skipped.merge(other.skipped)
        self.sources.extend(other.sources)
        for k, v in other.meta.items():
            self.meta.setdefault(k, v)


def stream_source(drive: Drive, name: str) -> str:
    """The file that supplied stream ``name`` (its Source path), or ``""`` when unknown."""
    named = [s.path for s in drive.sources if name in s.streams]
    if named:
        return named[0]
    unnamed = [s.path for s in drive.sources if not s.streams]
    return unnamed[0] if len(unnamed) == 1 else ""
