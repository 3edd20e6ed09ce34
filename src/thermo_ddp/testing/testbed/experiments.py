"""The seed report's elbow experiments (section 4.3) and randomised recordings, on the true plant.

Each function returns a :class:`SimulatedRecording`: the contract columns as the robot would log
them (noisy, quantised, irregularly sampled) plus the hidden :class:`Truth` (node temperatures,
true parameters, which effects were on), which never goes into the CSV.

Phases of every experiment: ``idle`` (arm at the pose, no payload) -> ``loading`` -> ``heating``
-> ``unloading`` -> ``lowering`` (arm back to hanging) -> ``cooling`` (motor off). The robot
stays powered while the motor cools, so with ``drive_heating`` the drive's idle losses go on.
"""
from __future__ import annotations

import csv
import dataclasses
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from ..._config import require
from ...recordings import Recording
from .physics import (EFFECTS, Ambient, Phase, PlantParameters, PlantSolution, Profile, constant, curl,
                      gaussian_pulses, hold, min_jerk, motor_voltage_v, phase_mechanics, simulate, staircase)
from .sensors import Sampling, SensorSettings, measure, sample_times

JOINT = "arm_left_4_joint"
COLUMNS = ("time_s", "current_a", "temperature_c", "position", "velocity", "effort", "ambient_c")
LOGGED_COLUMNS = COLUMNS + ("voltage_v",)  # the motor voltage is logged too; COLUMNS is the report's set
EXPERIMENTS = ("static_3a", "static_4a", "biceps")
HORIZONTAL_RAD = math.pi / 2
UNLOAD_S, LOWER_S = 20.0, 20.0


@dataclass(frozen=True, eq=False)
class Truth:
    """What the robot does not log: true temperatures and parameters (at the sample times)."""

    experiment: str
    seed: int
    parameters: PlantParameters
    ambient: Ambient
    sensors: SensorSettings
    phases: tuple[tuple[str, str, float, float], ...]  # (name, regime, start_s, end_s)
    details: dict
    sampling: Sampling
    time_s: np.ndarray
    winding_c: np.ndarray
    casing_c: np.ndarray
    drive_c: np.ndarray | None
    room_c: np.ndarray
    current_a: np.ndarray
    effort_nm: np.ndarray
    friction_w: np.ndarray  # friction heat into the motor (0 when friction_heating is off)
    joule_w: np.ndarray
    solution: PlantSolution  # dense: solution.temperatures(t) at any t

    @property
    def effects(self) -> dict[str, bool]:
        return self.parameters.effects

    def phase(self, name: str) -> tuple[float, float]:
        """(start_s, end_s) of the named phase."""
        for phase_name, _, start, end in self.phases:
            if phase_name == name:
                return start, end
        raise KeyError(name)


@dataclass(frozen=True, eq=False)
class SimulatedRecording:
    """Contract columns (``columns``) plus the hidden ``truth``."""

    name: str
    columns: dict[str, np.ndarray]
    truth: Truth

    @property
    def time_s(self) -> np.ndarray:
        return self.columns["time_s"]

    def to_csv(self, path: str | Path, columns: tuple[str, ...] = COLUMNS) -> Path:
        """Write the contract CSV (header row, one sample per row); ``columns`` picks a subset of
        :data:`LOGGED_COLUMNS` (default: the report's channels, no motor voltage)."""
        require(columns[:1] == ("time_s",) and set(columns) <= set(LOGGED_COLUMNS), "to_csv", "columns", columns,
                f"must start with time_s and be among {LOGGED_COLUMNS}")
        path = Path(path)
        table = np.column_stack([self.columns[c] for c in columns])
        with path.open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(columns)
            writer.writerows([[repr(float(v)) for v in row] for row in table])
        return path

    def to_recording(self, columns: tuple[str, ...] = COLUMNS) -> Recording:
        """The same data (``columns``, as :meth:`to_csv`) as a validated :class:`thermo_ddp.recordings.Recording`."""
        return Recording(name=self.name, joint=JOINT, source=f"testbed:{self.name}",
                         **{c: self.columns[c] for c in columns})


