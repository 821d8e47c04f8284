"""The pyvista adaptor: point clouds in, closed meshes out, rendered offscreen."""

import math
import os
import shutil
import subprocess
import sys
import textwrap

import numpy as np
import pytest

import isobar
from conftest import cubic_shape, lattice

pv = pytest.importorskip("pyvista")
import isobar.pyvista as ipv  # noqa: E402


def blob_cloud():
    """A ball of particles on a jittered lattice with point-data arrays."""
    rng = np.random.default_rng(7)
    xyz = lattice(10, 0.05) - 0.225
    xyz = xyz[np.linalg.norm(xyz, axis=1) < 0.23] + rng.normal(0, 0.003, (1, 3))
    cloud = pv.PolyData(xyz.astype(np.float32))
    cloud.point_data["pressure"] = 1.0 - np.linalg.norm(xyz, axis=1)
    cloud.point_data["velocity"] = np.column_stack([xyz[:, 1], -xyz[:, 0], np.zeros(len(xyz))])
    cloud.point_data["h"] = np.full(len(xyz), 0.05)
    return cloud


def test_free_surface_of_a_point_cloud_is_manifold_with_the_core_volume():
    cloud = blob_cloud()
    mesh = ipv.surface_from_polydata(cloud, 0.6, grid_factor=0.25, attributes=["velocity", "pressure"])
    assert isinstance(mesh, pv.PolyData) and mesh.n_cells > 1000
    assert mesh.is_all_triangles
    assert mesh.n_open_edges == 0
    assert mesh.is_manifold
    assert mesh.points.dtype == np.float64
    assert mesh.point_data.active_normals_name == "Normals"
    assert mesh.point_data["velocity"].shape == (mesh.n_points, 3)
    assert {"Normals", "SumOfWeights", "velocity", "pressure"} <= set(mesh.point_data.keys())
    # The same extraction through the numpy API: same mesh, same volume.
    particles = isobar.Particles.from_arrays(np.asarray(cloud.points), h=cloud.point_data["h"])
    core = isobar.extract(particles, 0.6, grid_factor=0.25)
    assert np.array_equal(core.points, mesh.points)
    assert core.volume() > 0
    assert mesh.volume == pytest.approx(core.volume(), rel=1e-9)
    # A ball of radius ~0.25 (particles to 0.23 plus a fraction of h).
    assert 0.5 * (4 / 3 * math.pi * 0.23**3) < core.volume() < 4 / 3 * math.pi * 0.3**3


def test_adaptive_method_of_a_point_cloud_is_the_cores_adaptive_surface():
    """method='adaptive' gives isobar.extract_adaptive's surface with the carried arrays,
    its stats in field data; an unknown method is refused by name."""
    import json

    cloud = blob_cloud()
    mesh = ipv.surface_from_polydata(cloud, 0.6, method="adaptive", grid_factor=0.25,
                                     attributes=["velocity"], backend="cpu")
    particles = isobar.Particles.from_arrays(np.asarray(cloud.points), h=cloud.point_data["h"],
                                             velocity=cloud.point_data["velocity"])
    core, stats = isobar.extract_adaptive(particles, 0.6, grid_factor=0.25, attributes=["velocity"],
                                          backend="cpu")
    assert np.array_equal(core.points, mesh.points) and mesh.n_cells == core.n_triangles > 100
    assert mesh.n_open_edges == 0 and mesh.is_manifold
    assert np.array_equal(mesh.point_data["velocity"], core.attributes["velocity"])
    assert json.loads(mesh.field_data["isobar_adaptive"][0])["triangles"] == stats["triangles"]
    with pytest.raises(isobar.InvalidArgumentError, match="method"):
        ipv.surface_from_polydata(cloud, 0.6, method="marching")


def test_single_particle_cloud_gives_the_kernel_sphere_volume():
    h, q = 0.2, 0.8
    cloud = pv.PolyData(np.array([[1.0, 2.0, 3.0]]))
    cloud.point_data["vol"] = np.array([2.0])
    cloud.point_data["p"] = np.array([3.0])
    iso = 3.0 * 2.0 / math.pi / h**3 * float(cubic_shape(q))
    mesh = ipv.surface_from_polydata(cloud, iso, field="p", h=h, volume_array="vol", grid_factor=0.05, trim=None)
    assert mesh.n_open_edges == 0 and mesh.is_manifold
    sphere = 4 / 3 * math.pi * (q * h) ** 3
    assert 0.99 * sphere < mesh.volume < sphere  # inscribed polyhedron: a little smaller
    r = np.linalg.norm(mesh.points - [1.0, 2.0, 3.0], axis=1)
    assert np.abs(r / (q * h) - 1).max() < 1e-6


