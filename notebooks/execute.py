"""Re-execute the notebooks in place, in their full configuration and quietly, then check them for leftovers.

    .venv/bin/python notebooks/execute.py                 # every notebooks/*.ipynb (make notebooks)
    .venv/bin/python notebooks/execute.py real_motors.ipynb
    .venv/bin/python notebooks/execute.py --check         # only the check of the saved outputs

Each notebook runs in a fresh kernel with notebooks/ as its folder; the files it writes go to a temporary
folder (THERMO_DDP_NOTEBOOK_OUT), not beside it. Cell timings are not recorded. Prints one line per notebook
and exits 1 when a notebook failed or its outputs carry a leftover (:func:`leftovers`, also run by
tests/test_notebooks_clean.py): a machine path, a Python warning or anything on stderr, a progress bar, a
widget, an error, or a stray value (an expression statement's integer, None or object address).
"""
from __future__ import annotations

import argparse
import json
import os
import re
import sys
import tempfile
import time
from pathlib import Path

HERE = Path(__file__).resolve().parent
MACHINE_PATH = re.compile(r"/work/|/home/|/tmp/|/Users/|/private/var/|[A-Za-z]:\\+Users|site-packages|dist-packages")
WARNING = re.compile(r"\b[A-Z]\w*Warning\b")
PROGRESS_BAR = re.compile(r"\d+%\|.*\||\d+(\.\d+)?(it/s|s/it)\]|\r(?!\n)")
STRAY_VALUE = re.compile(r"^(-?\d+|None|.*\bat 0x[0-9a-f]+>.*)$", re.S)
TEXT_TYPES = ("text/plain", "text/html", "text/markdown", "application/json")
WIDGET = "application/vnd.jupyter.widget-view+json"


def _texts(output: dict) -> list[str]:
    if output.get("output_type") == "stream":
        return ["".join(output.get("text", ""))]
    data = output.get("data", {})
    texts = [data[k] if isinstance(data[k], str) else json.dumps(data[k]) for k in TEXT_TYPES if k in data]
    return ["".join(t) for t in texts]


def _output_leftovers(where: str, output: dict) -> list[str]:
    kind, found = output.get("output_type"), []
    if kind == "error":
        found.append(f"{where}: an error ({output.get('ename')}: {output.get('evalue')})")
    if kind == "stream" and output.get("name") == "stderr":
        found.append(f"{where}: text on stderr ({''.join(output.get('text', '')).strip()[:80]!r})")
    if WIDGET in output.get("data", {}):
        found.append(f"{where}: a widget (a progress bar?)")
    for text in _texts(output):
        for pattern, what in ((MACHINE_PATH, "a machine path"), (WARNING, "a Python warning"),
                              (PROGRESS_BAR, "a progress bar")):
            if (m := pattern.search(text)):
                found.append(f"{where}: {what} ({text[max(0, m.start() - 30):m.end() + 30].strip()!r})")
    plain = "".join(output.get("data", {}).get("text/plain", ""))
    if kind == "execute_result" and STRAY_VALUE.match(plain.strip()):
        found.append(f"{where}: a stray value {plain.strip()[:60]!r} (end the statement with ';' or assign it)")
    return found


def leftovers(nb: dict) -> list[str]:
    """Every leftover in a notebook's saved outputs and metadata, one line each ([] when clean)."""
    found = []
    for k, cell in enumerate(nb.get("cells", [])):
        for output in cell.get("outputs", []):
            found += _output_leftovers(f"cell {k}", output)
    meta = json.dumps(nb.get("metadata", {}))
    if (m := MACHINE_PATH.search(meta)):
        found.append(f"metadata: a machine path ({meta[max(0, m.start() - 30):m.end() + 30]!r})")
    return found


def execute(path: Path, out_dir: Path) -> None:
    """Run ``path`` top to bottom in a fresh kernel and save it in place."""
    import nbformat
    from nbclient import NotebookClient

    os.environ.pop("THERMO_DDP_NOTEBOOK_SHORT", None)        # the full configuration
    os.environ["THERMO_DDP_NOTEBOOK_OUT"] = str(out_dir / path.stem)
    os.environ["TQDM_DISABLE"] = "1"
    nb = nbformat.read(path, as_version=4)
    NotebookClient(nb, timeout=None, kernel_name="python3", record_timing=False,
                   extra_arguments=["--IPKernelApp.log_level=ERROR"],
                   resources={"metadata": {"path": str(path.parent)}}).execute()
    nbformat.validate(nb)
    nbformat.write(nb, path)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("notebooks", nargs="*", help="notebook names in notebooks/ (default: all)")
    parser.add_argument("--check", action="store_true", help="only check the saved outputs for leftovers")
    args = parser.parse_args(argv)
    paths = [HERE / n for n in args.notebooks] or sorted(HERE.glob("*.ipynb"))
    failed = 0
    with tempfile.TemporaryDirectory(prefix="thermo-ddp-notebooks-") as out:
        for path in paths:
            start = time.perf_counter()
            if not args.check:
                try:
                    execute(path, Path(out))
                except Exception as err:  # a failing cell: say which notebook, keep the others going
                    print(f"{path.name}: FAILED ({type(err).__name__}: {str(err).strip().splitlines()[-1][:200]})")
                    failed += 1
                    continue
            found = leftovers(json.loads(path.read_text(encoding="utf-8")))
            ran = "" if args.check else f"executed in {time.perf_counter() - start:.0f} s, "
            print(f"{path.name}: {ran}{'clean' if not found else f'{len(found)} leftover(s)'}")
            for line in found:
                print(f"  {line}")
            failed += bool(found)
    return 1 if failed else 0


if __name__ == "__main__":
    sys.exit(main())
