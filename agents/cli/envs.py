"""``marine envs``: list the environments with their spaces. Its parser (:func:`add_parser`) beside
its handler (:func:`handle`)."""

from __future__ import annotations

import argparse
from typing import Any

from . import common


def add_parser(commands: Any) -> argparse.ArgumentParser:
    """Add ``marine envs`` to ``commands`` (the subparsers of ``marine``)."""
    envs = commands.add_parser("envs", help="list the environments with their spaces",
                               parents=[common.DEBUG])
    return envs


def handle(args: argparse.Namespace) -> int:
    import gymnasium as gym

    from marine_envs import ENVIRONMENTS

    for env_id in ENVIRONMENTS:
        env = gym.make(env_id)
        sim = env.unwrapped.sim
        print(f"{env_id}\n  model {sim.model.name}: states {', '.join(sim.model.state_names)}; "
              f"inputs {', '.join(sim.model.input_names)}\n  observation "
              f"{', '.join(sim.sensors.channels)} {env.observation_space}\n  action "
              f"{env.action_space}, dt {sim.dt} s")
    return 0
