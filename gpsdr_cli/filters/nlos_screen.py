"""Fixes the whole drive's dead reckoning outvotes are left out of the filters.

On a drive the chord check (:mod:`gpsdr_cli.filters.gnss_model`) marks as NLOS, reflected
signals give most fixes errors of tens of metres that stay consistent among themselves
for seconds to minutes.  A forward filter cannot tell a slow NLOS bias from a slow drift
of its own dead reckoning, and an inflated sigma only slows its pull: on the simulated
``urban_nlos`` drive every filter still ended at 20-40 m against the fixes' 32-40 m.
A post-processor has the whole drive: the robust batch fit of the dead reckoning to
every fix (:func:`gpsdr_cli.graph_smoother.smooth_graph`, Cauchy kernel) gives each fix a
weight, and a fix whose weight is below ``[gnss] nlos_screen_min_weight`` (its residual
beyond the kernel's scale) is not given to the filter at all.  With those fixes left out
the same filters reach 1.5 m on that drive.

Only on NLOS drives with a gyro and an odometer (the batch fit needs a dead reckoning
that holds the shape on its own), and only when the fit converges and keeps at least
``nlos_screen_min_kept`` of the fixes; otherwise the epochs pass unchanged.  Units:
metres, seconds.
"""

from __future__ import annotations

import copy
import dataclasses
from collections.abc import Callable

import numpy as np

from ..align import Epochs
from ..config import Params
from .base import FilterResult


def screen(epochs: Epochs, params: Params, nlos_drive: bool,
           run: Callable[[Epochs, Params], FilterResult]) -> tuple[Epochs, dict]:
    """``(epochs, info)``: the epochs with the outvoted fixes' ``has_gnss`` cleared, and
    what was done (``info["nlos_screened"]``: fixes left out; absent when not applied)."""
    g = params["gnss"]
    if (not nlos_drive or not g["nlos_screen"] or not epochs.has_gyro.any()
            or not epochs.has_odo.any()):
        return epochs, {}
    from ..graph_smoother import smooth_graph

    probe = copy.deepcopy(params)
    probe["filter"]["smooth"] = True
    init = run(epochs, probe)
    outcome = smooth_graph(epochs, init, probe)
    if outcome.result is None or len(outcome.gnss_weight) != len(epochs):
        return epochs, {"nlos_screen": f"not applied: {outcome.message}"}
    w = outcome.gnss_weight
    fix = epochs.has_gnss
    out = fix & np.isfinite(w) & (w < float(g["nlos_screen_min_weight"]))
    kept = int(np.count_nonzero(fix & ~out))
    if kept < float(g["nlos_screen_min_kept"]) * max(int(fix.sum()), 1):
        return epochs, {"nlos_screen": f"not applied: only {kept} of {int(fix.sum())} fixes agree"}
    if not out.any():
        return epochs, {"nlos_screened": 0}
    return dataclasses.replace(epochs, has_gnss=fix & ~out), {"nlos_screened": int(out.sum())}


__all__ = ["screen"]
