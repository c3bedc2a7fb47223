"""Writes three simulation output folders, laid out as the simulation codes lay them out, for
the series-detection tests (group a folder's files by name stem, take the largest group):

    python3 -m venv /tmp/fixv && /tmp/fixv/bin/pip install vtk numpy
    /tmp/fixv/bin/python tests/data/write_sph_folders.py [tests/data/sph_runs]

pysph_dam_break/  six fluid_NNNNN.vtp steps (VTK's vtkXMLPolyDataWriter at its defaults, Float64
                  points, one vertex cell each) of a collapsing 3D dam (z up, dx = 0.04), one
                  boundary.vtp (tank floor and two walls, array `kind` only), a JSON .info file
                  and a log; particle counts 960, 960, 960, 953, 953, 953.
swift_like/       four output_NNNN.csv snapshots (x,y,z,Density,Temperature,SmoothingLength,
                  %.17g, box side 100 offset to 1e4; 500, 503, 497, 511 rows) beside SWIFT's
                  text files, a dependency_graph_0.csv without coordinates and restart/.
gadget_like/      five snapshot_NNN.npy steps (float64, N x 5: x, y, z, mass, density;
                  1000, 1000, 998, 1003, 1001 rows), ics.npy (float32), restart_snapshot_003.npy,
                  GADGET-4's text logs and restartfiles/.

Everything is deterministic (fixed seeds, no time stamps in the files).
"""
import json
import os
import sys

import numpy as np
import vtk
from vtk.util import numpy_support

root = sys.argv[1] if len(sys.argv) > 1 else "tests/data/sph_runs"


def write_text(path, text):
    with open(path, "w", newline="\n") as f:
        f.write(text)


def mkdir(*parts):
    path = os.path.join(root, *parts)
    os.makedirs(path, exist_ok=True)
    return path


# ---------------------------------------------------------------- PySPH dam break (dump_vtk)

DX = 0.04
G = 9.81
RHO0 = 1000.0


def write_vtp(path, xyz, arrays):
    """Float64 points, one vertex cell per point, the given point arrays, VTK defaults."""
    n = len(xyz)
    points = vtk.vtkPoints()
    points.SetDataTypeToDouble()
    points.SetData(numpy_support.numpy_to_vtk(np.ascontiguousarray(xyz, dtype=np.float64), deep=1))
    verts = vtk.vtkCellArray()
    for i in range(n):
        verts.InsertNextCell(1)
        verts.InsertCellPoint(i)
    poly = vtk.vtkPolyData()
    poly.SetPoints(points)
    poly.SetVerts(verts)
    for name, values in arrays:
        array = numpy_support.numpy_to_vtk(np.ascontiguousarray(values), deep=1)
        array.SetName(name)
        poly.GetPointData().AddArray(array)
    writer = vtk.vtkXMLPolyDataWriter()
    writer.SetFileName(path)
    writer.SetInputData(poly)
    if not writer.Write():
        sys.exit("VTK could not write " + path)


