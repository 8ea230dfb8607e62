"""The sea estimated online: a bank of disturbance-model filters weighted by their innovations
(``kf_sea``) finds the sea's peak where the filter of the design sea assumes a wrong one."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import marine_envs  # noqa: F401
from agents.evaluation import make_env
from agents.lqr import LQRPolicy
from estimators.disturbance import disturbance_model
from estimators.kalman import KalmanFilter
from estimators.sea_bank import MultipleModelFilter, design_sea, sea_bank_filter


def scalar_filter(a: float) -> KalmanFilter:
    return KalmanFilter([[a]], [[0.0]], [[1.0]], [[1.0]], [[0.5]], dt=0.1, P0=[[4.0]])


def ar1(a: float, steps: int, seed: int) -> np.ndarray:
    """``x_{k+1} = a x_k + w``, measured with noise: what :func:`scalar_filter` (a) models."""
    rng = np.random.default_rng(seed)
    x, out = 0.0, []
    for _ in range(steps):
        x = a * x + rng.normal()
        out.append(x + np.sqrt(0.5) * rng.normal())
    return np.array(out)


def run(bank: MultipleModelFilter, ys: np.ndarray) -> None:
    for y in ys:
        bank.predict(np.zeros((bank.batch_size, 1)))
        bank.update(np.full((bank.batch_size, 1), y))


def test_the_bank_weighs_the_model_that_made_the_data():
    bank = MultipleModelFilter([scalar_filter(a) for a in (0.3, 0.95)], {"a": [0.3, 0.95]},
                               memory=1e6)
    run(bank, ar1(0.95, 400, seed=11))
    assert bank.weights[0, 1] > 0.999 and bank.parameters["a"][0] == pytest.approx(0.95, 1e-3)
    bank.reset()
    np.testing.assert_allclose(bank.weights, 0.5)
    run(bank, ar1(0.3, 400, seed=12))
    assert bank.weights[0, 0] > 0.999


def test_the_mixture_covariance_holds_the_spread_of_the_filters():
    bank = MultipleModelFilter([scalar_filter(a) for a in (0.3, 0.95)], {"a": [0.3, 0.95]})
    run(bank, ar1(0.6, 5, seed=13))
    w, xs = bank.weights[0], np.array([f.x[0, 0] for f in bank.filters])
    Ps = np.array([f.P[0, 0, 0] for f in bank.filters])
    assert bank.x[0, 0] == pytest.approx(w @ xs)
    assert bank.P[0, 0, 0] == pytest.approx(w @ (Ps + (xs - w @ xs) ** 2))


def test_a_missing_measurement_adds_no_evidence():
    """A dropped sample scores no filter: the scores only fade with the bank's memory."""
    bank = MultipleModelFilter([scalar_filter(a) for a in (0.3, 0.95)], {"a": [0.3, 0.95]},
                               memory=50.0)
    run(bank, ar1(0.95, 20, seed=14))
    before = bank.scores.copy()
    bank.predict(np.zeros((1, 1)))
    bank.update(np.array([[np.nan]]))
    np.testing.assert_allclose(bank.scores, np.exp(-0.1 / 50.0) * before, rtol=1e-12)
    assert np.isfinite(bank.x).all()


def test_the_bank_is_refused_where_there_is_no_sea_and_for_bad_settings():
    with pytest.raises(ValueError, match="no wave-driven"):
        sea_bank_filter(gym.make("marine_envs/ROV-v0"))
    with pytest.raises(ValueError, match="memory"):
        MultipleModelFilter([scalar_filter(0.5)], {"a": [0.5]}, memory=0.0)
    with pytest.raises(ValueError, match="one value per filter"):
        MultipleModelFilter([scalar_filter(0.5)], {"a": [0.5, 0.6]})


def test_the_hydrofoil_bank_finds_a_sea_the_design_filter_gets_wrong():
    """A sea off the bank's grid and away from the design sea (seeds no setting was chosen
    on): after 60 s the bank's peak is within 10 % of the sea's, the design sea's is 26 % off."""
    env_id, sea = "marine_envs/Hydrofoil-v0", {"tp": 1.9, "hs": 0.12}
    truth = next(iter(disturbance_model(gym.make(env_id, **sea).unwrapped.system)
                      .wave_peaks.values()))[0]
    design = next(iter(disturbance_model(gym.make(env_id).unwrapped.system)
                       .wave_peaks.values()))[0]
    assert abs(design / truth - 1) > 0.2
    assert design_sea(env_id) == pytest.approx((2.75, 0.3), abs=0.01)
    venv = make_env(env_id, 2, "kf_sea", env_kwargs=sea)
    policy = LQRPolicy.for_env(venv)
    obs, _ = venv.reset(seed=3000)
    for k in range(1200):
        obs, *_ = venv.step(policy.predict(obs, episode_start=np.full(2, k == 0))[0])
    peak = venv.estimator.parameters["zeta_dot_1_peak"]
    np.testing.assert_array_less(np.abs(peak / truth - 1), 0.10)
