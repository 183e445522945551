"""The whole job for one drive: frame -> align -> filter (+ smooth) -> track -> statistics.

``fuse(drive, params, reference)`` is what ``gpsdr fuse`` and ``gpsdr batch``
call; reading and writing stay in the callers so the pipeline is a pure
function of its inputs (it never changes the ``Drive`` it is given).

Conventions: :mod:`gpsdr_cli.conventions` (int64 ns UTC, metres in the local
east/north frame, heading clockwise from north, NaN = not measured; outputs
never hold NaN/inf in a column that is not documented as nullable).
"""

from __future__ import annotations

import copy
import dataclasses
import datetime as dt
import json
import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass, field
from datetime import UTC, datetime
from typing import TYPE_CHECKING, Any

import numpy as np
import pandas as pd

from . import __version__, config
from .config import Params
from .conventions import (
    GRAPH_TRACK_COLUMNS,
    NS_PER_S,
    QC_COLUMNS,
    STATS_COLUMNS,
    TRACK_COLUMNS,
    TRACK_EXTRA_COLUMNS,
)
from .errors import GpsdrError, InputError, NoDataError, UsageError
from .geodesy import LocalFrame, frame_from_metadata

if TYPE_CHECKING:
    from .epochs import Epochs
    from .filters.base import FilterResult
    from .io.drive import Drive
    from .io.reference import Reference

#: Track columns that may hold nulls (everything else must be finite).
NULLABLE_TRACK_COLUMNS = frozenset({"pdop", "gnss_e", "gnss_n", "nis", "separation_m",
                                    "gnss_weight"})

#: Columns track_frame builds from the filter result.
BASE_TRACK_UNITS: dict[str, str] = {**TRACK_COLUMNS, **TRACK_EXTRA_COLUMNS}
#: Column -> "unit, meaning" for the track file's field metadata.
TRACK_UNITS: dict[str, str] = {**BASE_TRACK_UNITS, **QC_COLUMNS}
#: ... and for the columns only the graph smoother writes.
GRAPH_TRACK_UNITS: dict[str, str] = dict(GRAPH_TRACK_COLUMNS)
#: What the writers label: every column a track may carry.
WRITTEN_TRACK_UNITS: dict[str, str] = {**TRACK_UNITS, **GRAPH_TRACK_UNITS}
SMOOTHERS = ("auto", "rts", "graph", "none")


def smoother_of(params: Params, epochs: Epochs | None = None) -> str:
    """The stage after the filter: ``[filter] smoother`` when set, else ``rts`` if the older
    boolean ``[filter] smooth`` is true, else ``none``.  ``auto`` (the default) is ``graph``
    on a drive with fixes and a gyro or an odometer (the whole drive's dead reckoning weighs
    every fix: docs/decisions/0071), ``rts`` on one with fixes alone (nothing to weigh them
    against) and ``none`` on dead reckoning alone (no fix to smooth towards); without
    ``epochs`` it stays ``auto``.  Dead reckoning alone is ``none`` whatever was asked
    (:data:`NO_FIX_TO_SMOOTH`)."""
    name = str(params["filter"].get("smoother", "")).strip().lower()
    if name:
        if name not in SMOOTHERS:
            raise UsageError(f"[filter] smoother = {name!r}: expected one of "
                             f"{', '.join(SMOOTHERS)}")
    else:
        name = "rts" if params["filter"]["smooth"] else "none"
    if epochs is None or name == "none":
        return name
    if not np.any(epochs.has_gnss):
        return "none"
    if name == "auto":
        return "graph" if np.any(epochs.has_gyro) or np.any(epochs.has_odo) else "rts"
    return name


#: Why a drive without any fix is not smoothed, even when asked: nothing observes the
#: position, so a smoothed track can only move the origin the user gave.  RTS did (5 m on
#: the 60-s comma2k19 sample's dead reckoning, RMSE 19.5 m against 19.6 m forward): the
#: forward pass's odometer rows are consider updates in GNSS outages (``[aekf]
#: odo_consider``), and a smoother's gain assumes the forward covariance is the optimal one.
NO_FIX_TO_SMOOTH = ("no GNSS fix to smooth towards; the track is the forward filter's "
                    "dead reckoning from the origin given")

Progress = Callable[[str], None]


class NonFiniteOutputError(GpsdrError):
    """A filter produced NaN or infinity where the output contract forbids it."""


@dataclass
class FuseResult:
    """Everything one run produced; ``metadata`` is what the track file carries."""

    track: pd.DataFrame
    stats: pd.DataFrame
    frame: LocalFrame
    #: None after :meth:`release_arrays`
    epochs: Epochs | None
    #: None after :meth:`release_arrays`
    result: FilterResult | None
    metadata: dict[str, str]
    reference_en: pd.DataFrame | None = None
    #: GNSS time offset used (s); estimated when ``auto_gnss_offset`` was asked for
    gnss_offset_s: float = 0.0
    #: the parameters actually used (with an estimated offset filled in)
    params: Params = field(default_factory=dict)
    #: readers' warnings about the inputs (e.g. a truncated MCAP summary)
    drive_warnings: list[str] = field(default_factory=list)
    _gnss_only: dict[str, float] | None = field(default=None, repr=False)

    def release_arrays(self) -> None:
        """Free the epochs and the filter's arrays once only the outputs and the summary are
        wanted (``gpsdr fuse`` before it writes: they were a third of the write's peak
        memory).  The fixes' own figures are kept for :meth:`gnss_only_summary`."""
        self._gnss_only = self.gnss_only_summary()
        self.epochs = None
        self.result = None

    @property
    def gnss_offset_note(self) -> str:
        """How ``--gnss-offset auto`` came to its value (empty when it was not asked for)."""
        return self.metadata.get("gnss_offset_auto_note", "")

    def summary(self) -> dict[str, float]:
        """Figures of the ``all`` segment: rmse_m, cep95_m, max_m, epochs (NaN when unknown)."""
        return summary_of(self.stats)


    def gnss_only_summary(self) -> dict[str, float]:
        """The same figures for the GNSS fixes alone (empty without a reference)."""
        if self._gnss_only is not None:
            return self._gnss_only
        if self.reference_en is None:
            return {}
        from .evaluation import gnss_only_errors, summarise

        return summarise(gnss_only_errors(self.epochs, self.reference_en))


def summary_of(stats: pd.DataFrame) -> dict[str, float]:
    """rmse_m, cep95_m, max_m, mean_m, epochs, ... of the ``all`` row (NaN for nulls)."""
    rows = stats[stats["segment"] == "all"] if "segment" in stats else stats.iloc[:0]
    out: dict[str, float] = {}
    for col in ("rmse_m", "cep95_m", "max_m", "mean_m", "epochs", "nis_in_95_share",
                "gnss_separation_rmse_m"):
        out[col] = math.nan
        if len(rows) and col in rows:
            out[col] = float(rows[col].to_numpy(dtype=float, na_value=np.nan)[0])
    return out


