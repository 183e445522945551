"""The filters, by registered name.

A filter is a module that decorates its ``run(epochs, params) -> FilterResult``
with ``@register("name")``; the per-epoch loop lives in a compiled kernel over
arrays.  ``get(name)`` imports the filter modules lazily (numba is slow to
import, and ``gpsdr --help`` must stay fast).
"""

from __future__ import annotations

import copy
import dataclasses
import functools
import importlib
import math
from collections.abc import Callable

from ..config import Params
from ..errors import UsageError
from .base import FilterResult

RunFn = Callable[..., FilterResult]

_REGISTRY: dict[str, RunFn] = {}
#: name -> the filter alone, without the GNSS model and the NLOS screen around it
_BARE: dict[str, RunFn] = {}

#: name -> module that registers it (imported on first use)
MODULES: dict[str, str] = {
    "ekf": "gpsdr_cli.filters.ekf",
    "aekf": "gpsdr_cli.filters.aekf",
    "fkf": "gpsdr_cli.filters.fkf",
    "fafkf": "gpsdr_cli.filters.fafkf",
}

NAMES: tuple[str, ...] = tuple(MODULES)


def register(name: str) -> Callable[[RunFn], RunFn]:
    def deco(fn: RunFn) -> RunFn:
        from .gnss_model import (
            doppler_misfit,
            drop_reflected_doppler,
            gnss_error_model,
            reflected_doppler,
        )

        @functools.wraps(fn)
        def run(epochs, params):  # every filter sees the same GNSS error model
            from ..gyro_stops import steady_params
            from .calibration import scaled_yaw
            from .nlos_screen import farthest_window, not_applied, screen

            # ... and the same gyro: a bias that the stops show steady walks less
            params, steady_note = steady_params(epochs, params)
            model_epochs, model_params = gnss_error_model(epochs, params)
            # the batch fit weighs each fix by its own sigma, not the chord-scaled one
            # ... and only with healthy dead reckoning: a clipped gyro or an odometer that reads
            # wrong or falls silent cannot outvote fixes (it drove city tracks 250 m off)
            nlos = model_epochs.nlos_drive and not epochs.dr_unhealthy
            # ... whose receiver velocities, where reflected, the odometer shows: one more than
            # a wheel's error off its speed is not the car's (decisions/0068)
            n_doppler = 0
            doppler = None
            if nlos and epochs.has_odo.any():
                # (the misfits before any velocity is left out: the screen weighs each segment
                # of fixes by them, decisions/0069)
                doppler = doppler_misfit(epochs, float(params["gnss"]["nlos_velocity_min_mps"]))
                epochs, n_doppler = drop_reflected_doppler(epochs, params, doppler)
                if n_doppler:
                    model_epochs, model_params = gnss_error_model(epochs, params)
            screened, info = screen(epochs, params, nlos, bare("ekf"), doppler)
            if n_doppler:
                info["nlos_doppler_dropped"] = n_doppler
            if model_epochs.nlos_drive and epochs.dr_unhealthy:
                info["nlos_screen_skipped"] = "the dead reckoning is unhealthy"
            if info.get("nlos_screened"):  # the fixes left are judged afresh
                model_epochs, model_params = gnss_error_model(
                    dataclasses.replace(epochs, has_gnss=screened.has_gnss), params,
                    vector=False)
                # ... but their receiver velocity is still an NLOS drive's
                model_params = reflected_doppler(model_params, bool(epochs.has_odo.any()))
                # ... and the fit's odometer scale, not the kept fixes' Doppler speeds (some
                # reflected: 1.026 for 0.999 on a 600-s drive, the fit 0.993; decisions/0038),
                # unless the user gave one
                fkf_p = model_params["fkf"]
                if "nlos_screen_odo_scale" in info and not float(fkf_p["known_odo_scale"]) > 0:
                    fkf_p["known_odo_scale"] = info["nlos_screen_odo_scale"]
                # ... and ekf/aekf start from the fit's calibration, unless the user gave one:
                # across minutes of fixes left out, a drift learnt from a few fixes turned the
                # track 175 m off (decisions/0072)
                gp = model_params["graph"]
                if "nlos_screen_gyro_bias_radps" in info and not math.isfinite(
                        float(gp["gyro_bias_radps"])):
                    gp["gyro_bias_radps"] = info["nlos_screen_gyro_bias_radps"]
                if "nlos_screen_odo_scale" in info and not math.isfinite(float(gp["odo_scale"])):
                    gp["odo_scale"] = info["nlos_screen_odo_scale"]
                # ... and read the gyro with the fit's scale correction, which no filter has a
                # state for (a gyro 3 % off turned each turn's heading 2.7 deg; decisions/0074)
                g_fit = info.get("nlos_screen_gyro_scale")
                if g_fit is not None:
                    model_epochs = scaled_yaw(model_epochs, 1.0 + g_fit)
                # ... and white about the dead reckoning (ekf/aekf): what was correlated in them
                # was the reflections; a 2-m bias state took the dead reckoning's drift across a
                # screened gap for a fix bias and the smoother carried it back over clean
                # fixes (decisions/0047)
                if not bool(params["gnss"]["nlos_screened_err_states"]) and \
                        model_params["aekf"]["gnss_err_states"]:
                    model_params["aekf"]["gnss_err_states"] = False
                    if name in ("ekf", "aekf"):
                        info["gnss_err_states_off"] = ("the NLOS screen kept only fixes that "
                                                       "agree with the dead reckoning")
            elif info.get("nlos_screen_not_applied"):
                # ... and where the screen could not judge the fixes, no dead reckoning outvotes
                # them: ekf/aekf's error states keep their clear-sky sigma (the NLOS drive's
                # 20 m let the dead reckoning carry the track 70 m from fixes at 25 m; white
                # fixes thrashed the gate; decisions/0061)
                model_params = clear_sky_errors(model_params, params)
            if epochs.dr_unhealthy:
                model_params = follow_the_fixes(model_params)
                info["pdop_r_factors"] = "off: the dead reckoning is unhealthy"
            elif not epochs.has_odo.any():
                # the R factors hand the track to the dead reckoning; without an odometer its
                # speed is the fixes' own (an HDOP-6 fix's 11-m sigma x 10 let a velocity
                # from one bad fix carry the track 135 m away from every later one)
                model_params = follow_the_fixes(model_params)
                info["pdop_r_factors"] = "off: no odometer measures the speed"
            # fixes screened out at the start leave epochs before the first kept fix: dead-
            # reckoned back from it, as a cold start's are (a filter started there began at
            # that fix's position 140 s early: 800 m off on a simulated city drive), with the
            # screen's gyro bias and odometer scale, fitted over the whole drive (the minute
            # of track after a first fix at a stop read a gyro bias of 0.11 rad/s)
            if info.get("nlos_screened"):
                from ..lead_in import run_from_first_fix

                bias = info.get("nlos_screen_gyro_bias_radps")
                if bias is not None and model_epochs.time_reversed:
                    bias = -bias  # the drive run backwards reads its yaw rates negated
                result = run_from_first_fix(model_epochs, fn, model_params, gyro_bias=bias,
                                            true_scale=info.get("nlos_screen_odo_scale"))
                # the judge's track stayed within a reflection's reach of the fixes, but this
                # filter's may not (minute-long reflections: over the same kept fixes fkf ran
                # 312 m from the fixes, 101 m RMS against their 18 m; decisions/0063)
                far_m, at_s = farthest_window(epochs, result, epochs.has_gnss)
                if far_m > float(params["gnss"]["nlos_screen_max_offset_m"]):
                    info = not_applied(f"the {name} track of the fixes it kept lies {far_m:.0f} m "
                                       f"from the fixes around {at_s:.0f} s")
                    model_epochs, model_params = gnss_error_model(epochs, params)
                    result = fn(model_epochs, clear_sky_errors(model_params, params))
            else:
                result = fn(model_epochs, model_params)
            result.info.update(info)
            if steady_note:
                result.info["gyro_steady"] = steady_note
            result.info["nlos_drive"] = bool(model_epochs.nlos_drive)
            return result

        _REGISTRY[name] = run
        _BARE[name] = fn
        return fn
    return deco


