"""Train and evaluate Stable-Baselines3 agents on the marine environments.

SB3 trains on the native batched environment through :class:`SB3VecEnv` (or, with
``backend="dummy"``, on SB3's ``DummyVecEnv`` of single environments), optionally behind a
state estimator. Hyperparameters come from ``agents/hyperparams.yaml`` (RL-Zoo style).
"""

from __future__ import annotations

import contextlib
import copy
import dataclasses
import difflib
import errno
import fcntl
import importlib.util
import inspect
import json
import math
import os
import pickle
import re
import shutil
import signal
import threading
import time
import traceback
import warnings
import zipfile
from collections.abc import Callable, Iterator, Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper
from stable_baselines3 import A2C, PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback
from stable_baselines3.common.logger import Logger
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.save_util import load_from_zip_file
from stable_baselines3.common.utils import configure_logger
from stable_baselines3.common.vec_env import (
    DummyVecEnv,
    VecEnv,
    VecEnvWrapper,
    VecMonitor,
    VecNormalize,
)
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

import marine_envs
from estimators import registry
from estimators.registry import ORACLE, RAW
from marine_envs.files import WriteError, atomic_path, write_json

from . import evaluation

#: The algorithms by name; a string ``"module:Class"`` is imported on first use (an extra's).
ALGOS: dict[str, type[BaseAlgorithm] | str] = {
    "ppo": PPO, "sac": SAC, "td3": TD3, "a2c": A2C,
    "ppo_lstm": "sb3_contrib:RecurrentPPO",  # RL-Zoo's name; the `recurrent` extra
}
#: The extra that installs each algorithm imported on first use.
ALGO_EXTRAS = {"ppo_lstm": "recurrent"}
BACKENDS = ("native", "dummy")
HYPERPARAMS = Path(__file__).with_name("hyperparams.yaml")
#: Algorithms that learn from fresh rollouts: their returns, not only observations, are scaled.
ON_POLICY = ("ppo", "a2c", "ppo_lstm")
#: First seed of the validation episodes: apart from training's (``seed``, ...) and from the
#: evaluation seeds (0, 1, ... in ``marine evaluate`` and ``marine bench``).
VALIDATION_SEED = 100_000


# -- validation and hyperparameters ---------------------------------------------------------

def _check_choice(name: str, value: Any, choices: Sequence[Any]) -> None:
    if value not in choices:
        raise ValueError(f"{name}={value!r} is invalid: one of {tuple(choices)}")


def algorithm(name: str) -> type[BaseAlgorithm]:
    """The SB3 algorithm class called ``name`` (:data:`ALGOS`), importing an extra's on first
    use; a missing extra is named."""
    _check_choice("algo", name, tuple(ALGOS))
    found = ALGOS[name]
    if isinstance(found, str):
        module, cls = found.split(":")
        try:
            found = getattr(importlib.import_module(module), cls)
        except ImportError:
            raise ValueError(f"algo {name!r} needs {module.replace('_', '-')}: pip install "
                             f"'marine-envs[{ALGO_EXTRAS[name]}]'") from None
        ALGOS[name] = found
    return found


def load_hyperparams(env_id: str, algo: str, path: Path = HYPERPARAMS) -> dict[str, Any]:
    """The settings of ``algo`` on ``env_id``: the file's ``default`` section for ``algo``,
    updated with the env's own entry. Keys: ``n_timesteps``, ``n_envs``, ``policy``,
    ``normalize`` (a bool or ``VecNormalize``'s keyword arguments), optional ``policy_kwargs``,
    ``failure_penalty`` and ``failure_cost_to_go`` (:class:`FailurePenalty`) and
    ``validation_episodes`` (:class:`KeepBest`), and algorithm keyword arguments
    (``learning_rate`` and ``clip_range`` may be RL-Zoo's ``"lin_<x>"``: decayed linearly to 0).

    The whole file is checked first (:func:`check_hyperparams`), not only the entry used.

    :raises ValueError: an unreadable file, an unknown section, algorithm or setting, or a
        value out of its range, named with the file.
    """
    _check_choice("env_id", env_id, tuple(marine_envs.ENVIRONMENTS))
    _check_choice("algo", algo, tuple(ALGOS))
    import yaml  # here: only reading the settings needs PyYAML

    try:
        table = yaml.safe_load(path.read_text())
    except yaml.YAMLError as error:
        raise ValueError(f"{path}: invalid YAML: {_one_line(error)}") from None
    check_hyperparams(table, path)
    sections = [table.get(key, {}).get(algo) or {} for key in ("default", env_id)]
    params = {**sections[0], **sections[1]}
    if not params:
        raise ValueError(f"{path} has no settings for algo {algo!r} (nor a default)")
    missing = [key for key in ("n_timesteps", "n_envs", "policy") if key not in params]
    if missing:
        raise ValueError(f"{path}: the settings of {algo!r} on {env_id} lack {missing}")
    return params


def check_hyperparams(table: Any, path: Path) -> None:
    """Check a hyperparameter table as read from ``path``: sections named by environment ids
    or ``default``, algorithms of :data:`ALGOS` in them, and in each the settings of ours
    (:data:`OWN_SETTINGS`) or keyword arguments of the algorithm (only their values when the
    algorithm's extra is not installed), each in its range: numbers of steps, batches and
    epochs >= 1, rates > 0 (or ``"lin_<x>"``), ``normalize`` a bool or ``VecNormalize``'s
    keyword arguments, ...

    :raises ValueError: the first mistake, named with ``path`` and where in it (a short id such
        as ``USV-v0`` for a section gets the full one suggested).
    """
    if not isinstance(table, dict):
        raise ValueError(f"{path}: must map environment ids (and 'default') to algorithms to "
                         "settings, as agents/hyperparams.yaml does")
    for section, entries in table.items():
        if section != "default" and section not in marine_envs.ENVIRONMENTS:
            raise ValueError(f"{path}: unknown section {section!r}{_env_suggestion(section)}: "
                             "sections are 'default' and environment ids "
                             f"({', '.join(marine_envs.ENVIRONMENTS)})")
        if not isinstance(entries, dict):
            raise ValueError(f"{path}: {section}: must map algorithms to their settings, "
                             "e.g. 'ppo: {n_steps: 512}'")
        for algo, entry in entries.items():
            if algo not in ALGOS:
                raise ValueError(f"{path}: {section}: unknown algorithm {algo!r}"
                                 f"{_did_you_mean(algo, ALGOS)}: one of {', '.join(ALGOS)}")
            if not isinstance(entry, dict | None):
                raise ValueError(f"{path}: {section}: {algo}: must map setting names to values")
            _check_settings(entry or {}, algo, f"{path}: {section}: {algo}")


def _is_int(value: Any) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _is_rate(value: Any) -> bool:
    """A number > 0, or RL-Zoo's ``"lin_<x>"`` with ``x`` > 0."""
    if isinstance(value, str) and value.startswith("lin_"):
        try:
            value = float(value[4:])
        except ValueError:
            return False
    return _is_number(value) and value > 0


_AT_LEAST_1 = (lambda v: _is_int(v) and v >= 1, "an integer >= 1")
_RATE = (_is_rate, "a number > 0, or 'lin_<x>' (decayed linearly from x > 0 to 0), "
                   "e.g. 'lin_3e-4'")
