"""The documentation keeps its promises: every code block of the README and the site runs as written (the
convention for the few that do not is in tests/_doc_blocks.py and docs/contributing.md), every relative link
resolves, the site builds with no warning, and its API reference covers every public name."""
from __future__ import annotations

import importlib
import inspect
import re
import shutil
import subprocess
import sys
import zlib
from pathlib import Path

import pytest

import _doc_blocks as docs
from _doc_blocks import ROOT

BIN = Path(sys.executable).parent
COPIED = ("data", "models", "examples")   # what the examples read, copied: an example never writes into the clone
LINK = re.compile(r"(?<!!)\[[^\]]*\]\((?P<target>[^)\s]+)\)|!\[[^\]]*\]\((?P<image>[^)\s]+)\)")


def _public_names() -> list[str]:
    """The names the API reference must cover, from their one home (the site's build check)."""
    sys.path.insert(0, str(ROOT / "docs" / "_ext"))
    try:
        return importlib.import_module("api_coverage").public_names()
    finally:
        sys.path.pop(0)


def _param(block: docs.Block):
    marks = [pytest.mark.slow] if docs.slow_reason(block) else []
    return pytest.param(block, id=block.id, marks=marks)


@pytest.fixture(scope="module")
def clone(tmp_path_factory) -> Path:
    """A folder with copies of data/, models/ and examples/, as a clone has them, and ../shared beside it
    when the project has one (read only: the examples that need it read recordings from it). The blocks
    share it, as a reader's clone would be shared by the pages' examples."""
    top = tmp_path_factory.mktemp("docs")
    for name in COPIED:
        shutil.copytree(ROOT / name, top / "clone" / name)
    if docs.SHARED.is_dir():
        (top / "shared").symlink_to(docs.SHARED, target_is_directory=True)
    return top / "clone"


@pytest.fixture
def workspace(clone, monkeypatch) -> Path:
    monkeypatch.chdir(clone)
    return clone


_RAN: set[tuple] = set()  # commands that already ran as written in the shared clone (pages repeat some)


def test_there_are_blocks_to_run():
    languages = [b.language for b in docs.run_blocks()]
    assert languages.count("python") >= 8 and languages.count("sh") >= 8, languages


@pytest.mark.parametrize("block", [_param(b) for b in docs.run_blocks()])
def test_code_block_runs_as_written(block, workspace):
    if (why := docs.skip_reason(block)):
        pytest.skip(why)
    if block.language == "python":
        exec(compile(block.text, block.id, "exec"), {"__name__": "__docs__"})
        return
    commands, skipped = docs.commands(block)
    if not commands:
        pytest.skip("; ".join(skipped))
    for cmd in commands:
        argv = docs.shortened(cmd.argv)
        if (argv, cmd.expected_exit) in _RAN:
            continue
        exe = sys.executable if argv[0] == "python" else str(BIN / argv[0])
        done = subprocess.run([exe, *argv[1:]], cwd=workspace, capture_output=True, text=True, timeout=900)
        where = f"{block.id}: {' '.join(argv)}\nstdout:\n{done.stdout[-3000:]}\nstderr:\n{done.stderr[-3000:]}"
        assert done.returncode == cmd.expected_exit, where
        assert "Traceback" not in done.stderr, where
        if cmd.expected_exit == 2:
            assert len(done.stderr.strip().splitlines()) == 1, where  # bad input: one line
        _RAN.add((argv, cmd.expected_exit))


def test_an_unmarked_command_is_an_error(tmp_path):
    page = tmp_path / "page.md"
    page.write_text("```sh\nrm -rf build   # cleans\nthermo-ddp cache --info\n```\n```sh\n# not tested: a "
                    "cluster\ndask scheduler\n```\n```sh\ndask worker x   # not tested: a cluster\n```\n")
    unmarked, block_marked, line_marked = docs.blocks(page)
    with pytest.raises(ValueError, match="rm -rf build"):
        docs.commands(unmarked)
    assert "a cluster" in docs.skip_reason(block_marked)
    assert docs.commands(line_marked) == ([], ["dask ...: not tested: a cluster"])


