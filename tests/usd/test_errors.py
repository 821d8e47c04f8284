"""Bad input gives a clear error naming what to change, and writes nothing."""

from __future__ import annotations

import os

import numpy as np
import pytest
from conftest import CLI_DAM, DAM, FRAME_01, ISO, link_frames, run_cli

import isobar
import isobar_usd


def _files(folder):
    return sorted(p.name for p in folder.iterdir())


def test_pattern_that_matches_nothing(cli, tmp_path, dam_frames):
    proc = run_cli(cli, "sph", dam_frames / "fr_####.vtk", *CLI_DAM, "-o", tmp_path / "x.usd", check=False)
    assert proc.returncode == 1
    assert "fr_####.vtk': no file in" in proc.stderr
    proc = run_cli(cli, "sph", tmp_path / "nope" / "frame_####.vtk", *CLI_DAM, "-o", tmp_path / "x.usd", check=False)
    assert proc.returncode == 1 and "cannot list" in proc.stderr
    with pytest.raises(isobar_usd.InputError, match="empty frame pattern"):
        isobar_usd.write_sequence("", tmp_path / "x.usd", ISO, **DAM)
    with pytest.raises(isobar_usd.InputError, match="matches none of the frames"):
        isobar_usd.write_sequence(dam_frames / "frame_####.vtk", tmp_path / "x.usd", ISO, frames="2-20", **DAM)
    assert _files(tmp_path) == []


def test_missing_frame_file(cli, tmp_path):
    proc = run_cli(cli, "sph", tmp_path / "missing.vtk", *CLI_DAM, "-o", tmp_path / "x.usd", check=False)
    assert proc.returncode == 1 and f"no such particle file: {tmp_path / 'missing.vtk'}" in proc.stderr
    with pytest.raises(isobar_usd.InputError, match="no such particle file: .*frame_0002.vtk"):
        isobar_usd.write_sequence([FRAME_01, tmp_path / "frame_0002.vtk"], tmp_path / "x.usd", ISO, **DAM)
    assert _files(tmp_path) == []


@pytest.mark.parametrize("jobs", [1, 2])
def test_dangling_frame_in_a_sequence(tmp_path, jobs):
    """A frame that vanishes (a broken link): the error names the frame; nothing is written."""
    frames = link_frames(tmp_path / "frames", {1: FRAME_01, 2: FRAME_01, 3: FRAME_01})
    (frames / "frame_0002.vtk").unlink()
    os.symlink(tmp_path / "gone.vtk", frames / "frame_0002.vtk")
    out = tmp_path / "seq.usd"
    with pytest.raises(isobar_usd.FrameError) as info:
        isobar_usd.write_sequence(frames / "frame_####.vtk", out, ISO, jobs=jobs, **DAM)
    assert info.value.frame == 2 and "frame 2 (" in str(info.value) and "no such particle file" in str(info.value)
    assert not out.exists() and not isobar_usd.clips_folder(out).exists()


def test_missing_arrays(cli, tmp_path, dam_frames):
    out = tmp_path / "x.usd"
    cases = [
        (["--field", "pressure", "--iso", "1", "--h", "0.05"], "no array named 'pressure' in the particle data (available: id, velocity)"),
        (["--iso", "0.6", "--h", "0.05", "--attributes", "density"], "no array named 'density'"),
        (["--iso", "0.6", "--h", "0.05", "--velocities", "vel"], "no particle array 'vel' for velocities (arrays: id, velocity)"),
        (["--iso", "0.6", "--h-array", "hsml"], "hsml"),
        (["--iso", "0.6"], "no smoothing-length array (arrays: id, velocity); pass --h VALUE or --h-array NAME"),
    ]
    for args, message in cases:
        proc = run_cli(cli, "sph", dam_frames / "frame_####.vtk", *args, "-o", out, check=False)
        assert proc.returncode == 1, args
        assert proc.stderr.startswith("isobar-usd: error: frame 1 ("), proc.stderr
        assert message in proc.stderr, (args, proc.stderr)
    assert _files(tmp_path) == []


def test_core_errors_keep_their_type(tmp_path, dam_frames):
    with pytest.raises(isobar_usd.FrameError) as info:
        isobar_usd.write_sequence(dam_frames / "frame_####.vtk", tmp_path / "x.usd", 1.0, field="pressure", h=0.05)
    assert isinstance(info.value.cause, isobar.InvalidInputError)
    assert isinstance(info.value.__cause__, isobar.InvalidInputError)
    assert info.value.source.endswith("frame_0001.vtk")


