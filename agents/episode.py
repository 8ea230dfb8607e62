"""``marine episode``: run one episode of any environment and plot what happened."""

from __future__ import annotations

import math
from collections.abc import Mapping
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import marine_envs  # noqa: F401  (registers the environments)
from estimators import registry
from marine_envs.provenance import save_figure

from .evaluation import Episode, episode_metrics, run_episode
from .policies import canonical, make_policy, names

#: The policies ``marine episode --policy`` runs: every policy of :mod:`agents.policies`.
EPISODE_POLICIES = names()
#: Estimators ``marine episode --estimator`` can put between the sensors and the policy.
EPISODE_ESTIMATORS = tuple(registry.ESTIMATORS)


def run(env_id: str, policy: str = "lqr-state", seconds: float | None = None, seed: int = 0,
        env_kwargs: Mapping[str, Any] | None = None, plot: str | Path | None = None,
        estimator: str | None = None) -> dict[str, float]:
    """One episode of ``env_id`` under ``policy``; optionally a figure of it.

    :param seconds: episode length, s (default: the environment's own episode).
    :param estimator: a registered estimator (:data:`estimators.registry.ESTIMATORS`:
        ``"kf"``, a Kalman filter of the env's model linearised at the reference and of its
        disturbances' models; ``"akf"``, the hydrofoil AKF paper's adaptive one on it;
        ``"kf_white"``, ``"akf_white"``, the same with white disturbances; ``"ekf"``, an
        extended Kalman filter of the nonlinear model; ``"pd"``, the USV observer patent's PD
        observer, USV only; ``"wave"`` and ``"wave_adaptive"``, the DP vessel's wave filter)
        turns the sensor output into the policy's observation.
    :return: summary: return, cost, failed, RMS error of each weighted state and input (SI;
        angles in degrees), and with an estimator the RMS estimation error of every state.
    """
    policy = canonical(policy)
    if estimator is not None and estimator not in EPISODE_ESTIMATORS:
        raise ValueError(f"estimator={estimator!r} is invalid: one of {EPISODE_ESTIMATORS}")
    if seconds is not None and not (math.isfinite(seconds) and seconds > 0):
        raise ValueError(f"seconds={seconds!r} is invalid: a positive episode length in s")
    env = gym.make(env_id, **dict(env_kwargs or {}))
    system = env.unwrapped.system
    steps = env.spec.max_episode_steps if seconds is None else max(1, round(seconds / system.dt))
    env = gym.wrappers.TimeLimit(env.unwrapped, steps)  # the requested length, not the spec's
    if estimator is not None:
        from estimators import EstimatorWrapper

        env = EstimatorWrapper(env, registry.make(estimator, env))
    episode = run_episode(env, make_policy(policy, env, seed), steps, seed=seed)
    if plot is not None:
        title = f"{env_id}, policy {policy}" + (f" on {estimator}" if estimator else "")
        plot_episode(episode, system, f"{title}, seed {seed}", Path(plot),
                     estimated=estimator is not None)
    return summarise(episode, system, estimated=estimator is not None)


def summarise(episode: Episode, system: Any, estimated: bool = False) -> dict[str, float]:
    """The episode's return and :func:`~agents.evaluation.episode_metrics` (its estimation
    errors too when the observations are estimates of the state)."""
    return {"return": episode.episode_return, **episode_metrics(
        system, episode.states, episode.inputs, episode.clipped, episode.terminated,
        episode.observations if estimated else None)}


def _measuring_channel(system: Any, state: int) -> int | None:
    """The sensor channel whose output moves with state ``state`` (itself, or e.g. the DP
    vessel's measured ``north`` = LF + WF motion for ``north_lf``), or None."""
    model = system.model
    x = model.x0[None].repeat(2, axis=0)
    x[1, state] += 1.0
    y = model.output(x)
    channels = [model.output_names.index(c) for c in system.channels]
    moved = np.flatnonzero(y[1, channels] != y[0, channels])
    return int(moved[0]) if moved.size else None


def plot_episode(episode: Episode, system: Any, title: str, path: Path,
                 estimated: bool = False) -> None:
    """True and measured (or, with ``estimated``, estimated) values of the weighted states,
    and the inputs, against time."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    model = system.model
    shown = [i for i in np.flatnonzero(system.task.q > 0)][:4]
    fig, axes = plt.subplots(len(shown) + 1, 1, figsize=(9, 1.8 * (len(shown) + 1) + 0.6),
                             sharex=True)
    for ax, i in zip(axes, shown, strict=False):
        name, unit = model.state_names[i], model.state_units[i]
        scale = 180 / math.pi if unit.startswith("rad") else 1.0
        channel = i if estimated else _measuring_channel(system, i)
        if channel is not None:
            seen = episode.observations[:, channel]
            ax.plot(episode.time, seen * scale, color="tab:orange", lw=0.6, alpha=0.7,
                    label="estimated" if estimated else "measured")
        ax.plot(episode.time, episode.states[:, i] * scale, color="tab:blue", label="true")
        ax.axhline(system.task.x_ref[i] * scale, color="0.5", lw=0.8, ls="--", label="reference")
        ax.set_ylabel(f"{name}\n({unit.replace('rad', 'deg')})")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, ncol=3, loc="upper right")
    low, high = model.u_bounds
    percent = 100 * (episode.inputs - (low + high) / 2) / ((high - low) / 2)
    for j, name in enumerate(model.input_names):
        axes[-1].plot(episode.time, percent[:, j], lw=0.9, label=name)
    axes[-1].set_ylabel("inputs\n(% of range)")
    axes[-1].legend(fontsize=8, ncol=len(model.input_names), loc="upper right")
    axes[-1].grid(alpha=0.3)
    axes[-1].set_xlabel("time (s)")
    fig.suptitle(title)
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=100)
    plt.close(fig)