_FRACTION = (lambda v: _is_number(v) and 0 <= v <= 1, "a number in [0, 1]")
#: What each setting's value must be (said so in an error); the algorithm checks the others.
_RULES: dict[str, tuple[Callable[[Any], bool], str]] = {
    "n_timesteps": _AT_LEAST_1, "n_envs": _AT_LEAST_1, "n_steps": _AT_LEAST_1,
    "batch_size": _AT_LEAST_1, "n_epochs": _AT_LEAST_1, "buffer_size": _AT_LEAST_1,
    "learning_starts": (lambda v: _is_int(v) and v >= 0, "an integer >= 0"),
    "gradient_steps": (lambda v: _is_int(v) and (v >= 1 or v == -1),
                       "an integer >= 1, or -1 (as many as environment steps)"),
    "validation_episodes": (lambda v: _is_int(v) and v >= 0,
                            "an integer >= 1, or 0 (no validation)"),
    "learning_rate": _RATE, "clip_range": _RATE,
    "gamma": _FRACTION, "gae_lambda": _FRACTION, "tau": _FRACTION,
    "failure_penalty": (lambda v: _is_number(v) and v >= 0, "a finite number >= 0"),
    "failure_cost_to_go": (lambda v: isinstance(v, bool), "true or false"),
    "normalize": (lambda v: isinstance(v, bool | Mapping),
                  "true, false or VecNormalize's keyword arguments, e.g. {clip_reward: 10000}"),
    "policy": (lambda v: isinstance(v, str) and bool(v), "a policy name, e.g. MlpPolicy"),
    "policy_kwargs": (lambda v: isinstance(v, Mapping),
                      "the policy's keyword arguments, e.g. {net_arch: [64, 64]}"),
}
#: Settings of ours (:func:`load_hyperparams`); the others are the algorithm's keyword arguments.
OWN_SETTINGS = ("n_timesteps", "n_envs", "policy", "normalize", "policy_kwargs",
                "failure_penalty", "failure_cost_to_go", "validation_episodes")
#: The algorithms' keyword arguments that :func:`train` sets itself: not settings.
_SET_BY_TRAIN = ("self", "policy", "env", "seed", "device", "verbose", "tensorboard_log",
                 "_init_setup_model")


def _check_settings(settings: Mapping[str, Any], algo: str, where: str) -> None:
    """Check the settings of one ``algo`` entry (see :func:`check_hyperparams`).

    :param where: what the settings are, for the error (e.g. ``"FILE: default: ppo"``).
    :raises ValueError: the first unknown setting or bad value, named with ``where``.
    """
    _check_choice("algo", algo, tuple(ALGOS))
    try:
        cls: type[BaseAlgorithm] | None = algorithm(algo)
    except ValueError:  # an extra that is not installed: its names are unknown here
        cls = None
    known = None if cls is None else (*OWN_SETTINGS, *_keywords(cls))
    for key, value in settings.items():
        if known is not None and key not in known:
            raise ValueError(f"{where}: unknown setting {key!r}{_did_you_mean(key, known)}")
        check, what = _RULES.get(key, (lambda v: True, ""))
        if not check(value):
            raise ValueError(f"{where}: {key}={value!r} is invalid: {what}{_text_hint(value)}")
    normalize = settings.get("normalize")
    if isinstance(normalize, Mapping):
        allowed = _keywords(VecNormalize, ("self", "venv"))
        unknown = [key for key in normalize if key not in allowed]
        if unknown:
            raise ValueError(f"{where}: normalize: unknown setting {unknown[0]!r}"
                             f"{_did_you_mean(unknown[0], allowed)}: VecNormalize takes "
                             f"{', '.join(allowed)}")
    policies, policy = getattr(cls, "policy_aliases", {}), settings.get("policy")
    if policies and policy is not None and policy not in policies:
        raise ValueError(f"{where}: policy={policy!r} is invalid: one of {', '.join(policies)}"
                         f"{_did_you_mean(policy, policies)}")


def _keywords(cls: type, leave_out: Sequence[str] = _SET_BY_TRAIN) -> tuple[str, ...]:
    """The keyword arguments of ``cls``, but those in ``leave_out``."""
    parameters = inspect.signature(cls.__init__).parameters.values()
    return tuple(p.name for p in parameters if p.name not in leave_out
                 and p.kind not in (p.VAR_POSITIONAL, p.VAR_KEYWORD))


def _did_you_mean(name: Any, choices: Sequence[str] | Mapping[str, Any]) -> str:
    close = difflib.get_close_matches(str(name), list(choices), n=1)
    return f" (did you mean {close[0]!r}?)" if close else ""


def _env_suggestion(name: Any) -> str:
    """`` (did you mean 'marine_envs/USV-v0'?)`` for ``USV-v0``, ``usv`` or a near miss."""
    for full in marine_envs.ENVIRONMENTS:
        short = full.split("/")[1].lower()
        if str(name).lower().removeprefix("marine_envs/") in (short, short.removesuffix("-v0")):
            return f" (did you mean {full!r}?)"
    return _did_you_mean(name, marine_envs.ENVIRONMENTS)


def _text_hint(value: Any) -> str:
    """A hint for a number YAML read as text: PyYAML (YAML 1.1) needs a dot in ``3.0e-4``."""
    if isinstance(value, str):
        try:
            float(value)
        except ValueError:
            return ""
        return " (YAML reads it as text: write the number with a decimal point, e.g. 3.0e-4)"
    return ""


def _one_line(error: BaseException) -> str:
    return " ".join(str(error).split())


def _schedule(value: Any) -> Any:
    """RL-Zoo's ``"lin_<x>"``: ``x`` decayed linearly to 0 over training (SB3 passes the
    remaining fraction of training, 1 -> 0); any other value as it is."""
    if isinstance(value, str) and value.startswith("lin_"):
        try:
            start = float(value[4:])
        except ValueError:
            raise ValueError(f"schedule {value!r} is invalid: 'lin_' and a number, e.g. "
                             "'lin_3e-4'") from None
        return lambda remaining: remaining * start
    return value


# -- the vector environment adapter ---------------------------------------------------------

def _split_info(info: Mapping[str, Any], n: int) -> list[dict[str, Any]]:
    """Gymnasium's batched info dict (``key`` + mask ``_key``) as one dict per environment."""
    out: list[dict[str, Any]] = [{} for _ in range(n)]
    for key, value in info.items():
        if key.startswith("_"):
            continue
        mask = info.get(f"_{key}")
        parts = _split_info(value, n) if isinstance(value, Mapping) else value
        for i in range(n):
            if mask is None or mask[i]:
                out[i][key] = parts[i]
    return out


def _chain(env: VectorEnv) -> list[VectorEnv]:
    """The wrappers of ``env`` from the outermost in, then the base environment."""
    chain = [env]
    while isinstance(chain[-1], VectorWrapper):
        chain.append(chain[-1].env)
    return chain


