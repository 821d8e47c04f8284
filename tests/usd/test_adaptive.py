"""The adaptive 3-level method through the USD writer: the stage holds exactly the core's
adaptive surface, closed, and the options that do not apply to it are refused by name."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import CLI_DAM, DAM, FRAME_26, ISO, assert_same_mesh, link_frames, mesh_at, need, open_stage, run_cli

import isobar
import isobar_usd


def _closed_and_oriented(triangles: np.ndarray) -> bool:
    """Every directed edge appears once and its reverse once: watertight, consistently wound."""
    directed = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]])
    keys = directed[:, 0].astype(np.int64) << 32 | directed[:, 1]
    reverse = directed[:, 1].astype(np.int64) << 32 | directed[:, 0]
    return len(np.unique(keys)) == len(keys) and np.array_equal(np.sort(keys), np.sort(reverse))


def test_cli_writes_the_cores_adaptive_surface(cli, tmp_path):
    frames = link_frames(tmp_path / "frames", {26: need(FRAME_26)})
    out = tmp_path / "adaptive.usd"
    run_cli(cli, "sph", frames / "frame_0026.vtk", *CLI_DAM, "--method", "adaptive", "-o", out, "-q")
    with isobar.Particles.read(str(FRAME_26)) as particles:
        surface, stats = isobar.extract_adaptive(particles, ISO, attributes=["velocity"], **DAM)
        corrected = isobar.extract(particles, ISO, **DAM)
    got = mesh_at(open_stage(out), 26)
    # The particles' velocities carried onto the vertices, as for Marching Correctors.
    assert_same_mesh(got, surface, velocity=True)
    assert np.abs(got["velocities"]).max() > 0.1
    assert _closed_and_oriented(surface.triangles.astype(np.int64))
    # What the method is for: fewer triangles than Marching Correctors on the finest grid.
    assert stats["triangles"] == surface.n_triangles < corrected.n_triangles
    corrected.release()
    surface.release()


@pytest.mark.parametrize(
    "extra, message",
    [
        (["--attributes", "pressure"], "no array named 'pressure'"),  # carried, so checked
        (["--preview"], "preview and full-grid"),
        (["--trim", "0.1,0.5"], "trimming applies"),
    ],
)
def test_cli_refuses_options_the_adaptive_method_lacks(cli, tmp_path, extra, message):
    frames = link_frames(tmp_path / "frames", {26: need(FRAME_26)})
    proc = run_cli(cli, "sph", frames / "frame_0026.vtk", *CLI_DAM, "--method", "adaptive", *extra,
                   "-o", tmp_path / "x.usd", check=False)
    assert proc.returncode != 0
    assert message in proc.stderr, proc.stderr
    assert not (tmp_path / "x.usd").exists()


def test_api_refuses_an_unknown_method(tmp_path):
    with pytest.raises(isobar_usd.Error, match="unknown extraction method 'marching'"):
        isobar_usd.write_sequence(str(need(FRAME_26)), tmp_path / "x.usd", ISO, method="marching", **DAM)


def test_api_refuses_several_isovalues_for_the_adaptive_method(tmp_path):
    with pytest.raises(isobar_usd.Error, match="one isovalue at a time"):
        isobar_usd.write_sequence(str(need(FRAME_26)), tmp_path / "x.usd", [0.5, 0.6], method="adaptive", **DAM)


def test_cli_gpu_backend_writes_the_cpu_surface_within_f32(cli, tmp_path):
    """--backend gpu (wgpu on lavapipe in CI; the test command installs it): the same
    triangles as the CPU path, positions within the GPU's f32 tolerance, closed."""
    frames = link_frames(tmp_path / "frames", {26: need(FRAME_26)})
    out = tmp_path / "gpu.usd"
    run_cli(cli, "sph", frames / "frame_0026.vtk", *CLI_DAM, "--method", "adaptive", "--backend", "gpu", "-o", out, "-q")
    with isobar.Particles.read(str(FRAME_26)) as particles:
        cpu, stats = isobar.extract_adaptive(particles, ISO, backend="cpu", **DAM)
    got = mesh_at(open_stage(out), 26)
    triangles = got["indices"].reshape(-1, 3).astype(np.int64)
    assert triangles.shape == cpu.triangles.shape
    assert _closed_and_oriented(triangles)
    assert np.abs(np.sort(got["points"], axis=0) - np.sort(cpu.points.astype(np.float32), axis=0)).max() <= 1e-4


def _correctors_via_cli(cli, tmp_path, backend):
    frames = link_frames(tmp_path / "frames", {26: need(FRAME_26)})
    out = tmp_path / f"correctors-{backend}.usd"
    proc = run_cli(cli, "sph", frames / "frame_0026.vtk", *CLI_DAM, "--no-velocities", "--backend", backend,
                   "-o", out, "-q", check=False)
    return proc, out


def test_cli_backend_cpu_applies_to_marching_correctors(cli, tmp_path):
    """--backend reaches isobar.extract for the default method: cpu writes exactly the
    core's Marching Correctors surface (and no longer asks for --method adaptive)."""
    proc, out = _correctors_via_cli(cli, tmp_path, "cpu")
    assert proc.returncode == 0, proc.stderr
    with isobar.Particles.read(str(FRAME_26)) as particles:
        surface = isobar.extract(particles, ISO, backend="cpu", **DAM)
    assert surface.stats["backend"] == "cpu"
    assert_same_mesh(mesh_at(open_stage(out), 26), surface, velocity=False)
    surface.release()


