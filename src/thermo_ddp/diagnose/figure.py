"""The thermal diagnosis figure (``thermo-ddp diagnose --plot``), drawn to be read.

One column per recording, up to :data:`MAX_COLUMNS` side by side and further recordings in the rows below,
every recording shown up to :data:`MAX_RECORDINGS` (the title says how many are shown). Per recording, four
panels, each with one unit: the sensor temperature recorded and predicted [°C], the residuals with the
shaded intervals explained in the legend [K], the RMS current over a minute [A] and the RMS speed over a
minute [rad/s]. About 5 inches a column at 100 dpi (three columns: 1,560 px), text 9 pt and larger.
"""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
from matplotlib import rc_context

from .._figures import new_figure
from ._thermal_localise import held_window_mean

MAX_COLUMNS, MAX_RECORDINGS = 3, 12
COLUMN_IN, PANEL_IN, DPI = 5.2, 1.9, 100
WINDOW_HALF_S = 30.0  # the RMS current and speed over a minute
SHADES = (("tab:red", "mismatch of the baseline"), ("0.5", "left unexplained by the final model"))
FONT = {"font.size": 10, "axes.titlesize": 10, "axes.labelsize": 10, "legend.fontsize": 9,
        "xtick.labelsize": 9, "ytick.labelsize": 9}


def plot_thermal_diagnosis(diagnosis, path: str | Path, max_recordings: int = MAX_RECORDINGS) -> Path:
    """Write the figure of ``diagnosis`` (a :class:`~thermo_ddp.diagnose.thermal.ThermalDiagnosis`) to ``path``."""
    grids = diagnosis.grids[:max_recordings]
    blocks = max(1, math.ceil(len(grids) / MAX_COLUMNS))
    columns = max(1, math.ceil(len(grids) / blocks))  # four recordings: two by two
    with rc_context(FONT):
        fig, axes = new_figure(4 * blocks, columns, figsize=(COLUMN_IN * columns, PANEL_IN * 4 * blocks + 0.6),
                               squeeze=False)
        for i, grid in enumerate(grids):
            block, column = divmod(i, columns)
            _recording_panels(diagnosis, grid, axes[4 * block:4 * block + 4, column])
        for i in range(len(grids), blocks * columns):  # empty places of the last row of recordings
            block, column = divmod(i, columns)
            for ax in axes[4 * block:4 * block + 4, column]:
                ax.set_visible(False)
        shown = f"all {len(diagnosis.grids)} recordings" if len(grids) == len(diagnosis.grids) else \
            f"the first {len(grids)} of {len(diagnosis.grids)} recordings (the JSON has every one)"
        fig.suptitle(f"thermal diagnosis: {diagnosis.status}; {shown}")
        fig.tight_layout(rect=(0, 0, 1, 1 - 0.4 / fig.get_figheight()))  # room for the title
        fig.savefig(path, dpi=DPI)
    return Path(path)


def _recording_panels(diagnosis, grid, ax) -> None:
    """The four panels of one recording (``ax``: four axes, top to bottom)."""
    t = grid.time_s
    for a in ax[1:]:
        a.sharex(ax[0])
    ax[0].plot(t, grid.measured_c, "k.", ms=1.5, label="recorded (sensor)")
    for fit, name in ((diagnosis.baseline_fit, "baseline"), (diagnosis.final_fit, "final")):
        if fit is not None:
            rows = fit.rows(grid.name)
            ax[0].plot(t, fit.fitted[rows], lw=1.2, label=f"{name}: {fit.model}")
            ax[1].plot(t, fit.residuals[rows], lw=0.7, label=f"{name}, rmse {fit.rmse:.3g} K")
    _shade(diagnosis, grid.name, ax[1])
    ax[2].plot(t, np.sqrt(np.maximum(held_window_mean(grid, 1, WINDOW_HALF_S), 0.0)), lw=0.9, color="tab:purple",
               label="RMS current over 1 min")
    ax[3].plot(t, np.sqrt(np.maximum(held_window_mean(grid, 3, WINDOW_HALF_S), 0.0)), lw=0.9, color="tab:brown",
               label=f"RMS speed over 1 min (from {grid.speed_source})")
    ax[0].set(title=grid.name, ylabel="temperature [°C]")
    ax[1].set(ylabel="residual [K]")
    ax[2].set(ylabel="current [A]")
    ax[3].set(ylabel="speed [rad/s]", xlabel="time [s]")
    for a in ax:
        a.grid(alpha=0.3)
        a.legend(loc="best")


