"""Shared helpers for the demo/benchmark data scripts (pysplishsplash, headless).

Used by ``make_demo_data.py`` and ``make_bench_frame.py``. Nothing here is needed by
the Rust crate; it only drives the SPlisHSPlasH solver from PyPI (``pysplishsplash``,
version pinned in ``requirements-demo.txt``) and reads back what its VTK exporter wrote.

Facts this relies on (checked against pysplishsplash 2.19.0):

* Importing ``pysplishsplash`` segfaults unless a libGLdispatch copy is loaded into the
  global symbol namespace first (clash between the wheel's bundled libGLdispatch and the
  one libGL pulls in).  ``import_pysplishsplash()`` does that with ctypes (the bundled copy
  in ``pysplishsplash.libs`` first, the system ``libGLdispatch.so.0`` as fallback), which
  is the in-process equivalent of ``LD_PRELOAD=/lib/x86_64-linux-gnu/libGLdispatch.so.0``.
* Headless driving: ``SimulatorBase.init(useGui=False, outputDir=..., sceneFile=...)``,
  ``setValueFloat(STOP_AT, t)``, ``activateExporter("VTK Exporter", True)``, ``run()``.
  (``timeStepNoGUI()`` without ``run()`` segfaults: the boundary data is only initialised
  inside ``runSimulation()``.)
* The VTK exporter writes legacy *big-endian* binary ``.vtk`` files: POINTS (float32),
  one VERTEX cell per particle, ``SCALARS id unsigned_int`` and a FIELD block holding the
  attributes listed in the scene's ``Configuration.particleAttributes`` (";"-separated,
  spaces in field names become "_").
* Field names per pressure solver (``simulationMethod``): 0 WCSPH and 1 PCISPH and
  3 IISPH expose ``pressure``; 4 DFSPH only exposes ``p / rho^2`` and ``p_v / rho^2``;
  5 PF exposes no pressure.  All expose ``density`` (kg/m^3) and ``velocity`` (m/s).
* IISPH stores pressure divided by the rest density (unit m^2/s^2): its pressure
  acceleration is ``-sum_j V_j (p_i/rho_i'^2 + p_j/rho_j'^2) gradW`` with
  ``rho' = rho/rho0`` and ``V_j`` a volume, which equals the physical
  ``-sum_j m_j (P_i/rho_i^2 + P_j/rho_j^2) gradW`` for ``P = rho0 * p``.  Checked
  numerically: a water layer settling in a box gives d(raw pressure)/d(depth) = 10.4
  (~ g = 9.81), i.e. raw = P / rho0.  WCSPH stores Pa (same check gives ~ rho g), but
  with the scenes' default stiffness it compresses the water by >50 %, so it is not
  offered.  PCISPH was not checked.  ``pressure_to_pascal()`` applies the factor.
"""

from __future__ import annotations

import ctypes
import glob
import importlib.util
import json
import os
import sysconfig

import numpy as np

PYSPLISHSPLASH_VERSION = "2.19.0"

# SPlisHSPlasH "simulationMethod" enum values (Simulation.ENUM_SIMULATION_*).
METHODS = {"wcsph": 0, "pcisph": 1, "pbf": 2, "iisph": 3, "dfsph": 4, "pf": 5}
# Field that holds the pressure, and the factor that turns it into Pa (times rho0 or 1).
PRESSURE_FIELD = {
    "wcsph": ("pressure", "Pa"),
    "iisph": ("pressure", "per_rho0"),
}


def import_pysplishsplash(threads: int | None = None):
    """Import pysplishsplash without the libGLdispatch segfault; optionally fix OpenMP threads."""
    if threads:
        # libgomp reads this when it is loaded, i.e. during the import below.
        os.environ["OMP_NUM_THREADS"] = str(threads)
    spec = importlib.util.find_spec("pysplishsplash")
    if spec is None or spec.origin is None:
        raise SystemExit(
            "pysplishsplash is not installed: pip install -r scripts/requirements-demo.txt"
        )
    libs_dir = os.path.join(os.path.dirname(spec.origin), "pysplishsplash.libs")
    candidates = sorted(glob.glob(os.path.join(libs_dir, "libGLdispatch*.so*")))
    candidates += ["libGLdispatch.so.0"]
    for cand in candidates:
        try:
            ctypes.CDLL(cand, mode=os.RTLD_GLOBAL | os.RTLD_NOW)
            break
        except OSError:
            continue
    import pysplishsplash  # noqa: E402  (must come after the preload)

    return pysplishsplash


