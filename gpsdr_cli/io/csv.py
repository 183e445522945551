"""Gyro, odometer and forward-accelerometer CSV readers.

Each file has a header row and one sample per line: a time column (UTC POSIX
seconds, or seconds relative to ``start_posix_s``) and one value column.  Units,
signs and time base follow :mod:`gpsdr_cli.conventions`: the gyro is converted
to rad/s positive counter-clockwise, the odometer (speed, distance per row or
cumulative ticks) to a forward speed in m/s, times to int64 ns.  A gyro CSV may
carry a second value column ``acc_x``: the forward specific force in m/s^2
(positive forward; an IMU row holds both), read into ``Drive.accel``; every row then
needs both values.  A separate accelerometer CSV has ``t,acc_x``
(:func:`read_accel_csv`) and shares the gyro's time options (one IMU clock).

Why two paths: ``pyarrow.csv`` parses a clean file at tens of millions of rows
per second, but it stops at the first non-numeric field and cannot say on which
line.  So a file is parsed by pyarrow first (the fast path); only when pyarrow
rejects it is it parsed again line by line with the standard ``csv`` module (the
slow path), which skips and counts every corrupt row with its first line number.

Times are parsed as decimal text, not as floats: ``pa.decimal128(., 9)`` holds
the time in integer nanoseconds exactly, so 1533226488.429536 becomes
1533226488429536000 ns without the ~240 ns quantisation of a float64.  Times
with more than 9 decimals are rounded (half to even) in the slow path.
"""

from __future__ import annotations

import csv as _stdcsv
import hashlib
import math
import re
from decimal import Decimal, InvalidOperation
from pathlib import Path
from typing import Any

import numpy as np

from ..conventions import NS_PER_S
from ..errors import ConfigError, InputError, NoDataError, UsageError
from .drive import Drive, ForwardAccel, Odometry, SkipReport, Source, YawRates

#: Header detection and the text checks shared with :func:`gpsdr_cli.io.readers.sniff`.
UTF8_BOM = b"\xef\xbb\xbf"
_NEWLINE_B = re.compile(rb"\r\n|\r|\n")
_NEWLINE = re.compile(r"\r\n|\r|\n")
_TIME_RANGE = "time beyond year 2262 (expected seconds, not ms/us/ns)"
_POSIX_PLAUSIBLE_S = 1.0e8  # 1973-03-03: earlier "POSIX" times are almost surely relative seconds


# --------------------------------------------------------------------------- file checks

def read_bytes(path: str | Path, limit: int | None = None) -> bytes:
    """The whole file (or its first ``limit`` bytes), or an :class:`InputError` naming it
    (missing, unreadable, a directory)."""
    try:
        if limit is None:
            return Path(path).read_bytes()
        with open(path, "rb") as f:
            return f.read(limit)
    except IsADirectoryError as err:
        raise InputError(path, "is a directory, expected a file") from err
    except FileNotFoundError as err:
        raise InputError(path, "no such file") from err
    except OSError as err:
        raise InputError(path, f"cannot read: {err.strerror or err}") from err


def text_problem(head: bytes) -> str | None:
    """Why ``head`` (the first bytes of a file) is not UTF-8/ASCII text, or None if it is."""
    if not head:
        return "empty file"
    if head.startswith((b"\xff\xfe", b"\xfe\xff")) or _looks_utf16(head[:4096]):
        return "UTF-16 text; save the file as UTF-8"
    if b"\x00" in head:
        return "binary data (NUL bytes), expected text"
    sample = head[:65536]
    try:
        sample.decode("utf-8")
    except UnicodeDecodeError as err:
        if err.start < len(sample) - 4:  # not just a multi-byte char cut by the sample end
            return f"not UTF-8 text (invalid byte 0x{sample[err.start]:02x} at offset {err.start})"
    return None


def _looks_utf16(head: bytes) -> bool:
    """BOM-less UTF-16 of mostly ASCII text: NULs in (nearly) every other byte only."""
    if len(head) < 8:
        return False
    odd, even = head[1::2], head[0::2]
    for zeros, other in ((odd, even), (even, odd)):
        if zeros.count(0) >= 0.9 * len(zeros) and other.count(0) <= 0.05 * len(other):
            return True
    return False


def _detect_delimiter(header: str) -> str:
    for d in (",", ";", "\t"):
        if d in header:
            return d
    return ","


