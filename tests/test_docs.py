"""The documentation site builds with warnings as errors (executing every guide and page), and its
API reference lists every public class and function of marine_envs, estimators and agents."""

from __future__ import annotations

import importlib
import inspect
import os
import pkgutil
import subprocess
import sys
import time
from collections.abc import Iterator
from pathlib import Path
from types import ModuleType

import pytest
from sphinx.util.inventory import InventoryFile

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("marine_envs", "estimators", "agents")
#: A build executes every guide (each budgeted well under a minute); a loaded machine is slower.
BUILD_TIMEOUT = 3600.0


@pytest.fixture(scope="module")
def built_site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The HTML site, built from docs/ as CI builds it: ``-W --keep-going``, fresh directories."""
    out = tmp_path_factory.mktemp("docs")
    env = {**os.environ, "PYTHONPATH": os.pathsep.join(
        [str(ROOT), *filter(None, [os.environ.get("PYTHONPATH")])]), "MPLBACKEND": "Agg"}
    command = [sys.executable, "-m", "sphinx", "-W", "--keep-going", "-q", "-b", "html",
               "-d", str(out / "doctrees"), str(ROOT / "docs"), str(out / "html")]
    start = time.perf_counter()
    done = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True,
                          timeout=BUILD_TIMEOUT)
    seconds = time.perf_counter() - start
    print(f"docs build: {seconds:.0f} s")
    problems = [line for line in done.stderr.splitlines() if "WARNING" in line or "ERROR" in line]
    assert done.returncode == 0, (
        f"the docs build failed (exit {done.returncode}, {seconds:.0f} s):\n"
        + "\n".join(problems or done.stderr.splitlines()[-40:]))
    return out / "html"


def test_the_docs_build_with_warnings_as_errors(built_site: Path) -> None:
    for page in ("index", "getting_started", "cli", "changelog", "environments/usv",
                 "environments/hovercraft", "api/index", "guides/index", "concepts/index",
                 "results/index"):
        assert (built_site / f"{page}.html").is_file(), f"{page}.html was not built"


def _modules(package: str) -> Iterator[ModuleType]:
    """``package`` and every public module below it (no part of the name starts with ``_``)."""
    root = importlib.import_module(package)
    yield root
    for found in pkgutil.walk_packages(root.__path__, f"{package}."):
        if not any(part.startswith("_") for part in found.name.split(".")):
            yield importlib.import_module(found.name)


def _public_names(module: ModuleType) -> list[str]:
    """The module's ``__all__`` if it defines one, else its own classes and functions."""
    if hasattr(module, "__all__"):
        return list(module.__all__)
    return [name for name, value in vars(module).items()
            if not name.startswith("_") and (inspect.isclass(value) or inspect.isfunction(value))
            and value.__module__ == module.__name__]


def _documented_as(module: ModuleType, name: str) -> tuple[str, ...]:
    """Names under which the reference may list ``module.name``: where the module exposes it, or
    where a class or function is defined (a package documents its re-exports there)."""
    value = getattr(module, name)
    names = [f"{module.__name__}.{name}"]
    if inspect.isclass(value) or inspect.isfunction(value):
        names.append(f"{value.__module__}.{value.__qualname__}")
    return tuple(names)


def test_the_api_reference_lists_every_public_class_and_function(built_site: Path) -> None:
    with open(built_site / "objects.inv", "rb") as stream:
        inventory = InventoryFile.load(stream, "", lambda base, uri: uri)
    documented = {name for kind, entries in inventory.items() if kind.startswith("py:")
                  for name in entries}
    missing, checked = [], 0
    for package in PACKAGES:
        for module in _modules(package):
            for name in _public_names(module):
                value = getattr(module, name)
                if not (inspect.isclass(value) or inspect.isfunction(value)):
                    continue  # constants and type aliases: documented where they carry a comment
                checked += 1
                if not documented.intersection(_documented_as(module, name)):
                    missing.append(f"{module.__name__}.{name}")
    assert checked > 500, f"only {checked} public classes and functions found: enumeration broke"
    assert not missing, (f"{len(missing)} of {checked} public classes and functions are not in "
                         "the API reference:\n" + "\n".join(missing))


#: What a figure's record must hold (marine_envs.provenance.run_record).
FIELDS = ("command", "commit", "date", "machine")
#: Folders a local docs build writes (not the project's figures).
BUILT = {"_build", "jupyter_execute", "generated"}


def test_every_figure_of_the_docs_names_the_run_that_made_it() -> None:
    """Each PNG in docs/ (the README's figure among them) carries the command, commit, date and
    machine of its run, written by marine_envs.provenance.save_figure."""
    from marine_envs.provenance import read_figure_provenance

    figures = sorted(path for path in (ROOT / "docs").rglob("*.png")
                     if not BUILT & set(path.relative_to(ROOT).parts))
    assert figures, "no figures found under docs/"
    missing = [f"{path.relative_to(ROOT)}: {sorted(set(FIELDS) - set(record))}"
               for path in figures
               for record in [read_figure_provenance(path)] if not set(FIELDS) <= set(record)]
    assert not missing, "figures without their run's record (regenerate them with the " \
        "script that made them):\n" + "\n".join(missing)

