"""``fafkf``: fuzzy adaptive federated Kalman filter (Tang et al.).

The local filters, model, inputs, modes and smoothing of :mod:`.fkf`, plus
the paper's two fuzzy controllers (:mod:`.fuzzy`, interpolated inside the
kernel :func:`~gpsdr_cli.filters.kernels_fkf.federated_pass`):

1. adaptive R by covariance matching, per measurement component
   (GNSS e, GNSS n, heading, distance): the window of the last ``[fafkf]
   window`` squared prior residuals gives ``Ra``; ``u = (Te - Ra)/Te`` drives
   the 5-rule controller; ``R_jj *= 1 + Delta`` within ``[r_min_factor,
   r_max_factor]`` x the nominal R (which for GNSS is the receiver's base sigma
   of each epoch squared);
2. fusion weights: reliabilities ``W_i`` from ``PE_i = tr(P_i P_i^T)`` and
   ``DE_i = tr(D_i D_i^T)`` (``D_i`` the diagonal of ``Dis_i`` divided by
   ``Te_i``: dimensionless, so the two filters' values compare), normalised by
   ``[fafkf] normalisation``; ``beta_1 = W_1/(W_1 + W_2)``.
   ``[fafkf] weights = "shares"`` (default, our choice): the fusion is the
   covariance weighting of fkf and beta is the FR information share ``c_1``
   (Carlson's beta_i: ``P_1 = P_g/beta``, ``P_2 = P_g/(1 - beta)``).  Why not
   the paper's convex ``x_g = beta x_1 + (1 - beta) x_2``: in FR mode both
   local filters start each epoch from x_g, so that form scales each local
   *update* by its weight -- neither the fix nor the odometer is used in full
   (evidence: docs/decisions/0015-evidence-behind-the-filter-choices.md#fafkf).
   Covariance weighting already weighs the filters by their covariances, which
   the adaptive R inflates when residuals outgrow them.
   ``"scalar"``: one beta for all shared states (the paper's convex form);
   ``"block"``: one for the position block [e, n] and one for the
   velocity/acceleration block, each from that block of P.  In FR mode PE is
   taken from ``c_i P_i`` (the filter's covariance before the reset's
   ``1/c_i`` inflation): otherwise the share given at the last reset would
   decide the next weight, a feedback loop.

Extras: ``beta_gnss`` (position) and ``beta_gnss_vel`` (velocity) fusion
weights of the GNSS filter; ``r_factor_gnss_e``, ``r_factor_gnss_n``,
``r_factor_heading``, ``r_factor_distance`` (R adaptation factors).

Conventions: :mod:`gpsdr_cli.conventions`.
"""

from __future__ import annotations

from ..config import Params
from ..epochs import Epochs
from . import register
from .base import FilterResult
from .fkf import run_federated


@register("fafkf")
def run(epochs: Epochs, params: Params) -> FilterResult:
    """Fuzzy adaptive federated Kalman filter (Tang et al.)."""
    return run_federated("fafkf", epochs, params)
