"""The public face of a simulated vehicle: ``env.unwrapped.system``, the action map, the
disturbance sources' own linear models and the true state's copy."""

import dataclasses

import gymnasium as gym
import numpy as np
import pytest

import marine_envs  # noqa: F401  (registers the environments)
from estimators.disturbance import disturbance_model
from marine_envs import ENVIRONMENTS
from marine_envs.envs.system import Actuation, System
from marine_envs.sea.processes import GaussMarkov, Stacked, StepEvent
from marine_envs.sea.shaping import linear_model_of, sample_blocks
from marine_envs.sea.waves import SeaState, WaveRealisation

#: Every vehicle, and the ROV with its six thrusters allocated.
SYSTEMS = [(env_id, {}) for env_id in ENVIRONMENTS] + [("marine_envs/ROV-v0",
                                                        {"actuation": "thrusters"})]


def system_of(env_id: str, **kwargs) -> System:
    return gym.make(env_id, disable_env_checker=True, **kwargs).unwrapped.system


def test_a_system_is_frozen():
    system = system_of("marine_envs/USV-v0")
    with pytest.raises(dataclasses.FrozenInstanceError):
        system.dt = 1.0  # type: ignore[misc]
    with pytest.raises(dataclasses.FrozenInstanceError):
        system.actuation.low = np.zeros(1)  # type: ignore[misc]
    with pytest.raises(ValueError, match="read-only"):
        system.task.q[0] = 1.0


@pytest.mark.parametrize("env_id", ENVIRONMENTS)
def test_single_and_vector_env_have_equal_systems(env_id):
    single = system_of(env_id)
    vector = gym.make_vec(env_id, num_envs=3, vectorization_mode="vector_entry_point")
    vector.reset(seed=1)
    vector.step(vector.action_space.sample())  # stepping changes no configuration
    assert single == vector.unwrapped.system
    assert single.vehicle == env_id.split("/")[1].removesuffix("-v0")


def test_systems_of_other_options_differ():
    usv = system_of("marine_envs/USV-v0")
    assert usv != system_of("marine_envs/USV-v0", hs=3.0)
    assert usv != system_of("marine_envs/USV-v0", noise_std=0.0)
    assert usv != system_of("marine_envs/Hydrofoil-v0")


@pytest.mark.parametrize(("env_id", "kwargs"), SYSTEMS)
def test_to_action_inverts_to_input(env_id, kwargs):
    system = system_of(env_id, **kwargs)
    act = system.actuation
    rng = np.random.default_rng(4)
    a = rng.uniform(-1, 1, (5, act.size))
    u = act.to_input(a)
    assert u.shape == (5, len(system.model.input_names))
    np.testing.assert_allclose(act.to_input(a[0]), u[0], rtol=0, atol=1e-12)
    # every input the actuators reach is applied again by its action (least squares where
    # thrusters are redundant); without an allocation the actions themselves come back
    back = act.to_action(u)
    np.testing.assert_allclose(act.to_input(back), u, rtol=0, atol=1e-12)
    np.testing.assert_allclose(act.to_action(u[0]), back[0], rtol=0, atol=1e-12)
    if act.matrix is None:
        np.testing.assert_allclose(back, a, rtol=0, atol=1e-12)
    else:
        np.testing.assert_allclose(act.to_action(act.to_input(back)), back, rtol=0, atol=1e-12)


@pytest.mark.parametrize(("env_id", "kwargs"), SYSTEMS)
def test_the_nominal_action_applies_the_nominal_input(env_id, kwargs):
    env = gym.make(env_id, disable_env_checker=True, **kwargs)
    system = env.unwrapped.system
    action = system.actuation.nominal_action(system.model)
    assert np.all(np.abs(action) <= 1)
    env.reset(seed=0)
    info = env.step(action.astype(np.float64))[4]
    np.testing.assert_allclose(info["action_commanded"], system.model.u0, rtol=0, atol=1e-12)


def test_an_actuation_names_a_matrix_of_the_wrong_shape():
    with pytest.raises(ValueError, match="matrix has shape"):
        Actuation(("f1", "f2"), np.zeros(2) - 1, np.ones(2), matrix=np.eye(3))


def test_the_true_state_is_a_copy():
    env = gym.make("marine_envs/USV-v0", disable_env_checker=True)
    _, info = env.reset(seed=2)
    x = env.unwrapped.true_state
    assert x.shape == (5,)
    np.testing.assert_array_equal(x, info["state"])
    x[:] = 99.0
    np.testing.assert_array_equal(env.unwrapped.true_state, info["state"])
    venv = gym.make_vec("marine_envs/USV-v0", num_envs=3, vectorization_mode="vector_entry_point")
    _, info = venv.reset(seed=2)
    xs = venv.unwrapped.true_state
    assert xs.shape == (3, 5)
    xs[:] = 99.0
    np.testing.assert_array_equal(venv.unwrapped.true_state, info["state"])


def test_set_state_moves_every_boat_and_measures_it():
    venv = gym.make_vec("marine_envs/USV-v0", num_envs=2, vectorization_mode="vector_entry_point",
                        noise_std=None, quantization=None)
    venv.reset(seed=0)
    x = np.array([[0.0, 0.1, 0.02, 0.0, 0.05], [0.0, -0.1, 0.0, 0.01, -0.05]])
    obs = venv.unwrapped.set_state(x)
    np.testing.assert_array_equal(venv.unwrapped.true_state, x)
    channels = [venv.unwrapped.system.model.state_names.index(c)
                for c in venv.unwrapped.system.channels]
    np.testing.assert_allclose(obs, x[:, channels], atol=1e-7)
    with pytest.raises(ValueError, match="state has shape"):
        venv.unwrapped.set_state(x[:1])


