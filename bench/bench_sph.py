"""Benchmark: isobar against splashsurf and VTK on the SPH sum-of-weights isosurface.

    python bench/bench_sph.py INPUT [--radius R] [--cube 0.75] [--iso 0.6]
        [--max-eval-vertices 200000] [--out results.md]

Every method reconstructs S(x) = sum_j V_j W(x - x_j, 2r) = iso (cubic spline, support 4r,
V_j = 1/sum_k W(x_j - x_k)) on cells of `cube` * r from the same particles, each in its own
process (own wall time, own peak RSS). One evaluator (sph_eval.py, numpy + scipy) then
measures |S - iso| at the vertices of every mesh. See bench/README.md.
"""

from __future__ import annotations

import argparse
import importlib.metadata
import json
import os
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import numpy as np
from particles import load_positions, radius_from_h
from sph_eval import SumOfWeights, closedness, sample_vertices

BENCH_DIR = Path(__file__).resolve().parent
DEFAULT_ISOBAR = BENCH_DIR.parent / "target" / "release" / "isobar"

# (label, isobar flags): the three isobar variants, all from the same CLI.
ISOBAR_VARIANTS = [
    ("isobar (corrected)", []),
    ("isobar --preview", ["--preview"]),
    ("isobar --full-grid", ["--full-grid"]),
]
TABLE_HEAD = (
    "| method | extract (s) | total (s) | CPU (s) | peak RSS (MiB) | triangles | closed "
    "| max \\|F−iso\\| | mean \\|F−iso\\| | extract time / splashsurf |"
)
# Figures from isobar's --stats-json copied into the report.
ISOBAR_STATS_KEYS = (
    "field_evaluations",
    "cache_hit_ratio",
    "unconverged_vertices",
    "time_field_build_s",
    "time_seed_cells_s",
    "time_tracking_s",
    "time_vertices_s",
    "time_extraction_total_s",
)
PYTHON_METHODS = [
    ("splashsurf (pysplashsurf)", "splashsurf"),
    ("VTK SPH + FlyingEdges3D", "vtk"),
]


@dataclass
class Run:
    """What one method's process produced and cost."""

    label: str
    status: str = "ok"
    wall_s: float = float("nan")
    cpu_s: float = float("nan")
    peak_rss_mib: float = float("nan")
    extract_s: float = float("nan")
    read_s: float = float("nan")
    vertices: np.ndarray | None = None
    triangles: np.ndarray | None = None
    details: dict = field(default_factory=dict)
    accuracy: dict = field(default_factory=dict)


@dataclass
class Settings:
    radius: float
    cube: float
    iso: float
    timeout: float
    isobar: Path
    workdir: Path


def run_measured(cmd: list[str], log: Path, timeout: float) -> dict:
    """Runs `cmd` under measure.py: status, wall_s, cpu_s, peak_rss_mib of that process."""
    result = log.with_suffix(".measure.json")
    launcher = [
        sys.executable,
        "-I",
        "-S",
        str(BENCH_DIR / "measure.py"),
        str(result),
        str(timeout),
    ]
    with log.open("w") as out:
        subprocess.run(launcher + cmd, stdout=out, stderr=subprocess.STDOUT, check=True)
    m = json.loads(result.read_text())
    return {
        "status": _status(m, log, timeout),
        "wall_s": m["wall_s"],
        "cpu_s": m["cpu_s"],
        "peak_rss_mib": m["peak_rss_kib"] / 1024.0,
    }


def _status(m: dict, log: Path, timeout: float) -> str:
    """'ok', or what went wrong, from measure.py's record of one run."""
    code = m["exit_code"]
    if m["timed_out"]:
        return f"timeout after {timeout:g} s"
    if code == -9:
        return "killed by SIGKILL (out of memory?)"
    if code < 0:
        return f"killed by signal {-code}"
    if code != 0:
        return f"failed (exit {code}): {_last_line(log)}"
    return "ok"


