"""A joint's thermal uncertainty set, its scenarios as models, and the worst motor of the set for a plan.

- :class:`UncertaintySet`: the box of the uncertain values, by dotted path (``thermal.casing_ambient_k_per_w``,
  ``motor.resistance_ohm``): every thermal capacity and resistance of the file's model, the winding
  resistance and the drive's losses, each within +-``fraction`` of the file's value; or the intervals of
  the file's ``[uncertainty]`` section (95 % intervals written by identify/diagnose).  A file that also has
  the fit's ``[covariance]`` gives its 95 % confidence ellipsoid instead: theta = file value x exp(A z) (log-
  scaled values; + A z for linear ones, floored at 0) with |z| <= 1, A = sqrt(chi2_{d,0.95}) V diag(sqrt(
  lambda)) from C = V diag(lambda) V^T, so z = +-e_k are the ends of its principal axes (the box's corners would be
  motors the fit excludes: two resistances in series whose sum the data pin down both at their upper bound).
- :func:`scenario_step`: one scenario's step ``(x, u, p, theta) -> x_next`` of the elbow with the uncertain
  values ``theta`` as a runtime input (the multi-model problem's dynamics); at the file's values it is the
  model's own step.
- :class:`WorstCase`: the replay of a plan (its current and motion) through the scenario model, exactly
  as the planner's constraint sees it, and the motor of the set with the highest winding peak: gradient
  ascent in the set (L-BFGS-B on the box, SLSQP in the ellipsoid's ball) from the point the gradient at the
  file's values points to (a vertex; the ellipsoid's first-order worst point) and from a few more. Every
  motor starts from its own equilibrium at rest, from given temperatures, or with its
  measured nodes (the casing sensor) at given temperatures and the others at its equilibrium given them.
"""
from __future__ import annotations

import copy
import dataclasses
from pathlib import Path

import casadi as ca
import numpy as np
from scipy.optimize import minimize

from .._config import require
from ..model.actuated import ActuatedArm
from ..model.integrators import make_step
from ..model.parameters import THERMAL_KEYS, JointParameters
from ..model.thermal import joint_heat_rhs, network_from_parameters

FRACTION_RANGE = "(0, 1)"
DRIVE_LOSSES = ("drive_idle_w", "drive_loss_w_per_a2")
WINDING_RESISTANCE = "motor.resistance_ohm"
_SRC = "uncertainty"
_STARTS = 3  # vertices the worst-case search starts from: the gradient's, its nearest neighbour, a random one


def uncertain_keys(params: JointParameters) -> tuple[str, ...]:
    """The values ``--uncertainty FRACTION`` varies: the thermal model's capacities and resistances, the drive's
    losses (when not zero) and the winding resistance, by dotted path."""
    th = params.thermal
    keys = [k for k in THERMAL_KEYS[th.model] if k not in DRIVE_LOSSES]
    keys += [k for k in DRIVE_LOSSES if th[k] != 0]
    return tuple(f"thermal.{k}" for k in keys) + (WINDING_RESISTANCE,)


def value_of(params: JointParameters, key: str) -> float:
    return float(params.value(key))


