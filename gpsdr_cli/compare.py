"""Every filter (and smoother) on the same drive, one row each (``gpsdr compare``).

The drive is read once by the caller; each run goes through :func:`gpsdr_cli.pipeline.fuse`
with only ``[filter] name`` and ``[filter] smooth`` changed, so a row's figures are
those ``gpsdr fuse`` reports for the same filter, smoother and parameters.

Columns of the table: ``filter``, ``smoother``, ``epochs``; against a reference
``rmse_m``, ``mean_m``, ``cep50_m``, ``cep95_m``, ``max_m`` (the ``all`` segment of
:mod:`gpsdr_cli.evaluation`); always the health figures ``nis_in_95_share`` and
``gnss_separation_rmse_m``; ``separation_rms_m`` and ``separation_p95_m`` of the
forward/backward ``separation_m`` column when the track has it; ``gnss_used`` and
``gnss_rejected`` fix counts and ``run_s`` (wall time of the run).

Smoothers: ``none``, ``rts``, ``graph`` and ``auto``, the pipeline's choice for the drive
(:func:`gpsdr_cli.pipeline.smoother_of`, what ``gpsdr fuse`` runs by default).  An ``auto``
row is labelled with the smoother that ran, and left out where that filter already has a
row of it (a drive without gyro or odometer: ``rts``).

Conventions: :mod:`gpsdr_cli.conventions` (metres, int64 ns UTC).
"""

from __future__ import annotations

import copy
import math
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from .config import Params
from .conventions import NS_PER_S
from .errors import UsageError

if TYPE_CHECKING:
    from .io.drive import Drive
    from .io.reference import Reference

#: Column -> "unit, meaning" for the table's Parquet field metadata.
COMPARE_COLUMNS: dict[str, str] = {
    "filter": "filter name",
    "smoother": "smoother over the forward pass (none = forward only)",
    "epochs": "count of filter epochs",
    "rmse_m": "m, horizontal RMS error against the reference",
    "mean_m": "m, mean horizontal error",
    "cep50_m": "m, 50th percentile of horizontal error",
    "cep95_m": "m, 95th percentile of horizontal error",
    "max_m": "m, largest horizontal error",
    "nis_in_95_share": "share of GNSS updates whose NIS is inside the 95 % chi-square(2) bound",
    "gnss_separation_rmse_m": "m, RMS distance between the GNSS fixes and the fused track",
    "separation_rms_m": "m, RMS of the forward/backward separation_m (null without the column)",
    "separation_p95_m": "m, 95th percentile of separation_m (null without the column)",
    "gnss_used": "count of GNSS fixes applied",
    "gnss_rejected": "count of GNSS fixes rejected by the innovation gate",
    "run_s": "s, wall time of the run",
}

_FIGURES = ("rmse_m", "mean_m", "cep50_m", "cep95_m", "max_m", "nis_in_95_share",
            "gnss_separation_rmse_m")


def smoother_names(params: Params) -> tuple[str, ...]:
    """The smoothers ``--smooth`` accepts (``[filter] smoother``'s values)."""
    from .pipeline import SMOOTHERS

    return tuple(SMOOTHERS)


def with_smoother(params: Params, smoother: str) -> Params:
    """A copy of ``params`` running ``smoother`` (``none``, ``rts``, ``graph``)."""
    names = smoother_names(params)
    if smoother not in names:
        raise UsageError(f"--smooth {smoother}: unknown smoother; choose from {', '.join(names)}")
    p = copy.deepcopy(params)
    p["filter"]["smoother"] = smoother
    p["filter"]["smooth"] = smoother != "none"
    return p


def parse_list(text: str, what: str, choices: tuple[str, ...] | None) -> list[str]:
    """``"ekf, aekf"`` -> ``["ekf", "aekf"]`` (in order, once each), checked against ``choices``."""
    items = list(dict.fromkeys(x.strip().lower() for x in text.split(",") if x.strip()))
    if not items:
        raise UsageError(f"--{what} {text!r}: give at least one name")
    if choices is not None:
        bad = [x for x in items if x not in choices]
        if bad:
            raise UsageError(f"--{what} {','.join(bad)}: unknown; choose from {', '.join(choices)}")
    return items


