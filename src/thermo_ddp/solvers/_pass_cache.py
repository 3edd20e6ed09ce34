"""Find the compiled DDP knot functions of a problem's structure without building them symbolically.

``codegen`` names a library by the hash of the generated functions, so finding it means building
them first (tens of ms for the lift, seconds for the 7-joint arm). This index maps a cheaper key to
that library: the hash of everything the knot functions are built from (the problem's functions,
weights and control bounds, the DDP settings that shape the code, the CasADi version, the host when
compiling with -march=native, and the source of the modules that build them and of the C driver).
The key holds nothing per request: no horizon (the driver loops over a runtime N), no x0, no
parameter values. A hit loads the library directly; a miss builds as before and records it.
Loaded libraries stay in this process (a dict from key to the ctypes handle), so a second solver
of the same structure, e.g. for another horizon, costs no file access either.
"""
from __future__ import annotations

import ctypes
import functools
import hashlib
import os
from importlib import resources
from pathlib import Path

import casadi as ca

from .. import codegen, ocp

DRIVER = "ddp_passes.c"
_LOADED: dict[str, ctypes.CDLL] = {}


@functools.lru_cache(maxsize=1)
def driver_source() -> str:
    """The C driver looping the knot functions over the horizon (package data)."""
    return resources.files(__package__).joinpath(DRIVER).read_text()


@functools.lru_cache(maxsize=1)
def _sources() -> bytes:
    here = Path(__file__).parent
    files = [here / "_backends.py", here / "_layout.py", here / "_riccati.py", here / "_pass_cache.py", Path(ocp.__file__),
             Path(codegen.__file__)]
    return b"".join(f.read_bytes() for f in files) + driver_source().encode()


def key(problem, settings) -> str | None:
    """The index key of this problem structure's knot functions (None if a function cannot be serialised)."""
    structure = problem.structure_digest
    if structure is None:
        return None
    flags = tuple(settings.compiler_flags)
    # the settings the code depends on
    shape = (settings.full_second_order, settings.box_iterations, settings.active_margin, flags)
    host = codegen._host_tag() if any("native" in f for f in flags) else ""
    digest = hashlib.sha256(_sources())
    for part in (ca.__version__, repr(shape), structure, host):
        digest.update(part.encode())
    return digest.hexdigest()[:24]


def _index(k: str) -> Path:
    return codegen.cache_dir() / f"ddp_passes_{k}.txt"


def load(k: str | None) -> ctypes.CDLL | None:
    """The library recorded under ``k`` (loaded once per process), or None."""
    if k is None:
        return None
    if k in _LOADED:
        return _LOADED[k]
    if not _index(k).exists():
        return None
    library = codegen.cache_dir() / _index(k).read_text().strip()
    if not codegen.use_library(library):
        return None
    return _load(k, library)


def record(k: str | None, library: Path) -> ctypes.CDLL:
    """Record ``library`` (already built) under ``k`` and load it."""
    if k is not None:
        index = _index(k)
        tmp = index.with_suffix(f".{os.getpid()}.tmp")
        tmp.write_text(library.name)
        os.replace(tmp, index)  # atomic: concurrent solvers never read half a name
    return _load(k, library)


def _load(k: str | None, library: Path) -> ctypes.CDLL:
    lib = ctypes.CDLL(str(library.resolve()))  # a bare name would be searched on the system paths
    if k is not None:
        _LOADED[k] = lib
    return lib
