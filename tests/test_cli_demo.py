"""`thermo-ddp demo`: the figures it prints follow from the model; bad input exits 2 in one line."""
from thermo_ddp.cli import main
from thermo_ddp.studies.demo import hold_demo


def test_demo_figures(capsys):
    assert main(["demo", "--payload-kg", "40"]) == 0
    out = capsys.readouterr().out
    d = hold_demo(40.0)
    # static current = gravity torque / (N K_m), with 11.06 N·m/A from the report
    assert abs(d.current_a - d.torque_nm / 11.06) < 1e-9
    assert 130 < abs(d.torque_nm) < 170  # 40 kg x 9.81 x 0.357 m plus the forearm
    assert d.idle_winding_c < d.winding_c_at[10.0] < d.winding_c_at[30.0] < d.winding_c_at[60.0]
    assert f"{d.winding_c_at[30.0]:.1f}" in out and f"{d.current_a:.2f}" in out


def test_bad_input_one_line_exit_2(capsys):
    assert main(["demo", "--payload-kg", "-1"]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "payload_kg" in err and "-1" in err
