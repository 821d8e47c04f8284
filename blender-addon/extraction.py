"""Particles in, a mesh ready for Blender out: the isobar call and the attribute naming.

No bpy here: :class:`Params` is read from the add-on's settings (or built directly), the
particles come from a file or from arrays, and :func:`extract` returns a :class:`FrameMesh`
of float32/int32 numpy arrays with Blender attribute names, which ``mesh.py`` writes into a
mesh and ``cache.py`` stores on disk.
"""

from __future__ import annotations

import json
import re
from dataclasses import asdict, dataclass, field
from typing import Callable, Dict, List, Optional, Tuple

import numpy as np

#: Prefix of the mesh attributes holding SPH quantities: Cycles treats some plain names
#: ('density', 'temperature', 'flame', 'heat', 'velocity' on volumes) as its own.
PREFIX = "sph_"

#: Name of the vertex velocity attribute Cycles uses for motion blur.
VELOCITY_ATTRIBUTE = "velocity"

#: Particle arrays never interpolated onto the surface (identifiers, not quantities).
ID_LIKE = frozenset({"id", "ids", "index", "idx", "particle_id", "particleid", "object_id", "objectid"})

#: Names taken as the particle velocity when present with 3 components, in this order.
VELOCITY_NAMES = ("velocity", "velocities", "vel", "v", "Velocity", "V")

#: Names taken as per-particle smoothing lengths (as isobar does).
H_NAMES = ("h", "smoothing_length", "hsml")

ProgressFn = Callable[[float, str], Optional[bool]]


def isobar_module():
    """The isobar package (imported on first use, so that the add-on registers and can
    report the problem when the bundled library cannot load)."""
    import isobar  # late: the add-on registers even when it fails

    return isobar


def auto_backend_note(backend: str) -> str:
    """Why Backend `backend` runs on the CPU: the core's reason (the text the CLI prints
    after "backend auto: running on the CPU (") for AUTO without a hardware GPU, else ""."""
    if backend.upper() != "AUTO":
        return ""
    return isobar_module().auto_backend_note() or ""


def _decimal(value):
    """Blender stores float properties in single precision: 0.05 comes back as
    0.05000000074505806. Return the shortest decimal that float32 value stands for (0.05),
    which is what the user typed."""
    if isinstance(value, float):
        return float(str(np.float32(value)))
    return value


@dataclass
class Params:
    """Extraction parameters (the add-on's settings, without the UI)."""

    field: str = "SumOfWeights"
    iso: float = 0.6
    kernel: str = "cubic"
    h_mode: str = "CONSTANT"  # or "ARRAY"
    h: float = 0.05
    h_array: str = "h"
    h_scale: float = 1.0
    grid_factor: float = 0.5
    method: str = "CORRECTORS"  # or "ADAPTIVE"
    splash_threshold: int = 0  # the core's adaptive default (the paper's rule is 1)
    max_error: float = 0.4  # the core's adaptive default (isobar.adaptive.default_params())
    bisection_iterations: int = 5  # the core's adaptive default, as max_error's
    backend: str = "CPU"  # CPU, GPU (wgpu) or AUTO (a hardware GPU when there is one); both methods
    correct: bool = True
    trim: str = "AUTO"  # AUTO, OFF, ON, CUSTOM
    trim_node: float = 0.1
    trim_vertex: float = 0.5
    attributes: str = "*"  # '*' for every particle array, else names separated by commas
    speed: bool = True
    velocity_array: str = "velocity"
    motion_blur: bool = True
    velocity_scale: float = 1.0
    normals: bool = True

    @classmethod
    def from_settings(cls, settings) -> "Params":
        """Reads an ``IsobarSettings`` property group (or anything with those names)."""
        values = {}
        for name in cls.__dataclass_fields__:
            if hasattr(settings, name):
                values[name] = _decimal(getattr(settings, name))
        return cls(**values)

    def fingerprint(self, source: str = "") -> str:
        """A stable text identifying the surface these parameters make from `source`
        (stored with baked frames: a cached frame is used only while it matches)."""
        data = asdict(self)
        for key, value in data.items():
            if isinstance(value, float):
                data[key] = repr(value)
        data["source"] = source
        # What the core makes of the same parameters changes between releases (the
        # adaptive surface gained the particle arrays, Marching Correctors empty
        # cavities): frames baked by another release are made again.
        try:
            data["isobar"] = isobar_module().__version__ + SURFACE_REVISION
        except Exception:  # the library cannot load: nothing is extracted either
            data["isobar"] = "unavailable" + SURFACE_REVISION
        return json.dumps(data, sort_keys=True)


