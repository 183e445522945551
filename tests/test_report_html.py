"""The HTML report: decimation, the data it carries, and the page drawn by headless Chromium."""

from __future__ import annotations

import json
import re

import numpy as np
import pandas as pd
import pytest

from gpsdr_cli import config
from gpsdr_cli.conventions import NS_PER_S
from gpsdr_cli.errors import InputError
from gpsdr_cli.report import html as rep
from gpsdr_cli.testing import browser

needs_chromium = pytest.mark.skipif(
    browser.find_chromium() is None,
    reason="headless Chromium is not installed (Debian: apt-get install chromium); "
           "the page is not rendered")

#: A port nothing listens on: the base-map test's tiles fail as they do offline.
DEAD_TILES = "http://127.0.0.1:9/{z}/{x}/{y}.png"


@pytest.fixture(scope="module")
def fused():
    """A 150 s tunnels drive (one 30 s outage) through the pipeline, with its truth."""
    from gpsdr_cli.pipeline import fuse
    from gpsdr_cli.simulate import simulate_drive

    sim = simulate_drive("tunnels", seed=1, duration_s=150.0)
    params = config.defaults()
    ref = sim.truth[["t_ns", "lat", "lon"]]
    res = fuse(sim.drive, params, ref)
    return res


def _with_qc_columns(track: pd.DataFrame) -> pd.DataFrame:
    """The columns other stages add: quality 1..6, separation_m, gnss_weight at the fixes."""
    t = track.copy()
    m = len(t)
    k = np.arange(m)
    t["quality"] = 1 + (k * 6) // m                  # six equal blocks, 1 .. 6
    t["separation_m"] = 0.1 + 0.01 * (k % 50)
    fix = t["gnss_e"].notna().to_numpy()
    w = np.where(fix, 1.0, np.nan)
    fix_idx = np.flatnonzero(fix & ~t["gnss_rejected"].to_numpy(bool))
    w[fix_idx[::10]] = 0.4                           # every tenth used fix: down-weighted
    t["gnss_weight"] = w
    return t


# ----------------------------------------------------------------------------- decimation

