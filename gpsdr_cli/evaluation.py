"""Error statistics of a fused track, against a reference trajectory or on its own.

docs/algorithms.md#statistics and INTERFACE.md "Statistics Parquet".  Conventions:
:mod:`gpsdr_cli.conventions` (int64 ns UTC, metres in the track's local frame,
heading clockwise from north).

With a reference
    The reference (lat/lon, or e/n already in the frame) is projected into the
    track's local frame and interpolated linearly in time onto the track epochs,
    only inside its span and only between reference samples at most
    ``max_gap_s`` (1 s) apart: no interpolation across a reference gap.
    Horizontal error per epoch ``d = |p_track - p_ref|``; statistics: count,
    mean, RMSE, CEP50 and CEP95 (50th/95th percentile of ``d``), max.  The error
    vector is split into an along-track part (its projection on the reference's
    direction of travel over +-0.5 s, positive = track ahead) and a cross-track
    part (positive = track to the right of the reference's travel).
Segments
    ``all``; ``open``: PDOP < ``[gnss] pdop_good`` outside outages; ``degraded``:
    PDOP >= pdop_good outside outages; ``outage``: the track's ``gnss_outage``
    flag; ``static``: the track's ``static`` flag (standstill detected).  Plus one
    row per GNSS outage, ``outage_<i>`` (i = 1, 2, ... in time order), with
    ``duration_s`` (from the last epoch before the outage to its last epoch),
    ``distance_m`` (driven meanwhile, step by step along the reference where it
    covers both epochs of a step, else along the fused track), ``end_error_m``
    (error at the outage's last epoch that the reference covers, before the
    returning fix is applied; that epoch's time is ``end_error_utc`` -- earlier
    than ``end_utc`` when the outage runs past the end of the reference, as a drive
    whose GNSS stops before the log does) and ``end_error_pct_distance`` (the end
    error over the distance driven from the last fix to that epoch).  An outage
    that begins before the reference does is measured the same way: its end
    error needs only the reference at its end, its distance falls back to the
    fused track where the reference is missing.
Without a reference (and always)
    ``nis_in_95_share``: share of 2-dof GNSS updates whose NIS is inside the 95 %
    chi-square bound 5.991; ``gnss_separation_rmse_m``: RMS of |GNSS fix -
    fused position| at GNSS epochs.
Quality checks (when the track has the columns, :mod:`gpsdr_cli.qc`)
    ``separation_rms_m``, ``separation_p95_m``, ``separation_max_m``: RMS, 95th
    percentile and largest forward/backward separation over the segment's epochs;
    ``quality_<k>_share`` (k = 1 .. 6): share of the segment's epochs in class k.

Every float column is pandas' nullable ``Float64``: a figure that cannot be
computed (no reference, empty segment) is a null, which Parquet stores as null.
"""

from __future__ import annotations

from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from .config import Params
from .conventions import NS_PER_S, STATS_COLUMNS
from .epochs import true_runs
from .errors import InputError

if TYPE_CHECKING:
    from .geodesy import LocalFrame
    from .io.reference import Reference

#: chi-square(2) 95 % quantile: -2 ln(0.05)
CHI2_2DOF_95 = 5.991464547107979
#: the reference is not interpolated across gaps longer than this (s)
MAX_REFERENCE_GAP_S = 1.0

SEGMENTS: tuple[str, ...] = ("all", "open", "degraded", "outage", "static")

_FLOAT_COLUMNS = [c for c in STATS_COLUMNS if c not in ("filter", "segment", "epochs")]


# --------------------------------------------------------------------------- reference

