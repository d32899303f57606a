"""Sphinx configuration of the sb3-genrl documentation (built offline, warnings as errors in the test suite)."""

from importlib import metadata

project = "sb3-genrl"
author = "the sb3-genrl authors"
copyright = "2026, the sb3-genrl authors"
try:
    release = metadata.version("sb3-genrl")
except metadata.PackageNotFoundError:  # a source tree that is not installed
    release = "0.0.0+unknown"
version = release

extensions = ["sphinx.ext.autodoc", "myst_parser"]
source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
# the study's tables and comparison are shown inside its reports
exclude_patterns = ["_build", "study/*/tables/*", "study/*/comparison/*.md"]
myst_heading_anchors = 3
myst_enable_extensions = ["dollarmath"]

autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_default_options = {"show-inheritance": True}

html_theme = "sphinx_rtd_theme"
html_title = f"sb3-genrl {release}"
html_static_path: list[str] = []
