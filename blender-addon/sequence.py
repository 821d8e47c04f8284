"""Numbered particle file sequences (frame_0001.vtk, frame_0002.vtk, ...).

Plain Python, no bpy: a sequence is a folder and a pattern in which a run of ``#`` stands
for the frame number, padded with zeros to the run's length (Blender's convention):
``frame_####.vtk`` names frame_0001.vtk, frame_0002.vtk, ... and also frame_12345.vtk;
``frame_#.vtk`` names unpadded frame_1.vtk ... frame_12.vtk. A pattern without ``#`` is
one static file, the same for every frame.
"""

from __future__ import annotations

import os
import re
from dataclasses import dataclass
from typing import List, Optional, Tuple

#: File extensions the isobar core reads particles from.
PARTICLE_EXTENSIONS = (".vtk", ".vtp", ".vtu", ".bgeo", ".ply", ".npz", ".npy", ".csv", ".xyz")

_NUMBER = re.compile(r"\d+")
_LAST_HASHES = re.compile(r"(#+)(?!.*#)")


@dataclass(frozen=True)
class Sequence:
    """A numbered file sequence found on disk."""

    directory: str
    pattern: str
    numbers: Tuple[int, ...]

    @property
    def first(self) -> int:
        return self.numbers[0]

    @property
    def last(self) -> int:
        return self.numbers[-1]

    def path(self, number: int) -> str:
        return path_for(self.directory, self.pattern, number)

    @property
    def is_static(self) -> bool:
        return is_static(self.pattern)

    def missing(self) -> List[int]:
        """Numbers between first and last with no file."""
        have = set(self.numbers)
        return [n for n in range(self.first, self.last + 1) if n not in have]


def split_pattern(pattern: str) -> Tuple[str, int, str]:
    """(prefix, width, suffix) of a pattern; the last run of ``#`` is the number.

    Raises:
        ValueError: the pattern has no ``#``.
    """
    match = _LAST_HASHES.search(pattern)
    if not match:
        raise ValueError(f"the file pattern '{pattern}' has no '#' for the frame number (e.g. frame_####.vtk)")
    return pattern[: match.start()], len(match.group(1)), pattern[match.end() :]


def is_static(pattern: str) -> bool:
    """Whether `pattern` names one file for every frame (it has no ``#``)."""
    return "#" not in pattern


def format_number(pattern: str, number: int) -> str:
    """The file name for `number` (negative numbers keep their sign before the padding;
    a static pattern is the file's own name)."""
    if is_static(pattern):
        return pattern
    prefix, width, suffix = split_pattern(pattern)
    digits = str(abs(number)).zfill(width)
    return f"{prefix}{'-' if number < 0 else ''}{digits}{suffix}"


def name_stem(pattern: str) -> str:
    """What names the files of `pattern`: the text before the number (the name without
    its extension for a static file)."""
    stem = _split_ext(pattern)[0] if is_static(pattern) else split_pattern(pattern)[0]
    return stem.rstrip("_-. ")


def path_for(directory: str, pattern: str, number: int) -> str:
    """The path of file `number` of the sequence."""
    return os.path.join(directory, format_number(pattern, number))


def pattern_from_file(filename: str) -> Tuple[str, int]:
    """The pattern of a sequence from one of its file names, and that file's number: the
    last run of digits before the extension is the frame number.

    Raises:
        ValueError: no digits in the name.
    """
    candidates = candidate_patterns(filename)
    if not candidates:
        raise ValueError(f"'{os.path.basename(filename)}' has no frame number in its name")
    return candidates[0]


def candidate_patterns(filename: str) -> List[Tuple[str, int]]:
    """(pattern, number) for each way the name can be a member of a sequence: any run of
    digits before the extension may be the frame number (a name may hold other numbers,
    such as a particle count), last run first; an unpadded number (no leading zero) may
    also belong to an unpadded sequence, whose other members have fewer or more digits."""
    stem, ext = _split_ext(os.path.basename(filename))
    out = []
    for match in reversed(list(_NUMBER.finditer(stem))):
        digits = match.group(0)
        widths = [len(digits)]
        if len(digits) > 1 and not digits.startswith("0"):
            widths.append(1)
        for width in widths:
            out.append((stem[: match.start()] + "#" * width + stem[match.end() :] + ext, int(digits)))
    return out


def scan(directory: str, pattern: str) -> List[int]:
    """Numbers of the files of the sequence present in `directory`, sorted."""
    prefix, width, suffix = split_pattern(pattern)
    regex = re.compile(re.escape(prefix) + r"(-?\d+)" + re.escape(suffix) + r"\Z")
    numbers = []
    try:
        names = os.listdir(directory)
    except OSError:
        return []
    for name in names:
        match = regex.match(name)
        if match and format_number(pattern, int(match.group(1))) == name:
            numbers.append(int(match.group(1)))
    return sorted(set(numbers))


def detect(filepath: str) -> Sequence:
    """The sequence a file belongs to: of the ways its name can be numbered, the one that
    finds the most files beside it; the file alone, static (its own name as the pattern),
    when no sibling file is found.

    Raises:
        ValueError: the file does not exist.
    """
    if not os.path.isfile(filepath):
        raise ValueError(f"particle file not found: {filepath}")
    directory = os.path.dirname(os.path.abspath(filepath))
    best = Sequence(directory, os.path.basename(filepath), (0,))
    for pattern, number in candidate_patterns(filepath):
        numbers = scan(directory, pattern)
        if number in numbers and len(numbers) > max(1, len(best.numbers)):
            best = Sequence(directory, pattern, tuple(numbers))
    return best


def file_number(frame: int, offset: int, first: int, last: int, hold: bool = True) -> Optional[int]:
    """The file number shown at scene `frame`: ``frame - offset``, held at the first or last
    file outside the sequence (or None there when `hold` is False)."""
    number = frame - offset
    if first <= number <= last:
        return number
    if not hold:
        return None
    return first if number < first else last


def _split_ext(name: str) -> Tuple[str, str]:
    # ".tar.gz"-like double extensions do not occur here; one extension is split off.
    stem, ext = os.path.splitext(name)
    return stem, ext


__all__ = [
    "PARTICLE_EXTENSIONS",
    "Sequence",
    "candidate_patterns",
    "detect",
    "file_number",
    "format_number",
    "is_static",
    "name_stem",
    "path_for",
    "pattern_from_file",
    "scan",
    "split_pattern",
]
