"""The interactive HTML report of a fused track: one self-contained file.

The page holds its data inline (JSON in a ``<script type="application/json">``), its
own small canvas drawing code (``report.js``) and style (``report.css``), both
packaged beside this module and inlined, so it draws the whole track with no
network.  The script is ours rather than a map library (Leaflet, OpenLayers):
the page must open offline, as one file, and needs only a pannable, zoomable local
east/north canvas, time panels and hover, a few hundred lines.  An OpenStreetMap
base map is optional, off by default, and loads tiles only when its checkbox is
ticked; the local frame is tied to Web Mercator by an affine fit over the track
(pyproj), exact to well under a pixel over a drive's extent.

What it shows (the same panels as the PNG report, :mod:`gpsdr_cli.plot`):
  * map: GNSS fixes (grey dots), down-weighted fixes (amber rings: ``gnss_weight``
    below :data:`DOWNWEIGHTED_BELOW`, when the column exists), rejected fixes (red
    crosses: ``gnss_rejected``, or a fix present but not used), the reference (black),
    the fused track coloured by its horizontal sigma, or by ``quality`` (1 best ..
    6 worst) when the track has it, GNSS outages (orange halo, start/end marks and
    length of outages of 10 s or more), hover details (time, speed, sigma, PDOP,
    quality, separation, error);
  * time panels (minutes since the start, outages shaded): horizontal error against
    the reference with the GNSS-only error and the filter's 3-sigma (without a
    reference: |GNSS - fused| and the 3-sigma, log scale); PDOP; the filter's 1-sigma
    east and north; the forward/backward ``separation_m`` when the track has it.  A linear
    y axis follows the PNG's rule over the time range in view (spikes above twice the
    99.5th percentile clip), recomputed by the script as the user zooms.

Decimation keeps an hour at 100 Hz (360 k epochs) light: the line keeps one epoch
per :func:`line_step_m` metres of path, every change of GNSS state or quality and
at least one epoch per :data:`LINE_MAX_GAP_S`; the time panels keep, per time
bucket, its first epoch and each series' minimum and maximum (spikes survive);
every GNSS fix is kept.

Conventions: :mod:`gpsdr_cli.conventions` (local east/north metres, int64 ns UTC).
"""

from __future__ import annotations

import json
import math
from importlib import resources
from pathlib import Path
from typing import Any

import numpy as np
import pandas as pd

from ..conventions import NS_PER_S
from ..errors import InputError
from .atomic import write_text_atomic

#: A fix whose ``gnss_weight`` (1 = full weight) is below this is drawn as down-weighted.
DOWNWEIGHTED_BELOW = 0.9
#: The line keeps at most about this many epochs (the step grows with the path length).
LINE_MAX_POINTS = 20_000
#: ... and never spaces them closer than this along the path (m).
LINE_MIN_STEP_M = 0.5
#: ... nor leaves more than this between two kept epochs (s), so a stop stays hoverable.
LINE_MAX_GAP_S = 5.0
#: Time buckets of the panels (each keeps its first epoch and each series' min and max).
PANEL_BUCKETS = 2_000
#: Outages at least this long get their length written on the map (s), as in the PNG.
OUTAGE_LABEL_S = 10.0
#: Default base-map tiles ({z}/{x}/{y}); only fetched when the page's checkbox is ticked.
OSM_TILES = "https://tile.openstreetmap.org/{z}/{x}/{y}.png"
OSM_ATTRIBUTION = "© OpenStreetMap contributors"


def _t_ns(track: pd.DataFrame) -> np.ndarray:
    from ..evaluation import _t_ns_of

    return _t_ns_of(track, "track")


def _col(track: pd.DataFrame, name: str) -> np.ndarray:
    if name not in track:
        return np.full(len(track), np.nan)
    return pd.to_numeric(track[name], errors="coerce").to_numpy(dtype=float, na_value=np.nan)


def _bcol(track: pd.DataFrame, name: str) -> np.ndarray:
    if name not in track:
        return np.zeros(len(track), bool)
    return track[name].fillna(False).to_numpy(bool)


