"""What every ``marine`` command shares: argument types, options, checks before any work.

The argument types; the shared options, one parent parser each (:data:`DEBUG`, :data:`SEED`,
:data:`JSON`, :data:`FORCE`, :data:`ENV_KWARGS`, :data:`QUIET`; by destination :data:`SHARED`),
which a command takes in its own words (:class:`Parser`'s ``option_help``); the checks of its
outputs and inputs before any work; and the :class:`Parser` that reports a mistake on one line.
"""

from __future__ import annotations

import argparse
import contextlib
import importlib.util
import json
import math
import os
import warnings
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any, NoReturn

#: Exit codes: a user mistake (argparse's own), and Ctrl-C (128 + SIGINT, the shell's convention).
EXIT_USAGE, EXIT_INTERRUPTED = 2, 130
#: A signal stopped the command: this plus the signal's number (the shell's convention).
EXIT_SIGNAL = 128
#: Exceptions that report a mistake in what was asked (a value, a file, a missing extra), not a
#: bug: one line, exit 2. Anything else keeps its traceback.
USER_ERRORS = (ValueError, OSError, ImportError)
#: Figure formats the commands write (matplotlib's raster and vector formats).
PLOT_SUFFIXES = (".png", ".pdf", ".svg", ".jpg", ".jpeg", ".eps", ".ps", ".tif", ".tiff",
                 ".webp")
#: Estimators that need an optional dependency: name -> (module, extra).
ESTIMATOR_EXTRAS = {"pd": ("cvxpy", "estimators")}

def argument_type(convert: Callable[[str], Any], check: Callable[[Any], bool], what: str
                  ) -> Callable[[str], Any]:
    """An argparse ``type``: ``convert`` the text, then require ``check``; else argparse's own
    one-line error naming the option and ``what`` it must be."""
    def parse(text: str) -> Any:
        try:
            value = convert(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"{text!r} is invalid: {what}") from None
        if not check(value):
            raise argparse.ArgumentTypeError(f"{text} is invalid: {what}")
        return value
    return parse


positive_int = argument_type(int, lambda v: v >= 1, "an integer >= 1")
seed_int = argument_type(int, lambda v: v >= 0, "an integer >= 0")
positive_float = argument_type(float, lambda v: math.isfinite(v) and v > 0,
                               "a finite number > 0")
finite_float = argument_type(float, math.isfinite, "a finite number")
fraction = argument_type(float, lambda v: math.isfinite(v) and 0 < v <= 1,
                         "a fraction in (0, 1]")


def env_id(text: str) -> str:
    """An argparse ``type``: a registered marine environment id; ``USV-v0`` and ``usv`` name
    ``marine_envs/USV-v0``."""
    from marine_envs import ENVIRONMENTS

    aliases = {}
    for full in ENVIRONMENTS:
        short = full.split("/")[1]
        aliases.update({short.lower(): full, short.removesuffix("-v0").lower(): full})
    found = text if text in ENVIRONMENTS else aliases.get(text.lower().removeprefix(
        "marine_envs/"))
    if found is None:
        raise argparse.ArgumentTypeError(f"{text!r} is not a marine environment: one of "
                                         f"{', '.join(ENVIRONMENTS)}")
    return found


