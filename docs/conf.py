"""Sphinx configuration of specguard's documentation (MyST Markdown pages, the furo theme).

Build it from the repository root, strictly (every warning an error), then run the pages' examples:

    sphinx-build -W --keep-going -b html docs docs/_build/html
    sphinx-build -W --keep-going -b doctest docs docs/_build/doctest
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from sphinx.application import Sphinx

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "plugins")]  # the checkout's specguard and plugins, installed or not

from specguard.version import __version__  # noqa: E402

project = "specguard"
author = "the specguard authors"
copyright = "the specguard authors"
release = version = __version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.doctest",
    "sphinx.ext.viewcode",
]

source_suffix = {".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build"]

# MyST: headings get GitHub's anchors, so that `page.md#a-heading` works on GitHub and in the site alike.
myst_heading_anchors = 3
myst_enable_extensions = ["colon_fence"]

# autodoc over the public API; docstrings are Google style (napoleon), with type hints in the signatures.
autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "signature"
autodoc_preserve_defaults = True
napoleon_google_docstring = True
napoleon_numpy_docstring = False
napoleon_custom_sections = [("Class attributes", "Attributes")]  # a section of this code base's docstrings

# The doctest builder runs the pages' {doctest} and {testcode} blocks. The docstrings' own examples are
# pytest's (--doctest-modules in every test run), so they are not run a second time here.
doctest_test_doctest_blocks = ""

html_theme = "furo"
html_title = f"specguard {release}"


def _skip_namedtuple_fields(app: Sphinx, what: str, name: str, obj: Any, skip: bool, options: Any) -> bool:
    """Leave out the ``Alias for field number N`` entries of NamedTuple fields.

    The classes document their fields in an ``Attributes:`` section; the generated
    aliases would describe the same names a second time (a duplicate-object warning).
    """
    return skip or (what == "class" and (getattr(obj, "__doc__", None) or "").startswith("Alias for field number"))


def setup(app: Sphinx) -> None:
    app.connect("autodoc-skip-member", _skip_namedtuple_fields)
