"""The Python API: frames from Surface objects and arrays, streamed sequences, flat and
clips layouts, partial rewrites, restitching, parallel writers, patterns."""

from __future__ import annotations

import os
import warnings

import numpy as np
import pytest
from conftest import (
    DAM,
    DEMO,
    FRAME_01,
    FRAME_26,
    ISO,
    assert_same_mesh,
    link_frames,
    mesh_at,
    need,
    open_stage,
    run_cli,
    validation_errors,
)

import isobar
import isobar_usd


def _primvar(stage, name, time, path="/Fluid/Surface"):
    from pxr import UsdGeom

    pv = UsdGeom.PrimvarsAPI(stage.GetPrimAtPath(path)).GetPrimvar(name)
    assert pv, f"no primvar {name}"
    return pv


def test_demo_frame_surface_with_primvars(tmp_path):
    """The embedded dam-break demo (46,656 particles, h array): velocity and pressure."""
    with isobar.Particles.read(str(need(DEMO))) as particles:
        assert len(particles) == 46656
        surface = isobar.extract(particles, 0.6, grid_factor=0.375, attributes=["velocity", "pressure"])
    out = tmp_path / "demo.usd"
    result = isobar_usd.write_frame(surface, out, time=7)
    assert result.frame == 7 and result.points == surface.n_points and result.triangles == surface.n_triangles
    stage = open_stage(out)
    got = mesh_at(stage, 7)
    assert_same_mesh(got, surface)  # velocities from the 'velocity' attribute
    pressure = _primvar(stage, "pressure", 7)
    assert pressure.GetInterpolation() == "vertex" and str(pressure.GetTypeName()) == "float[]"
    np.testing.assert_array_equal(np.asarray(pressure.Get(7)), surface.attributes["pressure"].astype(np.float32))
    names = {pv.GetPrimvarName() for pv in __import__("pxr").UsdGeom.PrimvarsAPI(got["mesh"]).GetAuthoredPrimvars()}
    assert names == {"pressure"}  # "auto": not SumOfWeights, not the velocity used for velocities
    assert validation_errors(stage) == []
    assert isobar_usd.check(out) == []


def test_frame_from_arrays(tmp_path):
    points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=np.float64)
    triangles = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], dtype=np.int64)
    attributes = {
        "temperature": np.arange(4.0),
        "uv": np.arange(8.0).reshape(4, 2),
        "stress:tensor": np.arange(20.0).reshape(4, 5),
        "SumOfWeights": np.ones(4),
    }
    vel = np.tile([1.0, 2.0, 3.0], (4, 1))
    out = tmp_path / "tet.usda"
    isobar_usd.write_frame({"points": points, "triangles": triangles, "attributes": attributes, "velocities": vel}, out, time=3, fps=30)
    stage = open_stage(out)
    got = mesh_at(stage, 3)
    np.testing.assert_array_equal(got["points"], points.astype(np.float32))
    np.testing.assert_array_equal(got["indices"], triangles.ravel())
    np.testing.assert_array_equal(got["velocities"], vel.astype(np.float32))
    assert got["normals"] is None
    assert str(_primvar(stage, "uv", 3).GetTypeName()) == "float2[]"
    stress = _primvar(stage, "stress_tensor", 3)
    assert stress.GetElementSize() == 5 and len(stress.Get(3)) == 20
    with pytest.raises(AssertionError):
        _primvar(stage, "SumOfWeights", 3)
    assert isobar_usd.check(out) == []
    assert validation_errors(stage) == []

    # a tuple works too, and an explicit primvar list
    out2 = tmp_path / "tuple.usda"
    isobar_usd.write_frame((points, triangles, None, attributes), out2, primvars=["SumOfWeights"])
    assert np.asarray(_primvar(open_stage(out2), "SumOfWeights", 0).Get(0)).tolist() == [1, 1, 1, 1]


