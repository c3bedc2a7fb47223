"""h5py reading the datasets `aarbf` reads for one step of a 4M-particle gas snapshot
(Coordinates f64 N x 3, Temperatures f32), best of 5, on the files it writes first:
uncompressed, and chunked with gzip + shuffle (h5py's defaults for both).

    python benches/peers/hdf5_read.py /tmp/big   # writes /tmp/big_raw.hdf5, /tmp/big_gz.hdf5
    cargo bench --profile checked --bench read_step -- --runs 5 --attribute Temperatures \\
        /tmp/big_raw.hdf5 /tmp/big_gz.hdf5

With --existing it only times the reads of files it wrote before (for rounds that alternate
with aarbf's bench on the same files): python benches/peers/hdf5_read.py --existing /tmp/big

Needs numpy and h5py (pip install numpy h5py).
"""
import sys
import time

import h5py
import numpy as np

args = sys.argv[1:]
existing = "--existing" in args
args = [a for a in args if a != "--existing"]
prefix = args[0] if args else "/tmp/big"
n = 4_000_000
rng = np.random.default_rng(0)
x = None if existing else rng.random((n, 3))
temperatures = None if existing else rng.random(n).astype(np.float32)
for name, options in [("raw", {}), ("gz", dict(compression="gzip", shuffle=True, chunks=True))]:
    path = f"{prefix}_{name}.hdf5"
    if not existing:
        with h5py.File(path, "w") as f:
            header = f.create_group("Header")
            counts = np.array([n, 0, 0, 0, 0, 0], np.uint64)
            header.attrs["NumPart_ThisFile"] = counts
            header.attrs["NumPart_Total"] = counts
            gas = f.create_group("PartType0")
            gas.create_dataset("Coordinates", data=x, **options)
            gas.create_dataset("Temperatures", data=temperatures, **options)
    best = float("inf")
    for _ in range(5):
        t = time.perf_counter()
        with h5py.File(path, "r") as f:
            f["PartType0/Coordinates"][:]
            f["PartType0/Temperatures"][:]
        best = min(best, time.perf_counter() - t)
    print(f"h5py {path}: best of 5 {best * 1e3:.1f} ms")
