"""Surfaces from particles already in the scene: mesh points, point clouds (geometry
nodes) and particle systems, read through the evaluated depsgraph."""

import bpy
import numpy as np
from conftest import FRAME_01, FRAME_26, GRID_FACTOR, ISO, H, assert_mesh_equals, attribute


def particle_mesh_object(isobar, path, name="particles", location=(0.0, 0.0, 0.0)):
    """A mesh object whose vertices are the particles of `path`, with a velocity attribute."""
    particles = isobar.Particles.read(str(path))
    pos = particles.positions.astype(np.float32)
    vel = particles.array("velocity").astype(np.float32)
    mesh = bpy.data.meshes.new(name)
    mesh.vertices.add(len(pos))
    mesh.vertices.foreach_set("co", pos.ravel())
    mesh.attributes.new("velocity", "FLOAT_VECTOR", "POINT").data.foreach_set("vector", vel.ravel())
    mesh.update()
    obj = bpy.data.objects.new(name, mesh)
    obj.location = location
    bpy.context.scene.collection.objects.link(obj)
    bpy.context.view_layer.objects.active = obj
    return obj, pos.astype(np.float64) + np.asarray(location), vel


def surface_from(source, **kwargs):
    params = dict(h=H, iso=ISO, grid_factor=GRID_FACTOR)
    params.update(kwargs)
    assert bpy.ops.isobar.surface_from_object(source=source.name, **params) == {"FINISHED"}
    obj = bpy.context.active_object
    assert obj.isobar.enabled and obj.isobar.source_type == "OBJECT" and obj is not source
    assert not obj.isobar.status_error, obj.isobar.status
    return obj


def test_surface_from_mesh_points_with_attributes(scene, isobar):
    source, pos, vel = particle_mesh_object(isobar, FRAME_26, location=(1.0, 2.0, -0.5))
    obj = surface_from(source)
    expected = isobar.extract(
        isobar.Particles.from_arrays(pos, velocity=vel), ISO, h=H, grid_factor=GRID_FACTOR, attributes=["velocity"]
    )
    assert_mesh_equals(obj, expected)
    np.testing.assert_allclose(attribute(obj, "velocity"), expected.attributes["velocity"], rtol=1e-5, atol=1e-6)
    assert "sph_speed" in obj.data.attributes
    # Moving the particles (a new frame, or an edit and Refresh) moves the surface.
    source.location = (0.0, 0.0, 0.0)
    scene.frame_set(scene.frame_current + 1)
    shifted = isobar.extract(isobar.Particles.from_arrays(pos - (1.0, 2.0, -0.5)), ISO, h=H, grid_factor=GRID_FACTOR)
    np.testing.assert_allclose(np.asarray(obj.data.vertices[0].co), shifted.points[0], atol=1e-5)
    assert len(obj.data.vertices) == shifted.n_points


def test_surface_from_point_cloud(scene, isobar):
    source, pos, vel = particle_mesh_object(isobar, FRAME_01)
    group = bpy.data.node_groups.new("to points", "GeometryNodeTree")
    group.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
    group.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    node_in, node_out = group.nodes.new("NodeGroupInput"), group.nodes.new("NodeGroupOutput")
    to_points = group.nodes.new("GeometryNodeMeshToPoints")
    group.links.new(node_in.outputs[0], to_points.inputs["Mesh"])
    group.links.new(to_points.outputs["Points"], node_out.inputs[0])
    source.modifiers.new("points", "NODES").node_group = group
    evaluated = source.evaluated_get(bpy.context.evaluated_depsgraph_get())
    assert evaluated.evaluated_geometry().pointcloud is not None
    obj = surface_from(source)
    expected = isobar.extract(isobar.Particles.from_arrays(pos), ISO, h=H, grid_factor=GRID_FACTOR)
    assert_mesh_equals(obj, expected)
    assert {"velocity", "sph_radius", "sph_speed"} <= set(obj.data.attributes.keys())


