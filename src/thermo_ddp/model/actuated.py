"""One differentiable ODE for the arm, its motors and their thermal networks.

State x = [q (rad), v (rad/s), T (°C) of every thermal node of every joint], input u = winding
current per joint (A), parameter p = room ambient (°C). Everything below is built from the
CasADi expressions of rigid_body, motor and thermal: simulation, derivatives, code generation
and the planner all use these same functions.
"""
from __future__ import annotations

import functools
import hashlib
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import casadi as ca
import numpy as np

from . import motor
from .arm import Arm, ArmSettings, build_arm
from .._memo import Memo
from ..errors import InputError
from .integrators import check_implicit_steps, make_step, rk4_step_jacobians, rk4_substeps, step_jacobians
from .parameters import BOUNDS, Bound, JointParameters, load_parameters, packaged_parameter_file, parameters_from_dict
from .rigid_body import RigidBodyDynamics
from .thermal import ThermalNetwork, joint_heat_rhs, network_from_parameters

_SRC = "model"
STEP_S = Bound(1e-6, 10.0, "s", "an integration step: microseconds to seconds")
MAX_STEPS = 2_000_000  # steps of one simulation: its states take nx * 8 bytes each
_RUNTIME_PAYLOAD = Memo()  # structure_key -> runtime_payload_functions


def check_integrator(source: str, integrator: str) -> str:
    """``integrator`` is rk4, rk4_<sub-steps> or implicit_euler; InputError otherwise."""
    ok = isinstance(integrator, str) and (integrator == "implicit_euler" or rk4_substeps(integrator) is not None)
    if not ok:
        raise InputError(source, "integrator", integrator, "choose rk4, rk4_<sub-steps> or implicit_euler")
    return integrator


def _finite_array(name: str, value, shape_text: str) -> np.ndarray:
    try:
        a = np.asarray(value, dtype=float)
    except (TypeError, ValueError):
        raise InputError(_SRC, name, repr(value)[:60], f"expected numbers, {shape_text}") from None
    if not np.all(np.isfinite(a)):
        raise InputError(_SRC, name, "non-finite values", f"expected finite numbers, {shape_text}")
    return a


