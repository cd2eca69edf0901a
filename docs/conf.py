"""Sphinx configuration of the lcc_synth documentation.

Build (after ``pip install -e ".[docs]"``), from the repository root::

    sphinx-build -W --keep-going -b html docs docs/_build/html

Generated sources (problem-file reference, CLI reference, API pages) are written to
``docs/_generated`` and the gallery to ``docs/gallery`` (both git-ignored) by
``docs/_ext/lcc_docs.py``; the examples write their files under ``docs/_build/gallery-out``.
No extension fetches anything from the internet (no intersphinx, no link check).
"""

from __future__ import annotations

import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(DOCS.parent))

import lcc_docs  # noqa: E402

import lcc_synth  # noqa: E402

lcc_docs.generate()
lcc_docs.allow_exit_zero()

project = "lcc_synth"
author = "lcc_synth contributors"
copyright = "2026, lcc_synth contributors"
release = version = lcc_synth.__version__

extensions = [
    "sphinx.ext.autodoc",
    "sphinx.ext.mathjax",
    "numpydoc",
    "myst_parser",
    "sphinx_gallery.gen_gallery",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
exclude_patterns = [
    "_build",
    "README.md",
    "gallery/*.ipynb",
    "gallery/*.py",
    "gallery/*.zip",
    "gallery/*.md5",
    "gallery/*.json",
]
root_doc = "index"
smartquotes = False  # keep "--out" and "it's" as written (CLI flags, code in prose)
nitpicky = True  # with -W: every unresolved cross-reference fails the build
# other packages' objects (no intersphinx: the build fetches nothing from the internet)
nitpick_ignore_regex = [
    (
        r"py:.*",
        r"(numpy|scipy|control|cvxpy|casadi|osqp|rerun|dask|"
        r"distributed|matplotlib|mpmath|numba|tomllib)(\..*)?",
    )
]

# -- autodoc / numpydoc -------------------------------------------------------------------------
autodoc_default_options = {"member-order": "bysource"}
autodoc_typehints = "none"  # numpydoc's Parameters sections carry the types
autodoc_mock_imports: list[str] = []
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False

# -- MyST ----------------------------------------------------------------------------------------
myst_enable_extensions = ["colon_fence", "deflist", "dollarmath"]
myst_heading_anchors = 3

# -- sphinx-gallery ------------------------------------------------------------------------------
sphinx_gallery_conf = {
    "examples_dirs": str(DOCS.parent / "examples"),
    "gallery_dirs": "gallery",
    "filename_pattern": r".*\.py$",  # run every example at build time
    "reset_argv": "lcc_docs.reset_argv",
    "image_scrapers": ("lcc_docs.png_scraper",),
    "within_subsection_order": "FileNameSortKey",
    "abort_on_example_error": True,
    "download_all_examples": False,
    "capture_repr": (),
    "show_memory": False,
    "remove_config_comments": True,
}

# -- HTML ----------------------------------------------------------------------------------------
html_theme = "pydata_sphinx_theme"
html_title = "lcc_synth"
html_static_path = ["_static"]
html_css_files = ["lcc.css"]
# the left sidebar lists a section's pages: only the API reference and the gallery have sections
html_sidebars = {"index": [], "guide/*": [], "_generated/*": []}
html_theme_options = {
    "navigation_depth": 3,
    "show_toc_level": 2,
    "navbar_align": "left",
    "secondary_sidebar_items": ["page-toc"],
}
html_show_sourcelink = False


def setup(app):
    """Docstring hooks of ``docs/_ext/lcc_docs.py``."""
    app.connect("autodoc-process-docstring", lcc_docs.escape_bars)
    app.connect("missing-reference", lcc_docs.resolve_short_names)
