"""Writes tests/data/vtk_written.vtu with VTK's own XML writer at its defaults (VTK 9.7:
appended data, base64-encoded, zlib-compressed in 32 KiB blocks, UInt32 headers).

    python3 -m venv /tmp/v && /tmp/v/bin/pip install vtk
    /tmp/v/bin/python tests/data/write_vtk_fixture.py tests/data/vtk_written.vtu [N]

4100 particles by default (so each array spans several compressed blocks), off the origin in
double precision, one vertex cell each, with point arrays of several types (Float64 density,
Int64 id, UInt8 kind, Float32 3-vector velocity), a cell array and field data;
tests/readers.rs knows the formulas below.
"""
import sys

import vtk

path = sys.argv[1]
n = int(sys.argv[2]) if len(sys.argv) > 2 else 4100

points = vtk.vtkPoints()
points.SetDataTypeToDouble()
density = vtk.vtkDoubleArray()
density.SetName("density")
ids = vtk.vtkTypeInt64Array()
ids.SetName("id")
kind = vtk.vtkUnsignedCharArray()
kind.SetName("kind")
velocity = vtk.vtkFloatArray()
velocity.SetName("velocity")
velocity.SetNumberOfComponents(3)
for i in range(n):
    points.InsertNextPoint(1.0e6 + 0.1 * i, -2.5e5 + 1.0 / 7.0, 1e-3 * i)
    density.InsertNextValue(1.0 / 3.0 + i * 1e-9)
    ids.InsertNextValue(i * 1000000007)
    kind.InsertNextValue(i % 3)
    velocity.InsertNextTuple3(i, -i, 0.5)

grid = vtk.vtkUnstructuredGrid()
grid.SetPoints(points)
for i in range(n):
    grid.InsertNextCell(vtk.VTK_VERTEX, 1, [i])
for array in (density, ids, kind, velocity):
    grid.GetPointData().AddArray(array)
cell_id = vtk.vtkIntArray()
cell_id.SetName("cell_id")
for i in range(n):
    cell_id.InsertNextValue(i)
grid.GetCellData().AddArray(cell_id)
time = vtk.vtkDoubleArray()
time.SetName("TimeValue")
time.InsertNextValue(0.25)
grid.GetFieldData().AddArray(time)

writer = vtk.vtkXMLUnstructuredGridWriter()
writer.SetFileName(path)
writer.SetInputData(grid)
if not writer.Write():
    sys.exit("VTK could not write " + path)
