"""Drives with known truth: a vehicle, its GNSS receiver, gyro and odometer.

Why hand-written: no maintained Python package simulates a *vehicle* log
(odometer ticks, a yaw gyro and an NMEA receiver with PDOP-dependent noise and
multipath) with the error models gpsdr's filters assume; the pieces are short.

Conventions (:mod:`gpsdr_cli.conventions`): int64 ns UTC time, local frame
east/north in metres (a transverse Mercator centred on the scenario's origin
city, :class:`~gpsdr_cli.geodesy.LocalFrame`), heading ``psi`` clockwise from
north, yaw rate positive counter-clockwise so ``d(psi)/dt = -yaw_rate``.

The vehicle
    A route is a curvature profile ``kappa(s)`` over path length ``s`` (straights,
    clothoid-ramped corners and curves; ``kappa > 0`` turns right, i.e. heading
    increases) plus stop lines with dwell times.  A driver model at 100 Hz
    follows the largest speed that respects the cruise speed, the lateral
    acceleration in curves (``v <= sqrt(a_lat / |kappa|)``) and braking to the
    next stop (``v <= sqrt(2 a_brake d)``), with limited acceleration and jerk.
    Heading rate ``d(psi)/dt = kappa v``; heading and position are the
    trapezoidal integrals of heading rate and velocity, so the truth is
    consistent to integration round-off.

The GNSS receiver (per epoch, per axis e/n)
    ``fix = truth(t + stamp_offset) + w + b + jump`` with white noise
    ``w ~ N(0, (gnss_sd_per_pdop_m * PDOP)^2)``, multipath ``b`` a first-order
    Gauss-Markov process whose sigma depends on the environment (open 0.4 m,
    suburban 1.2 m, urban canyon 4 m per axis) and which decorrelates with the
    distance driven (50 m in a canyon) and slowly in time when standing
    (``1/tau = 1/tau_still + speed/distance``), rare outlier jumps, and outages
    (fix quality 0) in tunnels or random drop-outs.  PDOP is a log-normal
    Gauss-Markov series around the environment's mean.  The receiver reports a
    sigma (NMEA GST / NavSatFix covariance) that includes the white part and only
    a share of the multipath sigma (all of it in open sky, 30 % in an urban
    canyon), as real receivers underestimate multipath.
    ``stamp_offset`` > 0 means the fix holds the position of a *later* instant than
    its stamp (the comma2k19 situation); the correction is
    ``[time] gnss_offset_s = stamp_offset``.

The gyro (consumer MEMS): ``(1 + scale_error) * yaw_rate + bias(t) + white`` with
white noise 0.1 deg/s per 100 Hz sample, scale error ~N(0, 0.5 %), and a bias
that is a stationary first-order Gauss-Markov process (the filters' own drift
model) of sigma 0.3 deg/s and correlation time 1 h: a turn-on bias that differs
per drive and wanders by about 0.05 deg/s a minute (a rate random walk of 1500
deg/h/sqrt(h), tens of times a consumer MEMS gyro's in-run wander: a pessimistic
gyro, whose wander also stands for the scale error and temperature drift the filters
do not model; decisions/0043).
The odometer: wheel ticks ``floor(40/m * (1 + scale_error) * distance)``
(scale error ~N(0, 2 %)) turned into speed over a 0.1 s moving window (so it
lags by 0.05 s and is quantised to 0.25 m/s steps), plus 0.02 m/s white noise.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import pandas as pd
from numba import njit

from .config import DEFAULTS, Params
from .conventions import FIX_GPS, FIX_NONE, NS_PER_S
from .errors import UsageError
from .geodesy import LocalFrame
from .io.drive import Drive, ForwardAccel, GnssFixes, Odometry, Source, YawRates
from .io.reference import Reference

SCENARIOS: tuple[str, ...] = ("open_sky", "urban_canyon", "tunnels", "stop_and_go", "one_hour",
                              "urban_nlos", "rtk", "no_odometer")

TRUTH_RATE_HZ = 100
DT_S = 1.0 / TRUTH_RATE_HZ
#: every drive starts at this UTC instant (a Tuesday morning)
START_NS = int(_dt.datetime(2024, 5, 14, 8, 0, 0, tzinfo=_dt.UTC).timestamp()) * NS_PER_S

# Environments: index -> name, and their GNSS error parameters.
ENV_NAMES = ("open", "suburban", "urban")
_ENV = {
    #          pdop_mean pdop_log_sd mp_sd_m mp_tau_s gst_mp_share outlier_p dropout_p mp_dist_m
    "open": (1.5, 0.12, 0.4, 120.0, 1.0, 0.0, 0.0, 300.0),
    "suburban": (2.2, 0.2, 1.2, 60.0, 0.7, 0.001, 0.0005, 100.0),
    "urban": (3.8, 0.3, 4.0, 60.0, 0.3, 0.004, 0.002, 50.0),
}


@dataclass
class _Scenario:
    route: str                 # "open" | "city" | "highway" | "stop_and_go" | "mixed"
    duration_s: float
    origin: tuple[float, float, float]  # lat deg, lon deg, ellipsoidal height m
    env: str | None            # one environment for the whole drive, or None: by route kind
    short_dropouts: bool = False
    #: the receiver's error model on top of the environment's: "gm" (white + Gauss-Markov
    #: multipath only), "nlos" (canyon sections with NLOS steps), "rtk" (fixed / float /
    #: false fixes), "rtk_fixed" (RTK fixed throughout)
    gnss_model: str = "gm"
    gnss_rate_hz: float | None = None   # the scenario's fix rate (None: simulate_drive's default)
    odometer: bool = True
    accel: bool = False                 # a forward accelerometer beside the gyro
    stop_p: float | None = None         # city route: chance of a stop line per block (None: 0.25)
    park_s: float = 0.0                 # > 0: one stop of this many seconds (a parked stretch)
    hills: bool = False                 # a rolling slope profile (the accelerometer feels g sin(pitch))
    brake_outages: bool = False         # 15-s GNSS outages while braking and accelerating


_SCENARIOS: dict[str, _Scenario] = {
    "open_sky": _Scenario("open", 600.0, (48.7665, 11.4258, 410.0), "open"),
    "urban_canyon": _Scenario("city", 600.0, (50.1109, 8.6821, 150.0), "urban", True),
    "tunnels": _Scenario("highway", 600.0, (48.7758, 9.1829, 300.0), "open"),
    "stop_and_go": _Scenario("stop_and_go", 900.0, (48.1372, 11.5756, 520.0), "suburban"),
    "one_hour": _Scenario("mixed", 3600.0, (52.5200, 13.4050, 40.0), None, True),
    "urban_nlos": _Scenario("city", 600.0, (35.6895, 139.6917, 40.0), "open", gnss_model="nlos"),
    "rtk": _Scenario("city", 600.0, (52.2297, 21.0122, 110.0), "open", gnss_model="rtk",
                     gnss_rate_hz=4.0, odometer=False, park_s=120.0),
    "no_odometer": _Scenario("city", 600.0, (47.3769, 8.5417, 410.0), "open",
                             gnss_model="rtk_fixed", gnss_rate_hz=4.0, odometer=False, accel=True,
                             stop_p=0.45, hills=True, brake_outages=True),
}

#: route kind code per distance grid point -> environment
_KIND_ENV = {0: "open", 1: "urban", 2: "suburban"}


@dataclass
class SimDrive:
    """A simulated drive: the sensor logs (``drive``) and what really happened.

    ``truth``: one row per 10 ms, columns t_ns (int64), lat, lon (deg), e, n (m),
    v_e, v_n, speed (m/s), heading_deg (clockwise from north), yaw_rate (rad/s,
    CCW+), alt (m).  ``noise``: the true error parameters (JSON-able).
    ``gnss_errors``: per GNSS epoch t_ns, pdop, hdop, env, white_e/n,
    multipath_e/n, jump_e/n (m), outlier, no_fix, true_sd_m (per axis, white and
    multipath stationary sigma) - what the receiver really did.
    """

    drive: Drive
    truth: pd.DataFrame
    frame: LocalFrame
    noise: dict
    scenario: str
    seed: int
    gnss_errors: pd.DataFrame = field(default_factory=pd.DataFrame)

    def reference(self) -> Reference:
        """The truth as a reference trajectory (``gpsdr fuse --reference``), no altitude."""
        t = self.truth
        return Reference(t_ns=t["t_ns"].to_numpy(np.int64), lat_deg=t["lat"].to_numpy(float),
                         lon_deg=t["lon"].to_numpy(float), alt_m=np.full(len(t), np.nan),
                         source=f"simulated {self.scenario} seed {self.seed}")


# --------------------------------------------------------------------------- route

def _pieces_city(rng: np.random.Generator, length_m: float, long_stops: bool,
                 stop_p: float | None = None
                 ) -> tuple[list[tuple[float, float, float]], list[tuple[float, float]], float]:
    """City blocks: straights, 90-degree corners at intersections, traffic lights (a stop
    line after a block with chance ``stop_p``; default 0.25, 0.3 with ``long_stops``)."""
    pieces: list[tuple[float, float, float]] = [(30.0, 0.0, 0.0)]
    stops: list[tuple[float, float]] = []
    s = 30.0
    while s < length_m:
        L = float(rng.uniform(80.0, 250.0))
        pieces.append((L, 0.0, 0.0))
        s += L
        if rng.random() < (stop_p if stop_p is not None else 0.3 if long_stops else 0.25):
            dwell = float(rng.uniform(120.0, 240.0)) if long_stops and rng.random() < 0.5 \
                else float(rng.uniform(8.0, 35.0))
            stops.append((s - 3.0, dwell))
        if rng.random() < 0.5:
            radius = float(rng.uniform(10.0, 18.0))
            sign = 1.0 if rng.random() < 0.5 else -1.0
            s += _add_turn(pieces, sign * math.pi / 2, radius, 5.0)
        elif rng.random() < 0.2:  # a gentle bend in the street
            s += _add_turn(pieces, float(rng.uniform(-0.4, 0.4)), float(rng.uniform(60, 150)), 10.0)
    return pieces, stops, 13.9


def _pieces_open(rng: np.random.Generator, length_m: float
                 ) -> tuple[list[tuple[float, float, float]], list[tuple[float, float]], float]:
    """Rural road: long straights, curves of 60-400 m radius, a few junctions."""
    pieces: list[tuple[float, float, float]] = [(50.0, 0.0, 0.0)]
    stops: list[tuple[float, float]] = []
    s = 50.0
    while s < length_m:
        L = float(rng.uniform(150.0, 600.0))
        pieces.append((L, 0.0, 0.0))
        s += L
        if rng.random() < 0.15:  # a junction: stop, then turn
            stops.append((s - 3.0, float(rng.uniform(5.0, 30.0))))
            s += _add_turn(pieces, (1 if rng.random() < 0.5 else -1) * math.pi / 2,
                           float(rng.uniform(12.0, 20.0)), 5.0)
        else:
            ang = float(rng.uniform(0.3, 1.6)) * (1 if rng.random() < 0.5 else -1)
            s += _add_turn(pieces, ang, float(rng.uniform(60.0, 400.0)), 20.0)
    return pieces, stops, 22.0


def _pieces_highway(rng: np.random.Generator, length_m: float
                    ) -> tuple[list[tuple[float, float, float]], list[tuple[float, float]], float,
                               list[tuple[float, float]]]:
    """Highway with three tunnels (30, 60, 120 s at cruise speed); the 60 s one holds a curve.

    Returns pieces, stops, cruise speed and the tunnels as (start s in m, duration s).
    """
    v = 22.0
    pieces: list[tuple[float, float, float]] = []

    def total() -> float:
        return sum(p[0] for p in pieces)

    pieces.append((1000.0 + float(rng.uniform(-100.0, 100.0)), 0.0, 0.0))
    _add_turn(pieces, 0.35, 800.0, 40.0)
    pieces.append((800.0, 0.0, 0.0))
    tunnels = [(total(), 30.0)]
    pieces.append((30.0 * v + 1500.0, 0.0, 0.0))
    tunnels.append((total(), 60.0))
    pieces.append((200.0, 0.0, 0.0))
    _add_turn(pieces, -1.2, 550.0, 60.0)  # about 660 m of curve inside the 1320 m tunnel
    pieces.append((60.0 * v - (total() - tunnels[1][0]) + 1800.0, 0.0, 0.0))
    tunnels.append((total(), 120.0))
    pieces.append((900.0, 0.0, 0.0))
    _add_turn(pieces, 0.25, 1500.0, 60.0)
    while total() < length_m:
        pieces.append((1200.0, 0.0, 0.0))
        _add_turn(pieces, float(rng.uniform(-0.5, 0.5)), float(rng.uniform(600, 1500)), 60.0)
    return pieces, [], v, tunnels


def _add_turn(pieces: list[tuple[float, float, float]], dpsi_rad: float, radius_m: float,
              ramp_m: float) -> float:
    """Append a clothoid-ramped arc turning by ``dpsi_rad`` (> 0: right); return its length."""
    kappa = math.copysign(1.0 / radius_m, dpsi_rad)
    ramp = min(ramp_m, 0.5 * abs(dpsi_rad) * radius_m)
    arc = abs(dpsi_rad) * radius_m - ramp  # two half-ramps turn by kappa*ramp in total
    pieces.extend([(ramp, 0.0, kappa), (arc, kappa, kappa), (ramp, kappa, 0.0)])
    return 2 * ramp + arc


def _grid(pieces: list[tuple[float, float, float]], kinds: list[int], ds: float
          ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Curvature and route kind on a distance grid of step ``ds`` metres."""
    total = sum(p[0] for p in pieces)
    s = np.arange(0.0, total + ds, ds)
    kappa = np.zeros_like(s)
    kind = np.zeros(len(s), np.int8)
    start = 0.0
    for (L, k0, k1), kd in zip(pieces, kinds, strict=True):
        m = (s >= start) & (s < start + L)
        kappa[m] = k0 + (k1 - k0) * (s[m] - start) / L
        kind[m] = kd
        start += L
    kind[s >= start] = kinds[-1]
    return s, kappa, kind


