"""The installed package: bundled library, versions, and the ctypes layouts against the
C header."""

import os
import shutil
import subprocess
from ctypes import sizeof
from pathlib import Path

import numpy as np
import pytest

import isobar
from isobar import _lib
from conftest import REPO, lattice

HEADER = REPO / "rust-core" / "include" / "isobar.h"


def test_versions_agree():
    assert isobar.__version__ == isobar.core_version()
    assert isobar.abi_version() == isobar.ABI_VERSION == 1


def test_library_is_inside_the_installed_package():
    if os.environ.get("ISOBAR_LIBRARY"):
        pytest.skip("ISOBAR_LIBRARY overrides the bundled library")
    package = Path(isobar.__file__).resolve().parent
    assert Path(isobar.library_path).resolve() == package / "libisobar.so"
    assert "site-packages" in str(package), "run through tests/python/run.sh (a real pip install)"


def test_defaults_match_the_core():
    d = isobar.default_params()
    assert d.struct_size == sizeof(_lib.SphParams)
    assert (d.kernel, d.h_scale, d.correct, d.trim, d.normals, d.full_grid) == (0, 1.0, 1, 1, 1, 0)
    assert (d.grid_factor, d.tolerance, d.trim_node, d.trim_vertex) == (0.5, 1e-6, 0.1, 0.5)


def _c_layout(struct, fields):
    """sizeof and offsetof of every field, as a C compiler sees isobar.h."""
    cc = shutil.which("gcc") or shutil.which("cc")
    if cc is None or not HEADER.is_file():
        pytest.skip("needs a C compiler and rust-core/include/isobar.h")
    prints = "".join(f'printf("%zu\\n", offsetof({struct}, {f}));' for f in fields)
    src = f'#include <stdio.h>\n#include <stddef.h>\n#include "isobar.h"\nint main(void){{printf("%zu\\n", sizeof({struct}));{prints}return 0;}}'
    return src, cc


@pytest.mark.parametrize("struct, ctype", [("IsobarSphParams", _lib.SphParams), ("IsobarStats", _lib.Stats)])
def test_ctypes_structs_match_the_header(struct, ctype, tmp_path):
    fields = [name for name, _ in ctype._fields_]
    src, cc = _c_layout(struct, fields)
    (tmp_path / "layout.c").write_text(src)
    exe = tmp_path / "layout"
    build = subprocess.run([cc, "-I", str(HEADER.parent), str(tmp_path / "layout.c"), "-o", str(exe)], capture_output=True, text=True)
    assert build.returncode == 0, build.stderr
    numbers = [int(x) for x in subprocess.run([str(exe)], capture_output=True, text=True, check=True).stdout.split()]
    assert numbers[0] == sizeof(ctype)
    assert numbers[1:] == [getattr(ctype, f).offset for f in fields]


def test_every_declared_function_is_in_the_header():
    if not HEADER.is_file():
        pytest.skip("no header")
    text = HEADER.read_text()
    for name in _lib._PROTOTYPES:
        assert f"{name}(" in text, name


def test_several_isovalues_attributes_and_kernels():
    xyz = lattice(6)
    velocity = np.column_stack([xyz[:, 0], -xyz[:, 1], np.ones(len(xyz))])
    p = isobar.Particles.from_arrays(xyz, velocity=velocity)
    s = isobar.extract(p, [0.3, 0.6], h=0.1, attributes="velocity")
    assert set(np.unique(s.attributes["Isovalue"])) == {0.3, 0.6}
    v = s.attributes["velocity"]
    assert v.shape == (s.n_points, 3)
    assert np.allclose(v[:, 2], 1.0, rtol=1e-12)  # normalised interpolation keeps constants
    for kernel in isobar.KERNELS:
        assert isobar.extract(p, 0.5, h=0.1, kernel=kernel).n_triangles > 0
    preview = isobar.extract(p, 0.5, h=0.1, correct=False, normals=False)
    assert preview.normals is None and preview.n_triangles > 0
    grid = isobar.extract(p, 0.5, h=0.1, full_grid=True)
    assert grid.n_triangles > 0
    assert abs(grid.volume() - isobar.extract(p, 0.5, h=0.1).volume()) < 0.02 * grid.volume()


def test_release_keeps_arrays_and_refuses_write(tmp_path):
    s = isobar.extract(isobar.Particles.from_arrays(lattice(4)), 0.5, h=0.1)
    points = s.points.copy()
    s.write(tmp_path / "a.ply")
    assert (tmp_path / "a.ply").stat().st_size > 0
    s.release()
    assert np.array_equal(s.points, points)
    with pytest.raises(isobar.InvalidArgumentError, match="release"):
        s.write(tmp_path / "b.ply")


def test_trim_auto_follows_the_command_line():
    xyz = lattice(6)
    # pressure * (sum of weights) = 1 also holds out where the weights fade (x near 0.5):
    # the part that trimming cuts.
    p = isobar.Particles.from_arrays(xyz, pressure=10 * xyz[:, 0])
    same = lambda a, b: np.array_equal(a.points, b.points) and np.array_equal(a.triangles, b.triangles)
    # SumOfWeights: no trimming; a named field: the default thresholds.
    assert same(isobar.extract(p, 0.6, h=0.1), isobar.extract(p, 0.6, h=0.1, trim=None))
    auto = isobar.extract(p, 1.0, field="pressure", h=0.1)
    assert same(auto, isobar.extract(p, 1.0, field="pressure", h=0.1, trim=(0.1, 0.5)))
    untrimmed = isobar.extract(p, 1.0, field="pressure", h=0.1, trim=None)
    assert auto.stats["trim_cut_points"] > 0 and auto.n_triangles < untrimmed.n_triangles


def test_threads_extract_from_one_particle_set_concurrently():
    from concurrent.futures import ThreadPoolExecutor

    p = isobar.Particles.from_arrays(lattice(8))
    reference = isobar.extract(p, 0.5, h=0.1)
    with ThreadPoolExecutor(4) as pool:
        results = list(pool.map(lambda _: isobar.extract(p, 0.5, h=0.1, progress=lambda f, ph: None), range(8)))
    for s in results:
        assert np.array_equal(s.points, reference.points) and np.array_equal(s.triangles, reference.triangles)