@dataclass
class Run:
    """One filter x smoother: its row and what the overlay plot draws."""

    filter: str
    smoother: str
    row: dict[str, Any]
    t_ns: np.ndarray
    e: np.ndarray
    n: np.ndarray
    sigma_h: np.ndarray
    err_m: np.ndarray | None  # against the reference, per epoch

    @property
    def label(self) -> str:
        return self.filter if self.smoother == "none" else f"{self.filter} + {self.smoother}"


@dataclass
class Comparison:
    table: pd.DataFrame
    runs: list[Run]
    reference_en: pd.DataFrame | None
    gnss_e: np.ndarray
    gnss_n: np.ndarray
    metadata: dict[str, str]


def compare(drive: Drive, params: Params, reference: Reference | None, filters: list[str],
            smoothers: list[str], *, auto_gnss_offset: bool = False,
            progress: Callable[[str], None] | None = None) -> Comparison:
    """Run every filter x smoother over ``drive`` (unchanged) and tabulate them."""
    from .evaluation import _t_ns_of, track_errors
    from .pipeline import fuse

    runs: list[Run] = []
    ref_en = None
    gnss_e = gnss_n = np.zeros(0)
    meta: dict[str, str] = {}
    for name in filters:
        for smoother in smoothers:
            p = with_smoother(params, smoother)
            p["filter"]["name"] = name
            if progress:
                progress(f"{name} + {smoother}")
            t0 = time.perf_counter()
            res = fuse(drive, p, reference, auto_gnss_offset=auto_gnss_offset)
            run_s = time.perf_counter() - t0
            s = _all_row(res.stats)
            track = res.track
            if smoother == "auto" or res.metadata.get("smoother") == "none":
                # labelled with what ran (a graph that failed to converge leaves RTS; dead
                # reckoning alone is not smoothed)
                smoother = res.metadata.get("smoother", smoother)
            if any(r.filter == name and r.smoother == smoother for r in runs):
                continue                         # auto's choice, run under its name too
            row: dict[str, Any] = {"filter": name, "smoother": smoother, "epochs": len(track)}
            row.update({k: s[k] for k in _FIGURES})
            sep = (pd.to_numeric(track["separation_m"], errors="coerce").to_numpy(float)
                   if "separation_m" in track else np.zeros(0))
            sep = sep[np.isfinite(sep)]
            row["separation_rms_m"] = float(np.sqrt(np.mean(sep ** 2))) if len(sep) else math.nan
            row["separation_p95_m"] = float(np.percentile(sep, 95)) if len(sep) else math.nan
            row["gnss_used"] = int(track["gnss_used"].sum())
            row["gnss_rejected"] = int(track["gnss_rejected"].sum())
            row["run_s"] = run_s
            ref_en = res.reference_en
            err = track_errors(track, ref_en)["err_m"].to_numpy() if ref_en is not None else None
            t_ns = _t_ns_of(track, "track")
            runs.append(Run(name, smoother, row, t_ns, track["e"].to_numpy(float),
                            track["n"].to_numpy(float),
                            np.hypot(track["sigma_e"].to_numpy(float),
                                     track["sigma_n"].to_numpy(float)), err))
            if not meta:
                gnss_e = track["gnss_e"].to_numpy(float)
                gnss_n = track["gnss_n"].to_numpy(float)
                meta = {k: v for k, v in res.metadata.items()
                        if k.startswith(("input", "frame.", "gpsdr.", "skipped", "reference"))}
    table = pd.DataFrame([r.row for r in runs], columns=list(COMPARE_COLUMNS))
    for col in _FIGURES + ("separation_rms_m", "separation_p95_m", "run_s"):
        vals = np.array(table[col].to_numpy(dtype=float, na_value=np.nan))
        vals[~np.isfinite(vals)] = np.nan
        table[col] = pd.array(vals, dtype="Float64")  # NaN -> <NA>: a Parquet null
    meta["compare.filters"] = ",".join(filters)
    meta["compare.smoothers"] = ",".join(smoothers)
    return Comparison(table, runs, ref_en, gnss_e, gnss_n, meta)


