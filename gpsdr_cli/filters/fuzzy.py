"""The two Mamdani fuzzy controllers of FAFKF (Tang et al., sections 3 and 4).

Plain numpy, written to be read and tested against hand-computed values; the
compiled kernels never call them.  Instead, at import, this module evaluates
both controllers on a regular grid (their *control surfaces*) and the kernels
interpolate those tables (:func:`gpsdr_cli.filters.kernels_fkf.interp1_uniform`,
``interp2_unit``): one evaluation then costs a few nanoseconds instead of a
full fuzzy inference per epoch (docs/algorithms.md#fafkf: "precompute the
control surfaces").  Hand-written rather than taken from scikit-fuzzy: that
package is not a dependency, and the whole inference is twenty lines.

Inference (both controllers): triangular membership functions, equally
spaced, each reaching zero at its neighbours' centres (so memberships sum to
1 everywhere inside the universe; the end sets are cut at the universe's
edge); rule strength = min of the antecedent memberships (AND); implication
by clipping (min); aggregation by max; centroid defuzzification on a fine
grid of the output universe.  Inputs outside their universe are clipped to it.

1. Adaptive R (Tang et al. section 3, covariance matching).  Input
   ``u = Dis_jj / Te_jj`` (**our choice**, dimensionless; ``Dis = Te - Ra``,
   so ``u = 1 - Ra_jj/Te_jj``), universe [-1, 1], sets NL NS ZO PS PL centred
   at -1, -0.5, 0, 0.5, 1.  Rules (Tang et al., 1)-5)): NL->PL, NS->PS, ZO->ZO,
   PS->NS, PL->NL.  Output: a normalised increment in [-1, 1] (same five
   centres); the kernel scales it by ``[fafkf] delta_max`` and applies
   ``R_jj *= 1 + Delta``.  Residuals larger than predicted (``Ra > Te``,
   ``u < 0``) raise R; smaller ones lower it.
2. Fusion reliability (Tang et al. section 4, Table 1).  Inputs PE and DE
   normalised to [0, 1] by the kernel, sets ZO VS NS NB VB centred at 0, 0.25,
   0.5, 0.75, 1; output W in [0, 1], sets VL NL M NH VH centred at 0, 0.25,
   0.5, 0.75, 1 (Tang et al. Fig. 1 shows five evenly spaced triangles).  Small
   covariance and small residual mismatch give a high reliability.  With
   centroid defuzzification W stays inside [1/12, 11/12]: no filter's weight
   ever reaches exactly 0 or 1.
"""

from __future__ import annotations

import numpy as np

#: Centres of the five sets of every universe, normalised to [0, 1].
CENTRES_UNIT = np.array([0.0, 0.25, 0.5, 0.75, 1.0])

#: Adaptive-R controller: input set names (low to high) and the output set each rule fires.
R_INPUT_SETS = ("NL", "NS", "ZO", "PS", "PL")
R_RULES = {"NL": "PL", "NS": "PS", "ZO": "ZO", "PS": "NS", "PL": "NL"}
R_OUTPUT_SETS = ("NL", "NS", "ZO", "PS", "PL")
R_CENTRES = np.array([-1.0, -0.5, 0.0, 0.5, 1.0])

#: Fusion controller: PE/DE sets from zero to very big, output sets from very low to very high.
PE_DE_SETS = ("ZO", "VS", "NS", "NB", "VB")
W_SETS = ("VL", "NL", "M", "NH", "VH")
#: Tang et al. Table 1: rows PE, columns DE, both in the order VB NB NS VS ZO as printed.
RULE_TABLE_PRINTED = (
    ("VL", "VL", "NL", "M", "M"),    # PE = VB
    ("VL", "NL", "NL", "M", "NH"),   # PE = NB
    ("NL", "NL", "M", "M", "NH"),    # PE = NS
    ("M", "M", "M", "NH", "VH"),     # PE = VS
    ("M", "NH", "NH", "VH", "VH"),   # PE = ZO
)
_PRINTED_ORDER = ("VB", "NB", "NS", "VS", "ZO")

#: Resolution of the defuzzification grid and of the precomputed tables.
N_DEFUZZ = 401
N_TABLE_R = 401
N_TABLE_W = 101


def tri(x: np.ndarray | float, left: float, centre: float, right: float) -> np.ndarray:
    """Triangular membership: 0 at ``left`` and ``right``, 1 at ``centre``."""
    x = np.asarray(x, dtype=float)
    up = (x - left) / (centre - left)
    down = (right - x) / (right - centre)
    return np.clip(np.minimum(up, down), 0.0, 1.0)


def memberships(x: np.ndarray | float, centres: np.ndarray) -> np.ndarray:
    """Membership of ``x`` (clipped to the universe) in each of the evenly spaced sets.

    Returns shape ``x.shape + (len(centres),)``.
    """
    x = np.clip(np.asarray(x, dtype=float), centres[0], centres[-1])
    step = centres[1] - centres[0]
    return np.stack([tri(x, c - step, c, c + step) for c in centres], axis=-1)


