"""High-order FE isosurface samples as USD Points: the stage holds exactly the core's
samples (positions, normals, widths = 2 × radius, primvars), each on the level set of the
elements by an independent evaluation, written atomically, and bad inputs are refused."""

from __future__ import annotations

import numpy as np
import pytest
from conftest import REPO, run_cli
from pxr import Usd, UsdGeom

import isobar
import isobar_usd

FE_DATA = REPO / "rust-core" / "data" / "fe"
FIXTURE = FE_DATA / "mixed_lagrange.vtu"


def _sphere_cell(path, order=3):
    """One Lagrange hexahedron over [-1, 1]³ in VTK's node order (as VTK lists it), with
    f = |x|², which order ≥ 2 reproduces exactly: the isosurface f = r² is the sphere."""
    for line in (FE_DATA / "vtk_lagrange_nodes.txt").read_text().splitlines():
        kind, p, count, *coords = line.split()
        if (kind, p) == ("hex", str(order)):
            pts = np.array(coords, dtype=float).reshape(int(count), 3) * 2.0 - 1.0
            break
    n = len(pts)
    offsets = np.array([0, n])
    mesh = isobar.FeMesh.from_arrays(pts, [72], offsets, np.arange(n), point_data={"f": (pts**2).sum(axis=1)})
    return mesh


def _points(path):
    stage = Usd.Stage.Open(str(path))
    prim = stage.GetDefaultPrim()
    points = UsdGeom.Points(stage.GetPrimAtPath(prim.GetPath().AppendChild("Samples")))
    assert points, "no Points prim under the default prim"
    return stage, points


def test_written_points_are_the_cores_samples_on_the_sphere(tmp_path):
    samples = isobar.sample_fe(_sphere_cell(tmp_path), "f", 0.64, spacing=0.07)
    out = isobar_usd.write_points(samples, tmp_path / "sphere.usda", up_axis="Z")
    stage, points = _points(out)
    assert UsdGeom.GetStageUpAxis(stage) == UsdGeom.Tokens.z
    xyz = np.asarray(points.GetPointsAttr().Get(), dtype=np.float64)
    np.testing.assert_array_equal(xyz, samples.points.astype(np.float32))
    # Independent evaluation: |x| = 0.8 (float32 positions: 1e-6 relative).
    assert np.abs(np.linalg.norm(xyz, axis=1) - 0.8).max() <= 1e-6
    widths = np.asarray(points.GetWidthsAttr().Get())
    np.testing.assert_allclose(widths, 2 * samples.radii, rtol=1e-6)
    assert points.GetWidthsInterpolation() == UsdGeom.Tokens.vertex
    normals = np.asarray(points.GetNormalsAttr().Get())
    assert (np.einsum("ij,ij->i", normals, xyz) > 0).all(), "normals point out of the sphere"
    api = UsdGeom.PrimvarsAPI(points.GetPrim())
    assert np.asarray(api.GetPrimvar("Reference").Get()).shape == (len(samples), 3)
    assert set(np.asarray(api.GetPrimvar("Element").Get()).tolist()) == {0}
    assert isobar_usd.check(out) == []


def test_cli_samples_a_vtu_and_the_stage_checks_clean(cli, tmp_path):
    out = tmp_path / "fe.usd"
    grid = isobar.FeMesh.read(str(FIXTURE))
    iso = float(np.median(grid.arrays["p"]))
    proc = run_cli(cli, "fe", FIXTURE, "--field", "p", "--iso", repr(iso), "-o", out, "--check")
    assert "samples" in proc.stdout
    _, points = _points(out)
    want = isobar.sample_fe(grid, "p", iso)
    np.testing.assert_array_equal(np.asarray(points.GetPointsAttr().Get()), want.points.astype(np.float32))


def test_bad_inputs_are_refused_and_the_old_stage_stays(cli, tmp_path):
    out = tmp_path / "keep.usd"
    samples = isobar.sample_fe(_sphere_cell(tmp_path), "f", 0.64, spacing=0.1)
    isobar_usd.write_points(samples, out)
    before = out.read_bytes()
    proc = run_cli(cli, "fe", FIXTURE, "--field", "nope", "--iso", "0", "-o", out, check=False)
    assert proc.returncode == 1 and "nope" in proc.stderr
    truncated = tmp_path / "cut.vtu"
    truncated.write_bytes(FIXTURE.read_bytes()[:500])
    proc = run_cli(cli, "fe", truncated, "--field", "p", "--iso", "0", "-o", out, check=False)
    assert proc.returncode == 1 and "cut.vtu" in proc.stderr
    assert out.read_bytes() == before
    with pytest.raises(isobar_usd.InputError, match=".usdz|.usd"):
        isobar_usd.write_points(samples, tmp_path / "x.abc")
    assert not list(tmp_path.glob(".*tmp*"))


def test_an_isovalue_beyond_the_field_is_one_warning_on_stderr(cli, tmp_path):
    out = tmp_path / "none.usd"
    proc = run_cli(cli, "fe", FIXTURE, "--field", "p", "--iso", "1e6", "-o", out)
    lines = [line for line in proc.stderr.splitlines() if "no surface at isovalue" in line]
    assert len(lines) == 1 and lines[0].startswith("isobar-usd: warning: "), proc.stderr
    assert "IsobarWarning" not in proc.stderr, proc.stderr  # Python's copy stays quiet
    assert "0 samples" in proc.stdout
    proc = run_cli(cli, "fe", FIXTURE, "--field", "p", "--iso", "1e6", "-o", out, "--quiet")
    assert "warning" not in proc.stderr, proc.stderr
    grid = isobar.FeMesh.read(str(FIXTURE))
    proc = run_cli(cli, "fe", FIXTURE, "--field", "p", "--iso", repr(float(np.median(grid.arrays["p"]))), "-o", out)
    assert "warning" not in proc.stderr, proc.stderr