# ----------------------------------------------------------------------------- experiments
def static_3a(*, heating_s: float = 7200.0, cooling_s: float = 5400.0, loading_s: float = 600.0,
              idle_s: float = 300.0, current_a: float = 3.0, payload_kg: float = 25.0,
              touches_per_hour: float = 4.0, sample_rate_hz: float | None = None, seed: int = 0,
              params: PlantParameters | None = None, sensors: SensorSettings | None = None,
              ambient: Ambient | None = None, start: str = "idle") -> SimulatedRecording:
    """Report experiment 1: 25 kg close to the elbow, ~3 A, bricks added slowly, touch spikes."""
    return static_hold(current_a, payload_kg=payload_kg, heating_s=heating_s, cooling_s=cooling_s,
                       loading_s=loading_s, idle_s=idle_s, touches_per_hour=touches_per_hour,
                       sample_rate_hz=sample_rate_hz, seed=seed, params=params, sensors=sensors,
                       ambient=ambient, start=start, name="static_3a")


def static_4a(*, heating_s: float = 7200.0, cooling_s: float = 5400.0, loading_s: float = 20.0,
              idle_s: float = 300.0, current_a: float = 4.0, payload_kg: float = 20.0,
              bump_at_s: float | None = None, bump_fraction: float = 0.08,
              sample_rate_hz: float | None = None, seed: int = 0, params: PlantParameters | None = None,
              sensors: SensorSettings | None = None, ambient: Ambient | None = None,
              start: str = "idle") -> SimulatedRecording:
    """Report experiment 2: 20 kg at the wrist, ~4 A, robot warm from its drives, a bump partway
    (the bag slips outward by ``bump_fraction`` of its lever at ``bump_at_s`` into heating)."""
    bump_at_s = 0.4 * heating_s if bump_at_s is None else bump_at_s
    return static_hold(current_a, payload_kg=payload_kg, heating_s=heating_s, cooling_s=cooling_s,
                       loading_s=loading_s, idle_s=idle_s, bump=(bump_at_s, bump_fraction),
                       sample_rate_hz=sample_rate_hz, seed=seed, params=params, sensors=sensors,
                       ambient=ambient, start=start, name="static_4a")


def static_hold(current_a: float, *, payload_kg: float = 20.0, angle_rad: float = HORIZONTAL_RAD,
                heating_s: float = 3600.0, cooling_s: float = 0.0, loading_s: float = 0.0,
                idle_s: float = 0.0, touches_per_hour: float = 0.0,
                bump: tuple[float, float] | None = None, sample_rate_hz: float | None = None,
                seed: int = 0, params: PlantParameters | None = None,
                sensors: SensorSettings | None = None, ambient: Ambient | None = None,
                start: str = "idle", name: str = "static_hold") -> SimulatedRecording:
    """A weight hung on the position-controlled forearm at ``angle_rad``; its lever is chosen so
    the hold needs ``current_a`` (report 4.3: "adjust it by displacing the application point")."""
    params = params or PlantParameters()
    rng = np.random.default_rng(seed)
    lever = hold_lever_m(params, current_a, payload_kg, angle_rad)
    lever_signal, bump_window = constant(lever), ()
    if bump is not None:
        at, fraction = bump
        require(0 < at < heating_s, name, "bump_at_s", at, f"must be inside the heating phase (0, {heating_s})")
        lever_signal = staircase([at], [fraction * lever], rise_s=2.0, start=lever)
        bump_window = ((max(at - 1.0, 0.0), min(at + 5.0, heating_s), 0.25),)
    touches = _touches(rng, heating_s, touches_per_hour)
    phases = [Phase("heating", "static", heating_s, hold(angle_rad), constant(payload_kg), lever_signal,
                    external_nm=gaussian_pulses(*touches), fine_windows=bump_window + _touch_windows(touches))]
    if loading_s > 0:
        phases.insert(0, Phase("loading", "static", loading_s, hold(angle_rad), _bricks(rng, payload_kg, loading_s),
                               constant(lever), max_step_s=1.0))
    if idle_s > 0:
        phases.insert(0, Phase("idle", "idle", idle_s, hold(angle_rad)))
    phases += _unload_and_cool(angle_rad, payload_kg, lever_signal(heating_s), cooling_s)
    details = {"current_a": current_a, "payload_kg": payload_kg, "lever_m": lever, "angle_rad": angle_rad,
               "bump": bump, "touches": [dict(zip(("center_s", "amplitude_nm", "width_s"), map(float, t)))
                                         for t in zip(*touches)]}
    return _record(name, Profile(tuple(phases)), params, ambient, sensors, sample_rate_hz, rng, seed, start, details)


