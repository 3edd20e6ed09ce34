"""How loud the command line is: the project's own log level and the third-party libraries' (Dask above all).

Verbosity (``-q`` -1, default 0, ``-v`` 1, ``-vv`` 2): the project logs errors only, warnings, its steps
(INFO) or everything (DEBUG), its per-solve lines (:data:`PER_SOLVE`) only with ``-vv``; third-party
libraries log errors only unless ``-vv``. Dask's level is also set through its configuration
(``DASK_LOGGING__DISTRIBUTED``) so that the scheduler and the worker processes it starts, which configure
their own logging from it, stay as quiet.
"""
from __future__ import annotations

import logging
import os
import sys

PROJECT = "thermo_ddp"
# One line per solve or per control period: a closed loop re-solves every 0.1 s, so these are debug lines
# whatever level they are logged at (-vv shows them), each logger kept at the level given here below -vv:
# the solvers' warnings still show; the controller's per-period lines (a failed re-solve, a shortened hold)
# are counted by the results instead (events, fallbacks: the loop and sweep reports print the counts).
PER_SOLVE = {"thermo_ddp.solvers.ddp": logging.WARNING, "thermo_ddp.solvers.reference": logging.WARNING,
             "thermo_ddp.mpc.controller": logging.ERROR}
THIRD_PARTY = ("distributed", "dask", "bokeh", "tornado", "asyncio", "matplotlib", "PIL", "fsspec")
_PROJECT_LEVELS = {-1: logging.ERROR, 0: logging.WARNING, 1: logging.INFO, 2: logging.DEBUG}


class _Stderr(logging.StreamHandler):
    """A handler on whatever ``sys.stderr`` is when a record comes (a caller may have replaced it since)."""

    @property
    def stream(self):
        return sys.stderr

    @stream.setter
    def stream(self, _value) -> None:
        pass


def configure_logging(verbosity: int) -> None:
    """One handler on stderr (``name: message``) and the levels of ``verbosity`` (see the module docstring)."""
    verbosity = max(-1, min(2, verbosity))
    root = logging.getLogger()
    if not any(isinstance(h, _Stderr) for h in root.handlers):
        handler = _Stderr()
        handler.setFormatter(logging.Formatter("%(name)s: %(message)s"))
        root.addHandler(handler)
    root.setLevel(logging.DEBUG if verbosity >= 2 else logging.WARNING)
    logging.getLogger(PROJECT).setLevel(_PROJECT_LEVELS[verbosity])
    for name, level in PER_SOLVE.items():
        logging.getLogger(name).setLevel(logging.DEBUG if verbosity >= 2 else max(level, _PROJECT_LEVELS[verbosity]))
    third = logging.INFO if verbosity >= 2 else logging.ERROR
    for name in THIRD_PARTY:
        logging.getLogger(name).setLevel(third)
    os.environ["DASK_LOGGING__DISTRIBUTED"] = logging.getLevelName(third).lower()
    if "dask" in sys.modules:  # already configured from the environment: set it here too
        import dask
        dask.config.set({"logging.distributed": logging.getLevelName(third).lower()})