def test_bad_options(cli, tmp_path, dam_frames):
    src = dam_frames / "frame_####.vtk"
    for args, message in [
        (["-o", tmp_path / "x.abc"], "give a .usd, .usda or .usdc file"),
        (["-o", tmp_path / "no" / "x.usd"], "does not exist"),
        (["-o", tmp_path / "x.usd", "--trim", "0.1"], "--trim takes NODE,VERTEX"),
        (["-o", tmp_path / "x.usd", "--fps", "0"], "fps must be a positive number"),
        (["-o", tmp_path / "x.usd", "--meters-per-unit", "-1"], "meters_per_unit must be a positive number"),
        (["-o", tmp_path / "x.usd", "--frames", "9-3"], "ends before it starts"),
        (["-o", tmp_path / "x.usd", "--prim", "1bad"], "not a valid USD prim name"),
    ]:
        proc = run_cli(cli, "sph", src, *CLI_DAM, *args, check=False)
        assert proc.returncode == 1, (args, proc.stderr)
        assert message in proc.stderr, (args, proc.stderr)
    proc = run_cli(cli, "sph", src, "--iso", "0.6", "--h", "0.05", "--h-array", "h", "-o", tmp_path / "x.usd", check=False)
    assert proc.returncode == 2 and "not allowed with argument" in proc.stderr
    with pytest.raises(isobar_usd.InputError, match="either h or h_array"):
        isobar_usd.write_sequence(src, tmp_path / "x.usd", ISO, h=0.05, h_array="h")
    with pytest.raises(isobar_usd.InputError, match="up_axis must be 'Y' or 'Z'"):
        isobar_usd.write_sequence(src, tmp_path / "x.usd", ISO, h=0.05, up_axis="X")
    with pytest.raises(isobar_usd.InputError, match="iso is needed"):
        isobar_usd.write_frame(FRAME_01, tmp_path / "x.usd", h=0.05)
    with pytest.raises(isobar_usd.InputError, match="jobs > 1 needs particle files"):
        isobar_usd.write_sequence({1: {"points": np.eye(3), "triangles": [[0, 1, 2]]}}, tmp_path / "x.usd", jobs=2, layout="clips")
    with pytest.raises(isobar_usd.InputError, match="frame 1 is given twice"):
        isobar_usd.write_sequence(iter([(1, FRAME_01), (1, FRAME_01)]), tmp_path / "x.usd", ISO, h=0.05)
    assert [p for p in _files(tmp_path)] == []


def test_stitch_and_check_commands_on_nothing(cli, tmp_path):
    proc = run_cli(cli, "stitch", tmp_path / "x.usd", check=False)
    assert proc.returncode == 1 and "no clips folder" in proc.stderr
    proc = run_cli(cli, "check", tmp_path / "x.usd", check=False)
    assert proc.returncode == 1 and "could not open" in proc.stderr


def test_array_missing_in_a_later_frame(cli, tmp_path):
    """Frame 9 has 'density', frame 23 no array: the error names frame 23; nothing is kept."""
    from conftest import DATA, need

    frames = tmp_path / "bgeo"
    frames.mkdir()
    for n, name in ((9, "dam_break_frame_9_6859_particles.bgeo"), (23, "dam_break_frame_23_24389_particles.bgeo")):
        (frames / f"frame_{n:04d}.bgeo").symlink_to(need(DATA / "splashsurf" / name))
    out = tmp_path / "b.usd"
    proc = run_cli(cli, "sph", frames / "frame_####.bgeo", "--iso", "0.6", "--h", "0.06", "--attributes", "density", "-o", out, check=False)
    assert proc.returncode == 1
    assert "frame 23 (" in proc.stderr and "no array named 'density' in the particle data (available: none)" in proc.stderr
    assert _files(tmp_path) == ["bgeo"]


def test_the_wrong_isobar_is_refused(tmp_path):
    """PyPI's 'isobar' (a music library) in place of this repository's package."""
    import subprocess
    import sys

    fake = tmp_path / "fake" / "isobar"
    fake.mkdir(parents=True)
    (fake / "__init__.py").write_text("'''isobar: musical patterns'''\n")
    proc = subprocess.run([sys.executable, "-c", "import isobar_usd"], capture_output=True, text=True,
                          env={**os.environ, "PYTHONPATH": str(fake.parent)})
    assert proc.returncode != 0
    assert "is not isobar's SPH package" in proc.stderr and "pip install ./rust-core/python" in proc.stderr
