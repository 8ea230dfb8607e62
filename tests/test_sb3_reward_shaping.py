"""The reward shaping of training: the action-rate penalty (agents.sb3.ActionRatePenalty,
setting ``action_rate_penalty``) and the fixed reward scale (agents.sb3.RewardScale, setting
``reward_scale``): what they do to the reward, and that a run's settings put them in front of the
agent."""

from __future__ import annotations

import numpy as np
import pytest

from agents.sb3 import ActionRatePenalty, RewardScale, check_hyperparams, make_vec_env, settings
from agents.sb3.training import _algorithm_kwargs, _environments

USV = "marine_envs/USV-v0"


def test_each_step_pays_its_action_change_squared_and_an_episode_start_pays_nothing():
    steps, weight = 25, 3.0
    plain = make_vec_env(USV, 3, estimator="kf", seed=7, max_episode_steps=steps)
    penalised = ActionRatePenalty(make_vec_env(USV, 3, estimator="kf", seed=7,
                                               max_episode_steps=steps), weight)
    plain.reset(), penalised.reset()
    rng = np.random.default_rng(0)
    previous = None
    charged_steps = 0
    for k in range(2 * steps + 5):  # across the time limit: a new episode on every boat
        action = rng.uniform(-1, 1, size=(3, *plain.action_space.shape)).astype(np.float32)
        _, base, done_plain, _ = plain.step(action)
        _, reward, done, _ = penalised.step(action)
        np.testing.assert_array_equal(done, done_plain)
        first = k % steps == 0  # every boat's episode starts here
        expected = base if first else base - weight * np.sum((action - previous) ** 2, axis=1)
        np.testing.assert_allclose(reward, expected, rtol=1e-5, atol=1e-6)
        charged_steps += not first
        previous = action
    assert charged_steps == 2 * steps + 5 - 3


def test_a_steady_action_costs_nothing_and_a_bad_weight_is_refused():
    penalised = ActionRatePenalty(make_vec_env(USV, 2, seed=1), 10.0)
    plain = make_vec_env(USV, 2, seed=1)
    penalised.reset(), plain.reset()
    action = np.full((2, *plain.action_space.shape), 0.3, dtype=np.float32)
    for _ in range(10):
        _, reward, _, _ = penalised.step(action)
        _, base, _, _ = plain.step(action)
        np.testing.assert_allclose(reward, base, rtol=1e-6)
    for bad in (-1.0, float("nan"), float("inf")):
        with pytest.raises(ValueError, match="action_rate_penalty"):
            ActionRatePenalty(plain, bad)


def test_the_setting_puts_the_penalty_in_training_and_a_bad_value_is_named(tmp_path):
    config = settings(USV, "ppo", "kf", hyperparams={"action_rate_penalty": 2.5,
                                                     "normalize": False})
    params, _, normalize, normalize_kwargs, penalty, _ = _algorithm_kwargs(config)
    assert "action_rate_penalty" not in params  # ours, not PPO's keyword
    venv = _environments(config, None, params, normalize, normalize_kwargs, penalty)
    assert isinstance(venv, ActionRatePenalty) and venv.weight == 2.5
    venv.close()
    with pytest.raises(ValueError, match="action_rate_penalty=-1.0 is invalid"):
        settings(USV, "ppo", hyperparams={"action_rate_penalty": -1.0})
    with pytest.raises(ValueError, match="action_rate_penalty"):
        check_hyperparams({USV: {"ppo": {"action_rate_penalty": "high"}}}, tmp_path / "h.yaml")


def test_the_reward_scale_multiplies_every_reward_and_a_bad_scale_is_refused():
    scaled = RewardScale(make_vec_env(USV, 2, estimator="kf", seed=3), 1.0e-3)
    plain = make_vec_env(USV, 2, estimator="kf", seed=3)
    scaled.reset(), plain.reset()
    rng = np.random.default_rng(1)
    for _ in range(20):
        action = rng.uniform(-1, 1, size=(2, *plain.action_space.shape)).astype(np.float32)
        _, reward, _, _ = scaled.step(action)
        _, base, _, _ = plain.step(action)
        assert np.all(base < 0)  # a cost: the test sees the rewards, not zeros
        np.testing.assert_allclose(reward, 1.0e-3 * base, rtol=1e-6)
    for bad in (0.0, -1.0, float("nan")):
        with pytest.raises(ValueError, match="reward_scale"):
            RewardScale(plain, bad)


def test_the_reward_scale_setting_wraps_the_training_env_inside_the_normalisation():
    config = settings(USV, "ppo", "kf", hyperparams={"reward_scale": 0.01,
                                                     "normalize": {"norm_reward": False}})
    params, _, normalize, normalize_kwargs, penalty, _ = _algorithm_kwargs(config)
    venv = _environments(config, None, params, normalize, normalize_kwargs, penalty)
    assert isinstance(venv.venv, RewardScale) and venv.venv.scale == 0.01
    venv.close()
    with pytest.raises(ValueError, match="reward_scale=0 is invalid"):
        settings(USV, "ppo", hyperparams={"reward_scale": 0})
