"""`model.step(dt)` answers in numpy, as `state()` does; the CasADi Function stays at hand (`step.function`,
`model.step_function`)."""
import casadi as ca
import numpy as np

from thermo_ddp import load_model


def test_step_returns_numpy_like_state_and_agrees_with_simulate_and_casadi():
    model = load_model(payload_kg=20.0)
    q = np.array([-1.2])
    x, u = model.state(q=q, v=[0.3]), model.static_current_a(q)
    step = model.step(0.01)
    x_next = step(x, u)
    assert isinstance(x_next, np.ndarray) and x_next.shape == x.shape == (model.nx,)
    traj = model.simulate(x, u.reshape(1, -1), dt_s=0.01)   # the oracle: one step of the plant simulation
    assert np.abs(x_next - traj.xs[1]).max() < 1e-12
    assert not np.allclose(x_next, x)                         # it moved
    symbolic = model.step_function(0.01)(ca.SX.sym("x", model.nx), ca.SX.sym("u", model.nu), 26.0)
    assert isinstance(symbolic, ca.SX) and isinstance(step.function, ca.Function)
    warmer = step(x, u, model.ambient_c + 10.0)                # the room as the third argument
    assert warmer[model.index("arm_left_4_joint", "winding_c")] > x_next[model.index("arm_left_4_joint", "winding_c")]
