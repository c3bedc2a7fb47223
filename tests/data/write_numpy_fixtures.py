"""Writes the NumPy-made fixtures tests/readers.rs reads (run from the repository root):

    python3 tests/data/write_numpy_fixtures.py      # needs numpy

- numpy_fortran_be.npy: 1001 particles x 5 columns, big-endian float64, Fortran order (as
  numpy.asfortranarray(a).astype('>f8') writes), positions 1e6 from the origin;
- numpy_int64.npy: 7 x 4 int64 (NumPy's default integer type);
- numpy_struct_be.ply: the same 1001 particles as a binary big-endian PLY written from a
  structured array (x, y, z float64, density float32, flag uchar, id int32: fixed-size rows);
- numpy_particles.csv: the same particles as text with every digit (repr), to compare with.
"""
import numpy as np

rng = np.random.default_rng(20261202)
n = 1001
xyz = 1.0e6 + rng.random((n, 3)) * 1e-3
density = rng.random(n) * 3.0
temperature = rng.standard_normal(n) * 1e4
a = np.column_stack([xyz, density, temperature])
np.save("tests/data/numpy_fortran_be.npy", np.asfortranarray(a).astype(">f8"))
np.save("tests/data/numpy_int64.npy", np.arange(28).reshape(7, 4) * 1000003)

rows = np.zeros(n, dtype=[("x", ">f8"), ("y", ">f8"), ("z", ">f8"), ("density", ">f4"),
                          ("flag", "u1"), ("id", ">i4")])
rows["x"], rows["y"], rows["z"] = xyz[:, 0], xyz[:, 1], xyz[:, 2]
rows["density"] = density.astype(np.float32)
rows["flag"] = np.arange(n) % 7
rows["id"] = np.arange(n) * -3
header = ("ply\nformat binary_big_endian 1.0\ncomment written by numpy\n"
          f"element vertex {n}\nproperty double x\nproperty double y\nproperty double z\n"
          "property float density\nproperty uchar flag\nproperty int id\nend_header\n")
with open("tests/data/numpy_struct_be.ply", "wb") as f:
    f.write(header.encode())
    f.write(rows.tobytes())

with open("tests/data/numpy_particles.csv", "w") as f:
    f.write("x,y,z,density,temperature,density32,flag,id\n")
    for i in range(n):
        f.write(",".join(repr(float(v)) for v in (*xyz[i], density[i], temperature[i],
                                                   np.float32(density[i]), i % 7, -3 * i)))
        f.write("\n")
