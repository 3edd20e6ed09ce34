"""True plant of the simulated elbow: numpy mechanics, scipy integration.

Its mechanics are independent of the package's model (prescribed motion, inverse dynamics of a
pendulum); its thermal network is data of the package's network type (``plant_network``) with heat
sources the contract's models lack or place differently, so the diagnosis tests compare those models
against a plant whose structure differs from theirs.

Conventions
- Joint angle q [rad]: 0 = forearm hanging down, positive = flexion, pi/2 = forearm
  horizontal. (Talos' URDF flexes the elbow with *negative* angles; this plant uses the
  pendulum convention, so the gravity torque the actuator supplies is positive.)
- Gravity torque: tau_g = g sin(q) (m_forearm l_com + m_payload lever).
- ``effort`` = torque after the harmonic drive (link side, as measured in report 4.3):
  effort = tau_g + J_link ddq + tau_external.
- Motor current (joint side): N Kt i = effort + N^2 B_m ddq + tau_friction(dq) + effort_offset,
  tau_friction = viscous dq + coulomb tanh(dq / smoothing).
- Friction heat |tau_friction dq| (joint side, >= 0): a fraction ``friction_to_winding``
  goes to the winding node, the rest to the casing (harmonic drive sits on the housing).
- Thermal nodes: winding, casing and (with ``drive_heating``) the drive electronics;
  the temperature sensor sits on the casing.
"""
from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Callable

import casadi as ca
import numpy as np
from scipy.integrate import solve_ivp

from ..._config import require
from ...model import motor
from ...model.parameters import BOUNDS, checked_value
from ...model.thermal import AMBIENT, HeatSource, Link, ThermalNetwork, joint_heat_rhs

Signal = Callable[[np.ndarray], np.ndarray]
Motion = Callable[[np.ndarray], tuple[np.ndarray, np.ndarray, np.ndarray]]

# The thermal values randomised() scales (the two_node_drive keys; this order fixes the random draws).
THERMAL_FIELDS = (
    "winding_capacity_j_per_k", "casing_capacity_j_per_k", "drive_capacity_j_per_k",
    "winding_casing_k_per_w", "casing_ambient_k_per_w", "drive_casing_k_per_w",
    "drive_ambient_k_per_w", "drive_idle_w", "drive_loss_w_per_a2",
)
FRICTION_FIELDS = ("viscous_friction_nm_s_per_rad", "coulomb_friction_nm")
REGIMES = ("idle", "static", "moving", "cooling")
IMPLICIT = ("Radau", "BDF", "LSODA")
# Fields outside the parameter-file catalogue (model.parameters.BOUNDS checks the others).
SIGNED_FIELDS = ("effort_offset_nm",)
NONNEGATIVE_FIELDS = ("friction_to_winding", "forearm_inertia_kg_m2")


