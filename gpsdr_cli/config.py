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
import re
import sys
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


#: Unit of a parameter from its name's suffix (the naming rule of :mod:`gpsdr_cli.conventions`).
UNIT_SUFFIXES: tuple[tuple[str, str], ...] = (
    ("_m2ps5", "m^2/s^5"), ("_mps2", "m/s^2"), ("_mps", "m/s"), ("_radps", "rad/s"),
    ("_rad", "rad"), ("_deg", "deg"), ("_hz", "Hz"), ("_m", "m"), ("_s", "s"),
    ("_epochs", "epochs"), ("_fixes", "fixes"), ("_count", "readings"),
)

_KEY_LINE = re.compile(r"^([A-Za-z_][A-Za-z0-9_]*)\s*=")
_CONTINUATION = re.compile(r"^\s{8,}#\s?(.*)$")


def unit_of(key: str) -> str:
    """The unit a parameter's name declares (``gate_reset_s`` -> ``s``), or "" (none or a ratio)."""
    for suffix, unit in UNIT_SUFFIXES:
        if key.endswith(suffix):
            return unit
    return ""


def parameter_docs(text: str = DEFAULTS_TOML) -> list[tuple[str, str, str]]:
    """``(section, key, meaning)`` for every parameter, in file order, from the TOML comments.

    The meaning is the comment after the value, joined with its indented continuation lines.
    """
    rows: list[tuple[str, str, str]] = []
    section = ""
    for line in text.splitlines():
        stripped = line.strip()
        if stripped.startswith("[") and stripped.endswith("]"):
            section = stripped[1:-1]
            continue
        cont = _CONTINUATION.match(line)
        if cont and rows:
            sec, key, meaning = rows[-1]
            rows[-1] = (sec, key, f"{meaning} {cont.group(1).strip()}".strip())
            continue
        m = _KEY_LINE.match(line)
        if m:
            comment = re.search(r"\s#\s?(.*)$", line[m.end():])
            rows.append((section, m.group(1), comment.group(1).strip() if comment else ""))
    return rows


def parameters_markdown(params: Params | None = None) -> str:
    """docs/parameters.md: every parameter with its section, default, unit and meaning."""
    params = DEFAULTS if params is None else params
    out = ["# Parameters", "",
           "Generated from `gpsdr_cli/defaults.toml` by "
           "`python -m gpsdr_cli.config --markdown > docs/parameters.md`; do not edit by hand.",
           "Override any subset with `gpsdr fuse --config PARAMS.toml`; "
           "`gpsdr fuse --print-config` prints the effective values.", ""]
    section = None
    for sec, key, meaning in parameter_docs():
        if sec != section:
            section = sec
            out += [f"## [{sec}]", "", "| parameter | default | unit | meaning |",
                    "|---|---|---|---|"]
        value = _fmt(params[sec][key]).replace("|", "\\|")
        text = meaning.replace("|", "\\|") or "-"
        out.append(f"| `{sec}.{key}` | `{value}` | {unit_of(key) or '-'} | {text} |")
        if sec != section:
            out.append("")
    lines: list[str] = []
    for i, line in enumerate(out):  # a blank line after each table
        if line.startswith("## [") and i and out[i - 1] != "":
            lines.append("")
        lines.append(line)
    return "\n".join(lines) + "\n"


def main(argv: list[str] | None = None) -> int:
    """``python -m gpsdr_cli.config --markdown``: print docs/parameters.md."""
    args = sys.argv[1:] if argv is None else argv
    if args != ["--markdown"]:
        print("usage: python -m gpsdr_cli.config --markdown > docs/parameters.md", file=sys.stderr)
        return 2
    sys.stdout.write(parameters_markdown())
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