@pytest.mark.parametrize(
    "frame, message",
    [
        ({"points": np.zeros((4, 2)), "triangles": np.zeros((1, 3), int)}, "points must have shape"),
        ({"points": np.zeros((4, 3)), "triangles": np.array([[0, 1, 4]])}, "index 4 is out of range for 4 points"),
        ({"points": np.zeros((4, 3)), "triangles": np.zeros((1, 3))}, "must be integer"),
        ({"points": np.zeros((4, 3))}, "no triangles"),
        ({"points": np.full((4, 3), np.nan), "triangles": np.zeros((1, 3), int)}, "NaN"),
        ({"points": np.zeros((4, 3)), "triangles": np.zeros((1, 3), int), "normals": np.zeros((3, 3))}, "normals must have shape (4, 3)"),
        ({"points": np.zeros((4, 3)), "triangles": np.zeros((1, 3), int), "attributes": {"p": np.zeros(5)}}, "one value per point (4)"),
    ],
)
def test_bad_arrays_are_refused(tmp_path, frame, message):
    out = tmp_path / "bad.usda"
    with pytest.raises(isobar_usd.InputError, match=None) as info:
        isobar_usd.write_frame(frame, out, primvars="auto")
    assert message in str(info.value)
    assert not out.exists()


def test_missing_primvar_and_velocity_names(tmp_path):
    frame = {"points": np.zeros((3, 3)), "triangles": [[0, 1, 2]], "attributes": {"a": np.zeros(3)}}
    with pytest.raises(isobar_usd.InputError, match="no attribute 'b' on the surface .attributes: a."):
        isobar_usd.write_frame(frame, tmp_path / "x.usda", primvars=["b"])
    with pytest.raises(isobar_usd.InputError, match="no attribute 'vel' for velocities"):
        isobar_usd.write_frame(frame, tmp_path / "x.usda", velocities="vel")


def test_streamed_sequence_of_surfaces(tmp_path, reference):
    """A generator of (frame, Surface) pairs: written one at a time, clips layout."""
    produced = []

    def frames():
        for f, src in ((1, FRAME_01), (26, FRAME_26)):
            s = reference(need(src), attributes=["velocity"])
            produced.append(f)
            yield f, s

    seen = []
    out = tmp_path / "stream.usd"
    result = isobar_usd.write_sequence(frames(), out, progress=lambda p: seen.append((p.frame, p.done, p.total)))
    assert result.layout == "clips" and result.frames == [1, 26] and result.written == [1, 26]
    assert seen == [(1, 1, None), (26, 2, None)]
    stage = open_stage(out)
    for f, src in ((1, FRAME_01), (26, FRAME_26)):
        assert_same_mesh(mesh_at(stage, f), reference(src, attributes=["velocity"]))
    assert validation_errors(stage) == []


def test_flat_and_clips_layouts_compose_the_same(tmp_path, dam_frames):
    flat = isobar_usd.write_sequence(dam_frames / "frame_####.vtk", tmp_path / "flat.usd", ISO, layout="flat", **DAM)
    clips = isobar_usd.write_sequence(dam_frames / "frame_####.vtk", tmp_path / "clips.usd", ISO, layout="clips", **DAM)
    assert flat.layout == "flat" and clips.layout == "clips" and flat.frames == clips.frames == [1, 26]
    assert flat.schema == clips.schema
    assert not (tmp_path / "flat.clips").exists()
    a, b = open_stage(tmp_path / "flat.usd"), open_stage(tmp_path / "clips.usd")
    for f in (1, 26):
        ma, mb = mesh_at(a, f), mesh_at(b, f)
        for key in ("points", "counts", "indices", "normals", "extent", "velocities"):
            np.testing.assert_array_equal(ma[key], mb[key])
    assert validation_errors(a) == [] and isobar_usd.check(tmp_path / "flat.usd") == []


def test_several_isovalues_give_an_isovalue_primvar(tmp_path, dam_frames, reference):
    out = tmp_path / "multi.usd"
    isobar_usd.write_sequence(dam_frames / "frame_0026.vtk", out, [0.4, 0.6], frames=[26], **DAM)
    stage = open_stage(out)
    surface = reference(dam_frames / "frame_0026.vtk", iso=[0.4, 0.6], attributes=["velocity"])
    iso = np.asarray(_primvar(stage, "Isovalue", 26).Get(26))
    np.testing.assert_array_equal(iso, surface.attributes["Isovalue"].astype(np.float32))
    assert set(np.unique(iso)) == {np.float32(0.4), np.float32(0.6)}


