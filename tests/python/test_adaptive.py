"""isobar.extract_adaptive: the adaptive 3-level-grid surface through the C ABI."""

import numpy as np
import pytest

import isobar


def ball_with_droplet():
    g = np.arange(-6, 7) * 0.1
    xyz = np.stack(np.meshgrid(g, g, g, indexing="ij"), axis=-1).reshape(-1, 3)
    xyz = xyz[np.linalg.norm(xyz, axis=1) <= 0.6]
    return np.vstack([xyz, [[1.6, 0.0, 0.0]]])


def edges_used_twice_oppositely(triangles):
    directed = {}
    for a, b, c in triangles.tolist():
        for e in ((a, b), (b, c), (c, a)):
            directed[e] = directed.get(e, 0) + 1
    return all(n == 1 and directed.get((b, a)) == 1 for (a, b), n in directed.items())


def test_adaptive_surface_is_closed_and_reports_levels():
    surface, stats = isobar.extract_adaptive(ball_with_droplet(), 0.5, h=0.2)
    assert surface.n_triangles == stats["triangles"] > 0
    assert edges_used_twice_oppositely(surface.triangles)
    assert stats["cells_per_level"][2] > 0, "the droplet's cell is level 3"
    assert sum(stats["triangles_per_level"]) + stats["crack_triangles"] == stats["triangles"]
    # Normals are unit and point away from the droplet's centre on its little sphere.
    n = np.linalg.norm(surface.normals, axis=1)
    assert np.allclose(n, 1, atol=1e-5)
    near = np.linalg.norm(surface.points - [1.6, 0, 0], axis=1) < 0.3
    radial = (surface.points[near] - [1.6, 0, 0]) * surface.normals[near]
    assert (radial.sum(axis=1) > 0).all()


def test_adaptive_refuses_bad_input_with_the_core_message():
    with pytest.raises(isobar.InvalidArgumentError, match="one isovalue at a time, got 2"):
        isobar.extract_adaptive(ball_with_droplet(), [0.5, 0.6], h=0.2)
    with pytest.raises(isobar.InvalidArgumentError, match="bisection_iterations"):
        isobar.extract_adaptive(ball_with_droplet(), 0.5, h=0.2, bisection_iterations=17)
    with pytest.raises(isobar.Cancelled):
        isobar.extract_adaptive(ball_with_droplet(), 0.5, h=0.2, progress=lambda f, p: False)


def test_adaptive_backend_choice_is_reported_and_checked():
    cpu, stats = isobar.extract_adaptive(ball_with_droplet(), 0.5, h=0.2, backend="cpu")
    assert stats["backend"] == "cpu"
    # gpu: wgpu (lavapipe in CI, installed by the test command); the same triangles, closed,
    # vertices within 1e-5 (nodes within f32 rounding of the isovalue take the CPU's side:
    # gpu/sides.rs; in detail: the Rust tests, gpu/tests.rs).
    gpu, stats = isobar.extract_adaptive(ball_with_droplet(), 0.5, h=0.2, backend="gpu")
    assert stats["backend"] == "gpu"
    assert edges_used_twice_oppositely(gpu.triangles)
    assert np.array_equal(gpu.triangles, cpu.triangles)
    assert np.abs(gpu.points - cpu.points).max() <= 1e-5
    # auto: a hardware GPU when there is one, else the CPU; closed either way.
    auto, stats = isobar.extract_adaptive(ball_with_droplet(), 0.5, h=0.2, backend="auto")
    assert stats["backend"] in ("cpu", "gpu")
    assert edges_used_twice_oppositely(auto.triangles)
    assert auto.n_triangles == cpu.n_triangles
    with pytest.raises(ValueError, match="backend"):
        isobar.extract_adaptive(ball_with_droplet(), 0.5, h=0.2, backend="cuda")


@pytest.mark.parametrize("max_error", [0.0, 0.1])
def test_max_error_reaches_the_core_like_the_command_line(cli, dam_break_path, tmp_path, max_error):
    """The error criterion's tolerance goes through the C ABI: the level counts and the
    triangles equal `isobar adaptive --max-error` on the same frame."""
    import json
    import subprocess

    stats_json = tmp_path / "stats.json"
    run = subprocess.run(
        [str(cli), "adaptive", str(dam_break_path), "--iso", "0.6", "--h", "0.05",
         "--grid-factor", "0.5", "--max-error", str(max_error), "--backend", "cpu",
         "--quiet", "--stats-json", str(stats_json), "-o", str(tmp_path / "cli.ply")],
        capture_output=True, text=True,
    )
    assert run.returncode == 0, run.stderr
    want = json.loads(stats_json.read_text())
    particles = isobar.Particles.read(dam_break_path)
    surface, stats = isobar.extract_adaptive(particles, 0.6, h=0.05, grid_factor=0.5,
                                             max_error=max_error, backend="cpu")
    assert stats["cells_per_level"] == [want[f"level_{l}_cells"] for l in (1, 2, 3)]
    assert stats["triangles"] == want["triangles"] == surface.n_triangles


def test_max_error_changes_the_levels_and_bad_values_are_refused():
    off, stats_off = isobar.extract_adaptive(ball_with_droplet(), 0.5, h=0.2, max_error=0)
    on, stats_on = isobar.extract_adaptive(ball_with_droplet(), 0.5, h=0.2, max_error=0.05)
    refined = lambda stats: stats["cells_per_level"][1] + stats["cells_per_level"][2]  # noqa: E731
    assert refined(stats_on) > refined(stats_off)
    assert isobar.adaptive.default_params().max_error > 0
    with pytest.raises(isobar.InvalidArgumentError, match="max_error"):
        isobar.extract_adaptive(ball_with_droplet(), 0.5, h=0.2, max_error=-1)


@pytest.mark.parametrize("backend", ["cpu", "gpu"])
def test_particle_arrays_are_carried_onto_the_adaptive_vertices(backend):
    """'side' is 1 on particles with x > 0, 0 elsewhere: a vertex farther than the kernel
    support (2h) from x = 0 carries exactly one or the other; 'v' = (x, -x, 7) keeps its
    components apart. The surface is the one extracted without arrays."""
    xyz = ball_with_droplet()
    particles = isobar.Particles.from_arrays(
        xyz, {"side": (xyz[:, 0] > 0).astype(float),
              "v": np.stack([xyz[:, 0], -xyz[:, 0], np.full(len(xyz), 7.0)], axis=1)})
    bare, _ = isobar.extract_adaptive(particles, 0.5, h=0.2, backend=backend)
    surface, stats = isobar.extract_adaptive(particles, 0.5, h=0.2, backend=backend,
                                             attributes=["side", "v"])
    assert np.array_equal(surface.points, bare.points)
    assert list(surface.attributes) == ["side", "v"]
    side, v = surface.attributes["side"], surface.attributes["v"]
    assert side.shape == (surface.n_points,) and v.shape == (surface.n_points, 3)
    x = surface.points[:, 0]
    assert (x > 0.4).sum() > 20 and (x < -0.4).sum() > 20
    assert (side[x > 0.4] == 1).all() and (side[x < -0.4] == 0).all()
    assert ((side >= 0) & (side <= 1)).all()
    assert np.allclose(v[:, 0], -v[:, 1], atol=1e-12) and np.allclose(v[:, 2], 7, atol=1e-12)
    with pytest.raises(isobar.InvalidInputError, match="pressure"):
        isobar.extract_adaptive(particles, 0.5, h=0.2, backend=backend, attributes="pressure")
