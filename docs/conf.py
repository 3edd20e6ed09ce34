"""Sphinx configuration of the thermo-ddp documentation site (make docs).

Sphinx because the docstrings are reStructuredText (``literals``, :class:`roles`) and autodoc reads them as
they are; MyST so that the pages, README-style, are Markdown and architecture.md stays one file.
"""
from __future__ import annotations

import sys
from importlib import metadata
from pathlib import Path

sys.path.insert(0, str(Path(__file__).parent / "_ext"))  # the local extension api_coverage (docs only)

project = "thermo-ddp"
author = "thermo-ddp contributors"
copyright = "thermo-ddp contributors, BSD-3-Clause"
release = version = metadata.version("thermo-ddp")

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.viewcode",
    "myst_parser",
    "api_coverage",
]
source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_ext", "Thumbs.db", ".DS_Store"]

# MyST: Markdown pages; links to headings like architecture.md#column-map-toml---columns-maptoml
myst_heading_anchors = 4
myst_enable_extensions = ["colon_fence"]

# autodoc: the reference follows the code. Members of a module with __all__ are exactly those names; a
# settings dataclass shows every field with its default in its signature. Members without a docstring are
# left out: every public class and function has one (tests/test_docs.py).
autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "signature"
autoclass_content = "both"
autodoc_preserve_defaults = True
python_maximum_signature_line_length = 88   # longer signatures: one parameter per line

html_theme = "furo"
html_title = f"thermo-ddp {release}"
html_show_sourcelink = False