def _alive_particles(emitter):
    evaluated = emitter.evaluated_get(bpy.context.evaluated_depsgraph_get())
    particles = evaluated.particle_systems[0].particles
    n = len(particles)
    loc, state = np.empty(3 * n, np.float32), np.empty(n, np.int32)
    particles.foreach_get("location", loc)
    particles.foreach_get("alive_state", state)
    alive = np.isin(state, [3, 4])  # ALIVE, DYING
    return loc.reshape(n, 3)[alive].astype(np.float64)


def test_surface_from_particle_system(scene, isobar):
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    emitter = bpy.context.active_object
    emitter.modifiers.new("fluid", "PARTICLE_SYSTEM")
    ps = emitter.particle_systems[0].settings
    ps.emit_from, ps.distribution, ps.grid_resolution = "VOLUME", "GRID", 12
    ps.frame_start = ps.frame_end = 1
    ps.lifetime = 1000
    scene.frame_set(1)
    obj = surface_from(emitter, h=0.08, grid_factor=0.5)
    assert obj.isobar.particle_system == emitter.particle_systems[0].name
    positions = _alive_particles(emitter)
    assert len(positions) > 1000
    expected = isobar.extract(isobar.Particles.from_arrays(positions), ISO, h=0.08, grid_factor=0.5)
    assert expected.n_points > 0
    assert_mesh_equals(obj, expected)
    for frame in range(2, 11):  # the particles fall; the handler follows them
        scene.frame_set(frame)
    positions = _alive_particles(emitter)
    assert positions[:, 2].max() < 0.4  # they did move
    expected = isobar.extract(isobar.Particles.from_arrays(positions), ISO, h=0.08, grid_factor=0.5)
    assert_mesh_equals(obj, expected)
    assert "velocity" in obj.data.attributes


def test_scene_source_errors_are_reported(scene, isobar):
    source, _, _ = particle_mesh_object(isobar, FRAME_01)
    obj = surface_from(source)
    shown = len(obj.data.vertices)
    obj.isobar.h = 1e-7  # absurdly small: over the memory budget, reported
    assert obj.isobar.status_error
    assert len(obj.data.vertices) == shown
    obj.isobar.h = H
    assert not obj.isobar.status_error
    obj.isobar.source_object = None
    assert obj.isobar.status_error and "choose the object" in obj.isobar.status
    assert len(obj.data.vertices) == shown


def test_bake_a_particle_system(scene, isobar, tmp_path):
    """Baking a scene source steps the scene through the frames (the depsgraph evaluates the
    particles), then returns to the frame it started on; playback reads the cache."""
    bpy.ops.mesh.primitive_cube_add(size=1.0)
    emitter = bpy.context.active_object
    emitter.modifiers.new("fluid", "PARTICLE_SYSTEM")
    ps = emitter.particle_systems[0].settings
    ps.emit_from, ps.distribution, ps.grid_resolution = "VOLUME", "GRID", 10
    ps.frame_start = ps.frame_end = 1
    ps.lifetime = 1000
    scene.frame_start, scene.frame_end = 1, 4
    scene.frame_set(1)
    obj = surface_from(emitter, h=0.1, grid_factor=0.5)
    obj.isobar.cache_directory = str(tmp_path / "cache")
    expected = {}
    for frame in range(1, 5):
        scene.frame_set(frame)
        expected[frame] = isobar.extract(
            isobar.Particles.from_arrays(_alive_particles(emitter)), ISO, h=0.1, grid_factor=0.5
        )
    scene.frame_set(2)
    assert bpy.ops.isobar.bake() == {"FINISHED"}
    assert scene.frame_current == 2
    assert sorted(p.name for p in (tmp_path / "cache" / obj.isobar.cache_name).iterdir()) == [
        f"frame_{f:06d}.npz" for f in range(1, 5)
    ]
    emitter.modifiers.remove(emitter.modifiers["fluid"])  # the particles are gone
    for frame in (4, 1, 3):
        scene.frame_set(frame)
        assert "bake" in obj.isobar.status, obj.isobar.status
        assert_mesh_equals(obj, expected[frame])
    assert expected[1].n_points != expected[4].n_points or not np.array_equal(expected[1].points, expected[4].points)
