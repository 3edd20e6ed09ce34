"""Figures, written to files (matplotlib)."""
from __future__ import annotations

import numpy as np

from .._figures import new_figure


def plot_lift(plan, path=None):
    """Four panels: angle; current; voltage; winding and casing vs the limit and the cut-off. Written to
    ``path`` when given; the Figure is returned either way."""
    t = plan.time_s
    joint = plan.model.joints[0]
    params = plan.model.params[joint]
    fig, ax = new_figure(4, 1, figsize=(8, 10), sharex=True)
    ax[0].plot(t, np.degrees(plan.series("q_rad")), label="elbow angle")
    ax[0].axhline(np.degrees(plan.settings.goal_rad), ls=":", c="k", label="goal")
    ax[0].set_ylabel("angle [deg]")
    ax[1].step(t, plan.currents(), where="post", label="current")
    ax[1].axhline(params.motor.current_peak_a, ls=":", c="r")
    ax[1].axhline(-params.motor.current_peak_a, ls=":", c="r", label="peak current")
    ax[1].set_ylabel("current [A]")
    ax[2].plot(t, plan.voltage_v(), c="tab:purple", label="voltage")
    ax[2].axhline(params.motor.bus_voltage_v, ls=":", c="r", label="bus voltage")
    ax[2].axhline(-params.motor.bus_voltage_v, ls=":", c="r")
    ax[2].set_ylabel("voltage [V]")
    ax[3].plot(t, plan.series("winding_c"), c="tab:red", label="winding")
    ax[3].plot(t, plan.sensor_c(), c="tab:orange", label="casing (sensor)")
    ax[3].axhline(plan.settings.limit_c, ls="--", c="k", label=f"winding limit {plan.settings.limit_c:g} °C")
    ax[3].axhline(params.limits.safety_cutoff_c, ls=":", c="grey", label=f"cut-off {params.limits.safety_cutoff_c:g} °C (casing sensor)")
    ax[3].set_ylabel("temperature [°C]")
    ax[3].set_xlabel("time [s]")
    for a in ax:
        a.legend(loc="best", fontsize=8)
        a.grid(alpha=0.3)
    ax[0].set_title(plan.headline(), fontsize=10, wrap=True)
    fig.tight_layout()
    if path is not None:
        fig.savefig(path, dpi=100)
    return fig
