"""pyvista adaptor: point clouds in, triangle meshes out.

pyvista is imported only when one of these functions runs, so ``import isobar`` never
needs it (``pip install pyvista`` for this module)::

    import pyvista as pv, isobar.pyvista
    cloud = pv.PolyData(xyz); cloud.point_data["pressure"] = p
    mesh = isobar.pyvista.surface_from_polydata(cloud, 0.6, h=0.05)
    mesh.plot()
"""

from __future__ import annotations

import json
from typing import Iterable, Optional

import numpy as np

from .adaptive import extract_adaptive
from .errors import InvalidArgumentError, issue, quiet_warnings
from .fe import FeMesh, Samples, sample_fe
from .particles import Particles
from .sph import DEFAULT_H_ARRAYS, extract, is_sum_of_weights
from .surface import Surface


def _pyvista():
    try:
        import pyvista
    except ImportError as e:  # pragma: no cover - depends on the environment
        raise ImportError("isobar.pyvista needs pyvista: pip install pyvista") from e
    return pyvista


def _field_arrays(field: Optional[str]) -> list:
    """Array names a field expression may refer to ("p", "v:mag", "v:0", "|v|")."""
    if is_sum_of_weights(field):
        return []
    names = [field]
    if field.startswith("|") and field.endswith("|") and len(field) > 1:
        names.append(field[1:-1])
    if ":" in field:
        names.append(field.rsplit(":", 1)[0])
    return names


def particles_from_dataset(dataset, arrays: Optional[Iterable[str]] = None) -> Particles:
    """A :class:`isobar.Particles` from a pyvista (or VTK-backed) dataset's points and
    point data.

    Args:
        dataset: ``pv.PolyData`` point cloud or any ``pv.DataSet``; float32/float64
            points go to the core without a Python-side copy.
        arrays: point-data array names to pass on (default: every numeric point array).
            Names absent from the point data are ignored.
    """
    pv = _pyvista()
    if not isinstance(dataset, pv.DataSet):
        dataset = pv.wrap(dataset)
    positions = np.asarray(dataset.points)
    particles = Particles.from_arrays(positions)
    wanted = None if arrays is None else set(arrays)
    n = positions.shape[0]
    for name in dataset.point_data.keys():
        if wanted is not None and name not in wanted:
            continue
        values = np.asarray(dataset.point_data[name])
        if values.dtype.kind not in "fiub" or values.ndim == 0 or values.shape[0] != n:
            continue  # strings, objects, or not one value per point
        particles.add_array(name, values)
    return particles


def to_pyvista(surface: Surface):
    """A ``pv.PolyData`` triangle mesh of an :class:`isobar.Surface`: float64 points,
    ``Normals`` (active normals) and every attribute as point data."""
    pv = _pyvista()
    if surface.n_points == 0:
        mesh = pv.PolyData()
    else:
        mesh = pv.PolyData.from_regular_faces(surface.points, surface.triangles.astype(np.int64))
    if surface.normals is not None and surface.n_points:
        mesh.point_data["Normals"] = surface.normals
        mesh.point_data.active_normals_name = "Normals"
    for name, values in surface.attributes.items():
        if surface.n_points:
            mesh.point_data[name] = values
    return mesh


def surface_from_polydata(cloud, iso, field: Optional[str] = None, h: Optional[float] = None,
                          method: str = "correctors", **kw):
    """Extracts an isosurface of a point cloud's SPH field and returns a ``pv.PolyData``.

    Args:
        cloud: ``pv.PolyData`` (or other ``pv.DataSet``) whose points are the particles and
            whose point data holds the per-particle arrays.
        iso: isovalue or sequence of isovalues.
        field: point-data array to contour (``"NAME"``, ``"NAME:mag"``, ``"NAME:K"``), or
            None for the free surface (SumOfWeights).
        h: constant smoothing length; else ``h_array=NAME`` in `kw`, or a point array
            named ``h``, ``smoothing_length`` or ``hsml``.
        method: "correctors" (Marching Correctors, :func:`isobar.extract`) or "adaptive"
            (the crack-free 3-level surface, :func:`isobar.extract_adaptive`: one
            isovalue, far fewer triangles; its stats are the returned mesh's
            ``field_data["isobar_adaptive"]`` as a JSON string).
        **kw: any other argument of that function (kernel, grid_factor, trim,
            attributes, volume_array, max_error, backend, progress ...).

    Returns:
        ``pv.PolyData`` triangles with ``Normals`` and the surface attributes as point data.
    """
    needed = set(_field_arrays(field))
    for key in ("h_array", "volume_array", "density_array", "mass_array"):
        if kw.get(key):
            needed.add(kw[key])
    attributes = kw.get("attributes", ())
    needed.update([attributes] if isinstance(attributes, str) else attributes)
    if h is None and not kw.get("h_array"):
        needed.update(DEFAULT_H_ARRAYS)
    if method not in ("correctors", "adaptive"):
        raise InvalidArgumentError(f"method must be 'correctors' or 'adaptive', got {method!r}")
    particles = particles_from_dataset(cloud, arrays=needed)
    stats = None
    try:
        with quiet_warnings():  # issued below, from the caller's line
            if method == "adaptive":
                surface, stats = extract_adaptive(particles, iso, field=field, h=h, **kw)
            else:
                surface = extract(particles, iso, field=field, h=h, **kw)
    finally:
        particles.close()
    issue(surface.warnings, stacklevel=2)  # the line that called surface_from_polydata()
    surface.release()
    mesh = to_pyvista(surface)
    if stats is not None:
        mesh.field_data["isobar_adaptive"] = [json.dumps(stats)]
    return mesh


