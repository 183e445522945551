"""What every filter returns: :class:`FilterResult`, one entry per epoch.

Conventions: :mod:`gpsdr_cli.conventions` (metres, ENU local frame, seconds).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

#: Upper bound (m/s) on the speed over a step no sensor measured (before the first fix
#: without an odometer, a lead-in without any sensor).
MAX_SPEED_MPS = 60.0


@dataclass
class FilterResult:
    """Per-epoch estimates, arrays of length ``n`` aligned with the input Epochs.

    ``e, n`` m; ``v_e, v_n`` m/s; ``var_e, var_n, cov_en`` m^2 (position block of P,
    after smoothing when the filter was asked to smooth);
    ``gnss_used``: a GNSS fix was applied at this epoch;
    ``gnss_rejected``: a fix was present but the innovation gate rejected it;
    ``nis``: normalised innovation squared of the GNSS update (2 dof), NaN where none;
    ``static``: standstill detected (zero-velocity update applied).
    ``extras``: filter-specific per-epoch arrays (e.g. ``gyro_bias_radps``,
    ``odo_scale``, ``a_e``, ``a_n``, fusion weights).
    ``info``: counters and scalars (e.g. ``gnss_rejected``, ``smoothed``).
    """

    t_ns: np.ndarray
    e: np.ndarray
    n: np.ndarray
    v_e: np.ndarray
    v_n: np.ndarray
    var_e: np.ndarray
    var_n: np.ndarray
    cov_en: np.ndarray
    gnss_used: np.ndarray
    gnss_rejected: np.ndarray
    nis: np.ndarray
    static: np.ndarray
    extras: dict[str, np.ndarray] = field(default_factory=dict)
    info: dict = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.t_ns)
