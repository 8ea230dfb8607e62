"""USV-v0 specifics and the simulator behaviour first built for it (what every environment shares
is tested in test_envs.py)."""

import math

import gymnasium as gym
import numpy as np
import pytest

import marine_envs  # noqa: F401
from marine_envs.envs import USVEnv
from marine_envs.envs.usv import make_usv_simulator
from marine_envs.models.integrate import RK4Step

ENV_ID = "marine_envs/USV-v0"
# settings that exercise every random and stateful sensor stage
BUSY_SENSORS = {"dropout": {"psi": 0.2, "phi": 0.1}, "delay": {"r": 2}, "bias": {"p": 0.001}}


def test_disturbance_seed_freezes_the_sea_but_not_the_noise():
    env = gym.make(ENV_ID, disturbance_seed=5, initial_spread={})
    records = []
    for seed in (1, 2):
        obs, _ = env.reset(seed=seed)
        steps = [env.step(np.zeros(1, dtype=np.float32)) for _ in range(30)]
        records.append((np.array([s[4]["disturbance"] for s in steps]),
                        np.array([s[0] for s in steps])))
    np.testing.assert_array_equal(records[0][0], records[1][0])
    assert not np.array_equal(records[0][1], records[1][1])


def test_observation_is_the_sensor_output_not_the_state():
    env = gym.make(ENV_ID)
    obs, info = env.reset(seed=0)
    true = info["state"][[1, 2, 3, 4]]
    assert not np.allclose(obs, true, atol=1e-9)  # noise and quantization
    assert np.allclose(obs, true, atol=np.radians(1.5))  # ... but small
    ideal = gym.make(ENV_ID, noise_std=0.0, quantization={}, waves=False)
    obs, info = ideal.reset(seed=0)
    np.testing.assert_allclose(obs, info["state"][[1, 2, 3, 4]].astype(np.float32))


def test_quantization_step_shows_in_the_observation():
    mu = np.radians(0.5)
    env = gym.make(ENV_ID, quantization={"psi": mu, "phi": mu}, noise_std=0.0)
    env.reset(seed=0)
    for _ in range(20):
        obs = env.step(np.array([0.3], dtype=np.float32))[0]
        for value in obs[[1, 3]]:
            assert abs(value / mu - round(value / mu)) < 1e-4


def test_reward_is_minus_the_lqr_stage_cost_of_state_and_input():
    env = gym.make(ENV_ID)
    system = env.unwrapped.system
    _, info = env.reset(seed=2)
    for action in (0.5, -0.2, 1.0):
        x = info["state"].copy()
        _, reward, _, _, info = env.step(np.array([action], dtype=np.float32))
        u = info["action_applied"]
        task = system.task
        assert reward == pytest.approx(-(x @ (task.q * x) + u @ (task.r * u)), rel=1e-12)
        assert u[0] == pytest.approx(action * math.radians(35))


def test_out_of_range_action_is_clipped_and_reported():
    env = gym.make(ENV_ID)
    env.reset(seed=0)
    info = env.step(np.array([3.0], dtype=np.float32))[4]
    assert info["action_clipped"] and info["action_applied"][0] == pytest.approx(math.radians(35))
    info = env.step(np.array([-0.5], dtype=np.float32))[4]
    assert not info["action_clipped"]
    vector = gym.make_vec(ENV_ID, num_envs=3, vectorization_mode="vector_entry_point")
    vector.reset(seed=0)
    info = vector.step(np.array([[0.2], [-7.0], [1.0]], dtype=np.float32))[4]
    np.testing.assert_array_equal(info["action_clipped"], [False, True, False])


def test_resetting_one_boat_keeps_the_others_clip_flags():
    sim = make_usv_simulator()
    sim.bind(2)
    sim.reset(np.arange(2), [np.random.default_rng(i) for i in range(2)])
    sim.apply(np.array([[5.0], [-5.0]]))
    sim.reset(np.array([1]), [np.random.default_rng(9)])
    np.testing.assert_array_equal(sim.clipped, [True, False])


