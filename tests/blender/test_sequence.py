"""Importing particle sequences, stepping frames, parameters, attributes and errors."""

import shutil
import struct
import warnings

import bpy
import numpy as np
import pytest
from conftest import (
    FRAME_01,
    FRAME_26,
    GRID_FACTOR,
    ISO,
    H,
    assert_mesh_equals,
    import_sequence,
    attribute,
    make_sequence,
    mesh_arrays,
    reference,
)


def test_import_and_step_frames(scene, isobar, demo_sequence):
    obj = import_sequence(demo_sequence[0])
    settings = obj.isobar
    assert settings.pattern == "frame_####.vtk"
    assert (settings.file_first, settings.file_last) == (1, 3)
    assert (scene.frame_start, scene.frame_end) == (1, 3)
    references = [reference(isobar, p) for p in demo_sequence]
    for frame in (1, 2, 3, 2, 1):
        scene.frame_set(frame)
        assert not settings.status_error, settings.status
        assert_mesh_equals(obj, references[frame - 1])
        assert f"Frame {frame}:" in settings.status
    assert references[0].n_points != references[1].n_points  # the frames do differ


def test_smooth_shading_custom_normals_and_attributes(scene, isobar, demo_sequence):
    obj = import_sequence(demo_sequence[1])
    scene.frame_set(2)
    ref = reference(isobar, demo_sequence[1], attributes=["velocity"])
    mesh = obj.data
    assert_mesh_equals(obj, ref)
    smooth = np.empty(len(mesh.polygons), bool)
    mesh.polygons.foreach_get("use_smooth", smooth)
    assert smooth.all()
    assert mesh.has_custom_normals
    corner = np.empty(len(mesh.loops) * 3, np.float32)
    mesh.corner_normals.foreach_get("vector", corner)
    corner = corner.reshape(-1, 3)
    sph = ref.normals[ref.triangles.ravel()]
    assert np.einsum("ij,ij->i", corner, sph).min() > 0.9999
    # SPH attributes for the shader's Attribute node, prefixed; velocity for motion blur.
    names = set(mesh.attributes.keys())
    assert {"sph_SumOfWeights", "sph_speed", "velocity"} <= names, names
    assert not {"speed", "SumOfWeights", "id", "sph_id"} & names
    sow = attribute(obj, "sph_SumOfWeights")
    np.testing.assert_array_equal(sow, ref.attributes["SumOfWeights"].astype(np.float32))
    np.testing.assert_array_equal(attribute(obj, "velocity"), ref.attributes["velocity"].astype(np.float32))
    assert mesh.attributes["velocity"].data_type == "FLOAT_VECTOR" and mesh.attributes["velocity"].domain == "POINT"
    # sph_speed interpolates the particles' |v| (between 0 and the largest particle speed).
    speed = attribute(obj, "sph_speed")
    vmax = np.linalg.norm(isobar.Particles.read(str(demo_sequence[1])).array("velocity"), axis=1).max()
    assert speed.min() >= 0 and 0 < speed.max() <= vmax * 1.0001
    assert obj.active_material is not None


def test_a_velocity_array_that_does_not_exist_is_an_error_not_replaced(scene, isobar, demo_sequence):
    """A Velocity name the user typed that the particles lack was silently replaced by
    'velocity'; it is an error naming it, as a wrong Attributes name is. The default
    name on a file without a velocity stays quiet (the import sets it regardless)."""
    obj = import_sequence(demo_sequence[1])
    scene.frame_set(2)
    settings = obj.isobar
    assert not settings.status_error, settings.status
    vertices = len(obj.data.vertices)
    settings.velocity_array = "nope"
    assert settings.status_error, settings.status
    assert "no velocity array named 'nope'" in settings.status and "velocity" in settings.status
    settings.velocity_array = "id"
    assert settings.status_error and "'id' has 1 components" in settings.status, settings.status
    settings.velocity_array = "velocity"
    assert not settings.status_error, settings.status
    assert len(obj.data.vertices) == vertices and "velocity" in obj.data.attributes


