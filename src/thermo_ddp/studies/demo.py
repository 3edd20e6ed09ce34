"""The model demo: can the elbow hold 40 kg at the gripper, and how fast does its winding heat?"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .._config import require
from ..model.actuated import load_model
from ..model.arm import ELBOW, PAYLOAD_KG
from ..model.parameters import BOUNDS, Bound
from ..tasks.limits import DEFAULT_HOLD_S, HOLD_S, limit_pair_c
from ..tasks.thermal_hold import first_crossing

_SRC = "hold_demo"
DT_S = Bound(1e-4, 0.1, "s", "the step resolves the arm's fast modes; the hold's steps are bounded by hold_s / dt_s")
MAX_STEPS = 1_000_000  # simulated steps: about 10 s of work
BURNT_C = BOUNDS["winding_max_c"].high  # no winding insulation survives it: the model's temperatures end there


@dataclass(frozen=True)
class HoldDemo:
    payload_kg: float
    lever_m: float
    torque_nm: float
    current_a: float
    nominal_current_a: float
    peak_current_a: float
    idle_winding_c: float
    winding_c_at: dict
    time_to_c: dict

    def report(self) -> str:
        lines = [f"Elbow holding {self.payload_kg:g} kg at {self.lever_m:.3f} m, forearm horizontal:",
                 f"  static joint torque {self.torque_nm:8.1f} N·m",
                 f"  static current      {self.current_a:8.2f} A  ({abs(self.current_a) / self.nominal_current_a:.1f}x nominal)",
                 f"  winding at start    {self.idle_winding_c:8.1f} °C (idle, drive-heated)"]
        if abs(self.current_a) > self.peak_current_a:
            lines.append(f"  CANNOT HOLD: the static current exceeds the motor's peak {self.peak_current_a:g} A "
                         "(the temperatures below assume it could)")
        lines += [f"  winding after {t:3.0f} s  {c:8.1f} °C" if c <= BURNT_C else
                  f"  winding after {t:3.0f} s  above {BURNT_C:g} °C: the insulation burns, the model ends there"
                  for t, c in self.winding_c_at.items()]
        lines += [f"  reaches {c:.0f} °C after {t:6.1f} s" if np.isfinite(t) else f"  never reaches {c:.0f} °C"
                  for c, t in self.time_to_c.items()]
        return "\n".join(lines)


def hold_demo(payload_kg: float = 40.0, hold_s: float = DEFAULT_HOLD_S, dt_s: float = 0.01) -> HoldDemo:
    """Hold ``payload_kg`` with the forearm horizontal for ``hold_s`` from idle: the winding at 10, 30 and
    60 s and when it reaches the elbow file's cut-off and short-term limits."""
    payload_kg = PAYLOAD_KG.check(_SRC, "payload_kg", payload_kg, "out of range")
    hold_s = HOLD_S.check(_SRC, "hold_s", hold_s, "out of range")
    dt_s = DT_S.check(_SRC, "dt_s", dt_s, "out of range")
    steps = max(1, round(hold_s / dt_s))
    require(steps <= MAX_STEPS, _SRC, "hold_s / dt_s", f"{steps} steps", f"at most {MAX_STEPS} steps (time): raise dt_s")
    model = load_model((ELBOW,), payload_kg=payload_kg)
    q = np.array([-np.pi / 2])
    current = model.static_current_a(q)
    traj = model.simulate(model.state(q=q), np.tile(current, (steps, 1)), dt_s)
    winding = traj["winding_c"][:, 0]
    at = {t: float(np.interp(t, traj.time_s, winding)) for t in (10.0, 30.0, 60.0) if t <= hold_s}
    first = {c: first_crossing(traj.time_s, winding, c) for c in limit_pair_c(model.params[ELBOW])}
    return HoldDemo(payload_kg, model.arm.settings.payload_lever_m, float(model.arm.gravity_torque_nm(q)[0]),
                    float(current[0]), model.params[ELBOW].motor.current_nominal_a,
                    model.params[ELBOW].motor.current_peak_a, float(winding[0]), at, first)
