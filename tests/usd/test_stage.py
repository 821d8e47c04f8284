"""The stage `isobar-usd sph` writes for the SPlisHSPlasH frames: its samples are the
core's meshes, its metadata and extents are right, usd-core's validators pass, and broken
stages are caught."""

from __future__ import annotations


import numpy as np
import pytest
from conftest import CLI_DAM, FRAME_01, FRAME_26, assert_same_mesh, mesh_at, open_stage, run_cli, validation_errors


@pytest.fixture(scope="module")
def written(cli, dam_frames, tmp_path_factory):
    """fluid.usd written by the command line from frames 1 and 26 (velocity -> velocities)."""
    out = tmp_path_factory.mktemp("stage") / "fluid.usd"
    proc = run_cli(cli, "sph", dam_frames / "frame_####.vtk", *CLI_DAM, "-o", out)
    assert "2 frame(s) (1..26)" in proc.stdout
    assert "frame 26" in proc.stderr  # per-frame progress
    return out


def test_the_command_is_installed(cli):
    proc = run_cli(cli, "--version")
    assert proc.stdout.startswith("isobar-usd ")
    proc = run_cli(cli, "sph", "--help")
    for option in ("--h-array", "--kernel", "--grid-factor", "--h-scale", "--preview", "--no-trim", "--attributes", "--jobs", "--frames", "--fps"):
        assert option in proc.stdout


def test_stage_metadata(written):
    from isobar_usd.layers import HOLD_BEFORE
    from pxr import UsdGeom

    stage = open_stage(written)
    layer = stage.GetRootLayer()
    assert stage.GetDefaultPrim().GetPath() == "/Fluid"
    assert stage.GetStartTimeCode() == 1 and stage.GetEndTimeCode() == 26
    assert stage.GetTimeCodesPerSecond() == 24 and stage.GetFramesPerSecond() == 24
    assert UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert UsdGeom.GetStageUpAxis(stage) == "Y"
    assert layer.pseudoRoot.HasInfo("metersPerUnit") and layer.pseudoRoot.HasInfo("upAxis")
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Fluid/Surface"))
    assert mesh.GetSubdivisionSchemeAttr().Get() == "none"
    assert mesh.GetOrientationAttr().Get() == "rightHanded"
    assert mesh.GetNormalsInterpolation() == "vertex"
    for attr in (mesh.GetPointsAttr(), mesh.GetFaceVertexCountsAttr(), mesh.GetFaceVertexIndicesAttr(),
                 mesh.GetNormalsAttr(), mesh.GetExtentAttr(), mesh.GetVelocitiesAttr()):
        # Frame 1's values again just before frame 26 (other point counts: held, extent too).
        assert attr.GetTimeSamples() == [1.0, 26.0 - HOLD_BEFORE, 26.0], attr.GetName()


def test_samples_equal_the_cores_mesh(written, dam_frames, reference):
    stage = open_stage(written)
    for frame, source in ((1, FRAME_01), (26, FRAME_26)):
        surface = reference(dam_frames / f"frame_{frame:04d}.vtk", attributes=["velocity"])
        assert surface.n_triangles > 1000
        got = mesh_at(stage, frame)
        assert_same_mesh(got, surface)
        assert got["normals"].shape == got["points"].shape


def test_between_frames_the_earlier_frame_holds(written, reference, dam_frames):
    stage = open_stage(written)
    surface = reference(dam_frames / "frame_0001.vtk", attributes=["velocity"])
    got = mesh_at(stage, 13.5)  # topology differs between frames: no interpolation
    np.testing.assert_array_equal(got["indices"], surface.triangles.astype(np.int32).ravel())
    np.testing.assert_array_equal(got["points"], surface.points.astype(np.float32))


