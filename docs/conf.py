"""Sphinx configuration of the mitsuba-veg docs (``make docs`` -> docs/_build/html).

Built inside the project's virtual environment with the real package: importing it selects a
Mitsuba variant and registers the plugins, so nothing is mocked. The API reference, the
command line, the plugin pages, the scenario schema and the performance and validation tables
are generated from the code and from ``benchmarks/results/*.json`` (``_ext/mvdocs.py``); the
gallery's examples run when the docs build (sphinx-gallery).
"""
import os
import sys
from pathlib import Path

DOCS = Path(__file__).resolve().parent
ROOT = DOCS.parent
sys.path.insert(0, str(DOCS / "_ext"))
sys.path.insert(0, str(ROOT))

import mitsuba_veg  # noqa: E402  (selects the variant, registers the plugins)

project = "mitsuba-veg"
author = "the mitsuba-veg authors"
copyright = "the mitsuba-veg authors, BSD-3-Clause"
release = version = mitsuba_veg.__version__

extensions = [
    "myst_parser",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "numpydoc",
    "sphinx_copybutton",
    "sphinx_gallery.gen_gallery",
    "mvdocs",
]

source_suffix = {".rst": "restructuredtext", ".md": "markdown"}
root_doc = "index"
exclude_patterns = ["_build", "_gen", "gallery/*.ipynb", "gallery/*.py", "gallery/*.zip",
                    "gallery/*.md5", "gallery/*.json", "**/sg_execution_times.rst"]
# included fragments are not pages of their own
templates_path = []

# --- MyST ----------------------------------------------------------------------------------
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist", "attrs_inline"]
myst_heading_anchors = 3
suppress_warnings = []

# --- autodoc, autosummary, numpydoc ----------------------------------------------------------
autosummary_generate = False        # the module pages are written by _ext/mvdocs.py
autodoc_member_order = "bysource"
autodoc_typehints = "none"          # the numpydoc sections carry the types and units
autodoc_class_signature = "separated"
numpydoc_show_class_members = False
numpydoc_class_members_toctree = False
numpydoc_xref_param_type = False
numpydoc_validation_checks = set()  # tests/test_docstrings.py checks every public name
add_module_names = False

# --- sphinx-gallery: examples/ run when the docs build, their figures go on the pages ------
sphinx_gallery_conf = {
    "examples_dirs": str(ROOT / "examples"),
    "gallery_dirs": str(DOCS / "gallery"),
    "filename_pattern": r"/plot_",
    "within_subsection_order": "FileNameSortKey",
    "download_all_examples": False,
    "remove_config_comments": True,
    "abort_on_example_error": True,
    "only_warn_on_example_error": False,
    "show_memory": False,
    "min_reported_time": 0,
    "matplotlib_animations": False,
    "image_scrapers": ("matplotlib",),
    "reset_modules": ("matplotlib",),
    "write_computation_times": False,
}

# --- HTML ------------------------------------------------------------------------------------
html_theme = "furo"
html_title = f"mitsuba-veg {release}"
html_static_path = ["_static"]
html_css_files = ["custom.css"]
html_theme_options = {
    "source_repository": "",
    "navigation_with_keys": True,
}
html_show_sourcelink = False
# only package registries are reachable: no remote intersphinx inventories
intersphinx_mapping = {}
copybutton_prompt_text = r"\$ "
copybutton_prompt_is_regexp = True

os.environ.setdefault("MPLBACKEND", "Agg")
