"""A one-page PNG report of a fused track: map, error against time, PDOP, sigmas.

matplotlib is imported inside :func:`plot_report` (it is slow to import and
only this command needs it), through its object API with the Agg canvas, so
no global pyplot state or GUI backend is touched.

Conventions: :mod:`gpsdr_cli.conventions` (local east/north metres, int64 ns UTC).
Panels:
  * map (east/north, equal axes): GNSS fixes (grey dots, rejected ones red
    crosses), fused track (blue), reference (black), the fused track inside
    GNSS outages in orange with the start, end and length of each outage of 10 s
    or more marked;
  * horizontal error against time with outages shaded: against the reference
    when one is given (fused and GNSS-only), else the GNSS-minus-fused
    separation; both with the filter's horizontal 3-sigma envelope;
  * PDOP beneath, with the ``pdop_good`` line;
  * the sigma envelope: the filter's 1-sigma east and north;
  * when the track has ``separation_m`` (:mod:`gpsdr_cli.qc`): the forward/backward
    separation against time, with its RMS and 95th percentile, beside the horizontal
    1-sigma (the two figures the quality class grades).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pandas as pd

from .conventions import NS_PER_S
from .errors import InputError


def _runs(flag: np.ndarray) -> list[tuple[int, int]]:
    from .evaluation import outage_runs

    return outage_runs(flag)


def plot_report(track: pd.DataFrame, out_path: str | Path, reference_en: pd.DataFrame | None = None,
                title: str = "", *, pdop_good: float = 3.0, dpi: int = 110) -> Path:
    """Render the report of ``track`` (a gpsdr track table) to ``out_path``; return the path."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    from .evaluation import _t_ns_of, track_errors

    for col in ("e", "n"):
        if col not in track:
            raise InputError(str(out_path), f"cannot plot: the track has no {col} column")
    if len(track) == 0:
        raise InputError(str(out_path), "cannot plot an empty track")
    m = len(track)
    t_ns = _t_ns_of(track, "track")
    t_min = (t_ns - t_ns[0]) / NS_PER_S / 60.0

    def col(name: str, fill: float = np.nan) -> np.ndarray:
        return track[name].to_numpy(float) if name in track else np.full(m, fill)

    def bcol(name: str) -> np.ndarray:
        return track[name].fillna(False).to_numpy(bool) if name in track else np.zeros(m, bool)

    e, n = col("e"), col("n")
    ge, gn = col("gnss_e"), col("gnss_n")
    rejected = bcol("gnss_rejected")
    outage = bcol("gnss_outage")
    sig_e, sig_n = col("sigma_e"), col("sigma_n")
    sig_h = np.hypot(sig_e, sig_n)
    pdop = col("pdop")
    runs = _runs(outage)

    fig = Figure(figsize=(14, 9), dpi=dpi, layout="constrained")
    FigureCanvasAgg(fig)
    qsep = col("separation_m") if "separation_m" in track else None
    heights = [1.5, 0.7, 0.8] + ([0.8] if qsep is not None else [])
    gs = fig.add_gridspec(len(heights), 2, width_ratios=[1.05, 1.0], height_ratios=heights)
    ax_map = fig.add_subplot(gs[:, 0])
    ax_err = fig.add_subplot(gs[0, 1])
    ax_pdop = fig.add_subplot(gs[1, 1], sharex=ax_err)
    ax_sig = fig.add_subplot(gs[2, 1], sharex=ax_err)
    ax_sep = fig.add_subplot(gs[3, 1], sharex=ax_err) if qsep is not None else None

    # --- map
    okg = np.isfinite(ge) & np.isfinite(gn)
    ax_map.plot(ge[okg & ~rejected], gn[okg & ~rejected], ".", ms=2.5, color="0.6",
                label=f"GNSS fixes ({int((okg & ~rejected).sum())})", zorder=1)
    if (okg & rejected).any():
        ax_map.plot(ge[okg & rejected], gn[okg & rejected], "x", ms=4, color="tab:red",
                    label=f"rejected fixes ({int((okg & rejected).sum())})", zorder=2)
    if reference_en is not None and len(reference_en):
        tr = reference_en["t_ns"].to_numpy(np.int64)
        span = (tr >= t_ns[0] - NS_PER_S) & (tr <= t_ns[-1] + NS_PER_S)  # the track's stretch only
        ax_map.plot(reference_en["e"].to_numpy()[span], reference_en["n"].to_numpy()[span], "-",
                    lw=1.0, color="k", label="reference", zorder=3)
    ax_map.plot(e, n, "-", lw=1.2, color="tab:blue", label="fused", zorder=4)
    for k, (i0, i1) in enumerate(runs):
        ax_map.plot(e[i0:i1 + 1], n[i0:i1 + 1], "-", lw=2.5, color="tab:orange",
                    label="fused in GNSS outage" if k == 0 else None, zorder=5)
        if (t_ns[i1] - t_ns[i0]) / NS_PER_S < 10.0:
            continue  # short drop-outs: coloured, not labelled (a city drive has dozens)
        ax_map.plot(e[i0], n[i0], ">", color="tab:orange", ms=7, zorder=6)
        ax_map.plot(e[i1], n[i1], "s", color="tab:orange", ms=6, zorder=6)
        ax_map.annotate(f"{(t_ns[i1] - t_ns[i0]) / NS_PER_S:.0f} s", (e[i1], n[i1]),
                        textcoords="offset points", xytext=(5, 5), fontsize=8, color="tab:orange")
    ax_map.plot(e[0], n[0], "o", color="tab:green", ms=7, label="start", zorder=7)
    ax_map.set_aspect("equal", adjustable="datalim")
    ax_map.set_xlabel("east (m)")
    ax_map.set_ylabel("north (m)")
    ax_map.grid(True, lw=0.3)
    ax_map.legend(loc="best", fontsize=8)
    ax_map.set_title("map (local frame)")

    # --- error against time
    def shade(ax) -> None:
        for k, (i0, i1) in enumerate(runs):
            ax.axvspan(t_min[i0], t_min[i1], color="tab:orange", alpha=0.18, lw=0,
                       label="GNSS outage" if k == 0 else None)

    shade(ax_err)
    if reference_en is not None and len(reference_en):
        errs = track_errors(track, reference_en)
        d = errs["err_m"].to_numpy()
        if okg.any():
            from .evaluation import interpolate_reference

            re, rn, _, _, valid = interpolate_reference(reference_en, t_ns[okg])
            dg = np.where(valid, np.hypot(ge[okg] - re, gn[okg] - rn), np.nan)
            ax_err.plot(t_min[okg], dg, ".", ms=2, color="0.6", label="GNSS-only error")
        ax_err.plot(t_min, d, "-", lw=1.0, color="tab:blue", label="fused error")
        fin = d[np.isfinite(d)]
        txt = (f"RMSE {np.sqrt(np.mean(fin**2)):.2f} m, CEP95 {np.percentile(fin, 95):.2f} m, "
               f"max {fin.max():.2f} m") if len(fin) else "reference does not cover the track"
        ax_err.set_title(f"horizontal error against the reference: {txt}", fontsize=10)
    else:
        sep = np.hypot(ge - e, gn - n)
        ax_err.plot(t_min[okg], sep[okg], ".", ms=2, color="0.5", label="|GNSS - fused|")
        ax_err.set_title("no reference: GNSS-minus-fused separation vs the filter's 3-sigma",
                         fontsize=10)
        ax_err.set_yscale("log")  # separations of decimetres and 3-sigma of tens of metres
    if np.isfinite(sig_h).any():
        ax_err.plot(t_min, 3.0 * sig_h, "--", lw=1.0, color="tab:red", label="filter 3-sigma (horizontal)")
    ax_err.set_ylabel("m")
    if ax_err.get_yscale() == "linear":
        top = _robust_top(ax_err)
        ax_err.set_ylim(0.0, top) if top else ax_err.set_ylim(bottom=0.0)
    ax_err.grid(True, lw=0.3)
    ax_err.legend(loc="upper left", fontsize=8)

    # --- PDOP
    shade(ax_pdop)
    pdop_shown = np.where(outage, np.nan, pdop)  # the track carries the last PDOP through outages
    ax_pdop.plot(t_min, pdop_shown, "-", lw=0.8, color="tab:purple", label="PDOP")
    ax_pdop.axhline(pdop_good, color="tab:purple", lw=0.6, ls=":", label=f"pdop_good = {pdop_good:g}")
    if not np.isfinite(pdop).any():
        ax_pdop.text(0.5, 0.5, "no PDOP in the input", transform=ax_pdop.transAxes,
                     ha="center", va="center", color="0.4")
    ax_pdop.set_ylabel("PDOP")
    ax_pdop.set_ylim(bottom=0.0)
    ax_pdop.grid(True, lw=0.3)
    ax_pdop.legend(loc="upper left", fontsize=8)

    # --- sigma envelope
    shade(ax_sig)
    ax_sig.plot(t_min, sig_e, "-", lw=0.9, color="tab:blue", label="sigma east")
    ax_sig.plot(t_min, sig_n, "-", lw=0.9, color="tab:green", label="sigma north")
    if np.nanmax(np.concatenate([sig_e, sig_n, [0.0]])) > 0:
        ax_sig.set_yscale("log")
    ax_sig.set_ylabel("filter 1-sigma (m)")
    ax_last = ax_sig
    if ax_sep is not None and qsep is not None:
        shade(ax_sep)
        fin = qsep[np.isfinite(qsep)]
        ax_sep.plot(t_min, qsep, "-", lw=0.9, color="tab:brown", label="forward/backward separation")
        ax_sep.plot(t_min, sig_h, ":", lw=0.9, color="tab:blue", label="horizontal 1-sigma")
        if len(fin):
            ax_sep.set_title(f"separation: RMS {np.sqrt(np.mean(fin**2)):.2f} m, p95 "
                             f"{np.percentile(fin, 95):.2f} m, max {fin.max():.2f} m", fontsize=10)
        ax_sep.set_ylabel("separation (m)")
        top = _robust_top(ax_sep)
        ax_sep.set_ylim(0.0, top) if top else ax_sep.set_ylim(bottom=0.0)
        ax_sep.grid(True, lw=0.3)
        ax_sep.legend(loc="upper left", fontsize=8)
        ax_last = ax_sep
    ax_last.set_xlabel("minutes since " + pd.Timestamp(int(t_ns[0]), unit="ns", tz="UTC")
                      .strftime("%Y-%m-%d %H:%M:%S UTC"))
    ax_sig.grid(True, lw=0.3, which="both")
    ax_sig.legend(loc="upper left", fontsize=8)

    fig.suptitle(title or "gpsdr track report", fontsize=13)
    out = Path(out_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(out)
    return out


def _robust_top(ax) -> float | None:
    """A y limit that shows the bulk of the lines with some headroom (large spikes clip)."""
    ys = []
    for line in ax.get_lines():
        y = np.asarray(line.get_ydata(), float)
        ys.append(y[np.isfinite(y)])
    y = np.concatenate(ys) if ys else np.zeros(0)
    if not len(y):
        return None
    top = float(np.percentile(y, 99.5))
    return max(1.15 * top, 1.0) if top < 0.5 * float(y.max()) else None


__all__ = ["plot_report"]
