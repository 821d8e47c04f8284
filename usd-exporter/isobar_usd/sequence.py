"""Frames and sequences: extraction (through the isobar package), one layer per frame,
value clips joining them, parallel writers, atomic commits."""

from __future__ import annotations

import inspect
import json
import multiprocessing
import os
import re
import signal
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Dict, Iterable, Iterator, List, Mapping, Optional, Tuple, Union

import numpy as np

from . import _atomic
from .errors import Error, FrameError, InputError, StitchError, frame_error
from .frames import expand_sequence, frame_number, is_pattern, parse_frame_selection
from .layers import (
    MeshLayer,
    StageSettings,
    check_output_path,
    check_writable_folder,
    merge_schema,
    mixed_settings,
    read_record,
    write_clips_root,
    write_manifest,
)
from .mesh import CORE_ATTRIBUTES, VELOCITY_ARRAY, FrameMesh, SchemaEntry, to_mesh

#: File name of the clip manifest inside a sequence's clips folder.
MANIFEST = "manifest.usda"
_LOCK = ".lock"

PathLike = Union[str, "os.PathLike[str]"]


# -- where things go ------------------------------------------------------------------


def clips_folder(output: PathLike) -> Path:
    """The folder holding a sequence's frame layers: ``fluid.usd`` -> ``fluid.clips/``."""
    output = Path(output)
    return output.with_name(output.stem + ".clips")


def _frame_text(frame: int) -> str:
    return f"-{abs(frame):04d}" if frame < 0 else f"{frame:04d}"


def clip_path(output: PathLike, frame: int) -> Path:
    """The frame layer of `frame` in the sequence `output`:
    ``fluid.usd``, 12 -> ``fluid.clips/fluid.0012.usdc``."""
    output = Path(output)
    return clips_folder(output) / f"{output.stem}.{_frame_text(int(frame))}.usdc"


def _committed_clips(output: Path) -> Dict[int, Path]:
    """Frame number -> frame layer, for the layers in the clips folder."""
    folder = clips_folder(output)
    pattern = re.compile(rf"^{re.escape(output.stem)}\.(-?[0-9]+)\.usdc$")
    found: Dict[int, Path] = {}
    try:
        names = os.listdir(folder)
    except FileNotFoundError:
        return found
    for name in names:
        match = pattern.match(name)
        if match:
            frame = int(match.group(1))
            if frame in found:  # fluid.0012 and fluid.012: keep the canonical name
                if found[frame].name != clip_path(output, frame).name:
                    found[frame] = folder / name
                continue
            found[frame] = folder / name
    return found


# -- stopping ------------------------------------------------------------------------

_STOP = threading.Event()


def request_stop() -> None:
    """Asks a running write to stop as soon as it can (safe to call from a signal
    handler): the extraction in progress is cancelled through the core's progress
    callback, the frame being written is finished, then KeyboardInterrupt unwinds the write
    (staged files removed, the previous stage intact). The command line calls this on
    SIGTERM and on the first Ctrl-C. A request made while no write runs stops the next."""
    _STOP.set()


def _check_stop() -> None:
    if _STOP.is_set():
        _STOP.clear()  # one request stops one write
        raise KeyboardInterrupt


# -- extraction options ---------------------------------------------------------------


#: Extraction methods: Marching Correctors (vertices on the level set, trimming) or the
#: adaptive 3-level grid (crack-free, far fewer triangles, one isovalue); both carry arrays.
METHODS = ("correctors", "adaptive")


def _signature(function, skip=("particles", "iso", "progress")) -> List[str]:
    return [p for p in inspect.signature(function).parameters if p not in skip]


def _extract_parameters() -> List[str]:
    import isobar

    adaptive_only = [p for p in _signature(isobar.extract_adaptive) if p not in _signature(isobar.extract)]
    return ["method"] + _signature(isobar.extract) + adaptive_only


def extraction_defaults(method: str) -> Dict[str, Any]:
    """The options `method` ("correctors" or "adaptive") takes when not given, as a
    frame record's ``extraction`` holds them (JSON), so that a frame written with a
    default left out compares equal to one that spelled it."""
    import isobar

    function = isobar.extract_adaptive if method == "adaptive" else isobar.extract
    defaults = {
        name: p.default
        for name, p in inspect.signature(function).parameters.items()
        if name in _signature(function) and p.default is not inspect.Parameter.empty
    }
    defaults["method"] = method
    return json.loads(json.dumps(defaults, default=str))


def check_extract_options(options: Mapping[str, Any]) -> Dict[str, Any]:
    """The options for :func:`isobar.extract` (or, with ``method="adaptive"``,
    :func:`isobar.extract_adaptive`); unknown names raise InputError."""
    allowed = _extract_parameters()
    unknown = [k for k in options if k not in allowed]
    if unknown:
        raise InputError(
            f"unknown extraction option{'s' if len(unknown) > 1 else ''} {', '.join(unknown)} "
            f"(isobar.extract takes {', '.join(allowed)})"
        )
    method = options.get("method", "correctors")
    if method not in METHODS:
        raise InputError(f"unknown extraction method '{method}' (methods: {', '.join(METHODS)})")
    out = dict(options)
    attributes = out.get("attributes")
    if isinstance(attributes, (str, bytes)):
        out["attributes"] = [attributes]
    elif attributes is not None:
        out["attributes"] = list(attributes)
    return out