@dataclass(frozen=True)
class PlantParameters:
    """True parameters of the simulated elbow (joint-side mechanics, SI units)."""

    # mechanics
    gear_ratio: float = 100.0  # Talos elbow, example-robot-data talos.srdf rotor_params gear_ratio
    torque_constant_nm_per_a: float = 0.1106  # motor side; report eq. 9 slope 11.06 N·m/A / 100
    rotor_inertia_kg_m2: float = 1e-5  # example-robot-data talos.srdf rotor_params "mass" (inertia)
    viscous_friction_nm_s_per_rad: float = 0.3  # as models/arm_left_4_joint.toml (assumption)
    coulomb_friction_nm: float = 1.17  # report eq. 9 offset
    coulomb_smoothing_rad_s: float = 0.05
    effort_offset_nm: float = 0.2  # small constant torque bias (sensor/cogging), an assumption
    forearm_mass_kg: float = 1.1  # talos_left_arm.urdf arm_left_4_link mass 1.10216 kg
    forearm_com_m: float = 0.15  # assumption: forearm centre of mass about 0.15 m from the elbow axis
    forearm_inertia_kg_m2: float = 0.0024  # about its COM, urdf arm_left_4_link iyy
    gravity_m_s2: float = 9.81
    # electrical: R(T_w) = R_ref (1 + alpha (T_w - T_ref)), report eq. 3
    resistance_ohm: float = 0.70  # as models/arm_left_4_joint.toml, at resistance_ref_c
    resistance_ref_c: float = 25.0
    copper_alpha_per_k: float = 0.00393  # report eq. 3, copper
    # thermal network: the values of models/arm_left_4_joint.toml (see its [sources])
    winding_capacity_j_per_k: float = 40.0
    casing_capacity_j_per_k: float = 1200.0
    drive_capacity_j_per_k: float = 300.0
    winding_casing_k_per_w: float = 0.9
    casing_ambient_k_per_w: float = 1.3
    drive_casing_k_per_w: float = 0.6
    drive_ambient_k_per_w: float = 2.5
    drive_idle_w: float = 23.0  # gives the report's idle casing ~43 °C in a 26 °C room
    drive_loss_w_per_a2: float = 0.1
    friction_to_winding: float = 0.5  # share of friction heat into the winding, rest to casing
    # effects the baseline one-node model lacks
    friction_heating: bool = True
    drive_heating: bool = True

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if field.type == "bool":
                require(isinstance(value, bool), "PlantParameters", field.name, value, "expected a bool")
                continue
            if field.name in BOUNDS:
                checked_value("PlantParameters", field.name, field.name, value)
                continue
            require(isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value),
                    "PlantParameters", field.name, value, "expected a finite number")
            if field.name in SIGNED_FIELDS:
                continue
            nonnegative = field.name in NONNEGATIVE_FIELDS
            require(value >= 0 if nonnegative else value > 0, "PlantParameters", field.name, value,
                    "must be >= 0" if nonnegative else "must be > 0")
        require(self.friction_to_winding <= 1, "PlantParameters", "friction_to_winding",
                self.friction_to_winding, "must be in [0, 1]")

    @property
    def node_names(self) -> tuple[str, ...]:
        return ("winding", "casing", "drive") if self.drive_heating else ("winding", "casing")

    @property
    def effects(self) -> dict[str, bool]:
        return {"friction_heating": self.friction_heating, "drive_heating": self.drive_heating}

    def with_effects(self, effects: str) -> "PlantParameters":
        """Copy with the effects 'none' | 'friction' | 'drive' | 'both' switched on."""
        require(effects in EFFECTS, "PlantParameters", "effects", effects, f"expected one of {EFFECTS}")
        return dataclasses.replace(self, friction_heating=effects in ("friction", "both"),
                                   drive_heating=effects in ("drive", "both"))

    def randomised(self, rng: np.random.Generator, thermal_spread: float = 0.25,
                   friction_spread: float = 0.30) -> "PlantParameters":
        """Copy with thermal values scaled by U(1 ± thermal_spread), friction by U(1 ± friction_spread)."""
        scaled = {name: getattr(self, name) * rng.uniform(1 - thermal_spread, 1 + thermal_spread)
                  for name in THERMAL_FIELDS}
        scaled |= {name: getattr(self, name) * rng.uniform(1 - friction_spread, 1 + friction_spread)
                   for name in FRICTION_FIELDS}
        scaled["friction_to_winding"] = rng.uniform(0.25, 1.0)
        return dataclasses.replace(self, **scaled)

    def to_dict(self) -> dict[str, float | bool]:
        return dataclasses.asdict(self)


EFFECTS = ("none", "friction", "drive", "both")


@dataclass(frozen=True)
class Ambient:
    """Room temperature: constant, optional linear drift and one smooth step."""

    room_c: float = 26.0
    drift_c_per_h: float = 0.0
    step_c: float = 0.0
    step_at_s: float = math.inf
    step_duration_s: float = 600.0

    def __call__(self, t: np.ndarray | float) -> np.ndarray:
        t = np.asarray(t, dtype=float)
        x = np.clip((t - self.step_at_s) / self.step_duration_s, 0.0, 1.0)
        return self.room_c + self.drift_c_per_h * t / 3600.0 + self.step_c * smoothstep(x)

    def breakpoints(self) -> tuple[float, ...]:
        if not math.isfinite(self.step_at_s):
            return ()
        return (self.step_at_s, self.step_at_s + self.step_duration_s)


# ----------------------------------------------------------------------------- signals
def smoothstep(x: np.ndarray) -> np.ndarray:
    """Cubic 0->1 on [0, 1] with zero slope at both ends."""
    x = np.clip(x, 0.0, 1.0)
    return x * x * (3.0 - 2.0 * x)