def _last_line(log: Path) -> str:
    lines = [
        line for line in log.read_text(errors="replace").splitlines() if line.strip()
    ]
    return lines[-1][:200] if lines else "no output"


def run_isobar(label: str, flags: list[str], positions: Path, cfg: Settings) -> Run:
    stem = cfg.workdir / label.split()[-1].strip("()-")
    stats, mesh = stem.with_suffix(".json"), stem.with_suffix(".vtp")
    cmd = [
        str(cfg.isobar), "sph", str(positions),
        "--field", "SumOfWeights", "--iso", repr(cfg.iso), "--kernel", "cubic",
        "--h", repr(2.0 * cfg.radius), "--grid-factor", repr(cfg.cube / 2.0),
        *flags, "--stats-json", str(stats), "--quiet", "-o", str(mesh),
    ]  # fmt: skip
    run = Run(label, **run_measured(cmd, stem.with_suffix(".log"), cfg.timeout))
    run.details["command"] = " ".join(cmd)
    if run.status != "ok":
        return run
    s = json.loads(stats.read_text())
    # isobar times the field build (neighbour grid, per-particle densities) apart from
    # the extraction; splashsurf's and VTK's times include their density pass, so add it.
    run.extract_s = s["time_field_build_s"] + s["time_extraction_total_s"]
    run.read_s = s["time_read_s"]
    run.details.update({k: s[k] for k in ISOBAR_STATS_KEYS if k in s})
    run.vertices, run.triangles = read_vtp(mesh)
    return run


def read_vtp(path: Path) -> tuple[np.ndarray, np.ndarray]:
    from vtkmodules.util.numpy_support import vtk_to_numpy
    from vtkmodules.vtkIOXML import vtkXMLPolyDataReader

    reader = vtkXMLPolyDataReader()
    reader.SetFileName(str(path))
    reader.Update()
    poly = reader.GetOutput()
    if poly.GetNumberOfPoints() == 0:
        return np.zeros((0, 3)), np.zeros((0, 3), dtype=np.int64)
    vertices = vtk_to_numpy(poly.GetPoints().GetData()).astype(np.float64)
    triangles = vtk_to_numpy(poly.GetPolys().GetConnectivityArray()).reshape(-1, 3)
    return vertices, triangles


def run_python(label: str, method: str, positions: Path, cfg: Settings) -> Run:
    stem = cfg.workdir / method
    mesh, result = stem.with_suffix(".npz"), stem.with_suffix(".json")
    cmd = [
        sys.executable, str(BENCH_DIR / "workers.py"), method, str(positions), str(mesh),
        str(result), "--radius", repr(cfg.radius), "--cube", repr(cfg.cube), "--iso", repr(cfg.iso),
    ]  # fmt: skip
    run = Run(label, **run_measured(cmd, stem.with_suffix(".log"), cfg.timeout))
    run.details["command"] = " ".join(cmd)
    if run.status != "ok":
        return run
    r = json.loads(result.read_text())
    run.extract_s, run.read_s = r["extract_s"], r["read_s"]
    run.details.update(r["phases"])
    run.details["baseline_rss_mib"] = round(r["baseline_rss_mib"], 1)
    with np.load(mesh) as m:
        run.vertices, run.triangles = m["vertices"], m["triangles"]
    return run


def evaluate(
    runs: list[Run], positions: np.ndarray, cfg: Settings, limit: int
) -> float:
    """Fills each run's accuracy from the reference evaluator; returns its setup time."""
    t0 = time.perf_counter()
    field_s = SumOfWeights(positions, 2.0 * cfg.radius)
    setup_s = time.perf_counter() - t0
    for run in runs:
        if run.status != "ok":
            continue
        sample = sample_vertices(run.vertices, limit)
        err = np.abs(field_s(sample) - cfg.iso) if len(sample) else np.zeros(1)
        run.accuracy = {
            "max": float(err.max()),
            "mean": float(err.mean()),
            "evaluated": len(sample),
        }
        run.accuracy.update(closedness(run.triangles))
    return setup_s


