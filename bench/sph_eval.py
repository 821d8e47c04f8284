"""Independent reference evaluator of the SPH sum of weights, in numpy + scipy only.

    S(x) = sum_j V_j W(|x - x_j|, h),   V_j = 1 / sum_k W(|x_j - x_k|, h)

with the cubic spline W(r, h) = 1/(pi h^3) * {1 - 1.5 q^2 + 0.75 q^3 (q < 1),
0.25 (2 - q)^3 (1 <= q < 2), 0 otherwise}, q = r / h. This is splashsurf's level-set
function (equal masses, each particle's own SPH density). It shares no code with isobar,
so it can judge every method, isobar included.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

# Points per neighbour query: bounds the (point, particle) pair list to a few hundred MB.
CHUNK = 50_000


def cubic_kernel(r: np.ndarray, h: float) -> np.ndarray:
    """The 3-D cubic spline kernel (support 2h) at distances `r`."""
    q = r / h
    near = 1.0 - 1.5 * q**2 + 0.75 * q**3
    far = 0.25 * np.clip(2.0 - q, 0.0, None) ** 3
    return np.where(q < 1.0, near, far) / (np.pi * h**3)


class SumOfWeights:
    """S(x) for fixed particles and smoothing length h."""

    def __init__(self, positions: np.ndarray, h: float):
        self.h = h
        self.tree = cKDTree(positions)
        self.volumes = 1.0 / self._kernel_sums(positions, np.ones(len(positions)))

    def __call__(self, points: np.ndarray) -> np.ndarray:
        return self._kernel_sums(points, self.volumes)

    def _kernel_sums(self, points: np.ndarray, weights: np.ndarray) -> np.ndarray:
        """sum_j weights_j W(|p - x_j|, h) for every point p, in chunks."""
        out = np.empty(len(points))
        for start in range(0, len(points), CHUNK):
            chunk = points[start : start + CHUNK]
            # The 'ndarray' output keeps zero distances, so a particle counts itself.
            pairs = cKDTree(chunk).sparse_distance_matrix(
                self.tree, 2.0 * self.h, output_type="ndarray"
            )
            contrib = weights[pairs["j"]] * cubic_kernel(pairs["v"], self.h)
            out[start : start + len(chunk)] = np.bincount(
                pairs["i"], weights=contrib, minlength=len(chunk)
            )
        return out


def sample_vertices(vertices: np.ndarray, limit: int, seed: int = 0) -> np.ndarray:
    """At most `limit` vertices, a fixed random subset when there are more."""
    if len(vertices) <= limit:
        return vertices
    rng = np.random.default_rng(seed)
    return vertices[rng.choice(len(vertices), size=limit, replace=False)]


def edge_use_counts(triangles: np.ndarray) -> np.ndarray:
    """How many triangles use each distinct undirected edge."""
    tri = triangles.astype(np.int64)
    edges = np.concatenate([tri[:, [0, 1]], tri[:, [1, 2]], tri[:, [2, 0]]])
    edges.sort(axis=1)
    keys = edges[:, 0] * (int(tri.max(initial=0)) + 1) + edges[:, 1]
    return np.unique(keys, return_counts=True)[1]


def closedness(triangles: np.ndarray) -> dict:
    """Edges used once (holes) and more than twice (non-manifold); closed if neither."""
    counts = edge_use_counts(triangles)
    open_edges = int(np.count_nonzero(counts == 1))
    nonmanifold = int(np.count_nonzero(counts > 2))
    return {
        "closed": len(triangles) > 0 and open_edges == 0 and nonmanifold == 0,
        "open_edges": open_edges,
        "nonmanifold_edges": nonmanifold,
    }
