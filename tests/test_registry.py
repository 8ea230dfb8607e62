"""Every estimator by name (estimators.registry): what the evaluation path, the CLI and the
benchmark accept, and that each name builds a working filter or refuses a vehicle it does not
fit, saying why."""

import gymnasium as gym
import numpy as np
import pytest

import marine_envs  # noqa: F401
from agents.evaluation import evaluate
from estimators import registry
from estimators.base import Estimator
from estimators.wave_frequency import AdaptiveWaveFilter, WaveFilter

VEHICLES = ["marine_envs/USV-v0", "marine_envs/Hydrofoil-v0", "marine_envs/ROV-v0",
            "marine_envs/DPVessel-v0", "marine_envs/Hovercraft-v0"]
ONLY = {"pd": "USV", "wave": "DPVessel", "wave_adaptive": "DPVessel"}


def test_names_hold_the_oracle_the_sensors_and_every_estimator_of_the_documents():
    assert registry.names()[:2] == ("true", "raw")
    assert {"kf", "akf", "ekf", "pd", "wave", "wave_adaptive"} <= set(registry.ESTIMATORS)
    assert all(registry.DESCRIPTIONS[name] for name in registry.ESTIMATORS)


@pytest.mark.parametrize("env_id", VEHICLES)
@pytest.mark.parametrize("name", ["kf", "akf", "ekf", "pd", "wave", "wave_adaptive"])
def test_each_name_builds_an_estimator_or_says_which_vehicle_it_needs(env_id, name):
    env = gym.make_vec(env_id, num_envs=2, vectorization_mode="vector_entry_point")
    if name in ONLY and ONLY[name] not in env_id:
        with pytest.raises(ValueError, match="USV|DP vessel"):
            registry.make(name, env)
        return
    estimator = registry.make(name, env)
    assert isinstance(estimator, Estimator)
    observed = registry.observe(env, name)
    obs, info = observed.reset(seed=0)
    obs, *_ = observed.step(np.zeros(env.action_space.shape, dtype=np.float32))
    assert obs.shape[0] == 2 and np.isfinite(obs).all()


def test_the_wave_filter_serves_the_dp_vessel_better_than_the_white_noise_kf():
    # seeds 0-1, 300 steps (150 s): LQR on the wave filter's LF estimate costs less than on
    # the Kalman filter's, whose white process noise cannot separate the wave motion
    kwargs = dict(seeds=range(2), max_episode_steps=300)
    wave = evaluate("marine_envs/DPVessel-v0", "lqr", "wave", **kwargs)
    kf = evaluate("marine_envs/DPVessel-v0", "lqr", "kf_white", **kwargs)
    assert np.mean([r["cost"] for r in wave]) < 0.9 * np.mean([r["cost"] for r in kf])
    assert (np.mean([r["estimation_rms_north_lf"] for r in wave])
            < np.mean([r["estimation_rms_north_lf"] for r in kf]))


def test_the_wave_filters_are_the_dp_wave_frequency_patents():
    env = gym.make("marine_envs/DPVessel-v0")
    wave = registry.make("wave", env)
    assert isinstance(wave, WaveFilter)
    np.testing.assert_allclose(wave.w0_initial, env.unwrapped.system.model.params.w0)
    assert isinstance(registry.make("wave_adaptive", env), AdaptiveWaveFilter)


def test_unknown_and_invalid_names_are_refused_with_the_known_ones():
    env = gym.make("marine_envs/USV-v0")
    with pytest.raises(ValueError, match="'kalman' is unknown: one of .*'kf'"):
        registry.observe(env, "kalman")
    with pytest.raises(ValueError, match="is invalid"):
        registry.register("raw", lambda env: None)
    with pytest.raises(ValueError, match="is invalid"):
        registry.register("not a name", lambda env: None)


def test_a_registered_estimator_reaches_the_evaluation_path(monkeypatch):
    monkeypatch.setitem(registry.ESTIMATORS, "kf_copy", registry.ESTIMATORS["kf"])
    monkeypatch.setitem(registry.DESCRIPTIONS, "kf_copy", "a copy")
    rows = evaluate("marine_envs/USV-v0", "lqr", "kf_copy", seeds=range(1),
                    max_episode_steps=50)
    same = evaluate("marine_envs/USV-v0", "lqr", "kf", seeds=range(1), max_episode_steps=50)
    assert rows == same
