"""Isovalue sliding on a volume: the object's mesh follows its isovalue property, each
change served by the core's slider, and equals the core's own slider mesh."""

import os
import sys

import bpy
import numpy as np
import pytest
from conftest import MODULE, mesh_arrays


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


def _import(path, **settings):
    assert bpy.ops.isobar.import_volume(filepath=str(path), **settings) == {"FINISHED"}
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


def test_a_small_memory_budget_writes_the_same_store_and_too_small_one_is_reported(scene, tmp_path):
    # 40³ nodes: an in-memory pre-encoding needs about 1.9 MB; 1.5 MiB sorts on disk.
    big = _volume(tmp_path / "big.npy", n=40)
    small = tmp_path / "small.npy"
    small.write_bytes(big.read_bytes())
    a = _import(big)
    b = _import(small, memory_budget=1.5 / 1024)
    assert (tmp_path / "big.npy.isoslider").read_bytes() == (tmp_path / "small.npy.isoslider").read_bytes()
    for x, y in zip(mesh_arrays(a), mesh_arrays(b)):
        np.testing.assert_array_equal(x, y)
    tiny = tmp_path / "tiny.npy"
    tiny.write_bytes(big.read_bytes())
    with pytest.raises(RuntimeError, match="memory budget"):
        bpy.ops.isobar.import_volume(filepath=str(tiny), memory_budget=1e-6)
    assert not (tmp_path / "tiny.npy.isoslider").exists()


def test_bad_volume_is_reported_not_raised(scene, tmp_path):
    bad = tmp_path / "broken.npy"
    bad.write_bytes(b"\x93NUMPY not really")
    with pytest.raises(RuntimeError, match="broken.npy"):
        bpy.ops.isobar.import_volume(filepath=str(bad))
    assert not [o for o in bpy.data.objects if o.isobar_slider.enabled]


def _trilinear(values, points):
    """The trilinear interpolant of an .npy volume ([z, y, x], node (i, j, k) at (i, j, k))
    at `points`, evaluated here with numpy, not by the core."""
    v = np.asarray(values, np.float64)
    g = np.asarray(points, np.float64)
    i0 = np.clip(np.floor(g).astype(np.int64), 0, np.array(v.shape[::-1]) - 2)
    t = g - i0
    assert np.all((t > -1e-6) & (t < 1 + 1e-6)), "a vertex lies outside the volume"
    out = np.zeros(len(g))
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                w = (t[:, 0] if dx else 1 - t[:, 0]) * (t[:, 1] if dy else 1 - t[:, 1]) * (t[:, 2] if dz else 1 - t[:, 2])
                out += w * v[i0[:, 2] + dz, i0[:, 1] + dy, i0[:, 0] + dx]
    return out


def _assert_closed_and_oriented(triangles):
    """Every edge in exactly two triangles, once each way; no degenerate triangle."""
    t = np.asarray(triangles, np.int64)
    assert len(t) and np.all((t[:, 0] != t[:, 1]) & (t[:, 1] != t[:, 2]) & (t[:, 2] != t[:, 0]))
    directed = np.concatenate([t[:, [0, 1]], t[:, [1, 2]], t[:, [2, 0]]])
    assert np.unique(directed, axis=0, return_counts=True)[1].max() == 1, "an edge is traversed twice the same way"
    counts = np.unique(np.sort(directed, axis=1), axis=0, return_counts=True)[1]
    assert np.all(counts == 2), f"{int(np.sum(counts != 2))} edges not in exactly two triangles"


def _canonical(points, triangles):
    """Triangles as sorted corner positions, rows sorted: independent of vertex numbering."""
    corners = np.asarray(points, np.float64)[np.asarray(triangles, np.int64)].reshape(-1, 3)
    tri = np.repeat(np.arange(len(triangles)), 3)
    rows = corners[np.lexsort((corners[:, 2], corners[:, 1], corners[:, 0], tri))].reshape(-1, 9)
    return rows[np.lexsort(rows.T[::-1])]


def test_lod_error_bound_coarsens_a_closed_mesh_on_the_surface(scene, isobar, tmp_path):
    path = _volume(tmp_path / "blobs.npy", n=48)
    values = np.load(path)
    value_range = float(values.max() - values.min())
    obj = _import(path)
    settings = obj.isobar_slider
    assert settings.lod_error_bound == 0.0
    settings.isovalue = 0.5
    iso = settings.isovalue
    exact_points, exact_triangles = mesh_arrays(obj)
    with isobar.Slider(settings.store) as core:
        want = core.set_isovalue(iso)
    # (A fresh slider numbers vertices its own way: compare the triangles as positions.)
    exact = _canonical(exact_points, exact_triangles)
    np.testing.assert_array_equal(exact, _canonical(want.points, want.triangles))
    slider = sys.modules[MODULE + ".volume_slider"]._OPEN[obj.session_uid][1]
    updates = slider.stats["updates"]

    counts = []
    for bound in (0.01, 0.03, 0.1):
        settings.lod_error_bound = bound
        assert not settings.status_error, settings.status
        points, triangles = mesh_arrays(obj)
        _assert_closed_and_oriented(triangles)
        # On the volume's trilinear surface: within the bound, in fact to float rounding.
        off = np.abs(_trilinear(values, points) - iso)
        assert off.max() <= bound * value_range and off.max() <= 1e-5 * value_range, (bound, off.max())
        assert settings.triangles == len(triangles)
        # The core's own level of detail of this surface, at the bound Blender stored.
        with isobar.Slider(settings.store, lod_error_bound=settings.lod_error_bound) as core:
            core.set_isovalue(iso)
            lod = core.lod_mesh()
        np.testing.assert_array_equal(_canonical(points, triangles), _canonical(lod.points, lod.triangles))
        counts.append(len(triangles))
        # A new bound re-ran the level of detail only: the slider did not move.
        assert slider.stats["updates"] == updates
    assert len(exact_triangles) > counts[0] > counts[1] > counts[2], (len(exact_triangles), counts)

    # Bound 0: the exact surface again (the same triangles, whatever the numbering).
    settings.lod_error_bound = 0.0
    points, triangles = mesh_arrays(obj)
    np.testing.assert_array_equal(_canonical(points, triangles), exact)

    # Sliding with a level of detail on shows the level of detail of the new surface.
    settings.lod_error_bound = 0.03
    settings.isovalue = 0.3
    points, triangles = mesh_arrays(obj)
    _assert_closed_and_oriented(triangles)
    assert np.abs(_trilinear(values, points) - settings.isovalue).max() <= 1e-5 * value_range
    assert slider.stats["updates"] == updates + 1
    assert "level of detail" in settings.status


