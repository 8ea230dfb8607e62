"""A new user's first hour: a light import, a word while the kernels compile, sensor options
that mean what they say, environments that pickle."""

from __future__ import annotations

import os
import pickle
import subprocess
import sys
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest

import marine_envs
from marine_envs.sensors import Quantizer, WrapAngle

ROOT = Path(__file__).resolve().parents[1]
ENV_IDS = list(marine_envs.ENVIRONMENTS)
#: Every sensor option off (None), so an observation is the true output.
SENSORS_OFF = dict.fromkeys(("noise_std", "bias", "quantization", "sensor_range",
                             "sample_period", "delay", "dropout"))


def run_python(code: str, **env: str) -> subprocess.CompletedProcess:
    """``code`` in a fresh interpreter with this checkout first on the path."""
    path = os.pathsep.join([str(ROOT), os.environ.get("PYTHONPATH", "")])
    environment = {**os.environ, "PYTHONPATH": path, **env}
    environment.pop("MARINE_ENVS_QUIET", None)  # (tests/conftest.py sets it for the suite)
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          env=environment, cwd=ROOT, timeout=600)


# -- a light import ------------------------------------------------------------------------------
@pytest.mark.parametrize("package", ["marine_envs", "estimators", "agents", "agents.cli"])
def test_import_leaves_the_heavy_modules_for_later(package):
    heavy = ["scipy.optimize", "scipy.signal", "scipy.stats", "scipy.linalg", "scipy.integrate",
             "matplotlib", "pandas", "torch", "stable_baselines3"]
    result = run_python(f"import sys, {package}; "
                        f"print(' '.join(m for m in {heavy!r} if m in sys.modules))")
    assert result.returncode == 0, result.stderr
    assert result.stdout.split() == []


# -- a word while the kernels compile ------------------------------------------------------------
def test_a_cold_first_use_says_it_compiles_once_and_a_warm_one_says_nothing(tmp_path):
    use = ("import gymnasium as gym, marine_envs\n"
           "for env in (gym.make('marine_envs/DPVessel-v0'),\n"
           "            gym.make_vec('marine_envs/DPVessel-v0', num_envs=2,\n"
           "                         vectorization_mode='vector_entry_point')):\n"
           "    env.reset(seed=0)\n"
           "    env.step(env.action_space.sample())\n")
    cache = str(tmp_path / "numba-cache")  # an empty disk cache: everything compiles
    cold = run_python(use, NUMBA_CACHE_DIR=cache)
    assert cold.returncode == 0, cold.stderr
    assert cold.stderr.splitlines().count(
        "compiling the DPVessel kernels (first use, 5-10 s)") == 1, cold.stderr
    assert cold.stdout == ""
    warm = run_python(use, NUMBA_CACHE_DIR=cache)
    assert warm.returncode == 0, warm.stderr
    assert "compiling" not in warm.stderr


def test_the_compile_note_can_be_silenced(monkeypatch, capsys):
    from marine_envs import compiled

    monkeypatch.setattr(compiled, "_ANNOUNCED", set())
    for quiet, said in (("1", ""), ("", "compiling the Boat kernels (first use, 5-10 s)\n")):
        monkeypatch.setenv("MARINE_ENVS_QUIET", quiet)
        with compiled.first_use("Boat"):
            compiled._announce()  # what a miss of the disk cache calls
        assert capsys.readouterr().err == said


