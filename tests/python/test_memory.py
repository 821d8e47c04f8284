"""Repeated create / extract / free cycles do not leak."""

import gc
import os

import numpy as np
import pytest

import isobar
from conftest import lattice

CYCLES = 1000
SLACK_MB = 20.0


def rss_mb():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024.0
    pytest.skip("no VmRSS in /proc/self/status")


def cycle(xyz, pressure, velocity, payload):
    # `payload` (64 values a particle, unused by the extraction) makes a leaked particle set
    # cost 64 kB, so that leaking either handle over 1000 cycles shows well above the slack.
    p = isobar.Particles.from_arrays(xyz, pressure=pressure, velocity=velocity, payload=payload)
    s = isobar.extract(p, 0.5, h=0.1, attributes=["velocity"], progress=lambda f, ph: None)
    n = s.n_triangles
    assert s.attributes["velocity"].shape == (s.n_points, 3)
    del s, p
    return n


def test_thousand_cycles_keep_rss_flat(record_property, capsys):
    xyz = lattice(5)
    pressure = np.linspace(0, 1, len(xyz))
    velocity = np.tile([1.0, 2.0, 3.0], (len(xyz), 1))
    payload = np.ones((len(xyz), 64))
    for _ in range(50):  # warm-up: allocator pools, thread pool, caches
        n0 = cycle(xyz, pressure, velocity, payload)
    gc.collect()
    before = rss_mb()
    for _ in range(CYCLES):
        assert cycle(xyz, pressure, velocity, payload) == n0
    gc.collect()
    after = rss_mb()
    record_property("rss_before_mb", before)
    record_property("rss_after_mb", after)
    with capsys.disabled():
        print(f"\nRSS over {CYCLES} cycles ({len(xyz)} particles, {n0} triangles each): "
              f"{before:.1f} MB -> {after:.1f} MB ({after - before:+.1f} MB), pid {os.getpid()}")
    assert after - before < SLACK_MB
