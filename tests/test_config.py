"""Parameters: defaults, TOML overrides, validation, and the --print-config round trip."""

from __future__ import annotations

import math
import tomllib

import pytest

from gpsdr_cli import config
from gpsdr_cli.errors import ConfigError


def _same(a: object, b: object) -> bool:
    return a == b or (isinstance(a, float) and isinstance(b, float) and math.isnan(a) and math.isnan(b))


def test_print_config_round_trips() -> None:
    params = config.defaults()
    back = tomllib.loads(config.to_toml(params))
    assert back.keys() == params.keys()
    for section, values in params.items():
        for key, value in values.items():
            assert _same(back[section][key], value), f"{section}.{key}"


def test_override_from_file(tmp_path) -> None:
    path = tmp_path / "p.toml"
    path.write_text('[filter]\nname = "fkf"\n[gnss]\nuere_m = 4\n', encoding="utf-8")
    params = config.load(path)
    assert params["filter"]["name"] == "fkf"
    assert params["gnss"]["uere_m"] == 4.0 and isinstance(params["gnss"]["uere_m"], float)
    assert config.DEFAULTS["filter"]["name"] == "aekf"  # defaults untouched


@pytest.mark.parametrize(
    ("text", "match"),
    [("[nosuch]\na = 1\n", "unknown section"),
     ("[gnss]\nuere = 1\n", "unknown parameter gnss.uere"),
     ("[gnss]\nuere_m = \"x\"\n", "expected float"),
     ("[filter]\nsmooth = 1\n", "expected bool"),
     ("[gnss\n", "invalid TOML")],
)
def test_bad_files_name_the_problem(tmp_path, text: str, match: str) -> None:
    path = tmp_path / "bad.toml"
    path.write_text(text, encoding="utf-8")
    with pytest.raises(ConfigError, match=match) as info:
        config.load(path)
    assert str(path) in str(info.value)


def test_missing_file_is_a_config_error(tmp_path) -> None:
    with pytest.raises(ConfigError, match="cannot read"):
        config.load(tmp_path / "nope.toml")


def test_flat_names_every_parameter() -> None:
    params = config.defaults()
    flat = config.flat(params)
    assert len(flat) == sum(len(v) for v in params.values())
    assert flat["filter.name"] == '"aekf"'
