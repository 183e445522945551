"""The package's imports form no loop: docs/contributing.md ("Where things live").

Every ``import`` and ``from ... import`` in ``gpsdr_cli`` counts, the lazy ones inside
functions too (a lazy import that closes a loop is still a loop: it only hides it from
the interpreter).  ``from . import name`` points at the submodule ``name`` when there is
one, else at the package's ``__init__``.
"""

from __future__ import annotations

import ast
import graphlib
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[1] / "gpsdr_cli"


def _module_name(path: Path) -> str:
    rel = path.relative_to(PKG.parent).with_suffix("")
    parts = list(rel.parts)
    if parts[-1] == "__init__":
        parts = parts[:-1]
    return ".".join(parts)


def _modules() -> dict[str, Path]:
    return {_module_name(p): p for p in PKG.rglob("*.py")}


def _resolve(importer: str, is_pkg: bool, level: int, module: str | None) -> str:
    base = importer.split(".") if is_pkg else importer.split(".")[:-1]
    if level > 1:
        base = base[: len(base) - (level - 1)]
    return ".".join(base + ([module] if module else []))


def import_graph() -> dict[str, set[str]]:
    """Module -> the package modules it imports (anywhere in its source)."""
    mods = _modules()
    graph: dict[str, set[str]] = {m: set() for m in mods}
    for name, path in mods.items():
        is_pkg = path.name == "__init__.py"
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            targets: list[str] = []
            if isinstance(node, ast.Import):
                targets = [a.name for a in node.names]
            elif isinstance(node, ast.ImportFrom):
                src = (_resolve(name, is_pkg, node.level, node.module) if node.level
                       else node.module or "")
                for a in node.names:
                    sub = f"{src}.{a.name}"
                    targets.append(sub if sub in mods else src)
            for t in targets:
                while t and t not in mods:  # gpsdr_cli.io.nmea.X -> gpsdr_cli.io.nmea
                    t = t.rpartition(".")[0]
                if t and t != name and t.startswith("gpsdr_cli"):
                    graph[name].add(t)
    return graph


def find_cycle(graph: dict[str, set[str]]) -> list[str] | None:
    """One loop of the graph in import order, from its smallest module (first == last), or
    None.  graphlib reads the imports as predecessors, so its loop runs the other way."""
    try:
        graphlib.TopologicalSorter(graph).prepare()
    except graphlib.CycleError as err:
        loop = err.args[1][:-1][::-1]
        k = loop.index(min(loop))
        loop = loop[k:] + loop[:k]
        return loop + loop[:1]
    return None


def test_the_finder_sees_a_loop_and_its_absence():
    assert find_cycle({"a": {"b"}, "b": {"c"}, "c": {"a"}}) == ["a", "b", "c", "a"]
    assert find_cycle({"a": {"b", "c"}, "b": {"c"}, "c": set()}) is None


def test_the_graph_reads_relative_and_lazy_imports():
    g = import_graph()
    assert "gpsdr_cli.epochs" in g["gpsdr_cli.align"]                # from .epochs import
    assert "gpsdr_cli.filters.base" in g["gpsdr_cli.filters.accel_speed"]  # from .base
    assert "gpsdr_cli.align" in g["gpsdr_cli.pipeline"]              # lazy, in fuse's helpers
    assert "gpsdr_cli.filters" in g["gpsdr_cli.filters.aekf"]        # from . import register


@pytest.mark.parametrize("low", ["gpsdr_cli.epochs", "gpsdr_cli.conventions",
                                 "gpsdr_cli.errors", "gpsdr_cli.geodesy"])
def test_the_ground_floor_imports_no_stage(low):
    stages = {"gpsdr_cli.align", "gpsdr_cli.pipeline", "gpsdr_cli.filters", "gpsdr_cli.io"}
    assert not {t for t in import_graph()[low] if t.rsplit(".", 1)[0] in stages or t in stages}


def test_no_module_imports_round_a_loop():
    assert find_cycle(import_graph()) is None
