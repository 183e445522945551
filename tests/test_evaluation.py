"""Error statistics on closed-form cases."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

from gpsdr_cli.config import defaults
from gpsdr_cli.conventions import NS_PER_S, STATS_COLUMNS, TRACK_COLUMNS, TRACK_EXTRA_COLUMNS
from gpsdr_cli.evaluation import (
    CHI2_2DOF_95,
    _t_ns_of,
    error_statistics,
    gnss_only_errors,
    interpolate_reference,
    reference_en,
)
from gpsdr_cli.geodesy import LocalFrame

T0 = 1_700_000_000 * NS_PER_S
SPEED = 10.0  # m/s, due north


def straight_track(n_ep: int = 1001, rate_hz: float = 10.0,
                   offset_en=(0.0, 0.0)) -> tuple[pd.DataFrame, pd.DataFrame]:
    """A vehicle driving north at 10 m/s; the track = truth + a constant offset (m)."""
    t = T0 + (np.arange(n_ep) * (NS_PER_S / rate_hz)).astype(np.int64)
    n_true = SPEED * (t - T0) / NS_PER_S
    e_true = np.zeros(n_ep)
    track = pd.DataFrame({
        "time": pd.to_datetime(t, unit="ns", utc=True),
        "lat": 0.0, "lon": 0.0,
        "e": e_true + offset_en[0], "n": n_true + offset_en[1],
        "v_e": 0.0, "v_n": SPEED, "speed": SPEED, "heading_deg": 0.0,
        "sigma_e": 1.0, "sigma_n": 1.0, "gnss_used": True, "pdop": 1.5,
        "gnss_e": e_true + 1.0, "gnss_n": n_true, "gnss_rejected": False,
        "gnss_outage": False, "static": False, "nis": 1.0,
    })
    assert list(track.columns) == list(TRACK_COLUMNS) + list(TRACK_EXTRA_COLUMNS)
    ref = pd.DataFrame({"t_ns": t, "e": e_true, "n": n_true})
    return track, ref


def row(stats: pd.DataFrame, seg: str) -> pd.Series:
    return stats[stats["segment"] == seg].iloc[0]


def test_constant_offset_gives_closed_form_figures():
    track, ref = straight_track(offset_en=(3.0, 0.0))
    st = error_statistics(track, ref, "ekf", defaults())
    a = row(st, "all")
    assert a["epochs"] == len(track)
    for col in ("rmse_m", "mean_m", "cep50_m", "cep95_m", "max_m"):
        assert a[col] == pytest.approx(3.0, abs=1e-9)  # m
    # 3 m east of a northbound reference: all cross-track (to the right), nothing along
    assert a["along_rmse_m"] == pytest.approx(0.0, abs=1e-9)
    assert a["cross_rmse_m"] == pytest.approx(3.0, abs=1e-9)
    assert a["gnss_separation_rmse_m"] == pytest.approx(2.0, abs=1e-9)  # fix 1 m east, track 3 m east
    assert a["nis_in_95_share"] == pytest.approx(1.0)
    assert list(st.columns[:len(STATS_COLUMNS)]) == list(STATS_COLUMNS)


def test_along_cross_split_of_a_known_offset():
    track, ref = straight_track(offset_en=(-4.0, 3.0))  # 3 m ahead, 4 m to the left
    st = error_statistics(track, ref, "ekf", defaults())
    a = row(st, "all")
    assert a["rmse_m"] == pytest.approx(5.0, abs=1e-9)
    assert a["along_rmse_m"] == pytest.approx(3.0, abs=1e-9)
    assert a["cross_rmse_m"] == pytest.approx(4.0, abs=1e-9)
    # a turning reference: heading east, the same offset vector is now 4 m behind / 3 m left
    track2 = track.copy()
    ref2 = ref.rename(columns={"e": "n", "n": "e"})[["t_ns", "e", "n"]]
    track2["e"], track2["n"] = ref2["e"] - 4.0, ref2["n"] + 3.0
    from gpsdr_cli.evaluation import track_errors

    te = track_errors(track2, ref2)
    assert np.allclose(te["along_m"], -4.0) and np.allclose(te["cross_m"], -3.0)


def test_percentiles_of_a_known_distribution():
    track, ref = straight_track(n_ep=101)
    d = np.arange(101, dtype=float)  # errors 0..100 m east
    track["e"] = d
    st = error_statistics(track, ref, "x", defaults())
    a = row(st, "all")
    assert a["cep50_m"] == pytest.approx(50.0)
    assert a["cep95_m"] == pytest.approx(95.0)
    assert a["max_m"] == pytest.approx(100.0)
    assert a["mean_m"] == pytest.approx(50.0)
    assert a["rmse_m"] == pytest.approx(np.sqrt(np.mean(d**2)))


def test_segments_and_outage_rows():
    track, ref = straight_track(n_ep=1001)  # 100 s at 10 Hz
    out = np.zeros(len(track), bool)
    out[200:500] = True   # 30 s outage
    out[700:800] = True   # 10 s outage
    track["gnss_outage"] = out
    track.loc[out, ["gnss_e", "gnss_n", "nis"]] = np.nan
    # the error grows linearly to 6 m at the end of the first outage, 1 m during the second
    err = np.zeros(len(track))
    err[200:500] = np.linspace(0.02, 6.0, 300)
    err[700:800] = 1.0
    track["e"] = err
    track.loc[600:649, "pdop"] = 4.0     # degraded stretch, 50 epochs
    track.loc[900:919, "static"] = True
    st = error_statistics(track, ref, "aekf", defaults())
    assert row(st, "outage")["epochs"] == 400
    assert row(st, "degraded")["epochs"] == 50
    assert row(st, "open")["epochs"] == 1001 - 400 - 50
    assert row(st, "static")["epochs"] == 20
    assert row(st, "open")["max_m"] == pytest.approx(0.0)
    o1, o2 = row(st, "outage_1"), row(st, "outage_2")
    assert o1["duration_s"] == pytest.approx(30.0)   # last fix at 19.9 s to last outage epoch 49.9 s
    assert o1["distance_m"] == pytest.approx(300.0, abs=0.5)  # along the reference, 10 m/s
    assert o1["end_error_m"] == pytest.approx(6.0)
    assert o1["end_error_pct_distance"] == pytest.approx(2.0, rel=2e-3)
    assert o2["duration_s"] == pytest.approx(10.0)
    assert o2["end_error_m"] == pytest.approx(1.0)
    assert pd.isna(row(st, "outage")["gnss_separation_rmse_m"])
    assert pd.isna(row(st, "all")["duration_s"])
    assert len(st) == 5 + 2


def test_without_reference_error_columns_are_null(tmp_path):
    track, _ = straight_track()
    nis = np.full(len(track), 1.0)
    nis[::4] = 10.0  # a quarter outside the 95 % bound
    track["nis"] = nis
    track.loc[5:9, "gnss_outage"] = True
    st = error_statistics(track, None, "fkf", defaults())
    a = row(st, "all")
    for col in ("rmse_m", "mean_m", "cep50_m", "cep95_m", "max_m", "along_rmse_m"):
        assert pd.isna(a[col])
    assert a["nis_in_95_share"] == pytest.approx(np.mean(nis <= CHI2_2DOF_95))
    assert a["gnss_separation_rmse_m"] == pytest.approx(1.0)
    o = row(st, "outage_1")
    assert pd.isna(o["end_error_m"]) and o["distance_m"] == pytest.approx(5.0, abs=1e-6)  # 0.5 s at 10 m/s
    # the nulls are nulls in Parquet, not NaN floats
    path = tmp_path / "stats.parquet"
    st.to_parquet(path)
    import pyarrow.parquet as pq

    tab = pq.read_table(path)
    assert tab.column("rmse_m").null_count == len(st)
    # empty segments (degraded, static) and the outage row have no NIS share: nulls
    assert tab.column("nis_in_95_share").null_count == 3
    back = pd.read_parquet(path)
    assert back["rmse_m"].isna().all()


def test_reference_gaps_and_span_are_respected():
    track, ref = straight_track(n_ep=301)
    track["e"] = 2.0
    gap = (ref["t_ns"] > T0 + 10 * NS_PER_S) & (ref["t_ns"] < T0 + 15 * NS_PER_S)
    ref_gap = ref[~gap]
    ref_short = ref_gap[ref_gap["t_ns"] <= T0 + 25 * NS_PER_S]
    e, _, _, u_n, valid = interpolate_reference(ref_short, _t_ns_of(track, "track"))
    t_s = np.arange(301) / 10.0
    assert not valid[(t_s > 10.0) & (t_s < 15.0)].any()
    assert not valid[t_s > 25.0].any()
    assert valid[t_s <= 10.0].all()
    assert np.allclose(e[valid], 0.0)
    assert np.allclose(u_n[valid], 1.0)
    st = error_statistics(track, ref_short, "x", defaults())
    a = row(st, "all")
    assert a["epochs"] == 301
    assert a["error_epochs"] == int(valid.sum())
    assert a["rmse_m"] == pytest.approx(2.0)


def test_reference_projection_and_gnss_only_errors():
    frame = LocalFrame.centred_on(48.0, 11.0)
    track, ref = straight_track(n_ep=101)
    lat, lon = frame.inverse(ref["e"].to_numpy(), ref["n"].to_numpy())
    ref_ll = pd.DataFrame({"time": track["time"], "lat": lat, "lon": lon})
    r = reference_en(ref_ll, frame)
    assert np.max(np.abs(r["n"] - ref["n"])) < 1e-6
    d = gnss_only_errors(track, r)
    assert len(d) == 101 and np.allclose(d, 1.0, atol=1e-6)


def test_simulated_drive_end_to_end():
    from gpsdr_cli.simulate import simulate_drive

    sim = simulate_drive("tunnels", seed=2, duration_s=200.0)
    tr = sim.truth
    # a track equal to the truth except an east offset growing in the first tunnel
    track = pd.DataFrame({"time": pd.to_datetime(tr["t_ns"], unit="ns", utc=True),
                          "e": tr["e"].to_numpy().copy(), "n": tr["n"], "pdop": 1.5})
    rel = (tr["t_ns"] - tr["t_ns"].iloc[0]).to_numpy() / NS_PER_S
    o = sim.noise["outages"][0]
    inside = (rel >= o["start_s"]) & (rel < o["start_s"] + o["duration_s"])
    track["gnss_outage"] = inside
    track.loc[inside, "e"] += np.linspace(0.0, 10.0, inside.sum())
    st = error_statistics(track, tr[["t_ns", "e", "n"]], "truth+drift", defaults())
    r1 = row(st, "outage_1")
    dist = float(np.sum(tr["speed"].to_numpy()[inside]) * 0.01)
    assert r1["duration_s"] == pytest.approx(30.0, abs=0.02)
    assert r1["distance_m"] == pytest.approx(dist, rel=0.01)
    assert r1["end_error_m"] == pytest.approx(10.0, abs=1e-6)
    assert r1["end_error_pct_distance"] == pytest.approx(1000.0 / dist, rel=0.01)


def test_figures_invariant_under_a_common_shift_and_exact_for_any_offset():
    from hypothesis import given, settings
    from hypothesis import strategies as st

    track0, ref0 = straight_track(n_ep=201)

    @settings(max_examples=40, deadline=None)
    @given(de=st.floats(-50, 50), dn=st.floats(-50, 50), se=st.floats(-1e5, 1e5),
           sn=st.floats(-1e5, 1e5))
    def check(de, dn, se, sn):
        track = track0.copy()
        track["e"] = track0["e"] + de + se
        track["n"] = track0["n"] + dn + sn
        ref = ref0.assign(e=ref0["e"] + se, n=ref0["n"] + sn)
        a = row(error_statistics(track, ref, "x", defaults()), "all")
        r = float(np.hypot(de, dn))
        assert a["rmse_m"] == pytest.approx(r, abs=1e-6)     # m
        assert a["cep95_m"] == pytest.approx(r, abs=1e-6)
        assert a["along_rmse_m"] == pytest.approx(abs(dn), abs=1e-6)  # northbound: along = north
        assert a["cross_rmse_m"] == pytest.approx(abs(de), abs=1e-6)

    check()
