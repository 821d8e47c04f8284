"""Errors carry the core's message and status; cancellation and callback exceptions."""

import numpy as np
import pytest

import isobar
from conftest import lattice


def cube():
    return isobar.Particles.from_arrays(lattice(6), pressure=np.linspace(0, 1, 216))


def test_nan_position_names_the_particle():
    xyz = lattice(3)
    xyz[17, 1] = np.nan
    with pytest.raises(isobar.InvalidInputError) as e:
        isobar.extract(isobar.Particles.from_arrays(xyz), 0.5, h=0.1)
    assert "particle 17" in str(e.value)
    assert e.value.status == isobar.Status.INVALID_INPUT == 2
    assert isinstance(e.value, isobar.Error) and isinstance(e.value, ValueError)


@pytest.mark.parametrize(
    "kw, name",
    [
        (dict(field="nope"), "nope"),
        (dict(field="nope:mag"), "nope"),
        (dict(field="pressure", attributes=["missing_attr"]), "missing_attr"),
        (dict(h=None, h_array="hh"), "hh"),
        (dict(volume_array="vv"), "vv"),
    ],
)
def test_missing_array_is_named(kw, name):
    kw = {"h": 0.1, **kw}
    with pytest.raises(isobar.InvalidInputError) as e:
        isobar.extract(cube(), 0.5, **kw)
    assert f"'{name}'" in str(e.value)
    assert "pressure" in str(e.value)  # the message lists the arrays there are


@pytest.mark.parametrize("h", [0.0, -0.1, float("nan")])
def test_non_positive_h_is_refused(h):
    with pytest.raises(isobar.InvalidArgumentError, match="'h': the smoothing length must be positive"):
        isobar.extract(cube(), 0.5, h=h)


def test_non_positive_h_array_names_the_particle():
    h = np.full(216, 0.1)
    h[40] = -1
    p = isobar.Particles.from_arrays(lattice(6), h=h)
    with pytest.raises(isobar.InvalidInputError, match="smoothing length of particle 40 is -1"):
        isobar.extract(p, 0.5)


def test_missing_smoothing_length_is_explained():
    with pytest.raises(isobar.InvalidArgumentError, match="h=VALUE or h_array=NAME"):
        isobar.extract(cube(), 0.5)


def test_empty_particles():
    with pytest.raises(isobar.InvalidInputError, match="empty"):
        isobar.extract(isobar.Particles.from_arrays(np.empty((0, 3))), 0.5, h=0.1)


def test_bad_parameters():
    with pytest.raises(isobar.InvalidArgumentError, match="kernel"):
        isobar.extract(cube(), 0.5, h=0.1, kernel="gaussian")
    with pytest.raises(isobar.InvalidArgumentError, match="mass"):
        isobar.extract(cube(), 0.5, h=0.1, mass=-1)
    with pytest.raises(isobar.Error, match="grid"):
        isobar.extract(cube(), 0.5, h=0.1, grid_factor=-1)
    with pytest.raises(isobar.Error, match="isovalue"):
        isobar.extract(cube(), [], h=0.1)


@pytest.mark.parametrize(
    "call, name",
    [
        (lambda: isobar.extract(cube(), 0.5, h=0.1, kernel=2**32), "kernel"),
        (lambda: isobar.extract(cube(), 0.5, h=0.1, memory_budget=2**64), "memory_budget"),
        (lambda: isobar.extract(cube(), 0.5, h=0.1, memory_budget=float("nan")), "memory_budget"),
        # A fraction (GiB in mind) used to be truncated to a budget of 0 bytes.
        (lambda: isobar.extract(cube(), 0.5, h=0.1, memory_budget=0.25), "memory_budget"),
        (lambda: isobar.extract_adaptive(cube(), 0.5, h=0.1, splash_threshold=-1), "splash_threshold"),
        (lambda: isobar.extract_adaptive(cube(), 0.5, h=0.1, splash_dilation=2**32 + 1), "splash_dilation"),
    ],
)
def test_integers_a_parameter_cannot_hold_are_refused(call, name):
    # ctypes kept the low bits: kernel 2**32 ran the cubic spline, a budget of 2**64 the
    # default, a splash threshold of -1 made every cell a splash cell.
    with pytest.raises(isobar.InvalidArgumentError, match=f"'{name}'"):
        call()


