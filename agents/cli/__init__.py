"""The ``marine`` command line: demo, simulate, episode, reproduce, diagnose, validate, train,
evaluate, zoo, bench, envs; one module a command (its parser beside its handler), the options they
share in :mod:`agents.cli.common`.

Every command checks what it is given (environment ids, numbers, input files, output paths and
the extras their formats need) before any work, and reports a mistake as one line
``marine CMD: error: ...`` with exit code 2, never a traceback (``marine --debug CMD ...``
shows it). An output that exists is refused unless ``--force``; forced, what the command wrote
there before (checkpoints, figures) is cleared first, so that two runs never mix; two outputs of
one command on the same path are refused.

Nothing is lost: every file is written whole or not at all (a temporary file beside it, renamed
over it at the end: :mod:`marine_envs.files`), so a full disk or an error leaves the earlier file
(or none), and a report folder is filled only once all of it is written. A file that cannot be
written or read is reported like a mistake, one line and exit code 2:
``marine CMD: error: cannot write PATH: No space left on device``.

Exit codes: 0 done; 2 a mistake in what was asked, or a file that cannot be read or written;
130 (128 + SIGINT) stopped by Ctrl-C, 143 (128 + SIGTERM) by SIGTERM, which every command takes
as Ctrl-C: ``marine train`` first saves the agent (``marine train --resume DIR`` continues it),
``marine simulate`` keeps the steps recorded so far; 141 (128 + SIGPIPE) when the reader of the
output went away (``marine envs | head -1``), silently.
"""


from __future__ import annotations

import argparse
import contextlib
import os
import signal
import sys
import threading
import warnings
from collections.abc import Iterator, Sequence
from typing import Any, NoReturn

from . import (
    bench,
    demo,
    diagnose,
    envs,
    episode,
    evaluate,
    reproduce,
    simulate,
    train,
    validate,
    zoo,
)
from .common import DEBUG, EXIT_INTERRUPTED, EXIT_SIGNAL, EXIT_USAGE, SHARED, USER_ERRORS, Parser
from .train import TRAIN_ALGOS, TRAIN_BACKENDS

__all__ = ["COMMANDS", "DESCRIPTION", "EXIT_INTERRUPTED", "EXIT_SIGNAL", "EXIT_USAGE",
           "TRAIN_ALGOS", "TRAIN_BACKENDS", "USER_ERRORS", "Parser", "Terminated",
           "build_parser", "main"]

DESCRIPTION = """\
marine-envs: Gymnasium environments for marine vehicles in waves, seen through noisy, quantized
sensors; the literature's state estimators as wrappers; LQR and RL agents on the same cost.

Angles on the command line are in degrees; everything inside (and in recordings) is SI/radians.
"""

#: The commands, in the order ``marine --help`` lists them. Each module says what the command is
#: (``HELP``, ``DESCRIPTION``), which shared options it takes in its own words
#: (``COMMON_OPTIONS``), its own arguments (``arguments``) and what it does (``handle``).
COMMANDS = (demo, simulate, episode, reproduce, diagnose, validate, train, evaluate, zoo, bench,
            envs)


def build_parser() -> argparse.ArgumentParser:
    """The parser of ``marine`` and its commands (importing nothing heavy: no torch)."""
    parser = Parser(prog="marine", description=DESCRIPTION, parents=[DEBUG],
                    formatter_class=argparse.RawDescriptionHelpFormatter)
    from marine_envs import __version__

    parser.add_argument("--version", action="version", version=f"marine-envs {__version__}")
    commands = parser.add_subparsers(dest="command", required=True, metavar="COMMAND")
    for command in COMMANDS:
        _add(commands, command)
    return parser


