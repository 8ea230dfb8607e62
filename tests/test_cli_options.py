"""The options every ``marine`` command shares come from one parent parser each: the same
option, parsed and checked the same way in every command that takes it."""

from __future__ import annotations

import pytest

from agents.cli import build_parser, main
from agents.cli.common import SHARED

#: Each command taking ``--seed``, with the least it needs to parse (its required arguments).
NEEDS = {"demo": [], "simulate": ["--out", "run.csv"], "episode": ["USV-v0"], "train": [],
         "evaluate": ["run"]}


def subcommands() -> dict:
    parser = build_parser()
    return next(a for a in parser._actions if a.dest == "command").choices


def shared_action(dest: str):
    (action,) = [a for a in SHARED[dest]._actions if a.dest == dest]
    return action


@pytest.mark.parametrize("name", sorted(subcommands()))
def test_a_command_takes_each_shared_option_from_its_one_parent(name):
    command = subcommands()[name]
    flags = {flag for parent in SHARED.values() for a in parent._actions
             for flag in a.option_strings}
    for action in command._actions:
        if set(action.option_strings) & flags:
            # the very option object of the parent parser, not a look-alike defined again
            assert action is shared_action(action.dest), (name, action.option_strings)
    assert any(action is shared_action("debug") for action in command._actions)


def test_seed_is_parsed_and_refused_alike_by_every_command(capsys):
    commands = subcommands()
    taking = sorted(name for name, command in commands.items()
                    if any(a is shared_action("seed") for a in command._actions))
    assert taking == sorted(NEEDS)
    refusals = set()
    for name in taking:
        assert commands[name].parse_args([*NEEDS[name], "--seed", "7"]).seed == 7
        assert commands[name].parse_args(NEEDS[name]).seed is None  # each command's default
        with pytest.raises(SystemExit) as stopped:
            commands[name].parse_args([*NEEDS[name], "--seed", "-1"])
        assert stopped.value.code == 2
        refusals.add(capsys.readouterr().err.replace(f"marine {name}", "marine CMD"))
    assert refusals == {"marine CMD: error: argument --seed: -1 is invalid: an integer >= 0 "
                        "(see marine CMD --help)\n"}


def test_each_command_words_its_shared_options_in_its_own_terms():
    commands = subcommands()
    assert "episode seed (random if omitted)" in " ".join(commands["simulate"].format_help()
                                                          .split())
    assert "first episode's seed; the others follow (default 0)" in " ".join(
        commands["evaluate"].format_help().split())
    assert "start afresh" in commands["bench"].format_help()


def test_debug_before_or_after_the_command_shows_the_traceback(tmp_path, capsys):
    missing = str(tmp_path / "no" / "run.csv")  # refused before any work: no such folder
    assert main(["simulate", "--out", missing, "--quiet"]) == 2
    assert "the folder" in capsys.readouterr().err
    for argv in (["--debug", "simulate", "--out", missing], ["simulate", "--out", missing,
                                                             "--debug"]):
        with pytest.raises(ValueError, match="does not exist"):
            main(argv)
