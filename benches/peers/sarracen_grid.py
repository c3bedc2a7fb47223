"""sarracen's grid interpolation on the same particles as `aarbf field --grid`, for a side-by-side
throughput figure (docs/benchmarks.md, "Against other tools").

    python3 -m venv /tmp/sarracen && /tmp/sarracen/bin/pip install sarracen scikit-learn
    aarbf generate uniform --count 1000000 --format npy --out /tmp/u1m
    /tmp/sarracen/bin/python benches/peers/sarracen_grid.py /tmp/u1m/uniform_0000.npy 0.02285 100

The particles are an N x 4 .npy (x, y, z, attribute), as `aarbf generate --format npy` writes
them. `RADIUS` is aarbf's RBF radius: sarracen's cubic spline reaches 2h, so h = RADIUS / 2 and a
grid point sees the same particles in both. sarracen interpolates the attribute with
`normalize=True` (the sum and the kernel's normalisation: what aarbf's Phi and Theta are), over
the particles' bounding box with cell-centred points, as `aarbf field --grid` samples. The first
call compiles sarracen's numba code on a small subset and is not timed; then `REPEATS` calls
(default 3) are timed and their median printed with the threads numba used.
"""

import statistics
import sys
import time

import numba
import numpy as np
import pandas as pd
import sarracen
from sarracen.interpolate import interpolate_3d_grid


def frame(particles: np.ndarray, radius: float) -> "sarracen.SarracenDataFrame":
    sdf = sarracen.SarracenDataFrame(
        pd.DataFrame(
            {
                "x": particles[:, 0],
                "y": particles[:, 1],
                "z": particles[:, 2],
                "h": np.full(len(particles), radius / 2),
                "rho": np.ones(len(particles)),
                "A": particles[:, 3],
            }
        ),
        params={"mass": 1.0},
    )
    return sdf


def main() -> None:
    if len(sys.argv) < 4:
        sys.exit(__doc__)
    path, radius, g = sys.argv[1], float(sys.argv[2]), int(sys.argv[3])
    repeats = int(sys.argv[4]) if len(sys.argv) > 4 else 3
    particles = np.load(path)
    lo, hi = particles[:, :3].min(axis=0), particles[:, :3].max(axis=0)
    limits = dict(
        xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]),
        x_pixels=g, y_pixels=g, z_pixels=g,
    )
    sdf = frame(particles, radius)
    warm = frame(particles[:1000], radius)
    interpolate_3d_grid(warm, "A", normalize=True, backend="cpu", **limits)
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        grid = interpolate_3d_grid(sdf, "A", normalize=True, backend="cpu", **limits)
        times.append(time.perf_counter() - started)
    print(
        f"sarracen {sarracen.__version__}: {len(particles)} particles onto {g}^3, "
        f"{numba.get_num_threads()} threads: median {statistics.median(times):.3f} s "
        f"of {', '.join(f'{t:.3f}' for t in times)} s; mean value {np.nanmean(grid):.6f}"
    )


if __name__ == "__main__":
    main()
