"""Particles: construction from numpy arrays and files, and reading arrays back."""

import numpy as np
import pytest

import isobar
from conftest import lattice


def test_from_arrays_round_trips_positions_and_arrays():
    xyz = lattice(4)
    velocity = np.arange(xyz.size, dtype=np.float64).reshape(-1, 3)
    p = isobar.Particles.from_arrays(xyz, pressure=np.linspace(0, 1, len(xyz)), velocity=velocity)
    assert len(p) == 64
    assert p.names == ["pressure", "velocity"]
    assert np.array_equal(p.positions, xyz)
    arrays = p.arrays
    assert arrays["velocity"].shape == (64, 3) and np.array_equal(arrays["velocity"], velocity)
    assert arrays["pressure"].shape == (64,) and np.array_equal(arrays["pressure"], np.linspace(0, 1, 64))
    # .arrays hands out copies: changing them does not change the particles.
    arrays["pressure"][:] = 7
    assert p.array("pressure")[0] == 0
    assert "velocity" in p and "nope" not in p


def test_float32_int_and_strided_inputs_are_converted_exactly():
    xyz = lattice(3).astype(np.float32)
    big = np.zeros((27, 6), dtype=np.float64)
    big[:, ::2] = xyz  # a non-contiguous (strided) view
    p = isobar.Particles.from_arrays(big[:, ::2], ids=np.arange(27, dtype=np.int32), m=np.ones(27, np.float32))
    assert np.array_equal(p.positions, xyz.astype(np.float64))
    assert np.array_equal(p.array("ids"), np.arange(27.0))
    assert p.array("m").dtype == np.float64


def test_names_that_are_not_identifiers_through_a_mapping():
    p = isobar.Particles.from_arrays(lattice(2), {"velocity x": np.ones(8)}, h=np.full(8, 0.1))
    assert set(p.names) == {"velocity x", "h"}


def test_from_arrays_makes_no_python_side_copy_of_contiguous_floats(monkeypatch):
    # A float64 / float32 C-contiguous buffer goes to the core as it is: the pointer passed
    # is the array's own data pointer.
    from isobar import particles as mod

    seen = []
    real = mod._float_buffer

    def spy(values):
        out = real(values)
        seen.append((values.ctypes.data, out[0].ctypes.data))
        return out

    monkeypatch.setattr(mod, "_float_buffer", spy)
    xyz = lattice(3)
    h = np.full(27, 0.1, dtype=np.float32)
    isobar.Particles.from_arrays(xyz, h=h)
    assert seen == [(xyz.ctypes.data, xyz.ctypes.data), (h.ctypes.data, h.ctypes.data)]


def test_read_a_file(dam_break_path):
    p = isobar.Particles.read(dam_break_path)
    assert len(p) == 4732
    assert p.names == ["id", "velocity"]
    assert p.array("velocity").shape == (4732, 3)
    assert np.array_equal(np.sort(p.array("id")), np.arange(4732.0))  # a permutation
    pv = pytest.importorskip("pyvista")
    other = pv.read(dam_break_path)  # VTK's own reader agrees on positions and arrays
    assert np.array_equal(p.positions, np.asarray(other.points, dtype=np.float64))
    assert np.array_equal(p.array("velocity"), np.asarray(other.point_data["velocity"], dtype=np.float64))


def test_wrong_shapes_and_lengths_are_refused():
    with pytest.raises(isobar.InvalidArgumentError, match=r"\(n, 3\)"):
        isobar.Particles.from_arrays(np.zeros((4, 2)))
    with pytest.raises(isobar.InvalidArgumentError) as e:
        isobar.Particles.from_arrays(lattice(2), p=np.zeros(5))
    assert "array 'p' has 5 items for 8 particles" in str(e.value)  # the core's words
    assert e.value.status == isobar.Status.INVALID_ARGUMENT
    with pytest.raises(isobar.InvalidInputError, match="no array named 'nope'"):
        isobar.Particles.from_arrays(lattice(2)).array("nope")


def test_closed_particles_refuse_use():
    p = isobar.Particles.from_arrays(lattice(2))
    with p:
        assert len(p) == 8
    assert p.closed
    with pytest.raises(isobar.InvalidArgumentError, match="closed"):
        len(p)
    p.close()  # twice is fine


def test_infos_lists_names_and_components():
    p = isobar.Particles.from_arrays(
        np.zeros((4, 3)), pressure=np.arange(4.0), velocity=np.ones((4, 3))
    )
    assert dict(p.infos()) == {"pressure": 1, "velocity": 3}