def centroid(strengths: np.ndarray, centres: np.ndarray) -> float:
    """Mamdani output: clip each output set at its rule strength, take the max, return the centroid.

    ``strengths[i]`` is the firing strength of output set ``i`` (max over the rules
    concluding it).  The integrals run over the output universe
    ``[centres[0], centres[-1]]`` with the trapezoid rule on ``N_DEFUZZ`` points.
    """
    y = np.linspace(centres[0], centres[-1], N_DEFUZZ)
    mu = memberships(y, centres)                       # (N_DEFUZZ, 5)
    agg = np.max(np.minimum(mu, strengths[None, :]), axis=1)
    area = np.trapezoid(agg, y)
    if area <= 0.0:
        return float(0.5 * (centres[0] + centres[-1]))
    return float(np.trapezoid(agg * y, y) / area)


def r_controller(u: float) -> float:
    """Adaptive-R controller: normalised ``Delta`` in [-1, 1] for ``u = Dis_jj/Te_jj``."""
    mu_in = memberships(u, R_CENTRES)
    strengths = np.zeros(5)
    for i, name in enumerate(R_INPUT_SETS):
        out = R_OUTPUT_SETS.index(R_RULES[name])
        strengths[out] = max(strengths[out], mu_in[i])
    return centroid(strengths, R_CENTRES)


def rule_output(pe_set: str, de_set: str) -> str:
    """Output set of Table 1 for the given PE and DE sets."""
    return RULE_TABLE_PRINTED[_PRINTED_ORDER.index(pe_set)][_PRINTED_ORDER.index(de_set)]


def weight_controller(pe: float, de: float) -> float:
    """Fusion controller: reliability W in [0, 1] from normalised PE and DE in [0, 1]."""
    mu_pe = memberships(pe, CENTRES_UNIT)
    mu_de = memberships(de, CENTRES_UNIT)
    strengths = np.zeros(5)
    for i, pe_set in enumerate(PE_DE_SETS):
        for j, de_set in enumerate(PE_DE_SETS):
            fire = min(mu_pe[i], mu_de[j])                 # AND = min
            out = W_SETS.index(rule_output(pe_set, de_set))
            strengths[out] = max(strengths[out], fire)     # aggregation = max
    return centroid(strengths, CENTRES_UNIT)


def _centroids(strengths: np.ndarray, centres: np.ndarray) -> np.ndarray:
    """:func:`centroid` for many rows of strengths at once, shape (m, 5) -> (m,)."""
    y = np.linspace(centres[0], centres[-1], N_DEFUZZ)
    mu = memberships(y, centres)                                       # (N_DEFUZZ, 5)
    out = np.empty(strengths.shape[0])
    for a in range(0, len(out), 256):                 # in chunks: bounded memory
        s = strengths[a:a + 256]
        agg = np.max(np.minimum(mu[None, :, :], s[:, None, :]), axis=2)
        out[a:a + 256] = np.trapezoid(agg * y, y, axis=1) / np.trapezoid(agg, y, axis=1)
    return out


def build_r_table(n: int = N_TABLE_R) -> np.ndarray:
    """Control surface of :func:`r_controller` on ``n`` points evenly over u in [-1, 1]."""
    mu_in = memberships(np.linspace(-1.0, 1.0, n), R_CENTRES)        # (n, 5)
    order = [R_OUTPUT_SETS.index(R_RULES[name]) for name in R_INPUT_SETS]
    strengths = np.zeros_like(mu_in)
    strengths[:, order] = mu_in          # one rule per output set: strength = membership
    return _centroids(strengths, R_CENTRES)


def build_w_table(n: int = N_TABLE_W) -> np.ndarray:
    """Control surface of :func:`weight_controller` on an ``n x n`` grid over [0, 1]^2
    (PE rows, DE columns)."""
    grid = np.linspace(0.0, 1.0, n)
    mu = memberships(grid, CENTRES_UNIT)                               # (n, 5)
    strengths = np.zeros((n, n, 5))
    for i, pe_set in enumerate(PE_DE_SETS):
        for j, de_set in enumerate(PE_DE_SETS):
            k = W_SETS.index(rule_output(pe_set, de_set))
            fire = np.minimum(mu[:, i, None], mu[None, :, j])          # AND = min
            strengths[:, :, k] = np.maximum(strengths[:, :, k], fire)  # aggregation = max
    return _centroids(strengths.reshape(n * n, 5), CENTRES_UNIT).reshape(n, n)


#: Precomputed at import (about 0.2 s): the kernels interpolate these.
R_TABLE: np.ndarray = build_r_table()
W_TABLE: np.ndarray = build_w_table()
