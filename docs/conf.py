"""Sphinx configuration of fusionbench's documentation site: ``sphinx-build -W -b html docs docs/_build/html``."""

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))

project = "fusionbench"
author = "the fusionbench authors"
copyright = "2026, the fusionbench authors"
release = version = "0.2.0"

extensions = [
    "myst_parser",              # the pages are Markdown, readable on a forge as they are
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "numpydoc",                 # the docstrings are numpydoc
]
source_suffix = {".md": "markdown", ".rst": "restructuredtext"}
root_doc = "index"
exclude_patterns = ["_build", "metrics.schema.json"]
myst_heading_anchors = 3        # "[text](page.md#a-heading)" links resolve as on a forge
myst_enable_extensions = ["colon_fence"]

autosummary_generate = True
autodoc_default_options = {"members": True, "member-order": "bysource"}
autodoc_typehints = "none"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False

html_theme = "pydata_sphinx_theme"
html_title = "fusionbench"
html_theme_options = {"navigation_depth": 2, "show_toc_level": 2}
