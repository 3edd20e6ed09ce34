"""Results by name: the trajectories of a plan, the plan JSON's arrays, and number formatting."""
from __future__ import annotations

import math

import numpy as np


def finite_or_none(value: float):
    return None if not math.isfinite(value) else float(value)


def format_s(t: float) -> str:
    return "never" if not math.isfinite(t) else f"{t:.1f} s"


class PlanSeries:
    """Trajectories by name and the plan JSON of a plan with ``model``, ``time_s``, ``xs`` (N+1, nx),
    ``us`` (N, nu), ``feasible``, ``status``, ``cause``, ``message``, ``solver``, ``binding_constraints`` and
    ``time_to_limit_s``."""

    @property
    def success(self) -> bool:
        """The planner reached a verdict (feasible or not): every status but ``failed``."""
        return self.status != "failed"

    def series(self, quantity: str) -> np.ndarray:
        """(N+1, joints) of a state quantity (q_rad, v_rad_s, winding_c, casing_c, drive_c)."""
        return self.xs[:, [self.model.index(j, quantity) for j in self.model.joints]]

    def sensor_c(self) -> np.ndarray:
        """(N+1, joints) of the measured node: the casing, or the winding itself in a one-node model."""
        return self.xs[:, self.model.sensor_indices()]

    def currents(self) -> np.ndarray:
        """(N+1, joints): u_k holds on [t_k, t_k+1); the last value is repeated at t_N."""
        return np.vstack([self.us, self.us[-1:]])

    def output(self, name: str) -> np.ndarray:
        """(N+1, joints) of a model output (voltage_v, joule_w, ...) with :meth:`currents`."""
        out = self.model.outputs.map(self.xs.shape[0])
        amb = np.full((1, self.xs.shape[0]), self.model.ambient_c)
        return np.array(out(self.xs.T, self.currents().T, amb)[self.model.outputs.name_out().index(name)]).T

    def voltage_v(self) -> np.ndarray:
        return self.output("voltage_v")

    def contract_dict(self, payload_kg: float, limit_c: float, hold_s: float, achieved_hold_s: float,
                      integrator: str, dt_s: float) -> dict:
        """The plan JSON (contract): arrays [time][joint], ``casing_c`` the sensor node, ``drive_c`` only
        when every joint has a drive node; the ``model`` echo, ``solver``, binding constraints and the
        time to the limit (None: never)."""
        d = {"success": self.success, "feasible": self.feasible, "status": self.status, "cause": self.cause,
             "message": self.message, "payload_kg": payload_kg,
             "limit_c": limit_c, "hold_s": hold_s, "achieved_hold_s": achieved_hold_s,
             "joints": list(self.model.joints), "time_s": self.time_s.tolist(), "q_rad": self.series("q_rad").tolist(),
             "v_rad_s": self.series("v_rad_s").tolist(), "current_a": self.currents().tolist(),
             "voltage_v": self.voltage_v().tolist(), "winding_c": self.series("winding_c").tolist(),
             "casing_c": self.sensor_c().tolist()}
        if all("drive" in self.model.networks[j].nodes for j in self.model.joints):
            d["drive_c"] = self.series("drive_c").tolist()
        d["model"] = self.model.to_dict(integrator, dt_s)
        d["solver"] = dict(self.solver)
        d["binding_constraints"] = list(self.binding_constraints)
        d["time_to_limit_s"] = finite_or_none(self.time_to_limit_s)
        return d