def test_partial_rewrite_keeps_the_other_frames(tmp_path, dam_frames, reference):
    out = tmp_path / "seq.usd"
    isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, ISO, **DAM)
    first = (isobar_usd.clip_path(out, 1)).read_bytes()
    # rewrite frame 26 only, at another isovalue
    result = isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, 0.5, frames="26", **DAM)
    assert result.written == [26] and result.frames == [1, 26]
    assert isobar_usd.clip_path(out, 1).read_bytes() == first
    stage = open_stage(out)
    assert_same_mesh(mesh_at(stage, 26), reference(dam_frames / "frame_0026.vtk", iso=0.5, attributes=["velocity"]))
    assert_same_mesh(mesh_at(stage, 1), reference(dam_frames / "frame_0001.vtk", attributes=["velocity"]))
    # a full run replaces the sequence: frames it does not write go
    only = link_frames(tmp_path / "only", {26: FRAME_26})
    result = isobar_usd.write_sequence(only / "frame_####.vtk", out, ISO, layout="clips", **DAM)
    assert result.frames == [26]
    assert not isobar_usd.clip_path(out, 1).exists()
    assert open_stage(out).GetStartTimeCode() == 26


def test_a_root_with_the_same_stem_keeps_its_frames(tmp_path, dam_frames):
    """fluid.usd and fluid.usda share the clips folder fluid.clips/: a second sequence
    written as fluid.usda replaced fluid.usd's frames and removed those it lacked."""
    out = tmp_path / "fluid.usd"
    isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, ISO, **DAM)
    before = {p.name: p.read_bytes() for p in isobar_usd.clips_folder(out).iterdir()}
    only = link_frames(tmp_path / "only", {26: FRAME_26})
    with pytest.raises(isobar_usd.InputError, match="also the one of .*fluid.usd"):
        isobar_usd.write_sequence(only / "frame_####.vtk", tmp_path / "fluid.usda", ISO, layout="clips", **DAM)
    assert {p.name: p.read_bytes() for p in isobar_usd.clips_folder(out).iterdir()} == before
    assert not (tmp_path / "fluid.usda").exists()


def test_a_partial_clips_rewrite_of_a_flat_root_is_refused(tmp_path, dam_frames):
    """A flat run over a clips root leaves the old clips folder; a later partial clips run
    joined its stale frames (another isovalue) to the new one without a word."""
    out = tmp_path / "fluid.usd"
    isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, ISO, **DAM)
    isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, 0.5, layout="flat", **DAM)
    flat = out.read_bytes()
    with pytest.raises(isobar_usd.InputError, match="is a flat layer"):
        isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, 0.5, frames="26", layout="clips", **DAM)
    assert out.read_bytes() == flat
    # Every frame: the clips folder is this run's alone again.
    result = isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, 0.5, layout="clips", **DAM)
    assert result.frames == [1, 26]


def test_frames_missing_from_a_sequence_are_reported(cli, tmp_path):
    """Frames 1, 2, 4 and 7 at stride 1: 3, 5 and 6 missing, said with the frame after each
    gap (in the result and on stderr), as the isobar CLI says it; a steady stride of 2
    lacks nothing."""
    from conftest import CLI_DAM, run_cli

    frames = link_frames(tmp_path / "gappy", {1: FRAME_01, 2: FRAME_26, 4: FRAME_01, 7: FRAME_26})
    result = isobar_usd.write_sequence(frames / "frame_####.vtk", tmp_path / "gappy.usd", ISO, **DAM)
    assert result.warnings == {
        4: ["frame 3 missing: the stage goes from frame 2 to frame 4"],
        7: ["frames 5, 6 missing: the stage goes from frame 4 to frame 7"],
    }, result.warnings
    proc = run_cli(cli, "sph", frames / "frame_####.vtk", *CLI_DAM, "-o", tmp_path / "cli.usd")
    assert "isobar-usd: warning: frame 7 (" in proc.stderr and "frames 5, 6 missing" in proc.stderr, proc.stderr
    steady = link_frames(tmp_path / "steady", {1: FRAME_01, 3: FRAME_26, 5: FRAME_01})
    assert isobar_usd.write_sequence(steady / "frame_####.vtk", tmp_path / "steady.usd", ISO, **DAM).warnings == {}