@dataclass(frozen=True)
class ActuatedArm:
    """The composed model. Build it with :func:`load_model` or :meth:`from_parameters`."""

    arm: Arm
    params: Mapping[str, JointParameters]
    networks: Mapping[str, ThermalNetwork]

    @classmethod
    def from_parameters(cls, arm_settings: ArmSettings, params: Mapping[str, JointParameters],
                        networks: Mapping[str, ThermalNetwork] | None = None) -> "ActuatedArm":
        """The model from parameter files; ``networks`` replaces the files' thermal networks (e.g. a
        simulated robot's own network, with heat sources the contract's models do not have)."""
        for j in arm_settings.joints:
            if j not in params:
                raise InputError("model", "parameters", j, "no parameter file for this joint")
            if params[j].joint != j:
                raise InputError(params[j].path, "joint.name", params[j].joint, f"expected {j}")
        arm = build_arm(arm_settings, {j: params[j].motor.armature_kg_m2 for j in arm_settings.joints})
        params = {j: params[j] for j in arm.joints}
        networks = {j: (networks or {}).get(j) or network_from_parameters(p.thermal) for j, p in params.items()}
        return cls(arm, params, networks)

    # --- functions at this model's payload (built on first use: a planner with the payload as a runtime
    # parameter uses only :attr:`runtime_payload_functions`, shared by every payload) ------------------
    @functools.cached_property
    def _functions(self) -> tuple[ca.Function, ca.Function, ca.Function]:
        return _build_functions(self.arm, self.params, self.networks)

    @property
    def ode(self) -> ca.Function:
        """``arm_ode(x, current_a, ambient_c) -> xdot``."""
        return self._functions[0]

    @property
    def ode_jacobians(self) -> ca.Function:
        """``arm_ode_jacobians(x, current_a, ambient_c) -> (xdot, dxdot_dx, dxdot_du)`` (analytic
        rigid-body partials)."""
        return self._functions[1]

    @property
    def outputs(self) -> ca.Function:
        """``arm_outputs(x, current_a, ambient_c) -> voltage_v, joint_torque_nm, joule_w, friction_w,
        winding_c, sensor_c`` (one entry per joint)."""
        return self._functions[2]

    @functools.cached_property
    def structure_key(self) -> str:
        """Hash of everything this model's functions are built from but the payload's mass: models that
        differ only in their payload share it (and their :attr:`runtime_payload_functions`)."""
        arm = self.arm
        text = repr((sorted((j, p.to_dict()) for j, p in self.params.items()), arm.settings.robot, arm.joints,
                     sorted(arm.locked_joints.items()), np.asarray(arm.model.gravity.linear).tolist(),
                     arm.payload_frame, arm.payload_translation_m.tolist(), sorted(self.networks.items())))
        return hashlib.sha256(text.encode()).hexdigest()[:24]

    @property
    def runtime_payload_functions(self) -> tuple[ca.Function, ca.Function]:
        """``ode`` and ``ode_jacobians`` with the payload as a runtime input: the third input is
        ``ambient_payload`` = [ambient_c, payload_kg] (this model's own payload is not used). Built once
        per :attr:`structure_key` in a process."""
        return _RUNTIME_PAYLOAD.get(self.structure_key, lambda: _build_functions(
            self.arm, self.params, self.networks, runtime_payload=True)[:2])

    # --- names and layout -------------------------------------------------------------
    @property
    def joints(self) -> tuple[str, ...]:
        return self.arm.joints

    @property
    def nu(self) -> int:
        return len(self.joints)

    @property
    def nx(self) -> int:
        return 2 * self.nu + sum(len(self.networks[j].nodes) for j in self.joints)

    @property
    def state_names(self) -> tuple[str, ...]:
        names = [f"{j}:q_rad" for j in self.joints] + [f"{j}:v_rad_s" for j in self.joints]
        for j in self.joints:
            names += [f"{j}:{s}" for s in self.networks[j].state_names]
        return tuple(names)

    @property
    def control_names(self) -> tuple[str, ...]:
        return tuple(f"{j}:current_a" for j in self.joints)

    def index(self, joint: str, quantity: str) -> int:
        """Index in x of e.g. ``("arm_left_4_joint", "winding_c")``."""
        return self.state_names.index(f"{joint}:{quantity}")

    def node_indices(self, node: str) -> list[int]:
        """Index of thermal ``node`` for each joint (ValueError if a joint lacks it)."""
        return [self.index(j, f"{node}_c") for j in self.joints]

    def sensor_indices(self) -> list[int]:
        """Index of each joint's measured node (the casing; the winding of a one-node network)."""
        return [self.index(j, f"{self.networks[j].sensor_node}_c") for j in self.joints]

    @property
    def ambient_c(self) -> float:
        return float(np.mean([p.thermal.ambient_c for p in self.params.values()]))

    def to_dict(self, integrator: str, dt_s: float) -> dict:
        """The plan JSON's ``model``: enough to rebuild this model and its step exactly."""
        return {"motors": {j: p.to_dict() for j, p in self.params.items()},
                "robot": self.arm.settings.robot,
                "locked_joints": dict(self.arm.locked_joints),
                "gravity_m_s2": np.asarray(self.arm.model.gravity.linear).tolist(),
                "payload": self.arm.payload_dict(),
                "integrator": integrator, "dt_s": dt_s}

    # --- states -----------------------------------------------------------------------
    def idle_temperatures(self, ambient_c: float | None = None) -> np.ndarray:
        """Steady temperatures of every node with no current and no motion (drive idle heat)."""
        amb = self.ambient_c if ambient_c is None else ambient_c
        return np.concatenate([self.networks[j].steady_state(motor.losses_w(self.params[j].motor, 0.0, 0.0, amb), amb)
                               for j in self.joints])

    def state(self, q=None, v=None, temperatures_c=None) -> np.ndarray:
        """A state vector; defaults: q = 0 (arm hanging), v = 0, the idle temperatures."""
        n = self.nu
        q = np.zeros(n) if q is None else self._vector("q", q, n, "rad")
        v = np.zeros(n) if v is None else self._vector("v", v, n, "rad/s")
        nt = self.nx - 2 * n
        t = self.idle_temperatures() if temperatures_c is None else self._vector("temperatures_c", temperatures_c, nt, "°C")
        return np.concatenate([q, v, t])

    @staticmethod
    def _vector(name: str, value, size: int, unit: str) -> np.ndarray:
        """``value`` as ``size`` finite numbers (InputError naming ``name``, the shape and the unit)."""
        a = _finite_array(name, value, f"shape ({size},) in {unit}").reshape(-1)
        if a.size != size:
            raise InputError(_SRC, name, f"{a.size} values", f"expected {size} (one per joint or node) in {unit}")
        return a

    # --- functions --------------------------------------------------------------------
    def step(self, dt_s: float, integrator: str = "rk4") -> "Step":
        """``step(x, current_a, ambient_c=None) -> x_next`` on numpy arrays, as :meth:`state` returns them
        (``ambient_c`` None: the model's room); its CasADi Function is ``step.function`` (:meth:`step_function`)."""
        return Step(self.step_function(dt_s, integrator), self.ambient_c)

    def step_function(self, dt_s: float, integrator: str = "rk4", runtime_payload: bool = False) -> ca.Function:
        """The CasADi Function ``step(x, current_a, ambient_c) -> x_next`` (symbolic use, ``mapaccum``,
        code generation); with ``runtime_payload`` the third input is ``ambient_payload`` = [ambient_c,
        payload_kg] (the model's own payload is then not used)."""
        dt_s = STEP_S.check(_SRC, "dt_s", dt_s, "out of range")
        ode = self.runtime_payload_functions[0] if runtime_payload else self.ode
        return make_step(ode, dt_s, check_integrator(_SRC, integrator))

    def step_jacobians(self, dt_s: float, integrator: str = "rk4", runtime_payload: bool = False) -> ca.Function:
        """Named ``step_jacobians(x, current_a, ambient_c) -> (x_next, A, B)`` (inputs as :meth:`step_function`)."""
        dt_s = STEP_S.check(_SRC, "dt_s", dt_s, "out of range")
        substeps = rk4_substeps(check_integrator(_SRC, integrator))
        if substeps is not None:
            jac = self.runtime_payload_functions[1] if runtime_payload else self.ode_jacobians
            return rk4_step_jacobians(jac, dt_s, substeps)
        return step_jacobians(self.step_function(dt_s, integrator, runtime_payload))

    def static_current_a(self, q) -> np.ndarray:
        """Currents that hold posture ``q`` (nu,) at rest, or each row of postures (K, nu) (gravity only;
        friction is zero at v = 0)."""
        rows = np.atleast_2d(_finite_array("q", q, f"shape ({self.nu},) or (K, {self.nu}) in rad"))
        if np.ndim(q) > 2 or rows.shape[1] != self.nu:
            raise InputError(_SRC, "q", f"shape {np.shape(q)}", f"expected ({self.nu},) or (K, {self.nu}) in rad")
        g = self.arm.gravity_torque_nm(rows)
        current = np.column_stack([np.asarray(motor.current_for_torque_a(self.params[j].motor, g[:, k]), float).ravel()
                                   for k, j in enumerate(self.joints)])
        return current if np.ndim(q) == 2 else current[0]

    def simulate(self, x0, current_a, dt_s: float, integrator: str = "rk4", ambient_c=None) -> "Trajectory":
        """Plant simulation with zero-order-hold currents ``current_a`` of shape (N, nu)."""
        x0, u, amb = self._simulation_inputs(x0, current_a, ambient_c)
        n = u.shape[0]
        sim = self.step_function(dt_s, integrator).mapaccum(n)
        xs = np.vstack([x0, np.array(sim(x0, u.T, amb.reshape(1, -1))).T])
        if integrator == "implicit_euler":  # its fixed Newton iterations, checked
            check_implicit_steps(self.ode, float(dt_s), xs, u, amb.reshape(-1, 1))
        return Trajectory(self, np.arange(n + 1) * float(dt_s), xs, u, amb)

    def _simulation_inputs(self, x0, current_a, ambient_c) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """x0 (nx,), currents (N, nu) and ambient (N,), checked: finite, shaped, N in 1..MAX_STEPS.
        Currents may be (N,) for one joint, or (nu,) for one step."""
        x0 = _finite_array("x0", x0, f"shape ({self.nx},)")
        if x0.shape != (self.nx,):
            raise InputError(_SRC, "x0", f"shape {x0.shape}", f"expected shape ({self.nx},): {', '.join(self.state_names)}")
        u = _finite_array("current_a", current_a, f"shape (N, {self.nu}) in A")
        if u.ndim == 1 and (self.nu == 1 or u.size == self.nu):
            u = u.reshape(-1, self.nu)
        if u.ndim != 2 or u.shape[1] != self.nu or not 1 <= u.shape[0] <= MAX_STEPS:
            raise InputError(_SRC, "current_a", f"shape {u.shape}",
                             f"expected shape (N, {self.nu}) with 1 <= N <= {MAX_STEPS} steps (memory)")
        n = u.shape[0]
        if ambient_c is None:
            return x0, u, np.full(n, self.ambient_c)
        amb = _finite_array("ambient_c", ambient_c, f"a number or shape ({n},) in °C")
        if amb.shape not in ((), (n,)):
            raise InputError(_SRC, "ambient_c", f"shape {amb.shape}", f"expected a number or shape ({n},) in °C")
        for value in np.unique(amb):
            BOUNDS["ambient_c"].check(_SRC, "ambient_c", value)
        return x0, u, np.broadcast_to(amb, (n,)).astype(float)