@dataclasses.dataclass(frozen=True)
class UncertaintySet:
    """The values ``keys`` around the file's ``nominal``: the box ``low <= theta <= high``, or (``axes`` given)
    the ellipsoid theta(z), |z| <= 1 (module docstring; ``low``, ``high``: its bounding box); ``label`` says
    where it comes from (``+-20 %``, the file's ``[uncertainty]`` or its ``[covariance]``)."""

    keys: tuple[str, ...]
    nominal: np.ndarray
    low: np.ndarray
    high: np.ndarray
    label: str
    axes: np.ndarray | None = None   # A (values x axes): the principal axes, columns, in log(value) or value
    log: tuple[bool, ...] = ()       # per value: A acts on log(value)

    @classmethod
    def from_fraction(cls, params: JointParameters, fraction: float) -> "UncertaintySet":
        keys = uncertain_keys(params)
        nominal = np.array([value_of(params, k) for k in keys])
        return cls(keys, nominal, nominal * (1 - fraction), nominal * (1 + fraction), f"+-{100 * fraction:g} %")

    @classmethod
    def from_file(cls, params: JointParameters, path: str | Path) -> "UncertaintySet":
        """The file's ``[uncertainty]`` intervals (dotted paths of the file's values; read and checked, each
        containing the file's value, when the file was loaded), or its ``[covariance]``'s 95 % ellipsoid."""
        intervals = params.scope.uncertainty
        require(len(intervals) > 0, str(path), "[uncertainty]", "<missing>",
                "no intervals: give --uncertainty FRACTION, or identify the motor to write them")
        cov = params.scope.covariance
        if cov is not None:
            return cls.ellipsoid(params, cov)
        keys = tuple(intervals)
        low, high = (np.array([intervals[k][i] for k in keys], float) for i in (0, 1))
        nominal = np.array([value_of(params, k) for k in keys])
        return cls(keys, nominal, low, high, "the file's [uncertainty]")

    @classmethod
    def ellipsoid(cls, params: JointParameters, cov) -> "UncertaintySet":
        """The 95 % confidence ellipsoid of a :class:`~thermo_ddp.model.scope.Covariance` (module docstring)."""
        lam, vec = np.linalg.eigh(cov.array)
        axes = cov.radius_95 * vec * np.sqrt(np.maximum(lam, 0.0))
        log = tuple(s == "log" for s in cov.scale)
        nominal = np.array([value_of(params, k) for k in cov.paths])
        reach = np.sqrt(np.sum(axes ** 2, axis=1))
        low, high = (np.where(log, nominal * np.exp(sign * reach), np.maximum(nominal + sign * reach, 0.0))
                     for sign in (-1, 1))
        return cls(cov.paths, nominal, low, high, "the file's [covariance] (95 % ellipsoid)", axes, log)

    @property
    def size(self) -> int:
        return len(self.keys)

    @property
    def is_ellipsoid(self) -> bool:
        return self.axes is not None

    def theta(self, z) -> np.ndarray:
        """The values at normalised coordinates ``z``: in [-1, 1]^d (the box's corners at +-1), or |z| <= 1
        (the ellipsoid's principal axes' ends at +-e_k)."""
        z = np.asarray(z, float)
        if self.is_ellipsoid:  # a linear value's ellipsoid may cross 0: no motor has a negative one
            step = self.axes @ z
            return np.where(self.log, self.nominal * np.exp(step), np.maximum(self.nominal + step, 0.0))
        return 0.5 * (self.low + self.high) + 0.5 * (self.high - self.low) * z

    def dtheta_dz(self, z) -> np.ndarray:
        """d theta / d z (values x d; a linear value held at 0 has a zero row)."""
        if self.is_ellipsoid:
            theta = self.theta(z)
            return np.where(self.log, theta, theta > 0.0)[:, None] * self.axes
        return np.diag(0.5 * (self.high - self.low))

    def z(self, theta) -> np.ndarray:
        theta = np.asarray(theta, float)
        if self.is_ellipsoid:
            step = np.where(self.log, np.log(np.maximum(theta, 1e-300) / self.nominal), theta - self.nominal)
            return np.linalg.lstsq(self.axes, step, rcond=None)[0]
        half = 0.5 * (self.high - self.low)
        return np.divide(theta - 0.5 * (self.low + self.high), half, out=np.zeros(self.size), where=half > 0)

    def sample(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` motors drawn uniformly in the box, or in the ellipsoid's ball of z, (count, d)."""
        if self.is_ellipsoid:
            z = self.boundary_points(rng, count) * rng.random((count, 1)) ** (1 / self.size)
            return np.array([self.theta(row) for row in z])
        return self.low + (self.high - self.low) * rng.random((count, self.size))

    def maximise(self, negative, starts, maxiter: int | None = None):
        """The best of local maximisations of a function in the set (``negative(z)`` -> (-f, -df/dz)) from
        ``starts``: L-BFGS-B on the box, SLSQP with |z|^2 <= 1 in the ellipsoid's ball."""
        if self.is_ellipsoid:
            ball = {"type": "ineq", "fun": lambda z: 1.0 - z @ z, "jac": lambda z: -2.0 * z}
            runs = (minimize(negative, z, jac=True, method="SLSQP", constraints=[ball],
                             options={"maxiter": maxiter or 100}) for z in starts)
        else:
            runs = (minimize(negative, z, jac=True, method="L-BFGS-B", bounds=[(-1, 1)] * self.size,
                             options={"maxiter": maxiter or 15000}) for z in starts)
        return min(runs, key=lambda r: r.fun)

    def project(self, z) -> np.ndarray:
        z = np.asarray(z, float)
        return z / max(1.0, float(np.linalg.norm(z))) if self.is_ellipsoid else np.clip(z, -1, 1)

    def first_order_worst(self, grad) -> np.ndarray:
        """The point of the set where the linearisation ``grad`` (of f by z) is largest: a vertex of the box,
        grad / |grad| on the ellipsoid's sphere."""
        grad = np.asarray(grad, float)
        if self.is_ellipsoid:
            return grad / max(float(np.linalg.norm(grad)), 1e-300)
        return np.where(grad >= 0, 1.0, -1.0)

    def neighbour(self, grad) -> np.ndarray:
        """A second start beside :meth:`first_order_worst`: the vertex with the smallest gradient component
        flipped, or the end of the ellipsoid's principal axis the gradient leans on most."""
        grad = np.asarray(grad, float)
        if self.is_ellipsoid:
            k = int(np.argmax(np.abs(grad)))
            return np.where(np.arange(self.size) == k, 1.0 if grad[k] >= 0 else -1.0, 0.0)
        out = self.first_order_worst(grad)
        out[np.argmin(np.abs(grad))] *= -1
        return out

    def boundary_points(self, rng: np.random.Generator, count: int) -> np.ndarray:
        """``count`` random points of z on the set's boundary: box vertices, or points of the ball's sphere."""
        if self.is_ellipsoid:
            direction = rng.standard_normal((count, self.size))
            return direction / np.linalg.norm(direction, axis=1)[:, None]
        return rng.choice([-1.0, 1.0], size=(count, self.size))

    def certified(self, z, grad) -> bool:
        """KKT of a maximum of f at ``z`` with gradient ``grad``: on the box, pointing out of every bound z
        sits on and vanishing elsewhere; in the ball, along +z on its sphere, vanishing inside."""
        scale = max(1e-9, float(np.abs(grad).max()))
        if self.is_ellipsoid:
            if abs(float(np.linalg.norm(z)) - 1.0) > 1e-4:
                return bool(np.abs(grad).max() <= 1e-3 * scale)
            return bool(grad @ z >= 0 and np.abs(grad - (grad @ z) * z).max() <= 1e-3 * scale)
        at_bound = np.abs(np.abs(z) - 1) < 1e-6
        return bool(np.all(np.where(at_bound, grad * z >= -1e-6 * scale, np.abs(grad) <= 1e-3 * scale)))

    def parameters(self, params: JointParameters, theta) -> JointParameters:
        """The parameter file with the values ``theta`` (validated like a file)."""
        values = dict(zip(self.keys, np.asarray(theta, float).tolist()))
        motor = params.with_values(values)  # one motor of the set: the file's own intervals no longer apply
        scope = dataclasses.replace(motor.scope, uncertainty={}, covariance=None)
        return dataclasses.replace(motor, scope=scope).checked()

    def to_dict(self) -> dict:
        out = {"set": self.label, "keys": list(self.keys), "low": self.low.tolist(), "high": self.high.tolist()}
        return out | ({"axes": self.axes.tolist()} if self.is_ellipsoid else {})


def check_fraction(fraction) -> float:
    ok = isinstance(fraction, (int, float, np.floating)) and not isinstance(fraction, bool) and 0 < fraction < 1
    require(ok, "plan_lift", "uncertainty", fraction, "expected a fraction 0 < FRACTION < 1 (0.2: every value "
            "within +-20 %)")
    return float(fraction)


# --------------------------------------------------------------------------------------------
# The scenario model: the elbow with theta as a runtime input
# --------------------------------------------------------------------------------------------
def _scenario_parameters(params: JointParameters, keys, theta):
    """The joint's motor and thermal network with the values ``keys`` replaced by the symbols ``theta``."""
    motor, values = params.motor, dict(params.thermal.values)
    for k, key in enumerate(keys):
        section, name = key.split(".", 1)
        if section == "motor":
            motor = dataclasses.replace(motor, **{name: theta[k]})
        else:
            values[name] = theta[k]
    return motor, network_from_parameters(dataclasses.replace(params.thermal, values=values))


def scenario_step(model: ActuatedArm, keys, dt_s: float, integrator: str, n_params: int, env_of) -> ca.Function:
    """``step(x, u, p, theta) -> x_next`` of the (one-joint) model: its mechanics (runtime payload) and its
    thermal network with the values ``keys`` read from ``theta``; ``env_of(p)`` gives [ambient_c, payload_kg]
    from the task's per-knot parameters ``p``."""
    joint, n = model.joints[0], model.nu
    x, u, env, theta = ca.SX.sym("x", model.nx), ca.SX.sym("u", n), ca.SX.sym("env", 2), ca.SX.sym("theta", len(keys))
    motor, network = _scenario_parameters(model.params[joint], keys, theta)
    mech = model.runtime_payload_functions[0](x, u, env)[:2 * n]
    heat = joint_heat_rhs(network, motor, x[2 * n:], u[0], x[n], env[0])
    ode = ca.Function("scenario_ode", [x, u, ca.vertcat(env, theta)], [ca.vertcat(mech, heat)],
                      ["x", "u", "env_theta"], ["xdot"])
    step = make_step(ode, dt_s, integrator)
    p = ca.SX.sym("p", n_params)
    return ca.Function("scenario_step", [x, u, p, theta], [step(x, u, ca.vertcat(env_of(p), theta))],
                       ["x", "u", "p", "theta"], ["x_next"])


def idle_temperatures(model: ActuatedArm, keys, pinned=()) -> ca.Function:
    """``idle(theta, ambient_c, start_c) -> temperatures_c`` at rest (no current, no motion) of scenario
    ``theta``: the nodes ``pinned`` (indices into the joint's thermal state) at ``start_c``'s values, every
    other node at its equilibrium given them (``pinned`` empty: the motor's own rest; every node: ``start_c``)."""
    joint = model.joints[0]
    theta, amb = ca.SX.sym("theta", len(keys)), ca.SX.sym("ambient_c")
    motor, network = _scenario_parameters(model.params[joint], keys, theta)
    n = len(network.nodes)
    temps, start = ca.SX.sym("t", n), ca.SX.sym("start_c", n)
    rhs = joint_heat_rhs(network, motor, temps, 0.0, 0.0, amb)
    a, b = ca.jacobian(rhs, temps), ca.substitute(rhs, temps, ca.DM.zeros(n))
    pinned = sorted(set(int(i) for i in pinned))
    free = [i for i in range(n) if i not in pinned]
    out = ca.SX(start)
    if free:  # the free nodes' heat balance with the pinned nodes given (the network is linear at rest)
        given = ca.mtimes(a[free, pinned], start[pinned]) if pinned else ca.DM.zeros(len(free))
        out[free] = ca.solve(a[free, free], -(b[free] + given))
    return ca.Function("idle_temperatures", [theta, amb, start], [out], ["theta", "ambient_c", "start_c"],
                       ["temperatures_c"])


# --------------------------------------------------------------------------------------------
# The worst motor of the set for a plan
# --------------------------------------------------------------------------------------------
@dataclasses.dataclass(frozen=True)
class WorstMotor:
    """The motor of the set with the highest winding peak for a plan: its values, peak, where on the
    box it sits, and whether the gradient there certifies a local maximum (KKT of the box)."""

    theta: np.ndarray
    peak_c: float
    z: np.ndarray
    certified: bool
    evaluations: int


class WorstCase:
    """Replays of one plan's current and motion (``us`` (N, 1), shared states ``qv`` (N+1, 2), per-knot
    parameters ``params`` (N+1, np)) through every motor of ``uset``: winding trajectories and their
    gradients with respect to theta, and the worst motor (:meth:`search`).

    Where every motor starts (:func:`idle_temperatures`): ``start_c`` None: each at its own rest; else the
    nodes ``pinned`` (None: every node) at ``start_c``, the others at each motor's equilibrium given them.
    ``start_c`` is the default of every method's ``start_c`` (a receding-horizon planner passes its estimate)."""

    def __init__(self, model: ActuatedArm, uset: UncertaintySet, step: ca.Function, winding_index: int,
                 start_c=None, pinned=None):
        self.model, self.uset, self.step, self.iw = model, uset, step, winding_index
        nodes = model.nx - 2 * model.nu
        self.pinned = () if start_c is None else tuple(range(nodes)) if pinned is None else tuple(pinned)
        self.idle = idle_temperatures(model, uset.keys)
        self.start = idle_temperatures(model, uset.keys, self.pinned)
        self.start_c = np.zeros(nodes) if start_c is None else np.asarray(start_c, float)
        self._replays: dict[int, ca.Function] = {}

    def with_set(self, uset: UncertaintySet) -> "WorstCase":
        """The same replays (compiled once) over another box of the same values."""
        require(uset.keys == self.uset.keys, "WorstCase", "uset.keys", uset.keys, f"expected {self.uset.keys}")
        other = copy.copy(self)
        other.uset = uset
        return other

    def initial_c(self, theta, ambient_c: float, start_c=None) -> np.ndarray:
        """Motor ``theta``'s temperatures at the start (see the class docstring)."""
        return np.array(self.start(theta, ambient_c, self._start(start_c))).ravel()

    def _start(self, start_c) -> np.ndarray:
        return self.start_c if start_c is None else np.asarray(start_c, float)

    def _replay(self, knots: int) -> ca.Function:
        """``replay(theta, qv, u, p, ambient_c) -> (winding_c (N+1,), peak_c, d peak / d theta)``."""
        if knots not in self._replays:
            self._replays[knots] = self._build_replay(knots)
        return self._replays[knots]

    def _build_replay(self, knots: int) -> ca.Function:
        n = self.model.nu
        t = ca.SX.sym("t", self.model.nx - 2 * n)
        qv, u, p, theta = (ca.SX.sym(k, s) for k, s in (("qv", 2 * n), ("u", n), ("p", self.step.size1_in(2)),
                                                         ("theta", self.uset.size)))
        thermal = ca.Function("thermal_next", [t, qv, u, p, theta], [self.step(ca.vertcat(qv, t), u, p, theta)[2 * n:]])
        roll = thermal.mapaccum(knots)
        th, amb = ca.MX.sym("theta", self.uset.size), ca.MX.sym("ambient_c")
        QV, U, P = ca.MX.sym("qv", 2 * n, knots), ca.MX.sym("u", n, knots), ca.MX.sym("p", p.numel(), knots)
        start = ca.MX.sym("start_c", t.numel())
        t0 = self.start(th, amb, start)
        temps = ca.horzcat(t0, roll(t0, QV, U, P, ca.repmat(th, 1, knots)))
        w = temps[self.iw - 2 * n, :].T
        peak = ca.mmax(w)  # its reverse-mode gradient is the gradient of the winding at the peak's knot
        return ca.Function("replay", [th, QV, U, P, amb, start], [w, peak, ca.gradient(peak, th)],
                           ["theta", "qv", "u", "p", "ambient_c", "start_c"], ["winding_c", "peak_c", "gradient"])

    def _call(self, theta, qv, us, params, ambient_c, start_c):
        return self._replay(us.shape[0])(theta, qv[:-1].T, us.T, params[:-1].T, ambient_c, self._start(start_c))

    def replay(self, theta, qv, us, params, ambient_c: float, start_c=None) -> np.ndarray:
        """Winding (N+1,) of motor ``theta`` under the plan."""
        return np.array(self._call(theta, qv, us, params, ambient_c, start_c)[0]).ravel()

    def peak(self, theta, qv, us, params, ambient_c: float, start_c=None) -> tuple[float, np.ndarray]:
        """The winding's peak of motor ``theta`` under the plan and its gradient with respect to theta."""
        _, peak, grad = self._call(theta, qv, us, params, ambient_c, start_c)
        return float(peak), np.array(grad).ravel()

    def search(self, qv, us, params, ambient_c: float, rng_seed: int = 0, start_c=None,
               starts: int = _STARTS) -> WorstMotor:
        """The motor with the highest winding peak: ascent in the set (:meth:`UncertaintySet.maximise`, z
        normalised) from the point the gradient at the file's values points to (a box vertex, or the
        ellipsoid's first-order worst point), its :meth:`UncertaintySet.neighbour` and random points of the
        set's boundary (``starts`` in all); the best end point, certified when the
        gradient there satisfies the set's KKT conditions (:meth:`UncertaintySet.certified`)."""
        calls = [0]
        uset = self.uset

        def negative_peak(z):
            calls[0] += 1
            peak, grad = self.peak(uset.theta(z), qv, us, params, ambient_c, start_c)
            return -peak, -grad @ uset.dtheta_dz(z)

        g0 = -negative_peak(uset.z(uset.nominal))[1]
        others = uset.boundary_points(np.random.default_rng(rng_seed), max(starts - 2, 0))
        best = uset.maximise(negative_peak, [uset.first_order_worst(g0), uset.neighbour(g0), *others][:starts],
                             maxiter=30)
        z = uset.project(best.x)
        grad = -negative_peak(z)[1]
        return WorstMotor(uset.theta(z), float(-best.fun), z, uset.certified(z, grad), calls[0])

    def hottest_idle_c(self, ambient_c: float) -> tuple[float, np.ndarray]:
        """The highest idle winding temperature of the set and its motor (the idle network is linear in
        the heat, so the search is the same ascent in the set)."""
        iw = self.iw - 2 * self.model.nu
        th = ca.SX.sym("theta", self.uset.size)
        w = self.idle(th, ambient_c, ca.DM.zeros(self.start_c.size))[iw]
        f = ca.Function("idle_winding", [th], [w, ca.gradient(w, th)])
        uset = self.uset

        def negative(z):
            value, grad = f(uset.theta(z))
            return -float(value), -np.array(grad).ravel() @ uset.dtheta_dz(z)

        z0 = uset.z(uset.nominal)
        best = uset.maximise(negative, [uset.first_order_worst(-negative(z0)[1]), z0])
        return -float(best.fun), uset.theta(uset.project(best.x))
