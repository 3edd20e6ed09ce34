"""Shared fixtures: the packaged parameter files, the repository's real recordings (data/), and the
recordings whose licence keeps them out of the repository (../shared/data, skipped when absent)."""
from __future__ import annotations

import os
from pathlib import Path

import pytest

from thermo_ddp.model.parameters import packaged_parameter_file

ROOT = Path(__file__).resolve().parent.parent
DATA = ROOT / "data"
SHARED_DATA = ROOT.parent / "shared" / "data"
NOTEBOOKS = ROOT / "notebooks"


def shared_data(relative: str) -> Path:
    """A file of ../shared/data; skips the test when it is absent (its licence is not stated, so the
    repository does not carry it: see README, "Tests and data")."""
    path = SHARED_DATA / relative
    if not path.is_file():
        pytest.skip(f"needs ../shared/data/{relative} beside the project (not redistributed: no licence stated)")
    return path


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
def emps_csv() -> Path:
    return shared_data("emps/emps_estimation.csv")


@pytest.fixture(scope="session")
def panda_bag() -> Path:
    return shared_data("ros/panda_joint_states.bag")


@pytest.fixture(scope="session")
def elbow_file() -> Path:
    return packaged_parameter_file("arm_left_4_joint")
