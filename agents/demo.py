"""``marine demo``: a short USV episode in waves, without and with an LQR autopilot."""

from __future__ import annotations

import math
from pathlib import Path

import gymnasium as gym
import numpy as np

import marine_envs  # noqa: F401  (registers the environments)
from marine_envs.provenance import save_figure

from .evaluation import Episode, run_episode
from .excitation import Zero
from .lqr import LQRPolicy


def _summary(episode: Episode) -> dict[str, float]:
    deg = np.degrees
    return {"return": episode.episode_return,
            "rms_heading_deg": float(deg(np.sqrt(np.mean(episode.states[:, 2] ** 2)))),
            "rms_roll_deg": float(deg(np.sqrt(np.mean(episode.states[:, 4] ** 2)))),
            "max_roll_deg": float(deg(np.abs(episode.states[:, 4]).max())),
            "rms_rudder_deg": float(deg(np.sqrt(np.mean(episode.inputs ** 2)))),
            "clipped_fraction": float(episode.clipped.mean())}


def run_demo(seconds: float = 100.0, seed: int = 0, hs: float = 2.0,
             plot: str | Path | None = "marine_demo.png") -> dict[str, dict[str, float]]:
    """Simulate the USV in a stern-quartering sea, rudder fixed vs LQR on the raw sensors.

    :param seconds: episode length, s.
    :param seed: episode seed (waves, noise, initial state).
    :param hs: significant wave height, m.
    :param plot: where to write the figure (PNG), or None.
    :return: summary numbers per controller.
    """
    dt = 0.1
    steps = int(round(seconds / dt))
    env = gym.make("marine_envs/USV-v0", hs=hs, dt=dt, max_episode_steps=steps)
    policies = {"rudder fixed": Zero(1, dt), "LQR on sensors": LQRPolicy.for_env(env)}
    episodes = {name: run_episode(env, policy, steps, seed=seed)
                for name, policy in policies.items()}
    if plot is not None:
        _plot(episodes, Path(plot))
    return {name: _summary(ep) for name, ep in episodes.items()}


def _plot(episodes: dict[str, Episode], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, 1, figsize=(9, 7), sharex=True)
    for (name, ep), color in zip(episodes.items(), ("tab:gray", "tab:blue"), strict=False):
        axes[0].plot(ep.time, np.degrees(ep.states[:, 2]), color=color, label=f"{name}: true",
                     zorder=3)
        axes[1].plot(ep.time, np.degrees(ep.states[:, 4]), color=color, label=name)
        axes[2].plot(ep.time, np.degrees(ep.inputs[:, 0]), color=color, label=name)
    lqr = episodes["LQR on sensors"]
    axes[0].step(lqr.time, np.degrees(lqr.observations[:, 1]), where="post", color="tab:orange",
                 lw=0.8, label="LQR: measured (noisy, quantized)")
    for ax, label in zip(axes, ("heading (deg)", "roll (deg)", "rudder (deg)"), strict=True):
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, ncol=3)
    axes[1].legend(fontsize=8)
    axes[2].set_xlabel("time (s)")
    fig.suptitle("USV-v0: course keeping and roll damping in a stern-quartering sea")
    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path, dpi=110)
    plt.close(fig)


def format_table(summary: dict[str, dict[str, float]]) -> str:
    """The summary as a fixed-width table."""
    columns = [("return", "{:>10.0f}"), ("rms_heading_deg", "{:>9.2f}"),
               ("rms_roll_deg", "{:>9.2f}"), ("max_roll_deg", "{:>9.2f}"),
               ("rms_rudder_deg", "{:>9.2f}"), ("clipped_fraction", "{:>8.1%}")]
    header = (f"{'controller':<16}{'return':>10}{'heading':>9}{'roll':>9}{'max roll':>9}"
              f"{'rudder':>9}{'clipped':>8}")
    units = f"{'':<16}{'':>10}{'rms deg':>9}{'rms deg':>9}{'deg':>9}{'rms deg':>9}{'':>8}"
    lines = [header, units]
    for name, row in summary.items():
        lines.append(f"{name:<16}" + "".join(fmt.format(row[key]) for key, fmt in columns))
    return "\n".join(lines)


def roll_reduction(summary: dict[str, dict[str, float]]) -> float:
    """Fraction by which the LQR reduces RMS roll against the fixed rudder."""
    fixed, lqr = summary["rudder fixed"]["rms_roll_deg"], summary["LQR on sensors"]["rms_roll_deg"]
    return 1 - lqr / fixed if fixed > 0 else math.nan
