"""Fault injectors: damage a drive the way real vehicle logs get damaged.

Plain functions, reused by ``tests/test_faults.py``, ``tests/test_fuzz_e2e.py``,
``benchmarks/fault_table.py`` and ``benchmarks/fuzz.py``.  Three levels:

* **In memory** (:class:`~gpsdr_cli.io.drive.Drive`): GNSS outages and jumps,
  gyro saturation, odometer dropouts, clock steps backwards, duplicated
  records, NaN values, missing streams, a shift across midnight.  Each returns
  a new Drive and leaves its argument untouched.  Times are given in seconds
  from the drive's first record (:func:`start_ns`).
* **SimDrive** (:mod:`gpsdr_cli.simulate`): faults that change what really
  happened, so the truth changes too (a standstill inserted into a drive, a
  shift of the whole drive across midnight).
* **Files** (bytes): truncation, corrupt bytes, binary garbage in NMEA, empty
  fields in NMEA and CSV, sentences removed, lines swapped or repeated; and the
  fuzz mutators (:func:`mutate`) built from the same operations.

Plus the checks every fault's outcome is held to (:func:`track_problems`,
:func:`error_line_problems`): a complete track without NaN in the required
columns, or one clear error line.

Why hand-written: the faults are specific to this tool's inputs (NMEA
checksums must be recomputed so an "empty field" reaches the parser as a valid
sentence; a standstill must move every later record in every stream and the
truth); no fault-injection library knows these formats.

Conventions: :mod:`gpsdr_cli.conventions` (int64 ns UTC times, metres, yaw
rate CCW-positive).
"""

from __future__ import annotations

import copy
import dataclasses
import math
import re
from collections.abc import Callable, Sequence
from typing import Any

import numpy as np
import pandas as pd

from ..conventions import NS_PER_S
from ..geodesy import LocalFrame
from ..io.drive import Drive, GnssFixes, Odometry, YawRates

STREAMS: tuple[str, ...] = ("gnss", "gyro", "odo")

#: Track columns that must be finite at every epoch (``pdop`` may be null, ``time`` is checked apart).
REQUIRED_FINITE: tuple[str, ...] = ("lat", "lon", "e", "n", "v_e", "v_n", "speed",
                                     "heading_deg", "sigma_e", "sigma_n")
#: Every required track column of INTERFACE.md.
REQUIRED_COLUMNS: tuple[str, ...] = ("time", *REQUIRED_FINITE[:2], *REQUIRED_FINITE[2:],
                                     "gnss_used", "pdop")

DAY_NS = 86_400 * NS_PER_S
#: Metres per degree of latitude (WGS84 mean, good to 0.5 % for offsets of a few hundred metres).
M_PER_DEG_LAT = 111_132.0

Stream = GnssFixes | YawRates | Odometry


# --------------------------------------------------------------------------------------------
# In-memory helpers
# --------------------------------------------------------------------------------------------

def copy_drive(drive: Drive) -> Drive:
    """A deep copy (arrays included), so an injector never changes its argument."""
    return copy.deepcopy(drive)


def start_ns(drive: Drive) -> int:
    """The earliest time stamp of any stream, ns (the zero of every ``*_s`` argument here)."""
    firsts = [int(np.min(s.t_ns)) for s in _streams(drive).values() if len(s)]
    if not firsts:
        raise ValueError("the drive has no records")
    return min(firsts)


def end_ns(drive: Drive) -> int:
    """The latest time stamp of any stream, ns."""
    return max(int(np.max(s.t_ns)) for s in _streams(drive).values() if len(s))


def _streams(drive: Drive) -> dict[str, Stream]:
    return {name: s for name in STREAMS if (s := getattr(drive, name)) is not None}


def take(stream: Stream, idx: np.ndarray) -> Stream:
    """Rows ``idx`` (indices or a boolean mask) of every array of a stream."""
    return dataclasses.replace(stream, **{f.name: getattr(stream, f.name)[idx]
                                          for f in dataclasses.fields(stream)})


def concat(a: Stream, b: Stream) -> Stream:
    """Rows of ``a`` then rows of ``b`` (same stream type), sorted by time (stable)."""
    joined = {f.name: np.concatenate([getattr(a, f.name), getattr(b, f.name)])
              for f in dataclasses.fields(a)}
    order = np.argsort(joined["t_ns"], kind="stable")
    return dataclasses.replace(a, **{k: v[order] for k, v in joined.items()})


def window(t_ns: np.ndarray, t0_ns: int, start_s: float, duration_s: float) -> np.ndarray:
    """Mask of ``start_s <= t - t0 < start_s + duration_s`` (seconds from ``t0_ns``)."""
    lo = t0_ns + round(start_s * NS_PER_S)
    hi = lo + round(duration_s * NS_PER_S)
    return (t_ns >= lo) & (t_ns < hi)


def _value_field(name: str) -> str:
    return {"gyro": "yaw_rate_radps", "odo": "speed_mps", "accel": "accel_mps2",
            "gnss": "lat_deg"}[name]


# --------------------------------------------------------------------------------------------
# In-memory faults on a Drive
# --------------------------------------------------------------------------------------------

def gnss_outage(drive: Drive, start_s: float, duration_s: float, *, mode: str = "nofix") -> Drive:
    """No GNSS fix for ``duration_s`` seconds from ``start_s``.

    ``mode="nofix"``: the receiver keeps reporting, with fix quality 0 and no
    position (GGA with an empty fix, as in a tunnel); ``"drop"``: no records at all.
    """
    out = copy_drive(drive)
    g = out.gnss
    if g is None:
        return out
    m = window(g.t_ns, start_ns(drive), start_s, duration_s)
    if mode == "drop":
        out.gnss = take(g, ~m)
    elif mode == "nofix":
        g.fix_quality[m] = 0
        g.n_sats[m] = 0
        for f in ("lat_deg", "lon_deg", "alt_m", "hdop", "pdop", "vdop", "sigma_e_m",
                  "sigma_n_m", "speed_mps", "course_deg"):
            getattr(g, f)[m] = np.nan
    else:
        raise ValueError(f"mode {mode!r}: expected 'nofix' or 'drop'")
    return out


def offset_latlon(lat_deg: np.ndarray, lon_deg: np.ndarray, distance_m: float,
                  bearing_deg: float) -> tuple[np.ndarray, np.ndarray]:
    """Move points ``distance_m`` along ``bearing_deg`` (clockwise from north), flat-earth."""
    b = math.radians(bearing_deg)
    dlat = distance_m * math.cos(b) / M_PER_DEG_LAT
    dlon = distance_m * math.sin(b) / (M_PER_DEG_LAT * np.cos(np.deg2rad(lat_deg)))
    return lat_deg + dlat, lon_deg + dlon


def gnss_jump(drive: Drive, at_s: float, *, distance_m: float = 100.0, bearing_deg: float = 90.0,
              duration_s: float = 1.0) -> Drive:
    """GNSS fixes in ``[at_s, at_s + duration_s)`` displaced by ``distance_m`` (a multipath jump)."""
    out = copy_drive(drive)
    g = out.gnss
    if g is None:
        return out
    m = window(g.t_ns, start_ns(drive), at_s, duration_s)
    g.lat_deg[m], g.lon_deg[m] = offset_latlon(g.lat_deg[m], g.lon_deg[m], distance_m,
                                               bearing_deg)
    return out


def gyro_saturation(drive: Drive, limit_radps: float) -> Drive:
    """The gyro clips at ``+-limit_radps`` (a sensor range too small for the manoeuvres)."""
    out = copy_drive(drive)
    if out.gyro is not None:
        out.gyro.yaw_rate_radps[:] = np.clip(out.gyro.yaw_rate_radps, -limit_radps, limit_radps)
    return out


def odo_dropout(drive: Drive, start_s: float, duration_s: float, *, mode: str = "missing") -> Drive:
    """The odometer stops reporting (``"missing"``) or reports 0 m/s (``"zero"``) for a while."""
    out = copy_drive(drive)
    o = out.odo
    if o is None:
        return out
    m = window(o.t_ns, start_ns(drive), start_s, duration_s)
    if mode == "missing":
        out.odo = take(o, ~m)
    elif mode == "zero":
        o.speed_mps[m] = 0.0
    else:
        raise ValueError(f"mode {mode!r}: expected 'missing' or 'zero'")
    return out


def time_step_backwards(drive: Drive, stream: str, at_s: float, step_s: float, *,
                        count: int | None = None) -> Drive:
    """The stream's clock steps back ``step_s`` seconds at ``at_s``.

    ``count=None``: for the rest of the log (a clock reset); else only for
    ``count`` records (a glitch), after which the clock is right again.
    """
    out = copy_drive(drive)
    s = getattr(out, stream)
    if s is None:
        return out
    after = np.flatnonzero(s.t_ns >= start_ns(drive) + round(at_s * NS_PER_S))
    if count is not None:
        after = after[:count]
    s.t_ns[after] -= round(step_s * NS_PER_S)
    return out


def duplicate_records(drive: Drive, stream: str, every: int = 10, *,
                      value_offset: float = 0.0) -> Drive:
    """Every ``every``-th record appears twice, the copy right after it.

    ``value_offset`` is added to the copy's value (a duplicate time stamp with
    a different reading, as two loggers merged).
    """
    out = copy_drive(drive)
    s = getattr(out, stream)
    if s is None or not len(s):
        return out
    idx = np.arange(len(s))
    rep = np.where(idx % every == 0, 2, 1)
    order = np.repeat(idx, rep)
    dup = take(s, order)
    is_copy = np.zeros(len(order), bool)
    is_copy[1:] = order[1:] == order[:-1]
    getattr(dup, _value_field(stream))[is_copy] += value_offset
    setattr(out, stream, dup)
    return out


def _some(drive: Drive, stream: str, fraction: float, seed: int
          ) -> tuple[Drive, Any, np.ndarray, np.random.Generator]:
    """A copy of ``drive``, its ``stream`` (None when absent), a random ``fraction`` of that
    stream's records as a mask, and the generator that drew it (for the values)."""
    out = copy_drive(drive)
    s = getattr(out, stream)
    rng = np.random.default_rng(seed)
    m = rng.random(len(s)) < fraction if s is not None else np.zeros(0, bool)
    return out, s, m, rng


