"""Output files: checked before any work, written atomically only when the run ends.

A run names its outputs up front (``Outputs.check``): a path that is also an input, whose folder
does not exist or cannot be written, that is a folder, or a figure of a format matplotlib cannot
write, is bad input (exit 2) before anything is computed. Results are then staged (``Outputs.text``,
``Outputs.figure``, ``Outputs.temporary`` for a library that writes the file itself) and written
together by ``Outputs.commit``: every file first goes to a temporary file in its own folder, and only
when all are complete are they renamed over their targets, so an interrupted or failed run leaves
every earlier file as it was. A run folder (``thermo-ddp loop --out``) is built beside its target and
swapped in at the end (:func:`check_output_folder`, :func:`write_folder_atomically`).
"""
from __future__ import annotations

import json
import os
import shutil
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
    _check_name(option, out)
    if out.is_dir():
        raise InputError(str(out), option, str(out), "is a folder; expected a file name")
    _check_parent(option, out)
    for source in inputs:
        if _same_file(out, Path(source)):
            raise InputError(str(out), option, str(out), "is also an input; refusing to overwrite it")
    if out.exists() and not out.is_file():
        raise InputError(str(out), option, str(out), "is not a regular file; expected a file name")
    return out


def _check_name(option: str, out: Path) -> None:
    """A path the system accepts (length, characters): stat it once and turn its refusal into one line."""
    try:
        out.exists()
    except (OSError, ValueError) as err:
        raise InputError(str(out)[:80], option, str(out), f"not a usable path ({getattr(err, 'strerror', err)})") from None


def _temporary_beside(target: Path) -> Path:
    """A new empty temporary file in ``target``'s folder (hidden; its name short enough for any target),
    with the permissions a plain new file gets (mkstemp's are owner-only)."""
    fd, tmp = tempfile.mkstemp(prefix=f".{target.name[:40]}.", suffix=target.suffix[:20], dir=target.parent)
    os.fchmod(fd, 0o666 & ~_umask())
    os.close(fd)
    return Path(tmp)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _check_parent(option: str, out: Path) -> None:
    if not out.parent.is_dir():
        raise InputError(str(out), option, str(out.parent), "folder does not exist")
    if not os.access(out.parent, os.W_OK | os.X_OK):
        raise InputError(str(out), option, str(out.parent), "folder is not writable")


def check_figure_path(option: str, path: str | Path, inputs: Iterable[str | Path] = ()) -> Path:
    """:func:`check_output_path` for a figure: its suffix must be a format matplotlib writes."""
    from matplotlib.backend_bases import FigureCanvasBase

    out = check_output_path(option, path, inputs)
    formats = FigureCanvasBase.get_supported_filetypes()
    if out.suffix.lstrip(".").lower() not in formats:
        raise InputError(str(out), option, str(out), f"unknown figure format; name it .{' .'.join(sorted(formats))}")
    return out


def write_atomically(path: str | Path, write: Callable[[Path], None]) -> Path:
    """Call ``write(tmp)`` on a temporary file beside ``path``, then rename it over ``path``."""
    path = Path(path)
    tmp = _temporary_beside(path)
    try:
        write(tmp)
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    return path


def write_text_atomically(path: str | Path, text: str) -> Path:
    return write_atomically(path, lambda tmp: tmp.write_text(text))


RUN_MARKER = ".thermo-ddp-run"  # in every run folder thermo-ddp wrote: only such a folder is replaced


def check_output_folder(option: str, path: str | Path, inputs: Iterable[str | Path] = ()) -> Path:
    """``path`` as a run folder of ``option``: new, empty, or an earlier run of thermo-ddp (its
    :data:`RUN_MARKER`); a file, a folder of other files, or one holding an input is bad input."""
    out = Path(path)
    if str(path).strip() == "":
        raise InputError(option, option, repr(str(path)), "expected a folder name")
    _check_name(option, out)
    if out.exists() and not out.is_dir():
        raise InputError(str(out), option, str(out), "is a file; expected a folder")
    out = out.resolve()
    if out == Path.cwd() or out in Path.cwd().parents:
        raise InputError(str(path), option, str(path), "is the current folder or holds it; name a new folder")
    _check_parent(option, out)
    if out.is_dir() and any(out.iterdir()) and not (out / RUN_MARKER).is_file():
        raise InputError(str(out), option, str(out), "folder is not empty and thermo-ddp did not write it; "
                                                     "name a new or empty folder")
    for source in inputs:
        if out.resolve() in Path(source).resolve().parents:
            raise InputError(str(out), option, str(source), "folder holds an input; refusing to replace it")
    return out


