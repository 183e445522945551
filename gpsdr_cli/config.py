"""Every parameter of gpsdr with its default, documented in one place.

The defaults are the packaged ``defaults.toml`` beside this module: it is what ``gpsdr fuse --print-config``
starts from, and a user's ``--config PARAMS.toml`` overrides any subset of it.
Units are in the names (see :mod:`gpsdr_cli.conventions`).  Defaults marked
"(benchmark)" were chosen by ``benchmarks/accuracy.py``.

``Params`` is a plain ``dict[str, dict[str, value]]`` (section -> key -> value),
validated against the defaults: unknown sections or keys and wrong types are a
:class:`~gpsdr_cli.errors.ConfigError`, never silently ignored.
"""

from __future__ import annotations

import copy
import math
import tomllib
from pathlib import Path
from typing import Any

from .errors import ConfigError

Params = dict[str, dict[str, Any]]

#: The packaged defaults (``gpsdr_cli/defaults.toml``), read once.
DEFAULTS_TOML = (Path(__file__).with_name("defaults.toml")).read_text(encoding="utf-8")



def _parse_defaults() -> Params:
    # tomllib does read nan; keep them as floats.
    return tomllib.loads(DEFAULTS_TOML)


DEFAULTS: Params = _parse_defaults()


def defaults() -> Params:
    """A fresh copy of the defaults."""
    return copy.deepcopy(DEFAULTS)


def merge(base: Params, overrides: dict[str, Any], source: str = "parameters") -> Params:
    """Return ``base`` updated by ``overrides``, checking sections, keys and types."""
    out = copy.deepcopy(base)
    for section, values in overrides.items():
        if section not in out:
            raise ConfigError(f"{source}: unknown section [{section}]; "
                              f"known: {', '.join(sorted(out))}")
        if not isinstance(values, dict):
            raise ConfigError(f"{source}: [{section}] must be a table of key = value")
        for key, value in values.items():
            if key not in out[section]:
                raise ConfigError(f"{source}: unknown parameter {section}.{key}; "
                                  f"known in [{section}]: {', '.join(sorted(out[section]))}")
            out[section][key] = _coerce(out[section][key], value, f"{source}: {section}.{key}")
    return out


def _coerce(default: Any, value: Any, where: str) -> Any:
    if isinstance(default, bool):
        if isinstance(value, bool):
            return value
    elif isinstance(default, int):
        if isinstance(value, int) and not isinstance(value, bool):
            return value
    elif isinstance(default, float):
        if isinstance(value, (int, float)) and not isinstance(value, bool):
            return float(value)
    elif isinstance(default, str) and isinstance(value, str):
        return value
    elif isinstance(default, list):
        # a list of floats (e.g. [gnss] lever_arm_m): 2 to len(default) numbers, padded with 0
        if (isinstance(value, (list, tuple)) and 2 <= len(value) <= len(default)
                and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)):
            return [float(v) for v in value] + [0.0] * (len(default) - len(value))
        raise ConfigError(f"{where} = {value!r}: expected a list of 2 to {len(default)} numbers")
    raise ConfigError(f"{where} = {value!r}: expected {type(default).__name__}")


def load(path: str | Path | None, base: Params | None = None) -> Params:
    """Defaults (or ``base``) overridden by a TOML file."""
    params = defaults() if base is None else base
    if path is None:
        return params
    try:
        text = Path(path).read_text(encoding="utf-8")
    except OSError as err:
        raise ConfigError(f"{path}: cannot read the parameter file: {err.strerror}") from err
    except UnicodeDecodeError as err:
        raise ConfigError(f"{path}: not UTF-8 text: {err}") from err
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise ConfigError(f"{path}: invalid TOML: {err}") from err
    return merge(params, data, str(path))


def set_value(params: Params, dotted: str, value: Any) -> Params:
    """Set ``section.key`` (from a command-line option) with the same checks."""
    section, _, key = dotted.partition(".")
    return merge(params, {section: {key: value}}, "option")


def _fmt(value: Any) -> str:
    if isinstance(value, bool):
        return "true" if value else "false"
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        return repr(value)
    if isinstance(value, list):
        return "[" + ", ".join(_fmt(v) for v in value) + "]"
    if isinstance(value, str):
        return '"' + value.replace("\\", "\\\\").replace('"', '\\"') + '"'
    return str(value)


def to_toml(params: Params) -> str:
    """The effective parameters as TOML (``--print-config``); loads back to the same values."""
    lines: list[str] = []
    for section, values in params.items():
        lines.append(f"[{section}]")
        lines.extend(f"{key} = {_fmt(v)}" for key, v in values.items())
        lines.append("")
    return "\n".join(lines)


def flat(params: Params) -> dict[str, str]:
    """``section.key -> value`` strings, for Parquet file metadata."""
    return {f"{s}.{k}": _fmt(v) for s, vals in params.items() for k, v in vals.items()}