def test_to_pyvista_of_an_empty_surface():
    p = isobar.Particles.from_arrays(lattice(3))
    with pytest.warns(isobar.IsobarWarning, match="no surface at isovalue 50"):
        s = isobar.extract(p, 50.0, h=0.1)  # far above any value: nothing
    assert s.n_triangles == 0
    assert ipv.to_pyvista(s).n_points == 0


RENDER = textwrap.dedent(
    """
    import sys, numpy as np, pyvista as pv
    mesh = pv.read(sys.argv[1])
    plotter = pv.Plotter(off_screen=True, window_size=(320, 240))
    plotter.set_background("white")
    plotter.add_mesh(mesh, color="steelblue", smooth_shading=True)
    plotter.view_isometric()
    image = plotter.screenshot(sys.argv[2], return_img=True)
    window = plotter.render_window.GetClassName()
    plotter.close()
    print("rendered", image.shape, "with", window)
    """
)


def render(vtp, png):
    """Renders in a child process (a broken GL stack must not take pytest down): EGL first,
    then xvfb-run when installed. Returns (how, stdout) or skips."""
    env = dict(os.environ, VTK_DEFAULT_OPENGL_WINDOW=os.environ.get("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow"))
    attempts = [("EGL", [sys.executable, "-c", RENDER, str(vtp), str(png)], env)]
    if shutil.which("xvfb-run"):
        xenv = {k: v for k, v in os.environ.items() if k != "VTK_DEFAULT_OPENGL_WINDOW"}
        attempts.append(("xvfb-run", ["xvfb-run", "-a", "-s", "-screen 0 640x480x24", sys.executable, "-c", RENDER, str(vtp), str(png)], xenv))
    failures = []
    for how, cmd, e in attempts:
        run = subprocess.run(cmd, env=e, capture_output=True, text=True, timeout=300)
        if run.returncode == 0 and png.is_file():
            return how, run.stdout
        failures.append(f"{how}: exit {run.returncode}: {run.stderr[-800:]}")
    pytest.skip("no offscreen rendering here (needs libegl1 + mesa, or xvfb): " + " | ".join(failures))


def test_offscreen_screenshot_is_not_blank(tmp_path):
    mesh = ipv.surface_from_polydata(blob_cloud(), 0.6, grid_factor=0.25)
    vtp = tmp_path / "surface.vtp"
    mesh.save(vtp)
    png = tmp_path / "surface.png"
    how, out = render(vtp, png)
    image = pv.read(png)  # vtkPNGReader: no imaging package needed
    dims = image.dimensions
    pixels = np.asarray(image.point_data[image.point_data.keys()[0]]).reshape(dims[1], dims[0], -1)[..., :3]
    assert pixels.shape[:2] == (240, 320)
    background = np.all(pixels >= 250, axis=-1)  # white
    covered = 1 - background.mean()
    print(f"\nscreenshot via {how}: {out.strip()}, {covered:.1%} of pixels covered, std {pixels.std():.1f}")
    assert 0.05 < covered < 0.95, covered
    assert pixels.std() > 20
    # Shaded, not flat: the surface shows several distinct intensities.
    assert len(np.unique(pixels[~background].mean(axis=-1).round())) > 20


def test_warnings_of_the_pyvista_helpers_name_the_callers_line():
    """A warning names the line that called the helper, not a line inside isobar: Python
    shows a warning once per place, so a loop over frames saw only the first frame's."""
    import warnings

    cloud = pv.PolyData(lattice(3))
    for _ in range(2):  # the same line twice: both reported under "always"
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            mesh = ipv.surface_from_polydata(cloud, 50.0, h=0.1)  # far above any value
        assert mesh.n_points == 0
        assert [w.filename for w in caught] == [__file__], [(w.filename, w.lineno) for w in caught]
        assert "no surface at isovalue 50" in str(caught[0].message)