@pytest.mark.parametrize("kwargs, name", [
    ({"hs": -1.0}, "hs"), ({"hs": float("nan")}, "hs"), ({"tp": 0.0}, "tp"),
    ({"quantization": 0.0}, "quantization"), ({"quantization": {"psi": -0.1}}, "quantization"),
    ({"noise_std": {"yaw": 0.1}}, "noise_std.*yaw"), ({"dropout": {"phi": 1.5}}, "dropout"),
    ({"delay": {"r": 0.5}}, "delay"), ({"dt": 0.0}, "dt"), ({"params": {"wn": -1}}, "wn"),
    ({"params": {"Kxx": 1}}, "Kxx"), ({"spectrum": "bretschneider"}, "spectrum"),
    ({"n_wave_components": 0}, "n_components"), ({"speed": -1.0}, "speed"),
    ({"max_roll": 0.0}, "max_roll"), ({"render_mode": "human"}, "render_mode"),
    ({"state_weights": {"psi": -1.0}}, "state_weights"),
])
def test_invalid_constructor_arguments_name_the_argument(kwargs, name):
    with pytest.raises(ValueError, match=name):
        USVEnv(**kwargs)


def test_capsize_terminates_and_reset_option_sets_the_state():
    env = gym.make(ENV_ID, max_roll=math.radians(20))
    x0 = np.array([0.0, 0.0, 0.1, 0.0, math.radians(25)])
    _, info = env.reset(seed=0, options={"state": x0})
    np.testing.assert_array_equal(info["state"], x0)
    assert env.step(np.zeros(1, dtype=np.float32))[2]  # terminated
    with pytest.raises(ValueError, match="options\\['state'\\]"):
        env.reset(options={"state": [0.0, 1.0]})
    with pytest.raises(ValueError, match="unknown reset option"):
        env.reset(options={"heading": 1.0})


def test_vector_env_autoresets_on_the_next_step():
    vector = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point",
                          max_episode_steps=5)
    vector.reset(seed=0)
    zeros = np.zeros((2, 1), dtype=np.float32)
    for _ in range(4):
        assert not vector.step(zeros)[3].any()
    assert vector.step(zeros)[3].all()  # truncated
    obs, reward, terminated, truncated, info = vector.step(zeros)
    np.testing.assert_array_equal(reward, 0.0)
    assert not truncated.any() and not terminated.any()
    np.testing.assert_array_equal(info["time"], 0.0)


def test_exact_and_rk4_integration_agree():
    settings = {"hs": 2.0}
    exact, rk4 = make_usv_simulator(**settings), make_usv_simulator(**settings)
    rk4.integrate = RK4Step(rk4.model, rk4.dt, substeps=8)
    for sim in (exact, rk4):
        sim.bind(2)
        sim.reset(np.arange(2), [np.random.default_rng(i) for i in range(2)])
    for k in range(300):
        action = np.full((2, 1), 0.5 * math.sin(0.05 * k))
        for sim in (exact, rk4):
            sim.apply(action)
            sim.advance()
    np.testing.assert_allclose(rk4.x, exact.x, atol=1e-6)


def test_long_batched_run_stays_finite_and_bounded():
    vector = gym.make_vec(ENV_ID, num_envs=16, vectorization_mode="vector_entry_point",
                          max_episode_steps=None, hs=4.0, dropout=0.1)
    obs, _ = vector.reset(seed=1)
    rng = np.random.default_rng(1)
    for _ in range(5000):  # 500 s of sea, 20 blocks
        obs, reward, terminated, _, info = vector.step(rng.uniform(-1, 1, (16, 1)))
        assert np.isfinite(obs).all() and np.isfinite(reward).all()
    assert np.isfinite(info["state"]).all()


def test_schedule_and_jonswap_seas_run():
    env = gym.make(ENV_ID, hs=[(0.0, 1.0), (20.0, 3.0)], spectrum="jonswap", tp=9.0)
    env.reset(seed=0)
    d = np.array([env.step(np.zeros(1, dtype=np.float32))[4]["disturbance"]
                  for _ in range(400)])
    assert np.abs(d[300:]).std() > 2 * np.abs(d[:100]).std()  # the sea builds up


def test_render_draws_heading_roll_and_rudder():
    env = gym.make(ENV_ID, render_mode="rgb_array")
    env.reset(seed=0, options={"state": np.zeros(5)})
    calm = env.render()
    env.reset(seed=0, options={"state": np.array([0, 0, 1.0, 0, 0.3])})
    env.step(np.array([1.0], dtype=np.float32))
    turned = env.render()
    assert calm.shape == turned.shape and calm.ndim == 3 and calm.dtype == np.uint8
    assert (calm != turned).any(axis=2).mean() > 0.01
    frames = gym.make_vec(ENV_ID, num_envs=2, vectorization_mode="vector_entry_point",
                          render_mode="rgb_array")
    frames.reset(seed=0)
    assert len(frames.render()) == 2
