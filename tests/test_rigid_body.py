"""CasADi RNEA/ABA against Pinocchio's own algorithms (the oracle), 100 random states each."""
import casadi as ca
import numpy as np
import pinocchio as pin
import pytest

from thermo_ddp.model.arm import LEFT_ARM, ArmSettings, build_arm
from thermo_ddp.model.rigid_body import RigidBodyDynamics

CASES = {1: ("arm_left_4_joint",), 2: ("arm_left_3_joint", "arm_left_4_joint"), 7: LEFT_ARM}
TOL = 1e-9


@pytest.fixture(scope="module", params=sorted(CASES))
def setup(request):
    joints = CASES[request.param]
    arm = build_arm(ArmSettings(joints=joints, payload_kg=40.0), {j: 0.1 for j in joints})
    rb = RigidBodyDynamics(arm.model)
    n = arm.nv
    q, v, a, tau = (ca.SX.sym(s, n) for s in "qvat")
    acc = rb.aba(q, v, tau)
    derivs = ca.Function("d", [q, v, tau], [ca.jacobian(acc, q), ca.jacobian(acc, v), ca.jacobian(acc, tau)])
    rnea, aba = rb.functions()
    return arm.model, rnea, aba, derivs


def _states(model, rng, count=100):
    lo, hi = model.lowerPositionLimit, model.upperPositionLimit
    for _ in range(count):
        yield rng.uniform(lo, hi), rng.normal(scale=2.0, size=model.nv), rng.normal(scale=3.0, size=model.nv), \
            rng.normal(scale=50.0, size=model.nv)


def _close(ours, theirs, tol=TOL):
    ours = np.array(ours, dtype=float).reshape(np.shape(theirs))
    scale = max(1.0, np.abs(theirs).max())
    assert np.abs(ours - theirs).max() <= tol * scale


def test_armature_and_payload_are_in_the_model(setup):
    model = setup[0]
    assert np.all(model.armature == 0.1)
    assert model.nv in CASES


def test_rnea_matches_pinocchio(setup):
    model, rnea, _, _ = setup
    data = model.createData()
    for q, v, a, _ in _states(model, np.random.default_rng(1)):
        _close(rnea(q, v, a), pin.rnea(model, data, q, v, a))


def test_aba_matches_pinocchio(setup):
    model, _, aba, _ = setup
    data = model.createData()
    for q, v, _, tau in _states(model, np.random.default_rng(2)):
        _close(aba(q, v, tau), pin.aba(model, data, q, v, tau))


def test_aba_derivatives_match_pinocchio(setup):
    model, _, _, derivs = setup
    data = model.createData()
    for q, v, _, tau in _states(model, np.random.default_rng(3)):
        ddq_dq, ddq_dv, minv = pin.computeABADerivatives(model, data, q, v, tau)
        dq, dv, dtau = derivs(q, v, tau)
        _close(dq, ddq_dq)
        _close(dv, ddq_dv)
        _close(dtau, minv)


@pytest.mark.parametrize("joints", [CASES[1], CASES[7]], ids=["elbow", "arm"])
def test_runtime_payload_matches_pinocchio_models_built_with_each_payload(joints):
    """One CasADi function with the payload as an input equals Pinocchio's model built with that payload."""
    arm = build_arm(ArmSettings(joints=joints, payload_kg=0.0), {j: 0.1 for j in joints})
    rb = RigidBodyDynamics(arm.model, (arm.unloaded_inertias, arm.inertias_per_payload_kg))
    q, v, tau, m = ca.SX.sym("q", arm.nv), ca.SX.sym("v", arm.nv), ca.SX.sym("tau", arm.nv), ca.SX.sym("m")
    aba = ca.Function("aba", [q, v, tau, m], [rb.aba(q, v, tau, m)])
    rng = np.random.default_rng(3)
    for payload_kg in (0.0, 7.5, 40.0, 100.0):
        loaded = build_arm(ArmSettings(joints=joints, payload_kg=payload_kg), {j: 0.1 for j in joints}).model
        data = loaded.createData()
        for q0, v0, _, tau0 in _states(loaded, rng, count=20):
            _close(aba(q0, v0, tau0, payload_kg), pin.aba(loaded, data, q0, v0, tau0))