def biceps(*, heating_s: float = 3600.0, cooling_s: float = 5400.0, idle_s: float = 300.0,
           current_rms_a: float = 2.57, amplitude_rad: float = 0.9, center_rad: float = 1.0,
           period_s: float = 2.5, lever_m: float = 0.357, sample_rate_hz: float | None = None,
           seed: int = 0, params: PlantParameters | None = None, sensors: SensorSettings | None = None,
           ambient: Ambient | None = None, start: str = "idle") -> SimulatedRecording:
    """Report experiment 3: position-controlled sinusoidal curl with a weight in the hand (gripper
    lever ``lever_m``), the weight chosen so the current RMS is ``current_rms_a``; robot warm."""
    params = params or PlantParameters()
    rng = np.random.default_rng(seed)
    require(0 < amplitude_rad <= center_rad, "biceps", "amplitude_rad", amplitude_rad,
            f"must be in (0, center_rad = {center_rad}] (q = 0 is hanging)")
    cycles = max(1, round(heating_s / period_s))
    moving_s = cycles * period_s
    bottom = center_rad - amplitude_rad
    payload = curl_payload_kg(params, current_rms_a, center_rad, amplitude_rad, period_s, lever_m)
    phases = [Phase("grasp", "static", 10.0, hold(bottom), staircase([0.0], [payload], rise_s=5.0), constant(lever_m)),
              Phase("heating", "moving", moving_s, curl(center_rad, amplitude_rad, period_s), constant(payload),
                    constant(lever_m), max_step_s=period_s / 4)]
    if idle_s > 0:
        phases.insert(0, Phase("idle", "idle", idle_s, hold(bottom)))
    phases += _unload_and_cool(bottom, payload, lever_m, cooling_s)
    details = {"current_rms_a": current_rms_a, "payload_kg": payload, "lever_m": lever_m,
               "center_rad": center_rad, "amplitude_rad": amplitude_rad, "period_s": period_s, "cycles": cycles}
    return _record("biceps", Profile(tuple(phases)), params, ambient, sensors, sample_rate_hz, rng, seed, start, details)


def winding_pulses(*, current_a: float = 8.0, pulse_s: float = 30.0, rest_s: float = 150.0, pulses: int = 3,
                   idle_s: float = 120.0, cooling_s: float = 600.0, payload_kg: float = 30.0,
                   angle_rad: float = HORIZONTAL_RAD, sample_rate_hz: float | None = None, seed: int = 0,
                   params: PlantParameters | None = None, sensors: SensorSettings | None = None,
                   ambient: Ambient | None = None, start: str = "idle") -> SimulatedRecording:
    """Not in the report: ``pulses`` steps of ``current_a`` for ``pulse_s`` (the weight hung on and taken
    off), ``rest_s`` apart. The report's hour-long holds barely excite the winding's time constant
    (C_w R_wc ~ 36 s); these steps do, and with the motor voltage logged they pin C_w and R_wc down.
    The defaults keep the true winding near 70 °C, under the 84 °C cut-off."""
    params = params or PlantParameters()
    rng = np.random.default_rng(seed)
    require(isinstance(pulses, int) and pulses >= 1, "winding_pulses", "pulses", pulses, "expected an integer >= 1")
    lever = hold_lever_m(params, current_a, payload_kg, angle_rad)
    phases = [Phase("idle", "idle", idle_s, hold(angle_rad))] if idle_s > 0 else []
    for k in range(pulses):
        phases += [Phase(f"pulse_{k + 1}", "static", pulse_s, hold(angle_rad), constant(payload_kg), constant(lever)),
                   Phase(f"rest_{k + 1}", "static", rest_s, hold(angle_rad))]
    phases += _unload_and_cool(angle_rad, 0.0, lever, cooling_s)
    details = {"current_a": current_a, "payload_kg": payload_kg, "lever_m": lever, "angle_rad": angle_rad,
               "pulse_s": pulse_s, "rest_s": rest_s, "pulses": pulses}
    return _record("winding_pulses", Profile(tuple(phases)), params, ambient, sensors, sample_rate_hz, rng, seed,
                   start, details)


