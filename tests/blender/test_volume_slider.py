"""Isovalue sliding on a volume: the object's mesh follows its isovalue property, each
change served by the core's slider, and equals the core's own slider mesh."""

import bpy
import numpy as np
import pytest
from conftest import mesh_arrays


def _volume(path, n=28):
    """Two overlapping blobs on an n³ grid (f32): they merge as the isovalue drops, so
    slides change topology, not only positions."""
    x = np.linspace(-1.0, 1.0, n, dtype=np.float32)
    z, y, xx = np.meshgrid(x, x, x, indexing="ij")
    values = np.exp(-6 * ((xx - 0.35) ** 2 + y**2 + z**2)) + np.exp(-6 * ((xx + 0.35) ** 2 + y**2 + z**2))
    np.save(path, values.astype(np.float32))
    return path


def _volume_of(points, triangles):
    """Enclosed volume of a closed, outward-wound triangle mesh (grid units)."""
    p = np.asarray(points, np.float64)[np.asarray(triangles, np.int64)]
    return abs(np.einsum("ij,ij->i", p[:, 0], np.cross(p[:, 1], p[:, 2])).sum()) / 6.0


def _import(path):
    assert bpy.ops.isobar.import_volume(filepath=str(path)) == {"FINISHED"}
    obj = bpy.context.active_object
    assert obj.isobar_slider.enabled
    return obj


def test_slide_follows_the_cores_slider_and_returns(scene, isobar, tmp_path):
    obj = _import(_volume(tmp_path / "blobs.npy"))
    settings = obj.isobar_slider
    store = settings.store
    assert store.endswith(".isoslider") and (tmp_path / "blobs.npy.isoslider").is_file()
    assert settings.value_min < settings.value_max
    shown = {}
    # The core's own slider driven along the same path: the import showed the midpoint,
    # and the isovalues are the property's own (Blender keeps floats in single precision).
    with isobar.Slider(store) as core:
        core.set_isovalue(settings.isovalue)
        for value in (0.3, 0.31, 0.5, 0.9, 0.2, 0.3):
            settings.isovalue = value
            iso = settings.isovalue
            assert not settings.status_error, settings.status
            points, triangles = mesh_arrays(obj)
            want = core.set_isovalue(iso)
            np.testing.assert_array_equal(triangles, want.triangles.astype(np.int32))
            np.testing.assert_array_equal(points, want.points.astype(np.float32))
            assert settings.triangles == len(triangles) > 0
            shown.setdefault(value, (points, triangles))
            # A fresh slider set straight to this isovalue numbers vertices its own way
            # (a slider reuses indices along its path) but shows the same surface.
            with isobar.Slider(store) as fresh:
                direct = fresh.set_isovalue(iso)
            assert len(direct.triangles) == len(triangles)
            volume = _volume_of(points, triangles)
            assert volume > 0 and abs(_volume_of(direct.points, direct.triangles) - volume) <= 1e-6 * volume
    # Sliding away and back gives the identical mesh.
    np.testing.assert_array_equal(mesh_arrays(obj)[0], shown[0.3][0])
    np.testing.assert_array_equal(mesh_arrays(obj)[1], shown[0.3][1])


def test_bad_volume_is_reported_not_raised(scene, tmp_path):
    bad = tmp_path / "broken.npy"
    bad.write_bytes(b"\x93NUMPY not really")
    with pytest.raises(RuntimeError, match="broken.npy"):
        bpy.ops.isobar.import_volume(filepath=str(bad))
    assert not [o for o in bpy.data.objects if o.isobar_slider.enabled]
