"""scene.render against `aarbf render` for the same scene, side by side, whole runs (open the
data, resolve, render, write the image) alternated, on the CPU backend.

    target/venv/bin/python python/benches/render_vs_cli.py DATA AARBF_BIN [repeats]

DATA is the dam break (`aarbf generate dambreak-demo --out data/`); the scene is the demo's
(step 14, marching, 16 spp) at 256x256.
"""

import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import aarbf


def main() -> None:
    data, binary = sys.argv[1], sys.argv[2]
    repeats = int(sys.argv[3]) if len(sys.argv) > 3 else 5
    out = Path(tempfile.mkdtemp())
    args = dict(width=256, height=256, spp=16, integrator="marching", backend="cpu")
    cli = [binary, "render", "--data", data, "--step", "14", "--attribute", "attribute",
           "--radius", "1.5%", "--up", "y", "--width", "256", "--height", "256", "--spp", "16",
           "--integrator", "marching", "--backend", "cpu", "--no-legend", "--force",
           "--out", str(out / "cli.png")]
    times = {"aarbf render": [], "scene.render": []}
    for _ in range(repeats):
        start = time.perf_counter()
        subprocess.run(cli, check=True, capture_output=True)
        times["aarbf render"].append(time.perf_counter() - start)
        start = time.perf_counter()
        scene = aarbf.Scene(aarbf.open(data), step=14, attribute="attribute", radius="1.5%")
        scene.render(up="y", **args).save(out / "py.png")
        times["scene.render"].append(time.perf_counter() - start)
    assert (out / "cli.png").read_bytes() == (out / "py.png").read_bytes(), "not the same image"
    for name, t in times.items():
        print(f"{name:13s} median {statistics.median(t):.3f} s  (runs: "
              + ", ".join(f"{x:.3f}" for x in t) + ")")
    ratio = statistics.median(times["scene.render"]) / statistics.median(times["aarbf render"])
    print(f"scene.render / aarbf render = {ratio:.3f}")


if __name__ == "__main__":
    main()
