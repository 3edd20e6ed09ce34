"""Closed-loop figure, written to a file (matplotlib)."""
from __future__ import annotations

import numpy as np

from .._figures import new_figure


def plot_closed_loop(result, path) -> None:
    """Angle; current and voltage; true/estimated/measured temperatures vs limits; solve times."""
    t, tk = result.time_s, result.time_s[:-1]
    s = result.settings
    fig, ax = new_figure(4, 1, figsize=(8, 11), sharex=True)
    ax[0].plot(t, np.degrees(result.q_rad), label="elbow angle (true)")
    ax[0].set_ylabel("angle [deg]")
    ax[1].step(tk, result.current_a, where="post", label="current")
    ax[1].set_ylabel("current [A]")
    twin = ax[1].twinx()
    twin.step(tk, result.voltage_v, where="post", c="tab:purple", label="voltage")
    twin.set_ylabel("voltage [V]")
    est, std = result.estimated_winding_c, result.winding_std_c
    ax[2].plot(t, result.winding_c, c="tab:red", label="winding (true)")
    ax[2].plot(t, est, c="tab:red", ls="--", label="winding (EKF)")
    ax[2].fill_between(t, est - 2 * std, est + 2 * std, color="tab:red", alpha=0.15, label="EKF ±2σ")
    ax[2].plot(t, result.casing_c, c="tab:orange", label="casing (true)")
    ax[2].plot(t, result.measured_casing_c, c="tab:orange", ls=":", label="casing (sensor)")
    ax[2].axhline(s.limit_c, c="k", ls="--", label=f"winding limit {s.limit_c:g} °C")
    ax[2].axhline(s.planning_limit_c, c="grey", ls="-.", label=f"planning limit {s.planning_limit_c:g} °C")
    ax[2].set_ylabel("temperature [°C]")
    ax[3].semilogy(tk, 1e3 * result.solve_s, ".", label="solve time per period")
    ax[3].set_ylabel("solve [ms]")
    ax[3].set_xlabel("time [s]")
    for a in ax:
        a.legend(loc="best", fontsize=7)
        a.grid(alpha=0.3)
    ax[0].set_title(f"closed loop {s.scenario.payload_kg:g} kg, hold {s.scenario.hold_s:g} s: {result.status}, "
                    f"margin {result.margin_c:.2f} K")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