# --------------------------------------------------------------------------- frame

def choose_frame(drive: Drive, params: Params) -> LocalFrame:
    """The local frame: EPSG on request, else centred on the first usable fix, else on the
    configured origin (dead-reckoning-only drives)."""
    fp = params["frame"]
    epsg = int(fp["epsg"]) or None
    lat = lon = np.zeros(0)
    if drive.gnss is not None and len(drive.gnss):
        ok = drive.gnss.valid
        lat, lon = drive.gnss.lat_deg[ok], drive.gnss.lon_deg[ok]
    if len(lat):
        return LocalFrame.for_fixes(lat, lon, epsg)
    olat, olon = float(fp["origin_lat_deg"]), float(fp["origin_lon_deg"])
    if math.isfinite(olat) and math.isfinite(olon):
        if epsg is not None:
            return LocalFrame.from_epsg(epsg, olat, olon)
        return LocalFrame.centred_on(olat, olon)
    where = drive.sources[0].path if drive.sources else None
    raise NoDataError(where, "no valid GNSS fix in the drive; for dead reckoning alone set "
                             "[frame] origin_lat_deg, origin_lon_deg and initial_heading_deg")


# --------------------------------------------------------------------------- track

def track_frame(epochs: Epochs, result: FilterResult, frame: LocalFrame,
                pdop: np.ndarray | None = None) -> pd.DataFrame:
    """The track table: TRACK_COLUMNS then TRACK_EXTRA_COLUMNS, one row per epoch.

    ``pdop``: the column (e.g. :func:`latest_gnss_pdop`); default the epochs' PDOP
    carried forward."""
    n_ep = len(epochs)
    if len(result) != n_ep:
        raise GpsdrError(f"filter returned {len(result)} epochs for {n_ep} input epochs")
    e = np.asarray(result.e, float)
    n = np.asarray(result.n, float)
    v_e = np.asarray(result.v_e, float)
    v_n = np.asarray(result.v_n, float)
    lat, lon = frame.inverse(e, n)
    # heading clockwise from north: psi = atan2(v_e, v_n)  (conventions charter)
    heading = np.degrees(np.arctan2(v_e, v_n)) % 360.0
    # ... taken before a stop's decayed velocity (1e-200 m/s and less after a minute of
    # zero-velocity updates) is written as the 0 it is; the heading keeps its direction
    speed = np.hypot(v_e, v_n)
    still = speed < 1e-9
    v_e, v_n, speed = (np.where(still, 0.0, a) for a in (v_e, v_n, speed))
    if pdop is None:
        pdop = pd.Series(np.asarray(epochs.pdop, float)).ffill().to_numpy()  # latest GNSS record
    cols: dict[str, Any] = {
        "time": pd.to_datetime(np.asarray(epochs.t_ns, np.int64), unit="ns", utc=True),
        "lat": lat,
        "lon": lon,
        "e": e,
        "n": n,
        "v_e": v_e,
        "v_n": v_n,
        "speed": speed,
        "heading_deg": heading,
        "sigma_e": _sd(result.var_e),
        "sigma_n": _sd(result.var_n),
        "gnss_used": np.asarray(result.gnss_used, bool),
        "pdop": pdop,
        "gnss_e": np.asarray(epochs.gnss_e, float),
        "gnss_n": np.asarray(epochs.gnss_n, float),
        "gnss_rejected": np.asarray(result.gnss_rejected, bool),
        "gnss_outage": np.asarray(epochs.gnss_outage, bool),
        "static": np.asarray(result.static, bool),
        "nis": np.asarray(result.nis, float),
    }
    # copy=False: one block per column, no consolidation into a 2-D float block.  A one-hour
    # track is 360 k rows x 19 columns; the consolidating copy cost ~55 MB of peak RSS and a
    # pass over memory (batch throughput is memory-bandwidth bound).
    df = pd.DataFrame({name: cols[name] for name in BASE_TRACK_UNITS}, copy=False)
    if df["time"].dtype != "datetime64[ns, UTC]":
        df["time"] = df["time"].astype("datetime64[ns, UTC]")
    return df


def _sd(var: np.ndarray) -> np.ndarray:
    """1-sigma from a variance; rounding may leave -1e-12, a real negative stays NaN (caught)."""
    v = np.asarray(var, float)
    v = np.where((v < 0) & (v > -1e-9), 0.0, v)
    with np.errstate(invalid="ignore"):
        return np.sqrt(v)


def check_finite(track: pd.DataFrame, stats: pd.DataFrame | None = None) -> None:
    """Raise :class:`NonFiniteOutputError` if NaN/inf reached a non-nullable column."""
    for col in track.columns:
        if col in NULLABLE_TRACK_COLUMNS or col == "time" or track[col].dtype == bool:
            continue
        vals = track[col].to_numpy(float)
        bad = ~np.isfinite(vals)
        if bad.any():
            k = int(np.flatnonzero(bad)[0])
            raise NonFiniteOutputError(
                f"filter output: column {col} is {vals[k]} at epoch {k} "
                f"({track['time'].iloc[k]}); {int(bad.sum())} epochs affected "
                "(the filter diverged; try --filter ekf or check the input streams)")
    for col in TRACK_UNITS:
        if col in NULLABLE_TRACK_COLUMNS and col in track:
            vals = track[col].to_numpy(float)
            if np.isinf(vals).any():
                raise NonFiniteOutputError(f"filter output: column {col} holds infinity")
    if stats is not None:
        for col in stats.columns:
            if not pd.api.types.is_float_dtype(stats[col]):
                continue
            if np.isinf(stats[col].to_numpy(dtype=float, na_value=np.nan)).any():
                raise NonFiniteOutputError(f"statistics: column {col} holds infinity")


# --------------------------------------------------------------------------- metadata

def _jsonable(value: Any) -> Any:
    if isinstance(value, dict):
        return {str(k): _jsonable(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_jsonable(v) for v in value]
    if isinstance(value, np.generic):
        value = value.item()
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, (str, int, float, bool)) or value is None:
        return value
    if isinstance(value, np.ndarray):
        return f"array{value.shape}"
    return str(value)


