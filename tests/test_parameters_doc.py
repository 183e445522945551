"""docs/parameters.md is generated from gpsdr_cli/defaults.toml and kept up to date."""

from __future__ import annotations

from pathlib import Path

from gpsdr_cli.config import DEFAULTS, parameter_docs, parameters_markdown, unit_of

REPO = Path(__file__).resolve().parents[1]


def test_parameters_md_is_up_to_date() -> None:
    on_disk = (REPO / "docs" / "parameters.md").read_text(encoding="utf-8")
    assert on_disk == parameters_markdown(), (
        "docs/parameters.md is stale: run "
        "python -m gpsdr_cli.config --markdown > docs/parameters.md")


def test_every_parameter_is_documented_once_with_a_meaning() -> None:
    rows = parameter_docs()
    keys = [(s, k) for s, k, _ in rows]
    assert len(keys) == len(set(keys))
    assert set(keys) == {(s, k) for s in DEFAULTS for k in DEFAULTS[s]}
    assert [f"{s}.{k}" for s, k, m in rows if not m] == []


def test_units_come_from_the_name() -> None:
    assert unit_of("gate_reset_s") == "s"
    assert unit_of("max_speed_mps") == "m/s"
    assert unit_of("a_max_mps2") == "m/s^2"
    assert unit_of("bias_sd_radps") == "rad/s"
    assert unit_of("uere_m") == "m"
    assert unit_of("k_good") == ""
    md = parameters_markdown()
    assert "| `gnss.gate_reset_s` | `10.0` | s |" in md
    assert "| `filter.name` | `\"aekf\"` | - | ekf \\| aekf \\| fkf \\| fafkf |" in md