class SB3VecEnv(VecEnv):
    """A Gymnasium ``VectorEnv`` seen as an SB3 ``VecEnv``, so that SB3 trains on the native
    batched environment (no Python loop over boats).

    SB3 expects a finished environment to be reset within the step that ended it (its obs is
    the new episode's first, ``info["terminal_observation"]`` the last). Gymnasium vector envs
    with ``AutoresetMode.SAME_STEP`` do that already. Ours use ``NEXT_STEP``: they reset a
    finished boat on the following step and ignore its action there, which SB3 would record
    as a bogus transition; so the adapter resets finished boats itself, right away, with the
    env's ``restart(idx)`` (:class:`~marine_envs.envs.base.MarineVectorEnv`, and
    :class:`~estimators.VectorEstimatorWrapper` over it).

    The batched environment is one object: ``get_attr``/``set_attr``/``env_method`` act on it
    and return its answer once per requested index.
    """

    def __init__(self, venv: VectorEnv) -> None:
        self.venv = venv
        self.mode = venv.metadata.get("autoreset_mode", AutoresetMode.NEXT_STEP)
        if self.mode == AutoresetMode.NEXT_STEP:
            self._check_restartable(venv)
        elif self.mode != AutoresetMode.SAME_STEP:
            raise ValueError(f"autoreset_mode {self.mode!r} is not supported: NEXT_STEP "
                             "(marine envs) or SAME_STEP")
        super().__init__(venv.num_envs, venv.single_observation_space, venv.single_action_space)
        self._actions: np.ndarray | None = None

    @staticmethod
    def _check_restartable(venv: VectorEnv) -> None:
        if not callable(getattr(venv, "restart", None)):
            raise ValueError("a NEXT_STEP vector env needs restart(idx) to reset finished boats "
                             "within the step (marine_envs' native vector envs and "
                             f"VectorEstimatorWrapper have it); got {venv}")

    # -- SB3's VecEnv interface ---------------------------------------------------------
    def reset(self) -> VecEnvObs:
        seeds = None if all(s is None for s in self._seeds) else list(self._seeds)
        options = self._options[0] or None
        if any(o != self._options[0] for o in self._options):
            raise ValueError("a batched env takes one set of reset options for all boats")
        obs, info = self.venv.reset(seed=seeds, options=options)
        self.reset_infos = _split_info(info, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        return obs

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, terminated, truncated, info = self.venv.step(self._actions)
        terminated, truncated = np.asarray(terminated), np.asarray(truncated)
        dones = terminated | truncated
        infos = _split_info(info, self.num_envs)
        done = np.flatnonzero(dones)
        if done.size:
            obs = np.array(obs)  # the rows of finished boats are replaced below
            final = info.get("final_obs")  # SAME_STEP: obs already holds the new episodes
            for i in done:
                infos[i].pop("final_obs", None)
                infos[i]["terminal_observation"] = obs[i].copy() if final is None else final[i]
                infos[i]["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
            if self.mode == AutoresetMode.NEXT_STEP:
                obs[done] = self._restart(done)
        return obs, np.asarray(rewards, dtype=np.float32), dones, infos

    def close(self) -> None:
        self.venv.close()

    def get_attr(self, attr_name: str, indices: Any = None) -> list[Any]:
        return [getattr(self.venv, attr_name)] * len(self._get_indices(indices))

    def set_attr(self, attr_name: str, value: Any, indices: Any = None) -> None:
        setattr(self.venv, attr_name, value)

    def env_method(self, method_name: str, *method_args: Any, indices: Any = None,
                   **method_kwargs: Any) -> list[Any]:
        result = getattr(self.venv, method_name)(*method_args, **method_kwargs)
        return [result] * len(self._get_indices(indices))

    def env_is_wrapped(self, wrapper_class: type, indices: Any = None) -> list[bool]:
        wrapped = any(isinstance(env, wrapper_class) for env in _chain(self.venv))
        return [wrapped] * len(self._get_indices(indices))

    # -- NEXT_STEP autoreset done at once ------------------------------------------------
    def _restart(self, idx: np.ndarray) -> np.ndarray:
        """Start new episodes of boats ``idx`` now and return their first observations: the
        env's own ``reset`` when every boat restarts (exact: the episode generators carry
        on), else its ``restart`` of those boats (see ``MarineVectorEnv.restart``)."""
        if idx.size == self.num_envs:
            obs, _ = self.venv.reset()
            return obs
        obs, _ = self.venv.restart(idx)
        return obs


class FailurePenalty(VecEnvWrapper):
    """Subtract ``penalty`` (reward units) from the reward of a step that ends its episode by
    failure (``terminated``, not the time limit); with ``episode_steps``, also the steps the
    episode had left times its mean cost a step so far (its cost-to-go had it carried on so).

    The marine rewards are minus a cost, so without it an agent on an unstable craft (the
    hydrofoil) learns that crashing early is cheapest. A fixed penalty is not enough where a
    poor policy's cost grows fast: an ROV drifting off its station costs ~1e4 a step, so
    capsizing after 7 s beats any fixed penalty of that order; charged the rest of the episode at
    its own rate, failing is no cheaper than carrying on. Training only: evaluation
    scores the task's own cost and reports failures apart.
    """

    def __init__(self, venv: VecEnv, penalty: float, episode_steps: int | None = None) -> None:
        if not (math.isfinite(penalty) and penalty >= 0):
            raise ValueError(f"failure_penalty={penalty!r} is invalid: a finite number >= 0")
        if episode_steps is not None and not (isinstance(episode_steps, int)
                                              and episode_steps >= 1):
            raise ValueError(f"episode_steps={episode_steps!r} is invalid: an integer >= 1")
        super().__init__(venv)
        self.penalty, self.episode_steps = float(penalty), episode_steps
        self._steps = np.zeros(venv.num_envs, dtype=np.int64)  # into each boat's episode
        self._cost = np.zeros(venv.num_envs)  # each boat's episode cost so far

    def reset(self) -> VecEnvObs:
        self._steps[:], self._cost[:] = 0, 0.0
        return self.venv.reset()

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        self._steps += 1
        self._cost -= rewards
        failed = np.array([bool(d and not info.get("TimeLimit.truncated", False))
                           for d, info in zip(dones, infos, strict=True)])
        charge = np.full(len(dones), self.penalty)
        if self.episode_steps is not None:
            left = np.maximum(self.episode_steps - self._steps, 0)
            charge += left * np.maximum(self._cost / self._steps, 0.0)
        done = np.asarray(dones, dtype=bool)
        self._steps[done], self._cost[done] = 0, 0.0
        return obs, (rewards - charge * failed).astype(np.float32), dones, infos


class KeepBest(BaseCallback):
    """Keep the best agent of a run, not the last: every ``every`` calls (vector steps) and at
    the end of training, score the agent on ``episodes`` validation episodes (seeds
    :data:`VALIDATION_SEED`, ...) with :func:`agents.evaluation.evaluate`, and save it into
    ``out/model.zip`` (and ``out/vecnormalize.pkl``) when it fails in fewer episodes than the
    best so far, or as few at a lower mean cost.

    PPO's last iterate is not its best: on the hydrofoil, a run whose every checkpoint from
    480k steps on flew all validation episodes ended with an agent that broaches at the start.

    :param stopped: whether training was stopped early (Ctrl-C): then the end of training
        validates nothing more, so that stopping is quick.
    """

    def __init__(self, env_id: str, estimator: str, episodes: int, every: int, out: Path,
                 max_episode_steps: int | None = None,
                 stopped: Callable[[], bool] = lambda: False) -> None:
        if not (isinstance(episodes, int) and episodes >= 1):
            raise ValueError(f"validation_episodes={episodes!r} is invalid: an integer >= 1 "
                             "(or 0 in the settings: no validation)")
        super().__init__()
        self.env_id, self.estimator, self.episodes = env_id, estimator, episodes
        self.every, self.out, self.max_episode_steps = every, out, max_episode_steps
        self.stopped = stopped
        #: one entry per validation: timesteps, failed episodes, mean cost
        self.history: list[dict[str, float]] = []
        self.best: dict[str, float] | None = None

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
        agent = Agent(self.model, normalizer, {})
        seeds = range(VALIDATION_SEED, VALIDATION_SEED + self.episodes)
        rows = evaluation.evaluate(self.env_id, lambda venv: agent, self.estimator, seeds,
                                   max_episode_steps=self.max_episode_steps)
        score = {"timesteps": self.num_timesteps,
                 "failed": int(sum(row["failed"] for row in rows)),
                 "cost": float(np.mean([row["cost"] for row in rows]))}
        self.history.append(score)
        if self.best is None or (score["failed"], score["cost"]) < (self.best["failed"],
                                                                    self.best["cost"]):
            self.best = score
            _save_agent(self.model, self.out / "model.zip", self.out / "vecnormalize.pkl")


# -- building environments ------------------------------------------------------------------

def estimator_choices() -> tuple[str | None, ...]:
    """What an agent may see: None (= ``"raw"``, the sensors), ``"true"`` (the true state) or
    a registered estimator (:data:`estimators.registry.ESTIMATORS`)."""
    return (None, *registry.names())


def _single_env(env_id: str, estimator: str | None, max_episode_steps: int | None) -> gym.Env:
    from estimators import EstimatorWrapper

    env = gym.make(env_id, max_episode_steps=max_episode_steps)
    if estimator in (None, RAW):
        return env
    if estimator == ORACLE:
        raise ValueError("the dummy backend has no true-state observation; use backend='native'")
    return EstimatorWrapper(env, registry.make(estimator, env))


def make_vec_env(env_id: str, n_envs: int, estimator: str | None = None, seed: int = 0,
                 backend: str = "native", max_episode_steps: int | None = None) -> VecEnv:
    """``n_envs`` copies of ``env_id`` as an SB3 ``VecEnv`` with episode statistics
    (``info["episode"]``), seeded ``seed, seed + 1, ...`` at their first reset.

    :param estimator: what the agent sees (:func:`estimator_choices`), e.g. ``"kf"``.
    :param backend: ``"native"``: the batched env through :class:`SB3VecEnv`; ``"dummy"``:
        SB3's ``DummyVecEnv`` of single envs (same numbers, slower).
    :param max_episode_steps: episode length, steps (default: the registered one).
    """
    _check_choice("env_id", env_id, tuple(marine_envs.ENVIRONMENTS))
    _check_choice("estimator", estimator, estimator_choices())
    _check_choice("backend", backend, BACKENDS)
    if not (isinstance(n_envs, int) and n_envs >= 1):
        raise ValueError(f"n_envs={n_envs!r} is invalid: an integer >= 1")
    steps = evaluation.episode_steps(env_id, max_episode_steps)
    if backend == "dummy":
        venv: VecEnv = DummyVecEnv([lambda: Monitor(_single_env(env_id, estimator, steps))
                                    for _ in range(n_envs)])
    else:
        native = evaluation.make_env(env_id, n_envs, estimator or RAW,
                                     max_episode_steps=steps)
        venv = VecMonitor(SB3VecEnv(native))
    venv.seed(seed)
    return venv


# -- training -------------------------------------------------------------------------------

#: ``config.json``'s ``status``: training (or killed without saving: its checkpoints remain),
#: stopped by Ctrl-C and saved, or done.
RUNNING, INTERRUPTED, COMPLETE = "running", "interrupted", "complete"
CONFIG = "config.json"
CHECKPOINTS = "checkpoints"
#: What :func:`train` writes into its folder; ``force`` clears exactly these.
OWNED = ("model.zip", "last_model.zip", "vecnormalize.pkl", "last_vecnormalize.pkl", CONFIG,
         CHECKPOINTS, "tb")
_CHECKPOINT = re.compile(r"model_(\d+)_steps\.zip")


@dataclasses.dataclass
class TrainResult:
    """What :func:`train` did: output directory, environment steps taken in all (a resumed run
    counts its earlier steps), wall-clock time of this session (s) and its throughput
    (environment steps per second, learning and validation included); with validation, the
    score of the agent kept in ``model.zip`` (timesteps, failed, cost); whether a signal
    stopped it (it was saved all the same), the step count it started from and the signal
    (``signal.SIGINT`` or ``signal.SIGTERM``; None when it ran to its end)."""

    out: Path
    timesteps: int
    wall_seconds: float
    steps_per_second: float
    selected: dict[str, float] | None = None
    interrupted: bool = False
    resumed_from: int = 0
    stop_signal: int | None = None


def _importable(*modules: str) -> bool:
    return all(importlib.util.find_spec(m) is not None for m in modules)


class _StopSignals:
    """While active: the first SIGINT (Ctrl-C) or SIGTERM (a scheduler's or ``kill``'s stop)
    asks training to stop at the next step, where everything can be saved whole; a second
    one interrupts at once (``KeyboardInterrupt``: a file being written is left as it was).
    Only in the main thread (where Python delivers signals); elsewhere they keep their
    handlers."""

    SIGNALS = (signal.SIGINT, signal.SIGTERM)

    def __init__(self) -> None:
        #: the signal that asked to stop, None until one did
        self.received: int | None = None
        self._previous: dict[int, Any] = {}

    @property
    def requested(self) -> bool:
        return self.received is not None

    def __enter__(self) -> _StopSignals:
        if threading.current_thread() is threading.main_thread():
            self._previous = {s: signal.signal(s, self._handle) for s in self.SIGNALS}
        return self

    def __exit__(self, *exc: object) -> None:
        for number, handler in self._previous.items():
            # None: a handler installed outside Python, which cannot be put back
            signal.signal(number, signal.SIG_DFL if handler is None else handler)

    def _handle(self, signum: int, frame: Any) -> None:
        if self.requested:
            raise KeyboardInterrupt
        self.received = signum


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


def _save_agent(model: BaseAlgorithm, path: Path, statistics: Path) -> None:
    """Save ``model`` to ``path`` and its normalisation statistics (if it has any) to
    ``statistics``, each written whole (:func:`marine_envs.files.atomic_path`): both are
    written before either replaces its file, so a full disk changes neither, and the statistics
    land first, so a model file is never without its own.

    :raises marine_envs.files.WriteError: a file could not be written (named).
    """
    normalizer = model.get_vec_normalize_env()
    try:
        with atomic_path(path) as model_file:
            with open(model_file, "wb") as f:  # closed on an error too (SB3 leaves its open)
                model.save(f)
            if normalizer is not None:
                with atomic_path(statistics) as statistics_file:
                    normalizer.save(str(statistics_file))
    except WriteError as error:  # the statistics' error, wrapped by the model's atomic_path
        while isinstance(error.__cause__, WriteError):
            error = error.__cause__
        raise error from None


def _write_config(out: Path, config: Mapping[str, Any]) -> None:
    """``config.json``, replaced whole (a reader never sees half of it)."""
    write_json(out / CONFIG, config)


def read_config(run: Path) -> dict[str, Any]:
    """The ``config.json`` of the run folder ``run``.

    :raises FileNotFoundError: no such folder or no config.json in it.
    :raises ValueError: it is not a JSON object of a run's settings.
    """
    path = Path(run) / CONFIG
    if not path.is_file():
        raise FileNotFoundError(f"{run} is not a 'marine train' folder: no {CONFIG} in it")
    try:
        config = json.loads(path.read_text())
    except json.JSONDecodeError as error:
        raise ValueError(f"{path}: invalid JSON: {error}") from None
    missing = [k for k in ("env_id", "algo", "hyperparams") if k not in (config or {})]
    if not isinstance(config, dict) or missing:
        raise ValueError(f"{path} is not a 'marine train' config: missing {missing}")
    return config


def existing_run(out: Path) -> list[str]:
    """What of a run (:data:`OWNED`) is in ``out`` already."""
    return [name for name in OWNED if (Path(out) / name).exists()]


def clear_run(out: Path) -> None:
    """Remove what :func:`train` wrote into ``out`` (:data:`OWNED`, and the temporary files of
    its writes that a kill cut short), and nothing else."""
    for name in OWNED:
        path = Path(out) / name
        if path.is_dir():
            shutil.rmtree(path)
        elif path.exists():
            path.unlink()
    for temporary in Path(out).glob(".*.part*"):  # marine_envs.files.atomic_path's
        if any(temporary.name.startswith(f".{name}.") for name in OWNED):
            temporary.unlink()


# -- one writer a run folder ----------------------------------------------------------------

#: The lock file of a run folder: locked by the training that writes the folder, holding its pid.
LOCK = ".lock"


class RunInUse(BlockingIOError):
    """Another training is writing the run folder: ``folder``, locked by process ``pid`` (None
    when it cannot be read)."""

    def __init__(self, folder: Path, pid: int | None) -> None:
        holder = "another process" if pid is None else f"pid {pid}"
        super().__init__(errno.EWOULDBLOCK, f"{folder} is being written by another training "
                         f"({holder}): wait for it to end, or train into another folder")
        self.folder, self.pid = folder, pid

    def __str__(self) -> str:
        return str(self.strerror)


@contextlib.contextmanager
def run_lock(out: Path) -> Iterator[None]:
    """Hold the lock of the run folder ``out`` (created if need be) for the block, so that
    two trainings (new, resumed or forced) never write into one folder. The lock is an
    ``flock`` of ``out/.lock``, which holds the writer's pid; the kernel drops it when the
    process ends, however it ends (SIGKILL too), so a dead run never leaves its folder locked.
    A folder made here is removed again if it holds none of a run when the block ends (a
    setting refused when the environments are built).

    :raises RunInUse: another process holds the lock.
    """
    out = Path(out)
    made = [folder for folder in (out, *out.parents) if not folder.exists()]  # deepest first
    out.mkdir(parents=True, exist_ok=True)
    lock = _lock(out / LOCK)
    try:
        yield
    finally:
        if made and not existing_run(out):
            (out / LOCK).unlink()  # while locked: see _lock
            with contextlib.suppress(OSError):  # one that something else wrote into stays
                for folder in made:
                    folder.rmdir()
        os.close(lock)  # releases the lock


def _lock(path: Path) -> int:
    """Lock ``path`` (created if need be) and write this process's pid into it; the returned
    descriptor holds the lock until it is closed.

    :raises RunInUse: another process holds it.
    """
    while True:
        descriptor = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        if not _flock(descriptor, fcntl.LOCK_EX, patience=0.5):  # a check_not_in_use's moment
            os.close(descriptor)
            raise RunInUse(path.parent, _holder(path))
        if _same_file(descriptor, path):
            break
        os.close(descriptor)  # removed since it was opened (a failed start's cleanup): anew
    try:
        os.ftruncate(descriptor, 0)
        os.write(descriptor, f"{os.getpid()}\n".encode())
    except OSError as error:
        os.close(descriptor)
        raise WriteError(error.errno or errno.EIO, f"cannot write {path}: {error.strerror}",
                         str(path)) from error
    return descriptor


def check_not_in_use(out: Path) -> None:
    """Refuse the run folder ``out`` if a training is writing it, before any work (and without
    creating anything: the training itself takes the lock, :func:`run_lock`).

    :raises RunInUse: a training holds its lock.
    """
    path = Path(out) / LOCK
    try:
        descriptor = os.open(path, os.O_RDONLY)
    except (FileNotFoundError, NotADirectoryError):
        return  # no lock file: never trained into
    try:
        if not _flock(descriptor, fcntl.LOCK_SH, patience=0.0):
            raise RunInUse(Path(out), _holder(path))
    finally:
        os.close(descriptor)  # releases the shared lock at once


def _flock(descriptor: int, operation: int, patience: float) -> bool:
    """Lock ``descriptor`` (``fcntl.LOCK_EX`` or ``LOCK_SH``) without blocking, trying again
    for ``patience`` seconds; whether it is locked."""
    deadline = time.monotonic() + patience
    while True:
        try:
            fcntl.flock(descriptor, operation | fcntl.LOCK_NB)
            return True
        except BlockingIOError:
            if time.monotonic() >= deadline:
                return False
            time.sleep(0.01)


def _same_file(descriptor: int, path: Path) -> bool:
    try:
        return os.path.samestat(os.fstat(descriptor), os.stat(path))
    except FileNotFoundError:
        return False


def _holder(path: Path) -> int | None:
    """The pid in the lock file ``path``, None if it holds none."""
    for _ in range(100):  # the holder writes it right after locking: give it a moment
        try:
            text = path.read_text().strip()
        except OSError:
            return None
        if text:
            return int(text) if text.isdigit() else None
        time.sleep(0.01)
    return None


def train(env_id: str, algo: str = "ppo", estimator: str | None = None,
          timesteps: int | None = None, out: Path = Path("runs/sb3"), seed: int = 0,
          n_envs: int | None = None, backend: str = "native", progress_bar: bool = True,
          hyperparams: Mapping[str, Any] | None = None,
          max_episode_steps: int | None = None, torch_threads: int | None = 1,
          hyperparams_file: Path = HYPERPARAMS, force: bool = True) -> TrainResult:
    """Train ``algo`` on ``env_id`` and save ``model.zip``, ``vecnormalize.pkl`` (when the
    settings normalise), ``config.json`` and ``checkpoints/`` into ``out``. With the setting
    ``validation_episodes`` (:class:`KeepBest`), ``model.zip`` is the best validated agent,
    ``last_model.zip`` the last, and ``config.json`` has each validation's scores.

    ``config.json`` is written first (``"status": "running"``) and rewritten at the end
    (``"complete"``, with the step count). Ctrl-C (SIGINT) or SIGTERM stops training at the
    next step and saves the agent as at the end (``"interrupted"``;
    :attr:`TrainResult.interrupted`); :func:`resume` continues it. Every file is written whole
    (a full disk or a kill leaves the earlier one, or none), and the folder is locked while
    training writes it (:func:`run_lock`).

    :param timesteps: environment steps (default: the YAML's ``n_timesteps``).
    :param n_envs: parallel environments (default: the YAML's).
    :param hyperparams: overrides of the YAML's settings (e.g. ``{"n_steps": 128}``).
    :param torch_threads: torch's intra-op threads while training (None: leave as is). One by
        default: small MLPs gain nothing from more, and torch's threads spinning against
        numpy's made training 20x slower on 2 cores.
    :param hyperparams_file: the RL-Zoo style YAML of settings (default: the package's).
    :param force: replace a run already in ``out``, clearing what it wrote
        (:func:`clear_run`), so that two runs never mix; False: refuse such a folder (what
        ``marine train`` does without ``--force``).
    :raises FileExistsError: ``out`` holds a run and ``force`` is False.
    :raises RunInUse: another training is writing ``out`` (``force`` or not).
    :raises marine_envs.files.WriteError: a file could not be written (named).
    """
    config = settings(env_id, algo, estimator, timesteps, seed, n_envs, backend, hyperparams,
                      max_episode_steps, hyperparams_file)
    out = Path(out)
    with run_lock(out):
        held = existing_run(out)
        if held and not force:
            raise FileExistsError(f"{out} already holds a training run ({', '.join(held)}): "
                                  "continue it with --resume, or replace it with --force")
        return _run(config, out, None, progress_bar, torch_threads)


def settings(env_id: str, algo: str = "ppo", estimator: str | None = None,
             timesteps: int | None = None, seed: int = 0, n_envs: int | None = None,
             backend: str = "native", hyperparams: Mapping[str, Any] | None = None,
             max_episode_steps: int | None = None, hyperparams_file: Path = HYPERPARAMS
             ) -> dict[str, Any]:
    """The validated settings of a :func:`train` run, as its ``config.json`` starts.

    :raises ValueError: an unknown env id, algorithm, estimator or backend, a step or
        environment count that is not a positive integer, or a setting of the file or of
        ``hyperparams`` out of its range or unknown (:func:`check_hyperparams`), naming it,
        before any work.
    """
    algorithm(algo)  # an extra's algorithm is imported here: a missing extra named up front
    _check_choice("estimator", estimator, estimator_choices())
    _check_choice("backend", backend, BACKENDS)
    _check_settings(dict(hyperparams or {}), algo, "hyperparams")
    params = {**load_hyperparams(env_id, algo, Path(hyperparams_file)),
              **dict(hyperparams or {})}
    yaml_timesteps, yaml_envs = params.pop("n_timesteps"), params.pop("n_envs")
    timesteps = int(yaml_timesteps if timesteps is None else timesteps)
    if timesteps <= 0:
        raise ValueError(f"timesteps={timesteps!r} is invalid: a positive number of steps")
    n_envs = yaml_envs if n_envs is None else n_envs
    if not (isinstance(n_envs, int) and n_envs >= 1):
        raise ValueError(f"n_envs={n_envs!r} is invalid: an integer >= 1")
    return {"env_id": env_id, "algo": algo, "estimator": estimator or RAW, "seed": seed,
            "n_envs": n_envs, "backend": backend, "max_episode_steps": max_episode_steps,
            "hyperparams_file": str(hyperparams_file), "hyperparams": copy.deepcopy(params),
            "status": RUNNING, "timesteps": 0, "target_timesteps": timesteps,
            # about five checkpoints (and validations) a run, in vector steps of n_envs boats
            "checkpoint_every": max(1, math.ceil(timesteps / 5 / n_envs)),
            "wall_seconds": 0.0}


@dataclasses.dataclass(frozen=True)
class Saved:
    """A saved agent: its ``model`` zip, the ``vecnormalize`` statistics saved with it (None
    if there are none), the run folder whose ``config.json`` describes it and its step
    count (None if unknown)."""

    model: Path
    vecnormalize: Path | None
    run: Path
    timesteps: int | None


class FallbackWarning(UserWarning):
    """The agent asked for cannot be used (a run killed before saving, a truncated or corrupt
    file): an earlier one is used instead; the message says which and why."""


def _statistics_of(model: Path) -> Path:
    """Where :func:`train` saves the normalisation statistics that go with ``model``."""
    found = _CHECKPOINT.fullmatch(model.name)
    if found:
        return model.with_name(f"model_vecnormalize_{found[1]}_steps.pkl")
    return model.with_name(model.name.replace("model.zip", "vecnormalize.pkl"))


def _saved(model: Path, run: Path, config: Mapping[str, Any], steps: int | None) -> Saved:
    """``model`` with its statistics, checked against the run's settings and loaded once, so
    that a truncated or corrupt file is found here rather than halfway through a command.

    :raises ValueError: a file is missing or cannot be loaded (saying which, and why).
    """
    statistics = _statistics_of(model)
    if config["hyperparams"].get("normalize") and not statistics.exists():
        raise ValueError(f"{model} was trained on normalised observations but {statistics.name} "
                         "is missing beside it")
    for path in (model, statistics) if statistics.exists() else (model,):
        why = _unreadable(path)
        if why is not None:
            raise ValueError(f"{path} is unreadable ({why})")
    return Saved(model, statistics if statistics.exists() else None, run, steps)


def _unreadable(path: Path) -> str | None:
    """Why the saved model (``.zip``) or statistics (``.pkl``) ``path`` cannot be loaded; None
    if it can."""
    try:
        if path.suffix != ".zip":
            with open(path, "rb") as f:
                pickle.load(f)
            return None
        with zipfile.ZipFile(path) as archive:
            corrupt = archive.testzip()  # every member against its checksum
        if corrupt is not None:
            return f"{corrupt} in it is corrupt"
        data, params, _ = load_from_zip_file(path, device="cpu", print_system_info=False)
        if data is None or "policy" not in params:  # e.g. cut short: a zip inside it is found
            return "not a whole Stable-Baselines3 model: no " + \
                ("data" if data is None else "policy") + " in it"
        return None
    except Exception as error:  # whatever a damaged file raises (zip, torch, pickle) says why
        return _one_line(error) or type(error).__name__


def _first_loadable(run: Path, config: Mapping[str, Any],
                    candidates: Sequence[tuple[Path, int | None]], reasons: list[str]) -> Saved:
    """The first of ``candidates`` (model file, steps) that loads (:func:`_saved`); when it is
    not the agent asked for, a :class:`FallbackWarning` says which it is and why (``reasons``,
    and why each candidate before it was passed over).

    :raises ValueError: none loads (saying why each did not).
    """
    for model, steps in candidates:
        try:
            saved = _saved(model, run, config, steps)
        except ValueError as error:
            reasons.append(str(error))
            continue
        if reasons:
            what = "checkpoint " if model.parent.name == CHECKPOINTS else ""
            count = "" if steps is None else f" ({steps} steps)"
            warnings.warn(f"using {what}{model}{count}: {'; '.join(reasons)}", FallbackWarning,
                          stacklevel=3)
        return saved
    if not reasons:
        raise ValueError(f"{run} holds no model.zip and no checkpoint yet")
    raise ValueError(f"{run} holds no loadable agent: {'; '.join(reasons)}")


def checkpoints(run: Path) -> list[tuple[int, Path]]:
    """The run's checkpoints as ``(steps, path)``, oldest first."""
    folder = Path(run) / CHECKPOINTS
    found = [(int(m[1]), p) for p in folder.glob("model_*_steps.zip")
             if (m := _CHECKPOINT.fullmatch(p.name))] if folder.is_dir() else []
    return sorted(found)


def find_agent(path: Path) -> Saved:
    """The agent that ``path`` names: a run folder (its ``model.zip``, else its latest
    checkpoint that loads: a run stopped before saving, or whose file is truncated or
    corrupt, with a :class:`FallbackWarning` saying so), or a model file (``model.zip``,
    ``last_model.zip`` or ``checkpoints/model_<N>_steps.zip``) of a run folder.

    :raises FileNotFoundError: no such file or folder.
    :raises ValueError: a file that is not a saved model of a run or does not load, or a run
        without any agent that loads.
    """
    path = Path(path)
    if path.is_dir():
        config = read_config(path)
        final = path / "model.zip"
        found = [(p, steps) for steps, p in reversed(checkpoints(path))]
        if final.exists():
            return _first_loadable(path, config, [(final, _final_steps(config, final.name)),
                                                  *found], [])
        killed = " (its training is running, or was stopped before saving)" \
            if config.get("status") == RUNNING else ""
        return _first_loadable(path, config, found,
                               [f"{path} has no model.zip{killed}"] if found else [])
    if not path.exists():
        raise FileNotFoundError(f"no such run folder or model file: {path}")
    run = path.parent.parent if path.parent.name == CHECKPOINTS else path.parent
    if path.suffix != ".zip" or not (run / CONFIG).is_file():
        raise ValueError(f"{path} is not a model saved by 'marine train': give its run folder, "
                         "its model.zip or a checkpoints/model_<N>_steps.zip")
    config = read_config(run)
    found = _CHECKPOINT.fullmatch(path.name)
    return _saved(path, run, config, int(found[1]) if found else _final_steps(config, path.name))


def _final_steps(config: Mapping[str, Any], name: str) -> int | None:
    """Steps of the run's final ``model.zip`` or ``last_model.zip`` (None: not known)."""
    if config.get("status", COMPLETE) == RUNNING:
        return None
    if name == "model.zip" and config.get("validation"):
        selected = config["validation"].get("selected")
        return None if selected is None else int(selected["timesteps"])
    return int(config["timesteps"])


def latest(run: Path) -> Saved:
    """Where :func:`resume` continues ``run``: the last agent it saved that loads, by step
    count (the final or interrupted one, or a later checkpoint of a run that was killed);
    a :class:`FallbackWarning` says when that is not the run's final agent, and why.

    :raises FileNotFoundError: ``run`` is not a run folder.
    :raises ValueError: nothing saved, or nothing that loads.
    """
    run = Path(run)
    config = read_config(run)
    candidates = [(steps, 1, path) for steps, path in checkpoints(run)]
    last = run / ("last_model.zip" if config.get("validation") else "model.zip")
    ended = config.get("status", COMPLETE) in (INTERRUPTED, COMPLETE)
    if ended and last.exists():  # else older than the checkpoints, if there at all
        candidates.append((int(config["timesteps"]), 2, last))  # the same steps: it wins
    if not candidates:
        raise ValueError(f"{run} holds no saved agent to resume from (no model, no checkpoint)")
    reasons = [] if ended else [f"{run} was not saved at its end (its config.json says "
                                f"{RUNNING!r}: it was killed, or stopped by an error)"]
    return _first_loadable(run, config, [(path, steps) for steps, _, path in
                                         sorted(candidates, reverse=True)], reasons)


def resume(run: Path, timesteps: int | None = None, progress_bar: bool = True,
           torch_threads: int | None = 1) -> TrainResult:
    """Continue the training run in ``run`` from its last saved agent (:func:`latest`), with
    the settings of its ``config.json``, the normalisation statistics saved with the agent
    and its step count (SB3's ``reset_num_timesteps=False``: schedules and checkpoint names
    go on), to ``timesteps`` steps in all (default: the run's own target). An off-policy
    algorithm's replay buffer is not saved: it refills from the resumed policy.

    :raises FileNotFoundError: ``run`` is not a run folder.
    :raises ValueError: nothing to resume from, or ``timesteps`` not beyond its steps.
    :raises RunInUse: another training is writing ``run``.
    """
    run = Path(run)
    read_config(run)  # a run folder: before the lock, which would make one
    with run_lock(run):
        saved = latest(run)
        config = read_config(run)
        target = int(config.get("target_timesteps", config.get("timesteps", 0))
                     if timesteps is None else timesteps)
        assert saved.timesteps is not None
        if target <= saved.timesteps:
            raise ValueError(f"{run} has trained {saved.timesteps} of {target} steps: nothing "
                             "to resume; give --timesteps beyond it to train further")
        config.update(status=RUNNING, target_timesteps=target,
                      estimator=config.get("estimator") or RAW)
        config.setdefault("checkpoint_every", max(1, math.ceil(target / 5 / config["n_envs"])))
        return _run(config, run, saved, progress_bar, torch_threads)


@dataclasses.dataclass(frozen=True)
class _Penalty:
    """A run's failure penalty (reward units) and whether a failure also costs the rest of
    its episode at its own rate (:class:`FailurePenalty`)."""

    penalty: float = 0.0
    cost_to_go: bool = False


def _algorithm_kwargs(config: Mapping[str, Any]) -> tuple[dict[str, Any], str, bool,
                                                         dict[str, Any], _Penalty, int]:
    """From the run's settings: the algorithm's keyword arguments (schedules built), the
    policy, whether and how to normalise, the failure penalty and the validation episodes."""
    params = copy.deepcopy(dict(config["hyperparams"]))
    policy, normalize = params.pop("policy"), params.pop("normalize", False)
    # normalize: a bool, or VecNormalize's keyword arguments (RL-Zoo style)
    normalize_kwargs = dict(normalize) if isinstance(normalize, Mapping) else {}
    penalty = _Penalty(float(params.pop("failure_penalty", 0.0)),
                       bool(params.pop("failure_cost_to_go", False)))
    validation_episodes = params.pop("validation_episodes", 0)
    for key in ("learning_rate", "clip_range"):
        if key in params:
            params[key] = _schedule(params[key])
    return params, policy, bool(normalize), normalize_kwargs, penalty, validation_episodes


def _environments(config: Mapping[str, Any], saved: Saved | None, params: Mapping[str, Any],
                  normalize: bool, normalize_kwargs: dict[str, Any], penalty: _Penalty
                  ) -> VecEnv:
    """The training environments: seeded on, after the steps already taken (a resumed run
    sees new episodes), behind the failure penalty and the normalisation (restored)."""
    start = 0 if saved is None else int(saved.timesteps or 0)
    venv = make_vec_env(config["env_id"], config["n_envs"], config["estimator"],
                        config["seed"] + start, config["backend"], config["max_episode_steps"])
    if penalty.penalty or penalty.cost_to_go:
        steps = evaluation.episode_steps(config["env_id"], config["max_episode_steps"]) \
            if penalty.cost_to_go else None
        venv = FailurePenalty(venv, penalty.penalty, steps)
    if not normalize:
        return venv
    if saved is not None and saved.vecnormalize is not None:
        venv = VecNormalize.load(str(saved.vecnormalize), venv)
        venv.training = True
        return venv
    # rewards too only on-policy: a replay buffer would keep stale scales
    normalize_kwargs = {"gamma": params.get("gamma", 0.99),
                        "norm_reward": config["algo"] in ON_POLICY, **normalize_kwargs}
    return VecNormalize(venv, **normalize_kwargs)


def _run(config: dict[str, Any], out: Path, saved: Saved | None, progress_bar: bool,
         torch_threads: int | None) -> TrainResult:
    """Train (or go on training ``saved``) to ``config["target_timesteps"]``, save and
    rewrite ``config.json``; SIGINT or SIGTERM stops at the next step and saves the same way.
    A new run's old files are cleared and ``config.json`` written once the environments and
    the model are built: a setting they refuse leaves no trace. The caller holds the lock of
    ``out`` (:func:`run_lock`)."""
    algo, target = config["algo"], int(config["target_timesteps"])
    params, policy, normalize, normalize_kwargs, penalty, episodes = _algorithm_kwargs(config)
    venv = _environments(config, saved, params, normalize, normalize_kwargs, penalty)
    tensorboard = str(out / "tb") if _importable("tensorboard") else None
    start = 0 if saved is None else int(saved.timesteps or 0)
    if saved is None:
        try:
            model = algorithm(algo)(policy, venv, seed=config["seed"], device="cpu", verbose=0,
                                    tensorboard_log=tensorboard, **params)
        except TypeError as error:  # a setting the algorithm does not take (a typo?)
            venv.close()
            raise ValueError(f"{config.get('hyperparams_file', 'the settings')}: {algo}: "
                             f"{error}") from None
        clear_run(out)
    else:
        schedules = {k: params[k] for k in ("learning_rate", "clip_range") if k in params}
        model = algorithm(algo).load(saved.model, env=venv, device="cpu",
                                     custom_objects=schedules, tensorboard_log=tensorboard)
        model.num_timesteps = start
        model.set_random_seed(config["seed"] + start)
    with _StopSignals() as stop:  # from here on, a stop request saves the run
        _write_config(out, config)
        keeper = _keeper(config, out, episodes, stop)
        callbacks: list[BaseCallback] = [
            _Checkpoints(config["checkpoint_every"], out / CHECKPOINTS),
            _StopWhen(lambda: stop.requested)]
        if keeper is not None:
            callbacks.append(keeper)
        progress = _Progress(start, target) if progress_bar and _importable("tqdm") else None
        if progress is not None:
            callbacks.append(progress)
        logger = configure_logger(0, tensorboard, type(model).__name__, saved is None)
        model.set_logger(logger)  # SB3's own, as learn() would make it, but closed here
        began = time.perf_counter()
        try:
            with _torch_threads(torch_threads), _log_closed(logger, out / "tb"):
                model.learn(target - start, callback=callbacks,
                            reset_num_timesteps=saved is None)
        finally:
            if progress is not None:
                progress.close(int(model.num_timesteps))
        wall = time.perf_counter() - began
        return _finish(model, venv, keeper, config, out, wall, start, stop.received)


@contextlib.contextmanager
def _torch_threads(threads: int | None) -> Iterator[None]:
    """Torch's intra-op threads set to ``threads`` for the block (None: left as they are)."""
    before = torch.get_num_threads()
    torch.set_num_threads(threads or before)
    try:
        yield
    finally:
        torch.set_num_threads(before)


@contextlib.contextmanager
def _log_closed(logger: Logger, folder: Path) -> Iterator[None]:
    """Close SB3's ``logger`` (its TensorBoard log is in ``folder``) when the block ends, and
    report a write error of the log (a full disk) as one naming ``folder``: TensorBoard writes
    in a thread of its own, whose error SB3's logger raises later without a file name (and
    the thread prints its traceback, left out here: the error is reported once)."""
    excepthook = threading.excepthook

    def quiet(args: Any) -> None:
        if not (isinstance(args.exc_value, OSError) and _from_tensorboard(args.exc_value)):
            excepthook(args)

    threading.excepthook = quiet
    try:
        try:
            yield
        except BaseException:
            with contextlib.suppress(OSError):  # an error is on its way: one is enough
                logger.close()
            raise
        logger.close()  # the last records written (or their error raised) here
    except OSError as error:
        if isinstance(error, WriteError) or not _from_tensorboard(error):
            raise
        raise WriteError(error.errno or errno.EIO, f"cannot write {folder}: "
                         f"{error.strerror or error}", str(folder)) from error
    finally:
        threading.excepthook = excepthook


def _from_tensorboard(error: BaseException) -> bool:
    """Whether ``error`` was raised in TensorBoard's code."""
    return any("tensorboard" in frame.f_code.co_filename
               for frame, _ in traceback.walk_tb(error.__traceback__))


def _keeper(config: Mapping[str, Any], out: Path, episodes: int, stop: _StopSignals
            ) -> KeepBest | None:
    """:class:`KeepBest` for the run (carrying on a resumed run's validations), or None."""
    if not episodes:
        return None
    keeper = KeepBest(config["env_id"], config["estimator"], episodes,
                      config["checkpoint_every"], out, config["max_episode_steps"],
                      stopped=lambda: stop.requested)
    validation = config.get("validation") or {}
    keeper.history = list(validation.get("history", []))
    keeper.best = validation.get("selected")
    return keeper


def _finish(model: BaseAlgorithm, venv: VecEnv, keeper: KeepBest | None,
            config: dict[str, Any], out: Path, wall: float, start: int,
            stop_signal: int | None) -> TrainResult:
    """Save the agent (model.zip, or last_model.zip beside KeepBest's choice) and its
    statistics, and write the final ``config.json``."""
    steps = int(model.num_timesteps)
    last = "" if keeper is None else "last_"  # model.zip is then KeepBest's choice
    _save_agent(model, out / f"{last}model.zip", out / f"{last}vecnormalize.pkl")
    if keeper is not None and not (out / "model.zip").exists():
        # stopped before the first validation: the last agent is all there is
        _save_agent(model, out / "model.zip", out / "vecnormalize.pkl")
    result = TrainResult(out, steps, wall, (steps - start) / max(wall, 1e-9),
                         None if keeper is None else keeper.best, stop_signal is not None,
                         start, stop_signal)
    config.update(status=COMPLETE if stop_signal is None else INTERRUPTED, timesteps=steps,
                  wall_seconds=float(config.get("wall_seconds", 0.0)) + wall,
                  steps_per_second=result.steps_per_second)
    if keeper is not None:
        config["validation"] = {"first_seed": VALIDATION_SEED, "episodes": keeper.episodes,
                                "selected": keeper.best, "history": keeper.history}
    _write_config(out, config)
    venv.close()
    return result


# -- using a trained agent ------------------------------------------------------------------

@dataclasses.dataclass
class Agent:
    """A trained model with SB3's ``predict``, fed single-env observations; normalises them as
    in training (frozen statistics) when training used ``VecNormalize``.

    A recurrent policy's memory is carried by the agent when the caller passes no ``state``
    (the evaluation loops, written for memoryless policies, drop it); ``episode_start`` clears
    it, as for the LQR's integrators."""

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

    @property
    def recurrent(self) -> bool:
        """Whether the policy has a memory (sb3-contrib's recurrent policies)."""
        return hasattr(self.model.policy, "lstm_hidden_state_shape")


def load_agent(path: Path) -> Agent:
    """The agent :func:`train` saved: ``path`` is its run folder, a checkpoint or a model file
    of it (:func:`find_agent`)."""
    saved = find_agent(Path(path))
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
        :func:`train`: two USV episodes took 16 s with torch's two threads, 2.9 s with one, on
        a loaded 2-core machine.
    :return: one row of :func:`~agents.evaluation.episode_metrics` per episode (cost,
        failures, RMS errors, actuator usage, estimation errors), with its ``seed``.
    """
    if not (isinstance(episodes, int) and episodes >= 1):
        raise ValueError(f"episodes={episodes!r} is invalid: an integer >= 1")
    agent = load_agent(out)
    config = agent.config
    with _torch_threads(torch_threads):
        return evaluation.evaluate(config["env_id"], lambda venv: agent,
                                   config["estimator"] or RAW, range(seed, seed + episodes),
                                   max_episode_steps=config.get("max_episode_steps"),
                                   progress=progress)