def reference_en(reference: Reference | pd.DataFrame, frame: LocalFrame) -> pd.DataFrame:
    """The reference in ``frame``: columns t_ns (int64), e, n (m), sorted, finite, unique times.

    Accepts a :class:`~gpsdr_cli.io.reference.Reference` (t_ns, lat_deg, lon_deg) or a
    DataFrame with ``t_ns`` (or ``time``) and ``lat``/``lon`` (projected) or
    ``e``/``n`` (taken as already in the frame).
    """
    if isinstance(reference, pd.DataFrame):
        t_ns = _t_ns_of(reference, "reference")
        if "lat" in reference and "lon" in reference:
            e, n = frame.forward(reference["lat"].to_numpy(float), reference["lon"].to_numpy(float))
        elif "e" in reference and "n" in reference:
            e, n = reference["e"].to_numpy(float), reference["n"].to_numpy(float)
        else:
            raise InputError("reference", "expected columns lat, lon or e, n; got "
                             + ", ".join(map(str, reference.columns)))
    else:
        t_ns = np.asarray(reference.t_ns, np.int64)
        e, n = frame.forward(np.asarray(reference.lat_deg, float), np.asarray(reference.lon_deg, float))
    ok = np.isfinite(e) & np.isfinite(n)
    t_ns, e, n = t_ns[ok], e[ok], n[ok]
    order = np.argsort(t_ns, kind="stable")
    t_ns, e, n = t_ns[order], e[order], n[order]
    keep = np.ones(len(t_ns), bool)
    keep[1:] = np.diff(t_ns) > 0
    return pd.DataFrame({"t_ns": t_ns[keep], "e": e[keep], "n": n[keep]})


def _t_ns_of(df: pd.DataFrame, what: str) -> np.ndarray:
    """int64 ns UTC from a ``t_ns`` column, else from ``time`` (timestamp or int64 ns)."""
    if "t_ns" in df:
        return df["t_ns"].to_numpy(np.int64)
    if "time" not in df:
        raise InputError(what, "expected a time column (time or t_ns)")
    col = df["time"]
    if pd.api.types.is_datetime64_any_dtype(col):
        if getattr(col.dt, "tz", None) is not None:
            col = col.dt.tz_convert("UTC").dt.tz_localize(None)
        return col.astype("datetime64[ns]").to_numpy().view(np.int64)
    return col.to_numpy(np.int64)