def _parse_header(path: str | Path, data: bytes) -> tuple[list[str], str, int]:
    """Column names, delimiter and the byte offset where the data rows start."""
    for magic, kind in ((b"\x89MCAP", "an MCAP log"), (b"PAR1", "a Parquet file")):
        if data.startswith(magic):
            raise InputError(path, f"is {kind}, expected a CSV with a header row")
    problem = text_problem(data[:65536])
    if problem:
        raise InputError(path, problem)
    start = len(UTF8_BOM) if data.startswith(UTF8_BOM) else 0
    m = _NEWLINE_B.search(data, start)
    end, body = (m.start(), m.end()) if m else (len(data), len(data))
    header = data[start:end].decode("utf-8", errors="replace")
    if not header.strip():
        raise InputError(path, "first line is empty; expected a header row of column names", line=1)
    if header.lstrip().startswith(("$", "!")) and "*" in header:
        raise InputError(path, "looks like an NMEA log, expected a CSV with a header row", line=1)
    delim = _detect_delimiter(header)
    try:
        fields = next(_stdcsv.reader([header], delimiter=delim, strict=False), [])
    except _stdcsv.Error as err:
        raise InputError(path, f"unreadable header row: {err}", line=1) from err
    names = [n.strip().strip("\"'").strip() for n in fields]
    if all(_is_number(n) for n in names if n):
        raise InputError(path, f"no header row: first line is {header[:60]!r}; "
                         "expected column names such as t,yaw_rate", line=1)
    return names, delim, body


def _is_number(text: str) -> bool:
    try:
        float(text)
    except ValueError:
        return False
    return True


def _seconds_to_ns(value: float) -> int:
    """A float of seconds (e.g. a config value) to int ns, via its shortest decimal repr."""
    return int(Decimal(repr(float(value))).scaleb(9).to_integral_value())


def _text_to_ns(text: str) -> int | None:
    """Decimal seconds text to int ns, rounded half to even; None if not a finite number.

    Raises OverflowError beyond int64 ns (year 2262: ms/us/ns stamps read as seconds)."""
    try:
        d = Decimal(text.strip())
    except InvalidOperation:
        return None
    if not d.is_finite():
        return None
    if d and d.adjusted() > 12:  # beyond int64 ns; checked first: scaleb would raise decimal.Overflow
        raise OverflowError(text)
    ns = d.scaleb(9).to_integral_value()
    if abs(ns) >= 2**63:
        raise OverflowError(text)
    return int(ns)


# --------------------------------------------------------------------------- table reading

def _missing_column(path: str | Path, names: list[str], column: str, option: str) -> InputError:
    found = ", ".join(n for n in names if n) or "(none)"
    return InputError(path, f"no column {column!r} (columns found: {found}); "
                      f"set {option} to the column to use", line=1)


def _read_table(path: str | Path, data: bytes, t_column: str, columns: list[str],
                options: list[str], skipped: SkipReport
                ) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray, dict[str, Any]]:
    """Times (int64 ns, as written), float64 value columns and each kept row's line number.

    Every row with an empty, non-numeric or non-finite value in any used column, a
    wrong field count, or an empty line is dropped and counted in ``skipped``.
    ``options`` names the option that sets each of ``[t_column, *columns]`` (for
    the message when a column is missing).
    """
    names, delim, body = _parse_header(path, data)
    for col, option in zip([t_column, *columns], options, strict=False):
        if col not in names:
            raise _missing_column(path, names, col, option)
    info: dict[str, Any] = {"columns": names, "delimiter": delim}
    try:
        t_ns, values, lines, n_rows = _fast_path(data, body, names, delim, t_column, columns,
                                                 path, skipped)
        info["parser"] = "pyarrow"
    except _FastPathFailed:
        t_ns, values, lines, n_rows = _slow_path(data, body, names, delim, t_column, columns,
                                                 path, skipped)
        info["parser"] = "line-by-line"
    info["rows"] = n_rows
    return t_ns, values, lines, info


#: An exponent of four or more digits: no real time stamp or sensor value has one.
_LONG_EXPONENT = re.compile(rb"[eE][+-]?0*[0-9]{4,}")


class _FastPathFailed(Exception):
    """pyarrow rejected the file; parse it line by line instead."""