def test_over_budget():
    with pytest.raises(isobar.OverBudgetError) as e:
        isobar.extract(cube(), 0.5, h=0.1, memory_budget=1000)
    assert "memory budget of 1000 bytes" in str(e.value)
    assert e.value.status == isobar.Status.OVER_BUDGET


def test_io_and_format_errors(tmp_path):
    missing = tmp_path / "no_such_file.vtk"
    with pytest.raises(isobar.IoError) as e:
        isobar.Particles.read(missing)
    assert str(missing) in str(e.value)
    bad = tmp_path / "bad.vtk"
    bad.write_text("# vtk DataFile Version 3.0\ntruncated\n")
    with pytest.raises(isobar.FormatError, match="bad.vtk"):
        isobar.Particles.read(bad)
    s = isobar.extract(cube(), 0.5, h=0.1)
    with pytest.raises(isobar.FormatError, match="xyz"):
        s.write(tmp_path / "surface.xyz")
    with pytest.raises(isobar.IoError):
        s.write(tmp_path / "no_such_dir" / "surface.ply")


def test_progress_reports_phases_in_order():
    seen = []
    isobar.extract(cube(), 0.5, h=0.1, progress=lambda f, phase: seen.append((f, phase)))
    fractions = [f for f, _ in seen]
    assert fractions == sorted(fractions) and 0 <= fractions[0] and fractions[-1] == 1.0
    assert seen[-1][1] == "done"
    assert {"seed cells", "surface tracking", "vertices"} <= {p for _, p in seen}


def test_progress_returning_false_cancels():
    calls = []

    def stop_at_tracking(fraction, phase):
        calls.append(phase)
        return phase != "surface tracking"

    with pytest.raises(isobar.Cancelled) as e:
        isobar.extract(cube(), 0.5, h=0.1, progress=stop_at_tracking)
    assert e.value.status == isobar.Status.CANCELLED
    assert calls[-1] == "surface tracking"  # no call after the cancel
    # The next extraction runs normally.
    assert isobar.extract(cube(), 0.5, h=0.1).n_triangles > 0


class Boom(Exception):
    pass


@pytest.mark.parametrize("exc", [Boom("from the callback"), KeyboardInterrupt()])
def test_exception_in_progress_propagates_and_cancels(exc):
    calls = []

    def explode(fraction, phase):
        calls.append(phase)
        if len(calls) == 3:
            raise exc

    with pytest.raises(type(exc)) as e:
        isobar.extract(cube(), 0.5, h=0.1, progress=explode)
    assert e.value is exc
    assert len(calls) == 3  # the core stopped at once
    assert isobar.extract(cube(), 0.5, h=0.1, progress=lambda f, p: None).n_triangles > 0


def test_exception_in_the_last_progress_call_still_propagates():
    def explode_when_done(fraction, phase):
        if phase == "done":
            raise Boom("at the end")

    with pytest.raises(Boom):
        isobar.extract(cube(), 0.5, h=0.1, progress=explode_when_done)


def test_error_message_is_per_call():
    with pytest.raises(isobar.InvalidArgumentError, match="got 0"):
        isobar.extract(cube(), 0.5, h=0.0)
    # A success afterwards, then a different error: each carries its own message.
    isobar.extract(cube(), 0.5, h=0.1)
    with pytest.raises(isobar.InvalidInputError, match="'zz'"):
        isobar.extract(cube(), 0.5, h=0.1, field="zz")


def test_closing_the_particles_from_their_own_progress_callback_is_refused():
    """The core reads the particles while it reports progress: closing them there used to
    free them under it (a segfault). The close is refused, the extraction ends with that
    error, and the particles still work afterwards."""
    particles = cube()

    def close_them(fraction, phase):
        particles.close()

    with pytest.raises(isobar.InvalidArgumentError, match="in use"):
        isobar.extract(particles, 0.5, h=0.1, progress=close_them)
    assert not particles.closed
    assert isobar.extract(particles, 0.5, h=0.1).n_triangles > 0
    particles.close()
    assert particles.closed
