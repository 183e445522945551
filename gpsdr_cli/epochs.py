"""The epochs every filter reads: one drive's streams merged onto one time axis.

:class:`Epochs` is what :func:`gpsdr_cli.align.build_epochs` makes and every stage after
it (the GNSS model, the filters, the smoothers, the evaluation) reads.  It lives in a
module of its own, below all of them, so that each can import it without importing the
merge (and the merge can use the stages that only need its type, such as the RTK
false-fix check).  Units: ns since the epoch (UTC) for times, seconds, metres, ENU.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Epochs:
    """Arrays of equal length ``n``, one entry per epoch (the filters' input).

    GNSS (at epochs with a usable fix, NaN elsewhere):
      ``gnss_e, gnss_n`` m; ``gnss_sd_e, gnss_sd_n`` base 1-sigma in m (GST or
      covariance, else HDOP x UERE, else the default, floored); ``pdop`` at GNSS
      records (NaN elsewhere); ``gnss_speed_mps``, ``gnss_course_rad`` (clockwise
      from north) where the receiver gave them.
    DR: ``yaw_rate_radps`` (CCW-positive), ``odo_speed_mps``; NaN where absent.
    ``accel_mps2``: forward specific force (m/s^2, positive forward, gravity on a slope
    included) at the accelerometer's records, on the gyro's clock (``[time]
    gyro_offset_s``: one IMU), NaN elsewhere; ``has_accel`` marks them.  Both default to
    "none" (False / NaN) for code that builds epochs without them.
    ``dt_s[k]`` = t[k] - t[k-1] in seconds (``dt_s[0] = 0``).
    ``gnss_outage``: the epoch lies in a gap between usable fixes longer than
    ``gap_s`` (also before the first / after the last fix when that stretch is).
    """

    t_ns: np.ndarray
    dt_s: np.ndarray
    has_gnss: np.ndarray
    gnss_e: np.ndarray
    gnss_n: np.ndarray
    gnss_sd_e: np.ndarray
    gnss_sd_n: np.ndarray
    pdop: np.ndarray
    gnss_speed_mps: np.ndarray
    gnss_course_rad: np.ndarray
    has_gyro: np.ndarray
    yaw_rate_radps: np.ndarray
    has_odo: np.ndarray
    odo_speed_mps: np.ndarray
    gnss_outage: np.ndarray
    gap_s: float
    has_accel: np.ndarray | None = None
    accel_mps2: np.ndarray | None = None
    #: share of the usable fixes that are RTK fixed (GGA quality 4)
    rtk_fixed_share: float = 0.0
    #: the fix quality (NMEA GGA code: 4 RTK fixed, 5 float, ...) at the usable fixes, 0 elsewhere
    gnss_quality: np.ndarray | None = None
    #: the GNSS model's verdict (filters.gnss_model): the fixes disagree with the dead
    #: reckoning often enough for a drive with reflected signals (NLOS)
    nlos_drive: bool = False
    #: dr_health left gyro samples out, or odometer samples spanning ``[health] odo_silent_s``
    #: or more, or the odometer fell silent that long: the dead reckoning cannot judge the fixes
    dr_unhealthy: bool = False
    #: the drive with time running backwards (:func:`gpsdr_cli.qc.reverse_epochs`)
    time_reversed: bool = False
    #: share of the fixes with a Doppler speed and the odometer's (both above ``[gnss]
    #: nlos_velocity_min_mps``) whose two speeds differ by more than ``nlos_doppler_odo_max_mps``,
    #: read as the epochs are built, before any velocity is left out
    #: (:func:`gpsdr_cli.filters.gnss_model.doppler_off_share`); 0 without both
    doppler_off_share: float = 0.0

    def __post_init__(self) -> None:
        n = len(self.t_ns)
        if self.has_accel is None:
            self.has_accel = np.zeros(n, bool)
        if self.accel_mps2 is None:
            self.accel_mps2 = np.full(n, np.nan)
        if self.gnss_quality is None:
            self.gnss_quality = np.zeros(n, np.int8)

    def __len__(self) -> int:
        return len(self.t_ns)

    @property
    def n_gnss(self) -> int:
        return int(self.has_gnss.sum())

    @property
    def velocity_share(self) -> float:
        """Share of the usable fixes that carry the receiver's speed (RMC/VTG); 0 without fixes."""
        n_fix = self.n_gnss
        if n_fix == 0:
            return 0.0
        return float(np.count_nonzero(self.has_gnss & np.isfinite(self.gnss_speed_mps))) / n_fix


def true_runs(flag: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """First and last index (inclusive, ascending int arrays) of every run of True in ``flag``."""
    d = np.diff(np.concatenate(([0], np.asarray(flag, bool).astype(np.int8), [0])))
    return np.flatnonzero(d == 1), np.flatnonzero(d == -1) - 1
