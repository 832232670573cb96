"""Sphinx configuration of the pneumatic_unload documentation site (``make docs``).

The reference pages (command line, nodes and their parameters, topics and messages, the
JSON output, the library API, the architecture) are generated from the code at each build
by the local extension ``docs/_ext/generated_reference.py`` into ``docs/_generated/``.
"""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

from sphinx.application import Sphinx
from sphinx.ext.napoleon.docstring import GoogleDocstring

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
# this checkout's package first (not another one installed in editable mode)
sys.path[:0] = [str(ROOT / "pneumatic_unload"), str(DOCS / "_ext")]

project = "pneumatic_unload"
author = "pneumatic_unload maintainers"
copyright = "pneumatic_unload maintainers, Apache-2.0"
release = "0.1.0"

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.napoleon",
    "sphinx.ext.viewcode",
    "generated_reference",
]
exclude_patterns = ["_build"]
# option names and help texts as the command prints them ('--x', not an en dash and quotes)
smartquotes = False
html_theme = "alabaster"
html_theme_options = {"description": "sonic conductance from tank discharges (ROS 2)",
                      "page_width": "1240px", "sidebar_width": "240px"}
html_sidebars = {"**": ["about.html", "navigation.html", "relations.html", "searchbox.html"]}
# docs/_static/wrap.css: long commands wrap instead of scrolling out of sight
html_static_path = ["_static"]
html_css_files = ["wrap.css"]

# numpy-style docstrings; Google style ("Args:") only in pneumatic_unload.io (see setup:
# elsewhere a "Parameters:" paragraph, as in the node modules' docstrings, is plain text)
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
autodoc_member_order = "bysource"
autodoc_typehints = "description"



def _google_style_in_io(app: Sphinx, what: str, name: str, obj: Any, options: Any,
                        lines: list[str]) -> None:
    """The Google-style docstrings of pneumatic_unload.io ("Args:", "Returns:",
    "Raises:") as reST, the way napoleon converts them."""
    if name == "pneumatic_unload.io" or name.startswith("pneumatic_unload.io."):
        lines[:] = GoogleDocstring(lines, app.config, app, what, name, obj, options).lines()


def setup(app: Sphinx) -> None:
    """Connect the io docstrings' converter (before napoleon's numpy-style pass)."""
    app.connect("autodoc-process-docstring", _google_style_in_io, priority=400)
