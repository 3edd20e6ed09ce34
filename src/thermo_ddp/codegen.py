"""Generate C for a CasADi function, compile it with gcc, cache the shared library on disk.

The cache key is a hash of the function's serialisation and the compiler flags, so a changed
model never loads a stale library. Default cache: ``$THERMO_DDP_CACHE`` or ``~/.cache/thermo_ddp``.
"""
from __future__ import annotations

import hashlib
import logging
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import casadi as ca

log = logging.getLogger(__name__)
FLAGS = ("-O2", "-fPIC", "-shared")


def cache_dir() -> Path:
    return Path(os.environ.get("THERMO_DDP_CACHE", Path.home() / ".cache" / "thermo_ddp"))


def function_hash(fn: ca.Function) -> str:
    return hashlib.sha256((fn.serialize() + " ".join(FLAGS)).encode()).hexdigest()[:16]


def compiled(fn: ca.Function) -> ca.Function:
    """The same function as compiled C (built once per hash). Raises if no C compiler works."""
    cc = shutil.which(os.environ.get("CC", "gcc"))
    if cc is None:
        raise RuntimeError("code generation needs a C compiler (gcc); none found")
    name = f"{fn.name()}_{function_hash(fn)}"
    lib = cache_dir() / f"{name}.so"
    if not lib.exists():
        lib.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.TemporaryDirectory() as tmp:
            src = Path(tmp) / f"{name}.c"
            gen = ca.CodeGenerator(src.name, {"with_header": False})
            gen.add(fn)
            gen.generate(tmp + os.sep)
            tmp_lib = lib.with_suffix(f".{os.getpid()}.tmp")
            subprocess.run([cc, *FLAGS, str(src), "-o", str(tmp_lib), "-lm"], check=True,
                           capture_output=True)
            os.replace(tmp_lib, lib)  # atomic: concurrent builders never see half a library
        log.info("compiled %s -> %s", fn.name(), lib)
    return ca.external(fn.name(), str(lib))