def test_write_frame_into_a_sequence_then_stitch(tmp_path, reference):
    out = tmp_path / "manual.usd"
    isobar_usd.clips_folder(out).mkdir()
    for f, src in ((5, FRAME_01), (6, FRAME_26)):
        isobar_usd.write_frame(reference(src, attributes=["velocity"]), isobar_usd.clip_path(out, f), time=f)
    assert not out.exists()
    result = isobar_usd.stitch(out)
    assert result.frames == [5, 6]
    stage = open_stage(out)
    assert stage.GetStartTimeCode() == 5 and stage.GetEndTimeCode() == 6
    assert_same_mesh(mesh_at(stage, 6), reference(FRAME_26, attributes=["velocity"]))
    assert isobar_usd.check(out) == []


def test_separate_writers_then_stitch(cli, tmp_path, dam_frames):
    """Two invocations with --frames and --no-stitch (as on a farm), then `stitch`."""
    from conftest import CLI_DAM, run_cli

    out = tmp_path / "farm.usd"
    run_cli(cli, "sph", dam_frames / "frame_####.vtk", *CLI_DAM, "-o", out, "--frames", "1", "--no-stitch", "-q")
    run_cli(cli, "sph", dam_frames / "frame_####.vtk", *CLI_DAM, "-o", out, "--frames", "26", "--no-stitch", "-q")
    assert not out.exists()
    proc = run_cli(cli, "stitch", out)
    assert "2 frame(s) (1..26)" in proc.stdout
    stage = open_stage(out)
    assert stage.GetStartTimeCode() == 1 and stage.GetEndTimeCode() == 26
    assert validation_errors(stage) == [] and isobar_usd.check(out) == []


def test_frames_rewritten_with_other_settings_are_named_by_stitch_and_check(cli, tmp_path, dam_frames):
    """A --frames re-run with another isovalue and h (a typo on the farm) used to make a
    mixed sequence that stitch and check both passed without a word."""
    from conftest import CLI_DAM, run_cli

    out = tmp_path / "mixed.usd"
    run_cli(cli, "sph", dam_frames / "frame_####.vtk", *CLI_DAM, "-o", out, "-q")
    assert isobar_usd.check(out) == []
    other = ["--iso", "0.3", "--h", "0.06", "--grid-factor", "0.375"]
    proc = run_cli(cli, "sph", dam_frames / "frame_####.vtk", *other, "-o", out, "--frames", "26", "-q")
    assert "isobar-usd: warning: the frames were extracted with different settings: frame(s) 26 with" in proc.stderr
    assert "iso [0.3] (not [0.6])" in proc.stderr and "h 0.06 (not 0.05)" in proc.stderr, proc.stderr
    result = isobar_usd.stitch(out)
    assert len(result.notes) == 1 and "against frame(s) 1" in result.notes[0], result.notes
    problems = isobar_usd.check(out)
    assert [(p.severity, p.check) for p in problems] == [("warning", "settings")], problems
    assert "frame(s) 26 with" in problems[0].message
    # The same settings again, or with only a larger memory budget (what an over-budget
    # error asks for), or through Python with a default spelled out: nothing to say.
    run_cli(cli, "sph", dam_frames / "frame_####.vtk", *CLI_DAM, "-o", out, "--frames", "26", "-q")
    assert isobar_usd.stitch(out).notes == [] and isobar_usd.check(out) == []
    proc = run_cli(cli, "sph", dam_frames / "frame_####.vtk", *CLI_DAM, "--memory-budget", "2", "-o", out,
                   "--frames", "26", "-q")
    assert "warning" not in proc.stderr and isobar_usd.check(out) == [], proc.stderr
    result = isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, 0.6, frames="26", kernel="cubic",
                                       method="correctors", **DAM)
    assert result.notes == [] and isobar_usd.check(out) == []