def programmed(programme, *, name: str = "programme", sample_rate_hz: float | None = None, seed: int = 0,
               params: PlantParameters | None = None, sensors: SensorSettings | None = None,
               ambient: Ambient | None = None, start: str = "idle") -> SimulatedRecording:
    """A programme (recording-format columns ``time_s``, ``current_a``, ``position``, ``velocity``: e.g. a
    designed experiment) on the position-controlled elbow: it follows the programmed position and velocity (the
    samples interpolated, the acceleration their slope) while an external load (a brake, a spring) takes the torque
    that makes the motor current the programmed one.  One phase per span of constant programmed current."""
    params = params or PlantParameters()
    t, current = (np.asarray(programme[c], float) for c in ("time_s", "current_a"))
    q, v = (np.asarray(programme[c], float) for c in ("position", "velocity"))
    require(t.size >= 2 and bool(np.all(np.diff(t) > 0)), name, "time_s", t.size, "expected increasing times")
    a = np.gradient(v, t)
    edges = np.flatnonzero(np.diff(current) != 0) + 1
    starts, ends = np.r_[0, edges], np.r_[edges, t.size - 1]
    phases = [_programme_phase(params, t, q, v, a, float(current[i]), i, j, k)
              for k, (i, j) in enumerate(zip(starts, ends)) if t[j] > t[i]]
    return _record(name, Profile(tuple(phases)), params, ambient, sensors, sample_rate_hz,
                   np.random.default_rng(seed), seed, start, {"programme_rows": int(t.size)})


def _programme_phase(params: PlantParameters, t, q, v, a, current_a: float, i: int, j: int, k: int) -> Phase:
    """Rows ``i``..``j`` of a programme as one phase at ``current_a`` (see :func:`programmed`)."""
    t0 = float(t[i])

    def motion(local):
        x = np.asarray(local, float) + t0
        return np.interp(x, t, q), np.interp(x, t, v), np.interp(x, t, a)

    free = Phase(f"programme_{k}", "moving", float(t[j] - t0), motion, max_step_s=0.5)
    torque_per_a = params.gear_ratio * params.torque_constant_nm_per_a

    def load_nm(local):
        return (current_a - phase_mechanics(params, free, local).current_a) * torque_per_a

    regime = "moving" if np.any(np.abs(v[i:j + 1]) > 0) else "static"
    return dataclasses.replace(free, regime=regime, external_nm=load_nm)


def random_recording(seed: int, effects: str = "random", experiment: str = "random",
                     heating_s: float | None = None, cooling_s: float | None = None,
                     params: PlantParameters | None = None) -> SimulatedRecording:
    """A recording with everything drawn from ``seed``: true parameters (thermal ±25 %, friction
    ±30 %), effects (none / friction / drive / both), experiment, room, sensor quality.
    ``params`` replaces the drawn true parameters (and their effects), as in :func:`random_campaign`."""
    require(effects in ("random",) + EFFECTS, "random_recording", "effects", effects, f"expected random or {EFFECTS}")
    require(experiment in ("random",) + EXPERIMENTS, "random_recording", "experiment", experiment,
            f"expected random or {EXPERIMENTS}")
    rng = np.random.default_rng(seed)
    drawn_effects, drawn_experiment = str(rng.choice(EFFECTS)), str(rng.choice(EXPERIMENTS))
    drawn_params = PlantParameters().randomised(rng)
    effects = drawn_effects if effects == "random" else effects
    experiment = drawn_experiment if experiment == "random" else experiment
    params = drawn_params.with_effects(effects) if params is None else params
    sensors, ambient = random_sensors(rng), random_ambient(rng)
    moving = experiment == "biceps"
    drawn_heating_s = rng.uniform(900, 2700) if moving else rng.uniform(1800, 5400)
    drawn_cooling_s = rng.uniform(1200, 3600)
    heating_s = drawn_heating_s if heating_s is None else heating_s
    cooling_s = drawn_cooling_s if cooling_s is None else cooling_s
    common = dict(heating_s=heating_s, cooling_s=cooling_s, seed=int(rng.integers(2**31)), params=params,
                  sensors=sensors, ambient=ambient, idle_s=rng.uniform(60, 600))
    if experiment == "static_3a":
        rec = static_3a(current_a=rng.uniform(2.7, 3.3), loading_s=rng.uniform(120, 900), **common)
    elif experiment == "static_4a":
        rec = static_4a(current_a=rng.uniform(3.6, 4.4), bump_fraction=rng.uniform(0.0, 0.15),
                        bump_at_s=rng.uniform(0.2, 0.8) * heating_s, **common)
    else:
        rec = biceps(current_rms_a=rng.uniform(2.3, 2.8), amplitude_rad=rng.uniform(0.5, 0.9),
                     period_s=rng.uniform(2.0, 4.0), **common)
    name = f"random-{seed}-{experiment}-{_effects_name(params)}"
    return dataclasses.replace(rec, name=name, truth=dataclasses.replace(rec.truth, seed=seed))


