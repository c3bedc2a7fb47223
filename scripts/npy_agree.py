#!/usr/bin/env python3
"""Agreement of two `aarbf field` outputs (M x 2 float64 .npy: Phi, Theta), with the standard
library alone (the device check runs where NumPy may be missing).

    python3 scripts/npy_agree.py reference.npy other.npy [TOLERANCE]

Prints one Markdown table row: the largest relative Phi difference where the reference's Phi is
above 1e-3 of its maximum, the largest Theta difference there relative to Theta's range, and
whether both are within TOLERANCE (default 1e-5, what `aarbf field --precision auto` promises).
"""
import array
import ast
import sys


def read_npy(path):
    with open(path, "rb") as f:
        if f.read(6) != b"\x93NUMPY":
            sys.exit(f"{path}: not a .npy file")
        major = f.read(2)[0]
        size = int.from_bytes(f.read(2 if major == 1 else 4), "little")
        header = ast.literal_eval(f.read(size).decode("latin1"))
        if header["descr"] != "<f8" or header["fortran_order"]:
            sys.exit(f"{path}: expected little-endian float64 in C order, got {header}")
        values = array.array("d")
        values.frombytes(f.read())
    rows, cols = header["shape"]
    return rows, cols, values


def main():
    ref_path, other_path = sys.argv[1], sys.argv[2]
    tolerance = float(sys.argv[3]) if len(sys.argv) > 3 else 1e-5
    rows, cols, ref = read_npy(ref_path)
    rows_b, cols_b, other = read_npy(other_path)
    if (rows, cols) != (rows_b, cols_b):
        sys.exit(f"shapes differ: {rows}x{cols} and {rows_b}x{cols_b}")
    phi_max = max(ref[i * cols] for i in range(rows))
    floor = 1e-3 * phi_max
    live = [i for i in range(rows) if ref[i * cols] > floor]
    thetas = [ref[i * cols + 1] for i in live]
    theta_range = (max(thetas) - min(thetas)) if thetas else 0.0
    phi_err = max((abs(other[i * cols] - ref[i * cols]) / ref[i * cols] for i in live), default=0.0)
    theta_err = max(
        (abs(other[i * cols + 1] - ref[i * cols + 1]) for i in live), default=0.0
    ) / (theta_range if theta_range > 0 else 1.0)
    verdict = "yes" if max(phi_err, theta_err) <= tolerance else "NO"
    print(f"| {other_path.rsplit('/', 1)[-1]} | {len(live)} | {phi_err:.3e} | {theta_err:.3e} | {verdict} |")


if __name__ == "__main__":
    main()
