"""notebooks/diagnose_elbow.ipynb runs end to end (short recordings) and finds the hidden physics."""
from __future__ import annotations

import json
import os
from pathlib import Path

import nbformat
from nbclient import NotebookClient

from thermo_ddp.parameters import parameters_from_dict

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "diagnose_elbow.ipynb"


def test_diagnose_notebook_runs_and_finds_friction_and_drive_heating(tmp_path, monkeypatch):
    monkeypatch.setenv("THERMO_DDP_NOTEBOOK_SHORT", "1")
    monkeypatch.setenv("THERMO_DDP_NOTEBOOK_OUT", str(tmp_path))
    monkeypatch.setenv("TQDM_DISABLE", "1")
    nb = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(nb, timeout=300, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    text = "".join(o.get("text", "") for cell in nb.cells for o in cell.get("outputs", []))
    assert "missing physics:" in text and "planner network nodes: ('winding', 'casing', 'drive')" in text
    result = json.loads((tmp_path / "diagnose_elbow.json").read_text())
    assert {"friction_heating", "drive_heating"} <= {m["term"] for m in result["missing_physics"]}
    assert parameters_from_dict(result["parameter_file"]).thermal.model == "two_node_drive"
    assert (tmp_path / "diagnose_elbow.png").stat().st_size > 10_000
    assert os.environ["THERMO_DDP_NOTEBOOK_SHORT"] == "1"