def test_parallel_jobs_write_the_same_bytes(tmp_path):
    frames = link_frames(tmp_path / "frames", {i: FRAME_01 if i % 2 else FRAME_26 for i in range(1, 7)})
    serial = isobar_usd.write_sequence(frames / "frame_####.vtk", tmp_path / "serial.usd", ISO, jobs=1, **DAM)
    parallel = isobar_usd.write_sequence(frames / "frame_####.vtk", tmp_path / "parallel.usd", ISO, jobs=2, **DAM)
    assert serial.frames == parallel.frames == list(range(1, 7))
    for f in range(1, 7):
        a = isobar_usd.clip_path(tmp_path / "serial.usd", f).read_bytes()
        b = isobar_usd.clip_path(tmp_path / "parallel.usd", f).read_bytes()
        assert a == b, f
    assert isobar_usd.check(tmp_path / "parallel.usd") == []


def test_stitch_refuses_conflicting_frames(tmp_path):
    out = tmp_path / "mixed.usd"
    isobar_usd.clips_folder(out).mkdir()
    base = {"points": np.eye(3), "triangles": [[0, 1, 2]]}
    isobar_usd.write_frame({**base, "attributes": {"p": np.zeros(3)}}, isobar_usd.clip_path(out, 1), time=1)
    isobar_usd.write_frame({**base, "attributes": {"p": np.zeros((3, 2))}}, isobar_usd.clip_path(out, 2), time=2)
    with pytest.raises(isobar_usd.StitchError, match="attribute 'primvars:p' is float\\[\\] .* in frame 1 but float2\\[\\]"):
        isobar_usd.stitch(out)
    isobar_usd.write_frame({**base, "attributes": {"p": np.zeros(3)}}, isobar_usd.clip_path(out, 2), time=2, meters_per_unit=0.01)
    with pytest.raises(isobar_usd.StitchError, match="metersPerUnit"):
        isobar_usd.stitch(out)
    isobar_usd.write_frame({**base, "attributes": {"p": np.zeros(3)}}, isobar_usd.clip_path(out, 2), time=3)
    with pytest.raises(isobar_usd.StitchError, match="holds frame"):
        isobar_usd.stitch(out)
    # frames where only some have an attribute are fine: the manifest holds the union
    isobar_usd.write_frame(base, isobar_usd.clip_path(out, 2), time=2)
    assert isobar_usd.stitch(out).frames == [1, 2]
    stage = open_stage(out)
    assert isobar_usd.check(out) == []
    assert _primvar(stage, "p", 1).Get(1) is not None
    with pytest.raises(isobar_usd.StitchError, match="no clips folder"):
        isobar_usd.stitch(tmp_path / "nothing.usd")
    isobar_usd.clips_folder(tmp_path / "nothing.usd").mkdir()
    with pytest.raises(isobar_usd.StitchError, match="no frame layers"):
        isobar_usd.stitch(tmp_path / "nothing.usd")


# -- patterns and frame selections ---------------------------------------------------


