"""The benchmark's update rows through `isobar slide`, several builds interleaved: the
same isovalue sequence as bench_slider.py (the start, then per row three steps up and
three down of 0.1 %, 1 %, 5 %, 10 % of the value range), fed to each build's `isobar
slide STORE` in turn, N times; prints per build and row the median over runs of each
run's median update time (and the fastest run's).

    python3 bench/slider/rows.py VOLUME.npy START_FRACTION N BUILD:STORE...

VOLUME.npy and the stores as bench_slider.py leaves them in its --out folder (a store
per build where the store format differs); START_FRACTION 0.35 for mni152, 0.3 for
gaussians. Needs numpy.
"""

import statistics
import subprocess
import sys
import tempfile

import numpy as np

PCTS = (0.1, 1.0, 5.0, 10.0)


def sequence(npy, start_fraction):
    vol = np.load(npy, mmap_mode="r")
    lo, hi = float(vol.min()), float(vol.max())
    rng = hi - lo
    start = lo + start_fraction * rng
    isos = [start]
    for pct in PCTS:
        iso = start
        isos.append(iso)
        for k in range(6):
            iso += pct / 100 * rng if k < 3 else -pct / 100 * rng
            isos.append(iso)
    return isos


def main():
    npy, start_fraction, runs, builds = sys.argv[1], float(sys.argv[2]), int(sys.argv[3]), sys.argv[4:]
    with tempfile.NamedTemporaryFile("w", suffix=".txt") as seq:
        seq.write("".join(f"{v!r}\n" for v in sequence(npy, start_fraction)))
        seq.flush()
        rows = {b: [[] for _ in PCTS] for b in builds}
        for _ in range(runs):
            for b in builds:
                cli, store = b.split(":", 1)
                with open(seq.name) as stdin:
                    out = subprocess.run([cli, "slide", store], stdin=stdin, capture_output=True, text=True, check=True)
                # `update_ms` is the eighth field of each line; line 0 is the first surface,
                # then per row its start (not timed) and six steps.
                ms = [float(line.split()[7]) for line in out.stdout.splitlines() if line.strip()]
                for r in range(len(PCTS)):
                    rows[b][r].append(statistics.median(ms[2 + 7 * r : 8 + 7 * r]))
    for b in builds:
        cells = (f"{p} %: {statistics.median(t):.2f} (min {min(t):.2f})" for p, t in zip(PCTS, rows[b]))
        print(b.split(":", 1)[0], " ".join(cells))


if __name__ == "__main__":
    main()
