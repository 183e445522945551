"""Adaptive pieces shared by the compiled filter kernels (aekf, ekf; reusable by fkf/fafkf).

All are small numba functions (``cache=True``) on scalars, callable from any
``@njit`` kernel and from Python:

- :func:`gate_threshold` / :func:`nis_2d`: chi-square innovation gating of a 2-D
  GNSS position fix (the gate and its no-lock-out reset live in the kernel:
  after ``gate_reset_s`` of continuous rejections a fix is accepted and the
  position variance inflated by the squared innovation).
- :func:`adaptive_factor`: the innovation-factor paper's innovation-based adaptive factor
  ``beta = sqrt(v^T v / tr(C))``, ``alpha = 1`` if ``beta <= c`` else ``c/beta``;
  used (docs/algorithms.md#adaptive-factor, Yang's form) as ``P(k|k-1) <- P(k|k-1)/alpha``.
- :func:`fading_factor`: fading memory (Zeng et al.) ``P(k|k-1) = lambda Phi P Phi^T + Q``
  with lambda given per second and applied as ``lambda**T``, so the forgetting
  does not depend on the epoch rate.
- :func:`sage_husa_r`: Sage-Husa maximum a posteriori estimate of a scale factor on
  the GNSS R (Zeng et al.), with the divergence guard: each sample and the
  estimate are clamped to ``[r_min, r_max]`` so R stays positive definite and
  cannot collapse or blow up.

Written by hand: none of these exists in a library that numba can call.
"""

from __future__ import annotations

import math

from numba import njit


def gate_threshold(prob: float, dof: int = 2) -> float:
    """Chi-square quantile for the innovation gate (dimensionless).

    For 2 degrees of freedom closed form ``-2 ln(1 - p)``; otherwise SciPy.
    """
    if dof == 2:
        return -2.0 * math.log1p(-prob)
    from scipy.stats import chi2

    return float(chi2.ppf(prob, dof))


@njit(cache=True)
def nis_2d(ye: float, yn: float, s00: float, s01: float, s11: float) -> float:
    """Normalised innovation squared ``y^T S^-1 y`` for a 2-vector y and symmetric 2x2 S."""
    det = s00 * s11 - s01 * s01
    if not (det > 0.0):
        return math.inf
    return (s11 * ye * ye - 2.0 * s01 * ye * yn + s00 * yn * yn) / det


@njit(cache=True)
def adaptive_factor(ye: float, yn: float, trace_c: float, c: float) -> float:
    """innovation adaptive factor alpha in (0, 1] from the innovation (y_e, y_n) and tr(C).

    ``C = H P(k|k-1) H^T + R``; ``beta = sqrt(v^T v / tr C)``; ``alpha = 1`` if
    ``beta <= c`` else ``c / beta`` (c = 0.9 in the paper).
    """
    if not (trace_c > 0.0):
        return 1.0
    beta = math.sqrt((ye * ye + yn * yn) / trace_c)
    if beta <= c:
        return 1.0
    return c / beta


@njit(cache=True)
def fading_factor(lambda_per_s: float, T: float) -> float:
    """Fading-memory multiplier for a step of T seconds: ``lambda_per_s ** T`` (>= 1)."""
    if T <= 0.0 or lambda_per_s <= 1.0:
        return 1.0
    return math.exp(T * math.log(lambda_per_s))


@njit(cache=True)
def sage_husa_r(r_prev: float, m: int, b: float, sample: float, r_min: float,
                r_max: float) -> float:
    """One Sage-Husa step on a dimensionless R scale factor (Zeng et al.).

    ``d_m = (1 - b)/(1 - b^(m+1))``; ``r_m = (1 - d_m) r_(m-1) + d_m * sample`` where
    the caller's sample is ``(y^T y - H P(k|k-1) H^T) / R_nominal`` (the unbiased
    innovation-based estimate).  Divergence guard: the sample, which goes
    negative when P is too large, and the result are clamped to [r_min, r_max].
    """
    d = (1.0 - b) / (1.0 - b ** (m + 1))
    s = min(max(sample, r_min), r_max)
    r = (1.0 - d) * r_prev + d * s
    return min(max(r, r_min), r_max)
