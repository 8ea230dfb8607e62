"""A trained agent in use: loaded from its run folder with the normalisation statistics it was
trained with (:func:`load_agent`), and scored on seeded episodes behind its training estimator
(:func:`evaluate`).
"""

from __future__ import annotations

import dataclasses
import pickle
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.vec_env import VecNormalize

from estimators.registry import RAW

from .. import evaluation
from .hyperparams import _torch_threads, algorithm
from .residual import ResidualPolicy, base_policy, residual_of
from .runs import find_agent, read_config
from .zoo import agent_path, kind_of

# -- using a trained agent ------------------------------------------------------------------

@dataclasses.dataclass
class Agent:
    """A trained model with SB3's ``predict``, fed single-env observations; normalises them as
    in training (frozen statistics) when training used ``VecNormalize``.

    A recurrent policy's memory is carried by the agent when the caller passes no ``state``
    (the evaluation loops, written for memoryless policies, drop it); ``episode_start`` clears
    it, as for the LQR's integrators.

    A residual agent (its settings name a ``residual`` controller, :mod:`agents.sb3.residual`)
    predicts only the correction: call the agent with the environment it is to act on,
    ``agent(venv)``, for the policy that acts there (the controller plus the correction).
    Every agent is so a policy factory, as :func:`agents.evaluation.evaluate` takes them."""

    model: BaseAlgorithm
    normalizer: VecNormalize | None
    config: dict[str, Any]
    memory: Any = dataclasses.field(default=None, repr=False)

    def predict(self, observation: np.ndarray, state: Any = None, episode_start: Any = None,
                deterministic: bool = True) -> tuple[np.ndarray, Any]:
        obs = np.asarray(observation)
        if self.normalizer is not None:
            obs = self.normalizer.normalize_obs(obs)
        if state is not None or not self.recurrent:
            return self.model.predict(obs, state, episode_start, deterministic)
        rows = obs.shape[0] if obs.ndim > 1 else 1
        memory = self.memory if self.memory is not None and \
            self.memory[0].shape[1] == rows else None  # a new batch starts afresh
        action, self.memory = self.model.predict(obs, memory, episode_start, deterministic)
        return action, self.memory

    def __call__(self, venv: Any) -> Any:
        """The policy acting on the native vector env ``venv`` (seen through the agent's
        estimator): this agent, or for a residual agent its controller on ``venv`` plus it."""
        base, scale = residual_of(self.config.get("hyperparams", {}))
        if base is None:
            return self
        estimator = self.config.get("estimator") or RAW
        return ResidualPolicy(base_policy(base, venv, estimator), self, scale)

    @property
    def kind(self) -> str:
        """The agent's name in tables and in the zoo: its algorithm (``ppo``), prefixed
        ``residual_`` for a correction to a controller (``residual_ppo``)."""
        return kind_of(self.config)

    @classmethod
    def load(cls, name_or_path: str | Path) -> Agent:
        """The agent :func:`load_agent` loads: a zoo name (``"zoo:ROV-v0/residual_ppo"``), a run
        folder or a model file."""
        return load_agent(name_or_path)

    @property
    def recurrent(self) -> bool:
        """Whether the policy has a memory (sb3-contrib's recurrent policies)."""
        return hasattr(self.model.policy, "lstm_hidden_state_shape")


def load_agent(path: str | Path) -> Agent:
    """The agent :func:`~agents.sb3.training.train` saved: ``path`` is its run folder, a checkpoint
    or a model file of it (:func:`~agents.sb3.runs.find_agent`), or the name of a shipped agent,
    ``"zoo:ROV-v0/residual_ppo"`` (:func:`~agents.sb3.zoo.path_of`)."""
    saved = find_agent(agent_path(path))
    config = read_config(saved.run)
    model = algorithm(config["algo"]).load(saved.model, device="cpu")
    normalizer = None
    if saved.vecnormalize is not None:
        # unpickled without its env: only its statistics are used, never updated
        with open(saved.vecnormalize, "rb") as f:
            normalizer = pickle.load(f)
        normalizer.training = False
    return Agent(model, normalizer, {**config, "model": str(saved.model),
                                     "model_timesteps": saved.timesteps})


def evaluate(out: Path, episodes: int = 5, seed: int = 0,
             progress: Callable[[int], None] | None = None, torch_threads: int | None = 1
             ) -> list[dict[str, float]]:
    """Score the agent saved in ``out`` (a run folder, a checkpoint or a model file of it) on
    ``episodes`` episodes of seeds ``seed, seed + 1, ...``, behind its training estimator
    (:func:`agents.evaluation.evaluate`).

    :param progress: called with the number of steps done since its last call.
    :param torch_threads: torch's intra-op threads meanwhile (None: leave as is); one, as in
        :func:`~agents.sb3.training.train`: two USV episodes took 16 s with torch's two threads, 2.9
        s with one, on a loaded 2-core machine.
    :return: one row of :func:`~agents.evaluation.episode_metrics` per episode (cost,
        failures, RMS errors, actuator usage, estimation errors), with its ``seed``.
    """
    if not (isinstance(episodes, int) and episodes >= 1):
        raise ValueError(f"episodes={episodes!r} is invalid: an integer >= 1")
    agent = load_agent(out)
    config = agent.config
    with _torch_threads(torch_threads):
        return evaluation.evaluate(config["env_id"], agent,
                                   config["estimator"] or RAW, range(seed, seed + episodes),
                                   max_episode_steps=config.get("max_episode_steps"),
                                   progress=progress)