@dataclass(frozen=True)
class Step:
    """One integration step on numpy arrays: ``step(x, current_a, ambient_c=None)`` -> ``x_next`` (nx,);
    ``function`` is the CasADi Function it calls (for symbolic use)."""

    function: ca.Function
    default_ambient_c: float

    def __call__(self, x, current_a, ambient_c=None) -> np.ndarray:
        ambient = self.default_ambient_c if ambient_c is None else ambient_c
        return np.asarray(self.function(x, current_a, ambient), dtype=float).reshape(-1)


@dataclass(frozen=True)
class Trajectory:
    """States xs (N+1, nx) and currents us (N, nu) on ``time_s``, with named accessors."""

    model: ActuatedArm
    time_s: np.ndarray
    xs: np.ndarray
    us: np.ndarray
    ambient_c: np.ndarray

    def __getitem__(self, quantity: str) -> np.ndarray:
        """``traj["winding_c"]`` -> (N+1, joints); also q_rad, v_rad_s and other node names."""
        return self.xs[:, [self.model.index(j, quantity) for j in self.model.joints]]

    def output(self, name: str) -> np.ndarray:
        """(N, joints) of an ``outputs`` quantity (voltage_v, joule_w, ...) at each control knot."""
        f = self.model.outputs.map(len(self.us))
        out = f(self.xs[:-1].T, self.us.T, self.ambient_c.reshape(1, -1))
        return np.array(out[self.model.outputs.name_out().index(name)]).T


