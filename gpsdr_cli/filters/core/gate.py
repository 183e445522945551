"""The chi-square innovation gate and its reset rule, for every filter.

docs/algorithms.md#gate.  The caller arms the gate (a threshold > 0, the warm-up of
``gnss.gate_warmup_fixes`` accepted fixes over) and passes the test statistic: the NIS
of a fix against its chi-square quantile, or any squared quantity against its bound.
A failing value is rejected until the fixes have disagreed for ``gate_reset_s``; then it
is accepted (no lock-out: the state, not the fixes, is the outlier).  When that time
starts is the one thing the families do differently, a named rule:

``RESET_AFTER_FIRST_REJECT`` (ekf, aekf): from the first rejected value of the current
run of rejections (``t - t_ref >= gate_reset_s``; a passing value ends the run);
``RESET_AFTER_LAST_ACCEPT`` (fkf, fafkf): from the last accepted value
(``t - t_ref > gate_reset_s``; the caller moves ``t_ref`` when it accepts).

They are not merged: the first rejection comes one fix interval after the last
acceptance, so either rule in both families moves the reset by that interval and
changes the tracks of the drives whose gate resets (docs/decisions/0013).
"""

from __future__ import annotations

from numba import njit

#: verdicts of :func:`chi2_gate`
GATE_PASS, GATE_FAIL, GATE_RESET = 0, 1, 2
#: reset rules (see the module docstring)
RESET_AFTER_FIRST_REJECT, RESET_AFTER_LAST_ACCEPT = 0, 1


@njit(cache=True, error_model="numpy", inline="always")
def chi2_gate(stat: float, bound: float, t: float, t_ref: float, reset_s: float, rule: int,
              force_reset: bool) -> tuple[int, float]:
    """The verdict on ``stat`` against ``bound`` at time ``t`` (s), and the new ``t_ref``.

    ``t_ref`` (s): with RESET_AFTER_FIRST_REJECT the first rejection of the current run
    (< 0: none), kept here; with RESET_AFTER_LAST_ACCEPT the last acceptance, which the
    caller keeps.  ``force_reset``: accept a failing value now (a caller's own evidence
    that the state is the outlier, e.g. most recent fixes rejected).  NaN passes.
    """
    if not (stat > bound):
        if rule == RESET_AFTER_FIRST_REJECT:
            return GATE_PASS, -1.0
        return GATE_PASS, t_ref
    if rule == RESET_AFTER_FIRST_REJECT:
        if t_ref < 0.0:
            t_ref = t
        if t - t_ref >= reset_s or force_reset:
            return GATE_RESET, -1.0
        return GATE_FAIL, t_ref
    if t - t_ref > reset_s or force_reset:
        return GATE_RESET, t_ref
    return GATE_FAIL, t_ref
