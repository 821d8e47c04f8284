"""ISOSLIDER benchmark: slider update time for 0.1 %, 1 %, 5 % and 10 % isovalue changes
against a full vtkFlyingEdges3D recompute of the same 256^3 volume in the same run; store
size against volume size; resident memory of `isobar slide` (a separate process).

Volumes: the MNI152 T1 template shipped in PyPI `nilearn` (a real MRI average, 197x233x189,
resampled trilinearly to 256^3), and a synthetic sum of Gaussians with noise.

    .venv-bench/bin/python bench/slider/bench_slider.py [--size 256] [--out DIR]
(needs: pip install nilearn vtk scipy "numpy<2"; cargo build --release)
"""

import argparse
import json
import os
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parents[2]
os.environ.setdefault("ISOBAR_LIBRARY", str(REPO / "target" / "release" / "libisobar.so"))
sys.path.insert(0, str(REPO / "rust-core" / "python"))
import isobar  # noqa: E402

CLI = Path(os.environ.get("ISOBAR_CLI", REPO / "target" / "release" / "isobar"))


def mni(size):
    from nilearn import datasets
    from scipy import ndimage

    img = datasets.load_mni152_template(resolution=1)
    data = np.asarray(img.get_fdata(), dtype=np.float32)  # [x, y, z]
    zoom = [size / s for s in data.shape]
    vol = ndimage.zoom(data, zoom, order=1).astype(np.float32)
    return np.ascontiguousarray(vol.transpose(2, 1, 0))  # [z, y, x]


def synthetic(size):
    rng = np.random.default_rng(1)
    ax = np.linspace(-1, 1, size, dtype=np.float32)
    z, y, x = np.meshgrid(ax, ax, ax, indexing="ij")
    vol = np.zeros_like(x)
    for _ in range(12):
        c = rng.uniform(-0.7, 0.7, 3).astype(np.float32)
        r = np.float32(rng.uniform(0.1, 0.35))
        vol += np.exp(-((x - c[0]) ** 2 + (y - c[1]) ** 2 + (z - c[2]) ** 2) / (r * r))
    vol += np.float32(0.02) * rng.standard_normal(vol.shape).astype(np.float32)
    return vol


def flying_edges_seconds(vol, iso, repeats=3):
    import vtk
    from vtk.util import numpy_support

    img = vtk.vtkImageData()
    nz, ny, nx = vol.shape
    img.SetDimensions(nx, ny, nz)
    arr = numpy_support.numpy_to_vtk(vol.ravel(), deep=1)
    img.GetPointData().SetScalars(arr)
    fe = vtk.vtkFlyingEdges3D()
    fe.SetInputData(img)
    fe.ComputeNormalsOn()
    fe.SetValue(0, iso)
    fe.Update()
    count = fe.GetOutput().GetNumberOfPolys()  # at exactly `iso`, for the comparison
    best = None
    for k in range(repeats):
        fe.SetValue(0, iso + 1e-6 * (k + 1))  # force a re-execution
        t = time.perf_counter()
        fe.Update()
        dt = time.perf_counter() - t
        best = dt if best is None else min(best, dt)
    return best, count


def slide_memory(store, isovalues):
    """Memory of `isobar slide STORE` fed one isovalue at a time: after each update, its
    own memory (anonymous resident pages: the slider's maps and lists, the allocator's
    heap) and the store's pages it has mapped (clean page cache, shared and reclaimable:
    the kernel maps whole folios, up to 2 MiB here, around each value read), then the
    peak RSS of the whole run (VmHWM, both kinds and the program's own code)."""
    proc = subprocess.Popen(
        [str(CLI), "slide", str(store)],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )

    def status():
        fields = {}
        for line in Path(f"/proc/{proc.pid}/status").read_text().splitlines():
            key, _, value = line.partition(":")
            if value.strip().endswith("kB"):
                fields[key] = int(value.split()[0]) / 1024
        return fields

    def store_mib():
        kib, in_store = 0, False
        for line in Path(f"/proc/{proc.pid}/smaps").read_text().splitlines():
            head = line.split()
            if "-" in head[0] and ":" not in head[0]:
                in_store = len(head) >= 6 and Path(head[5]) == Path(store).resolve()
            elif in_store and head[0] == "Rss:":
                kib += int(head[1])
        return kib / 1024

    after = []
    for iso in isovalues:
        proc.stdin.write(f"{iso}\n")
        proc.stdin.flush()
        line = proc.stdout.readline().split()
        s = status()
        after.append(
            {
                "isovalue": iso,
                "triangles": int(line[line.index("triangles") + 1]),
                "held_mib": float(line[line.index("held_mib") + 1]),
                "own_mib": s["RssAnon"],
                "store_pages_mib": store_mib(),
            }
        )
    peak = status()["VmHWM"]
    proc.stdin.close()
    proc.wait()
    return {"after_updates": after, "peak_rss_mib": peak}


