"""Shared fixtures: paths to the project's models and to ../shared data."""
from __future__ import annotations

import os
from pathlib import Path

import matplotlib
import pytest

matplotlib.use("Agg")

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared"
MODELS = ROOT / "models"
NOTEBOOKS = ROOT / "notebooks"


def run_notebook(name: str, out_dir: Path, monkeypatch) -> str:
    """Execute ``notebooks/<name>`` in its short configuration, outputs written to ``out_dir``;
    returns the text the cells printed."""
    import nbformat
    from nbclient import NotebookClient

    monkeypatch.setenv("THERMO_DDP_NOTEBOOK_SHORT", "1")
    monkeypatch.setenv("THERMO_DDP_NOTEBOOK_OUT", str(out_dir))
    monkeypatch.setenv("TQDM_DISABLE", "1")
    nb = nbformat.read(NOTEBOOKS / name, as_version=4)
    NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(out_dir)}}).execute()
    return "".join(o.get("text", "") for cell in nb.cells for o in cell.get("outputs", []))


@pytest.fixture(autouse=True, scope="session")
def _codegen_cache(tmp_path_factory):
    """Compiled libraries go to a per-run cache unless the caller chose one."""
    os.environ.setdefault("THERMO_DDP_CACHE", str(tmp_path_factory.mktemp("codegen_cache")))


@pytest.fixture(scope="session")
def shared_dir() -> Path:
    if not SHARED.is_dir():
        pytest.fail(f"shared data not found at {SHARED} (expected ../shared beside the project)")
    return SHARED


@pytest.fixture(scope="session")
def elbow_file() -> Path:
    return MODELS / "arm_left_4_joint.toml"
