"""Handing N float64 particles to aarbf.Particles copies them at most once: its time and peak
memory against numpy.copy of the same arrays.

    target/venv/bin/python python/benches/copy_once.py [N]      (default N = 10_000_000)

Each measurement runs in a fresh interpreter (peak RSS is per process): the arrays are made,
the resident memory noted, then the operation run and the peak resident memory read back.
"""

import json
import resource
import subprocess
import sys
import time

CHILD = r"""
import json, resource, sys, time
import numpy as np
import aarbf  # loaded before measuring, for every case alike
n, what = int(sys.argv[1]), sys.argv[2]
rng = np.random.default_rng(1)
pos = rng.random((n, 3))
t = rng.random(n)
def rss_kib():
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1])
before = rss_kib()
start = time.perf_counter()
if what == "numpy.copy":
    out = (np.copy(pos), np.copy(t))
elif what == "aarbf.Particles":
    out = aarbf.Particles(pos, attributes={"T": t})
elif what == "aarbf.Particles(fortran)":
    f = np.asfortranarray(pos)
    before = rss_kib()
    start = time.perf_counter()
    out = aarbf.Particles(f, attributes={"T": t})
seconds = time.perf_counter() - start
peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(json.dumps({"what": what, "seconds": seconds, "extra_mib": (peak - before) / 1024,
                  "data_mib": (pos.nbytes + t.nbytes) / 2**20}))
"""


def main() -> None:
    n = int(sys.argv[1]) if len(sys.argv) > 1 else 10_000_000
    rows = []
    for what in ["numpy.copy", "aarbf.Particles", "aarbf.Particles(fortran)"]:
        runs = []
        for _ in range(3):
            out = subprocess.run([sys.executable, "-c", CHILD, str(n), what],
                                 capture_output=True, text=True, check=True)
            runs.append(json.loads(out.stdout))
        best = min(runs, key=lambda r: r["seconds"])
        rows.append(best)
        print(f"{what:26s} {best['seconds']:.3f} s (best of 3)  peak +{best['extra_mib']:.0f} MiB"
              f"  (arrays: {best['data_mib']:.0f} MiB)", flush=True)
    base = rows[0]
    for r in rows[1:]:
        print(f"{r['what']}: {r['seconds'] / base['seconds']:.2f}x numpy.copy's time, "
              f"{r['extra_mib'] / base['extra_mib']:.2f}x its extra memory")


if __name__ == "__main__":
    main()
