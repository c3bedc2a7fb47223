"""Renders the dam break from Python (docs/python.md's picture).

    target/venv/bin/python python/examples/render_demo.py DATA.particles OUT.png [SIZE]
"""

import logging
import sys

import aarbf

logging.basicConfig(level=logging.INFO, format="%(message)s")
data, out = sys.argv[1], sys.argv[2]
size = int(sys.argv[3]) if len(sys.argv) > 3 else 384
series = aarbf.open(data)
print(series.info())
scene = aarbf.Scene(series, step=14, attribute="attribute", radius="1.5%")
image = scene.render(aarbf.Camera.orbit(30, 20, up="y"), width=size, height=size, spp=16,
                     integrator="marching", backend="cpu")
image.save(out)
print(f"wrote {out}: {image.shape}, alpha {image[..., 3].mean():.3f} on average")
