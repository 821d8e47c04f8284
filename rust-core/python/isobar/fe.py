"""Isosurfaces of high-order finite elements, sampled by a particle system.

Meshes of Lagrange hexahedra, tetrahedra and wedges (VTK types 72, 71, 73, any order, in
VTK's node order), or of VTK's linear and quadratic tetrahedra, hexahedra, voxels and wedges,
come from a .vtu file or from arrays as VTK holds them; the isosurface of
a scalar point array comes back as oriented point samples on the exact level set of the
element's own polynomial (no resampling, no tessellation)::

    import isobar
    mesh = isobar.FeMesh.read("solution.vtu")
    samples = isobar.sample_fe(mesh, "p", 0.0, spacing=0.05)
    samples.points, samples.normals, samples.radii, samples.arrays["Curvature"]
    samples.write("samples.vtp")
"""

from __future__ import annotations

import weakref
from ctypes import POINTER, byref, c_double, c_int64, c_uint8, c_uint32, sizeof
from typing import Dict, Mapping, Optional, Tuple

import numpy as np

from ._lib import FeMeshHandle, FeParams, FeStats, SamplesHandle, check, encode, lib
from .errors import InvalidArgumentError, issue
from .sph import ProgressCallback, _call
from .surface import _attributes, _copy

#: VTK cell types of the Lagrange cells the core reads.
LAGRANGE_TETRAHEDRON = 71
LAGRANGE_HEXAHEDRON = 72
LAGRANGE_WEDGE = 73


def _contiguous(values, dtype, what: str) -> np.ndarray:
    a = np.ascontiguousarray(values, dtype=dtype)
    if a.ndim == 0:
        raise InvalidArgumentError(f"{what} must be an array")
    return a


def _integers(values, dtype, what: str) -> np.ndarray:
    """`values` as a flat array of `dtype`, refusing numbers that are not whole or do not
    fit (a cast would truncate 3.5 to 3, or wrap 300 to 44, without a word)."""
    a = np.asarray(values)
    if a.ndim == 0:
        raise InvalidArgumentError(f"{what} must be an array")
    a = a.ravel()
    if a.dtype.kind not in "iub":
        if a.dtype.kind != "f":
            raise InvalidArgumentError(f"{what} must hold integers, not {a.dtype}")
        bad = np.flatnonzero(~np.isfinite(a) | (a != np.round(a)))
        if bad.size:
            raise InvalidArgumentError(f"{what}[{bad[0]}] is {a[bad[0]]}, not a whole number")
    if a.size:
        info = np.iinfo(dtype)
        lo, hi = a.min(), a.max()
        if lo < info.min or hi > info.max:
            i = int(np.argmin(a)) if lo < info.min else int(np.argmax(a))
            raise InvalidArgumentError(f"{what}[{i}] is {a[i]}, outside {info.min}..{info.max}")
    return np.ascontiguousarray(a, dtype=dtype)