def test_cli_backend_gpu_applies_to_marching_correctors(cli, tmp_path):
    """--backend gpu with Marching Correctors: what isobar.extract(backend="gpu") does. With
    an adapter (lavapipe in CI) the GPU seed search gives exactly the CPU's seeds, so the
    stage holds exactly the CPU surface; without one the exporter fails with the core's
    "no GPU adapter" error and writes nothing."""
    with isobar.Particles.read(str(need(FRAME_26))) as particles:
        cpu = isobar.extract(particles, ISO, backend="cpu", **DAM)
        try:
            gpu = isobar.extract(particles, ISO, backend="gpu", **DAM)
        except isobar.Error as e:
            assert "no GPU adapter" in str(e), e
            gpu = None
    proc, out = _correctors_via_cli(cli, tmp_path, "gpu")
    if gpu is None:
        assert proc.returncode == 1, proc.stderr
        assert "no GPU adapter" in proc.stderr, proc.stderr
        assert not out.exists()
    else:
        assert proc.returncode == 0, proc.stderr
        assert gpu.stats["backend"] == "gpu"
        assert_same_mesh(mesh_at(open_stage(out), 26), cpu, velocity=False)
        gpu.release()
    cpu.release()


def _adaptive_stage_and_core(cli, tmp_path, option, value, keyword):
    """Writes frame 26 with `isobar-usd sph --method adaptive option value`, checks the
    stage holds the core's surface with `keyword=value`, and returns (that surface, the
    core's default surface, the frames folder); the caller releases both surfaces."""
    frames = link_frames(tmp_path / "frames", {26: need(FRAME_26)})
    out = tmp_path / "adaptive.usd"
    run_cli(cli, "sph", frames / "frame_0026.vtk", *CLI_DAM, "--method", "adaptive", option, str(value),
            "-o", out, "-q")
    with isobar.Particles.read(str(FRAME_26)) as particles:
        chosen, _ = isobar.extract_adaptive(particles, ISO, **{keyword: value}, **DAM)
        default, _ = isobar.extract_adaptive(particles, ISO, **DAM)
    assert_same_mesh(mesh_at(open_stage(out), 26), chosen, velocity=False)
    return chosen, default, frames


def test_cli_passes_max_error_to_the_core(cli, tmp_path):
    """`--max-error` reaches isobar.extract_adaptive: the stage holds the core's surface
    with that tolerance, and 0 (the splash criterion alone) differs from the default."""
    off, default, _ = _adaptive_stage_and_core(cli, tmp_path, "--max-error", 0.0, "max_error")
    assert off.n_triangles != default.n_triangles
    off.release()
    default.release()


def test_cli_passes_bisection_iterations_to_the_core(cli, tmp_path):
    """`--bisection-iterations` reaches isobar.extract_adaptive: the stage holds the core's
    surface with linear level-3 points at 0, whose points differ from the default's; 17 is
    refused with the core's message naming the parameter."""
    linear, default, frames = _adaptive_stage_and_core(cli, tmp_path, "--bisection-iterations", 0,
                                                       "bisection_iterations")
    assert not np.array_equal(np.sort(linear.points, axis=0), np.sort(default.points, axis=0))
    linear.release()
    default.release()
    proc = run_cli(cli, "sph", frames / "frame_0026.vtk", *CLI_DAM, "--method", "adaptive",
                   "--bisection-iterations", "17", "-o", tmp_path / "bad.usd", "-q", check=False)
    assert proc.returncode != 0 and "bisection_iterations" in proc.stderr, proc.stderr
    assert not (tmp_path / "bad.usd").exists()


def _record(path):
    from pxr import Sdf

    return dict(Sdf.Layer.FindOrOpen(str(path)).customLayerData["isobarUsd"])


def test_backend_auto_on_the_cpu_says_why_on_stderr_and_in_the_layer(cli, tmp_path):
    """--backend auto where it runs on the CPU (lavapipe in CI is a software rasteriser):
    the isobar CLI's line on stderr (not with -q), the core's reason in the layer's
    customLayerData record as backendNote; another backend says nothing."""
    note = isobar.auto_backend_note()
    frames = link_frames(tmp_path / "frames", {26: need(FRAME_26)})
    line = f"backend auto: running on the CPU ({note})"
    for method, backend, quiet in [("adaptive", "auto", False), ("correctors", "auto", True),
                                   ("adaptive", "cpu", False)]:
        out = tmp_path / f"{method}-{backend}-{quiet}.usd"
        proc = run_cli(cli, "sph", frames / "frame_0026.vtk", *CLI_DAM, "--method", method, "--backend", backend,
                       "--layout", "flat", "--no-velocities", "-o", out, *(["-q"] if quiet else []))
        said = [x for x in proc.stderr.splitlines() if x.startswith("backend auto:")]
        auto = note is not None and backend == "auto"
        assert said == ([line] if auto and not quiet else []), proc.stderr
        assert _record(out).get("backendNote") == (note if auto else None)
    # The API records it too, the method's default backend included (adaptive: auto).
    out = tmp_path / "api.usd"
    isobar_usd.write_frame(str(need(FRAME_26)), out, ISO, method="adaptive", **DAM)
    assert _record(out).get("backendNote") == note
