"""Generate C for CasADi functions, compile with gcc, cache the shared library on disk.

The library's name is a hash of the functions' serialisation, any hand-written C linked with them,
the CasADi version and the compiler flags (and the CPU when the flags say -march=native), so a
changed model, driver or option never loads a stale library. Cache folder: ``$THERMO_DDP_CACHE`` or
``~/.cache/thermo_ddp``.

Build: each function's C goes to its own file; the files are compiled to objects in parallel (up to
``os.cpu_count()`` compilers, the longest first) and linked. gcc's time grows steeply with the size
of one function at -O2, so a generated file above ``LARGE_SOURCE_BYTES`` is compiled at -O1 and one
above ``HUGE_SOURCE_BYTES`` at -O0 (measured on this machine: -O2 0.03-0.08, -O1 0.16, -O0 0.7 MB of
generated C per second; runtime cost in benchmarks/README.md).

The cache is bounded: after a build pushes the libraries over ``$THERMO_DDP_CACHE_MAX_MB`` (default
2000), the least recently used ones are removed. Each use stamps a library's access time (its
modification time stays the build's) just before loading it. Removal cannot break a process that
has already loaded a library (on POSIX the mapping keeps the unlinked file alive); the only window is
between finding a file and loading it, so eviction skips every library used in the last
``EVICTION_GRACE_S`` seconds, and a loader that finds its library gone builds it again.
"""
from __future__ import annotations

import hashlib
import logging
import math
import os
import platform
import shutil
import subprocess
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path
from typing import Mapping

import casadi as ca

from .errors import InputError

log = logging.getLogger(__name__)
DEFAULT_FLAGS = ("-O2",)
# The parts of -ffast-math that only reorder arithmetic (x / c as x * (1/c), sums regrouped): results move by
# rounding only. Not -ffinite-math-only (NaN and inf tests stay), nor -ffast-math itself, whose link step adds
# crtfastmath.o (denormals flushed to zero in the whole process). Measured on the lift's full-DDP knots
# (rk4_4, N = 645, benchmarks/README.md): backward pass 1.77 -> 1.30 ms, forward pass 0.53 -> 0.41 ms.
REASSOCIATING_FLAGS = ("-freciprocal-math", "-fassociative-math", "-fno-signed-zeros", "-fno-trapping-math")
DEFAULT_CACHE_MAX_MB = 2000.0
EVICTION_GRACE_S = 60.0  # far longer than finding and loading a library takes
LARGE_SOURCE_BYTES = 1_500_000  # generated C above this is compiled at -O1 ...
HUGE_SOURCE_BYTES = 8_000_000  # ... above this at -O0
_SECONDS_PER_MB = {"-O0": 1.4, "-O1": 6.0}  # gcc on generated C, else ~15 (-O2): the order of the compilations
_LIBRARY_GLOB = "*_" + "[0-9a-f]" * 20 + ".so"  # what library_path names; nothing else is removed
_INDEX_GLOB = "ddp_passes_*.txt"  # solvers' index of compiled passes (see solvers/_pass_cache.py)


def cache_dir() -> Path:
    return Path(os.environ.get("THERMO_DDP_CACHE", Path.home() / ".cache" / "thermo_ddp"))


def cache_max_bytes() -> int:
    """The size cap of the cache, from ``$THERMO_DDP_CACHE_MAX_MB`` (MB = 10^6 bytes)."""
    text = os.environ.get("THERMO_DDP_CACHE_MAX_MB", str(DEFAULT_CACHE_MAX_MB))
    try:
        mb = float(text)
    except ValueError:
        mb = -1.0
    if not (math.isfinite(mb) and mb >= 0):
        raise InputError("environment", "THERMO_DDP_CACHE_MAX_MB", text, "expected a size in MB >= 0")
    return int(mb * 1e6)


def _libraries(folder: Path) -> list[tuple[Path, os.stat_result]]:
    """The cached libraries and their status (files removed meanwhile by another process left out)."""
    found = []
    for lib in sorted(folder.glob(_LIBRARY_GLOB)):
        try:
            found.append((lib, lib.stat()))
        except FileNotFoundError:
            continue
    return found