def constant(value: float) -> Signal:
    value = float(value)
    return lambda t: 0.0 * t + value  # works on floats (fast ODE path) and arrays


def staircase(times_s: np.ndarray, increments: np.ndarray, rise_s: float, start: float = 0.0) -> Signal:
    """start + sum of smooth steps of ``increments`` beginning at ``times_s`` (each rising over rise_s)."""
    times_s, increments = np.asarray(times_s, float), np.asarray(increments, float)

    def signal(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, float)
        x = (t[..., None] - times_s) / rise_s
        return start + (smoothstep(x) * increments).sum(axis=-1)
    return signal


def gaussian_pulses(centers_s: np.ndarray, amplitudes: np.ndarray, widths_s: np.ndarray) -> Signal:
    """Sum of Gaussian bumps (touch spikes on the load torque)."""
    centers_s, amplitudes, widths_s = (np.asarray(a, float) for a in (centers_s, amplitudes, widths_s))

    def signal(t: np.ndarray) -> np.ndarray:
        t = np.asarray(t, float)
        z = (t[..., None] - centers_s) / widths_s
        return (amplitudes * np.exp(-0.5 * z * z)).sum(axis=-1)
    return signal


def hold(q_rad: float) -> Motion:
    q_rad = float(q_rad)
    return lambda t: (0.0 * t + q_rad, 0.0 * t, 0.0 * t)


def min_jerk(q0: float, q1: float, duration_s: float) -> Motion:
    """Quintic rest-to-rest move from q0 to q1."""
    def motion(t: np.ndarray):
        x = np.clip(np.asarray(t, float) / duration_s, 0.0, 1.0)
        d = q1 - q0
        q = q0 + d * (10 * x**3 - 15 * x**4 + 6 * x**5)
        dq = d * (30 * x**2 - 60 * x**3 + 30 * x**4) / duration_s
        ddq = d * (60 * x - 180 * x**2 + 120 * x**3) / duration_s**2
        return q, dq, ddq
    return motion


def curl(center_rad: float, amplitude_rad: float, period_s: float) -> Motion:
    """Biceps curl q = center - amplitude cos(w t): starts at rest at the bottom of the swing."""
    w = 2 * math.pi / period_s

    def motion(t: np.ndarray):
        t = np.asarray(t, float)
        c, s = np.cos(w * t), np.sin(w * t)
        return center_rad - amplitude_rad * c, amplitude_rad * w * s, amplitude_rad * w * w * c
    return motion


# ----------------------------------------------------------------------------- profile
@dataclass(frozen=True)
class Phase:
    """One stretch of the experiment: prescribed motion and load as functions of local time."""

    name: str
    regime: str
    duration_s: float
    motion: Motion
    payload_kg: Signal = constant(0.0)
    lever_m: Signal = constant(0.0)
    external_nm: Signal = constant(0.0)
    motor_on: bool = True
    max_step_s: float = math.inf
    fine_windows: tuple[tuple[float, float, float], ...] = ()  # (start, end, max_step) local time

    def __post_init__(self) -> None:
        require(self.regime in REGIMES, "Phase", "regime", self.regime, f"expected one of {REGIMES}")
        require(self.duration_s > 0, "Phase", "duration_s", self.duration_s, "must be > 0")


@dataclass(frozen=True)
class Mechanics:
    """Joint-side mechanical quantities at given times (arrays)."""

    q_rad: np.ndarray
    v_rad_s: np.ndarray
    a_rad_s2: np.ndarray
    gravity_nm: np.ndarray
    effort_nm: np.ndarray
    friction_nm: np.ndarray
    current_a: np.ndarray
    friction_w: np.ndarray  # mechanical friction power (whether or not it heats the motor)