def _fast_path(data: bytes, body: int, names: list[str], delim: str, t_column: str,
               columns: list[str], path: str | Path,
               skipped: SkipReport) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray, int]:
    import pyarrow as pa
    import pyarrow.csv as pacsv

    if len(set(names)) != len(names) or any(not n for n in names):
        raise _FastPathFailed  # pyarrow needs unique, non-empty names
    if body >= len(data):
        return np.zeros(0, np.int64), {c: np.zeros(0) for c in columns}, np.zeros(0, np.int64), 0
    # the byte searches run at memchr speed; the regex (~7 ms per MB) only when one hits
    if (data.find(b"e", body) >= 0 or data.find(b"E", body) >= 0) \
            and _LONG_EXPONENT.search(data, body):
        # pyarrow 26's decimal128 parser crashes the process (SIGSEGV) on exponents such as
        # 1e-320100000; the line-by-line path handles them as out-of-range values.
        raise _FastPathFailed
    types = {t_column: pa.decimal128(28, 9)}
    types.update({c: pa.float64() for c in columns})
    try:
        # One thread: pyarrow's worker threads allocate from their own malloc arenas, whose
        # freed pages numpy's (main-thread) arrays cannot reuse; that held ~20 MB of a
        # one-hour drive's peak RSS, for a parse that takes ~0.05 s on one core.
        table = pacsv.read_csv(
            pa.BufferReader(data),
            read_options=pacsv.ReadOptions(column_names=names, skip_rows=1, block_size=1 << 22,
                                          use_threads=False),
            parse_options=pacsv.ParseOptions(delimiter=delim, ignore_empty_lines=False,
                                             newlines_in_values=False),
            convert_options=pacsv.ConvertOptions(column_types=types,
                                                 include_columns=[t_column, *columns]),
        )
    except (pa.ArrowInvalid, pa.ArrowNotImplementedError, pa.ArrowTypeError) as err:
        raise _FastPathFailed from err
    n = table.num_rows
    tcol = table.column(t_column).combine_chunks()
    # decimal128(., 9) stores value x 1e9 as a 128-bit integer: its low 64 bits are the ns.
    raw = np.frombuffer(tcol.buffers()[1], dtype=np.int64)
    hi = raw[1::2][tcol.offset:tcol.offset + n]
    t_ns = raw[0::2][tcol.offset:tcol.offset + n].copy()
    ok = tcol.is_valid().to_numpy(zero_copy_only=False)
    # Values beyond int64 ns (year 2262) have a high word that is not the low word's sign.
    over = ok & (hi != (t_ns >> 63))
    if over.any():
        skipped.add(_TIME_RANGE, f"{path}:{int(np.flatnonzero(over)[0]) + 2}", int(over.sum()))
    ok &= ~over
    values = {}
    all_null = ~tcol.is_valid().to_numpy(zero_copy_only=False)
    for c in columns:
        col = table.column(c)
        v = col.to_numpy().astype(np.float64, copy=False) if col.null_count == 0 else \
            col.to_numpy(zero_copy_only=False).astype(np.float64)
        valid = np.isfinite(v)
        all_null &= col.is_null().to_numpy(zero_copy_only=False)
        ok &= valid
        values[c] = v
    if not ok.all():
        bad = np.flatnonzero(~ok)
        empty = bad[all_null[bad]]
        other = bad[~all_null[bad]]
        if len(empty):
            skipped.add("empty line", f"{path}:{int(empty[0]) + 2}", len(empty))
        other = other[~over[other]]
        if len(other):
            skipped.add("missing, non-numeric or non-finite value", f"{path}:{int(other[0]) + 2}",
                        len(other))
        t_ns = t_ns[ok]
        values = {c: v[ok] for c, v in values.items()}
        return t_ns, values, np.flatnonzero(ok) + 2, n
    return t_ns, values, np.arange(2, n + 2, dtype=np.int64), n