def use_library(library: Path) -> bool:
    """Stamp ``library`` as used now (access time; the build's modification time is kept) before
    loading it; False when it is not in the cache."""
    try:
        os.utime(library, ns=(time.time_ns(), library.stat().st_mtime_ns))
    except FileNotFoundError:
        return False
    return True


def _remove(path: Path) -> bool:
    """Remove one cache file by rename-then-unlink, so a loader sees the whole file or none and two
    processes trimming at once never both count it; False when another process removed it first."""
    doomed = path.with_name(f".{path.name}.{os.getpid()}.removed")
    try:
        os.replace(path, doomed)
    except FileNotFoundError:
        return False
    doomed.unlink()
    return True


def trim_cache(max_bytes: int | None = None, keep: Path | None = None) -> list[Path]:
    """Remove least recently used libraries until the cache holds at most ``max_bytes`` (default
    :func:`cache_max_bytes`). ``keep`` and libraries used within ``EVICTION_GRACE_S`` stay.
    Returns the removed paths."""
    max_bytes = cache_max_bytes() if max_bytes is None else max_bytes
    entries = _libraries(cache_dir())
    total = sum(st.st_size for _, st in entries)
    recent = time.time_ns() - int(EVICTION_GRACE_S * 1e9)
    removed = []
    for lib, st in sorted(entries, key=lambda e: e[1].st_atime_ns):
        if total <= max_bytes:
            break
        if lib == keep or st.st_atime_ns > recent:
            continue
        if _remove(lib):
            removed.append(lib)
        total -= st.st_size
    if removed:
        log.info("cache over %.0f MB: removed %d least recently used libraries", max_bytes / 1e6, len(removed))
    return removed


@dataclass(frozen=True)
class CacheInfo:
    """What the cache folder holds."""
    folder: Path
    libraries: int
    size_bytes: int
    max_bytes: int

    def report(self) -> str:
        return (f"cache folder: {self.folder}\n"
                f"libraries: {self.libraries}\n"
                f"size: {self.size_bytes / 1e6:.1f} MB (cap {self.max_bytes / 1e6:.0f} MB, THERMO_DDP_CACHE_MAX_MB)")


def cache_info() -> CacheInfo:
    libraries = _libraries(cache_dir())
    return CacheInfo(cache_dir(), len(libraries), sum(st.st_size for _, st in libraries), cache_max_bytes())


def clear_cache() -> int:
    """Remove every library (and the solvers' index of them) from the cache folder, nothing else;
    returns how many files were removed. Processes that already loaded a library keep running."""
    folder = cache_dir()
    files = [lib for lib, _ in _libraries(folder)] + sorted(folder.glob(_INDEX_GLOB))
    return sum(_remove(path) for path in files)


def _host_tag() -> str:
    """CPU model and instruction-set flags: code built with -march=native runs only there."""
    try:
        lines = Path("/proc/cpuinfo").read_text().splitlines()
    except OSError:
        return platform.machine() + platform.processor()
    return platform.machine() + "".join([ln for ln in lines if ln.startswith(("model name", "flags"))][:2])


def library_path(functions: Mapping[str, ca.Function], flags=DEFAULT_FLAGS,
                 sources: Mapping[str, str] | None = None) -> Path:
    """Where the library for these functions, extra C ``sources`` (file name -> text) and flags is
    (or will be) cached."""
    digest = hashlib.sha256()
    digest.update(ca.__version__.encode())
    digest.update(" ".join(flags).encode())
    digest.update(f"{LARGE_SOURCE_BYTES} {HUGE_SOURCE_BYTES}".encode())
    if any("native" in f for f in flags):
        digest.update(_host_tag().encode())
    for name in sorted(functions):
        digest.update(name.encode())
        digest.update(functions[name].serialize().encode())
    for name, text in sorted((sources or {}).items()):
        digest.update(name.encode())
        digest.update(text.encode())
    prefix = next(iter(functions)) if len(functions) == 1 else "functions"
    return cache_dir() / f"{prefix}_{digest.hexdigest()[:20]}.so"


