"""The command layer: help everywhere, exit statuses, one-line errors, fast start."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import click
import pytest

from gpsdr_cli.cli.main import cli
from tests.conftest import one_line_error

COMMANDS = sorted(cli.commands)


def test_all_commands_are_there() -> None:
    assert set(COMMANDS) >= {"fuse", "info", "stats", "simulate", "plot", "batch"}


@pytest.mark.parametrize("name", COMMANDS)
def test_every_command_has_help_with_an_example(gpsdr, name: str) -> None:
    result = gpsdr([name, "--help"])
    assert result.exit_code == 0, result.output
    assert "Examples:" in result.stdout
    assert f"gpsdr {name}" in result.stdout.split("Examples:", 1)[1]
    assert cli.commands[name].help and len(cli.commands[name].help) > 80


def test_group_help_and_version(gpsdr) -> None:
    result = gpsdr(["--help"])
    assert result.exit_code == 0
    for name in COMMANDS:
        assert name in result.stdout
    assert "Examples:" in result.stdout
    version = gpsdr(["--version"])
    assert version.exit_code == 0 and "0.1.0" in version.stdout


def test_filter_choices_match_the_registry() -> None:
    from gpsdr_cli.cli.options import FILTER_NAMES
    from gpsdr_cli.filters import NAMES

    assert FILTER_NAMES == NAMES


def test_cli_import_does_not_load_the_numeric_stack() -> None:
    """`gpsdr --help` must not import numpy/pandas/numba/pyarrow (they take ~1 s)."""
    code = ("import sys, gpsdr_cli.cli.main as m; "
            "print(sorted(x for x in ('numpy','pandas','numba','pyarrow','pyproj','rich','dask')"
            " if x in sys.modules))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


def test_print_config_round_trips(gpsdr, tmp_path: Path) -> None:
    from gpsdr_cli import config

    result = gpsdr(["fuse", "--print-config", "--filter", "fkf", "--smooth", "--gnss-offset",
                    "0.1", "--epsg", "32610"])
    assert result.exit_code == 0, result.output
    cfg = tmp_path / "p.toml"
    cfg.write_text(result.stdout)
    params = config.load(cfg)
    assert params["filter"] == {"name": "fkf", "smooth": True, "smoother": "rts"}
    assert params["time"]["gnss_offset_s"] == 0.1
    assert params["frame"]["epsg"] == 32610
    again = gpsdr(["fuse", "--print-config", "--config", cfg])
    assert again.stdout == result.stdout


@pytest.mark.parametrize("args", [
    ["fuse"],                                   # no input at all
    ["fuse", "--filter", "kalman", "x.nmea"],   # not a filter
    ["fuse", "--date", "02/08/2018", "x.nmea"],  # not ISO
    ["fuse", "--gnss-offset", "soon", "x.nmea"],
    ["fuse", "--topic", "gnss", "x.mcap"],      # KIND=NAME expected
    ["fuse", "a.mcap", "--gps", "b.nmea"],      # both forms at once
    ["nosuchcommand"],
    ["batch", "x"],                             # -o is required
    ["simulate"],                               # -o is required
    ["stats"],
])
def test_usage_errors_exit_2(gpsdr, args: list[str]) -> None:
    result = gpsdr(args)
    assert result.exit_code == 2, result.output
    assert "Traceback" not in result.output


def test_bad_toml_is_a_one_line_usage_error(gpsdr, tmp_path: Path) -> None:
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[filter\nname = 'aekf'\n")
    result = gpsdr(["fuse", "--print-config", "--config", cfg])
    assert result.exit_code == 2
    line = one_line_error(result)
    assert str(cfg) in line and "TOML" in line


def test_unknown_parameter_is_a_usage_error(gpsdr, tmp_path: Path) -> None:
    cfg = tmp_path / "p.toml"
    cfg.write_text("[filter]\nnmae = 'aekf'\n")
    result = gpsdr(["fuse", "--print-config", "--config", cfg])
    assert result.exit_code == 2
    assert "filter.nmae" in one_line_error(result)


def test_missing_config_file(gpsdr, tmp_path: Path) -> None:
    result = gpsdr(["fuse", "--print-config", "--config", tmp_path / "none.toml"])
    assert result.exit_code == 2
    assert "none.toml" in one_line_error(result)


def test_internal_errors_are_one_line_unless_debug(monkeypatch: pytest.MonkeyPatch, gpsdr) -> None:
    from gpsdr_cli.cli import options

    def boom(*args: object, **kwargs: object) -> None:
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(options, "make_params", boom)
    monkeypatch.setattr("gpsdr_cli.cli.fuse.make_params", boom)
    result = gpsdr(["fuse", "--print-config"])
    assert result.exit_code == 1
    line = one_line_error(result)
    assert line.startswith("gpsdr: error: internal error: ZeroDivisionError")
    debug = gpsdr(["fuse", "--print-config", "--debug"])
    assert debug.exit_code == 1
    assert "Traceback" in debug.stderr and "boom" in debug.stderr


def test_console_script_entry_point_runs(tmp_path: Path) -> None:
    out = subprocess.run([sys.executable, "-c", "from gpsdr_cli.cli.main import main; main()",
                          "fuse", "--nope"], check=False, capture_output=True, text=True)
    assert out.returncode == 2
    assert "No such option" in out.stderr


def test_fuse_default_output_names() -> None:
    from gpsdr_cli.cli.fuse import default_outputs, stats_next_to

    assert default_outputs("d/LOG.mcap", "parquet") == (Path("d/LOG.fused.parquet"),
                                                         Path("d/LOG.stats.parquet"))
    assert default_outputs("G.nmea", "csv") == (Path("G.fused.csv"), Path("G.stats.csv"))
    assert stats_next_to(Path("o/run.parquet"), "parquet") == Path("o/run.stats.parquet")
    assert stats_next_to(Path("x.fused.parquet"), "parquet") == Path("x.stats.parquet")


def test_click_usage_error_class_is_exit_2() -> None:
    assert click.UsageError("x").exit_code == 2
