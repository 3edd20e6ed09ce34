"""notebooks/limits_84_vs_140.ipynb runs end to end (short configuration); its table is consistent."""
import json

from conftest import run_notebook


def test_limits_notebook(tmp_path, monkeypatch):
    text = run_notebook("limits_84_vs_140.ipynb", tmp_path, monkeypatch)
    rows = {(r["payload_kg"], r["limit_c"]): r for r in json.loads((tmp_path / "limits_84_vs_140.json").read_text())}
    for (kg, lim), r in rows.items():
        assert r["peak_winding_c"] <= lim + 1e-3
        assert rows[(kg, 140.0)]["hold_s"] >= rows[(kg, 84.0)]["hold_s"]
    assert rows[(40.0, 140.0)]["hold_s"] > 2 * rows[(40.0, 84.0)]["hold_s"]
    assert rows[(20.0, 84.0)]["feasible"]
    assert "40 kg: hold" in text and "at 140 °C" in text
    assert (tmp_path / "holds.png").stat().st_size > 10_000 and (tmp_path / "profiles_40kg.png").stat().st_size > 10_000
