"""The Python package and the command line give the same surface, bit for bit."""

import os
import subprocess
import sys

import numpy as np
import pytest

import isobar

ARGS = dict(iso=0.6, h=0.05, grid_factor=0.375)


@pytest.fixture(scope="module")
def cli_vtp(cli, dam_break_path, tmp_path_factory):
    out = tmp_path_factory.mktemp("cli") / "out.vtp"
    run = subprocess.run(
        [
            str(cli),
            "sph",
            str(dam_break_path),
            "--iso",
            str(ARGS["iso"]),
            "--h",
            str(ARGS["h"]),
            "--grid-factor",
            str(ARGS["grid_factor"]),
            "--quiet",
            "-o",
            str(out),
        ],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr
    return out


@pytest.fixture(scope="module")
def py_surface(dam_break_path):
    particles = isobar.Particles.read(dam_break_path)
    # The command line does not trim the SumOfWeights (free surface) field.
    return isobar.extract(particles, ARGS["iso"], h=ARGS["h"], grid_factor=ARGS["grid_factor"], trim=None)


def test_positions_triangles_normals_equal_the_command_line_bit_for_bit(cli_vtp, py_surface):
    pv = pytest.importorskip("pyvista")
    mesh = pv.read(cli_vtp)
    points = np.asarray(mesh.points)
    assert points.dtype == np.float64, "the .vtp keeps f64 positions"
    faces = np.asarray(mesh.faces).reshape(-1, 4)
    assert (faces[:, 0] == 3).all()
    triangles = faces[:, 1:]

    s = py_surface
    assert s.points.dtype == np.float64 and s.points.shape == points.shape
    assert s.triangles.dtype == np.uint32 and s.triangles.shape == triangles.shape
    assert s.n_triangles > 100_000  # a real frame, not a trivial case
    # Bit-for-bit: compare the raw 64-bit patterns, not values with a tolerance.
    assert np.array_equal(s.points.view(np.uint64), points.view(np.uint64))
    assert np.array_equal(s.triangles.astype(np.int64), triangles.astype(np.int64))
    normals = np.asarray(mesh.point_data["Normals"])
    assert s.normals.dtype == np.float32
    assert np.array_equal(s.normals.view(np.uint32), normals.astype(np.float32).view(np.uint32))
    sow = np.asarray(mesh.point_data["SumOfWeights"])
    assert np.array_equal(s.attributes["SumOfWeights"].view(np.uint64), sow.astype(np.float64).view(np.uint64))


def test_python_write_gives_the_command_line_file_byte_for_byte(cli_vtp, py_surface, tmp_path):
    mine = tmp_path / "python.vtp"
    py_surface.write(mine)
    assert mine.read_bytes() == cli_vtp.read_bytes()


def test_surface_is_on_the_level_set_and_closed_where_it_should_be(py_surface):
    s = py_surface
    # Vertices are corrected onto SumOfWeights = 0.6 to 1e-6 relative.
    assert np.abs(s.attributes["SumOfWeights"] - 0.6).max() <= 0.6 * 1e-6
    assert s.stats["unconverged_vertices"] == 0
    assert s.stats["vertices"] == s.n_points and s.stats["triangles"] == s.n_triangles
    lengths = np.linalg.norm(s.normals, axis=1)
    assert np.allclose(lengths, 1.0, atol=1e-5)


def test_backend_gpu_gives_the_same_surface_from_python_and_the_command_line(cli, dam_break_path, py_surface, tmp_path):
    """Backend "gpu" (wgpu; lavapipe in CI) runs the seed cells' neighbour search on the
    device: the surface is the CPU's bit for bit, and the statistics say the GPU ran."""
    assert py_surface.stats["backend"] == "cpu"
    with isobar.Particles.read(dam_break_path) as particles:
        gpu = isobar.extract(particles, ARGS["iso"], h=ARGS["h"], grid_factor=ARGS["grid_factor"], trim=None,
                             backend="gpu")
    assert gpu.stats["backend"] == "gpu"
    assert gpu.stats["seed_cells"] == py_surface.stats["seed_cells"]
    assert np.array_equal(gpu.points.view(np.uint64), py_surface.points.view(np.uint64))
    assert np.array_equal(gpu.triangles, py_surface.triangles)
    assert np.array_equal(gpu.normals, py_surface.normals)

    out, stats = tmp_path / "gpu.ply", tmp_path / "gpu.json"
    common = [str(cli), "sph", str(dam_break_path), "--iso", str(ARGS["iso"]), "--h", str(ARGS["h"]),
              "--grid-factor", str(ARGS["grid_factor"]), "--quiet"]
    run = subprocess.run(common + ["--backend", "gpu", "-o", str(out), "--stats-json", str(stats)],
                         capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert '"backend": "gpu"' in stats.read_text()
    cpu_out = tmp_path / "cpu.ply"
    run = subprocess.run(common + ["-o", str(cpu_out)], capture_output=True, text=True)
    assert run.returncode == 0, run.stderr
    assert out.read_bytes() == cpu_out.read_bytes()


def test_backend_is_checked():
    with pytest.raises(ValueError, match="backend"):
        isobar.extract(np.zeros((1, 3)), 0.5, h=0.1, backend="cuda")
    # The full-grid baseline runs on the CPU only: a GPU request is refused, not ignored.
    with pytest.raises(isobar.InvalidArgumentError, match="CPU only"):
        isobar.extract(np.zeros((1, 3)), 0.5, h=0.1, full_grid=True, backend="gpu")


CPU_LEAD = "backend auto: running on the CPU ("


def cli_auto_note(cli, dam_break_path, tmp_path):
    """What `isobar sph --backend auto` says after CPU_LEAD up to the line's ')' (None: no
    such line, AUTO runs on a GPU here)."""
    run = subprocess.run(
        [str(cli), "sph", str(dam_break_path), "--iso", "0.6", "--h", "0.05", "--backend", "auto",
         "-o", str(tmp_path / "auto.ply")],
        capture_output=True,
        text=True,
    )
    assert run.returncode == 0, run.stderr
    for line in run.stderr.splitlines():
        if line.startswith(CPU_LEAD) and line.endswith(")"):
            return line[len(CPU_LEAD) : -1]
    return None


def test_auto_backend_note_is_what_the_cli_says(cli, dam_break_path, tmp_path):
    note = isobar.auto_backend_note()
    assert note is None or note.strip(), repr(note)
    assert note == cli_auto_note(cli, dam_break_path, tmp_path)
    # The note is exactly when AUTO ran on the CPU.
    particles = isobar.Particles.read(dam_break_path)
    _, stats = isobar.extract_adaptive(particles, 0.6, h=0.05, backend="auto")
    assert stats["backend"] == ("cpu" if note else "gpu")


def test_the_gpu_probe_is_quiet_without_a_desktop_session():
    """Mesa's device-select Vulkan layer connected to Wayland while listing devices, and
    without XDG_RUNTIME_DIR (a server, a notebook kernel) libwayland printed an error line
    twice on stderr at every first GPU probe, shown in red by Jupyter. The probe switches
    the layer off for itself then and leaves the environment as it was."""
    env = {k: v for k, v in os.environ.items() if k not in ("XDG_RUNTIME_DIR", "WAYLAND_DISPLAY", "NODEVICE_SELECT")}
    code = (
        "import os, isobar\n"
        "isobar.auto_backend_note()\n"
        "print('NODEVICE_SELECT' in os.environ)\n"
    )
    run = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, timeout=300)
    assert run.returncode == 0, run.stderr
    assert "XDG_RUNTIME_DIR" not in run.stderr, run.stderr
    assert run.stdout.strip() == "False"
