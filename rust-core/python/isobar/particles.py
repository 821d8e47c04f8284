"""Particle sets: positions plus named per-particle arrays, held by the core."""

from __future__ import annotations

import contextlib
import threading
import weakref
from ctypes import POINTER, byref, c_char_p, c_double, c_float, c_size_t
from typing import Dict, Iterator, List, Mapping, Optional, Tuple

import numpy as np

from ._lib import ParticlesHandle, check, encode, lib
from .errors import InvalidArgumentError


def _float_buffer(values: np.ndarray):
    """`values` as a C-contiguous float32 or float64 array: the same buffer when it is one
    already, else a converted copy. Returns (array, ctypes pointer, is_f32)."""
    if values.dtype == np.float32 or values.dtype == np.float64:
        arr = np.ascontiguousarray(values)  # no copy when already contiguous
    else:
        arr = np.ascontiguousarray(values, dtype=np.float64)
    if arr.dtype == np.float32:
        return arr, arr.ctypes.data_as(POINTER(c_float)), True
    return arr, arr.ctypes.data_as(POINTER(c_double)), False


class Particles:
    """A particle set owned by the isobar core: positions and named per-particle arrays.

    Build one with :meth:`from_arrays` or :meth:`read`. The core copies what it is given
    (as f64), so the numpy arrays passed in may be changed or dropped afterwards. The core
    memory is freed when the object is garbage collected, or at once by :meth:`close`
    (also on leaving a ``with`` block).
    """

    __slots__ = ("_handle", "_finalizer", "_uses", "_uses_lock", "__weakref__")

    def __init__(self, handle):
        """Wraps a core handle (internal; use :meth:`from_arrays` or :meth:`read`)."""
        if not handle:
            raise InvalidArgumentError("Particles needs a non-NULL core handle")
        self._handle = handle
        self._uses = 0
        self._uses_lock = threading.Lock()
        self._finalizer = weakref.finalize(self, lib.isobar_particles_free, handle)

    # -- construction -----------------------------------------------------------------

    @classmethod
    def from_arrays(cls, positions, arrays: Optional[Mapping[str, object]] = None, /, **named) -> "Particles":
        """Creates a particle set from an (n, 3) position array and named arrays.

        Args:
            positions: (n, 3) array-like. float32 or float64 C-contiguous arrays are handed
                to the core as they are (no copy on the Python side); anything else is
                converted to float64 first.
            arrays: optional mapping name -> values, for names that are not Python
                identifiers (``{"velocity:x": ...}``).
            **named: per-particle arrays, each (n,) for a scalar or (n, k) for k components
                (float32/float64 passed as they are, other dtypes converted).

        Returns:
            The new :class:`Particles`.

        Raises:
            isobar.Error: the core refused the data (an array of the wrong length ...).
        """
        pos = np.asarray(positions)
        if pos.ndim != 2 or pos.shape[1] != 3:
            raise InvalidArgumentError(f"positions must have shape (n, 3), got {pos.shape}")
        buf, ptr, is_f32 = _float_buffer(pos)
        handle = POINTER(ParticlesHandle)()
        create = lib.isobar_particles_create_f32 if is_f32 else lib.isobar_particles_create
        check(create(ptr, buf.shape[0], byref(handle)))
        particles = cls(handle)
        all_arrays = dict(arrays or {})
        all_arrays.update(named)
        for name, values in all_arrays.items():
            particles.add_array(name, values)
        return particles

    @classmethod
    def read(cls, path) -> "Particles":
        """Reads a particle file in any format the ``isobar`` command line reads (.vtk,
        .vtp, .vtu, .ply, .bgeo, .csv, .xyz, .npy, .npz).

        Raises:
            isobar.IoError: the file cannot be read.
            isobar.FormatError: the file is not what its name says.
        """
        handle = POINTER(ParticlesHandle)()
        check(lib.isobar_particles_read(encode(path, "path"), byref(handle)))
        return cls(handle)

    def add_array(self, name: str, values) -> None:
        """Adds (or replaces) the per-particle array `name`: (n,) or (n, k) values
        (more trailing dimensions are flattened into components).

        Raises:
            isobar.InvalidArgumentError: wrong length or shape, empty name.
        """
        self._check_open()
        arr = np.asarray(values)
        if arr.ndim == 0:
            raise InvalidArgumentError(f"array '{name}' must have one value per particle, got a scalar")
        count = arr.shape[0]
        components = int(np.prod(arr.shape[1:], dtype=np.int64)) if arr.ndim > 1 else 1
        buf, ptr, is_f32 = _float_buffer(arr)
        add = lib.isobar_particles_add_array_f32 if is_f32 else lib.isobar_particles_add_array
        check(add(self._handle, encode(name, "array name"), ptr, count, components))

    # -- access -----------------------------------------------------------------------

    def __len__(self) -> int:
        """Number of particles."""
        self._check_open()
        return lib.isobar_particles_count(self._handle)

    @property
    def names(self) -> List[str]:
        """Names of the per-particle arrays, in the core's order."""
        return [name for name, _ in self.infos()]

    def infos(self) -> List[Tuple[str, int]]:
        """(name, components) of each per-particle array, in the core's order."""
        self._check_open()
        out = []
        name = c_char_p()
        components = c_size_t()
        for i in range(lib.isobar_particles_array_count(self._handle)):
            check(lib.isobar_particles_array_info(self._handle, i, byref(name), byref(components)))
            out.append((name.value.decode("utf-8", "replace"), components.value))
        return out

    @property
    def positions(self) -> np.ndarray:
        """A float64 (n, 3) copy of the positions."""
        self._check_open()
        out = np.empty((len(self), 3), dtype=np.float64)
        check(lib.isobar_particles_copy_positions(self._handle, out.ctypes.data_as(POINTER(c_double)), out.size))
        return out

    def array(self, name: str) -> np.ndarray:
        """A float64 copy of array `name`: (n,) for one component, (n, k) for k.

        Raises:
            isobar.InvalidInputError: no such array (the message lists those there are).
        """
        self._check_open()
        components = dict(self.infos()).get(name)
        n = len(self)
        if components is None:
            # Let the core word the error (it lists the arrays there are).
            check(lib.isobar_particles_copy_array(self._handle, encode(name, "array name"), None, 0))
            raise InvalidArgumentError(f"no array named '{name}'")  # if the core ever accepted it
        out = np.empty((n, components) if components != 1 else (n,), dtype=np.float64)
        check(
            lib.isobar_particles_copy_array(
                self._handle, encode(name, "array name"), out.ctypes.data_as(POINTER(c_double)), out.size
            )
        )
        return out

    @property
    def arrays(self) -> Dict[str, np.ndarray]:
        """All per-particle arrays as a dict name -> float64 numpy copy (made on each
        access)."""
        return {name: self.array(name) for name in self.names}

    def __contains__(self, name: str) -> bool:
        return name in self.names

    def __iter__(self) -> Iterator[str]:
        return iter(self.names)

    def __repr__(self) -> str:
        if self._handle is None:
            return "<isobar.Particles (closed)>"
        return f"<isobar.Particles {len(self)} particles, arrays {self.infos()}>"

    # -- lifetime ---------------------------------------------------------------------

    def close(self) -> None:
        """Frees the core's copy now (later use raises isobar.InvalidArgumentError).
        Refused while an extraction is reading the particles (from its progress
        callback): the core would go on reading freed memory."""
        with self._uses_lock:
            if self._uses:
                raise InvalidArgumentError(
                    "these Particles are in use by an extraction in progress; close them after it returns"
                )
            self._finalizer()
            self._handle = None

    @contextlib.contextmanager
    def _in_use(self):
        """The core handle, kept from :meth:`close` while the block runs."""
        with self._uses_lock:
            self._check_open()
            self._uses += 1
        try:
            yield self._handle
        finally:
            with self._uses_lock:
                self._uses -= 1

    @property
    def closed(self) -> bool:
        """True after :meth:`close`."""
        return self._handle is None

    def __enter__(self) -> "Particles":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def _check_open(self) -> None:
        if self._handle is None:
            raise InvalidArgumentError("this Particles object was closed")

    @property
    def _as_parameter_(self):
        """Lets a Particles object be passed to the C functions directly."""
        self._check_open()
        return self._handle


__all__ = ["Particles"]
