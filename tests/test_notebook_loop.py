"""notebooks/close_the_loop.ipynb runs end to end (short experiments) and its table backs its claims."""
from __future__ import annotations

import json

from conftest import run_notebook
from thermo_ddp.model.parameters import load_parameters


def test_close_the_loop_notebook_runs_and_the_improved_model_holds_both_limits(tmp_path, monkeypatch):
    text = run_notebook("close_the_loop.ipynb", tmp_path, monkeypatch)
    assert "close the loop: ok" in text and "truth (hidden)" in text and "re-identified at full rate" in text
    table = json.loads((tmp_path / "close_the_loop.json").read_text())
    assert table["settings"]["hold_s"] == 45.0 and table["settings"]["limits_c"] == [84.0, 140.0]
    assert {"friction_heating", "drive_heating"} <= set(table["diagnosis"]["missing_physics"])
    improved = load_parameters(table["model_files"]["improved"])
    assert improved.thermal.model == "two_node_drive"
    rows = {(r["model"], r["limit_c"]): r for r in table["rows"]}
    for lim in (84.0, 140.0):
        orig, impr = rows["original", lim], rows["improved", lim]
        # the improved plan respects the limit in its own model, and the robot's TRUE winding stays under it
        assert impr["plan_peak_winding_c"] <= lim + 1e-3 and impr["planned_hold_s"] > 0
        assert impr["peak_true_winding_c"] <= lim and impr["cutoff_trips"] == 0 and impr["closed_loop_hold_s"] > 0
        assert impr["margin_c"] < 8.0  # small: the voltage-informed winding node (5.5 K at most when written)
        # the original model breaks the limit, or else is more conservative (more margin, shorter hold)
        assert orig["margin_c"] < 0 or (orig["margin_c"] > impr["margin_c"]
                                        and orig["closed_loop_hold_s"] < impr["closed_loop_hold_s"])
    # 140 °C buys hold time with the improved model
    assert rows["improved", 140.0]["closed_loop_hold_s"] > rows["improved", 84.0]["closed_loop_hold_s"]
    for fig in ("loop.png", "loop_summary.png", "diagnosis.png"):
        assert (tmp_path / fig).stat().st_size > 10_000
