"""The figures of ``thermo-ddp loop``: per limit the closed loops of every model (loop.png), and the holds
and margins side by side (loop_summary.png)."""
from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from .._figures import new_figure
from .loop import ORACLE

if TYPE_CHECKING:
    from .loop import LoopResult

_COLORS = {"original": "tab:blue", "improved": "tab:green", ORACLE: "tab:gray"}


def plot_loop(result: LoopResult, path: Path) -> Path:
    """Per limit (a column): true and estimated winding [°C], current [A], measured casing [°C] of every model."""
    limits = result.settings.limits_c
    fig, axes = new_figure(3, len(limits), figsize=(7 * len(limits), 10), sharex="col", squeeze=False)
    for c, lim in enumerate(limits):
        ax = axes[:, c]
        for model in result.settings.models:
            e, color = result.execution(model, lim), _COLORS[model]
            r = e.run
            ax[0].plot(r.time_s, r.winding_c, c=color, label=f"{model}: true winding (peak {r.peak_winding_c:.1f} °C)")
            ax[0].plot(r.time_s, r.estimated_winding_c, c=color, ls="--", label=f"{model}: planner's estimate")
            ax[1].step(r.time_s[:-1], r.current_a, where="post", c=color,
                       label=f"{model}: current (hold {r.achieved_hold_s:.1f} s)")
            ax[2].plot(r.time_s, r.measured_casing_c, c=color, label=f"{model}: measured casing")
        ax[0].axhline(lim, c="k", ls="--", label=f"winding limit {lim:g} °C")
        ax[0].set(title=f"{result.settings.payload_kg:g} kg lift, winding limit {lim:g} °C (closed loop on the "
                        "robot's true physics)", ylabel="winding [°C]")
        ax[1].set(ylabel="current [A]")
        ax[2].axhline(result.execution("improved", lim).run.safety_cutoff_c, c="r", ls=":", label="safety cut-off")
        ax[2].set(ylabel="casing sensor [°C]", xlabel="time [s]")
        for a in ax:
            a.grid(alpha=0.3)
            a.legend(fontsize=7, loc="best")
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    return path


def plot_summary(result: LoopResult, path: Path) -> Path:
    """Bars per model and limit: planned and executed hold [s], margin to the limit [K]."""
    rows = result.rows()
    labels = [f"{r['model']}\n{r['limit_c']:g} °C" for r in rows]
    x = np.arange(len(rows))
    fig, ax = new_figure(1, 2, figsize=(12, 4))
    ax[0].bar(x - 0.2, [r["planned_hold_s"] for r in rows], 0.4, label="planned (open loop, model)")
    ax[0].bar(x + 0.2, [r["closed_loop_hold_s"] for r in rows], 0.4, label="executed (closed loop, robot)")
    ax[0].axhline(result.settings.hold_s, c="grey", ls=":", label="requested")
    ax[0].set(ylabel="hold [s]")
    margins = [r["margin_c"] for r in rows]
    ax[1].bar(x, margins, color=["tab:red" if m < 0 else _COLORS[r["model"]] for m, r in zip(margins, rows)])
    ax[1].axhline(0.0, c="k", lw=0.8)
    ax[1].set(ylabel="limit - peak TRUE winding [K] (< 0: limit broken)")
    ax[1].set_title("margin to the limit")
    ax[0].set_title("hold")
    for a in ax:
        a.set_xticks(x, labels)
        a.set_xlabel("model, winding limit [°C]")
        a.grid(alpha=0.3, axis="y")
    ax[0].legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=90)
    return path
