"""The dead reckoning's known calibration, as the filters start from it.

``[graph] gyro_bias_radps``, ``odo_scale`` and ``gyro_scale`` are calibration priors: the user's
(``--gyro-bias``, ``--odo-scale``, ``--gyro-scale``, ``gpsdr batch --calibrate-per-vehicle``) or,
on a drive the NLOS screen judged, its whole-drive batch fit (:mod:`.nlos_screen`), which sees
every fix and every reading while a forward filter learns a drift from the fixes it has met
so far.  Conventions: ``yaw_measured = yaw_true + bias`` (rad/s, counter-clockwise positive),
``true speed = scale x odometer reading`` and ``true yaw rate = gyro scale x reading`` (the
pipeline multiplies the readings by a known gyro scale before any filter sees them).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from ..config import Params
from ..epochs import Epochs


def known_gyro_bias(epochs: Epochs, params: Params) -> float | None:
    """The known gyro bias (rad/s) in ``epochs``' own sense (a drive run backwards reads its
    yaw rates negated, and its bias with them), or None."""
    bias = float(params["graph"]["gyro_bias_radps"])
    if not math.isfinite(bias):
        return None
    return -bias if epochs.time_reversed else bias


def scaled_yaw(epochs: Epochs, factor: float) -> Epochs:
    """``epochs`` with the yaw rates multiplied by ``factor`` (a gyro scale correction 1 + g,
    or a sign or units the readings were misread by)."""
    return dataclasses.replace(epochs, yaw_rate_radps=factor * np.asarray(epochs.yaw_rate_radps))


def known_gyro_scale(params: Params) -> float | None:
    """The known gyro scale (true yaw rate over the reading), or None."""
    scale = float(params["graph"]["gyro_scale"])
    return scale if math.isfinite(scale) and scale > 0.0 else None


def known_odo_scale(params: Params) -> float | None:
    """The known odometer scale (true speed over the reading), or None."""
    scale = float(params["graph"]["odo_scale"])
    return scale if math.isfinite(scale) and scale > 0.0 else None