def random_campaign(seed: int, effects: str = "random", experiments: tuple[str, ...] = EXPERIMENTS,
                    heating_s: float | None = None, cooling_s: float | None = None) -> tuple[SimulatedRecording, ...]:
    """Several experiments on ONE randomised robot (same true parameters and effects), each with
    its own room and sensor draw. A curl alone cannot tell friction heating from a larger Joule
    gain (a one-node fit absorbs it in C and R); a static hold of the same robot can."""
    require(effects in ("random",) + EFFECTS, "random_campaign", "effects", effects, f"expected random or {EFFECTS}")
    rng = np.random.default_rng(seed)
    drawn_effects = str(rng.choice(EFFECTS))
    params = PlantParameters().randomised(rng).with_effects(drawn_effects if effects == "random" else effects)
    seeds = rng.integers(2**31, size=len(experiments))
    recordings = []
    for k, (experiment, sub_seed) in enumerate(zip(experiments, seeds)):
        rec = random_recording(int(sub_seed), experiment=experiment, heating_s=heating_s, cooling_s=cooling_s,
                               params=params)
        recordings.append(dataclasses.replace(rec, name=f"campaign-{seed}-{k}-{experiment}-{_effects_name(params)}"))
    return tuple(recordings)


def _effects_name(params: PlantParameters) -> str:
    names = {(False, False): "none", (True, False): "friction", (False, True): "drive", (True, True): "both"}
    return names[params.friction_heating, params.drive_heating]


def random_sensors(rng: np.random.Generator) -> SensorSettings:
    """Sensor quality drawn from the ranges of issue 4 (noise 0.05-0.2 °C, quantum 0.1-0.5 °C, 0.2-2 Hz)."""
    return SensorSettings(sample_rate_hz=rng.uniform(0.2, 2.0), jitter_fraction=rng.uniform(0.0, 0.3),
                          temperature_noise_c=rng.uniform(0.05, 0.2),
                          temperature_quantum_c=float(rng.choice([0.1, 0.2, 0.25, 0.5])),
                          current_noise_a=rng.uniform(0.01, 0.05), effort_noise_nm=rng.uniform(0.1, 0.5),
                          gap_count=int(rng.integers(0, 4)), dropout_probability=rng.uniform(0.0, 0.02))


def random_ambient(rng: np.random.Generator) -> Ambient:
    """Room at 22-28 °C, slow drift, and in a third of the cases a door-opening step."""
    step = rng.uniform() < 1 / 3
    return Ambient(room_c=rng.uniform(22, 28), drift_c_per_h=rng.uniform(-0.5, 0.5),
                   step_c=rng.uniform(-2, 2) if step else 0.0, step_at_s=rng.uniform(600, 3600) if step else math.inf)


# ----------------------------------------------------------------------------- loads
def hold_lever_m(params: PlantParameters, current_a: float, payload_kg: float, angle_rad: float) -> float:
    """Lever at which ``payload_kg`` needs ``current_a`` to be held still at ``angle_rad``."""
    p = params
    sin_q = math.sin(angle_rad)
    torque = p.gear_ratio * p.torque_constant_nm_per_a * current_a - p.effort_offset_nm
    lever = (torque / (p.gravity_m_s2 * sin_q) - p.forearm_mass_kg * p.forearm_com_m) / payload_kg if sin_q > 0 else -1
    require(lever > 0, "static_hold", "current_a", current_a,
            f"cannot be reached with {payload_kg} kg at {angle_rad:.3f} rad")
    return lever


