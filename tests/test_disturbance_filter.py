"""The Kalman filter with the disturbances' own models (``kf``): each channel gets the model its
source implies, and behind it LQR does better than behind the raw sensors."""

from __future__ import annotations

import copy
import importlib.util

import gymnasium as gym
import numpy as np
import pytest
import scipy.signal

import marine_envs  # noqa: F401
from agents.evaluation import evaluate, make_env
from agents.lqr import LQRPolicy
from estimators import registry
from estimators.disturbance import (
    MODEL_ERROR_MARGIN,
    augmented_system,
    disturbance_model,
    model_error_covariance,
)
from estimators.kalman import KalmanFilter

#: seeds no setting of the filter was chosen on (the README's tuning set is 1000-1005, its
#: held-out set 2000-2005)
SEEDS = list(range(3000, 3006))


def system_of(env_id: str, **kwargs):
    return gym.make(env_id, **kwargs).unwrapped.system


def test_gauss_markov_wind_is_its_exact_ar1_about_its_mean():
    system = system_of("marine_envs/Hovercraft-v0")
    wind, model = system.disturbances, disturbance_model(system)
    assert model.names == ("wind_north", "wind_east")
    np.testing.assert_allclose(np.diag(model.F), wind.a)
    np.testing.assert_allclose(np.diag(model.Q), wind.std**2 * (1 - wind.a**2))
    np.testing.assert_allclose(np.diag(model.P0), wind.std**2)
    np.testing.assert_allclose(model.mean, wind.mean)
    np.testing.assert_array_equal(model.C, np.eye(2))


def test_white_noise_channels_stay_process_noise():
    system = system_of("marine_envs/DPVessel-v0")
    model = disturbance_model(system)
    assert model.size == 0  # the DP vessel's six inputs are white: no state to add
    np.testing.assert_allclose(np.diag(model.white), system.disturbances.std**2)


def test_step_event_is_a_random_walk_carrying_the_jump_over_its_window():
    system = system_of("marine_envs/ROV-v0")
    model = disturbance_model(system)
    assert model.names == ("current_n", "current_e", "current_d", "s_cmd")
    morph = model.names.index("s_cmd")
    assert model.F[morph, morph] == 1.0 and model.P0[morph, morph] == 0.0
    window = system.disturbances.sources[1].window
    assert model.Q[morph, morph] == pytest.approx(1.0 / ((window[1] - window[0]) / system.dt))
    np.testing.assert_allclose(model.mean[:3], system.disturbances.sources[0].mean)


def test_wave_shaping_filter_peaks_where_an_unseen_realisation_of_the_sea_does():
    """The AR(2) of each USV wave channel peaks within 15 % of the periodogram peak of a
    realisation of a seed the fit never saw, and predicts most of the channel a step ahead."""
    system = system_of("marine_envs/USV-v0")
    model = disturbance_model(system)
    source = copy.deepcopy(system.disturbances)
    source.bind(1)
    source.reset(np.array([0]), [np.random.default_rng(12345)])
    samples = np.concatenate([source.step() for _ in range(2 ** 14)])
    for c, name in enumerate(system.model.disturbance_names):
        freq, power = scipy.signal.welch(samples[:, c], fs=1 / system.dt, nperseg=2048)
        peak = 2 * np.pi * freq[np.argmax(power)]
        wn, zeta = model.wave_peaks[name]
        assert wn == pytest.approx(peak, rel=0.15), name
        assert 0 < zeta < 0.5
        block = model.names.index(name)
        innovation, stationary = model.Q[block, block], model.P0[block, block]
        assert innovation < 0.2 * stationary  # a coloured signal: mostly predictable


def test_augmented_model_predicts_the_vehicle_with_the_disturbance_states():
    env = gym.make("marine_envs/Hovercraft-v0")
    system = augmented_system(env)
    n_x = len(env.unwrapped.system.model.state_names)
    assert system.state_names[n_x:] == ("wind_north", "wind_east")
    assert np.abs(system.F[:n_x, n_x:]).max() > 0  # the wind moves the craft
    np.testing.assert_array_equal(system.F[n_x:, :n_x], 0)  # and nothing moves the wind
    np.testing.assert_array_equal(system.H[:, n_x:], 0)  # which no sensor measures


def test_model_error_is_the_linearisations_own():
    """Zero for the linear USV (its exact model), and for the ROV as large as what its
    nonlinear equations do beyond the linear model along the calibration run."""
    for env_id, linear in (("marine_envs/USV-v0", True), ("marine_envs/ROV-v0", False)):
        env = gym.make(env_id)
        plain = augmented_system(env, model_error=False)
        full = augmented_system(env)
        n_x = len(env.unwrapped.system.model.state_names)
        extra = np.diag(full.Q - plain.Q)[:n_x]
        if linear:
            assert extra.max() < 1e-12
        else:
            assert extra.max() > 1e3 * np.diag(plain.Q)[:n_x].max()
    assert MODEL_ERROR_MARGIN >= 1


