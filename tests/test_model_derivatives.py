"""ODE and step Jacobians (by state and by input) against central finite differences."""
import numpy as np
import pytest

from thermo_ddp.model.actuated import load_model

REL_TOL = 1e-6


def _central_difference(f, z, h):
    cols = []
    for k in range(z.size):
        e = np.zeros_like(z)
        e[k] = h[k]
        cols.append((f(z + e) - f(z - e)) / (2 * h[k]))
    return np.array(cols).T


def _random_points(model, rng, count):
    n = model.nu
    for _ in range(count):
        q = rng.uniform(-2.0, 0.0, n)
        v = rng.normal(scale=1.0, size=n)
        temps = model.idle_temperatures() + rng.uniform(0, 60, size=model.nx - 2 * n)
        yield np.concatenate([q, v, temps]), rng.normal(scale=5.0, size=n)


def _check(fn, model, x, u, ambient=26.0):
    """Jacobian of fn(x, u, ambient) w.r.t. [x, u] by AD vs by central differences (relative)."""
    z = np.concatenate([x, u])
    nx = x.size

    def f(zz):
        return np.array(fn(zz[:nx], zz[nx:], ambient)).ravel()

    import casadi as ca
    xs, us = ca.SX.sym("x", nx), ca.SX.sym("u", u.size)
    out = fn(xs, us, ambient)
    jac = np.array(ca.Function("j", [xs, us], [ca.jacobian(out, ca.vertcat(xs, us))])(x, u))
    h = 1e-5 * np.maximum(1.0, np.abs(z))
    fd = _central_difference(f, z, h)
    err = np.abs(jac - fd).max() / max(1.0, np.abs(jac).max())
    assert err <= REL_TOL, err


@pytest.mark.parametrize("joints", [("arm_left_4_joint",), ("arm_left_3_joint", "arm_left_4_joint")])
def test_ode_jacobian(joints):
    model = load_model(joints, payload_kg=20.0)
    for x, u in _random_points(model, np.random.default_rng(0), 10):
        _check(model.ode, model, x, u)


@pytest.mark.parametrize("integrator", ["rk4", "rk4_4", "implicit_euler"])
def test_step_jacobians(integrator):
    model = load_model(("arm_left_3_joint", "arm_left_4_joint"), payload_kg=20.0)
    step = model.step(0.01, integrator)
    jac = model.step_jacobians(0.01, integrator)
    for x, u in _random_points(model, np.random.default_rng(1), 5):
        _check(step.function, model, x, u)
        xn, a, b = (np.array(m) for m in jac(x, u, 26.0))
        assert np.allclose(xn.ravel(), np.array(step(x, u, 26.0)).ravel(), rtol=0, atol=1e-12)
        assert a.shape == (model.nx, model.nx) and b.shape == (model.nx, model.nu)


def test_step_jacobians_are_the_ad_jacobians():
    """The named step_jacobians function returns exactly d step/dx and d step/du (vs FD)."""
    model = load_model(payload_kg=40.0)
    jac = model.step_jacobians(0.02)
    step = model.step(0.02)
    rng = np.random.default_rng(2)
    for x, u in _random_points(model, rng, 5):
        _, a, b = (np.array(m) for m in jac(x, u, 26.0))
        h = 1e-5 * np.maximum(1.0, np.abs(np.concatenate([x, u])))
        fd = _central_difference(lambda z: np.array(step(z[:x.size], z[x.size:], 26.0)).ravel(),
                                 np.concatenate([x, u]), h)
        assert np.abs(np.hstack([a, b]) - fd).max() <= REL_TOL * max(1.0, np.abs(fd).max())


def test_analytic_rk4_jacobians_equal_automatic_differentiation_for_seven_joints():
    """The chain-rule RK4 Jacobians built on the analytic ABA partials equal AD of the RK4 step."""
    from thermo_ddp.model.arm import LEFT_ARM
    from thermo_ddp.model.integrators import step_jacobians

    model = load_model(LEFT_ARM, payload_kg=40.0)
    ours, ad = model.step_jacobians(0.01), step_jacobians(model.step_function(0.01))
    for x, u in _random_points(model, np.random.default_rng(4), 3):
        for a, b in zip(ours(x, u, 26.0), ad(x, u, 26.0)):
            a, b = np.array(a), np.array(b)
            assert np.abs(a - b).max() <= 1e-10 * max(1.0, np.abs(b).max())
