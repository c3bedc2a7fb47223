"""Shared fixtures: the CLI the package is compared with, and the dam break it generates."""

import os
import shutil
import subprocess
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


def _cli() -> str:
    """The `aarbf` binary: $AARBF_BIN (set by `cargo xtask test`), else the checked build."""
    candidates = [os.environ.get("AARBF_BIN")]
    target = os.environ.get("CARGO_TARGET_DIR")
    if target:
        candidates.append(str(Path(target) / "checked" / "aarbf"))
    candidates += [str(ROOT / "target" / "checked" / "aarbf"), shutil.which("aarbf")]
    for c in candidates:
        if c and Path(c).is_file():
            return c
    raise RuntimeError(
        "no aarbf binary: set AARBF_BIN or build it (cargo build --profile checked)"
    )


@pytest.fixture(scope="session")
def cli():
    """Runs the CLI with the given arguments; fails the test on a non-zero exit."""
    binary = _cli()

    def run(*args):
        out = subprocess.run(
            [binary, *map(str, args)], capture_output=True, text=True, check=False
        )
        assert out.returncode == 0, f"aarbf {' '.join(map(str, args))}:\n{out.stderr}"
        return out

    return run


@pytest.fixture(scope="session")
def dambreak(cli, tmp_path_factory):
    """`aarbf generate dambreak-demo`: 20K particles, 3 steps (of the demo's 48), as the CLI writes them."""
    out = tmp_path_factory.mktemp("dambreak")
    cli("generate", "dambreak-demo", "--steps", 3, "--out", out)
    header = out / "dambreak-demo.particles"
    assert header.is_file()
    return header
