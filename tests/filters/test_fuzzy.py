"""The two Mamdani controllers of FAFKF (Tang et al.) against hand-computed values."""

from __future__ import annotations

import numpy as np
import pytest

from gpsdr_cli.filters import fuzzy
from gpsdr_cli.filters.kernels_fkf import interp1_uniform, interp2_unit

#: tolerance of the discretised centroid against the exact integral (dimensionless)
CENTROID_TOL = 1e-4


def test_memberships_are_triangles_summing_to_one() -> None:
    x = np.linspace(-1.0, 1.0, 41)
    mu = fuzzy.memberships(x, fuzzy.R_CENTRES)
    assert np.allclose(mu.sum(axis=1), 1.0, atol=1e-12)
    # -0.25 lies halfway between NS (-0.5) and ZO (0)
    assert np.allclose(fuzzy.memberships(-0.25, fuzzy.R_CENTRES), [0, 0.5, 0.5, 0, 0])
    # outside the universe: clipped to the end set
    assert np.allclose(fuzzy.memberships(-7.0, fuzzy.R_CENTRES), [1, 0, 0, 0, 0])


@pytest.mark.parametrize(("u", "expected"), [
    (0.0, 0.0),            # ZO -> ZO: symmetric triangle, centroid 0
    (-1.0, 5.0 / 6.0),     # NL -> PL: half triangle on [0.5, 1], centroid (0.5 + 1 + 1)/3
    (1.0, -5.0 / 6.0),     # PL -> NL
    (-0.5, 0.5),           # NS -> PS: full triangle centred at 0.5
    (-0.25, 0.25),         # NS 0.5 and ZO 0.5: union symmetric about 0.25
    (0.25, -0.25),
])
def test_r_controller_hand_values(u: float, expected: float) -> None:
    assert fuzzy.r_controller(u) == pytest.approx(expected, abs=CENTROID_TOL)


def test_r_controller_raises_r_when_residuals_exceed_prediction() -> None:
    # u = Dis/Te < 0 means Ra > Te: residuals larger than predicted -> Delta > 0
    u = np.linspace(-1.0, 1.0, 81)
    d = np.array([fuzzy.r_controller(v) for v in u])
    assert np.all(np.diff(d) <= 1e-12)          # monotone non-increasing
    assert np.all(d[u < 0] > 0) and np.all(d[u > 0] < 0)
    assert np.allclose(d, -d[::-1], atol=1e-9)  # odd symmetry of the rule base


@pytest.mark.parametrize(("pe", "de", "expected"), [
    (0.0, 0.0, 11.0 / 12.0),   # ZO, ZO -> VH: half triangle on [0.75, 1], centroid 11/12
    (1.0, 1.0, 1.0 / 12.0),    # VB, VB -> VL
    (0.5, 0.5, 0.5),           # NS, NS -> M
    (0.25, 0.25, 0.75),        # VS, VS -> NH
    (1.0, 0.0, 0.5),           # VB, ZO -> M
    (0.0, 1.0, 0.5),           # ZO, VB -> M
    (0.75, 0.0, 0.75),         # NB, ZO -> NH
])
def test_weight_controller_hand_values(pe: float, de: float, expected: float) -> None:
    assert fuzzy.weight_controller(pe, de) == pytest.approx(expected, abs=CENTROID_TOL)


def test_rule_table_orientation() -> None:
    # Tang et al. Table 1: rows PE, columns DE, order VB NB NS VS ZO
    assert fuzzy.rule_output("VB", "VB") == "VL"
    assert fuzzy.rule_output("ZO", "ZO") == "VH"
    assert fuzzy.rule_output("VB", "VS") == "M"
    assert fuzzy.rule_output("NB", "ZO") == "NH"
    assert fuzzy.rule_output("VS", "VB") == "M"


def test_weight_decreases_with_covariance_and_mismatch() -> None:
    # at the set centres (one rule fires) Table 1 never rewards a bigger PE or DE
    centres = fuzzy.CENTRES_UNIT
    w = np.array([[fuzzy.weight_controller(a, b) for b in centres] for a in centres])
    assert np.all(np.diff(w, axis=0) <= 1e-9)
    assert np.all(np.diff(w, axis=1) <= 1e-9)
    grid = np.linspace(0.0, 1.0, 11)
    w = np.array([[fuzzy.weight_controller(a, b) for b in grid] for a in grid])
    assert w.min() == pytest.approx(1 / 12, abs=CENTROID_TOL)
    assert w.max() == pytest.approx(11 / 12, abs=CENTROID_TOL)


def test_tables_match_the_controllers_and_interpolate() -> None:
    u = np.linspace(-1.0, 1.0, len(fuzzy.R_TABLE))
    for i in range(0, len(u), 37):
        assert fuzzy.R_TABLE[i] == pytest.approx(fuzzy.r_controller(u[i]), abs=1e-12)
    g = np.linspace(0.0, 1.0, len(fuzzy.W_TABLE))
    for i in range(0, len(g), 13):
        for j in range(0, len(g), 17):
            assert fuzzy.W_TABLE[i, j] == pytest.approx(fuzzy.weight_controller(g[i], g[j]),
                                                        abs=1e-12)
    # between grid points the interpolated surface stays within 2e-3 of the inference
    rng = np.random.default_rng(3)
    for v in rng.uniform(-1, 1, 20):
        assert interp1_uniform(fuzzy.R_TABLE, -1.0, 1.0, v) == pytest.approx(
            fuzzy.r_controller(v), abs=2e-3)
    for a, b in rng.uniform(0, 1, (20, 2)):
        assert interp2_unit(fuzzy.W_TABLE, a, b) == pytest.approx(
            fuzzy.weight_controller(a, b), abs=2e-3)
    # clamped outside the universe
    assert interp1_uniform(fuzzy.R_TABLE, -1.0, 1.0, -5.0) == fuzzy.R_TABLE[0]
    assert interp2_unit(fuzzy.W_TABLE, 2.0, -1.0) == fuzzy.W_TABLE[-1, 0]
