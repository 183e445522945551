"""Test and benchmark helpers that ship with the package: fault injectors and output checks.

:mod:`gpsdr_cli.testing.faults` holds plain functions that damage a drive the
way real logs get damaged (outages, jumps, clock steps, corrupt bytes), reused
by the test suite, ``benchmarks/fault_table.py`` and ``benchmarks/fuzz.py``.
"""

from __future__ import annotations

from . import faults

__all__ = ["faults"]