def test_a_systems_simulator_is_its_own():
    env = gym.make("marine_envs/ROV-v0", disable_env_checker=True)
    env.reset(seed=0)
    sim = env.unwrapped.system.simulator(3)
    sim.reset(np.arange(3), [np.random.default_rng(s) for s in range(3)])
    sim.step(np.zeros((3, 6)))
    assert sim.x.shape == (3, 13) and env.unwrapped.true_state.shape == (13,)
    assert env.unwrapped.system == system_of("marine_envs/ROV-v0")


# -- each disturbance source's own linear model ----------------------------------------------
def test_gauss_markov_variance_and_memory_match_a_long_run():
    source = GaussMarkov([1.0, -2.0], [0.5, 2.0], [2.0, 5.0], dt=0.1)
    model = source.linear_model(0.1, ("a", "b"))
    samples = sample_blocks(source, 400_000, seed=7)
    np.testing.assert_allclose(samples.var(axis=0), np.diag(model.stationary_covariance()),
                               rtol=0.05)
    np.testing.assert_allclose(samples.mean(axis=0), model.mean, atol=0.05)
    centred = samples - model.mean
    lag1 = (centred[1:] * centred[:-1]).mean(axis=0) / centred.var(axis=0)
    np.testing.assert_allclose(lag1, np.diag(model.F), atol=0.01)


def test_white_gauss_markov_channels_are_white_noise():
    model = GaussMarkov([0.0], [3.0], [0.0], dt=0.1).linear_model(0.1)
    assert model.size == 0 and model.names == ()
    np.testing.assert_allclose(model.stationary_covariance(), [[9.0]])


def test_the_wave_shaping_filter_has_the_variance_of_an_unseen_sea():
    sea = WaveRealisation(SeaState(hs=2.0, tp=8.0), dt=0.1)
    model = sea.linear_model(0.1, ("zeta",))
    samples = sample_blocks(sea, 2**15, seed=12345)  # a seed the fit never saw
    assert samples.var() == pytest.approx(model.stationary_covariance()[0, 0], rel=0.05)
    x = samples[:, 0] - samples.mean()
    lag1 = (x[1:] @ x[:-1]) / (x @ x)
    assert lag1 == pytest.approx(model.P0[0, 1] / model.P0[0, 0], abs=0.01)  # its memory
    assert 0 < model.wave_peaks["zeta"][1] < 0.5  # a resonance, not a lag
    with pytest.raises(ValueError, match="sampled every 0.1 s"):
        sea.linear_model(0.2)


def test_the_step_events_random_walk_carries_the_jump_over_its_window():
    event = StepEvent([0.0], [2.0], dt=0.1, window=(10.0, 30.0))
    model = event.linear_model(0.1, ("s",))
    window_steps = round(20.0 / 0.1)
    jumps = [sample_blocks(event, 400, seed)[-1, 0] - sample_blocks(event, 1, seed)[0, 0]
             for seed in range(20)]
    assert model.Q[0, 0] * window_steps == pytest.approx(np.mean(np.square(jumps)), rel=1e-9)
    assert model.P0[0, 0] == 0.0 and np.isinf(model.stationary_covariance()[0, 0])


def test_stacked_sources_are_their_models_side_by_side():
    flow = GaussMarkov([0.1, 0.0], [0.05, 0.05], [30.0, 30.0], dt=0.1)
    event = StepEvent([0.0], [1.0], dt=0.1, time=5.0)
    model = Stacked(flow, event).linear_model(0.1, ("n", "e", "s"))
    parts = [flow.linear_model(0.1, ("n", "e")), event.linear_model(0.1, ("s",))]
    assert model.names == ("n", "e", "s")
    np.testing.assert_array_equal(model.F, np.diag([*np.diag(parts[0].F), 1.0]))
    np.testing.assert_array_equal(model.mean, [0.1, 0.0, 0.0])


def test_a_source_without_a_model_is_white_noise_of_its_covariance():
    class Replayed:  # the source protocol only: bind, reset, step
        def bind(self, batch_size):
            self.k = 0

        def reset(self, idx, rngs):
            self.rng = rngs[0]

        def step(self):
            return self.rng.normal(3.0, 2.0, (1, 1))

    model = linear_model_of(Replayed(), 0.1, ("w",))
    assert model.size == 0
    assert model.mean[0] == pytest.approx(3.0, abs=0.15)
    assert model.white[0, 0] == pytest.approx(4.0, rel=0.1)


@pytest.mark.parametrize("env_id", ENVIRONMENTS)
def test_the_disturbance_model_is_the_sources_own(env_id):
    system = system_of(env_id)
    model = disturbance_model(system)
    names = system.model.disturbance_names
    if system.disturbances is None:
        assert model.size == 0
        return
    own = system.disturbances.linear_model(system.dt, names)
    for field in ("F", "C", "Q", "P0", "mean", "white"):
        np.testing.assert_array_equal(getattr(model, field), getattr(own, field))