def test_parameter_change_reextracts(scene, isobar, demo_sequence):
    obj = import_sequence(demo_sequence[0])
    scene.frame_set(2)
    settings = obj.isobar
    path = demo_sequence[1]
    settings.iso = 0.5
    assert_mesh_equals(obj, reference(isobar, path, iso=0.5))
    settings.h_scale = 1.2
    assert_mesh_equals(obj, reference(isobar, path, iso=0.5, h_scale=1.2))
    settings.grid_factor = 0.5
    assert_mesh_equals(obj, reference(isobar, path, iso=0.5, h_scale=1.2, grid_factor=0.5))
    settings.kernel = "wendland"
    assert_mesh_equals(obj, reference(isobar, path, iso=0.5, h_scale=1.2, grid_factor=0.5, kernel="wendland"))
    settings.correct = False
    assert_mesh_equals(
        obj, reference(isobar, path, iso=0.5, h_scale=1.2, grid_factor=0.5, kernel="wendland", correct=False)
    )
    settings.trim = "CUSTOM"
    settings.trim_node, settings.trim_vertex = 0.1, 0.5
    expected = reference(
        isobar, path, iso=0.5, h_scale=1.2, grid_factor=0.5, kernel="wendland", correct=False, trim=(0.1, 0.5)
    )
    assert_mesh_equals(obj, expected)
    # Another field: the magnitude of the velocity, trimmed at the free surface.
    settings.correct, settings.trim, settings.kernel, settings.h_scale, settings.grid_factor = (
        True,
        "AUTO",
        "cubic",
        1.0,
        0.5,
    )
    settings.field = "velocity:mag"
    settings.iso = 1.5
    assert not settings.status_error, settings.status
    expected = reference(isobar, path, iso=1.5, grid_factor=0.5, field="velocity:mag")
    assert expected.n_points > 1000
    assert_mesh_equals(obj, expected)
    settings.iso = 0.5
    # Live update off: no re-extraction until refreshed.
    settings.live_update = False
    before = mesh_arrays(obj)[0].shape
    settings.field = "SumOfWeights"
    assert mesh_arrays(obj)[0].shape == before
    assert bpy.ops.isobar.refresh() == {"FINISHED"}
    assert_mesh_equals(obj, reference(isobar, path, iso=0.5, grid_factor=0.5))


def test_frame_offset_and_hold(scene, isobar, demo_sequence):
    obj = import_sequence(demo_sequence[0], frame_offset=10)
    assert (scene.frame_start, scene.frame_end) == (11, 13)
    first, second = reference(isobar, demo_sequence[0]), reference(isobar, demo_sequence[1])
    scene.frame_set(12)
    assert_mesh_equals(obj, second)
    scene.frame_set(5)  # before the sequence: the first file
    assert_mesh_equals(obj, first)
    scene.frame_set(40)  # after it: the last file (frame 3 = dam break frame 1)
    assert_mesh_equals(obj, first)
    obj.isobar.hold = False
    assert len(obj.data.vertices) == 0 and not obj.isobar.status_error
    scene.frame_set(12)
    assert_mesh_equals(obj, second)


def _write_ply(path, positions, velocity):
    header = (
        "ply\nformat binary_little_endian 1.0\n"
        f"element vertex {len(positions)}\n"
        "property double x\nproperty double y\nproperty double z\n"
        "property float vx\nproperty float vy\nproperty float vz\nend_header\n"
    ).encode()
    rows = np.zeros(len(positions), dtype=[("p", "<f8", 3), ("v", "<f4", 3)])
    rows["p"], rows["v"] = positions, velocity
    path.write_bytes(header + rows.tobytes())


@pytest.mark.parametrize("fmt", ["npz", "ply", "bgeo"])
def test_other_formats(scene, isobar, tmp_path, fmt):
    folder = tmp_path / fmt
    folder.mkdir()
    if fmt == "bgeo":
        data = FRAME_01.parent
        paths = make_sequence(
            folder,
            [data / "dam_break_frame_9_6859_particles.bgeo", data / "dam_break_frame_23_24389_particles.bgeo"],
            "frame_{:04d}.bgeo",
        )
    else:
        paths = []
        for i, src in enumerate([FRAME_01, FRAME_26], start=1):
            particles = isobar.Particles.read(str(src))
            path = folder / f"frame_{i:04d}.{fmt}"
            if fmt == "npz":
                np.savez(path, positions=particles.positions, velocity=particles.array("velocity"))
            else:
                _write_ply(path, particles.positions, particles.array("velocity"))
            paths.append(path)
    obj = import_sequence(paths[0])
    assert obj.isobar.pattern == f"frame_####.{fmt}"
    for frame, path in enumerate(paths, start=1):
        scene.frame_set(frame)
        assert not obj.isobar.status_error, obj.isobar.status
        assert_mesh_equals(obj, reference(isobar, path))
        names = isobar.Particles.read(str(path)).names
        has_velocity = "velocity" in names or "vx" in names  # PLY: vx, vy, vz joined
        assert ("velocity" in obj.data.attributes) == has_velocity
        assert ("sph_speed" in obj.data.attributes) == has_velocity
    if fmt == "npz":  # same particles as the VTK files: same surfaces
        assert_mesh_equals(obj, reference(isobar, FRAME_26))