def build_metadata(drive: Drive, params: Params, frame: LocalFrame, epochs: Epochs,
                   result: FilterResult, skipped: Any, reference: Reference | None,
                   gnss_offset_auto_s: float | None) -> dict[str, str]:
    """File metadata: tool version, filter and every parameter, frame, inputs with SHA-256,
    skipped records by reason."""
    smoother = smoother_of(params, epochs)
    meta: dict[str, str] = {
        "gpsdr.version": __version__,
        "created_utc": datetime.now(UTC).isoformat(timespec="seconds"),
        "filter": str(params["filter"]["name"]),
        "smoothed": "true" if smoother != "none" else "false",
        # what ran: a graph solve that failed leaves the RTS track
        "smoother": "graph" if result.info.get("smoothing") == "graph" else
        ("none" if smoother == "none" else "rts"),
        "params_toml": config.to_toml(params),
    }
    meta.update({f"param.{k}": v for k, v in config.flat(params).items()})
    with warnings.catch_warnings():
        # pyproj warns that a PROJ string loses information; the WKT beside it is exact
        warnings.simplefilter("ignore", UserWarning)
        meta.update({f"frame.{k}": v for k, v in frame.describe().items()})
    meta["inputs"] = json.dumps([{"path": s.path, "sha256": s.sha256, "streams": list(s.streams)}
                                 for s in drive.sources])
    for i, s in enumerate(drive.sources):
        meta[f"input.{i}.path"] = s.path
        meta[f"input.{i}.sha256"] = s.sha256
    meta["skipped"] = json.dumps({reason: {"count": int(c), "first": skipped.first.get(reason, "")}
                                  for reason, c in sorted(skipped.counts.items())})
    meta["skipped_total"] = str(skipped.total)
    meta["epochs"] = str(len(epochs))
    meta["gnss_epochs"] = str(epochs.n_gnss)
    meta["gnss_used"] = str(int(np.asarray(result.gnss_used, bool).sum()))
    meta["filter_info"] = json.dumps(_jsonable(result.info))
    if reference is not None:
        meta["reference"] = str(getattr(reference, "source", ""))
    if gnss_offset_auto_s is not None:
        meta["gnss_offset_auto_s"] = repr(gnss_offset_auto_s)
    return meta


# --------------------------------------------------------------------------- stray records

#: A stretch without records longer than this splits a stream into separate clusters (s).
STRAY_GAP_S = 3600.0
#: A cluster holding less than this share of a stream's records is stray (a corrupt stamp).
STRAY_SHARE = 0.01


def stray_mask(t_ns: np.ndarray, all_t_ns: np.ndarray | None = None) -> np.ndarray:
    """True for records of ``t_ns`` to keep.

    The stamps of every stream (``all_t_ns``, default ``t_ns`` itself) are split into
    clusters wherever they leave a gap of more than STRAY_GAP_S; a cluster holding less
    than STRAY_SHARE of all records (and not the largest) is stray: a corrupt digit in a
    stamp or date would otherwise make the filter predict across days or years.  Judged
    over all streams together, because a short stream (60 GNSS fixes) gives one corrupt
    record a share above the threshold on its own.
    """
    t = np.asarray(t_ns, np.int64)
    pool = t if all_t_ns is None else np.asarray(all_t_ns, np.int64)
    keep = np.ones(len(t), bool)
    if len(pool) < 3 or len(t) == 0:
        return keep
    ordered = np.sort(pool)
    gaps = np.diff(ordered) > STRAY_GAP_S * NS_PER_S
    if not gaps.any():
        return keep
    cluster = np.concatenate(([0], np.cumsum(gaps)))
    counts = np.bincount(cluster)
    small = (counts < STRAY_SHARE * len(pool)) & (np.arange(len(counts)) != np.argmax(counts))
    # the cluster of each record of t: clusters are contiguous ranges of the sorted pool
    starts = ordered[np.concatenate(([0], np.flatnonzero(gaps) + 1))]
    of_t = np.searchsorted(starts, t, side="right") - 1
    keep = ~small[np.clip(of_t, 0, len(counts) - 1)]
    return keep


def _drop_far_no_fix(drive: Drive) -> None:
    """Drop (and count) GNSS records without a fix lying more than STRAY_GAP_S from every
    fix and sensor record: a receiver's cold start stamps them with its default date
    (1980, 2000, ...) and they carry no position, yet they would stretch the drive over
    years and hold most of a short log's records, so the cluster test cannot call them stray."""
    g = drive.gnss
    if g is None or not len(g):
        return
    valid = g.valid
    if valid.all():
        return
    info = [g.t_ns[valid]] + [s.t_ns for s in (drive.gyro, drive.odo, drive.accel)
                              if s is not None and len(s)]
    ref = np.sort(np.concatenate(info))
    if not len(ref):
        return
    t = g.t_ns
    i = np.clip(np.searchsorted(ref, t), 1, len(ref) - 1) if len(ref) > 1 else np.zeros(len(t), int)
    near = np.minimum(np.abs(t - ref[i]), np.abs(t - ref[np.maximum(i - 1, 0)]))
    far = ~valid & (near > np.int64(STRAY_GAP_S * NS_PER_S))
    if not far.any():
        return
    k = int(np.flatnonzero(far)[0])
    drive.skipped.add(f"gnss: record without a fix more than {STRAY_GAP_S:.0f} s away from any "
                      "fix or sensor record (a receiver's default date before its first fix)",
                      f"gnss record {k + 1} ({_iso(t[k])})", int(far.sum()))
    keep = ~far
    drive.gnss = dataclasses.replace(
        g, **{f.name: getattr(g, f.name)[keep] for f in dataclasses.fields(g)})


def _own_warnings(meta: dict) -> dict:
    """``meta`` with a warnings list of its own: a run's warnings stay with that run."""
    return {**meta, "warnings": list(meta.get("warnings", []))}


def drop_stray_records(drive: Drive) -> Drive:
    """A copy of ``drive`` without stray-stamped records, counted in its SkipReport."""
    out = dataclasses.replace(drive, skipped=copy.deepcopy(drive.skipped),
                              meta=_own_warnings(drive.meta))
    _drop_far_no_fix(out)
    streams = [(name, getattr(out, name)) for name in ("gnss", "gyro", "odo")]
    streams = [(name, s) for name, s in streams if s is not None and len(s)]
    if not streams:
        return out
    all_t = np.concatenate([s.t_ns for _, s in streams])
    for name, stream in streams:
        keep = stray_mask(stream.t_ns, all_t)
        if keep.all():
            continue
        k = int(np.flatnonzero(~keep)[0])
        out.skipped.add(f"{name}: time stamp more than {STRAY_GAP_S:.0f} s away from the rest "
                        "of the drive", f"{name} record {k + 1} ({_iso(stream.t_ns[k])})",
                        int((~keep).sum()))
        setattr(out, name, dataclasses.replace(
            stream, **{f.name: getattr(stream, f.name)[keep]
                       for f in dataclasses.fields(stream)}))
    return out


