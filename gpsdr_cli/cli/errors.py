"""Library exceptions turned into the one line a user sees, and gpsdr's exit status.

Exit status: 0 success; 1 a processing failure (any :class:`GpsdrError`, or an
internal error); 2 a usage error (:class:`UsageError`, :class:`ConfigError`).
Its own module so that a command (``info`` reports one failed file and goes on)
and the group in :mod:`gpsdr_cli.cli.main` share it without importing each other.
"""

from __future__ import annotations

from typing import Any

import click

from ..errors import GpsdrError, UsageError


class GpsdrException(click.ClickException):
    """A one-line error with gpsdr's exit status."""

    def __init__(self, message: str, exit_code: int = 1) -> None:
        super().__init__(message)
        self.exit_code = exit_code

    def show(self, file: Any = None) -> None:
        click.echo(f"gpsdr: error: {self.format_message()}", err=True)


def to_click_exception(err: BaseException) -> click.ClickException:
    """Turn a library exception into the one line the user sees."""
    if isinstance(err, UsageError):
        return GpsdrException(str(err), 2)
    if isinstance(err, GpsdrError):
        return GpsdrException(str(err) or type(err).__name__, 1)
    if isinstance(err, MemoryError):
        return GpsdrException("out of memory", 1)
    text = " ".join(str(err).split()) or type(err).__name__
    return GpsdrException(f"internal error: {type(err).__name__}: {text} "
                          "(rerun with --debug for the traceback)", 1)
