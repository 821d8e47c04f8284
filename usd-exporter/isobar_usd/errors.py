"""Exceptions of the USD writer. Catch :class:`Error` for all of them."""

from __future__ import annotations


class Error(Exception):
    """The USD writer failed; the message says what to change."""


class InputError(Error, ValueError):
    """Bad input: a missing frame file, a pattern that matches nothing, a missing particle
    array, arrays of the wrong shape, a malformed option."""


class FrameError(Error):
    """Extracting or writing one frame failed.

    Attributes:
        frame: the frame number.
        source: the particle file (or a description of the in-memory frame).
        cause: the original exception (an :class:`isobar.Error` for a core failure);
            also ``__cause__``.
    """

    def __init__(self, frame: int, source: str, cause: BaseException):
        self.frame = frame
        self.source = source
        self.cause = cause
        super().__init__(f"frame {frame} ({source}): {cause}")

    def __reduce__(self):
        return (type(self), (self.frame, self.source, self.cause))


class StitchError(Error):
    """The frame layers of a sequence cannot be joined (none written, or an attribute with
    different types in different frames)."""


def frame_error(frame: int, source: str, exc: BaseException) -> FrameError:
    """Wraps `exc` (raised while handling frame `frame`) into a :class:`FrameError`."""
    if isinstance(exc, FrameError):
        return exc
    err = FrameError(frame, source, exc)
    err.__cause__ = exc
    return err


__all__ = ["Error", "FrameError", "InputError", "StitchError"]
