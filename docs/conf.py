"""Sphinx configuration of the marine-envs documentation site.

Build it with ``python -m sphinx -W --keep-going -b html docs docs/_build/html`` (the
``docs`` extra installs what it needs). Guides are MyST notebooks executed at every build:
a guide that fails, a broken link or a missing reference fails the build.
"""

from __future__ import annotations

import importlib
import inspect
import os
import re
import shutil
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT))  # the packages themselves, installed or not
os.environ.setdefault("MPLBACKEND", "Agg")
os.environ.setdefault("MARINE_ENVS_QUIET", "1")  # no first-use compile note in the pages

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
# a cell may display a Markdown table (IPython.display.Markdown), e.g. the environment pages
nb_render_markdown_format = "myst"

# API reference from the docstrings (reST field lists, ``:param x: ... [m]``; no napoleon: it
# would read a "#: unit: text" comment as a type). Each object is documented once, in the module
# that defines it (the template ignores a package's __all__ re-exports).
autosummary_generate = True
autosummary_imported_members = False
# autosummary writes a page per module but never deletes one: a module since moved or split
# (estimators.ekf_compiled) would fail to import and break a -W build in an old checkout
shutil.rmtree(Path(__file__).parent / "api" / "generated", ignore_errors=True)
autodoc_default_options = {"members": True, "show-inheritance": True}
autodoc_member_order = "bysource"
autodoc_typehints = "description"
autodoc_typehints_format = "short"
autoclass_content = "both"
# a method without its own docstring shows none: an inherited one (Gymnasium's Google-style
# ``Env.step``, a base class's text) would describe it in another class's terms
autodoc_inherit_docstrings = False

# Missing references are errors, except names from other projects (no intersphinx: the build
# must work without a network).
nitpicky = True
nitpick_ignore_regex = [
    (r"py:.*", r"(np|numpy|numpy\.typing|npt|gym|gymnasium|torch|scipy|pandas|pd|matplotlib|plt"
               r"|stable_baselines3|sb3_contrib|ray|cvxpy|numba|yaml|rich|tqdm|pyarrow)(\..*)?"),
    # the standard library (its modules, and what they define)
    (r"py:.*", rf"({'|'.join(sorted(sys.stdlib_module_names))})(\..*)?"),
    (r"py:class", r"(Any|Callable|Iterator|Iterable|Mapping|Sequence|Path|PathLike|NDArray"
                  r"|ArrayLike|DTypeLike|Self|Unpack|TypedDict|Literal|Optional|Union|Generator"
                  r"|ndarray|array|float|int|str|bool|None|optional|callable|array_like"
                  r"|FloatArray|IntArray|BoolArray|VectorEnv|Env|Wrapper|ObsType|ActType|Space"
                  r"|array-like|default|shape|.*\(.*)"),
]

html_theme = "furo"
html_title = f"marine-envs {release}"
html_static_path: list[str] = []
html_theme_options = {"navigation_with_keys": True}


# -- The project's docstring conventions, read as reST ---------------------------------------
# Environment classes use Gymnasium's layout (``## Description``, ``## Action Space``, ...): a
# rubric each. ``|x|`` is an absolute value, not a substitution. ``:param a, b: text`` documents
# two parameters at once (reST would take ``a,`` for the type of ``b``).
_HEADING = re.compile(r"^(\s*)## (.+)$")
_ABSOLUTE = re.compile(r"(?<![\w|`\\])\|([^|\s`](?:[^|`]*[^|\s`])?)\|(?![\w|`])")
_SHARED_PARAM = re.compile(r"^(\s*):param (\w+(?:,\s*\w+)+):(.*)$")


