"""The code blocks of the README and the documentation pages, and how the tests run them.

The convention, visible to a reader in the block itself (docs/contributing.md):
- a ``python`` block is executed; an ``sh`` block's ``thermo-ddp``, ``python`` and ``make plan`` lines are
  run as processes (``make test`` is the suite itself: listed as skipped); blocks in any other language
  (toml, json, text) are shown, not run;
- ``# not tested: <why>`` on a block's first line skips the block, at the end of a line that line;
- ``# needs ../shared/data/<file>`` runs the block or line only when that file is beside the project;
- ``# exits N: <why>`` expects exit status N (1: a run that failed; 2: bad input, one line on stderr), on the
  block's first line for every command, at the end of a line for that one.
Any other command in an ``sh`` block is an error: run by the tests, or marked.
"""
from __future__ import annotations

import dataclasses
import re
import shlex
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SHARED = ROOT.parent / "shared"
RUN_LANGUAGES = {"python": "python", "py": "python", "sh": "sh", "bash": "sh", "shell": "sh"}
FENCE = re.compile(r"^(?P<indent> *)(?P<fence>`{3,}|~{3,})\s*(?P<info>[^`]*)$")
NOT_TESTED = re.compile(r"#\s*not tested:\s*(?P<why>.+)$")
NEEDS = re.compile(r"#\s*needs (?P<path>\.\./shared/\S+)")
EXITS = re.compile(r"#\s*exits (?P<code>\d+)\b")
# Commands that take minutes as written: the tests run them in the slow set, with the settings shortened
# where an option does it; the default run covers them elsewhere (named here).
SLOW = {"loop": "tests/test_loop.py runs the same --short loop", "sweep": "tests/test_sweep_dask.py runs the CLI sweep"}
SHORTER = {"sweep": (("--runs", "2"), ("--short", None))}


@dataclasses.dataclass(frozen=True)
class Block:
    path: Path
    line: int            # 1-based line of the opening fence
    language: str        # "python" or "sh" when run, else the info string's first word
    text: str

    @property
    def id(self) -> str:
        where = self.path.relative_to(ROOT) if self.path.is_relative_to(ROOT) else self.path
        return f"{where}:{self.line}"

    @property
    def first_line(self) -> str:
        return next((ln.strip() for ln in self.text.splitlines() if ln.strip()), "")


@dataclasses.dataclass(frozen=True)
class Command:
    argv: tuple[str, ...]
    expected_exit: int
    line: str


def doc_files() -> list[Path]:
    """The README and every Markdown page of the site (not the build)."""
    pages = sorted(p for p in (ROOT / "docs").rglob("*.md") if "_build" not in p.parts)
    return [ROOT / "README.md", *pages]


def blocks(path: Path) -> list[Block]:
    """Fenced code blocks of a Markdown file, with their language and first line."""
    found, lines, i = [], path.read_text(encoding="utf-8").splitlines(), 0
    while i < len(lines):
        m = FENCE.match(lines[i])
        if not m:
            i += 1
            continue
        fence, indent, start = m["fence"], len(m["indent"]), i
        word = (m["info"].split() or [""])[0]
        body = []
        i += 1
        while i < len(lines) and not (lines[i].strip().startswith(fence) and not lines[i].strip().strip(fence[0])):
            body.append(lines[i][indent:] if not lines[i][:indent].strip() else lines[i].lstrip())
            i += 1
        found.append(Block(path, start + 1, RUN_LANGUAGES.get(word, word), "\n".join(body) + "\n"))
        i += 1
    return found


def run_blocks() -> list[Block]:
    return [b for p in doc_files() for b in blocks(p) if b.language in ("python", "sh")]


def skip_reason(block: Block) -> str | None:
    """Why a whole block is not run here (its first line says so, or it needs a file that is absent)."""
    m = NOT_TESTED.search(block.first_line) if block.first_line.startswith("#") else None
    if m:
        return f"the block says: not tested: {m['why']}"
    m = NEEDS.search(block.first_line) if block.first_line.startswith("#") else None
    if m and not (ROOT / m["path"]).exists():
        return f"needs {m['path']} beside the project"
    return None


def _comment(line: str) -> str:
    """The text after the first unquoted '#' of a shell line ('' without one)."""
    quote = None
    for k, ch in enumerate(line):
        if quote:
            quote = None if ch == quote else quote
        elif ch in "'\"":
            quote = ch
        elif ch == "#" and (k == 0 or line[k - 1].isspace()):
            return line[k:]
    return ""


def shell_lines(text: str) -> list[str]:
    """Logical lines of an sh block (backslash continuations joined), comment lines dropped."""
    joined = re.sub(r"\\\n\s*", " ", text)
    return [ln.strip() for ln in joined.splitlines() if ln.strip() and not ln.strip().startswith("#")]


def makefile_recipe(target: str) -> list[str]:
    """The command lines of a Makefile target, $(VENV)/bin/ removed (the tests run the installed commands)."""
    lines = (ROOT / "Makefile").read_text().splitlines()
    start = lines.index(next(ln for ln in lines if ln.startswith(f"{target}:"))) + 1
    recipe = []
    for ln in lines[start:]:
        if not ln.startswith("\t"):
            break
        recipe.append(ln.strip().replace("$(VENV)/bin/", ""))
    return recipe


def commands(block: Block) -> tuple[list[Command], list[str]]:
    """What an sh block runs, and why lines are skipped; raises ValueError on an unmarked other command."""
    run, skipped = [], []
    first = EXITS.search(block.first_line) if block.first_line.startswith("#") else None
    default = int(first["code"]) if first else 0   # "# exits N: ..." on the first line: every command
    for line in shell_lines(block.text):
        note = _comment(line)
        argv = shlex.split(line, comments=True)
        if (m := NOT_TESTED.search(note)):
            skipped.append(f"{argv[0]} ...: not tested: {m['why']}")
            continue
        if (m := NEEDS.search(note)) and not (ROOT / m["path"]).exists():
            skipped.append(f"{' '.join(argv[:2])} ...: needs {m['path']} beside the project")
            continue
        code = int(m["code"]) if (m := EXITS.search(note)) else default
        if argv[:2] == ["make", "test"]:  # the suite itself: CI runs it (.ci/run)
            skipped.append("make test: the test suite itself, run by CI")
        elif argv[:2] == ["make", "plan"]:
            run += [Command(tuple(shlex.split(r)), code, line) for r in makefile_recipe("plan")]
        elif argv[0] in ("thermo-ddp", "python"):
            run.append(Command(tuple(argv), code, line))
        else:
            raise ValueError(f"{block.id}: '{line}' is neither run by the tests (thermo-ddp, python, make plan, "
                             "make test) nor marked '# not tested: <why>'")
    return run, skipped


def shortened(argv: tuple[str, ...]) -> tuple[str, ...]:
    """The command with the settings of SHORTER applied (an option's value replaced, a flag added)."""
    args = list(argv)
    for option, value in SHORTER.get(args[1] if len(args) > 1 else "", ()):
        if option in args and value is not None:
            args[args.index(option) + 1] = value
        elif option not in args:
            args += [option] + ([value] if value is not None else [])
    return tuple(args)


def slow_reason(block: Block) -> str | None:
    if block.language != "sh":
        return None
    words = {ln.split()[1] for ln in shell_lines(block.text) if ln.startswith("thermo-ddp ") and len(ln.split()) > 1}
    return next((SLOW[w] for w in sorted(words) if w in SLOW), None)
