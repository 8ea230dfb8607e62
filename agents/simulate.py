"""``marine simulate``: record an episode of any environment in the recording format."""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from typing import Any

import gymnasium as gym

import marine_envs  # noqa: F401  (registers the environments)
from marine_envs.recording import Recording

from .evaluation import run_episode
from .excitation import SIGNALS, Dithered, RandomSteps
from .lqr import LQRPolicy

POLICIES = (*SIGNALS, "lqr")


#: Hold time of the dither on ``lqr``, s: the random steps the diagnosis's own generator uses.
DITHER_HOLD = 2.0


def make_policy(name: str, env: Any, seed: int | None, **options: float) -> Any:
    """An excitation signal (``zero``, ``sine``, ``random``, ``prbs``) about the vehicle's
    nominal input, or ``lqr`` for ``env``: with ``amplitude`` (a share of each actuator's half
    range) and optionally ``hold`` (s), LQR plus a random-step dither on every input."""
    if name == "lqr":
        unknown = sorted(set(options) - {"amplitude", "hold"})
        if unknown:
            raise ValueError(f"policy 'lqr' takes amplitude and hold (a dither), not {unknown}")
        lqr = LQRPolicy.for_env(env)
        if not options.get("amplitude"):
            if "hold" in options:
                raise ValueError("policy 'lqr': a dither hold needs a dither amplitude")
            return lqr
        dither = RandomSteps(env.action_space.shape[0], env.unwrapped.dt, seed=seed,
                             amplitude=options["amplitude"],
                             hold=options.get("hold", DITHER_HOLD))
        return Dithered(lqr, dither)
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
             disturbances: Sequence[str] = (), **policy_options: float) -> Recording:
    """Record ``steps`` steps of ``env_id`` under ``policy``: the applied inputs and the sensor
    outputs, in SI units, with the model name, its parameters and the settings as metadata.

    :param disturbances: the model's disturbance channels to record too, exact (a logged
        command such as the ROV's morph ``s_cmd``, or an ideal wind or current sensor).
    :raises ValueError: ``steps < 2`` or an unknown disturbance name, before any simulation.
    """
    if steps < 2:
        raise ValueError(f"steps={steps!r} is invalid: a recording needs at least 2 steps")
    env = gym.make(env_id, max_episode_steps=steps, **dict(env_kwargs or {}))
    names = env.unwrapped.sim.model.disturbance_names
    unknown = sorted(set(disturbances) - set(names))
    if unknown:
        raise ValueError(f"unknown disturbance(s) {unknown} of {env_id}: choose from "
                         f"{', '.join(names) or 'none'}")
    episode = run_episode(env, make_policy(policy, env, seed, **policy_options), steps,
                          seed=seed, progress=progress)
    sim = env.unwrapped.sim
    measurements = {name: episode.observations[:, i]
                    for i, name in enumerate(sim.sensors.channels)}
    params = dataclasses.asdict(sim.model.params)
    meta = {"env": env_id, "seed": seed, "policy": policy,
            "policy_options": dict(policy_options), "dt": sim.dt,
            "env_kwargs": dict(env_kwargs or {}), "terminated": episode.terminated}
    recorded = {name: episode.disturbances[:, names.index(name)] for name in disturbances}
    return Recording.from_arrays(sim.model.name, episode.time, episode.inputs, measurements,
                                 params=params, meta=meta, disturbances=recorded)