def nan_values(drive: Drive, stream: str, fraction: float, *, seed: int = 0,
               value: float = np.nan, field: str | None = None) -> Drive:
    """A random ``fraction`` of a stream's values replaced by ``value`` (NaN, inf, a spike):
    its main values (GNSS: latitude and longitude), or only the array ``field`` (e.g. the
    receiver's ``speed_mps``)."""
    out, s, m, _ = _some(drive, stream, fraction, seed)
    if s is None:
        return out
    getattr(s, field or _value_field(stream))[m] = value
    if stream == "gnss" and field is None:
        s.lon_deg[m] = value
    return out


def random_values(drive: Drive, stream: str, fraction: float, low: float, high: float, *,
                  seed: int = 0) -> Drive:
    """A random ``fraction`` of a DR stream's values replaced by plausible wrong ones, uniform in
    [``low``, ``high``] (a CAN frame with flipped bits, still in range)."""
    out, s, m, rng = _some(drive, stream, fraction, seed)
    if s is not None:
        getattr(s, _value_field(stream))[m] = rng.uniform(low, high, int(m.sum()))
    return out


def wrong_velocities(drive: Drive, fraction: float = 0.05, *, seed: int = 8,
                     max_speed_mps: float = 40.0) -> Drive:
    """A random ``fraction`` of the receiver's velocities replaced by a plausible wrong one: a
    speed uniform in [0, ``max_speed_mps``] along a uniform course (a receiver's bad epoch,
    a mis-parsed but valid field)."""
    out, g, m, rng = _some(drive, "gnss", fraction, seed)
    if g is not None:
        g.speed_mps[m] = rng.uniform(0.0, max_speed_mps, int(m.sum()))
        g.course_deg[m] = rng.uniform(0.0, 360.0, int(m.sum()))
    return out


def drop_streams(drive: Drive, *names: str) -> Drive:
    """The drive without the named streams (``"gnss"``: no GNSS at all; ``"gyro", "odo"``: no DR)."""
    out = copy_drive(drive)
    for name in names:
        if name not in STREAMS:
            raise ValueError(f"unknown stream {name!r}; expected one of {STREAMS}")
        setattr(out, name, None)
    return out


def shift_time(drive: Drive, delta_ns: int) -> Drive:
    """Every time stamp moved by ``delta_ns``."""
    out = copy_drive(drive)
    for s in _streams(out).values():
        s.t_ns[:] = s.t_ns + np.int64(delta_ns)
    return out


