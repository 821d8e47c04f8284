"""Exceptions raised by isobar: one per status code of the core's C ABI.

Every exception carries the core's own message (which names the file, array, parameter or
particle at fault) and the numeric status code. Catch :class:`Error` for all of them.
"""

from __future__ import annotations

import contextlib
import enum
import warnings


class Status(enum.IntEnum):
    """Status codes of the C ABI (``IsobarStatus``)."""

    OK = 0
    INVALID_ARGUMENT = 1
    INVALID_INPUT = 2
    IO = 3
    FORMAT = 4
    OVER_BUDGET = 5
    CANCELLED = 6
    INTERNAL = 7


class Error(Exception):
    """An isobar call failed.

    Attributes:
        message: the core's message, worded for the person who supplied the input.
        status: the :class:`Status` code (an int for codes this package does not know).
    """

    default_status = None

    def __init__(self, message: str, status: int | None = None):
        super().__init__(message)
        self.message = message
        code = self.default_status if status is None else status
        try:
            self.status = Status(code) if code is not None else None
        except ValueError:
            self.status = code

    def __str__(self) -> str:
        return self.message


class InvalidArgumentError(Error, ValueError):
    """A parameter out of range, a bad length, a NULL, non-UTF-8 text (status 1)."""

    default_status = Status.INVALID_ARGUMENT


class InvalidInputError(Error, ValueError):
    """Data that cannot form a field: NaN positions, h <= 0, no particles, a missing
    array (status 2)."""

    default_status = Status.INVALID_INPUT


class IoError(Error):
    """A file could not be read or written (status 3)."""

    default_status = Status.IO


class FormatError(Error):
    """A file is not in the format its name says (status 4)."""

    default_status = Status.FORMAT


class OverBudgetError(Error):
    """The work would exceed the memory budget; nothing was allocated (status 5)."""

    default_status = Status.OVER_BUDGET


class Cancelled(Error):
    """The progress callback asked to stop (status 6)."""

    default_status = Status.CANCELLED


class InternalError(Error):
    """A bug in isobar, caught before it could crash the process (status 7)."""

    default_status = Status.INTERNAL


class IsobarWarning(UserWarning):
    """An extraction succeeded but its input looks wrong: an isovalue the field never
    crosses (an empty surface), a kernel wider than the whole particle set (h in other
    units than the positions). Also kept in :attr:`isobar.Surface.warnings`."""


def issue(texts, stacklevel: int) -> None:
    """Issues each of a result's warnings as an :class:`IsobarWarning`; `stacklevel`
    counts as :func:`warnings.warn` does, from the function calling this one."""
    for text in texts:
        warnings.warn(text, IsobarWarning, stacklevel=stacklevel + 1)


@contextlib.contextmanager
def quiet_warnings():
    """Inside, extractions keep their warnings in :attr:`isobar.Surface.warnings` only and
    issue no :class:`IsobarWarning`: for hosts that show them their own way (a panel, a
    report, a per-frame line), where Python's copy would print each a second time.
    Other warnings pass as usual."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", IsobarWarning)
        yield


_BY_STATUS = {
    Status.INVALID_ARGUMENT: InvalidArgumentError,
    Status.INVALID_INPUT: InvalidInputError,
    Status.IO: IoError,
    Status.FORMAT: FormatError,
    Status.OVER_BUDGET: OverBudgetError,
    Status.CANCELLED: Cancelled,
    Status.INTERNAL: InternalError,
}


def error_for(status: int, message: str) -> Error:
    """The exception for a non-zero status code and the core's message."""
    cls = _BY_STATUS.get(status, Error)
    if not message:
        message = f"isobar call failed with status {status} and no message"
    return cls(message, status)
