"""Numbered frame sequences and frame selections.

:func:`expand_sequence` follows the isobar command line's rules (``rust-core/src/io/
sequence.rs``), which the ``isobar`` Python package does not expose: ``frame_####.vtk``
(that many digits, zero padded, or more once the number outgrows the padding),
``frame_{}.vtk`` and ``frame_%d.vtk`` (any digits), ``frame_%04d.vtk`` (like ``####``), or
the path of one existing frame, which stands for every sibling with the same prefix,
extension and padding.
"""

from __future__ import annotations

import os
import re
from pathlib import Path
from typing import Callable, Iterable, List, Optional, Tuple, Union

from .errors import InputError

PathLike = Union[str, "os.PathLike[str]"]

# (prefix, width or None for any digits, suffix)
_Placeholder = Tuple[str, Optional[int], str]


def _split_extension(name: str) -> Tuple[str, str]:
    """Stem and extension of a file name, ``.x.gz`` counting as one extension."""
    dot = name.rfind(".")
    if dot <= 0:
        return name, ""
    stem, ext = name[:dot], name[dot:]
    if ext.lower() == ".gz":
        inner = stem.rfind(".")
        if inner > 0:
            return name[:inner], name[inner:]
    return stem, ext


def _trailing_digits(text: str) -> str:
    match = re.search(r"[0-9]+$", text)
    return match.group(0) if match else ""


def frame_number(path: PathLike) -> Optional[int]:
    """The frame number of a file: the digits that end its name before the extension
    (``frame_0042.vtk`` and ``frame_0042.bgeo.gz`` give 42; ``particles.vtk`` gives None)."""
    stem, _ = _split_extension(Path(path).name)
    digits = _trailing_digits(stem)
    if not digits or len(digits) > 19:  # more than an unsigned 64-bit counter holds
        return None
    return int(digits)


def _placeholder(name: str) -> Optional[_Placeholder]:
    """Finds the frame-number placeholder in a file name."""
    start = name.find("#")
    if start >= 0:
        width = len(name[start:]) - len(name[start:].lstrip("#"))
        return name[:start], width, name[start + width :]
    start = name.find("{}")
    if start >= 0:
        return name[:start], None, name[start + 2 :]
    for match in re.finditer(r"%([0-9]*)d", name):
        spec = match.group(1)
        width = int(spec) if spec.startswith("0") and spec.lstrip("0") else None
        return name[: match.start()], width, name[match.end() :]
    return None


def _accepts(width: Optional[int], digits: str) -> bool:
    if not digits or not digits.isascii() or not digits.isdigit():
        return False
    if width is None:
        return True
    return len(digits) == width or (len(digits) > width and not digits.startswith("0"))


def is_pattern(text: PathLike) -> bool:
    """True when `text` holds a frame-number placeholder in its file name."""
    return _placeholder(Path(text).name) is not None


def expand_sequence(pattern: PathLike) -> List[Path]:
    """Expands a frame pattern into the existing files it names, sorted by frame number.

    Raises:
        InputError: nothing matches (the message names the pattern and folder), the folder
            cannot be listed, or a placeholder sits in the folder part.
    """
    text = os.fspath(pattern)
    path = Path(text)
    directory = Path(os.path.dirname(text)) if os.path.dirname(text) else None
    name = path.name
    if not name:
        raise InputError(f"'{text}' names no file")

    if path.is_file():
        stem, ext = _split_extension(name)
        run = _trailing_digits(stem)
        if not run:
            return [path]
        prefix, width, suffix = stem[: len(stem) - len(run)], len(run), ext
    else:
        parsed = _placeholder(name)
        if parsed is None:
            if directory is not None and _placeholder(str(directory)) is not None:
                why = "the frame-number placeholder must be in the file name, not the folder"
            else:
                why = "no such file, and no frame-number placeholder (####, {}, %d or %04d) in it"
            raise InputError(f"frame pattern '{text}': {why}")
        prefix, width, suffix = parsed

    listing = directory if directory is not None else Path(".")
    try:
        entries = os.listdir(listing)
    except OSError as e:
        raise InputError(f"frame pattern '{text}': cannot list {listing}: {e.strerror or e}") from e
    frames = []
    for entry in entries:
        if not (entry.startswith(prefix) and entry.endswith(suffix)) or len(entry) < len(prefix) + len(suffix):
            continue
        middle = entry[len(prefix) : len(entry) - len(suffix)]
        if not _accepts(width, middle) or len(middle) > 19 or (listing / entry).is_dir():
            continue
        frames.append((int(middle), entry))
    if not frames:
        raise InputError(f"frame pattern '{text}': no file in {listing} matches")
    frames.sort()
    return [(directory / entry) if directory is not None else Path(entry) for _, entry in frames]


def parse_frame_selection(spec: Union[None, str, int, Iterable[int]]) -> Optional[Callable[[int], bool]]:
    """A predicate on frame numbers from ``"10-20"``, ``"1-5,8,12-"``, ``"-20"``, an int
    or an iterable of ints; None for every frame.

    Raises:
        InputError: a malformed selection.
    """
    if spec is None:
        return None
    if isinstance(spec, int):
        return lambda f, _n=spec: f == _n
    if not isinstance(spec, str):
        chosen = set()
        for item in spec:
            if isinstance(item, bool) or not isinstance(item, int):
                raise InputError(f"frame selection: {item!r} is not a frame number")
            chosen.add(item)
        return chosen.__contains__
    ranges = []
    for part in spec.replace(" ", "").split(","):
        single = re.fullmatch(r"[0-9]+", part)
        span = re.fullmatch(r"([0-9]*)-([0-9]*)", part)
        if single:
            ranges.append((int(part), int(part)))
        elif span and (span.group(1) or span.group(2)):
            lo = int(span.group(1)) if span.group(1) else None
            hi = int(span.group(2)) if span.group(2) else None
            if lo is not None and hi is not None and hi < lo:
                raise InputError(f"frame selection '{spec}': range '{part}' ends before it starts")
            ranges.append((lo, hi))
        else:
            raise InputError(
                f"frame selection '{spec}': '{part}' is not N, A-B, A- or -B (frame numbers, comma separated)"
            )

    def selected(frame: int) -> bool:
        return any((lo is None or frame >= lo) and (hi is None or frame <= hi) for lo, hi in ranges)

    return selected


__all__ = ["expand_sequence", "frame_number", "is_pattern", "parse_frame_selection"]
