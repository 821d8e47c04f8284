"""Bad input gives a clear error naming what to change, and writes nothing."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest
from conftest import CLI_DAM, DAM, FRAME_01, FRAME_26, ISO, link_frames, mesh_at, open_stage, run_cli

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


# --- an output folder that cannot be written in ---------------------------------------

def _fe_fixture():
    from conftest import REPO, need

    return need(REPO / "rust-core" / "data" / "fe" / "mixed_lagrange.vtu")


class _Unwritable:
    """`folder` cannot be written in: "immutable" (chattr +i: it stops root too, which
    chmod does not) or "file" (the output's parent is a regular file)."""

    def __init__(self, tmp_path, kind):
        import subprocess

        self.kind = kind
        self.locked = []
        if kind == "file":
            self.folder = tmp_path / "some_file"
            self.folder.write_text("not a folder\n")
            self.reason = "is not a folder"
            return
        self.folder = tmp_path / "ro"
        self.folder.mkdir()
        # What is there already must stay as it was.
        (self.folder / "t.usd").write_bytes(b"previous root")
        (self.folder / "t.clips").mkdir()
        (self.folder / "t.clips" / "t.0001.usdc").write_bytes(b"previous frame")
        (self.folder / "fe.usd").write_bytes(b"previous fe")
        self.before = self.snapshot()
        proc = subprocess.run(["chattr", "+i", str(self.folder)], capture_output=True, text=True)
        if proc.returncode != 0:
            pytest.skip(f"chattr +i is not available here: {proc.stderr.strip()}")
        self.locked.append(self.folder)
        try:
            (self.folder / "probe").write_bytes(b"")
        except OSError:
            pass
        else:
            (self.folder / "probe").unlink()
            self.close()
            pytest.skip("chattr +i does not stop writes here")
        self.reason = "cannot write in folder"

    def lock(self, folder):
        import subprocess

        subprocess.run(["chattr", "+i", str(folder)], check=True)
        self.locked.append(folder)

    def snapshot(self):
        return {p.relative_to(self.folder): (p.read_bytes() if p.is_file() else None) for p in sorted(self.folder.rglob("*"))}

    def close(self):
        import subprocess

        while self.locked:
            subprocess.run(["chattr", "-i", str(self.locked.pop())], check=False)


@pytest.fixture(params=["immutable", "file"])
def unwritable(request, tmp_path):
    folder = _Unwritable(tmp_path, request.param)
    try:
        yield folder
    finally:
        folder.close()


def _assert_clean_error(proc, folder, reason):
    assert proc.returncode == 1, (proc.returncode, proc.stdout, proc.stderr)
    assert "Traceback" not in proc.stderr, proc.stderr
    assert proc.stderr.startswith("isobar-usd: error: "), proc.stderr
    assert f"'{folder}'" in proc.stderr and reason in proc.stderr, proc.stderr
    # Refused before any extraction: no frame was reported.
    assert "] frame " not in proc.stderr and proc.stdout == "", (proc.stdout, proc.stderr)


def test_unwritable_output_folder_cli(cli, dam_frames, unwritable):
    """Clips and flat layouts and the fe command: `isobar-usd: error:` naming the folder and
    the reason, before any extraction; no traceback; the files there stay as they were."""
    src = dam_frames / "frame_####.vtk"
    for layout in ("clips", "flat"):
        proc = run_cli(cli, "sph", src, *CLI_DAM, "--layout", layout, "-o", unwritable.folder / "t.usd", check=False)
        _assert_clean_error(proc, unwritable.folder, unwritable.reason)
    proc = run_cli(cli, "sph", src, *CLI_DAM, "--jobs", "2", "-o", unwritable.folder / "t.usd", check=False)
    _assert_clean_error(proc, unwritable.folder, unwritable.reason)
    proc = run_cli(cli, "fe", _fe_fixture(), "--field", "p", "--iso", "0", "-o", unwritable.folder / "fe.usd", check=False)
    _assert_clean_error(proc, unwritable.folder, unwritable.reason)
    if unwritable.kind == "immutable":
        assert unwritable.snapshot() == unwritable.before


def test_unwritable_output_folder_api(dam_frames, unwritable):
    """The Python API raises InputError (an isobar_usd.Error) with the same message, not a
    PermissionError or USD's Tf error."""
    src = dam_frames / "frame_####.vtk"
    out = unwritable.folder / "t.usd"
    for layout in ("clips", "flat"):
        with pytest.raises(isobar_usd.InputError, match=unwritable.reason) as info:
            isobar_usd.write_sequence(src, out, ISO, layout=layout, **DAM)
        assert f"'{unwritable.folder}'" in str(info.value)
    with pytest.raises(isobar_usd.InputError, match=unwritable.reason):
        isobar_usd.write_frame(FRAME_01, out, ISO, **DAM)
    with pytest.raises(isobar_usd.InputError, match=unwritable.reason):
        isobar_usd.write_fe_samples(_fe_fixture(), unwritable.folder / "fe.usd", "p", 0.0)
    with pytest.raises(isobar_usd.InputError, match=unwritable.reason):
        isobar_usd.stitch(out)
    if unwritable.kind == "immutable":
        assert unwritable.snapshot() == unwritable.before


def test_unwritable_clips_folder(cli, tmp_path, dam_frames):
    """The output's folder is writable, its clips folder is not: refused before extracting,
    naming the clips folder."""
    unwritable = _Unwritable(tmp_path, "immutable")
    try:
        clips = unwritable.folder / "t.clips"
        unwritable.close()
        unwritable.lock(clips)
        proc = run_cli(cli, "sph", dam_frames / "frame_####.vtk", *CLI_DAM, "-o", unwritable.folder / "t.usd", check=False)
        _assert_clean_error(proc, clips, "cannot write in folder")
        with pytest.raises(isobar_usd.InputError, match="cannot write in folder"):
            isobar_usd.write_sequence(dam_frames / "frame_####.vtk", unwritable.folder / "t.usd", ISO, **DAM)
        assert unwritable.snapshot() == unwritable.before
    finally:
        unwritable.close()


# --- jobs > 1 from a script without the __main__ guard ----------------------------------

_SCRIPT = """\
import sys
import isobar_usd

{indent}result = isobar_usd.write_sequence(sys.argv[1], sys.argv[2], 0.6, h=0.05, grid_factor=0.375, jobs=2,
{indent}                                   progress=lambda p: print(p.frame, p.triangles))
{indent}print("wrote", result.frames)
"""


def _run_script(path, *args, timeout=90):
    import signal
    import subprocess
    import sys

    proc = subprocess.Popen([sys.executable, str(path), *map(str, args)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)  # the script and the workers it spawned
        proc.communicate()
        pytest.fail(f"{path.name} did not end within {timeout} s (the worker pool respawns forever?)")
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
    return proc.returncode, out, err


def test_parallel_write_from_an_unguarded_script_fails_clearly(tmp_path, dam_frames):
    """The README's jobs=2 example pasted at the top level of a script: every spawned worker
    re-imports the script. It must end with an error that names the guard, not respawn the
    workers forever; under the guard it writes the sequence."""
    src = dam_frames / "frame_####.vtk"
    bare = tmp_path / "bare.py"
    bare.write_text(_SCRIPT.format(indent=""))
    out = tmp_path / "bare.usd"
    code, stdout, stderr = _run_script(bare, src, out)
    assert code != 0, (stdout, stderr)
    assert 'if __name__ == "__main__":' in stderr, stderr
    assert "bootstrapping phase" not in stderr, stderr
    # The script's, one per started worker, and those of the workers the pool started in
    # their place before the parent's next look (every 0.25 s; on a loaded machine a
    # replacement can die before it, and CI once counted 5): a few, not a stream.
    assert stderr.count("Traceback") <= 8, stderr
    assert "wrote" not in stdout
    assert not out.exists() and not isobar_usd.clips_folder(out).exists()

    guarded = tmp_path / "guarded.py"
    guarded.write_text(_SCRIPT.format(indent="    ").replace("import isobar_usd\n", "import isobar_usd\n\nif __name__ == \"__main__\":"))
    out = tmp_path / "guarded.usd"
    code, stdout, stderr = _run_script(guarded, src, out)
    assert code == 0, (stdout, stderr)
    assert "wrote [1, 26]" in stdout, stdout
    assert out.is_file()


@pytest.mark.parametrize("jobs, layout", [(1, "clips"), (2, "clips"), (1, "flat")])
def test_keep_going_skips_a_truncated_frame_and_writes_the_others(cli, tmp_path, jobs, layout):
    """One truncated cache file among good frames used to throw away every frame already
    extracted. With --keep-going the bad frame is named on stderr and skipped, the others
    are committed and stitched, and the exit status is 1; without it nothing is written."""
    folder = link_frames(tmp_path / "in", {1: FRAME_01, 2: FRAME_26, 4: FRAME_26})
    bad = folder / "frame_0003.vtk"
    bad.write_bytes(Path(FRAME_01).read_bytes()[:5000])
    out = tmp_path / f"fluid_{layout}.usd"
    args = ["sph", folder / "frame_####.vtk", *CLI_DAM, "-o", out, "-j", str(jobs), "--layout", layout, "-q"]
    plain = run_cli(cli, *args, check=False)
    assert plain.returncode == 1 and "frame 3 (" in plain.stderr and not out.exists(), plain.stderr
    proc = run_cli(cli, *args, "--keep-going", check=False)
    assert proc.returncode == 1, proc.stderr
    assert "isobar-usd: error: frame 3 (" in proc.stderr and "(skipped)" in proc.stderr, proc.stderr
    stage = open_stage(out)
    assert stage.GetStartTimeCode() == 1 and stage.GetEndTimeCode() == 4
    assert [len(mesh_at(stage, t)["points"]) > 1000 for t in (1, 2, 4)] == [True] * 3
    assert isobar_usd.check(out) == []
    # The library says the same in the result.
    result = isobar_usd.write_sequence(folder / "frame_####.vtk", tmp_path / "api.usd", 0.6, keep_going=True,
                                       layout=layout, jobs=jobs, **DAM)
    assert result.frames == [1, 2, 4] and list(result.failed) == [3], result
    assert "frame_0003.vtk" in result.failed[3]
    # Every frame bad: an error naming the first, nothing written.
    with pytest.raises(isobar_usd.InputError, match=r"no frame could be written \(1 failed\); the first: frame 3"):
        isobar_usd.write_sequence({3: bad}, tmp_path / "none.usd", 0.6, keep_going=True, **DAM)
    assert not (tmp_path / "none.usd").exists()