# --------------------------------------------------------------------------- fuse

def _run_once(drive: Drive, params: Params, frame: LocalFrame, progress: Progress | None,
              ready: Callable[[], object] | None = None, *, with_qc: bool = False,
              ) -> tuple[Epochs, FilterResult, pd.DataFrame, Drive]:
    """(epochs, result, track, the drive as processed: its ``skipped`` and ``meta["warnings"]``
    say what aligning it dropped).  ``with_qc``: the track gets the QC columns
    (:func:`add_qc_columns`)."""
    from . import gyro_sign, lever_arm, qc
    from .align import build_epochs
    from .filters.calibration import known_gyro_scale, scaled_yaw

    # build_epochs counts what it drops into the drive's SkipReport: work on a copy so
    # a second run (auto offset, batch retry) does not count twice.
    work = drop_stray_records(drive)
    if progress:
        progress("aligning streams")
    epochs = build_epochs(work, frame, params)
    if len(epochs) == 0:
        where = drive.sources[0].path if drive.sources else None
        raise NoDataError(where, "no GNSS, gyro or odometer record to process")
    gyro_scale = known_gyro_scale(params)
    if gyro_scale is not None and gyro_scale != 1.0:
        epochs = scaled_yaw(epochs, gyro_scale)  # --gyro-scale: every filter reads true rates
    # a yaw rate logged with the other sign convention mirrors every turn (gyro_sign.py)
    epochs, sign_note = gyro_sign.check(epochs)
    if sign_note:
        _warn(work, sign_note)
    smoother = smoother_of(params, epochs)
    asked = smoother_of(params)
    if smoother == "none" and asked not in ("none", "auto"):
        _warn(work, f"{asked} smoother not run: {NO_FIX_TO_SMOOTH}")
    if ready is not None:
        ready()  # e.g. a background compile of the kernels (gpsdr_cli.warmup) has finished
    # the filters read the boolean; the graph starts from the RTS solution
    fparams = params
    if bool(params["filter"]["smooth"]) != (smoother != "none"):
        fparams = copy.deepcopy(params)
        fparams["filter"]["smooth"] = smoother != "none"
    arm = lever_arm.arm_of(fparams)
    # The QC passes first: their arrays are gone (the two tracks kept as e, n) before the
    # main pass allocates the ones the track table is made of, which lowers the peak memory.
    # A lever arm changes the epochs the QC passes run on: after the main pass then.
    qc_on = with_qc and qc.qc_enabled(params)
    qc_en = _qc_passes(epochs, params, progress) if qc_on and arm is None else None
    if progress:
        progress(f"running {params['filter']['name']}"
                 + {"rts": " + RTS smoother", "graph": " + RTS, then the graph smoother",
                    "none": ""}[smoother])
    epochs, result, weight = _main_pass(epochs, fparams, params, arm, work, smoother, progress)
    if qc_on and qc_en is None:
        qc_en = _qc_passes(epochs, params, progress)
    sep = _separation(qc_en, result) if qc_on else None
    del qc_en
    pdop = None
    if work.gnss is not None and len(work.gnss):
        shift = np.int64(round(float(params["time"]["gnss_offset_s"]) * NS_PER_S))
        pdop = latest_gnss_pdop(epochs, work.gnss.t_ns + shift)
    track = track_frame(epochs, result, frame, pdop)
    if weight is not None:
        track["gnss_weight"] = weight
    if with_qc:
        track = _with_qc_columns(track, sep, params)
    return epochs, result, track, work


def _main_pass(epochs: Epochs, fparams: Params, params: Params,
               arm: tuple[float, float, float] | None, work: Drive, smoother: str,
               progress: Progress | None) -> tuple[Epochs, FilterResult, np.ndarray | None]:
    """The filter (at the lever arm's reference point, if any), then the graph smoother:
    (epochs as filtered, result, the graph's per-epoch fix weights or None)."""
    from . import lever_arm

    if arm is not None:
        epochs, result = lever_arm.apply(epochs, fparams, arm, run_filter)
    else:
        result = run_filter(epochs, fparams)
    if result.info.get("gyro_steady"):
        _warn(work, str(result.info["gyro_steady"]))
    n_screened = int(result.info.get("nlos_screened") or 0)
    if n_screened:
        _warn(work, f"reflected signals (NLOS): {n_screened} of {int(epochs.has_gnss.sum())} "
                    "fixes disagree with the whole drive's dead reckoning and were not used "
                    "([gnss] nlos_screen)")
    n_doppler = int(result.info.get("nlos_doppler_dropped") or 0)
    if n_doppler:
        _warn(work, f"reflected signals (NLOS): {n_doppler} receiver velocities more than "
                    f"{float(fparams['gnss']['nlos_doppler_odo_max_mps']):g} m/s off the "
                    "odometer's speed were not used ([gnss] nlos_doppler_odo_max_mps)")
    skipped = result.info.get("nlos_screen_skipped")
    not_applied = result.info.get("nlos_screen_not_applied")
    if not_applied:
        _warn(work, "reflected signals (NLOS) suspected, but the whole drive's dead reckoning "
                    f"cannot judge the fixes ({not_applied}): the track follows the fixes")
    elif skipped in ("no odometer", "no gyro"):
        # simulated city drives without an odometer, seeds 1-7: aekf forward 0.49-1.3 x the
        # fixes, fafkf up to 1.9 x, the graph smoother 0.17-0.80 x (docs/benchmarks.md)
        _warn(work, f"reflected signals (NLOS) suspected, and with {skipped} nothing outvotes "
                    "them: the filter's track can be further off than the fixes"
                    + ("" if smoother == "graph" else
                       "; --smooth graph weighs every fix against the whole drive"))
    elif skipped:
        _warn(work, "reflected signals (NLOS) suspected, but the gyro or odometer is unhealthy "
                    "or silent for long: the track follows the fixes rather than a dead "
                    "reckoning that cannot judge them")
    weight = None
    if smoother == "graph":
        from .filters.graph import smooth_graph

        if progress:
            progress("graph smoother")
        outcome = smooth_graph(epochs, result, params)
        if outcome.result is not None:
            result = outcome.result
            weight = outcome.gnss_weight
        else:
            result.info["graph_failed"] = outcome.message
            work.meta.setdefault("warnings", []).append(
                f"graph smoother: {outcome.message}; the track is the RTS smoother's")
    _gyro_scale_note(work, result.info)
    return epochs, result, weight


#: a gyro scale correction beyond this (the graph's or the NLOS screen's fit) is not a sensor's
#: scale error (0.5-3 %) but a configuration's: the sign, the units
GYRO_SCALE_WARN = 0.1