def clear_sky_errors(model_params: Params, params: Params) -> Params:
    """``model_params`` (the GNSS model's) with ekf/aekf's error states at the clear-sky sigma
    of ``params`` instead of an NLOS drive's: where the NLOS screen is not applied, no dead
    reckoning outvotes the fixes (decisions/0061)."""
    out = copy.deepcopy(model_params)
    out["aekf"]["gnss_err_sd_m"] = float(params["aekf"]["gnss_err_sd_m"])
    return out


def follow_the_fixes(params: Params) -> Params:
    """``params`` without the R factors of a poor PDOP ([gnss] k_medium, k_poor = k_good):
    they let the dead reckoning outvote the fixes in a city, which an unhealthy dead
    reckoning must not (a clipping gyro's unmeasured turn put aekf + RTS 20 m off for 150 s,
    above the fixes; decisions/0010)."""
    out = copy.deepcopy(params)
    g = out["gnss"]
    g["k_medium"] = g["k_poor"] = g["k_good"]
    return out


def bare(name: str) -> RunFn:
    """The ``run`` function of filter ``name`` alone: no GNSS model, no NLOS screen."""
    get(name)
    return _BARE[name]


def get(name: str) -> RunFn:
    """The ``run`` function of filter ``name``."""
    if name not in MODULES:
        raise UsageError(f"unknown filter {name!r}; choose one of {', '.join(NAMES)}")
    if name not in _REGISTRY:
        importlib.import_module(MODULES[name])
    return _REGISTRY[name]


__all__ = ["NAMES", "FilterResult", "bare", "get", "register"]
