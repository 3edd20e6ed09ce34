"""Output files: checked before any work, written atomically only when the run ends.

A run names its outputs up front (``Outputs.check``): a path that is also an input, whose folder
does not exist, or that is a folder, is bad input (exit 2) before anything is computed. Results
are then staged (``Outputs.text``, ``Outputs.figure``) and written together by ``Outputs.commit``:
each file goes to a temporary file in its own folder and is renamed over the target, so an
interrupted or failed run leaves every earlier file as it was.
"""
from __future__ import annotations

import json
import os
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterable, Mapping

from .errors import InputError


def _same_file(a: Path, b: Path) -> bool:
    if a.resolve() == b.resolve():
        return True
    try:
        return a.exists() and b.exists() and os.path.samefile(a, b)
    except OSError:
        return False


def check_output_path(option: str, path: str | Path, inputs: Iterable[str | Path] = ()) -> Path:
    """``path`` as a writable output of ``option``, or InputError (one line) naming why not."""
    out = Path(path)
    if str(path).strip() == "":
        raise InputError(option, option, repr(str(path)), "expected a file name")
    if out.is_dir():
        raise InputError(str(out), option, str(out), "is a folder; expected a file name")
    if not out.parent.is_dir():
        raise InputError(str(out), option, str(out.parent), "folder does not exist")
    for source in inputs:
        if _same_file(out, Path(source)):
            raise InputError(str(out), option, str(out), "is also an input; refusing to overwrite it")
    return out


def write_atomically(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it over ``path``."""
    path = Path(path)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=path.suffix, dir=path.parent)
    os.close(fd)
    try:
        write(Path(tmp))
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_text_atomically(path: str | Path, text: str) -> Path:
    return write_atomically(path, lambda tmp: tmp.write_text(text))


@dataclass
class Outputs:
    """The outputs of one run: checked first, staged while it runs, written together at its end."""

    inputs: tuple[Path, ...] = ()
    paths: dict[str, Path] = field(default_factory=dict)
    _staged: dict[str, Callable[[Path], None]] = field(default_factory=dict)

    @classmethod
    def check(cls, outputs: Mapping[str, str | Path | None], inputs: Iterable[str | Path] = ()) -> "Outputs":
        """Validate every named output (``{"--json": path or None, ...}``) against the inputs and each other."""
        inputs = tuple(Path(p) for p in inputs)
        run = cls(inputs)
        for option, path in outputs.items():
            if path is None:
                continue
            out = check_output_path(option, path, inputs + tuple(run.paths.values()))
            run.paths[option] = out
        return run

    def wanted(self, option: str) -> bool:
        return option in self.paths

    def text(self, option: str, text: str) -> None:
        self._stage(option, lambda tmp: tmp.write_text(text))

    def json(self, option: str, data: Mapping) -> None:
        self.text(option, json.dumps(data, indent=2, allow_nan=False) + "\n")

    def figure(self, option: str, draw: Callable[[Path], object]) -> None:
        """``draw(path)`` writes the figure; it runs at commit time, on the temporary file."""
        self._stage(option, draw)

    def _stage(self, option: str, write: Callable[[Path], None]) -> None:
        if option in self.paths:
            self._staged[option] = write

    def commit(self) -> list[Path]:
        """Write every staged output (each atomically); returns the paths written."""
        return [write_atomically(self.paths[option], write) for option, write in self._staged.items()]