def _gyro_scale_note(work: Drive, info: dict) -> None:
    """Warn where the fitted gyro scale correction g (true rate = (1 + g) x reading - bias)
    says the readings' sign or units are wrong: the track uses the corrected rate."""
    g = info.get("graph_gyro_scale", info.get("nlos_screen_gyro_scale"))
    if g is None or not math.isfinite(float(g)) or abs(float(g)) <= GYRO_SCALE_WARN:
        return
    factor = 1.0 / (1.0 + float(g)) if abs(1.0 + float(g)) > 1e-9 else math.inf
    _warn(work, f"the gyro reads {factor:+.3g} times the turn the fixes show (a wrong [gyro] "
                "sign or units?); the track uses the rate corrected by that factor")


def _warn(work, note: str) -> None:
    """Add a warning line to the drive's summary, once."""
    warnings = work.meta.setdefault("warnings", [])
    if note not in warnings:
        warnings.append(note)


def run_filter(epochs: Epochs, params: Params) -> FilterResult:
    """The configured filter over ``epochs``: it starts at the first usable fix, and the
    epochs before it (gyro and odometer logged before the receiver had a fix) are
    dead-reckoned back from it (:mod:`gpsdr_cli.lead_in`).  On a drive without an
    odometer, the forward accelerometer's speed (without one, the last fixes' speed) carries
    the track through the GNSS outages along the gyro's heading (:mod:`gpsdr_cli.filters.accel_speed`)."""
    from . import filters
    from .filters.accel_speed import bridge_outages
    from .lead_in import run_from_first_fix

    def run(from_fix: Epochs, p: Params) -> FilterResult:
        # no odometer: the speed through the GNSS outages
        return bridge_outages(from_fix, filters.get(p["filter"]["name"])(from_fix, p), p,
                              smoothed=bool(p["filter"]["smooth"]))

    return run_from_first_fix(epochs, run, params)


def add_qc_columns(track: pd.DataFrame, epochs: Epochs, result: FilterResult,
                   params: Params, progress: Progress | None = None) -> pd.DataFrame:
    """``separation_m`` (forward vs an independent backward pass, m; with ``[qc]
    backward_pass``) and ``quality`` (int8, 1 best .. 6 worst) appended to ``track``
    (:mod:`gpsdr_cli.qc`).  Both passes are unsmoothed: a smoothed track's own pass
    has seen the backward data."""
    return _with_qc_columns(track, qc_separation(epochs, result, params, progress), params)


def qc_separation(epochs: Epochs, result: FilterResult, params: Params,
                  progress: Progress | None = None) -> np.ndarray | None:
    """``separation_m`` of :func:`add_qc_columns` (m per epoch), None without ``[qc]
    backward_pass``."""
    from . import qc

    if not qc.qc_enabled(params):
        return None
    return _separation(_qc_passes(epochs, params, progress), result)


def _qc_passes(epochs: Epochs, params: Params, progress: Progress | None
               ) -> tuple[np.ndarray | None, np.ndarray | None, np.ndarray, np.ndarray]:
    """:func:`qc_separation`'s unsmoothed passes as positions (m): (forward e, n, or None,
    None when the main pass is itself the unsmoothed forward one; backward e, n in forward
    order)."""
    from . import qc

    if progress:
        progress("backward pass")
    raw = copy.deepcopy(params)
    raw["filter"]["smooth"] = False
    # copies: a result's e and n are views of its whole state array
    e_b, n_b, _, _ = qc.reverse_result_positions(run_filter(qc.reverse_epochs(epochs), raw))
    e_b, n_b = e_b.copy(), n_b.copy()
    if smoother_of(params, epochs) == "none":
        return None, None, e_b, n_b
    fwd = run_filter(epochs, raw)
    return np.array(fwd.e, float), np.array(fwd.n, float), e_b, n_b


def _separation(passes: tuple[np.ndarray | None, np.ndarray | None, np.ndarray, np.ndarray],
                result: FilterResult) -> np.ndarray:
    """The QC passes' separation (m per epoch); ``result`` stands in for the forward pass
    where :func:`_qc_passes` did not run one."""
    from . import qc

    e_f, n_f, e_b, n_b = passes
    return qc.separation(result.e if e_f is None else e_f, result.n if n_f is None else n_f,
                         e_b, n_b)


def _with_qc_columns(track: pd.DataFrame, separation_m: np.ndarray | None,
                     params: Params) -> pd.DataFrame:
    from . import qc

    if separation_m is not None:
        track["separation_m"] = separation_m
    track["quality"] = qc.track_quality(track, params["qc"])
    return track


def latest_gnss_pdop(epochs: Epochs, gnss_t_ns: np.ndarray) -> np.ndarray:
    """PDOP of the latest GNSS record at or before each epoch; NaN before the first record
    and where that record carried no PDOP (track_frame's forward fill cannot tell a record
    without PDOP from an epoch without a record)."""
    from .align import sorted_member

    t = np.asarray(epochs.t_ns, np.int64)
    is_record = sorted_member(t, np.sort(np.asarray(gnss_t_ns, np.int64)))  # np.isin, faster
    last = np.maximum.accumulate(np.where(is_record, np.arange(len(t)), -1)) if len(t) else \
        np.zeros(0, np.int64)
    pdop = np.asarray(epochs.pdop, float)
    return np.where(last >= 0, pdop[np.maximum(last, 0)], np.nan)


#: ``auto_gnss_offset``: probes at most this many times, until the residual estimate is
#: below OFFSET_TOL_S (s)
OFFSET_ITERATIONS = 4
OFFSET_TOL_S = 0.003


#: the filters whose odometer is read earlier.  fkf and fafkf take the fixes' speed and
#: course into their heading and odometer scale, which hides the lag on their track and
#: absorbs it: moved by the lag an ekf pass finds, fkf got worse on every simulated drive
#: whose odometer or fixes were off (open_sky, 5-Hz CAN: 0.30 -> 0.61 m; decisions/0024)
LAG_FILTERS = ("ekf", "aekf")
#: a forward track reads a large lag short (an odometer 0.23 s late: 0.17 s forward, 0.215 s
#: smoothed; one_hour's 0.05 s: +0.078 forward, +0.074 smoothed): the reading on the track
#: with the odometer moved is added while it is at least LAG_REST_S, in at most LAG_STEPS passes
LAG_REST_S = 0.02
LAG_STEPS = 2


