"""The project's own exceptions.

Every error a user can cause derives from :class:`GpsdrError`; the CLI turns
them into one line on stderr (exit status 1, or 2 for :class:`UsageError`).
Anything else escaping is a bug in gpsdr.
"""

from __future__ import annotations

from pathlib import Path


class GpsdrError(Exception):
    """Base of every error gpsdr raises on purpose."""


class UsageError(GpsdrError):
    """The command line or the configuration asks for something impossible (exit 2)."""


class ConfigError(UsageError):
    """A TOML parameter file or a parameter value is invalid."""


class InputError(GpsdrError):
    """An input file cannot be used.

    Carries the file, the line (1-based) or record number where known, and the
    reason, so the message reads ``FILE:LINE: reason``.
    """

    def __init__(self, path: str | Path | None, reason: str, *, line: int | None = None,
                 record: int | None = None) -> None:
        self.path = None if path is None else str(path)
        self.reason = reason
        self.line = line
        self.record = record
        where = self.path or "<input>"
        if line is not None:
            where += f":{line}"
        elif record is not None:
            where += f": record {record}"
        super().__init__(f"{where}: {reason}")


class ParseError(InputError):
    """A record could not be parsed (skipped and counted unless strict)."""


class ChecksumError(ParseError):
    """An NMEA sentence's checksum does not match its contents."""


class NoDataError(InputError):
    """A file parsed, but holds no usable records of the kind required."""


class MissingDateError(NoDataError):
    """An NMEA log with fixes but no date (GGA without RMC/ZDA) and none given."""
