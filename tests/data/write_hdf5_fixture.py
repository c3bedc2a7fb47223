"""Writes two small SWIFT-like snapshots with h5py, laid out as SWIFT lays them out (Header,
Units, Cosmology and Code groups, PartType0 and PartType1, chunked gzip + shuffle datasets,
fixed-length string and 1-element array attributes as SWIFT writes them), for the HDF5
reader's test of a file written by another program (tests/hdf5_snapshots.rs):

    python3 -m venv /tmp/h5v && /tmp/h5v/bin/pip install h5py numpy
    /tmp/h5v/bin/python tests/data/write_hdf5_fixture.py [tests/data/h5py_swift]

snap_0000.hdf5: 203 gas, 50 dark matter; snap_0001.hdf5: 197 gas, 50 dark matter.
Gas particle i: position (0.01 i, 0.5, 0.25 + 0.001 i) float64, Temperatures 1e4 + i,
SmoothingLengths 0.05, Velocities (i, -i, 0), Masses 1, Densities 1 + i / 100 (float32).
"""
import os
import sys

import h5py
import numpy as np

root = sys.argv[1] if len(sys.argv) > 1 else "tests/data/h5py_swift"
os.makedirs(root, exist_ok=True)


def arr(values, dtype):
    return np.array(values, dtype=dtype)


def write(path, n_gas, n_dm, time):
    with h5py.File(path, "w", track_order=True) as f:
        h = f.create_group("Header")
        counts = arr([n_gas, n_dm, 0, 0, 0, 0, 0], np.uint64)
        h.attrs["NumPart_ThisFile"] = counts
        h.attrs["NumPart_Total"] = counts
        h.attrs["NumPart_Total_HighWord"] = arr([0] * 7, np.uint64)
        h.attrs["NumFilesPerSnapshot"] = arr([1], np.int32)
        h.attrs["BoxSize"] = arr([3.0, 3.0, 3.0], np.float64)
        h.attrs["Time"] = arr([time], np.float64)
        h.attrs["Redshift"] = arr([0.0], np.float64)
        h.attrs["Scale-factor"] = arr([1.0], np.float64)
        h.attrs["Code"] = np.bytes_("SWIFT")
        f.create_group("Code").attrs["Code"] = np.bytes_("SWIFT")
        u = f.create_group("Units")
        u.attrs["Unit length in cgs (U_L)"] = arr([3.08567758e21], np.float64)
        u.attrs["Unit mass in cgs (U_M)"] = arr([1.98841e43], np.float64)
        u.attrs["Unit time in cgs (U_t)"] = arr([3.08567758e16], np.float64)
        c = f.create_group("Cosmology")
        c.attrs["Cosmological run"] = arr([0], np.int32)
        c.attrs["h"] = arr([0.7], np.float64)

        i = np.arange(n_gas)
        gas = f.create_group("PartType0")
        opts = dict(compression="gzip", shuffle=True, chunks=(64,))
        xyz = np.stack([0.01 * i, np.full(n_gas, 0.5), 0.25 + 0.001 * i], axis=1)
        gas.create_dataset("Coordinates", data=xyz, compression="gzip", shuffle=True, chunks=(64, 3))
        gas.create_dataset("Temperatures", data=(1e4 + i).astype(np.float32), **opts)
        gas.create_dataset("SmoothingLengths", data=np.full(n_gas, 0.05, np.float32), **opts)
        v = np.stack([i, -i, np.zeros(n_gas)], axis=1).astype(np.float32)
        gas.create_dataset("Velocities", data=v, compression="gzip", shuffle=True, chunks=(64, 3))
        gas.create_dataset("Masses", data=np.ones(n_gas, np.float32))
        gas.create_dataset("Densities", data=(1 + i / 100).astype(np.float32), **opts)
        for name in gas:
            gas[name].attrs["a-scale exponent"] = arr([1.0 if name in ("Coordinates", "SmoothingLengths") else 0.0], np.float32)
        dm = f.create_group("PartType1")
        j = np.arange(n_dm)
        dm.create_dataset("Coordinates", data=np.stack([j * 0.05, j * 0.01, j * 0.02], axis=1))
        dm.create_dataset("Masses", data=np.full(n_dm, 5.0))


write(os.path.join(root, "snap_0000.hdf5"), 203, 50, 0.0)
write(os.path.join(root, "snap_0001.hdf5"), 197, 50, 0.25)
