"""End-to-end fuzzing: mutated NMEA, CSV and MCAP files through the readers and ``fuse``.

Hypothesis draws the mutation seed (and the filter); the mutations are
:func:`gpsdr_cli.testing.faults.mutate` on a small simulated drive, run
in process (:func:`gpsdr_cli.testing.faults.fuzz_case`).  The contract: only
GpsdrError subclasses escape, and a successful ``fuse`` gives a track with one
row per epoch and finite required columns (``NonFiniteOutputError``, the
pipeline's own "the filter diverged" guard, counts as a failure too: a
damaged input must be skipped or named, not blow the filter up).  The
readers' own fuzz tests live with the readers; ``benchmarks/fuzz.py`` runs
10^5 of these cases.  The regression tests at the end pin the bugs fuzzing
found, with the smallest input that shows each.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpsdr_cli import config
from gpsdr_cli.errors import GpsdrError
from gpsdr_cli.filters import NAMES
from gpsdr_cli.testing import faults as F


def _settings(max_examples: int) -> settings:
    return settings(max_examples=max_examples, deadline=None, derandomize=True, database=None,
                    suppress_health_check=[HealthCheck.too_slow])


@pytest.fixture(scope="module")
def seeds(tmp_path_factory: pytest.TempPathFactory) -> dict[str, bytes]:
    return F.fuzz_seed_files(tmp_path_factory.mktemp("seed"))


@pytest.fixture(scope="module")
def work(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return tmp_path_factory.mktemp("work")


def _check(target: str, seeds: dict[str, bytes], work: Path, case_seed: int,
           filter_name: str | None = None) -> None:
    key, _ = F.fuzz_case(target, seeds, np.random.default_rng(case_seed), work,
                         filter_name=filter_name)
    assert not F.is_bug(key), f"{target} case_seed={case_seed} filter={filter_name}: {key}"


@pytest.mark.parametrize("target", ["nmea", "gyro_csv", "odo_csv", "mcap"])
def test_readers_raise_only_gpsdr_errors(target: str, seeds: dict[str, bytes], work: Path) -> None:
    @_settings(300)
    @given(case_seed=st.integers(0, 2**63 - 1))
    def run(case_seed: int) -> None:
        _check(target, seeds, work, case_seed)

    run()


@pytest.mark.parametrize("target", ["e2e_files", "e2e_mcap"])
def test_fuse_on_mutated_files(target: str, seeds: dict[str, bytes], work: Path) -> None:
    @_settings(250)
    @given(case_seed=st.integers(0, 2**63 - 1), filter_name=st.sampled_from(NAMES))
    def run(case_seed: int, filter_name: str) -> None:
        _check(target, seeds, work, case_seed, filter_name)

    run()


def test_fuse_on_nmea_with_inserted_bytes(seeds: dict[str, bytes], work: Path) -> None:
    """Hypothesis' own bytes spliced into the NMEA log (binary noise, partial sentences)."""
    from gpsdr_cli.io.readers import read_drive
    from gpsdr_cli.pipeline import fuse

    nmea = seeds["gps.nmea"]
    for name in ("gyro.csv", "odo.csv"):
        (work / name).write_bytes(seeds[name])
    params = config.defaults()

    @_settings(150)
    @given(pos=st.integers(0, len(nmea)), blob=st.binary(min_size=1, max_size=200),
           filter_name=st.sampled_from(NAMES))
    def run(pos: int, blob: bytes, filter_name: str) -> None:
        (work / "gps.nmea").write_bytes(nmea[:pos] + blob + nmea[pos:])
        p = config.merge(params, {"filter": {"name": filter_name}})
        try:
            drive = read_drive(gps=work / "gps.nmea", gyro=work / "gyro.csv",
                               odo=work / "odo.csv", params=p)
            res = fuse(drive, p)
        except GpsdrError as err:
            assert type(err).__name__ != "NonFiniteOutputError", str(err)
            return
        assert F.track_problems(res.track, n_epochs=len(res.epochs)) == []

    run()


# ---------------------------------------------------------------------------- found by fuzzing

def test_csv_with_a_carriage_return_inside_a_row(tmp_path: Path) -> None:
    """readers: a lone CR inside a CSV row made the slow path's csv module raise _csv.Error."""
    from gpsdr_cli.io.csv import read_gyro_csv

    p = tmp_path / "gyro.csv"
    p.write_bytes(b"t,yaw_rate\n1715673600.0,0.1\n1715673600.1,0.\r1\n1715673600.2,0.1\n")
    try:
        d = read_gyro_csv(p, config.defaults()["gyro"])
    except GpsdrError:
        return
    assert d.gyro is not None and np.isfinite(d.gyro.yaw_rate_radps).all()