def test_missing_file_reports_and_keeps_last_good_mesh(scene, isobar, demo_sequence):
    obj = import_sequence(demo_sequence[0])
    first = reference(isobar, demo_sequence[0])
    demo_sequence[1].unlink()  # frame_0002.vtk disappears
    scene.frame_set(2)  # no exception from the handler
    assert obj.isobar.status_error
    assert "frame_0002.vtk" in obj.isobar.status
    assert_mesh_equals(obj, first)  # the mesh of the last good frame
    # An operator reports it (a script sees the report as RuntimeError).
    with pytest.raises(RuntimeError, match="frame_0002.vtk"):
        bpy.ops.isobar.refresh()
    assert_mesh_equals(obj, first)
    scene.frame_set(3)  # the next good frame shows again
    assert not obj.isobar.status_error
    assert_mesh_equals(obj, reference(isobar, demo_sequence[2]))


def test_bad_parameters_report_and_keep_mesh(scene, isobar, demo_sequence):
    obj = import_sequence(demo_sequence[0])
    first = reference(isobar, demo_sequence[0])
    obj.isobar.field = "no_such_array"
    assert obj.isobar.status_error and "no_such_array" in obj.isobar.status
    assert_mesh_equals(obj, first)
    obj.isobar.field = "SumOfWeights"
    obj.isobar.h_mode = "ARRAY"
    obj.isobar.h_array = "hsml"
    assert obj.isobar.status_error and "hsml" in obj.isobar.status
    assert_mesh_equals(obj, first)
    obj.isobar.h_mode = "CONSTANT"
    assert not obj.isobar.status_error
    assert_mesh_equals(obj, first)


def test_import_errors_are_reported(scene, tmp_path):
    with pytest.raises(RuntimeError, match="not found"):
        bpy.ops.isobar.import_sequence(filepath=str(tmp_path / "frame_0001.vtk"))
    bad = tmp_path / "frame_0001.vtk"
    bad.write_bytes(struct.pack("<4d", 1, 2, 3, 4))
    with pytest.raises(RuntimeError):
        bpy.ops.isobar.import_sequence(filepath=str(bad))
    assert len(bpy.data.objects) == 0  # nothing half-made is left behind
    with pytest.raises(RuntimeError):  # no number: a static file, which the core refuses
        bpy.ops.isobar.import_sequence(filepath=str(FRAME_01.parent / "LICENSE"))
    assert len(bpy.data.objects) == 0


def test_unpadded_numbers_import_the_whole_sequence_from_any_member(scene, isobar, tmp_path):
    paths = make_sequence(tmp_path / "sim", [FRAME_01, FRAME_26] * 6, "ParticleData_Fluid_{}.vtk")
    for picked in (paths[11], paths[2]):  # ParticleData_Fluid_12.vtk, ParticleData_Fluid_3.vtk
        obj = import_sequence(picked)
        settings = obj.isobar
        assert settings.pattern == "ParticleData_Fluid_#.vtk"
        assert (settings.file_first, settings.file_last) == (1, 12)
        assert (scene.frame_start, scene.frame_end) == (1, 12)
    scene.frame_set(2)
    assert "ParticleData_Fluid_2.vtk" in settings.status, settings.status
    assert_mesh_equals(obj, reference(isobar, paths[1]))


def test_the_frame_number_need_not_be_the_last_number(scene, tmp_path):
    make_sequence(tmp_path / "sim", [FRAME_01, FRAME_26, FRAME_01], "run_{}_4732_particles.vtk")
    obj = import_sequence(tmp_path / "sim" / "run_2_4732_particles.vtk")
    assert obj.isobar.pattern == "run_#_4732_particles.vtk"
    assert (obj.isobar.file_first, obj.isobar.file_last) == (1, 3)