def phase_mechanics(params: PlantParameters, phase: Phase, local_t: np.ndarray) -> Mechanics:
    """Inverse dynamics of the prescribed motion: the current the position controller needs."""
    p = params
    q, dq, ddq = phase.motion(local_t)
    m_p, lever = phase.payload_kg(local_t), phase.lever_m(local_t)
    static_moment = p.forearm_mass_kg * p.forearm_com_m + m_p * lever
    gravity = p.gravity_m_s2 * np.sin(q) * static_moment
    link_inertia = p.forearm_inertia_kg_m2 + p.forearm_mass_kg * p.forearm_com_m**2 + m_p * lever**2
    effort = gravity + link_inertia * ddq + phase.external_nm(local_t)
    friction = p.viscous_friction_nm_s_per_rad * dq + p.coulomb_friction_nm * np.tanh(dq / p.coulomb_smoothing_rad_s)
    motor_torque = effort + p.gear_ratio**2 * p.rotor_inertia_kg_m2 * ddq + friction + p.effort_offset_nm
    on = 1.0 if phase.motor_on else 0.0
    current = on * motor_torque / (p.gear_ratio * p.torque_constant_nm_per_a)
    return Mechanics(q, dq, ddq, on * gravity, on * effort, on * friction, current, on * np.abs(friction * dq))


def motor_voltage_v(params: PlantParameters, current_a: np.ndarray, winding_c: np.ndarray,
                    velocity_rad_s: np.ndarray) -> np.ndarray:
    """Motor terminal voltage R(T_w) i + K_b N v (report eqs. 2-4; K_b = K_m in SI units)."""
    p = params
    resistance = p.resistance_ohm * (1 + p.copper_alpha_per_k * (winding_c - p.resistance_ref_c))
    return resistance * current_a + p.torque_constant_nm_per_a * p.gear_ratio * velocity_rad_s


@dataclass(frozen=True)
class Profile:
    """The experiment as a sequence of phases starting at t = 0."""

    phases: tuple[Phase, ...]

    @property
    def starts_s(self) -> np.ndarray:
        return np.concatenate([[0.0], np.cumsum([ph.duration_s for ph in self.phases])[:-1]])

    @property
    def duration_s(self) -> float:
        return float(sum(ph.duration_s for ph in self.phases))

    def phase_table(self) -> tuple[tuple[str, str, float, float], ...]:
        """(name, regime, start_s, end_s) of every phase."""
        return tuple((ph.name, ph.regime, float(s), float(s + ph.duration_s))
                     for ph, s in zip(self.phases, self.starts_s))

    def mechanics(self, params: PlantParameters, t: np.ndarray) -> Mechanics:
        """Mechanics at absolute times t (any shape is flattened)."""
        t = np.atleast_1d(np.asarray(t, float)).ravel()
        index = np.clip(np.searchsorted(self.starts_s, t, side="right") - 1, 0, len(self.phases) - 1)
        out = {f.name: np.zeros_like(t) for f in dataclasses.fields(Mechanics)}
        for k, (phase, start) in enumerate(zip(self.phases, self.starts_s)):
            mask = index == k
            if mask.any():
                part = phase_mechanics(params, phase, t[mask] - start)
                for name in out:
                    out[name][mask] = getattr(part, name)
        return Mechanics(**out)

    def segments(self, extra_breaks: tuple[float, ...] = ()) -> list[tuple[int, float, float, float]]:
        """(phase index, start, end, max_step) pieces on which the inputs are smooth."""
        pieces = []
        for k, (phase, start) in enumerate(zip(self.phases, self.starts_s)):
            end = start + phase.duration_s
            cuts = {start, end} | {start + w for win in phase.fine_windows for w in win[:2]}
            cuts |= {b for b in extra_breaks if start < b < end}
            cuts = sorted(c for c in cuts if start <= c <= end)
            for a, b in zip(cuts[:-1], cuts[1:]):
                if b - a < 1e-9:
                    continue
                step = phase.max_step_s
                for w0, w1, w_step in phase.fine_windows:
                    if start + w0 <= a and b <= start + w1:
                        step = min(step, w_step)
                pieces.append((k, a, b, step))
        return pieces


# ----------------------------------------------------------------------------- thermal
def plant_network(params: PlantParameters) -> ThermalNetwork:
    """The plant's thermal network, as data of the package's network type: winding and casing (and,
    with ``drive_heating``, the drive node), Joule heat R(T_w) i^2 in the winding and the concealed
    sources the baseline model lacks: friction heat split between winding and casing
    (``friction_to_winding``), the drive's idle and i^2 losses. The sensor is on the casing."""
    p = params
    nodes, caps = ("winding", "casing"), (p.winding_capacity_j_per_k, p.casing_capacity_j_per_k)
    links = (Link("winding", "casing", p.winding_casing_k_per_w), Link("casing", AMBIENT, p.casing_ambient_k_per_w))
    sources = (HeatSource("winding", "joule_w"),)
    if p.friction_heating:
        sources += (HeatSource("winding", "friction_w", p.friction_to_winding),
                    HeatSource("casing", "friction_w", 1 - p.friction_to_winding))
    if p.drive_heating:
        nodes, caps = nodes + ("drive",), caps + (p.drive_capacity_j_per_k,)
        links += (Link("drive", "casing", p.drive_casing_k_per_w), Link("drive", AMBIENT, p.drive_ambient_k_per_w))
        sources += (HeatSource("drive", "current_sq_a2", p.drive_loss_w_per_a2, p.drive_idle_w),)
    return ThermalNetwork(nodes, caps, links, sources, sensor_node="casing")