def _odometer_lag(drive: Drive, params: Params, track: pd.DataFrame, result: FilterResult,
                  auto_gnss_offset: bool) -> tuple[float, str] | None:
    """The odometer's lag (s, at least ``HINT_OFFSET_S``, to 0.01 s) and how it was found,
    when ekf's or aekf's ``track`` shows the fixes clearly ahead of the dead reckoning along
    the track; else None.

    Read from speed changes alone (:func:`gpsdr_cli.latency.significant_offset`, ``along``:
    in turns an antenna ahead of the reference point reads as an offset too).  That reading
    is close to the lag itself, forward or smoothed (one_hour seed 3: +0.078 / +0.074 s,
    then +0.030 / +0.025 s with the odometer moved by 0.05 s), so the track is made again
    with the odometer moved by it (:data:`LAG_STEPS`), not probed.  Rounded to 0.01 s: a
    100-Hz drive's odometer stays on its gyro's stamps (moved off that grid, one drive's
    epochs went from 30001 to 59968).

    Fixes ahead of the dead reckoning are either stamped early or met by an odometer that is
    late.  A receiver stamps a position with the satellites' time, the best clock on the
    vehicle, while a wheel speed always describes the past (ticks counted over a window, a
    CAN signal filtered or averaged over its period), so the odometer is read earlier.  On
    a drive whose fixes really are early (comma2k19 against its reference) the track then
    keeps the fixes' timing error, as the fixes alone do, instead of lagging behind its
    changes (decisions/0024).  Only with every offset at 0 and an odometer, never on an
    NLOS drive (its reflections read as offsets of tenths of a second) or with
    ``--gnss-offset auto`` (which moves the fixes instead)."""
    tp = params["time"]
    if (auto_gnss_offset or drive.odo is None or not bool(tp["odo_lag_auto"])
            or str(params["filter"]["name"]) not in LAG_FILTERS
            or any(float(tp[k]) != 0.0 for k in ("gnss_offset_s", "odo_offset_s",
                                                  "gyro_offset_s"))
            or result.info.get("nlos_drive")):
        return None
    from .latency import HINT_OFFSET_S, significant_offset

    # the warning's bar, 10 standard errors: the regression's own are 2-4 times too small, and
    # at 5 the bundled urban sample's multipath read 0.28 +- 0.048 s and took aekf + RTS from
    # 1.18 to 1.92 m
    est = significant_offset(track, along=True)
    if est is None or est.offset_s <= 0.0:
        return None
    lag = min(round(float(est.offset_s), 2), float(tp["dr_clock_min_s"]))
    return (lag, est.describe()) if lag >= HINT_OFFSET_S else None


def fuse(drive: Drive, params: Params, reference: Reference | None = None, *,
         auto_gnss_offset: bool = False, progress: Progress | None = None,
         ready: Callable[[], object] | None = None) -> FuseResult:
    """Fuse one drive.  ``reference`` (optional) is projected into the same local frame
    and the statistics are taken against it; without one, only the health rows.

    ``ready`` is called once the inputs are aligned, just before the first filter
    pass (``gpsdr fuse`` joins its background kernel compile there).

    ``auto_gnss_offset``: run once, estimate the GNSS time offset from the along-track
    residuals (:func:`gpsdr_cli.latency.estimate_gnss_offset_s`), add it to
    ``[time] gnss_offset_s`` and run again.
    """
    from . import evaluation

    if drive.gnss is None and drive.gyro is None and drive.odo is None:
        where = drive.sources[0].path if drive.sources else None
        raise NoDataError(where, "no GNSS, gyro or odometer stream found")
    params = copy.deepcopy(params)
    drive = dataclasses.replace(drive, meta=_own_warnings(drive.meta))  # the caller's stays
    frame = choose_frame(drive, params)
    from . import clock_check

    drive, step_notes = clock_check.gnss_clock_steps(drive, params)
    params, clock_notes = clock_check.check(drive, params)
    clock_notes = step_notes + clock_notes
    for note in clock_notes:
        _warn(drive, note)
    from . import rtk_odo_lag

    params, lag_note = rtk_odo_lag.apply(drive, params, frame, auto_gnss_offset)
    if lag_note:
        _warn(drive, lag_note)
    offset_auto: float | None = None
    offset_note = ""
    if auto_gnss_offset:
        from .latency import estimate_gnss_offset

        if progress:
            progress("estimating the GNSS time offset")
        # From the track's own kinematics, never from the reference: the error statistics
        # against the reference must stay an independent check.  The probe pass is smoothed:
        # a forward track lags the truth by the filter's own delay, which the regression
        # would otherwise read as GNSS latency (ekf +0.19 s vs +0.12 s smoothed on comma2k19).
        probe = copy.deepcopy(params)
        probe["filter"]["smooth"] = True
        probe["filter"]["smoother"] = "rts"
        offset_auto = float(params["time"]["gnss_offset_s"])
        # The fixes' own speed and course pull the probe's velocity toward the GNSS clock, so
        # one estimate falls short of the offset by a share of it; probing again at the
        # estimate until the residual is below OFFSET_TOL_S reaches the fixed point, where
        # the GNSS and the dead reckoning agree.
        for i in range(OFFSET_ITERATIONS):
            probe["time"]["gnss_offset_s"] = offset_auto
            _, _, probe_track, _ = _run_once(drive, probe, frame, progress, ready)
            est = estimate_gnss_offset(probe_track)
            if not (est.identified and math.isfinite(est.offset_s)):
                if i == 0:
                    offset_note = f"not estimated ({est.reason}); kept {offset_auto:+.3f} s"
                break
            offset_auto += float(est.offset_s)
            offset_note = est.describe()
            if abs(est.offset_s) < OFFSET_TOL_S:
                break
        params["time"]["gnss_offset_s"] = offset_auto
    epochs, result, track, work = _run_once(drive, params, frame, progress, ready, with_qc=True)
    odo_lag = _odometer_lag(drive, params, track, result, auto_gnss_offset)
    if odo_lag is not None:
        from .latency import estimate_gnss_offset

        lag, how = odo_lag
        for step in range(LAG_STEPS):
            if progress:
                progress("the odometer read earlier")
            params["time"]["odo_offset_s"] = -lag
            del epochs, result, track, work      # not alive beside the next pass's: peak memory
            epochs, result, track, work = _run_once(drive, params, frame, progress, ready,
                                                    with_qc=True)
            if step + 1 == LAG_STEPS:
                break
            rest = estimate_gnss_offset(track, along=True).offset_s
            more = min(round(lag + rest, 2), float(params["time"]["dr_clock_min_s"]))
            if not (rest >= LAG_REST_S and more > lag):
                break
            lag = more
        _warn(work, f"the odometer's speed reads {lag:.2f} s late against the GNSS fixes "
                    f"({how}): read that much earlier ([time] odo_offset_s; "
                    "odo_lag_auto = false keeps it as logged)")
    skipped = work.skipped
    # the fixes stamped off the dead reckoning's clock; not on a drive with reflected signals,
    # whose errors of tens of metres read as offsets of 0.7 s there
    if (not auto_gnss_offset and (drive.gyro is not None or drive.odo is not None)
            and not result.info.get("nlos_drive")):
        from .latency import offset_hint

        hint = offset_hint(track, odometer=drive.odo is not None)
        if hint:
            _warn(work, hint)

    if progress:
        progress("statistics")
    ref_en = evaluation.reference_en(reference, frame) if reference is not None else None
    name = str(params["filter"]["name"])
    stats = evaluation.error_statistics(track, ref_en, name, params)
    stats = order_stats(stats)
    check_finite(track, stats)
    meta = build_metadata(drive, params, frame, epochs, result, skipped, reference, offset_auto)
    if offset_note:
        meta["gnss_offset_auto_note"] = offset_note
    return FuseResult(track=track, stats=stats, frame=frame, epochs=epochs, result=result,
                      metadata=meta, reference_en=ref_en,
                      gnss_offset_s=float(params["time"]["gnss_offset_s"]), params=params,
                      drive_warnings=list(dict.fromkeys(  # reading's, then aligning's, once each
                          str(w) for w in (*drive.meta.get("warnings", []),
                                           *work.meta.get("warnings", [])))))


