"""Figures written to files with matplotlib's object API: no pyplot state and no backend chosen,
so the library never changes the caller's matplotlib set-up."""
from __future__ import annotations

from matplotlib.figure import Figure


def new_figure(nrows: int, ncols: int, figsize: tuple[float, float], **subplots):
    """A ``Figure`` and its axes (``Figure.subplots`` keywords, e.g. ``sharex``, ``squeeze``)."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **subplots)



def plot_comparison(plans, path) -> None:
    """``thermo-ddp compare --plot``: winding temperature and motor current of the lift under each limit."""
    fig, (temp, current) = new_figure(2, 1, figsize=(8, 6), sharex=True)
    for plan in plans:
        limit = plan.settings.limit_c
        line, = temp.plot(plan.time_s, plan.series("winding_c")[:, 0],
                          label=f"limit {limit:g} °C: holds {plan.achieved_hold_s:.1f} s")
        temp.axhline(limit, color=line.get_color(), ls="--", lw=0.8)
        current.step(plan.time_s[:-1], plan.us[:, 0], where="post", color=line.get_color(), label=f"limit {limit:g} °C")
    p0 = plans[0].settings
    temp.set(ylabel="winding [°C]", title=f"{p0.payload_kg:g} kg lift, {p0.hold_s:g} s hold asked (dashed: the limits)")
    current.set(ylabel="current [A]", xlabel="time [s]")
    for ax in (temp, current):
        ax.grid(alpha=0.3)
        ax.legend(fontsize=9, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=100)