# -- None turns a sensor stage off ---------------------------------------------------------------
def true_outputs(env: gym.Env, state: np.ndarray) -> np.ndarray:
    system = env.unwrapped.system
    idx = [system.model.output_names.index(c) for c in system.channels]
    return system.model.output(state[None])[0, idx]


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_every_sensor_option_none_measures_the_true_output(env_id):
    env = gym.make(env_id, **SENSORS_OFF)
    assert all(isinstance(s, WrapAngle) for s in env.unwrapped.system.sensors.stages)
    obs, info = env.reset(seed=3)
    rng = np.random.default_rng(3)
    for _ in range(5):
        expected = true_outputs(env, info["state"])
        error = obs - expected
        error = (error + np.pi) % (2 * np.pi) - np.pi  # angles are wrapped to (-pi, pi]
        np.testing.assert_allclose(error, 0.0, atol=1e-6 * (1 + np.abs(expected).max()))
        obs, _, _, _, info = env.step(rng.uniform(-1, 1, env.action_space.shape))


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_quantization_none_is_no_quantization_not_the_default_step(env_id):
    none, empty = (gym.make(env_id, quantization=q) for q in (None, {}))
    assert not any(isinstance(s, Quantizer) for s in none.unwrapped.system.sensors.stages)
    rng = np.random.default_rng(1)
    actions = rng.uniform(-1, 1, (10, *none.action_space.shape))
    np.testing.assert_array_equal(rollout(none, actions, seed=1),
                                  rollout(empty, actions, seed=1))


def test_a_channel_mapped_to_none_is_unquantized_and_the_default_stays_when_omitted():
    mu = np.radians(0.5)
    default = gym.make("marine_envs/USV-v0")
    assert any(isinstance(s, Quantizer) for s in default.unwrapped.system.sensors.stages)
    mixed = gym.make("marine_envs/USV-v0", quantization={"psi": None, "phi": mu})
    phi_only = gym.make("marine_envs/USV-v0", quantization={"phi": mu})
    actions = np.full((20, 1), 0.3)
    observed = rollout(mixed, actions, seed=2)
    np.testing.assert_array_equal(observed, rollout(phi_only, actions, seed=2))
    channels = mixed.unwrapped.system.channels
    phi, psi = observed[:, channels.index("phi")], observed[:, channels.index("psi")]
    np.testing.assert_allclose(phi / mu, np.round(phi / mu), atol=1e-3)  # on the grid
    assert np.abs(psi / mu - np.round(psi / mu)).max() > 0.05  # off it: not quantized


def rollout(env: gym.Env, actions: np.ndarray, seed: int) -> np.ndarray:
    """The observations of an episode from ``reset(seed=seed)`` under ``actions``."""
    observations = [env.reset(seed=seed)[0]]
    observations += [env.step(a)[0] for a in actions]
    return np.array(observations)


# -- environments pickle -------------------------------------------------------------------------
def same_step(a, b):
    for x, y in zip(a[:4], b[:4], strict=True):
        np.testing.assert_array_equal(x, y)
    assert a[4].keys() == b[4].keys()
    for key in a[4]:
        np.testing.assert_array_equal(a[4][key], b[4][key], err_msg=key)


@pytest.mark.parametrize("vector", [False, True], ids=["single", "vector"])
@pytest.mark.parametrize("env_id", ENV_IDS)
def test_an_unpickled_environment_steps_as_the_original(env_id, vector):
    # busy sensors: their state (delay lines, held samples, dropout) must travel too
    busy = {"dropout": 0.2, "delay": 1, "sample_period": 2}
    env = (gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point", **busy)
           if vector else gym.make(env_id, **busy))
    env.reset(seed=7)
    env.action_space.seed(7)
    for _ in range(5):  # mid-episode: random streams, sensor buffers and step counts in use
        env.step(env.action_space.sample())
    copy = pickle.loads(pickle.dumps(env))
    assert copy.unwrapped._sim.compiled == env.unwrapped._sim.compiled
    np.testing.assert_array_equal(copy.unwrapped._sim.valid, env.unwrapped._sim.valid)
    for _ in range(30):
        action = env.action_space.sample()
        same_step(env.step(action), copy.step(action))
    (obs, info), (copy_obs, copy_info) = env.reset(seed=8), copy.reset(seed=8)
    same_step((obs, 0, False, False, info), (copy_obs, 0, False, False, copy_info))
