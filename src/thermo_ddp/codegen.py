"""Generate C for CasADi functions, compile with gcc, cache the shared library on disk.

The library's name is a hash of the functions' serialisation, the CasADi version and the compiler
flags (and the CPU when the flags say -march=native), so a changed model or option never loads a
stale library. Cache folder: ``$THERMO_DDP_CACHE`` or ``~/.cache/thermo_ddp``.
"""
from __future__ import annotations

import hashlib
import logging
import os
import platform
import shutil
import subprocess
import tempfile
from pathlib import Path
from typing import Mapping

import casadi as ca

log = logging.getLogger(__name__)
DEFAULT_FLAGS = ("-O2",)


def cache_dir() -> Path:
    return Path(os.environ.get("THERMO_DDP_CACHE", Path.home() / ".cache" / "thermo_ddp"))


def _host_tag() -> str:
    """CPU model and instruction-set flags: code built with -march=native runs only there."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return platform.machine() + platform.processor()
    return platform.machine() + "".join([ln for ln in lines if ln.startswith(("model name", "flags"))][:2])


def library_path(functions: Mapping[str, ca.Function], flags=DEFAULT_FLAGS) -> Path:
    """Where the library for these functions and flags is (or will be) cached."""
    digest = hashlib.sha256()
    digest.update(ca.__version__.encode())
    digest.update(" ".join(flags).encode())
    if any("native" in f for f in flags):
        digest.update(_host_tag().encode())
    for name in sorted(functions):
        digest.update(name.encode())
        digest.update(functions[name].serialize().encode())
    prefix = next(iter(functions)) if len(functions) == 1 else "functions"
    return cache_dir() / f"{prefix}_{digest.hexdigest()[:20]}.so"


def compile_functions(functions: Mapping[str, ca.Function], flags=DEFAULT_FLAGS) -> dict[str, ca.Function]:
    """The functions as compiled C from one cached library (built on first use).

    Raises RuntimeError when no C compiler is found, CalledProcessError when gcc fails.
    """
    cc = shutil.which(os.environ.get("CC", "gcc"))
    if cc is None:
        raise RuntimeError("code generation needs a C compiler (gcc); none found")
    library = library_path(functions, flags)
    if not library.exists():
        library.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory(dir=library.parent) as tmp:
            source = library.with_suffix(".c").name
            gen = ca.CodeGenerator(source, {"with_header": False})
            for name in sorted(functions):
                gen.add(functions[name])
            gen.generate(tmp + os.sep)
            built = Path(tmp) / library.name
            log.info("compiling %s with %s %s", source, cc, " ".join(flags))
            subprocess.run([cc, *flags, "-shared", "-fPIC", "-o", str(built), str(Path(tmp) / source), "-lm"],
                           check=True, capture_output=True)
            os.replace(built, library)  # atomic: concurrent builders never see half a library
    return {name: ca.external(f.name(), str(library)) for name, f in functions.items()}


def compiled(fn: ca.Function, flags=DEFAULT_FLAGS) -> ca.Function:
    """One function as compiled C (see :func:`compile_functions`)."""
    return compile_functions({fn.name(): fn}, flags)[fn.name()]
