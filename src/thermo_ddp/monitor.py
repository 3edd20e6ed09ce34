"""Per-joint winding monitor for recordings (ROS bags with several joints).

Per joint, an open-loop simulation of its thermal network driven by the recorded current and
velocity, initialised from the casing reading; reports each joint's winding estimate, the hottest
joint and the time to the limit (each joint's parameter file's, unless ``limit_c`` is given). A joint
without a current signal (or without a parameter file) is reported as not estimable, never guessed.
"""
from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Mapping, Sequence

import casadi as ca
import numpy as np
from tqdm import tqdm

from .errors import InputError
from .model.integrators import rk4
from .model.parameters import JointParameters, load_parameters, packaged_parameter_file
from .model.thermal import ThermalNetwork, network_from_parameters
from .recordings import Recording, TopicMap, read_bag_joints
from .tasks.limits import default_limit_c
from .tasks.series import finite_or_none, format_s
from .tasks.thermal_hold import first_crossing, joint_thermal_rhs


@dataclasses.dataclass(frozen=True)
class JointWindingEstimate:
    """One joint's estimated winding temperature over the recording (``status`` "estimated" or why not)."""

    joint: str
    status: str
    message: str
    time_s: np.ndarray | None = None
    winding_c: np.ndarray | None = None
    casing_c: np.ndarray | None = None
    measured_casing_c: np.ndarray | None = None
    limit_c: float = math.nan
    time_to_limit_s: float = math.nan

    @property
    def estimated(self) -> bool:
        return self.status == "estimated"

    @property
    def peak_winding_c(self) -> float:
        return float(self.winding_c.max()) if self.estimated else math.nan

    @property
    def first_over_limit_s(self) -> float:
        """Recording time when the estimate first reached the limit (inf: never)."""
        return first_crossing(self.time_s, self.winding_c, self.limit_c) if self.estimated else math.nan

    @property
    def casing_rmse_c(self) -> float:
        """RMS of the predicted minus measured casing (the model's check on the recording)."""
        return float(np.sqrt(np.mean((self.casing_c - self.measured_casing_c) ** 2))) if self.estimated else math.nan

    def to_dict(self) -> dict:
        d = {"joint": self.joint, "status": self.status, "message": self.message}
        if self.estimated:
            d.update(limit_c=self.limit_c, time_s=self.time_s.tolist(), winding_c=self.winding_c.tolist(),
                     casing_c=self.casing_c.tolist(),
                     peak_winding_c=self.peak_winding_c, final_winding_c=float(self.winding_c[-1]),
                     first_over_limit_s=finite_or_none(self.first_over_limit_s),
                     time_to_limit_s=finite_or_none(self.time_to_limit_s), casing_rmse_c=self.casing_rmse_c)
        return d


def _initial_temperatures(rhs: ca.Function, net: ThermalNetwork, casing_c: float, current_a: float, velocity: float,
                          ambient_c: float) -> np.ndarray:
    """The sensor node at its reading, every other node in quasi-steady state with it (the network is
    linear in T for given current and velocity)."""
    n, s = len(net.nodes), net.index(net.sensor_node)
    t = ca.SX.sym("t", n)
    jac = ca.Function("lin", [t], [ca.jacobian(rhs(t, current_a, velocity, ambient_c), t),
                                   rhs(t, current_a, velocity, ambient_c)])
    a, b = (np.array(m, float) for m in jac(np.zeros(n)))
    free = [k for k in range(n) if k != s]
    temps = np.zeros(n)
    temps[s] = casing_c
    if free:
        rows = a[np.ix_(free, free)]
        temps[free] = np.linalg.solve(rows, -(b.ravel()[free] + a[free, s] * casing_c))
    return temps


def _missing_signal(recording: Recording, joint: str, limit_c: float) -> JointWindingEstimate | None:
    """A not-estimable result when the recording lacks the current or the casing temperature."""
    for column, why in (("current_a", "without a current signal the Joule heating is unknown"),
                        ("temperature_c", "without a casing temperature there is no initial state")):
        if getattr(recording, column) is None:
            return JointWindingEstimate(joint, f"no_{column.split('_')[0]}", f"cannot estimate the winding of {joint}: "
                                        f"{why} (recording {recording.name} has {', '.join(recording.columns)})",
                                        limit_c=limit_c)
    return None


def estimate_winding(recording: Recording, params: JointParameters, limit_c: float | None = None,
                     max_step_s: float = 1.0, horizon_s: float = 3600.0) -> JointWindingEstimate:
    """Open-loop simulation of the joint's thermal network driven by the recorded current (zero-order
    hold) and velocity, started from the casing reading; plus the time to ``limit_c`` (None: the
    file's) holding the last current. Needs ``current_a`` and ``temperature_c``; without them the
    status says so."""
    joint = recording.joint or params.joint
    limit_c = default_limit_c(params) if limit_c is None else limit_c
    missing = _missing_signal(recording, joint, limit_c)
    if missing is not None:
        return missing
    net = network_from_parameters(params.thermal)
    rhs = joint_thermal_rhs(net, params.motor)
    time_s = recording.time_s
    dt = np.diff(time_s)
    substeps = max(1, math.ceil(float(dt.max(initial=0.0)) / max_step_s))
    h = ca.SX.sym("dt_s")
    args = [ca.SX.sym(rhs.name_in(k), rhs.size1_in(k)) for k in range(4)]
    x = args[0]
    for _ in range(substeps):
        x = rk4(rhs, x, h / substeps, *args[1:])
    step = ca.Function("joint_thermal_step", [*args, h], [x], [*rhs.name_in(), "dt_s"], ["temperatures_next_c"])
    velocity = recording.velocity if recording.velocity is not None else np.zeros(len(recording))
    ambient = recording.ambient_c
    if ambient is None:
        ambient = np.full(len(recording), params.thermal.ambient_c)
    t0 = _initial_temperatures(rhs, net, recording.temperature_c[0], recording.current_a[0], velocity[0], ambient[0])
    temps = t0[:, None]
    if dt.size:
        sim = step.mapaccum(dt.size)
        temps = np.hstack([temps, np.array(sim(t0, recording.current_a[:-1][None, :], velocity[:-1][None, :],
                                               ambient[:-1][None, :], dt[None, :]))])
    w, c = temps[net.index(net.limit_node)], temps[net.index(net.sensor_node)]
    hold = step.mapaccum(int(horizon_s))
    ahead = np.array(hold(temps[:, -1], recording.current_a[-1], 0.0, ambient[-1], 1.0))[net.index(net.limit_node)]
    ttl = first_crossing(np.arange(ahead.size + 1, dtype=float), np.r_[w[-1], ahead], limit_c)
    return JointWindingEstimate(joint, "estimated", f"open-loop thermal simulation of {joint} ({net.nodes})",
                                time_s, w, c, recording.temperature_c, limit_c, ttl)