def interpolate_reference(ref: pd.DataFrame, t_ns: np.ndarray,
                          max_gap_s: float = MAX_REFERENCE_GAP_S
                          ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Reference e, n, unit direction of travel (u_e, u_n) and a validity mask at ``t_ns``.

    Valid: inside the reference span and between samples at most ``max_gap_s`` apart.
    Direction: reference displacement over +-0.5 s; where it moved less than 5 cm,
    the last direction that was known (forward fill, then backward fill); NaN
    when the reference never moves.
    """
    t = np.asarray(t_ns, np.int64)
    tr = ref["t_ns"].to_numpy(np.int64)
    er = ref["e"].to_numpy(float)
    nr = ref["n"].to_numpy(float)
    m = len(t)
    nan = np.full(m, np.nan)
    if len(tr) < 2 or m == 0:
        return nan, nan.copy(), nan.copy(), nan.copy(), np.zeros(m, bool)
    x = (t - tr[0]).astype(float)
    xr = (tr - tr[0]).astype(float)
    i = np.clip(np.searchsorted(tr, t, side="right") - 1, 0, len(tr) - 2)
    exact = t == tr[np.minimum(np.searchsorted(tr, t), len(tr) - 1)]
    gap_ok = (tr[i + 1] - tr[i]) <= max_gap_s * NS_PER_S
    valid = (t >= tr[0]) & (t <= tr[-1]) & (gap_ok | exact)
    e = np.where(valid, np.interp(x, xr, er), np.nan)
    n = np.where(valid, np.interp(x, xr, nr), np.nan)
    half = 0.5 * NS_PER_S
    xa = np.clip(x - half, xr[0], xr[-1])
    xb = np.clip(x + half, xr[0], xr[-1])
    de = np.interp(xb, xr, er) - np.interp(xa, xr, er)
    dn = np.interp(xb, xr, nr) - np.interp(xa, xr, nr)
    norm = np.hypot(de, dn)
    moving = norm > 0.05
    with np.errstate(invalid="ignore", divide="ignore"):
        u_e = pd.Series(np.where(moving, de / norm, np.nan)).ffill().bfill().to_numpy()
        u_n = pd.Series(np.where(moving, dn / norm, np.nan)).ffill().bfill().to_numpy()
    return e, n, u_e, u_n, valid


# --------------------------------------------------------------------------- figures

def summarise(err_m: np.ndarray) -> dict[str, float]:
    """count, mean, RMSE, CEP50, CEP95, max of horizontal errors (finite values only)."""
    d = np.asarray(err_m, float)
    d = d[np.isfinite(d)]
    if not len(d):
        return {"count": 0, "mean_m": np.nan, "rmse_m": np.nan, "cep50_m": np.nan,
                "cep95_m": np.nan, "max_m": np.nan}
    return {"count": len(d), "mean_m": float(np.mean(d)), "rmse_m": float(np.sqrt(np.mean(d * d))),
            "cep50_m": float(np.percentile(d, 50)), "cep95_m": float(np.percentile(d, 95)),
            "max_m": float(np.max(d))}


def _rms(x: np.ndarray) -> float:
    x = x[np.isfinite(x)]
    return float(np.sqrt(np.mean(x * x))) if len(x) else np.nan


def track_errors(track: pd.DataFrame, ref_en: pd.DataFrame) -> pd.DataFrame:
    """Per-epoch errors of the track: t_ns, err_e, err_n, err_m, along_m, cross_m, ref_e,
    ref_n, ref_valid.  NaN where the reference does not cover the epoch."""
    t = _t_ns_of(track, "track")
    re, rn, u_e, u_n, valid = interpolate_reference(ref_en, t)
    de = track["e"].to_numpy(float) - re
    dn = track["n"].to_numpy(float) - rn
    return pd.DataFrame({
        "t_ns": t, "err_e": de, "err_n": dn, "err_m": np.hypot(de, dn),
        "along_m": de * u_e + dn * u_n,          # positive: track ahead of the reference
        "cross_m": de * u_n - dn * u_e,          # positive: track right of the direction of travel
        "ref_e": re, "ref_n": rn, "ref_valid": valid,
    })


def gnss_only_errors(epochs_or_track: Any, reference_en: pd.DataFrame) -> np.ndarray:
    """Horizontal errors (m) of the GNSS fixes themselves at the epochs that have one.

    Accepts :class:`~gpsdr_cli.epochs.Epochs` (``t_ns``, ``gnss_e/n``, ``has_gnss``) or a
    track DataFrame (``time``/``t_ns``, ``gnss_e``, ``gnss_n``).  NaN-free: fixes
    outside the reference's cover are left out.
    """
    if isinstance(epochs_or_track, pd.DataFrame):
        t = _t_ns_of(epochs_or_track, "track")
        ge = epochs_or_track["gnss_e"].to_numpy(float)
        gn = epochs_or_track["gnss_n"].to_numpy(float)
        has = np.isfinite(ge) & np.isfinite(gn)
    else:
        t = np.asarray(epochs_or_track.t_ns, np.int64)
        ge = np.asarray(epochs_or_track.gnss_e, float)
        gn = np.asarray(epochs_or_track.gnss_n, float)
        has = np.asarray(epochs_or_track.has_gnss, bool) & np.isfinite(ge) & np.isfinite(gn)
    re, rn, _, _, valid = interpolate_reference(reference_en, t[has])
    d = np.hypot(ge[has] - re, gn[has] - rn)
    return d[valid & np.isfinite(d)]


def outage_runs(flag: np.ndarray) -> list[tuple[int, int]]:
    """(first, last) index of every run of True in ``flag`` (:func:`gpsdr_cli.epochs.true_runs`)."""
    starts, ends = true_runs(flag)
    return list(zip(starts.tolist(), ends.tolist(), strict=True))


def _path_length(e: np.ndarray, n: np.ndarray) -> float:
    ok = np.isfinite(e) & np.isfinite(n)
    if ok.sum() < 2:
        return np.nan
    return float(np.sum(np.hypot(np.diff(e[ok]), np.diff(n[ok]))))


# --------------------------------------------------------------------------- the table

def error_statistics(track: pd.DataFrame, reference_en: pd.DataFrame | None, filter_name: str,
                     params: Params) -> pd.DataFrame:
    """The statistics table: one row per segment, then one per GNSS outage.

    Columns: :data:`gpsdr_cli.conventions.STATS_COLUMNS` plus ``error_epochs`` (epochs
    the reference covers) and ``start_utc``/``end_utc``/``end_error_utc`` strings for
    outage rows (``end_error_utc``: the epoch ``end_error_m`` is taken at).
    """
    m = len(track)
    t = _t_ns_of(track, "track")
    e = track["e"].to_numpy(float)
    n = track["n"].to_numpy(float)
    pdop = track["pdop"].to_numpy(float) if "pdop" in track else np.full(m, np.nan)
    outage = _bool_col(track, "gnss_outage", m)
    static = _bool_col(track, "static", m)
    nis = track["nis"].to_numpy(float) if "nis" in track else np.full(m, np.nan)
    ge = track["gnss_e"].to_numpy(float) if "gnss_e" in track else np.full(m, np.nan)
    gn = track["gnss_n"].to_numpy(float) if "gnss_n" in track else np.full(m, np.nan)
    pdop_good = float(params["gnss"]["pdop_good"])

    qsep = track["separation_m"].to_numpy(float) if "separation_m" in track else None
    quality = track["quality"].to_numpy(np.int64) if "quality" in track else None

    errs = track_errors(track, reference_en) if reference_en is not None else None
    sep = np.hypot(ge - e, gn - n)

    has_pdop = np.isfinite(pdop)
    masks = {
        "all": np.ones(m, bool),
        "open": has_pdop & (pdop < pdop_good) & ~outage,
        "degraded": has_pdop & (pdop >= pdop_good) & ~outage,
        "outage": outage,
        "static": static,
    }
    rows: list[dict[str, Any]] = []
    for seg in SEGMENTS:
        mask = masks[seg]
        row: dict[str, Any] = {"filter": filter_name, "segment": seg, "epochs": int(mask.sum())}
        if errs is not None:
            d = errs["err_m"].to_numpy()[mask]
            s = summarise(d)
            row.update({k: v for k, v in s.items() if k != "count"})
            row["error_epochs"] = s["count"]
            row["along_rmse_m"] = _rms(errs["along_m"].to_numpy()[mask])
            row["cross_rmse_m"] = _rms(errs["cross_m"].to_numpy()[mask])
        nis_m = nis[mask]
        nis_m = nis_m[np.isfinite(nis_m)]
        row["nis_in_95_share"] = float(np.mean(nis_m <= CHI2_2DOF_95)) if len(nis_m) else np.nan
        row["gnss_separation_rmse_m"] = _rms(sep[mask])
        row.update(qc_figures(qsep, quality, mask))
        rows.append(row)

    for k, (i0, i1) in enumerate(outage_runs(outage), start=1):
        rows.append(_outage_row(k, i0, i1, t, e, n, errs, filter_name))

    out = pd.DataFrame(rows)
    for col in STATS_COLUMNS:
        if col not in out:
            out[col] = np.nan
    if "error_epochs" not in out:
        out["error_epochs"] = 0
    out["epochs"] = out["epochs"].astype("int64")
    out["error_epochs"] = out["error_epochs"].fillna(0).astype("int64")
    for col in _FLOAT_COLUMNS + [c for c in QC_STATS_COLUMNS if c in out]:
        vals = np.array(pd.to_numeric(out[col], errors="coerce").to_numpy(dtype=float, na_value=np.nan))
        vals[~np.isfinite(vals)] = np.nan
        out[col] = pd.array(vals, dtype="Float64")  # NaN -> <NA>: a Parquet null
    for col in ("start_utc", "end_utc", "end_error_utc"):
        if col not in out:
            out[col] = None
        out[col] = out[col].astype("string")
    first = [c for c in STATS_COLUMNS if c in out]
    return out[first + [c for c in out.columns if c not in first]].reset_index(drop=True)


#: Statistics columns of the quality checks (units for the Parquet field metadata).
QC_STATS_COLUMNS: dict[str, str] = {
    "separation_rms_m": "m, RMS of the forward/backward separation over the segment",
    "separation_p95_m": "m, 95th percentile of the forward/backward separation",
    "separation_max_m": "m, largest forward/backward separation",
    **{f"quality_{k}_share": f"share of the segment's epochs in quality class {k} (1 best .. 6 worst)"
       for k in range(1, 7)},
}


def qc_figures(separation_m: np.ndarray | None, quality: np.ndarray | None,
               mask: np.ndarray) -> dict[str, float]:
    """Separation RMS / p95 / max (m) and the share per quality class over ``mask``;
    nothing for a column the track does not have."""
    out: dict[str, float] = {}
    if separation_m is not None:
        s = separation_m[mask]
        s = s[np.isfinite(s)]
        out["separation_rms_m"] = _rms(s)
        out["separation_p95_m"] = float(np.percentile(s, 95)) if len(s) else np.nan
        out["separation_max_m"] = float(np.max(s)) if len(s) else np.nan
    if quality is not None:
        q = quality[mask]
        for k in range(1, 7):
            out[f"quality_{k}_share"] = float(np.mean(q == k)) if len(q) else np.nan
    return out


def _bool_col(track: pd.DataFrame, name: str, m: int) -> np.ndarray:
    if name not in track:
        return np.zeros(m, bool)
    return track[name].fillna(False).to_numpy(bool)


def _outage_row(k: int, i0: int, i1: int, t: np.ndarray, e: np.ndarray, n: np.ndarray,
                errs: pd.DataFrame | None, filter_name: str) -> dict[str, Any]:
    """The ``outage_<k>`` row of the outage at epochs ``i0 .. i1`` (see the module docstring).

    The end error is read at the last epoch of the outage whose error is known (the
    reference covers it), not blindly at ``i1``: an outage that runs to the end of the
    log usually outlasts the reference, and would otherwise have no end error at all.
    """
    start = i0 - 1 if i0 > 0 else i0  # the last epoch before the outage (last fix)
    duration = (t[i1] - t[start]) / NS_PER_S
    row: dict[str, Any] = {"filter": filter_name, "segment": f"outage_{k}", "epochs": i1 - i0 + 1,
                           "duration_s": float(duration),
                           "start_utc": pd.Timestamp(int(t[i0]), unit="ns", tz="UTC").isoformat(),
                           "end_utc": pd.Timestamp(int(t[i1]), unit="ns", tz="UTC").isoformat()}
    if errs is None:
        row["distance_m"] = _path_length(e[start:i1 + 1], n[start:i1 + 1])
        return row
    err = errs["err_m"].to_numpy()
    valid = errs["ref_valid"].to_numpy(bool) & np.isfinite(err)
    ref_e, ref_n = errs["ref_e"].to_numpy(), errs["ref_n"].to_numpy()
    row["distance_m"] = _mixed_path_length(e, n, ref_e, ref_n, valid, start, i1)
    s = summarise(err[i0:i1 + 1])
    row.update({kk: v for kk, v in s.items() if kk != "count"})
    row["error_epochs"] = s["count"]
    row["along_rmse_m"] = _rms(errs["along_m"].to_numpy()[i0:i1 + 1])
    row["cross_rmse_m"] = _rms(errs["cross_m"].to_numpy()[i0:i1 + 1])
    covered = np.flatnonzero(valid[i0:i1 + 1])
    if len(covered):
        i_end = i0 + int(covered[-1])
        end = float(err[i_end])
        row["end_error_m"] = end
        row["end_error_utc"] = pd.Timestamp(int(t[i_end]), unit="ns", tz="UTC").isoformat()
        dist = _mixed_path_length(e, n, ref_e, ref_n, valid, start, i_end)
        if np.isfinite(dist) and dist >= 1.0:
            row["end_error_pct_distance"] = 100.0 * end / dist
    return row


def _mixed_path_length(e: np.ndarray, n: np.ndarray, ref_e: np.ndarray, ref_n: np.ndarray,
                       ref_valid: np.ndarray, i0: int, i1: int) -> float:
    """Distance (m) driven from epoch ``i0`` to ``i1``: each step along the reference where it
    covers both ends of the step, else along the fused track; NaN with fewer than two epochs
    or a step neither covers."""
    if i1 <= i0:
        return np.nan
    sl = slice(i0, i1 + 1)
    ok = ref_valid[sl]
    both = ok[1:] & ok[:-1]
    d_ref = np.hypot(np.diff(ref_e[sl]), np.diff(ref_n[sl]))
    d_trk = np.hypot(np.diff(e[sl]), np.diff(n[sl]))
    step = np.where(both, d_ref, d_trk)
    return float(np.sum(step)) if np.all(np.isfinite(step)) else np.nan


__all__ = [
    "CHI2_2DOF_95",
    "QC_STATS_COLUMNS",
    "SEGMENTS",
    "error_statistics",
    "gnss_only_errors",
    "interpolate_reference",
    "outage_runs",
    "qc_figures",
    "reference_en",
    "summarise",
    "track_errors",
]
