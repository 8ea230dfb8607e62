"""``marine simulate``: record an episode of any environment in the recording format."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping
from typing import Any

import gymnasium as gym

import marine_envs  # noqa: F401  (registers the environments)
from marine_envs.recording import Recording

from .evaluation import run_episode
from .excitation import SIGNALS
from .lqr import LQRPolicy

POLICIES = (*SIGNALS, "lqr")


def make_policy(name: str, env: Any, seed: int | None, **options: float) -> Any:
    """An excitation signal (``zero``, ``sine``, ``random``, ``prbs``) about the vehicle's
    nominal input, or ``lqr`` for ``env``."""
    if name == "lqr":
        return LQRPolicy.for_env(env)
    if name not in SIGNALS:
        raise ValueError(f"unknown policy {name!r}; choose from {', '.join(POLICIES)}")
    n_inputs = env.action_space.shape[0]
    if name in ("random", "prbs"):
        options = {**options, "seed": seed}
    signal = SIGNALS[name](n_inputs, env.unwrapped.dt, **options)
    signal.centre = env.unwrapped.sim.nominal_action()
    return signal


def simulate(env_id: str, steps: int, seed: int | None = None, policy: str = "prbs",
             env_kwargs: Mapping[str, Any] | None = None, progress: bool = False,
             **policy_options: float) -> Recording:
    """Record ``steps`` steps of ``env_id`` under ``policy``: the applied inputs and the sensor
    outputs, in SI units, with the model name, its parameters and the settings as metadata."""
    if steps < 2:
        raise ValueError(f"steps={steps!r} is invalid: a recording needs at least 2 steps")
    env = gym.make(env_id, max_episode_steps=steps, **dict(env_kwargs or {}))
    episode = run_episode(env, make_policy(policy, env, seed, **policy_options), steps,
                          seed=seed, progress=progress)
    sim = env.unwrapped.sim
    measurements = {name: episode.observations[:, i]
                    for i, name in enumerate(sim.sensors.channels)}
    params = dataclasses.asdict(sim.model.params)
    meta = {"env": env_id, "seed": seed, "policy": policy, "dt": sim.dt,
            "env_kwargs": dict(env_kwargs or {}), "terminated": episode.terminated}
    return Recording.from_arrays(sim.model.name, episode.time, episode.inputs, measurements,
                                 params=params, meta=meta)
