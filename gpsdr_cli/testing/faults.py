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
    return {"gyro": "yaw_rate_radps", "odo": "speed_mps", "gnss": "lat_deg"}[name]


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


def nan_values(drive: Drive, stream: str, fraction: float, *, seed: int = 0,
               value: float = np.nan) -> Drive:
    """A random ``fraction`` of a stream's values replaced by ``value`` (NaN, or inf)."""
    out = copy_drive(drive)
    s = getattr(out, stream)
    if s is None:
        return out
    rng = np.random.default_rng(seed)
    m = rng.random(len(s)) < fraction
    getattr(s, _value_field(stream))[m] = value
    if stream == "gnss":
        s.lon_deg[m] = value
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
                      gnss_sd_m: float = 1.5, gyro_bias_radps: float = 0.003,
                      gyro_sd_radps: float = 0.0017453, seed: int = 0) -> tuple[Any, int]:
    """Insert a stop of ``duration_s`` seconds into a simulated drive.

    The stop begins at the truth epoch of lowest speed within ``search_s`` of
    ``at_s``; everything after it (every stream and the truth) moves later by
    ``duration_s``.  During the stop: truth holds position with zero velocity;
    the odometer reads exactly 0 m/s; the gyro reads its bias plus white noise
    (rad/s); GNSS (when ``gnss``) gives fixes scattered ``gnss_sd_m`` (1-sigma per
    axis) around the true position, else nothing (a parking garage).
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
            add = YawRates(times, gyro_bias_radps + rng.normal(0.0, gyro_sd_radps, n))
        else:
            add = Odometry(times, np.zeros(n))
        setattr(out, name, concat(s, add))
    return with_drive(sim, out, new_truth), t_stop


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
            tv = t.to_numpy().astype("datetime64[ns]").astype(np.int64)
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
    return track["time"].to_numpy().astype("datetime64[ns]").astype(np.int64)


def nmea_fix_checksums(data: bytes) -> bytes:
    """Every ``$...*hh`` sentence given its correct checksum (so fuzzed fields reach the parser)."""
    return nmea_map_sentences(data, lambda f: f)
