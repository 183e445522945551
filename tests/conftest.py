"""Shared fixtures: the bundled comma2k19 sample drive and a CliRunner for ``gpsdr``;
:func:`load_benchmark` for the tests of the benchmark scripts."""

from __future__ import annotations

import importlib.util
import sys
from collections.abc import Callable, Sequence
from pathlib import Path
from types import ModuleType

import pytest
from click.testing import CliRunner, Result

REPO = Path(__file__).resolve().parents[1]

#: Modules whose tests are slow on a warm numba cache (measured with ``python -m pytest
#: FILE --durations=0``); single tests are listed in tests/slow_tests.txt.  ``pytest -m
#: "not slow"`` leaves them out of the edit-test loop; plain ``pytest`` (the README's
#: command, CI) runs them.  Lists rather than decorators: one place to keep up to date,
#: and no edits scattered over the test files.
SLOW_MODULES = frozenset({
    "tests/filters/test_aekf_reference.py",   # the plain-numpy reference, per epoch
    "tests/test_fuzz_e2e.py",                 # gpsdr fuse on many mutated files
    "tests/test_warmup.py",                   # compiles the kernels in fresh processes
    "tests/test_faults.py",                   # every fault x filter, ~1 min in all
    "tests/io/test_nmea_props.py",            # hypothesis, ~2 s per property
    "tests/test_accel_outages.py",            # no-odometer drives through the pipeline, ~15 s
    "tests/test_dr_health.py",                # faulty city drives, every filter, ~40 s
    "tests/filters/test_nlos_screen.py",      # batch fit + four filters on a city drive
})
#: Single slow tests (module::function, every parametrisation), one per line in
#: tests/slow_tests.txt: more than ~0.25 s each, so that the rest runs in under a minute.
SLOW_TESTS = frozenset(
    line.strip() for line in (REPO / "tests" / "slow_tests.txt").read_text().splitlines()
    if line.strip() and not line.startswith("#"))


def pytest_collection_modifyitems(config: pytest.Config, items: list[pytest.Item]) -> None:
    """Mark the tests of :data:`SLOW_MODULES` and :data:`SLOW_TESTS` ``slow``."""
    for item in items:
        module = Path(str(item.path)).resolve().relative_to(REPO).as_posix()
        name = getattr(item, "originalname", None) or item.name
        if module in SLOW_MODULES or f"{module}::{name}" in SLOW_TESTS:
            item.add_marker(pytest.mark.slow)
SAMPLE = REPO / "sample_logs" / "comma2k19"
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.hookimpl(wrapper=True)
def pytest_runtest_call(item: pytest.Item):
    """A test that reads the real logs beside the repository (``../shared/data``) is
    skipped, not failed, in a checkout that does not have them."""
    try:
        return (yield)
    except Exception as err:
        if not SHARED_DATA.exists() and str(SHARED_DATA.parent) in str(err):
            pytest.skip(f"the real data beside the repository is not here: {SHARED_DATA}")
        raise


@pytest.fixture(scope="session")
def sample_dir() -> Path:
    """sample_logs/comma2k19: gps.nmea, gyro.csv, odo.csv, truth.csv (60 s, real data)."""
    return SAMPLE


@pytest.fixture
def gpsdr() -> Callable[..., Result]:
    """Run ``gpsdr ARGS`` in-process; stdout and stderr are kept apart."""
    from gpsdr_cli.cli.main import cli

    runner = CliRunner()

    def run(args: Sequence[str], input: bytes | str | None = None) -> Result:
        return runner.invoke(cli, [str(a) for a in args], input=input, catch_exceptions=False)

    return run


def load_benchmark(name: str) -> ModuleType:
    """``benchmarks/<name>.py`` imported as the module ``<name>_bench`` (benchmarks/ is no package)."""
    spec = importlib.util.spec_from_file_location(f"{name}_bench", REPO / "benchmarks" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[f"{name}_bench"] = mod
    spec.loader.exec_module(mod)
    return mod


def one_line_error(result: Result) -> str:
    """The stderr of a failed run: exactly one line, no traceback."""
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    return lines[0]