def midnight_delta_ns(t_start_ns: int, before_s: float, *, day: str | None = None) -> int:
    """The shift that puts ``t_start_ns`` ``before_s`` seconds before a UTC midnight.

    ``day`` (ISO date) names the day whose end is crossed, e.g. ``"2024-12-31"``
    for a change of year or ``"2024-02-28"`` for a leap day; default: the
    midnight after ``t_start_ns``.
    """
    if day is None:
        midnight = (t_start_ns // DAY_NS + 1) * DAY_NS
    else:
        midnight = int(pd.Timestamp(day, tz="UTC").value) + DAY_NS
    return midnight - round(before_s * NS_PER_S) - t_start_ns


def decimate(drive: Drive, stream: str, rate_hz: float) -> Drive:
    """Block-average a DR stream down to ``rate_hz`` (keeps the integral of rate and speed).

    Each block of ``1/rate_hz`` seconds becomes one record stamped at its last
    sample with the mean value.  Used to keep long in-memory drives to few epochs.
    """
    out = copy_drive(drive)
    s = getattr(out, stream)
    if s is None or not len(s) or stream == "gnss":
        return out
    period = round(NS_PER_S / rate_hz)
    t = s.t_ns
    key = (t - t[0]) // period
    _, first, counts = np.unique(key, return_index=True, return_counts=True)
    last = first + counts - 1
    field = _value_field(stream)
    sums = np.add.reduceat(getattr(s, field), first)
    kwargs: dict[str, Any] = {"t_ns": t[last].copy(), field: sums / counts}
    setattr(out, stream, dataclasses.replace(s, **kwargs))
    return out


# --------------------------------------------------------------------------------------------
# SimDrive faults (the truth changes too)
# --------------------------------------------------------------------------------------------

def with_drive(sim: Any, drive: Drive, truth: pd.DataFrame | None = None, **changes: Any) -> Any:
    """A copy of a SimDrive with its drive (and optionally truth) replaced."""
    return dataclasses.replace(sim, drive=drive, truth=sim.truth if truth is None else truth,
                               **changes)


def sim_shift_time(sim: Any, delta_ns: int) -> Any:
    """Drive and truth moved by ``delta_ns`` (e.g. :func:`midnight_delta_ns`)."""
    truth = sim.truth.copy()
    truth["t_ns"] = truth["t_ns"].to_numpy(np.int64) + np.int64(delta_ns)
    return with_drive(sim, shift_time(sim.drive, delta_ns), truth)


def sim_cross_midnight(sim: Any, before_s: float = 30.0, *, day: str | None = None) -> Any:
    """The drive shifted so that UTC midnight (end of ``day``) falls ``before_s`` after its start."""
    return sim_shift_time(sim, midnight_delta_ns(start_ns(sim.drive), before_s, day=day))


def _median_dt_ns(t_ns: np.ndarray) -> int:
    d = np.diff(np.sort(t_ns))
    d = d[d > 0]
    return int(np.median(d)) if len(d) else NS_PER_S


def insert_standstill(sim: Any, at_s: float, duration_s: float, *, gnss: bool = True,
                      dr_rate_hz: float | None = None, search_s: float = 20.0,
                      gnss_sd_m: float = 1.5, gyro_bias_radps: float | None = None,
                      gyro_sd_radps: float = 0.0017453, seed: int = 0) -> tuple[Any, int]:
    """Insert a stop of ``duration_s`` seconds into a simulated drive.

    The stop begins at the truth epoch of lowest speed within ``search_s`` of
    ``at_s``; everything after it (every stream and the truth) moves later by
    ``duration_s``.  During the stop: truth holds position with zero velocity;
    the odometer reads exactly 0 m/s; the gyro reads its bias plus white noise
    (rad/s), the bias being the one it had in the 10 s before the stop unless
    ``gyro_bias_radps`` says otherwise (a gyro's bias does not step when the car
    stops, and a step would be a different fault); GNSS (when ``gnss``) gives fixes
    scattered ``gnss_sd_m`` (1-sigma per axis) around the true position, else nothing
    (a parking garage).
    ``dr_rate_hz`` sets the DR rate during the stop (default: the stream's own).

    Returns the new SimDrive and the stop's start time in ns.
    """
    rng = np.random.default_rng(seed)
    truth = sim.truth
    tt = truth["t_ns"].to_numpy(np.int64)
    t0 = start_ns(sim.drive)
    near = window(tt, t0, at_s - search_s, 2 * search_s)
    if not near.any():
        raise ValueError(f"no truth epoch within {search_s} s of {at_s} s")
    cand = np.flatnonzero(near)
    k = int(cand[np.argmin(truth["speed"].to_numpy()[cand])])
    t_stop = int(tt[k])
    d_ns = round(duration_s * NS_PER_S)

    # Truth: rows after the stop move later; stop rows copy row k with zero motion.
    truth_dt = _median_dt_ns(tt)
    n_stop = max(1, d_ns // truth_dt)
    stop = pd.DataFrame({c: np.repeat(truth[c].to_numpy()[k:k + 1], n_stop) for c in truth})
    stop["t_ns"] = t_stop + np.arange(n_stop, dtype=np.int64) * truth_dt
    for c in ("v_e", "v_n", "speed", "yaw_rate"):
        if c in stop:
            stop[c] = 0.0
    later = truth.iloc[k:].copy()
    later["t_ns"] = later["t_ns"].to_numpy(np.int64) + d_ns
    new_truth = pd.concat([truth.iloc[:k], stop, later], ignore_index=True)

    out = copy_drive(sim.drive)
    lat0, lon0 = float(truth["lat"].iloc[k]), float(truth["lon"].iloc[k])
    for name, s in _streams(out).items():
        move = s.t_ns >= t_stop
        s.t_ns[move] += np.int64(d_ns)
        if name == "gnss" and not gnss:
            continue
        dt = _median_dt_ns(s.t_ns) if (dr_rate_hz is None or name == "gnss") \
            else round(NS_PER_S / dr_rate_hz)
        times = t_stop + np.arange(d_ns // dt, dtype=np.int64) * dt
        n = len(times)
        if name == "gnss":
            before = np.flatnonzero((s.t_ns < t_stop) & s.valid)
            src = int(before[-1]) if len(before) else int(np.flatnonzero(s.valid)[0])
            add = take(s, np.full(n, src))
            add.t_ns = times
            de, dn = rng.normal(0.0, gnss_sd_m, (2, n))
            add.lat_deg = lat0 + dn / M_PER_DEG_LAT
            add.lon_deg = lon0 + de / (M_PER_DEG_LAT * math.cos(math.radians(lat0)))
            add.speed_mps = np.zeros(n)
            add.course_deg = np.full(n, np.nan)
        elif name == "gyro":
            bias = (_gyro_bias_before(sim, t_stop) if gyro_bias_radps is None
                    else gyro_bias_radps)
            add = YawRates(times, bias + rng.normal(0.0, gyro_sd_radps, n))
        else:
            add = Odometry(times, np.zeros(n))
        setattr(out, name, concat(s, add))
    return with_drive(sim, out, new_truth), t_stop


#: rad/s: the stopped gyro's bias when the drive gives none to keep (no gyro records before it)
STOP_GYRO_BIAS_RADPS = 0.003


def _gyro_bias_before(sim: Any, t_ns: int, span_s: float = 10.0) -> float:
    """The gyro's bias (rad/s) over the ``span_s`` seconds before ``t_ns``: its readings
    less the true yaw rate times its scale (the simulator's noise record), averaged."""
    g = sim.drive.gyro
    if g is None or not len(g) or "yaw_rate" not in sim.truth:
        return STOP_GYRO_BIAS_RADPS
    sel = (g.t_ns < t_ns) & (g.t_ns >= t_ns - round(span_s * NS_PER_S))
    if not sel.any():
        return STOP_GYRO_BIAS_RADPS
    omega = np.interp(g.t_ns[sel], sim.truth["t_ns"].to_numpy(np.int64),
                      sim.truth["yaw_rate"].to_numpy(float))
    scale = float(sim.noise.get("gyro_scale_error", 0.0))
    return float(np.mean(g.yaw_rate_radps[sel] - (1.0 + scale) * omega))


# --------------------------------------------------------------------------------------------
# File faults (bytes)
# --------------------------------------------------------------------------------------------

def truncate(data: bytes, fraction: float) -> bytes:
    """The first ``fraction`` of the bytes (a log cut by a power loss or a full disk)."""
    return data[: int(len(data) * fraction)]


def corrupt(data: bytes, n_bytes: int, *, seed: int = 0, start_frac: float = 0.0,
            end_frac: float = 1.0) -> bytes:
    """``n_bytes`` random bytes overwritten with random values inside ``[start_frac, end_frac)``."""
    rng = np.random.default_rng(seed)
    buf = bytearray(data)
    lo, hi = int(len(buf) * start_frac), max(int(len(buf) * end_frac), int(len(buf) * start_frac) + 1)
    hi = min(hi, len(buf))
    if hi <= lo:
        return bytes(buf)
    for pos in rng.integers(lo, hi, n_bytes):
        buf[pos] = int(rng.integers(0, 256))
    return bytes(buf)


def insert_garbage(data: bytes, n_chunks: int, *, seed: int = 0, max_len: int = 80,
                   inside_lines: bool = True) -> bytes:
    """Random binary chunks (1..max_len bytes) inserted at ``n_chunks`` places.

    ``inside_lines``: anywhere (breaking the line they land in); else only at
    line starts (whole garbage lines between good sentences).
    """
    rng = np.random.default_rng(seed)
    if inside_lines or b"\n" not in data:
        places = np.sort(rng.integers(0, len(data) + 1, n_chunks))
    else:
        starts = np.concatenate(([0], np.flatnonzero(np.frombuffer(data, np.uint8) == 10) + 1))
        places = np.sort(rng.choice(starts, n_chunks))
    parts, prev = [], 0
    for p in places:
        parts.append(data[prev:p])
        chunk = rng.integers(0, 256, int(rng.integers(1, max_len + 1)), dtype=np.uint8).tobytes()
        parts.append(chunk if inside_lines else chunk.replace(b"\n", b" ") + b"\n")
        prev = int(p)
    parts.append(data[prev:])
    return b"".join(parts)


def nmea_checksum(body: bytes) -> bytes:
    """Two hex digits: XOR of the bytes between ``$`` and ``*``."""
    x = 0
    for b in body:
        x ^= b
    return b"%02X" % x


_SENTENCE = re.compile(rb"\$([^*\r\n]*)\*[0-9A-Fa-f]{2}")


def nmea_map_sentences(data: bytes, fn: Callable[[list[bytes]], list[bytes] | None]) -> bytes:
    """Apply ``fn`` to each sentence's fields (``[b"GPGGA", ...]``); None drops the line.

    Checksums are recomputed, so a changed sentence still reaches the parser as valid.
    """
    out = []
    for line in data.splitlines(keepends=True):
        m = _SENTENCE.search(line)
        if m is None:
            out.append(line)
            continue
        fields = fn(m.group(1).split(b","))
        if fields is None:
            continue
        body = b",".join(fields)
        out.append(line[: m.start()] + b"$" + body + b"*" + nmea_checksum(body) + line[m.end():])
    return b"".join(out)


def nmea_empty_fields(data: bytes, fraction: float, *, seed: int = 0, value: bytes = b"") -> bytes:
    """A random ``fraction`` of the data fields of every sentence set to ``value`` (valid checksums)."""
    rng = np.random.default_rng(seed)

    def blank(fields: list[bytes]) -> list[bytes]:
        return [fields[0]] + [value if rng.random() < fraction else f for f in fields[1:]]

    return nmea_map_sentences(data, blank)


def nmea_drop_sentences(data: bytes, kinds: Sequence[str]) -> bytes:
    """Remove sentences by type, any talker (e.g. ``("RMC", "ZDA")``: no date in the log)."""
    wanted = {k.encode() for k in kinds}
    return nmea_map_sentences(data, lambda f: None if f[0][-3:] in wanted else f)


def csv_fields(data: bytes, fraction: float, *, seed: int = 0, value: bytes = b"",
               header_lines: int = 1) -> bytes:
    """A random ``fraction`` of the data cells of a CSV replaced by ``value`` (b"", b"nan", ...)."""
    rng = np.random.default_rng(seed)
    lines = data.splitlines(keepends=True)
    for i in range(header_lines, len(lines)):
        body = lines[i].rstrip(b"\r\n")
        end = lines[i][len(body):]
        cells = [value if rng.random() < fraction else c for c in body.split(b",")]
        lines[i] = b",".join(cells) + end
    return b"".join(lines)


def swap_lines(data: bytes, n_swaps: int, *, seed: int = 0, header_lines: int = 1) -> bytes:
    """``n_swaps`` random pairs of adjacent data lines exchanged (time steps backwards)."""
    rng = np.random.default_rng(seed)
    lines = data.splitlines(keepends=True)
    if len(lines) - header_lines < 2:
        return data
    for i in rng.integers(header_lines, len(lines) - 1, n_swaps):
        lines[i], lines[i + 1] = lines[i + 1], lines[i]
    return b"".join(_ensure_newlines(lines))


def repeat_lines(data: bytes, every: int, *, header_lines: int = 1) -> bytes:
    """Every ``every``-th data line written twice (duplicate records)."""
    lines = _ensure_newlines(data.splitlines(keepends=True))
    out = lines[:header_lines]
    for i, line in enumerate(lines[header_lines:]):
        out.append(line)
        if i % every == 0:
            out.append(line)
    return b"".join(out)


def _ensure_newlines(lines: list[bytes]) -> list[bytes]:
    return [ln if ln.endswith(b"\n") else ln + b"\n" for ln in lines]


# --------------------------------------------------------------------------------------------
# Fuzz mutators
# --------------------------------------------------------------------------------------------

#: Tokens that often break parsers of numbers, CSV and NMEA.
INTERESTING: tuple[bytes, ...] = (
    b"", b",", b",,", b"*", b"$", b"\r", b"\n", b"\r\n", b"\x00", b"\xff\xfe", b"nan", b"NaN",
    b"inf", b"-inf", b"-0", b"0", b"-1", b"1e308", b"-1e308", b"1e-320", b"9" * 30, b"0x1F",
    b"\xe2\x82\xac", b'"', b"'", b";", b" ", b"\t", b"235959.99", b"240000", b"999999",
    b"311299", b"290223", b"-90", b"181", b"E", b"W", b"N", b"S", b"$GPGGA", b"$GNRMC",
    b"*00", b"t,yaw_rate\n", b"t,speed\n",
)


def _m_flip(buf: bytearray, rng: np.random.Generator) -> None:
    if buf:
        i = int(rng.integers(len(buf)))
        buf[i] ^= 1 << int(rng.integers(8))


def _m_set(buf: bytearray, rng: np.random.Generator) -> None:
    if buf:
        buf[int(rng.integers(len(buf)))] = int(rng.integers(256))


def _m_insert(buf: bytearray, rng: np.random.Generator) -> None:
    i = int(rng.integers(len(buf) + 1))
    buf[i:i] = rng.integers(0, 256, int(rng.integers(1, 17)), dtype=np.uint8).tobytes()


def _m_token(buf: bytearray, rng: np.random.Generator) -> None:
    i = int(rng.integers(len(buf) + 1))
    tok = INTERESTING[int(rng.integers(len(INTERESTING)))]
    if rng.random() < 0.5 and i < len(buf):  # replace up to the next separator
        j = i
        while j < len(buf) and buf[j] not in b",*\n":
            j += 1
        buf[i:j] = tok
    else:
        buf[i:i] = tok


def _m_delete(buf: bytearray, rng: np.random.Generator) -> None:
    if buf:
        i = int(rng.integers(len(buf)))
        del buf[i:i + int(rng.integers(1, 65))]


def _m_duplicate(buf: bytearray, rng: np.random.Generator) -> None:
    if buf:
        i = int(rng.integers(len(buf)))
        j = min(len(buf), i + int(rng.integers(1, 257)))
        k = int(rng.integers(len(buf) + 1))
        buf[k:k] = buf[i:j]


def _m_truncate(buf: bytearray, rng: np.random.Generator) -> None:
    if buf:
        del buf[int(rng.integers(len(buf))):]


def _m_digit(buf: bytearray, rng: np.random.Generator) -> None:
    digits = [i for i in rng.integers(0, max(len(buf), 1), 32) if i < len(buf)
              and 48 <= buf[i] <= 57]
    if digits:
        buf[int(digits[0])] = 48 + int(rng.integers(10))


def _m_swap_lines(buf: bytearray, rng: np.random.Generator) -> None:
    lines = bytes(buf).split(b"\n")
    if len(lines) > 2:
        i = int(rng.integers(len(lines) - 1))
        lines[i], lines[i + 1] = lines[i + 1], lines[i]
        buf[:] = b"\n".join(lines)


MUTATORS: dict[str, Callable[[bytearray, np.random.Generator], None]] = {
    "flip": _m_flip, "set": _m_set, "insert": _m_insert, "token": _m_token,
    "delete": _m_delete, "duplicate": _m_duplicate, "truncate": _m_truncate,
    "digit": _m_digit, "swap_lines": _m_swap_lines,
}
_TRUNCATE_WEIGHT = 0.03


def mutate(data: bytes, rng: np.random.Generator, n_mutations: int | None = None) -> bytes:
    """``data`` with 1..8 (or ``n_mutations``) random mutations from :data:`MUTATORS`.

    Truncation is drawn rarely (it would hide every later mutation).
    """
    buf = bytearray(data)
    n = int(rng.integers(1, 9)) if n_mutations is None else n_mutations
    names = list(MUTATORS)
    w = np.array([_TRUNCATE_WEIGHT if k == "truncate" else 1.0 for k in names])
    w /= w.sum()
    for _ in range(n):
        MUTATORS[names[int(rng.choice(len(names), p=w))]](buf, rng)
    return bytes(buf)


# --------------------------------------------------------------------------------------------
# Checks on outcomes
# --------------------------------------------------------------------------------------------

def track_problems(track: pd.DataFrame, *, n_epochs: int | None = None) -> list[str]:
    """What is wrong with a track by INTERFACE.md; empty when it is complete and finite.

    Checks: every required column present; ``time`` non-null and strictly
    increasing; :data:`REQUIRED_FINITE` finite; sigmas >= 0; heading in [0, 360];
    ``gnss_used`` without nulls; ``pdop`` finite or null (never inf); one row per
    epoch when ``n_epochs`` is given; at least one row.
    """
    problems: list[str] = []
    missing = [c for c in REQUIRED_COLUMNS if c not in track.columns]
    if missing:
        problems.append(f"missing columns {missing}")
    if len(track) == 0:
        problems.append("empty track")
    if n_epochs is not None and len(track) != n_epochs:
        problems.append(f"{len(track)} rows for {n_epochs} epochs")
    if "time" in track:
        t = track["time"]
        if t.isna().any():
            problems.append(f"time: {int(t.isna().sum())} nulls")
        elif len(t) > 1:
            tv = _time_ns(t)
            if np.any(np.diff(tv) <= 0):
                problems.append(f"time: {int(np.sum(np.diff(tv) <= 0))} steps not increasing")
    for c in REQUIRED_FINITE:
        if c in track:
            v = pd.to_numeric(track[c], errors="coerce").to_numpy(np.float64, na_value=np.nan)
            bad = ~np.isfinite(v)
            if bad.any():
                problems.append(f"{c}: {int(bad.sum())} non-finite of {len(v)}")
    for c in ("sigma_e", "sigma_n"):
        if c in track and (pd.to_numeric(track[c], errors="coerce") < 0).any():
            problems.append(f"{c}: negative")
    if "heading_deg" in track:
        h = pd.to_numeric(track["heading_deg"], errors="coerce")
        if ((h < 0) | (h > 360)).any():
            problems.append("heading_deg: outside [0, 360]")
    if "gnss_used" in track and track["gnss_used"].isna().any():
        problems.append("gnss_used: nulls")
    if "pdop" in track:
        p = pd.to_numeric(track["pdop"], errors="coerce").to_numpy(np.float64, na_value=np.nan)
        if np.isinf(p).any():
            problems.append("pdop: inf")
    return problems


def error_line_problems(stderr: str) -> list[str]:
    """What is wrong with a failed run's stderr: it must be exactly one line, no traceback."""
    lines = [ln for ln in stderr.splitlines() if ln.strip()]
    problems = []
    if not lines:
        problems.append("no error message on stderr")
    elif len(lines) > 1:
        problems.append(f"{len(lines)} lines on stderr: {lines[:3]!r}")
    if "Traceback" in stderr:
        problems.append("traceback on stderr")
    return problems


def horizontal_error_m(track: pd.DataFrame, truth: pd.DataFrame) -> np.ndarray:
    """Distance (m) between the track and the truth interpolated to the track's times.

    Compared in lat/lon, both projected into one frame centred on the truth's
    first point, so the track's own frame choice does not matter.
    """
    t = track_t_ns(track)
    tt = truth["t_ns"].to_numpy(np.int64)
    lat0, lon0 = float(truth["lat"].iloc[0]), float(truth["lon"].iloc[0])
    frame = LocalFrame.centred_on(lat0, lon0)
    te, tn = frame.forward(np.interp(t, tt, truth["lat"].to_numpy(float)),
                           np.interp(t, tt, truth["lon"].to_numpy(float)))
    e, n = frame.forward(track["lat"].to_numpy(float), track["lon"].to_numpy(float))
    return np.hypot(e - te, n - tn)


def track_t_ns(track: pd.DataFrame) -> np.ndarray:
    """The track's ``time`` as int64 ns since the epoch."""
    if "t_ns" in track:
        return track["t_ns"].to_numpy(np.int64)
    return _time_ns(track["time"])


def _time_ns(t: pd.Series) -> np.ndarray:
    naive = pd.to_datetime(t, utc=True).dt.tz_localize(None)
    return naive.to_numpy(dtype="datetime64[ns]").view(np.int64)


def nmea_fix_checksums(data: bytes) -> bytes:
    """Every ``$...*hh`` sentence given its correct checksum (so fuzzed fields reach the parser)."""
    return nmea_map_sentences(data, lambda f: f)


# --------------------------------------------------------------------------------------------
# Running gpsdr on a damaged drive, and judging the outcome
# --------------------------------------------------------------------------------------------

@dataclasses.dataclass
class Outcome:
    """What one run produced.

    ``status``: exit status (0/1/2; in-memory runs: 0 or 1); ``stderr`` the
    error text; ``escape``: the name of an exception that is not a
    GpsdrError (a bug), or of an "internal error" the CLI caught; ``track``
    the track read back (None on failure); ``epochs`` from its metadata.
    """

    status: int
    stderr: str = ""
    escape: str | None = None
    track: pd.DataFrame | None = None
    epochs: int | None = None
    meta: dict[str, str] = dataclasses.field(default_factory=dict)

    @property
    def kind(self) -> str:
        """``track`` | ``error<status>`` | ``escape:<name>``."""
        if self.escape:
            return f"escape:{self.escape}"
        return "track" if self.status == 0 else f"error{self.status}"


def stream_args(paths: dict[str, Any], *, mcap: bool = False) -> list[str]:
    """``gpsdr fuse`` arguments for the files :func:`gpsdr_cli.simulate.write_drive` made."""
    if mcap:
        return [str(paths["drive.mcap"])]
    return ["--gps", str(paths["gps.nmea"]), "--gyro", str(paths["gyro.csv"]),
            "--odo", str(paths["odo.csv"])]


def run_cli(args: Sequence[str], out_dir: Any, *, filter_name: str | None = None,
            subprocess_exe: str | None = None, track_name: str = "track.parquet",
            timeout_s: float = 600.0) -> Outcome:
    """Run ``gpsdr fuse ARGS -o OUT_DIR/track.parquet --stats ...`` and read the track back.

    In process with click's CliRunner (fast), or as a real process when
    ``subprocess_exe`` names the ``gpsdr`` executable (stopped after ``timeout_s``:
    ``subprocess.TimeoutExpired``).  A failed run's stderr
    holding "internal error" (an exception gpsdr did not raise on purpose) or a
    traceback is reported as an escape.
    """
    import pathlib

    out = pathlib.Path(out_dir)
    track_path = out / track_name
    argv = ["fuse", *map(str, args), "-o", str(track_path),
            "--stats", str(out / (track_name + ".stats.parquet")), "-q"]
    if filter_name:
        argv += ["--filter", filter_name]
    if subprocess_exe:
        import subprocess

        proc = subprocess.run([subprocess_exe, *argv], capture_output=True, text=True,
                              timeout=timeout_s, check=False)
        status, stderr = proc.returncode, proc.stderr
        escape = None
    else:
        from click.testing import CliRunner

        from ..cli.main import cli

        res = CliRunner().invoke(cli, argv, catch_exceptions=True)
        status, stderr = res.exit_code, res.stderr
        escape = None
        if res.exception is not None and not isinstance(res.exception, SystemExit):
            escape = type(res.exception).__name__
    if escape is None and status != 0:
        if "internal error" in stderr:
            m = re.search(r"internal error: (\w+)", stderr)
            escape = m.group(1) if m else "internal"
        elif "Traceback" in stderr:
            escape = "traceback"
        elif "NonFiniteOutputError" in stderr or "filter output: column" in stderr:
            escape = "NonFiniteOutput"
    outcome = Outcome(status=status, stderr=stderr, escape=escape)
    if status == 0:
        import pyarrow.parquet as pq

        outcome.track = pd.read_parquet(track_path)
        raw = pq.read_schema(track_path).metadata or {}
        outcome.meta = {k.decode(): v.decode() for k, v in raw.items()}
        if "epochs" in outcome.meta:
            outcome.epochs = int(outcome.meta["epochs"])
    return outcome


def run_inmemory(drive: Drive, params: dict) -> Outcome:
    """``pipeline.fuse`` on a Drive: a track, a GpsdrError (status 1/2) or an escape."""
    from ..errors import GpsdrError, UsageError
    from ..pipeline import fuse

    try:
        res = fuse(drive, params)
    except UsageError as err:
        return Outcome(status=2, stderr=str(err))
    except GpsdrError as err:
        name = type(err).__name__
        return Outcome(status=1, stderr=str(err),
                       escape="NonFiniteOutput" if name == "NonFiniteOutputError" else None)
    except Exception as err:  # noqa: BLE001 - anything else escaping is the bug we report
        return Outcome(status=1, stderr=f"{type(err).__name__}: {err}", escape=type(err).__name__)
    return Outcome(status=0, track=res.track, epochs=len(res.epochs), meta=res.metadata)


def outcome_problems(outcome: Outcome, expect: str) -> list[str]:
    """Why an outcome breaks the contract.

    ``expect``: ``track`` (must succeed), ``error`` (must fail cleanly) or
    ``either``.  A success must give a complete finite track with one row per
    epoch; a failure exactly one stderr line (CLI) and no escape.
    """
    problems: list[str] = []
    if outcome.escape:
        problems.append(f"escape {outcome.escape}: {outcome.stderr.strip()[:200]}")
    if outcome.status == 0:
        if expect == "error":
            problems.append("succeeded where an error was expected")
        if outcome.track is not None:
            problems += track_problems(outcome.track, n_epochs=outcome.epochs)
    else:
        if expect == "track":
            problems.append(f"exit {outcome.status} where a track was expected: "
                            f"{outcome.stderr.strip()[:200]}")
        if "\n" in outcome.stderr.strip() or "Traceback" in outcome.stderr:
            problems += error_line_problems(outcome.stderr)
    return problems


# --------------------------------------------------------------------------------------------
# The fault catalogue: what tests/test_faults.py and benchmarks/fault_table.py run
# --------------------------------------------------------------------------------------------

#: The base drive of the file cases: seconds, and the simulator's DR rates (Hz).
BASE_DURATION_S = 120.0
BASE_RATES = {"gnss_rate_hz": 5.0, "gyro_rate_hz": 20.0, "odo_rate_hz": 10.0}


@dataclasses.dataclass
class CaseInputs:
    """A damaged drive ready to run: CLI ``args`` (file cases) or a ``drive`` (in-memory cases).

    ``sim``: the SimDrive whose truth holds for the damaged drive; ``focus_ns``:
    the time window where the fault acts (for the window metrics); ``config``:
    parameter overrides (written to a ``--config`` TOML for file cases).
    """

    sim: Any
    args: list[str] = dataclasses.field(default_factory=list)
    drive: Drive | None = None
    focus_ns: tuple[int, int] | None = None
    config: dict[str, dict[str, Any]] = dataclasses.field(default_factory=dict)
    #: where the inputs and outputs of the run are (set by :func:`run_case`)
    out_dir: Any = None


@dataclasses.dataclass
class FaultCase:
    """One fault: how to make it from a base SimDrive into a directory, and what must happen.

    ``expect``: ``track`` (a complete finite track), ``error`` (one clear error
    line, exit 1/2) or ``either``.  ``base``: ``short`` (the 120 s file drive)
    or ``long`` (built by the case itself, in memory).
    """

    name: str
    description: str
    expect: str
    make: Callable[[Any, Any], CaseInputs]
    base: str = "short"


def base_sim(seed: int = 7, duration_s: float = BASE_DURATION_S, scenario: str = "open_sky",
             **rates: float) -> Any:
    """The simulated drive faults are injected into (open sky: every error is the fault's)."""
    from ..simulate import simulate_drive

    return simulate_drive(scenario, seed, duration_s, **{**BASE_RATES, **rates})


_FILE_CACHE: dict[int, tuple[Any, dict[str, bytes]]] = {}


def _files(sim: Any, out_dir: Any, *, mcap: bool = False) -> dict[str, Any]:
    """The SimDrive's logs written into ``out_dir`` (MCAP only when asked: it is slow to write).

    The bytes of the last few drives are cached, so the file faults on one
    base drive do not each re-encode it.
    """
    import pathlib

    from ..simulate import write_drive

    out = pathlib.Path(out_dir)
    cached = _FILE_CACHE.get(id(sim))
    if cached is None or cached[0] is not sim or (mcap and "drive.mcap" not in cached[1]):
        paths = write_drive(sim, out, mcap=mcap)
        if len(_FILE_CACHE) > 8:
            _FILE_CACHE.clear()
        _FILE_CACHE[id(sim)] = (sim, {k: p.read_bytes() for k, p in paths.items()})
        return paths
    out.mkdir(parents=True, exist_ok=True)
    paths = {}
    for name, data in cached[1].items():
        if name == "drive.mcap" and not mcap:
            continue
        paths[name] = out / name
        paths[name].write_bytes(data)
    return paths


def _rel_ns(sim: Any, start_s: float, duration_s: float) -> tuple[int, int]:
    t0 = start_ns(sim.drive)
    return t0 + round(start_s * NS_PER_S), t0 + round((start_s + duration_s) * NS_PER_S)


def _drive_case(fault: Callable[[Drive], Drive], focus: tuple[float, float] | None = None,
                mcap: bool = False) -> Callable[[Any, Any], CaseInputs]:
    """A case made by an in-memory fault on the drive, then written as files."""
    def make(sim: Any, out_dir: Any) -> CaseInputs:
        bad = with_drive(sim, fault(sim.drive))
        paths = _files(bad, out_dir, mcap=mcap)
        return CaseInputs(sim=bad, args=stream_args(paths, mcap=mcap),
                          focus_ns=None if focus is None else _rel_ns(sim, *focus))
    return make


def _file_case(name: str, fault: Callable[[bytes], bytes], *, mcap: bool = False,
               focus: tuple[float, float] | None = None,
               extra: Sequence[str] = ()) -> Callable[[Any, Any], CaseInputs]:
    """A case made by damaging one written file's bytes."""
    def make(sim: Any, out_dir: Any) -> CaseInputs:
        paths = _files(sim, out_dir, mcap=mcap)
        p = paths[name]
        p.write_bytes(fault(p.read_bytes()))
        return CaseInputs(sim=sim, args=[*stream_args(paths, mcap=mcap), *extra],
                          focus_ns=None if focus is None else _rel_ns(sim, *focus))
    return make


def _subset_case(streams: Sequence[str], config: Callable[[Any], dict] | None = None
                 ) -> Callable[[Any, Any], CaseInputs]:
    """Only some of the streams given on the command line."""
    def make(sim: Any, out_dir: Any) -> CaseInputs:
        paths = _files(sim, out_dir)
        flag = {"gnss": ("--gps", "gps.nmea"), "gyro": ("--gyro", "gyro.csv"),
                "odo": ("--odo", "odo.csv")}
        args: list[str] = []
        for s in streams:
            args += [flag[s][0], str(paths[flag[s][1]])]
        return CaseInputs(sim=sim, args=args, config=config(sim) if config else {})
    return make


def _origin_config(sim: Any) -> dict[str, dict[str, Any]]:
    tr = sim.truth
    return {"frame": {"origin_lat_deg": float(tr["lat"].iloc[0]),
                      "origin_lon_deg": float(tr["lon"].iloc[0]),
                      "initial_heading_deg": float(tr["heading_deg"].iloc[0])}}


def _midnight_case(before_s: float, day: str | None, *, drop: Sequence[str] = (),
                   with_date: bool = False) -> Callable[[Any, Any], CaseInputs]:
    def make(sim: Any, out_dir: Any) -> CaseInputs:
        moved = sim_cross_midnight(sim, before_s, day=day)
        paths = _files(moved, out_dir)
        extra: list[str] = []
        if drop:
            p = paths["gps.nmea"]
            p.write_bytes(nmea_drop_sentences(p.read_bytes(), drop))
        if with_date:
            d0 = pd.Timestamp(start_ns(moved.drive), unit="ns", tz="UTC").date()
            extra = ["--date", d0.isoformat()]
        t_mid = start_ns(moved.drive) + round(before_s * NS_PER_S)
        return CaseInputs(sim=moved, args=[*stream_args(paths), *extra],
                          focus_ns=(t_mid - 5 * NS_PER_S, t_mid + 5 * NS_PER_S))
    return make


def long_sim(duration_s: float = 780.0, seed: int = 11) -> Any:
    """The in-memory base for long faults: DR block-averaged to 10 Hz to keep epochs few."""
    sim = base_sim(seed, duration_s, gnss_rate_hz=1.0, gyro_rate_hz=10.0, odo_rate_hz=10.0)
    return sim


def _outage_long(duration_s: float) -> Callable[[Any, Any], CaseInputs]:
    def make(_sim: Any, _out_dir: Any) -> CaseInputs:
        sim = long_sim(duration_s + 180.0)
        drive = gnss_outage(sim.drive, 90.0, duration_s)
        return CaseInputs(sim=with_drive(sim, drive), drive=drive,
                          focus_ns=_rel_ns(sim, 90.0, duration_s))
    return make


def _rtk_after_long_gap(gap_s: float) -> Callable[[Any, Any], CaseInputs]:
    """GNSS only, no fix for ``gap_s`` from 90 s on, then RTK fixed: the fixes after the gap
    on the truth with a 1.5-cm sigma (gpsd's nmea-rtk.log: a 630-s gap of a Trimble log
    ending in RTK fixes left fkf's covariance indefinite)."""
    def make(_sim: Any, _out_dir: Any) -> CaseInputs:
        sim = long_sim(gap_s + 180.0)
        drive = drop_streams(gnss_outage(sim.drive, 90.0, gap_s, mode="drop"), "gyro", "odo")
        g = drive.gnss
        after = g.valid & (g.t_ns >= _rel_ns(sim, 90.0, gap_s)[1])
        t_truth = sim.truth["t_ns"].to_numpy(np.int64)
        for name, col in (("lat_deg", "lat"), ("lon_deg", "lon")):
            values = getattr(g, name).copy()
            values[after] = np.interp(g.t_ns[after], t_truth, sim.truth[col].to_numpy(float))
            setattr(g, name, values)
        g.fix_quality = np.where(after, 4, g.fix_quality).astype(g.fix_quality.dtype)
        g.sigma_e_m = np.where(after, 0.015, g.sigma_e_m)
        g.sigma_n_m = np.where(after, 0.015, g.sigma_n_m)
        return CaseInputs(sim=with_drive(sim, drive), drive=drive,
                          focus_ns=_rel_ns(sim, 90.0, gap_s))
    return make


def _standstill_long(duration_s: float, gnss: bool) -> Callable[[Any, Any], CaseInputs]:
    def make(_sim: Any, _out_dir: Any) -> CaseInputs:
        sim = long_sim(120.0)
        moved, t_stop = insert_standstill(sim, 60.0, duration_s, gnss=gnss, dr_rate_hz=10.0)
        return CaseInputs(sim=moved, drive=moved.drive,
                          focus_ns=(t_stop, t_stop + round(duration_s * NS_PER_S)))
    return make


def rtklib_pos(drive: Drive) -> bytes:
    """The drive's GNSS fixes as an RTKLIB ``.pos`` solution (llh form, GPST, Q 5 single;
    no-fix epochs left out, as RTKLIB writes no line without a solution)."""
    g = drive.gnss
    lines = ["% program   : gpsdr fault suite (RTKLIB .pos layout)",
             ("% (lat/lon/height=WGS84/ellipsoidal,Q=1:fix,2:float,3:sbas,4:dgps,5:single,"
             "6:ppp,ns=# of satellites)"),
             ("%  GPST                  latitude(deg) longitude(deg)  height(m)   Q  ns   sdn(m)"
             "   sde(m)   sdu(m)  sdne(m)  sdeu(m)  sdun(m) age(s)  ratio")]
    ok = g.valid if g is not None else np.zeros(0, bool)
    for i in np.flatnonzero(ok):
        gpst = pd.Timestamp(int(g.t_ns[i]) + 18 * NS_PER_S, unit="ns")  # GPST - UTC since 2017
        alt = g.alt_m[i] if np.isfinite(g.alt_m[i]) else 0.0
        lines.append(f"{gpst.strftime('%Y/%m/%d %H:%M:%S.%f')[:-3]}  {g.lat_deg[i]:13.9f}  "
                     f"{g.lon_deg[i]:13.9f} {alt:10.4f}   5  {max(int(g.n_sats[i]), 4):2d}"
                     "   1.2000   1.0000   2.5000   0.1000   0.2000   0.3000   0.00    0.0")
    return ("\n".join(lines) + "\n").encode()


def _pos_case(fault: Callable[[bytes], bytes]) -> Callable[[Any, Any], CaseInputs]:
    """The GNSS given as an RTKLIB .pos (``--gps rover.pos``), damaged by ``fault``."""
    def make(sim: Any, out_dir: Any) -> CaseInputs:
        import pathlib

        paths = _files(sim, out_dir)
        pos = pathlib.Path(out_dir) / "rover.pos"
        pos.write_bytes(fault(rtklib_pos(sim.drive)))
        return CaseInputs(sim=sim, args=["--gps", str(pos), "--gyro", str(paths["gyro.csv"]),
                                         "--odo", str(paths["odo.csv"])])
    return make


def _utf16(data: bytes, *, bom: bool = True, big_endian: bool = False) -> bytes:
    """Text re-encoded as UTF-16 (little-endian with a byte-order mark by default)."""
    text = data.decode("latin-1")
    if bom:
        return text.encode("utf-16-be" if big_endian else "utf-16")  # "utf-16": BOM + LE
    return text.encode("utf-16-be" if big_endian else "utf-16-le")


def _mcap_case(fault: Callable[[bytes], bytes]) -> Callable[[Any, Any], CaseInputs]:
    return _file_case("drive.mcap", fault, mcap=True)


def _ubx_case(fault: Callable[[bytes], bytes]) -> Callable[[Any, Any], CaseInputs]:
    """The drive as an F9R-like UBX log (NAV-PVT, ESF-MEAS gyro and speed), then damaged."""
    def make(sim: Any, out_dir: Any) -> CaseInputs:
        import pathlib

        from .ubx_log import ubx_log

        out = pathlib.Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        p = out / "drive.ubx"
        p.write_bytes(fault(ubx_log(sim.drive)))
        return CaseInputs(sim=sim, args=[str(p)])
    return make


def _bag_case(fault: Callable[[bytes], bytes]) -> Callable[[Any, Any], CaseInputs]:
    """The drive as a ROS 2 SQLite bag, its .db3 file then damaged."""
    def make(sim: Any, out_dir: Any) -> CaseInputs:
        import pathlib

        from .bags import write_rosbag

        out = pathlib.Path(out_dir)
        out.mkdir(parents=True, exist_ok=True)
        bag = write_rosbag(sim.drive, out / "drive_bag")
        db = next(bag.glob("*.db3"))
        db.write_bytes(fault(db.read_bytes()))
        return CaseInputs(sim=sim, args=[str(bag)])
    return make


CATALOGUE: tuple[FaultCase, ...] = (
    FaultCase("clean", "no fault (baseline)", "track", _drive_case(lambda d: d)),
    FaultCase("outage_10s", "GNSS outage 10 s at ~20 m/s (fix quality 0)", "track",
              _drive_case(lambda d: gnss_outage(d, 15.0, 10.0), (15.0, 10.0))),
    FaultCase("outage_60s", "GNSS outage 60 s with a 25 s stop in it (no records)", "track",
              _drive_case(lambda d: gnss_outage(d, 30.0, 60.0, mode="drop"), (30.0, 60.0))),
    FaultCase("outage_10min", "GNSS outage 600 s, in memory, 10 Hz DR", "track",
              _outage_long(600.0), base="long"),
    FaultCase("gap_rtk", "GNSS only, no fix for 1000 s, then RTK fixed (1.5 cm), in "
              "memory", "track", _rtk_after_long_gap(1000.0), base="long"),
    FaultCase("standstill_30min", "30 min stop with GNSS, in memory, 10 Hz DR", "track",
              _standstill_long(1800.0, True), base="long"),
    FaultCase("standstill_30min_nognss", "30 min stop without GNSS (garage)", "track",
              _standstill_long(1800.0, False), base="long"),
    FaultCase("gnss_clock_back", "GNSS clock steps back 2 s for good at 50 s", "track",
              _drive_case(lambda d: time_step_backwards(d, "gnss", 50.0, 2.0), (50.0, 4.0))),
    FaultCase("gyro_clock_glitch", "5 gyro records stamped 1 s early at 50 s", "track",
              _drive_case(lambda d: time_step_backwards(d, "gyro", 50.0, 1.0, count=5))),
    FaultCase("duplicates", "every 7th record of each stream twice, copy off by +1", "track",
              _drive_case(lambda d: duplicate_records(duplicate_records(duplicate_records(
                  d, "gnss", 7, value_offset=1e-4), "gyro", 7, value_offset=1.0),
                  "odo", 7, value_offset=5.0))),
    FaultCase("swapped_lines", "20 adjacent gyro CSV line pairs swapped", "track",
              _file_case("gyro.csv", lambda b: swap_lines(b, 20, seed=1))),
    FaultCase("nan_values", "5 % of gyro, odometer and GNSS values NaN", "track",
              _drive_case(lambda d: nan_values(nan_values(nan_values(d, "gyro", 0.05), "odo",
                                                          0.05, seed=1), "gnss", 0.05, seed=2))),
    FaultCase("csv_nan_text", "5 % of odometer CSV cells 'nan'", "track",
              _file_case("odo.csv", lambda b: csv_fields(b, 0.05, seed=3, value=b"nan"))),
    FaultCase("csv_inf_text", "2 % of gyro CSV cells 'inf'", "track",
              _file_case("gyro.csv", lambda b: csv_fields(b, 0.02, seed=4, value=b"inf"))),
    FaultCase("csv_empty", "5 % of gyro CSV cells empty", "track",
              _file_case("gyro.csv", lambda b: csv_fields(b, 0.05, seed=5))),
    FaultCase("nmea_empty_fields", "5 % of NMEA fields empty (valid checksums)", "track",
              _file_case("gps.nmea", lambda b: nmea_empty_fields(b, 0.05, seed=6))),
    FaultCase("first_fix_5m", "the first GNSS fix 5 m north of the truth", "track",
              _drive_case(lambda d: gnss_jump(d, 0.0, distance_m=5.0, bearing_deg=0.0,
                                              duration_s=0.1))),
    FaultCase("nmea_repeat", "every 7th NMEA line written twice", "track",
              _file_case("gps.nmea", lambda b: repeat_lines(b, 7, header_lines=0))),
    FaultCase("jump_100m", "GNSS fixes 100 m east for 1 s at 60 s", "track",
              _drive_case(lambda d: gnss_jump(d, 60.0, distance_m=100.0), (60.0, 1.0))),
    FaultCase("gyro_saturation", "gyro clips at 0.05 rad/s (2.9 deg/s)", "track",
              _drive_case(lambda d: gyro_saturation(d, 0.05))),
    FaultCase("odo_dropout", "no odometer records for 30 s", "track",
              _drive_case(lambda d: odo_dropout(d, 40.0, 30.0), (40.0, 30.0))),
    FaultCase("odo_zero", "odometer reads 0 m/s for 10 s while moving", "track",
              _drive_case(lambda d: odo_dropout(d, 40.0, 10.0, mode="zero"), (40.0, 10.0))),
    FaultCase("odo_spikes", "1 % of odometer readings 1000 m/s (glitches)", "track",
              _drive_case(lambda d: nan_values(d, "odo", 0.01, seed=4, value=1000.0))),
    FaultCase("gyro_spikes", "1 % of gyro readings 100 rad/s (glitches)", "track",
              _drive_case(lambda d: nan_values(d, "gyro", 0.01, seed=4, value=100.0))),
    FaultCase("odo_huge", "odometer readings of 1e308 m/s (corrupt numbers), the first before "
              "the first fix", "track",
              _drive_case(lambda d: gnss_outage(nan_values(d, "odo", 0.005, seed=5, value=1e308),
                                                0.0, 5.0), (0.0, 5.0))),
    FaultCase("gnss_speed_huge", "receiver speeds of 1.6e7 m/s (a corrupt RMC field)", "track",
              _drive_case(lambda d: nan_values(d, "gnss", 0.005, seed=6, value=1.6e7,
                                              field="speed_mps"))),
    FaultCase("odo_glitches", "1 % of odometer readings a random 0-40 m/s", "track",
              _drive_case(lambda d: random_values(d, "odo", 0.01, 0.0, 40.0, seed=9))),
    FaultCase("gyro_glitches", "1 % of gyro readings a random -8..8 rad/s", "track",
              _drive_case(lambda d: random_values(d, "gyro", 0.01, -8.0, 8.0, seed=10))),
    FaultCase("gnss_velocity_wrong", "5 % of receiver velocities a random speed (0-40 m/s) and "
              "course", "track", _drive_case(wrong_velocities)),
    FaultCase("no_odo", "GNSS and gyro, no odometer", "track", _subset_case(("gnss", "gyro"))),
    FaultCase("no_gyro", "GNSS and odometer, no gyro", "track", _subset_case(("gnss", "odo"))),
    FaultCase("no_gnss", "no GNSS and no origin configured", "error", _subset_case(("gyro", "odo"))),
    FaultCase("no_gnss_origin", "no GNSS, origin and heading configured (pure DR)", "track",
              _subset_case(("gyro", "odo"), _origin_config)),
    FaultCase("no_dr", "GNSS only (no gyro, no odometer)", "track", _subset_case(("gnss",))),
    FaultCase("midnight", "drive crosses UTC midnight 30 s in", "track",
              _midnight_case(30.0, None)),
    FaultCase("new_year", "drive crosses 2024-12-31/2025-01-01", "track",
              _midnight_case(30.0, "2024-12-31")),
    FaultCase("leap_day", "drive crosses 2024-02-28/29", "track",
              _midnight_case(30.0, "2024-02-28")),
    FaultCase("midnight_gga_date", "crosses midnight, GGA only (no RMC/ZDA), --date", "track",
              _midnight_case(30.0, None, drop=("RMC", "ZDA"), with_date=True)),
    FaultCase("midnight_gga_nodate", "crosses midnight, GGA only, no date given", "either",
              _midnight_case(30.0, None, drop=("RMC", "ZDA"))),
    FaultCase("mcap_clean", "the same drive as MCAP", "track", _mcap_case(lambda b: b)),
    FaultCase("mcap_trunc_99", "MCAP cut at 99 % (no summary, no footer)", "track",
              _mcap_case(lambda b: truncate(b, 0.99))),
    FaultCase("mcap_trunc_50", "MCAP cut at 50 %", "either", _mcap_case(lambda b: truncate(b, 0.5))),
    FaultCase("mcap_trunc_head", "MCAP cut after 40 bytes (magic + part of header)", "error",
              _mcap_case(lambda b: truncate(b, 40 / len(b)))),
    FaultCase("mcap_corrupt", "200 random bytes overwritten in the middle of the MCAP", "either",
              _mcap_case(lambda b: corrupt(b, 200, seed=8, start_frac=0.3, end_frac=0.7))),
    FaultCase("mcap_empty", "MCAP of 0 bytes", "error", _mcap_case(lambda b: b"")),
    FaultCase("ubx_clean", "the same drive as a UBX log (NAV-PVT, ESF-MEAS)", "track",
              _ubx_case(lambda b: b)),
    FaultCase("ubx_trunc_60", "UBX log cut at 60 % (inside a frame)", "either",
              _ubx_case(lambda b: truncate(b, 0.6))),
    FaultCase("bag_corrupt", "ROS 2 bag: 4 kB of its .db3 overwritten at 40 %", "either",
              _bag_case(lambda b: corrupt(b, 4096, seed=13, start_frac=0.4, end_frac=0.45))),
    FaultCase("nmea_garbage_lines", "50 binary garbage lines between NMEA sentences", "track",
              _file_case("gps.nmea", lambda b: insert_garbage(b, 50, seed=9, inside_lines=False))),
    FaultCase("nmea_garbage_inline", "50 binary chunks inside NMEA lines", "track",
              _file_case("gps.nmea", lambda b: insert_garbage(b, 50, seed=10))),
    FaultCase("nmea_all_garbage", "the NMEA file is 64 kB of random bytes", "error",
              _file_case("gps.nmea", lambda b: np.random.default_rng(12).integers(
                  0, 256, 65536, dtype=np.uint8).tobytes())),
    FaultCase("nmea_utf16", "the NMEA log saved as UTF-16 (little-endian, BOM)", "track",
              _file_case("gps.nmea", _utf16)),
    FaultCase("nmea_utf16_be_nobom", "the NMEA log as UTF-16 big-endian without a BOM", "track",
              _file_case("gps.nmea", lambda b: _utf16(b, bom=False, big_endian=True))),
    FaultCase("pos_clean", "the GNSS as an RTKLIB .pos (llh, GPST)", "track",
              _pos_case(lambda b: b)),
    FaultCase("pos_corrupt", "RTKLIB .pos with 300 random bytes overwritten", "track",
              _pos_case(lambda b: corrupt(b, 300, seed=13, start_frac=0.1, end_frac=0.9))),
    FaultCase("pos_truncated_head", "RTKLIB .pos cut inside its header", "error",
              _pos_case(lambda b: b[:150])),
)

CASES: dict[str, FaultCase] = {c.name: c for c in CATALOGUE}


def write_config(config: dict[str, dict[str, Any]], path: Any) -> list[str]:
    """Write parameter overrides as TOML; the ``--config`` arguments (none when empty)."""
    if not config:
        return []
    lines = []
    for section, values in config.items():
        lines.append(f"[{section}]")
        for k, v in values.items():
            lines.append(f"{k} = {v!r}" if not isinstance(v, str) else f'{k} = "{v}"')
    import pathlib

    pathlib.Path(path).write_text("\n".join(lines) + "\n", encoding="utf-8")
    return ["--config", str(path)]


def run_case(case: FaultCase, filter_name: str, out_dir: Any, sim: Any | None = None,
             *, subprocess_exe: str | None = None, smoother: str = ""
             ) -> tuple[CaseInputs, Outcome]:
    """Make the case's inputs in ``out_dir`` and run gpsdr on them with ``filter_name`` (and
    ``smoother``: rts | graph | none; empty: the default)."""
    import pathlib

    from .. import config as cfg

    out = pathlib.Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    inputs = case.make(sim, out)
    inputs.out_dir = out
    chosen = {"name": filter_name, **({"smoother": smoother} if smoother else {})}
    if inputs.drive is not None:
        params = cfg.merge(cfg.defaults(), {"filter": chosen, **inputs.config})
        return inputs, run_inmemory(inputs.drive, params)
    args = [*inputs.args, *write_config(inputs.config, out / "params.toml"),
            *(["--smooth", smoother] if smoother else [])]
    return inputs, run_cli(args, out, filter_name=filter_name, subprocess_exe=subprocess_exe)


def case_metrics(inputs: CaseInputs, outcome: Outcome, *, settle_s: float = 60.0
                 ) -> dict[str, float]:
    """Figures of a successful run against the truth (m), NaN where they do not apply.

    ``rmse_m``: whole track; ``focus_max_m``: largest error inside the fault's
    window; ``sigma_growth``: horizontal sigma at the window's last epoch over
    the one at its first; ``rejected``: fixes rejected inside the window;
    ``end_error_sigmas``: error at the window's last epoch over the horizontal
    sigma there (a consistent filter stays below ~3.7, the 99.9 % chi-square(2) radius);
    ``drift_m``: largest displacement of the track inside the window from its
    position ``settle_s`` after the window opens (a standstill's drift; the
    first minute at rest may still absorb the error the approach left).
    """
    nan = float("nan")
    m = {"rmse_m": nan, "focus_max_m": nan, "sigma_growth": nan, "rejected": nan,
         "drift_m": nan, "end_error_sigmas": nan}
    tr = outcome.track
    if tr is None or not len(tr) or track_problems(tr):
        return m
    err = horizontal_error_m(tr, inputs.sim.truth)
    m["rmse_m"] = float(np.sqrt(np.mean(err ** 2)))
    if inputs.focus_ns is None:
        return m
    t = track_t_ns(tr)
    lo, hi = inputs.focus_ns
    w = (t >= lo) & (t < hi)
    if not w.any():
        return m
    m["focus_max_m"] = float(err[w].max())
    sig = np.hypot(tr["sigma_e"].to_numpy(float), tr["sigma_n"].to_numpy(float))
    k = np.flatnonzero(w)
    m["sigma_growth"] = float(sig[k[-1]] / sig[k[0]]) if sig[k[0]] > 0 else nan
    m["end_error_sigmas"] = float(err[k[-1]] / sig[k[-1]]) if sig[k[-1]] > 0 else nan
    if "gnss_rejected" in tr:
        m["rejected"] = float(tr["gnss_rejected"].to_numpy(bool)[w].sum())
    settle = w & (t >= lo + round(settle_s * NS_PER_S))
    if settle.any():
        e, n = tr["e"].to_numpy(float), tr["n"].to_numpy(float)
        k0 = int(np.flatnonzero(settle)[0])
        m["drift_m"] = float(np.hypot(e[settle] - e[k0], n[settle] - n[k0]).max())
    return m


# --------------------------------------------------------------------------------------------
# Fuzzing: mutated files through the readers and through read_drive + fuse
# --------------------------------------------------------------------------------------------

#: Fuzz targets: which file is mutated and what runs on it.
FUZZ_TARGETS: tuple[str, ...] = ("nmea", "gyro_csv", "odo_csv", "mcap", "e2e_files", "e2e_mcap")
FUZZ_FILES = ("gps.nmea", "gyro.csv", "odo.csv", "drive.mcap", "raw.mcap")


def fuzz_seed_files(out_dir: Any, seed: int = 3, duration_s: float = 12.0) -> dict[str, bytes]:
    """Small valid inputs to mutate: a 12 s urban drive (GNSS 5 Hz, DR 10 Hz) as files
    (plus ``raw.mcap``, the MCAP uncompressed in small chunks); returns their bytes."""
    from ..simulate import simulate_drive, write_drive

    sim = simulate_drive("urban_canyon", seed, duration_s, gnss_rate_hz=5.0, gyro_rate_hz=10.0,
                         odo_rate_hz=10.0)
    paths = write_drive(sim, out_dir)
    raw = paths["drive.mcap"].with_name("raw.mcap")
    raw.write_bytes(mcap_uncompressed(paths["drive.mcap"].read_bytes()))
    paths["raw.mcap"] = raw
    return {name: paths[name].read_bytes() for name in FUZZ_FILES}


def mcap_uncompressed(data: bytes, chunk_size: int = 2048) -> bytes:
    """The same MCAP rewritten without compression in small chunks.

    Mutations of a zstd chunk mostly just fail its decompression; uncompressed
    small chunks let them reach the record and message parsers.
    """
    import io

    from mcap.reader import make_reader
    from mcap.writer import CompressionType, Writer

    out = io.BytesIO()
    w = Writer(out, chunk_size=chunk_size, compression=CompressionType.NONE)
    w.start(profile="ros2", library="gpsdr-fuzz")
    schemas: dict[int, int] = {}
    channels: dict[int, int] = {}
    for schema, channel, msg in make_reader(io.BytesIO(data)).iter_messages():
        if schema is not None and schema.id not in schemas:
            schemas[schema.id] = w.register_schema(schema.name, schema.encoding, schema.data)
        if channel.id not in channels:
            channels[channel.id] = w.register_channel(
                channel.topic, channel.message_encoding,
                schemas.get(channel.schema_id, 0), channel.metadata)
        w.add_message(channels[channel.id], msg.log_time, msg.data, msg.publish_time,
                      msg.sequence)
    w.finish()
    return out.getvalue()


def _where(err: BaseException) -> str:
    """``module:line`` of the innermost frame inside gpsdr_cli (where the escape happened)."""
    tb = err.__traceback__
    place = "?"
    while tb is not None:
        fname = tb.tb_frame.f_code.co_filename
        if "gpsdr_cli" in fname and "testing" not in fname:
            place = f"{fname.rsplit('gpsdr_cli', 1)[-1].lstrip('/')}:{tb.tb_lineno}"
        tb = tb.tb_next
    return place


def fuzz_case(target: str, seeds: dict[str, bytes], rng: np.random.Generator, work_dir: Any,
              params: dict | None = None, filter_name: str | None = None) -> tuple[str, dict[str, bytes]]:
    """Run one fuzz case; return its outcome key and the mutated files.

    Keys: ``ok``, ``ok:empty`` (reader returned no records), ``gpsdr:<Class>``
    (a GpsdrError: the contract's clean failure), ``nan:<problem>`` (a
    successful fuse whose track breaks :func:`track_problems`: a bug) and
    ``escape:<Class>@<module:line>`` (any other exception: a bug).
    """
    import pathlib

    from .. import config as cfg
    from ..errors import GpsdrError

    work = pathlib.Path(work_dir)
    params = cfg.defaults() if params is None else params
    files = dict(seeds)
    if target == "nmea":
        names = ["gps.nmea"]
    elif target == "gyro_csv":
        names = ["gyro.csv"]
    elif target == "odo_csv":
        names = ["odo.csv"]
    elif target in ("mcap", "e2e_mcap"):
        names = ["drive.mcap" if rng.random() < 0.3 else "raw.mcap"]
    elif target == "e2e_files":
        k = int(rng.integers(1, 4))
        names = list(rng.choice(["gps.nmea", "gyro.csv", "odo.csv"], k, replace=False))
    else:
        raise ValueError(f"unknown fuzz target {target!r}")
    for name in names:
        data = mutate(files[name], rng)
        if name == "gps.nmea" and rng.random() < 0.5:
            data = nmea_fix_checksums(data)  # let mutated fields reach the field parsers
        files[name] = data
    written = {}
    for name in FUZZ_FILES:
        p = work / name
        p.write_bytes(files[name])
        written[name] = p
    try:
        if target == "nmea":
            from ..io.nmea import parse_nmea

            fixes, _, _ = parse_nmea(files["gps.nmea"], name=str(written["gps.nmea"]))
            return ("ok" if len(fixes) else "ok:empty"), files
        if target == "gyro_csv":
            from ..io.csv import read_gyro_csv

            d = read_gyro_csv(written["gyro.csv"], params["gyro"])
            return ("ok" if d.gyro is not None and len(d.gyro) else "ok:empty"), files
        if target == "odo_csv":
            from ..io.csv import read_odo_csv

            d = read_odo_csv(written["odo.csv"], params["odo"])
            return ("ok" if d.odo is not None and len(d.odo) else "ok:empty"), files
        if target == "mcap":
            from ..io.mcap import read_mcap

            read_mcap(written[names[0]])
            return "ok", files
        from ..io.readers import read_drive
        from ..pipeline import fuse

        p = cfg.merge(params, {"filter": {"name": filter_name}}) if filter_name else params
        if target == "e2e_mcap":
            drive = read_drive(written[names[0]], params=p)
        else:
            drive = read_drive(gps=written["gps.nmea"], gyro=written["gyro.csv"],
                               odo=written["odo.csv"], params=p)
        res = fuse(drive, p)
        problems = track_problems(res.track, n_epochs=len(res.epochs))
        if problems:
            return "nan:" + problems[0].split(":")[0], files
        return "ok", files
    except GpsdrError as err:
        if type(err).__name__ == "NonFiniteOutputError":
            return f"nan:NonFiniteOutputError@{_where(err)}", files
        return f"gpsdr:{type(err).__name__}", files
    except Exception as err:  # noqa: BLE001 - anything else escaping is the bug we look for
        return f"escape:{type(err).__name__}@{_where(err)}", files


def is_bug(outcome_key: str) -> bool:
    """An escape or a NaN/invalid track: what the contract forbids."""
    return outcome_key.startswith(("escape:", "nan:"))


#: RMSE bound against the truth (m) of a fault's whole track; the default holds for the
#: open-sky base drive with GNSS almost throughout (clean: ~1 m; a GNSS clock stepping 2 s
#: back is re-stamped by the dead reckoning, clock_check.gnss_clock_steps).  Larger where the
#: fault itself forbids it: no GNSS at all (120 s of DR); long outages are bounded inside the
#: outage by dr_bound_m instead.
DEFAULT_RMSE_BOUND_M = 5.0
RMSE_BOUND_M: dict[str, float] = {"no_gnss_origin": 250.0,
                                  "outage_60s": math.inf, "outage_10min": math.inf,
                                  "standstill_30min_nognss": 10.0,
                                  # followed, they took 300-s drives to 8-180 m
                                  "gnss_velocity_wrong": 1.5,
                                  # ekf/aekf 8-86 m on 300-s drives with 0.5 %
                                  "odo_glitches": 1.5, "gyro_glitches": 1.5}
#: 99.9 % radius of a chi-square(2) error, in sigmas: a consistent covariance stays inside it.
CONSISTENT_SIGMAS = 3.7
#: A standstill may drift this much (m) over the stop.
STANDSTILL_DRIFT_M = 1.0
#: Within a fault window, the largest error while 100 m GNSS jumps are present (m).
JUMP_MAX_ERROR_M = 5.0


def dr_bound_m(inputs: CaseInputs) -> float:
    """5 m + 10 % of the distance driven in the fault window (a common dead-reckoning spec)."""
    tr = inputs.sim.truth
    t = tr["t_ns"].to_numpy(np.int64)
    lo, hi = inputs.focus_ns
    w = (t >= lo) & (t < hi)
    dist_m = float(np.sum(tr["speed"].to_numpy(float)[w]) * _median_dt_ns(t) / NS_PER_S)
    return 5.0 + 0.1 * dist_m


def accuracy_problems(case: FaultCase, inputs: CaseInputs, outcome: Outcome) -> list[str]:
    """What a successful run of ``case`` gets wrong against the truth (empty when fine).

    Every track fault: RMSE under :data:`RMSE_BOUND_M`.  Outages: horizontal sigma
    larger at the end than at the start, forward (a stop inside the outage may trim it
    through the zero-velocity update; the consistency check judges that); largest error
    under :func:`dr_bound_m`; end error within
    :data:`CONSISTENT_SIGMAS`.  Jumps: every displaced fix rejected, error under
    :data:`JUMP_MAX_ERROR_M`.  Standstills: drift under :data:`STANDSTILL_DRIFT_M`.
    """
    if outcome.status != 0 or outcome.track is None or track_problems(outcome.track):
        return []
    m = case_metrics(inputs, outcome)
    out: list[str] = []
    bound = RMSE_BOUND_M.get(case.name, DEFAULT_RMSE_BOUND_M)
    if case.expect == "track" and not m["rmse_m"] < bound:
        out.append(f"rmse {m['rmse_m']:.1f} m > {bound} m")
    if inputs.focus_ns is None:
        return out
    tr = outcome.track
    t = track_t_ns(tr)
    lo, hi = inputs.focus_ns
    w = (t >= lo) & (t < hi)
    if case.name.startswith("outage"):
        sig = np.hypot(tr["sigma_e"].to_numpy(float), tr["sigma_n"].to_numpy(float))[w]
        # (a smoothed sigma need not grow: the fixes after the outage bound it too, and the
        # graph's is mostly the fixes' common error, which the dead reckoning carries across)
        if outcome.meta.get("smoothed") != "true" and not sig[-1] > sig[0]:
            out.append(f"sigma {sig[0]:.2f} -> {sig[-1]:.2f} m: no growth in the outage")
        b = dr_bound_m(inputs)
        if not m["focus_max_m"] < b:
            out.append(f"max error {m['focus_max_m']:.1f} m > {b:.1f} m in the outage")
        if not m["end_error_sigmas"] < CONSISTENT_SIGMAS:
            out.append(f"end error {m['end_error_sigmas']:.1f} sigma (> {CONSISTENT_SIGMAS}):"
                       " covariance overconfident")
    elif case.name.startswith("jump"):
        g = inputs.sim.drive.gnss
        n_jump = int(((g.t_ns >= lo) & (g.t_ns < hi)).sum())
        if not m["rejected"] >= n_jump:
            out.append(f"{m['rejected']:.0f} of {n_jump} jumped fixes rejected")
        if not m["focus_max_m"] < JUMP_MAX_ERROR_M:
            out.append(f"max error {m['focus_max_m']:.1f} m > {JUMP_MAX_ERROR_M} m at the jump")
    elif case.name.startswith("standstill") and not m["drift_m"] < STANDSTILL_DRIFT_M:
        out.append(f"drift {m['drift_m']:.2f} m > {STANDSTILL_DRIFT_M} m over the stop")
    return out