def _add(commands: Any, command: Any) -> None:
    """Add ``command`` (a module of :data:`COMMANDS`) to the subparsers ``commands``: its
    --debug and the shared options it takes (their one parent parser each, worded in its
    terms), its own arguments and its handler."""
    shared = command.COMMON_OPTIONS
    parser = commands.add_parser(
        command.__name__.rsplit(".", 1)[1], help=command.HELP, description=command.DESCRIPTION,
        formatter_class=getattr(command, "FORMATTER", argparse.HelpFormatter),
        parents=[SHARED["debug"], *(SHARED[dest] for dest in shared)],
        option_help={dest: words for dest, words in shared.items() if words is not None})
    command.arguments(parser)
    if parser.get_default("run") is None:  # (train's handler takes its parser too)
        parser.set_defaults(run=command.handle)


@contextlib.contextmanager
def _warnings_as_lines(command: str) -> Iterator[None]:
    """The project's own warnings (implausible values, solver troubles) as one line each,
    ``marine CMD: warning: ...``; others as Python shows them."""
    show = warnings.showwarning

    def line(message: Warning | str, category: type[Warning], filename: str, lineno: int,
             file: Any = None, text: str | None = None) -> None:
        if category.__module__.split(".")[0] in ("marine_envs", "estimators", "agents"):
            print(f"{command}: warning: {message}", file=sys.stderr)
        else:
            show(message, category, filename, lineno, file, text)

    warnings.showwarning = line
    try:
        yield
    finally:
        warnings.showwarning = show


#: Hints in the library's messages that name a Python argument, and what a command-line user
#: does instead.
COMMAND_LINE_HINTS = {
    "pass require_uniform=False to accept non-uniform sampling":
        "resample the record to a uniform time step (its median step, say) first",
    "pass model=... to read the file as SI units with nominal parameters":
        "give --model to read the file as SI units with nominal parameters",
    "pass model=...": "give --model",
    "use method='free' (or 'auto')": "use --method free (or auto)",
}


def _one_line(error: BaseException) -> str:
    text = "; ".join(part.strip() for part in str(error).splitlines() if part.strip()) \
        or type(error).__name__
    for python, command_line in COMMAND_LINE_HINTS.items():
        text = text.replace(python, command_line)
    return text


class Terminated(KeyboardInterrupt):
    """SIGTERM (``kill``, a batch system's time limit), raised where the program is, as Ctrl-C
    raises :class:`KeyboardInterrupt`: every command stops (and saves) the same way for both."""


@contextlib.contextmanager
def _sigterm_as_interrupt() -> Iterator[None]:
    """Within the block, SIGTERM raises :class:`Terminated` (signals are caught only in the
    main thread: elsewhere nothing changes)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return

    def terminate(number: int, frame: Any) -> NoReturn:
        raise Terminated

    before = signal.signal(signal.SIGTERM, terminate)
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, before)


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``marine`` with ``argv`` (default: the command line); the exit code (see the module's
    docstring): 0, 2 for a mistake in what was asked (one line on stderr), 128 + the signal's
    number when a signal stopped it."""
    try:
        try:
            return _main(argv)
        finally:
            sys.stdout.flush()  # a reader that went away shows here, not at the exit
    except BrokenPipeError:
        # Python's recipe (the signal module's docs): what is left goes nowhere, no message
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return EXIT_SIGNAL + signal.SIGPIPE


def _main(argv: Sequence[str] | None) -> int:
    with warnings.catch_warnings(record=True) as parsing:  # said once the command is known
        warnings.simplefilter("default")
        args = build_parser().parse_args(argv)
    command = f"marine {args.command}"
    try:
        with _warnings_as_lines(command), _sigterm_as_interrupt():
            for said in parsing:  # e.g. an old name of a policy
                warnings.showwarning(said.message, said.category, said.filename, said.lineno)
            return args.run(args)
    except KeyboardInterrupt as error:
        terminated = isinstance(error, Terminated)
        print(f"{command}: {'terminated' if terminated else 'interrupted'}", file=sys.stderr)
        return EXIT_SIGNAL + (signal.SIGTERM if terminated else signal.SIGINT)
    except BrokenPipeError:
        raise
    except USER_ERRORS as error:
        if getattr(args, "debug", False):
            raise
        print(f"{command}: error: {_one_line(error)}", file=sys.stderr)
        return EXIT_USAGE
