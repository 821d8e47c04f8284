"""Pieces of a data-parallel run: a shared lattice plus clip boxes through the C ABI."""

import numpy as np

import isobar


def test_two_clipped_pieces_on_a_lattice_make_the_whole_surface(dam_break_path):
    particles = isobar.Particles.read(dam_break_path)
    cell = 0.375 * 0.05
    common = dict(h=0.05, lattice=(0.001, -0.002, 0.003, cell), trim=None)
    whole = isobar.extract(particles, 0.6, **common)
    x = particles.positions[:, 0]
    split = float(np.median(x))
    far = 100.0
    left = isobar.extract(particles, 0.6, clip=((-far, -far, -far), (split, far, far)), **common)
    right = isobar.extract(particles, 0.6, clip=((split, -far, -far), (far, far, far)), **common)
    assert len(left.triangles) > 1000 and len(right.triangles) > 1000
    assert len(left.triangles) + len(right.triangles) == len(whole.triangles)

    def corners(s):
        return np.sort(np.sort(s.points[s.triangles].reshape(-1, 9), axis=1), axis=0)

    joined = np.sort(np.vstack([corners(left), corners(right)]), axis=0)
    assert np.array_equal(joined, corners(whole))


def test_lattice_changes_the_grid_and_keeps_vertices_exact(dam_break_path):
    particles = isobar.Particles.read(dam_break_path)
    a = isobar.extract(particles, 0.6, h=0.05, grid_factor=0.375, trim=None)
    b = isobar.extract(particles, 0.6, h=0.05, lattice=(0.0042, 0.0, 0.0, 0.375 * 0.05), trim=None)
    assert not np.array_equal(a.points[:10], b.points[:10])
    assert b.stats["unconverged_vertices"] == 0