@dataclass(frozen=True)
class AffineNetwork:
    """The plant network in numpy form for fast integration:
    dT/dt = (a0 + i^2 a_i2) T + i^2 b_i2 + P_f b_f + T_room b_room + b_0, T = (winding, casing[, drive])."""

    a0: np.ndarray
    a_i2: np.ndarray
    b_i2: np.ndarray
    b_f: np.ndarray
    b_room: np.ndarray
    b_0: np.ndarray

    def system(self, current_a: float, friction_w: float, room_c: float) -> tuple[np.ndarray, np.ndarray]:
        """(A, b) for the given inputs (friction_w = mechanical friction power)."""
        i2 = current_a * current_a
        return self.a0 + i2 * self.a_i2, i2 * self.b_i2 + friction_w * self.b_f + room_c * self.b_room + self.b_0

    def rate(self, temps: np.ndarray, current_a: float, friction_w: float, room_c: float) -> np.ndarray:
        i2 = current_a * current_a
        return (self.a0 @ temps + i2 * (self.a_i2 @ temps + self.b_i2) + friction_w * self.b_f
                + room_c * self.b_room + self.b_0)


def thermal_network(params: PlantParameters) -> AffineNetwork:
    """The coefficients of :func:`plant_network` heated by the plant's motor (``joint_heat_rhs``), which
    is affine in T for given i^2, friction power P_f and room temperature, and affine in each of them."""
    net = plant_network(params)
    temps, current, friction, room = (ca.SX.sym(name, size) for name, size in
                                      (("temperatures_c", len(net.nodes)), ("current_a", 1), ("friction_w", 1),
                                       ("room_c", 1)))
    rhs = joint_heat_rhs(net, params, temps, current, 0.0, room, held={"friction_w": friction})
    f = ca.Function("plant_thermal", [current, friction, room], [ca.jacobian(rhs, temps),
                                                                 ca.substitute(rhs, temps, ca.DM.zeros(len(net.nodes)))])
    (a0, b_0), (a1, b_1), (_, b_f), (_, b_room) = ([np.array(m, dtype=float) for m in f(*inputs)]
                                                  for inputs in ((0, 0, 0), (1, 0, 0), (0, 1, 0), (0, 0, 1)))
    b_0 = b_0.ravel()
    return AffineNetwork(a0, a1 - a0, b_1.ravel() - b_0, b_f.ravel() - b_0, b_room.ravel() - b_0, b_0)


@dataclass(frozen=True)
class HeatFlows:
    """Heat flows [W] at given times: sources into the motor and losses to the room."""

    joule_w: np.ndarray
    friction_w: np.ndarray  # the part that heats the motor (0 when friction_heating is off)
    drive_w: np.ndarray
    to_ambient_w: np.ndarray

    @property
    def heat_in_w(self) -> np.ndarray:
        return self.joule_w + self.friction_w + self.drive_w