def _slow_path(data: bytes, body: int, names: list[str], delim: str, t_column: str,
               columns: list[str], path: str | Path,
               skipped: SkipReport) -> tuple[np.ndarray, dict[str, np.ndarray], np.ndarray, int]:
    text = data[body:].decode("utf-8", errors="replace")
    n_fields = len(names)
    ti = names.index(t_column)
    cis = [names.index(c) for c in columns]
    t_out: list[int] = []
    line_out: list[int] = []
    v_out: list[list[float]] = [[] for _ in columns]
    n_rows = 0
    lines = _NEWLINE.split(text)  # the newlines pyarrow knows: \n, \r\n and a lone \r
    if lines and lines[-1] == "":
        lines.pop()  # the newline that ends the last row
    reader = _stdcsv.reader
    for lineno, line in enumerate(lines, start=2):
        n_rows += 1
        where = f"{path}:{lineno}"
        if "\x00" in line:
            skipped.add("NUL byte in a line", where)
            continue
        # One reader per line: an unbalanced quote cannot swallow the following lines.
        row = next(reader([line], delimiter=delim, strict=False), [])
        if not row or (len(row) == 1 and not row[0].strip()):
            skipped.add("empty line", where)
            continue
        if len(row) != n_fields:
            skipped.add(f"wrong field count (expected {n_fields})", where)
            continue
        try:
            t = _text_to_ns(row[ti])
        except OverflowError:
            skipped.add(_TIME_RANGE, where)
            continue
        if t is None:
            skipped.add("missing, non-numeric or non-finite value", where)
            continue
        vals = []
        for ci in cis:
            try:
                x = float(row[ci])
            except ValueError:
                x = math.nan
            if not math.isfinite(x):
                break
            vals.append(x)
        if len(vals) != len(cis):
            skipped.add("missing, non-numeric or non-finite value", where)
            continue
        t_out.append(t)
        line_out.append(lineno)
        for lst, x in zip(v_out, vals, strict=False):
            lst.append(x)
    t_ns = np.array(t_out, dtype=np.int64)
    return (t_ns, {c: np.array(v, dtype=np.float64) for c, v in zip(columns, v_out, strict=False)},
            np.array(line_out, dtype=np.int64), n_rows)


# --------------------------------------------------------------------------- options

def _opt(opts: dict, key: str, default: Any) -> Any:
    return opts.get(key, default)


def _choice(opts: dict, section: str, key: str, default: str, allowed: tuple[str, ...]) -> str:
    value = str(_opt(opts, key, default))
    if value not in allowed:
        raise ConfigError(f"{section}.{key} = {value!r}: expected one of {', '.join(allowed)}")
    return value


def _apply_time(path: str | Path, t_ns: np.ndarray, opts: dict, section: str,
                warnings: list[str]) -> np.ndarray:
    mode = _choice(opts, section, "time", "posix", ("posix", "relative"))
    if mode == "relative":
        start = float(_opt(opts, "start_posix_s", 0.0))
        if not math.isfinite(start):
            raise ConfigError(f"{section}.start_posix_s = {start!r}: expected a finite number")
        if start == 0.0:
            warnings.append(f"{path}: {section}.time = \"relative\" with {section}.start_posix_s = 0: "
                            "times fall in 1970 and will not line up with GNSS time")
        return t_ns + np.int64(_seconds_to_ns(start))
    if len(t_ns) and int(t_ns.max()) < _POSIX_PLAUSIBLE_S * NS_PER_S:
        warnings.append(f"{path}: times end at {t_ns.max() / NS_PER_S:.3f} s, before 1973: "
                        f"relative seconds? then set {section}.time = \"relative\" and "
                        f"{section}.start_posix_s")
    return t_ns


def _source(path: str | Path, data: bytes, stream: str) -> Source:
    return Source(str(path), hashlib.sha256(data).hexdigest(), (stream,))


# --------------------------------------------------------------------------- public readers

