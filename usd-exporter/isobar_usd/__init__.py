"""isobar_usd: isobar's SPH isosurfaces as USD stages (usd-core).

One UsdGeomMesh whose points, faceVertexCounts, faceVertexIndices, normals, extent,
velocities and primvars are time-sampled per frame; long sequences as one layer per frame
joined by value clips, so no process ever holds more than one frame::

    import isobar_usd
    isobar_usd.write_sequence("frames/frame_####.vtk", "fluid.usd", iso=0.6, h=0.05,
                              grid_factor=0.375, jobs=2)
    isobar_usd.write_frame(surface, "frame.usd", time=12)       # an isobar.Surface or arrays
    isobar_usd.check("fluid.usd")                               # [] when sound

High-order FE isosurfaces (point samples) become a UsdGeomPoints with widths and normals::

    isobar_usd.write_fe_samples("solution.vtu", "surface.usd", field="p", iso=0.0)

Command line: ``isobar-usd sph 'frames/frame_####.vtk' --iso 0.6 --h 0.05 -o fluid.usd``,
``isobar-usd fe solution.vtu --field p --iso 0 -o surface.usd``.
"""

from ._version import __version__


def _require_isobar():
    """Imports the isobar SPH package, refusing PyPI's unrelated 'isobar' (a music
    library that holds the same name)."""
    try:
        import isobar
    except ImportError as e:
        raise ImportError(
            "isobar_usd needs the isobar Python package of this repository: "
            "pip install ./rust-core/python (it is not the 'isobar' on PyPI)"
        ) from e
    if not (hasattr(isobar, "extract") and hasattr(isobar, "Particles") and hasattr(isobar, "ABI_VERSION")):
        raise ImportError(
            f"the 'isobar' package at {getattr(isobar, '__file__', '?')} is not isobar's SPH package "
            "(PyPI's 'isobar' is an unrelated music library); pip uninstall isobar, then "
            "pip install ./rust-core/python"
        )
    return isobar


_require_isobar()

from .check import Problem, check  # noqa: E402
from .errors import Error, FrameError, InputError, StitchError  # noqa: E402
from .frames import expand_sequence, frame_number, parse_frame_selection  # noqa: E402
from .layers import StageSettings  # noqa: E402
from .mesh import FrameMesh, to_mesh  # noqa: E402
from .points import write_fe_samples, write_points  # noqa: E402
from .sequence import (  # noqa: E402
    FrameProgress,
    FrameResult,
    SequenceResult,
    clip_path,
    clips_folder,
    request_stop,
    stitch,
    write_frame,
    write_sequence,
)

__all__ = [
    "__version__",
    "Error",
    "FrameError",
    "FrameMesh",
    "FrameProgress",
    "FrameResult",
    "InputError",
    "Problem",
    "SequenceResult",
    "StageSettings",
    "StitchError",
    "check",
    "clip_path",
    "clips_folder",
    "expand_sequence",
    "frame_number",
    "parse_frame_selection",
    "request_stop",
    "stitch",
    "to_mesh",
    "write_fe_samples",
    "write_frame",
    "write_points",
    "write_sequence",
]