def _offsets(grid):
    """VTK 9's cell offsets (``cell_offsets`` in pyvista ≥ 0.45, ``offset`` before)."""
    return grid.cell_offsets if hasattr(grid, "cell_offsets") else grid.offset


def fe_mesh_from_dataset(grid, arrays: Optional[Iterable[str]] = None) -> FeMesh:
    """A :class:`isobar.FeMesh` from a ``pv.UnstructuredGrid`` of Lagrange cells (VTK types
    71, 72, 73) or of linear and quadratic tetrahedra, hexahedra, voxels and wedges (read as
    the Lagrange cells of the same functions; see :meth:`isobar.FeMesh.from_arrays`), with
    its ``HigherOrderDegrees`` cell array when present and its numeric point arrays (or
    only `arrays`). An ``ImageData``, ``RectilinearGrid``, ``StructuredGrid`` or
    ``ExplicitStructuredGrid`` is taken as the unstructured grid of its cells."""
    pv = _pyvista()
    if not isinstance(grid, pv.DataSet):
        grid = pv.wrap(grid)
    structured = (pv.ImageData, pv.RectilinearGrid, pv.StructuredGrid, pv.ExplicitStructuredGrid)
    if isinstance(grid, structured):
        grid = grid.cast_to_unstructured_grid()
    if not isinstance(grid, pv.UnstructuredGrid):
        raise TypeError(f"a finite-element mesh must be a pyvista.UnstructuredGrid, not {type(grid).__name__}")
    degrees = grid.cell_data["HigherOrderDegrees"] if "HigherOrderDegrees" in grid.cell_data else None
    mesh = FeMesh.from_arrays(grid.points, grid.celltypes, _offsets(grid), grid.cell_connectivity, degrees=degrees)
    wanted = None if arrays is None else set(arrays)
    n = grid.n_points
    for name in grid.point_data.keys():
        values = np.asarray(grid.point_data[name])
        if (wanted is None or name in wanted) and values.dtype.kind in "fiub" and values.ndim and values.shape[0] == n:
            mesh.add_array(name, values)
    return mesh


def samples_to_pyvista(samples: Samples):
    """A ``pv.PolyData`` of vertices: ``Normals`` (active normals), ``Radius`` and every
    per-sample array as point data (render as splats: ``style="points_gaussian"`` with
    ``Radius`` as the scale array)."""
    pv = _pyvista()
    cloud = pv.PolyData(samples.points) if len(samples) else pv.PolyData()
    if len(samples):
        cloud.point_data["Normals"] = samples.normals
        cloud.point_data.active_normals_name = "Normals"
        cloud.point_data["Radius"] = samples.radii
        for name, values in samples.arrays.items():
            cloud.point_data[name] = values
    return cloud


def samples_from_unstructured_grid(grid, field: str, iso: float, **kw):
    """Samples the isosurface ``field == iso`` of a ``pv.UnstructuredGrid`` (of the cells
    :func:`fe_mesh_from_dataset` reads) and
    returns the points as ``pv.PolyData`` (see :func:`samples_to_pyvista`); `kw` are the
    options of :func:`isobar.sample_fe` (spacing, rho, tolerance, levels, seed, progress)."""
    pv = _pyvista()
    if not isinstance(grid, pv.DataSet):
        grid = pv.wrap(grid)
    names = _field_arrays(field)
    if not any(n in grid.point_data for n in names):
        cell_array = next((n for n in names if n in grid.cell_data), None)
        if cell_array is not None:
            raise InvalidArgumentError(
                f"field {field!r}: {cell_array!r} is a cell array, and the isosurface needs values "
                f"at the points; grid.cell_data_to_point_data() interpolates them")
        names = None  # every point array, so the error lists them
    with quiet_warnings():  # issued below, from the caller's line
        samples = sample_fe(fe_mesh_from_dataset(grid, arrays=names), field, iso, **kw)
    issue(samples.warnings, stacklevel=2)  # the line that called samples_from_unstructured_grid()
    samples.release()
    return samples_to_pyvista(samples)


__all__ = [
    "surface_from_polydata",
    "to_pyvista",
    "particles_from_dataset",
    "fe_mesh_from_dataset",
    "samples_to_pyvista",
    "samples_from_unstructured_grid",
]