#: Raised when the surfaces made from unchanged parameters change within one version of
#: the isobar package (baked frames must then be made again).
SURFACE_REVISION = "+s35"


@dataclass
class FrameMesh:
    """One frame's surface for Blender: float32 points and normals, int32 triangles, and
    point attributes by their Blender names."""

    points: np.ndarray  # (n, 3) float32
    triangles: np.ndarray  # (m, 3) int32
    normals: Optional[np.ndarray] = None  # (n, 3) float32
    attributes: Dict[str, np.ndarray] = field(default_factory=dict)  # (n,) or (n, k) float32
    info: Dict[str, object] = field(default_factory=dict)
    #: What the extraction warned about although it succeeded (isobar's Surface.warnings:
    #: an isovalue the field never crosses, a kernel wider than the particles).
    warnings: List[str] = field(default_factory=list)

    @property
    def n_points(self) -> int:
        return int(self.points.shape[0])

    @property
    def n_triangles(self) -> int:
        return int(self.triangles.shape[0])


def blender_name(name: str) -> str:
    """Mesh attribute name for an SPH quantity: 'sph_' + the name, characters other than
    letters, digits and '_' replaced by '_' (at most 63 bytes, Blender's limit)."""
    clean = re.sub(r"[^0-9A-Za-z_]", "_", name) or "value"
    return (PREFIX + clean)[:63]


def velocity_name(names: List[Tuple[str, int]], preferred: str = "") -> str:
    """The particle velocity array: `preferred` when present with 3 components, else the
    first of :data:`VELOCITY_NAMES` that is; '' when there is none.

    Raises:
        ValueError: `preferred` is a name the user chose (not one of VELOCITY_NAMES, which
            the import sets whether or not the file has a velocity) and the particles have
            no such 3-component array: another array must not stand in for it silently.
    """
    components = dict(names)
    if preferred and components.get(preferred) == 3:
        return preferred
    if preferred and preferred not in VELOCITY_NAMES:
        if preferred in components:
            raise ValueError(f"velocity array '{preferred}' has {components[preferred]} "
                             f"components; a velocity needs 3")
        vectors = ", ".join(n for n, k in names if k == 3) or "none"
        raise ValueError(f"no velocity array named '{preferred}' (3-component arrays: {vectors})")
    for candidate in VELOCITY_NAMES:
        if components.get(candidate) == 3:
            return candidate
    return ""


def h_array_name(names) -> str:
    """The first smoothing-length array among `names`, or ''."""
    present = set(names)
    return next((n for n in H_NAMES if n in present), "")


def _selected_arrays(params: Params, names: List[Tuple[str, int]], velocity: str) -> List[str]:
    """Particle arrays to interpolate onto the surface."""
    spec = (params.attributes or "").strip()
    if spec in ("", "*"):
        skip = set(ID_LIKE)
        if params.h_mode == "ARRAY" and params.h_array:
            skip.add(params.h_array)
        chosen = [n for n, _ in names if n.lower() not in skip and n not in skip]
    elif spec.lower() == "none":
        chosen = []
    else:
        chosen = [s.strip() for s in re.split(r"[,;\s]+", spec) if s.strip()]
    if velocity and params.motion_blur and velocity not in chosen:
        chosen.append(velocity)
    return chosen


#: Scalar component triples that make a velocity (PLY files store vx, vy, vz).
VELOCITY_COMPONENTS = (("vx", "vy", "vz"), ("velocity_x", "velocity_y", "velocity_z"), ("v_x", "v_y", "v_z"))


def _join_velocity_components(particles, names: List[Tuple[str, int]]) -> str:
    """Adds a 'velocity' array from scalar component arrays (vx, vy, vz) when the
    particles have those and no velocity array; returns its name or ''."""
    scalars = {n for n, k in names if k == 1}
    if "velocity" in dict(names):
        return ""
    for triple in VELOCITY_COMPONENTS:
        if all(c in scalars for c in triple):
            particles.add_array("velocity", np.stack([particles.array(c) for c in triple], axis=1))
            return "velocity"
    return ""


def _isobar_kwargs(params: Params) -> dict:
    isobar = isobar_module()
    kwargs = dict(
        iso=float(params.iso),
        field=None if isobar.sph.is_sum_of_weights(params.field) else params.field,
        kernel=params.kernel.lower(),
        h_scale=float(params.h_scale),
        grid_factor=float(params.grid_factor),
        correct=bool(params.correct),
        normals=bool(params.normals),
        backend=params.backend.lower(),
    )
    if params.h_mode == "ARRAY":
        kwargs["h_array"] = params.h_array
    else:
        kwargs["h"] = float(params.h)
    trim = params.trim.upper()
    if trim == "AUTO":
        kwargs["trim"] = "auto"
    elif trim == "OFF":
        kwargs["trim"] = None
    elif trim == "ON":
        kwargs["trim"] = True
    else:
        kwargs["trim"] = (float(params.trim_node), float(params.trim_vertex))
    return kwargs


