"""Run one filter on a simulated drive and measure it against the simulator's truth.

Shared by the test suite and ``benchmarks/no_odometer.py``: build the epochs in the
simulation's frame, run the registered filter with the defaults (and any overrides),
and return the horizontal error per epoch (m) next to the fixes' own error.
"""

from __future__ import annotations

import copy
from dataclasses import dataclass

import numpy as np

from .. import config, filters
from ..align import build_epochs
from ..epochs import Epochs
from ..filters.base import FilterResult


@dataclass
class SimRun:
    """``result`` and ``epochs`` of one run; ``err_m`` horizontal error per epoch (m);
    ``gnss_err_m`` the fixes' error at the fix epochs (m); ``true_speed_mps`` per epoch."""

    result: FilterResult
    epochs: Epochs
    err_m: np.ndarray
    gnss_err_m: np.ndarray
    true_speed_mps: np.ndarray

    @property
    def rmse_m(self) -> float:
        return float(np.sqrt(np.mean(self.err_m ** 2)))

    @property
    def gnss_rmse_m(self) -> float:
        return float(np.sqrt(np.mean(self.gnss_err_m ** 2))) if len(self.gnss_err_m) else float("nan")


def run_filter(sim, drive, name: str, smooth: bool = False,
               overrides: dict[str, dict] | None = None, *, pipeline: bool = False) -> SimRun:
    """``name`` over ``drive`` (a copy is aligned; the drive is not changed) with the default
    parameters updated section by section from ``overrides``; errors against ``sim.truth``.
    ``pipeline``: through :func:`gpsdr_cli.pipeline.run_filter` (the lead-in and the
    no-odometer outage speed), as ``gpsdr fuse`` runs it, not the bare filter."""
    p = config.defaults()
    p["filter"]["name"] = name
    p["filter"]["smooth"] = smooth
    for section, values in (overrides or {}).items():
        p[section].update(values)
    ep = build_epochs(copy.deepcopy(drive), sim.frame, p)
    if pipeline:
        from ..pipeline import run_filter as run_pipeline_filter

        r = run_pipeline_filter(ep, p)
    else:
        r = filters.get(name)(ep, p)
    tr = sim.truth
    te = np.interp(ep.t_ns, tr.t_ns, tr.e)
    tn = np.interp(ep.t_ns, tr.t_ns, tr.n)
    f = ep.has_gnss
    return SimRun(result=r, epochs=ep, err_m=np.hypot(r.e - te, r.n - tn),
                  gnss_err_m=np.hypot(ep.gnss_e[f] - te[f], ep.gnss_n[f] - tn[f]),
                  true_speed_mps=np.interp(ep.t_ns, tr.t_ns, tr.speed))