def write_folder_atomically(path: str | Path, write: Callable[[Path], object]) -> object:
    """Call ``write(tmp)`` on a fresh folder beside ``path``; when it returns, the folder (marked with
    :data:`RUN_MARKER`) replaces ``path``. A failed ``write`` leaves ``path`` as it was."""
    path = Path(path)
    tmp = Path(tempfile.mkdtemp(prefix=f".{path.name[:40]}.", dir=path.parent))
    old = None
    try:
        result = write(tmp)
        (tmp / RUN_MARKER).write_text("written by thermo-ddp; the next run into this folder replaces it\n")
        if path.is_dir() and any(path.iterdir()):
            old = Path(tempfile.mkdtemp(prefix=f".{path.name[:40]}.old.", dir=path.parent))
            os.replace(path, old / path.name)
        os.replace(tmp, path)
    except BaseException:
        if old is not None and not path.exists():
            os.replace(old / path.name, path)
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    finally:
        if old is not None:
            shutil.rmtree(old, ignore_errors=True)
    return result


@dataclass
class Outputs:
    """The outputs of one run: checked first, staged while it runs, written together at its end."""

    inputs: tuple[Path, ...] = ()
    paths: dict[str, Path] = field(default_factory=dict)
    _staged: dict[str, Callable[[Path], None]] = field(default_factory=dict)
    _temporaries: list[Path] = field(default_factory=list)

    @classmethod
    def check(cls, outputs: Mapping[str, str | Path | None], inputs: Iterable[str | Path] = (),
              figures: Iterable[str] = ()) -> "Outputs":
        """Validate every named output (``{"--json": path or None, ...}``) against the inputs and each
        other; the options named in ``figures`` must also name a figure format."""
        inputs = tuple(Path(p) for p in inputs)
        run = cls(inputs)
        figures = set(figures)
        for option, path in outputs.items():
            if path is None:
                continue
            check = check_figure_path if option in figures else check_output_path
            run.paths[option] = check(option, path, inputs + tuple(run.paths.values()))
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

    def temporary(self, option: str) -> Path | None:
        """A temporary file beside ``option``'s target for a library that writes the file itself (None
        when the output is not wanted); :meth:`commit` renames it over the target."""
        if option not in self.paths:
            return None
        tmp = _temporary_beside(self.paths[option])
        self._staged[option] = lambda into: os.replace(tmp, into)
        self._temporaries.append(tmp)
        return tmp

    def _stage(self, option: str, write: Callable[[Path], None]) -> None:
        if option in self.paths:
            self._staged[option] = write

    def commit(self) -> list[Path]:
        """Write every staged output: all to temporary files first, then all renamed over their targets
        (a failure while writing any leaves every target untouched; an output left empty, e.g. a figure
        the library did not draw, does not replace its target); returns the paths written."""
        ready: list[tuple[Path, Path]] = []
        try:
            for option, write in self._staged.items():
                target = self.paths[option]
                ready.append((_temporary_beside(target), target))
                write(ready[-1][0])
        except BaseException:
            self.discard(t for t, _ in ready)
            raise
        written = [(tmp, target) for tmp, target in ready if tmp.stat().st_size > 0]  # empty: nothing was made
        for tmp, target in written:
            os.replace(tmp, target)
        self.discard(t for t, _ in ready)
        return [target for _, target in written]

    def discard(self, extra: Iterable[Path] = ()) -> None:
        """Remove the temporary files of this run (a failed or refused run writes nothing)."""
        for tmp in (*self._temporaries, *extra):
            tmp.unlink(missing_ok=True)
        self._temporaries.clear()