def pysph():
    out = mkdir("pysph_dam_break")
    # Fluid block: 10 x 8 x 12 particles on a cubic lattice of spacing DX from (0.02, 0.02, 0.02),
    # z fastest, with a deterministic jitter of 1e-6.
    nx, ny, nz = 10, 8, 12
    i, j, k = np.meshgrid(np.arange(nx), np.arange(ny), np.arange(nz), indexing="ij")
    base = np.stack([0.02 + i.ravel() * DX, 0.02 + j.ravel() * DX, 0.02 + k.ravel() * DX], axis=1)
    base += np.random.default_rng(20240611).uniform(-1e-6, 1e-6, base.shape)
    n0 = len(base)
    lo, hi = base.min(axis=0), base.max(axis=0)
    rel = (base - lo) / (hi - lo)  # 0..1 in each direction

    dt = 2e-3
    iterations = [0, 37, 74, 120, 171, 230]  # iteration counts, uneven output gaps
    ax, az = 3.0, 2.0  # collapse: front runs along +x, the top sinks (gravity along -z)
    steps = []
    for n_iter in iterations:
        t = n_iter * dt
        fx = (0.5 + rel[:, 0]) * (1.0 - 0.5 * rel[:, 2])
        fz = rel[:, 2]
        xyz = base.copy()
        xyz[:, 0] += 0.5 * ax * t * t * fx
        xyz[:, 2] -= 0.5 * az * t * t * fz
        vel = np.zeros_like(xyz)
        vel[:, 0] = ax * t * fx
        vel[:, 2] = -az * t * fz + 0.0  # no -0.0 at t = 0
        vel[:, 1] = 1e-3 * t * np.sin(7.0 * base[:, 0] + 3.0 * base[:, 2])
        steps.append((n_iter, xyz, vel))

    # Pressure: a per-step offset plus hydrostatic variation below the free surface; the
    # offsets rise linearly so the whole series spans -13800 .. 22800 Pa.
    p_min, p_max = -13800.0, 22800.0
    last_depth = RHO0 * G * (steps[-1][1][:, 2].max() - steps[-1][1][:, 2].min())
    offsets = np.linspace(p_min, p_max - last_depth, len(steps))
    for step, ((n_iter, xyz, vel), offset) in enumerate(zip(steps, offsets)):
        n = n0 - 7 if step >= 3 else n0  # outflow: the last 7 particles leave from step 3 on
        xyz, vel = xyz[:n], vel[:n]
        p = offset + RHO0 * G * (xyz[:, 2].max() - xyz[:, 2])
        rho = RHO0 + p / 5000.0
        m = np.full(n, RHO0 * DX ** 3)
        h = np.full(n, 1.3 * DX)
        write_vtp(os.path.join(out, "fluid_%05d.vtp" % n_iter), xyz,
                  [("rho", rho), ("p", p), ("vel", vel), ("m", m), ("h", h)])

    # Boundary: a floor of 30 x 10 particles at z = 0 and two walls (x = 0 and x = 1.2) of
    # 10 x 15 particles each, same spacing; kind 1 = floor, 2 = wall.
    fi, fj = np.meshgrid(np.arange(30), np.arange(10), indexing="ij")
    floor = np.stack([0.02 + fi.ravel() * DX, 0.02 + fj.ravel() * DX, np.zeros(fi.size)], axis=1)
    wj, wk = np.meshgrid(np.arange(10), np.arange(15), indexing="ij")
    walls = [np.stack([np.full(wj.size, x), 0.02 + wj.ravel() * DX, 0.02 + wk.ravel() * DX], axis=1)
             for x in (0.0, 1.2)]
    boundary = np.concatenate([floor] + walls)
    kind = np.concatenate([np.full(len(floor), 1, np.uint8), np.full(2 * len(walls[0]), 2, np.uint8)])
    write_vtp(os.path.join(out, "boundary.vtp"), boundary, [("kind", kind)])

    info = {"fname": "dam_break_3d", "output_dir": "dam_break_3d_output", "dt": dt,
            "tf": iterations[-1] * dt, "n_output": len(iterations), "completed": True}
    write_text(os.path.join(out, "dam_break_3d.info"), json.dumps(info, indent=2) + "\n")
    write_text(os.path.join(out, "dam_break_3d_output.log"),
               "INFO|pysph.solver.application|Generating output in dam_break_3d_output\n"
               "INFO|pysph.solver.solver|Run completed: %d iterations, dt = %g\n"
               % (iterations[-1], dt))


# ---------------------------------------------------------------- SWIFT-like run directory

def clumped(rng, n, origin, side, n_clumps, spread):
    """n positions in [origin, origin + side)^3, clustered around n_clumps centres."""
    centres = rng.uniform(0.1 * side, 0.9 * side, (n_clumps, 3))
    which = rng.integers(0, n_clumps, n)
    xyz = centres[which] + rng.normal(0.0, spread, (n, 3))
    return origin + np.mod(xyz, side), which


