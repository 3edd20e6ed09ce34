"""The robust lift's figure: the nominal plan's panels and the band of winding temperatures over the set."""
from __future__ import annotations

import numpy as np

from .._figures import new_figure


def plot_robust_lift(plan, path) -> None:
    """Three panels: angle; current; the winding of the nominal motor, the band over the set (replayed
    motors and the worst one) and the worst motor's, against the limit."""
    t, r = plan.time_s, plan.robust
    fig, ax = new_figure(3, 1, figsize=(8, 8), sharex=True)
    ax[0].plot(t, np.degrees(plan.series("q_rad")), label="elbow angle")
    ax[0].axhline(np.degrees(plan.settings.goal_rad), ls=":", c="k", label="goal")
    ax[0].set_ylabel("angle [deg]")
    ax[1].step(t, plan.currents(), where="post", label="current")
    ax[1].set_ylabel("current [A]")
    ax[2].fill_between(t, r.band_c[:, 0], r.band_c[:, 1], color="tab:red", alpha=0.25,
                       label=f"winding over the set ({r.uset.label})")
    ax[2].plot(t, plan.series("winding_c"), c="tab:red", label="winding, nominal motor")
    ax[2].plot(t, plan.sensor_c(), c="tab:orange", label="casing (sensor), nominal motor")
    ax[2].axhline(plan.settings.limit_c, ls="--", c="k", label=f"winding limit {plan.settings.limit_c:g} °C")
    ax[2].set_ylabel("temperature [°C]")
    ax[2].set_xlabel("time [s]")
    for a in ax:
        a.legend(loc="best", fontsize=8)
        a.grid(alpha=0.3)
    ax[0].set_title(f"robust {plan.settings.payload_kg:g} kg lift, limit {plan.settings.limit_c:g} °C: {plan.status}, "
                    f"hold {plan.achieved_hold_s:.1f} s (nominal {r.nominal_hold_s:.1f} s)")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