def test_extents(written):
    from pxr import UsdGeom

    stage = open_stage(written)
    for frame in (1, 26):
        got = mesh_at(stage, frame)
        pts = got["points"]
        np.testing.assert_array_equal(got["extent"], np.stack([pts.min(0), pts.max(0)]))
        np.testing.assert_array_equal(got["extent"], np.asarray(UsdGeom.PointBased.ComputeExtent(got["mesh"].GetPointsAttr().Get(frame))))
        assert len(got["normals"]) == len(pts)
        # the stage's bound at that time is the frame's
        bound = UsdGeom.BBoxCache(frame, [UsdGeom.Tokens.default_]).ComputeWorldBound(stage.GetPrimAtPath("/Fluid"))
        box = bound.ComputeAlignedRange()
        np.testing.assert_allclose([box.GetMin(), box.GetMax()], got["extent"], rtol=1e-6)


def _points_outside_the_extent(stage, time):
    got = mesh_at(stage, time)
    pts, (lo, hi) = got["points"], np.asarray(got["extent"])
    return int(np.count_nonzero((pts < lo).any(1) | (pts > hi).any(1)))


@pytest.mark.parametrize("layout", ["clips", "flat"])
def test_between_frames_of_other_point_counts_the_extent_holds_with_the_points(tmp_path, layout):
    """Between frames whose point counts differ USD holds the points but interpolated the
    extent: halfway, points lay outside it (a renderer's motion-blur sample there culls
    them), and next to an empty frame (an isovalue not crossed) the extent's corners were
    near ±FLT_MAX/2, around no point at all."""
    import isobar_usd

    def tetra(offset, scale):
        points = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], np.float32) * scale + offset
        return points, np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]], np.int32)

    def two_tetras(offset):
        (p, t), (q, u) = tetra(offset, 1.0), tetra(offset + 3.0, 0.5)
        return np.vstack([p, q]), np.vstack([t, u + 4])

    empty = (np.zeros((0, 3), np.float32), np.zeros((0, 3), np.int32))
    frames = {1: two_tetras(0.0), 5: tetra(10.0, 2.0), 8: empty, 10: two_tetras(-4.0)}
    out = tmp_path / f"{layout}.usda"
    isobar_usd.write_sequence(frames, out, layout=layout)
    stage = open_stage(out)
    assert [len(mesh_at(stage, t)["points"]) for t in (1, 5, 8, 10)] == [8, 4, 0, 8]
    for time in (1, 1.5, 3, 4.99, 5, 5.5, 7.99, 8, 9, 9.999, 10):
        assert _points_outside_the_extent(stage, time) == 0, time
        if len(mesh_at(stage, time)["points"]):  # the extent is the held points' own
            got = mesh_at(stage, time)
            np.testing.assert_array_equal(got["extent"], np.stack([got["points"].min(0), got["points"].max(0)]))
    assert validation_errors(stage) == []


def test_orientation_matches_the_winding(written):
    """rightHanded: a triangle's (b-a)x(c-a) points where its vertex normals point."""
    stage = open_stage(written)
    got = mesh_at(stage, 26)
    p, t = got["points"].astype(np.float64), got["indices"].reshape(-1, 3)
    face = np.cross(p[t[:, 1]] - p[t[:, 0]], p[t[:, 2]] - p[t[:, 0]])
    vertex = got["normals"][t].sum(axis=1)
    agree = np.mean(np.einsum("ij,ij->i", face, vertex) > 0)
    assert agree > 0.999, agree


def test_usd_validators_pass(written):
    import isobar_usd

    stage = open_stage(written)
    assert validation_errors(stage) == []
    problems = isobar_usd.check(written)
    assert [str(p) for p in problems if p.severity != "info"] == []


def test_check_command(cli, written):
    proc = run_cli(cli, "check", written)
    assert "0 error(s)" in proc.stdout


def test_each_frame_layer_is_a_stage_of_its_own(written):
    import isobar_usd
    from pxr import Usd

    clips = isobar_usd.clips_folder(written)
    layers = sorted(p.name for p in clips.iterdir() if not p.name.startswith("."))
    assert layers == ["fluid.0001.usdc", "fluid.0026.usdc", "manifest.usda"]
    stage = Usd.Stage.Open(str(clips / "fluid.0026.usdc"))
    assert stage.GetStartTimeCode() == 26 and stage.GetDefaultPrim().GetPath() == "/Fluid"
    assert validation_errors(stage) == []
    assert isobar_usd.check(clips / "fluid.0026.usdc") == []
    # the root holds no samples itself: the values come from the clips
    from pxr import Sdf

    root = Sdf.Layer.OpenAsAnonymous(str(written))
    points = root.GetAttributeAtPath(Sdf.Path("/Fluid/Surface.points"))
    assert points and not points.HasInfo("timeSamples") and not points.HasInfo("default")
    assert root.GetNumTimeSamplesForPath(Sdf.Path("/Fluid/Surface.points")) == 0
    assert "clips" in root.GetPrimAtPath(Sdf.Path("/Fluid")).ListInfoKeys()


