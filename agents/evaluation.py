"""One evaluation path for every policy (LQR, SB3, nominal input) behind every estimator.

:func:`run_episode` runs one single environment (for plots and recordings); :func:`rollout`
runs a batch of boats in the native vector environment, one episode each, and
:func:`evaluate` scores it: the task's quadratic cost, the RMS error of each weighted state in
physical units (degrees where the unit is rad), actuator usage and the estimator's own error.
The batch equals single environments seeded ``seed, seed + 1, ...``, so numbers from either
path agree.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from numpy.typing import NDArray

import marine_envs  # noqa: F401  (registers the environments)
from estimators.registry import ORACLE, RAW, observe

from .policies import ALIASES, LQR, POLICIES, canonical, make_policy, names

FloatArray = NDArray[np.float64]


@dataclasses.dataclass
class Episode:
    """One episode, row k holding what was seen and done at time ``time[k]``.

    ``observations[k]`` is what the policy saw before choosing ``actions[k]``; ``states[k]`` the
    true state then; ``inputs[k]`` the physical input applied from ``time[k]`` for one step,
    ``disturbances[k]`` the disturbance (sea, wind, current, command) over it; ``rewards[k]``
    the reward of that step.
    """

    time: NDArray[np.float64]
    observations: NDArray[np.float64]
    states: NDArray[np.float64]
    actions: NDArray[np.float64]
    inputs: NDArray[np.float64]
    disturbances: NDArray[np.float64]
    rewards: NDArray[np.float64]
    clipped: NDArray[np.bool_]
    terminated: bool

    @property
    def episode_return(self) -> float:
        return float(self.rewards.sum())


def run_episode(env: Any, policy: Any, steps: int, seed: int | None = None,
                progress: bool = False) -> Episode:
    """Run ``policy`` (anything with SB3's ``predict``) for at most ``steps`` steps.

    :param progress: show a progress bar (tqdm).
    """
    obs, info = env.reset(seed=seed)
    rows: dict[str, list] = {k: [] for k in ("time", "observations", "states", "actions",
                                             "inputs", "disturbances", "rewards", "clipped")}
    terminated = False
    bar = None
    if progress:
        from tqdm import tqdm

        # counted by hand: a bar over range(steps) left by the last step's break ends one short
        bar = tqdm(total=steps, desc="simulating", unit="step")
    try:
        for k in range(steps):
            # SB3's convention: episode_start resets a stateful policy (e.g. LQR's integrators)
            action, _ = policy.predict(obs, episode_start=np.array([k == 0]), deterministic=True)
            rows["time"].append(info["time"])
            rows["observations"].append(obs)
            rows["states"].append(info["state"])
            obs, reward, terminated, truncated, info = env.step(action)
            rows["actions"].append(action)
            rows["inputs"].append(info["action_applied"])
            rows["disturbances"].append(info["disturbance"])
            rows["rewards"].append(reward)
            rows["clipped"].append(info["action_clipped"])
            if bar is not None:
                bar.update()
            if terminated or truncated:
                break
    finally:
        if bar is not None:
            bar.close()
    arrays = {k: np.asarray(v, dtype=bool if k == "clipped" else float) for k, v in rows.items()}
    return Episode(**arrays, terminated=bool(terminated))


# -- batched episodes --------------------------------------------------------------------------

@dataclasses.dataclass
class Rollout:
    """One episode of each of N boats run side by side: arrays ``(T, N, ...)``, row k holding
    what was seen and done at step k; boat i's episode is its first ``lengths[i]`` rows."""

    observations: FloatArray
    states: FloatArray
    inputs: FloatArray
    clipped: NDArray[np.bool_]
    lengths: NDArray[np.intp]
    terminated: NDArray[np.bool_]

    def episode(self, i: int) -> dict[str, Any]:
        """Boat ``i``'s rows as ``{observations, states, inputs, clipped, terminated}``."""
        k = int(self.lengths[i])
        return {"observations": self.observations[:k, i], "states": self.states[:k, i],
                "inputs": self.inputs[:k, i], "clipped": self.clipped[:k, i],
                "terminated": bool(self.terminated[i])}


def rollout(venv: Any, policy: Any, steps: int, seed: int,
            progress: Callable[[int], None] | None = None) -> Rollout:
    """Run ``policy`` on every boat of the vector env ``venv`` for one episode of at most
    ``steps`` steps, boat i seeded ``seed + i``; a finished boat's later steps are ignored.

    :param policy: anything with SB3's ``predict`` taking a batch of observations.
    :param progress: called with the number of steps done since its last call.
    """
    n = venv.num_envs
    obs, info = venv.reset(seed=seed)
    rows: dict[str, list] = {k: [] for k in ("observations", "states", "inputs", "clipped")}
    lengths, terminated = np.full(n, steps), np.zeros(n, dtype=bool)
    running = np.ones(n, dtype=bool)
    for k in range(steps):
        action, _ = policy.predict(obs, episode_start=np.full(n, k == 0), deterministic=True)
        rows["observations"].append(np.asarray(obs, dtype=float))
        rows["states"].append(np.array(info["state"], dtype=float))  # the env's own array
        obs, _, term, trunc, info = venv.step(action)
        rows["inputs"].append(np.array(info["action_applied"], dtype=float))
        rows["clipped"].append(np.array(info["action_clipped"], dtype=bool))
        ended = running & (np.asarray(term) | np.asarray(trunc))
        lengths[ended], terminated[ended & np.asarray(term)] = k + 1, True
        running &= ~ended
        if progress is not None and k % 100 == 99:
            progress(100)
        if not running.any():
            break
    if progress is not None:
        progress(len(rows["states"]) % 100)
    return Rollout(**{k: np.stack(v) for k, v in rows.items()}, lengths=lengths,
                   terminated=terminated)


# -- what an episode scores --------------------------------------------------------------------

def _in_user_units(name: str, unit: str, value: float) -> tuple[str, float]:
    """``(name, value)`` in SI, or ``(name + "_deg", value in degrees)`` where the unit is
    rad or rad/s."""
    if unit.startswith("rad"):
        return f"{name}_deg", math.degrees(value)
    return name, value


def _rms(a: FloatArray) -> FloatArray:
    return np.sqrt(np.mean(a * a, axis=0))


def episode_metrics(system: Any, states: FloatArray, inputs: FloatArray, clipped: NDArray[np.bool_],
                    terminated: bool, estimates: FloatArray | None = None) -> dict[str, float]:
    """What one episode scored on the task of ``system`` (an environment's
    :class:`~marine_envs.envs.system.System`).

    :param states: true states ``(K, n_x)`` at the steps' starts; ``inputs`` ``(K, n_u)`` the
        physical inputs applied over them; ``clipped`` ``(K,)`` whether an action was clipped.
    :param estimates: the estimator's estimate ``(K, >= n_x)`` (its first ``n_x`` columns are the
        model's states), or None.
    :return: ``cost`` (the task's quadratic cost summed over the episode, = -return /
        reward_scale), ``failed`` (1 if the episode ended by failure), ``seconds``;
        ``rms_<state>`` of each weighted state's deviation from the reference, ``rms_<input>``
        of each input's from trim, ``saturated`` (fraction of steps with an action clipped);
        with ``estimates``, ``estimation_rms_<state>`` of every model state. Angles and rates
        in degrees (``_deg`` names), the rest SI.
    """
    task, model = system.task, system.model
    dx, du = states - task.x_ref, inputs - task.u_ref
    cost = float(np.sum(dx * dx * task.q) + np.sum(du * du * task.r))
    out = {"cost": cost, "failed": float(terminated), "seconds": len(states) * system.dt}
    for i, rms in zip(np.flatnonzero(task.q > 0), _rms(dx[:, task.q > 0]), strict=True):
        name, value = _in_user_units(model.state_names[i], model.state_units[i], float(rms))
        out[f"rms_{name}"] = value
    for j, rms in enumerate(_rms(du)):
        name, value = _in_user_units(model.input_names[j], model.input_units[j], float(rms))
        out[f"rms_{name}"] = value
    out["saturated"] = float(np.mean(clipped))
    if estimates is not None:
        miss = estimates[:, :dx.shape[1]] - states
        angles = [i for i, u in enumerate(model.state_units) if u == "rad"]
        miss[:, angles] = np.angle(np.exp(1j * miss[:, angles]))  # wrapped estimates
        for i, rms in enumerate(_rms(miss)):
            name, value = _in_user_units(model.state_names[i], model.state_units[i], float(rms))
            out[f"estimation_rms_{name}"] = value
    return out


# -- policies --------------------------------------------------------------------------

def lqr_for(venv: Any, estimator: str) -> Any:
    """The task's discrete LQR acting on what ``estimator`` gives (a name of
    :func:`estimators.registry.observe`): the policy ``lqr`` of :mod:`agents.policies`."""
    return make_policy(LQR, venv, estimator=estimator)


def _batched(policy: str | Callable[[Any], Any]) -> str | Callable[[Any], Any]:
    """``policy``, a factory or the one name of a policy that acts on a batch of boats.

    :raises ValueError: neither (before any work).
    """
    if callable(policy):
        return policy
    if isinstance(policy, str) and (policy in POLICIES or policy in ALIASES):
        name = canonical(policy)
        if POLICIES[name].batched:
            return name
    allowed = ", ".join(repr(name) for name in sorted(names(batched=True)))
    raise ValueError(f"policy={policy!r} is invalid: {allowed} or a factory")


# -- evaluation --------------------------------------------------------------------------------

def episode_steps(env_id: str, max_episode_steps: int | None = None) -> int:
    """``max_episode_steps``, or the registered episode length of ``env_id``."""
    return max_episode_steps or gym.spec(env_id).max_episode_steps


def make_env(env_id: str, episodes: int, estimator: str = RAW,
             env_kwargs: Mapping[str, Any] | None = None,
             max_episode_steps: int | None = None) -> Any:
    """``episodes`` boats of ``env_id`` in one native vector env, seen through ``estimator``.

    :param max_episode_steps: episode length, steps (default: the registered one).
    """
    venv = gym.make_vec(env_id, num_envs=episodes, vectorization_mode="vector_entry_point",
                        max_episode_steps=episode_steps(env_id, max_episode_steps),
                        **dict(env_kwargs or {}))
    return observe(venv, estimator)


def evaluate(env_id: str, policy: str | Callable[[Any], Any], estimator: str = RAW,
             seeds: Sequence[int] | int = 5, env_kwargs: Mapping[str, Any] | None = None,
             max_episode_steps: int | None = None,
             progress: Callable[[int], None] | None = None) -> list[dict[str, float]]:
    """Score ``policy`` on ``env_id`` behind ``estimator``, one episode per seed.

    :param policy: the name of a policy that acts on a batch of boats (:mod:`agents.policies`:
        ``"lqr"``, ``"nominal"``), or ``venv -> policy`` (e.g. an SB3 agent's factory); the
        policy must take a batch of observations.
    :param estimator: a name of :func:`estimators.registry.observe`.
    :param seeds: the episodes' seeds (consecutive: one batch), or a count from 0.
    :return: one :func:`episode_metrics` dict per seed, with its ``seed``.
    """
    policy = _batched(policy)
    seeds = list(range(seeds)) if isinstance(seeds, int) else list(seeds)
    if not seeds or seeds != list(range(seeds[0], seeds[0] + len(seeds))):
        raise ValueError(f"seeds={seeds!r} is invalid: consecutive integers (one batch)")
    steps = episode_steps(env_id, max_episode_steps)
    venv = make_env(env_id, len(seeds), estimator, env_kwargs, steps)
    actor = make_policy(policy, venv, estimator=estimator) if isinstance(policy, str) \
        else policy(venv)
    result = rollout(venv, actor, steps, seeds[0], progress)
    system = venv.unwrapped.system
    estimated = estimator not in (ORACLE, RAW)
    venv.close()
    rows = []
    for i, seed in enumerate(seeds):
        ep = result.episode(i)
        rows.append({"seed": seed, **episode_metrics(
            system, ep["states"], ep["inputs"], ep["clipped"], ep["terminated"],
            ep["observations"] if estimated else None)})
    return rows
