"""notebooks/limits_84_vs_140.ipynb runs end to end (short configuration); its table is consistent."""
import json
from pathlib import Path

import nbformat
from nbclient import NotebookClient

NOTEBOOK = Path(__file__).resolve().parents[1] / "notebooks" / "limits_84_vs_140.ipynb"


def test_limits_notebook(tmp_path, monkeypatch):
    monkeypatch.setenv("THERMO_DDP_NOTEBOOK_SHORT", "1")
    monkeypatch.setenv("THERMO_DDP_NOTEBOOK_OUT", str(tmp_path))
    nb = nbformat.read(NOTEBOOK, as_version=4)
    NotebookClient(nb, timeout=600, kernel_name="python3", resources={"metadata": {"path": str(tmp_path)}}).execute()
    rows = {(r["payload_kg"], r["limit_c"]): r for r in json.loads((tmp_path / "limits_84_vs_140.json").read_text())}
    for (kg, lim), r in rows.items():
        assert r["peak_winding_c"] <= lim + 1e-3
        assert rows[(kg, 140.0)]["hold_s"] >= rows[(kg, 84.0)]["hold_s"]
    assert rows[(40.0, 140.0)]["hold_s"] > 2 * rows[(40.0, 84.0)]["hold_s"]
    assert rows[(20.0, 84.0)]["feasible"]
    text = "".join(o.get("text", "") for cell in nb.cells for o in cell.get("outputs", []))
    assert "40 kg: hold" in text and "at 140 °C" in text
    assert (tmp_path / "holds.png").stat().st_size > 10_000 and (tmp_path / "profiles_40kg.png").stat().st_size > 10_000
