"""``marine envs``: list the environments with their spaces. Its arguments (:func:`arguments`)
beside its handler (:func:`handle`)."""

from __future__ import annotations

import argparse

#: The command's line in ``marine --help``.
HELP = "list the environments with their spaces"
DESCRIPTION = None
#: The options it shares with other commands (:data:`agents.cli.common.SHARED`), each in
#: the command's own words (None: the common wording).
COMMON_OPTIONS = {}


def arguments(parser: argparse.ArgumentParser) -> None:
    """``marine envs``'s own arguments."""


def handle(args: argparse.Namespace) -> int:
    """Run ``marine envs`` as ``args`` ask; the exit code."""
    import gymnasium as gym

    from marine_envs import ENVIRONMENTS

    for env_id in ENVIRONMENTS:
        env = gym.make(env_id)
        system = env.unwrapped.system
        model = system.model
        print(f"{env_id}\n  model {model.name}: states {', '.join(model.state_names)}; "
              f"inputs {', '.join(model.input_names)}\n  observation "
              f"{', '.join(system.channels)} {env.observation_space}\n  action "
              f"{env.action_space}, dt {system.dt} s")
    return 0