def test_import_with_a_lod_error_bound(scene, isobar, tmp_path):
    path = _volume(tmp_path / "blobs.npy", n=48)
    obj = _import(path, lod_error_bound=0.03)
    settings = obj.isobar_slider
    assert abs(settings.lod_error_bound - 0.03) < 1e-7 and not settings.status_error
    points, triangles = mesh_arrays(obj)
    _assert_closed_and_oriented(triangles)
    with isobar.Slider(settings.store) as core:
        exact = core.set_isovalue(settings.isovalue)
        core.set_lod(settings.lod_error_bound)
        lod = core.lod_mesh()
    assert len(triangles) == len(lod.triangles) < len(exact.triangles)


def test_a_store_of_another_version_beside_the_volume_is_rebuilt(scene, isobar, tmp_path):
    volume = _volume(tmp_path / "old.npy")
    store = tmp_path / "old.npy.isoslider"
    # What an earlier isobar left: the magic, format version 2, newer than the volume.
    store.write_bytes(b"ISOSLIDE" + (2).to_bytes(4, "little") + bytes(4096))
    with pytest.raises(isobar.FormatError, match="version 2"):
        isobar.Slider(store)
    obj = _import(volume)
    settings = obj.isobar_slider
    assert not settings.status_error and settings.triangles > 0, settings.status
    with isobar.Slider(store) as core:
        want = core.set_isovalue(settings.isovalue)
    np.testing.assert_array_equal(mesh_arrays(obj)[1], want.triangles.astype(np.int32))


def test_a_volume_rewritten_after_import_is_rebuilt_on_the_next_slide(scene, isobar, tmp_path):
    volume = _volume(tmp_path / "blobs.npy")
    obj = _import(volume)
    settings = obj.isobar_slider
    old_max = settings.value_max
    values = np.load(volume)
    np.save(volume, values * 2)  # the next simulation step, twice as strong
    later = os.path.getmtime(settings.store) + 10
    os.utime(volume, (later, later))  # written after the store, whatever the clock's grain
    settings.isovalue = 1.5 * old_max  # above every value of the old volume
    assert not settings.status_error and "rebuilt" in settings.status, settings.status
    assert settings.value_max == pytest.approx(2 * old_max, rel=1e-5)
    with isobar.Slider(settings.store) as core:
        want = core.set_isovalue(settings.isovalue)
    assert settings.triangles == len(want.triangles) > 0
    assert len(mesh_arrays(obj)[1]) == len(want.triangles)


class _ImportVolume:
    """Stands in for a running Import Volume operator: its settings, and its reports."""

    def __init__(self, path):
        self.filepath, self.memory_budget, self.lod_error_bound = str(path), 4.0, 0.0
        self.reports = []

    def report(self, kind, message):
        self.reports.append((set(kind), message))


def test_a_float64_volume_the_store_holds_coarsely_is_a_warning(scene, addon, tmp_path):
    """The store holds float32: a pressure of 101325 Pa plus small variations, saved as
    float64, becomes a few float32 steps. The import says so (what to do included); the
    same variations without the offset import without a word."""
    x = np.linspace(-1.0, 1.0, 20)
    z, y, xx = np.meshgrid(x, x, x, indexing="ij")
    variation = 0.02 * np.exp(-4 * (xx**2 + y**2 + z**2))
    for name, values, warned in (("pressure.npy", 101325.0 + variation, True), ("variation.npy", variation, False)):
        np.save(tmp_path / name, values)
        op = _ImportVolume(tmp_path / name)
        assert addon.operators.ISOBAR_OT_import_volume.execute(op, bpy.context) == {"FINISHED"}
        said = [m for kind, m in op.reports if "WARNING" in kind]
        if warned:
            assert len(said) == 1 and said[0].startswith(f"{name}: the values are held as float32, in steps of 0.0078125"), op.reports
            assert "subtract an offset" in said[0]
        else:
            assert said == [], op.reports
        assert not [m for kind, m in op.reports if "ERROR" in kind], op.reports
