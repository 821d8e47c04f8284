"""isobar.Slider: build a store from a numpy volume, slide, check against numpy."""

import numpy as np
import pytest

import isobar


def _volume():
    z, y, x = np.meshgrid(np.arange(14), np.arange(12), np.arange(16), indexing="ij")
    r = np.sqrt((x - 7.5) ** 2 + (y - 5.5) ** 2 + (z - 6.5) ** 2)
    return (10.0 - r + 0.3 * np.sin(x)).astype(np.float32)  # [z, y, x]


def _cut_edges(vol, iso):
    """Every lattice edge whose ends lie on both sides of iso, as lower-end (z, y, x, axis)."""
    above = vol > iso
    cut = set()
    for axis, sl in ((2, np.s_[:, :, :-1]), (1, np.s_[:, :-1, :]), (0, np.s_[:-1, :, :])):
        shifted = np.roll(above, -1, axis=axis)[sl]
        for zyx in np.argwhere(above[sl] != shifted):
            cut.add((tuple(int(v) for v in zyx), axis))
    return cut


def test_slider_matches_numpy_and_is_closed(tmp_path):
    vol = _volume()
    store = tmp_path / "ball.isoslider"
    isobar.Slider.build_array(vol, store, origin=(1.0, 2.0, 3.0), spacing=(0.5, 0.5, 0.5))
    with isobar.Slider(store) as slider:
        lo, hi = slider.value_range
        assert lo == pytest.approx(float(vol.min())) and hi == pytest.approx(float(vol.max()))
        for iso in (5.0, 5.2, 4.0, 7.5, 5.0):
            u = slider.set_isovalue(iso)
            cut = _cut_edges(vol, iso)
            assert len(u.points) == len(cut)
            assert u.points.dtype == np.float32 and u.triangles.dtype == np.uint32
            # Each vertex lies on a cut edge at the linear crossing.
            g = (u.points.astype(np.float64) - (1.0, 2.0, 3.0)) / 0.5  # (x, y, z) lattice units
            base = np.floor(g + 1e-6).astype(int)
            for p, b in zip(g, base):
                frac = p - b
                axis_xyz = int(np.argmax(frac))
                x, y, zz = b
                a = vol[zz, y, x]
                step = [0, 0, 0]
                step[axis_xyz] = 1
                bval = vol[zz + step[2], y + step[1], x + step[0]]
                t = (iso - a) / (bval - a)
                assert abs(frac[axis_xyz] - t) < 1e-4
            if iso < 5.0:
                continue  # the sphere of radius 10 - iso leaves the volume
            # Closed and consistently oriented: every directed edge once, its reverse once.
            tri = u.triangles.astype(np.int64)
            directed = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
            keys = set(map(tuple, directed))
            assert len(keys) == len(directed)
            assert all((b, a) in keys for a, b in keys)
            assert np.allclose(np.linalg.norm(u.normals, axis=1), 1.0, atol=1e-4)
        assert slider.stats["updates"] == 5


def test_change_lists_describe_the_update(tmp_path):
    store = tmp_path / "c.isoslider"
    isobar.Slider.build_array(_volume(), store)
    slider = isobar.Slider(store)
    first = slider.set_isovalue(5.0)
    assert len(first.added) == len(first.triangles) and len(first.removed) == 0
    second = slider.set_isovalue(5.3)
    assert len(second.triangles) == len(first.triangles) - len(second.removed) + len(second.added)
    assert second.moved.shape[1] == 2
    slider.close()
    with pytest.raises(isobar.InvalidArgumentError):
        slider.set_isovalue(1.0)


def test_bad_stores_raise_clear_errors(tmp_path):
    with pytest.raises(isobar.IoError):
        isobar.Slider(tmp_path / "missing.isoslider")
    bad = tmp_path / "bad.isoslider"
    bad.write_bytes(b"ISOSLIDE" + (7).to_bytes(4, "little") + bytes(200))
    with pytest.raises(isobar.FormatError, match="version 7"):
        isobar.Slider(bad)
    with pytest.raises(isobar.InvalidArgumentError):
        isobar.Slider.build_array(np.zeros((3, 3)), tmp_path / "x.isoslider")
