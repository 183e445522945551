"""A GGA-only NMEA log (no RMC/ZDA: no date) with gyro/odometer CSVs: the UTC date comes
from the CSVs' POSIX stamps (:func:`gpsdr_cli.io.readers.read_drive`), with a warning,
instead of the old "pass --date" failure; alone it still asks for --date."""

from __future__ import annotations

import datetime as dt
import functools
import operator

import pytest

from gpsdr_cli import config
from gpsdr_cli.conventions import NS_PER_S
from gpsdr_cli.errors import MissingDateError
from gpsdr_cli.io.readers import read_drive


def _nmea(body: str) -> str:
    return f"${body}*{functools.reduce(operator.xor, body.encode(), 0):02X}\n"


def _gga(hhmmss: str) -> str:
    return _nmea(f"GPGGA,{hhmmss}.00,4807.038,N,01131.000,E,1,08,0.9,545.4,M,46.9,M,,")


def _files(tmp_path, gga_times: list[str], gyro_start_s: float) -> tuple[str, str]:
    gps = tmp_path / "gps.nmea"
    gps.write_text("".join(_gga(t) for t in gga_times))
    gyro = tmp_path / "gyro.csv"
    gyro.write_text("t,yaw_rate\n" + "".join(f"{gyro_start_s + 0.1 * i:.3f},0.0\n" for i in range(50)))
    return str(gps), str(gyro)


def _posix(y: int, mo: int, d: int, h: int, mi: int, s: int) -> float:
    return dt.datetime(y, mo, d, h, mi, s, tzinfo=dt.UTC).timestamp()


def test_the_date_comes_from_the_gyro_csv(tmp_path) -> None:
    gps, gyro = _files(tmp_path, ["120001", "120002"], _posix(2024, 5, 14, 12, 0, 0))
    drive = read_drive(gps=gps, gyro=gyro, params=config.defaults())
    assert drive.gnss.t_ns[0] == int(_posix(2024, 5, 14, 12, 0, 1)) * NS_PER_S
    assert any("no date in the log; took 2024-05-14" in w for w in drive.meta["warnings"])


def test_across_midnight_the_fixes_take_the_next_day(tmp_path) -> None:
    """The gyro starts at 23:59:58 on 14 May; the first fix at 00:00:01 is on 15 May."""
    gps, gyro = _files(tmp_path, ["000001", "000002"], _posix(2024, 5, 14, 23, 59, 58))
    drive = read_drive(gps=gps, gyro=gyro, params=config.defaults())
    assert drive.gnss.t_ns[0] == int(_posix(2024, 5, 15, 0, 0, 1)) * NS_PER_S


def test_without_dr_files_it_still_asks_for_a_date(tmp_path) -> None:
    gps, _ = _files(tmp_path, ["120001"], 0.0)
    with pytest.raises(MissingDateError, match="--date"):
        read_drive(gps=gps, params=config.defaults())


def test_an_explicit_date_wins(tmp_path) -> None:
    gps, gyro = _files(tmp_path, ["120001"], _posix(2024, 5, 14, 12, 0, 0))
    drive = read_drive(gps=gps, gyro=gyro, params=config.defaults(), date=dt.date(2020, 1, 2))
    assert drive.gnss.t_ns[0] == int(_posix(2020, 1, 2, 12, 0, 1)) * NS_PER_S
    assert not any("no date" in w for w in drive.meta.get("warnings", []))