def test_make_plan_runs_the_makefile_recipe():
    block = docs.Block(ROOT / "README.md", 1, "sh", "make plan   # the lift\n")
    (cmd,), _ = docs.commands(block)
    assert cmd.argv[:2] == ("thermo-ddp", "compare")


def test_short_settings_replace_and_add():
    assert docs.shortened(("thermo-ddp", "sweep", "--runs", "200", "--seed", "0")) == (
        "thermo-ddp", "sweep", "--runs", "2", "--seed", "0", "--short")
    assert docs.shortened(("thermo-ddp", "plan", "--hold-s", "30")) == ("thermo-ddp", "plan", "--hold-s", "30")


def test_code_lines_fit_the_page():
    """The site shows 80 characters of a code line without scrolling."""
    long = [f"{b.id}: {ln}" for b in docs.run_blocks() for ln in b.text.splitlines() if len(ln) > 80]
    assert not long, "\n".join(long)


@pytest.mark.parametrize("page", docs.doc_files(), ids=lambda p: str(p.relative_to(ROOT)))
def test_relative_links_resolve(page):
    text = re.sub(r"```.*?```", "", page.read_text(encoding="utf-8"), flags=re.S)
    for m in LINK.finditer(text):
        target = (m["target"] or m["image"]).split("#")[0]
        if not target or re.match(r"^[a-z]+:", target):
            continue
        assert (page.parent / target).exists(), f"{page.relative_to(ROOT)}: link to {target}, which does not exist"


def test_public_names_have_docstrings():
    """What the API reference shows of a class or function is its docstring: each has its own."""
    missing = []
    for name in _public_names():
        module, _, attr = name.rpartition(".")
        obj = getattr(importlib.import_module(module), attr)
        if not (inspect.isclass(obj) or inspect.isfunction(obj)):
            continue
        doc = inspect.getdoc(obj) or ""
        if not doc or doc.startswith(f"{obj.__name__}("):   # a dataclass without one gets its signature
            missing.append(name)
    assert not missing, f"public names without a docstring: {missing}"


def _inventory(path: Path) -> set[str]:
    """The Python objects of a Sphinx objects.inv (4 header lines, then zlib-compressed 'name domain:role ...')."""
    raw = path.read_bytes()
    body = zlib.decompress(raw.split(b"\n", 4)[4]).decode()
    return {line.split(" ", 1)[0] for line in body.splitlines() if " py:" in line}


@pytest.fixture(scope="module")
def built_site(tmp_path_factory) -> Path:
    pytest.importorskip("sphinx", reason="needs the docs extra: make docs installs it")
    out = tmp_path_factory.mktemp("site")
    done = subprocess.run([sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
                           str(ROOT / "docs"), str(out)], capture_output=True, text=True, timeout=900)
    assert done.returncode == 0 and not done.stderr.strip(), done.stderr
    return out


def test_site_builds_without_warnings_and_covers_every_public_name(built_site):
    names = _public_names()
    documented = _inventory(built_site / "objects.inv")
    import thermo_ddp
    assert {f"thermo_ddp.{n}" for n in thermo_ddp.__all__} <= set(names)
    assert not [n for n in names if n not in documented]
    assert {"thermo_ddp.solvers.DDPSolver.solve", "thermo_ddp.ocp.OptimalControlProblem"} <= documented
    for page in ("getting-started", "guide/planning", "guide/recordings", "guide/identify-diagnose",
                 "guide/real-motors", "guide/mpc-sweeps", "guide/bad-input", "guide/outputs", "architecture",
                 "benchmarks", "api/thermo_ddp", "api/ocp", "api/solvers"):
        assert (built_site / f"{page}.html").is_file(), page