def table(runs: list[Run]) -> str:
    ref = next(
        (r.extract_s for r in runs if r.label.startswith("splashsurf")), float("nan")
    )
    rows = [TABLE_HEAD, "|" + "---|" * 10]
    for r in runs:
        if r.status != "ok":
            rows.append(
                f"| {r.label} | {r.status} | {r.wall_s:.2f} | {r.cpu_s:.2f} "
                f"| {r.peak_rss_mib:.0f} |  |  |  |  |  |"
            )
            continue
        a = r.accuracy
        closed = (
            "yes"
            if a["closed"]
            else f"no ({a['open_edges']} open, {a['nonmanifold_edges']} non-manifold)"
        )
        rows.append(
            f"| {r.label} | {r.extract_s:.3f} | {r.wall_s:.2f} | {r.cpu_s:.2f} "
            f"| {r.peak_rss_mib:.0f} "
            f"| {len(r.triangles):,} | {closed} | {a['max']:.2e} | {a['mean']:.2e} "
            f"| {ratio(r.extract_s, ref)} |"
        )
    return "\n".join(rows)


def ratio(value: float, ref: float) -> str:
    """value / ref as '1.23×', or '–' when splashsurf did not run."""
    return f"{value / ref:.2f}×" if np.isfinite(ref) and ref > 0 else "–"


def details(runs: list[Run]) -> str:
    lines = []
    for r in runs:
        extra = {k: v for k, v in r.details.items() if k != "command"}
        if r.status == "ok":
            extra = {
                "read_s": round(r.read_s, 4),
                "vertices": len(r.vertices),
                "evaluated_vertices": r.accuracy["evaluated"],
                **extra,
            }
        lines.append(f"- **{r.label}**: `{r.details.get('command', '')}`")
        lines.append(f"  - {json.dumps(extra, default=_json_number)}")
    return "\n".join(lines)


def _json_number(value):
    return float(value) if isinstance(value, np.floating) else int(value)


def versions(isobar: Path) -> str:
    """The versions of everything measured, for the report's header."""
    found = []
    if os.access(isobar, os.X_OK):
        cmd = [str(isobar), "--version"]
        out = subprocess.run(cmd, capture_output=True, text=True, check=False)
        found.append(out.stdout.strip())
    for package in ("pysplashsurf", "vtk", "numpy", "scipy"):
        found.append(f"{package} {importlib.metadata.version(package)}")
    return ", ".join(found)


def header(args, n: int, cfg: Settings, eval_setup_s: float, load: float) -> str:
    setting = (
        f"r = {cfg.radius:g}, h = 2r = {2 * cfg.radius:g} (cubic spline, support 4r), "
        f"cell = {cfg.cube:g} r = {cfg.cube * cfg.radius:g}, iso = {cfg.iso:g}; "
        f"{os.cpu_count()} cores (1-min load average {load:.1f} at start); "
        f"{versions(cfg.isobar)}; best of {args.repeat} round(s) of every method."
    )
    evaluator = (
        f"Reference evaluator set-up (volumes of all particles): {eval_setup_s:.1f} s; "
        f"at most {args.max_eval_vertices:,} vertices evaluated per method."
    )
    return "\n".join(
        [f"## {Path(args.input).name}: {n:,} particles", "", setting, evaluator]
    )