def test_model_error_covariance_vanishes_for_the_exact_discrete_model():
    system = system_of("marine_envs/USV-v0")
    model, x_ref, u_ref = system.model, system.task.x_ref, system.task.u_ref
    A, B, E = model.linearize(x_ref, u_ref)
    from marine_envs.models import zoh
    Phi, Gamma = zoh(A, np.column_stack([B, E, model.rhs(x_ref, u_ref)]), system.dt)
    n_u = B.shape[1]
    c = x_ref - Phi @ x_ref - Gamma[:, :n_u] @ u_ref + Gamma[:, -1]
    Q = model_error_covariance(system, Phi, Gamma[:, :n_u], Gamma[:, n_u:-1], c,
                               np.zeros(E.shape[1]))
    assert np.abs(Q).max() < 1e-20


def test_prior_is_the_envs_initial_state_distribution():
    """The DP vessel starts with a bias of tens of kN: the filter's prior says so."""
    env = gym.make("marine_envs/DPVessel-v0")
    system = augmented_system(env)
    bias = env.unwrapped.system.model.state_names.index("b_north")
    sigma_b = env.unwrapped.system.model.params.sigma_b[0]
    assert np.sqrt(system.P0[bias, bias]) == pytest.approx(sigma_b, rel=0.1)


def test_lqr_behind_kf_feeds_the_estimated_waves_forward():
    venv = make_env("marine_envs/USV-v0", 2, "kf")
    policy = LQRPolicy.for_env(venv)
    n_x = len(venv.unwrapped.system.model.state_names)
    assert policy.K.shape[1] > n_x and np.abs(policy.K[:, n_x:]).max() > 0
    plain = LQRPolicy.for_env(venv, feedforward=False)
    assert plain.K.shape[1] == n_x
    white = LQRPolicy.for_env(make_env("marine_envs/USV-v0", 2, "kf_white"))
    assert white.K.shape[1] == n_x


def mean_cost(env_id: str, estimator: str) -> float:
    return float(np.mean([row["cost"] for row in evaluate(env_id, "lqr", estimator, SEEDS)]))


@pytest.mark.parametrize("vehicle, bound", [("USV", 1.0), ("ROV", 0.9), ("Hovercraft", 1.0)])
def test_lqr_behind_kf_costs_no_more_than_behind_the_raw_sensors(vehicle, bound):
    env_id = f"marine_envs/{vehicle}-v0"
    assert mean_cost(env_id, "kf") <= bound * mean_cost(env_id, "raw")


def test_lqr_behind_kf_on_the_dp_vessel_comes_near_the_true_state():
    """The README's acceptance is 1.3x on held-out seeds; this guard leaves room for a seed set
    that is harder (measured on these seeds: see the README table)."""
    env_id = "marine_envs/DPVessel-v0"
    assert mean_cost(env_id, "kf") <= 1.45 * mean_cost(env_id, "true")
    assert mean_cost(env_id, "kf") < 0.85 * mean_cost(env_id, "kf_white")


# -- missing measurements ------------------------------------------------------------------------
def applicable(vehicle: str) -> list[str]:
    names = [name for name in registry.ESTIMATORS if name != "pd" or
             importlib.util.find_spec("cvxpy") is not None]
    env = gym.make(f"marine_envs/{vehicle}-v0")
    out = []
    for name in names:
        try:
            registry.make(name, env)
        except ValueError:
            continue
        out.append(name)
    return out


@pytest.mark.parametrize("vehicle", ["USV", "Hydrofoil", "ROV", "DPVessel", "Hovercraft"])
def test_every_estimator_takes_nan_as_a_dropped_channel(vehicle):
    """A NaN in a measurement (a logger's dropped sample) is a missing channel: the update is
    the one with that channel masked out, and the estimate stays finite."""
    env = gym.make(f"marine_envs/{vehicle}-v0")
    y, info = env.reset(seed=7)
    y = np.asarray(y, dtype=float)[None]
    u = np.asarray(env.unwrapped.system.task.u_ref)[None]
    gaps = y.copy()
    gaps[0, 0] = np.nan
    mask = np.ones(y.shape, dtype=bool)
    mask[0, 0] = False
    for name in applicable(vehicle):
        with_nan, masked = registry.make(name, env), registry.make(name, env)
        for est, (meas, m) in ((with_nan, (gaps, None)), (masked, (y, mask))):
            est.bind(1)
            est.reset()
            est.predict(u)
            est.update(meas, m)
        assert np.isfinite(with_nan.x).all(), name
        np.testing.assert_allclose(with_nan.x, masked.x, rtol=1e-12, atol=1e-12, err_msg=name)


def test_kf_is_a_kalman_filter_of_the_augmented_model():
    env = gym.make("marine_envs/ROV-v0")
    kf = registry.make("kf", env)
    assert isinstance(kf, KalmanFilter)
    assert kf.state_names[-1] == "s_cmd"
    assert registry.make("kf_white", env).state_names == env.unwrapped.system.model.state_names
