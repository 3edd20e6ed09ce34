"""The API reference's promise, checked at every build: each public name has an entry.

Public names: everything in ``thermo_ddp.__all__`` and ``thermo_ddp.solvers.__all__``, and the classes and
functions that ``thermo_ddp.ocp`` defines without a leading underscore. A name without an entry in the
built reference is a warning, so ``make docs`` (warnings as errors) fails on it. ``tests/test_docs.py``
reads the same list.
"""
from __future__ import annotations

import importlib
import inspect

WITH_ALL = ("thermo_ddp", "thermo_ddp.solvers")   # modules whose __all__ is their public API
DEFINED_IN = ("thermo_ddp.ocp",)                   # modules without __all__: their own public classes, functions


def public_names() -> list[str]:
    """Fully qualified names the API reference must document."""
    names = []
    for modname in WITH_ALL:
        module = importlib.import_module(modname)
        names += [f"{modname}.{name}" for name in module.__all__]
    for modname in DEFINED_IN:
        module = importlib.import_module(modname)
        names += [f"{modname}.{name}" for name, obj in vars(module).items()
                  if not name.startswith("_") and (inspect.isclass(obj) or inspect.isfunction(obj))
                  and obj.__module__ == modname]
    return names


def _check(app, env) -> None:
    from sphinx.util import logging  # here, so that the tests read public_names() without Sphinx

    log = logging.getLogger(__name__)
    documented = set(env.get_domain("py").objects)
    missing = [name for name in public_names() if name not in documented]
    for name in missing:
        log.warning("API reference: no entry for the public name %s (docs/api/*.md: automodule with :members:)",
                    name, type="api_coverage")


def setup(app):
    app.connect("env-check-consistency", _check)
    return {"parallel_read_safe": True, "parallel_write_safe": True}