@dataclass(frozen=True)
class PlantSolution:
    """Integrated plant: dense node temperatures plus the inputs that produced them."""

    params: PlantParameters
    profile: Profile
    ambient: Ambient
    pieces: tuple[tuple[float, float, object], ...]  # (start, end, scipy OdeSolution)

    @property
    def node_names(self) -> tuple[str, ...]:
        return self.params.node_names

    def temperatures(self, t: np.ndarray) -> np.ndarray:
        """Node temperatures [°C], shape (n_nodes, len(t))."""
        t = np.atleast_1d(np.asarray(t, float)).ravel()
        ends = np.array([piece[1] for piece in self.pieces])
        index = np.clip(np.searchsorted(ends, t, side="left"), 0, len(self.pieces) - 1)
        out = np.empty((len(self.node_names), t.size))
        for k in np.unique(index):
            mask = index == k
            out[:, mask] = self.pieces[k][2](t[mask])
        return out

    def heat_flows(self, t: np.ndarray) -> HeatFlows:
        p, t = self.params, np.atleast_1d(np.asarray(t, float)).ravel()
        temps, mech, net = self.temperatures(t), self.profile.mechanics(p, t), plant_network(self.params)
        powers = {"joule_w": motor.joule_w(p, mech.current_a, temps[0]), "friction_w": mech.friction_w,
                  "current_sq_a2": mech.current_a**2}
        heat = {name: np.zeros_like(t) for name in powers}
        for src in net.sources:
            heat[src.name] = heat[src.name] + src.power_w(powers)
        room = self.ambient(t)
        out = sum((temps[net.index(link.a)] - room) / link.resistance_k_per_w for link in net.links if link.b == AMBIENT)
        return HeatFlows(heat["joule_w"], heat["friction_w"], heat["current_sq_a2"], out)


def steady_state(params: PlantParameters, current_a: float, friction_w: float, ambient_c: float) -> np.ndarray:
    """Equilibrium node temperatures for constant inputs (raises on thermal runaway)."""
    a, b = thermal_network(params).system(current_a, friction_w, ambient_c)
    require(bool(np.all(np.linalg.eigvals(a).real < 0)), "steady_state", "current_a", current_a,
            "thermal runaway: no stable equilibrium at this current")
    return np.linalg.solve(a, -b)


def simulate(params: PlantParameters, profile: Profile, ambient: Ambient | None = None,
             initial: str | np.ndarray = "idle", method: str = "LSODA", rtol: float = 1e-8,
             atol: float = 1e-8) -> PlantSolution:
    """Integrate the thermal network through ``profile``, piece by piece where the inputs are smooth.

    LSODA (switches between Adams and BDF; analytic Jacobian, the network is linear in T) with
    tight tolerances; any solve_ivp ``method`` works.

    ``initial``: "idle" = equilibrium of the powered robot with the motor unloaded (zero current),
    "cold" = every node at room temperature, or an array of node temperatures [°C].
    """
    ambient = ambient or Ambient()
    state = _initial_state(params, ambient, initial)
    network, pieces = thermal_network(params), []
    room = _room_function(ambient)
    for k, start, end, max_step in profile.segments(ambient.breakpoints()):
        phase, offset = profile.phases[k], float(profile.starts_s[k])

        def inputs(t: float, phase=phase, offset=offset) -> tuple[float, float, float]:
            mech = phase_mechanics(params, phase, t - offset)
            return float(mech.current_a), float(mech.friction_w), room(t)

        def rhs(t, y, inputs=inputs):
            return network.rate(y, *inputs(t))

        jac = {"jac": lambda t, y, inputs=inputs: network.system(*inputs(t))[0]} if method in IMPLICIT else {}
        sol = solve_ivp(rhs, (start, end), state, method=method, rtol=rtol, atol=atol, max_step=max_step,
                        dense_output=True, **jac)
        require(sol.success, "simulate", f"phase {phase.name}", (start, end), f"integration failed: {sol.message}")
        pieces.append((start, end, sol.sol))
        state = sol.y[:, -1]
    return PlantSolution(params, profile, ambient, tuple(pieces))


def _initial_state(params: PlantParameters, ambient: Ambient, initial: str | np.ndarray) -> np.ndarray:
    n = len(params.node_names)
    if isinstance(initial, str):
        require(initial in ("idle", "cold"), "simulate", "initial", initial, "expected 'idle', 'cold' or an array")
        if initial == "cold":
            return np.full(n, float(ambient(0.0)))
        return steady_state(params, 0.0, 0.0, float(ambient(0.0)))
    state = np.asarray(initial, float).ravel()
    require(state.size == n and bool(np.all(np.isfinite(state))), "simulate", "initial", initial,
            f"expected {n} finite node temperatures {params.node_names}")
    return state



def _room_function(ambient: Ambient) -> Callable[[float], float]:
    """Room temperature as a cheap scalar function (constant rooms skip numpy)."""
    if ambient.drift_c_per_h == 0 and ambient.step_c == 0:
        return lambda t: ambient.room_c
    return lambda t: float(ambient(t))