class FeMesh:
    """A mesh of Lagrange cells with named per-point arrays, held by the core.

    The core checks every element when the mesh is made (a degenerate cell, one inverted
    in part, or a mirrored cell among upright ones is refused, naming it; a mesh mirrored
    as a whole is read) and builds the face adjacency the particle system walks.
    """

    __slots__ = ("_handle", "_finalizer", "__weakref__")

    def __init__(self, handle):
        self._handle = handle
        self._finalizer = weakref.finalize(self, lib.isobar_fe_mesh_free, handle)

    @classmethod
    def read(cls, path) -> "FeMesh":
        """Reads a .vtu file of Lagrange cells, or a Gmsh .msh (v4.1) with high-order
        elements and $NodeData, with its point arrays."""
        handle = POINTER(FeMeshHandle)()
        check(lib.isobar_fe_mesh_read(encode(path, "path"), byref(handle)))
        return cls(handle)

    @classmethod
    def from_arrays(
        cls,
        points,
        cell_types,
        offsets,
        connectivity,
        degrees=None,
        point_data: Optional[Mapping[str, np.ndarray]] = None,
    ) -> "FeMesh":
        """A mesh from VTK-style arrays (copied).

        Args:
            points: (n, 3) coordinates.
            cell_types: (c,) VTK cell types: Lagrange tetrahedra, hexahedra and wedges
                (71, 72, 73), or VTK's linear and quadratic cells, read as the Lagrange
                cells of the same functions: tetra (10), voxel (11), hexahedron (12),
                wedge (13), quadratic tetra (24), quadratic hexahedron (25, serendipity),
                quadratic wedge (26, serendipity), triquadratic hexahedron (29),
                quadratic-linear wedge (31), biquadratic-quadratic wedge (32).
            offsets: (c + 1,) cell c's nodes are ``connectivity[offsets[c]:offsets[c+1]]``
                (VTK 9's offsets array).
            connectivity: point indices in VTK's node order of each cell type.
            degrees: optional (c, 3) orders per cell (VTK's HigherOrderDegrees); without
                it the order follows from each cell's node count.
            point_data: name -> (n,) or (n, k) arrays.
        """
        xyz = _contiguous(points, np.float64, "points")
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise InvalidArgumentError(f"points must have shape (n, 3), not {xyz.shape}")
        types = _integers(cell_types, np.uint8, "cell_types")
        offs = _integers(offsets, np.int64, "offsets")
        conn = _integers(connectivity, np.int64, "connectivity")
        if offs.shape[0] != types.shape[0] + 1:
            raise InvalidArgumentError(f"offsets has {offs.shape[0]} entries for {types.shape[0]} cells; it needs cells + 1")
        deg_ptr = None
        if degrees is not None:
            deg = _integers(degrees, np.uint32, "degrees")
            if deg.shape[0] != 3 * types.shape[0]:
                raise InvalidArgumentError(f"degrees has {deg.shape[0]} values for {types.shape[0]} cells; it needs 3 a cell")
            deg_ptr = deg.ctypes.data_as(POINTER(c_uint32))
        handle = POINTER(FeMeshHandle)()
        check(
            lib.isobar_fe_mesh_create(
                xyz.ctypes.data_as(POINTER(c_double)),
                xyz.shape[0],
                types.ctypes.data_as(POINTER(c_uint8)),
                types.shape[0],
                offs.ctypes.data_as(POINTER(c_int64)),
                conn.ctypes.data_as(POINTER(c_int64)),
                conn.shape[0],
                deg_ptr,
                byref(handle),
            )
        )
        mesh = cls(handle)
        for name, values in (point_data or {}).items():
            mesh.add_array(name, values)
        return mesh

    def add_array(self, name: str, values) -> None:
        """Adds (or replaces) a per-point array: (n,) or (n, k) numbers."""
        a = _contiguous(values, np.float64, f"array '{name}'")
        n = a.shape[0]
        k = 1 if a.ndim == 1 else int(np.prod(a.shape[1:]))
        check(lib.isobar_fe_mesh_add_array(self._handle, encode(name, "name"), a.ctypes.data_as(POINTER(c_double)), n, k))

    def probe(self, points, field: Optional[str] = None) -> Tuple[np.ndarray, np.ndarray]:
        """The scalar point array ``field`` at arbitrary world points.

        The core finds the cell holding each point, inverts that cell's (curved) mapping
        by Newton's method and interpolates with the cell's Lagrange basis, so the value
        is the finite-element solution itself, not a linearisation.

        Args:
            points: (n, 3) world coordinates (a single (3,) point is taken as (1, 3)).
                A NaN or infinite coordinate raises :class:`InvalidArgumentError` naming
                the point's index.
            field: a scalar point array; None takes the mesh's only scalar array.

        Returns:
            ``(values, cells)``: (n,) float64 values, NaN outside the mesh, and (n,)
            int64 cell ids, -1 outside the mesh.
        """
        xyz = _contiguous(points, np.float64, "points")
        if xyz.ndim == 1 and xyz.shape[0] == 3:
            xyz = xyz.reshape(1, 3)
        if xyz.ndim != 2 or xyz.shape[1] != 3:
            raise InvalidArgumentError(f"points must have shape (n, 3), not {xyz.shape}")
        if field is None:
            scalars = [name for name, a in self.arrays.items() if a.ndim == 1]
            if len(scalars) != 1:
                raise InvalidArgumentError(
                    f"name the field to probe: the mesh has scalar point arrays {scalars or 'none'}"
                )
            field = scalars[0]
        n = xyz.shape[0]
        values = np.empty(n, dtype=np.float64)
        cells = np.empty(n, dtype=np.int64)
        check(
            lib.isobar_fe_probe(
                self._handle,
                encode(field, "field"),
                xyz.ctypes.data_as(POINTER(c_double)),
                n,
                values.ctypes.data_as(POINTER(c_double)),
                cells.ctypes.data_as(POINTER(c_int64)),
                None,
            )
        )
        return values, cells

    @property
    def arrays(self) -> Dict[str, np.ndarray]:
        """Copies of the per-point arrays: name -> (n,) or (n, k) float64."""
        return _attributes(self._handle, self.n_points, lib.isobar_fe_mesh_array_count, lib.isobar_fe_mesh_array)

    @property
    def n_points(self) -> int:
        return int(lib.isobar_fe_mesh_point_count(self._handle))

    @property
    def n_cells(self) -> int:
        """The volume cells: vertex, line and surface cells given beside them are left
        out (the cell ids in ``Element`` and :meth:`probe` still count them)."""
        return int(lib.isobar_fe_mesh_cell_count(self._handle))

    def __repr__(self) -> str:
        return f"<isobar.FeMesh {self.n_cells} cells, {self.n_points} points>"