@dataclass
class Job:
    """Everything a process needs to turn one frame into one layer (picklable)."""

    iso: Optional[List[float]]
    options: Dict[str, Any]
    velocities: Union[str, None]
    primvars: Union[str, None, List[str]]
    settings: StageSettings

    def describe(self) -> str:
        return json.dumps({"iso": self.iso, **self.options}, default=str, sort_keys=True)


def _isovalues(iso) -> Optional[List[float]]:
    if iso is None:
        return None
    if isinstance(iso, str):
        try:
            return [float(v) for v in iso.split(",") if v.strip()]
        except ValueError:
            raise InputError(f"iso must be numbers, got '{iso}'") from None
    try:
        values = [float(v) for v in (iso if isinstance(iso, (list, tuple)) else np.atleast_1d(iso).ravel())]
    except (TypeError, ValueError):
        raise InputError(f"iso must be a number or a sequence of numbers, got {iso!r}") from None
    if not values:
        raise InputError("iso: give at least one isovalue")
    return values


def _velocity_option(velocities):
    if velocities is None or velocities is False:
        return None
    if velocities is True:
        return "auto"
    if isinstance(velocities, str):
        if velocities:
            return velocities
    elif hasattr(velocities, "__len__"):
        return velocities  # an (n, 3) array, for one in-memory frame
    raise InputError(f"velocities must be 'auto', an array name, an (n, 3) array or None, got {velocities!r}")


def _primvar_option(primvars) -> Union[str, None, List[str]]:
    if primvars is None or (isinstance(primvars, str) and primvars == "auto"):
        return primvars
    if isinstance(primvars, str):
        return [primvars]
    return list(primvars)


def make_job(iso, extract_options, velocities, primvars, settings: StageSettings) -> Job:
    if extract_options.get("h") is not None and extract_options.get("h_array") is not None:
        raise InputError("give either h or h_array, not both")
    return Job(
        iso=_isovalues(iso),
        options=check_extract_options(extract_options),
        velocities=_velocity_option(velocities),
        primvars=_primvar_option(primvars),
        settings=settings,
    )


# -- one frame ------------------------------------------------------------------------


def _is_path(item) -> bool:
    return isinstance(item, (str, os.PathLike))


def _label(item) -> str:
    if _is_path(item):
        return os.fspath(item)
    name = type(item).__name__
    return f"in-memory {name}"


def extract_file(path: PathLike, job: Job) -> FrameMesh:
    """Reads a particle file, extracts the isosurface, converts it for USD."""
    import isobar

    path = os.fspath(path)
    if job.iso is None:
        raise InputError("iso is needed to extract a surface from particle files")
    if not os.path.exists(path):
        raise InputError(f"no such particle file: {path}")
    if not os.path.isfile(path):
        raise InputError(f"not a file: {path}")
    particles = isobar.Particles.read(path)
    try:
        infos = dict(particles.infos())
        options = dict(job.options)
        attributes = list(options.pop("attributes", None) or [])
        velocity = None
        if job.velocities is not None and not isinstance(job.velocities, str):
            raise InputError("a velocities array applies to in-memory surfaces, not to particle files")
        if job.velocities == "auto":
            velocity = VELOCITY_ARRAY if infos.get(VELOCITY_ARRAY) == 3 else None
        elif job.velocities is not None:
            if job.velocities not in infos and len(particles) == 0:
                pass  # an empty file need not declare it (VTK writes no point data)
            elif job.velocities not in infos:
                raise InputError(
                    f"no particle array '{job.velocities}' for velocities "
                    f"(arrays: {', '.join(infos) or 'none'})"
                )
            elif infos[job.velocities] != 3:
                raise InputError(
                    f"particle array '{job.velocities}' has {infos[job.velocities]} components; "
                    "velocities need 3"
                )
            velocity = job.velocities
        if job.primvars == "auto":
            primvars = list(attributes) + (["Isovalue"] if len(job.iso) > 1 else [])
        elif job.primvars is None:
            primvars = []
        else:
            primvars = list(job.primvars)
        wanted = list(attributes)
        for name in primvars + ([velocity] if velocity else []):
            if name not in wanted and name not in CORE_ATTRIBUTES:
                wanted.append(name)
        if len(particles) == 0:
            # An emitter before its first particle, or a fluid that has drained: an
            # empty frame, as ParaView's filter and the Blender add-on give. The core
            # refuses empty data, so that a whole empty input is an error there.
            surface = _empty_surface(path, infos, wanted + primvars + [velocity] if velocity else wanted + primvars, options)
            present = surface["attributes"]
            return to_mesh(
                surface,
                primvars=[name for name in primvars if name in present],
                velocities=velocity if velocity in present else None,
            )
        keep_going = lambda _f, _p: not _STOP.is_set()  # noqa: E731
        try:
            # The warnings travel in FrameMesh.warnings (the results, the progress reports,
            # across worker processes): Python's copy would print each again, per worker.
            with isobar.quiet_warnings():
                if options.pop("method", "correctors") == "adaptive":
                    surface = _extract_adaptive(particles, job, options, wanted, velocity, keep_going)
                else:
                    surface = isobar.extract(particles, job.iso, attributes=wanted, progress=keep_going, **options)
        except isobar.Cancelled:
            _check_stop()
            raise
    finally:
        particles.close()
    try:
        return to_mesh(surface, primvars=primvars, velocities=velocity)
    finally:
        surface.release()


