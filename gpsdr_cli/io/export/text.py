"""Column-at-a-time text formatting shared by the XML and JSON writers.

Each helper turns one numpy column into a list of strings (one per row), so a writer joins
rows with ``zip`` instead of building an object per point: that is what keeps a 360 k-point
export within its time budget (docs/decisions/0006-export-writers.md).  Also the track's
``time`` column as int64 ns (:func:`time_ns`), which every writer reads.
"""

from __future__ import annotations

from typing import TYPE_CHECKING
from xml.sax.saxutils import escape, quoteattr

import numpy as np

if TYPE_CHECKING:
    import pandas as pd

#: Decimals for lat/lon in text formats: 1e-10 deg (0.01 mm), so a reader's value is within
#: 5e-11 deg of the double gpsdr holds.
DEG_DECIMALS = 10


def _formatted(fmt: str, values: np.ndarray) -> list[str]:
    arr = np.asarray(values, float)
    out = [fmt.format(v) for v in arr.tolist()]
    for k in np.flatnonzero(~np.isfinite(arr)).tolist():
        out[k] = ""
    return out


def numbers(values: np.ndarray, decimals: int) -> list[str]:
    """``values`` as fixed-point text; NaN becomes ``""`` (the caller omits the element)."""
    return _formatted(f"{{:.{decimals}f}}", values)


def elements(tag: str, values: np.ndarray, decimals: int) -> list[str]:
    """``<tag>value</tag>`` per row, ``""`` where the value is NaN (an optional element)."""
    return _formatted(f"<{tag}>{{:.{decimals}f}}</{tag}>", values)


def nullable(values: np.ndarray, decimals: int) -> list[float | None]:
    """``values`` rounded to ``decimals``, NaN/inf as None (JSON null)."""
    arr = np.round(np.asarray(values, float), decimals)
    out = arr.astype(object)
    out[~np.isfinite(arr)] = None
    return out.tolist()


def integers(tag: str, values: np.ndarray) -> list[str]:
    """``<tag>k</tag>`` per row of an integer or bool column (a float column: NaN omitted)."""
    arr = np.asarray(values)
    if arr.dtype.kind == "f":
        return elements(tag, arr, 0)
    return [f"<{tag}>{v}</{tag}>" for v in arr.astype(np.int64).tolist()]


def iso_times(t_ns: np.ndarray) -> list[str]:
    """int64 ns UTC -> ``YYYY-MM-DDThh:mm:ss.ffffffZ`` (microseconds: what GPX readers parse)."""
    text = np.datetime_as_string(np.asarray(t_ns, np.int64).astype("datetime64[ns]")
                                 .astype("datetime64[us]"), unit="us")
    return [s + "Z" for s in text.tolist()]


def time_ns(track: pd.DataFrame) -> np.ndarray:
    """The ``time`` column as int64 ns since the UTC epoch."""
    return track["time"].to_numpy("datetime64[ns]").view(np.int64)


__all__ = ["DEG_DECIMALS", "elements", "escape", "integers", "iso_times", "nullable",
           "numbers", "quoteattr", "time_ns"]
