"""isobar.Slider: build a store from a numpy volume, slide, check against numpy."""

import os
import signal
import warnings

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


def _sphere_distance(n=48):
    """Minus the distance to a point off the lattice, [z, y, x]: closed spheres at -r."""
    z, y, x = np.meshgrid(np.arange(n), np.arange(n), np.arange(n), indexing="ij")
    c = n / 2 + np.array([0.3, 0.17, -0.21])
    return (-np.sqrt((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2)).astype(np.float32)


def _trilinear(vol, points):
    """The trilinear interpolant of vol [z, y, x] (origin 0, spacing 1) at (x, y, z) points."""
    p = points.astype(np.float64)
    b = np.minimum(np.floor(p).astype(int), np.array(vol.shape[::-1]) - 2)
    f = p - b
    out = np.zeros(len(p))
    for dz in (0, 1):
        for dy in (0, 1):
            for dx in (0, 1):
                w = (f[:, 0] if dx else 1 - f[:, 0]) * (f[:, 1] if dy else 1 - f[:, 1]) * (f[:, 2] if dz else 1 - f[:, 2])
                out += w * vol[b[:, 2] + dz, b[:, 1] + dy, b[:, 0] + dx]
    return out


def _closed_oriented(triangles):
    tri = triangles.astype(np.int64)
    if np.any((tri[:, 0] == tri[:, 1]) | (tri[:, 1] == tri[:, 2]) | (tri[:, 0] == tri[:, 2])):
        return False
    directed = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    keys = set(map(tuple, directed))
    return len(keys) == len(directed) and all((b, a) in keys for a, b in keys)


def _canon(points, triangles):
    """Triangles as position triples, rotated to start at the smallest, sorted."""
    keys = [tuple(p) for p in points.view(np.uint32).reshape(-1, 3).tolist()]
    out = []
    for t in triangles.tolist():
        k = [keys[i] for i in t]
        r = k.index(min(k))
        out.append((k[r], k[(r + 1) % 3], k[(r + 2) % 3]))
    return sorted(out)


def test_lod_mesh_is_coarser_closed_and_exact_at_bound_zero(tmp_path):
    vol = _sphere_distance()
    store = tmp_path / "sphere.isoslider"
    isobar.Slider.build_array(vol, store)
    with isobar.Slider(store) as slider:
        assert slider.lod_error_bound == 0.0 and slider.lod_max_level == 3
        exact = slider.set_isovalue(-19.0)
        assert len(exact.triangles) > 1000
        # Bound 0: the exact mesh, vertices renumbered.
        lod = slider.lod_mesh()
        assert len(lod.triangles) == len(exact.triangles)
        assert _canon(lod.points, lod.triangles) == _canon(exact.points, exact.triangles)

        counts = []
        for bound in (0.001, 0.01, 0.03):
            slider.lod_error_bound = bound
            assert slider.lod_error_bound == bound
            lod = slider.lod_mesh()
            assert lod.error_bound == bound
            assert lod.points.dtype == np.float32 and lod.triangles.dtype == np.uint32
            assert _closed_oriented(lod.triangles), bound
            assert np.allclose(np.linalg.norm(lod.normals, axis=1), 1.0, atol=1e-4)
            # Every vertex (edge crossings and fan apexes) lies on the level-0 surface.
            assert np.max(np.abs(_trilinear(vol, lod.points) + 19.0)) < 1e-3
            # Normals point to decreasing values: outwards from the centre.
            c = 24 + np.array([0.3, 0.17, -0.21])
            assert np.all(np.sum(lod.normals * (lod.points - c), axis=1) > 0)
            counts.append(len(lod.triangles))
        assert counts[0] <= len(exact.triangles)
        assert counts[1] <= counts[0] and counts[2] <= counts[1]
        assert counts[1] < 0.6 * len(exact.triangles), (counts, len(exact.triangles))

        # The setting survives updates; the exact arrays ignore it.
        moved = slider.set_isovalue(-15.0)
        fresh = isobar.Slider(store).set_isovalue(-15.0)
        assert np.array_equal(moved.triangles, fresh.triangles)
        lod = slider.lod_mesh()
        assert len(lod.triangles) < len(moved.triangles) and _closed_oriented(lod.triangles)
        assert np.max(np.abs(_trilinear(vol, lod.points) + 15.0)) < 1e-3

        slider.lod_max_level = 1
        assert (slider.lod_error_bound, slider.lod_max_level) == (0.03, 1)
        one_level = slider.lod_mesh()
        assert len(lod.triangles) <= len(one_level.triangles) < len(moved.triangles)


def test_lod_parameters_are_checked(tmp_path):
    store = tmp_path / "p.isoslider"
    isobar.Slider.build_array(_volume(), store)
    slider = isobar.Slider(store, lod_error_bound=0.01, lod_max_level=2)
    assert (slider.lod_error_bound, slider.lod_max_level) == (0.01, 2)
    for bad in (-0.1, 1.0, float("nan")):
        with pytest.raises(isobar.InvalidArgumentError):
            slider.lod_error_bound = bad
    for bad in (7, -1, 2.5):
        with pytest.raises(isobar.InvalidArgumentError):
            slider.lod_max_level = bad
    assert (slider.lod_error_bound, slider.lod_max_level) == (0.01, 2)
    empty = slider.lod_mesh()  # no isovalue yet: an empty surface
    assert empty.points.shape == (0, 3) and empty.triangles.shape == (0, 3)
    slider.close()
    with pytest.raises(isobar.InvalidArgumentError):
        slider.lod_mesh()


def test_builds_within_a_small_memory_budget_write_the_same_store(tmp_path):
    # 40 x 44 x 48 nodes: an in-memory build needs about 29 bytes a node (2.4 MB); with
    # 1.5 MiB the core sorts the values on disk and spools the skip-list levels.
    z, y, x = np.meshgrid(np.arange(40), np.arange(44), np.arange(48), indexing="ij")
    vol = (-np.sqrt((x - 23.3) ** 2 + (y - 21.6) ** 2 + (z - 19.8) ** 2)).astype(np.float32)
    whole, spooled = tmp_path / "whole.isoslider", tmp_path / "spooled.isoslider"
    isobar.Slider.build_array(vol, whole)
    isobar.Slider.build_array(vol, spooled, memory_budget=3 << 19)
    assert whole.read_bytes() == spooled.read_bytes()
    npy = tmp_path / "ball.npy"
    np.save(npy, vol)
    from_file = tmp_path / "file.isoslider"
    isobar.Slider.build(npy, from_file, memory_budget=3 << 19)
    assert from_file.read_bytes() == whole.read_bytes()
    # Nothing but the stores and the volume left in the folder.
    assert sorted(p.name for p in tmp_path.iterdir()) == ["ball.npy", "file.isoslider", "spooled.isoslider", "whole.isoslider"]
    # Too small even for sorting on disk: a clear error, no store.
    with pytest.raises(isobar.OverBudgetError, match="memory budget"):
        isobar.Slider.build_array(vol, tmp_path / "refused.isoslider", memory_budget=20000)
    assert not (tmp_path / "refused.isoslider").exists()
    with pytest.raises(isobar.InvalidArgumentError):
        isobar.Slider.build_array(vol, tmp_path / "bad.isoslider", memory_budget=-1)


def test_updates_from_several_threads_take_turns(tmp_path):
    """Eight threads sliding one slider at once: each update is whole (the surface of its
    own isovalue, as a lone slider gives it), and the process survives (it used to corrupt
    the core's state: a panic, then a double free)."""
    import threading

    vol = _volume()
    store = tmp_path / "t.isoslider"
    isobar.Slider.build_array(vol, store)
    isos = [4.5 + 0.25 * i for i in range(8)]
    with isobar.Slider(store) as alone:
        expect = {iso: len(alone.set_isovalue(iso).triangles) for iso in isos}
    slider = isobar.Slider(store)
    seen, errors = [], []

    def work(k):
        try:
            for step in range(6):
                iso = isos[(k + step) % len(isos)]
                seen.append((iso, len(slider.set_isovalue(iso).triangles)))
        except Exception as e:  # noqa: BLE001 - reported below
            errors.append(e)

    threads = [threading.Thread(target=work, args=(k,)) for k in range(8)]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert not errors
    assert len(seen) == 48 and all(n == expect[iso] for iso, n in seen)
    slider.close()


def _record(calls, answer=None):
    """A progress callback that appends (fraction, phase) to `calls` and returns `answer`."""

    def progress(fraction, phase):
        calls.append((fraction, phase))
        return answer

    return progress


def _check_reports(calls):
    assert calls, "the progress callback was never called"
    for fraction, phase in calls:
        assert isinstance(phase, str) and phase
        assert 0.0 <= fraction <= 1.0
    # Within a phase the fraction never goes back (a phase may come back: compare runs).
    for (f0, p0), (f1, p1) in zip(calls, calls[1:]):
        if p0 == p1:
            assert f1 >= f0, (p0, f0, f1)


def test_builds_report_progress(tmp_path):
    vol = _sphere_distance(64)
    quiet, reported = tmp_path / "quiet.isoslider", tmp_path / "reported.isoslider"
    isobar.Slider.build_array(vol, quiet)
    calls = []
    isobar.Slider.build_array(vol, reported, progress=_record(calls))
    _check_reports(calls)
    assert reported.read_bytes() == quiet.read_bytes()

    npy = tmp_path / "sphere.npy"
    np.save(npy, vol)
    from_file = tmp_path / "file.isoslider"
    calls = []
    isobar.Slider.build(npy, from_file, progress=_record(calls, answer=True))  # True goes on
    _check_reports(calls)
    assert from_file.read_bytes() == quiet.read_bytes()

    # Sorting on disk (4 MiB for 64³ nodes) reports its own phases.
    calls = []
    isobar.Slider.build_array(vol, tmp_path / "spooled.isoslider", memory_budget=4 << 20, progress=_record(calls))
    _check_reports(calls)
    assert any("disk" in phase for _, phase in calls)


# Where to cancel: at the first report, or halfway through the edge lists (on-disk sorts'
# spools are open then).
_CANCEL_AT = {
    "first": lambda fraction, phase: False,
    "middle": lambda fraction, phase: fraction < 0.5,
}


@pytest.mark.parametrize("when", sorted(_CANCEL_AT))
@pytest.mark.parametrize("budget", [0, 4 << 20], ids=["in-memory", "on-disk"])
def test_progress_returning_false_cancels_the_build(tmp_path, when, budget):
    vol = _sphere_distance(64)
    npy = tmp_path / "sphere.npy"
    np.save(npy, vol)
    store = tmp_path / "s.isoslider"
    for build in (
        lambda progress: isobar.Slider.build_array(vol, store, memory_budget=budget, progress=progress),
        lambda progress: isobar.Slider.build(npy, store, memory_budget=budget, progress=progress),
    ):
        calls = []
        stop = _CANCEL_AT[when]

        def progress(fraction, phase):
            calls.append(fraction)
            return stop(fraction, phase)

        with pytest.raises(isobar.Cancelled):
            build(progress)
        assert calls[-1] < 1.0 and not stop(calls[-1], "")  # stopped where it was told to
        # No store, and no temporary beside it (os.listdir shows hidden files too).
        assert os.listdir(tmp_path) == ["sphere.npy"]

    # An earlier store at the path is left as it was.
    isobar.Slider.build_array(vol[:32], store)
    before = store.read_bytes()
    with pytest.raises(isobar.Cancelled):
        isobar.Slider.build_array(vol, store, memory_budget=budget, progress=_CANCEL_AT[when])
    assert store.read_bytes() == before
    assert sorted(os.listdir(tmp_path)) == ["s.isoslider", "sphere.npy"]


def test_an_exception_in_progress_stops_the_build_and_propagates(tmp_path):
    class Boom(Exception):
        pass

    vol = _sphere_distance(64)
    npy = tmp_path / "sphere.npy"
    np.save(npy, vol)
    store = tmp_path / "s.isoslider"
    for build in (
        lambda progress: isobar.Slider.build_array(vol, store, progress=progress),
        lambda progress: isobar.Slider.build(npy, store, progress=progress),
    ):
        calls = []
        boom = Boom("from the callback")

        def progress(fraction, phase):
            calls.append(fraction)
            if len(calls) == 2:
                raise boom

        with pytest.raises(Boom) as caught:
            build(progress)
        assert caught.value is boom  # the callback's own exception, not a Cancelled
        assert len(calls) == 2  # the build stopped there
        assert os.listdir(tmp_path) == ["sphere.npy"]


def test_ctrl_c_during_a_build_cancels_it(tmp_path, python_sigint):
    vol = _sphere_distance(64)
    store = tmp_path / "s.isoslider"
    calls = []

    def progress(fraction, phase):
        calls.append(fraction)
        if len(calls) == 1:
            os.kill(os.getpid(), signal.SIGINT)  # as if Ctrl-C were pressed now

    with pytest.raises(KeyboardInterrupt):
        isobar.Slider.build_array(vol, store, progress=progress)
    assert calls[-1] < 1.0
    assert os.listdir(tmp_path) == []
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler


def test_a_cancel_once_the_store_is_in_place_is_too_late(tmp_path):
    # The last report comes after the store is renamed into place: a False there must not
    # raise Cancelled over a store that exists (it did).
    vol = _sphere_distance(32)
    quiet, late = tmp_path / "quiet.isoslider", tmp_path / "late.isoslider"
    isobar.Slider.build_array(vol, quiet)
    calls = []

    def progress(fraction, phase):
        calls.append(fraction)
        return fraction < 1.0

    isobar.Slider.build_array(vol, late, progress=progress)
    assert calls[-1] == 1.0
    assert late.read_bytes() == quiet.read_bytes()


def test_a_long_jump_reports_progress_and_a_cancel_keeps_the_surface(tmp_path):
    vol = _sphere_distance(64)  # 262,144 ranks: a jump across them passes several reports
    store = tmp_path / "jump.isoslider"
    isobar.Slider.build_array(vol, store)
    lo, hi = float(vol.min()), float(vol.max())
    near, far = lo + 0.02 * (hi - lo), lo + 0.9 * (hi - lo)
    with isobar.Slider(store) as slider, isobar.Slider(store) as fresh:
        before = slider.set_isovalue(near)
        calls = []
        with pytest.raises(isobar.Cancelled):
            slider.set_isovalue(far, progress=_record(calls, answer=False))
        assert len(calls) == 1
        # Nothing moved: the same surface, and the next update goes on from it.
        again = slider.set_isovalue(near)
        assert len(again.added) == 0 and len(again.removed) == 0
        assert np.array_equal(again.triangles, before.triangles)
        # Cancelled halfway, with blocks of edge changes already gathered: still nothing moved.
        calls = []

        def stop_midway(fraction, phase):
            calls.append((fraction, phase))
            return fraction == 0.0

        with pytest.raises(isobar.Cancelled):
            slider.set_isovalue(far, progress=stop_midway)
        assert len(calls) == 2 and calls[1][0] > 0.0
        again = slider.set_isovalue(near)
        assert len(again.added) == 0 and len(again.removed) == 0
        assert np.array_equal(again.triangles, before.triangles)
        calls = []
        jumped = slider.set_isovalue(far, progress=_record(calls))
        _check_reports(calls)
        assert len(calls) >= 2
        direct = fresh.set_isovalue(far)
        assert np.array_equal(jumped.points, direct.points)
        assert len(jumped.triangles) == len(direct.triangles)


def test_float64_values_that_float32_cannot_resolve_warn_and_values_beyond_it_are_refused(tmp_path):
    """The slider keeps float32 values: a pressure of 101325 ± 0.02 Pa became a few
    hundred float32 steps without a word (the surfaces were those of the rounded values),
    and a finite 1e40 turned infinite and was blamed on the data. The core narrows the
    values and says so, for arrays and for files (a float64 .npy, as the CLI reads it)."""
    z, y, x = np.mgrid[0:16, 0:16, 0:16].astype(np.float64)
    pressure = 101325.0 + 0.02 * np.sin(x / 3.0) * np.cos(y / 4.0) * np.cos(z / 5.0)
    coarse = r"held as float32, in steps of 0\.0078125 near 101325\.0\d+: 19\.\d\d % of the value range 101324\.98\d+\.\.101325\.01\d+; subtract"
    with pytest.warns(isobar.IsobarWarning, match=coarse) as caught:
        isobar.Slider.build_array(pressure, tmp_path / "p.isoslider")
    assert caught[0].filename == __file__  # the caller's line
    np.save(tmp_path / "p.npy", pressure)
    with pytest.warns(isobar.IsobarWarning, match=coarse) as caught:
        isobar.Slider.build(tmp_path / "p.npy", tmp_path / "pf.isoslider")
    assert caught[0].filename == __file__
    offset = pressure - pressure.mean()  # what the warning advises: no warning
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        # Each build issues its own warnings only, not the coarse builds' above.
        isobar.Slider.build_array(offset, tmp_path / "q.isoslider")
        isobar.Slider.build_array(offset.astype(np.float32), tmp_path / "q32.isoslider")
        isobar.Slider.build_array(np.zeros((16, 16, 16), np.int64) + np.arange(16), tmp_path / "i.isoslider")
    huge = offset.copy()
    huge[3, 2, 1] = 1e40
    beyond = r"node 801 \(x=1, y=2, z=3\) is 1e40, beyond the range of float32"
    with pytest.raises(isobar.InvalidInputError, match=beyond):
        isobar.Slider.build_array(huge, tmp_path / "r.isoslider")
    np.save(tmp_path / "r.npy", huge)
    with pytest.raises(isobar.Error, match=r"r\.npy: .*" + beyond):
        isobar.Slider.build(tmp_path / "r.npy", tmp_path / "rf.isoslider")
    assert not (tmp_path / "r.isoslider").exists() and not (tmp_path / "rf.isoslider").exists()


def test_origin_and_spacing_are_three_numbers(tmp_path):
    """ctypes padded a two-value origin with 0 (a volume placed at z = 0 without a word)
    and failed on four with a bare IndexError."""
    values = np.zeros((4, 4, 4), np.float32)
    for bad in ((5.0, 5.0), (1.0, 2.0, 3.0, 4.0), "abc", "123"):
        with pytest.raises(isobar.InvalidArgumentError, match="origin must be three numbers"):
            isobar.Slider.build_array(values, tmp_path / "o.isoslider", origin=bad)
        with pytest.raises(isobar.InvalidArgumentError, match="spacing must be three numbers"):
            isobar.Slider.build_array(values, tmp_path / "s.isoslider", spacing=bad)
    assert not list(tmp_path.iterdir())
