"""Peak memory of the writer does not grow with the number of frames: 200 frames (the same
real frame repeated through symlinks frame_0001..0200) cost what 10 do."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from conftest import CLI_DAM, FRAME_01, link_frames

#: Runs the command line in this interpreter and prints its peak RSS (KiB) last: VmHWM,
#: the high-water mark of this process's own memory. (ru_maxrss is not that: Linux keeps
#: it across execve, and Python starts subprocesses with vfork, so a child's ru_maxrss is
#: at least the RSS of the process that started it: the whole pytest process here.)
WRAPPER = """
import resource, sys
from isobar_usd.cli import main
rc = main(sys.argv[1:])
hwm = [l for l in open("/proc/self/status") if l.startswith("VmHWM:")][0].split()[1]
print("MAXRSS_KIB", hwm, resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, file=sys.stderr)
sys.exit(rc)
"""

#: What holding every frame would add: about 1.1 MB of USD arrays per frame of this data
#: (15,934 points, 31,860 triangles), 220 MB for 200; the slack allows a tenth of that.
SLACK_KIB = 24 * 1024


def peak_rss(frames_dir, out, count, *extra):
    proc = subprocess.run(
        [sys.executable, "-c", WRAPPER, "sph", str(frames_dir / "frame_####.vtk"), *CLI_DAM,
         "-o", str(out), "--frames", f"1-{count}", "-q", *extra],
        capture_output=True, text=True, timeout=900,
        env={**os.environ, "RAYON_NUM_THREADS": "2"},
    )
    assert proc.returncode == 0, proc.stderr
    line = [l for l in proc.stderr.splitlines() if l.startswith("MAXRSS_KIB")][-1]
    return int(line.split()[1])


@pytest.fixture(scope="module")
def frames_200(tmp_path_factory):
    return link_frames(tmp_path_factory.mktemp("mem") / "frames", {i: FRAME_01 for i in range(1, 201)})


def test_peak_memory_does_not_grow_with_frames(frames_200, tmp_path, record_property):
    import isobar_usd

    rss = {n: peak_rss(frames_200, tmp_path / f"seq{n}.usd", n, "--layout", "clips") for n in (1, 10, 200)}
    print(f"\npeak RSS of isobar-usd (clips): 1 frame {rss[1] / 1024:.1f} MiB, 10 frames {rss[10] / 1024:.1f} MiB, "
          f"200 frames {rss[200] / 1024:.1f} MiB")
    for n, v in rss.items():
        record_property(f"peak_rss_kib_{n}", v)
    assert isobar_usd.check(tmp_path / "seq200.usd", max_frames=3) == []
    assert len(list(isobar_usd.clips_folder(tmp_path / "seq200.usd").glob("seq200.*.usdc"))) == 200
    assert rss[200] <= rss[10] + SLACK_KIB, rss
    assert rss[10] <= rss[1] + 2 * SLACK_KIB, rss


def test_the_measure_sees_frames_held_in_memory(frames_200, tmp_path):
    """Control: the flat layout keeps every frame until the file is written; the same
    measure sees that growth, so the test above would see it too."""
    flat = {n: peak_rss(frames_200, tmp_path / f"flat{n}.usd", n, "--layout", "flat") for n in (10, 80)}
    print(f"\npeak RSS of isobar-usd (flat): 10 frames {flat[10] / 1024:.1f} MiB, 80 frames {flat[80] / 1024:.1f} MiB")
    assert flat[80] - flat[10] > 2 * SLACK_KIB, flat