def test_patterns_follow_the_command_line(tmp_path):
    for name in ["frame_0010.vtk", "frame_0002.vtk", "frame_0001.vtk", "frame_12345.vtk", "frame_01.vtk",
                 "frame_00010.vtk", "frame_0003.vtu", "other_0001.vtk", "frame_0004.bgeo.gz"]:
        (tmp_path / name).write_bytes(b"")
    (tmp_path / "frame_0005.vtk").mkdir()
    names = lambda p: [x.name for x in isobar_usd.expand_sequence(p)]  # noqa: E731
    padded = ["frame_0001.vtk", "frame_0002.vtk", "frame_0010.vtk", "frame_12345.vtk"]
    assert names(f"{tmp_path}/frame_####.vtk") == padded
    assert names(f"{tmp_path}/frame_%04d.vtk") == padded
    assert names(f"{tmp_path}/frame_0002.vtk") == padded
    assert names(f"{tmp_path}/frame_{{}}.vtk") == [
        "frame_0001.vtk", "frame_01.vtk", "frame_0002.vtk", "frame_00010.vtk", "frame_0010.vtk", "frame_12345.vtk"]
    assert len(names(f"{tmp_path}/frame_%d.vtk")) == 6
    assert names(f"{tmp_path}/frame_0004.bgeo.gz") == ["frame_0004.bgeo.gz"]
    assert isobar_usd.expand_sequence(f"{tmp_path}/frame_####.vtk")[0] == tmp_path / "frame_0001.vtk"
    with pytest.raises(isobar_usd.InputError, match="nothing_####.vtk.*no file in"):
        isobar_usd.expand_sequence(f"{tmp_path}/nothing_####.vtk")
    with pytest.raises(isobar_usd.InputError, match="missing.vtk.*no such file"):
        isobar_usd.expand_sequence(f"{tmp_path}/missing.vtk")
    with pytest.raises(isobar_usd.InputError, match="placeholder must be in the file name"):
        isobar_usd.expand_sequence(f"{tmp_path}/f_##/a.vtk")
    assert isobar_usd.frame_number("a/frame_0042.vtk") == 42
    assert isobar_usd.frame_number("frame_7.bgeo.gz") == 7
    assert isobar_usd.frame_number("particles.vtk") is None
    # relative patterns stay relative
    cwd = os.getcwd()
    try:
        os.chdir(tmp_path)
        assert [str(p) for p in isobar_usd.expand_sequence("frame_####.vtk")][:1] == ["frame_0001.vtk"]
    finally:
        os.chdir(cwd)


def test_frame_selections():
    sel = isobar_usd.parse_frame_selection
    assert [f for f in range(30) if sel("10-12,20,25-")(f)] == [10, 11, 12, 20, 25, 26, 27, 28, 29]
    assert [f for f in range(5) if sel("-2")(f)] == [0, 1, 2]
    assert sel(None) is None and sel(3)(3) and not sel([1, 2])(3)
    for bad in ("a", "5-3", "1-2-3", "", "-"):
        with pytest.raises(isobar_usd.InputError):
            sel(bad)


def test_unknown_extraction_option(tmp_path, dam_frames):
    with pytest.raises(isobar_usd.InputError, match="unknown extraction option grid_size .*grid_factor"):
        isobar_usd.write_sequence(dam_frames / "frame_####.vtk", tmp_path / "x.usd", ISO, h=0.05, grid_size=1)


def test_an_empty_frame_in_a_sequence(tmp_path):
    """A frame with no surface (all fluid gone, iso out of range) is written as empty
    arrays and USD's empty extent; the sequence stays valid."""
    tet = {"points": np.eye(3), "triangles": [[0, 1, 2]], "normals": np.tile([0.0, 0.0, 1.0], (3, 1))}
    empty = {"points": np.zeros((0, 3)), "triangles": np.zeros((0, 3), np.uint32), "normals": np.zeros((0, 3))}
    out = tmp_path / "gap.usd"
    result = isobar_usd.write_sequence({1: tet, 2: empty, 3: tet}, out)
    assert result.frames == [1, 2, 3]
    stage = open_stage(out)
    got = mesh_at(stage, 2)
    assert got["points"].shape == (0, 3) and got["indices"].shape == (0,)
    assert got["extent"][0, 0] > got["extent"][1, 0]  # USD's empty range
    assert isobar_usd.check(out) == []
    assert validation_errors(stage) == []