def compile_library(functions: Mapping[str, ca.Function], flags=DEFAULT_FLAGS,
                    sources: Mapping[str, str] | None = None) -> Path:
    """The cached library holding the functions (C names = their names) and the extra C ``sources``
    (file name -> text, e.g. a driver calling them); built on first use.

    Raises RuntimeError when no C compiler is found (or CasADi cannot generate C for a function),
    CalledProcessError when gcc fails.
    """
    cc = shutil.which(os.environ.get("CC", "gcc"))
    if cc is None:
        raise RuntimeError("code generation needs a C compiler (gcc); none found")
    library = library_path(functions, flags, sources)
    if not use_library(library):
        _build(functions, sources or {}, library, cc, flags)
        trim_cache(keep=library)
    return library


def compile_functions(functions: Mapping[str, ca.Function], flags=DEFAULT_FLAGS) -> dict[str, ca.Function]:
    """The functions as compiled C from one cached library (see :func:`compile_library`)."""
    library = compile_library(functions, flags)
    return {name: ca.external(f.name(), str(library)) for name, f in functions.items()}


def _build(functions: Mapping[str, ca.Function], sources: Mapping[str, str], library: Path, cc: str,
           flags) -> None:
    library.parent.mkdir(parents=True, exist_ok=True)
    with tempfile.TemporaryDirectory(dir=library.parent) as tmp:
        files = [_generate(functions[name], Path(tmp)) for name in sorted(functions)]
        for name, text in sources.items():
            files.append(Path(tmp) / name)
            files[-1].write_text(text)
        log.info("compiling %s (%d C files, %.1f MB) with %s %s", library.name, len(files),
                 sum(f.stat().st_size for f in files) / 1e6, cc, " ".join(flags))
        objects = _compile_objects(files, cc, flags)
        built = Path(tmp) / library.name
        subprocess.run([cc, *flags, "-shared", "-o", str(built), *map(str, objects), "-lm"],
                       check=True, capture_output=True)
        os.replace(built, library)  # atomic: concurrent builders never see half a library


def _generate(fn: ca.Function, folder: Path) -> Path:
    """The C of one function in its own file (its static helpers stay private to that file)."""
    source = f"{fn.name()}.c"
    gen = ca.CodeGenerator(source, {"with_header": False})
    gen.add(fn)
    gen.generate(str(folder) + os.sep)
    return folder / source


def source_flags(size_bytes: int, flags) -> list[str]:
    """The compiler flags for a generated C file of this size: -O1 above LARGE_SOURCE_BYTES, -O0 above
    HUGE_SOURCE_BYTES (in place of the flags' own optimisation level)."""
    if size_bytes <= LARGE_SOURCE_BYTES:
        return list(flags)
    return [f for f in flags if not f.startswith("-O")] + ["-O0" if size_bytes > HUGE_SOURCE_BYTES else "-O1"]


def _compile_objects(files: list[Path], cc: str, flags) -> list[Path]:
    """Compile the C files to position-independent objects, up to cpu_count at once, the longest first."""
    def command(source: Path) -> list[str]:
        return [cc, *source_flags(source.stat().st_size, flags), "-fPIC", "-c", "-o", str(source.with_suffix(".o")),
                str(source)]

    def expected_s(source: Path) -> float:
        level = next((f for f in reversed(command(source)) if f.startswith("-O")), "-O2")
        return source.stat().st_size / 1e6 * _SECONDS_PER_MB.get(level, 15.0)

    def run(source: Path) -> None:
        start = time.perf_counter()
        subprocess.run(command(source), check=True, capture_output=True)
        log.debug("%s (%.1f MB, %s): %.1f s", source.name, source.stat().st_size / 1e6,
                  " ".join(source_flags(source.stat().st_size, flags)), time.perf_counter() - start)

    longest_first = sorted(files, key=expected_s, reverse=True)
    with ThreadPoolExecutor(max_workers=min(len(files), os.cpu_count() or 1)) as pool:
        list(pool.map(run, longest_first))
    return [f.with_suffix(".o") for f in files]


def compiled(fn: ca.Function, flags=DEFAULT_FLAGS) -> ca.Function:
    """One function as compiled C (see :func:`compile_functions`)."""
    return compile_functions({fn.name(): fn}, flags)[fn.name()]
