"""EstimatorWrapper: the estimate as observation, on single and vector environments."""

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from stable_baselines3.common.env_checker import check_env as sb3_check_env

import marine_envs  # noqa: F401
from agents.evaluation import run_episode
from agents.lqr import LQRPolicy
from estimators import EstimatorWrapper, KalmanFilter, VectorEstimatorWrapper, wrap

USV = "marine_envs/USV-v0"


def usv_kf_env(**env_kwargs):
    env = gym.make(USV, **env_kwargs)
    return EstimatorWrapper(env, KalmanFilter.for_env(env))


@pytest.mark.parametrize("env_id", ["USV", "Hydrofoil", "ROV", "DPVessel", "Hovercraft"])
def test_wrapped_envs_pass_the_checkers(env_id):
    env = gym.make(f"marine_envs/{env_id}-v0")
    wrapped = wrap(env, KalmanFilter.for_env(env))
    check_env(wrapped, skip_render_check=True)
    sb3_check_env(wrapped, warn=False)
    obs, info = wrapped.reset(seed=0)
    n = len(env.unwrapped.model.state_names)
    assert obs.shape == (n,) and obs.dtype == np.float32
    assert info["estimate"].shape == (n,) and info["covariance"].shape == (n, n)
    assert info["innovation"].shape == (len(env.unwrapped.system.channels),)


NOISY = {"hs": 3.0, "tp": 9.0, "noise_std": 0.03}  # 1.7 deg, 1.7 deg/s: a cheap compass and gyro


def test_kf_estimates_the_unmeasured_sway_speed_and_helps_the_autopilot():
    env = usv_kf_env(**NOISY)
    policy_on_estimate = LQRPolicy.for_env(env.env, observed=None)
    errors, sway = [], []
    obs, info = env.reset(seed=3)
    for _ in range(600):
        obs, _, terminated, truncated, info = env.step(policy_on_estimate.predict(obs)[0])
        errors.append(info["estimate"] - info["state"])
        sway.append(info["state"][0])
    errors = np.array(errors)[100:]
    v_rms = np.sqrt(np.mean(np.square(sway[100:])))
    assert np.sqrt(np.mean(errors[:, 0] ** 2)) < 0.5 * v_rms  # v is never measured
    # the same seas and noise: LQR on the KF estimate costs less than LQR on raw sensors
    raw_env = gym.make(USV, **NOISY)
    raw = run_episode(raw_env, LQRPolicy.for_env(raw_env), seed=3, steps=600)
    filtered = run_episode(usv_kf_env(**NOISY), policy_on_estimate, seed=3, steps=600)
    assert filtered.episode_return > raw.episode_return  # minus the cost


def test_vector_wrapper_equals_single_wrappers_across_autoresets():
    kwargs = {"hs": 2.0, "tp": 8.0}
    n, steps = 3, 40
    vec = gym.make_vec(USV, num_envs=n, vectorization_mode="vector_entry_point",
                       max_episode_steps=12, **kwargs)
    single_env = gym.make(USV, **kwargs)
    wrapped = VectorEstimatorWrapper(vec, KalmanFilter.for_env(single_env))
    singles = [usv_kf_env(**kwargs) for _ in range(n)]
    obs_vec, _ = wrapped.reset(seed=10)
    obs_one = [s.reset(seed=10 + i)[0] for i, s in enumerate(singles)]
    rng = np.random.default_rng(0)
    ended = np.zeros(n, dtype=bool)
    for _ in range(steps):
        np.testing.assert_allclose(obs_vec, np.array(obs_one), atol=1e-6)
        actions = rng.uniform(-0.3, 0.3, (n, 1)).astype(np.float32)
        obs_vec, _, term, trunc, info = wrapped.step(actions)
        assert info["estimate"].shape == (n, 5)
        for i, s in enumerate(singles):
            # the vector env resets a finished boat on the next step, ignoring its action
            obs_one[i] = s.reset()[0] if ended[i] else s.step(actions[i])[0]
        ended = term | trunc


def test_sensor_channels_must_match_the_estimator():
    env = gym.make(USV)
    kf = KalmanFilter.for_env(gym.make("marine_envs/Hydrofoil-v0"))
    with pytest.raises(ValueError, match="expects measurements"):
        EstimatorWrapper(env, kf)


def test_missing_samples_are_not_fed_to_the_filter():
    """Dropped-out channels are held by the sensor and flagged: the filter coasts on them."""
    env = gym.make(USV, dropout={"psi": 0.5})
    wrapped = EstimatorWrapper(env, KalmanFilter.for_env(env))
    wrapped.reset(seed=1)
    held = 0
    for _ in range(100):
        _, _, _, _, info = wrapped.step(np.zeros(1, dtype=np.float32))
        if not info["measurement_mask"][1]:
            held += 1
            assert info["innovation"][1] == 0.0
    assert held > 20


def test_divergence_is_reported_and_reinitialised_on_request():
    """A heading sensor with a 30 deg bias the filter does not know: its innovations blow up."""
    for reinit in (False, True):
        env = gym.make(USV, bias={"psi": np.radians(30)}, noise_std=1e-4)
        kf = KalmanFilter.for_env(env, R=np.eye(4) * 1e-8)
        wrapped = EstimatorWrapper(env, kf, reinitialise_on_divergence=reinit)
        obs, info = wrapped.reset(seed=2)
        flags = []
        for _ in range(50):
            obs, _, _, _, info = wrapped.step(np.zeros(1, dtype=np.float32))
            flags.append(info["estimator_diverged"])
            assert np.isfinite(obs).all()
        assert any(flags)
