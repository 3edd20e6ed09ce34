"""Find the compiled DDP passes of a problem without building them symbolically.

``codegen`` names a library by the hash of the generated functions, so finding it means building
them first (tens of ms for the lift). This index maps a cheaper key to that library: the hash of
everything the passes are built from (the problem's functions, weights, bounds and horizon, the
DDP settings, the CasADi version, the host when compiling with -march=native, and the source of
the modules that build the passes). A hit loads the library directly; a miss builds as before and
records the library under the key.
"""
from __future__ import annotations

import functools
import hashlib
import os
from pathlib import Path

import casadi as ca

from .. import codegen, ocp


@functools.lru_cache(maxsize=1)
def _sources() -> bytes:
    here = Path(__file__).parent
    files = [here / "_backends.py", here / "_riccati.py", here / "_pass_cache.py", Path(ocp.__file__),
             Path(codegen.__file__)]
    return b"".join(f.read_bytes() for f in files)


def key(problem, settings) -> str | None:
    """The index key of this problem's passes (None if a function cannot be serialised)."""
    digest = hashlib.sha256(_sources())
    flags = tuple(settings.compiler_flags)
    for part in (ca.__version__, repr(settings), str(problem.horizon), problem.u_lb.tobytes().hex(),
                 problem.u_ub.tobytes().hex(), codegen._host_tag() if any("native" in f for f in flags) else ""):
        digest.update(part.encode())
    funs = [problem.dynamics, problem.dynamics_jacobians]
    funs += [c.residual for c in problem.costs + problem.terminal_costs]
    funs += [c.function for c in problem.constraints + problem.terminal_constraints]
    try:
        for f in funs:
            digest.update(b"-" if f is None else f.serialize().encode())
    except RuntimeError:
        return None
    for c in problem.costs + problem.terminal_costs:
        digest.update(c.weight.tobytes())
    return digest.hexdigest()[:24]


def _index(k: str) -> Path:
    return codegen.cache_dir() / f"ddp_passes_{k}.txt"


def load(k: str | None) -> dict[str, ca.Function] | None:
    """The compiled passes recorded under ``k``, or None."""
    if k is None or not _index(k).exists():
        return None
    library, *names = _index(k).read_text().split()
    library = codegen.cache_dir() / library
    if not codegen.use_library(library):
        return None
    return {name: ca.external(fname, str(library)) for name, fname in zip(names[::2], names[1::2])}


def record(k: str | None, passes: dict[str, ca.Function], flags) -> None:
    """Record the library of ``passes`` (already compiled) under ``k``."""
    if k is None:
        return
    index = _index(k)
    tmp = index.with_suffix(f".{os.getpid()}.tmp")
    names = " ".join(f"{name} {f.name()}" for name, f in passes.items())
    tmp.write_text(f"{codegen.library_path(passes, flags).name} {names}")
    os.replace(tmp, index)  # atomic: concurrent solvers never read half a name
