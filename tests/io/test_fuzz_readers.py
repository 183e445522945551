"""Property tests: random and mutated CSV text and MCAP bytes never let anything but
gpsdr's own errors escape, and what is read is finite and consistent."""

from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from gpsdr_cli import config
from gpsdr_cli.errors import GpsdrError
from gpsdr_cli.io import ros2_fast
from gpsdr_cli.io.csv import read_gyro_csv, read_odo_csv
from gpsdr_cli.io.mcap import read_mcap
from gpsdr_cli.io.readers import sniff

SMALL_MCAP = Path(__file__).resolve().parents[1] / "data" / "mcap" / "small_drive.mcap"
MCAP_BYTES = SMALL_MCAP.read_bytes()
P = config.defaults()
# GPSDR_FUZZ_EXAMPLES=5000 for a longer hunt
SETTINGS = settings(max_examples=int(os.environ.get("GPSDR_FUZZ_EXAMPLES", "150")), deadline=None,
                    suppress_health_check=[HealthCheck.function_scoped_fixture])

_field = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.integers(-10**20, 10**20).map(str),
    st.text(alphabet=st.characters(codec="utf-8", exclude_categories=("Cs",)), max_size=8),
    st.sampled_from(["", "nan", "-inf", "1e400", "1.5e9", "1700000000.0000000001", '"3"', " 2 "]),
)
_row = st.lists(_field, min_size=0, max_size=4).map(lambda fs: ",".join(fs))


def _write(data: bytes, suffix: str) -> Path:
    with tempfile.NamedTemporaryFile(suffix=suffix, delete=False) as f:
        f.write(data)
    return Path(f.name)


def _check_finite(drive) -> None:
    for stream, value in (("gyro", "yaw_rate_radps"), ("odo", "speed_mps")):
        s = getattr(drive, stream)
        if s is not None:
            assert s.t_ns.dtype == np.int64 and len(s.t_ns) == len(getattr(s, value))
            assert np.all(np.isfinite(getattr(s, value)))


@SETTINGS
@given(header=st.sampled_from(["t,yaw_rate", "t,speed", "t,distance", "t,ticks", "yaw_rate,t,x", "t"]),
       rows=st.lists(_row, max_size=30), newline=st.sampled_from(["\n", "\r\n"]))
def test_random_csv_rows(header, rows, newline):
    path = _write((newline.join([header, *rows]) + newline).encode("utf-8", "surrogatepass"), ".csv")
    try:
        for read, section in ((read_gyro_csv, "gyro"), (read_odo_csv, "odo")):
            opts = {**P[section], "ticks_per_m": 10.0}
            try:
                drive = read(path, opts)
            except GpsdrError as err:
                assert str(path) in str(err)
                continue
            _check_finite(drive)
            # every data row is either read or skipped-and-counted, exactly once
            n_rows = drive.meta[f"{section}_csv"]["rows"]
            n_out = len(drive.gyro if section == "gyro" else drive.odo)
            assert n_out + drive.skipped.total == n_rows
    finally:
        path.unlink()


@SETTINGS
@given(data=st.binary(max_size=400))
def test_random_bytes_everywhere(data):
    path = _write(data, ".bin")
    try:
        for fn in (sniff, lambda p: read_gyro_csv(p, P["gyro"]), lambda p: read_odo_csv(p, P["odo"]),
                   read_mcap):
            try:
                fn(path)
            except GpsdrError:
                pass
    finally:
        path.unlink()


@SETTINGS
@given(cut=st.integers(0, len(MCAP_BYTES)),
       flips=st.lists(st.tuples(st.integers(0, len(MCAP_BYTES) - 1), st.integers(1, 255)), max_size=6))
def test_truncated_and_bit_flipped_mcap(cut, flips):
    raw = bytearray(MCAP_BYTES)
    for pos, mask in flips:
        raw[pos] ^= mask
    path = _write(bytes(raw[:cut]), ".mcap")
    try:
        try:
            drive = read_mcap(path)
        except GpsdrError as err:
            assert str(path) in str(err)
            return
        _check_finite(drive)
        g = drive.gnss
        if g is not None:
            ok = g.fix_quality > 0
            assert np.all(np.abs(g.lat_deg[ok]) <= 90) and np.all(np.abs(g.lon_deg[ok]) <= 180)
            assert not np.any(np.isinf(g.sigma_e_m))
        if cut == len(MCAP_BYTES) and not flips:
            assert "warnings" not in drive.meta and len(drive.gyro) == 100
        else:  # damage may go unnoticed (a flipped float is valid data), but only ever shrinks
            assert drive.gyro is None or len(drive.gyro) <= 100
    finally:
        path.unlink()


@SETTINGS
@given(layout=st.sampled_from(sorted(ros2_fast.SCHEMAS)), junk=st.binary(max_size=200),
       cut=st.integers(0, 400), ros1=st.booleans())
def test_fast_path_never_reads_out_of_bounds(layout, junk, cut, ros1):
    good = ros2_fast.encode(layout, 1_700_000_000_000_000_000, "gps", ros1=ros1, lat=1.0, lon=2.0,
                            wz=0.1, vx=1.0, text="$GPGGA")
    msgs = [junk, good[:cut], junk + good]
    blob = b"".join(msgs)
    sizes = np.array([len(m) for m in msgs])
    offs = np.concatenate([[0], np.cumsum(sizes)[:-1]])
    fields, ok = ros2_fast.decode(layout, np.frombuffer(blob, np.uint8), offs, sizes, ros1=ros1)
    assert ok[1] == (cut >= len(good))
    if ok[1]:
        assert fields["stamp_ns"][1] == 1_700_000_000_000_000_000


_PAYLOAD_SCHEMAS = {
    "loc:protobuf": ("foxglove.LocationFix", "protobuf", b""),
    "loc:json": ("foxglove.LocationFix", "jsonschema", b"{}"),
    "nav:json": ("sensor_msgs/msg/NavSatFix", "jsonschema", b"{}"),
}
_KEYS = sorted(ros2_fast.SCHEMAS) + sorted(_PAYLOAD_SCHEMAS)


@SETTINGS
@given(key=st.sampled_from(_KEYS),
       payloads=st.lists(st.one_of(
           st.binary(max_size=120),
           st.sampled_from([b"{}", b"[]", b"null", b'{"latitude": "x"}', b'{"header": 5}',
                            b'{"timestamp": {"sec": 1e300}}', b"\x00\x01\x00\x00" + b"\xff" * 40])),
           min_size=1, max_size=8))
def test_garbage_payloads_are_counted_not_raised(key, payloads):
    """Random message bodies on every decodable channel type (CDR fast path + generic
    decoder, JSON, protobuf): undecodable ones are counted, nothing else escapes."""
    from tests.io.test_mcap import write_mcap

    t0 = 1_700_000_000_000_000_000
    msgs = [(t0 + i, t0 + i, p) for i, p in enumerate(payloads)]
    path = _write(b"", ".mcap")
    try:
        write_mcap(path, [("/x", key, msgs)], schemas=_PAYLOAD_SCHEMAS)
        try:
            drive = read_mcap(path)
        except GpsdrError as err:
            assert str(path) in str(err)
            return
        _check_finite(drive)
        n = sum(len(s) for s in (drive.gnss, drive.gyro, drive.odo) if s is not None)
        assert n + drive.skipped.total >= 1
    finally:
        path.unlink()