def order_stats(stats: pd.DataFrame) -> pd.DataFrame:
    """Documented statistics columns first, in the charter's order; others after."""
    first = [c for c in STATS_COLUMNS if c in stats.columns]
    rest = [c for c in stats.columns if c not in STATS_COLUMNS]
    return stats[first + rest].reset_index(drop=True)


#: Statistics columns evaluation adds beyond the charter's.
STATS_EXTRA_UNITS: dict[str, str] = {
    "error_epochs": "count of epochs in the segment that the reference covers",
    "start_utc": "UTC ISO 8601, start of the outage (outage rows)",
    "end_utc": "UTC ISO 8601, end of the outage (outage rows)",
    "end_error_utc": "UTC ISO 8601, epoch end_error_m is taken at: the outage's last epoch the "
                     "reference covers (outage rows)",
}


def stats_units(stats: pd.DataFrame) -> dict[str, str]:
    """Column -> "unit, meaning" for the statistics file's field metadata."""
    from .evaluation import QC_STATS_COLUMNS

    known = {**STATS_COLUMNS, **STATS_EXTRA_UNITS, **QC_STATS_COLUMNS}
    return {c: known[c] for c in stats.columns if c in known}


# --------------------------------------------------------------------------- stats of a file

def params_from_metadata(meta: dict[str, str]) -> Params:
    """The parameters a track was made with (defaults when the file does not say)."""
    text = meta.get("params_toml")
    if not text:
        return config.defaults()
    import tomllib

    try:
        return config.merge(config.defaults(), tomllib.loads(text), "track metadata")
    except (tomllib.TOMLDecodeError, UsageError):
        return config.defaults()


def prepare_track(track: pd.DataFrame, meta: dict[str, str], reference: Reference | None,
                  name: str = "track") -> tuple[pd.DataFrame, LocalFrame, pd.DataFrame | None]:
    """An existing track ready for evaluation: its own frame from its metadata, else a frame
    centred on its first position (e/n recomputed from lat/lon); the reference in that frame."""
    from . import evaluation

    missing = [c for c in ("time", "lat", "lon") if c not in track.columns]
    if missing:
        raise InputError(name, f"not a gpsdr track: missing column(s) {', '.join(missing)}")
    if len(track) == 0:
        raise NoDataError(name, "the track has no rows")
    track = track.copy()
    frame = frame_from_metadata(meta)
    if frame is None or "e" not in track or "n" not in track:
        lat = track["lat"].to_numpy(float)
        lon = track["lon"].to_numpy(float)
        frame = LocalFrame.for_fixes(lat, lon)
        track["e"], track["n"] = frame.forward(lat, lon)
        if "gnss_e" in track and "gnss_n" in track:
            track["gnss_e"] = np.nan
            track["gnss_n"] = np.nan
    for col, unit in BASE_TRACK_UNITS.items():  # QC columns are not made up for an older file
        if col not in track.columns:
            track[col] = False if unit.startswith("bool") else np.nan
    ref_en = evaluation.reference_en(reference, frame) if reference is not None else None
    return track, frame, ref_en


def track_statistics(track: pd.DataFrame, meta: dict[str, str], reference: Reference | None,
                     name: str = "track") -> tuple[pd.DataFrame, pd.DataFrame | None]:
    """Statistics of an existing track (``gpsdr stats``) and the reference in its frame."""
    from . import evaluation

    track, _, ref_en = prepare_track(track, meta, reference, name)
    params = params_from_metadata(meta)
    stats = evaluation.error_statistics(track, ref_en, meta.get("filter", "track"), params)
    return order_stats(stats), ref_en


def time_span_s(t_ns: np.ndarray) -> float:
    return float((t_ns[-1] - t_ns[0]) / NS_PER_S) if len(t_ns) > 1 else 0.0


# --------------------------------------------------------------------------- what a log holds

def _iso(t_ns: int) -> str:
    return pd.Timestamp(int(t_ns), unit="ns", tz="UTC").isoformat()


def _stream_row(name: str, t_ns: np.ndarray) -> dict[str, Any]:
    t = np.sort(np.asarray(t_ns, np.int64))
    span = time_span_s(t)
    row: dict[str, Any] = {"stream": name, "records": len(t), "rate_hz": math.nan,
                           "start": _iso(t[0]) if len(t) else "", "end": _iso(t[-1]) if len(t) else "",
                           "duration_s": span}
    steps = np.diff(t)
    steps = steps[steps > 0]
    if len(steps):
        # the median step: a 10-Hz log with a 10-min gap is 10 Hz, not its mean 0.06 Hz
        row["rate_hz"] = NS_PER_S / float(np.median(steps))
    return row


def _distribution(values: np.ndarray) -> dict[str, float] | None:
    v = np.asarray(values, float)
    v = v[np.isfinite(v)]
    if not len(v):
        return None
    return {"min": float(v.min()), "median": float(np.median(v)),
            "p95": float(np.percentile(v, 95)), "max": float(v.max()), "count": len(v)}


def gnss_outages(t_valid_ns: np.ndarray, params: Params) -> tuple[list[dict[str, Any]], float]:
    """Gaps between usable fixes longer than max(outage_gap_s, 2.5 x median fix interval)."""
    t = np.sort(np.asarray(t_valid_ns, np.int64))
    gap_s = float(params["time"]["outage_gap_s"])
    if len(t) > 2:
        gap_s = max(gap_s, 2.5 * float(np.median(np.diff(t))) / NS_PER_S)
    out = []
    if len(t) > 1:
        d = np.diff(t) / NS_PER_S
        for k in np.flatnonzero(d > gap_s):
            out.append({"start": _iso(t[k]), "length_s": float(d[k])})
    return out, gap_s