def read_gyro_csv(path: str | Path, opts: dict) -> Drive:
    """Read a gyro CSV (``params["gyro"]``) into ``Drive.gyro`` (rad/s, CCW-positive)."""
    t_column = str(_opt(opts, "t_column", "t"))
    column = str(_opt(opts, "column", "yaw_rate"))
    units = _choice(opts, "gyro", "units", "rad/s", ("rad/s", "deg/s"))
    sign = _choice(opts, "gyro", "sign", "ccw", ("ccw", "cw"))
    data = read_bytes(path)
    skipped = SkipReport()
    names, _, _ = _parse_header(path, data)
    accel_column = ACCEL_COLUMN if ACCEL_COLUMN in names and ACCEL_COLUMN != column else ""
    columns = [column, accel_column] if accel_column else [column]
    t_ns, values, _, info = _read_table(path, data, t_column, columns,
                                        ["gyro.t_column", "gyro.column", ACCEL_COLUMN], skipped)
    warnings: list[str] = []
    t_ns = _apply_time(path, t_ns, opts, "gyro", warnings)
    rate = values[column]
    if units == "deg/s":
        rate = np.deg2rad(rate)
    if sign == "cw":
        rate = -rate  # charter: CCW-positive seen from above
    _require_rows(path, t_ns, "gyro", info, skipped)
    info.update(units=units, sign=sign)
    stream = YawRates(t_ns=t_ns, yaw_rate_radps=np.ascontiguousarray(rate, np.float64))
    drive = _drive(path, data, "gyro", stream, skipped, info, warnings)
    if accel_column:
        drive.accel = ForwardAccel(t_ns=t_ns.copy(), accel_mps2=np.ascontiguousarray(
            values[accel_column], np.float64))
        drive.sources[0].streams = ("gyro", "accel")
        info["accel_column"] = accel_column
    return drive


#: the forward accelerometer's column, in a gyro CSV or an accelerometer CSV (m/s^2)
ACCEL_COLUMN = "acc_x"


def read_accel_csv(path: str | Path, opts: dict) -> Drive:
    """Read a forward-accelerometer CSV (``t,acc_x``, m/s^2 positive forward; time options
    from ``opts``, the gyro's section: one IMU clock) into ``Drive.accel``."""
    t_column = str(_opt(opts, "t_column", "t"))
    data = read_bytes(path)
    names, _, _ = _parse_header(path, data)
    if ACCEL_COLUMN not in names:
        found = ", ".join(n for n in names if n) or "(none)"
        raise InputError(path, f"no column {ACCEL_COLUMN!r} (columns found: {found}); expected "
                         f"t,{ACCEL_COLUMN} with the forward acceleration in m/s^2", line=1)
    skipped = SkipReport()
    t_ns, values, _, info = _read_table(path, data, t_column, [ACCEL_COLUMN],
                                        ["gyro.t_column", ACCEL_COLUMN], skipped)
    warnings: list[str] = []
    t_ns = _apply_time(path, t_ns, opts, "gyro", warnings)
    _require_rows(path, t_ns, "accelerometer", info, skipped)
    stream = ForwardAccel(t_ns=t_ns, accel_mps2=np.ascontiguousarray(values[ACCEL_COLUMN],
                                                                     np.float64))
    return _drive(path, data, "accel", stream, skipped, info, warnings)


_ODO_KINDS = ("speed", "distance", "ticks")