@pytest.mark.parametrize("name", ["bunny_frame_14_7705_particles.vtk", "demo_dam_break.vtk"])
def test_a_file_alone_imports_static_without_moving_the_timeline(scene, isobar, tmp_path, name):
    path = tmp_path / name
    shutil.copyfile(FRAME_26, path)
    scene.frame_start, scene.frame_end = 1, 48
    scene.frame_set(5)
    obj = import_sequence(path)
    assert (scene.frame_start, scene.frame_end, scene.frame_current) == (1, 48, 5)
    expected = reference(isobar, path)
    for frame in (5, 40, 1):
        scene.frame_set(frame)
        assert not obj.isobar.status_error and name in obj.isobar.status, obj.isobar.status
        assert_mesh_equals(obj, expected)


def test_adaptive_method(scene, isobar, demo_sequence):
    """Method 'Adaptive' puts the core's adaptive 3-level surface in the object: closed,
    with fewer triangles than Marching Correctors, and back to Correctors on request."""
    obj = import_sequence(demo_sequence[0])
    scene.frame_set(2)
    settings = obj.isobar
    path = demo_sequence[1]
    correctors = reference(isobar, path)
    settings.method = "ADAPTIVE"
    assert not settings.status_error, settings.status
    with isobar.Particles.read(str(path)) as particles:
        adaptive, stats = isobar.extract_adaptive(particles, ISO, h=H, grid_factor=GRID_FACTOR)
    assert_mesh_equals(obj, adaptive)
    assert stats["triangles"] == adaptive.n_triangles < correctors.n_triangles
    # Closed and consistently wound: each directed edge once, its reverse once.
    _, triangles = mesh_arrays(obj)
    directed = np.concatenate([triangles[:, [0, 1]], triangles[:, [1, 2]], triangles[:, [2, 0]]]).astype(np.int64)
    forward = np.sort(directed[:, 0] << 32 | directed[:, 1])
    assert len(np.unique(forward)) == len(forward)
    assert np.array_equal(forward, np.sort(directed[:, 1] << 32 | directed[:, 0]))
    # The particle velocities reach the adaptive vertices (motion blur), as the core carries them.
    with isobar.Particles.read(str(path)) as particles:
        carried, _ = isobar.extract_adaptive(particles, ISO, h=H, grid_factor=GRID_FACTOR, attributes=["velocity"])
    np.testing.assert_array_equal(attribute(obj, "velocity"), carried.attributes["velocity"].astype(np.float32))
    assert np.abs(carried.attributes["velocity"]).max() > 0.1
    # Splash Threshold reaches the core: the panel's default is the core's (0, no splash
    # cells), and the paper's rule (1) refines the cells holding one particle: more
    # triangles, the core's mesh at that threshold.
    assert settings.splash_threshold == isobar.adaptive.default_params().splash_threshold == 0
    settings.splash_threshold = 1
    with isobar.Particles.read(str(path)) as particles:
        paper, _ = isobar.extract_adaptive(particles, ISO, h=H, grid_factor=GRID_FACTOR, splash_threshold=1)
    assert_mesh_equals(obj, paper)
    assert paper.n_triangles > adaptive.n_triangles
    settings.splash_threshold = 0
    with isobar.Particles.read(str(path)) as particles:
        coarse, coarse_stats = isobar.extract_adaptive(particles, ISO, h=H, grid_factor=GRID_FACTOR, splash_threshold=0)
    assert_mesh_equals(obj, coarse)
    # Max Error reaches the core: the panel's default is the core's, and 0 (off) leaves only
    # the cells the hidden-surface rule raises (it is not switched off by max_error), so
    # fewer refined cells and triangles: a different mesh.
    assert settings.max_error == pytest.approx(isobar.adaptive.default_params().max_error)
    settings.max_error = 0.0
    with isobar.Particles.read(str(path)) as particles:
        flat, flat_stats = isobar.extract_adaptive(
            particles, ISO, h=H, grid_factor=GRID_FACTOR, splash_threshold=0, max_error=0.0
        )
    assert_mesh_equals(obj, flat)
    refined = lambda stats: sum(stats["cells_per_level"][1:])
    assert refined(flat_stats) < refined(coarse_stats) and flat.n_triangles < coarse.n_triangles
    # Bisection Iterations reaches the core: the panel's default is the core's, and 0 gives
    # the core's surface with linear level-3 points, a mesh whose points moved.
    assert settings.bisection_iterations == isobar.adaptive.default_params().bisection_iterations
    settings.bisection_iterations = 0
    with isobar.Particles.read(str(path)) as particles:
        linear, _ = isobar.extract_adaptive(
            particles, ISO, h=H, grid_factor=GRID_FACTOR, splash_threshold=0, max_error=0.0, bisection_iterations=0
        )
    assert_mesh_equals(obj, linear)
    assert not np.array_equal(np.sort(mesh_arrays(obj)[0], axis=0), np.sort(flat.points.astype(np.float32), axis=0))
    settings.bisection_iterations = 5
    assert_mesh_equals(obj, flat)
    # Backend GPU: the core's wgpu path (lavapipe in CI, installed by the test command).
    settings.backend = "GPU"
    assert not settings.status_error, settings.status
    with isobar.Particles.read(str(path)) as particles:
        gpu, gpu_stats = isobar.extract_adaptive(
            particles, ISO, h=H, grid_factor=GRID_FACTOR, splash_threshold=0, max_error=0.0, backend="gpu"
        )
    assert gpu_stats["backend"] == "gpu"
    assert_mesh_equals(obj, gpu)
    settings.backend = "CPU"
    settings.method = "CORRECTORS"
    assert_mesh_equals(obj, correctors)
    # Marching Correctors with Backend GPU: the seed search on the device, the same mesh.
    settings.backend = "GPU"
    assert not settings.status_error, settings.status
    assert_mesh_equals(obj, correctors)
    settings.backend = "CPU"


