"""Surfaces a user meets in production files: a fluid surface linked from the FX shot's
.blend (its mesh is read-only: writing it crashed Blender on the first frame change), a
frame before the emitter's first particle (0 particles: an empty surface, not an error
that stopped bakes and USD exports), and Attributes 'none'."""

import bpy
from conftest import assert_mesh_equals, FRAME_26, import_sequence, make_sequence, reference

EMPTY_VTK = "# vtk DataFile Version 3.0\nno particles yet\nASCII\nDATASET POLYDATA\nPOINTS 0 float\n"


def test_a_linked_fluid_surface_keeps_its_library_mesh_and_is_not_written(scene, addon, demo_sequence, tmp_path):
    importer = addon.importer
    obj = import_sequence(demo_sequence[0])
    name, shown = obj.name, len(obj.data.vertices)
    assert shown > 1000
    library = tmp_path / "fx.blend"
    bpy.data.libraries.write(str(library), {obj})
    mesh = obj.data
    bpy.data.objects.remove(obj)
    bpy.data.meshes.remove(mesh)

    with bpy.data.libraries.load(str(library), link=True) as (_src, dst):
        dst.objects = [name]
    linked = dst.objects[0]
    scene.collection.objects.link(linked)
    assert importer.is_fluid(linked) and importer.linked_from(linked).endswith("fx.blend")
    scene.frame_set(2)  # crashed Blender: the handler wrote into the linked mesh
    scene.frame_set(3)
    assert len(linked.data.vertices) == shown  # the mesh the library saved
    ok, message = importer.update_object(linked, scene, force=True)
    assert not ok and f"'{name}' is linked from " in message and "Make Local" in message, message


def test_a_frame_without_particles_is_an_empty_surface_and_bakes(scene, isobar, tmp_path):
    folder = tmp_path / "sim"
    paths = make_sequence(folder, [FRAME_26, FRAME_26], start=2)
    (folder / "frame_0001.vtk").write_text(EMPTY_VTK)
    obj = import_sequence(paths[0])
    settings = obj.isobar
    scene.frame_set(1)
    assert not settings.status_error, settings.status
    assert "0 particles" in settings.status, settings.status
    assert len(obj.data.vertices) == 0 and len(obj.data.polygons) == 0
    scene.frame_set(2)
    assert_mesh_equals(obj, reference(isobar, FRAME_26))

    settings.cache_directory = str(tmp_path / "cache")
    scene.frame_start, scene.frame_end = 1, 3
    assert bpy.ops.isobar.bake() == {"FINISHED"}  # stopped at frame 1 before
    baked = sorted(p.name for p in (tmp_path / "cache" / settings.cache_name).iterdir())
    assert baked == ["frame_000001.npz", "frame_000002.npz", "frame_000003.npz"], baked
    scene.frame_set(1)
    assert not settings.status_error and len(obj.data.vertices) == 0, settings.status


def test_attributes_none_writes_no_sph_arrays(scene, demo_sequence):
    obj = import_sequence(demo_sequence[1])
    assert "sph_SumOfWeights" in obj.data.attributes
    settings = obj.isobar
    settings.speed = False
    settings.motion_blur = False
    settings.attributes = "none"
    assert not settings.status_error, settings.status
    names = set(obj.data.attributes.keys())
    assert not {n for n in names if n.startswith("sph_")} and "velocity" not in names, names
    assert len(obj.data.vertices) > 1000


def test_a_linked_duplicate_gets_a_mesh_of_its_own(scene, isobar, demo_sequence):
    """Alt+D shares the mesh: the duplicate's surface (other settings) was written into the
    original's mesh too, under the original's status."""
    obj = import_sequence(demo_sequence[0])  # shows frame 1
    dup = obj.copy()  # what Alt+D makes: a new object, the same mesh, the same settings
    scene.collection.objects.link(dup)
    assert dup.data == obj.data
    dup.isobar.iso = 0.3
    assert not dup.isobar.status_error, dup.isobar.status
    assert dup.data != obj.data
    assert_mesh_equals(dup, reference(isobar, demo_sequence[0], iso=0.3))
    assert_mesh_equals(obj, reference(isobar, demo_sequence[0]))
    assert f"{len(obj.data.vertices)} vertices" in obj.isobar.status


def test_a_plain_object_sharing_the_surface_mesh_on_purpose_keeps_sharing_it(scene, demo_sequence):
    """Ctrl+L (the fluid shown twice): only another surface the add-on writes makes the
    mesh split; a plain object kept showing the first frame after the split."""
    obj = import_sequence(demo_sequence[0])
    viewer = bpy.data.objects.new("viewer", obj.data)
    scene.collection.objects.link(viewer)
    scene.frame_set(2)
    assert viewer.data == obj.data and len(viewer.data.vertices) == len(obj.data.vertices) > 1000