def run(name, vol, out, start_fraction):
    npy = out / f"{name}.npy"
    np.save(npy, vol)
    store = out / f"{name}.isoslider"
    t = time.perf_counter()
    subprocess.run([str(CLI), "slide-build", "--quiet", str(npy), "-o", str(store)], check=True)
    build_s = time.perf_counter() - t
    lo, hi = float(vol.min()), float(vol.max())
    rng = hi - lo
    start = lo + start_fraction * rng
    slider = isobar.Slider(store)
    first = slider.set_isovalue(start)
    rows = []
    for pct in (0.1, 1.0, 5.0, 10.0):
        step = pct / 100 * rng
        times, walls, tris, isos = [], [], [], []
        iso = start
        slider.set_isovalue(iso)
        for k in range(6):  # up and back: +step, +step, +step, -step, -step, -step
            iso += step if k < 3 else -step
            t = time.perf_counter()
            u = slider.set_isovalue(iso)
            walls.append(time.perf_counter() - t)
            times.append(u.seconds)
            tris.append(len(u.triangles))
            isos.append(iso)
        fe, fe_tris = flying_edges_seconds(vol, isos[0])
        rows.append(
            {
                "change_pct": pct,
                "slider_update_ms_mean": 1e3 * float(np.mean(times)),
                "slider_update_ms_max": 1e3 * float(np.max(times)),
                "slider_update_ms_median": 1e3 * float(np.median(times)),
                # The Python call: the update plus computing and copying V, N and I.
                "slider_with_arrays_ms_median": 1e3 * float(np.median(walls)),
                "flying_edges_ms": 1e3 * fe,
                "speedup_mean": fe / float(np.mean(times)),
                "triangles_slider": tris[0],
                "triangles_flying_edges": fe_tris,
            }
        )
    slider.close()
    # Resident memory of a separate `isobar slide` process over the same isovalues.
    memory = slide_memory(store, [start + s * rng for s in (0, 0.001, 0.01, 0.05, 0.1, 0.05, 0)])
    return {
        "volume": name,
        "dims": list(vol.shape[::-1]),
        "volume_bytes": int(vol.nbytes),
        "store_bytes": store.stat().st_size,
        "store_over_volume": store.stat().st_size / vol.nbytes,
        "build_s": build_s,
        "start_iso": start,
        "start_triangles": len(first.triangles),
        "slide_peak_rss_mib": memory["peak_rss_mib"],
        "rss_over_volume": memory["peak_rss_mib"] * 2**20 / vol.nbytes,
        "slide_memory_after_updates": memory["after_updates"],
        "own_over_volume_max": max(m["own_mib"] for m in memory["after_updates"])
        * 2**20
        / vol.nbytes,
        "rows": rows,
    }


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--size", type=int, default=256)
    ap.add_argument("--out", type=Path, default=REPO / "out" / "bench-slider")
    args = ap.parse_args()
    args.out.mkdir(parents=True, exist_ok=True)
    results = []
    for name, make, frac in (("mni152", mni, 0.35), ("gaussians", synthetic, 0.3)):
        vol = make(args.size)
        r = run(name, vol, args.out, frac)
        results.append(r)
        print(json.dumps(r, indent=1), flush=True)
    (args.out / "results.json").write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
