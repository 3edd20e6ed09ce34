"""Figures written to files with matplotlib's object API: no pyplot state and no backend chosen,
so the library never changes the caller's matplotlib set-up."""
from __future__ import annotations

from matplotlib.figure import Figure


def new_figure(nrows: int, ncols: int, figsize: tuple[float, float], **subplots):
    """A ``Figure`` and its axes (``Figure.subplots`` keywords, e.g. ``sharex``, ``squeeze``)."""
    fig = Figure(figsize=figsize)
    return fig, fig.subplots(nrows, ncols, **subplots)