def curl_payload_kg(params: PlantParameters, current_rms_a: float, center_rad: float, amplitude_rad: float,
                    period_s: float, lever_m: float) -> float:
    """Hand weight for which the curl's current RMS over one cycle is ``current_rms_a``.

    The current is affine in the payload mass (gravity and inertia terms), so the RMS condition
    is a quadratic in the mass; its positive root is returned.
    """
    t = np.linspace(0.0, period_s, 4001)[:-1]

    def current(mass: float) -> np.ndarray:
        phase = Phase("curl", "moving", period_s, curl(center_rad, amplitude_rad, period_s), constant(mass),
                      constant(lever_m))
        return phase_mechanics(params, phase, t).current_a

    base = current(0.0)
    slope = current(1.0) - base
    a, b, c = np.mean(slope**2), np.mean(slope * base), np.mean(base**2) - current_rms_a**2
    mass = (-b + math.sqrt(max(b * b - a * c, 0.0))) / a
    require(mass > 0, "biceps", "current_rms_a", current_rms_a, "reached without any weight: raise it")
    return float(mass)


def _bricks(rng: np.random.Generator, payload_kg: float, loading_s: float):
    """Bricks of ~2.5 kg added one by one at irregular times during ``loading_s``."""
    count = max(1, round(payload_kg / 2.5))
    rise = min(2.0, loading_s / (2 * count))
    times = np.sort(rng.uniform(0.0, loading_s - rise, count))
    return staircase(times, np.full(count, payload_kg / count), rise_s=rise)


def _touches(rng: np.random.Generator, heating_s: float, per_hour: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Centers, amplitudes [N·m] and widths [s] of people touching the arm."""
    if heating_s <= 120:  # too short for a touch away from the phase's ends
        return np.zeros(0), np.zeros(0), np.zeros(0)
    count = rng.poisson(per_hour * heating_s / 3600.0)
    centers = rng.uniform(60.0, heating_s - 60.0, count)
    amplitudes = rng.choice([-1.0, 1.0], count) * rng.uniform(3.0, 12.0, count)
    return centers, amplitudes, rng.uniform(0.5, 3.0, count)


def _touch_windows(touches) -> tuple[tuple[float, float, float], ...]:
    return tuple((float(c - 6 * w), float(c + 6 * w), float(w / 4)) for c, _, w in zip(*touches))


def _unload_and_cool(angle_rad: float, payload_kg: float, lever_m: float, cooling_s: float) -> list[Phase]:
    """Weight off, arm lowered to hanging, motor off for ``cooling_s`` (nothing when 0)."""
    if cooling_s <= 0:
        return []
    return [Phase("unloading", "static", UNLOAD_S, hold(angle_rad),
                  staircase([0.0], [-payload_kg], rise_s=UNLOAD_S / 2, start=payload_kg), constant(lever_m)),
            Phase("lowering", "moving", LOWER_S, min_jerk(angle_rad, 0.0, LOWER_S), max_step_s=1.0),
            Phase("cooling", "cooling", cooling_s, hold(0.0), motor_on=False)]


# ----------------------------------------------------------------------------- recording
def _record(name: str, profile: Profile, params: PlantParameters, ambient: Ambient | None,
            sensors: SensorSettings | None, sample_rate_hz: float | None, rng: np.random.Generator,
            seed: int, start: str, details: dict) -> SimulatedRecording:
    """Integrate the plant, sample it and corrupt the samples."""
    ambient = ambient or Ambient()
    sensors = sensors or SensorSettings()
    if sample_rate_hz is not None:
        sensors = dataclasses.replace(sensors, sample_rate_hz=sample_rate_hz)
    solution = simulate(params, profile, ambient, initial=start)
    sampling = sample_times(profile.duration_s, sensors, rng)
    t = sampling.time_s
    temps, mech, flows = solution.temperatures(t), profile.mechanics(params, t), solution.heat_flows(t)
    room = ambient(t)
    true = {"current_a": mech.current_a, "temperature_c": temps[1], "position": mech.q_rad,
            "velocity": mech.v_rad_s, "effort": mech.effort_nm, "ambient_c": room,
            "voltage_v": motor_voltage_v(params, mech.current_a, temps[0], mech.v_rad_s)}
    columns = {"time_s": t} | measure(true, sensors, rng)
    truth = Truth(name, seed, params, ambient, sensors, profile.phase_table(), details, sampling, t,
                  temps[0], temps[1], temps[2] if params.drive_heating else None, room, mech.current_a,
                  mech.effort_nm, flows.friction_w, flows.joule_w, solution)
    return SimulatedRecording(name, {c: columns[c] for c in LOGGED_COLUMNS}, truth)
