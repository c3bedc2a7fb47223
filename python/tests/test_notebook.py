"""python/examples/aarbf.ipynb runs from top to bottom (nbclient), so it cannot rot."""

import os
from pathlib import Path

import pytest

NOTEBOOK = Path(__file__).resolve().parents[1] / "examples" / "aarbf.ipynb"


def test_the_notebook_runs(dambreak, cli, tmp_path):
    nbformat = pytest.importorskip("nbformat")
    nbclient = pytest.importorskip("nbclient")
    data = dambreak.parent
    if not (data / "clusters_0000.vtp").exists():
        cli("generate", "clusters", "--count", 20000, "--format", "vtk-xml", "--out", data)
    nb = nbformat.read(NOTEBOOK, as_version=4)
    env = {"AARBF_DATA": str(data), "AARBF_SIZE": "64"}
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    try:
        nbclient.NotebookClient(nb, timeout=300, kernel_name="python3",
                                resources={"metadata": {"path": str(tmp_path)}}).execute()
    finally:
        for k, v in old.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    outputs = [o for c in nb.cells if c.cell_type == "code" for o in c.get("outputs", [])]
    assert not [o for o in outputs if o.get("output_type") == "error"]
    pngs = [o for o in outputs if "image/png" in o.get("data", {})]
    assert len(pngs) == 2, "both renders show as images"
