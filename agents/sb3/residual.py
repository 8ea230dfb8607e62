"""Residual RL: the agent learns a bounded correction to the LQR autopilot on the same estimate
(residual policy learning: Johannink et al. 2019, Silver et al. 2018).

The action applied is ``clip(a_lqr + scale * a_agent, -1, 1)``: ``a_lqr`` the task's LQR on the
observation the agent sees (its gain folded with the estimator's disturbance model, as
``marine bench``'s ``lqr``), ``a_agent`` in [-1, 1] the agent's. The agent's output layer starts
at zero, so the untrained agent is the LQR itself: training starts at the LQR's cost, and the
validation (:class:`~agents.sb3.callbacks.KeepBest`, which scores the untrained agent first)
keeps a learnt correction only where it lowers the cost.

In training the correction is added by :class:`ResidualVectorEnv`, a wrapper of the native
batched environment; in use, by :class:`ResidualPolicy` around the trained agent. Both add the
same way (:func:`combine`).
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
import torch
from gymnasium.vector import VectorEnv, VectorWrapper
from numpy.typing import NDArray
from stable_baselines3.common.base_class import BaseAlgorithm

#: What a correction may be added to, by name (the ``residual`` setting).
BASES = ("lqr",)
#: The default bound of the correction, a fraction of each action's half range.
DEFAULT_SCALE = 0.5


def residual_of(hyperparams: Mapping[str, Any]) -> tuple[str | None, float]:
    """A run's residual base (None: a pure agent) and the correction's bound, from its
    settings (``residual``, ``residual_scale``)."""
    return hyperparams.get("residual"), float(hyperparams.get("residual_scale", DEFAULT_SCALE))


def base_policy(base: str, venv: Any, estimator: str) -> Any:
    """The controller named ``base`` for the native vector env ``venv`` (seen through
    ``estimator``), acting on a batch of boats."""
    from ..policies import make_policy

    if base not in BASES:
        raise ValueError(f"residual={base!r} is invalid: one of {', '.join(BASES)}")
    return make_policy(base, venv, estimator=estimator)


def combine(base: NDArray[np.float32], correction: NDArray[np.float32],
            scale: float) -> NDArray[np.float32]:
    """The action applied: ``clip(base + scale * clip(correction, -1, 1), -1, 1)``."""
    step = scale * np.clip(np.asarray(correction, dtype=np.float32), -1.0, 1.0)
    return np.clip(base + step, -1.0, 1.0).astype(np.float32)


class ResidualPolicy:
    """A trained correction ``agent`` on top of ``base`` (both with SB3's ``predict``, on a
    batch of observations): :func:`combine` of their actions."""

    def __init__(self, base: Any, agent: Any, scale: float) -> None:
        self.base, self.agent, self.scale = base, agent, float(scale)

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        base, _ = self.base.predict(observation, episode_start=episode_start)
        correction, state = self.agent.predict(observation, state, episode_start, deterministic)
        return combine(base, correction, self.scale), state


class ResidualVectorEnv(VectorWrapper):
    """The native batched environment ``env`` with its actions taken as corrections to
    ``base`` on each boat's observation (training's side of :class:`ResidualPolicy`).

    The base's memory (LQR's integrators) restarts with each boat's episode: on the reset,
    on a same-step :meth:`restart` (SB3's adapter) and on the step after an episode ended
    (the env's own next-step autoreset).
    """

    def __init__(self, env: VectorEnv, base: Any, scale: float) -> None:
        if not (np.isfinite(scale) and 0 < scale <= 2):
            raise ValueError(f"residual_scale={scale!r} is invalid: a number in (0, 2], a "
                             "fraction of each action's half range")
        super().__init__(env)
        self.base, self.scale = base, float(scale)
        self._obs: np.ndarray | None = None
        self._starting = np.ones(self.num_envs, dtype=bool)  # next action starts an episode
        self._ended = np.zeros(self.num_envs, dtype=bool)  # reset by the env at the next step

    def reset(self, *, seed: Any = None, options: dict[str, Any] | None = None):
        obs, info = self.env.reset(seed=seed, options=options)
        self._obs = np.asarray(obs)
        self._starting[:], self._ended[:] = True, False
        return obs, info

    def step(self, actions):
        if self._obs is None:
            raise RuntimeError("ResidualVectorEnv: step() before reset()")
        base, _ = self.base.predict(self._obs, episode_start=self._starting)
        obs, reward, terminated, truncated, info = self.env.step(
            combine(base, actions, self.scale))
        # a boat that ended last step was reset in this one: its observation starts an episode
        self._starting = self._ended.copy()
        self._ended = np.asarray(terminated) | np.asarray(truncated)
        self._obs = np.asarray(obs)
        return obs, reward, terminated, truncated, info

    def restart(self, idx: Any) -> tuple[np.ndarray, np.ndarray]:
        """The wrapped env's same-step restart of boats ``idx``; their base starts afresh."""
        idx = np.asarray(idx, dtype=np.intp)
        obs, valid = self.env.restart(idx)
        assert self._obs is not None
        self._obs = np.array(self._obs)
        self._obs[idx] = obs
        self._starting[idx], self._ended[idx] = True, False
        return obs, valid


def zero_output(model: BaseAlgorithm) -> None:
    """Set the last layer of ``model``'s actor to zero, so its deterministic action is 0 (the
    correction starts at nothing): PPO/A2C's ``action_net``, SAC's ``mu`` (tanh(0) = 0), TD3's
    last linear layer before its tanh (and its target's)."""
    policy = model.policy
    layers = []
    if hasattr(policy, "action_net"):
        layers.append(policy.action_net)
    for actor in (getattr(policy, "actor", None), getattr(policy, "actor_target", None)):
        if actor is None:
            continue
        mu = actor.mu
        linear = [m for m in mu.modules() if isinstance(m, torch.nn.Linear)]
        layers.append(linear[-1])
    if not layers:
        raise ValueError(f"a residual {type(model).__name__} agent: no actor output layer found")
    with torch.no_grad():
        for layer in layers:
            layer.weight.zero_()
            layer.bias.zero_()