class Samples:
    """Oriented point samples of an isosurface, in numpy arrays.

    Attributes:
        points: (n, 3) float64 world positions, each with |F - C| at most the tolerance.
        normals: (n, 3) float32 unit normals along the field's gradient.
        radii: (n,) float64 radii of the disks the points stand for (hosts draw them
            as splats or point gaussians): each reaches its sample's Voronoi cell, so
            the disks cover the surface.
        arrays: ``Element`` (cell id), ``Reference`` ((n, 3) coordinates in the cell),
            ``Curvature`` (sqrt(k1² + k2²)), ``Energy``.
        stats: particles, seeds, iterations, evaluations, splits, deletes, spacing,
            max_residual.
        warnings: what the run warned about although it succeeded (an isovalue that gave
            no sample); each was also issued as an :class:`isobar.IsobarWarning`.
    """

    __slots__ = ("points", "normals", "radii", "arrays", "stats", "warnings", "_handle", "_finalizer", "__weakref__")

    def __init__(self, handle):
        try:
            n = lib.isobar_samples_count(handle)
            self.points = _copy(lib.isobar_samples_positions(handle), 3 * n, np.float64).reshape(n, 3)
            self.normals = _copy(lib.isobar_samples_normals(handle), 3 * n, np.float32).reshape(n, 3)
            self.radii = _copy(lib.isobar_samples_radii(handle), n, np.float64)
            self.arrays: Dict[str, np.ndarray] = _attributes(
                handle, n, lib.isobar_samples_attribute_count, lib.isobar_samples_attribute
            )
            stats = FeStats()
            stats.struct_size = sizeof(FeStats)
            check(lib.isobar_samples_stats(handle, byref(stats)))
            self.stats = {f: getattr(stats, f) for f, _ in FeStats._fields_ if f != "struct_size"}
            self.warnings = lib.isobar_samples_warnings(handle).decode("utf-8", "replace").splitlines()
        except BaseException:
            lib.isobar_samples_free(handle)
            raise
        self._handle = handle
        self._finalizer = weakref.finalize(self, lib.isobar_samples_free, handle)

    def __len__(self) -> int:
        return int(self.points.shape[0])

    def write(self, path) -> None:
        """Writes a .vtp file: vertices with Normals, Radius and the arrays."""
        if self._handle is None:
            raise InvalidArgumentError("these Samples were released; write them before release()")
        check(lib.isobar_samples_write(self._handle, encode(path, "path")))

    def release(self) -> None:
        """Frees the core's copy now; the numpy arrays stay."""
        self._finalizer()
        self._handle = None

    def __repr__(self) -> str:
        return f"<isobar.Samples {len(self)} points, arrays [{', '.join(self.arrays)}]>"


def default_fe_params() -> FeParams:
    """The core's default ``IsobarFeParams`` (with ``struct_size`` set)."""
    params = FeParams()
    check(lib.isobar_fe_params_default(byref(params)))
    return params


def sample_fe(
    mesh: FeMesh,
    field: str,
    iso: float,
    spacing: float = 0.0,
    rho: float = 0.0,
    tolerance: Optional[float] = None,
    levels: Optional[int] = None,
    seed: Optional[int] = None,
    progress: Optional[ProgressCallback] = None,
) -> Samples:
    """Samples the isosurface ``field == iso`` of a high-order mesh with the particle
    system (Meyer et al. 2007): samples kept in reference space, projected to the level
    set by Newton steps, spread by a curvature-scaled repulsion.

    Args:
        field: a scalar point array of the mesh, or ``"NAME:K"`` for component K (from
            0) of a vector point array.
        spacing: distance between samples on flat parts (world units); 0 picks 1/40 of
            the bounding-box diagonal.
        rho: extra density on curved parts (0: uniform).
        tolerance: every sample has |F - iso| at most this (core default 1e-6).
        levels: coarse-to-fine levels (core default 2).
        seed: seed of the split/delete random bias (same seed, same samples).
        progress: ``progress(fraction, phase)``; returning False cancels
            (:class:`isobar.Cancelled`).
    """
    params = default_fe_params()
    params.iso = float(iso)
    params.spacing = float(spacing)
    params.rho = float(rho)
    if tolerance is not None:
        params.tolerance = float(tolerance)
    if levels is not None:
        params.levels = int(levels)
    if seed is not None:
        params.seed = int(seed)
    handle = _call(
        lambda callback, out: lib.isobar_fe_sample(
            mesh._handle, encode(field, "field"), byref(params), callback, None, byref(out)
        ),
        progress,
        POINTER(SamplesHandle)(),
        lib.isobar_samples_free,
    )
    samples = Samples(handle)
    issue(samples.warnings, stacklevel=2)  # the line that called sample_fe()
    return samples


__all__ = ["FeMesh", "Samples", "sample_fe", "default_fe_params"]
