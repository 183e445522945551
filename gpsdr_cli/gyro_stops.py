"""Is this drive's gyro bias steady?  Read from what the gyro says at the stops.

The filters' default gyro model lets the bias wander (``[gyro] bias_sd_radps`` over
``bias_tau_s``: a cheap MEMS gyro's, whose scale error and temperature drift also read as
wander).  An automotive yaw-rate sensor on a CAN bus holds one bias over a drive: issue 14's
real city drive dead-reckons its 283 s within 1.4 m with one bias and one speed scale.  A
loose bias walk then only lets a run of reflected fixes bend the dead reckoning.  Which of
the two a drive has is measured where the truth is known: standing still, the gyro reads
its bias (and its noise).

At every stop (odometer below ``[standstill] speed_mps`` for ``STOP_MIN_S`` or more, its
first and last ``STOP_TRIM_S`` left out: a CAN speed reads zero while the car still
creeps), the mean yaw rate and its standard error (the readings' scatter over the root of
their number).  Between consecutive stops the bias moves by N(0, se_a^2 + se_b^2 + q dt)
with q = 2 sd^2 / tau.  The drive's gyro is steady when, over at least ``MIN_STOPS`` stops,
the steady model's q (``[gyro] steady_bias_sd_radps``) explains the moves (their
chi-square below its 95 % point) and is likelier than the default's.  Then every filter and
the graph smoother take that tighter bias walk for this drive.  A drive without an odometer,
or with fewer stops, keeps the default.

On forty simulated 283-s city drives (5-Hz CAN rates), with the simulator's wandering gyro
2 are judged steady (a 95 % test's false alarms); with its bias held constant, 27 (of the
28 with three stops or more; docs/decisions/0060).

Off by default (``[gyro] steady_from_stops = false``): a bias that holds at the stops says
nothing of the gyro's scale, and the loose walk also absorbs a scale error while turning.
With the bias held constant and a scale error of 3 % (a phone's), the tight walk took 5 of
the forty drives above their fixes, against 2 with the loose one.  Units: rad/s, seconds.
"""

from __future__ import annotations

import copy
import math

import numpy as np

from .config import Params
from .conventions import NS_PER_S
from .epochs import Epochs, true_runs

#: a stop counts when the odometer reads still for at least this long (s), after the trim
STOP_MIN_S = 3.0
#: the first and last seconds of a stop are left out (s)
STOP_TRIM_S = 1.0
#: a stop's mean needs at least this many gyro readings
STOP_MIN_READINGS = 10
#: at least this many stops (so two moves between them) to judge
MIN_STOPS = 3


def _chi2_95(k: int) -> float:
    """The chi-square distribution's 95 % point at ``k`` degrees of freedom (Wilson and
    Hilferty's cube-root normal approximation: 7.78 for 3 against scipy.stats.chi2.ppf's
    7.815, within 1 % from 2 degrees on)."""
    c = 2.0 / (9.0 * k)
    return k * (1.0 - c + 1.6449 * math.sqrt(c)) ** 3


def stop_biases(epochs: Epochs, params: Params) -> list[tuple[float, float, float]]:
    """Per stop, in time order: (middle time s, mean yaw rate rad/s, its standard error rad/s)."""
    if not (epochs.has_odo.any() and epochs.has_gyro.any()):
        return []
    t_s = (np.asarray(epochs.t_ns, np.int64) - int(epochs.t_ns[0])) / NS_PER_S
    has_odo = epochs.has_odo & np.isfinite(epochs.odo_speed_mps)
    last = np.maximum.accumulate(np.where(has_odo, np.arange(len(t_s)), -1))
    speed = np.where(last >= 0, epochs.odo_speed_mps[np.maximum(last, 0)], np.nan)
    with np.errstate(invalid="ignore"):
        still = np.abs(speed) < float(params["standstill"]["speed_mps"])
    gyro = epochs.has_gyro & np.isfinite(epochs.yaw_rate_radps)
    out = []
    for a, b in zip(*true_runs(still), strict=True):
        t0, t1 = t_s[a] + STOP_TRIM_S, t_s[b] - STOP_TRIM_S
        if t1 - t0 < STOP_MIN_S:
            continue
        i0, i1 = np.searchsorted(t_s, [t0, t1])
        y = epochs.yaw_rate_radps[i0:i1 + 1][gyro[i0:i1 + 1]]
        if len(y) < STOP_MIN_READINGS:
            continue
        out.append((0.5 * (t0 + t1), float(np.mean(y)), float(np.std(y, ddof=1) / math.sqrt(len(y)))))
    return out


def judge(stops: list[tuple[float, float, float]], q_steady: float, q_default: float
          ) -> tuple[bool, float, float]:
    """``(steady, chi-square under the steady model, its 95 % point)`` for the bias moves
    between consecutive ``stops`` (:func:`stop_biases`); q: bias random-walk intensity,
    rad^2/s^3."""
    if len(stops) < MIN_STOPS:
        return False, math.nan, math.nan
    x2 = ll_steady = ll_default = 0.0
    for (ta, ba, sa), (tb, bb, sb) in zip(stops[:-1], stops[1:], strict=True):
        z2 = (bb - ba) ** 2
        dt = tb - ta
        v_s = sa * sa + sb * sb + q_steady * dt
        v_d = sa * sa + sb * sb + q_default * dt
        x2 += z2 / v_s
        ll_steady -= 0.5 * (z2 / v_s + math.log(v_s))
        ll_default -= 0.5 * (z2 / v_d + math.log(v_d))
    limit = _chi2_95(len(stops) - 1)
    return bool(x2 <= limit and ll_steady > ll_default), x2, limit


def steady_params(epochs: Epochs, params: Params) -> tuple[Params, str]:
    """``(params, note)``: with ``[gyro] steady_from_stops`` and a gyro the stops judge steady,
    a copy with ``bias_sd_radps`` at ``steady_bias_sd_radps`` and a line saying so; else
    ``params`` unchanged and ""."""
    gy = params["gyro"]
    sd_steady = float(gy["steady_bias_sd_radps"])
    sd = float(gy["bias_sd_radps"])
    if not (bool(gy["steady_from_stops"]) and 0.0 < sd_steady < sd):
        return params, ""
    tau = float(gy["bias_tau_s"])
    stops = stop_biases(epochs, params)
    ok, _, _ = judge(stops, 2.0 * sd_steady ** 2 / tau, 2.0 * sd ** 2 / tau)
    if not ok:
        return params, ""
    out = steady_walk(params)
    spread = max(s[1] for s in stops) - min(s[1] for s in stops)
    return out, (f"gyro bias steady across {len(stops)} stops (within {spread:.1e} rad/s): "
                 f"its drift sigma is {sd_steady:g} rad/s ([gyro] steady_from_stops)")


def steady_walk(params: Params) -> Params:
    """A copy of ``params`` with the steady gyro's drift sigma (``[gyro] bias_sd_radps`` at
    ``steady_bias_sd_radps``)."""
    out = copy.deepcopy(params)
    out["gyro"]["bias_sd_radps"] = float(out["gyro"]["steady_bias_sd_radps"])
    return out


__all__ = ["judge", "steady_params", "steady_walk", "stop_biases"]