def _empty_surface(path: str, infos: Mapping[str, int], names: List[str], options: Mapping[str, Any]) -> Dict[str, Any]:
    """The surface of a file with 0 particles, shaped as an extraction would give it: the
    arrays `names` asks for, with no rows (the core's own, SumOfWeights and Isovalue,
    one component each). An array the file does not declare is left out, not refused:
    VTK writes no point data for 0 points, and the sequence's other frames declare it
    (a primvar a frame lacks is allowed; one whose type differs is not)."""
    components = {**{name: 1 for name in CORE_ATTRIBUTES}, **infos}
    attributes = {
        name: np.zeros((0, components[name]) if components[name] > 1 else 0, dtype=np.float32)
        for name in dict.fromkeys(names)
        if name in components
    }
    return {
        "points": np.zeros((0, 3), np.float32),
        "triangles": np.zeros((0, 3), np.int32),
        "normals": np.zeros((0, 3), np.float32) if options.get("normals", True) else None,
        "attributes": attributes,
        "warnings": [f"{os.path.basename(path)} holds 0 particles: an empty surface"],
    }


def _extract_adaptive(particles, job: Job, options: Dict[str, Any], wanted, velocity, progress):
    """The adaptive 3-level surface: one isovalue, the SPH field options and the particle
    arrays to carry (it places vertices by bisection on its own grids)."""
    import isobar

    if len(job.iso) != 1:
        raise InputError(f"the adaptive method extracts one isovalue at a time, got {len(job.iso)}")
    if not options.get("correct", True) or options.get("full_grid", False):
        raise InputError("preview and full-grid apply to method 'correctors', not 'adaptive'")
    if options.get("trim", "auto") not in ("auto", None, False):
        raise InputError("trimming applies to method 'correctors', not 'adaptive'")
    accepted = set(_signature(isobar.extract_adaptive))
    chosen = {k: v for k, v in options.items() if k in accepted and v is not None}
    surface, _stats = isobar.extract_adaptive(
        particles, job.iso[0], progress=progress, attributes=wanted, **chosen
    )
    return surface


def produce(item, job: Job) -> FrameMesh:
    """A FrameMesh from a particle file (extracting it) or an in-memory surface, with
    what the extraction warned about."""
    if _is_path(item):
        return extract_file(item, job)
    return to_mesh(item, primvars=job.primvars if job.primvars is not None else (), velocities=job.velocities)


def auto_backend_note(options: Mapping[str, Any]) -> str:
    """Why the extraction `options` ask for (backend "auto", given or the method's
    default) run on the CPU here: the core's reason, the text the isobar CLI prints after
    "backend auto: running on the CPU ("; "" when another backend is asked for or Auto
    picks a GPU."""
    import isobar

    fn = isobar.extract_adaptive if options.get("method") == "adaptive" else isobar.extract
    backend = options.get("backend", inspect.signature(fn).parameters["backend"].default)
    return (isobar.auto_backend_note() or "") if backend == "auto" else ""


def _frame_info(item, job: Job, mesh: FrameMesh) -> Dict[str, Any]:
    info: Dict[str, Any] = {"source": _label(item), "points": mesh.n_points, "triangles": mesh.n_triangles}
    if _is_path(item):
        info["extraction"] = job.describe()
        note = auto_backend_note(job.options)
        if note:
            info["backendNote"] = note
    return info


def write_clip(frame: int, item, staged: PathLike, job: Job) -> Dict[str, Any]:
    """Extracts/converts one frame and writes its layer to `staged` (not atomically:
    `staged` is itself a staging file). Returns a summary."""
    t0 = time.perf_counter()
    mesh = produce(item, job)
    info = _frame_info(item, job, mesh)
    layer = MeshLayer(job.settings, info)
    found = mesh.warnings
    try:
        layer.add(mesh, frame)
        del mesh
        layer.export(Path(staged), atomic=False)
    finally:
        layer.release()
    # For the caller (from a worker process too), not the layer's record.
    info["seconds"] = time.perf_counter() - t0
    info["warnings"] = found
    return info