def _build_functions(arm: Arm, params, networks, runtime_payload: bool = False) -> tuple[ca.Function, ...]:
    """``arm_ode``, ``arm_ode_jacobians`` (analytic rigid-body partials) and ``arm_outputs``, at the arm's
    payload or, with ``runtime_payload``, with the input ``ambient_payload`` = [ambient_c, payload_kg]."""
    n = arm.nv
    sizes = [len(networks[j].nodes) for j in arm.joints]
    x = ca.SX.sym("x", 2 * n + sum(sizes))
    u = ca.SX.sym("current_a", n)
    ambient, env = ca.SX.sym("ambient_c"), ca.SX.sym("ambient_payload", 2)
    if runtime_payload:
        ambient, payload = env[0], env[1]
        rigid = RigidBodyDynamics(arm.model, (arm.unloaded_inertias, arm.inertias_per_payload_kg))
    else:
        payload, rigid = None, RigidBodyDynamics(arm.model)
    q, v = x[:n], x[n:2 * n]
    offsets = np.cumsum([2 * n] + sizes)
    tau, dtemps, outs = [], [], {k: [] for k in ("voltage_v", "joint_torque_nm", "joule_w", "friction_w",
                                                 "winding_c", "sensor_c")}
    for k, j in enumerate(arm.joints):
        m, net = params[j].motor, networks[j]
        temps = x[offsets[k]:offsets[k + 1]]
        winding = temps[net.index(net.limit_node)]
        tau.append(motor.joint_torque_nm(m, u[k], v[k]))
        dtemps.append(joint_heat_rhs(net, m, temps, u[k], v[k], ambient))
        for key, val in (("voltage_v", motor.voltage_v(m, u[k], v[k], winding)), ("joint_torque_nm", tau[-1]),
                         ("joule_w", motor.joule_w(m, u[k], winding)), ("friction_w", motor.friction_w(m, v[k])),
                         ("winding_c", winding), ("sensor_c", temps[net.index(net.sensor_node)])):
            outs[key].append(val)
    tau, dtemps = ca.vertcat(*tau), ca.vertcat(*dtemps)
    tau_sym = ca.SX.sym("tau", n)
    acc, da_dq, da_dv, minv = (ca.substitute(e, tau_sym, tau) for e in rigid.aba_derivatives(q, v, tau_sym, payload))
    xdot = ca.vertcat(v, acc, dtemps)
    nt = x.numel() - 2 * n
    dxdot_dx = ca.vertcat(
        ca.horzcat(ca.SX.zeros(n, n), ca.SX.eye(n), ca.SX.zeros(n, nt)),
        ca.horzcat(da_dq, da_dv + minv @ ca.jacobian(tau, v), ca.SX.zeros(n, nt)),
        ca.jacobian(dtemps, x))
    dxdot_du = ca.vertcat(ca.SX.zeros(n, n), minv @ ca.jacobian(tau, u), ca.jacobian(dtemps, u))
    p, suffix = (env, "_payload") if runtime_payload else (ambient, "")
    names_in = ["x", "current_a", "ambient_payload" if runtime_payload else "ambient_c"]
    ode = ca.Function("arm_ode" + suffix, [x, u, p], [xdot], names_in, ["xdot"])
    ode_jac = ca.Function("arm_ode_jacobians" + suffix, [x, u, p], [xdot, dxdot_dx, dxdot_du], names_in,
                          ["xdot", "dxdot_dx", "dxdot_du"])
    outputs = ca.Function("arm_outputs" + suffix, [x, u, p], [ca.vertcat(*vals) for vals in outs.values()],
                          names_in, list(outs))
    return ode, ode_jac, outputs