def _rounded(values: np.ndarray, digits: int) -> list[float | None]:
    """A JSON-ready list: rounded, NaN/inf -> null (JSON has neither)."""
    v = np.round(np.asarray(values, float), digits)
    ok = np.isfinite(v)
    if ok.all():
        return v.tolist()
    out: list[float | None] = v.tolist()
    for k in np.flatnonzero(~ok).tolist():
        out[k] = None
    return out


def line_step_m(path_length_m: float) -> float:
    """Spacing (m) of the kept line epochs along the path: LINE_MIN_STEP_M, or longer so
    the line keeps about LINE_MAX_POINTS epochs."""
    if not math.isfinite(path_length_m):
        return LINE_MIN_STEP_M
    return max(LINE_MIN_STEP_M, path_length_m / LINE_MAX_POINTS)


def decimate_line(e: np.ndarray, n: np.ndarray, t_ns: np.ndarray,
                  keep_changes: list[np.ndarray]) -> np.ndarray:
    """Indices of the epochs the map line keeps (sorted, unique, first and last included).

    Min-distance decimation along the path (one epoch per :func:`line_step_m` metres of
    cumulative path length), plus every epoch where one of ``keep_changes`` changes value
    (and the one before it), plus one epoch per LINE_MAX_GAP_S.
    """
    m = len(e)
    if m <= 2:
        return np.arange(m)
    step = np.hypot(np.diff(e), np.diff(n))
    step[~np.isfinite(step)] = 0.0
    s = np.concatenate(([0.0], np.cumsum(step)))
    d = line_step_m(float(s[-1]))
    keep = np.zeros(m, bool)
    keep[0] = keep[-1] = True
    cell = np.floor(s / d)
    keep[1:] |= cell[1:] != cell[:-1]
    tcell = (t_ns - t_ns[0]) // int(LINE_MAX_GAP_S * NS_PER_S)
    keep[1:] |= tcell[1:] != tcell[:-1]
    for flag in keep_changes:
        f = np.asarray(flag)
        change = np.flatnonzero(f[1:] != f[:-1])
        keep[change] = True
        keep[change + 1] = True
    return np.flatnonzero(keep)


def decimate_panels(t_ns: np.ndarray, series: list[np.ndarray],
                    buckets: int = PANEL_BUCKETS) -> np.ndarray:
    """Indices the time panels keep: per time bucket its first epoch and each series'
    minimum and maximum (NaN ignored), so a one-epoch spike is still drawn."""
    m = len(t_ns)
    if m <= 3 * buckets:
        return np.arange(m)
    span = max(int(t_ns[-1] - t_ns[0]), 1)
    b = np.minimum(((t_ns - t_ns[0]) * buckets) // span, buckets - 1)
    keep = np.zeros(m, bool)
    keep[0] = keep[-1] = True
    keep[1:] |= b[1:] != b[:-1]
    groups = pd.Series(b)
    for v in series:
        s = pd.Series(np.asarray(v, float))
        if not s.notna().any():
            continue
        ok = s.notna()
        g = s[ok].groupby(groups[ok])
        keep[g.idxmin().to_numpy()] = True
        keep[g.idxmax().to_numpy()] = True
    return np.flatnonzero(keep)


def _mercator_affine(e: np.ndarray, n: np.ndarray, lat: np.ndarray,
                     lon: np.ndarray) -> list[float] | None:
    """[a, b, c, d, f, g] with x = a e + b n + c, y = d e + f n + g (Web Mercator metres,
    EPSG:3857), fitted by least squares over the track; None without lat/lon."""
    ok = np.isfinite(e) & np.isfinite(n) & np.isfinite(lat) & np.isfinite(lon)
    if ok.sum() < 3:
        return None
    from pyproj import Transformer

    idx = np.flatnonzero(ok)
    if len(idx) > 5000:
        idx = idx[np.linspace(0, len(idx) - 1, 5000).astype(int)]
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:3857", always_xy=True).transform(
        lon[idx], lat[idx])
    a_mat = np.column_stack([e[idx], n[idx], np.ones(len(idx))])
    if np.linalg.matrix_rank(a_mat) < 3:  # a standstill: one point; scale from the latitude
        k = 1.0 / math.cos(math.radians(float(np.mean(lat[idx]))))
        return [k, 0.0, float(x[0] - k * e[idx[0]]), 0.0, k, float(y[0] - k * n[idx[0]])]
    cx = np.linalg.lstsq(a_mat, x, rcond=None)[0]
    cy = np.linalg.lstsq(a_mat, y, rcond=None)[0]
    return [float(v) for v in (*cx, *cy)]