def test_one_record_with_a_far_future_time_stamp(tmp_path: Path) -> None:
    """pipeline/align: one gyro record stamped 23 days late (a corrupt digit) made the filter
    predict over 2e6 s; lat became inf and fuse failed with 'the filter diverged'."""
    from gpsdr_cli.io.readers import read_drive
    from gpsdr_cli.pipeline import fuse

    sim = F.base_sim(duration_s=20.0)
    paths = F._files(sim, tmp_path)
    lines = paths["gyro.csv"].read_bytes().splitlines(keepends=True)
    lines[-1] = lines[-1].replace(b"17156", b"17176", 1)  # +2e6 s on the last record
    paths["gyro.csv"].write_bytes(b"".join(lines))
    p = config.defaults()
    drive = read_drive(gps=paths["gps.nmea"], gyro=paths["gyro.csv"], odo=paths["odo.csv"],
                       params=p)
    try:
        res = fuse(drive, p)
    except GpsdrError as err:
        # a clear error naming the input is acceptable, the divergence guard is not
        assert type(err).__name__ != "NonFiniteOutputError", str(err)
        return
    assert F.track_problems(res.track, n_epochs=len(res.epochs)) == []


@pytest.mark.parametrize("cell", [b"1e999999", b"1715673603.901e3080000", b"-1e999999"])
def test_csv_time_with_a_huge_exponent(tmp_path: Path, cell: bytes) -> None:
    """readers: a time cell like '1.9e3080000' raised decimal.Overflow out of the CSV reader."""
    from gpsdr_cli.io.csv import read_gyro_csv

    p = tmp_path / "gyro.csv"
    p.write_bytes(b"t,yaw_rate\n1715673600.0,0.1\n" + cell + b",0.1\n1715673600.2,0.1\n")
    try:
        d = read_gyro_csv(p, config.defaults()["gyro"])
    except GpsdrError:
        return
    assert d.gyro is not None and np.isfinite(d.gyro.yaw_rate_radps).all()


@pytest.mark.parametrize("cell", [b"1e-320100000", b"1715673605.1e-320100000"])
def test_csv_time_with_a_huge_negative_exponent_does_not_crash(tmp_path: Path, cell: bytes) -> None:
    """readers: pyarrow's decimal128 conversion of '1e-320100000' segfaulted the process
    (gpsdr fuse --gyro F exited 139, no error line).  Run in a child so pytest survives."""
    import subprocess
    import sys

    p = tmp_path / "gyro.csv"
    p.write_bytes(b"t,yaw_rate\n1715673600.0,0.1\n" + cell + b",0.1\n1715673600.2,0.1\n")
    code = ("import sys\nfrom gpsdr_cli import config\nfrom gpsdr_cli.errors import GpsdrError\n"
            "from gpsdr_cli.io.csv import read_gyro_csv\n"
            "try:\n    read_gyro_csv(sys.argv[1], config.defaults()['gyro'])\n"
            "except GpsdrError:\n    pass\n")
    proc = subprocess.run([sys.executable, "-c", code, str(p)], capture_output=True, text=True,
                          timeout=120, check=False)
    assert proc.returncode == 0, f"exit {proc.returncode}: {proc.stderr[-300:]}"


def _replay(seed: int, index: int, expect: tuple[str, str], seeds: dict[str, bytes],
            work: Path) -> None:
    """``benchmarks/fuzz.py --one INDEX --seed SEED``: its case drawn the same way, which must
    be ``expect`` (target, filter), and no bug."""
    rng = np.random.default_rng(seed * 1_000_000_007 + index)
    weights = np.array([0.3, 0.15, 0.15, 0.2, 0.12, 0.08])  # fuzz.WEIGHTS, same order
    target = ["nmea", "gyro_csv", "odo_csv", "mcap", "e2e_files", "e2e_mcap"][
        int(rng.choice(6, p=weights / weights.sum()))]
    filter_name = NAMES[int(rng.integers(len(NAMES)))]
    assert (target, filter_name) == expect
    key, _ = F.fuzz_case(target, seeds, rng, work, filter_name=filter_name)
    assert not F.is_bug(key), key


def test_fuzz_case_19115_far_future_rmc_date(seeds: dict[str, bytes], work: Path) -> None:
    """Replays ``benchmarks/fuzz.py --one 19115 --seed 1`` (target e2e_files, filter ekf): a fix
    dated 2046 (mutated RMC year) as the last epoch made ekf predict over 22 years; the
    pipeline now drops stamps far from the rest of the drive, judged over all streams."""
    _replay(1, 19115, ("e2e_files", "ekf"), seeds, work)


def test_fuzz_case_37973_an_odometer_speed_of_1e308(seeds: dict[str, bytes], work: Path) -> None:
    """Replays ``benchmarks/fuzz.py --one 37973 --seed 20261205`` (target e2e_files, filter
    aekf): mutated odometer rows read 1e308 and 253409 m/s, and the dead reckoning before the
    first fix went to infinity.  The readers now leave out readings beyond a vehicle's
    physics (:data:`gpsdr_cli.io.readers.DR_LIMITS`), counted."""
    _replay(20261205, 37973, ("e2e_files", "aekf"), seeds, work)


def test_fuzz_case_28269_a_receiver_speed_of_1e7(seeds: dict[str, bytes], work: Path) -> None:
    """Replays ``benchmarks/fuzz.py --one 28269 --seed 20261206`` (target e2e_files, filter
    fkf): a mutated RMC speed field read 16 014 615 m/s, and fkf's receiver-velocity row sent
    the track to infinity.  The readers now leave such a speed out with its course, counted
    (the fix's position stays)."""
    _replay(20261206, 28269, ("e2e_files", "fkf"), seeds, work)