def array_infos(particles) -> List[Tuple[str, int]]:
    """(name, components) of the particle arrays."""
    return [(str(n), int(k)) for n, k in particles.infos()]


def extract(particles, params: Params, progress: Optional[ProgressFn] = None) -> FrameMesh:
    """Extracts the surface of `particles` (an ``isobar.Particles``) with `params`.

    Adds a 'speed' array (|velocity|) to the particles when asked and possible, so that
    the speed is SPH-interpolated like every other quantity. What the extraction warns
    about is in the FrameMesh's ``warnings`` and nowhere else: the operators report them,
    the panel and the console show them, so Python's copy would print each twice.

    Raises:
        isobar.Error: the core refused the data or the parameters (its message names the
            array, file or parameter), isobar.Cancelled when `progress` returned False.
    """
    with isobar_module().quiet_warnings():
        return _extract(particles, params, progress)


def _extract(particles, params: Params, progress: Optional[ProgressFn]) -> FrameMesh:
    """Either method's surface with the particle arrays interpolated onto its vertices and
    the velocity as motion blur: Marching Correctors (vertices on the level set) or the
    adaptive 3-level grid (vertices by bisection on its own grids)."""
    isobar = isobar_module()
    names = array_infos(particles)
    velocity = velocity_name(names, params.velocity_array)
    if not velocity:
        velocity = _join_velocity_components(particles, names)
        if velocity:
            names = array_infos(particles)
    arrays = _selected_arrays(params, names, velocity)
    if params.speed and velocity and "speed" not in dict(names):
        particles.add_array("speed", np.linalg.norm(particles.array(velocity), axis=1))
        if "speed" not in arrays:
            arrays.append("speed")
    kwargs = _isobar_kwargs(params)
    if params.method == "ADAPTIVE":
        for correctors_only in ("correct", "trim"):
            kwargs.pop(correctors_only)
        surface, _stats = isobar.extract_adaptive(
            particles,
            progress=progress,
            attributes=arrays,
            splash_threshold=int(params.splash_threshold),
            max_error=float(params.max_error),
            bisection_iterations=int(params.bisection_iterations),
            **kwargs,
        )
    else:
        surface = isobar.extract(particles, progress=progress, attributes=arrays, **kwargs)
    try:
        mesh = frame_mesh_from_surface(surface, velocity if params.motion_blur else "", params.velocity_scale)
    finally:
        surface.release()
    if (params.attributes or "").strip().lower() == "none":
        # Marching Correctors gives every vertex its sum of weights; "none" asks for no
        # sph_* array.
        mesh.attributes.pop(blender_name("SumOfWeights"), None)
    return mesh


def frame_mesh_from_surface(surface, velocity: str = "", velocity_scale: float = 1.0) -> FrameMesh:
    """Converts an ``isobar.Surface``: float32 positions and normals, int32 triangles,
    attributes renamed for Blender (the velocity array to 'velocity', scaled), its
    warnings."""
    n = surface.points.shape[0]
    attributes: Dict[str, np.ndarray] = {}
    for name, values in surface.attributes.items():
        if name == "Isovalue":
            continue  # constant for one isovalue
        values = np.asarray(values, dtype=np.float32)
        if velocity and name == velocity and values.ndim == 2 and values.shape[1] == 3:
            attributes[VELOCITY_ATTRIBUTE] = values * np.float32(velocity_scale)
            continue
        attributes[blender_name(name)] = values  # (n,) or (n, k) already
    normals = None if surface.normals is None else np.ascontiguousarray(surface.normals, dtype=np.float32)
    stats = surface.stats or {}
    info = {
        "vertices": int(n),
        "triangles": int(surface.triangles.shape[0]),
        "seconds": float(stats.get("seconds_total", 0.0)),
    }
    return FrameMesh(
        points=np.ascontiguousarray(surface.points, dtype=np.float32),
        triangles=np.ascontiguousarray(surface.triangles, dtype=np.int32),
        normals=normals,
        attributes=attributes,
        info=info,
        warnings=list(surface.warnings),
    )


__all__ = [
    "FrameMesh",
    "H_NAMES",
    "ID_LIKE",
    "PREFIX",
    "Params",
    "VELOCITY_ATTRIBUTE",
    "VELOCITY_NAMES",
    "array_infos",
    "auto_backend_note",
    "blender_name",
    "extract",
    "frame_mesh_from_surface",
    "h_array_name",
    "isobar_module",
    "velocity_name",
]