@njit(cache=True)
def _drive_kernel(s_grid: np.ndarray, v_allow: np.ndarray, kappa: np.ndarray,
                  stop_s: np.ndarray, dwell_s: np.ndarray, n_steps: int, dt: float,
                  a_acc: float, a_brake: float, jerk: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:  # pragma: no cover - numba
    """The driver: speed and heading rate at every step (100 Hz)."""
    ds = s_grid[1] - s_grid[0]
    n_grid = len(s_grid)
    v_out = np.zeros(n_steps)
    psidot = np.zeros(n_steps)
    s_out = np.zeros(n_steps)
    s = 0.0
    v = 0.0
    a = 0.0
    j = 0           # next stop
    dwell = -1.0    # > 0 while standing at stop j
    floor_s = 0.0   # look up the allowed speed no earlier than this (after a stop)
    for k in range(n_steps):
        if dwell > 0.0:
            dwell -= dt
            v = 0.0
            a = 0.0
            if dwell <= 0.0:
                floor_s = stop_s[j] + ds
                j += 1
        else:
            look = max(s + 0.3 * v, floor_s)
            i = min(int(look / ds), n_grid - 2)
            w = look / ds - i
            w = min(w, 1.0)
            v_t = v_allow[i] * (1.0 - w) + v_allow[i + 1] * w
            a_cmd = 1.5 * (v_t - v)
            a_cmd = min(a_cmd, a_acc)
            a_cmd = max(a_cmd, -2.0 * a_brake)
            da = a_cmd - a
            lim = jerk * dt
            da = min(da, lim)
            da = max(da, -lim)
            a += da
            near_stop = j < len(stop_s) and s > stop_s[j] - 4.0
            if near_stop and (v < 0.8 or s > stop_s[j] - 1.0):
                # final metres: brake to stand still at the line (overshoot < 1 m)
                gap = max(stop_s[j] - s, 0.3)
                a = -min(4.0, max(0.8, v * v / (2.0 * gap)))
            v += a * dt
            if v <= 0.0:
                v = 0.0
                a = max(a, 0.0)
                if near_stop:
                    dwell = dwell_s[j]
            if s >= s_grid[n_grid - 1] - 1.0:
                v = 0.0
                a = 0.0
        i = min(int(s / ds), n_grid - 2)
        w = s / ds - i
        w = min(w, 1.0)
        kap = kappa[i] * (1.0 - w) + kappa[i + 1] * w
        v_out[k] = v
        psidot[k] = kap * v
        s_out[k] = s
        s += v * dt
    return v_out, psidot, s_out


def _allowed_speed(s: np.ndarray, kappa: np.ndarray, v_cap: np.ndarray, stops: np.ndarray,
                   a_lat: float, a_brake: float) -> np.ndarray:
    """Largest speed at each grid point: cruise cap, curve limit, braking to the next stop."""
    v = np.minimum(v_cap, np.sqrt(a_lat / np.maximum(np.abs(kappa), 1e-9)))
    for st in stops:
        v[np.searchsorted(s, st):np.searchsorted(s, st) + 1] = 0.0
    v[-1] = 0.0
    ds = s[1] - s[0]
    for i in range(len(v) - 2, -1, -1):  # backward pass: braking distance (v^2 = v1^2 + 2 a d)
        v[i] = min(v[i], math.sqrt(v[i + 1] ** 2 + 2.0 * a_brake * ds))
    return v


def _route(sc: _Scenario, rng: np.random.Generator, duration_s: float) -> dict:
    """Pieces and stops for the scenario's route, long enough for ``duration_s``."""
    tunnels: list[tuple[float, float]] = []
    if sc.route == "highway":
        pieces, stops, v_cruise, tunnels = _pieces_highway(rng, 22.0 * duration_s + 2000.0)
        kinds = [0] * len(pieces)
    elif sc.route == "open":
        pieces, stops, v_cruise = _pieces_open(rng, 22.0 * duration_s + 2000.0)
        kinds = [0] * len(pieces)
    elif sc.route in ("city", "stop_and_go"):
        pieces, stops, v_cruise = _pieces_city(rng, 14.0 * duration_s + 1000.0,
                                               sc.route == "stop_and_go", sc.stop_p)
        kinds = [1] * len(pieces)
    else:  # mixed: alternate city (urban), suburban and open-road blocks
        pieces, stops, kinds = [], [], []
        s0 = 0.0
        block = 0
        while s0 < 16.0 * duration_s + 2000.0:
            kind = (1, 2, 0)[block % 3]
            if kind == 0:
                p, st, _ = _pieces_open(rng, 5000.0)
            else:
                p, st, _ = _pieces_city(rng, 3000.0, False)
            stops.extend((s0 + a, d) for a, d in st)
            pieces.extend(p)
            kinds.extend([kind] * len(p))
            s0 += sum(x[0] for x in p)
            block += 1
        v_cruise = 22.0
    return {"pieces": pieces, "stops": stops, "v_cruise": v_cruise, "kinds": kinds,
            "tunnels": tunnels}


def _vehicle(sc: _Scenario, rng: np.random.Generator, duration_s: float
             ) -> tuple[dict[str, np.ndarray], dict]:
    route = _route(sc, rng, duration_s)
    if sc.park_s > 0:
        route["stops"] = _with_parking(route["stops"], sc.park_s)
    ds = 0.5
    s_grid, kappa, kind = _grid(route["pieces"], route["kinds"], ds)
    v_cap = np.full(len(s_grid), route["v_cruise"])
    if sc.route == "mixed":
        v_cap = np.where(kind == 0, 22.0, np.where(kind == 1, 13.9, 16.7))
    # per-straight speed variation (drivers do not hold the limit exactly)
    wobble = 1.0 + 0.06 * np.sin(2 * np.pi * s_grid / float(rng.uniform(700, 1300)) + rng.uniform(0, 6))
    v_cap = v_cap * wobble
    a_lat = 1.5 if sc.route == "highway" else 2.0
    stops = np.array([s for s, _ in route["stops"]], float)
    dwell = np.array([d for _, d in route["stops"]], float)
    a_brake = 1.5
    v_allow = _allowed_speed(s_grid, kappa, v_cap, stops, a_lat, a_brake)
    n_steps = round(duration_s * TRUTH_RATE_HZ) + 1
    v, psidot, s = _drive_kernel(s_grid, v_allow, kappa, stops, dwell, n_steps, DT_S,
                                 1.5, a_brake, 2.0)
    return {"v": v, "psidot": psidot, "s": s, "kind": kind[np.minimum(
        (s / ds).astype(np.int64), len(kind) - 1)]}, route


def _with_parking(stops: list[tuple[float, float]], dwell_s: float,
                  after_m: float = 1500.0) -> list[tuple[float, float]]:
    """The stops with the first one beyond ``after_m`` metres held ``dwell_s`` seconds (a
    parked stretch; added at ``after_m`` when the route has no stop there)."""
    out = sorted(stops)
    later = [i for i, (s, _) in enumerate(out) if s >= after_m]
    if later:
        out[later[0]] = (out[later[0]][0], float(dwell_s))
    else:
        out.append((after_m, float(dwell_s)))
    return sorted(out)


def _cumtrapz(y: np.ndarray, dt: float, y0: float = 0.0) -> np.ndarray:
    out = np.empty_like(y)
    out[0] = y0
    out[1:] = y0 + np.cumsum(0.5 * (y[1:] + y[:-1]) * dt)
    return out


# --------------------------------------------------------------------------- sensors

def _gauss_markov(rng: np.random.Generator, n: int, dt: float, tau: np.ndarray | float,
                  sd: np.ndarray | float, shape: tuple[int, ...] = ()) -> np.ndarray:
    """First-order Gauss-Markov samples, stationary from the start (x0 ~ N(0, sd^2)).

    ``x[k] = phi x[k-1] + sd sqrt(1 - phi^2) w``, ``phi = exp(-dt/tau)``; ``tau`` and
    ``sd`` may vary per step.
    """
    tau_a = np.broadcast_to(np.asarray(tau, float), (n,))
    sd_a = np.broadcast_to(np.asarray(sd, float), (n,))
    phi = np.exp(-dt / tau_a)
    w = rng.standard_normal((n, *shape))
    x = np.empty((n, *shape))
    x[0] = sd_a[0] * w[0]
    drive_sd = sd_a * np.sqrt(1.0 - phi * phi)
    for k in range(1, n):
        x[k] = phi[k] * x[k - 1] + drive_sd[k] * w[k]
    return x


def simulate_drive(scenario: str = "urban_canyon", seed: int = 0, duration_s: float | None = None,
                   *, gnss_rate_hz: float | None = None, gyro_rate_hz: float = 100.0,
                   odo_rate_hz: float = 100.0, gnss_stamp_offset_s: float = 0.0) -> SimDrive:
    """Simulate one drive of ``scenario`` with random generator ``seed``.

    ``duration_s`` defaults to the scenario's length (600 s; stop_and_go 900 s;
    one_hour 3600 s).  ``gnss_rate_hz`` 0.5-20 Hz (default: the scenario's, 5 Hz; rtk and
    no_odometer 4 Hz); gyro, accelerometer and odometer rates must divide 100 Hz.
    ``gnss_stamp_offset_s``: each fix holds the true position at
    ``stamp + offset`` (> 0: fixes ahead of their stamps, as in comma2k19).
    Same arguments, same drive (bit for bit).
    """
    if scenario not in _SCENARIOS:
        raise UsageError(f"unknown scenario {scenario!r}; choose one of {', '.join(SCENARIOS)}")
    if gnss_rate_hz is None:
        gnss_rate_hz = _SCENARIOS[scenario].gnss_rate_hz or 5.0
    if not 0.5 <= gnss_rate_hz <= 20.0:
        raise UsageError(f"gnss_rate_hz = {gnss_rate_hz}: expected 0.5 to 20 Hz")
    for name, rate in (("gyro_rate_hz", gyro_rate_hz), ("odo_rate_hz", odo_rate_hz)):
        step = TRUTH_RATE_HZ / rate
        if rate <= 0 or abs(step - round(step)) > 1e-9:
            raise UsageError(f"{name} = {rate}: expected a divisor of {TRUTH_RATE_HZ} Hz")
    sc = _SCENARIOS[scenario]
    dur = float(sc.duration_s if duration_s is None else duration_s)
    if not dur >= 10.0:
        raise UsageError(f"duration_s = {duration_s}: expected at least 10 s")
    rng = np.random.default_rng(seed)
    rng_route, rng_gnss, rng_gyro, rng_odo = (np.random.default_rng(s)
                                              for s in rng.spawn(4))
    # the new scenarios' extra error models draw from generators of their own (spawned
    # after the four above): the older scenarios' drives stay bit for bit what they were
    rng_model, rng_accel = (np.random.default_rng(s) for s in rng.spawn(2))

    veh, route = _vehicle(sc, rng_route, dur)
    n = len(veh["v"])
    t_ns = START_NS + np.arange(n, dtype=np.int64) * (NS_PER_S // TRUTH_RATE_HZ)
    v = veh["v"]
    psidot = veh["psidot"]
    psi0 = float(rng_route.uniform(0.0, 2 * np.pi))
    psi = _cumtrapz(psidot, DT_S, psi0)
    v_e = v * np.sin(psi)
    v_n = v * np.cos(psi)
    e = _cumtrapz(v_e, DT_S)
    nn = _cumtrapz(v_n, DT_S)
    lat0, lon0, alt0 = sc.origin
    frame = LocalFrame.centred_on(lat0, lon0)
    lat, lon = frame.inverse(e, nn)
    if sc.hills:
        alt, pitch, hills = _hills(rng_model, veh["s"], alt0)
    else:
        alt = alt0 + 3.0 * np.sin(veh["s"] / 1500.0)
    truth = pd.DataFrame({
        "t_ns": t_ns, "lat": lat, "lon": lon, "e": e, "n": nn, "v_e": v_e, "v_n": v_n,
        "speed": v, "heading_deg": np.mod(np.degrees(psi), 360.0), "yaw_rate": -psidot,
        "alt": alt,
    })
    if sc.accel:
        truth["pitch_deg"] = np.degrees(pitch) if sc.hills else 0.0

    # environment per truth step
    if sc.env is not None:
        env_idx = np.full(n, ENV_NAMES.index(sc.env), np.int8)
    else:
        env_idx = np.array([ENV_NAMES.index(_KIND_ENV[int(k)]) for k in range(3)],
                           np.int8)[veh["kind"]]
    outages = _outages(sc, route, veh["s"], dur, rng_gnss)
    extra_noise: dict = {}
    if sc.gnss_model not in ("gm", "nlos"):
        outages = []  # the RTK drives: no bridges (their outages are the withheld windows)
    if sc.brake_outages:
        brake = _brake_outages(rng_model, v, dur)
        outages = sorted(outages + [(t0, d) for t0, d, _ in brake])
        extra_noise["brake_outages"] = [{"start_s": t0, "duration_s": d, "kind": kind}
                                        for t0, d, kind in brake]

    gnss, gerr, gnss_noise = _gnss(rng_gnss, truth, frame, env_idx, outages, gnss_rate_hz,
                                   gnss_stamp_offset_s, sc.short_dropouts)
    if sc.gnss_model == "nlos":
        gnss, gerr, model_noise = _nlos(rng_model, gnss, gerr, truth, frame, veh["s"],
                                        gnss_stamp_offset_s)
    elif sc.gnss_model in ("rtk", "rtk_fixed"):
        gnss, gerr, model_noise = _rtk(rng_model, gnss, gerr, truth, frame, gnss_stamp_offset_s,
                                       faults=sc.gnss_model == "rtk")
    else:
        model_noise = {}
    gnss_noise.update(model_noise)
    gyro, gyro_noise = _gyro(rng_gyro, truth, gyro_rate_hz)
    odo, odo_noise = _odo(rng_odo, truth, odo_rate_hz) if sc.odometer else (None, {"odometer": False})
    accel = None
    if sc.accel:
        accel, accel_noise, f_true = _accel(rng_accel, truth, np.radians(truth["pitch_deg"].to_numpy()),
                                            gyro_rate_hz)
        truth["accel_fwd"] = f_true
        extra_noise.update(accel_noise)
        if sc.hills:
            extra_noise["hills"] = hills

    noise = {
        "scenario": scenario, "seed": int(seed), "duration_s": dur,
        "origin_lat_deg": lat0, "origin_lon_deg": lon0, "origin_alt_m": alt0,
        "start_utc": _dt.datetime.fromtimestamp(START_NS / NS_PER_S, _dt.UTC).isoformat(),
        "truth_rate_hz": TRUTH_RATE_HZ,
        **gnss_noise, **gyro_noise, **odo_noise, **extra_noise,
    }
    streams = tuple(n for n, x in (("gnss", gnss), ("gyro", gyro), ("odo", odo), ("accel", accel))
                    if x is not None)
    drive = Drive(gnss=gnss, gyro=gyro, odo=odo, accel=accel,
                  sources=[Source(f"<simulated {scenario} seed {seed}>", "", streams)],
                  meta={"simulated": scenario, "seed": int(seed)})
    return SimDrive(drive=drive, truth=truth, frame=frame, noise=noise, scenario=scenario,
                    seed=int(seed), gnss_errors=gerr)


def _outages(sc: _Scenario, route: dict, s_path: np.ndarray, dur: float,
             rng: np.random.Generator) -> list[tuple[float, float]]:
    """GNSS outages as (start s since the drive start, duration s)."""
    out: list[tuple[float, float]] = []
    for s_start, d in route["tunnels"]:
        i = int(np.searchsorted(s_path, s_start))
        if i < len(s_path) - 1:
            out.append((i * DT_S, d))
    if sc.route == "mixed":  # tunnels on the open-road blocks: 30 s and 60 s, alternating
        for k, t0 in enumerate(np.arange(500.0, dur - 200.0, 900.0)):
            out.append((float(t0 + rng.uniform(0, 200)), (30.0, 60.0)[k % 2]))
    if sc.route == "city":  # under bridges / dense high-rise: a few short no-fix stretches
        for t0 in rng.uniform(30.0, max(dur - 30.0, 31.0), size=max(1, int(dur / 200))):
            out.append((float(t0), float(rng.uniform(4.0, 10.0))))
    return sorted((t0, d) for t0, d in out if t0 < dur)


def _gnss(rng: np.random.Generator, truth: pd.DataFrame, frame: LocalFrame, env_idx: np.ndarray,
          outages: list[tuple[float, float]], rate_hz: float, stamp_offset_s: float,
          dropouts: bool) -> tuple[GnssFixes, pd.DataFrame, dict]:
    t_truth = truth["t_ns"].to_numpy()
    dur = (t_truth[-1] - t_truth[0]) / NS_PER_S
    step_ns = round(NS_PER_S / rate_hz)
    t_fix = np.arange(t_truth[0], t_truth[-1] + 1, step_ns, dtype=np.int64)
    m = len(t_fix)
    dt = 1.0 / rate_hz
    rel = (t_fix - t_truth[0]) / NS_PER_S
    k_truth = np.minimum(np.searchsorted(t_truth, t_fix), len(t_truth) - 1)
    env = env_idx[k_truth]
    par = np.array([_ENV[name] for name in ENV_NAMES])[env]  # (m, 8)
    pdop_mean, pdop_lsd, mp_sd, mp_tau_still, gst_share, p_out, p_drop, mp_dist = par.T
    # multipath decorrelates with the distance driven (the reflection geometry changes)
    # and slowly with time when standing: 1/tau = 1/tau_still + speed/distance
    speed_fix = np.interp(rel, (t_truth - t_truth[0]) / NS_PER_S, truth["speed"].to_numpy())
    mp_tau = 1.0 / (1.0 / mp_tau_still + speed_fix / mp_dist)

    # PDOP: log-normal Gauss-Markov around the environment's mean (tau 30 s), floor 1
    pdop = np.maximum(pdop_mean * np.exp(_gauss_markov(rng, m, dt, 30.0, pdop_lsd)), 1.0)
    hdop = pdop * np.clip(0.62 + 0.04 * _gauss_markov(rng, m, dt, 120.0, 1.0), 0.5, 0.75)
    vdop = np.sqrt(np.maximum(pdop**2 - hdop**2, 0.01))
    n_sats = np.clip(np.round(4 + 18 / pdop), 4, 24).astype(np.int16)

    sd_per_pdop = 0.6
    white_sd = sd_per_pdop * pdop  # per axis
    white = rng.standard_normal((m, 2)) * white_sd[:, None]
    mp = _gauss_markov(rng, m, dt, mp_tau, mp_sd, (2,))  # seed-free model: first-order GM
    jump = np.zeros((m, 2))
    outlier = np.zeros(m, bool)
    k = 0
    u = rng.random(m)
    while k < m:
        if u[k] < p_out[k]:
            length = int(rng.integers(1, int(2 * rate_hz) + 1))
            mag = float(rng.uniform(10.0, 40.0))
            ang = float(rng.uniform(0, 2 * np.pi))
            jump[k:k + length] = mag * np.array([math.sin(ang), math.cos(ang)])
            outlier[k:k + length] = True
            k += length
        k += 1

    no_fix = np.zeros(m, bool)
    for t0, d in outages:
        no_fix |= (rel >= t0) & (rel < t0 + d)
    if dropouts:
        k = 0
        u = rng.random(m)
        while k < m:
            if u[k] < p_drop[k]:
                length = int(rng.uniform(1.0, 4.0) * rate_hz)
                no_fix[k:k + length] = True
                k += length
            k += 1

    # the fix: truth at stamp + offset, plus the errors
    t_true = (t_fix - t_truth[0]) / NS_PER_S + stamp_offset_s
    tt = (t_truth - t_truth[0]) / NS_PER_S
    e_true = np.interp(t_true, tt, truth["e"].to_numpy())
    n_true = np.interp(t_true, tt, truth["n"].to_numpy())
    ve = np.interp(t_true, tt, truth["v_e"].to_numpy())
    vn = np.interp(t_true, tt, truth["v_n"].to_numpy())
    err = white + mp + jump
    lat, lon = frame.inverse(e_true + err[:, 0], n_true + err[:, 1])
    alt = np.interp(t_true, tt, truth["alt"].to_numpy()) + rng.standard_normal(m) * 1.6 * white_sd
    vel_sd = 0.03 * pdop  # Doppler velocity, per axis
    ve_m = ve + rng.standard_normal(m) * vel_sd
    vn_m = vn + rng.standard_normal(m) * vel_sd
    speed = np.hypot(ve_m, vn_m)
    course = np.where(speed > 0.2, np.mod(np.degrees(np.arctan2(ve_m, vn_m)), 360.0), np.nan)
    reported_sd = np.sqrt(white_sd**2 + (gst_share * mp_sd) ** 2)

    q = np.where(no_fix, FIX_NONE, FIX_GPS).astype(np.int8)
    nan_if = np.where(no_fix, np.nan, 1.0)
    fixes = GnssFixes(
        t_ns=t_fix, lat_deg=lat * nan_if, lon_deg=lon * nan_if, alt_m=alt * nan_if,
        fix_quality=q, n_sats=np.where(no_fix, 0, n_sats).astype(np.int16),
        hdop=hdop * nan_if, pdop=pdop * nan_if, vdop=vdop * nan_if,
        sigma_e_m=reported_sd * nan_if, sigma_n_m=reported_sd * nan_if,
        speed_mps=speed * nan_if, course_deg=course * nan_if,
    )
    gerr = pd.DataFrame({
        "t_ns": t_fix, "pdop": pdop, "hdop": hdop, "env": np.array(ENV_NAMES)[env],
        "white_e": white[:, 0], "white_n": white[:, 1], "multipath_e": mp[:, 0],
        "multipath_n": mp[:, 1], "jump_e": jump[:, 0], "jump_n": jump[:, 1],
        "outlier": outlier, "no_fix": no_fix,
        "white_sd_m": white_sd, "true_sd_m": np.sqrt(white_sd**2 + mp_sd**2),
        "reported_sd_m": reported_sd,
    })
    valid = ~no_fix
    used_env = sorted({ENV_NAMES[i] for i in np.unique(env[valid])}) if valid.any() else []
    mp_rms = float(np.sqrt(np.mean(mp_sd[valid] ** 2))) if valid.any() else 0.0
    mp_tau_mean = float(np.median(mp_tau[valid])) if valid.any() else 60.0
    noise = {
        "gnss_rate_hz": float(rate_hz),
        "gnss_stamp_offset_s": float(stamp_offset_s),
        "gnss_sd_per_pdop_m": sd_per_pdop,
        "gnss_sd_note": "white noise 1-sigma per axis (east, north) = gnss_sd_per_pdop_m x PDOP",
        "gnss_environments": {name: dict(zip(
            ("pdop_mean", "pdop_log_sd", "multipath_sd_m", "multipath_tau_s", "gst_multipath_share",
             "outlier_prob", "dropout_prob", "multipath_decorrelation_m"), _ENV[name], strict=True))
            for name in used_env},
        "multipath_tau_note": "per epoch 1/tau = 1/multipath_tau_s + speed/multipath_decorrelation_m; "
                              "multipath_tau_s at top level is the drive's median",
        "multipath_sd_m": mp_rms, "multipath_tau_s": mp_tau_mean,
        "gnss_true_sd_rms_m": float(np.sqrt(np.mean((white_sd**2 + mp_sd**2)[valid])))
        if valid.any() else 0.0,
        "outlier_jump_m": [10.0, 40.0], "outlier_epochs": int(outlier[valid].sum()),
        "outages": [{"start_s": float(t0), "duration_s": float(min(d, dur - t0))}
                    for t0, d in outages],
        "no_fix_epochs": int(no_fix.sum()),
    }
    return fixes, gerr, noise


#: the gyro bias's Gauss-Markov correlation time (s); inf holds it at its first draw (an
#: automotive yaw-rate sensor's; ``benchmarks/short_city.py --steady-gyro``)
GYRO_BIAS_TAU_S = 3600.0
#: a gyro scale error added to the drawn one (``(1 + scale + this) x`` the true rate; a phone
#: gyro's 3 %: ``benchmarks/short_city.py --gyro-scale-error``)
GYRO_EXTRA_SCALE = 0.0
#: the gyro sampled this many seconds after the odometer (rounded to the 10-ms truth grid,
#: less than one gyro period): real logs stamp a CAN yaw rate and wheel speed apart
#: (``benchmarks/short_city.py --gyro-phase``); 0 stamps both at the same instants
GYRO_PHASE_S = 0.0


# --------------------------------------------------------------------------- error models of
# the newer scenarios (urban_nlos, rtk, no_odometer), applied to the fixes of :func:`_gnss`

#: NLOS steps: plateau size (m, log-uniform), duration (s, log-uniform), the chance that
#: the next step follows directly (the error moves from one reflection to the next without
#: a clean fix between), else the clean gap before it (s, uniform), on/off ramp (s, uniform,
#: at most a third of the step: the receiver's own filter smooths the jump), drift (random
#: walk, m per sqrt(s) per axis), share of steps across the street (toward a facade) and
#: their spread about the perpendicular (deg)
NLOS_STEP_M = (10.0, 80.0)
NLOS_DURATION_S = (5.0, 60.0)
NLOS_CHAIN_P = 0.5
NLOS_GAP_S = (1.0, 6.0)
NLOS_RAMP_S = (1.0, 4.0)
NLOS_DRIFT_M_PER_SQRT_S = 0.25
NLOS_ACROSS_SHARE = 0.7
NLOS_ACROSS_SPREAD_DEG = 20.0
#: the shape of the canyon's position errors: "steps" (the plateaus above) or "wander"
#: (``benchmarks/short_city.py --nlos-wander``): a Gauss-Markov error per axis of
#: ``NLOS_WANDER_SD_M`` that decorrelates over ``NLOS_WANDER_DIST_M`` driven (other
#: reflectors) and ``NLOS_WANDER_TAU_S`` parked (the satellites move), blended in and out over
#: ``NLOS_WANDER_EDGE_S`` at the canyon's ends; the receiver velocity keeps the steps' errors
NLOS_SHAPE = "steps"
NLOS_WANDER_SD_M = 20.0
NLOS_WANDER_DIST_M = 100.0
NLOS_WANDER_TAU_S = 600.0
NLOS_WANDER_EDGE_S = 5.0
#: the receiver's Doppler velocity in a step: reflected signals shift it too, a bias per step
#: and axis (m/s, 1 sigma) plus white noise (m/s per axis)
NLOS_VEL_BIAS_SD_MPS = 1.0
NLOS_VEL_WHITE_SD_MPS = 0.3
#: ... or, with ``NLOS_VEL_MODEL = "speed"``, the error a reflection makes: a signal off a wall
#: reads the range rate of the receiver's mirror image, whose velocity has the wall-normal
#: component reversed, so the velocity error is a linear map of the true velocity (per step,
#: a 2x2 matrix of entries with this sigma) and vanishes at a standstill, the white noise
#: with it (full at NLOS_VEL_WHITE_FULL_MPS and faster); ``benchmarks/short_city.py
#: --nlos-doppler speed``
NLOS_VEL_MODEL = "bias"
NLOS_VEL_SPEED_SD = 0.1
NLOS_VEL_WHITE_FULL_MPS = 5.0
#: canyon and open-sky sections along the route (m, uniform); the drive starts in the open
CANYON_M = (500.0, 1500.0)
OPEN_M = (150.0, 300.0)
#: what the receiver reports in this scenario, whatever the error: HDOP and GST sigma ranges
NLOS_HDOP = (0.6, 1.3)
NLOS_GST_M = (0.5, 3.0)

#: RTK: reported (and true) 1-sigma per axis, fixed (m), float start and floor (m)
RTK_FIXED_SD_M = (0.01, 0.025)
RTK_FLOAT_SD_M = (0.1, 0.5)
RTK_FLOAT_S = (10.0, 40.0)          # float stretch length, s
RTK_FALSE_JUMP_M = (0.2, 1.0)       # a false fix's position jump
RTK_FALSE_S = (5.0, 30.0)           # how long it stays off, s
RTK_FIXED_TAU_S = 5.0               # correlation time of the fixed solution's error
RTK_FLOAT_TAU_S = 10.0
RTK_FLOAT_CONVERGE_S = 15.0         # float sigma decays from its start toward 0.1 m
FIX_RTK, FIX_FLOAT = 4, 5

#: 15-s GNSS outages around stops (no_odometer)
BRAKE_OUTAGE_S = 15.0
BRAKE_SPACING_S = 20.0              # fixes between two outages at least this long

#: slope profile (no_odometer): sum of two sines, amplitude m and wavelength m (the second
#: at 0.35 x the amplitude and 1/2.3 of the wavelength)
HILL_AMP_M = (6.0, 12.0)
HILL_WAVE_M = (900.0, 1500.0)
GRAVITY_MPS2 = 9.80665

#: forward accelerometer (consumer MEMS, road vibration included)
ACCEL_NOISE_SD_MPS2 = 0.05          # white, per 100 Hz sample
ACCEL_BIAS_SD_MPS2 = 0.1            # turn-on bias and its stationary wander (~10 mg)
ACCEL_BIAS_TAU_S = 3600.0
ACCEL_SCALE_SD = 0.01


def _fix_truth(truth: pd.DataFrame, t_fix: np.ndarray, stamp_offset_s: float
               ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """True east, north (m) and altitude (m) at each fix stamp + offset."""
    tt = (truth["t_ns"].to_numpy() - truth["t_ns"].iloc[0]) / NS_PER_S
    tf = (t_fix - truth["t_ns"].iloc[0]) / NS_PER_S + stamp_offset_s
    return (np.interp(tf, tt, truth["e"].to_numpy()), np.interp(tf, tt, truth["n"].to_numpy()),
            np.interp(tf, tt, truth["alt"].to_numpy()))


def _replace_positions(fixes: GnssFixes, frame: LocalFrame, e: np.ndarray, n: np.ndarray,
                       **fields: np.ndarray) -> GnssFixes:
    """``fixes`` at the local positions (e, n) m, with other fields replaced; no-fix epochs
    stay NaN."""
    nan_if = np.where(fixes.valid, 1.0, np.nan)
    lat, lon = frame.inverse(e, n)
    out = {**fixes.__dict__, "lat_deg": lat * nan_if, "lon_deg": lon * nan_if}
    out.update({k: v * nan_if if v.dtype.kind == "f" else v for k, v in fields.items()})
    return GnssFixes(**out)


def _loguniform(rng: np.random.Generator, lo_hi: tuple[float, float]) -> float:
    return float(math.exp(rng.uniform(math.log(lo_hi[0]), math.log(lo_hi[1]))))


def _nlos(rng: np.random.Generator, fixes: GnssFixes, gerr: pd.DataFrame, truth: pd.DataFrame,
          frame: LocalFrame, s_path: np.ndarray, stamp_offset_s: float
          ) -> tuple[GnssFixes, pd.DataFrame, dict]:
    """Canyon sections with NLOS steps on top of the open-sky errors of ``fixes``.

    Along the route, open-sky sections of ``OPEN_M`` alternate with canyon sections of
    ``CANYON_M``.  In a canyon, steps follow each other, directly (``NLOS_CHAIN_P``: the
    bias moves from one step's to the next's) or after a clean gap of ``NLOS_GAP_S``:
    each a bias of ``NLOS_STEP_M`` metres (log-uniform) held for ``NLOS_DURATION_S``
    seconds (log-uniform, cut at the canyon's end, never shorter than 5 s), ramped on and
    off over ``NLOS_RAMP_S``, pointing across the street (perpendicular to the heading,
    either side, +-20 deg) in 70 % of steps and anywhere in the rest, plus a random-walk
    drift.  So the fixes of a step agree with each other to the white noise and the drift:
    a gate on one fix's innovation sees no jump after the first.  The reported velocity
    (RMC speed and course) gets a bias of ``NLOS_VEL_BIAS_SD_MPS`` per step and axis and
    white noise of ``NLOS_VEL_WHITE_SD_MPS`` during the step (``NLOS_VEL_MODEL = "speed"``:
    an error proportional to the true velocity instead, none at a standstill).  The receiver reports HDOP
    in ``NLOS_HDOP`` and GST sigmas in ``NLOS_GST_M`` whatever the error.
    """
    t_fix = fixes.t_ns
    m = len(t_fix)
    t0 = int(truth["t_ns"].iloc[0])
    rel = (t_fix - t0) / NS_PER_S
    tt = (truth["t_ns"].to_numpy() - t0) / NS_PER_S
    s_fix = np.interp(rel, tt, s_path)
    heading = np.interp(rel, tt, np.unwrap(np.radians(truth["heading_deg"].to_numpy())))
    # sections along the route (m)
    sections: list[tuple[float, float]] = []
    s = float(rng.uniform(*OPEN_M))
    while s < s_path[-1]:
        length = float(rng.uniform(*CANYON_M))
        sections.append((s, s + length))
        s += length + float(rng.uniform(*OPEN_M))
    canyon = np.zeros(m, bool)
    for a, b in sections:
        canyon |= (s_fix >= a) & (s_fix < b)
    bias = np.zeros((m, 2))
    drift = np.zeros((m, 2))
    vel_err = np.zeros((m, 2))
    v_true = np.column_stack([np.interp(rel, tt, truth["v_e"].to_numpy()),
                              np.interp(rel, tt, truth["v_n"].to_numpy())])
    step_id = np.full(m, -1, np.int32)
    gst_factor = np.ones(m)
    steps: list[dict] = []
    d = np.diff(np.concatenate(([0], canyon.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)  # ends exclusive
    for i0, i1 in zip(starts, ends, strict=True):
        t_end_canyon = rel[i1 - 1]
        t = rel[i0]
        chained = False               # this step starts where the previous one stands
        prev_vec = np.zeros(2)
        while True:
            t_on = t if chained else t + float(rng.uniform(*NLOS_GAP_S))
            left = t_end_canyon - t_on
            if left < NLOS_DURATION_S[0]:
                break
            dur = min(_loguniform(rng, NLOS_DURATION_S), left)
            mag = _loguniform(rng, NLOS_STEP_M)
            ramp_on, ramp_off = (min(float(rng.uniform(*NLOS_RAMP_S)), dur / 3.0)
                                 for _ in range(2))
            next_chained = bool(rng.random() < NLOS_CHAIN_P)
            k_on = int(np.searchsorted(rel, t_on))
            across = bool(rng.random() < NLOS_ACROSS_SHARE)
            if across:
                side = 1.0 if rng.random() < 0.5 else -1.0
                ang = float(heading[min(k_on, m - 1)] + side * math.pi / 2
                            + math.radians(rng.normal(0.0, NLOS_ACROSS_SPREAD_DEG)))
            else:
                ang = float(rng.uniform(0.0, 2 * math.pi))
            sel = (rel >= t_on) & (rel < t_on + dur)
            tk = rel[sel] - t_on
            vec = mag * np.array([math.sin(ang), math.cos(ang)])
            w_on = np.clip(tk / ramp_on, 0.0, 1.0)[:, None]
            w_off = (np.ones(len(tk)) if next_chained
                     else np.clip((dur - tk) / ramp_off, 0.0, 1.0))[:, None]
            start = prev_vec if chained else np.zeros(2)
            bias[sel] = (start * (1.0 - w_on) + vec * w_on) * w_off
            prof = np.clip(np.minimum(tk / ramp_on, (dur - tk) / ramp_off), 0.0, 1.0)
            dtk = np.diff(np.concatenate(([0.0], tk)))
            walk = np.cumsum(rng.standard_normal((len(tk), 2)) * NLOS_DRIFT_M_PER_SQRT_S
                             * np.sqrt(dtk)[:, None], axis=0)
            drift[sel] = walk * prof[:, None]
            if NLOS_VEL_MODEL == "speed":
                mirror = rng.normal(0.0, NLOS_VEL_SPEED_SD, (2, 2))
                v_sel = v_true[sel]
                white = NLOS_VEL_WHITE_SD_MPS * np.minimum(
                    np.hypot(v_sel[:, 0], v_sel[:, 1]) / NLOS_VEL_WHITE_FULL_MPS, 1.0)
                vel_err[sel] = ((v_sel @ mirror.T) * prof[:, None]
                                + rng.standard_normal((len(tk), 2)) * white[:, None])
            else:
                v_bias = rng.normal(0.0, NLOS_VEL_BIAS_SD_MPS, 2)
                vel_err[sel] = (v_bias * prof[:, None]
                                + rng.standard_normal((len(tk), 2)) * NLOS_VEL_WHITE_SD_MPS)
            sid = len(steps)
            step_id[sel] = sid
            gst_factor[sel] = float(rng.uniform(1.0, 2.0))
            steps.append({"start_s": float(t_on), "duration_s": float(dur), "magnitude_m": mag,
                          "direction_deg": float(np.degrees(ang) % 360.0), "across_street": across,
                          "from_previous": chained, "ramp_on_s": ramp_on, "ramp_off_s": ramp_off})
            t = t_on + dur
            chained, prev_vec = next_chained, vec
    valid = fixes.valid
    e_fix, n_fix = frame.forward(fixes.lat_deg, fixes.lon_deg)
    nlos_e = bias[:, 0] + drift[:, 0]
    nlos_n = bias[:, 1] + drift[:, 1]
    wander = None
    if NLOS_SHAPE == "wander":
        wander = _nlos_wander(np.random.default_rng(int(rng.integers(1 << 31))), rel, s_fix,
                              canyon)
        nlos_e, nlos_n = wander[:, 0], wander[:, 1]
    hdop = np.clip(fixes.hdop, *NLOS_HDOP)
    vdop = np.sqrt(np.maximum(fixes.pdop**2 - hdop**2, 0.01))
    sigma = np.clip(gerr["reported_sd_m"].to_numpy() * gst_factor, *NLOS_GST_M)
    crs = np.radians(fixes.course_deg)
    moving = np.isfinite(crs)  # the receiver gives no course below 0.2 m/s: ~0 there
    ve = np.where(moving, fixes.speed_mps * np.sin(np.where(moving, crs, 0.0)), 0.0) + vel_err[:, 0]
    vn = np.where(moving, fixes.speed_mps * np.cos(np.where(moving, crs, 0.0)), 0.0) + vel_err[:, 1]
    in_step = step_id >= 0
    speed = np.where(in_step, np.hypot(ve, vn), fixes.speed_mps)
    course = np.where(in_step, np.where(speed > 0.2, np.mod(np.degrees(np.arctan2(ve, vn)), 360.0),
                                        np.nan), fixes.course_deg)
    out = _replace_positions(fixes, frame, e_fix + nlos_e, n_fix + nlos_n, hdop=hdop, vdop=vdop,
                             sigma_e_m=sigma, sigma_n_m=sigma.copy(), speed_mps=speed,
                             course_deg=course)
    gerr = gerr.copy()
    gerr["env"] = np.where(canyon, "urban", gerr["env"].to_numpy())
    gerr["hdop"] = hdop
    gerr["reported_sd_m"] = sigma
    gerr["canyon"] = canyon
    gerr["nlos"] = ((step_id >= 0) if wander is None else np.hypot(nlos_e, nlos_n) > 0) & valid
    gerr["nlos_step"] = step_id
    gerr["nlos_e"], gerr["nlos_n"] = nlos_e, nlos_n
    gerr["nlos_bias_e"], gerr["nlos_bias_n"] = bias[:, 0], bias[:, 1]
    gerr["nlos_vel_e"], gerr["nlos_vel_n"] = vel_err[:, 0] * in_step, vel_err[:, 1] * in_step
    canyon_s = float(np.sum(canyon) / max(_fixes_rate(t_fix), 1e-9))
    noise = {
        "gnss_model": "nlos",
        "nlos_note": "canyon sections: NLOS steps (bias held, ramped on/off, plus a random-walk "
                     "drift) on top of the open-sky errors; HDOP and GST sigma do not show them",
        "nlos_step_m": list(NLOS_STEP_M), "nlos_duration_s": list(NLOS_DURATION_S),
        "nlos_chain_p": NLOS_CHAIN_P, "nlos_gap_s": list(NLOS_GAP_S),
        "nlos_ramp_s": list(NLOS_RAMP_S),
        "nlos_drift_m_per_sqrt_s": NLOS_DRIFT_M_PER_SQRT_S,
        "nlos_across_share": NLOS_ACROSS_SHARE, "nlos_hdop": list(NLOS_HDOP),
        "nlos_velocity_bias_sd_mps": NLOS_VEL_BIAS_SD_MPS,
        "nlos_velocity_white_sd_mps": NLOS_VEL_WHITE_SD_MPS,
        "nlos_velocity_model": NLOS_VEL_MODEL,
        "nlos_gst_m": list(NLOS_GST_M),
        "canyon_sections_m": [[a, b] for a, b in sections],
        "canyon_s": canyon_s,
        "nlos_steps": steps,
        "nlos_steps_per_canyon_min": 60.0 * len(steps) / canyon_s if canyon_s > 0 else 0.0,
        "nlos_fix_share": float(np.mean(gerr["nlos"][valid])) if valid.any() else 0.0,
    }
    if wander is not None:
        noise.update({"nlos_shape": "wander", "nlos_wander_sd_m": NLOS_WANDER_SD_M,
                      "nlos_wander_dist_m": NLOS_WANDER_DIST_M,
                      "nlos_wander_tau_s": NLOS_WANDER_TAU_S})
    return out, gerr, noise


def _nlos_wander(rng: np.random.Generator, t_s: np.ndarray, s_m: np.ndarray,
                 canyon: np.ndarray) -> np.ndarray:
    """(m, 2) east/north error (m) of ``NLOS_SHAPE = "wander"`` at fixes stamped ``t_s`` (s),
    ``s_m`` along the route (m): inside the ``canyon`` mask a Gauss-Markov process per axis
    (sigma ``NLOS_WANDER_SD_M``, 1/correlation = 1/``NLOS_WANDER_TAU_S`` s + speed /
    ``NLOS_WANDER_DIST_M`` m), blended in and out over ``NLOS_WANDER_EDGE_S``."""
    m = len(t_s)
    if not m:
        return np.zeros((0, 2))
    # per step, the decorrelation in units of one correlation time (as 1/tau at dt = 1)
    x = np.concatenate(([1.0], np.diff(t_s) / NLOS_WANDER_TAU_S
                        + np.abs(np.diff(s_m)) / NLOS_WANDER_DIST_M))
    with np.errstate(divide="ignore"):
        err = _gauss_markov(rng, m, 1.0, 1.0 / x, NLOS_WANDER_SD_M, (2,))
    width = max(1, round(NLOS_WANDER_EDGE_S * _fixes_rate(t_s * NS_PER_S)))
    blend = np.convolve(canyon.astype(float), np.ones(width) / width, mode="same")
    return err * blend[:, None]


def _fixes_rate(t_ns: np.ndarray) -> float:
    """Fix rate (Hz) of evenly stamped epochs."""
    return NS_PER_S / float(np.median(np.diff(t_ns))) if len(t_ns) > 1 else 1.0


def _rtk(rng: np.random.Generator, fixes: GnssFixes, gerr: pd.DataFrame, truth: pd.DataFrame,
         frame: LocalFrame, stamp_offset_s: float, *, faults: bool
         ) -> tuple[GnssFixes, pd.DataFrame, dict]:
    """An RTK receiver's fixes in place of ``fixes``' errors (same epochs, same outages).

    Fixed epochs (GGA quality 4): a reported sigma per axis wandering in
    ``RTK_FIXED_SD_M`` (log-normal Gauss-Markov, 60 s) and an error of that size (a
    Gauss-Markov part of 5 s and a white part, each half the variance).  With
    ``faults``: float stretches (quality 5) of ``RTK_FLOAT_S`` whose sigma starts in 0.3-0.5
    m and converges toward 0.1 m (``RTK_FLOAT_CONVERGE_S``), the error again of the reported
    size; and false fixes right after some of them: quality 4 reported at centimetres while
    the position is off by a constant ``RTK_FALSE_JUMP_M`` for ``RTK_FALSE_S`` seconds.
    """
    t_fix = fixes.t_ns
    m = len(t_fix)
    rate = _fixes_rate(t_fix)
    dt = 1.0 / rate
    rel = (t_fix - t_fix[0]) / NS_PER_S
    dur = float(rel[-1]) if m else 0.0
    valid = fixes.valid
    lo, hi = RTK_FIXED_SD_M
    sd_fixed = np.clip(math.sqrt(lo * hi) * np.exp(_gauss_markov(rng, m, dt, 60.0, 0.25)), lo, hi)
    gm_fixed = _gauss_markov(rng, m, dt, RTK_FIXED_TAU_S, 1.0, (2,))
    gm_float = _gauss_markov(rng, m, dt, RTK_FLOAT_TAU_S, 1.0, (2,))
    white_unit = rng.standard_normal((m, 2))
    alt_unit = rng.standard_normal(m)
    quality = np.full(m, FIX_RTK, np.int8)
    sd = sd_fixed.copy()
    jump = np.zeros((m, 2))
    false_fix = np.zeros(m, bool)
    floats: list[dict] = []
    falses: list[dict] = []
    if faults and dur > 60.0:
        n_false = max(2, round(dur / 200.0))
        n_float = n_false + max(1, round(dur / 300.0))
        # float stretches at distinct places, each with room for a false fix after it
        slot = (dur - 30.0) / n_float
        order = rng.permutation(n_float)
        for j in range(n_float):
            length = float(rng.uniform(*RTK_FLOAT_S))
            t_on = 20.0 + j * slot + float(rng.uniform(0.0, max(slot - length - 35.0, 0.0)))
            sel = (rel >= t_on) & (rel < t_on + length)
            sd0 = float(rng.uniform(0.3, RTK_FLOAT_SD_M[1]))
            sd_f = np.maximum(sd0 * np.exp(-(rel[sel] - t_on) / RTK_FLOAT_CONVERGE_S),
                              RTK_FLOAT_SD_M[0])
            quality[sel] = FIX_FLOAT
            sd[sel] = sd_f
            floats.append({"start_s": t_on, "duration_s": length, "sigma_start_m": sd0})
            if order[j] < n_false:  # this float stretch resolves to a wrong fix
                f_on = t_on + length
                f_len = float(rng.uniform(*RTK_FALSE_S))
                mag = float(rng.uniform(*RTK_FALSE_JUMP_M))
                ang = float(rng.uniform(0.0, 2 * math.pi))
                fsel = (rel >= f_on) & (rel < f_on + f_len)
                jump[fsel] = mag * np.array([math.sin(ang), math.cos(ang)])
                false_fix[fsel] = True
                falses.append({"start_s": f_on, "duration_s": f_len, "jump_m": mag,
                               "direction_deg": math.degrees(ang)})
    is_float = quality == FIX_FLOAT
    # per axis: half the variance correlated, half white (fixed); float: 0.64 / 0.36
    w_gm = np.where(is_float, 0.8, math.sqrt(0.5))
    w_wh = np.where(is_float, 0.6, math.sqrt(0.5))
    gm = np.where(is_float[:, None], gm_float, gm_fixed) * (w_gm * sd)[:, None]
    white = white_unit * (w_wh * sd)[:, None]
    err = gm + white + jump
    e_true, n_true, alt_true = _fix_truth(truth, t_fix, stamp_offset_s)
    q = np.where(valid, quality, fixes.fix_quality).astype(np.int8)
    out = _replace_positions(fixes, frame, e_true + err[:, 0], n_true + err[:, 1],
                             alt_m=alt_true + 1.6 * sd * alt_unit, fix_quality=q,
                             sigma_e_m=sd, sigma_n_m=sd.copy())
    gerr = gerr.copy()
    gerr["white_e"], gerr["white_n"] = white[:, 0], white[:, 1]
    gerr["multipath_e"], gerr["multipath_n"] = gm[:, 0], gm[:, 1]
    gerr["jump_e"], gerr["jump_n"] = jump[:, 0], jump[:, 1]
    gerr["outlier"] = false_fix & valid
    gerr["false_fix"] = false_fix & valid
    gerr["fix_quality"] = q
    # a false fix's true sigma per axis holds its jump (|jump| / sqrt 2): what an oracle knows
    jump_sd = np.hypot(jump[:, 0], jump[:, 1]) / math.sqrt(2.0)
    gerr["white_sd_m"] = np.hypot(w_wh * sd, jump_sd)
    gerr["true_sd_m"] = np.hypot(sd * np.sqrt(w_gm**2 + w_wh**2), jump_sd)
    gerr["reported_sd_m"] = sd
    ok_fixed = valid & ~is_float
    envs = {"rtk_fixed": {"multipath_sd_m": float(math.sqrt(0.5) * np.sqrt(np.mean(sd[ok_fixed] ** 2)))
                          if ok_fixed.any() else 0.0,
                          "multipath_tau_s": RTK_FIXED_TAU_S},
            "rtk_float": {"multipath_sd_m": float(0.8 * np.sqrt(np.mean(sd[valid & is_float] ** 2)))
                          if (valid & is_float).any() else 0.0,
                          "multipath_tau_s": RTK_FLOAT_TAU_S}}
    for env in envs.values():
        env.update(pdop_mean=1.5, pdop_log_sd=0.12, gst_multipath_share=1.0, outlier_prob=0.0,
                   dropout_prob=0.0, multipath_decorrelation_m=1.0e6)
    if not (valid & is_float).any():
        del envs["rtk_float"]
    n_valid = max(int(valid.sum()), 1)
    noise = {
        "gnss_model": "rtk" if faults else "rtk_fixed",
        "rtk_note": "quality 4 fixed (sigma 1-2.5 cm, error of that size), 5 float (0.1-0.5 m); "
                    "false fixes: quality 4 at cm while the position is off by jump_m",
        "gnss_environments": envs,
        "multipath_sd_m": float(np.sqrt(np.mean((w_gm * sd)[valid] ** 2))) if valid.any() else 0.0,
        "multipath_tau_s": RTK_FIXED_TAU_S,
        "gnss_true_sd_rms_m": float(np.sqrt(np.mean((sd**2)[valid]))) if valid.any() else 0.0,
        "gnss_sigma_min_m": float(lo) / 2.0,
        "rtk_fixed_sd_m": list(RTK_FIXED_SD_M), "rtk_float_sd_m": list(RTK_FLOAT_SD_M),
        "rtk_float_stretches": floats, "rtk_false_fixes": falses,
        "rtk_fixed_share": float(np.sum(valid & (quality == FIX_RTK) & ~false_fix)) / n_valid,
        "rtk_float_share": float(np.sum(valid & is_float)) / n_valid,
        "rtk_false_share": float(np.sum(valid & false_fix)) / n_valid,
        "outlier_epochs": int((false_fix & valid).sum()),
    }
    return out, gerr, noise


def _brake_outages(rng: np.random.Generator, v: np.ndarray, dur: float
                   ) -> list[tuple[float, float, str]]:
    """15-s GNSS outages around the stops of the truth speed ``v`` (100 Hz): "braking" ends
    1-3 s after the car comes to rest, "accelerating" starts 0-2 s before it drives off;
    alternating, at least ``BRAKE_SPACING_S`` of fixes between two and none in the first 30 s."""
    stopped = v < 1e-3
    d = np.diff(np.concatenate(([0], stopped.astype(np.int8), [0])))
    starts, ends = np.flatnonzero(d == 1), np.flatnonzero(d == -1)  # ends: first moving step
    out: list[tuple[float, float, str]] = []
    last_end = 30.0 - BRAKE_SPACING_S
    kind_next = 0
    for i0, i1 in zip(starts, ends, strict=True):
        if i0 == 0 or i1 >= len(v):
            continue  # the standstill at the start or the end of the drive
        t_rest, t_off = i0 * DT_S, i1 * DT_S
        cands = [("braking", t_rest + float(rng.uniform(1.0, 3.0)) - BRAKE_OUTAGE_S),
                 ("accelerating", t_off - float(rng.uniform(0.0, 2.0)))]
        if kind_next == 1:
            cands.reverse()
        for kind, t0 in cands:
            if t0 >= last_end + BRAKE_SPACING_S and t0 + BRAKE_OUTAGE_S < dur - 10.0:
                out.append((float(t0), BRAKE_OUTAGE_S, kind))
                last_end = t0 + BRAKE_OUTAGE_S
                kind_next = 1 - (("braking", "accelerating").index(kind))
                break
    return out


def _hills(rng: np.random.Generator, s_path: np.ndarray, alt0: float
           ) -> tuple[np.ndarray, np.ndarray, dict]:
    """A rolling slope profile along the path length ``s_path`` (m, horizontal): altitude
    (m) and pitch (rad, nose up positive) per truth step, and its description."""
    amp = [float(rng.uniform(*HILL_AMP_M)) for _ in range(2)]
    amp[1] *= 0.35  # a shorter, lower swell on the long hill: grades up to ~8 %
    wave = [float(rng.uniform(*HILL_WAVE_M)), float(rng.uniform(*HILL_WAVE_M)) / 2.3]
    phase = [float(rng.uniform(0.0, 2 * math.pi)) for _ in range(2)]
    k = [2 * math.pi / w for w in wave]
    alt = alt0 + sum(a * np.sin(kk * s_path + p) for a, kk, p in zip(amp, k, phase, strict=True))
    grade = sum(a * kk * np.cos(kk * s_path + p) for a, kk, p in zip(amp, k, phase, strict=True))
    pitch = np.arctan(grade)
    return alt, pitch, {"amplitude_m": amp, "wavelength_m": wave,
                        "max_grade_pct": float(100 * np.max(np.abs(grade)))}


def _accel(rng: np.random.Generator, truth: pd.DataFrame, pitch: np.ndarray, rate_hz: float
           ) -> tuple[ForwardAccel, dict, np.ndarray]:
    """Forward accelerometer at the gyro's stamps: ``(1 + scale) f + bias(t) + white``, with
    ``f = d(v_road)/dt + g sin(pitch)`` the true specific force along the car (m/s^2;
    ``v_road = speed / cos(pitch)``, the truth's speed being horizontal).  Returns the stream,
    its noise and ``f`` at every truth step."""
    step = round(TRUTH_RATE_HZ / rate_hz)
    v_road = truth["speed"].to_numpy() / np.cos(pitch)
    f = np.gradient(v_road, DT_S) + GRAVITY_MPS2 * np.sin(pitch)
    t = truth["t_ns"].to_numpy()[::step]
    m = len(t)
    scale = float(rng.normal(0.0, ACCEL_SCALE_SD))
    bias = _gauss_markov(rng, m, step * DT_S, ACCEL_BIAS_TAU_S, ACCEL_BIAS_SD_MPS2)
    meas = (1.0 + scale) * f[::step] + bias + rng.standard_normal(m) * ACCEL_NOISE_SD_MPS2
    noise = {"accel_rate_hz": float(rate_hz), "accel_noise_sd_mps2": ACCEL_NOISE_SD_MPS2,
             "accel_bias_sd_mps2": ACCEL_BIAS_SD_MPS2, "accel_bias_tau_s": ACCEL_BIAS_TAU_S,
             "accel_bias_initial_mps2": float(bias[0]), "accel_scale_error": scale,
             "accel_scale_sd": ACCEL_SCALE_SD,
             "accel_note": "specific force along the car: d(road speed)/dt + g sin(pitch)"}
    return ForwardAccel(t_ns=t, accel_mps2=meas), noise, f


def _gyro(rng: np.random.Generator, truth: pd.DataFrame, rate_hz: float) -> tuple[YawRates, dict]:
    step = round(TRUTH_RATE_HZ / rate_hz)
    phase = round(GYRO_PHASE_S * TRUTH_RATE_HZ) % step
    t = truth["t_ns"].to_numpy()[phase::step]
    omega = truth["yaw_rate"].to_numpy()[phase::step]
    m = len(t)
    dt = step * DT_S
    noise_sd = math.radians(0.1)       # white noise per sample, rad/s
    bias_sd = math.radians(0.3)        # stationary sigma of the Gauss-Markov bias
    bias_tau = GYRO_BIAS_TAU_S  # with bias_sd: a rate random walk of 1500 deg/h/sqrt(h) (module docstring)
    scale_sd = 0.005
    scale = float(rng.normal(0.0, scale_sd))
    bias = _gauss_markov(rng, m, dt, bias_tau, bias_sd)
    meas = (1.0 + scale + GYRO_EXTRA_SCALE) * omega + bias + rng.standard_normal(m) * noise_sd
    noise = {"gyro_rate_hz": float(rate_hz), "gyro_noise_sd_radps": noise_sd,
             "gyro_bias_sd_radps": bias_sd, "gyro_bias_tau_s": bias_tau,
             "gyro_bias_initial_radps": float(bias[0]), "gyro_scale_error": scale + GYRO_EXTRA_SCALE,
             "gyro_scale_sd": scale_sd}
    return YawRates(t_ns=t, yaw_rate_radps=meas), noise


def _odo(rng: np.random.Generator, truth: pd.DataFrame, rate_hz: float) -> tuple[Odometry, dict]:
    step = round(TRUTH_RATE_HZ / rate_hz)
    ticks_per_m = 40.0
    scale_sd = 0.02
    scale = float(rng.normal(0.0, scale_sd))
    dist = _cumtrapz(truth["speed"].to_numpy(), DT_S)
    ticks = np.floor(ticks_per_m * (1.0 + scale) * dist + rng.uniform())
    window = 10  # steps of 10 ms: speed over the last 0.1 s
    spd = np.zeros(len(ticks))
    spd[window:] = (ticks[window:] - ticks[:-window]) / (ticks_per_m * window * DT_S)
    spd[:window] = ticks[:window] / (ticks_per_m * window * DT_S)
    white_sd = 0.02
    meas = np.maximum(spd + rng.standard_normal(len(spd)) * white_sd * (spd > 0), 0.0)
    t = truth["t_ns"].to_numpy()[::step]
    q_sd = 1.0 / (ticks_per_m * window * DT_S) / math.sqrt(6.0)  # difference of two uniform roundings
    noise = {"odo_rate_hz": float(rate_hz), "odo_scale_error": scale, "odo_scale_sd": scale_sd,
             "odo_noise_sd_mps": white_sd, "odo_ticks_per_m": ticks_per_m,
             "odo_window_s": window * DT_S,
             "odo_lag_s": 0.5 * window * DT_S,  # a speed over the last window describes its middle
             "odo_effective_sd_mps": float(math.hypot(white_sd, q_sd))}
    return Odometry(t_ns=t, speed_mps=meas[::step]), noise


# --------------------------------------------------------------------------- oracle

def oracle_params(noise: dict, params: Params) -> Params:
    """``params`` with the true noise of a simulated drive written into the filter model.

    Gyro: white noise, Gauss-Markov drift (the simulator's drift *is* the model's);
    odometer: effective speed sigma and scale-factor prior; FKF: the GNSS error
    states' clear-sky model gets the multipath sigma, time constant and
    decorrelation distance of the drive's environment with the least multipath,
    its obstructed-sky model those of the one with the most; ekf/aekf's multipath
    states (``[aekf] gnss_err_*``) get the drive's RMS multipath sigma and the
    time constant and decorrelation distance of its environment with the largest
    multipath (the simulator's 1/tau = 1/tau_s + speed/distance is the model's);
    the PDOP regime factors become 1 (feed :func:`oracle_drive`'s fixes, whose
    sigmas are the true ones); the RTK scenarios lower ``[gnss] sigma_min_m`` below their
    centimetre sigmas.  Only keys that exist in the defaults are set.
    """
    import copy

    out = copy.deepcopy(params)
    envs = list((noise.get("gnss_environments") or {}).values())
    worst = max(envs, key=lambda e: e["multipath_sd_m"]) if envs else {}
    best = min(envs, key=lambda e: e["multipath_sd_m"]) if envs else {}
    want = {
        "gyro": {"noise_sd_radps": noise.get("gyro_noise_sd_radps"),
                 "bias_tau_s": noise.get("gyro_bias_tau_s"),
                 "bias_sd_radps": noise.get("gyro_bias_sd_radps"),
                 "bias_init_sd_radps": noise.get("gyro_bias_sd_radps")},
        "odo": {"noise_sd_mps": noise.get("odo_effective_sd_mps"),
                "scale_init_sd": noise.get("odo_scale_sd"),
                "scale_rw_sd": 1e-5},
        "gnss": {"k_good": 1.0, "k_medium": 1.0, "k_poor": 1.0,
                 "sigma_min_m": noise.get("gnss_sigma_min_m")},
        "fkf": {"gnss_err_sd_m": best.get("multipath_sd_m"),
                "gnss_err_tau_s": best.get("multipath_tau_s"),
                "gnss_err_dist_m": best.get("multipath_decorrelation_m"),
                "gnss_err_obstructed_sd_m": worst.get("multipath_sd_m"),
                "gnss_err_obstructed_tau_s": worst.get("multipath_tau_s"),
                "gnss_err_obstructed_dist_m": worst.get("multipath_decorrelation_m")},
        "aekf": {"gnss_err_sd_m": noise.get("multipath_sd_m"),
                 "gnss_err_tau_s": worst.get("multipath_tau_s"),
                 "gnss_err_dist_m": worst.get("multipath_decorrelation_m")},
        "time": {"gnss_offset_s": noise.get("gnss_stamp_offset_s", 0.0)},
    }
    for section, values in want.items():
        if section not in DEFAULTS:
            continue
        for key, value in values.items():
            if key in DEFAULTS[section] and value is not None:
                out.setdefault(section, {})[key] = float(value)
    return out


def oracle_drive(sim: SimDrive, *, multipath_in_sigma: bool = True) -> Drive:
    """The drive with every fix's sigma replaced by its true sigma.

    ``multipath_in_sigma``: white noise and the multipath's stationary sigma (for
    filters whose GNSS errors are white: ekf, aekf with ``gnss_err_states`` off);
    False: white noise only, for filters that carry the multipath as Gauss-Markov
    states (fkf, fafkf, and ekf/aekf by default; told its sigma and correlation
    time by :func:`oracle_params`).

    The oracle also knows which fixes lie: urban_nlos' NLOS fixes are taken out (quality
    0, no position), as a receiver that flagged them would; rtk's false fixes stay, with
    their jump in the true sigma (taking them out leaves 5-30 s gyro-only gaps without an
    odometer, which the fixes' owner would not choose; evidence:
    docs/decisions/0015-evidence-behind-the-filter-choices.md#simulate).
    """
    g = sim.drive.gnss
    if g is None:
        raise UsageError(f"simulated drive {sim.scenario!r} has no GNSS stream")
    col = "true_sd_m" if multipath_in_sigma else "white_sd_m"
    ge = sim.gnss_errors
    lying = np.zeros(len(g), bool)
    if "nlos" in ge:
        lying |= ge["nlos"].to_numpy(bool)
    keep = np.where(g.valid & ~lying, 1.0, np.nan)
    true_sd = ge[col].to_numpy() * keep
    fields = {**g.__dict__, "sigma_e_m": true_sd.copy(), "sigma_n_m": true_sd.copy()}
    if lying.any():
        fields.update(lat_deg=g.lat_deg * keep, lon_deg=g.lon_deg * keep, alt_m=g.alt_m * keep,
                      fix_quality=np.where(lying, FIX_NONE, g.fix_quality).astype(g.fix_quality.dtype))
    fixes = GnssFixes(**fields)
    return Drive(gnss=fixes, gyro=sim.drive.gyro, odo=sim.drive.odo, accel=sim.drive.accel,
                 sources=list(sim.drive.sources), meta=dict(sim.drive.meta))


# --------------------------------------------------------------------------- writers

def _nmea(body: str) -> str:
    cs = 0
    for ch in body.encode("ascii"):
        cs ^= ch
    return f"${body}*{cs:02X}\r\n"


def _lat_str(lat: float) -> tuple[str, str]:
    a = abs(lat)
    d = int(a)
    return f"{d:02d}{(a - d) * 60:09.6f}", "N" if lat >= 0 else "S"


def _lon_str(lon: float) -> tuple[str, str]:
    a = abs(lon)
    d = int(a)
    return f"{d:03d}{(a - d) * 60:09.6f}", "E" if lon >= 0 else "W"


def nmea_lines(fixes: GnssFixes) -> list[str]:
    """RMC, GGA, GSA and GST per epoch (talker GN), NMEA 0183 with checksums."""
    out: list[str] = []
    for k in range(len(fixes)):
        t = _dt.datetime.fromtimestamp(int(fixes.t_ns[k]) / NS_PER_S, _dt.UTC)
        hms = f"{t:%H%M%S}.{t.microsecond // 10000:02d}"
        dmy = f"{t:%d%m%y}"
        if fixes.fix_quality[k] == FIX_NONE or not np.isfinite(fixes.lat_deg[k]):
            out.append(_nmea(f"GNRMC,{hms},V,,,,,,,{dmy},,,N"))
            out.append(_nmea(f"GNGGA,{hms},,,,,0,00,99.99,,M,,M,,"))
            out.append(_nmea("GNGSA,A,1,,,,,,,,,,,,,99.99,99.99,99.99"))
            continue
        la, ns = _lat_str(float(fixes.lat_deg[k]))
        lo, ew = _lon_str(float(fixes.lon_deg[k]))
        kn = float(fixes.speed_mps[k]) / 0.514444
        crs = "" if not np.isfinite(fixes.course_deg[k]) else f"{fixes.course_deg[k]:.2f}"
        out.append(_nmea(f"GNRMC,{hms},A,{la},{ns},{lo},{ew},{kn:.3f},{crs},{dmy},,,A"))
        out.append(_nmea(f"GNGGA,{hms},{la},{ns},{lo},{ew},{int(fixes.fix_quality[k])},"
                         f"{int(fixes.n_sats[k]):02d},{fixes.hdop[k]:.2f},{fixes.alt_m[k]:.3f},M,0.0,M,,"))
        ids = [str(i) for i in (2, 5, 6, 9, 12, 13, 15, 17, 19, 24, 25, 28)[:min(12, int(fixes.n_sats[k]))]]
        ids += [""] * (12 - len(ids))
        out.append(_nmea(f"GNGSA,A,3,{','.join(ids)},{fixes.pdop[k]:.2f},{fixes.hdop[k]:.2f},"
                         f"{fixes.vdop[k]:.2f}"))
        sd_e, sd_n = float(fixes.sigma_e_m[k]), float(fixes.sigma_n_m[k])
        out.append(_nmea(f"GNGST,{hms},{math.hypot(sd_e, sd_n):.3f},{max(sd_e, sd_n):.3f},"
                         f"{min(sd_e, sd_n):.3f},0.0,{sd_n:.3f},{sd_e:.3f},{1.6 * sd_n:.3f}"))
    return out


_TIME = "int32 sec\nuint32 nanosec\n"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
_SEP = "\n" + "=" * 80 + "\n"
_NAVSATSTATUS = ("int8 STATUS_NO_FIX = -1\nint8 STATUS_FIX = 0\nint8 STATUS_SBAS_FIX = 1\n"
                 "int8 STATUS_GBAS_FIX = 2\nint8 status\nuint16 SERVICE_GPS = 1\n"
                 "uint16 SERVICE_GLONASS = 2\nuint16 SERVICE_COMPASS = 4\n"
                 "uint16 SERVICE_GALILEO = 8\nuint16 service\n")
MSGDEF_NAVSATFIX = (
    "uint8 COVARIANCE_TYPE_UNKNOWN = 0\nuint8 COVARIANCE_TYPE_APPROXIMATED = 1\n"
    "uint8 COVARIANCE_TYPE_DIAGONAL_KNOWN = 2\nuint8 COVARIANCE_TYPE_KNOWN = 3\n"
    "std_msgs/Header header\nNavSatStatus status\nfloat64 latitude\nfloat64 longitude\n"
    "float64 altitude\nfloat64[9] position_covariance\nuint8 position_covariance_type\n"
    + _SEP + "MSG: std_msgs/Header\n" + _HEADER
    + _SEP + "MSG: builtin_interfaces/Time\n" + _TIME
    + _SEP + "MSG: sensor_msgs/NavSatStatus\n" + _NAVSATSTATUS
)
_VEC3 = "float64 x\nfloat64 y\nfloat64 z\n"
MSGDEF_IMU = (
    "std_msgs/Header header\ngeometry_msgs/Quaternion orientation\n"
    "float64[9] orientation_covariance\ngeometry_msgs/Vector3 angular_velocity\n"
    "float64[9] angular_velocity_covariance\ngeometry_msgs/Vector3 linear_acceleration\n"
    "float64[9] linear_acceleration_covariance\n"
    + _SEP + "MSG: std_msgs/Header\n" + _HEADER
    + _SEP + "MSG: builtin_interfaces/Time\n" + _TIME
    + _SEP + "MSG: geometry_msgs/Quaternion\nfloat64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
    + _SEP + "MSG: geometry_msgs/Vector3\n" + _VEC3
)
MSGDEF_TWISTSTAMPED = (
    "std_msgs/Header header\nTwist twist\n"
    + _SEP + "MSG: std_msgs/Header\n" + _HEADER
    + _SEP + "MSG: builtin_interfaces/Time\n" + _TIME
    + _SEP + "MSG: geometry_msgs/Twist\nVector3 linear\nVector3 angular\n"
    + _SEP + "MSG: geometry_msgs/Vector3\n" + _VEC3
)


MSGDEF_TWISTWITHCOVSTAMPED = (
    "std_msgs/Header header\nTwistWithCovariance twist\n"
    + _SEP + "MSG: std_msgs/Header\n" + _HEADER
    + _SEP + "MSG: builtin_interfaces/Time\n" + _TIME
    + _SEP + "MSG: geometry_msgs/TwistWithCovariance\nTwist twist\nfloat64[36] covariance\n"
    + _SEP + "MSG: geometry_msgs/Twist\nVector3 linear\nVector3 angular\n"
    + _SEP + "MSG: geometry_msgs/Vector3\n" + _VEC3
)


def _stamp(t_ns: int, frame_id: str) -> dict:
    return {"stamp": {"sec": int(t_ns // NS_PER_S), "nanosec": int(t_ns % NS_PER_S)},
            "frame_id": frame_id}


def write_mcap(drive: Drive, path: str | Path) -> Path:
    """ROS 2 CDR MCAP (zstd chunks): /gnss/fix NavSatFix (status GBAS for a differential
    fix, as the u-blox driver sends it, else FIX), /gnss/fix_velocity
    TwistWithCovarianceStamped (the receiver's Doppler velocity in ENU, x east, y north, as
    the u-blox driver publishes it, with every fix that has a speed: zero where it is too
    slow for a course), /imu Imu
    (linear_acceleration.x: the forward accelerometer when sampled with the gyro, else 0
    with covariance[0] = -1, "not given"), /vehicle/twist TwistStamped (the wheel speed,
    body frame; none without an odometer)."""
    from mcap_ros2.writer import Writer

    path = Path(path)
    g, y, o = drive.gnss, drive.gyro, drive.odo
    events: list[tuple[int, int, int]] = []  # (t_ns, stream, index)
    for code, stream in enumerate((g, y, o)):
        if stream is not None:
            events.extend((int(t), code, i) for i, t in enumerate(stream.t_ns))
    events.sort()
    zero9 = [0.0] * 9
    gyro_var = math.radians(0.1) ** 2
    acc_x = _imu_accel(drive)  # in the Imu message when sampled with the gyro
    acc_cov = [ACCEL_NOISE_SD_MPS2 ** 2] + [0.0] * 8 if acc_x is not None else [-1.0] + zero9[1:]
    with path.open("wb") as fh:
        w = Writer(fh)
        s_fix = w.register_msgdef("sensor_msgs/msg/NavSatFix", MSGDEF_NAVSATFIX)
        s_imu = w.register_msgdef("sensor_msgs/msg/Imu", MSGDEF_IMU)
        s_tw = w.register_msgdef("geometry_msgs/msg/TwistStamped", MSGDEF_TWISTSTAMPED)
        s_vel = w.register_msgdef("geometry_msgs/msg/TwistWithCovarianceStamped",
                                  MSGDEF_TWISTWITHCOVSTAMPED)
        vel_var = 0.1 ** 2  # (m/s)^2, a u-blox's typical speed accuracy
        for t, code, i in events:
            if code == 0:
                ok = bool(g.fix_quality[i] > 0 and np.isfinite(g.lat_deg[i]))
                var_e = float(g.sigma_e_m[i]) ** 2 if ok else 0.0
                var_n = float(g.sigma_n_m[i]) ** 2 if ok else 0.0
                var_u = (1.6 * float(g.sigma_n_m[i])) ** 2 if ok else 0.0
                msg = {"header": _stamp(t, "gnss"),
                       # the u-blox driver's mapping: a differential fix (DGPS, RTK fixed
                       # or float) is GBAS, any other fix FIX
                       "status": {"status": (2 if g.fix_quality[i] in (2, 4, 5) else 0) if ok
                                  else -1, "service": 1},
                       "latitude": float(g.lat_deg[i]), "longitude": float(g.lon_deg[i]),
                       "altitude": float(g.alt_m[i]),
                       "position_covariance": [var_e, 0.0, 0.0, 0.0, var_n, 0.0, 0.0, 0.0, var_u],
                       "position_covariance_type": 2 if ok else 0}
                w.write_message("/gnss/fix", s_fix, msg, log_time=t, publish_time=t)
                spd, crs = float(g.speed_mps[i]), math.radians(float(g.course_deg[i]))
                if ok and math.isfinite(spd) and not math.isfinite(crs):
                    spd, crs = 0.0, 0.0  # too slow for a course: the driver still sends ~0
                if ok and math.isfinite(spd):
                    cov = [0.0] * 36
                    cov[0] = cov[7] = cov[14] = vel_var
                    vel = {"header": _stamp(t, "gnss"),
                           "twist": {"twist": {"linear": {"x": spd * math.sin(crs),
                                                          "y": spd * math.cos(crs), "z": 0.0},
                                               "angular": {"x": 0.0, "y": 0.0, "z": 0.0}},
                                     "covariance": cov}}
                    w.write_message("/gnss/fix_velocity", s_vel, vel, log_time=t, publish_time=t)
            elif code == 1:
                msg = {"header": _stamp(t, "imu"),
                       "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                       "orientation_covariance": [-1.0] + [0.0] * 8,
                       "angular_velocity": {"x": 0.0, "y": 0.0, "z": float(y.yaw_rate_radps[i])},
                       "angular_velocity_covariance": [0.0] * 8 + [gyro_var],
                       "linear_acceleration": {"x": 0.0 if acc_x is None else float(acc_x[i]),
                                               "y": 0.0, "z": 0.0},
                       "linear_acceleration_covariance": acc_cov}
                w.write_message("/imu", s_imu, msg, log_time=t, publish_time=t)
            else:
                msg = {"header": _stamp(t, "base_link"),
                       "twist": {"linear": {"x": float(o.speed_mps[i]), "y": 0.0, "z": 0.0},
                                 "angular": {"x": 0.0, "y": 0.0, "z": 0.0}}}
                w.write_message("/vehicle/twist", s_tw, msg, log_time=t, publish_time=t)
        w.finish()
    return path


def _imu_accel(drive: Drive) -> np.ndarray | None:
    """The forward acceleration (m/s^2) per gyro sample when the accelerometer shares the
    gyro's stamps (one IMU), else None."""
    a, y = drive.accel, drive.gyro
    if a is None or y is None or len(a) != len(y) or not np.array_equal(a.t_ns, y.t_ns):
        return None
    return a.accel_mps2


def _posix(t_ns: int) -> str:
    """UTC POSIX seconds with 6 decimals, exact from integer nanoseconds (no float rounding,
    so streams sampled at the same instant keep identical stamps)."""
    sec, ns = divmod(int(t_ns), NS_PER_S)
    return f"{sec}.{ns // 1000:06d}"


def _write_csv(path: Path, header: str, t_ns: np.ndarray, cols: list[np.ndarray],
               fmts: list[str]) -> None:
    with path.open("w", encoding="ascii", newline="\n") as fh:
        fh.write(header + "\n")
        for k in range(len(t_ns)):
            fh.write(",".join([_posix(t_ns[k]), *(f.format(c[k]) for f, c in zip(fmts, cols, strict=True))])
                     + "\n")


def write_drive(sim: SimDrive, out_dir: str | Path, *, truth_rate_hz: float = 20.0,
                mcap: bool = True) -> dict[str, Path]:
    """Write the drive's logs and truth into ``out_dir`` (created if missing).

    Files: gps.nmea, gyro.csv (t,yaw_rate[,acc_x]), odo.csv (t,speed; not for a drive
    without an odometer), drive.mcap, truth.csv (t,lat,lon,alt,heading at
    ``truth_rate_hz``), noise.json.  ``t`` is UTC POSIX seconds.  A forward accelerometer
    sampled with the gyro (one IMU) is gyro.csv's ``acc_x`` column (m/s^2, positive
    forward), as a logged IMU row carries both; sampled apart it goes to accel.csv (t,acc_x).
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    d = sim.drive
    names = ["gps.nmea", "gyro.csv", "odo.csv", "drive.mcap", "truth.csv", "noise.json"]
    if d.odo is None:
        names.remove("odo.csv")
    together = _imu_accel(d) is not None
    if d.accel is not None and not together:
        names.append("accel.csv")
    paths = {name: out / name for name in names}
    paths["gps.nmea"].write_text("".join(nmea_lines(d.gnss)), encoding="ascii", newline="")
    if together:
        _write_csv(paths["gyro.csv"], "t,yaw_rate,acc_x", d.gyro.t_ns,
                   [d.gyro.yaw_rate_radps, d.accel.accel_mps2], ["{:.7f}", "{:.6f}"])
    else:
        _write_csv(paths["gyro.csv"], "t,yaw_rate", d.gyro.t_ns, [d.gyro.yaw_rate_radps],
                   ["{:.7f}"])
    if d.accel is not None and not together:
        _write_csv(paths["accel.csv"], "t,acc_x", d.accel.t_ns, [d.accel.accel_mps2], ["{:.6f}"])
    if d.odo is not None:
        _write_csv(paths["odo.csv"], "t,speed", d.odo.t_ns, [d.odo.speed_mps], ["{:.6f}"])
    step = max(1, round(TRUTH_RATE_HZ / truth_rate_hz))
    tr = sim.truth.iloc[::step]
    _write_csv(paths["truth.csv"], "t,lat,lon,alt,heading", tr["t_ns"].to_numpy(),
               [tr["lat"].to_numpy(), tr["lon"].to_numpy(), tr["alt"].to_numpy(),
                tr["heading_deg"].to_numpy()], ["{:.9f}", "{:.9f}", "{:.3f}", "{:.3f}"])
    paths["noise.json"].write_text(json.dumps(sim.noise, indent=2, sort_keys=True) + "\n",
                                   encoding="utf-8")
    if mcap:
        write_mcap(d, paths["drive.mcap"])
    else:
        del paths["drive.mcap"]
    return paths


def write_sample_log(out_dir: str | Path, name: str = "urban_drive") -> dict[str, Path]:
    """The bundled sample: a 5-minute urban-canyon drive (seed 47) as ``<name>.mcap`` plus
    ``<name>.truth.csv`` and ``<name>.noise.json`` in ``out_dir``.

    Reproduces ``sample_logs/urban_drive.*`` bit for bit (MCAP bytes aside from the
    library's version string).
    """
    import shutil
    import tempfile

    sim = simulate_drive("urban_canyon", seed=47, duration_s=300.0)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory() as tmp:
        files = write_drive(sim, tmp)
        paths = {"mcap": out / f"{name}.mcap", "truth": out / f"{name}.truth.csv",
                 "noise": out / f"{name}.noise.json"}
        shutil.copyfile(files["drive.mcap"], paths["mcap"])
        shutil.copyfile(files["truth.csv"], paths["truth"])
        shutil.copyfile(files["noise.json"], paths["noise"])
    return paths


__all__ = [
    "SCENARIOS",
    "SimDrive",
    "oracle_drive",
    "oracle_params",
    "simulate_drive",
    "write_drive",
    "write_mcap",
    "write_sample_log",
]
