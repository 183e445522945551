"""The PNG report: written, non-empty, with and without a reference."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from gpsdr_cli.conventions import NS_PER_S
from gpsdr_cli.errors import InputError
from gpsdr_cli.plot import plot_report
from gpsdr_cli.simulate import simulate_drive


@pytest.fixture(scope="module")
def track_and_ref():
    sim = simulate_drive("tunnels", seed=1, duration_s=150.0)
    tr = sim.truth.iloc[::10].reset_index(drop=True)  # 10 Hz
    rng = np.random.default_rng(0)
    rel = (tr["t_ns"] - tr["t_ns"].iloc[0]).to_numpy() / NS_PER_S
    o = sim.noise["outages"][0]
    outage = (rel >= o["start_s"]) & (rel < o["start_s"] + o["duration_s"])
    drift = np.cumsum(outage) * 0.02
    track = pd.DataFrame({
        "time": pd.to_datetime(tr["t_ns"], unit="ns", utc=True),
        "e": tr["e"] + drift, "n": tr["n"] + 0.3 * rng.standard_normal(len(tr)),
        "sigma_e": 0.5 + drift / 3, "sigma_n": 0.5 + drift / 3,
        "gnss_e": np.where(outage, np.nan, tr["e"] + rng.standard_normal(len(tr))),
        "gnss_n": np.where(outage, np.nan, tr["n"] + rng.standard_normal(len(tr))),
        "gnss_rejected": rng.random(len(tr)) < 0.01, "gnss_outage": outage,
        "pdop": 1.5 + 0.2 * np.sin(rel / 10),
    })
    return track, tr[["t_ns", "e", "n"]]


def _is_png(path) -> bool:
    return path.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_report_with_reference(tmp_path, track_and_ref):
    track, ref = track_and_ref
    out = plot_report(track, tmp_path / "sub" / "report.png", reference_en=ref, title="test")
    assert out.exists() and _is_png(out)
    assert out.stat().st_size > 30_000  # bytes: four panels of lines, not a blank page


def test_report_without_reference_and_minimal_track(tmp_path, track_and_ref):
    track, _ = track_and_ref
    out = plot_report(track, tmp_path / "noref.png")
    assert _is_png(out) and out.stat().st_size > 30_000
    minimal = track[["time", "e", "n"]]
    out2 = plot_report(minimal, tmp_path / "minimal.png")
    assert _is_png(out2) and out2.stat().st_size > 10_000


def test_report_rejects_unplottable(tmp_path, track_and_ref):
    track, _ = track_and_ref
    with pytest.raises(InputError):
        plot_report(track.iloc[:0], tmp_path / "empty.png")
    with pytest.raises(InputError):
        plot_report(track.drop(columns=["e"]), tmp_path / "no_e.png")


def test_default_title_names_the_smoother() -> None:
    from gpsdr_cli.cli.plot import default_title

    assert default_title({"filter": "aekf", "smoothed": "true"}) == "aekf + RTS"
    assert default_title({"filter": "fkf", "smoothed": "false"}) == "fkf"
    assert default_title({}) == ""
