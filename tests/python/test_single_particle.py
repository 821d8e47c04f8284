"""One particle: the isosurface is the sphere the cubic spline kernel gives.

With one particle at c of volume V and value a, the field is a V W(|x - c|, h) with
W(r, h) = sigma / h^3 f(r / h), sigma = 1 / pi. The level set a V sigma / h^3 f(q) = iso is
the sphere of radius q h.
"""

import math
import warnings

import numpy as np
import pytest

import isobar
from conftest import cubic_shape

CENTER = np.array([[0.1, -0.2, 0.3]])
H = 0.5
V = 1.3
A = 2.0


def iso_for(q):
    """The isovalue whose sphere has radius q h."""
    return A * V * (1 / math.pi) / H**3 * float(cubic_shape(q))


def one_particle():
    return isobar.Particles.from_arrays(CENTER, a=np.array([A]), vol=np.array([V]))


@pytest.mark.parametrize("q", [0.7, 1.4], ids=["inner-branch", "outer-branch"])
def test_vertices_lie_on_the_kernel_sphere_with_radial_normals(q):
    radius = q * H
    s = isobar.extract(one_particle(), iso_for(q), field="a", h=H, volume_array="vol", grid_factor=0.1, trim=None)
    assert s.n_points > 500
    d = s.points - CENTER
    r = np.linalg.norm(d, axis=1)
    assert np.abs(r / radius - 1).max() < 1e-6
    # Normals: unit, radial, pointing out (towards decreasing field values).
    radial = d / r[:, None]
    assert np.allclose(np.linalg.norm(s.normals, axis=1), 1, atol=1e-6)
    assert (np.einsum("ij,ij->i", s.normals.astype(np.float64), radial) > 1 - 1e-5).all()
    # Triangles wind counter-clockwise seen from outside: positive volume close to the sphere's.
    sphere = 4 / 3 * math.pi * radius**3
    assert 0.97 * sphere < s.volume() < sphere
    assert s.attributes["SumOfWeights"] == pytest.approx(np.full(s.n_points, iso_for(q) / A), rel=1e-5)


def test_sum_of_weights_of_one_particle_with_computed_volume():
    # Computed volume: V = 1 / W(0, h), so the free-surface field is f(q) itself.
    q = 0.9
    s = isobar.extract(isobar.Particles.from_arrays(CENTER), float(cubic_shape(q)), h=H, grid_factor=0.1)
    r = np.linalg.norm(s.points - CENTER, axis=1)
    assert np.abs(r / (q * H) - 1).max() < 1e-6


def test_float32_positions_give_the_same_sphere_as_float64():
    center32 = CENTER.astype(np.float32)
    p32 = isobar.Particles.from_arrays(center32, a=np.array([A], np.float32), vol=np.array([V]))
    p64 = isobar.Particles.from_arrays(center32.astype(np.float64), a=np.array([A]), vol=np.array([V]))
    kw = dict(field="a", h=H, volume_array="vol", grid_factor=0.2, trim=None)
    s32 = isobar.extract(p32, iso_for(0.7), **kw)
    s64 = isobar.extract(p64, iso_for(0.7), **kw)
    assert np.array_equal(s32.points, s64.points)
    assert np.array_equal(s32.triangles, s64.triangles)


def test_an_isovalue_above_the_peak_warns_and_gives_an_empty_surface():
    peak = iso_for(0.0)
    with pytest.warns(isobar.IsobarWarning, match=r"no surface at isovalue .*never crosses it") as caught:
        s = isobar.extract(one_particle(), 2 * peak, field="a", h=H, volume_array="vol", trim=None)
    assert s.n_triangles == 0
    assert s.warnings == [str(w.message) for w in caught]
    assert len(s.warnings) == 1
    # The warning points at the caller's line, not at the package.
    assert caught[0].filename == __file__


def test_a_kernel_wider_than_the_particles_warns_and_a_sound_one_does_not():
    rng = np.random.default_rng(3)
    cloud = rng.uniform(0.0, 1.0, (200, 3))
    with pytest.warns(isobar.IsobarWarning, match=r"kernel support .* is wider than the particles' extent"):
        s = isobar.extract(isobar.Particles.from_arrays(cloud), 0.5, h=5.0, trim=None)
    assert any("wider than" in w for w in s.warnings)
    with warnings.catch_warnings():
        warnings.simplefilter("error", isobar.IsobarWarning)
        sound = isobar.extract(isobar.Particles.from_arrays(cloud), 0.5, h=0.15, trim=None)
    assert sound.warnings == [] and sound.n_triangles > 0


def test_quiet_warnings_keeps_them_on_the_surface_only():
    with warnings.catch_warnings():
        warnings.simplefilter("error", isobar.IsobarWarning)
        with isobar.quiet_warnings():
            s = isobar.extract(one_particle(), 2 * iso_for(0.0), field="a", h=H, volume_array="vol", trim=None)
        with pytest.raises(isobar.IsobarWarning, match="no surface at isovalue"):
            isobar.extract(one_particle(), 2 * iso_for(0.0), field="a", h=H, volume_array="vol", trim=None)
    assert s.n_triangles == 0 and len(s.warnings) == 1
