"""sarracen's SPH grid interpolation against `aarbf field --grid --kernel sph-cubic` on the same
particles, for a side-by-side throughput figure and a statement of agreement (docs/benchmarks.md,
"Against other tools").

    python3 -m venv /tmp/sarracen && /tmp/sarracen/bin/pip install sarracen scikit-learn
    aarbf generate uniform --count 1000000 --format npy --out /tmp/u1m
    /tmp/sarracen/bin/python benches/peers/sarracen_sph_grid.py make /tmp/u1m/uniform_0000.npy /tmp/sph1m.npy
    aarbf field --data /tmp/sph1m.npy --grid 100 --kernel sph-cubic --radius-attribute col4 \\
        --mass col5 --density col6 --attribute col3 --backend cpu --out /tmp/sph-grid.npy --force
    /tmp/sarracen/bin/python benches/peers/sarracen_sph_grid.py time /tmp/sph1m.npy 100 /tmp/sph-grid.npy

`make` turns an N x 4 .npy (x, y, z, attribute, as `aarbf generate --format npy` writes it)
into the N x 7 array both sides read: x, y, z, A, h, m, rho, with h from the particles' own
spacing as an SPH code sets it (h = 1.2 (m / rho)^(1/3), about 58 neighbours within 2h), equal
masses summing to 1 and rho = 1 / V over the bounding box, perturbed by 10% so that every
particle has its own volume m / rho. `time` runs sarracen's `interpolate_3d_grid` (cubic
spline, support 2h, `normalize=True`: the sum over m/rho A W divided by the sum over m/rho W,
what aarbf's Theta is) over the particles' bounding box with cell-centred points, as `aarbf
field --grid` samples; the first call compiles numba's code on a small subset and is not
timed, then `REPEATS` calls (default 2) are timed. Given aarbf's output, it states the
agreement: the largest relative difference of Theta where aarbf's Phi is above 1e-3 of its
maximum, and of Phi (sarracen with `normalize=False` on a column of ones, once, untimed).
"""

import statistics
import sys
import time

import numba
import numpy as np
import pandas as pd
import sarracen
from sarracen.interpolate import interpolate_3d_grid


def make(src: str, dst: str) -> None:
    p = np.load(src)
    n = len(p)
    lo, hi = p[:, :3].min(axis=0), p[:, :3].max(axis=0)
    rng = np.random.default_rng(7)
    m = np.full(n, 1.0 / n)
    rho = 1.0 / np.prod(hi - lo) * (1.0 + 0.1 * (rng.random(n) - 0.5))
    h = 1.2 * np.cbrt(m / rho)
    out = np.column_stack([p[:, :4], h, m, rho]).astype(np.float64)
    np.save(dst, out)
    print(f"{n} particles, h {h.min():.6g}..{h.max():.6g} -> {dst}")


def frame(p: np.ndarray) -> "sarracen.SarracenDataFrame":
    return sarracen.SarracenDataFrame(
        pd.DataFrame(
            {
                "x": p[:, 0],
                "y": p[:, 1],
                "z": p[:, 2],
                "A": p[:, 3],
                "h": p[:, 4],
                "m": p[:, 5],
                "rho": p[:, 6],
                "one": np.ones(len(p)),
            }
        )
    )


def time_it(path: str, g: int, aarbf_out: str | None, repeats: int) -> None:
    p = np.load(path)
    lo, hi = p[:, :3].min(axis=0), p[:, :3].max(axis=0)
    limits = dict(
        xlim=(lo[0], hi[0]), ylim=(lo[1], hi[1]), zlim=(lo[2], hi[2]),
        x_pixels=g, y_pixels=g, z_pixels=g,
    )
    sdf = frame(p)
    interpolate_3d_grid(frame(p[:1000]), "A", normalize=True, backend="cpu", **limits)
    times = []
    for _ in range(repeats):
        started = time.perf_counter()
        theta = interpolate_3d_grid(sdf, "A", normalize=True, backend="cpu", **limits)
        times.append(time.perf_counter() - started)
    print(
        f"sarracen {sarracen.__version__}: {len(p)} particles onto {g}^3, "
        f"{numba.get_num_threads()} threads: median {statistics.median(times):.3f} s "
        f"of {', '.join(f'{t:.3f}' for t in times)} s"
    )
    if aarbf_out is None:
        return
    phi = interpolate_3d_grid(sdf, "one", normalize=False, backend="cpu", **limits)
    a = np.load(aarbf_out).reshape(g, g, g, -1)  # z, y, x, (Phi, Theta)
    a_phi, a_theta = a[..., 0], a[..., 1]
    keep = a_phi > 1e-3 * a_phi.max()
    d_phi = np.abs(phi[keep] / a_phi[keep] - 1.0).max()
    d_theta = np.abs(theta[keep] / a_theta[keep] - 1.0).max()
    print(
        f"agreement where Phi > 1e-3 of its maximum ({keep.sum()} of {keep.size} points): "
        f"Phi {d_phi:.2e}, Theta {d_theta:.2e} largest relative difference"
    )


def main() -> None:
    if len(sys.argv) >= 4 and sys.argv[1] == "make":
        make(sys.argv[2], sys.argv[3])
    elif len(sys.argv) >= 4 and sys.argv[1] == "time":
        out = sys.argv[4] if len(sys.argv) > 4 else None
        repeats = int(sys.argv[5]) if len(sys.argv) > 5 else 2
        time_it(sys.argv[2], int(sys.argv[3]), out, repeats)
    else:
        sys.exit(__doc__)


if __name__ == "__main__":
    main()
