"""Writes ``step_reference.npz``: episodes of the environments' numpy path as it was when it was a
second implementation of the step beside the compiled kernel.

Made with the code of branch ``integrate`` at dfe1e3c (``PYTHONPATH=<that checkout> python
tests/data/make_step_reference.py``), where ``Simulator.apply`` and ``Simulator.advance`` were
numpy expressions (BLAS products for the allocation, the cost and the exact step) and the RK4 step
ran the batched ``model.rhs``. Recorded: every environment's vector env (busy sensors, clipped
actions, episodes that end) run in numpy, the hovercraft's zig-zag test (a simulator with its
own rudder law: numpy only) and a diagnosed USV run in numpy.
"""

import copy
from pathlib import Path

import gymnasium as gym
import numpy as np
from make_effects_reference import ENVS, effects

import marine_envs  # noqa: F401 - registers the environments
from marine_envs import ENVIRONMENTS

BUSY = {  # every stateful sensor stage, clipped actions, episodes that end
    "marine_envs/USV-v0": {"dropout": {"psi": 0.2}, "delay": {"r": 2}, "sample_period": {"p": 3},
                           "bias": {"phi": 0.01}, "max_roll": 0.05},
    "marine_envs/Hydrofoil-v0": {"dropout": {"theta": 0.2}, "delay": {"xi": 2},
                                 "sample_period": {"xi_dot": 3}, "sensor_range": {"xi": 1.5}},
    "marine_envs/ROV-v0": {"dropout": {"z": 0.2}, "delay": {"psi": 1}, "morph_time": 2.0},
    "marine_envs/DPVessel-v0": {"dropout": {"north": 0.3}, "delay": {"psi": 2},
                                "sample_period": {"east": 2}},
    "marine_envs/Hovercraft-v0": {"dropout": {"v": 0.2}, "sample_period": {"u": 2},
                                  "quantization": {"r": 1e-3}},
}
#: Vector envs: boats, steps (beyond a wave block of 256 steps), episode length, seeds.
BOATS, STEPS, EPISODE, SEED, ACTION_SEED = 3, 400, 170, 11, 7
#: The zig-zag test: steps, seed (actions are ignored: zero).
ZIGZAG, ZIGZAG_STEPS, ZIGZAG_SEED = "20/20", 200, 0
#: A diagnosed USV (state terms, actuator effects, a sensor bias: make_effects_reference.ENVS).
USV_STEPS, USV_SEED, USV_ACTION_SEED = 200, 3, 4
KEYS = ("obs", "reward", "state", "action_applied", "action_commanded", "disturbance",
        "action_clipped", "measurement_mask", "time", "terminated", "truncated")


def busy_env(env_id: str) -> gym.vector.VectorEnv:
    return gym.make_vec(env_id, num_envs=BOATS, vectorization_mode="vector_entry_point",
                        max_episode_steps=EPISODE, **BUSY[env_id])


def usv_with_effects() -> gym.vector.VectorEnv:
    env_id, entries, kwargs = ENVS["usv"]
    return gym.make_vec(env_id, num_envs=BOATS, vectorization_mode="vector_entry_point",
                        effects=effects(entries), **kwargs)


def run(env, seed: int, actions: np.ndarray) -> dict[str, np.ndarray]:
    """The episode's outputs step by step, by :data:`KEYS` (those the env gives)."""
    env.reset(seed=seed)
    rows: dict[str, list] = {}
    for action in actions:
        obs, reward, term, trunc, info = env.step(action)
        values = {"obs": obs, "reward": reward, "terminated": term, "truncated": trunc, **info}
        for key in KEYS:
            if key in values:
                rows.setdefault(key, []).append(np.array(values[key], copy=True))
    return {key: np.array(v) for key, v in rows.items()}


def in_numpy(env):
    """``env`` stepped by the simulator's numpy path."""
    env = copy.deepcopy(env)
    env.unwrapped._sim.run_in_numpy()
    return env


def busy_actions(env) -> np.ndarray:
    rng = np.random.default_rng(ACTION_SEED)
    return rng.uniform(-1.3, 1.3, (STEPS, *env.action_space.shape))  # some clipped


def usv_actions(env) -> np.ndarray:
    rng = np.random.default_rng(USV_ACTION_SEED)
    return rng.uniform(-1.3, 1.3, (USV_STEPS, *env.action_space.shape))


def record() -> dict[str, np.ndarray]:
    out = {}
    for env_id in ENVIRONMENTS:
        env = busy_env(env_id)
        out |= {f"{env_id}/{k}": v for k, v in run(in_numpy(env), SEED, busy_actions(env)).items()}
    zigzag = gym.make("marine_envs/Hovercraft-v0", zigzag=ZIGZAG)
    actions = np.zeros((ZIGZAG_STEPS, *zigzag.action_space.shape))
    out |= {f"zigzag/{k}": v for k, v in run(zigzag, ZIGZAG_SEED, actions).items()}
    usv = usv_with_effects()
    out |= {f"usv_effects/{k}": v
            for k, v in run(in_numpy(usv), USV_SEED, usv_actions(usv)).items()}
    return out


if __name__ == "__main__":
    np.savez_compressed(Path(__file__).with_name("step_reference.npz"), **record())