def read_odo_csv(path: str | Path, opts: dict) -> Drive:
    """Read an odometer CSV (``params["odo"]``) into ``Drive.odo`` (forward speed, m/s).

    ``speed``: m/s as is.  ``distance``: metres since the previous row, speed =
    distance / dt; a distance column that is the odometer's running total (it never
    decreases and per row would be faster than any vehicle) is read as such, speed =
    d(distance) / dt, with a warning.  ``ticks``: a cumulative count, speed =
    d(ticks) / ticks_per_m / dt.
    For distance and ticks the first row has no previous row: it is dropped and
    counted, as are rows whose time does not increase.
    """
    t_column = str(_opt(opts, "t_column", "t"))
    kind = _choice(opts, "odo", "kind", "auto", ("auto", *_ODO_KINDS))
    column = str(_opt(opts, "column", "") or "")
    data = read_bytes(path)
    if kind == "auto":
        if column:
            if column not in _ODO_KINDS:
                raise UsageError(f"{path}: odo.column = {column!r} with odo.kind = \"auto\": "
                                 "set odo.kind to speed, distance or ticks")
            kind = column
        else:
            names, _, _ = _parse_header(path, data)
            kind = next((k for k in _ODO_KINDS if k in names), "")
            if not kind:
                found = ", ".join(n for n in names if n) or "(none)"
                raise InputError(path, f"no speed, distance or ticks column (columns found: {found}); "
                                 "set odo.kind and odo.column", line=1)
    column = column or kind
    ticks_per_m = float(_opt(opts, "ticks_per_m", 0.0))
    if kind == "ticks" and not (math.isfinite(ticks_per_m) and ticks_per_m > 0):
        raise UsageError(f"{path}: odometer ticks need odo.ticks_per_m > 0 "
                         f"(got {ticks_per_m!r})")
    skipped = SkipReport()
    t_ns, values, lines, info = _read_table(path, data, t_column, [column],
                                            ["odo.t_column", "odo.column"], skipped)
    warnings: list[str] = []
    t_ns = _apply_time(path, t_ns, opts, "odo", warnings)
    v = values[column]
    cumulative = 0.0
    if kind == "speed":
        speed = v
    else:
        if len(t_ns):
            skipped.add(f"first row of a {kind} odometer (no previous row)", f"{path}:{lines[0]}")
        dt_s = np.diff(t_ns).astype(np.float64) / NS_PER_S
        cumulative = kind == "distance" and _cumulative_distance(v, dt_s)
        if cumulative:
            warnings.append(f"{path}: the {column!r} column never decreases and, read as "
                            f"metres per row, gives {cumulative:.0f} m/s: read as the "
                            "odometer's total (cumulative metres), speed = its step / dt")
        step = v[1:] if kind == "distance" and not cumulative else (
            np.diff(v) if cumulative else np.diff(v) / ticks_per_m)
        good = dt_s > 0
        if not good.all():
            first = int(np.flatnonzero(~good)[0])
            skipped.add("time not increasing (distance/ticks need dt > 0)",
                        f"{path}:{lines[first + 1]}", int((~good).sum()))
        if kind == "distance" and not cumulative:
            # After a skipped line the distance covers an unknown part of dt: drop it.
            # (Cumulative ticks need no such care: their difference spans the same dt.)
            after_gap = good & (np.diff(lines) > 1)
            if after_gap.any():
                skipped.add("distance row after a skipped line (interval unknown)",
                            f"{path}:{lines[int(np.flatnonzero(after_gap)[0]) + 1]}",
                            int(after_gap.sum()))
                good &= ~after_gap
        t_ns = t_ns[1:][good]
        speed = step[good] / dt_s[good]
    _require_rows(path, t_ns, "odometer", info, skipped)
    info.update(kind="distance (cumulative)" if kind == "distance" and cumulative else kind,
                column=column)
    stream = Odometry(t_ns=t_ns, speed_mps=np.ascontiguousarray(speed, np.float64))
    return _drive(path, data, "odo", stream, skipped, info, warnings)


#: No vehicle odometer reads faster (m/s): a "distance" column whose rows divided by
#: their interval exceed it is the odometer's running total.
MAX_SPEED_MPS = 150.0


def _cumulative_distance(v: np.ndarray, dt_s: np.ndarray) -> float:
    """The median speed (m/s) a ``distance`` column gives read as metres per row, when
    that is impossible (over :data:`MAX_SPEED_MPS`) while its steps give a possible one
    and it never decreases (at most 1 % of the rows: a reversing vehicle): then it is a
    running total.  0.0 otherwise."""
    good = dt_s > 0
    if good.sum() < 10 or (np.diff(v) < 0).mean() > 0.01:
        return 0.0
    per_row = float(np.median(np.abs(v[1:][good]) / dt_s[good]))
    per_step = float(np.median(np.abs(np.diff(v)[good]) / dt_s[good]))
    return per_row if per_row > MAX_SPEED_MPS >= per_step else 0.0


def _require_rows(path: str | Path, t_ns: np.ndarray, what: str, info: dict,
                  skipped: SkipReport) -> None:
    if len(t_ns) == 0:
        raise NoDataError(path, f"no usable {what} rows ({info['rows']} rows, "
                          f"{skipped.total} skipped; first: {_first_skip(skipped)})")


def _drive(path: str | Path, data: bytes, name: str, stream: YawRates | Odometry | ForwardAccel,
           skipped: SkipReport, info: dict, warnings: list[str]) -> Drive:
    """The reader's Drive: ``stream`` as ``drive.<name>``, its report, source and meta."""
    drive = Drive(skipped=skipped, sources=[_source(path, data, name)],
                  meta={f"{name}_csv": info})
    setattr(drive, name, stream)
    if warnings:
        drive.meta["warnings"] = warnings
    return drive


def _first_skip(skipped: SkipReport) -> str:
    if not skipped.counts:
        return "none"
    reason = next(iter(skipped.counts))
    return f"{reason} at {skipped.first.get(reason, '?')}"
