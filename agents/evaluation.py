"""Run a policy through an environment and keep what happened, for any SB3-style policy."""

from __future__ import annotations

import dataclasses
from typing import Any

import numpy as np
from numpy.typing import NDArray


@dataclasses.dataclass
class Episode:
    """One episode, row k holding what was seen and done at time ``time[k]``.

    ``observations[k]`` is what the policy saw before choosing ``actions[k]``; ``states[k]`` the
    true state then; ``inputs[k]`` the physical input applied from ``time[k]`` for one step;
    ``rewards[k]`` the reward of that step.
    """

    time: NDArray[np.float64]
    observations: NDArray[np.float64]
    states: NDArray[np.float64]
    actions: NDArray[np.float64]
    inputs: NDArray[np.float64]
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
                                             "inputs", "rewards", "clipped")}
    terminated = False
    iterator = range(steps)
    if progress:
        from tqdm import tqdm

        iterator = tqdm(iterator, desc="simulating", unit="step")
    for k in iterator:
        # SB3's convention: episode_start resets a stateful policy (e.g. LQR's integrators)
        action, _ = policy.predict(obs, episode_start=np.array([k == 0]), deterministic=True)
        rows["time"].append(info["time"])
        rows["observations"].append(obs)
        rows["states"].append(info["state"])
        obs, reward, terminated, truncated, info = env.step(action)
        rows["actions"].append(action)
        rows["inputs"].append(info["action_applied"])
        rows["rewards"].append(reward)
        rows["clipped"].append(info["action_clipped"])
        if terminated or truncated:
            break
    arrays = {k: np.asarray(v, dtype=bool if k == "clipped" else float) for k, v in rows.items()}
    return Episode(**arrays, terminated=bool(terminated))