def swift():
    out = mkdir("swift_like")
    mkdir("swift_like", "restart")
    for step, n in enumerate([500, 503, 497, 511]):
        rng = np.random.default_rng(1000 + step)
        xyz, which = clumped(rng, n, 1e4, 100.0, 5, 6.0 + step)
        density = rng.lognormal(0.0, 0.5, n) * (1.0 + which)
        temperature = 1e4 * rng.lognormal(0.0, 0.3, n)
        smoothing = 2.0 * density ** (-1.0 / 3.0)
        table = np.column_stack([xyz, density, temperature, smoothing])
        np.savetxt(os.path.join(out, "output_%04d.csv" % step), table, fmt="%.17g", delimiter=",",
                   header="x,y,z,Density,Temperature,SmoothingLength", comments="")
    write_text(os.path.join(out, "statistics.txt"),
               "# Step Time a z Kin_Energy Int_Energy\n"
               + "".join("%6d %12.6e %12.6e %12.6e %12.6e %12.6e\n"
                         % (s, 0.01 * s, 1.0, 0.0, 1.5 + 0.1 * s, 3.0 - 0.05 * s) for s in range(8)))
    write_text(os.path.join(out, "timesteps.txt"),
               "# Step Time Scale-factor Redshift Time-step Time-bins Updates Wall-clock\n"
               + "".join("%6d %12.6e %12.6e %12.6e %12.6e %4d %6d %10.3f\n"
                         % (s, 0.01 * s, 1.0, 0.0, 0.01, 40, 500, 12.5 * s) for s in range(8)))
    write_text(os.path.join(out, "used_parameters.yml"),
               "Snapshots:\n  basename: output\n  delta_time: 0.02\n  output_list_on: 0\n"
               "TimeIntegration:\n  time_begin: 0.\n  time_end: 0.07\n  dt_max: 1e-2\n"
               "SPH:\n  resolution_eta: 1.2348\n  CFL_condition: 0.1\n"
               "InitialConditions:\n  file_name: ./ics.hdf5\n  shift: [10000, 10000, 10000]\n")
    write_text(os.path.join(out, "unused_parameters.yml"),
               "Statistics:\n  delta_time: 1e-2\n")
    write_text(os.path.join(out, "dependency_graph_0.csv"),
               "task,depends_on,count\n"
               "drift_part,sort,12\nsort,density,48\ndensity,ghost,12\nghost,force,48\n"
               "force,kick2,12\nkick2,timestep,12\n")
    with open(os.path.join(out, "restart", "swift_000000.rst"), "wb") as f:
        f.write(b"SWIFT restart\x00" + bytes(range(256)) * 4)


# ---------------------------------------------------------------- GADGET-4-like run directory

def gadget_snapshot(rng, n, dtype):
    xyz, which = clumped(rng, n, 0.0, 50.0, 4, 3.0)
    mass = np.full(n, 0.01)
    density = rng.lognormal(0.0, 0.7, n) * (1.0 + which)
    return np.column_stack([xyz, mass, density]).astype(dtype)


def gadget():
    out = mkdir("gadget_like")
    mkdir("gadget_like", "restartfiles")
    np.save(os.path.join(out, "ics.npy"), gadget_snapshot(np.random.default_rng(42), 1024, np.float32))
    for step, n in enumerate([1000, 1000, 998, 1003, 1001]):
        snap = gadget_snapshot(np.random.default_rng(2000 + step), n, np.float64)
        np.save(os.path.join(out, "snapshot_%03d.npy" % step), snap)
        if step == 3:
            np.save(os.path.join(out, "restart_snapshot_003.npy"), snap)
    write_text(os.path.join(out, "cpu.txt"),
               "Step 0, Time: 0, CPUs: 4, HighestActiveTimeBin: 20\n"
               "                          diff                 cumulative\n"
               "total                     0.05  100.0%        0.05  100.0%\n"
               "treegrav                  0.02   40.0%        0.02   40.0%\n")
    write_text(os.path.join(out, "info.txt"),
               "".join("Sync-Point %d, Time: %g, Systemstep: 0.01\n" % (s + 1, 0.01 * s) for s in range(5)))
    write_text(os.path.join(out, "energy.txt"),
               "".join("%g %g %g %g\n" % (0.01 * s, 1.0 + 0.01 * s, -2.0 - 0.01 * s, 0.5) for s in range(5)))
    write_text(os.path.join(out, "timebins.txt"),
               "Sync-Point 1, Time: 0, Systemstep: 0.01\n"
               "Occupied timebins: gravity         hydro     dt\n"
               " X  bin=20          1000          1000     0.01\n")
    with open(os.path.join(out, "restartfiles", "restart.0"), "wb") as f:
        f.write(b"GADGET-4 restart\x00" + bytes(range(255, -1, -1)) * 4)


pysph()
swift()
gadget()
