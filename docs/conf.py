"""Sphinx configuration of the pneumatic_unload documentation site (``make docs``).

The reference pages (command line, nodes and their parameters, topics and messages, the
JSON output, the library API, the architecture) are generated from the code at each build
by the local extension ``docs/_ext/generated_reference.py`` into ``docs/_generated/``.
"""

from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
# this checkout's package first (not another one installed in editable mode)
sys.path[:0] = [str(ROOT), str(DOCS / "_ext")]

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
html_theme_options = {"description": "sonic conductance from tank discharges (ROS 2)"}
html_sidebars = {"**": ["about.html", "navigation.html", "relations.html", "searchbox.html"]}

# numpy-style docstrings throughout; keep each docstring's own section names
napoleon_google_docstring = False
napoleon_numpy_docstring = True
napoleon_use_rtype = False
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"show-inheritance": True}
