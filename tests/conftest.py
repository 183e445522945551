"""Shared fixtures: the bundled comma2k19 sample drive and a CliRunner for ``gpsdr``."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from pathlib import Path

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


def one_line_error(result: Result) -> str:
    """The stderr of a failed run: exactly one line, no traceback."""
    lines = [ln for ln in result.stderr.splitlines() if ln.strip()]
    assert len(lines) == 1, result.stderr
    assert "Traceback" not in result.stderr
    return lines[0]
