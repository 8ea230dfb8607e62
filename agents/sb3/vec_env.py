"""The vector environments SB3 trains on: the native batched environment seen as an SB3
``VecEnv`` (:class:`SB3VecEnv`), or SB3's ``DummyVecEnv`` of single environments, optionally
behind a state estimator (:func:`make_vec_env`), and the reward shaping of training: the failure
penalty (:class:`FailurePenalty`), the action-rate penalty (:class:`ActionRatePenalty`) and a
fixed reward scale (:class:`RewardScale`).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode, VectorEnv, VectorWrapper
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.vec_env import DummyVecEnv, VecEnv, VecEnvWrapper, VecMonitor
from stable_baselines3.common.vec_env.base_vec_env import VecEnvObs, VecEnvStepReturn

import marine_envs
from estimators import registry
from estimators.registry import ORACLE, RAW

from .. import evaluation
from .hyperparams import BACKENDS, _check_choice, estimator_choices
from .residual import DEFAULT_SCALE, ResidualVectorEnv, base_policy

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


class ActionRatePenalty(VecEnvWrapper):
    """Subtract ``weight * sum((a_t - a_{t-1})**2)`` (reward units; actions in the agent's
    normalised units, -1..1) from each step's reward: a policy whose thrust chatters from step
    to step pays for it. An episode's first step has no previous action and pays nothing.

    The task's cost weighs the thrust, not its changes, so an agent that reacts to every wiggle
    of the estimate (wave motion, sensor noise) loses little on the task but learns a jumpy,
    imprecise policy; the penalty smooths it. Training only: evaluation scores the task's own
    cost.
    """

    def __init__(self, venv: VecEnv, weight: float) -> None:
        if not (math.isfinite(weight) and weight >= 0):
            raise ValueError(f"action_rate_penalty={weight!r} is invalid: a finite number >= 0")
        super().__init__(venv)
        self.weight = float(weight)
        shape = (venv.num_envs, *(venv.action_space.shape or ()))
        self._previous = np.zeros(shape)  # each boat's last action
        self._first = np.ones(venv.num_envs, dtype=bool)  # no last action yet
        self._actions = np.zeros(shape)

    def reset(self) -> VecEnvObs:
        self._first[:] = True
        return self.venv.reset()

    def step_async(self, actions: np.ndarray) -> None:
        self._actions = np.asarray(actions, dtype=float).reshape(self._previous.shape)
        self.venv.step_async(actions)

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        change = (self._actions - self._previous).reshape(self.num_envs, -1)
        charge = self.weight * np.sum(change * change, axis=1) * ~self._first
        self._previous = self._actions.copy()
        self._first = np.asarray(dones, dtype=bool).copy()  # a new episode starts next step
        return obs, (rewards - charge).astype(np.float32), dones, infos


class RewardScale(VecEnvWrapper):
    """Multiply each step's reward by ``scale`` (training only): a fixed scale for a run that
    does not normalise its rewards.

    VecNormalize divides the rewards by the standard deviation of the discounted return over
    all of training. Where early episodes cost orders of magnitude more than a good agent's
    (a DP vessel driving off costs ~1e3 a step and the failure's cost-to-go ~1e6, keeping
    station ~1), that running figure stays at the early returns', so a good agent's rewards
    shrink to ~1e-5 and its value function cannot tell them apart; a fixed scale keeps them
    as they are.
    """

    def __init__(self, venv: VecEnv, scale: float) -> None:
        if not (math.isfinite(scale) and scale > 0):
            raise ValueError(f"reward_scale={scale!r} is invalid: a finite number > 0")
        super().__init__(venv)
        self.scale = float(scale)

    def reset(self) -> VecEnvObs:
        return self.venv.reset()

    def step_wait(self) -> VecEnvStepReturn:
        obs, rewards, dones, infos = self.venv.step_wait()
        return obs, (np.asarray(rewards) * self.scale).astype(np.float32), dones, infos


# -- building environments ------------------------------------------------------------------

def _single_env(env_id: str, estimator: str | None, max_episode_steps: int | None) -> gym.Env:
    from estimators import EstimatorWrapper

    env = gym.make(env_id, max_episode_steps=max_episode_steps)
    if estimator in (None, RAW):
        return env
    if estimator == ORACLE:
        raise ValueError("the dummy backend has no true-state observation; use backend='native'")
    return EstimatorWrapper(env, registry.make(estimator, env))


def make_vec_env(env_id: str, n_envs: int, estimator: str | None = None, seed: int = 0,
                 backend: str = "native", max_episode_steps: int | None = None,
                 residual: str | None = None, residual_scale: float = DEFAULT_SCALE) -> VecEnv:
    """``n_envs`` copies of ``env_id`` as an SB3 ``VecEnv`` with episode statistics
    (``info["episode"]``), seeded ``seed, seed + 1, ...`` at their first reset.

    :param estimator: what the agent sees (:func:`~agents.sb3.hyperparams.estimator_choices`), e.g.
        ``"kf"``.
    :param backend: ``"native"``: the batched env through :class:`SB3VecEnv`; ``"dummy"``:
        SB3's ``DummyVecEnv`` of single envs (same numbers, slower).
    :param max_episode_steps: episode length, steps (default: the registered one).
    :param residual: the controller the actions correct (:mod:`agents.sb3.residual`), or None:
        the actions are applied as they are. Native backend only.
    :param residual_scale: the correction's bound, a fraction of each action's half range.
    """
    _check_choice("env_id", env_id, tuple(marine_envs.ENVIRONMENTS))
    _check_choice("estimator", estimator, estimator_choices())
    _check_choice("backend", backend, BACKENDS)
    if not (isinstance(n_envs, int) and n_envs >= 1):
        raise ValueError(f"n_envs={n_envs!r} is invalid: an integer >= 1")
    if residual is not None and backend != "native":
        raise ValueError(f"residual={residual!r} needs backend='native' (the batched env the "
                         f"controller acts on), not {backend!r}")
    steps = evaluation.episode_steps(env_id, max_episode_steps)
    if backend == "dummy":
        venv: VecEnv = DummyVecEnv([lambda: Monitor(_single_env(env_id, estimator, steps))
                                    for _ in range(n_envs)])
    else:
        native = evaluation.make_env(env_id, n_envs, estimator or RAW,
                                     max_episode_steps=steps)
        if residual is not None:
            base = base_policy(residual, native, estimator or RAW)
            native = ResidualVectorEnv(native, base, residual_scale)
        venv = VecMonitor(SB3VecEnv(native))
    venv.seed(seed)
    return venv
