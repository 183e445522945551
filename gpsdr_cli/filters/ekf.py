"""EKF: the non-adaptive baseline on Fang et al.'s 8-state model (docs/algorithms.md#cs-model).

Same state, measurements, asynchronous cycle and kernel as :mod:`.aekf`, but
with FIXED noise: Q from the constant ``aekf.sigma_a_mps2`` (no current
statistical adaptation, no K_a regimes) and R from ONE constant GNSS sigma for
the whole drive: the median over the fixes of the base sigma
``sqrt((sd_e^2 + sd_n^2)/2)`` (reported as ``info["ekf_gnss_sigma_m"]``), no
PDOP regimes.  The ``[adaptive]`` options, the gate, the standstill logic and the
GNSS error states (``aekf.gnss_err_states``: the multipath as two Gauss-Markov states
with fixed sigma and correlation time) apply as for every filter, so the benchmark
can compare like with like.
"""

from __future__ import annotations

from ..config import Params
from ..epochs import Epochs
from . import register
from .aekf import run_cs
from .base import FilterResult


@register("ekf")
def run(epochs: Epochs, params: Params) -> FilterResult:
    """Fixed-Q, fixed-R EKF over the epochs (RTS-smoothed when ``filter.smooth``)."""
    return run_cs(epochs, params, adaptive=False, name="ekf")