def _broken_copy(written, tmp_path):
    """A text copy of the root beside the clips (clip paths stay valid)."""
    from pxr import Sdf

    layer = Sdf.Layer.OpenAsAnonymous(str(written))
    copy = written.parent / f"broken_{tmp_path.name}.usda"
    assert layer.Export(str(copy))
    return copy


def test_missing_metadata_is_caught(written, tmp_path):
    import isobar_usd
    from pxr import Sdf

    copy = _broken_copy(written, tmp_path)
    layer = Sdf.Layer.FindOrOpen(str(copy))
    layer.ClearDefaultPrim()
    layer.pseudoRoot.ClearInfo("metersPerUnit")
    layer.Save()
    stage = open_stage(copy)
    names = {name for name, _ in validation_errors(stage)}
    assert {"MissingDefaultPrim", "MissingMetersPerUnitMetadata"} <= names, names
    problems = isobar_usd.check(copy)
    assert any("MissingDefaultPrim" in p.check for p in problems)
    copy.unlink()


def test_mismatched_topology_is_caught(tmp_path, reference, dam_frames):
    """usd-core 26 has no topology validator; isobar_usd.check catches indices past the
    points, normals of the wrong count and a stale extent, frame by frame."""
    import isobar_usd
    from pxr import Sdf, Vt

    surface = reference(dam_frames / "frame_0001.vtk", attributes=["velocity"])
    out = tmp_path / "frame.usda"
    isobar_usd.write_frame(surface, out, time=1)
    assert isobar_usd.check(out) == []

    layer = Sdf.Layer.FindOrOpen(str(out))
    n = surface.n_points
    indices = surface.triangles.astype(np.int32).ravel().copy()
    indices[5] = n + 7
    layer.SetTimeSample("/Fluid/Surface.faceVertexIndices", 1.0, Vt.IntArray.FromNumpy(indices))
    layer.SetTimeSample("/Fluid/Surface.normals", 1.0, Vt.Vec3fArray.FromNumpy(surface.normals[:-3].copy()))
    layer.SetTimeSample("/Fluid/Surface.extent", 1.0, Vt.Vec3fArray([(0, 0, 0), (1, 1, 1)]))
    layer.Save()
    layer.Reload(True)
    problems = isobar_usd.check(out)
    kinds = {p.check for p in problems if p.severity == "error"}
    assert {"topology", "normals", "extent"} <= kinds, problems
    assert any(f"{n + 7}" in p.message for p in problems if p.check == "topology")
    assert all(p.time == 1.0 for p in problems if p.check in ("topology", "normals", "extent"))


def test_check_command_fails_on_a_broken_stage(cli, tmp_path, reference, dam_frames):
    import isobar_usd
    from pxr import Sdf, Vt

    surface = reference(dam_frames / "frame_0001.vtk", attributes=["velocity"])
    out = tmp_path / "frame.usda"
    isobar_usd.write_frame(surface, out, time=1)
    layer = Sdf.Layer.FindOrOpen(str(out))
    layer.SetTimeSample("/Fluid/Surface.faceVertexCounts", 1.0, Vt.IntArray([3, 3]))
    layer.Save()
    proc = run_cli(cli, "check", out, check=False)
    assert proc.returncode == 1
    assert "topology" in proc.stderr


