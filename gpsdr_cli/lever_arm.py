"""The GNSS antenna's lever arm: fixes moved from the antenna to the vehicle reference point.

The arm ``(fwd, left, up)`` (m, vehicle frame; ``[gnss] lever_arm_m``, ``--lever-arm``)
goes from the vehicle reference point to the antenna, so with heading ``h`` (clockwise
from north) the antenna is at ``p_ant = p_ref + R(h) arm`` with, in (east, north),
the forward unit vector ``(sin h, cos h)`` and the left unit vector ``(-cos h, sin h)``::

    d_e = fwd sin h - left cos h
    d_n = fwd cos h + left sin h
    p_ref = p_ant - (d_e, d_n)

``up`` is accepted and recorded in the file metadata but moves nothing: the track is
horizontal, and with no pitch or roll estimate the horizontal part of a vertical arm
(``up sin(pitch)``) is unknown and ignored.

The backward pass of :mod:`gpsdr_cli.qc` runs on the corrected fixes (those of the
last forward pass), so its separation does not see the arm.

How it enters the filters (honestly): not through their measurement model.  The
kernels' GNSS row is ``h(x) = p``; instead the filter runs once on the fixes as
logged, its heading at each fix epoch (``atan2(v_e, v_n)``, the constant-speed
model has no heading state; below ``lever_arm_min_speed_mps`` the last heading at
speed is held, the first one before any) turns the arm, each fix is shifted by
``-R(h) arm``, and the filter runs again on the shifted fixes (``lever_arm_passes``
times, 1 or 2).  So the arm enters through the fixes with the heading of the
previous pass.  Why that converges: the shift's error is ``|arm| x`` the heading
error of the previous pass.  A first pass on antenna fixes is off in heading mainly
in turns, by about the antenna's sideways speed over the vehicle's,
``atan(yaw_rate x fwd / speed)`` (1.5 m ahead at 0.3 rad/s and 5 m/s: 5 deg, a
13 cm shift error), and a pass on corrected fixes carries the filter's own heading
error only, so a second pass changes the fixes by millimetres.  Heading where the
vehicle stands or creeps is held from the last motion, where it is right unless the
vehicle turned in place.

Written here, not taken from a library: the rotation is two lines; what matters is
the pass structure around our filters.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from typing import TYPE_CHECKING

import numpy as np

from .errors import UsageError

if TYPE_CHECKING:
    from .config import Params
    from .epochs import Epochs
    from .filters.base import FilterResult


def parse_lever_arm(text: str) -> list[float]:
    """``"FWD,LEFT[,UP]"`` (metres) -> ``[fwd, left, up]``; a clear error otherwise."""
    parts = [p.strip() for p in str(text).split(",")]
    try:
        vals = [float(p) for p in parts]
    except ValueError as err:
        raise UsageError(f"--lever-arm {text!r}: expected FWD,LEFT[,UP] in metres, "
                         "e.g. 1.5,0 or 1.5,-0.3,1.2") from err
    if not 2 <= len(vals) <= 3 or not all(math.isfinite(v) for v in vals):
        raise UsageError(f"--lever-arm {text!r}: expected two or three finite numbers "
                         "FWD,LEFT[,UP] in metres")
    return vals + [0.0] * (3 - len(vals))


def arm_of(params: Params) -> tuple[float, float, float] | None:
    """``(fwd, left, up)`` from ``[gnss] lever_arm_m``; None when its horizontal part is zero."""
    arm = [float(v) for v in params["gnss"]["lever_arm_m"]] + [0.0, 0.0, 0.0]
    fwd, left, up = arm[:3]
    if not all(math.isfinite(v) for v in (fwd, left, up)):
        raise UsageError(f"[gnss] lever_arm_m = {params['gnss']['lever_arm_m']}: expected finite metres")
    if fwd == 0.0 and left == 0.0:
        return None
    return fwd, left, up


def antenna_offset_en(heading_rad: np.ndarray, fwd_m: float, left_m: float
                      ) -> tuple[np.ndarray, np.ndarray]:
    """``R(h) arm`` in (east, north) metres: antenna minus reference point at heading ``h``
    (rad, clockwise from north)."""
    h = np.asarray(heading_rad, float)
    s, c = np.sin(h), np.cos(h)
    return fwd_m * s - left_m * c, fwd_m * c + left_m * s


def held_heading(v_e: np.ndarray, v_n: np.ndarray, min_speed_mps: float) -> np.ndarray:
    """Heading (rad, clockwise from north) of the velocity where its speed is at least
    ``min_speed_mps``; elsewhere the last such heading, the first one before any; NaN
    when the vehicle never reaches that speed."""
    v_e = np.asarray(v_e, float)
    v_n = np.asarray(v_n, float)
    ok = np.hypot(v_e, v_n) >= min_speed_mps
    ok &= np.isfinite(v_e) & np.isfinite(v_n)
    h = np.arctan2(v_e, v_n)
    if not ok.any():
        return np.full(len(v_e), np.nan)
    last = np.maximum.accumulate(np.where(ok, np.arange(len(ok)), -1))
    return h[np.where(last >= 0, last, int(np.argmax(ok)))]


def corrected_epochs(antenna: Epochs, result: FilterResult, arm: tuple[float, float, float],
                     min_speed_mps: float) -> Epochs:
    """``antenna``'s fixes moved to the reference point with ``result``'s heading."""
    h = held_heading(result.v_e, result.v_n, min_speed_mps)
    d_e, d_n = antenna_offset_en(np.nan_to_num(h), arm[0], arm[1])
    known = np.isfinite(h)
    # no heading at all (the vehicle never moved): the fixes stay where they are
    d_e = np.where(known, d_e, 0.0)
    d_n = np.where(known, d_n, 0.0)
    return dataclasses.replace(antenna, gnss_e=antenna.gnss_e - d_e, gnss_n=antenna.gnss_n - d_n)


def apply(epochs: Epochs, params: Params, arm: tuple[float, float, float],
          run: Callable[[Epochs, Params], FilterResult]) -> tuple[Epochs, FilterResult]:
    """Run ``run`` on the antenna fixes, then ``[gnss] lever_arm_passes`` times on fixes
    corrected with the previous pass's heading; return the corrected epochs and the last
    result (the track at the reference point)."""
    passes = int(params["gnss"]["lever_arm_passes"])
    if passes not in (1, 2):
        raise UsageError(f"[gnss] lever_arm_passes = {passes}: expected 1 or 2")
    min_speed = float(params["gnss"]["lever_arm_min_speed_mps"])
    result = run(epochs, params)
    corrected = epochs
    for _ in range(passes):
        corrected = corrected_epochs(epochs, result, arm, min_speed)
        result = run(corrected, params)
    return corrected, result


__all__ = ["antenna_offset_en", "apply", "arm_of", "corrected_epochs", "held_heading",
           "parse_lever_arm"]