def json_object(text: str) -> dict[str, Any]:
    """An argparse ``type``: a JSON object."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise argparse.ArgumentTypeError(f"{text!r} is not valid JSON: {error}") from None
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: a JSON object, e.g. "
                                         '\'{"hs": 3.0}\'')
    return value


def policy_name(text: str) -> str:
    """An argparse ``type``: a policy's name (:mod:`agents.policies`), an old one replaced by
    the policy's one name (with a warning); the command's ``choices`` then check it."""
    from ..policies import ALIASES, canonical

    return canonical(text) if text in ALIASES else text


def output_file(path: str | None, force: bool, option: str,
                suffixes: Sequence[str] | None = None, companions: Sequence[Path] = (),
                creates: Path | None = None) -> Path | None:
    """``path``, a file the command will write, checked before any work: a known suffix, an
    existing writable folder (or ``creates``, an output folder the command makes, or one in
    it), not a folder itself; an existing file (or one of its ``companions``, e.g. a CSV's
    sidecar) is refused unless ``force``.

    :raises ValueError: a bad suffix or folder.  :raises FileExistsError: it exists.
    """
    if path is None:
        return None
    out = Path(path)
    if out.exists() and not (out.is_file() or out.is_dir()):
        return out  # a device or a pipe (/dev/stdout): written through, never replaced
    if suffixes is not None and out.suffix.lower() not in suffixes:
        raise ValueError(f"{option} {path}: unknown format {out.suffix or '(no suffix)'!r}: "
                         f"one of {', '.join(suffixes)}")
    folder = out.parent
    made = creates is not None and Path(creates).resolve() in (folder.resolve(),
                                                               *folder.resolve().parents)
    if not folder.is_dir() and not made:
        raise ValueError(f"{option} {path}: the folder {folder} does not exist")
    if folder.is_dir() and not os.access(folder, os.W_OK | os.X_OK):
        raise ValueError(f"{option} {path}: the folder {folder} is not writable")
    if out.is_dir():
        raise ValueError(f"{option} {path} is a folder, not a file")
    existing = [str(p) for p in (out, *companions) if p.exists()]
    if existing == [str(out)] and not force:
        raise FileExistsError(f"{option} {path} exists: use --force to replace it")
    if existing and not force:
        raise FileExistsError(f"{option} {path}: {' and '.join(existing)} exist: use --force "
                              "to replace them")
    return out


def output_dir(path: str, force: bool, option: str, owned: Callable[[Path], list[str]],
               hint: str = "") -> Path:
    """``path``, a folder the command will write into (created when work starts), checked
    before any work: not a file, under a writable folder; one that already holds what the
    command writes (``owned``) is refused unless ``force`` (which clears it when work
    starts), so that two runs never mix.

    :raises ValueError: not a folder, or not writable.  :raises FileExistsError: owned files.
    """
    out = Path(path)
    if out.exists() and not out.is_dir():
        raise ValueError(f"{option} {path} is a file, not a folder")
    ancestor = next(p for p in (out, *out.parents) if p.exists())
    if not (ancestor.is_dir() and os.access(ancestor, os.W_OK | os.X_OK)):
        raise ValueError(f"{option} {path}: {ancestor} is not a writable folder")
    held = owned(out) if out.is_dir() else []
    if held and not force:
        raise FileExistsError(f"{option} {path} already holds {', '.join(held)}{hint}: use "
                              "--force to replace them")
    return out


def check_estimator(name: str | None, option: str = "--estimator") -> None:
    """:raises ImportError: ``name`` needs an extra that is not installed (before any work)."""
    if name in ESTIMATOR_EXTRAS:
        module, extra = ESTIMATOR_EXTRAS[name]
        if importlib.util.find_spec(module) is None:
            raise ImportError(f"{option} {name} needs {module}: pip install "
                              f"\"marine-envs[{extra}]\"")


def check_env(env: str, kwargs: Mapping[str, Any]) -> None:
    """Build ``env`` with ``kwargs`` once, so that an argument it refuses (or does not know)
    is reported before any work; its plausibility warnings come with the real run."""
    import gymnasium as gym

    import marine_envs  # noqa: F401  (registers the environments)
    from marine_envs.plausibility import PlausibilityWarning

    with warnings.catch_warnings():
        warnings.simplefilter("ignore", PlausibilityWarning)
        try:
            gym.make(env, **kwargs).close()
        except TypeError as error:  # an argument the environment does not take
            raise ValueError(f"--env-kwargs: {error}") from None


def plot_path(path: str | None, force: bool, option: str = "--plot") -> Path | None:
    return output_file(path, force, option, PLOT_SUFFIXES)


def distinct(*outputs: tuple[str, Path | None]) -> None:
    """Refuse two outputs of one command on the same file (the second would overwrite the
    first): ``outputs`` are ``(option, path)``; devices and pipes are shared freely.

    :raises ValueError: naming both options.
    """
    seen: dict[str, str] = {}
    for option, path in outputs:
        if path is None or (path.exists() and not path.is_file()):
            continue
        key = os.path.realpath(path)
        if key in seen and seen[key] != option:
            raise ValueError(f"{seen[key]} and {option} name the same file {path}: give each "
                             "its own")
        seen.setdefault(key, option)


def write_json_output(path: Path | None, document: Any) -> None:
    from marine_envs.files import write_json

    if path is not None:
        write_json(path, document, default=float)


@contextlib.contextmanager
def progress_bar(total: int, description: str, show: bool) -> Iterator[Any]:
    """A tqdm bar (None when not ``show``), closed whatever happens."""
    if not show:
        yield None
        return
    from tqdm import tqdm

    bar = tqdm(total=total, desc=description, dynamic_ncols=True)
    try:
        yield bar
    finally:
        bar.close()


# -- the parser and the shared options -----------------------------------------------------------
class Parser(argparse.ArgumentParser):
    """argparse, with a mistake reported on one line, ``marine CMD: error: ...`` (exit 2).

    :param option_help: the shared options' help worded for this command, by destination (e.g.
        ``{"seed": "episode seed (0)"}``): one option, one meaning, said in the command's terms.
    """

    def __init__(self, *args: Any, option_help: Mapping[str, str] | None = None,
                 **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        wording = dict(option_help or {})
        unknown = sorted(set(wording) - set(SHARED))
        if unknown:
            raise ValueError(f"option_help words {unknown}: only the shared options "
                             f"{', '.join(SHARED)} take a command's wording")
        if wording:
            self.formatter_class = _worded(self.formatter_class, wording)

    def error(self, message: str) -> NoReturn:
        self.exit(EXIT_USAGE, f"{self.prog}: error: {message} (see {self.prog} --help)\n")


def _worded(formatter: type[argparse.HelpFormatter], wording: Mapping[str, str]
            ) -> type[argparse.HelpFormatter]:
    """``formatter``, showing a shared option's help in the command's ``wording`` (the hook
    argparse's own ``ArgumentDefaultsHelpFormatter`` uses)."""

    class Worded(formatter):  # type: ignore[misc, valid-type]
        def _get_help_string(self, action: argparse.Action) -> str | None:
            return wording.get(action.dest, action.help)

    return Worded


def _shared(*flags: str, **options: Any) -> argparse.ArgumentParser:
    """A parent parser (argparse's ``parents=``) holding one option: every command that takes
    the option takes this one, so it parses and checks the same everywhere."""
    parent = argparse.ArgumentParser(add_help=False)
    parent.add_argument_group(SHARED_TITLE).add_argument(*flags, **options)
    return parent


#: The heading of the shared options in a command's help, after the command's own options.
SHARED_TITLE = "common options"


#: ``--debug``: a traceback instead of the one-line error. Given before the command (``marine
#: --debug CMD``) or after it; absent from the namespace when not given (``getattr(args,
#: "debug", False)``), so that a command's parser never resets the top-level one's.
DEBUG = _shared("--debug", action="store_true", default=argparse.SUPPRESS,
                help="show the traceback of an error (for a bug report)")
#: ``--seed``: an integer >= 0; None when not given (each command says what it then does).
SEED = _shared("--seed", type=seed_int, help="seed (an integer >= 0)")
#: ``--json PATH``: also write the command's result as JSON.
JSON = _shared("--json", metavar="PATH", help="also write the result as JSON")
#: ``--force``: replace existing outputs (what the command wrote there before is cleared first).
FORCE = _shared("--force", action="store_true", help="replace existing outputs")
#: ``--env-kwargs JSON``: the environment's arguments, a JSON object.
ENV_KWARGS = _shared("--env-kwargs", metavar="JSON", type=json_object,
                     help="environment arguments, SI units, a JSON object")
#: ``--quiet``: no progress bar.
QUIET = _shared("--quiet", action="store_true", help="no progress bar")
#: The shared options by destination.
SHARED = {"debug": DEBUG, "seed": SEED, "json": JSON, "force": FORCE, "env_kwargs": ENV_KWARGS,
          "quiet": QUIET}