def model_from_dict(data: Mapping) -> ActuatedArm:
    """Rebuild the model echoed in a plan's ``model`` (see :meth:`ActuatedArm.to_dict`)."""
    motors = data["motors"]
    settings = ArmSettings(joints=tuple(motors), posture=dict(data["locked_joints"]),
                           payload_kg=data["payload"]["mass_kg"], payload_lever_m=data["payload"]["lever_m"],
                           robot=data["robot"])
    params = {j: parameters_from_dict(sections, f"plan model.motors.{j}") for j, sections in motors.items()}
    model = ActuatedArm.from_parameters(settings, params)
    if not np.allclose(model.arm.model.gravity.linear, data["gravity_m_s2"]):
        raise InputError("plan model", "gravity_m_s2", data["gravity_m_s2"], "only standard gravity is supported")
    return model


def load_model(joints=("arm_left_4_joint",), payload_kg: float = 0.0, payload_lever_m: float | None = None,
               posture: Mapping[str, float] | None = None,
               parameter_files: Mapping[str, str | Path] | None = None) -> ActuatedArm:
    """The composed model from the packaged ``models/<joint>.toml`` (or the given files)."""
    files = {j: packaged_parameter_file(j) for j in joints}
    files.update(parameter_files or {})
    kwargs = {} if payload_lever_m is None else {"payload_lever_m": payload_lever_m}
    settings = ArmSettings(joints=tuple(joints), posture=dict(posture or {}), payload_kg=payload_kg, **kwargs)
    return ActuatedArm.from_parameters(settings, {j: load_parameters(files[j]) for j in joints})