def _project_docstring(app, what, name, obj, options, lines: list[str]) -> None:
    converted: list[str] = []
    pending: list[str] = []  # the other names of a shared field, after its continuation lines
    indent = ""
    for line in lines:
        if pending and not (line.startswith(indent + " ") and line.strip()):
            converted += pending
            pending = []
        heading = _HEADING.match(line)
        shared = _SHARED_PARAM.match(line)
        if heading:
            converted += [f"{heading[1]}.. rubric:: {heading[2]}", ""]
        elif shared:
            indent = shared[1]
            first, *others = (n.strip() for n in shared[2].split(","))
            converted.append(f"{indent}:param {first}:{shared[3]}")
            pending = [f"{indent}:param {n}: see ``{first}``." for n in others]
        else:
            converted.append(_ABSOLUTE.sub(r"\\|\1\\|", line))
    lines[:] = converted + pending


# -- References through the project's imports -------------------------------------------------
# A docstring names things as its module (or its package) sees them: ``:class:`Simulator``` in a
# module that imports it, ``:class:`KalmanFilter``` in a package that re-exports it,
# ``:attr:`x0``` of a base class. Each object is documented once, where it is defined; this
# resolves such a name to there. A name of something that exists but has no entry of its own (a
# private helper, a constant without a comment, an instance attribute, another project's object)
# is shown as code, unlinked; a name of nothing at all stays an error.


def _canonical(obj) -> str | None:
    if inspect.ismodule(obj):
        return obj.__name__
    module, qualname = getattr(obj, "__module__", None), getattr(obj, "__qualname__", None)
    return f"{module}.{qualname}" if isinstance(module, str) and isinstance(qualname, str) else None


def _import(name: str):
    try:
        return importlib.import_module(name)
    except ImportError:
        return None


def _scopes(parts: list[str], module: str | None, cls: str | None):
    """Objects in which ``parts`` may be looked up, nearest first, with the parts to look up."""
    if module and _import(module) is not None:
        owner = _import(module)
        for name in cls.split(".") if cls else ():
            owner = getattr(owner, name, None)
        if inspect.isclass(owner):
            yield owner, parts
        packages = module.split(".")
        for i in range(len(packages), 0, -1):  # the module, then its packages
            yield _import(".".join(packages[:i])), parts
    for i in range(len(parts) - 1, 0, -1):  # a dotted path, through a package's re-exports
        scope = _import(".".join(parts[:i]))
        if scope is not None:
            yield scope, parts[i:]


def _instance_attribute(cls: type, name: str) -> bool:
    """Whether instances of ``cls`` carry ``name`` (annotated, a slot, or set as ``self.name``)."""
    if name in getattr(cls, "__annotations__", {}) or name in getattr(cls, "__slots__", ()):
        return True
    try:
        source = inspect.getsource(cls)
    except (OSError, TypeError):
        return False
    return re.search(rf"self\.{re.escape(name)}\b", source) is not None


def _lookup(target: str, module: str | None, cls: str | None) -> tuple[list[str], bool]:
    """Documented names ``target`` may mean, and whether it names an existing object at all."""
    names, exists = [], False
    for scope, parts in _scopes(target.split("."), module, cls):
        parent = scope
        for name in parts[:-1]:
            parent = getattr(parent, name, None)
        if parent is None:
            continue
        owners = inspect.getmro(parent) if inspect.isclass(parent) else (parent,)
        for owner in owners:
            if parts[-1] in vars(owner):
                exists = True
                names += [_canonical(vars(owner)[parts[-1]]), f"{_canonical(owner)}.{parts[-1]}"]
            elif inspect.isclass(owner) and _instance_attribute(owner, parts[-1]):
                exists = True
    return [n for n in names if n], exists


def _resolve_through_imports(app, env, node, contnode):
    if node.get("refdomain") != "py":
        return None
    from sphinx.util.nodes import make_refnode

    objects = env.get_domain("py").objects
    names, exists = _lookup(node["reftarget"].lstrip(".~"), node.get("py:module"),
                            node.get("py:class"))
    for name in names:
        if name in objects:
            entry = objects[name]
            return make_refnode(app.builder, node["refdoc"], entry.docname, entry.node_id,
                                contnode, name)
    return contnode if exists else None


def setup(app):
    app.connect("autodoc-process-docstring", _project_docstring)
    app.connect("missing-reference", _resolve_through_imports)