def describe_drive(drive: Drive, params: Params) -> dict[str, Any]:
    """Streams with record counts, rates and time spans; GNSS fix quality, outages and
    DOP distributions; skipped records by reason (``gpsdr info``)."""
    desc: dict[str, Any] = {"streams": [], "sources": [s.path for s in drive.sources]}
    g = drive.gnss
    if g is not None and len(g):
        desc["streams"].append(_stream_row("gnss", g.t_ns))
        valid = g.valid
        quality = pd.Series(np.asarray(g.fix_quality, int)).value_counts().sort_index()
        outages, gap_s = gnss_outages(g.t_ns[valid], params)
        desc["gnss"] = {
            "fixes": len(g), "valid": int(valid.sum()),
            "fix_quality": {int(k): int(v) for k, v in quality.items()},
            "outage_threshold_s": gap_s, "outages": outages,
            "pdop": _distribution(g.pdop), "hdop": _distribution(g.hdop),
            "sigma_e_m": _distribution(g.sigma_e_m), "n_sats": _distribution(
                np.where(g.n_sats >= 0, g.n_sats, np.nan)),
        }
    if drive.gyro is not None and len(drive.gyro):
        desc["streams"].append(_stream_row("gyro", drive.gyro.t_ns))
        desc["gyro"] = {"yaw_rate_radps": _distribution(drive.gyro.yaw_rate_radps)}
    if drive.odo is not None and len(drive.odo):
        desc["streams"].append(_stream_row("odo", drive.odo.t_ns))
        desc["odo"] = {"speed_mps": _distribution(drive.odo.speed_mps)}
    if drive.accel is not None and len(drive.accel):
        desc["streams"].append(_stream_row("accel", drive.accel.t_ns))
        desc["accel"] = {"accel_mps2": _distribution(drive.accel.accel_mps2)}
    desc["skipped"] = {r: {"count": int(c), "first": drive.skipped.first.get(r, "")}
                       for r, c in sorted(drive.skipped.counts.items())}
    desc["notes"] = list(drive.meta.get("notes", [])) + list(drive.meta.get("warnings", []))
    desc["meta"] = _jsonable({k: v for k, v in drive.meta.items() if k not in ("notes", "warnings")})
    return desc


def describe_log(path: str, params: Params, *, topics: dict[str, str] | None = None,
                 date: Any = None, use_log_time: bool = False) -> dict[str, Any]:
    """Describe one file of any kind gpsdr reads (``gpsdr info``)."""
    from .io.readers import sniff

    kind = sniff(path)
    if kind == "parquet":
        from .io.parquet import read_track

        df, meta = read_track(path)
        desc: dict[str, Any] = {"streams": [], "skipped": {}}
        if "time" in df and len(df):
            desc["streams"].append(_stream_row("track", df["time"].astype("int64").to_numpy()))
        desc["track"] = {"rows": len(df), "columns": ", ".join(map(str, df.columns)),
                         "filter": meta.get("filter", "-"), "gpsdr": meta.get("gpsdr.version", "-")}
        return {"path": str(path), "kind": kind, **desc}
    if kind == "mcap":
        from .io.mcap import read_mcap

        drive = read_mcap(path, topics=topics, use_log_time=use_log_time, date=date)
    elif kind in ("ubx", "rosbag"):
        from .io.readers import read_log

        drive = read_log(path, topics=topics, date=date, use_log_time=use_log_time,
                         params=params)
    elif kind == "nmea":
        from .io.nmea import read_nmea

        try:
            drive = read_nmea(path, date=date)
        except NoDataError as err:
            if date is not None or "no date" not in err.reason:
                return {"path": str(path), "kind": kind, "streams": [], "skipped": {},
                        "notes": [f"nothing usable: {err.reason}"]}
            # a log without any date still tells its times of day: show them on 1970-01-01
            try:
                drive = read_nmea(path, date=dt.date(1970, 1, 1))
            except NoDataError as err2:
                return {"path": str(path), "kind": kind, "streams": [], "skipped": {},
                        "notes": [f"nothing usable: {err2.reason}"]}
            drive.meta.setdefault("notes", []).append(
                "no date in the log (no RMC/ZDA date): times are times of day shown on "
                "1970-01-01; give --date YYYY-MM-DD")
    elif kind == "rtklib":
        from .io.rtklib import read_rtklib

        drive = read_rtklib(path)
    else:
        drive, ref = _read_csv_any(path, params)
        if ref is not None:
            desc = {"streams": [_stream_row("reference", ref.t_ns)], "skipped": {},
                    "reference": {"lat_deg": _distribution(ref.lat_deg),
                                  "lon_deg": _distribution(ref.lon_deg)}}
            return {"path": str(path), "kind": "reference csv", **desc}
    return {"path": str(path), "kind": kind, **describe_drive(drive, params)}


def _read_csv_any(path: str, params: Params) -> tuple[Drive | None, Any]:
    """A CSV is a gyro log, an odometer log or a reference, told apart by its header."""
    from .io.csv import read_gyro_csv, read_odo_csv

    with open(path, "rb") as fh:
        header = fh.readline().decode("utf-8", "replace").lstrip("\ufeff")
    cols = {c.strip().lower() for c in header.split(",")}
    if cols & {"latitude", "lat"} and cols & {"longitude", "lon", "lng"} and not {"lat", "lon"} <= cols:
        # positions under other names (a phone's export): not an odometer for its speed
        raise InputError(path, f"line 1: CSV header {header.strip()!r} holds positions; gpsdr "
                               "reads a CSV of positions as a reference with columns t (or time, "
                               "timestamp; UTC POSIX s), lat, lon (rename them), and GNSS "
                               "input from NMEA, UBX, RTKLIB .pos, ROS bag or MCAP logs")
    if params["gyro"]["column"].lower() in cols:
        return read_gyro_csv(path, params["gyro"]), None
    if {"lat", "lon"} <= cols:  # a reference, whatever else it carries (a speed column)
        from .io.reference import read_reference

        return None, read_reference(path)
    odo_cols = {"speed", "distance", "ticks", params["odo"]["column"].lower()} - {""}
    if cols & odo_cols:
        return read_odo_csv(path, params["odo"]), None
    raise InputError(path, f"line 1: CSV header {header.strip()!r} is neither a gyro log "
                           f"({params['gyro']['column']}), an odometer log (speed, distance, "
                           "ticks) nor a reference (t, lat, lon)")