def _all_row(stats: pd.DataFrame) -> dict[str, float]:
    """The figures of the statistics' ``all`` segment (NaN for nulls and missing columns)."""
    rows = stats[stats["segment"] == "all"]
    return {c: float(rows[c].to_numpy(dtype=float, na_value=np.nan)[0])
            if c in rows and len(rows) else math.nan for c in _FIGURES}


def plot_overlay(cmp: Comparison, out_path: Any, title: str = "") -> Any:
    """Overlay of the runs' tracks on one map (GNSS fixes grey, reference black), and beside
    it the horizontal error against time per run (with a reference) or the filters'
    horizontal 1-sigma (without).  Written atomically; returns the path."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from .report.atomic import atomic_path

    fig = Figure(figsize=(14, 7), dpi=110, layout="constrained")
    FigureCanvasAgg(fig)
    ax_map, ax_t = fig.subplots(1, 2, width_ratios=[1.0, 1.1])
    ok = np.isfinite(cmp.gnss_e) & np.isfinite(cmp.gnss_n)
    ax_map.plot(cmp.gnss_e[ok], cmp.gnss_n[ok], ".", ms=2, color="0.7",
                label=f"GNSS fixes ({int(ok.sum())})", zorder=1)
    t_first = cmp.runs[0].t_ns if cmp.runs else np.zeros(1, np.int64)
    ref = cmp.reference_en
    if ref is not None and len(ref):
        tr = ref["t_ns"].to_numpy(np.int64)
        span = (tr >= t_first[0] - NS_PER_S) & (tr <= t_first[-1] + NS_PER_S)
        ax_map.plot(ref["e"].to_numpy()[span], ref["n"].to_numpy()[span], "-", lw=1.6,
                    color="k", label="reference", zorder=2)
    # one colour per filter, the line style per smoother (solid: forward only)
    names = list(dict.fromkeys(r.filter for r in cmp.runs))
    colours = [f"C{names.index(r.filter) % 10}" for r in cmp.runs]
    for run, colour in zip(cmp.runs, colours, strict=True):
        dash = "-" if run.smoother == "none" else ("--", ":", "-.")[
            (list(dict.fromkeys(r.smoother for r in cmp.runs)).index(run.smoother) - 1) % 3]
        rmse = run.row.get("rmse_m")
        label = run.label + (f" (RMSE {rmse:.2f} m)" if rmse is not None and
                             not pd.isna(rmse) else "")
        ax_map.plot(run.e, run.n, dash, lw=1.0, color=colour, label=label, zorder=3)
        t_min = (run.t_ns - t_first[0]) / NS_PER_S / 60.0
        if run.err_m is not None:
            ax_t.plot(t_min, run.err_m, dash, lw=0.9, color=colour, label=run.label)
        else:
            ax_t.plot(t_min, run.sigma_h, dash, lw=0.9, color=colour, label=run.label)
    ax_map.set_aspect("equal", adjustable="datalim")
    ax_map.set_xlabel("east (m)")
    ax_map.set_ylabel("north (m)")
    ax_map.grid(True, lw=0.3)
    ax_map.legend(loc="best", fontsize=8)
    ax_map.set_title("tracks (local frame)")
    if ref is not None:
        ax_t.set_title("horizontal error against the reference")
        ax_t.set_ylabel("m")
        ax_t.set_ylim(bottom=0.0)
    else:
        ax_t.set_title("no reference: the filters' horizontal 1-sigma")
        ax_t.set_ylabel("m")
        ax_t.set_yscale("log")
    ax_t.set_xlabel("minutes since " + pd.Timestamp(int(t_first[0]), unit="ns", tz="UTC")
                    .strftime("%Y-%m-%d %H:%M:%S UTC"))
    ax_t.grid(True, lw=0.3, which="both")
    ax_t.legend(loc="upper left", fontsize=8, ncol=2)
    fig.suptitle(title or "gpsdr compare", fontsize=13)
    with atomic_path(out_path) as tmp:
        fig.savefig(tmp, format=str(out_path).rsplit(".", 1)[-1].lower()
                    if "." in str(out_path) else "png")
    return out_path


__all__ = ["COMPARE_COLUMNS", "Comparison", "compare", "parse_list", "plot_overlay",
           "smoother_names", "with_smoother"]