class _Reports:
    """Stands in for a running operator: collects its reports."""

    def __init__(self, object_name):
        self.object_name = object_name
        self.reports = []

    def report(self, kind, message):
        self.reports.append((set(kind), message))


def test_backend_auto_on_the_cpu_is_reported_with_the_core_reason(scene, addon, isobar, demo_sequence):
    # Without a hardware GPU (lavapipe in CI is a software rasteriser) Auto runs on the CPU:
    # the surface keeps the reason (shown in the panel) and the operators warn with the
    # CLI's line; Backend CPU has no note.
    note = isobar.auto_backend_note() or ""
    obj = import_sequence(demo_sequence[0])
    settings = obj.isobar
    assert settings.backend == "CPU" and settings.backend_note == ""
    settings.backend = "AUTO"  # a live update re-extracts
    assert not settings.status_error, settings.status
    assert settings.backend_note == note
    op = _Reports(obj.name)
    assert addon.operators.ISOBAR_OT_refresh.execute(op, bpy.context) == {"FINISHED"}
    warnings = [m for kind, m in op.reports if "WARNING" in kind]
    assert warnings == ([f"backend auto: running on the CPU ({note})"] if note else []), op.reports
    settings.backend = "CPU"
    assert settings.backend_note == ""
    op = _Reports(obj.name)
    addon.operators.ISOBAR_OT_refresh.execute(op, bpy.context)
    assert not [m for kind, m in op.reports if "WARNING" in kind], op.reports


def test_an_isovalue_above_the_field_is_a_warning(scene, addon, isobar, demo_sequence):
    # The sum of weights never reaches 1e6: no surface, which the core warns about. Not an
    # error: the mesh is empty, the panel's status keeps the warning, the frame-change
    # handler prints it, the operators report it as a WARNING, and nothing raises (Python's
    # own copy of the warning is kept quiet, so the console does not show it twice).
    with warnings.catch_warnings(record=True) as python_warnings:
        warnings.simplefilter("always")
        obj = import_sequence(demo_sequence[0], iso=1e6)  # bpy.ops raises only for errors
        settings = obj.isobar
        assert not settings.status_error and settings.status.startswith("Frame 1: 0 vertices"), settings.status
        assert "no surface at isovalue" in settings.status_warnings, settings.status_warnings
        scene.frame_set(2)  # the handler
        assert not settings.status_error and settings.status.startswith("Frame 2: 0 vertices"), settings.status
        assert settings.status_warnings.startswith("no surface at isovalue"), settings.status_warnings
        op = _Reports(obj.name)
        assert addon.operators.ISOBAR_OT_refresh.execute(op, bpy.context) == {"FINISHED"}
    assert not [w for w in python_warnings if issubclass(w.category, isobar.IsobarWarning)]
    reported = [m for kind, m in op.reports if "WARNING" in kind]
    assert len(reported) == 1 and reported[0].startswith("no surface at isovalue"), op.reports
    assert len(obj.data.polygons) == 0
    settings.iso = ISO  # a surface again: no warning left in the panel
    assert not settings.status_error and settings.status_warnings == "", settings.status_warnings
    assert len(obj.data.polygons) > 0