def parse_args() -> argparse.Namespace:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument(
        "input", help="particle file (.npz .npy .bgeo .vtk .vtu .vtp .ply .csv)"
    )
    p.add_argument(
        "--radius",
        type=float,
        help="particle radius r (default: h/2 from a uniform 'h' array of an .npz)",
    )
    p.add_argument("--cube", type=float, default=0.75, help="cell size in units of r")
    p.add_argument("--iso", type=float, default=0.6)
    p.add_argument("--max-eval-vertices", type=int, default=200_000)
    p.add_argument("--out", type=Path, help="write the markdown table here too")
    p.add_argument("--isobar", type=Path, default=DEFAULT_ISOBAR, help="isobar binary")
    p.add_argument(
        "--timeout", type=float, default=600.0, help="seconds per method run"
    )
    p.add_argument(
        "--repeat", type=int, default=1, help="rounds of every method; each method's fastest run counts"
    )
    p.add_argument(
        "--skip", nargs="*", default=[], choices=["isobar", "splashsurf", "vtk"]
    )
    p.add_argument(
        "--workdir", type=Path, help="keep meshes and logs here (default: temp)"
    )
    return p.parse_args()


def best_of(runs: list[Run]) -> Run:
    """One method's runs: fastest times, largest peak RSS; a failure if any failed."""
    failed = [r for r in runs if r.status != "ok"]
    if failed:
        return failed[0]
    best = min(runs, key=lambda r: r.extract_s)
    best.wall_s = min(r.wall_s for r in runs)
    best.cpu_s = min(r.cpu_s for r in runs)
    best.peak_rss_mib = max(r.peak_rss_mib for r in runs)
    return best


def jobs(args, cfg: Settings, particles_npy: Path):
    """(label, runner taking no argument) for every method not skipped."""
    if "isobar" not in args.skip:
        for label, flags in ISOBAR_VARIANTS:
            yield label, partial(run_isobar, label, flags, particles_npy, cfg)
    for label, method in PYTHON_METHODS:
        if method not in args.skip:
            yield label, partial(run_python, label, method, particles_npy, cfg)


def run_all(args, cfg: Settings, particles_npy: Path) -> list[Run]:
    """Every method once a round, `--repeat` rounds, the best run of each method kept.

    Rounds, not each method's runs back to back: a shared machine's speed drifts over
    minutes (by up to 2x on the development machine), and methods run at different times
    would each be timed in a different phase of it, which skews their ratios. A method
    that failed (crash, timeout, refusal) is not run again: it would not get better.
    """
    methods = list(jobs(args, cfg, particles_npy))
    runs: dict[str, list[Run]] = {label: [] for label, _ in methods}
    for _ in range(args.repeat):
        for label, job in methods:
            if runs[label] and runs[label][-1].status != "ok":
                continue
            run = job()
            runs[label].append(run)
            print(f"{label}: {run.status}, {run.wall_s:.2f} s", file=sys.stderr, flush=True)
    return [best_of(runs[label]) for label, _ in methods]


def main() -> None:
    args = parse_args()
    if "isobar" not in args.skip and not os.access(args.isobar, os.X_OK):
        sys.exit(
            f"no isobar binary at {args.isobar}: run `cargo build --release` or --isobar"
        )
    try:
        positions = load_positions(args.input)
        if args.radius is None:
            args.radius = radius_from_h(args.input)
    except (OSError, ValueError) as e:
        sys.exit(f"bench_sph.py: {e}")
    load = os.getloadavg()[0]
    with tempfile.TemporaryDirectory(prefix="isobar-bench-") as tmp:
        workdir = args.workdir or Path(tmp)
        workdir.mkdir(parents=True, exist_ok=True)
        cfg = Settings(
            args.radius, args.cube, args.iso, args.timeout, args.isobar, workdir
        )
        particles_npy = workdir / "particles.npy"
        np.save(particles_npy, positions)
        runs = run_all(args, cfg, particles_npy)
        eval_setup_s = evaluate(runs, positions, cfg, args.max_eval_vertices)
    report = "\n\n".join(
        [
            header(args, len(positions), cfg, eval_setup_s, load),
            table(runs),
            details(runs),
        ]
    )
    if args.out:
        args.out.write_text(report + "\n")
    print(report)


if __name__ == "__main__":
    main()
