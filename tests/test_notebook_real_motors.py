"""notebooks/real_motors.ipynb runs end to end on the repository's real recordings (issue 12's figures)."""
import json

from conftest import ROOT, run_notebook


def test_real_motors_notebook(tmp_path, monkeypatch):
    monkeypatch.setenv("THERMO_DDP_REPO", str(ROOT))
    text = run_notebook("real_motors.ipynb", tmp_path, monkeypatch)
    result = json.loads((tmp_path / "real_motors.json").read_text())
    pad = result["paderborn"]
    held = pad["held_out_rmse"]
    assert held["copper + iron"] <= min(held["copper only"] / 3, 4.0)
    assert pad["validate_rmse"]["written file (+ iron)"] < pad["validate_rmse"]["packaged copper-only file"]
    # the diagnosis itself names a speed-dependent running loss the motor can have ([hardware]: no drive heat),
    # says what one speed cannot separate, and its held-out error drops
    named = set(pad["named_by_diagnosis"])
    assert {"iron_losses", "friction_heating"} & named and "drive_heating" not in named
    assert pad["not_determinable_by_diagnosis"]
    before, after = pad["diagnosis_cv_rmse"]
    assert after <= min(before / 3, 4.0)
    assert pad["not_determinable"]["rms_prediction_difference_k"] < 0.5  # constant vs k w^2: same prediction
    for joint, r in result["ur3"].items():
        assert r["success"] and r["later_rmse"] <= 1.0, joint
        assert r["rows"] == {"used": 7355, "skipped": 54, "segments": 3}
        # no missing physics claimed unless it improves the held-out fit: leaving one stretch out, and on the later one
        for term in r["missing_physics"]:
            assert r["held_out"]["terms"][term]["rmse_with"] < r["held_out"]["terms"][term]["rmse_without"], joint
            assert r["later_rmse"] <= r["later_rmse_without"][term], (joint, term)
        assert not any(t["named"] for name, t in r["held_out"]["terms"].items() if name not in r["missing_physics"])
    # every stator sensor on both profiles (profile 60 when ../shared/data has it): a grown network that fits
    # each profile's winding better than the one-node file, no drive heat (the motor's [hardware] has none)
    net = result["paderborn_network"]
    assert {"winding", "tooth", "yoke"} <= set(net["nodes"]) and "drive_heating" not in net["sources"]
    for profile, errors in net["per_profile_rmse"].items():
        assert set(errors) == {"winding", "tooth", "yoke"}
        assert errors["winding"] < net["baseline_winding_rmse"][profile], profile
    if "paderborn_envelope" in result:  # the file from profile 24 alone, used on profile 60
        env = result["paderborn_envelope"]
        assert env["outside"] and env["quantities"]["ambient_c"]["outside"] and "never identified" in env["message"]
        assert env["rmse_written"] <= env["rmse_packaged"]
    assert (tmp_path / "paderborn_network_graph.png").stat().st_size > 10_000
    assert "identified on first 75 %" in text
    assert (tmp_path / "paderborn_later.png").stat().st_size > 10_000