@pytest.mark.parametrize("layout", ["clips", "flat"])
def test_a_frame_with_no_particles(tmp_path, layout):
    """An emitter's first frame holds 0 particles: that frame is an empty surface with the
    sequence's primvars (no rows; the core's Isovalue too, for several isovalues), a
    warning names the file, and the next frame equals the core's extraction. An array
    the empty file does not declare (VTK writes no point data for 0 points) is not an
    error, and that frame shows none of the next frame's values (in a flat layer USD
    would hold the nearest sample: 400 pressures against 0 points)."""
    rng = np.random.default_rng(7)
    blob = rng.normal(scale=0.04, size=(400, 3))
    arrays = {"velocity": np.tile([0.0, -1.0, 0.0], (400, 1)), "pressure": np.linalg.norm(blob, axis=1)}
    folder = tmp_path / "frames"
    folder.mkdir()
    np.savez(folder / "drip_0001.npz", positions=blob[:0])
    np.savez(folder / "drip_0002.npz", positions=blob, **arrays)
    out = tmp_path / "drip.usda"
    isos = [ISO, 0.3]
    options = dict(h=0.03, attributes=["pressure"])
    result = isobar_usd.write_sequence(folder / "drip_####.npz", out, isos, layout=layout, velocities="velocity", **options)
    assert result.frames == [1, 2] and result.layout == layout
    assert result.warnings == {1: ["drip_0001.npz holds 0 particles: an empty surface"]}

    from pxr import UsdGeom

    stage = open_stage(out)
    empty = mesh_at(stage, 1)
    assert empty["points"].shape == (0, 3) and empty["indices"].shape == (0,)
    assert empty["normals"].shape == (0, 3)
    assert empty["velocities"] is None or empty["velocities"].shape == (0, 3)
    primvars = UsdGeom.PrimvarsAPI(empty["mesh"])
    for name in ("Isovalue", "pressure"):
        value = primvars.GetPrimvar(name).Get(1)
        assert value is None or len(value) == 0, (name, value)
    with isobar.Particles.read(str(folder / "drip_0002.npz")) as particles:
        surface = isobar.extract(particles, isos, h=0.03, attributes=["pressure", "velocity"])
    assert surface.triangles.shape[0] > 0
    assert_same_mesh(mesh_at(stage, 2), surface)
    for name in ("pressure", "Isovalue"):
        np.testing.assert_array_equal(primvars.GetPrimvar(name).Get(2), surface.attributes[name].astype(np.float32))
    assert isobar_usd.check(out) == []
    assert validation_errors(stage) == []


def test_an_empty_extraction(tmp_path, dam_frames):
    """An isovalue above every value of the field: no triangles, still a valid stage."""
    out = tmp_path / "none.usda"
    result = isobar_usd.write_frame(dam_frames / "frame_0026.vtk", out, 1e6, h=0.05)
    assert result.triangles == 0 and result.frame == 26
    assert isobar_usd.check(out) == []


def test_an_isovalue_the_field_never_crosses_is_a_warning(cli, tmp_path, dam_frames):
    """No surface at the isovalue: the frames are written empty (exit status 0) and the
    core's warning is printed once per frame, naming it as an error would, not a second
    time through Python's warnings (from the parent or a worker process); the API keeps
    the warnings on the result and the progress reports."""
    out = tmp_path / "none.usd"
    proc = run_cli(cli, "sph", dam_frames / "frame_####.vtk", "--iso", "1e6", "--h", "0.05", "-j", "2", "-o", out)
    warned = sorted(line for line in proc.stderr.splitlines() if "no surface at isovalue" in line)
    assert len(warned) == 2, proc.stderr
    for frame, line in zip((1, 26), warned):
        assert line.startswith(f"isobar-usd: warning: frame {frame} ({dam_frames / f'frame_{frame:04d}.vtk'}): "), line
    assert "IsobarWarning" not in proc.stderr, proc.stderr
    assert isobar_usd.check(out) == []

    progress = []
    with warnings.catch_warnings():
        warnings.simplefilter("error", isobar.IsobarWarning)
        result = isobar_usd.write_sequence(dam_frames / "frame_####.vtk", tmp_path / "api.usd", 1e6, h=0.05, progress=progress.append)
    assert sorted(result.warnings) == [1, 26]
    assert all(len(texts) == 1 and texts[0].startswith("no surface at isovalue") for texts in result.warnings.values())
    assert {p.frame: p.warnings for p in progress} == result.warnings


def test_check_reports_a_corrupt_frame_layer_instead_of_raising(tmp_path, dam_frames):
    out = tmp_path / "broken.usd"
    isobar_usd.write_sequence(dam_frames / "frame_####.vtk", out, 0.6, **DAM)
    isobar_usd.clip_path(out, 26).write_bytes(b"PXR-USDC" + b"\0" * 64)
    problems = isobar_usd.check(out)
    assert any(p.severity == "error" and p.check == "clips" and "broken.0026.usdc cannot be read" in p.message
               for p in problems), problems