def test_line_decimation_keeps_the_shape_and_the_state_changes() -> None:
    # a 100 Hz hour: a 20 km circle, one 30 s outage
    m = 360_000
    t_ns = np.arange(m, dtype=np.int64) * (NS_PER_S // 100)
    ang = np.linspace(0.0, 2 * np.pi, m)
    r = 20_000.0 / (2 * np.pi)
    e, n = r * np.cos(ang), r * np.sin(ang)
    outage = np.zeros(m, bool)
    outage[100_000:103_000] = True
    keep = rep.decimate_line(e, n, t_ns, [outage])
    assert keep[0] == 0 and keep[-1] == m - 1
    assert np.all(np.diff(keep) > 0)
    assert {99_999, 100_000, 102_999, 103_000} <= set(keep.tolist())
    assert len(keep) <= rep.LINE_MAX_POINTS + 3_000  # + the one-per-5-s stamps
    # the chord between kept points stays within 1 cm of the circle (a 1 m step at r = 3.2 km)
    mid = 0.5 * (ang[keep[1:]] + ang[keep[:-1]])
    chord_mid = np.hypot(0.5 * (e[keep[1:]] + e[keep[:-1]]), 0.5 * (n[keep[1:]] + n[keep[:-1]]))
    assert np.max(r - chord_mid) < 0.01  # m
    assert np.all(np.isfinite(mid))
    # no two kept epochs further apart than the path step allows (+ float slack), in metres
    step = np.hypot(np.diff(e[keep]), np.diff(n[keep]))
    assert step.max() <= rep.line_step_m(20_000.0) * 1.01


def test_line_keeps_an_epoch_every_few_seconds_at_a_standstill() -> None:
    m = 6_000  # 60 s at 100 Hz, not moving
    t_ns = np.arange(m, dtype=np.int64) * (NS_PER_S // 100)
    keep = rep.decimate_line(np.zeros(m), np.zeros(m), t_ns, [])
    gaps_s = np.diff(t_ns[keep]) / NS_PER_S
    assert gaps_s.max() <= rep.LINE_MAX_GAP_S + 1e-9
    assert len(keep) <= 60 / rep.LINE_MAX_GAP_S + 2


def test_panel_decimation_keeps_a_one_epoch_spike() -> None:
    m = 360_000
    t_ns = np.arange(m, dtype=np.int64) * (NS_PER_S // 100)
    v = np.full(m, 1.0)
    v[123_457] = 50.0
    v[200_001] = -3.0
    keep = rep.decimate_panels(t_ns, [v])
    assert 123_457 in keep and 200_001 in keep
    assert len(keep) <= 3 * rep.PANEL_BUCKETS + 2


# ----------------------------------------------------------------------------- the data

def test_report_data_of_a_fused_track(fused) -> None:
    data = rep.report_data(fused.track, fused.reference_en, "t")
    track = fused.track
    assert data["counts"]["epochs"] == len(track)
    assert data["counts"]["fixes"] == int(track["gnss_e"].notna().sum())
    assert data["counts"]["rejected"] == int((track["gnss_rejected"]
                                              & track["gnss_e"].notna()).sum())
    # a fused track carries the QC columns: coloured by quality, with a separation panel
    assert data["colour_by"] == "quality" and data["has"]["quality"]
    assert [p["id"] for p in data["panels"]] == ["error", "pdop", "sigma", "separation"]
    # the page's RMSE is the statistics' RMSE
    rmse = float(fused.stats.loc[fused.stats["segment"] == "all", "rmse_m"].iloc[0])
    assert f"RMSE {rmse:.2f} m" in data["stats_text"]
    # one outage of the tunnels drive, 30 s long give or take a fix interval
    long = [o for o in data["outages"] if o["labelled"]]
    assert len(long) == 1 and abs(long[0]["duration_s"] - 30.0) <= 1.0
    # the local -> Web Mercator affine maps the track onto its own lat/lon within 0.5 m
    from pyproj import Transformer

    a = data["mercator"]
    x, y = Transformer.from_crs("EPSG:4326", "EPSG:3857", always_xy=True).transform(
        track["lon"].to_numpy(), track["lat"].to_numpy())
    e, n = track["e"].to_numpy(), track["n"].to_numpy()
    k = 1.0 / np.cos(np.radians(track["lat"].to_numpy()))  # Mercator metres per ground metre
    dx = (a[0] * e + a[1] * n + a[2] - x) / k
    dy = (a[3] * e + a[4] * n + a[5] - y) / k
    assert np.max(np.hypot(dx, dy)) < 0.5  # m on the ground


def test_report_data_with_quality_separation_and_weights(fused) -> None:
    track = _with_qc_columns(fused.track)
    data = rep.report_data(track, None)
    assert data["colour_by"] == "quality"
    assert [p["id"] for p in data["panels"]] == ["error", "pdop", "sigma", "separation"]
    fix = track["gnss_e"].notna()
    rejected = int((track["gnss_rejected"] & fix).sum())
    down = int((track["gnss_weight"] < rep.DOWNWEIGHTED_BELOW).sum())
    assert down > 0
    assert data["counts"]["downweighted"] == down
    assert data["counts"]["rejected"] == rejected
    assert data["counts"]["used"] == int(fix.sum()) - down - rejected
    assert sorted(set(data["line"]["quality"])) == [1, 2, 3, 4, 5, 6]
    assert data["fixes"]["state"].count(2) == down


def test_page_is_self_contained_and_safe(tmp_path, fused) -> None:
    out = rep.write_html_report(fused.track, tmp_path / "r.html", fused.reference_en,
                                title="a </script><b>title</b>")
    text = out.read_text(encoding="utf-8")
    assert "<script src" not in text and "<link" not in text  # nothing fetched to draw
    assert text.count("</script>") == 2  # the data and the code; the title cannot end either
    payload = re.search(r'<script type="application/json" id="gpsdr-data">(.*?)</script>',
                        text, re.DOTALL).group(1)
    data = json.loads(payload)  # strict JSON: no NaN / Infinity
    assert data["title"] == "a </script><b>title</b>"
    assert "NaN" not in payload and "Infinity" not in payload
    assert not list(tmp_path.glob(".*tmp*"))  # the temporary file was renamed


def test_unplottable_tracks_are_one_line_errors(tmp_path, fused) -> None:
    with pytest.raises(InputError, match="empty track"):
        rep.write_html_report(fused.track.iloc[:0], tmp_path / "e.html")
    with pytest.raises(InputError, match="no e column"):
        rep.write_html_report(fused.track.drop(columns=["e"]), tmp_path / "e.html")
    assert not (tmp_path / "e.html").exists()


# ----------------------------------------------------------------------------- the browser

@needs_chromium
def test_chromium_draws_every_point_and_every_panel(tmp_path, fused) -> None:
    track = _with_qc_columns(fused.track)
    out = rep.write_html_report(track, tmp_path / "r.html", fused.reference_en)
    data = rep.report_data(track, fused.reference_en)
    run = browser.dump_dom(out)
    st = run.status()
    assert st.get("data-state") == "done", (st, browser.console_errors(run.stderr))
    assert browser.console_errors(run.stderr) == []
    assert int(st["data-line-points"]) == data["counts"]["line_points"]
    assert int(st["data-visible-points"]) == data["counts"]["line_points"]  # fitted view
    assert int(st["data-fixes"]) == data["counts"]["fixes"]
    assert st["data-panels"] == "error,pdop,sigma,separation"
    assert st["data-basemap"] == "off"


@needs_chromium
def test_chromium_hover_shows_time_speed_sigma_pdop(tmp_path, fused) -> None:
    track = _with_qc_columns(fused.track)
    out = rep.write_html_report(track, tmp_path / "r.html", fused.reference_en)
    data = rep.report_data(track, fused.reference_en)
    k = 200
    run = browser.dump_dom(out, f"probe={k}")
    assert run.status().get("data-state") == "done"
    tip = run.element_text("probe")
    line = data["line"]
    t = pd.Timestamp(data["start_ms"] + line["t"][k] * 1000, unit="ms", tz="UTC")
    assert t.strftime("%Y-%m-%d %H:%M:%S") in tip
    assert f"speed {line['speed'][k]:.2f} m/s" in tip
    assert f"sigma {line['sigma'][k]:.3f} m" in tip
    pdop = line["pdop"][k]
    assert (f"PDOP {pdop:.2f}" if pdop is not None else "PDOP -") in tip
    assert f"quality {line['quality'][k]:.0f}" in tip
    assert f"separation {line['sep'][k]:.3f} m" in tip
    assert f"error {line['err'][k]:.3f} m" in tip


@needs_chromium
def test_chromium_zoom_and_an_unreachable_base_map(tmp_path, fused) -> None:
    out = rep.write_html_report(fused.track, tmp_path / "r.html", fused.reference_en,
                                tiles_url=DEAD_TILES)
    n_line = rep.report_data(fused.track, fused.reference_en)["counts"]["line_points"]
    zoomed = browser.dump_dom(out, "zoom=8").status()
    assert zoomed["data-state"] == "done"
    assert 0 < int(zoomed["data-visible-points"]) < n_line / 3  # 8x: a fraction in view
    offline = browser.dump_dom(out, "basemap=1")
    st = offline.status()
    assert st["data-state"] == "done" and st["data-basemap"] == "on"
    assert int(st["data-visible-points"]) == n_line  # the track is drawn all the same


@needs_chromium
def test_chromium_screenshot_shows_the_track(tmp_path, fused) -> None:
    from PIL import Image

    out = rep.write_html_report(fused.track, tmp_path / "r.html", fused.reference_en)
    png = tmp_path / "shot.png"
    browser.screenshot(out, png)
    img = np.asarray(Image.open(png).convert("RGB")).astype(int)
    assert img.shape[:2] == (1000, 1400)
    # the outage halo (#f28e2b at 70 % on white) and the panels' fused-error blue (#1f77b4)
    orange = (np.abs(img - [246, 176, 107]).sum(axis=2) < 30).sum()
    blue = (np.abs(img - [31, 119, 180]).sum(axis=2) < 30).sum()
    assert orange > 200 and blue > 200  # pixels


# ----------------------------------------------------------------------------- the command

def test_gpsdr_plot_html_with_and_without_a_reference(gpsdr, tmp_path, fused) -> None:
    from gpsdr_cli.io.parquet import write_table
    from gpsdr_cli.pipeline import TRACK_UNITS
    from gpsdr_cli.simulate import simulate_drive

    track = tmp_path / "track.parquet"
    write_table(fused.track, track, metadata=fused.metadata, units=TRACK_UNITS)
    truth = simulate_drive("tunnels", seed=1, duration_s=150.0).truth
    ref_csv = tmp_path / "truth.csv"
    pd.DataFrame({"t": truth["t_ns"] / NS_PER_S, "lat": truth["lat"],
                  "lon": truth["lon"]}).to_csv(ref_csv, index=False)
    out = tmp_path / "report.html"
    png = tmp_path / "report.png"
    res = gpsdr(["plot", track, "--reference", ref_csv, "--html", out, "-o", png])
    assert res.exit_code == 0, res.stderr
    assert f"wrote {out}" in res.stderr and f"wrote {png}" in res.stderr
    text = out.read_text(encoding="utf-8")
    data = json.loads(re.search(r'id="gpsdr-data">(.*?)</script>', text, re.DOTALL).group(1))
    rmse = float(fused.stats.loc[fused.stats["segment"] == "all", "rmse_m"].iloc[0])
    assert f"RMSE {rmse:.2f} m" in data["stats_text"]  # the same figure as gpsdr fuse's
    assert data["title"] == "aekf + graph"  # from the track's metadata (the default smoother)
    noref = gpsdr(["plot", track, "--html", tmp_path / "noref.html", "-q"])
    assert noref.exit_code == 0 and noref.stderr == ""
    assert "no reference" in (tmp_path / "noref.html").read_text(encoding="utf-8")
    neither = gpsdr(["plot", track])
    assert neither.exit_code == 2 and "--html" in neither.stderr


#: Appended to a copy of the page: real pointer events on the map and the first panel, and
#: what the tooltip then says, into <pre id="selftest">.
_EVENTS_JS = """<script>
(function () {
  var out = [], tip = document.getElementById("tooltip");
  function move(el, x, y) {
    el.dispatchEvent(new PointerEvent("pointermove", {clientX: x, clientY: y, bubbles: true}));
  }
  var panel = document.querySelector(".panel canvas"), r = panel.getBoundingClientRect();
  move(panel, r.left + r.width / 2, r.top + r.height / 2);
  out.push("panel:" + (tip.hidden ? "" : tip.textContent));
  var map = document.getElementById("map"), m = map.getBoundingClientRect(), found = "";
  for (var y = m.top + 5; y < m.bottom && !found; y += 6) {
    for (var x = m.left + 5; x < m.right && !found; x += 6) {
      move(map, x, y);
      if (!tip.hidden) { found = tip.textContent; }
    }
  }
  out.push("map:" + found);
  var pre = document.createElement("pre"); pre.id = "selftest";
  pre.textContent = out.join("\\n----\\n"); document.body.appendChild(pre);
})();
</script>
</body>"""


@needs_chromium
def test_chromium_pointer_events_show_the_tooltip(tmp_path, fused) -> None:
    out = rep.write_html_report(fused.track, tmp_path / "r.html", fused.reference_en)
    page = tmp_path / "events.html"
    page.write_text(out.read_text(encoding="utf-8").replace("</body>", _EVENTS_JS),
                    encoding="utf-8")
    run = browser.dump_dom(page)
    assert run.status().get("data-state") == "done", browser.console_errors(run.stderr)
    text = run.element_text("selftest")
    panel, _, map_part = text.partition("----")
    # the panel's cursor at mid-drive: the epoch's time and the panel's own series
    assert "UTC" in panel and "speed" in panel and "fused error:" in panel
    t_mid = pd.Timestamp(fused.track["time"].iloc[0]) + pd.Timedelta(
        seconds=(fused.track["time"].iloc[-1] - fused.track["time"].iloc[0]).total_seconds() / 2)
    assert t_mid.strftime("%H:%M:") in panel  # within the minute of the middle of the drive
    # somewhere on the map the pointer finds the track or a fix
    assert "speed" in map_part or "GNSS fix" in map_part


@needs_chromium
def test_the_benchmark_script_runs(capsys) -> None:
    from tests.conftest import load_benchmark

    bench = load_benchmark("html_report")
    assert bench.main(["--duration", "60", "--runs", "1"]) == 0
    out = capsys.readouterr().out
    assert "6001 epochs" in out and "target <= 5 s: met" in out