def packaged_scene_dir() -> str:
    """The wheel installs its data/ folder next to the interpreter's scripts (venv/bin/data)."""
    cands = [
        os.path.join(sysconfig.get_path("scripts"), "data", "Scenes"),
        os.path.join(sysconfig.get_path("data"), "bin", "data", "Scenes"),
    ]
    for c in cands:
        if os.path.isdir(c):
            return c
    raise SystemExit("cannot find pysplishsplash's data/Scenes folder (looked in %s)" % cands)


def resolve_scene(scene: str) -> str:
    """A scene name shipped with the wheel ("DamBreakModel") or a path to a JSON file."""
    if os.path.isfile(scene):
        return os.path.abspath(scene)
    name = scene if scene.endswith(".json") else scene + ".json"
    path = os.path.join(packaged_scene_dir(), name)
    if not os.path.isfile(path):
        raise SystemExit(f"scene {scene!r} not found (not a file, not in {packaged_scene_dir()})")
    return path


def absolutize_scene_paths(scene: dict, scene_dir: str) -> None:
    """Make geometry/sample file paths absolute so the edited scene can live elsewhere."""
    for key in ("RigidBodies", "FluidModels"):
        for obj in scene.get(key, []):
            for fk in ("geometryFile", "particleFile", "mapFile"):
                if fk in obj and not os.path.isabs(obj[fk]):
                    obj[fk] = os.path.normpath(os.path.join(scene_dir, obj[fk]))


def write_scene(scene: dict, workdir: str, name: str = "scene.json") -> str:
    os.makedirs(workdir, exist_ok=True)
    path = os.path.join(workdir, name)
    with open(path, "w") as f:
        json.dump(scene, f, indent=2)
    return path


_VTK_TYPES = {"float": ">f4", "double": ">f8", "unsigned_int": ">u4", "int": ">i4"}


def read_splishsplash_vtk(path: str) -> dict:
    """Read a particle file written by SPlisHSPlasH's VTK exporter (legacy, binary, BE).

    Returns a dict: 'position' (N,3), 'id' (N,) and one entry per exported attribute
    (names as in the file, i.e. spaces replaced by '_'), as native-endian arrays.
    """
    with open(path, "rb") as f:
        data = f.read()
    pos = 0

    def readline() -> str:
        nonlocal pos
        end = data.index(b"\n", pos)
        line = data[pos:end].decode("ascii")
        pos = end + 1
        return line

    header = [readline() for _ in range(4)]
    if not header[0].startswith("# vtk DataFile") or header[2].strip() != "BINARY":
        raise ValueError(f"{path}: not a binary legacy VTK file")
    out: dict = {}
    n = None
    while pos < len(data):
        line = readline().strip()
        if not line:
            continue
        tok = line.split()
        if tok[0] == "POINTS":
            n = int(tok[1])
            dt = np.dtype(_VTK_TYPES[tok[2]])
            size = dt.itemsize * 3 * n
            out["position"] = np.frombuffer(data, dt, 3 * n, pos).reshape(n, 3).astype(dt.newbyteorder("="))
            pos += size
        elif tok[0] == "CELLS":
            pos += int(tok[2]) * 4
        elif tok[0] == "CELL_TYPES":
            pos += int(tok[1]) * 4
        elif tok[0] == "POINT_DATA":
            n = int(tok[1])
        elif tok[0] == "SCALARS":
            name, dt = tok[1], np.dtype(_VTK_TYPES[tok[2]])
            readline()  # LOOKUP_TABLE
            out[name] = np.frombuffer(data, dt, n, pos).astype(dt.newbyteorder("="))
            pos += dt.itemsize * n
        elif tok[0] == "FIELD":
            continue
        else:
            name, ncomp, count, typ = tok[0], int(tok[1]), int(tok[2]), tok[3]
            dt = np.dtype(_VTK_TYPES[typ])
            arr = np.frombuffer(data, dt, ncomp * count, pos).astype(dt.newbyteorder("="))
            pos += dt.itemsize * ncomp * count
            out[name] = arr.reshape(count, ncomp) if ncomp > 1 else arr
    return out


def pressure_to_pascal(method: str, raw: np.ndarray, density0: float) -> np.ndarray:
    field, kind = PRESSURE_FIELD[method]
    if kind == "per_rho0":
        return (raw.astype(np.float64) * density0).astype(np.float32)
    return raw.astype(np.float32)
