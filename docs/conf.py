"""Sphinx configuration of the marine-envs documentation site.

Build it with ``python -m sphinx -W --keep-going -b html docs docs/_build/html`` (the
``docs`` extra installs what it needs). Guides are MyST notebooks executed at every build:
a guide that fails, a broken link or a missing reference fails the build.
"""

from __future__ import annotations

import os
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the packages themselves, installed or not
os.environ.setdefault("MPLBACKEND", "Agg")

import marine_envs  # noqa: E402

project = "marine-envs"
author = "The marine-envs developers"
copyright = "2026, The marine-envs developers"
release = marine_envs.__version__
version = release

extensions = [
    "myst_nb",
    "sphinx.ext.autodoc",
    "sphinx.ext.autosummary",
    "sphinx.ext.napoleon",
    "sphinx.ext.mathjax",
    "sphinx.ext.viewcode",
    "sphinx_copybutton",
]

source_suffix = {".rst": "restructuredtext", ".md": "myst-nb", ".ipynb": "myst-nb"}
root_doc = "index"
exclude_patterns = ["_build", "Thumbs.db", ".DS_Store", "**/.ipynb_checkpoints", "jupyter_execute"]
templates_path = ["_templates"]

# MyST: $math$, definition lists, ::: fences, heading anchors for [links](page.md#anchor)
myst_enable_extensions = ["dollarmath", "amsmath", "colon_fence", "deflist", "substitution"]
myst_heading_anchors = 3

# every guide runs at every build (a guide that raises fails the build)
nb_execution_mode = "force"
nb_execution_timeout = 600
nb_execution_raise_on_error = True
nb_execution_show_tb = True
nb_merge_streams = True

# API reference from the docstrings
autosummary_generate = True
autosummary_imported_members = False
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_format = "short"
autoclass_content = "both"
napoleon_google_docstring = True
napoleon_numpy_docstring = True

# Missing references are errors, except names from other projects (no intersphinx: the build
# must work without a network).
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(np|numpy|numpy\.typing|npt|gym|gymnasium|torch|scipy|pandas|pd|matplotlib|plt"
               r"|stable_baselines3|sb3_contrib|ray|cvxpy|numba|yaml|rich|tqdm|pyarrow)(\..*)?"),
    (r"py:.*", r"(typing|collections|collections\.abc|pathlib|os|io|dataclasses|enum|abc|types"
               r"|argparse|contextlib|concurrent|threading|signal)\..*"),
    (r"py:class", r"(Any|Callable|Iterator|Iterable|Mapping|Sequence|Path|PathLike|NDArray"
                  r"|ArrayLike|DTypeLike|Self|Unpack|TypedDict|Literal|Optional|Union|Generator"
                  r"|ndarray|array|float|int|str|bool|None|optional|callable|array_like"
                  r"|array-like|default|shape|.*\(.*)"),
]

html_theme = "furo"
html_title = f"marine-envs {release}"
html_static_path: list[str] = []
html_theme_options = {"navigation_with_keys": True}
