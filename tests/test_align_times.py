"""Time-stamp cleaning (align.clean_times): a lone spike costs one record, a clock step
back costs only the overlap, every drop is reported by stream, file and reason.

Why these cases: a logger writes duplicate stamps, jitters backwards by a sample, writes
one corrupt stamp (the comma2k19 degraded benchmark's +480 s row made the old
running-maximum rule drop 11,030 of 11,808 records), or has its clock stepped back.
"""

from __future__ import annotations

import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from gpsdr_cli import config
from gpsdr_cli.align import (
    REASON_DUPLICATE,
    REASON_SPIKE,
    REASON_STEP,
    build_epochs,
    clean_times,
    increasing_subsequence,
)
from gpsdr_cli.conventions import NS_PER_S
from gpsdr_cli.io.drive import Drive, Odometry, SkipReport, Source, YawRates

T0 = 1_533_226_488 * NS_PER_S
STEP_NS = 10_000_000  # 100 Hz


def _gyro_drive(t_ns: np.ndarray) -> Drive:
    return Drive(gyro=YawRates(t_ns, np.arange(len(t_ns), dtype=float)),
                 sources=[Source("logs/gyro.csv", "", ("gyro",))])


def _lis_length(t: list[int]) -> int:
    """O(n^2) textbook longest strictly increasing subsequence length (the oracle)."""
    best = [1] * len(t)
    for i in range(len(t)):
        for j in range(i):
            if t[j] < t[i]:
                best[i] = max(best[i], best[j] + 1)
    return max(best, default=0)


def test_one_stamp_480_s_late_costs_that_record_alone() -> None:
    t = T0 + np.arange(6000) * STEP_NS                     # 60 s at 100 Hz
    spiked = np.insert(t, 101, t[100] + 480 * NS_PER_S)    # the benchmark's damage
    drive = _gyro_drive(spiked)
    ep = build_epochs(drive, None, config.defaults())
    assert len(ep) == 6000                                  # every good record kept
    np.testing.assert_array_equal(ep.t_ns, t)
    assert drive.skipped.total == 1
    reason = f"gyro: {REASON_SPIKE}"
    assert drive.skipped.counts[reason] == 1
    where = drive.skipped.first[reason]
    assert where.startswith("logs/gyro.csv: gyro record 102 (") and "+480.000 s" in where
    assert "warnings" not in drive.meta                     # 1 of 6001 is under 1 %


def test_a_stamp_early_and_one_late_at_the_ends_are_the_ones_dropped() -> None:
    t = T0 + np.arange(100) * STEP_NS
    damaged = t.copy()
    damaged[1] -= 300 * NS_PER_S    # second record 300 s early: t[0] must stay
    damaged[-2] += 41 * NS_PER_S    # last but one 41 s late: the last must stay
    keep = clean_times(damaged, np.ones(100, bool), "odo", SkipReport())
    np.testing.assert_array_equal(keep, np.r_[0, 2:98, 99])


def test_jitter_and_duplicates_cost_one_record_each_first_wins() -> None:
    t = T0 + np.arange(50) * STEP_NS
    t[[10, 11]] = t[[11, 10]]                      # one swapped pair
    t = np.insert(t, 30, t[29])                    # one repeated stamp (a different reading)
    values = np.arange(len(t), dtype=float)
    drive = Drive(odo=Odometry(t, values), sources=[Source("odo.csv", "", ("odo",))])
    ep = build_epochs(drive, None, config.defaults())
    assert len(ep) == 49                            # 51 records, 2 dropped
    assert np.all(np.diff(ep.t_ns) > 0)
    assert drive.skipped.counts[f"odo: {REASON_DUPLICATE}"] == 1
    assert drive.skipped.counts[f"odo: {REASON_SPIKE}"] == 1
    assert ep.odo_speed_mps[list(ep.t_ns).index(t[29])] == 29.0   # the first of the pair


def test_a_clock_step_back_drops_only_the_overlap_and_warns() -> None:
    before = T0 + np.arange(1000) * STEP_NS                       # 0 .. 9.99 s
    after = before[-1] - 2 * NS_PER_S + 5_000_000 + np.arange(3000) * STEP_NS  # back 2 s, on
    drive = _gyro_drive(np.concatenate([before, after]))
    ep = build_epochs(drive, None, config.defaults())
    lost = 4000 - len(ep)
    assert 199 <= lost <= 201                       # 2 s at 100 Hz, one side of the overlap
    assert np.all(np.diff(ep.t_ns) > 0)
    assert ep.t_ns[-1] == after[-1]                  # the drive after the step is all there
    assert drive.skipped.counts[f"gyro: {REASON_STEP}"] == lost
    where = drive.skipped.first[f"gyro: {REASON_STEP}"]
    assert where.startswith("logs/gyro.csv: gyro record 1001 (") and "-1.995 s after" in where
    (msg,) = drive.meta["warnings"]
    assert msg.startswith(f"logs/gyro.csv: gyro: {lost} of 4000 records (5.0 %) dropped")
    build_epochs(drive, None, config.defaults())     # aligning again adds no second warning
    assert len(drive.meta["warnings"]) == 1


@settings(max_examples=200, deadline=None)
@given(st.lists(st.integers(-50, 50), max_size=40))
def test_kept_stamps_increase_and_are_a_longest_such_subsequence(t: list[int]) -> None:
    arr = np.asarray(t, np.int64)
    keep = clean_times(arr, np.ones(len(arr), bool), "gnss", SkipReport())
    assert np.all(np.diff(arr[keep]) > 0)
    assert len(keep) == _lis_length(t)
    assert increasing_subsequence(arr).sum() == _lis_length(t)


@settings(max_examples=200, deadline=None)
@given(st.integers(3, 60), st.data())
def test_one_spike_anywhere_leaves_every_good_record(n: int, data: st.DataObject) -> None:
    t = T0 + np.cumsum(data.draw(st.lists(st.integers(1, 3), min_size=n, max_size=n))) * STEP_NS
    at = data.draw(st.integers(0, n))
    off = data.draw(st.integers(-10_000, 10_000).filter(lambda k: abs(k) > 4 * n)) * STEP_NS
    base = t[min(at, n - 1)]
    spiked = np.insert(t, at, base + off)
    report = SkipReport()
    keep = clean_times(spiked, np.ones(n + 1, bool), "gyro", report)
    kept = spiked[keep]
    if 0 < at < n or (at == 0 and off > 0) or (at == n and off < 0):   # out of line
        np.testing.assert_array_equal(kept, t)
        assert report.total == 1
    else:  # before the first / after the last record: in order, nothing to drop
        np.testing.assert_array_equal(kept, spiked)
