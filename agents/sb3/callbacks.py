"""The callbacks of a training run: validation keeping the best agent (:class:`KeepBest`),
checkpoints written whole, a progress bar, and a stop at the next step when asked.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from stable_baselines3.common.callbacks import BaseCallback

from .. import evaluation
from .agent import Agent
from .hyperparams import VALIDATION_SEED
from .runs import _save_agent, _statistics_of


class KeepBest(BaseCallback):
    """Keep the best agent of a run, not the last: every ``every`` calls (vector steps) and at
    the end of training, score the agent on ``episodes`` validation episodes (seeds
    :data:`~agents.sb3.hyperparams.VALIDATION_SEED`, ...) with :func:`agents.evaluation.evaluate`,
    and save it into ``out/model.zip`` (and ``out/vecnormalize.pkl``) when it fails in fewer
    episodes than the best so far, or as few at a lower mean cost.

    PPO's last iterate is not its best: on the hydrofoil, a run whose every checkpoint from
    480k steps on flew all validation episodes ended with an agent that broaches at the start.

    :param stopped: whether training was stopped early (Ctrl-C): then the end of training
        validates nothing more, so that stopping is quick.
    :param agent_config: the run's settings (its ``config.json``), which say how the agent
        acts (a residual agent corrects a controller).
    :param from_start: also score the untrained agent, before any step: a residual agent's is
        the controller it corrects, so a correction is kept only if it scores better.
    """

    def __init__(self, env_id: str, estimator: str, episodes: int, every: int, out: Path,
                 max_episode_steps: int | None = None,
                 stopped: Callable[[], bool] = lambda: False,
                 agent_config: Mapping[str, Any] | None = None,
                 from_start: bool = False) -> None:
        if not (isinstance(episodes, int) and episodes >= 1):
            raise ValueError(f"validation_episodes={episodes!r} is invalid: an integer >= 1 "
                             "(or 0 in the settings: no validation)")
        super().__init__()
        self.env_id, self.estimator, self.episodes = env_id, estimator, episodes
        self.every, self.out, self.max_episode_steps = every, out, max_episode_steps
        self.stopped = stopped
        self.agent_config, self.from_start = dict(agent_config or {}), from_start
        #: one entry per validation: timesteps, failed episodes, mean cost
        self.history: list[dict[str, float]] = []
        self.best: dict[str, float] | None = None

    def _on_training_start(self) -> None:
        if self.from_start and not self.history:
            self._validate()

    def _on_step(self) -> bool:
        if self.n_calls % self.every == 0:
            self._validate()
        return True

    def _on_training_end(self) -> None:
        if self.stopped():
            return
        if not self.history or self.history[-1]["timesteps"] != self.num_timesteps:
            self._validate()

    def _validate(self) -> None:
        normalizer = self.model.get_vec_normalize_env()  # its statistics as they are now
        agent = Agent(self.model, normalizer, self.agent_config)
        seeds = range(VALIDATION_SEED, VALIDATION_SEED + self.episodes)
        rows = evaluation.evaluate(self.env_id, agent, self.estimator, seeds,
                                   max_episode_steps=self.max_episode_steps)
        score = {"timesteps": self.num_timesteps,
                 "failed": int(sum(row["failed"] for row in rows)),
                 "cost": float(np.mean([row["cost"] for row in rows]))}
        self.history.append(score)
        if self.best is None or (score["failed"], score["cost"]) < (self.best["failed"],
                                                                    self.best["cost"]):
            self.best = score
            _save_agent(self.model, self.out / "model.zip", self.out / "vecnormalize.pkl")


class _StopWhen(BaseCallback):
    """Ends training at the next step once ``stop()`` is true."""

    def __init__(self, stop: Callable[[], bool]) -> None:
        super().__init__()
        self.stop = stop

    def _on_step(self) -> bool:
        return not self.stop()


class _Progress(BaseCallback):
    """A tqdm bar over the environment steps, from ``start`` to ``total``; it ends full
    (at the steps taken, which an on-policy rollout may take past ``total``) and is closed
    whatever ends training."""

    def __init__(self, start: int, total: int) -> None:
        super().__init__()
        from tqdm import tqdm

        self.bar = tqdm(total=total, initial=start, unit="step", desc="training",
                        dynamic_ncols=True)

    def _on_step(self) -> bool:
        self.bar.update(min(self.num_timesteps, self.bar.total) - self.bar.n)
        return True

    def close(self, steps: int) -> None:
        self.bar.total = max(self.bar.total, steps)
        self.bar.update(steps - self.bar.n)
        self.bar.close()


class _Checkpoints(BaseCallback):
    """Every ``every`` calls (vector steps), save the agent into ``folder`` as
    ``model_<steps>_steps.zip`` with its normalisation statistics
    ``model_vecnormalize_<steps>_steps.pkl`` (SB3's ``CheckpointCallback`` names), each file
    whole (:func:`_save_agent`; SB3's callback writes in place, so a full disk or a kill left
    a truncated checkpoint)."""

    def __init__(self, every: int, folder: Path) -> None:
        super().__init__()
        self.every, self.folder = every, folder

    def _init_callback(self) -> None:
        self.folder.mkdir(parents=True, exist_ok=True)

    def _on_step(self) -> bool:
        if self.n_calls % self.every == 0:
            model = self.folder / f"model_{self.num_timesteps}_steps.zip"
            _save_agent(self.model, model, _statistics_of(model))
        return True


