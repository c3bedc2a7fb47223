"""VTK's own reader against aarbf's on .vtu files VTK wrote (raw appended, zlib, its defaults):
positions and one point array read, the others left alone (VTK: SetPointArrayStatus; aarbf:
--attribute). Writes the files first if they are not there.

    python3 -m venv /tmp/v && /tmp/v/bin/pip install vtk numpy
    /tmp/v/bin/python benches/peers/vtk_read.py /tmp/vtkbig 1000000 3 kind
    aarbf bench playback --data /tmp/vtkbig --attribute kind --backend cpu --size 64x64
"""
import os
import sys
import time

import numpy as np
import vtk
from vtk.util import numpy_support

out, n, steps, array = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]
os.makedirs(out, exist_ok=True)
rng = np.random.default_rng(1)
for s in range(steps):
    path = os.path.join(out, f"step_{s:03d}.vtu")
    if os.path.exists(path):
        continue
    grid = vtk.vtkUnstructuredGrid()
    points = vtk.vtkPoints()
    points.SetData(numpy_support.numpy_to_vtk(rng.random((n, 3)) + 1000.0, deep=True))
    grid.SetPoints(points)
    arrays = {
        "density": rng.random(n),
        "id": np.arange(n, dtype=np.int64),
        "kind": (np.arange(n) % 3).astype(np.uint8),
        "velocity": rng.random((n, 3)).astype(np.float32),
        "pressure": rng.random(n),
        "temperature": rng.random(n).astype(np.float32),
    }
    for name, values in arrays.items():
        a = numpy_support.numpy_to_vtk(values, deep=True)
        a.SetName(name)
        grid.GetPointData().AddArray(a)
    writer = vtk.vtkXMLUnstructuredGridWriter()
    writer.SetFileName(path)
    writer.SetInputData(grid)
    writer.Write()

for s in range(steps):
    path = os.path.join(out, f"step_{s:03d}.vtu")
    reader = vtk.vtkXMLUnstructuredGridReader()
    reader.SetFileName(path)
    reader.UpdateInformation()
    for i in range(reader.GetNumberOfPointArrays()):
        name = reader.GetPointArrayName(i)
        reader.SetPointArrayStatus(name, 1 if name == array else 0)
    started = time.perf_counter()
    reader.Update()
    elapsed = time.perf_counter() - started
    got = reader.GetOutput().GetPointData().GetNumberOfArrays()
    print(f"VTK {vtk.vtkVersion.GetVTKVersion()}: {path}: {n} points + {got} array(s) in {elapsed:.3f} s")
