"""NumPy reading an N x k .npy step as a particle reader needs it: positions and the selected
columns as contiguous float64 arrays (np.load with mmap_mode, then a copy of each column),
and np.load of the whole array; best of R runs, beside `cargo bench --bench read_step`.

    python3 benches/peers/npy_read.py FILE [R] [COLUMN...]    # columns default: 3
"""
import sys
import time

import numpy as np

path = sys.argv[1]
runs = int(sys.argv[2]) if len(sys.argv) > 2 else 9
columns = [int(c) for c in sys.argv[3:]] or [3]


def best(f):
    t_best = float("inf")
    for _ in range(runs):
        t = time.perf_counter()
        f()
        t_best = min(t_best, time.perf_counter() - t)
    return t_best


def selected():
    a = np.load(path, mmap_mode="r")
    return [np.ascontiguousarray(a[:, c], dtype=np.float64) for c in (0, 1, 2, *columns)]


print(f"| {path} | numpy: mmap + x, y, z, cols {columns} as float64 | {1e3 * best(selected):.2f} ms |")
print(f"| {path} | numpy: np.load, whole array | {1e3 * best(lambda: np.load(path)):.2f} ms |")
