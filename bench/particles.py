"""Reads particle positions from the formats the benchmark accepts.

The benchmark reads the input once here, writes the positions to one float64 .npy file and
hands that file to every method, so all of them see bit-identical particles and pay the
same (small) reading cost.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

# Names tried, in order, for the position array of an .npz file.
POSITION_KEYS = ("positions", "position", "pos", "x", "points")


def load_positions(path: str | Path) -> np.ndarray:
    """Returns the particle positions of `path` as a C-ordered (N, 3) float64 array."""
    path = Path(path)
    suffix = path.suffix.lower()
    readers = {
        ".npz": _read_npz,
        ".npy": _read_npy,
        ".csv": _read_text,
        ".xyz": _read_text,
        ".bgeo": _read_bgeo,
        ".vtk": _read_vtk,
        ".vtu": _read_vtk,
        ".vtp": _read_vtk,
        ".ply": _read_vtk,
    }
    if suffix not in readers:
        raise ValueError(f"{path}: unsupported particle format {suffix!r}")
    points = np.ascontiguousarray(readers[suffix](path), dtype=np.float64)
    if points.ndim != 2 or points.shape[1] != 3:
        raise ValueError(
            f"{path}: positions have shape {points.shape}, expected (N, 3)"
        )
    return points


def radius_from_h(path: str | Path) -> float:
    """r = h/2 from a uniform per-particle 'h' array of an .npz (the demo frame's layout)."""
    path = Path(path)
    if path.suffix.lower() != ".npz":
        raise ValueError(
            f"{path}: give --radius (only .npz files carry an 'h' array here)"
        )
    with np.load(path) as data:
        if "h" not in data:
            raise ValueError(f"{path}: no 'h' array; give --radius")
        h = data["h"].astype(np.float64)
    if h.max() > h.min() * (1.0 + 1e-6):
        raise ValueError(f"{path}: h varies ({h.min()} .. {h.max()}); give --radius")
    return float(h[0]) / 2.0


def _read_npz(path: Path) -> np.ndarray:
    with np.load(path) as data:
        for key in POSITION_KEYS:
            if key in data:
                return data[key]
        for key in data.files:
            if data[key].ndim == 2 and data[key].shape[1] == 3:
                return data[key]
    raise ValueError(f"{path}: no (N, 3) position array among {data.files}")


def _read_npy(path: Path) -> np.ndarray:
    return np.load(path)


def _read_text(path: Path) -> np.ndarray:
    # The first three numeric columns are the position; a header line is skipped.
    first = path.read_text().splitlines()[0]
    skip = 0 if _is_numeric_row(first) else 1
    delimiter = "," if "," in first else None
    return np.loadtxt(
        path, delimiter=delimiter, skiprows=skip, usecols=(0, 1, 2), ndmin=2
    )


def _is_numeric_row(line: str) -> bool:
    try:
        [float(v) for v in line.replace(",", " ").split()]
    except ValueError:
        return False
    return True


def _read_bgeo(path: Path) -> np.ndarray:
    # pysplashsurf ships the BGEO reader of the splashsurf authors (needs meshio).
    from pysplashsurf.bgeo import readbgeo_to_meshio

    return readbgeo_to_meshio(str(path)).points


def _read_vtk(path: Path) -> np.ndarray:
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOLegacy import vtkGenericDataObjectReader
    from vtkmodules.vtkIOPLY import vtkPLYReader
    from vtkmodules.vtkIOXML import vtkXMLGenericDataObjectReader

    suffix = path.suffix.lower()
    if suffix == ".vtk":
        reader = vtkGenericDataObjectReader()
    elif suffix == ".ply":
        reader = vtkPLYReader()
    else:
        reader = vtkXMLGenericDataObjectReader()
    reader.SetFileName(str(path))
    reader.Update()
    return vtk_to_numpy(reader.GetOutputDataObject(0).GetPoints().GetData())
