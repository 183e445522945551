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
SAMPLE = REPO / "sample_logs" / "comma2k19"
SHARED_DATA = REPO.parent / "shared" / "data"


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