@dataclasses.dataclass(frozen=True)
class ArmMonitor:
    """Every joint's winding estimate from one recording session; flags the hottest joint."""

    source: str
    limit_c: float | None    # as requested (None: each joint's parameter file's)
    estimates: tuple[JointWindingEstimate, ...]

    @property
    def estimated(self) -> tuple[JointWindingEstimate, ...]:
        return tuple(e for e in self.estimates if e.estimated)

    @property
    def success(self) -> bool:
        return bool(self.estimated)

    @property
    def status(self) -> str:
        if len(self.estimated) == len(self.estimates):
            return "estimated"
        return "partial" if self.estimated else "cannot_estimate"

    @property
    def message(self) -> str:
        missing = [e for e in self.estimates if not e.estimated]
        if not missing:
            return f"estimated the winding of {len(self.estimates)} joints"
        head = f"{len(missing)} of {len(self.estimates)} joints not estimated"
        return f"{head}: {missing[0].message}" if len(missing) == len(self.estimates) else head

    @property
    def hottest_joint(self) -> str | None:
        """The joint with the highest estimated winding at the end of the recording."""
        est = self.estimated
        return max(est, key=lambda e: e.winding_c[-1]).joint if est else None

    @property
    def first_to_limit(self) -> str | None:
        """The joint that would reach the limit first holding its last current."""
        est = self.estimated
        return min(est, key=lambda e: (e.time_to_limit_s, -e.winding_c[-1])).joint if est else None

    def __getitem__(self, joint: str) -> JointWindingEstimate:
        for e in self.estimates:
            if e.joint == joint:
                return e
        raise KeyError(joint)

    def to_dict(self) -> dict:
        return {"source": self.source, "limit_c": self.limit_c, "status": self.status, "success": self.success,
                "message": self.message, "hottest_joint": self.hottest_joint, "first_to_limit": self.first_to_limit,
                "joints": {e.joint: e.to_dict() for e in self.estimates}}

    def report(self) -> str:
        limit = "each joint's own" if self.limit_c is None else f"{self.limit_c:g} °C"
        lines = [f"winding monitor, {self.source}, limit {limit}: {self.status} - {self.message}"]
        for e in self.estimates:
            if e.estimated:
                lines.append(f"  {e.joint:>17}: final {e.winding_c[-1]:6.1f} °C, peak {e.peak_winding_c:6.1f} °C, "
                             f"limit {e.limit_c:g} °C, over it at {format_s(e.first_over_limit_s)}, "
                             f"time to limit {format_s(e.time_to_limit_s)}, casing rmse {e.casing_rmse_c:.2f} °C")
            else:
                lines.append(f"  {e.joint:>17}: {e.status} ({e.message})")
        if self.hottest_joint:
            lines.append(f"  hottest: {self.hottest_joint}; first to reach the limit: {self.first_to_limit}")
        return "\n".join(lines)


def _parameter_file(joint: str, files: Mapping[str, str | Path]) -> Path | None:
    """The joint's parameter file: the given one, else the packaged one; None when there is none."""
    if joint in files:
        path = Path(files[joint])
        return path if path.is_file() else None
    try:
        return packaged_parameter_file(joint)
    except InputError:
        return None


def monitor_recordings(recordings: Mapping[str, Recording], limit_c: float | None = None,
                       parameter_files: Mapping[str, str | Path] | None = None, source: str = "") -> ArmMonitor:
    """:func:`estimate_winding` for each joint's recording, with ``models/<joint>.toml`` unless given;
    ``limit_c`` None: each joint's file's limit."""
    files = dict(parameter_files or {})
    out = []
    for joint, rec in tqdm(recordings.items(), desc="joints", unit="joint", leave=False, disable=None):
        missing = _missing_signal(rec, joint, math.nan if limit_c is None else limit_c)
        path = None if missing is not None else _parameter_file(joint, files)
        if missing is not None:
            out.append(missing)
        elif path is None:
            out.append(JointWindingEstimate(joint, "no_model", f"cannot estimate the winding of {joint}: "
                                            f"no parameter file ({files.get(joint, 'none packaged')})"))
        else:
            out.append(estimate_winding(rec, load_parameters(path), limit_c))
    return ArmMonitor(source, limit_c, tuple(out))


def monitor_bag(path: str | Path, topic_maps: Sequence[TopicMap], limit_c: float | None = None,
                parameter_files: Mapping[str, str | Path] | None = None) -> ArmMonitor:
    """Read every joint of ``topic_maps`` from one bag and estimate each joint's winding temperature."""
    recordings = read_bag_joints(path, topic_maps)
    return monitor_recordings(recordings, limit_c, parameter_files, source=str(path))
