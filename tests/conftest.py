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
    """Compiled libraries go to a per-run cache unless the caller chose one, shared by the run's xdist workers
    (the cache is safe for concurrent builders: codegen.py)."""
    root = tmp_path_factory.getbasetemp()
    if os.environ.get("PYTEST_XDIST_WORKER"):
        root = root.parent  # each worker's base is <run>/popen-gwN
    (root / "codegen_cache").mkdir(exist_ok=True)
    os.environ.setdefault("THERMO_DDP_CACHE", str(root / "codegen_cache"))


@pytest.fixture(scope="session")
def emps_csv() -> Path:
    return shared_data("emps/emps_estimation.csv")


@pytest.fixture(scope="session")
def panda_bag() -> Path:
    return shared_data("ros/panda_joint_states.bag")


@pytest.fixture(scope="session")
def elbow_file() -> Path:
    return packaged_parameter_file("arm_left_4_joint")


UNIT = r"\[[^\]]+\]|\([^)]*(?:°C|K|A|V|s|kg|rad|deg|N|W|%|count)[^)]*\)"


def axes_without_units(fig) -> list[str]:
    """Every drawn axis of ``fig`` whose label carries no unit in brackets or parentheses: each visible axes'
    y label, and every x label that is set (the panels of a column share the bottom one's)."""
    import re
    bad = []
    for ax in fig.axes:
        if not ax.get_visible() or not (ax.lines or ax.patches or ax.collections):
            continue
        for axis, label in (("y", ax.get_ylabel()), ("x", ax.get_xlabel())):
            if (axis == "y" or label) and not re.search(UNIT, label):
                bad.append(f"{ax.get_title() or fig.texts[0].get_text() if fig.texts else ''} {axis}: {label!r}")
    if not any(re.search(UNIT, ax.get_xlabel()) for ax in fig.axes if ax.get_visible()):
        bad.append("no x axis with a unit")
    return bad


@pytest.fixture
def figures_drawn(monkeypatch):
    """Every matplotlib Figure saved while the test runs (they are still written)."""
    from matplotlib.figure import Figure
    drawn, save = [], Figure.savefig

    def record(fig, *args, **kwargs):
        drawn.append(fig)
        return save(fig, *args, **kwargs)
    monkeypatch.setattr(Figure, "savefig", record)
    return drawn
