"""An interrupted write leaves the previous stage intact: an exception inside the writer,
a progress callback that stops it, a failing rename, a killed process."""

from __future__ import annotations

import os
import signal
import subprocess
import time
from pathlib import Path

import numpy as np
import pytest
from conftest import CLI_DAM, DAM, FRAME_26, ISO, link_frames, mesh_at, open_stage

import isobar_usd
from isobar_usd import _atomic, sequence


def snapshot(folder: Path, name: str = "seq") -> dict:
    """Relative path -> bytes of the stage `name` in `folder`: its root and the committed
    files of its clips folder (hidden staging files and the lock file aside)."""
    files = [folder / f"{name}.usd"] + sorted((folder / f"{name}.clips").glob("*"))
    return {
        str(p.relative_to(folder)): p.read_bytes()
        for p in files
        if p.is_file() and not p.name.startswith(".")
    }


@pytest.fixture
def sequence_on_disk(tmp_path, dam_frames):
    out = tmp_path / "seq.usd"
    isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, ISO, **DAM)
    before = snapshot(tmp_path)
    assert set(before) == {"seq.usd", "seq.clips/seq.0001.usdc", "seq.clips/seq.0026.usdc", "seq.clips/manifest.usda"}
    return out, before


def test_exception_inside_the_writer(sequence_on_disk, monkeypatch, dam_frames):
    out, before = sequence_on_disk
    calls = []
    original = sequence.write_clip

    def failing(frame, item, staged, job):
        calls.append(frame)
        if len(calls) == 2:
            raise RuntimeError("injected failure while writing frame 26")
        return original(frame, item, staged, job)

    monkeypatch.setattr(sequence, "write_clip", failing)
    with pytest.raises(isobar_usd.FrameError, match="frame 26 .*injected failure") as info:
        isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, 0.5, **DAM)  # another isovalue
    assert isinstance(info.value.cause, RuntimeError)
    assert calls == [1, 26]
    assert snapshot(out.parent) == before  # frame 1 was written, staged, then discarded
    assert not [p for p in out.parent.rglob(".*.tmp.*")]


def test_exception_while_a_layer_is_authored(sequence_on_disk, monkeypatch, dam_frames):
    """Deeper: the conversion to USD arrays raises half way through a frame."""
    out, before = sequence_on_disk
    from isobar_usd import layers

    original = layers._array
    count = []

    def failing(values, type_name):
        count.append(type_name)
        if len(count) == 9:  # the second frame's attributes
            raise MemoryError("injected")
        return original(values, type_name)

    monkeypatch.setattr(layers, "_array", failing)
    with pytest.raises(isobar_usd.FrameError):
        isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, 0.5, **DAM)
    assert snapshot(out.parent) == before


def test_progress_callback_stops_the_write(sequence_on_disk, dam_frames):
    out, before = sequence_on_disk

    def stop(p):
        raise KeyboardInterrupt

    with pytest.raises(KeyboardInterrupt):
        isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, 0.5, progress=stop, **DAM)
    assert snapshot(out.parent) == before
    assert not [p for p in out.parent.rglob(".*.tmp.*")]


def test_failed_rename_of_a_single_file(tmp_path, monkeypatch):
    out = tmp_path / "one.usda"
    frame = {"points": np.eye(3), "triangles": [[0, 1, 2]]}
    isobar_usd.write_frame(frame, out, time=1)
    before = out.read_bytes()

    def refuse(staged, final):
        raise OSError("injected: disk full")

    monkeypatch.setattr(_atomic, "replace", refuse)
    with pytest.raises(OSError, match="disk full"):
        isobar_usd.write_frame({"points": np.eye(3) * 2, "triangles": [[0, 1, 2]]}, out, time=1)
    assert out.read_bytes() == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["one.usda"]


def test_killed_writer_leaves_the_previous_stage(cli, sequence_on_disk, tmp_path):
    """SIGKILL in the middle of a 40-frame rewrite: the 2-frame stage is untouched; the
    staging files the dead process left are swept by the next write."""
    out, before = sequence_on_disk
    many = link_frames(tmp_path / "many", {i: FRAME_26 for i in range(1, 41)})
    proc = subprocess.Popen(
        [str(cli), "sph", str(many / "frame_####.vtk"), *CLI_DAM, "-o", str(out), "-q"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    clips = isobar_usd.clips_folder(out)
    deadline = time.monotonic() + 120
    staged = []
    try:
        while time.monotonic() < deadline and proc.poll() is None:
            staged = [p for p in clips.iterdir() if p.name.startswith(".seq.") and ".tmp." in p.name]
            if len(staged) >= 3:
                break
            time.sleep(0.02)
        assert proc.poll() is None, f"the writer ended before it could be killed: {proc.stderr.read()!r}"
        os.kill(proc.pid, signal.SIGKILL)
    finally:
        proc.wait(timeout=30)
    assert proc.returncode == -signal.SIGKILL
    assert len(staged) >= 3
    assert snapshot(out.parent) == before
    stage = open_stage(out)
    assert stage.GetEndTimeCode() == 26 and mesh_at(stage, 26)["points"] is not None
    del stage
    leftovers = [p for p in clips.iterdir() if ".tmp." in p.name]
    assert leftovers, "the killed process left its staging files"

    # the next write sweeps what the dead process left, then writes normally
    result = isobar_usd.write_sequence(many / "frame_####.vtk", out, ISO, frames="1-3", **DAM)
    assert result.frames == [1, 2, 3, 26]
    assert not [p for p in clips.iterdir() if ".tmp." in p.name]
    assert isobar_usd.check(out) == []


@pytest.mark.parametrize("signum, jobs", [(signal.SIGTERM, 1), (signal.SIGINT, 1), (signal.SIGTERM, 2)])
def test_sigterm_and_ctrl_c_unwind_and_clean_up(cli, sequence_on_disk, tmp_path, signum, jobs):
    """SIGTERM (a farm's time limit) and Ctrl-C stop the writer at the next safe point:
    exit status 130, the previous stage intact, no staging file left behind."""
    out, before = sequence_on_disk
    many = link_frames(tmp_path / "many", {i: FRAME_26 for i in range(1, 41)})
    proc = subprocess.Popen(
        [str(cli), "sph", str(many / "frame_####.vtk"), *CLI_DAM, "-o", str(out), "-q", "--jobs", str(jobs)],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        # Ctrl-C as a terminal delivers it: a test run started in the background by a
        # shell without job control would hand the writer an ignored SIGINT.
        preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL),
    )
    clips = isobar_usd.clips_folder(out)
    deadline = time.monotonic() + 120
    while time.monotonic() < deadline and proc.poll() is None:
        if len([p for p in clips.iterdir() if ".tmp." in p.name]) >= 2:
            break
        time.sleep(0.02)
    assert proc.poll() is None, proc.communicate()
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "interrupted" in err
    assert snapshot(out.parent) == before
    assert not [p for p in clips.iterdir() if ".tmp." in p.name]


def test_request_stop_from_python(sequence_on_disk, dam_frames):
    out, before = sequence_on_disk

    def stop_after_first(p):
        isobar_usd.request_stop()

    with pytest.raises(KeyboardInterrupt):
        isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, 0.5, progress=stop_after_first, **DAM)
    assert snapshot(out.parent) == before
    # the request was used up: the next write runs
    assert isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, 0.5, **DAM).frames == [1, 26]
