"""Train and evaluate Stable-Baselines3 agents on the marine environments.

SB3 trains on the native batched environment through :class:`SB3VecEnv` (or, with
``backend="dummy"``, on SB3's ``DummyVecEnv`` of single environments), optionally behind a
state estimator. Hyperparameters come from ``agents/hyperparams.yaml`` (RL-Zoo style).
"""

from __future__ import annotations

import copy
import dataclasses
import importlib.util
import json
import math
import pickle
import time
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
import torch
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper
from stable_baselines3 import A2C, PPO, SAC, TD3
from stable_baselines3.common.base_class import BaseAlgorithm
from stable_baselines3.common.callbacks import BaseCallback, CheckpointCallback
from stable_baselines3.common.monitor import Monitor
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
    ``validation_episodes``
    (:class:`KeepBest`), and algorithm keyword arguments (``learning_rate`` and ``clip_range``
    may be RL-Zoo's ``"lin_<x>"``: decayed linearly to 0)."""
    _check_choice("env_id", env_id, tuple(marine_envs.ENVIRONMENTS))
    _check_choice("algo", algo, tuple(ALGOS))
    import yaml  # here: only reading the settings needs PyYAML

    table = yaml.safe_load(path.read_text())
    params = dict(table.get("default", {}).get(algo, {}))
    params.update(table.get(env_id, {}).get(algo, {}) or {})
    if not params:
        raise ValueError(f"{path} has no settings for algo {algo!r} (nor a default)")
    return params


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
    """

    def __init__(self, env_id: str, estimator: str, episodes: int, every: int, out: Path,
                 max_episode_steps: int | None = None) -> None:
        if not (isinstance(episodes, int) and episodes >= 1):
            raise ValueError(f"validation_episodes={episodes!r} is invalid: an integer >= 1 "
                             "(or 0 in the settings: no validation)")
        super().__init__()
        self.env_id, self.estimator, self.episodes = env_id, estimator, episodes
        self.every, self.out, self.max_episode_steps = every, out, max_episode_steps
        #: one entry per validation: timesteps, failed episodes, mean cost
        self.history: list[dict[str, float]] = []
        self.best: dict[str, float] | None = None

    def _on_step(self) -> bool:
        if self.n_calls % self.every == 0:
            self._validate()
        return True

    def _on_training_end(self) -> None:
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
            self.model.save(self.out / "model.zip")
            if normalizer is not None:
                normalizer.save(str(self.out / "vecnormalize.pkl"))


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

@dataclasses.dataclass
class TrainResult:
    """What :func:`train` did: output directory, environment steps taken, wall-clock time (s)
    and throughput (environment steps per second, learning and validation included); with
    validation, the score of the agent kept in ``model.zip`` (timesteps, failed, cost)."""

    out: Path
    timesteps: int
    wall_seconds: float
    steps_per_second: float
    selected: dict[str, float] | None = None


def _importable(*modules: str) -> bool:
    return all(importlib.util.find_spec(m) is not None for m in modules)


def train(env_id: str, algo: str = "ppo", estimator: str | None = None,
          timesteps: int | None = None, out: Path = Path("runs/sb3"), seed: int = 0,
          n_envs: int | None = None, backend: str = "native", progress_bar: bool = True,
          hyperparams: Mapping[str, Any] | None = None,
          max_episode_steps: int | None = None, torch_threads: int | None = 1) -> TrainResult:
    """Train ``algo`` on ``env_id`` and save ``model.zip``, ``vecnormalize.pkl`` (when the
    settings normalise), ``config.json`` and ``checkpoints/`` into ``out``. With the setting
    ``validation_episodes`` (:class:`KeepBest`), ``model.zip`` is the best validated agent,
    ``last_model.zip`` the last, and ``config.json`` has each validation's scores.

    :param timesteps: environment steps (default: the YAML's ``n_timesteps``).
    :param n_envs: parallel environments (default: the YAML's).
    :param hyperparams: overrides of the YAML's settings (e.g. ``{"n_steps": 128}``).
    :param torch_threads: torch's intra-op threads while training (None: leave as is). One by
        default: small MLPs gain nothing from more, and torch's threads spinning against
        numpy's made training 20x slower on 2 cores.
    """
    _check_choice("algo", algo, tuple(ALGOS))
    _check_choice("estimator", estimator, estimator_choices())
    _check_choice("backend", backend, BACKENDS)
    params = {**load_hyperparams(env_id, algo), **dict(hyperparams or {})}
    yaml_timesteps, yaml_envs = params.pop("n_timesteps"), params.pop("n_envs")
    timesteps = int(yaml_timesteps if timesteps is None else timesteps)
    if timesteps <= 0:
        raise ValueError(f"timesteps={timesteps!r} is invalid: a positive number of steps")
    n_envs = int(yaml_envs if n_envs is None else n_envs)
    config = {"env_id": env_id, "algo": algo, "estimator": estimator, "seed": seed,
              "n_envs": n_envs, "backend": backend, "max_episode_steps": max_episode_steps,
              "hyperparams": copy.deepcopy(params)}
    policy, normalize = params.pop("policy"), params.pop("normalize", False)
    # normalize: a bool, or VecNormalize's keyword arguments (RL-Zoo style)
    normalize_kwargs = dict(normalize) if isinstance(normalize, Mapping) else {}
    normalize = bool(normalize)
    penalty = float(params.pop("failure_penalty", 0.0))
    cost_to_go = bool(params.pop("failure_cost_to_go", False))
    for key in ("learning_rate", "clip_range"):
        if key in params:
            params[key] = _schedule(params[key])
    # about five checkpoints (and validations) a run; every counts vector steps of n_envs boats
    every = max(1, math.ceil(timesteps / 5 / n_envs))
    validation_episodes = params.pop("validation_episodes", 0)
    out = Path(out)
    keeper = KeepBest(env_id, estimator or RAW, validation_episodes, every, out,
                      max_episode_steps) if validation_episodes else None
    out.mkdir(parents=True, exist_ok=True)
    venv = make_vec_env(env_id, n_envs, estimator, seed, backend, max_episode_steps)
    if penalty or cost_to_go:
        steps = evaluation.episode_steps(env_id, max_episode_steps) if cost_to_go else None
        venv = FailurePenalty(venv, penalty, steps)
    if normalize:  # rewards too only on-policy: a replay buffer would keep stale scales
        normalize_kwargs = {"gamma": params.get("gamma", 0.99), "norm_reward": algo in ON_POLICY,
                            **normalize_kwargs}
        venv = VecNormalize(venv, **normalize_kwargs)
    tensorboard = str(out / "tb") if _importable("tensorboard") else None
    model = algorithm(algo)(policy, venv, seed=seed, device="cpu", verbose=0,
                        tensorboard_log=tensorboard, **params)
    callbacks: list[BaseCallback] = [CheckpointCallback(
        every, str(out / "checkpoints"), name_prefix="model", save_vecnormalize=normalize)]
    if keeper is not None:
        callbacks.append(keeper)
    threads = torch.get_num_threads()
    torch.set_num_threads(torch_threads or threads)
    start = time.perf_counter()
    try:
        model.learn(timesteps, callback=callbacks,
                    progress_bar=progress_bar and _importable("tqdm", "rich"))
    finally:
        torch.set_num_threads(threads)
    wall = time.perf_counter() - start
    result = TrainResult(out, int(model.num_timesteps), wall, model.num_timesteps / wall,
                         None if keeper is None else keeper.best)
    last = "" if keeper is None else "last_"  # model.zip is then KeepBest's choice
    model.save(out / f"{last}model.zip")
    if normalize:
        venv.save(str(out / f"{last}vecnormalize.pkl"))
    config.update(timesteps=result.timesteps, wall_seconds=wall,
                  steps_per_second=result.steps_per_second)
    if keeper is not None:
        config["validation"] = {"first_seed": VALIDATION_SEED, "episodes": validation_episodes,
                                "selected": keeper.best, "history": keeper.history}
    (out / "config.json").write_text(json.dumps(config, indent=2) + "\n")
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


def load_agent(out: Path) -> Agent:
    """The agent :func:`train` saved into ``out``."""
    out = Path(out)
    config = json.loads((out / "config.json").read_text())
    model = algorithm(config["algo"]).load(out / "model.zip", device="cpu")
    normalizer = None
    if (out / "vecnormalize.pkl").exists():
        # unpickled without its env: only its statistics are used, never updated
        with open(out / "vecnormalize.pkl", "rb") as f:
            normalizer = pickle.load(f)
        normalizer.training = False
    return Agent(model, normalizer, config)


def evaluate(out: Path, episodes: int = 5, seed: int = 0) -> list[dict[str, float]]:
    """Score the agent saved in ``out`` on ``episodes`` episodes of seeds ``seed, seed + 1,
    ...``, behind its training estimator (:func:`agents.evaluation.evaluate`).

    :return: one row of :func:`~agents.evaluation.episode_metrics` per episode (cost,
        failures, RMS errors, actuator usage, estimation errors), with its ``seed``.
    """
    if not (isinstance(episodes, int) and episodes >= 1):
        raise ValueError(f"episodes={episodes!r} is invalid: an integer >= 1")
    agent = load_agent(out)
    config = agent.config
    return evaluation.evaluate(config["env_id"], lambda venv: agent,
                               config["estimator"] or RAW, range(seed, seed + episodes),
                               max_episode_steps=config.get("max_episode_steps"))
