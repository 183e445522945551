"""The slow-test lists (conftest.py, slow_tests.txt) name tests that exist (a renamed test
would silently join the quick loop otherwise)."""

from __future__ import annotations

import ast

from .conftest import REPO, SLOW_MODULES, SLOW_TESTS


def test_every_listed_slow_test_exists() -> None:
    for module in SLOW_MODULES:
        assert (REPO / module).is_file(), module
    names: dict[str, set[str]] = {}
    for entry in sorted(SLOW_TESTS):
        module, _, name = entry.partition("::")
        if module not in names:
            tree = ast.parse((REPO / module).read_text(encoding="utf-8"))
            names[module] = {n.name for n in ast.walk(tree) if isinstance(n, ast.FunctionDef)}
        assert name in names[module], entry
