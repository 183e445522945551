"""Forward/backward quality checks: an independent backward pass, the separation, a quality class.

Backward pass
    The same filter runs on the drive with time reversed (:func:`reverse_epochs`).
    Reversing time maps the vehicle to one driving backwards along the same path:
    ``t' = t_first + t_last - t`` (epochs in reverse order, so ``t'`` increases again
    and ``dt'`` is the forward step sequence reversed); heading ``psi' = psi + pi``
    (the GNSS course turned by pi); ``d(psi')/dt' = d(psi)/dt`` in value, but a
    reversed film turns the other way, so the yaw rate (CCW-positive) changes sign;
    speeds (odometer, receiver) are magnitudes and positions are where they were, so
    both stay; the forward accelerometer's axis turns round with the car, so its reading
    (specific force, gravity on a slope included) changes sign.  ``gnss_outage`` is
    symmetric in time (a gap is as long either way), PDOP and sigmas are attributes of
    an instant.  The filters' own standstill
    detection and their start at the first fix (``pipeline._run_once``'s lead-in,
    which dead-reckons the epochs before the first fix) see the reversed drive as
    any other: the backward lead-in is the forward tail after the last fix.  Every
    field of :class:`~gpsdr_cli.epochs.Epochs` not named here is reversed as is.
    The backward pass is never smoothed: forward and backward must not share data
    beyond the measurements, or their separation says nothing.

Separation
    ``separation_m = |p_forward - p_backward|`` (horizontal, m) per epoch, both
    passes unsmoothed.  Where the two agree, the drive's measurements tell one
    story; where they part (an outage, a multipath stretch, a time offset), at least
    one of them is wrong by about that much.  It is a consistency figure, not an
    error: two passes drifting the same way in a long outage agree and are both off.

Quality class (``quality``, int8, 1 best .. 6 worst; docs/qc.md)
    ``h = max(sqrt(sigma_e^2 + sigma_n^2), separation_m)`` (separation only where it
    was computed) is graded by the ``[qc] class_*_m`` thresholds: ``h <= class_1_m``
    is 1, ... , ``h <= class_5_m`` is 5, else 6.  The GNSS state then caps it: an
    epoch in a GNSS outage is at least ``outage_min_class``, in an outage longer
    than ``outage_long_s`` it is 6; where the latest fix at or before the epoch was
    rejected by the innovation gate (and no fix was applied since), it is at least
    ``rejected_min_class``.

Written here rather than taken from a library: the reversal is specific to our epoch
layout, and the class table is our own documented convention (docs/qc.md).
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING

import numpy as np

from .conventions import NS_PER_S
from .epochs import Epochs, true_runs

if TYPE_CHECKING:
    import pandas as pd

    from .config import Params
    from .filters.base import FilterResult

#: quality classes, best to worst
QUALITY_CLASSES: tuple[int, ...] = (1, 2, 3, 4, 5, 6)


def reverse_epochs(epochs: Epochs) -> Epochs:
    """The same drive with time running backwards (see the module docstring).

    ``t' = t_first + t_last - t`` (int64 ns, ascending again); ``dt_s`` from ``t'``;
    ``yaw_rate_radps`` negated; ``gnss_course_rad`` + pi wrapped to (-pi, pi];
    ``accel_mps2`` negated (the car drives backwards: its forward axis turns round, and
    the specific force along it, gravity on a slope included, changes sign); every other
    per-epoch array reversed as is; ``time_reversed`` toggled.
    """
    n_ep = len(epochs)
    fields: dict[str, object] = {}
    made_below = ("t_ns", "dt_s", "yaw_rate_radps", "gnss_course_rad", "accel_mps2")
    for f in dataclasses.fields(Epochs):
        value = getattr(epochs, f.name)
        if f.name not in made_below:
            fields[f.name] = value[::-1].copy() if isinstance(value, np.ndarray) else value
    t = np.asarray(epochs.t_ns, np.int64)
    t_rev = (t[0] + t[-1]) - t[::-1] if n_ep else t.copy()
    fields["t_ns"] = t_rev
    dt = np.zeros(n_ep)
    if n_ep > 1:
        dt[1:] = np.diff(t_rev) / NS_PER_S
    fields["dt_s"] = dt
    fields["yaw_rate_radps"] = -np.asarray(epochs.yaw_rate_radps, float)[::-1]
    fields["accel_mps2"] = -np.asarray(epochs.accel_mps2, float)[::-1]
    course = np.asarray(epochs.gnss_course_rad, float)[::-1] + math.pi
    fields["gnss_course_rad"] = np.angle(np.exp(1j * course))  # NaN stays NaN
    fields["time_reversed"] = not epochs.time_reversed
    return Epochs(**fields)  # type: ignore[arg-type]


def reverse_result_positions(result: FilterResult) -> tuple[np.ndarray, np.ndarray,
                                                            np.ndarray, np.ndarray]:
    """A backward pass's ``(e, n, var_e, var_n)`` back in forward epoch order (m, m^2)."""
    return (np.asarray(result.e, float)[::-1], np.asarray(result.n, float)[::-1],
            np.asarray(result.var_e, float)[::-1], np.asarray(result.var_n, float)[::-1])


