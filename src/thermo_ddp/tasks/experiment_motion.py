"""The designed experiment as a programme the robot runs, and its figure.

The control of the design is a current and a joint speed per knot; the programme moves the joint back and
forth inside its range at that speed, reversing and stopping with a bounded acceleration (careful motion),
with the current held per knot: the recording format's ``time_s``, ``current_a``, ``position``, ``velocity``.
"""
from __future__ import annotations

import numpy as np

from ..model.actuated import ActuatedArm
from ..model.arm import ArmSettings
from .limits import joint_range_rad

PROGRAMME_COLUMNS = ("time_s", "current_a", "position", "velocity")


def joint_bounds(params, margin_rad: float) -> tuple[float, float, float]:
    """(lower, upper, speed limit) of the parameter file's joint: its URDF range ``margin_rad`` inside."""
    model = ActuatedArm.from_parameters(ArmSettings(joints=(params.joint,)), {params.joint: params})
    lo, hi = (float(b[0]) for b in joint_range_rad(model, margin_rad))
    return lo, hi, float(model.arm.model.velocityLimit[0])


def sweep(speed_rad_s: np.ndarray, sample_s: float, lower: float, upper: float, acceleration: float
          ) -> tuple[np.ndarray, np.ndarray]:
    """Position and velocity of a back-and-forth motion at the given speed per sample (>= 0), starting at rest
    in the middle of [lower, upper]: the joint reverses when its stopping distance reaches the bound ahead and
    comes to rest at the end; the velocity changes by at most ``acceleration`` * ``sample_s`` per sample."""
    n = speed_rad_s.size
    q, v = np.empty(n), np.empty(n)
    qk, vk, direction = 0.5 * (lower + upper), 0.0, 1.0
    dv = acceleration * sample_s
    for k in range(n):
        q[k], v[k] = qk, vk
        ahead = upper - qk if direction > 0 else qk - lower
        if vk * direction > 0 and ahead <= vk * vk / (2 * acceleration) + abs(vk) * sample_s + 0.5 * dv * sample_s:
            direction = -direction
        stopping = (n - 1 - k) * dv <= abs(vk) + dv
        target = 0.0 if stopping else direction * speed_rad_s[k]
        vk += float(np.clip(target - vk, -dv, dv))
        qk += vk * sample_s
    return q, v


def programme(knot_s: float, current_a: np.ndarray, speed_rad_s: np.ndarray, bounds: tuple[float, float],
              acceleration: float, sample_s: float) -> dict[str, np.ndarray]:
    """The rows of the programme: every ``sample_s`` over the knots (each ``knot_s`` long)."""
    n = current_a.size
    t = np.arange(0.0, n * knot_s - 0.5 * sample_s, sample_s)
    k = np.minimum((t / knot_s).astype(int), n - 1)
    q, v = sweep(np.asarray(speed_rad_s, float)[k], sample_s, *bounds, acceleration)
    return {"time_s": t, "current_a": np.asarray(current_a, float)[k], "position": q, "velocity": v}


def plot_experiment(design, path) -> None:
    """Planned current and speed, and each explanation's predicted sensor temperature and winding, with the
    limit drawn."""
    from .._figures import new_figure

    fig, axes = new_figure(3, 1, (12, 8), sharex=True)
    t_min = design.time_s / 60.0
    axes[0].step(t_min[:-1], design.current_a, where="post", color="tab:blue")
    axes[0].set_ylabel("current [A]")
    axes[1].step(t_min[:-1], design.speed_rad_s, where="post", color="tab:green")
    axes[1].set_ylabel("speed [rad/s]")
    for k, label in enumerate(design.labels):
        line, = axes[2].plot(t_min, design.sensor_c[:, k], label=label)
        axes[2].plot(t_min, design.winding_c[:, k], ls="--", color=line.get_color(), lw=0.8)
    axes[2].plot([], [], ls="--", color="0.4", lw=0.8, label="dashed: the same explanation's winding")
    axes[2].axhline(design.limit_c, color="k", ls=":", label=f"winding limit {design.limit_c:g} °C")
    axes[2].set_ylabel("temperature [°C]\n(solid: sensor, dashed: winding)")
    axes[2].set_xlabel("time [min]")
    # beside the axes, never over the curves (the windings run up to the limit line)
    axes[2].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0.0)
    axes[0].set_title(f"designed experiment: {', '.join(design.targets)}")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
