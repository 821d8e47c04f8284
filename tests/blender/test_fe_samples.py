"""High-order FE isosurfaces in Blender: File > Import makes a point-cloud object whose
points are the core's samples (radius, normal, element, curvature attributes), each on the
level set by an independent evaluation, and changing the isovalue samples again without
reading the file again."""

from pathlib import Path

import bpy
import numpy as np
import pytest

FE_DATA = Path(__file__).resolve().parents[2] / "rust-core" / "data" / "fe"
FIXTURE = FE_DATA / "mixed_lagrange.vtu"
NODES = FE_DATA / "vtk_lagrange_nodes.txt"


def _attribute(cloud, name, width):
    a = cloud.attributes[name]
    key = "vector" if width == 3 else "value"
    out = np.zeros(len(cloud.points) * width, dtype=np.int32 if a.data_type == "INT" else np.float32)
    a.data.foreach_get(key, out)
    return out.reshape(-1, width) if width == 3 else out


def _cube_vtu(path):
    """One order-2 Lagrange hexahedron over [-1, 1]³ with f = |x|² (reproduced exactly at
    order 2), in VTK's node order as VTK itself lists it (rust-core/data/fe)."""
    for line in NODES.read_text().splitlines():
        kind, order, count, *coords = line.split()
        if (kind, order) == ("hex", "2"):
            pts = np.array(coords, dtype=float).reshape(int(count), 3) * 2.0 - 1.0
            break
    f = (pts**2).sum(axis=1)
    fmt = lambda a: " ".join(repr(float(v)) for v in np.ravel(a))  # noqa: E731
    path.write_text(
        f"""<?xml version="1.0"?>
<VTKFile type="UnstructuredGrid" version="2.2" byte_order="LittleEndian">
 <UnstructuredGrid><Piece NumberOfPoints="27" NumberOfCells="1">
  <PointData><DataArray type="Float64" Name="f" format="ascii">{fmt(f)}</DataArray></PointData>
  <Points><DataArray type="Float64" NumberOfComponents="3" format="ascii">{fmt(pts)}</DataArray></Points>
  <Cells>
   <DataArray type="Int64" Name="connectivity" format="ascii">{" ".join(map(str, range(27)))}</DataArray>
   <DataArray type="Int64" Name="offsets" format="ascii">27</DataArray>
   <DataArray type="UInt8" Name="types" format="ascii">72</DataArray>
  </Cells>
 </Piece></UnstructuredGrid>
</VTKFile>
"""
    )
    return path


def test_import_makes_a_point_cloud_on_the_sphere_and_resamples_on_isovalue_change(scene, isobar, tmp_path):
    path = _cube_vtu(tmp_path / "cube.vtu")
    result = bpy.ops.isobar.import_fe(filepath=str(path), field="f", isovalue=0.49, spacing=0.08)
    assert result == {"FINISHED"}
    obj = bpy.context.active_object
    settings = obj.isobar_fe
    assert obj.type == "POINTCLOUD" and settings.enabled and not settings.status_error, settings.status
    assert (settings.value_min, settings.value_max) == pytest.approx((0.0, 3.0))
    for iso in (0.49, 0.25, 0.64):
        settings.isovalue = iso
        assert not settings.status_error, settings.status
        cloud = obj.data
        n = len(cloud.points)
        assert n == settings.samples > 50, settings.status
        points = _attribute(cloud, "position", 3).astype(np.float64)
        # Independent evaluation: f = |x|², so every point is on the sphere of radius
        # r = sqrt(iso): |f - iso| <= 1e-6 is |x| - r <= 1e-6 / 2r, plus float32 rounding.
        r = np.sqrt(settings.isovalue)
        assert np.abs(np.linalg.norm(points, axis=1) - r).max() <= 1e-6 / (2 * r) + 1e-6 * r
        normals = _attribute(cloud, "normal", 3)
        assert (np.einsum("ij,ij->i", normals, points) > 0).all(), "normals point out of the sphere"
        radius = _attribute(cloud, "radius", 1)
        assert (radius > 0).all() and radius.max() < r
        assert (_attribute(cloud, "element", 1) == 0).all()
        # The same samples as the package's own call on the same file.
        direct = isobar.sample_fe(isobar.FeMesh.read(str(path)), "f", settings.isovalue, spacing=settings.spacing)
        np.testing.assert_array_equal(points, direct.points.astype(np.float32).astype(np.float64))
    # One point-cloud datablock in the file: old ones are removed on each resample.
    assert len([c for c in bpy.data.pointclouds if c.users]) == 1


def test_the_mixed_cell_fixture_imports_with_the_first_field(scene, isobar):
    assert bpy.ops.isobar.import_fe(filepath=str(FIXTURE)) == {"FINISHED"}
    obj = bpy.context.active_object
    assert obj.isobar_fe.field == "p" and len(obj.data.points) > 20, obj.isobar_fe.status


def test_bad_files_and_fields_are_reported_without_an_object(scene, tmp_path):
    before = set(bpy.data.objects.keys())
    missing = tmp_path / "missing.vtu"
    with pytest.raises(RuntimeError, match="missing.vtu"):
        bpy.ops.isobar.import_fe(filepath=str(missing))
    truncated = tmp_path / "cut.vtu"
    truncated.write_bytes(FIXTURE.read_bytes()[:400])
    with pytest.raises(RuntimeError, match="cut.vtu"):
        bpy.ops.isobar.import_fe(filepath=str(truncated))
    with pytest.raises(RuntimeError, match="nope"):
        bpy.ops.isobar.import_fe(filepath=str(FIXTURE), field="nope")
    assert set(bpy.data.objects.keys()) == before


def test_an_isovalue_the_field_never_crosses_is_a_warning_under_the_status(scene, isobar, tmp_path):
    import warnings

    path = _cube_vtu(tmp_path / "cube.vtu")
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        assert bpy.ops.isobar.import_fe(filepath=str(path), field="f", isovalue=10.0, spacing=0.08) == {"FINISHED"}
    settings = bpy.context.active_object.isobar_fe
    assert not settings.status_error and settings.samples == 0, settings.status
    assert "no surface at isovalue" in settings.status_warnings, settings.status_warnings
    assert len(settings.status_warnings.splitlines()) == 1
    # Shown by the panel and the operator's report only: Python's copy is kept quiet.
    assert not [w for w in caught if issubclass(w.category, isobar.IsobarWarning)], caught
    settings.isovalue = 0.49
    assert settings.samples > 50 and settings.status_warnings == "", settings.status_warnings


def test_resampling_keeps_the_point_clouds_name(scene, tmp_path):
    assert bpy.ops.isobar.import_fe(filepath=str(_cube_vtu(tmp_path / "cube.vtu")), field="f", isovalue=1.0) == {"FINISHED"}
    obj = bpy.context.active_object
    name = obj.data.name
    for iso in (0.8, 1.2, 0.9):
        obj.isobar_fe.isovalue = iso
        assert not obj.isobar_fe.status_error, obj.isobar_fe.status
        assert obj.data.name == name
    assert [c.name for c in bpy.data.pointclouds] == [name]  # no orphans either