def _worker_init(jobs: int) -> None:
    # Ctrl-C reaches the whole process group: the parent stops the pool, workers must not
    # die half way through a task on their own (the pool would wait for it forever).
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    # Each worker extracts with the core's threads (rayon); share the cores between them.
    if "RAYON_NUM_THREADS" not in os.environ and jobs > 1:
        os.environ["RAYON_NUM_THREADS"] = str(max(1, (os.cpu_count() or 1) // jobs))


def _pool_task(task):
    frame, item, staged, job = task
    try:
        return frame, write_clip(frame, item, staged, job), None
    except Exception as e:  # noqa: BLE001 - sent back to the parent, which raises it
        _atomic.discard(Path(staged))
        try:
            import pickle

            pickle.loads(pickle.dumps(e))
            return frame, None, e
        except Exception:  # noqa: BLE001
            return frame, None, Error(f"{type(e).__name__}: {e}")


# -- frame sources --------------------------------------------------------------------


@dataclass
class FrameEntry:
    number: int
    item: Any
    #: What the sequence lacks just before this frame ("frames 4, 5 missing: ..."), said
    #: with this frame's warnings.
    gap: Optional[str] = None


def _frame_entries(source) -> Tuple[Iterator[FrameEntry], Optional[int], str]:
    """(entries, count or None, description) for a pattern, a list of files, a mapping
    frame -> item or an iterable of (frame, item) pairs."""
    if _is_path(source):
        text = os.fspath(source)
        if not text:
            raise InputError("empty frame pattern")
        if not is_pattern(text) and not os.path.exists(text):
            raise InputError(f"no such particle file: {text}")
        paths = expand_sequence(text)
        numbers = [frame_number(p) for p in paths]
        if len(paths) == 1 and numbers[0] is None:
            numbers = [0]
        return _numbered(paths, numbers, text), len(paths), text
    if isinstance(source, Mapping):
        entries = [FrameEntry(_as_frame(k), v) for k, v in source.items()]
        _no_duplicates(e.number for e in entries)
        entries.sort(key=lambda e: e.number)
        return iter(entries), len(entries), f"{len(entries)} frames"
    if isinstance(source, (list, tuple)) and all(_is_path(p) for p in source):
        if not source:
            raise InputError("no frames given (an empty list)")
        missing = [os.fspath(p) for p in source if not os.path.isfile(p)]
        if missing:
            more = f" (and {len(missing) - 1} more)" if len(missing) > 1 else ""
            raise InputError(f"no such particle file: {missing[0]}{more}")
        numbers = [frame_number(p) for p in source]
        return _numbered(list(source), numbers, "file list"), len(source), f"{len(source)} files"
    if isinstance(source, (str, bytes)) or not isinstance(source, Iterable):
        raise InputError(
            f"frames must be a pattern, a list of files, a mapping frame -> surface or (frame, surface) pairs, "
            f"got {type(source).__name__}"
        )
    count = len(source) if hasattr(source, "__len__") else None

    def pairs():
        for pair in source:
            if not (isinstance(pair, tuple) and len(pair) == 2):
                raise InputError("an iterable of frames must yield (frame number, surface or file) pairs")
            yield FrameEntry(_as_frame(pair[0]), pair[1])

    return pairs(), count, "frames"


def _as_frame(value) -> int:
    if isinstance(value, bool):
        raise InputError(f"frame number must be an integer, got {value!r}")
    try:
        number = int(value)
    except (TypeError, ValueError):
        raise InputError(f"frame number must be an integer, got {value!r}") from None
    if number != value:
        raise InputError(f"frame number must be an integer, got {value!r}")
    return number


def _no_duplicates(numbers: Iterable[int]) -> None:
    seen = set()
    for n in numbers:
        if n in seen:
            raise InputError(f"frame {n} is given twice")
        seen.add(n)


def _numbered(paths, numbers, what) -> Iterator[FrameEntry]:
    if any(n is None for n in numbers) or len(set(numbers)) != len(numbers):
        if len(paths) > 1 and all(n is not None for n in numbers):
            counts: Dict[int, List[str]] = {}
            for p, n in zip(paths, numbers):
                counts.setdefault(n, []).append(os.fspath(p))
            dup = next((n, ps) for n, ps in counts.items() if len(ps) > 1)
            raise InputError(f"{what}: files {' and '.join(dup[1])} both have frame number {dup[0]}")
        numbers = list(range(len(paths)))  # names without numbers: their order
        return iter([FrameEntry(n, p) for n, p in zip(numbers, paths)])
    gaps = _gaps(numbers)
    return iter([FrameEntry(n, p, gaps.get(n)) for n, p in zip(numbers, paths)])


def _gaps(numbers: List[int]) -> Dict[int, str]:
    """frame -> what is missing just before it, at the sequence's stride (its smallest
    step; 0, 10, 20, 50 lacks 30 and 40), as the isobar CLI reports gaps: a hole left by
    a failed solver step is not passed over in silence. Irregular steps have no stride."""
    ordered = sorted(numbers)
    steps = [b - a for a, b in zip(ordered, ordered[1:]) if b > a]
    if not steps or any(d % min(steps) for d in steps):
        return {}
    stride = min(steps)
    gaps = {}
    for a, b in zip(ordered, ordered[1:]):
        count = (b - a) // stride - 1  # counted, not listed: a stray frame_20240101
        if count > 0:
            lacking = range(a + stride, min(b, a + 11 * stride), stride)
            shown = ", ".join(map(str, lacking)) + (f" and {count - 10} more" if count > 10 else "")
            gaps[b] = f"frame{'s' if count > 1 else ''} {shown} missing: the stage goes from frame {a} to frame {b}"
    return gaps


# -- results --------------------------------------------------------------------------


@dataclass
class FrameProgress:
    """Passed to a progress callback after each frame."""

    done: int
    total: Optional[int]
    frame: int
    source: str
    points: int
    triangles: int
    seconds: float
    #: What the frame's extraction warned about (an isovalue the field never crosses, a
    #: kernel wider than the particles).
    warnings: List[str] = field(default_factory=list)


@dataclass
class FrameResult:
    """What :func:`write_frame` wrote (``warnings``: what the extraction warned about)."""

    path: Path
    frame: int
    points: int
    triangles: int
    schema: List[SchemaEntry]
    warnings: List[str] = field(default_factory=list)


@dataclass
class SequenceResult:
    """What :func:`write_sequence` or :func:`stitch` did.

    Attributes:
        output: the stage's root file.
        layout: "clips" or "flat".
        written: frame numbers written by this call.
        frames: frame numbers the stage holds now.
        clips: the clips folder (clips layout).
        schema: the time-sampled attributes (name, type, interpolation, elementSize).
        seconds: wall time.
        warnings: frame number -> what its extraction warned about, for the frames
            written by this call that warned.
        notes: what the stitch found about the sequence as a whole (frames extracted
            with different settings).
        failed: frame number -> why it could not be written, for the frames a
            ``keep_going`` call skipped (empty otherwise: an error stops the call).
    """

    output: Path
    layout: str
    written: List[int] = field(default_factory=list)
    frames: List[int] = field(default_factory=list)
    clips: Optional[Path] = None
    schema: List[SchemaEntry] = field(default_factory=list)
    seconds: float = 0.0
    warnings: Dict[int, List[str]] = field(default_factory=dict)
    notes: List[str] = field(default_factory=list)
    failed: Dict[int, str] = field(default_factory=dict)


# -- public API -----------------------------------------------------------------------


def _settings(fps, meters_per_unit, up_axis, prim, mesh) -> StageSettings:
    return StageSettings(fps=fps, meters_per_unit=meters_per_unit, up_axis=up_axis, prim=prim, mesh=mesh).checked()


def write_frame(
    source,
    path: PathLike,
    iso=None,
    *,
    time: Optional[int] = None,
    fps: float = 24.0,
    meters_per_unit: float = 1.0,
    up_axis: str = "Y",
    prim: str = "Fluid",
    mesh: str = "Surface",
    velocities="auto",
    primvars="auto",
    **extract_options,
) -> FrameResult:
    """Writes one frame as a complete single-layer stage, atomically.

    Args:
        source: a particle file (extracted with `iso` and `extract_options`, as
            :func:`isobar.extract` takes them), an :class:`isobar.Surface`, a mapping of
            arrays (``points``, ``triangles``, optional ``normals``, ``velocities``,
            ``attributes``) or a tuple ``(points, triangles[, normals[, attributes]])``.
        path: the .usd/.usda/.usdc file to write. Write ``clip_path(seq, frame)`` to
            (re)write a frame of the sequence ``seq``, then call :func:`stitch`.
        time: the time code of the samples (default: the file's frame number, else 0).
        velocities: "auto" (the 3-component particle array ``velocity`` when there is
            one), an array name, an (n, 3) array (in-memory frames), or None.
        primvars: attribute names written as vertex primvars; "auto": for particle files
            the extracted ``attributes`` (plus ``Isovalue`` for several isovalues), for
            surfaces every attribute but ``SumOfWeights``/``Isovalue``/the velocities.

    What the extraction warns about is in the result's ``warnings``, rather than issued
    through Python's warnings.

    Raises:
        InputError: bad input (missing file or array, wrong shapes, bad option).
        FrameError: the extraction failed (``.cause`` is the isobar error).
    """
    settings = _settings(fps, meters_per_unit, up_axis, prim, mesh)
    path = check_output_path(Path(path))
    job = make_job(iso, extract_options, velocities, primvars, settings)
    if time is None:
        time = (frame_number(source) if _is_path(source) else None) or 0
    frame = _as_frame(time)
    try:
        frame_mesh = produce(source, job)
    except InputError:
        raise
    except Exception as e:
        raise frame_error(frame, _label(source), e) from e
    layer = MeshLayer(settings, _frame_info(source, job, frame_mesh))
    try:
        entries = layer.add(frame_mesh, frame)
        layer.export(path)
    finally:
        layer.release()
    return FrameResult(path, frame, frame_mesh.n_points, frame_mesh.n_triangles, entries, frame_mesh.warnings)


def write_sequence(
    source,
    output: PathLike,
    iso=None,
    *,
    frames=None,
    jobs: Optional[int] = 1,
    layout: str = "auto",
    replace: Optional[bool] = None,
    stitch: bool = True,
    fps: float = 24.0,
    meters_per_unit: float = 1.0,
    up_axis: str = "Y",
    prim: str = "Fluid",
    mesh: str = "Surface",
    velocities="auto",
    primvars="auto",
    progress: Optional[Callable[[FrameProgress], Any]] = None,
    keep_going: bool = False,
    **extract_options,
) -> SequenceResult:
    """Writes a sequence of frames as one USD stage.

    Layout "clips" (the default for more than one frame): one layer per frame in
    ``<output stem>.clips/`` joined by value clips in the root file `output`, plus a clip
    manifest; one frame is in memory at a time (per process), so sequences of any length
    fit. Layout "flat": every frame's time samples in the one file `output` (all frames
    are held in memory until it is written; for short sequences). "auto": flat for a
    single frame, clips otherwise.

    Nothing changes on disk until every selected frame has been written: frames are
    staged under hidden names, then renamed into place and the root restitched under a
    lock. An error, Ctrl-C or a killed process leaves the previous stage as it was.

    Args:
        source: a frame pattern (``frames/frame_####.vtk``, ``{}``, ``%04d``, or one
            frame standing for its numbered siblings), a list of particle files, a mapping
            frame number -> (file | isobar.Surface | arrays), or an iterable of
            (frame number, file | surface) pairs (streamed: a generator can produce
            surfaces one at a time).
        output: the root .usd/.usda/.usdc file.
        iso: isovalue(s) for particle files.
        frames: only these frame numbers ("10-20", "1-5,9", an int, an iterable).
        jobs: processes writing frames in parallel (particle files only; None or 0:
            one per core).
        replace: remove the sequence's frame layers that this call did not write
            (default: True when `frames` is not given, i.e. the call writes the whole
            sequence; False for a partial rewrite).
        stitch: rewrite the root and manifest after committing the frames (False for
            separate invocations that run side by side; run :func:`stitch` after them).
        fps, meters_per_unit, up_axis, prim, mesh: stage settings (see StageSettings).
        velocities, primvars: as in :func:`write_frame`.
        progress: called with a :class:`FrameProgress` after each frame; raise to stop.
        keep_going: a frame that cannot be read or extracted (a truncated cache file)
            is skipped and named in the result's ``failed`` instead of stopping the
            call; the other frames are committed and stitched (a skipped frame shows
            the frame before it, as any gap does). Without it, nothing is written.
        **extract_options: passed to :func:`isobar.extract` (field, h, h_array, kernel,
            h_scale, grid_factor, correct, tolerance, trim, attributes, ...).

    What the extractions warn about (an isovalue the field never crosses, a kernel wider
    than the particles) is in each :class:`FrameProgress` and in the result's
    ``warnings`` (frame -> texts), rather than issued through Python's warnings.

    Raises:
        InputError, FrameError, StitchError (all :class:`isobar_usd.Error`).
    """
    t0 = time.perf_counter()
    _check_not_bootstrapping(jobs)
    settings = _settings(fps, meters_per_unit, up_axis, prim, mesh)
    output = check_output_path(Path(output))
    job = make_job(iso, extract_options, velocities, primvars, settings)
    selected = parse_frame_selection(frames)
    entries, total, what = _frame_entries(source)
    if selected is not None:
        entries = [e for e in entries if selected(e.number)]
        if not entries:
            raise InputError(f"frame selection {frames!r} matches none of the frames of {what}")
        total = len(entries)
    if jobs is None or jobs == 0:
        jobs = os.cpu_count() or 1
    jobs = int(jobs)
    if jobs < 0:
        raise InputError(f"jobs must be >= 0, got {jobs}")
    if layout not in ("auto", "clips", "flat"):
        raise InputError(f"layout must be 'auto', 'clips' or 'flat', got '{layout}'")
    if layout == "auto":
        layout = "flat" if total == 1 and selected is None else "clips"
    if layout == "flat":
        if jobs > 1:
            raise InputError("jobs > 1 needs the clips layout (a flat file is written by one process)")
        return _write_flat(entries, total, output, job, progress, t0, keep_going)
    if replace is None:
        replace = selected is None
    return _write_clips(entries, total, output, job, jobs, bool(replace), stitch, progress, t0, keep_going)


def _skip_or_raise(failed: Dict[int, str], error: FrameError, keep_going: bool) -> None:
    """Keeps `error` in `failed` when the call keeps going, else raises it."""
    if not keep_going:
        raise error
    failed[error.frame] = str(error)


def _nothing_written(failed: Dict[int, str]) -> Error:
    """The error of a call that wrote no frame: the first failure when every frame failed."""
    if failed:
        first = min(failed)
        return InputError(f"no frame could be written ({len(failed)} failed); the first: {failed[first]}")
    return InputError("no frames to write")


def _report(progress, warned: Dict[int, List[str]], done, total, frame, item, info, gap: Optional[str] = None) -> None:
    """A frame is written: keeps its warnings in `warned` (for the result), the `gap`
    before it first, and tells `progress`."""
    if gap:
        info = {**info, "warnings": [gap, *info.get("warnings", ())]}
    if info.get("warnings"):
        warned[frame] = list(info["warnings"])
    if progress is not None:
        progress(
            FrameProgress(
                done=done,
                total=total,
                frame=frame,
                source=info.get("source", _label(item)),
                points=int(info.get("points", 0)),
                triangles=int(info.get("triangles", 0)),
                seconds=float(info.get("seconds", 0.0)),
                warnings=list(info.get("warnings", ())),
            )
        )


def _write_flat(entries, total, output: Path, job: Job, progress, t0, keep_going: bool = False) -> SequenceResult:
    _atomic.sweep(output.parent if str(output.parent) else Path("."))
    layer = MeshLayer(job.settings, {"layout": "flat"})
    seen = set()
    warned: Dict[int, List[str]] = {}
    failed: Dict[int, str] = {}
    try:
        for done, entry in enumerate(entries, 1):
            _check_stop()
            if entry.number in seen:
                raise InputError(f"frame {entry.number} is given twice")
            seen.add(entry.number)
            t = time.perf_counter()
            try:
                frame_mesh = produce(entry.item, job)
            except Exception as e:
                _skip_or_raise(failed, frame_error(entry.number, _label(entry.item), e), keep_going)
                continue
            try:
                layer.add(frame_mesh, entry.number)
            except Exception as e:
                raise frame_error(entry.number, _label(entry.item), e) from e
            info = _frame_info(entry.item, job, frame_mesh)
            info["seconds"] = time.perf_counter() - t
            info["warnings"] = frame_mesh.warnings
            if "backendNote" in info:  # the flat layer's record says it too
                layer.info["backendNote"] = info["backendNote"]
            del frame_mesh
            _report(progress, warned, done, total, entry.number, entry.item, info, entry.gap)
        if not layer.frames:
            raise _nothing_written(failed)
        _check_stop()
        layer.export(output)
        schema = sorted(layer.schema.values())
        frames = sorted(layer.frames)
    finally:
        layer.release()
    return SequenceResult(
        output, "flat", frames, frames, None, schema, time.perf_counter() - t0, dict(sorted(warned.items())),
        failed=dict(sorted(failed.items())),
    )


#: Root-file suffixes whose clips folders coincide for one stem (``fluid.clips/``).
_ROOT_SUFFIXES = (".usd", ".usda", ".usdc")


def _clips_folder_for_writing(output: Path, replace: bool) -> Path:
    """The clips folder of `output`; raises InputError, before any extraction, when it is
    there but frames cannot be written in it, when it is another root's too (the same
    stem with another suffix: writing would replace that stage's frames), or when a
    partial rewrite would join frame layers the root does not use (the root is now a
    flat layer; its clips are from an earlier run)."""
    folder = clips_folder(output)
    if folder.is_dir():
        check_writable_folder(folder, f"output '{output}'")
        for suffix in _ROOT_SUFFIXES:
            other = output.with_suffix(suffix)
            if suffix != output.suffix.lower() and other.exists() and _layout_of(other) == "clips":
                raise InputError(
                    f"output '{output}': its clips folder '{folder}' is also the one of '{other}' "
                    "(the same name with another suffix), whose frames this run would replace: "
                    f"choose another output name, or remove '{other}' first"
                )
        if not replace and output.exists() and _layout_of(output) == "flat":
            raise InputError(
                f"output '{output}' is a flat layer, and '{folder}' holds the frame layers of an "
                "earlier clips run, which a partial rewrite would join to this one's: write every "
                "frame (no frame selection) or remove that folder"
            )
    elif folder.exists() or folder.is_symlink():
        raise InputError(f"output '{output}': '{folder}' (its clips folder) is not a folder")
    return folder


def _layout_of(root: Path) -> Optional[str]:
    """The layout the writer recorded in root layer `root` ("flat", "clips"), or None."""
    try:
        return str(read_record(root).info.get("layout")) or None
    except Error:
        return None


_GUARD_HINT = (
    "with jobs > 1 each worker process imports the main module (multiprocessing, start method "
    "spawn), so a script must make the call under `if __name__ == \"__main__\":`"
)


def _check_not_bootstrapping(jobs) -> None:
    """Raises InputError when this process is a worker still importing the caller's main
    module: the script called write_sequence at its top level, without the guard, and a
    pool here would fail the same way in every worker it starts."""
    if jobs is not None and jobs != 0 and not (isinstance(jobs, (int, float)) and jobs > 1):
        return
    if getattr(multiprocessing.current_process(), "_inheriting", False):
        raise InputError(
            f"write_sequence(jobs={jobs}) was called while a worker process imports the main module; {_GUARD_HINT}"
        )


def _check_workers(pool, pids: set, done: int) -> None:
    """Raises Error when a worker of `pool` died: multiprocessing.Pool would replace it
    and wait forever for its task (or, when workers die while starting, respawn them
    forever)."""
    for process in list(getattr(pool, "_pool", ())):
        code = process.exitcode
        if process.pid not in pids or (code is not None and code != 0):
            how = "" if code is None else f" (exit status {code})" if code >= 0 else f" (signal {-code})"
            if done == 0:
                raise Error(
                    f"a worker process ended before writing any frame{how}; see its error above. "
                    f"If a script calls write_sequence at its top level: {_GUARD_HINT}"
                ) from None
            raise Error(f"a worker process ended while writing a frame{how}; killed for memory?") from None


def _write_clips(
    entries, total, output: Path, job: Job, jobs: int, replace: bool, stitch_after: bool, progress, t0, keep_going: bool = False
) -> SequenceResult:
    folder = _clips_folder_for_writing(output, replace)
    created = not folder.exists()
    try:
        folder.mkdir(exist_ok=True)
    except OSError as e:
        raise InputError(f"output '{output}': cannot create the clips folder '{folder}': {e.strerror or e}") from None
    _atomic.sweep(folder)
    _atomic.sweep(output.parent if str(output.parent) else Path("."))
    staged: Dict[int, Tuple[Path, Path]] = {}
    warned: Dict[int, List[str]] = {}
    failed: Dict[int, str] = {}

    def skip(frame: int, error: FrameError) -> None:
        _skip_or_raise(failed, error, keep_going)
        tmp, _ = staged.pop(frame)
        _atomic.discard(tmp)

    try:
        if jobs > 1:
            entries = list(entries)
            total = len(entries)
            for e in entries:
                if not _is_path(e.item):
                    raise InputError("jobs > 1 needs particle files; in-memory frames are written by one process")
            _no_duplicates(e.number for e in entries)
            tasks = []
            for e in entries:
                final = clip_path(output, e.number)
                staged[e.number] = (_atomic.staging_path(final), final)
                tasks.append((e.number, os.fspath(e.item), os.fspath(staged[e.number][0]), job))
            labels = {e.number: _label(e.item) for e in entries}
            gaps = {e.number: e.gap for e in entries}
            ctx = multiprocessing.get_context("spawn")
            with ctx.Pool(processes=min(jobs, max(1, len(tasks))), initializer=_worker_init, initargs=(jobs,)) as pool:
                pids = {p.pid for p in getattr(pool, "_pool", ())}
                done = 0
                results = pool.imap_unordered(_pool_task, tasks)
                while True:
                    try:
                        frame, info, err = results.next(timeout=0.25)
                    except multiprocessing.TimeoutError:
                        _check_stop()
                        _check_workers(pool, pids, done)
                        continue
                    except StopIteration:
                        break
                    _check_stop()
                    if err is not None:
                        skip(frame, frame_error(frame, labels[frame], err))
                        continue
                    done += 1
                    _report(progress, warned, done, total, frame, labels[frame], info, gaps.get(frame))
        else:
            for done, entry in enumerate(entries, 1):
                _check_stop()
                if entry.number in staged:
                    raise InputError(f"frame {entry.number} is given twice")
                final = clip_path(output, entry.number)
                staged[entry.number] = (_atomic.staging_path(final), final)
                try:
                    info = write_clip(entry.number, entry.item, staged[entry.number][0], job)
                except Exception as e:
                    skip(entry.number, frame_error(entry.number, _label(entry.item), e))
                    continue
                _report(progress, warned, done, total, entry.number, entry.item, info, entry.gap)
        if not staged:
            raise _nothing_written(failed)

        _check_stop()
        # Commit: rename the staged frames into place and restitch, under the lock.
        with _atomic.locked(folder / _LOCK):
            for frame in sorted(staged):
                tmp, final = staged[frame]
                _atomic.replace(tmp, final)
            written = sorted(staged)
            staged.clear()
            if replace:
                keep = set(written)
                for frame, path in _committed_clips(output).items():
                    if frame not in keep:
                        _atomic.discard(path)
            if stitch_after:
                result = _stitch_locked(output, job.settings)
                result.written = written
                result.seconds = time.perf_counter() - t0
                result.warnings = dict(sorted(warned.items()))
                result.failed = dict(sorted(failed.items()))
                return result
            committed = sorted(_committed_clips(output))
            return SequenceResult(
                output, "clips", written, committed, folder, [], time.perf_counter() - t0, dict(sorted(warned.items())),
                failed=dict(sorted(failed.items())),
            )
    except BaseException:
        for tmp, _ in staged.values():
            _atomic.discard(tmp)
        if created:
            try:
                folder.rmdir()  # only when this call made it and nothing is in it
            except OSError:
                pass
        raise


def stitch(
    output: PathLike,
    *,
    fps: Optional[float] = None,
    meters_per_unit: Optional[float] = None,
    up_axis: Optional[str] = None,
) -> SequenceResult:
    """(Re)writes the root layer and clip manifest of the sequence `output` from the frame
    layers in its clips folder (after frames were written separately, e.g. by
    ``write_sequence(..., stitch=False)`` or :func:`write_frame` to :func:`clip_path`).

    Stage settings come from the frame layers (which must agree); `fps` may override
    theirs. `meters_per_unit` and `up_axis`, when given, must match the frames.

    Raises:
        StitchError: no frame layers, frames with conflicting attributes or settings.
    """
    t0 = time.perf_counter()
    output = check_output_path(Path(output))
    folder = clips_folder(output)
    if not folder.is_dir():
        raise StitchError(f"no clips folder {folder}: write frames first")
    with _atomic.locked(folder / _LOCK):
        result = _stitch_locked(output, None, fps=fps, meters_per_unit=meters_per_unit, up_axis=up_axis)
    result.seconds = time.perf_counter() - t0
    return result


def _stitch_locked(
    output: Path,
    settings: Optional[StageSettings],
    fps: Optional[float] = None,
    meters_per_unit: Optional[float] = None,
    up_axis: Optional[str] = None,
) -> SequenceResult:
    folder = clips_folder(output)
    clips = _committed_clips(output)
    if not clips:
        raise StitchError(f"no frame layers ({output.stem}.NNNN.usdc) in {folder}")
    schema: Dict[str, SchemaEntry] = {}
    where: Dict[str, str] = {}
    chosen = settings
    chosen_from = "this run" if settings is not None else None
    # Point counts, for the holds between frames that differ (-1: not recorded, held).
    counts: Dict[int, int] = {}
    extractions: Dict[int, Optional[str]] = {}
    for frame in sorted(clips):
        path = clips[frame]
        record = read_record(path)
        counts[frame] = int(record.info.get("points", -1))
        extractions[frame] = record.info.get("extraction")
        if record.frames != [frame]:
            raise StitchError(f"{path} holds frame(s) {record.frames}, not frame {frame} (renamed by hand?)")
        merge_schema(schema, record.schema, f"frame {frame}", where)
        theirs = record.settings
        if theirs is None:
            raise StitchError(f"{path} records no stage settings")
        if chosen is None:
            chosen, chosen_from = theirs, f"frame {frame}"
            continue
        for name, label in (("meters_per_unit", "metersPerUnit"), ("up_axis", "upAxis"), ("prim", "prim"), ("mesh", "mesh")):
            if getattr(theirs, name) != getattr(chosen, name):
                raise StitchError(
                    f"frame {frame} was written with {label} {getattr(theirs, name)!r} but {chosen_from} "
                    f"with {getattr(chosen, name)!r}; rewrite the frames with the same settings"
                )
        if settings is None and fps is None and theirs.fps != chosen.fps:
            raise StitchError(
                f"frame {frame} was written at {theirs.fps} fps but {chosen_from} at {chosen.fps}; pass fps to choose"
            )
    assert chosen is not None
    overrides = {"fps": fps, "meters_per_unit": meters_per_unit, "up_axis": up_axis}
    for name in ("meters_per_unit", "up_axis"):
        value = overrides[name]
        if value is not None and StageSettings(**{**chosen.__dict__, name: value}).checked() != chosen:
            raise StitchError(
                f"{name} {value!r} differs from the frames' {getattr(chosen, name)!r}; rewrite the frames instead"
            )
    if fps is not None:
        chosen = StageSettings(**{**chosen.__dict__, "fps": fps}).checked()
    entries = sorted(schema.values())
    write_manifest(folder / MANIFEST, chosen, entries)
    rel = f"./{folder.name}"
    info = {"frames_count": len(clips)}
    write_clips_root(
        output,
        chosen,
        entries,
        [(f, f"{rel}/{clips[f].name}") for f in sorted(clips)],
        f"{rel}/{MANIFEST}",
        info,
        point_counts=counts,
    )
    frames = sorted(clips)
    mixed = mixed_settings(extractions, extraction_defaults)
    return SequenceResult(output, "clips", [], frames, folder, entries, notes=[mixed] if mixed else [])


__all__ = [
    "FrameProgress",
    "FrameResult",
    "SequenceResult",
    "clip_path",
    "clips_folder",
    "request_stop",
    "stitch",
    "write_frame",
    "write_sequence",
]
