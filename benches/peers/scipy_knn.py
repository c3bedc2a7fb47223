"""SciPy's k-d tree on the smoothing-length query of `benches/knn.rs`: N points uniform in the
unit cube, h = the distance to the K-th nearest other point (`query(k=K + 1)`: the point
itself comes first), every core (`workers=-1`), the tree's build included; best of R runs.

    python benches/peers/scipy_knn.py [N] [K] [R]     (defaults: 1000000 32 3)

Needs numpy and scipy (pip install numpy scipy).
"""
import sys
import time

import numpy as np
from scipy.spatial import cKDTree

n = int(sys.argv[1]) if len(sys.argv) > 1 else 1_000_000
k = int(sys.argv[2]) if len(sys.argv) > 2 else 32
runs = int(sys.argv[3]) if len(sys.argv) > 3 else 3
x = np.random.default_rng(1).random((n, 3))
best = float("inf")
for _ in range(runs):
    t = time.perf_counter()
    d, _ = cKDTree(x).query(x, k=k + 1, workers=-1)
    h = d[:, -1]
    best = min(best, time.perf_counter() - t)
print(f"scipy cKDTree: {n} points, K = {k}: best of {runs} {best * 1e3:.0f} ms (mean h {h.mean():.5f})")