def test_single_file_is_a_flat_stage(cli, tmp_path, reference):
    """One file (no pattern) -> one layer; the time code is its frame number."""
    src = tmp_path / "dam_26.vtk"
    src.symlink_to(FRAME_26)
    out = tmp_path / "one.usda"
    run_cli(cli, "sph", src, *CLI_DAM, "-o", out, "--attributes", "velocity")
    assert not (tmp_path / "one.clips").exists()
    stage = open_stage(out)
    assert stage.GetStartTimeCode() == 26 == stage.GetEndTimeCode()
    surface = reference(src, attributes=["velocity"])
    got = mesh_at(stage, 26)
    assert_same_mesh(got, surface)
    from pxr import UsdGeom

    pv = UsdGeom.PrimvarsAPI(got["mesh"]).GetPrimvar("velocity")
    assert pv and pv.GetInterpolation() == "vertex"
    np.testing.assert_array_equal(np.asarray(pv.Get(26)), surface.attributes["velocity"].astype(np.float32))
    assert validation_errors(stage) == []


def test_options_reach_the_stage(cli, tmp_path, dam_frames):
    from pxr import UsdGeom

    out = tmp_path / "opts.usd"
    run_cli(cli, "sph", dam_frames / "frame_####.vtk", *CLI_DAM, "-o", out, "--fps", "30", "--up-axis", "Z",
            "--meters-per-unit", "0.01", "--prim", "Water", "--mesh", "Skin", "--no-velocities", "-q")
    stage = open_stage(out)
    assert stage.GetTimeCodesPerSecond() == 30 == stage.GetFramesPerSecond()
    assert UsdGeom.GetStageUpAxis(stage) == "Z"
    assert UsdGeom.GetStageMetersPerUnit(stage) == 0.01
    assert stage.GetDefaultPrim().GetPath() == "/Water"
    mesh = UsdGeom.Mesh(stage.GetPrimAtPath("/Water/Skin"))
    assert mesh and not mesh.GetVelocitiesAttr().HasAuthoredValue()
    assert len(mesh.GetPointsAttr().Get(26)) > 0
    assert validation_errors(stage) == []


def test_preview_trim_and_kernel_options_match_the_core(cli, tmp_path, dam_frames, reference):
    out = tmp_path / "prev.usd"
    run_cli(cli, "sph", dam_frames / "frame_####.vtk", "--iso", "0.5", "--h", "0.05", "--grid-factor", "0.5",
            "--kernel", "wendland", "--h-scale", "0.9", "--preview", "--no-normals", "--frames", "26", "-o", out, "-q")
    stage = open_stage(out)
    surface = reference(dam_frames / "frame_0026.vtk", iso=0.5, grid_factor=0.5, kernel="wendland",
                        h_scale=0.9, correct=False, normals=False, attributes=["velocity"])
    got = mesh_at(stage, 26)
    np.testing.assert_array_equal(got["points"], surface.points.astype(np.float32))
    np.testing.assert_array_equal(got["indices"], surface.triangles.astype(np.int32).ravel())
    assert got["normals"] is None


def test_bgeo_frames_with_and_without_velocity(cli, tmp_path, reference):
    """splashsurf's Houdini frames: frame 9 carries 'velocity', frame 23 no array at all.
    Frame 23 gets no velocities (not frame 9's, which would not match its points)."""
    from conftest import DATA, need

    frames = tmp_path / "bgeo"
    frames.mkdir()
    for n, name in ((9, "dam_break_frame_9_6859_particles.bgeo"), (23, "dam_break_frame_23_24389_particles.bgeo")):
        (frames / f"frame_{n:04d}.bgeo").symlink_to(need(DATA / "splashsurf" / name))
    out = tmp_path / "bgeo.usd"
    run_cli(cli, "sph", frames / "frame_####.bgeo", "--iso", "0.6", "--h", "0.06", "-o", out, "-q")
    stage = open_stage(out)
    f9 = reference(frames / "frame_0009.bgeo", h=0.06, grid_factor=0.5, attributes=["velocity"])
    f23 = reference(frames / "frame_0023.bgeo", h=0.06, grid_factor=0.5)
    assert_same_mesh(mesh_at(stage, 9), f9)
    got = mesh_at(stage, 23)
    assert_same_mesh(got, f23, velocity=False)
    assert got["velocities"] is None
    import isobar_usd

    assert isobar_usd.check(out) == [] and validation_errors(stage) == []