def report_data(track: pd.DataFrame, reference_en: pd.DataFrame | None = None, title: str = "",
                *, pdop_good: float = 3.0, tiles_url: str = OSM_TILES,
                tiles_attribution: str = OSM_ATTRIBUTION) -> dict[str, Any]:
    """Everything the page draws, as a JSON-ready dict (see the module docstring)."""
    from ..evaluation import interpolate_reference, outage_runs, track_errors

    for name in ("e", "n"):
        if name not in track:
            raise InputError("track", f"cannot plot: the track has no {name} column")
    if len(track) == 0:
        raise InputError("track", "cannot plot an empty track")
    m = len(track)
    t_ns = _t_ns(track)
    t_s = (t_ns - t_ns[0]) / NS_PER_S
    e, n = _col(track, "e"), _col(track, "n")
    sig_e, sig_n = _col(track, "sigma_e"), _col(track, "sigma_n")
    sig_h = np.hypot(sig_e, sig_n)
    speed = _col(track, "speed")
    if not np.isfinite(speed).any() and "v_e" in track and "v_n" in track:
        speed = np.hypot(_col(track, "v_e"), _col(track, "v_n"))
    pdop = _col(track, "pdop")
    outage = _bcol(track, "gnss_outage")
    pdop_shown = np.where(outage, np.nan, pdop)  # the track carries the last PDOP through outages
    ge, gn = _col(track, "gnss_e"), _col(track, "gnss_n")
    has_fix = np.isfinite(ge) & np.isfinite(gn)
    used = _bcol(track, "gnss_used") if "gnss_used" in track else has_fix.copy()
    rejected = _bcol(track, "gnss_rejected") | (has_fix & ~used)
    has_quality = "quality" in track and pd.to_numeric(track["quality"], errors="coerce").notna().any()
    quality = _col(track, "quality") if has_quality else None
    has_sep = "separation_m" in track and np.isfinite(_col(track, "separation_m")).any()
    separation = _col(track, "separation_m") if has_sep else None
    weight = _col(track, "gnss_weight") if "gnss_weight" in track else None
    if weight is not None:
        rejected |= has_fix & (weight <= 0.0)
        downweighted = has_fix & ~rejected & (weight < DOWNWEIGHTED_BELOW)
    else:
        downweighted = np.zeros(m, bool)
    # GNSS state of a line epoch: 0 fixes available, 4 in an outage (the fixes' own state,
    # used / down-weighted / rejected, goes with each fix: a 10 Hz receiver flips "fix at
    # this epoch" every few epochs, which would defeat the line's decimation)
    state = np.where(outage, 4, 0).astype(int)

    ref = reference_en if reference_en is not None and len(reference_en) else None
    err = None
    stats_text = ""
    gnss_dot = np.where(has_fix, np.hypot(ge - e, gn - n), np.nan)  # no reference: |GNSS - fused|
    if ref is not None:
        err = track_errors(track, ref)["err_m"].to_numpy()
        re, rn, _, _, valid = interpolate_reference(ref, t_ns[has_fix])
        gnss_dot = np.full(m, np.nan)
        gnss_dot[has_fix] = np.where(valid, np.hypot(ge[has_fix] - re, gn[has_fix] - rn), np.nan)
        fin = err[np.isfinite(err)]
        stats_text = (f"RMSE {np.sqrt(np.mean(fin ** 2)):.2f} m, CEP95 {np.percentile(fin, 95):.2f} m,"
                      f" max {fin.max():.2f} m" if len(fin) else "reference does not cover the track")

    changes = [state]
    if quality is not None:
        changes.append(np.nan_to_num(quality, nan=0.0))
    li = decimate_line(e, n, t_ns, changes)
    line: dict[str, Any] = {
        "t": _rounded(t_s[li], 3), "e": _rounded(e[li], 2), "n": _rounded(n[li], 2),
        "sigma": _rounded(sig_h[li], 3), "speed": _rounded(speed[li], 2),
        "pdop": _rounded(pdop_shown[li], 2), "state": state[li].tolist(),
    }
    if quality is not None:
        line["quality"] = _rounded(quality[li], 0)
    if separation is not None:
        line["sep"] = _rounded(separation[li], 3)
    if err is not None:
        line["err"] = _rounded(err[li], 3)

    fi = np.flatnonzero(has_fix)
    fixes: dict[str, Any] = {
        "t": _rounded(t_s[fi], 3), "e": _rounded(ge[fi], 2), "n": _rounded(gn[fi], 2),
        "state": np.where(rejected[fi], 3, np.where(downweighted[fi], 2, 1)).tolist(),
        "pdop": _rounded(pdop[fi], 2),
    }
    if weight is not None:
        fixes["weight"] = _rounded(weight[fi], 3)

    ref_line = None
    if ref is not None:
        tr = ref["t_ns"].to_numpy(np.int64)
        span = (tr >= t_ns[0] - NS_PER_S) & (tr <= t_ns[-1] + NS_PER_S)  # the track's stretch only
        re_, rn_ = ref["e"].to_numpy(float)[span], ref["n"].to_numpy(float)[span]
        ri = decimate_line(re_, rn_, tr[span], [])
        ref_line = {"e": _rounded(re_[ri], 2), "n": _rounded(rn_[ri], 2)}

    runs = outage_runs(outage)
    outages = []
    for i0, i1 in runs:
        start = i0 - 1 if i0 > 0 else i0  # from the last fix, as the statistics do
        outages.append({"t0": round(float(t_s[start]), 3), "t1": round(float(t_s[i1]), 3),
                        "duration_s": round(float(t_s[i1] - t_s[start]), 2),
                        "e0": round(float(e[i0]), 2), "n0": round(float(n[i0]), 2),
                        "e1": round(float(e[i1]), 2), "n1": round(float(n[i1]), 2),
                        "labelled": bool(t_s[i1] - t_s[start] >= OUTAGE_LABEL_S)})

    series_src: dict[str, np.ndarray] = {"sigma3": 3.0 * sig_h, "sig_e": sig_e, "sig_n": sig_n,
                                         "pdop": pdop_shown}
    if err is not None:
        series_src["err"] = err
    if separation is not None:
        series_src["sep"] = separation
    pi = decimate_panels(t_ns, [v for k, v in series_src.items() if k != "sig_n"])
    series = {"t": _rounded(t_s[pi], 3)}
    series.update({k: _rounded(v[pi], 3) for k, v in series_src.items()})
    dots = {"t": _rounded(t_s[has_fix], 3), "v": _rounded(gnss_dot[has_fix], 3)}

    panels: list[dict[str, Any]] = []
    sigma_item = {"kind": "line", "src": "sigma3", "color": "#d62728", "dash": [6, 4],
                  "label": "filter 3-sigma (horizontal)"}
    if err is not None:
        panels.append({"id": "error", "title": f"horizontal error against the reference: {stats_text}",
                       "ylabel": "m", "log": False,
                       "items": [{"kind": "dots", "src": "gnss", "color": "#999999",
                                  "label": "GNSS-only error"},
                                 {"kind": "line", "src": "err", "color": "#1f77b4",
                                  "label": "fused error"}, sigma_item]})
    else:
        panels.append({"id": "error", "title": "no reference: GNSS-minus-fused separation vs the "
                                               "filter's 3-sigma", "ylabel": "m", "log": True,
                       "items": [{"kind": "dots", "src": "gnss", "color": "#808080",
                                  "label": "|GNSS - fused|"}, sigma_item]})
    panels.append({"id": "pdop", "title": "PDOP", "ylabel": "PDOP", "log": False,
                   "empty": None if np.isfinite(pdop).any() else "no PDOP in the input",
                   "items": [{"kind": "line", "src": "pdop", "color": "#9467bd", "label": "PDOP"},
                             {"kind": "hline", "value": pdop_good, "color": "#9467bd",
                              "dash": [2, 3], "label": f"pdop_good = {pdop_good:g}"}]})
    panels.append({"id": "sigma", "title": "filter 1-sigma", "ylabel": "m", "log": True,
                   "items": [{"kind": "line", "src": "sig_e", "color": "#1f77b4",
                              "label": "sigma east"},
                             {"kind": "line", "src": "sig_n", "color": "#2ca02c",
                              "label": "sigma north"}]})
    if separation is not None:
        panels.append({"id": "separation", "title": "forward/backward separation",
                       "ylabel": "m", "log": False,
                       "items": [{"kind": "line", "src": "sep", "color": "#8c564b",
                                  "label": "separation_m"}]})

    lat, lon = _col(track, "lat"), _col(track, "lon")
    dist = float(np.nansum(np.hypot(np.diff(e), np.diff(n)))) if m > 1 else 0.0
    counts = {"epochs": m, "line_points": len(li), "fixes": len(fi),
              "used": int((has_fix & ~rejected & ~downweighted).sum()),
              "downweighted": int(downweighted.sum()), "rejected": int((has_fix & rejected).sum()),
              "outages": len(runs), "panel_points": len(pi)}
    return {
        "title": title or "gpsdr track report",
        "start_ms": int(t_ns[0] // 1_000_000),
        "start_utc": pd.Timestamp(int(t_ns[0]), unit="ns", tz="UTC").strftime("%Y-%m-%d %H:%M:%S UTC"),
        "duration_s": round(float(t_s[-1]), 3), "distance_m": round(dist, 1),
        "colour_by": "quality" if quality is not None else "sigma",
        "has": {"quality": quality is not None, "separation": separation is not None,
                "weight": weight is not None, "reference": ref is not None},
        "stats_text": stats_text, "counts": counts, "downweighted_below": DOWNWEIGHTED_BELOW,
        "line": line, "fixes": fixes, "reference": ref_line, "outages": outages,
        "series": series, "dots": {"gnss": dots}, "panels": panels,
        "mercator": _mercator_affine(e, n, lat, lon),
        "tiles": {"url": tiles_url, "attribution": tiles_attribution},
    }


def _asset(name: str) -> str:
    return resources.files(__package__).joinpath(name).read_text(encoding="utf-8")


def _script_safe(text: str) -> str:
    """JSON inside <script>: no ``</`` (would end the element) and no ``<!--``."""
    return text.replace("</", "<\\/").replace("<!--", "<\\!--")


def render_html(data: dict[str, Any]) -> str:
    """The page: HTML skeleton, inlined style, data and script."""
    import html

    payload = _script_safe(json.dumps(data, separators=(",", ":"), allow_nan=False))
    title = html.escape(data["title"])
    return f"""<!DOCTYPE html>
<html lang="en">
<head>
<meta charset="utf-8">
<meta name="viewport" content="width=device-width, initial-scale=1">
<meta name="generator" content="gpsdr">
<title>{title}</title>
<style>
{_asset("report.css")}
</style>
</head>
<body>
<header>
  <h1>{title}</h1>
  <p id="summary"></p>
</header>
<div id="controls"></div>
<main>
  <section id="map-box">
    <canvas id="map" aria-label="map of the track in the local east/north frame"></canvas>
    <div id="legend"></div>
    <div id="attribution"></div>
    <div id="basemap-note"></div>
  </section>
  <section id="panels"></section>
</main>
<div id="tooltip" hidden></div>
<footer>
  <output id="status" data-state="loading">drawing ...</output>
  <pre id="probe" hidden></pre>
  <span class="help">Map: drag to pan, wheel to zoom, double-click to fit. Panels: drag or wheel
  to pan and zoom the time axis, double-click to show all. Hover for details.</span>
</footer>
<script type="application/json" id="gpsdr-data">{payload}</script>
<script>
{_asset("report.js")}
</script>
</body>
</html>
"""


def write_html_report(track: pd.DataFrame, out_path: str | Path,
                      reference_en: pd.DataFrame | None = None, title: str = "", *,
                      pdop_good: float = 3.0, tiles_url: str = OSM_TILES) -> Path:
    """Write the HTML report of ``track`` to ``out_path`` atomically; return the path."""
    try:
        data = report_data(track, reference_en, title, pdop_good=pdop_good, tiles_url=tiles_url)
    except InputError as err:
        raise InputError(str(out_path), err.reason) from err
    return write_text_atomic(out_path, render_html(data))


__all__ = [
    "DOWNWEIGHTED_BELOW",
    "decimate_line",
    "decimate_panels",
    "render_html",
    "report_data",
    "write_html_report",
]