def separation(e_fwd: np.ndarray, n_fwd: np.ndarray, e_bwd: np.ndarray,
               n_bwd: np.ndarray) -> np.ndarray:
    """Horizontal distance (m) between two solutions at each epoch; NaN where one is not finite."""
    return np.hypot(np.asarray(e_fwd, float) - e_bwd, np.asarray(n_fwd, float) - n_bwd)


def _latest_fix_rejected(used: np.ndarray, rejected: np.ndarray) -> np.ndarray:
    """True where the latest fix at or before the epoch (applied or rejected) was rejected."""
    seen = used | rejected
    if not seen.any():
        return np.zeros(len(used), bool)
    last = np.maximum.accumulate(np.where(seen, np.arange(len(used)), -1))
    return (last >= 0) & rejected[np.maximum(last, 0)]


def quality_class(sigma_h_m: np.ndarray, separation_m: np.ndarray | None, gnss_used: np.ndarray,
                  gnss_rejected: np.ndarray, gnss_outage: np.ndarray, t_ns: np.ndarray,
                  qc: dict) -> np.ndarray:
    """The per-epoch quality class (int8, 1 best .. 6 worst) by the ``[qc]`` thresholds.

    ``sigma_h_m``: horizontal 1-sigma sqrt(sigma_e^2 + sigma_n^2) (m); ``separation_m``:
    forward/backward separation (m) or None; the GNSS flags per epoch; ``t_ns`` int64 ns.
    A non-finite figure counts as worst (6).
    """
    h = np.asarray(sigma_h_m, float).copy()
    if separation_m is not None:
        s = np.asarray(separation_m, float)
        h = np.where(np.isfinite(s), np.maximum(h, s), np.inf)
    h = np.where(np.isfinite(h), h, np.inf)
    bounds = np.array([float(qc[f"class_{k}_m"]) for k in range(1, 6)])
    if np.any(np.diff(bounds) < 0):
        from .errors import ConfigError

        raise ConfigError(f"[qc] class_1_m .. class_5_m = {bounds.tolist()}: expected ascending")
    cls = (1 + np.searchsorted(bounds, h, side="left")).astype(np.int8)  # h <= bound_k -> k
    outage = np.asarray(gnss_outage, bool)
    cls = np.where(outage, np.maximum(cls, int(qc["outage_min_class"])), cls)
    t = np.asarray(t_ns, np.int64)
    long_s = float(qc["outage_long_s"])
    for i0, i1 in zip(*true_runs(outage), strict=True):
        before = i0 - 1 if i0 > 0 else i0     # the outage lasts from the last fix
        after = i1 + 1 if i1 + 1 < len(t) else i1
        if (t[after] - t[before]) / NS_PER_S > long_s:
            cls[i0:i1 + 1] = 6
    rej = _latest_fix_rejected(np.asarray(gnss_used, bool), np.asarray(gnss_rejected, bool))
    cls = np.where(rej, np.maximum(cls, int(qc["rejected_min_class"])), cls)
    return np.clip(cls, 1, 6).astype(np.int8)


def track_quality(track: pd.DataFrame, qc: dict) -> np.ndarray:
    """:func:`quality_class` of a track table (its sigma, separation and GNSS columns)."""
    from .evaluation import _t_ns_of

    m = len(track)

    def flag(name: str) -> np.ndarray:
        return track[name].fillna(False).to_numpy(bool) if name in track else np.zeros(m, bool)

    sig_h = np.hypot(track["sigma_e"].to_numpy(float), track["sigma_n"].to_numpy(float))
    sep = track["separation_m"].to_numpy(float) if "separation_m" in track else None
    return quality_class(sig_h, sep, flag("gnss_used"), flag("gnss_rejected"),
                         flag("gnss_outage"), _t_ns_of(track, "track"), qc)


def qc_enabled(params: Params) -> bool:
    """True when ``[qc] backward_pass`` asks for the backward pass and the separation."""
    return bool(params["qc"]["backward_pass"])


__all__ = ["QUALITY_CLASSES", "quality_class", "reverse_epochs", "reverse_result_positions",
           "separation", "track_quality"]