def _shade(diagnosis, recording: str, ax) -> None:
    """The baseline's mismatch intervals and the final model's unexplained ones, each named once in the legend."""
    for localisation, (color, meaning) in zip(diagnosis.localisations or (), SHADES):
        spans = [m for m in localisation.mismatches if m.recording == recording]
        for k, m in enumerate(spans):
            ax.axvspan(m.start_s, m.end_s, color=color, alpha=0.2, lw=0, label=f"{meaning} ({len(spans)})" if k == 0
                       else None)


def draw_network(spec, ax, sensors=()) -> None:
    """Draw a thermal network (:class:`~thermo_ddp.model.network_spec.NetworkSpec`) on ``ax`` as a graph:
    its nodes (capacity; measured ones, ``sensors``, filled), its links (resistance), the heat sink (and the
    room, when a link reaches it), and each heat source with its share at the nodes it heats."""
    from ..model.network_spec import AMBIENT, ROOM

    names = spec.node_names
    angle = np.linspace(np.pi * 0.9, np.pi * 0.1, len(names)) if len(names) > 1 else np.array([np.pi / 2])
    where = {n: (1.6 * np.cos(a), 1.2 * np.sin(a)) for n, a in zip(names, angle)}  # an arc above the sink
    boundaries = {AMBIENT: ((0.0, -1.2), f"{AMBIENT} (sink)"), ROOM: ((1.6, -1.2), ROOM)}
    boundaries = {b: v for b, v in boundaries.items() if b == AMBIENT or any(b in k.between for k in spec.links)}
    where |= {b: xy for b, (xy, _) in boundaries.items()}
    for link in spec.links:
        (xa, ya), (xb, yb) = where[link.between[0]], where[link.between[1]]
        ax.plot([xa, xb], [ya, yb], "-", color="0.4", lw=1.5, zorder=1)
        ax.text((xa + xb) / 2, (ya + yb) / 2, f"{float(link.resistance_k_per_w):.3g} K/W", fontsize=8,
                ha="center", va="center", bbox={"fc": "white", "ec": "none", "alpha": 0.8}, zorder=2)
    for node in spec.nodes:
        x, y = where[node.name]
        measured = node.name in sensors
        ax.scatter([x], [y], s=900, color="tab:blue" if measured else "white", edgecolors="tab:blue", zorder=3)
        ax.text(x, y - 0.22, f"{node.name}\n{float(node.capacity_j_per_k):.3g} J/K" + ("\n(measured)" if measured else ""),
                ha="center", va="top", fontsize=8, zorder=4)
    for (x, y), label in boundaries.values():
        ax.scatter([x], [y], s=900, marker="s", color="0.85", edgecolors="0.3", zorder=3)
        ax.text(x, y - 0.25, label, ha="center", va="top", fontsize=8)
    heated: dict[str, int] = {}
    for src in spec.sources:
        for node, share in src.split.items():
            x, y = where[node]
            k = heated[node] = heated.get(node, -1) + 1  # the k-th source of this node: one line further out
            ax.annotate(f"{src.label} {100 * float(share):.0f} %", (x, y + 0.1), (x, y + 0.45 + 0.2 * k), fontsize=8,
                        ha="center", color="tab:red", arrowprops={"arrowstyle": "->", "color": "tab:red"}, zorder=4)
    ax.set(xlim=(-2.3, 2.3), ylim=(-1.8, 2.4))
    ax.axis("off")
